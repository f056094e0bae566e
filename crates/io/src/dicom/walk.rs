//! A check of a DICOM file's structure before `dicom-object` parses it.
//!
//! `dicom-parser` allocates (and zero-fills) each value's declared length before reading it, so
//! a 100-byte file that declares a 4 GiB element would allocate 4 GiB; and it builds nested
//! sequences by recursion, so a file of a million nested sequences would overflow the stack.
//! This walk follows the parser's own state machine (`dicom_parser::dataset::read::
//! DataSetReader` 0.10, and `dicom_object::meta::FileMetaTable::read_from` for the file meta
//! group) over the same bytes, reading headers only, and refuses a file in which any length the
//! parser would allocate runs past the end of the data, or sequences nest deeper than
//! [`MAX_NESTING`]. The file encoding is PS3.10 §7 (preamble, `DICM`, file meta group in
//! explicit VR little endian) and PS3.5 §7 (data elements), §7.5 (nested data sets) and §A.4
//! (encapsulated pixel data).

use crate::error::{IoError, Result};
use dicom_core::Tag;
use dicom_core::VR;
use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry};
use dicom_dictionary_std::StandardDataDictionary;
use dicom_encoding::Codec;
use dicom_encoding::transfer_syntax::{Endianness, TransferSyntaxIndex};
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;
use std::io::Read;
use std::path::Path;

/// Deepest nesting of sequences and items accepted (each nested sequence counts twice: the
/// sequence and its item). Real files nest a few levels.
pub(super) const MAX_NESTING: usize = 64;

const PIXEL_DATA: Tag = Tag(0x7FE0, 0x0010);
const ITEM_END: Tag = Tag(0xFFFE, 0xE00D);
const IMPLICIT_VR_LE: &str = "1.2.840.10008.1.2";
const EXPLICIT_VR_LE: &str = "1.2.840.10008.1.2.1";
/// Media Storage Directory Storage: a DICOMDIR (PS3.10 §8), never an image.
pub(super) const DICOMDIR_SOP_CLASS: &str = "1.2.840.10008.1.3.10";
/// A value length meaning "undefined" (PS3.5 §7.1.1).
pub(super) const UNDEFINED: u32 = 0xFFFF_FFFF;

/// What the walk found.
#[derive(Debug, Clone)]
pub(super) struct Walked {
    /// The transfer syntax UID the data set is read with (trailing NUL and spaces removed): the
    /// file meta group's, or implicit/explicit VR little endian where the data set is written
    /// in the other one ([`Walked::vr_mismatch`]).
    pub(super) ts_uid: String,
    /// The transfer syntax name from dicom-rs's registry.
    pub(super) ts_name: String,
    /// MediaStorageSOPClassUID (0002,0002) of the file meta group (empty if absent).
    pub(super) media_sop_class: String,
    /// The data set is written in the other VR encoding than the meta group declares (explicit
    /// VR declared, implicit written, or the reverse); it is read as written, as pydicom does.
    /// Holds the declared UID.
    pub(super) vr_mismatch: Option<String>,
    /// The top-level Pixel Data (7FE0,0010) element's declared length ([`UNDEFINED`] when
    /// encapsulated) and where its value starts in the file; `None` when the walk ended
    /// before it. For a deflated data set, the position is in the inflated stream.
    pub(super) pixel: Option<(u32, u64)>,
    /// Whether the data set is deflated (PS3.5 §A.5).
    pub(super) deflated: bool,
}

/// The image size a data set's top level declares, as read by the walk (not validated).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct Declared {
    pub(super) rows: Option<u16>,
    pub(super) cols: Option<u16>,
    pub(super) samples: Option<u16>,
    pub(super) bits_allocated: Option<u16>,
    pub(super) frames: Option<u64>,
}

impl Declared {
    /// Bytes of pixel data the attributes declare (at least one byte per sample), or `None`
    /// when Rows or Columns is missing.
    pub(super) fn image_bytes(&self) -> Option<u64> {
        let px = u64::from(self.rows?) * u64::from(self.cols?);
        let bytes = u64::from(self.bits_allocated.unwrap_or(16))
            .div_ceil(8)
            .max(1);
        Some(
            px.saturating_mul(u64::from(self.samples.unwrap_or(1).max(1)))
                .saturating_mul(bytes)
                .saturating_mul(self.frames.unwrap_or(1).max(1)),
        )
    }
}

