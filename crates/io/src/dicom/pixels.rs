//! Pixel data of one DICOM image: native (PS3.5 §8.1), encapsulated (PS3.5 §8.2, §A.4) with
//! RLE (PS3.5 Annex G), JPEG (ISO 10918-1 processes 1, 2/4 at 8 bits, 14; by `jpeg-decoder`),
//! uncompressed fragments and deflated frames; stored values as PS3.3 §C.7.6.3.1.1 defines
//! them (Bits Allocated, Bits Stored, High Bit, Pixel Representation).

use crate::error::{IoError, Result};
use dicom_core::value::{PrimitiveValue, Value};
use dicom_object::InMemDicomObject;
use std::io::Read;
use std::path::Path;

/// How pixel data of a transfer syntax is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum PixelCoding {
    /// Native little-endian words (implicit/explicit VR little endian, deflated data set).
    NativeLe,
    /// Native big-endian words (explicit VR big endian, retired).
    NativeBe,
    /// Encapsulated Uncompressed Explicit VR Little Endian (1.2.840.10008.1.2.1.98).
    EncapsulatedRaw,
    /// Deflated Image Frame Compression (1.2.840.10008.1.2.8.1).
    DeflatedFrames,
    /// RLE Lossless (1.2.840.10008.1.2.5).
    Rle,
    /// JPEG baseline, extended (8-bit), lossless (processes 1, 2/4, 14).
    Jpeg,
}

impl PixelCoding {
    /// The coding of a transfer syntax UID, or `None` where no decoder is built in.
    pub(super) fn of(ts_uid: &str, big_endian: bool, encapsulated: bool) -> Option<Self> {
        Some(match ts_uid {
            "1.2.840.10008.1.2.1.98" => PixelCoding::EncapsulatedRaw,
            "1.2.840.10008.1.2.8.1" => PixelCoding::DeflatedFrames,
            "1.2.840.10008.1.2.5" => PixelCoding::Rle,
            "1.2.840.10008.1.2.4.50"
            | "1.2.840.10008.1.2.4.51"
            | "1.2.840.10008.1.2.4.57"
            | "1.2.840.10008.1.2.4.70" => PixelCoding::Jpeg,
            _ if encapsulated => return None,
            _ if big_endian => PixelCoding::NativeBe,
            _ => PixelCoding::NativeLe,
        })
    }
}

/// The layout of stored values (PS3.3 §C.7.6.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct PixelFormat {
    pub rows: u16,
    pub cols: u16,
    /// 8, 16 or 32.
    pub bits_allocated: u16,
    /// 1 ..= bits_allocated.
    pub bits_stored: u16,
    /// bits_stored − 1 ..= bits_allocated − 1.
    pub high_bit: u16,
    /// Pixel Representation 1: two's complement.
    pub signed: bool,
}

impl PixelFormat {
    pub(super) fn pixels(&self) -> usize {
        self.rows as usize * self.cols as usize
    }

    pub(super) fn frame_bytes(&self) -> usize {
        self.pixels() * (self.bits_allocated as usize / 8)
    }

    /// The stored value in a word: bits `high_bit − bits_stored + 1 ..= high_bit`, sign-extended
    /// for signed data.
    #[inline]
    fn value(&self, word: u32, shift: u32) -> i64 {
        let bits = self.bits_stored as u32;
        let mask: u64 = (1u64 << bits) - 1;
        let v = ((word as u64) >> shift) & mask;
        if self.signed && v >> (bits - 1) & 1 == 1 {
            v as i64 - (1i64 << bits)
        } else {
            v as i64
        }
    }
}

