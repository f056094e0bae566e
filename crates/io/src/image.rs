//! PNG output of rendered images (docs/design.md §3: 8-bit sRGB-encoded unless linear is asked for).

use crate::atomic::write_atomic;
use crate::error::{IoError, Result};
use std::path::Path;
use volsplat_core::{Image, ScalarImage};

/// Bits per channel of a PNG file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum PngBitDepth {
    /// 8 bits per channel (code values 0–255).
    #[default]
    Eight,
    /// 16 bits per channel (code values 0–65535).
    Sixteen,
}

impl PngBitDepth {
    /// Parses a bit count as given on a command line: 8 or 16.
    pub fn from_bits(bits: u32) -> Option<Self> {
        match bits {
            8 => Some(PngBitDepth::Eight),
            16 => Some(PngBitDepth::Sixteen),
            _ => None,
        }
    }

    /// The number of bits per channel.
    pub fn bits(self) -> u32 {
        match self {
            PngBitDepth::Eight => 8,
            PngBitDepth::Sixteen => 16,
        }
    }

    fn max_code(self) -> f64 {
        match self {
            PngBitDepth::Eight => 255.0,
            PngBitDepth::Sixteen => 65535.0,
        }
    }

    fn png(self) -> png::BitDepth {
        match self {
            PngBitDepth::Eight => png::BitDepth::Eight,
            PngBitDepth::Sixteen => png::BitDepth::Sixteen,
        }
    }
}

/// How [`write_png`] turns a premultiplied linear RGBA float image into an RGB PNG.
#[derive(Debug, Clone, PartialEq)]
pub struct PngSettings {
    /// Bits per channel (default 8).
    pub bits: PngBitDepth,
    /// `false` (default; decision 0012): store linear values, as VTK, ParaView and 3D Slicer
    /// write their framebuffers, and write `gAMA` = 1.0. `true` (`--srgb`): encode linear values
    /// with the sRGB transfer curve and write an `sRGB` chunk. Applies to both bit depths.
    pub srgb: bool,
    /// Opaque background colour, linear RGB in [0, 1], that the image is composited over
    /// (default black).
    pub background: [f32; 3],
}

impl Default for PngSettings {
    fn default() -> Self {
        PngSettings {
            bits: PngBitDepth::Eight,
            srgb: false,
            background: [0.0; 3],
        }
    }
}

/// The sRGB transfer function (IEC 61966-2-1): linear [0, 1] → encoded [0, 1].
pub fn srgb_encode(linear: f64) -> f64 {
    if linear <= 0.0031308 {
        12.92 * linear
    } else {
        1.055 * linear.powf(1.0 / 2.4) - 0.055
    }
}

/// Quantises a value in [0, 1] (clamped; NaN → 0) to a code value.
fn quantize(v: f64, srgb: bool, bits: PngBitDepth) -> u16 {
    // NaN fails `v > 0` and maps to 0.
    let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
    let v = if srgb { srgb_encode(v) } else { v };
    (v * bits.max_code()).round().clamp(0.0, bits.max_code()) as u16
}

fn check_size(path: &Path, width: usize, height: usize) -> Result<(u32, u32)> {
    let w = u32::try_from(width)
        .ok()
        .filter(|&w| w > 0 && w <= i32::MAX as u32);
    let h = u32::try_from(height)
        .ok()
        .filter(|&h| h > 0 && h <= i32::MAX as u32);
    match (w, h) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(IoError::invalid_argument(
            path,
            "image size",
            format!("{width}×{height} pixels; PNG needs 1 to 2³¹−1 pixels on each side"),
        )),
    }
}

fn push_code(out: &mut Vec<u8>, code: u16, bits: PngBitDepth) {
    match bits {
        PngBitDepth::Eight => out.push(code as u8),
        PngBitDepth::Sixteen => out.extend_from_slice(&code.to_be_bytes()),
    }
}