/// How the data set after the file meta group is encoded.
#[derive(Debug, Clone, Copy)]
struct Enc {
    explicit: bool,
    big_endian: bool,
}

fn err(path: &Path, at: u64, what: String) -> IoError {
    IoError::Dicom {
        path: path.to_path_buf(),
        message: format!("byte {at}: {what}"),
    }
}

/// Bytes inflated at first from a deflated data set to find the image attributes (and, for a
/// header, all of it up to Pixel Data).
const INFLATE_PREFIX: u64 = 1 << 20;

/// Whether the first data element of `data` looks explicit-VR encoded (a known VR after the
/// tag), as pydicom decides it (`filereader._is_implicit_vr`). `None`: too short to tell.
fn looks_explicit(data: &[u8]) -> Option<bool> {
    let b = data.get(4..6)?;
    Some(VR::from_binary([b[0], b[1]]).is_some())
}

/// Walks `bytes` (a DICOM file from its `DICM` magic on: the 128-byte preamble, if any, already
/// removed; `offset` is where `DICM` was in the file, added to byte positions in messages).
/// `until_pixel_data`: stop at the first top-level element at or after Pixel Data
/// (7FE0,0010), as `OpenFileOptions::read_until(PIXEL_DATA)` does. `max_inflated`: the most
/// bytes a deflated data set (PS3.5 §A.5) may inflate to; it is lowered to the image size the
/// data set declares plus `other_bytes` (issue 28: a 3 MB deflated bomb no longer inflates
/// towards the voxel limit's 64 GiB).
pub(super) fn walk(
    path: &Path,
    bytes: &[u8],
    offset: u64,
    until_pixel_data: bool,
    max_inflated: u64,
    other_bytes: u64,
) -> Result<Walked> {
    if bytes.len() < 4 || &bytes[..4] != b"DICM" {
        return Err(IoError::Dicom {
            path: path.to_path_buf(),
            message: "not a DICOM file (no `DICM` magic after the 128-byte preamble; PS3.10 \
                      §7.1)"
                .into(),
        });
    }
    let meta = walk_meta(path, bytes, offset)?;
    let ts = TransferSyntaxRegistry.get(&meta.ts_uid).ok_or_else(|| {
        IoError::unsupported(
            path,
            "TransferSyntaxUID (0002,0010)",
            &meta.ts_uid,
            "the transfer syntaxes known to dicom-rs",
        )
    })?;
    // The registry's spelling, which the parser uses.
    let declared_ts = ts.uid().to_string();
    let enc = Enc {
        explicit: declared_ts != IMPLICIT_VR_LE,
        big_endian: ts.endianness() == Endianness::Big,
    };
    let rest = &bytes[meta.end..];
    let deflated = matches!(ts.codec(), Codec::Dataset(_));
    if until_pixel_data && meta.sop_class == DICOMDIR_SOP_CLASS {
        // A directory: told by its meta group; its records are not needed.
        return Ok(Walked {
            ts_name: ts.name().to_string(),
            ts_uid: declared_ts,
            media_sop_class: meta.sop_class,
            vr_mismatch: None,
            pixel: None,
            deflated,
        });
    }
    let walk_data = |data: &[u8], base: u64| -> Result<Walked> {
        let mut enc = enc;
        let mut ts_uid = declared_ts.clone();
        let mut vr_mismatch = None;
        // Read as written, as the parser will (`header::parse_walked` maps the declared UID to
        // the written encoding). Only for the two native little-endian syntaxes: inside a
        // deflated stream the parser has no such mapping (and the walk must follow the
        // parser), and an encapsulated syntax's UID must stay to choose the pixel decoder.
        if matches!(declared_ts.as_str(), IMPLICIT_VR_LE | EXPLICIT_VR_LE)
            && let Some(explicit) = looks_explicit(data)
            && explicit != enc.explicit
        {
            enc.explicit = explicit;
            vr_mismatch = Some(declared_ts.clone());
            ts_uid = if explicit {
                EXPLICIT_VR_LE
            } else {
                IMPLICIT_VR_LE
            }
            .to_string();
        }
        let found = walk_dataset(path, data, base, enc, until_pixel_data)?;
        let ts_name = TransferSyntaxRegistry
            .get(&ts_uid)
            .map_or_else(|| ts_uid.clone(), |t| t.name().to_string());
        Ok(Walked {
            ts_uid,
            ts_name,
            media_sop_class: meta.sop_class.clone(),
            vr_mismatch,
            pixel: found.pixel,
            deflated,
        })
    };
    if !deflated {
        return walk_data(rest, offset + meta.end as u64);
    }
    if until_pixel_data {
        // A header: inflate a little, more only if the header runs past it, and never more
        // than `other_bytes` (the allowance for everything but pixel data).
        let mut limit = INFLATE_PREFIX.min(other_bytes);
        loop {
            let (data, complete) = inflate_prefix(path, rest, limit)?;
            match walk_data(&data, 0) {
                Err(_) if !complete && limit < other_bytes => limit = other_bytes,
                Err(_) if !complete => {
                    return Err(IoError::TooLarge {
                        path: path.to_path_buf(),
                        what: "inflated size of the deflated data set's elements before Pixel \
                               Data (bytes; 64 MiB at most)"
                            .into(),
                        value: data.len() as u128,
                        limit: limit as u128,
                    });
                }
                r => return r,
            }
        }
    }
    let data = inflate(path, rest, max_inflated, other_bytes)?;
    walk_data(&data, 0)
}