/// Decodes frame `frame` of `frames` in `obj` into `out` (stored values, row by row; cleared
/// first).
pub(super) fn decode_frame(
    path: &Path,
    obj: &InMemDicomObject,
    coding: PixelCoding,
    fmt: &PixelFormat,
    frames: u32,
    frame: u32,
    out: &mut Vec<i64>,
) -> Result<()> {
    out.clear();
    let elem = obj
        .get(dicom_dictionary_std::tags::PIXEL_DATA)
        .ok_or_else(|| IoError::missing(path, "PixelData (7FE0,0010)"))?;
    let frame_bytes = fmt.frame_bytes();
    match (coding, elem.value()) {
        (PixelCoding::NativeLe | PixelCoding::NativeBe, Value::Primitive(p)) => {
            let be = coding == PixelCoding::NativeBe;
            let bytes = file_order_bytes(p, be);
            let start = frame as usize * frame_bytes;
            let needed = frames as usize * frame_bytes;
            if bytes.len() < needed {
                return Err(IoError::Truncated {
                    path: path.to_path_buf(),
                    what: format!(
                        "PixelData (7FE0,0010) of {frames} frame(s) of {} × {} × {} bits",
                        fmt.cols, fmt.rows, fmt.bits_allocated
                    ),
                    expected: needed as u64,
                    actual: bytes.len() as u64,
                    unit: "bytes",
                });
            }
            words_to_values(&bytes[start..start + frame_bytes], fmt, be, true, out);
            Ok(())
        }
        (PixelCoding::NativeLe | PixelCoding::NativeBe, _) => Err(IoError::Dicom {
            path: path.to_path_buf(),
            message: "PixelData (7FE0,0010) is encapsulated (fragments) but the transfer syntax \
                      is native"
                .into(),
        }),
        (_, Value::PixelSequence(seq)) => {
            let data = frame_fragments(path, seq.fragments(), seq.offset_table(), frames, frame)?;
            match coding {
                PixelCoding::EncapsulatedRaw => {
                    if data.len() < frame_bytes {
                        return Err(IoError::Truncated {
                            path: path.to_path_buf(),
                            what: format!("uncompressed pixel data fragment of frame {frame}"),
                            expected: frame_bytes as u64,
                            actual: data.len() as u64,
                            unit: "bytes",
                        });
                    }
                    words_to_values(&data[..frame_bytes], fmt, false, true, out);
                }
                PixelCoding::DeflatedFrames => {
                    let mut raw = Vec::new();
                    flate2::read::DeflateDecoder::new(&data[..])
                        .take(frame_bytes as u64 + 1)
                        .read_to_end(&mut raw)
                        .map_err(|e| IoError::Decompress {
                            path: path.to_path_buf(),
                            what: format!("deflated pixel data of frame {frame}"),
                            error: e,
                        })?;
                    if raw.len() < frame_bytes {
                        return Err(IoError::Truncated {
                            path: path.to_path_buf(),
                            what: format!("deflated pixel data of frame {frame}"),
                            expected: frame_bytes as u64,
                            actual: raw.len() as u64,
                            unit: "bytes",
                        });
                    }
                    words_to_values(&raw[..frame_bytes], fmt, false, true, out);
                }
                PixelCoding::Rle => {
                    let raw = rle_decode(path, &data, fmt, frame)?;
                    // Segments hold the most significant byte first: big-endian words.
                    words_to_values(&raw, fmt, true, true, out);
                }
                PixelCoding::Jpeg => jpeg_decode(path, &data, fmt, frame, out)?,
                // Native codings take the arms above.
                PixelCoding::NativeLe | PixelCoding::NativeBe => {}
            }
            Ok(())
        }
        (_, _) => Err(IoError::Dicom {
            path: path.to_path_buf(),
            message: "PixelData (7FE0,0010) is native but the transfer syntax is encapsulated \
                      (PS3.5 §A.4)"
                .into(),
        }),
    }
}

/// The value's bytes in file order: 16- and 32-bit values (OW, OL) are decoded by dicom-rs into
/// host integers, so they are written back in the transfer syntax's byte order.
fn file_order_bytes(p: &PrimitiveValue, be: bool) -> std::borrow::Cow<'_, [u8]> {
    use std::borrow::Cow;
    macro_rules! back {
        ($v:expr) => {
            Cow::Owned(
                $v.iter()
                    .flat_map(|x| {
                        if be {
                            x.to_be_bytes().to_vec()
                        } else {
                            x.to_le_bytes().to_vec()
                        }
                    })
                    .collect(),
            )
        };
    }
    match p {
        PrimitiveValue::U8(v) => Cow::Borrowed(&v[..]),
        PrimitiveValue::U16(v) => back!(v),
        PrimitiveValue::I16(v) => back!(v),
        PrimitiveValue::U32(v) => back!(v),
        PrimitiveValue::I32(v) => back!(v),
        PrimitiveValue::F32(v) => back!(v),
        PrimitiveValue::F64(v) => back!(v),
        PrimitiveValue::U64(v) => back!(v),
        PrimitiveValue::I64(v) => back!(v),
        other => other.to_bytes(),
    }
}

