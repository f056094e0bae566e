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
//! Every size a block header declares is checked before anything is allocated (module
//! `blocks`): the byte count and the compressed sizes against the bytes the array's block
//! holds in the file (inline: the decoded text; appended: up to the next appended array's
//! offset, or `</AppendedData>`), and each compressed block's share of the samples against the
//! most its compressed bytes decode to (zlib 1032:1, LZ4 256:1). Counts written with the other
//! word width than `header_type` says (a `UInt64` file with 4-byte counts, which VTK 9.7.2 reads
//! shifted by one sample) are an error saying so, as is a count larger than the block.

use crate::error::{IoError, Result, clip};
use crate::limits::checked_dims;
use crate::payload::{FileType, decode};
use crate::{LoadedVolume, ReadOptions};
use blocks::Layout;
use std::io::Read;
use std::path::Path;

mod blocks;
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{AnyVolume, CoreError, Grid, Volume};

/// Reads the default array (active scalars, else the first) of a `.vti` file with default
/// limits. See the [module documentation](self).
pub fn read_vti(path: impl AsRef<Path>) -> Result<AnyVolume> {
    read_vti_with(path, &ReadOptions::default()).map(|l| l.volume)
}

/// Reads a `.vti` file with [`ReadOptions`] (`array` picks a point-data array by name); the
/// result lists the arrays present. A `.vti` file holds one volume: a `frame` other than 0 or
/// a `series` is an error.
pub fn read_vti_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let path = path.as_ref();
    options.refuse_series(path)?;
    options.refuse_frame(path)?;
    options.refuse_multiscale(path, "VTK image data")?;
    let bytes = read_whole_file(path, &options.limits)?;
    // Split off <AppendedData>: raw appended data are not XML.
    let (xml_bytes, appended) = split_appended(path, &bytes)?;
    let doc = parse_xml(path, &xml_bytes)?;
    let root = doc.root_element();
    let encoding = FileEncoding::of(path, &root)?;
    let image = child(&root, "ImageData").ok_or_else(|| IoError::missing(path, "ImageData"))?;
    let extent = WholeExtent::of(path, &image)?;
    let grid = image_grid(path, &image, &extent, &options.limits)?;
    let piece = the_piece(path, &image, &extent)?;
    let choice = choose_array(path, &piece, options.array.as_deref())?;
    let array = ArrayRef {
        doc: &doc,
        node: choice.arrays[choice.chosen],
        name: &choice.names[choice.chosen],
    };
    let volume = read_array(path, array, &encoding, grid, appended)?;
    Ok(LoadedVolume {
        arrays: choice.names,
        ..LoadedVolume::single(volume, "VTK image data", choice.notes)
    })
}

/// The file's bytes, read whole: at most [`crate::Limits::max_xml_bytes`], a regular file, not a
/// link out of [`crate::Limits::confine_to`] (a VTK XML image data file names no other file).
fn read_whole_file(path: &Path, limits: &crate::Limits) -> Result<Vec<u8>> {
    crate::confine::Confinement::of(path, limits)?;
    crate::limits::require_regular_file(path, "volume file")?;
    let limit = limits.max_xml_bytes;
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
    Ok(bytes)
}

/// The XML part of the file (UTF-8, well-formed) as a document whose root is `<VTKFile>`.
fn parse_xml<'x>(path: &Path, xml_bytes: &'x [u8]) -> Result<roxmltree::Document<'x>> {
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
    Ok(doc)
}

/// How `<VTKFile>` says its binary data are written.
struct FileEncoding {
    /// `byte_order="BigEndian"`.
    big_endian: bool,
    /// `header_type="UInt64"` (else `UInt32`).
    header64: bool,
    /// A `compressor` is named.
    compressed: bool,
    /// The compressor is `vtkLZ4DataCompressor` (else zlib).
    lz4: bool,
}

impl FileEncoding {
    /// The `<VTKFile>` attributes `type` (must be `ImageData`), `byte_order`, `header_type`
    /// and `compressor`, checked.
    fn of(path: &Path, root: &roxmltree::Node) -> Result<Self> {
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
        Ok(FileEncoding {
            big_endian,
            header64,
            compressed,
            lz4,
        })
    }
}

/// `<ImageData WholeExtent="x0 x1 y0 y1 z0 z1">`, as written and parsed.
struct WholeExtent<'x> {
    /// The attribute's text, for messages.
    text: &'x str,
    /// First and last index along x, y, z (inclusive).
    extent: [i64; 6],
}

