//! Pixel data of one DICOM image: native (PS3.5 §8.1), encapsulated (PS3.5 §8.2, §A.4) with
//! RLE (PS3.5 Annex G), JPEG, JPEG-LS and JPEG 2000 (`codecs.rs`), uncompressed fragments and
//! deflated frames; stored values as PS3.3 §C.7.6.3.1.1 defines them (Bits Allocated, Bits
//! Stored, High Bit, Pixel Representation); grey palettes (PS3.3 §C.7.6.3.1.5-6).

use super::codecs;
use super::header::{FileHeader, PALETTE_DATA, PALETTE_DESCRIPTORS};
use crate::error::{IoError, Result};
use dicom_core::Tag;
use dicom_core::value::{PrimitiveValue, Value};
use dicom_object::InMemDicomObject;
use std::borrow::Cow;
use std::io::Read;
use std::ops::Range;
use std::path::Path;

/// The transfer syntaxes whose pixel data is decoded, for messages.
pub(super) const SUPPORTED_SYNTAXES: &str = "implicit/explicit VR little endian, explicit VR big \
     endian, deflated, encapsulated uncompressed, deflated image frames, RLE lossless, JPEG \
     baseline, extended (8 and 12 bits) and lossless, JPEG-LS lossless and near-lossless, JPEG \
     2000 (lossless and lossy); not HTJ2K, JPEG XL or video";

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
    /// JPEG baseline, extended, lossless (processes 1, 2/4, 14; ISO 10918-1).
    Jpeg,
    /// JPEG-LS lossless and near-lossless (ISO 14495-1).
    JpegLs,
    /// JPEG 2000 lossless and lossy (ISO 15444-1).
    Jpeg2000,
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
            "1.2.840.10008.1.2.4.80" | "1.2.840.10008.1.2.4.81" => PixelCoding::JpegLs,
            "1.2.840.10008.1.2.4.90" | "1.2.840.10008.1.2.4.91" => PixelCoding::Jpeg2000,
            _ if encapsulated => return None,
            _ if big_endian => PixelCoding::NativeBe,
            _ => PixelCoding::NativeLe,
        })
    }
}

/// The layout of stored values (PS3.3 §C.7.6.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct PixelFormat {
    pub(super) rows: u16,
    pub(super) cols: u16,
    /// 8, 16 or 32.
    pub(super) bits_allocated: u16,
    /// 1 ..= bits_allocated.
    pub(super) bits_stored: u16,
    /// bits_stored − 1 ..= bits_allocated − 1.
    pub(super) high_bit: u16,
    /// Pixel Representation 1: two's complement.
    pub(super) signed: bool,
    /// PALETTE COLOR with a grey palette: stored values are indices into it.
    pub(super) palette: bool,
}

impl PixelFormat {
    pub(super) fn pixels(&self) -> usize {
        self.rows as usize * self.cols as usize
    }

    /// Bytes of one frame (Bits Allocated 8, 16, 32; for 1, the bytes one frame spans when
    /// it starts on a byte).
    pub(super) fn frame_bytes(&self) -> usize {
        if self.bits_allocated == 1 {
            self.pixels().div_ceil(8)
        } else {
            self.pixels() * (self.bits_allocated as usize / 8)
        }
    }

    /// Bytes of `frames` frames.
    fn frames_bytes(&self, frames: usize) -> usize {
        if self.bits_allocated == 1 {
            (frames * self.pixels()).div_ceil(8)
        } else {
            frames * self.frame_bytes()
        }
    }