/// Words of `bits_allocated` bits → stored values. `shifted`: apply the High Bit position
/// (native and RLE data); decoded JPEG samples are the stored values already.
fn words_to_values(bytes: &[u8], fmt: &PixelFormat, be: bool, shifted: bool, out: &mut Vec<i64>) {
    let shift = if shifted {
        (fmt.high_bit + 1 - fmt.bits_stored) as u32
    } else {
        0
    };
    out.reserve(fmt.pixels());
    match fmt.bits_allocated {
        8 => out.extend(bytes.iter().map(|&b| fmt.value(b as u32, shift))),
        16 => out.extend(bytes.chunks_exact(2).map(|c| {
            let w = if be {
                u16::from_be_bytes([c[0], c[1]])
            } else {
                u16::from_le_bytes([c[0], c[1]])
            };
            fmt.value(w as u32, shift)
        })),
        _ => out.extend(bytes.chunks_exact(4).map(|c| {
            let a = [c[0], c[1], c[2], c[3]];
            let w = if be {
                u32::from_be_bytes(a)
            } else {
                u32::from_le_bytes(a)
            };
            fmt.value(w, shift)
        })),
    }
}

/// The bytes of frame `frame` from encapsulated fragments (PS3.5 §A.4): all fragments when there
/// is one frame, fragment `frame` when there is one fragment per frame, else the fragments the
/// Basic Offset Table points at.
fn frame_fragments(
    path: &Path,
    fragments: &[Vec<u8>],
    offsets: &[u32],
    frames: u32,
    frame: u32,
) -> Result<Vec<u8>> {
    if fragments.is_empty() {
        return Err(IoError::Dicom {
            path: path.to_path_buf(),
            message: "encapsulated PixelData (7FE0,0010) has no fragments".into(),
        });
    }
    if frames == 1 {
        return Ok(fragments.concat());
    }
    if fragments.len() == frames as usize {
        return Ok(fragments[frame as usize].clone());
    }
    if offsets.len() != frames as usize {
        return Err(IoError::Dicom {
            path: path.to_path_buf(),
            message: format!(
                "{} pixel data fragments for {frames} frames, and the Basic Offset Table has {} \
                 entries: cannot tell which fragments make frame {frame} (PS3.5 §A.4)",
                fragments.len(),
                offsets.len()
            ),
        });
    }
    let begin = offsets[frame as usize] as u64;
    let end = offsets
        .get(frame as usize + 1)
        .map_or(u64::MAX, |&o| o as u64);
    let mut out = Vec::new();
    let mut at: u64 = 0;
    for f in fragments {
        if at >= begin && at < end {
            out.extend_from_slice(f);
        }
        at += f.len() as u64 + 8;
    }
    if out.is_empty() {
        return Err(IoError::Dicom {
            path: path.to_path_buf(),
            message: format!(
                "the Basic Offset Table entry {begin} of frame {frame} points at no fragment"
            ),
        });
    }
    Ok(out)
}

/// RLE Lossless (PS3.5 Annex G): a 64-byte header (segment count, 15 offsets), one PackBits
/// segment per byte of a sample, most significant byte first. Returns big-endian words.
fn rle_decode(path: &Path, data: &[u8], fmt: &PixelFormat, frame: u32) -> Result<Vec<u8>> {
    let bad = |m: String| IoError::Dicom {
        path: path.to_path_buf(),
        message: format!("RLE frame {frame}: {m} (PS3.5 Annex G)"),
    };
    if data.len() < 64 {
        return Err(bad(format!(
            "the 64-byte header is truncated ({} bytes)",
            data.len()
        )));
    }
    let word = |i: usize| u32::from_le_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]);
    let bytes_per = fmt.bits_allocated as usize / 8;
    let nseg = word(0) as usize;
    if nseg != bytes_per {
        return Err(bad(format!(
            "{nseg} segments, but {bytes_per} are needed for {}-bit samples",
            fmt.bits_allocated
        )));
    }
    let n = fmt.pixels();
    let mut out = vec![0u8; n * bytes_per];
    let mut seg = Vec::with_capacity(n);
    for s in 0..nseg {
        let start = word(4 + 4 * s) as usize;
        let end = if s + 1 < nseg {
            word(8 + 4 * s) as usize
        } else {
            data.len()
        };
        if start < 64 || start > end || end > data.len() {
            return Err(bad(format!(
                "segment {s} offsets {start}..{end} lie outside the {} bytes of the fragment",
                data.len()
            )));
        }
        packbits(&data[start..end], n, &mut seg);
        if seg.len() < n {
            return Err(bad(format!(
                "segment {s} decodes to {} bytes, {n} expected",
                seg.len()
            )));
        }
        for (p, &b) in seg.iter().take(n).enumerate() {
            out[p * bytes_per + s] = b;
        }
    }
    Ok(out)
}

