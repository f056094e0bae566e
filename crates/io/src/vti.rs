//! VTK XML image data (`.vti`, <https://docs.vtk.org/en/latest/vtk_file_formats/vtkxml_file_format.html>).
//!
//! # What is read
//!
//! - `<VTKFile type="ImageData">` with `byte_order` (`LittleEndian`, `BigEndian`),
//!   `header_type` (`UInt32`, the default, or `UInt64`) and `compressor` (none,
//!   `vtkZLibDataCompressor`, or `vtkLZ4DataCompressor`, whose blocks are raw LZ4 blocks; LZMA is
//!   rejected).
//! - `<ImageData>`: `WholeExtent` (`x0 x1 y0 y1 z0 z1`, inclusive), `Origin`, `Spacing` and
//!   `Direction` (row-major 3×3, VTK ≥ 9; default identity). The grid's voxel (0,0,0) is the
//!   extent's first point: origin `Origin + D·(x0·sx, y0·sy, z0·sz)`. A negative spacing is folded
//!   into the direction (`|s|`, column negated). World frame: as written (VTK has no anatomical
//!   frame; no conversion).
//! - One `<Piece>` covering the whole extent; its `<PointData>` arrays (`<DataArray>`) of one
//!   component. The array read is `ReadOptions::array` if given, else the `Scalars` attribute
//!   of `<PointData>`, else the first array.
//! - `format`: `ascii`, `binary` (base64 inline) and `appended` (`<AppendedData encoding="raw">`
//!   or `"base64"`, at the array's `offset`). Binary blocks follow VTK's layout: a byte-count
//!   header (`header_type`), or with compression `[blocks, block size, last block size,
//!   compressed sizes…]` followed by zlib streams.
//! - `type`: `Int8`, `UInt8`, `Int16`, `UInt16`, `Float32` as they are; `Int32`, `UInt32`,
//!   `Float64` converted to f32 (as the NRRD reader). 64-bit integers are rejected.
//!
//! # Limits
//!
//! The file is read whole (at most [`crate::Limits::max_xml_bytes`]); the voxel count is checked
//! against the limit before decoding; decompressed blocks never grow past the needed size.

use crate::error::{IoError, Result, clip};
use crate::limits::checked_dims;
use crate::payload::{FileType, decode};
use crate::{LoadedVolume, ReadOptions};
use base64::Engine;
use std::io::Read;
use std::path::Path;
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{AnyVolume, CoreError, Grid, Volume};

/// Reads the default array (active scalars, else the first) of a `.vti` file with default
/// limits. See the [module documentation](self).
pub fn read_vti(path: impl AsRef<Path>) -> Result<AnyVolume> {
    read_vti_with(path, &ReadOptions::default()).map(|l| l.volume)
}