    /// The stored value in a word: bits `high_bit − bits_stored + 1 ..= high_bit`, sign-extended
    /// for signed data.
    #[inline]
    pub(super) fn value(&self, word: u32, shift: u32) -> i64 {
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

/// One file's pixel data, prepared once (native words in file order, or the fragments of each
/// frame) so that decoding all frames is linear in their number (issue 28: a 176-frame
/// enhanced MR converted the whole pixel data for every frame).
pub(super) struct PixelSource<'a> {
    path: &'a Path,
    fmt: PixelFormat,
    coding: PixelCoding,
    data: Data<'a>,
}

enum Data<'a> {
    /// Native data in file byte order, all frames.
    Native(Cow<'a, [u8]>),
    /// Encapsulated fragments and, per frame, the range of fragments that make it.
    Fragments(&'a [Vec<u8>], Vec<Range<usize>>),
}

/// Extended Offset Table (PS3.5 §A.4, PS3.3 §C.7.6.3.1.8): 64-bit frame offsets.
const EXTENDED_OFFSET_TABLE: Tag = Tag(0x7FE0, 0x0001);

impl<'a> PixelSource<'a> {
    pub(super) fn new(
        path: &'a Path,
        obj: &'a InMemDicomObject,
        header: &FileHeader,
        fmt: &PixelFormat,
    ) -> Result<Self> {
        let elem = obj
            .get(dicom_dictionary_std::tags::PIXEL_DATA)
            .ok_or_else(|| IoError::missing(path, "PixelData (7FE0,0010)"))?;
        let encapsulated = matches!(elem.value(), Value::PixelSequence(_));
        let coding = header.coding(encapsulated)?;
        let frames = header.frames;
        let data = match (coding, elem.value()) {
            (PixelCoding::NativeLe | PixelCoding::NativeBe, Value::Primitive(p)) => {
                let bytes = file_order_bytes(p, coding == PixelCoding::NativeBe);
                let needed = fmt.frames_bytes(frames as usize);
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
                Data::Native(bytes)
            }
            (PixelCoding::NativeLe | PixelCoding::NativeBe, _) => {
                return Err(IoError::Dicom {
                    path: path.to_path_buf(),
                    message: "PixelData (7FE0,0010) is encapsulated (fragments) but the \
                              transfer syntax is native"
                        .into(),
                });
            }
            (_, Value::PixelSequence(_)) if fmt.bits_allocated == 1 => {
                return Err(IoError::unsupported(
                    path,
                    "BitsAllocated (0028,0100)",
                    "1 in encapsulated pixel data",
                    "1 with native (uncompressed) transfer syntaxes; 8, 16, 32",
                ));
            }
            (_, Value::PixelSequence(seq)) => {
                let extended = extended_offsets(obj);
                let offsets: Vec<u64> = match &extended {
                    Some(e) => e.clone(),
                    None => seq.offset_table().iter().map(|&o| u64::from(o)).collect(),
                };
                let ranges = frame_ranges(path, seq.fragments(), &offsets, frames, coding)?;
                Data::Fragments(seq.fragments(), ranges)
            }
            (_, _) => {
                return Err(IoError::Dicom {
                    path: path.to_path_buf(),
                    message: "PixelData (7FE0,0010) is native but the transfer syntax is \
                              encapsulated (PS3.5 §A.4)"
                        .into(),
                });
            }
        };
        Ok(PixelSource {
            path,
            fmt: *fmt,
            coding,
            data,
        })
    }

    /// Decodes frame `frame` into `out` (stored values, row by row; cleared first).
    pub(super) fn decode_frame(&self, frame: u32, out: &mut Vec<i64>) -> Result<()> {
        out.clear();
        let (path, fmt) = (self.path, &self.fmt);
        let frame_bytes = fmt.frame_bytes();
        let (fragments, ranges) = match &self.data {
            Data::Native(bytes) if fmt.bits_allocated == 1 => {
                // Packed bits, first pixel in the least significant bit (PS3.5 §8.1.1), frames
                // one after another without padding.
                let first = frame as usize * fmt.pixels();
                if (first + fmt.pixels()).div_ceil(8) > bytes.len() {
                    return Err(IoError::Dicom {
                        path: path.to_path_buf(),
                        message: format!("frame {frame} lies past the end of the pixel data"),
                    });
                }
                out.reserve(fmt.pixels());
                out.extend((first..first + fmt.pixels()).map(|b| {
                    let bit = (bytes[b / 8] >> (b % 8)) & 1;
                    fmt.value(u32::from(bit), 0)
                }));
                return Ok(());
            }
            Data::Native(bytes) => {
                let start = frame as usize * frame_bytes;
                let be = self.coding == PixelCoding::NativeBe;
                let words =
                    bytes
                        .get(start..start + frame_bytes)
                        .ok_or_else(|| IoError::Dicom {
                            path: path.to_path_buf(),
                            message: format!("frame {frame} lies past the end of the pixel data"),
                        })?;
                words_to_values(words, fmt, be, true, out);
                return Ok(());
            }
            Data::Fragments(f, r) => (f, r),
        };
        let range = ranges.get(frame as usize).cloned().unwrap_or(0..0);
        let parts = &fragments[range];
        let data: Cow<'_, [u8]> = match parts {
            [one] => Cow::Borrowed(&one[..]),
            _ => Cow::Owned(parts.concat()),
        };
        match self.coding {
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
                // Deflate expands at most 1032:1 (RFC 1951 §3.2.5's longest match per bit).
                if (data.len() as u64).saturating_mul(1032) < frame_bytes as u64 {
                    return Err(IoError::Truncated {
                        path: path.to_path_buf(),
                        what: format!(
                            "deflated pixel data of frame {frame} (deflate expands at most \
                             1032:1)"
                        ),
                        expected: (frame_bytes as u64).div_ceil(1032),
                        actual: data.len() as u64,
                        unit: "bytes",
                    });
                }
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
            PixelCoding::Jpeg => codecs::jpeg(path, &data, fmt, frame, out)?,
            PixelCoding::JpegLs => codecs::jpeg_ls(path, &data, fmt, frame, out)?,
            PixelCoding::Jpeg2000 => codecs::jpeg2000(path, &data, fmt, frame, out)?,
            // Native codings take the branch above.
            PixelCoding::NativeLe | PixelCoding::NativeBe => {}
        }
        Ok(())
    }
}

/// The Extended Offset Table's offsets, when present and well formed.
fn extended_offsets(obj: &InMemDicomObject) -> Option<Vec<u64>> {
    let bytes = obj.get(EXTENDED_OFFSET_TABLE)?.value().to_bytes().ok()?;
    if bytes.is_empty() || bytes.len() % 8 != 0 {
        return None;
    }
    Some(
        bytes
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
            .collect(),
    )
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
pub(super) fn words_to_values(
    bytes: &[u8],
    fmt: &PixelFormat,
    be: bool,
    shifted: bool,
    out: &mut Vec<i64>,
) {
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

/// Which fragments make each frame (PS3.5 §A.4): all of them for one frame; one each when
/// there are as many as frames; else as the (Extended or Basic) Offset Table says; else, with
/// no table, a new frame at each fragment that starts a codestream (JPEG SOI `FF D8`, JPEG 2000
/// SOC `FF 4F`), as pydicom splits them.
fn frame_ranges(
    path: &Path,
    fragments: &[Vec<u8>],
    offsets: &[u64],
    frames: u32,
    coding: PixelCoding,
) -> Result<Vec<Range<usize>>> {
    let n = fragments.len();
    let frames = frames as usize;
    if n == 0 {
        return Err(IoError::Dicom {
            path: path.to_path_buf(),
            message: "encapsulated PixelData (7FE0,0010) has no fragments".into(),
        });
    }
    if frames == 1 {
        return Ok(std::iter::once(0..n).collect());
    }
    if n == frames {
        return Ok((0..n).map(|k| k..k + 1).collect());
    }
    if offsets.len() == frames {
        // Fragment k starts at this position (item headers of 8 bytes included).
        let mut starts = Vec::with_capacity(n);
        let mut at = 0u64;
        for f in fragments {
            starts.push(at);
            at = at.saturating_add(f.len() as u64 + 8);
        }
        let mut ranges = Vec::with_capacity(frames);
        for (k, &begin) in offsets.iter().enumerate() {
            let end = offsets.get(k + 1).copied().unwrap_or(u64::MAX);
            let first = starts.partition_point(|&s| s < begin);
            let last = starts.partition_point(|&s| s < end);
            if first >= last || starts.get(first) != Some(&begin) {
                return Err(IoError::Dicom {
                    path: path.to_path_buf(),
                    message: format!(
                        "the offset table entry {begin} of frame {k} points at no fragment \
                         start (PS3.5 §A.4)"
                    ),
                });
            }
            ranges.push(first..last);
        }
        return Ok(ranges);
    }
    let starts_stream = |f: &Vec<u8>| match coding {
        PixelCoding::Jpeg | PixelCoding::JpegLs => f.starts_with(&[0xFF, 0xD8]),
        PixelCoding::Jpeg2000 => {
            f.starts_with(&[0xFF, 0x4F]) || f.starts_with(&[0, 0, 0, 0x0C, 0x6A, 0x50])
        }
        _ => false,
    };
    if offsets.is_empty() {
        let firsts: Vec<usize> = (0..n).filter(|&k| starts_stream(&fragments[k])).collect();
        if firsts.len() == frames && firsts.first() == Some(&0) {
            let mut ranges: Vec<Range<usize>> = firsts.windows(2).map(|w| w[0]..w[1]).collect();
            ranges.push(firsts[frames - 1]..n);
            return Ok(ranges);
        }
    }
    Err(IoError::Dicom {
        path: path.to_path_buf(),
        message: format!(
            "{n} pixel data fragments for {frames} frames, and the offset table has {} \
             entries: cannot tell which fragments make each frame (PS3.5 §A.4)",
            offsets.len()
        ),
    })
}

/// A grey palette (PALETTE COLOR whose red, green and blue tables are equal; PS3.3
/// §C.7.6.3.1.5-6): stored values below the first mapped value take the first entry, above
/// the last the last entry.
pub(super) struct Palette {
    first: i64,
    table: Vec<i64>,
}

impl Palette {
    /// Reads the red table (the three are equal; checked when the header was read).
    pub(super) fn read(path: &Path, obj: &InMemDicomObject, big_endian: bool) -> Result<Self> {
        let (da, ta) = (PALETTE_DESCRIPTORS[0], PALETTE_DATA[0]);
        let bad = |why: String| IoError::field(path, da.label(), "", why);
        let desc: Vec<i64> = obj
            .get(da.tag())
            .and_then(|e| e.to_multi_int::<i64>().ok())
            .ok_or_else(|| IoError::missing(path, da.label()))?;
        let [entries, first, bits] = desc[..] else {
            return Err(bad(format!("3 values expected, found {}", desc.len())));
        };
        let entries = match entries {
            0 => 65536,
            1..=65535 => entries as usize,
            // A descriptor read as signed (SS): 0x8000.. means 32768..
            -32768..=-1 => (entries + 65536) as usize,
            _ => return Err(bad(format!("{entries} entries"))),
        };
        if bits != 8 && bits != 16 {
            return Err(bad(format!("{bits} bits per entry (8 or 16 expected)")));
        }
        let e = obj
            .get(ta.tag())
            .ok_or_else(|| IoError::missing(path, ta.label()))?;
        let bytes = match e.value() {
            Value::Primitive(p) => file_order_bytes(p, big_endian),
            _ => {
                return Err(IoError::field(
                    path,
                    ta.label(),
                    "",
                    "not a table of values",
                ));
            }
        };
        let table: Vec<i64> = if bits == 8 && bytes.len() == entries {
            bytes.iter().map(|&b| i64::from(b)).collect()
        } else {
            bytes
                .chunks_exact(2)
                .map(|c| {
                    let w = if big_endian {
                        u16::from_be_bytes([c[0], c[1]])
                    } else {
                        u16::from_le_bytes([c[0], c[1]])
                    };
                    i64::from(if bits == 8 { w & 0xFF } else { w })
                })
                .collect()
        };
        if table.len() < entries {
            return Err(IoError::field(
                path,
                ta.label(),
                &format!("{} entries", table.len()),
                format!("{entries} expected from the descriptor"),
            ));
        }
        Ok(Palette {
            first,
            table: table[..entries].to_vec(),
        })
    }

    /// Maps stored values through the palette.
    pub(super) fn apply(&self, values: &mut [i64]) {
        let last = self.table.len() as i64 - 1;
        for v in values {
            let i = (*v - self.first).clamp(0, last);
            *v = self.table[i as usize];
        }
    }
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
    // Segment bounds first, and whether each can hold its n bytes (PackBits expands at most
    // 64:1, a 2-byte run of 128), before the frame's memory is taken.
    let mut bounds = Vec::with_capacity(nseg);
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
        if (end - start).saturating_mul(64) < n {
            return Err(bad(format!(
                "segment {s} has {} bytes, too few for {n} samples (PackBits expands at most \
                 64:1)",
                end - start
            )));
        }
        bounds.push((start, end));
    }
    let mut out = vec![0u8; n * bytes_per];
    let mut seg = Vec::with_capacity(n);
    for (s, &(start, end)) in bounds.iter().enumerate() {
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
            palette: false,
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