/// PackBits (PS3.5 §G.3.1) into `out` (cleared), at most `limit` bytes.
fn packbits(src: &[u8], limit: usize, out: &mut Vec<u8>) {
    out.clear();
    let mut i = 0;
    while i < src.len() && out.len() < limit {
        let h = src[i] as i8;
        i += 1;
        if h >= 0 {
            let n = h as usize + 1;
            let end = (i + n).min(src.len());
            let take = (end - i).min(limit - out.len());
            out.extend_from_slice(&src[i..i + take]);
            i = end;
        } else if h != -128 {
            let n = (1 - h as isize) as usize;
            if let Some(&b) = src.get(i) {
                let take = n.min(limit - out.len());
                out.extend(std::iter::repeat_n(b, take));
            }
            i += 1;
        }
    }
}

/// One JPEG frame by `jpeg-decoder`: its size must be the image's, its samples one component
/// of at most 16 bits (lossless) or 8 bits (DCT).
fn jpeg_decode(
    path: &Path,
    data: &[u8],
    fmt: &PixelFormat,
    frame: u32,
    out: &mut Vec<i64>,
) -> Result<()> {
    let bad = |m: String| IoError::Dicom {
        path: path.to_path_buf(),
        message: format!("JPEG frame {frame}: {m}"),
    };
    let mut d = jpeg_decoder::Decoder::new(data);
    d.read_info().map_err(|e| bad(e.to_string()))?;
    let info = d.info().ok_or_else(|| bad("no frame header".into()))?;
    if info.width != fmt.cols || info.height != fmt.rows {
        return Err(bad(format!(
            "the JPEG image is {} × {}, but Columns × Rows is {} × {}",
            info.width, info.height, fmt.cols, fmt.rows
        )));
    }
    let two = match info.pixel_format {
        jpeg_decoder::PixelFormat::L8 => false,
        jpeg_decoder::PixelFormat::L16 => true,
        other => {
            return Err(bad(format!(
                "{other:?} samples; only one-component (grayscale) JPEG is read"
            )));
        }
    };
    d.set_max_decoding_buffer_size(fmt.pixels().saturating_mul(if two { 2 } else { 1 }));
    let px = d.decode().map_err(|e| bad(e.to_string()))?;
    let n = fmt.pixels();
    let want = if two { 2 * n } else { n };
    if px.len() < want {
        return Err(bad(format!("decoded {} bytes, {want} expected", px.len())));
    }
    out.reserve(n);
    if two {
        out.extend(
            px.chunks_exact(2)
                .take(n)
                .map(|c| fmt.value(u16::from_ne_bytes([c[0], c[1]]) as u32, 0)),
        );
    } else {
        out.extend(px.iter().take(n).map(|&b| fmt.value(b as u32, 0)));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_values_follow_high_bit_and_sign() {
        // 12 bits stored in the low bits of 16, unsigned; overlay bits above are masked.
        let f = PixelFormat {
            rows: 1,
            cols: 1,
            bits_allocated: 16,
            bits_stored: 12,
            high_bit: 11,
            signed: false,
        };
        assert_eq!(f.value(0xF123, 0), 0x123);
        // Signed 12-bit: 0x800 is −2048.
        let s = PixelFormat { signed: true, ..f };
        assert_eq!(s.value(0x0800, 0), -2048);
        assert_eq!(s.value(0x07FF, 0), 2047);
        // High bit 15, 12 bits stored: the value sits in the top bits.
        let h = PixelFormat { high_bit: 15, ..f };
        assert_eq!(h.value(0x1230, 4), 0x123);
        let w = PixelFormat {
            bits_allocated: 32,
            bits_stored: 32,
            high_bit: 31,
            signed: true,
            ..f
        };
        assert_eq!(w.value(0xFFFF_FFFF, 0), -1);
    }

    #[test]
    fn packbits_runs_literals_and_limits() {
        let mut out = Vec::new();
        // 3 literals, a run of 4 × 9, a no-op, then a literal cut by the limit.
        packbits(&[2, 1, 2, 3, 0xFD, 9, 0x80, 1, 7, 8], 9, &mut out);
        assert_eq!(out, [1, 2, 3, 9, 9, 9, 9, 7, 8]);
        packbits(&[0xFD, 9], 2, &mut out);
        assert_eq!(out, [9, 9]);
        // A run header at the end, a literal longer than the data: no panic.
        packbits(&[0xFD], 10, &mut out);
        assert!(out.is_empty());
        packbits(&[100, 1, 2], 10, &mut out);
        assert_eq!(out, [1, 2]);
    }
}