/// Reads a `.vti` file with [`ReadOptions`] (`array` picks a point-data array by name); the
/// result lists the arrays present.
pub fn read_vti_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let path = path.as_ref();
    crate::limits::require_regular_file(path, "volume file")?;
    let limit = options.limits.max_xml_bytes;
    let file = std::fs::File::open(path).map_err(|e| IoError::os(path, "open", e))?;
    let len = file
        .metadata()
        .map_err(|e| IoError::os(path, "stat", e))?
        .len();
    if len > limit {
        return Err(IoError::TooLarge {
            path: path.to_path_buf(),
            what: "VTK XML file size in bytes (max_xml_bytes)".into(),
            value: len as u128,
            limit: limit as u128,
        });
    }
    let mut bytes = Vec::new();
    file.take(limit)
        .read_to_end(&mut bytes)
        .map_err(|e| IoError::os(path, "read", e))?;

    // Split off <AppendedData>: raw appended data are not XML.
    let (xml_bytes, appended) = split_appended(path, &bytes)?;
    let xml_bytes: &[u8] = &xml_bytes;
    let xml = std::str::from_utf8(xml_bytes).map_err(|e| IoError::Syntax {
        path: path.to_path_buf(),
        line: line_of(xml_bytes, e.valid_up_to()),
        text: String::new(),
        reason: format!("not UTF-8 text: {e}"),
    })?;
    let doc = roxmltree::Document::parse(xml).map_err(|e| IoError::Syntax {
        path: path.to_path_buf(),
        line: e.pos().row as usize,
        text: String::new(),
        reason: format!("not well-formed XML: {e}"),
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "VTKFile" {
        return Err(IoError::field(
            path,
            "root element",
            root.tag_name().name(),
            "not a VTK XML file (expected <VTKFile>)",
        ));
    }
    let attr = |name: &str| root.attribute(name);
    match attr("type") {
        Some("ImageData") => {}
        other => {
            return Err(IoError::unsupported(
                path,
                "VTKFile type",
                other.unwrap_or(""),
                "ImageData (.vti)",
            ));
        }
    }
    let big_endian = match attr("byte_order").unwrap_or("LittleEndian") {
        "LittleEndian" => false,
        "BigEndian" => true,
        other => {
            return Err(IoError::field(
                path,
                "byte_order",
                other,
                "must be LittleEndian or BigEndian",
            ));
        }
    };
    let header64 = match attr("header_type").unwrap_or("UInt32") {
        "UInt32" => false,
        "UInt64" => true,
        other => {
            return Err(IoError::unsupported(
                path,
                "header_type",
                other,
                "UInt32, UInt64",
            ));
        }
    };
    let (compressed, lz4) = match attr("compressor") {
        None | Some("") => (false, false),
        Some("vtkZLibDataCompressor") => (true, false),
        Some("vtkLZ4DataCompressor") => (true, true),
        Some(other) => {
            return Err(IoError::unsupported(
                path,
                "compressor",
                other,
                "none, vtkZLibDataCompressor, vtkLZ4DataCompressor",
            ));
        }
    };
    let image = child(&root, "ImageData").ok_or_else(|| IoError::missing(path, "ImageData"))?;
    let ext_text = image
        .attribute("WholeExtent")
        .ok_or_else(|| IoError::missing(path, "WholeExtent"))?;
    let ext = parse_extent(path, "WholeExtent", ext_text)?;
    let sizes = [0, 1, 2].map(|a| (ext[2 * a + 1] - ext[2 * a]) as u64 + 1);
    let dims = checked_dims(path, "WholeExtent", ext_text, sizes, &options.limits)?;
    let origin: [f64; 3] = floats(path, "Origin", image.attribute("Origin"), [0.0; 3])?;
    let mut spacing: [f64; 3] = floats(path, "Spacing", image.attribute("Spacing"), [1.0; 3])?;
    let d: [f64; 9] = floats(
        path,
        "Direction",
        image.attribute("Direction"),
        [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
    )?;
    // Row-major: column c of D is (d[c], d[3 + c], d[6 + c]).
    let mut cols = [0, 1, 2].map(|c| DVec3::new(d[c], d[3 + c], d[6 + c]));
    for a in 0..3 {
        if spacing[a] < 0.0 {
            spacing[a] = -spacing[a];
            cols[a] = -cols[a];
        }
    }
    let direction = DMat3::from_cols(cols[0], cols[1], cols[2]);
    let first = DVec3::new(
        ext[0] as f64 * spacing[0],
        ext[2] as f64 * spacing[1],
        ext[4] as f64 * spacing[2],
    );
    let origin0 = (DVec3::from(origin) + direction * first).to_array();
    let grid = Grid::new(dims, spacing, origin0, direction).map_err(|e| match &e {
        CoreError::InvalidField { field, .. } if field == "direction" => IoError::field(
            path,
            "Direction",
            image.attribute("Direction").unwrap_or(""),
            "axis directions must be orthonormal (sheared grids are not supported)",
        ),
        CoreError::InvalidField { field, .. } if field.starts_with("spacing") => IoError::field(
            path,
            "Spacing",
            image.attribute("Spacing").unwrap_or(""),
            "spacings must be non-zero finite numbers",
        ),
        _ => IoError::core(path, e),
    })?;

    let pieces: Vec<_> = image
        .children()
        .filter(|n| n.has_tag_name("Piece"))
        .collect();
    let piece = match pieces.as_slice() {
        [p] => *p,
        [] => return Err(IoError::missing(path, "Piece")),
        _ => {
            return Err(IoError::unsupported(
                path,
                "Piece",
                &format!("{} pieces", pieces.len()),
                "one piece covering the WholeExtent",
            ));
        }
    };
    if let Some(pe) = piece.attribute("Extent")
        && parse_extent(path, "Piece Extent", pe)? != ext
    {
        return Err(IoError::unsupported(
            path,
            "Piece Extent",
            pe,
            format!("the WholeExtent ({ext_text}); partial pieces are not supported"),
        ));
    }
    let point_data =
        child(&piece, "PointData").ok_or_else(|| IoError::missing(path, "PointData"))?;
    let arrays: Vec<roxmltree::Node> = point_data
        .children()
        .filter(|n| n.has_tag_name("DataArray"))
        .collect();
    let names: Vec<String> = arrays
        .iter()
        .enumerate()
        .map(|(i, a)| {
            a.attribute("Name")
                .map_or_else(|| format!("#{i}"), str::to_string)
        })
        .collect();
    if arrays.is_empty() {
        return Err(IoError::missing(path, "PointData DataArray"));
    }
    let mut notes = Vec::new();
    let chosen = match (&options.array, point_data.attribute("Scalars")) {
        (Some(want), _) => names.iter().position(|n| n == want).ok_or_else(|| {
            IoError::invalid_argument(
                path,
                "array",
                format!("no point-data array named {want:?}; the file has {names:?}"),
            )
        })?,
        (None, Some(active)) => names.iter().position(|n| n == active).ok_or_else(|| {
            IoError::field(
                path,
                "PointData Scalars",
                active,
                format!("names no array; the file has {names:?}"),
            )
        })?,
        (None, None) => 0,
    };
    if names.len() > 1 {
        notes.push(format!(
            "point-data arrays: {}; read {:?}",
            names.join(", "),
            names[chosen]
        ));
    }
    let array = arrays[chosen];
    let name = &names[chosen];
    let field = |f: &str| format!("DataArray {name:?} {f}");
    if let Some(n) = array.attribute("NumberOfComponents")
        && n.trim() != "1"
    {
        return Err(IoError::unsupported(
            path,
            field("NumberOfComponents"),
            n,
            "1 (scalar arrays only)",
        ));
    }
    let ty = array.attribute("type").unwrap_or("");
    let ft = match ty {
        "Int8" | "Char" => FileType::I8,
        "UInt8" | "UnsignedChar" => FileType::U8,
        "Int16" | "Short" => FileType::I16,
        "UInt16" | "UnsignedShort" => FileType::U16,
        "Int32" | "Int" => FileType::I32,
        "UInt32" | "UnsignedInt" => FileType::U32,
        "Float32" | "Float" => FileType::F32,
        "Float64" | "Double" => FileType::F64,
        _ => {
            return Err(IoError::unsupported(
                path,
                field("type"),
                ty,
                "Int8, UInt8, Int16, UInt16, Float32; converted to Float32: Int32, UInt32, \
                 Float64",
            ));
        }
    };
    let count = grid.voxel_count();
    let needed = count * ft.size_bytes() as usize;
    let layout = Layout {
        path,
        what: field("data"),
        header64,
        big_endian,
        compressed,
        lz4,
        needed,
    };
    let format = array.attribute("format").unwrap_or("ascii");
    let bytes = match format {
        "ascii" => {
            let text = array.text().unwrap_or("");
            return finish(
                path,
                ascii_volume(path, &field("data"), text, ft, grid)?,
                names,
                notes,
            );
        }
        "binary" => {
            let text: Vec<u8> = array
                .text()
                .unwrap_or("")
                .bytes()
                .filter(|b| !b.is_ascii_whitespace())
                .collect();
            layout.base64_block(&text)?
        }
        "appended" => {
            let Some((encoding, data)) = appended else {
                return Err(IoError::missing(path, "AppendedData"));
            };
            let off_text = array.attribute("offset").unwrap_or("0");
            let offset: usize = off_text.trim().parse().map_err(|_| {
                IoError::field(path, field("offset"), off_text, "not a whole number ≥ 0")
            })?;
            match encoding.as_str() {
                "raw" => {
                    let at = data.get(offset..).ok_or_else(|| IoError::Truncated {
                        path: path.to_path_buf(),
                        what: "appended data (before the array's offset)".into(),
                        expected: offset as u64,
                        actual: data.len() as u64,
                        unit: "bytes",
                    })?;
                    layout.raw_block(at)?
                }
                "base64" => {
                    let text: Vec<u8> = data
                        .iter()
                        .copied()
                        .filter(|b| !b.is_ascii_whitespace())
                        .collect();
                    let at = text.get(offset..).ok_or_else(|| IoError::Truncated {
                        path: path.to_path_buf(),
                        what: "appended base64 data (before the array's offset)".into(),
                        expected: offset as u64,
                        actual: text.len() as u64,
                        unit: "bytes",
                    })?;
                    layout.base64_block(at)?
                }
                other => {
                    return Err(IoError::unsupported(
                        path,
                        "AppendedData encoding",
                        other,
                        "raw, base64",
                    ));
                }
            }
        }
        other => {
            return Err(IoError::unsupported(
                path,
                field("format"),
                other,
                "ascii, binary, appended",
            ));
        }
    };
    let volume = decode(bytes, ft, big_endian, grid, path)?;
    finish(path, volume, names, notes)
}

fn finish(
    _path: &Path,
    volume: AnyVolume,
    arrays: Vec<String>,
    notes: Vec<String>,
) -> Result<LoadedVolume> {
    Ok(LoadedVolume {
        volume,
        format: "VTK image data".into(),
        frames: 1,
        frame: 0,
        arrays,
        series: Vec::new(),
        series_uid: None,
        notes,
    })
}

fn child<'a, 'i>(node: &roxmltree::Node<'a, 'i>, name: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children().find(|n| n.has_tag_name(name))
}

fn line_of(bytes: &[u8], at: usize) -> usize {
    bytes[..at.min(bytes.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// The XML part of a file, and the appended data's encoding and bytes if any.
type Split<'a> = (std::borrow::Cow<'a, [u8]>, Option<(String, &'a [u8])>);

/// Splits the file at `<AppendedData …>`: returns the XML before it (closed with
/// `</VTKFile>`) and, if present, the encoding and the bytes after its `_` marker.
fn split_appended<'a>(path: &Path, bytes: &'a [u8]) -> Result<Split<'a>> {
    let tag = b"<AppendedData";
    let Some(p) = bytes.windows(tag.len()).position(|w| w == tag) else {
        return Ok((std::borrow::Cow::Borrowed(bytes), None));
    };
    let Some(q) = bytes[p..].iter().position(|&b| b == b'>').map(|q| p + q) else {
        return Err(IoError::Syntax {
            path: path.to_path_buf(),
            line: line_of(bytes, p),
            text: String::new(),
            reason: "unterminated <AppendedData> tag".into(),
        });
    };
    let tag_text = String::from_utf8_lossy(&bytes[p..=q]).into_owned();
    let encoding = tag_text
        .split("encoding=")
        .nth(1)
        .and_then(|r| {
            let quote = r.chars().next()?;
            r[quote.len_utf8()..]
                .split(quote)
                .next()
                .map(str::to_string)
        })
        .unwrap_or_else(|| "raw".into());
    let Some(u) = bytes[q..].iter().position(|&b| b == b'_').map(|u| q + u) else {
        return Err(IoError::Syntax {
            path: path.to_path_buf(),
            line: line_of(bytes, q),
            text: clip(&tag_text),
            reason: "appended data must start with `_`".into(),
        });
    };
    let mut data = &bytes[u + 1..];
    // Drop the closing tags if present (raw data may contain anything; the array offsets and
    // byte counts say how much is used).
    if encoding == "base64"
        && let Some(end) = data.windows(2).position(|w| w == b"</")
    {
        data = &data[..end];
    }
    let mut xml = bytes[..p].to_vec();
    xml.extend_from_slice(b"</VTKFile>");
    Ok((std::borrow::Cow::Owned(xml), Some((encoding, data))))
}

fn parse_extent(path: &Path, field: &str, text: &str) -> Result<[i64; 6]> {
    let v: [i64; 6] = crate::header::parse_numbers(path, field, text, "a whole number", |t| {
        t.parse::<i64>().ok()
    })?;
    for a in 0..3 {
        let n = v[2 * a + 1].checked_sub(v[2 * a]);
        if !matches!(n, Some(n) if (0..i64::MAX).contains(&n)) {
            return Err(IoError::field(
                path,
                field,
                text,
                format!("axis {a}: the end must not be less than the start"),
            ));
        }
    }
    Ok(v)
}

fn floats<const N: usize>(
    path: &Path,
    field: &str,
    text: Option<&str>,
    default: [f64; N],
) -> Result<[f64; N]> {
    match text {
        None => Ok(default),
        Some(t) => crate::header::parse_numbers(
            path,
            field,
            t,
            "a finite number",
            crate::header::parse_finite,
        ),
    }
}

fn ascii_volume(
    path: &Path,
    field: &str,
    text: &str,
    ft: FileType,
    grid: Grid,
) -> Result<AnyVolume> {
    let count = grid.voxel_count();
    let mut vals = Vec::with_capacity(count.min(text.len() / 2 + 1));
    for (n, t) in text.split_ascii_whitespace().enumerate() {
        if n == count {
            break;
        }
        let v = t
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                IoError::field(
                    path,
                    format!("{field} (value #{n})"),
                    t,
                    "not a finite number",
                )
            })?;
        let (lo, hi) = match ft {
            FileType::U8 => (0.0, 255.0),
            FileType::I8 => (-128.0, 127.0),
            FileType::U16 => (0.0, 65535.0),
            FileType::I16 => (-32768.0, 32767.0),
            _ => (f64::NEG_INFINITY, f64::INFINITY),
        };
        if v < lo || v > hi || (ft.size_bytes() <= 2 && v.fract() != 0.0) {
            return Err(IoError::field(
                path,
                format!("{field} (value #{n})"),
                t,
                format!("out of range for type {}", ft.name()),
            ));
        }
        vals.push(v);
    }
    if vals.len() < count {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: format!("{field} (ascii)"),
            expected: count as u64,
            actual: vals.len() as u64,
            unit: "values",
        });
    }
    let r: std::result::Result<AnyVolume, CoreError> = match ft {
        FileType::U8 => Volume::new(grid, vals.iter().map(|&x| x as u8).collect()).map(Into::into),
        FileType::I8 => Volume::new(grid, vals.iter().map(|&x| x as i8).collect()).map(Into::into),
        FileType::U16 => {
            Volume::new(grid, vals.iter().map(|&x| x as u16).collect()).map(Into::into)
        }
        FileType::I16 => {
            Volume::new(grid, vals.iter().map(|&x| x as i16).collect()).map(Into::into)
        }
        _ => Volume::new(grid, vals.iter().map(|&x| x as f32).collect()).map(Into::into),
    };
    r.map_err(|e| IoError::core(path, e))
}