impl<'x> WholeExtent<'x> {
    /// The `WholeExtent` attribute of `<ImageData>` (required).
    fn of(path: &Path, image: &roxmltree::Node<'x, '_>) -> Result<Self> {
        let text = image
            .attribute("WholeExtent")
            .ok_or_else(|| IoError::missing(path, "WholeExtent"))?;
        let extent = parse_extent(path, "WholeExtent", text)?;
        Ok(WholeExtent { text, extent })
    }
}

/// The grid of `<ImageData>`: the extent's sizes (checked against the voxel limit), `Origin`,
/// `Spacing` and `Direction`. A negative spacing is folded into the direction; voxel (0,0,0) is
/// the extent's first point, at `Origin + D·(x0·sx, y0·sy, z0·sz)` (world frame as written).
fn image_grid(
    path: &Path,
    image: &roxmltree::Node,
    whole: &WholeExtent,
    limits: &crate::Limits,
) -> Result<Grid> {
    let ext = whole.extent;
    let sizes = [0, 1, 2].map(|a| (ext[2 * a + 1] - ext[2 * a]) as u64 + 1);
    let dims = checked_dims(path, "WholeExtent", whole.text, sizes, limits)?;
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
    Grid::new(dims, spacing, origin0, direction).map_err(|e| match &e {
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
    })
}

/// The one `<Piece>` of `<ImageData>`, which must cover the whole extent.
fn the_piece<'a, 'i>(
    path: &Path,
    image: &roxmltree::Node<'a, 'i>,
    whole: &WholeExtent,
) -> Result<roxmltree::Node<'a, 'i>> {
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
        && parse_extent(path, "Piece Extent", pe)? != whole.extent
    {
        return Err(IoError::unsupported(
            path,
            "Piece Extent",
            pe,
            format!(
                "the WholeExtent ({}); partial pieces are not supported",
                whole.text
            ),
        ));
    }
    Ok(piece)
}

/// The point-data arrays of a piece and the one to read.
struct ArrayChoice<'a, 'i> {
    /// The `<DataArray>` elements, in file order.
    arrays: Vec<roxmltree::Node<'a, 'i>>,
    /// Their names (`#i` for an unnamed one).
    names: Vec<String>,
    /// The index of the array to read: `wanted` by name, else the active `Scalars`, else the
    /// first.
    chosen: usize,
    /// A note listing the arrays when there are several.
    notes: Vec<String>,
}

/// Chooses the array of `piece` to read; see [`ArrayChoice`].
fn choose_array<'a, 'i>(
    path: &Path,
    piece: &roxmltree::Node<'a, 'i>,
    wanted: Option<&str>,
) -> Result<ArrayChoice<'a, 'i>> {
    let point_data =
        child(piece, "PointData").ok_or_else(|| IoError::missing(path, "PointData"))?;
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
    let chosen = match (wanted, point_data.attribute("Scalars")) {
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
    Ok(ArrayChoice {
        arrays,
        names,
        chosen,
        notes,
    })
}

/// The `<DataArray>` to read, in its document.
#[derive(Clone, Copy)]
struct ArrayRef<'d, 'a, 'i> {
    doc: &'d roxmltree::Document<'i>,
    node: roxmltree::Node<'a, 'i>,
    /// Its name (or `#i`), for messages.
    name: &'d str,
}