fn inflate_error(path: &Path, e: std::io::Error) -> IoError {
    IoError::Decompress {
        path: path.to_path_buf(),
        what: "deflated data set".into(),
        error: e,
    }
}

/// The first `limit` bytes of a deflated data set (`limit` + 1 when there are more), and
/// whether that is all of it.
fn inflate_prefix(path: &Path, rest: &[u8], limit: u64) -> Result<(Vec<u8>, bool)> {
    let mut out = Vec::new();
    flate2::read::DeflateDecoder::new(rest)
        .take(limit + 1)
        .read_to_end(&mut out)
        .map_err(|e| inflate_error(path, e))?;
    let complete = (out.len() as u64) <= limit;
    Ok((out, complete))
}

/// Inflates a whole deflated data set (PS3.5 §A.5: raw deflate after the meta group), refused
/// beyond the image size its attributes declare plus `other_bytes`, and beyond `max_inflated`
/// in any case.
fn inflate(path: &Path, rest: &[u8], max_inflated: u64, other_bytes: u64) -> Result<Vec<u8>> {
    let mut dec = flate2::read::DeflateDecoder::new(rest);
    let mut out = Vec::new();
    let first = INFLATE_PREFIX.min(max_inflated.saturating_add(1));
    (&mut dec)
        .take(first)
        .read_to_end(&mut out)
        .map_err(|e| inflate_error(path, e))?;
    if (out.len() as u64) < first {
        return Ok(out);
    }
    // More to come: cap it by what the first part declares.
    let declared = declared_in_prefix(path, &out);
    let cap = match declared.image_bytes() {
        Some(img) => img.saturating_add(other_bytes).min(max_inflated),
        None => other_bytes.min(max_inflated),
    };
    (&mut dec)
        .take(cap.saturating_add(1).saturating_sub(out.len() as u64))
        .read_to_end(&mut out)
        .map_err(|e| inflate_error(path, e))?;
    if out.len() as u64 > cap {
        return Err(too_large(path, out.len() as u64, cap, declared));
    }
    Ok(out)
}

fn too_large(path: &Path, value: u64, limit: u64, d: Declared) -> IoError {
    let what = match d.image_bytes() {
        Some(_) => format!(
            "inflated size of the deflated data set (bytes; the image it declares, Rows {} × \
             Columns {} × {} frame(s), plus 64 MiB for other elements)",
            d.rows.map_or("?".into(), |v| v.to_string()),
            d.cols.map_or("?".into(), |v| v.to_string()),
            d.frames.unwrap_or(1)
        ),
        None => "inflated size of the deflated data set (bytes; no Rows/Columns before the \
                 first MiB, so 64 MiB at most)"
            .into(),
    };
    IoError::TooLarge {
        path: path.to_path_buf(),
        what,
        value: value as u128,
        limit: limit as u128,
    }
}