/// How a binary array block is laid out (VTK's `vtkXMLDataElement` binary formats).
struct Layout<'a> {
    path: &'a Path,
    what: String,
    header64: bool,
    big_endian: bool,
    compressed: bool,
    /// Compressed blocks are raw LZ4 blocks (`vtkLZ4DataCompressor`) rather than zlib streams.
    lz4: bool,
    /// Bytes of samples needed.
    needed: usize,
}

impl Layout<'_> {
    fn word(&self) -> usize {
        if self.header64 { 8 } else { 4 }
    }

    fn read_word(&self, b: &[u8]) -> u64 {
        if self.header64 {
            let a: [u8; 8] = b.get(..8).and_then(|s| s.try_into().ok()).unwrap_or([0; 8]);
            if self.big_endian {
                u64::from_be_bytes(a)
            } else {
                u64::from_le_bytes(a)
            }
        } else {
            let a: [u8; 4] = b.get(..4).and_then(|s| s.try_into().ok()).unwrap_or([0; 4]);
            (if self.big_endian {
                u32::from_be_bytes(a)
            } else {
                u32::from_le_bytes(a)
            }) as u64
        }
    }

    fn truncated(&self, part: &str, expected: u64, actual: u64) -> IoError {
        IoError::Truncated {
            path: self.path.to_path_buf(),
            what: format!("{} ({part})", self.what),
            expected,
            actual,
            unit: "bytes",
        }
    }

    /// The compressed header `[blocks, block size, last size, sizes…]` from its first words;
    /// returns (block count, block size, last block size, header bytes).
    fn compressed_header(&self, first: &[u8]) -> Result<(u64, u64, u64, usize)> {
        let w = self.word();
        if first.len() < 3 * w {
            return Err(self.truncated("compression header", 3 * w as u64, first.len() as u64));
        }
        let nblocks = self.read_word(first);
        let bsize = self.read_word(&first[w..]);
        let last = self.read_word(&first[2 * w..]);
        // The blocks must hold exactly the samples needed.
        let total = if nblocks == 0 {
            0u128
        } else {
            (nblocks as u128 - 1) * bsize as u128 + if last == 0 { bsize } else { last } as u128
        };
        if total < self.needed as u128 || nblocks > self.needed as u64 + 1 {
            return Err(IoError::field(
                self.path,
                format!("{} compression header", self.what),
                &format!("{nblocks} blocks of {bsize} bytes, last {last}"),
                format!("the blocks must hold the {} bytes of samples", self.needed),
            ));
        }
        Ok((nblocks, bsize, last, (3 + nblocks as usize) * w))
    }

    /// An appended raw block.
    fn raw_block(&self, b: &[u8]) -> Result<Vec<u8>> {
        let w = self.word();
        if !self.compressed {
            if b.len() < w {
                return Err(self.truncated("byte-count header", w as u64, b.len() as u64));
            }
            let n = self.read_word(b);
            if n < self.needed as u64 {
                return Err(self.truncated("byte count in the header", self.needed as u64, n));
            }
            let data = &b[w..];
            if data.len() < self.needed {
                return Err(self.truncated("samples", self.needed as u64, data.len() as u64));
            }
            return Ok(data[..self.needed].to_vec());
        }
        let (nblocks, bsize, last, hbytes) = self.compressed_header(b)?;
        if b.len() < hbytes {
            return Err(self.truncated("compression header", hbytes as u64, b.len() as u64));
        }
        let sizes: Vec<u64> = (0..nblocks as usize)
            .map(|k| self.read_word(&b[(3 + k) * w..]))
            .collect();
        self.inflate_blocks(&b[hbytes..], &sizes, bsize, last)
    }

    /// A base64 block (inline `binary`, or appended `base64`): the header and the data are
    /// encoded separately when compressed, and either way when not.
    fn base64_block(&self, text: &[u8]) -> Result<Vec<u8>> {
        let engine = base64::engine::general_purpose::STANDARD;
        let chars = |bytes: usize| bytes.div_ceil(3) * 4;
        let dec = |t: &[u8], part: &str| -> Result<Vec<u8>> {
            engine.decode(t).map_err(|e| {
                IoError::field(
                    self.path,
                    format!("{} ({part})", self.what),
                    &String::from_utf8_lossy(&t[..t.len().min(60)]),
                    format!("invalid base64: {e}"),
                )
            })
        };
        let w = self.word();
        if !self.compressed {
            let hc = chars(w);
            if text.len() < hc {
                return Err(self.truncated(
                    "base64 byte-count header",
                    hc as u64,
                    text.len() as u64,
                ));
            }
            // Header encoded on its own (padded with '=') or together with the data.
            let all = if text[hc - 1] == b'=' {
                let mut h = dec(&text[..hc], "byte-count header")?;
                let end = text[hc..]
                    .iter()
                    .position(|&c| c == b'=')
                    .map_or(text.len(), |p| {
                        hc + p + text[hc + p..].iter().take_while(|&&c| c == b'=').count()
                    });
                h.extend(dec(&text[hc..end], "samples")?);
                h
            } else {
                let end = text
                    .iter()
                    .position(|&c| c == b'=')
                    .map_or(text.len(), |p| {
                        p + text[p..].iter().take_while(|&&c| c == b'=').count()
                    });
                dec(&text[..end], "samples")?
            };
            return self.raw_block_uncompressed(&all);
        }
        // Compressed: the first three words tell the header size.
        let first = dec(&text[..chars(3 * w).min(text.len())], "compression header")?;
        let (nblocks, bsize, last, hbytes) = self.compressed_header(&first)?;
        let hc = chars(hbytes);
        if text.len() < hc {
            return Err(self.truncated("base64 compression header", hc as u64, text.len() as u64));
        }
        let header = dec(&text[..hc], "compression header")?;
        if header.len() < hbytes {
            return Err(self.truncated(
                "base64 compression header",
                hbytes as u64,
                header.len() as u64,
            ));
        }
        let sizes: Vec<u64> = (0..nblocks as usize)
            .map(|k| self.read_word(&header[(3 + k) * w..]))
            .collect();
        let rest = &text[hc..];
        let end = rest
            .iter()
            .position(|&c| c == b'=')
            .map_or(rest.len(), |p| {
                p + rest[p..].iter().take_while(|&&c| c == b'=').count()
            });
        let data = dec(&rest[..end], "compressed samples")?;
        self.inflate_blocks(&data, &sizes, bsize, last)
    }

    fn raw_block_uncompressed(&self, all: &[u8]) -> Result<Vec<u8>> {
        let c = Layout {
            compressed: false,
            path: self.path,
            what: self.what.clone(),
            ..*self
        };
        c.raw_block(all)
    }

    /// Inflates zlib (or LZ4) blocks of the given compressed sizes into exactly `needed` bytes.
    fn inflate_blocks(&self, data: &[u8], sizes: &[u64], bsize: u64, last: u64) -> Result<Vec<u8>> {
        // Grows with the data actually inflated (never past `needed`): the header's sizes are
        // not trusted for allocation.
        let mut out: Vec<u8> = Vec::new();
        let mut at = 0usize;
        for (k, &cs) in sizes.iter().enumerate() {
            if out.len() >= self.needed {
                break;
            }
            let cs = usize::try_from(cs).unwrap_or(usize::MAX);
            let block = data.get(at..at.saturating_add(cs)).ok_or_else(|| {
                self.truncated(
                    &format!("compressed block {k}"),
                    cs as u64,
                    data.len().saturating_sub(at) as u64,
                )
            })?;
            at += cs;
            let want = if k + 1 == sizes.len() && last != 0 {
                last
            } else {
                bsize
            };
            let want = (want as usize).min(self.needed - out.len());
            let before = out.len();
            let codec = if self.lz4 { "LZ4" } else { "zlib" };
            if self.lz4 {
                // A raw LZ4 block (LZ4_compress_default): decoded into at most `want` bytes.
                let mut buf = vec![0u8; want];
                let n = lz4_flex::block::decompress_into(block, &mut buf).map_err(|e| {
                    IoError::Decompress {
                        path: self.path.to_path_buf(),
                        what: format!("{} (LZ4 block {k})", self.what),
                        error: std::io::Error::new(std::io::ErrorKind::InvalidData, e),
                    }
                })?;
                out.extend_from_slice(&buf[..n]);
            } else {
                let mut z = flate2::read::ZlibDecoder::new(block).take(want as u64);
                z.read_to_end(&mut out).map_err(|e| IoError::Decompress {
                    path: self.path.to_path_buf(),
                    what: format!("{} (zlib block {k})", self.what),
                    error: e,
                })?;
            }
            if out.len() - before < want {
                return Err(self.truncated(
                    &format!("{codec} block {k}, decompressed"),
                    want as u64,
                    (out.len() - before) as u64,
                ));
            }
        }
        if out.len() < self.needed {
            return Err(self.truncated(
                "decompressed samples",
                self.needed as u64,
                out.len() as u64,
            ));
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;
    use std::path::PathBuf;
    use volsplat_core::ScalarType;

    const B64: base64::engine::GeneralPurpose = base64::engine::general_purpose::STANDARD;

    fn zlib(data: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    fn word(v: usize, h64: bool) -> Vec<u8> {
        if h64 {
            (v as u64).to_le_bytes().to_vec()
        } else {
            (v as u32).to_le_bytes().to_vec()
        }
    }

    /// VTK's binary block for `data`: header + data, compressed in blocks of `bs` bytes or not.
    fn block(data: &[u8], h64: bool, compress: Option<usize>) -> (Vec<u8>, Vec<u8>) {
        match compress {
            None => (word(data.len(), h64), data.to_vec()),
            Some(bs) => {
                let chunks: Vec<Vec<u8>> = data.chunks(bs).map(zlib).collect();
                let last = data.len() % bs;
                let mut h = word(chunks.len(), h64);
                h.extend(word(bs, h64));
                h.extend(word(last, h64));
                for c in &chunks {
                    h.extend(word(c.len(), h64));
                }
                (h, chunks.concat())
            }
        }
    }

    fn doc(header: &str, image_attrs: &str, arrays: &str, appended: &[u8]) -> Vec<u8> {
        let mut s = format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" \
             byte_order=\"LittleEndian\" {header}>\n  <ImageData {image_attrs}>\n    \
             <Piece Extent=\"0 2 0 1 0 1\">\n      <PointData Scalars=\"density\">\n{arrays}      \
             </PointData>\n      <CellData/>\n    </Piece>\n  </ImageData>\n"
        )
        .into_bytes();
        if !appended.is_empty() {
            s.extend_from_slice(appended);
        }
        s.extend_from_slice(b"</VTKFile>\n");
        s
    }

    const IMAGE: &str = "WholeExtent=\"0 2 0 1 0 1\" Origin=\"1 2 3\" Spacing=\"0.5 1 2\" \
                         Direction=\"0 -1 0 1 0 0 0 0 1\"";

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn values() -> Vec<f32> {
        (0..12).map(|i| i as f32 * 1.5 - 4.0).collect()
    }

    fn f32_bytes(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    fn check(p: &Path) {
        let l = read_vti_with(p, &ReadOptions::default()).unwrap();
        let v = &l.volume;
        assert_eq!(v.scalar_type(), ScalarType::F32);
        assert_eq!(v.to_f32().data(), &values()[..]);
        let g = v.grid();
        assert_eq!(g.dims, [3, 2, 2]);
        assert_eq!(g.spacing, [0.5, 1.0, 2.0]);
        assert_eq!(g.origin, [1.0, 2.0, 3.0]);
        // Row-major "0 -1 0 1 0 0 0 0 1": column 0 (the i axis) is (0, 1, 0).
        assert_eq!(g.direction.col(0), DVec3::Y);
        assert_eq!(g.direction.col(1), -DVec3::X);
        assert_eq!(l.arrays, vec!["other".to_string(), "density".to_string()]);
    }

    /// `vtkLZ4DataCompressor`: the same header as zlib, raw LZ4 blocks; inline and appended;
    /// a damaged block is an error naming it.
    #[test]
    fn lz4_compressed_blocks() {
        let dir = tempfile::tempdir().unwrap();
        let data = f32_bytes(&values());
        let other = "        <DataArray type=\"UInt8\" Name=\"other\" format=\"ascii\">1 2 3 4 5 6 7 8 9 10 11 12</DataArray>\n";
        for bs in [16usize, 1000] {
            let chunks: Vec<Vec<u8>> = data.chunks(bs).map(lz4_flex::block::compress).collect();
            let mut h = word(chunks.len(), false);
            h.extend(word(bs, false));
            h.extend(word(data.len() % bs, false));
            for c in &chunks {
                h.extend(word(c.len(), false));
            }
            let d = chunks.concat();
            let header = "header_type=\"UInt32\" compressor=\"vtkLZ4DataCompressor\"";
            let arrays = format!(
                "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">\n  {}{}\n</DataArray>\n",
                B64.encode(&h),
                B64.encode(&d)
            );
            check(&write(
                dir.path(),
                "l.vti",
                &doc(header, IMAGE, &arrays, b""),
            ));
            let mut app = b"  <AppendedData encoding=\"raw\">\n   _".to_vec();
            app.extend_from_slice(&h);
            app.extend_from_slice(&d);
            app.extend_from_slice(b"\n  </AppendedData>\n");
            let arrays = format!(
                "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"0\"/>\n"
            );
            check(&write(
                dir.path(),
                "m.vti",
                &doc(header, IMAGE, &arrays, &app),
            ));
            // Damage the first block: a clear error, never a panic.
            let mut bad = d.clone();
            bad[0] = 0xFF;
            bad.truncate(3);
            let arrays = format!(
                "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">\n  {}{}\n</DataArray>\n",
                B64.encode(&h),
                B64.encode(&bad)
            );
            let e = read_vti(write(
                dir.path(),
                "n.vti",
                &doc(header, IMAGE, &arrays, b""),
            ))
            .unwrap_err()
            .to_string();
            assert!(e.contains("n.vti"), "{e}");
        }
    }

    #[test]
    fn every_encoding_and_header_type() {
        let dir = tempfile::tempdir().unwrap();
        let data = f32_bytes(&values());
        let other = "        <DataArray type=\"UInt8\" Name=\"other\" format=\"ascii\">1 2 3 4 5 6 7 8 9 10 11 12</DataArray>\n";
        // ascii
        let text: Vec<String> = values().iter().map(|v| v.to_string()).collect();
        let arrays = format!(
            "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"ascii\">\n{}\n</DataArray>\n",
            text.join(" ")
        );
        check(&write(dir.path(), "a.vti", &doc("", IMAGE, &arrays, b"")));
        for h64 in [false, true] {
            let ht = if h64 {
                "header_type=\"UInt64\""
            } else {
                "header_type=\"UInt32\""
            };
            for compress in [None, Some(16), Some(1000)] {
                let comp = if compress.is_some() {
                    " compressor=\"vtkZLibDataCompressor\""
                } else {
                    ""
                };
                let header = format!("{ht}{comp}");
                let (h, d) = block(&data, h64, compress);
                // inline base64: header and data encoded separately, and (uncompressed) together.
                let mut encodings = vec![format!("{}{}", B64.encode(&h), B64.encode(&d))];
                if compress.is_none() {
                    encodings.push(B64.encode([h.clone(), d.clone()].concat()));
                }
                for enc in encodings {
                    let arrays = format!(
                        "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">\n  {enc}\n</DataArray>\n"
                    );
                    check(&write(
                        dir.path(),
                        "b.vti",
                        &doc(&header, IMAGE, &arrays, b""),
                    ));
                }
                // appended raw, after a dummy array at offset 0.
                let dummy = [0xABu8; 5];
                let mut app = b"  <AppendedData encoding=\"raw\">\n   _".to_vec();
                app.extend_from_slice(&dummy);
                app.extend_from_slice(&h);
                app.extend_from_slice(&d);
                app.extend_from_slice(b"\n  </AppendedData>\n");
                let arrays = format!(
                    "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"{}\"/>\n",
                    dummy.len()
                );
                check(&write(
                    dir.path(),
                    "c.vti",
                    &doc(&header, IMAGE, &arrays, &app),
                ));
                // appended base64.
                let enc = format!("{}{}", B64.encode(&h), B64.encode(&d));
                let app = format!(
                    "  <AppendedData encoding=\"base64\">\n   _AAAA{enc}\n  </AppendedData>\n"
                );
                let arrays = format!(
                    "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"4\"/>\n"
                );
                check(&write(
                    dir.path(),
                    "d.vti",
                    &doc(&header, IMAGE, &arrays, app.as_bytes()),
                ));
            }
        }
    }

    #[test]
    fn array_choice_and_types() {
        let dir = tempfile::tempdir().unwrap();
        let arrays = "        <DataArray type=\"Int16\" Name=\"a\" format=\"ascii\">-1 2 3 4 5 6 7 8 9 10 11 -32768</DataArray>\n\
                      <DataArray type=\"Float64\" Name=\"b\" format=\"ascii\">0.5 2 3 4 5 6 7 8 9 10 11 1e30</DataArray>\n";
        let text = String::from_utf8(doc("", IMAGE, arrays, b"")).unwrap();
        // No Scalars attribute: the first array.
        let p = write(
            dir.path(),
            "t.vti",
            text.replace(" Scalars=\"density\"", "").as_bytes(),
        );
        let v = read_vti(&p).unwrap();
        assert_eq!(v.scalar_type(), ScalarType::I16);
        let o = ReadOptions {
            array: Some("b".into()),
            ..ReadOptions::default()
        };
        let l = read_vti_with(&p, &o).unwrap();
        assert_eq!(l.volume.scalar_type(), ScalarType::F32);
        assert_eq!(l.volume.to_f32().data()[0], 0.5);
        let o = ReadOptions {
            array: Some("c".into()),
            ..ReadOptions::default()
        };
        let e = read_vti_with(&p, &o).unwrap_err().to_string();
        assert!(e.contains("\"c\"") && e.contains("\"a\""), "{e}");
        // The active scalars name a missing array.
        let p = write(dir.path(), "t.vti", text.as_bytes());
        let e = read_vti(&p).unwrap_err().to_string();
        assert!(e.contains("Scalars") && e.contains("density"), "{e}");
        // Through the dispatcher.
        let p = write(
            dir.path(),
            "u.vti",
            text.replace("Scalars=\"density\"", "Scalars=\"b\"")
                .as_bytes(),
        );
        let l = crate::read_volume_with(&p, &ReadOptions::default()).unwrap();
        assert_eq!(l.format, "VTK image data");
        assert_eq!(l.volume.scalar_type(), ScalarType::F32);
    }

    #[test]
    fn extent_offset_and_negative_spacing() {
        let dir = tempfile::tempdir().unwrap();
        let arrays = "        <DataArray type=\"UInt8\" Name=\"density\" format=\"ascii\">1 2 3 4 5 6 7 8 9 10 11 12</DataArray>\n";
        let text = String::from_utf8(doc(
            "",
            "WholeExtent=\"10 12 0 1 -1 0\" Origin=\"0 0 0\" Spacing=\"-2 1 1\"",
            arrays,
            b"",
        ))
        .unwrap()
        .replace("Extent=\"0 2 0 1 0 1\"", "Extent=\"10 12 0 1 -1 0\"");
        let p = write(dir.path(), "e.vti", text.as_bytes());
        let v = read_vti(&p).unwrap();
        let g = v.grid();
        assert_eq!(g.spacing, [2.0, 1.0, 1.0]);
        // Point (10, 0, -1) is at x = 10·(−2) = −20, z = −1.
        assert_eq!(g.origin, [-20.0, 0.0, -1.0]);
        assert_eq!(g.direction.col(0), -DVec3::X);
    }

    #[test]
    fn malformed_files_are_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let data = f32_bytes(&values());
        let (h, d) = block(&data, false, Some(16));
        let ok_arrays = format!(
            "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}{}</DataArray>\n",
            B64.encode(&h),
            B64.encode(&d)
        );
        let comp = "compressor=\"vtkZLibDataCompressor\"";
        let ok = String::from_utf8(doc(comp, IMAGE, &ok_arrays, b"")).unwrap();
        read_vti(write(dir.path(), "ok.vti", ok.as_bytes())).unwrap();
        let cases: Vec<(String, &str)> = vec![
            (
                ok.replace("ImageData\" version", "PolyData\" version"),
                "VTKFile type",
            ),
            (
                ok.replace("WholeExtent=\"0 2", "WholeExtent=\"2 0"),
                "`WholeExtent`",
            ),
            (
                ok.replace(
                    "WholeExtent=\"0 2 0 1 0 1\"",
                    "WholeExtent=\"0 9223372036854775806 0 9223372036854775806 0 3\"",
                ),
                "`WholeExtent`",
            ),
            (ok.replace("Spacing=\"0.5", "Spacing=\"0"), "`Spacing`"),
            (
                ok.replace("Direction=\"0 -1 0", "Direction=\"1 1 0"),
                "`Direction`",
            ),
            (ok.replace("Float32", "Int64"), "type"),
            (ok.replace("vtkZLib", "vtkLZMA"), "`compressor`"),
            (
                ok.replace("UInt32", "UInt16")
                    .replace("byte_order", "header_type=\"UInt16\" byte_order"),
                "`header_type`",
            ),
            (
                ok.replace("format=\"binary\">", "format=\"binary\">!!!!"),
                "base64",
            ),
            (
                ok.replace(
                    "format=\"binary\">",
                    "NumberOfComponents=\"3\" format=\"binary\">",
                ),
                "NumberOfComponents",
            ),
            (
                ok.replace("<Piece", "<Piece Foo=\"1\"")
                    .replace("</ImageData>", "<Piece/></ImageData>"),
                "`Piece`",
            ),
            (ok.replace("</DataArray>", ""), "XML"),
            (
                ok.replace("format=\"binary\"", "format=\"appended\""),
                "AppendedData",
            ),
        ];
        for (text, want) in cases {
            let p = write(dir.path(), "bad.vti", text.as_bytes());
            let e = read_vti(&p).unwrap_err().to_string();
            assert!(
                e.contains(want) && e.contains("bad.vti"),
                "want {want}: {e}"
            );
        }
        // Truncated compressed data, a lying block count, raw appended data cut short.
        let cut = format!(
            "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}{}</DataArray>\n",
            B64.encode(&h),
            B64.encode(&d[..d.len() / 2])
        );
        let p = write(dir.path(), "cut.vti", &doc(comp, IMAGE, &cut, b""));
        assert!(read_vti(&p).is_err());
        let mut lying = h.clone();
        lying[0..4].copy_from_slice(&1000u32.to_le_bytes());
        let arrays = format!(
            "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}{}</DataArray>\n",
            B64.encode(&lying),
            B64.encode(&d)
        );
        let p = write(dir.path(), "lie.vti", &doc(comp, IMAGE, &arrays, b""));
        assert!(read_vti(&p).is_err());
        let (h, d) = block(&data, true, None);
        let mut app = b"<AppendedData encoding=\"raw\">_".to_vec();
        app.extend_from_slice(&h);
        app.extend_from_slice(&d[..20]);
        let arrays =
            "<DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"0\"/>\n";
        let p = write(
            dir.path(),
            "raw.vti",
            &doc("header_type=\"UInt64\"", IMAGE, arrays, &app),
        );
        let e = read_vti(&p).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        let arrays =
            "<DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"99999\"/>\n";
        let p = write(
            dir.path(),
            "raw.vti",
            &doc("header_type=\"UInt64\"", IMAGE, arrays, &app),
        );
        assert!(read_vti(&p).is_err());
    }
}