/// The samples of one scalar `<DataArray>` on `grid`: its `type` as a [`FileType`], then its
/// data as `ascii` text, `binary` (inline base64 blocks) or `appended` (raw or base64 blocks in
/// `<AppendedData>`, at the array's `offset`), decoded with the file's byte order.
fn read_array(
    path: &Path,
    array: ArrayRef,
    encoding: &FileEncoding,
    grid: Grid,
    appended: Option<(String, &[u8])>,
) -> Result<AnyVolume> {
    let name = array.name;
    let node = array.node;
    let field = |f: &str| format!("DataArray {name:?} {f}");
    if let Some(n) = node.attribute("NumberOfComponents")
        && n.trim() != "1"
    {
        return Err(IoError::unsupported(
            path,
            field("NumberOfComponents"),
            n,
            "1 (scalar arrays only)",
        ));
    }
    let ft = array_type(path, &field("type"), node.attribute("type").unwrap_or(""))?;
    let count = grid.voxel_count();
    let needed = count * ft.size_bytes() as usize;
    let layout = Layout {
        path,
        what: field("data"),
        header64: encoding.header64,
        big_endian: encoding.big_endian,
        compressed: encoding.compressed,
        lz4: encoding.lz4,
        needed,
    };
    let bytes = match node.attribute("format").unwrap_or("ascii") {
        "ascii" => {
            let text = node.text().unwrap_or("");
            return ascii_volume(path, &field("data"), text, ft, grid);
        }
        "binary" => {
            let text: Vec<u8> = node
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
            let region = appended_region(path, array.doc, node, &field("offset"), &encoding, data)?;
            match encoding.as_str() {
                "raw" => layout.raw_block(&region)?,
                _ => layout.base64_block(&region)?,
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
    decode(bytes, ft, encoding.big_endian, grid, path)
}

/// A `<DataArray>`'s `type` (`field` names it in messages): 8- and 16-bit integers and
/// `Float32` as they are; `Int32`, `UInt32`, `Float64` to be converted to f32.
fn array_type(path: &Path, field: &str, ty: &str) -> Result<FileType> {
    Ok(match ty {
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
                field,
                ty,
                "Int8, UInt8, Int16, UInt16, Float32; converted to Float32: Int32, UInt32, \
                 Float64",
            ));
        }
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
    // Drop the closing tags if present: base64 text ends at the first `</`; raw data (which may
    // hold any bytes) at the last `</AppendedData>`, so that no array's block reaches into them.
    let end = if encoding == "base64" {
        data.windows(2).position(|w| w == b"</")
    } else {
        let close = b"</AppendedData>";
        data.windows(close.len()).rposition(|w| w == close)
    };
    if let Some(end) = end {
        data = &data[..end];
    }
    let mut xml = bytes[..p].to_vec();
    xml.extend_from_slice(b"</VTKFile>");
    Ok((std::borrow::Cow::Owned(xml), Some((encoding, data))))
}

/// The bytes of one appended array's block (for `base64`, its text without whitespace): from
/// its `offset` to the next offset of any appended array in the file, or to the end of the
/// appended data. Block headers are checked against this region, so a byte count that runs
/// past it (into the next array or the closing tags) is an error, not data.
fn appended_region<'a>(
    path: &Path,
    doc: &roxmltree::Document,
    array: roxmltree::Node,
    field: &str,
    encoding: &str,
    data: &'a [u8],
) -> Result<std::borrow::Cow<'a, [u8]>> {
    use std::borrow::Cow;
    let offset_of = |n: &roxmltree::Node| n.attribute("offset").map(|t| t.trim().parse::<usize>());
    let off_text = array.attribute("offset").unwrap_or("0");
    let offset = match offset_of(&array) {
        None => 0,
        Some(Ok(o)) => o,
        Some(Err(_)) => {
            return Err(IoError::field(
                path,
                field,
                off_text,
                "not a whole number ≥ 0",
            ));
        }
    };
    let next = doc
        .descendants()
        .filter(|n| n.has_tag_name("DataArray") && n.attribute("format") == Some("appended"))
        .filter_map(|n| offset_of(&n).and_then(|o| o.ok()))
        .filter(|&o| o > offset)
        .min();
    let (what, data) = match encoding {
        "raw" => ("appended data", Cow::Borrowed(data)),
        "base64" => (
            "appended base64 data",
            Cow::Owned(
                data.iter()
                    .copied()
                    .filter(|b| !b.is_ascii_whitespace())
                    .collect::<Vec<u8>>(),
            ),
        ),
        other => {
            return Err(IoError::unsupported(
                path,
                "AppendedData encoding",
                other,
                "raw, base64",
            ));
        }
    };
    let len = data.len();
    let end = next.unwrap_or(len).min(len);
    if offset > len {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: format!("{what} (before the array's offset)"),
            expected: offset as u64,
            actual: len as u64,
            unit: "bytes",
        });
    }
    Ok(match data {
        Cow::Borrowed(d) => Cow::Borrowed(&d[offset..end]),
        Cow::Owned(mut d) => {
            d.truncate(end);
            d.drain(..offset);
            Cow::Owned(d)
        }
    })
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
        // Float arrays may hold NaN and infinities (VTK writes `nan`, `inf`): `Volume::new`
        // replaces them and says so (decision 0030). Integer arrays may not.
        let float = matches!(ft, FileType::F32 | FileType::F64);
        let v = t
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() || float)
            .ok_or_else(|| {
                IoError::field(
                    path,
                    format!("{field} (value #{n})"),
                    t,
                    if float {
                        "not a number"
                    } else {
                        "not a finite number"
                    },
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
        // Finite doubles beyond float32 are an error naming the sample, as in the other
        // readers (decision 0030); NaN and infinities are replaced by `Volume::new`.
        _ => Volume::new(
            grid,
            crate::payload::doubles_to_f32(vals.iter().copied(), path)?,
        )
        .map(Into::into),
    };
    r.map_err(|e| IoError::core(path, e))
}

#[cfg(test)]
mod tests;