/// The image attributes of the start of an inflated data set (explicit VR little endian, the
/// only deflated syntax, PS3.5 §A.5), read until the walk stops (at Pixel Data, or where the
/// prefix ends).
fn declared_in_prefix(path: &Path, data: &[u8]) -> Declared {
    let enc = Enc {
        explicit: true,
        big_endian: false,
    };
    let mut found = Found::default();
    // An element running past the prefix ends the walk with an error; what was read before it
    // stays in `found`.
    let _ = walk_dataset_into(path, data, 0, enc, true, &mut found);
    found.declared
}

/// A byte cursor that never reads past the end./// A byte cursor that never reads past the end.
struct Cur<'a> {
    b: &'a [u8],
    pos: usize,
    be: bool,
}

impl Cur<'_> {
    fn remaining(&self) -> usize {
        self.b.len() - self.pos
    }
    fn take(&mut self, n: usize) -> Option<&[u8]> {
        if self.remaining() < n {
            return None;
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Some(s)
    }
    fn u16(&mut self) -> Option<u16> {
        let s = self.take(2)?;
        let a = [s[0], s[1]];
        Some(if self.be {
            u16::from_be_bytes(a)
        } else {
            u16::from_le_bytes(a)
        })
    }
    fn u32(&mut self) -> Option<u32> {
        let s = self.take(4)?;
        let a = [s[0], s[1], s[2], s[3]];
        Some(if self.be {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }
}

/// VRs with a 2-byte length in explicit VR encodings (PS3.5 §7.1.2, Table 7.1-2).
fn short_length(vr: VR) -> bool {
    matches!(
        vr,
        VR::AE
            | VR::AS
            | VR::AT
            | VR::CS
            | VR::DA
            | VR::DS
            | VR::DT
            | VR::FL
            | VR::FD
            | VR::IS
            | VR::LO
            | VR::LT
            | VR::PN
            | VR::SH
            | VR::SL
            | VR::SS
            | VR::ST
            | VR::TM
            | VR::UI
            | VR::UL
            | VR::US
    )
}

/// A data element header as the parser reads it: `None` at a clean end (no bytes, or a partial
/// tag, as the parser ends gracefully there), `Err` for a header cut after its tag.
fn element_header(
    c: &mut Cur<'_>,
    enc: Enc,
    path: &Path,
    base: u64,
) -> Result<Option<(Tag, VR, u32)>> {
    let at = base + c.pos as u64;
    let (Some(g), Some(e)) = (c.u16(), c.u16()) else {
        return Ok(None);
    };
    let tag = Tag(g, e);
    let cut = || err(path, at, format!("element {tag} header is truncated"));
    if g == 0xFFFE {
        let len = c.u32().ok_or_else(cut)?;
        return Ok(Some((tag, VR::UN, len)));
    }
    if !enc.explicit {
        let len = c.u32().ok_or_else(cut)?;
        let vr = if tag == PIXEL_DATA || (g >> 8 == 0x60 && e == 0x3000) {
            VR::OW
        } else {
            StandardDataDictionary
                .by_tag(tag)
                .map(|entry| entry.vr().relaxed())
                .unwrap_or(VR::UN)
        };
        return Ok(Some((tag, vr, len)));
    }
    let v = c.take(2).ok_or_else(cut)?;
    let vr = VR::from_binary([v[0], v[1]]).unwrap_or(VR::UN);
    let len = if short_length(vr) {
        u32::from(c.u16().ok_or_else(cut)?)
    } else {
        c.take(2).ok_or_else(cut)?;
        c.u32().ok_or_else(cut)?
    };
    Ok(Some((tag, vr, len)))
}

/// Checks that a value of `len` bytes at the cursor lies within the data, then skips it.
fn skip_value(c: &mut Cur<'_>, len: u32, tag: Tag, path: &Path, base: u64) -> Result<()> {
    let at = base + c.pos as u64;
    if len as usize > c.remaining() {
        return Err(err(
            path,
            at,
            format!(
                "element {tag} declares {len} bytes but only {} remain (truncated or corrupt \
                 file)",
                c.remaining()
            ),
        ));
    }
    c.pos += len as usize;
    Ok(())
}

/// What the file meta group says.
struct Meta {
    /// TransferSyntaxUID (0002,0010).
    ts_uid: String,
    /// MediaStorageSOPClassUID (0002,0002), empty if absent.
    sop_class: String,
    /// Where the data set starts.
    end: usize,
}

/// The file meta group (PS3.10 §7.1): explicit VR little endian, `(0002,0000)` first giving the
/// group's length.
fn walk_meta(path: &Path, bytes: &[u8], base: u64) -> Result<Meta> {
    let mut c = Cur {
        b: bytes,
        pos: 4,
        be: false,
    };
    let enc = Enc {
        explicit: true,
        big_endian: false,
    };
    let first = element_header(&mut c, enc, path, base)?;
    let Some((Tag(0x0002, 0x0000), _, 4)) = first else {
        return Err(err(
            path,
            base + 4,
            "the file meta group must start with (0002,0000) FileMetaInformationGroupLength \
             of 4 bytes (PS3.10 §7.1)"
                .into(),
        ));
    };
    let group_length = c.u32().ok_or_else(|| {
        err(
            path,
            base + c.pos as u64,
            "file meta group is truncated".into(),
        )
    })?;
    let mut total: u32 = 0;
    let mut ts = None;
    let mut sop_class = String::new();
    while total < group_length {
        let at = c.pos as u64;
        let (tag, _, len) = element_header(&mut c, enc, path, base)?
            .ok_or_else(|| err(path, base + at, "file meta group is truncated".into()))?;
        if len == UNDEFINED {
            return Err(err(
                path,
                base + at,
                format!("file meta element {tag} has an undefined length"),
            ));
        }
        let header_bytes = (c.pos as u64 - at) as u32;
        let start = c.pos;
        skip_value(&mut c, len, tag, path, base)?;
        let text = || {
            String::from_utf8_lossy(&bytes[start..c.pos])
                // As dicom-object's `FileMetaTable::transfer_syntax` trims (a trailing tab
                // too: found by fuzzing, the walk read explicit VR where the parser read
                // implicit).
                .trim_end_matches(|c: char| c.is_whitespace() || c == '\0')
                .to_string()
        };
        if tag == Tag(0x0002, 0x0010) {
            ts = Some(text());
        } else if tag == Tag(0x0002, 0x0002) {
            sop_class = text();
        }
        total = total.saturating_add(header_bytes).saturating_add(len);
    }
    let ts_uid = ts.ok_or_else(|| IoError::missing(path, "TransferSyntaxUID (0002,0010)"))?;
    Ok(Meta {
        ts_uid,
        sop_class,
        end: c.pos,
    })
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Sequence,
    Item,
}

#[derive(Debug, Clone, Copy)]
struct Token {
    kind: Kind,
    pixel: bool,
    len: u32,
    /// The parser's position (see [`Walker::logical`]) where the sequence or item starts.
    base: u64,
}

/// Bytes the parser actually reads for a value of `len` bytes: numeric VRs read whole numbers
/// only (`dicom_parser::stateful::decode`, e.g. `read_value_od` reads `len >> 3` doubles),
/// while its position still advances by `len`.
fn consumed(vr: VR, len: u32) -> u32 {
    match vr {
        VR::US | VR::OW | VR::SS => len & !1,
        VR::AT | VR::FL | VR::OF | VR::UL | VR::OL | VR::SL => len & !3,
        VR::FD | VR::OD | VR::UV | VR::OV | VR::SV => len & !7,
        _ => len,
    }
}

/// The data set walk: the stream position (`c.pos`, bytes actually read) and the parser's own
/// position counter (`logical`, which sequence and item lengths are compared with) differ once
/// a numeric value's length is not a multiple of its size.
struct Walker<'a> {
    c: Cur<'a>,
    logical: u64,
    path: &'a Path,
    base: u64,
}

impl Walker<'_> {
    fn at(&self) -> u64 {
        self.base + self.c.pos as u64
    }

    fn fail(&self, what: String) -> IoError {
        err(self.path, self.at(), what)
    }

    /// A value the parser allocates `len` bytes for and reads `read` bytes of.
    fn value(&mut self, tag: Tag, len: u32, read: u32) -> Result<()> {
        if len as usize > self.c.remaining() {
            return Err(self.fail(format!(
                "element {tag} declares {len} bytes but only {} remain (truncated or corrupt \
                 file)",
                self.c.remaining()
            )));
        }
        self.c.pos += read as usize;
        self.logical += len as u64;
        Ok(())
    }

    /// An item header (tag and length, no VR); `None` at the end of the data.
    fn item_header(&mut self) -> Option<(Tag, u32)> {
        let (g, e, len) = (self.c.u16()?, self.c.u16()?, self.c.u32()?);
        self.logical += 8;
        Some((Tag(g, e), len))
    }
}