/// The bytes of a PNG file; `path` only names the image in errors.
fn encode_png_data(
    path: &Path,
    width: u32,
    height: u32,
    color: png::ColorType,
    bits: PngBitDepth,
    srgb_chunk: Option<bool>,
    data: &[u8],
) -> Result<Vec<u8>> {
    let png_err = |e: png::EncodingError| match e {
        png::EncodingError::IoError(e) => IoError::os(path, "write", e),
        other => IoError::Png {
            path: path.to_path_buf(),
            message: other.to_string(),
        },
    };
    let mut out = Vec::with_capacity(data.len() / 2 + 1024);
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_color(color);
        enc.set_depth(bits.png());
        match srgb_chunk {
            Some(true) => enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual),
            Some(false) => enc.set_source_gamma(png::ScaledFloat::new(1.0)),
            None => {}
        }
        let mut writer = enc.write_header().map_err(png_err)?;
        writer.write_image_data(data).map_err(png_err)?;
        writer.finish().map_err(png_err)?;
    }
    Ok(out)
}

/// The RGB code values [`write_png`] stores for `image` (row-major, three per pixel): each
/// premultiplied pixel composited over `settings.background` (`c + (1 − a)·background`, linear),
/// clamped to [0, 1] (NaN → 0), encoded (linear or sRGB) and quantised to the bit depth.
pub fn rgb_codes(image: &Image, settings: &PngSettings) -> Vec<u16> {
    let bg = settings.background;
    let mut codes = Vec::with_capacity(image.pixels().len() * 3);
    for p in image.pixels() {
        let t = 1.0 - p[3] as f64;
        for c in 0..3 {
            let v = p[c] as f64 + t * bg[c] as f64;
            codes.push(quantize(v, settings.srgb, settings.bits));
        }
    }
    codes
}

/// Writes a premultiplied RGBA float image as an opaque RGB PNG.
///
/// Each pixel is composited over `settings.background` (`c + (1 − a)·background`, linear), clamped
/// to [0, 1] (NaN → 0), then encoded as `settings` says: sRGB-encoded with an `sRGB` chunk, or
/// linear with `gAMA` 1.0, at 8 or 16 bits. Row 0 of the image is the top row of the PNG. Written
/// atomically. Errors if the image is empty.
pub fn write_png(path: impl AsRef<Path>, image: &Image, settings: &PngSettings) -> Result<()> {
    let path = path.as_ref();
    write_encoded(path, rgb_png(path, image, settings)?)
}

/// The bytes [`write_png`] writes for `image`, in memory (for a server or a notebook that sends
/// them on): the same encoder, settings and chunks, so the bytes are identical.
pub fn encode_png(image: &Image, settings: &PngSettings) -> Result<Vec<u8>> {
    rgb_png(Path::new(IN_MEMORY), image, settings)
}

/// What errors of the in-memory encoders name instead of a file.
const IN_MEMORY: &str = "(image in memory)";

fn write_encoded(path: &Path, bytes: Vec<u8>) -> Result<()> {
    write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(&bytes)
            .map_err(|e| IoError::os(path, "write", e))
    })
}

fn rgb_png(path: &Path, image: &Image, settings: &PngSettings) -> Result<Vec<u8>> {
    let (w, h) = check_size(path, image.width(), image.height())?;
    let codes = rgb_codes(image, settings);
    let bytes_per = if settings.bits == PngBitDepth::Sixteen {
        2
    } else {
        1
    };
    let mut data = Vec::with_capacity(codes.len() * bytes_per);
    for &c in &codes {
        push_code(&mut data, c, settings.bits);
    }
    encode_png_data(
        path,
        w,
        h,
        png::ColorType::Rgb,
        settings.bits,
        Some(settings.srgb),
        &data,
    )
}

/// Writes a scalar image as a greyscale PNG: `lo` maps to black and `hi` to white, linearly in
/// the image's units (values outside are clamped, NaN → black). Code values are proportional to
/// `(v − lo)/(hi − lo)` (a display window, no colour-management chunk written). Written
/// atomically. Errors if the image is empty or `lo`, `hi` are not finite with `lo < hi`.
pub fn write_png_gray(
    path: impl AsRef<Path>,
    image: &ScalarImage,
    lo: f32,
    hi: f32,
    bits: PngBitDepth,
) -> Result<()> {
    let path = path.as_ref();
    write_encoded(path, gray_png(path, image, lo, hi, bits)?)
}

