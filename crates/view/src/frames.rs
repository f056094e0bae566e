//! Frames as bytes: JPEG previews, the PNG final frame (`volsplat render`'s own bytes), and
//! the volume's histogram for the transfer-function editor.

use crate::error::{Result, ViewError};
use volsplat::core::{AnyVolume, Histogram};
use volsplat::io::{PngBitDepth, PngSettings};
use volsplat::{Output, RenderRequest};

/// Default JPEG quality of previews (docs/viewer.md, "Frames": 512² previews at 85 encode in
/// a few milliseconds and lose less to JPEG than the preview loses to its size).
pub const DEFAULT_PREVIEW_QUALITY: u8 = 85;

/// The picture a frame shows as 8-bit RGB, row 0 at the top: exactly the code values of the
/// 8-bit PNG `volsplat render` writes for it (composite over the background, encoded linear or
/// sRGB; MIP, MinIP and X-ray values through the grey window, X-ray without one from 0 to its
/// brightest value), whatever the bit depth of the file the screenshot button saves. The mode
/// and the output options are `request`'s, the request `out` was rendered from (a preview's
/// request carries its final frame's options).
pub fn display_rgb(out: &Output, request: &RenderRequest) -> (usize, usize, Vec<u8>) {
    let (w, h) = (out.image.width(), out.image.height());
    let (mode, output) = (request.mode, &request.output);
    let window = output.window.map(|[lo, hi]| (lo, hi));
    let grey = volsplat::writes_values(out.values.is_some(), mode, window);
    if let (Some(values), true) = (&out.values, grey) {
        let (lo, hi) = window.unwrap_or_else(|| {
            let max = values
                .values()
                .iter()
                .filter(|v| v.is_finite())
                .fold(0.0f32, |m, &v| m.max(v));
            (0.0, max.max(f32::MIN_POSITIVE))
        });
        // volsplat_io::write_png_gray's code values, computed as it computes them.
        let (lo, hi) = (lo as f64, hi as f64);
        let rgb = values
            .values()
            .iter()
            .flat_map(|&v| {
                let t = (v as f64 - lo) / (hi - lo);
                let t = if t > 0.0 { t.min(1.0) } else { 0.0 };
                let c = (t * 255.0).round().clamp(0.0, 255.0) as u8;
                [c, c, c]
            })
            .collect();
        return (w, h, rgb);
    }
    let settings = PngSettings {
        bits: PngBitDepth::Eight,
        srgb: output.srgb,
        background: output.background,
    };
    let rgb = volsplat::io::rgb_codes(&out.image, &settings)
        .into_iter()
        .map(|c| c.min(255) as u8)
        .collect();
    (w, h, rgb)
}

/// A preview as JPEG at `quality` (1..=100).
pub fn preview_jpeg(out: &Output, request: &RenderRequest, quality: u8) -> Result<Vec<u8>> {
    let (w, h, rgb) = display_rgb(out, request);
    let (w16, h16) = match (u16::try_from(w), u16::try_from(h)) {
        (Ok(w), Ok(h)) => (w, h),
        _ => return Err(ViewError::Encode(format!("{w}×{h} is too large for JPEG"))),
    };
    let mut bytes = Vec::with_capacity(w * h / 4 + 1024);
    let encoder = jpeg_encoder::Encoder::new(&mut bytes, quality.clamp(1, 100));
    encoder
        .encode(&rgb, w16, h16, jpeg_encoder::ColorType::Rgb)
        .map_err(|e| ViewError::Encode(e.to_string()))?;
    Ok(bytes)
}