/// What the data set walk records on its way.
#[derive(Debug, Default)]
struct Found {
    pixel: Option<(u32, u64)>,
    declared: Declared,
}

impl Found {
    /// Records the value of a top-level image attribute (binary or text, as written).
    fn capture(&mut self, tag: Tag, value: &[u8], be: bool) {
        let us = || {
            (value.len() == 2).then(|| {
                let a = [value[0], value[1]];
                if be {
                    u16::from_be_bytes(a)
                } else {
                    u16::from_le_bytes(a)
                }
            })
        };
        match (tag.0, tag.1) {
            (0x0028, 0x0002) => self.declared.samples = us(),
            (0x0028, 0x0010) => self.declared.rows = us(),
            (0x0028, 0x0011) => self.declared.cols = us(),
            (0x0028, 0x0100) => self.declared.bits_allocated = us(),
            (0x0028, 0x0008) => {
                self.declared.frames = std::str::from_utf8(value)
                    .ok()
                    .and_then(|t| t.trim_matches(|c: char| c == '\0' || c == ' ').parse().ok());
            }
            _ => {}
        }
    }
}

/// The data set, as `DataSetReader` tokenises it. `base` (the data set's offset in the file)
/// is added to positions in messages.
fn walk_dataset(
    path: &Path,
    bytes: &[u8],
    base: u64,
    enc: Enc,
    until_pixel: bool,
) -> Result<Found> {
    let mut found = Found::default();
    walk_dataset_into(path, bytes, base, enc, until_pixel, &mut found)?;
    Ok(found)
}