/// The bytes [`write_png_gray`] writes, in memory (identical bytes).
pub fn encode_png_gray(
    image: &ScalarImage,
    lo: f32,
    hi: f32,
    bits: PngBitDepth,
) -> Result<Vec<u8>> {
    gray_png(Path::new(IN_MEMORY), image, lo, hi, bits)
}

fn gray_png(
    path: &Path,
    image: &ScalarImage,
    lo: f32,
    hi: f32,
    bits: PngBitDepth,
) -> Result<Vec<u8>> {
    let (w, h) = check_size(path, image.width(), image.height())?;
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(IoError::invalid_argument(
            path,
            "grey window (lo, hi)",
            format!("({lo}, {hi}); need finite numbers with lo < hi"),
        ));
    }
    let (lo, hi) = (lo as f64, hi as f64);
    let mut data = Vec::with_capacity(image.values().len() * 2);
    for &v in image.values() {
        let t = (v as f64 - lo) / (hi - lo);
        push_code(&mut data, quantize(t, false, bits), bits);
    }
    encode_png_data(path, w, h, png::ColorType::Grayscale, bits, None, &data)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(
        path: &Path,
    ) -> (
        png::OutputInfo,
        Vec<u8>,
        Option<png::SrgbRenderingIntent>,
        bool,
    ) {
        let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
        let mut reader = png::Decoder::new(file).read_info().unwrap();
        let srgb = reader.info().srgb;
        let gama1 = reader
            .info()
            .gama_chunk
            .is_some_and(|g| g.into_value() == 1.0);
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        (info, buf, srgb, gama1)
    }

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 4]) -> Image {
        let mut px = Vec::new();
        for y in 0..h {
            for x in 0..w {
                px.push(f(x, y));
            }
        }
        Image::from_pixels(w, h, px).unwrap()
    }

    /// The in-memory encoders give exactly the bytes the writers put in a file, for every
    /// bit depth and encoding and for grey windows.
    #[test]
    fn encoded_bytes_are_the_written_file() {
        let dir = tempfile::tempdir().unwrap();
        let img = image(7, 5, |x, y| {
            let v = (x as f32 * 0.13 + y as f32 * 0.07).min(1.0);
            [v * 0.5, v * 0.25, v, v]
        });
        for bits in [PngBitDepth::Eight, PngBitDepth::Sixteen] {
            for srgb in [false, true] {
                let settings = PngSettings {
                    bits,
                    srgb,
                    background: [0.1, 0.2, 0.3],
                };
                let path = dir.path().join("rgb.png");
                write_png(&path, &img, &settings).unwrap();
                let bytes = encode_png(&img, &settings).unwrap();
                assert_eq!(bytes, std::fs::read(&path).unwrap(), "{bits:?} srgb {srgb}");
            }
            let values =
                ScalarImage::from_values(3, 2, vec![f32::NAN, -1.0, 0.5, 2.0, 7.5, 9.0]).unwrap();
            let path = dir.path().join("grey.png");
            write_png_gray(&path, &values, 0.0, 8.0, bits).unwrap();
            let bytes = encode_png_gray(&values, 0.0, 8.0, bits).unwrap();
            assert_eq!(bytes, std::fs::read(&path).unwrap(), "grey {bits:?}");
        }
        let e = encode_png_gray(&ScalarImage::new(2, 2), 1.0, 1.0, PngBitDepth::Eight)
            .unwrap_err()
            .to_string();
        assert!(e.contains("in memory") && e.contains("lo < hi"), "{e}");
    }

    #[test]
    fn srgb_half_is_188() {
        assert_eq!(quantize(0.5, true, PngBitDepth::Eight), 188);
        assert_eq!(quantize(0.5, false, PngBitDepth::Eight), 128);
        assert_eq!(quantize(f64::NAN, true, PngBitDepth::Eight), 0);
        assert_eq!(quantize(7.0, true, PngBitDepth::Sixteen), 65535);
        assert_eq!(quantize(-1.0, true, PngBitDepth::Sixteen), 0);
    }

    #[test]
    fn png_8bit_srgb_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        // (0,0): opaque grey 0.5; (1,0): transparent over a white background; (0,1): half-
        // transparent red over white; (1,1): opaque white.
        let img = image(2, 2, |x, y| match (x, y) {
            (0, 0) => [0.5, 0.5, 0.5, 1.0],
            (1, 0) => [0.0, 0.0, 0.0, 0.0],
            (0, 1) => [0.5, 0.0, 0.0, 0.5],
            _ => [1.0, 1.0, 1.0, 1.0],
        });
        let s = PngSettings {
            background: [1.0, 1.0, 1.0],
            srgb: true,
            ..PngSettings::default()
        };
        write_png(&p, &img, &s).unwrap();
        let (info, buf, srgb, _) = decode(&p);
        assert_eq!((info.width, info.height), (2, 2));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        assert!(srgb.is_some());
        assert_eq!(&buf[0..3], &[188, 188, 188]);
        assert_eq!(&buf[3..6], &[255, 255, 255]);
        // red: 0.5 + 0.5·1 = 1 → 255; green, blue: 0 + 0.5·1 = 0.5 → 188.
        assert_eq!(&buf[6..9], &[255, 188, 188]);
        assert_eq!(&buf[9..12], &[255, 255, 255]);
    }

    /// Decision 0012: the default is linear, as VTK writes PNGs.
    #[test]
    fn png_default_is_linear() {
        assert!(!PngSettings::default().srgb);
    }

    #[test]
    fn png_linear_and_16bit() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("lin.png");
        let img = image(1, 1, |_, _| [0.5, 0.25, 1.0, 1.0]);
        let s = PngSettings {
            srgb: false,
            ..PngSettings::default()
        };
        write_png(&p, &img, &s).unwrap();
        let (_, buf, srgb, gama1) = decode(&p);
        assert!(srgb.is_none() && gama1);
        assert_eq!(buf, vec![128, 64, 255]);

        let s16 = PngSettings {
            bits: PngBitDepth::Sixteen,
            srgb: false,
            ..PngSettings::default()
        };
        write_png(&p, &img, &s16).unwrap();
        let (info, buf, _, _) = decode(&p);
        assert_eq!(info.bit_depth, png::BitDepth::Sixteen);
        let px: Vec<u16> = buf
            .chunks(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect();
        assert_eq!(px, vec![32768, 16384, 65535]);

        let s16srgb = PngSettings {
            bits: PngBitDepth::Sixteen,
            srgb: true,
            ..PngSettings::default()
        };
        write_png(&p, &img, &s16srgb).unwrap();
        let (_, buf, srgb, _) = decode(&p);
        assert!(srgb.is_some());
        let r = u16::from_be_bytes([buf[0], buf[1]]);
        assert_eq!(r, (srgb_encode(0.5) * 65535.0).round() as u16);
    }

    #[test]
    fn png_gray_window() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("g.png");
        let img = ScalarImage::from_values(4, 1, vec![-1.0, 0.0, 5.0, 20.0]).unwrap();
        write_png_gray(&p, &img, 0.0, 10.0, PngBitDepth::Eight).unwrap();
        let (info, buf, _, _) = decode(&p);
        assert_eq!(info.color_type, png::ColorType::Grayscale);
        assert_eq!(buf, vec![0, 0, 128, 255]);
        write_png_gray(&p, &img, 0.0, 10.0, PngBitDepth::Sixteen).unwrap();
        let (_, buf, _, _) = decode(&p);
        assert_eq!(u16::from_be_bytes([buf[4], buf[5]]), 32768);
        let e = write_png_gray(&p, &img, 1.0, 1.0, PngBitDepth::Eight).unwrap_err();
        assert!(e.to_string().contains("lo < hi"), "{e}");
    }

    #[test]
    fn png_rejects_empty_image_and_missing_dir() {
        let dir = tempfile::tempdir().unwrap();
        let e = write_png(
            dir.path().join("e.png"),
            &Image::new(0, 3),
            &PngSettings::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("image size"), "{e}");
        let p = dir.path().join("nope").join("x.png");
        let e = write_png(&p, &Image::new(1, 1), &PngSettings::default()).unwrap_err();
        assert!(e.to_string().contains("x.png"), "{e}");
        assert!(!p.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn bit_depth_parsing() {
        assert_eq!(PngBitDepth::from_bits(16), Some(PngBitDepth::Sixteen));
        assert_eq!(PngBitDepth::from_bits(12), None);
        assert_eq!(PngBitDepth::Eight.bits(), 8);
    }
}
