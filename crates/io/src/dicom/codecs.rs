//! Compressed frames (decision 0026): JPEG (ISO 10918-1) by `jpeg-decoder` (baseline,
//! extended 8-bit, progressive, lossless) and `openreadout-codecs` (extended 12-bit), JPEG-LS
//! (ISO 14495-1) by `openreadout-codecs` over `pure_jpegls`, JPEG 2000 (ISO 15444-1) by
//! `hayro-jpeg2000`. All pure Rust.
//!
//! Each stream's own header is read here first (frame size, components, precision, coding
//! process) and must agree with Rows, Columns and Samples per Pixel before a decoder runs, so
//! no decoder allocates beyond one frame. Decoders are third-party code fed untrusted bytes: a
//! panic inside one is caught (`catch_unwind`) and becomes an error naming the file and frame,
//! never an abort; the fuzz target `dicom` runs with a panic hook that aborts, so it still
//! finds them.

use super::pixels::PixelFormat;
use crate::error::{IoError, Result};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

fn frame_error(path: &Path, codec: &str, frame: u32, m: impl std::fmt::Display) -> IoError {
    IoError::Dicom {
        path: path.to_path_buf(),
        message: format!("{codec} frame {frame}: {m}"),
    }
}

/// Runs a third-party decoder; a panic becomes an error.
fn guarded<T>(path: &Path, codec: &str, frame: u32, f: impl FnOnce() -> Result<T>) -> Result<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(_) => Err(frame_error(
            path,
            codec,
            frame,
            "the decoder failed on malformed data (it panicked; the panic was caught)",
        )),
    }
}

/// Stored values from decoded samples, as the frame's format reads them: `word` is each
/// sample's bit pattern (two's complement for signed codestreams), masked to Bits Stored and
/// sign-extended when Pixel Representation is 1 (pydicom does the same; a codestream whose
/// signedness differs from Pixel Representation is read as Pixel Representation says).
fn push_words(out: &mut Vec<i64>, fmt: &PixelFormat, words: impl Iterator<Item = u32>) {
    out.reserve(fmt.pixels());
    out.extend(words.take(fmt.pixels()).map(|w| fmt.value(w, 0)));
}