/// [`walk_dataset`], recording into `found` as it goes (kept when the walk fails).
///
/// One token per step, as the parser reads them ([`DataSetWalk`]): first the sequences and
/// items whose defined length has been reached are closed; then, by state, an item header
/// inside a sequence, a fragment of encapsulated pixel data, the value of the element whose
/// header was just read, or the next element header.
fn walk_dataset_into(
    path: &Path,
    bytes: &[u8],
    base: u64,
    enc: Enc,
    until_pixel: bool,
    found: &mut Found,
) -> Result<()> {
    let mut walk = DataSetWalk {
        w: Walker {
            c: Cur {
                b: bytes,
                pos: 0,
                be: enc.big_endian,
            },
            logical: 0,
            path,
            base,
        },
        enc,
        until_pixel,
        stack: Vec::new(),
        in_sequence: false,
        last_header: None,
        check_pending: false,
        offset_table_next: false,
    };
    loop {
        if walk.check_pending && walk.close_ended()? {
            continue;
        }
        let step = if walk.in_sequence {
            walk.item_header()?
        } else if let Some(item) = walk.pixel_item() {
            walk.pixel_fragment(item)?
        } else if let Some(header) = walk.last_header.take() {
            walk.element_value(header, found)?
        } else {
            walk.element_header(found)?
        };
        if step == Step::End {
            return Ok(());
        }
    }
}

/// Whether the walk goes on after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// More tokens to read.
    Next,
    /// The end of the data (or, with `until_pixel`, of the elements before Pixel Data).
    End,
}