/// The final frame as the page receives it: [`display_rgb`]'s code values, lossless, in a PNG
/// compressed for speed (fdeflate) rather than size: the pixels of `render`'s file, a few
/// times faster to encode than its bytes (docs/viewer.md, "Frames").
pub fn final_frame(out: &Output, request: &RenderRequest) -> Result<Vec<u8>> {
    let (w, h, rgb) = display_rgb(out, request);
    let mut bytes = Vec::with_capacity(rgb.len() / 2 + 1024);
    {
        let mut enc = png::Encoder::new(&mut bytes, w as u32, h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let enc_err = |e: png::EncodingError| ViewError::Encode(e.to_string());
        let mut writer = enc.write_header().map_err(enc_err)?;
        writer.write_image_data(&rgb).map_err(enc_err)?;
        writer.finish().map_err(enc_err)?;
    }
    Ok(bytes)
}

/// The screenshot: exactly the bytes `volsplat render --scene S -o FILE.png` writes for the
/// saved request `request` (its mode and output options; [`Output::png_bytes`]).
pub fn screenshot_png(out: &Output, request: &RenderRequest) -> Result<Vec<u8>> {
    Ok(out.png_bytes(request)?)
}

/// The smallest and largest finite value of a MIP, MinIP or X-ray frame.
pub fn values_range(out: &Output) -> Option<[f32; 2]> {
    let values = out.values.as_ref()?;
    let (lo, hi) = values
        .values()
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    (lo <= hi).then_some([lo, hi])
}

/// Sample counts of `vol` in `bins` equal bins over its value range (one pass over the
/// volume, through [`Histogram::from_volume`]'s exact bins, merged).
pub fn histogram(vol: &AnyVolume, bins: usize) -> (Vec<u64>, [f64; 2]) {
    let fine = Histogram::from_volume(vol);
    let (lo, hi) = vol.value_range();
    let bins = bins.max(1);
    let mut counts = vec![0u64; bins];
    let span = hi - lo;
    for (n, &c) in fine.counts().iter().enumerate() {
        if c == 0 {
            continue;
        }
        let t = if span > 0.0 {
            (fine.bin_center(n) - lo) / span
        } else {
            0.0
        };
        let k = ((t * bins as f64).floor().max(0.0) as usize).min(bins - 1);
        counts[k] += c;
    }
    (counts, [lo, hi])
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat::core::{Grid, Volume};

    /// The frame the page shows holds the code values of render's 8-bit PNG, for composite
    /// (linear and sRGB, over a background), MIP through a window and X-ray scaled to its
    /// brightest value; and the screenshot is render's file.
    #[test]
    fn the_final_frame_shows_the_pixels_of_renders_file() {
        let dir = tempfile::tempdir().unwrap();
        let scene = volsplat::Scene {
            volume: volsplat::VolumeSource::Phantom {
                phantom: volsplat::PhantomKind::Head,
                grid: Some(vec![24, 28, 26]),
            },
            ..volsplat::Scene::default()
        };
        let mut renderer = volsplat::Renderer::new();
        let plain = volsplat::OutputOptions::default();
        let srgb = volsplat::OutputOptions {
            srgb: true,
            background: [0.2, 0.3, 0.4],
            ..plain
        };
        let window = volsplat::OutputOptions {
            window: Some([-200.0, 900.0]),
            ..plain
        };
        use volsplat::Mode;
        for (mode, output) in [
            (Mode::Composite, plain),
            (Mode::Composite, srgb),
            (Mode::Mip, window),
            (Mode::Xray, plain),
        ] {
            let mut req = volsplat::RenderRequest::new(scene.clone(), 40, 30);
            req.mode = mode;
            req.output = output;
            if mode == Mode::Xray {
                // Line integrals of Hounsfield units are mostly negative: X-ray a density.
                req.scene.volume = volsplat::VolumeSource::Phantom {
                    phantom: volsplat::PhantomKind::Blobs,
                    grid: Some(vec![24]),
                };
            }
            let out = renderer.render(&req, &mut |_| true).unwrap();
            let path = dir.path().join("r.png");
            out.write(&path, &req).unwrap();
            let file = std::fs::read(&path).unwrap();
            assert_eq!(screenshot_png(&out, &req).unwrap(), file);
            let (_, _, expect) = crate::replay::decode_rgb("png", &file).unwrap();
            let frame = final_frame(&out, &req).unwrap();
            let (w, h, shown) = crate::replay::decode_rgb("png", &frame).unwrap();
            assert_eq!((w, h), (40, 30));
            assert_eq!(shown, expect, "{mode:?}");
            assert!(
                expect.iter().any(|&v| v > 30),
                "{mode:?}: an empty frame proves nothing"
            );
        }
    }

    #[test]
    fn histogram_counts_every_sample_in_the_right_bin() {
        let data: Vec<u8> = (0..64).map(|n| (n % 8) as u8 * 10).collect();
        let grid = Grid::with_dims([4, 4, 4]).unwrap();
        let vol: AnyVolume = Volume::new(grid, data).unwrap().into();
        let (counts, range) = histogram(&vol, 8);
        assert_eq!(range, [0.0, 70.0]);
        assert_eq!(counts.iter().sum::<u64>(), 64);
        // Values 0, 10, …, 70 over [0, 70] in 8 bins of 8.75: one value per bin.
        assert_eq!(counts, vec![8; 8]);
    }
}