fn check_size(
    path: &Path,
    codec: &str,
    frame: u32,
    fmt: &PixelFormat,
    (w, h, comps): (u32, u32, u32),
) -> Result<()> {
    if (w, h) != (u32::from(fmt.cols), u32::from(fmt.rows)) {
        return Err(frame_error(
            path,
            codec,
            frame,
            format!(
                "the codestream is {w} × {h} pixels, but Columns × Rows is {} × {}",
                fmt.cols, fmt.rows
            ),
        ));
    }
    if comps != 1 {
        return Err(frame_error(
            path,
            codec,
            frame,
            format!(
                "the codestream has {comps} components (a colour image); volsplat reads \
                 grey-scale (one component) only"
            ),
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// JPEG (ISO 10918-1)

/// A JPEG frame header (SOFn, ISO 10918-1 §B.2.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct JpegFrame {
    /// The SOF marker's low byte: 0xC0 baseline, 0xC1 extended, 0xC2 progressive, 0xC3
    /// lossless; others hierarchical or arithmetic-coded.
    pub(super) marker: u8,
    pub(super) precision: u8,
    pub(super) height: u16,
    pub(super) width: u16,
    pub(super) components: u8,
}

/// The frame header of a JPEG stream, read without decoding: markers from SOI to the first
/// SOFn. `None` when there is none before the first scan or the end.
pub(super) fn jpeg_frame(data: &[u8]) -> Option<JpegFrame> {
    if data.get(..2)? != [0xFF, 0xD8] {
        return None;
    }
    let mut i = 2usize;
    loop {
        if *data.get(i)? != 0xFF {
            return None;
        }
        let mk = *data.get(i + 1)?;
        if mk == 0xFF {
            i += 1;
            continue;
        }
        if mk == 0x01 || (0xD0..=0xD8).contains(&mk) {
            i += 2;
            continue;
        }
        if mk == 0xDA || mk == 0xD9 {
            return None;
        }
        let len = usize::from(u16::from_be_bytes([*data.get(i + 2)?, *data.get(i + 3)?]));
        if (0xC0..=0xCF).contains(&mk) && !matches!(mk, 0xC4 | 0xC8 | 0xCC) {
            let s = data.get(i + 4..i + 10)?;
            return Some(JpegFrame {
                marker: mk,
                precision: s[0],
                height: u16::from_be_bytes([s[1], s[2]]),
                width: u16::from_be_bytes([s[3], s[4]]),
                components: s[5],
            });
        }
        i = i.checked_add(2 + len)?;
    }
}

/// What a JPEG coding process is, in words, when it is one no decoder here reads.
fn jpeg_unsupported(f: &JpegFrame) -> Option<String> {
    let what = match f.marker {
        0xC0..=0xC3 => return None,
        0xC5..=0xC7 => "hierarchical (differential) coding",
        0xC9..=0xCB | 0xCD..=0xCF => "arithmetic entropy coding",
        _ => "an unknown coding process",
    };
    Some(format!(
        "{what} (frame marker SOF{}) is not supported; baseline, extended, progressive and \
         lossless Huffman-coded JPEG are",
        f.marker - 0xC0
    ))
}

/// A `jpeg-decoder` error in words (its enum names are not messages for users).
fn jpeg_decoder_error(e: &jpeg_decoder::Error) -> String {
    use jpeg_decoder::UnsupportedFeature as U;
    match e {
        jpeg_decoder::Error::Format(s) => format!("corrupt JPEG data: {s}"),
        jpeg_decoder::Error::Io(e) => format!("the JPEG data ends early ({e})"),
        jpeg_decoder::Error::Internal(e) => format!("the JPEG decoder failed: {e}"),
        jpeg_decoder::Error::Unsupported(f) => match f {
            U::Hierarchical => "hierarchical JPEG is not supported".into(),
            U::ArithmeticEntropyCoding => "arithmetic-coded JPEG is not supported".into(),
            U::SamplePrecision(p) => format!(
                "{p}-bit samples are not supported in this JPEG process (8 and 12 bits for \
                 DCT, 2 to 16 for lossless)"
            ),
            U::ComponentCount(n) => format!("JPEG with {n} components is not supported"),
            U::DNL => "a frame height defined by a DNL marker is not supported".into(),
            U::SubsamplingRatio | U::NonIntegerSubsamplingRatio => {
                "this JPEG's component subsampling is not supported".into()
            }
            U::ColorTransform(_) => "this JPEG's colour transform is not supported".into(),
        },
    }
}

/// One JPEG frame: 8-bit DCT (baseline, extended, progressive) and lossless (2-16 bits) by
/// `jpeg-decoder`; 12-bit sequential DCT (extended, process 4) by `openreadout-codecs`.
pub(super) fn jpeg(
    path: &Path,
    data: &[u8],
    fmt: &PixelFormat,
    frame: u32,
    out: &mut Vec<i64>,
) -> Result<()> {
    const CODEC: &str = "JPEG";
    let f = jpeg_frame(data)
        .ok_or_else(|| frame_error(path, CODEC, frame, "no JPEG frame header (SOF) found"))?;
    if let Some(why) = jpeg_unsupported(&f) {
        return Err(frame_error(path, CODEC, frame, why));
    }
    if f.height == 0 {
        return Err(frame_error(
            path,
            CODEC,
            frame,
            "a frame height defined by a DNL marker is not supported",
        ));
    }
    check_size(
        path,
        CODEC,
        frame,
        fmt,
        (
            u32::from(f.width),
            u32::from(f.height),
            u32::from(f.components),
        ),
    )?;
    let lossless = f.marker == 0xC3;
    if !lossless && f.precision == 12 {
        if f.marker == 0xC2 {
            return Err(frame_error(
                path,
                CODEC,
                frame,
                "progressive JPEG with 12-bit samples is not supported",
            ));
        }
        let raster = guarded(path, CODEC, frame, || {
            openreadout_codecs::jpeg_decode_limited(data, fmt.pixels() * 2)
                .map_err(|e| frame_error(path, CODEC, frame, e))
        })?;
        return raster_words(path, CODEC, frame, fmt, &raster, out);
    }
    if !lossless && f.precision != 8 {
        return Err(frame_error(
            path,
            CODEC,
            frame,
            format!(
                "{}-bit samples in a DCT (lossy) JPEG; 8 and 12 bits are defined (ISO 10918-1 \
                 §B.2.2)",
                f.precision
            ),
        ));
    }
    let two = f.precision > 8;
    let px = guarded(path, CODEC, frame, || {
        let mut d = jpeg_decoder::Decoder::new(data);
        d.set_max_decoding_buffer_size(fmt.pixels().saturating_mul(if two { 2 } else { 1 }));
        d.decode()
            .map_err(|e| frame_error(path, CODEC, frame, jpeg_decoder_error(&e)))
    })?;
    let n = fmt.pixels();
    let want = if two { 2 * n } else { n };
    if px.len() < want {
        return Err(frame_error(
            path,
            CODEC,
            frame,
            format!("decoded {} bytes, {want} expected", px.len()),
        ));
    }
    if two {
        push_words(
            out,
            fmt,
            px.chunks_exact(2)
                .map(|c| u32::from(u16::from_ne_bytes([c[0], c[1]]))),
        );
    } else {
        push_words(out, fmt, px.iter().map(|&b| u32::from(b)));
    }
    Ok(())
}

/// Samples of an `openreadout-codecs` raster (one component; 8-bit, or little-endian 16-bit).
fn raster_words(
    path: &Path,
    codec: &str,
    frame: u32,
    fmt: &PixelFormat,
    r: &openreadout_codecs::Raster,
    out: &mut Vec<i64>,
) -> Result<()> {
    check_size(path, codec, frame, fmt, (r.width, r.height, r.channels))?;
    let n = fmt.pixels();
    match r.bits_per_sample {
        8 if r.data.len() >= n => push_words(out, fmt, r.data.iter().map(|&b| u32::from(b))),
        16 if r.data.len() >= 2 * n => push_words(
            out,
            fmt,
            r.data
                .chunks_exact(2)
                .map(|c| u32::from(u16::from_le_bytes([c[0], c[1]]))),
        ),
        b => {
            return Err(frame_error(
                path,
                codec,
                frame,
                format!(
                    "decoded {} bytes of {b}-bit samples for {n} pixels",
                    r.data.len()
                ),
            ));
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// JPEG-LS (ISO 14495-1)

/// One JPEG-LS frame (lossless or near-lossless, one component, 2-16 bits).
pub(super) fn jpeg_ls(
    path: &Path,
    data: &[u8],
    fmt: &PixelFormat,
    frame: u32,
    out: &mut Vec<i64>,
) -> Result<()> {
    const CODEC: &str = "JPEG-LS";
    // The SOF55 frame header: size and components, checked before the decoder runs.
    let f = jpeg_frame(data)
        .filter(|f| f.marker == 0xF7)
        .or_else(|| jls_frame(data))
        .ok_or_else(|| frame_error(path, CODEC, frame, "no JPEG-LS frame header (SOF55) found"))?;
    check_size(
        path,
        CODEC,
        frame,
        fmt,
        (
            u32::from(f.width),
            u32::from(f.height),
            u32::from(f.components),
        ),
    )?;
    let raster = guarded(path, CODEC, frame, || {
        openreadout_codecs::jpegls_decode_limited(data, fmt.pixels() * 2)
            .map_err(|e| frame_error(path, CODEC, frame, e))
    })?;
    raster_words(path, CODEC, frame, fmt, &raster, out)
}

/// The SOF55 (`FF F7`) frame header of a JPEG-LS stream (ISO 14495-1 §C.2.2), found by the
/// same marker walk as JPEG's.
fn jls_frame(data: &[u8]) -> Option<JpegFrame> {
    if data.get(..2)? != [0xFF, 0xD8] {
        return None;
    }
    let mut i = 2usize;
    loop {
        if *data.get(i)? != 0xFF {
            return None;
        }
        let mk = *data.get(i + 1)?;
        if mk == 0xFF {
            i += 1;
            continue;
        }
        if mk == 0xDA || mk == 0xD9 {
            return None;
        }
        let len = usize::from(u16::from_be_bytes([*data.get(i + 2)?, *data.get(i + 3)?]));
        if mk == 0xF7 {
            let s = data.get(i + 4..i + 10)?;
            return Some(JpegFrame {
                marker: mk,
                precision: s[0],
                height: u16::from_be_bytes([s[1], s[2]]),
                width: u16::from_be_bytes([s[3], s[4]]),
                components: s[5],
            });
        }
        i = i.checked_add(2 + len)?;
    }
}

// ---------------------------------------------------------------------------------------------
// JPEG 2000 (ISO 15444-1)

/// The image and tile size marker (SIZ, ISO 15444-1 §A.5.1) of a codestream, found after the
/// SOC marker (`FF 4F FF 51`), also inside a JP2 file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Siz {
    width: u32,
    height: u32,
    components: u16,
    /// First component: precision in bits and signedness (Ssiz).
    precision: u8,
    signed: bool,
}

fn j2k_siz(data: &[u8]) -> Option<Siz> {
    let at = data
        .windows(4)
        .position(|w| w == [0xFF, 0x4F, 0xFF, 0x51])?
        + 4;
    let s = data.get(at..at + 41)?;
    let u32_at = |k: usize| u32::from_be_bytes([s[k], s[k + 1], s[k + 2], s[k + 3]]);
    let (xsiz, ysiz, xo, yo) = (u32_at(4), u32_at(8), u32_at(12), u32_at(16));
    let ssiz = s[38];
    Some(Siz {
        width: xsiz.checked_sub(xo)?,
        height: ysiz.checked_sub(yo)?,
        components: u16::from_be_bytes([s[36], s[37]]),
        precision: (ssiz & 0x7F) + 1,
        signed: ssiz & 0x80 != 0,
    })
}

/// One JPEG 2000 frame (raw codestream or JP2), lossless or lossy, one component. Lossy samples
/// are rounded to the nearest integer and clamped to the codestream's range.
pub(super) fn jpeg2000(
    path: &Path,
    data: &[u8],
    fmt: &PixelFormat,
    frame: u32,
    out: &mut Vec<i64>,
) -> Result<()> {
    const CODEC: &str = "JPEG 2000";
    let siz = j2k_siz(data).ok_or_else(|| {
        frame_error(
            path,
            CODEC,
            frame,
            "no JPEG 2000 codestream header (SOC and SIZ markers) found",
        )
    })?;
    check_size(
        path,
        CODEC,
        frame,
        fmt,
        (siz.width, siz.height, u32::from(siz.components)),
    )?;
    if !(1..=24).contains(&siz.precision) {
        return Err(frame_error(
            path,
            CODEC,
            frame,
            format!(
                "{}-bit samples; 1 to 24 are read (BitsAllocated is {})",
                siz.precision, fmt.bits_allocated
            ),
        ));
    }
    let samples = guarded(path, CODEC, frame, || {
        let settings = hayro_jpeg2000::DecodeSettings {
            resolve_palette_indices: false,
            strict: false,
            target_resolution: None,
        };
        let image = hayro_jpeg2000::Image::new(data, &settings)
            .map_err(|e| frame_error(path, CODEC, frame, e))?;
        if (image.width(), image.height()) != (siz.width, siz.height) {
            return Err(frame_error(
                path,
                CODEC,
                frame,
                format!(
                    "the decoder reads a {} × {} image from a {} × {} codestream",
                    image.width(),
                    image.height(),
                    siz.width,
                    siz.height
                ),
            ));
        }
        let mut ctx = hayro_jpeg2000::DecoderContext::default();
        let decoded = image
            .decode(&mut ctx)
            .map_err(|e| frame_error(path, CODEC, frame, e))?;
        match decoded.components() {
            [one] => Ok(one.samples().to_vec()),
            c => Err(frame_error(
                path,
                CODEC,
                frame,
                format!("decoded {} components, 1 expected", c.len()),
            )),
        }
    })?;
    if samples.len() < fmt.pixels() {
        return Err(frame_error(
            path,
            CODEC,
            frame,
            format!(
                "decoded {} samples, {} expected",
                samples.len(),
                fmt.pixels()
            ),
        ));
    }
    // The decoder adds 2^(p−1) to every sample (ISO 15444-1 §G.1.2, DC level shift), also
    // to signed components; undo it for those.
    let p = u32::from(siz.precision);
    let half = f64::from(1u32 << (p - 1));
    let (lo, hi) = if siz.signed {
        (-half, half - 1.0)
    } else {
        (0.0, 2.0 * half - 1.0)
    };
    let shift = if siz.signed { half } else { 0.0 };
    push_words(
        out,
        fmt,
        samples.iter().map(|&v| {
            let x = (f64::from(v) - shift).round().clamp(lo, hi);
            (x as i64) as u32
        }),
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jpeg_frame_headers_are_read_without_decoding() {
        // SOI, APP0 (4 bytes of payload), SOF1: 12 bits, 3 rows, 4 columns, 1 component.
        let s = [
            0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x06, 1, 2, 3, 4, 0xFF, 0xC1, 0x00, 0x0B, 12, 0, 3, 0, 4,
            1, 1, 0x11, 0,
        ];
        let f = jpeg_frame(&s).unwrap();
        assert_eq!(
            f,
            JpegFrame {
                marker: 0xC1,
                precision: 12,
                height: 3,
                width: 4,
                components: 1
            }
        );
        assert!(jpeg_unsupported(&f).is_none());
        let arith = JpegFrame { marker: 0xC9, ..f };
        assert!(jpeg_unsupported(&arith).unwrap().contains("arithmetic"));
        // Truncated: no frame header, no panic.
        for cut in 0..s.len() - 6 {
            assert!(jpeg_frame(&s[..cut]).is_none(), "{cut}");
        }
    }

    #[test]
    fn decoder_messages_are_words_not_enum_names() {
        let e =
            jpeg_decoder::Error::Unsupported(jpeg_decoder::UnsupportedFeature::SamplePrecision(12));
        let m = jpeg_decoder_error(&e);
        assert!(!m.contains("SamplePrecision"), "{m}");
        assert!(m.contains("12-bit samples"), "{m}");
    }

    #[test]
    fn siz_gives_size_precision_and_sign() {
        let mut s = vec![0xFF, 0x4F, 0xFF, 0x51, 0, 41, 0, 0];
        for v in [7u32, 5, 1, 0, 7, 5, 0, 0] {
            s.extend(v.to_be_bytes());
        }
        s.extend([0, 1, 0x8B, 1, 1]);
        let siz = j2k_siz(&s).unwrap();
        assert_eq!(
            siz,
            Siz {
                width: 6,
                height: 5,
                components: 1,
                precision: 12,
                signed: true
            }
        );
        assert!(j2k_siz(&s[..s.len() - 1]).is_none());
    }
}