/// The state of [`walk_dataset_into`]: the parser's token stack and what it expects next.
struct DataSetWalk<'a> {
    w: Walker<'a>,
    enc: Enc,
    /// Stop at the first top-level element at or after Pixel Data.
    until_pixel: bool,
    /// The open sequences and items, outermost first (at most [`MAX_NESTING`]).
    stack: Vec<Token>,
    /// An item header is expected (inside a sequence, between its items).
    in_sequence: bool,
    /// The element header just read, whose value comes next.
    last_header: Option<(Tag, VR, u32)>,
    /// A sequence or item of defined length may have ended: check before the next token.
    check_pending: bool,
    /// The next pixel data fragment is the basic offset table.
    offset_table_next: bool,
}

impl DataSetWalk<'_> {
    fn too_deep(&self) -> IoError {
        self.w.fail(format!(
            "sequences nest deeper than {} levels",
            MAX_NESTING / 2
        ))
    }

    /// Closes the innermost sequence or item if its defined length ends here (`true`: check
    /// again); an element that runs past its end is an error. Clears `check_pending` otherwise.
    fn close_ended(&mut self) -> Result<bool> {
        if let Some(top) = self.stack.last().copied()
            && top.len != UNDEFINED
        {
            let end = top.base + top.len as u64;
            if end == self.w.logical {
                self.stack.pop();
                self.in_sequence = top.kind == Kind::Item;
                return Ok(true);
            }
            if end < self.w.logical {
                return Err(self.w.fail(format!(
                    "a sequence or item of {} bytes ends inside an element",
                    top.len
                )));
            }
        }
        self.check_pending = false;
        Ok(false)
    }

    /// An item header inside a sequence: (FFFE,E000) item, (FFFE,E00D) item end, (FFFE,E0DD)
    /// sequence end.
    fn item_header(&mut self) -> Result<Step> {
        let Some((tag, len)) = self.w.item_header() else {
            return Ok(Step::End);
        };
        match (tag.0, tag.1) {
            (0xFFFE, 0xE000) => {
                self.in_sequence = false;
                let Some(parent) = self.stack.last().copied() else {
                    return Err(self.w.fail("item outside a sequence".into()));
                };
                if self.stack.len() >= MAX_NESTING {
                    return Err(self.too_deep());
                }
                self.stack.push(Token {
                    kind: Kind::Item,
                    pixel: parent.pixel,
                    len,
                    base: self.w.logical,
                });
                if len == 0 {
                    self.check_pending = true;
                }
            }
            (0xFFFE, 0xE00D) => {
                self.stack.pop();
                self.in_sequence = true;
                self.check_pending = true;
            }
            (0xFFFE, 0xE0DD) => {
                self.stack.pop();
                self.in_sequence = false;
                self.check_pending = true;
            }
            _ => {
                return Err(self
                    .w
                    .fail(format!("expected an item tag (FFFE,E000), found {tag}")));
            }
        }
        Ok(Step::Next)
    }

    /// The innermost token when it is an item of encapsulated pixel data.
    fn pixel_item(&self) -> Option<Token> {
        self.stack
            .last()
            .copied()
            .filter(|top| top.kind == Kind::Item && top.pixel)
    }

    /// The basic offset table or a fragment of encapsulated pixel data (PS3.5 §A.4), the
    /// value of `item`.
    fn pixel_fragment(&mut self, item: Token) -> Result<Step> {
        if item.len == UNDEFINED {
            return Err(self
                .w
                .fail("pixel data fragment of undefined length".into()));
        }
        if self.offset_table_next {
            self.offset_table_next = false;
            self.w.value(PIXEL_DATA, item.len, item.len & !3)?;
            // The parser advances by the u32 values read, not by the length.
            self.w.logical -= (item.len & 3) as u64;
        } else {
            self.w.value(PIXEL_DATA, item.len, item.len)?;
        }
        self.check_pending = true;
        Ok(Step::Next)
    }

    /// The value of the element whose header was just read: encapsulated pixel data open a
    /// sequence and its basic offset table item; any other value is skipped (a top-level image
    /// attribute of group 0028 recorded in `found`).
    fn element_value(&mut self, (tag, vr, len): (Tag, VR, u32), found: &mut Found) -> Result<Step> {
        if tag == PIXEL_DATA && len == UNDEFINED {
            return self.encapsulated_pixel_data();
        }
        let w = &mut self.w;
        if self.stack.is_empty()
            && tag.0 == 0x0028
            && let Some(v) = w.c.b.get(w.c.pos..w.c.pos + len as usize)
        {
            found.capture(tag, v, self.enc.big_endian);
        }
        let read = if len == 0 { 0 } else { consumed(vr, len) };
        w.value(tag, len, read)?;
        self.check_pending = true;
        Ok(Step::Next)
    }

    /// Pixel Data of undefined length: a sequence of fragments, opened by the basic offset
    /// table item (or closed at once by a sequence delimiter).
    fn encapsulated_pixel_data(&mut self) -> Result<Step> {
        if self.stack.len() + 2 > MAX_NESTING {
            return Err(self.too_deep());
        }
        self.stack.push(Token {
            kind: Kind::Sequence,
            pixel: true,
            len: UNDEFINED,
            base: self.w.logical,
        });
        let Some((itag, ilen)) = self.w.item_header() else {
            return Err(self.w.fail("encapsulated pixel data is truncated".into()));
        };
        match (itag.0, itag.1) {
            (0xFFFE, 0xE000) => {
                self.in_sequence = false;
                self.stack.push(Token {
                    kind: Kind::Item,
                    pixel: true,
                    len: ilen,
                    base: self.w.logical,
                });
                if ilen == 0 {
                    self.check_pending = true;
                } else {
                    self.offset_table_next = true;
                }
            }
            (0xFFFE, 0xE0DD) => {
                self.stack.pop();
                self.in_sequence = false;
            }
            _ => {
                return Err(self.w.fail(format!(
                    "expected the basic offset table item (FFFE,E000) in encapsulated \
                     pixel data, found {itag}"
                )));
            }
        }
        Ok(Step::Next)
    }

    /// The next element header: opens a sequence (explicit SQ, or any other element of
    /// undefined length), ends an item at a stray item delimiter, or leaves the header for
    /// [`DataSetWalk::element_value`]. Records where top-level Pixel Data start.
    fn element_header(&mut self, found: &mut Found) -> Result<Step> {
        let before = self.w.c.pos;
        let Some((tag, vr, len)) =
            element_header(&mut self.w.c, self.enc, self.w.path, self.w.base)?
        else {
            return Ok(Step::End);
        };
        self.w.logical += (self.w.c.pos - before) as u64;
        if self.stack.is_empty() && tag == PIXEL_DATA {
            found.pixel = Some((len, self.w.at()));
        }
        // Item and delimitation tags (group FFFE) sort after Pixel Data but are not data
        // elements: the parser's `read_until` never stops at them (found by fuzzing: a
        // stray item delimiter at the top level ended this walk while the parser read on
        // into a 2.4 GB value).
        if self.until_pixel && self.stack.is_empty() && tag >= PIXEL_DATA && tag.0 != 0xFFFE {
            return Ok(Step::End);
        }
        if vr == VR::SQ || (len == UNDEFINED && !(tag == PIXEL_DATA || tag == ITEM_END)) {
            // A sequence: explicit SQ, or any other element of undefined length (the
            // parser reads those as sequences too, PS3.5 §7.5.1 and §6.2.2 note 4).
            if self.stack.len() >= MAX_NESTING {
                return Err(self.too_deep());
            }
            self.in_sequence = true;
            self.stack.push(Token {
                kind: Kind::Sequence,
                pixel: false,
                len,
                base: self.w.logical,
            });
            if len == 0 {
                self.check_pending = true;
            }
        } else if tag == ITEM_END {
            // An item delimiter where an element is expected: ends the item (ignored at
            // the top level).
            if !self.stack.is_empty() {
                self.in_sequence = true;
                self.stack.pop();
                self.check_pending = true;
            }
        } else {
            self.last_header = Some((tag, vr, len));
        }
        Ok(Step::Next)
    }
}
