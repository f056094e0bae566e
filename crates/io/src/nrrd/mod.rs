//! NRRD volumes (Teem's "nearly raw raster data", <http://teem.sourceforge.net/nrrd/format.html>):
//! reading attached (`.nrrd`) and detached (`.nhdr`) headers, and writing attached files.
//!
//! # What is read
//!
//! - Magic `NRRD0001` … `NRRD0005`; `#` comments and `key:=value` pairs are ignored, as are
//!   informational fields (`content`, `kinds`, `centers`, `units`, `labels`, `min`, `max`, …).
//! - `dimension` must be 3; `sizes` gives the grid dimensions (i fastest, as in NRRD).
//! - `type`: `uint8`/`uchar`/`unsigned char`, `int8`/`signed char`, `uint16`/`ushort`/
//!   `unsigned short`, `int16`/`short`, `float` and their other Teem spellings are read as is.
//!   `int32`/`int`, `uint32`/`uint` and `double` are **converted to `f32`** (integers above
//!   2²⁴ in magnitude and doubles lose precision; doubles outside the `f32` range are an error).
//!   64-bit integers and `block` are rejected.
//! - `encoding`: `raw`, `gzip`/`gz`, and `ascii`/`text`/`txt`. Others (`bzip2`, `hex`, …) are
//!   rejected. `endian` (`little`/`big`) is required for multi-byte binary types.
//! - Geometry: `space directions` (vectors such as `(1,0,0)`, or `none`) give per-axis spacing
//!   (the vector's length, world units) and direction (the normalised vector, one column of
//!   [`Grid::direction`]); `spacings` is used for axes without a direction vector (`nan` → 1);
//!   `space origin` gives the world position of voxel (0,0,0) (default 0). **World frame LPS**
//!   (decision 0008, as ITK): `space: right-anterior-superior` (`RAS`) and
//!   `left-anterior-superior` (`LAS`) are converted by negating x and y (RAS) or y (LAS) of the
//!   directions and origin; `LPS`, non-anatomical spaces (`scanner-xyz`, `3D-right-handed`, …)
//!   and files without `space` are kept as written (VTK's NRRD reader never converts); a file
//!   without `space` draws a note that its axes are taken as LPS. The
//!   directions must be orthogonal (sheared grids are rejected). Only 3-D spaces are accepted
//!   (`space` such as `RAS`, `LPS`, `scanner-xyz`, `3D-right-handed`, or `space dimension: 3`).
//! - Data: attached after the blank line ending the header, or in `data file` (`datafile`),
//!   resolved relative to the header's directory; `LIST` and numbered multi-file forms are
//!   rejected. `line skip` counts lines of the data file (before decompression); `byte skip`
//!   counts bytes after them (after decompression for gzip); `byte skip: -1` (raw only) means
//!   the samples are the last bytes of the file. Trailing data after the samples is ignored.
//!
//! # Limits
//!
//! Header at most [`crate::MAX_HEADER_BYTES`]; voxel count at most
//! [`volsplat_core::volume::MAX_VOXELS`] (checked from `sizes` before anything is allocated); a raw
//! payload must hold at least the needed bytes (checked against the file size before
//! allocating); a gzip payload is never inflated past the needed size.

use crate::atomic::{write_atomic, write_err};
use crate::confine::Confinement;
use crate::error::{IoError, Result};
use crate::header::{
    Field, Fields, LineAction, normalize_words, parse_finite, parse_numbers, read_header, require,
    resolve_data_path,
};
use crate::limits::{Limits, checked_dims};
use crate::payload::{ByteSkip, Encoding, FileType, PayloadSpec, read_payload, write_samples_le};
use crate::{LoadedVolume, ReadOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{AnyVolume, CoreError, Grid};

mod source;
pub use source::{NrrdHeader, NrrdSource};

/// The `type` spellings accepted, for error messages.
const SUPPORTED_TYPES: &str = "uint8 (uchar, unsigned char), int8 (signed char), \
     uint16 (ushort, unsigned short), int16 (short), float; converted to float: \
     int32 (int), uint32 (uint), double";
const SUPPORTED_ENCODINGS: &str = "raw, gzip (gz), ascii (text, txt)";

/// Reads a NRRD volume (attached `.nrrd` or detached `.nhdr` header) into a runtime-typed volume,
/// with default [`ReadOptions`].
///
/// World space is LPS for RAS/LAS files, else the file's space as written (see the [module documentation](self) for the
/// fields, conversions and limits). Errors name the file, the header field and its value.
pub fn read_nrrd(path: impl AsRef<Path>) -> Result<AnyVolume> {
    read_nrrd_with(path, &ReadOptions::default()).map(|l| l.volume)
}

/// [`read_nrrd`] with [`ReadOptions`]: its [`Limits`] (header bytes, voxel count, confinement)
/// apply; a NRRD file holds one volume, so a `frame` other than 0, an `array` or a `series`
/// is an error. The notes say how the world frame was taken (RAS/LAS converted to LPS, or
/// no `space` field and the axes taken as LPS).
pub fn read_nrrd_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let path = path.as_ref();
    options.refuse_all_but_limits(path, "NRRD")?;
    let (volume, notes) = read_nrrd_file(path, &options.limits)?;
    Ok(LoadedVolume::single(volume, "NRRD", notes))
}

/// Reads a NRRD file; also returns notes for the user (e.g. the world-frame conversion).
///
/// The steps: the header's lines (up to the first blank line), its fields, the grid's size
/// (checked against the voxel limit before anything else), the samples' type, encoding and
/// byte order, the world grid (converted to LPS), the skips, where the data lie; then the
/// payload.
fn read_nrrd_file(path: &Path, limits: &Limits) -> Result<(AnyVolume, Vec<String>)> {
    with_payload(path, limits, |spec, grid, notes| {
        Ok((read_payload(spec, grid)?, notes))
    })
}

/// The NRRD file at `path` opened for reading one z slice at a time (`convert -o X.zarr`),
/// with its grid and notes; `None` for encodings other than raw (read those whole).
pub(crate) fn nrrd_slices(
    path: &Path,
    options: &ReadOptions,
) -> Result<Option<(crate::payload::RawSlices, Grid, Vec<String>)>> {
    options.refuse_all_but_limits(path, "NRRD")?;
    with_payload(path, &options.limits, |spec, grid, notes| {
        if spec.encoding != Encoding::Raw {
            return Ok(None);
        }
        let slices = crate::payload::RawSlices::open(spec, &grid)?;
        Ok(Some((slices, grid, notes)))
    })
}

/// Parses the header of `path` and calls `f` with its payload, grid and notes.
fn with_payload<R>(
    path: &Path,
    limits: &Limits,
    f: impl FnOnce(&PayloadSpec<'_>, Grid, Vec<String>) -> Result<R>,
) -> Result<R> {
    let confine = Confinement::of(path, limits)?;
    let header = read_header(path, limits.max_header_bytes, |n, line| {
        if n > 1 && line.trim().is_empty() {
            LineAction::EndBefore
        } else {
            LineAction::Keep
        }
    })?;
    let fields = parse_fields(path, &header.lines)?;
    let dims = parse_dims(path, &fields, limits)?;
    let samples = Samples::parse(path, &fields)?;
    let mut notes = Vec::new();
    let grid = world_grid(path, &fields, dims, &mut notes)?;
    let skips = Skips::parse(path, &fields, samples.encoding)?;
    let (data_path, start) = data_location(path, &fields, confine.as_ref(), header.end)?;
    let spec = PayloadSpec {
        data_path: &data_path,
        start,
        line_skip: skips.line_skip,
        byte_skip: skips.byte_skip,
        skip_field: skips.skip_field,
        encoding: samples.encoding,
        file_type: samples.file_type,
        big_endian: samples.big_endian,
        exact: false,
    };
    f(&spec, grid, notes)
}

/// The header's fields by canonical name ([`canonical_field`]).
/// Checks the magic line and collects the fields of the header's other lines: `#` comments
/// and `key:=value` pairs are skipped, a field given twice is an error naming both lines.
fn parse_fields(path: &Path, lines: &[(usize, String)]) -> Result<Fields> {
    let mut lines = lines.iter();
    match lines.next() {
        Some((_, magic)) if is_nrrd_magic(magic) => {}
        Some((n, magic)) => {
            return Err(IoError::Syntax {
                path: path.to_path_buf(),
                line: *n,
                text: crate::error::clip(magic),
                reason: "not a NRRD file (expected magic NRRD0001 … NRRD0005)".into(),
            });
        }
        None => {
            return Err(IoError::Syntax {
                path: path.to_path_buf(),
                line: 1,
                text: String::new(),
                reason: "empty file; not a NRRD file".into(),
            });
        }
    }
    let mut fields = Fields::new();
    for (n, text) in lines {
        if text.starts_with('#') || text.trim().is_empty() {
            continue;
        }
        let key_value = text.find(":=");
        let colon = text.find(':');
        let Some(colon) = colon else {
            return Err(IoError::Syntax {
                path: path.to_path_buf(),
                line: *n,
                text: crate::error::clip(text),
                reason: "expected `field: value`, `key:=value` or a `#` comment".into(),
            });
        };
        if key_value == Some(colon) {
            continue; // key:=value pair: free-form metadata, ignored.
        }
        let name = text[..colon].trim().to_string();
        let value = text[colon + 1..].trim().to_string();
        if name.is_empty() {
            return Err(IoError::Syntax {
                path: path.to_path_buf(),
                line: *n,
                text: crate::error::clip(text),
                reason: "empty field name".into(),
            });
        }
        let canon = canonical_field(&name);
        if let Some(prev) = fields.get(&canon) {
            return Err(IoError::Syntax {
                path: path.to_path_buf(),
                line: *n,
                text: crate::error::clip(text),
                reason: format!("field `{name}` given twice (first on line {})", prev.line),
            });
        }
        fields.insert(
            canon,
            Field {
                line: *n,
                name,
                value,
            },
        );
    }
    Ok(fields)
}

/// `dimension` (must be 3) and `sizes`, checked against the voxel limit.
fn parse_dims(path: &Path, fields: &Fields, limits: &Limits) -> Result<[usize; 3]> {
    let dim = require(path, fields, "dimension", "dimension")?;
    let d: usize = dim
        .value
        .parse()
        .map_err(|_| IoError::field(path, &dim.name, &dim.value, "not a whole number"))?;
    if d != 3 {
        return Err(IoError::field(
            path,
            &dim.name,
            &dim.value,
            "only 3-D volumes are supported (dimension must be 3)",
        ));
    }
    let sizes_f = require(path, fields, "sizes", "sizes")?;
    let sizes: [u64; 3] = parse_numbers(
        path,
        &sizes_f.name,
        &sizes_f.value,
        "a whole number ≥ 1",
        |t| t.parse::<u64>().ok().filter(|&v| v > 0),
    )?;
    checked_dims(path, &sizes_f.name, &sizes_f.value, sizes, limits)
}

/// How the samples are stored: `type`, `encoding` and `endian`.
struct Samples {
    file_type: FileType,
    encoding: Encoding,
    /// `endian: big`; `endian` is required for multi-byte binary types.
    big_endian: bool,
}

impl Samples {
    /// The fields `type`, `encoding` and `endian`, checked.
    fn parse(path: &Path, fields: &Fields) -> Result<Self> {
        let type_f = require(path, fields, "type", "type")?;
        let file_type = parse_type(&type_f.value).ok_or_else(|| {
            IoError::unsupported(path, &type_f.name, &type_f.value, SUPPORTED_TYPES)
        })?;
        let enc_f = require(path, fields, "encoding", "encoding")?;
        let encoding = match normalize_words(&enc_f.value).as_str() {
            "raw" => Encoding::Raw,
            "gzip" | "gz" => Encoding::Gzip,
            "ascii" | "text" | "txt" => Encoding::Ascii,
            _ => {
                return Err(IoError::unsupported(
                    path,
                    &enc_f.name,
                    &enc_f.value,
                    SUPPORTED_ENCODINGS,
                ));
            }
        };
        let big_endian = match fields.get("endian") {
            Some(f) => match normalize_words(&f.value).as_str() {
                "little" => false,
                "big" => true,
                _ => {
                    return Err(IoError::field(
                        path,
                        &f.name,
                        &f.value,
                        "must be `little` or `big`",
                    ));
                }
            },
            None if file_type.size_bytes() > 1 && encoding != Encoding::Ascii => {
                return Err(IoError::missing(path, "endian"));
            }
            None => false,
        };
        Ok(Samples {
            file_type,
            encoding,
            big_endian,
        })
    }
}

/// The grid in LPS: [`parse_geometry`], then RAS/LAS `space`s converted (decision 0008); a
/// file without `space` is kept as written, with a note that its axes are taken as LPS.
fn world_grid(
    path: &Path,
    fields: &Fields,
    dims: [usize; 3],
    notes: &mut Vec<String>,
) -> Result<Grid> {
    let grid = parse_geometry(path, fields, dims)?;
    Ok(match fields.get("space") {
        Some(f) => {
            let space = normalize_words(&f.value);
            let (grid, note) = crate::frame::to_lps(path, &space, grid)?;
            notes.extend(note);
            grid
        }
        None => {
            notes.push(
                "world frame: no `space` field; the axes are taken as LPS (as ITK does), \
                 the file's coordinates as written"
                    .into(),
            );
            grid
        }
    })
}

/// `line skip` and `byte skip`.
struct Skips<'f> {
    /// Lines of the data file to skip (before decompression).
    line_skip: u64,
    /// Bytes to skip after them (after decompression), or `-1`: the data end the file.
    byte_skip: ByteSkip,
    /// The `byte skip` field as spelled, for messages.
    skip_field: &'f str,
}

impl<'f> Skips<'f> {
    /// The skips, checked: `byte skip: -1` only with raw encoding.
    fn parse(path: &Path, fields: &'f Fields, encoding: Encoding) -> Result<Self> {
        let line_skip = match fields.get("lineskip") {
            Some(f) => f
                .value
                .parse::<u64>()
                .map_err(|_| IoError::field(path, &f.name, &f.value, "not a whole number ≥ 0"))?,
            None => 0,
        };
        let (byte_skip, skip_field) = match fields.get("byteskip") {
            Some(f) => {
                let v: i64 = f
                    .value
                    .parse()
                    .map_err(|_| IoError::field(path, &f.name, &f.value, "not a whole number"))?;
                let skip = match v {
                    -1 => ByteSkip::FromEnd,
                    v if v >= 0 => ByteSkip::Bytes(v as u64),
                    _ => {
                        return Err(IoError::field(
                            path,
                            &f.name,
                            &f.value,
                            "must be ≥ 0, or -1 for data at the end of the file",
                        ));
                    }
                };
                (skip, f.name.as_str())
            }
            None => (ByteSkip::Bytes(0), "byte skip"),
        };
        if byte_skip == ByteSkip::FromEnd && encoding != Encoding::Raw {
            return Err(IoError::field(
                path,
                skip_field,
                "-1",
                "-1 (data at the end of the file) is only allowed with raw encoding",
            ));
        }
        Ok(Skips {
            line_skip,
            byte_skip,
            skip_field,
        })
    }
}

/// Where the samples lie: the `data file` (inside the confinement folder, if any) from its
/// start, or this file after the header (`header_end` bytes); a detached `.nhdr` header needs a
/// `data file`.
fn data_location(
    path: &Path,
    fields: &Fields,
    confine: Option<&Confinement>,
    header_end: u64,
) -> Result<(PathBuf, u64)> {
    match fields.get("datafile") {
        Some(f) => {
            let data = parse_data_file(path, f)?;
            if let Some(c) = confine {
                c.check(
                    path,
                    &format!("field `{}`: data file", f.name),
                    &f.value,
                    &data,
                )?;
            }
            Ok((data, 0))
        }
        None => {
            let detached = path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("nhdr"));
            if detached {
                return Err(IoError::missing(path, "data file"));
            }
            Ok((path.to_path_buf(), header_end))
        }
    }
}

fn is_nrrd_magic(line: &str) -> bool {
    matches!(
        line.trim_end(),
        "NRRD0001" | "NRRD0002" | "NRRD0003" | "NRRD0004" | "NRRD0005"
    )
}

/// Field names are matched case-insensitively and without spaces (`data file` = `datafile`).
fn canonical_field(name: &str) -> String {
    name.chars()
        .filter(|c| !c.is_whitespace())
        .collect::<String>()
        .to_ascii_lowercase()
}

/// Teem's spellings of the scalar types.
fn parse_type(value: &str) -> Option<FileType> {
    Some(match normalize_words(value).as_str() {
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => FileType::U8,
        "signed char" | "char" | "int8" | "int8_t" => FileType::I8,
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => FileType::U16,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            FileType::I16
        }
        "int" | "signed int" | "int32" | "int32_t" => FileType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => FileType::U32,
        "float" => FileType::F32,
        "double" => FileType::F64,
        _ => return None,
    })
}

/// `data file: NAME`; `LIST` and numbered multi-file forms are rejected.
fn parse_data_file(path: &Path, f: &Field) -> Result<PathBuf> {
    let tokens: Vec<&str> = f.value.split_whitespace().collect();
    if tokens.is_empty() {
        return Err(IoError::field(path, &f.name, &f.value, "empty file name"));
    }
    if tokens[0] == "LIST" {
        return Err(IoError::unsupported(
            path,
            &f.name,
            &f.value,
            "a single data file name (LIST is not supported)",
        ));
    }
    if tokens.len() >= 4 && tokens[0].contains('%') {
        return Err(IoError::unsupported(
            path,
            &f.name,
            &f.value,
            "a single data file name (numbered multi-file data are not supported)",
        ));
    }
    Ok(resolve_data_path(path, &f.value))
}

/// The number of world dimensions from `space` / `space dimension`, if given.
fn space_dimension(path: &Path, fields: &Fields) -> Result<Option<usize>> {
    let mut dim = None;
    if let Some(f) = fields.get("space") {
        let d = match normalize_words(&f.value).as_str() {
            "right-anterior-superior"
            | "ras"
            | "left-anterior-superior"
            | "las"
            | "left-posterior-superior"
            | "lps"
            | "scanner-xyz"
            | "3d-right-handed"
            | "3d-left-handed" => 3,
            "right-anterior-superior-time"
            | "rast"
            | "left-anterior-superior-time"
            | "last"
            | "left-posterior-superior-time"
            | "lpst"
            | "scanner-xyz-time"
            | "3d-right-handed-time"
            | "3d-left-handed-time" => 4,
            _ => {
                return Err(IoError::unsupported(
                    path,
                    &f.name,
                    &f.value,
                    "RAS, LAS, LPS, scanner-xyz, 3D-right-handed, 3D-left-handed \
                     (and their long forms)",
                ));
            }
        };
        if d != 3 {
            return Err(IoError::unsupported(
                path,
                &f.name,
                &f.value,
                "a 3-D space (spaces with time are not supported)",
            ));
        }
        dim = Some(d);
    }
    if let Some(f) = fields.get("spacedimension") {
        let d: usize = f
            .value
            .parse()
            .map_err(|_| IoError::field(path, &f.name, &f.value, "not a whole number"))?;
        if d != 3 {
            return Err(IoError::field(
                path,
                &f.name,
                &f.value,
                "only 3-D world spaces are supported",
            ));
        }
        dim = Some(d);
    }
    Ok(dim)
}

/// Parses a vector `(x,y,z)`; errors name `field`.
fn parse_vector(path: &Path, f: &Field, text: &str) -> Result<DVec3> {
    let inner = text
        .trim()
        .strip_prefix('(')
        .and_then(|t| t.strip_suffix(')'))
        .ok_or_else(|| {
            IoError::field(
                path,
                &f.name,
                &f.value,
                format!("`{text}` is not a vector like (1,0,0)"),
            )
        })?;
    let comps: Vec<&str> = inner.split(',').map(str::trim).collect();
    if comps.len() != 3 {
        return Err(IoError::field(
            path,
            &f.name,
            &f.value,
            format!(
                "vector `{text}` has {} components; the space is 3-D",
                comps.len()
            ),
        ));
    }
    let mut v = [0.0; 3];
    for (o, c) in v.iter_mut().zip(&comps) {
        *o = parse_finite(c).ok_or_else(|| {
            IoError::field(
                path,
                &f.name,
                &f.value,
                format!("`{c}` is not a finite number"),
            )
        })?;
    }
    Ok(DVec3::from(v))
}

/// Splits `space directions` into per-axis items: `(…)` vectors (which may contain spaces) or
/// words such as `none`.
fn split_vectors(value: &str) -> Vec<String> {
    let mut items = Vec::new();
    let mut cur = String::new();
    let mut depth = 0usize;
    for c in value.chars() {
        match c {
            '(' => {
                depth += 1;
                cur.push(c);
            }
            ')' => {
                depth = depth.saturating_sub(1);
                cur.push(c);
                if depth == 0 {
                    items.push(std::mem::take(&mut cur));
                }
            }
            c if c.is_whitespace() && depth == 0 => {
                if !cur.is_empty() {
                    items.push(std::mem::take(&mut cur));
                }
            }
            c => cur.push(c),
        }
    }
    if !cur.is_empty() {
        items.push(cur);
    }
    items
}

/// Builds the grid from `space directions`, `spacings` and `space origin`.
fn parse_geometry(path: &Path, fields: &Fields, dims: [usize; 3]) -> Result<Grid> {
    // Validates `space` / `space dimension` (3-D only). Without either, `space directions` are
    // still accepted as 3-vectors (lenient; Teem requires a space).
    space_dimension(path, fields)?;
    // Per-axis world step vectors where known.
    let mut steps: [Option<DVec3>; 3] = [None; 3];
    let mut spacings: [Option<f64>; 3] = [None; 3];
    if let Some(f) = fields.get("spacings") {
        let vals: [f64; 3] =
            parse_numbers(path, &f.name, &f.value, "a non-zero number or nan", |t| {
                let v = t.parse::<f64>().ok()?;
                (v.is_nan() || (v.is_finite() && v != 0.0)).then_some(v)
            })?;
        for (s, v) in spacings.iter_mut().zip(vals) {
            *s = (!v.is_nan()).then_some(v);
        }
    }
    let dirs_field = fields.get("spacedirections");
    if let Some(f) = dirs_field {
        let items = split_vectors(&f.value);
        if items.len() != 3 {
            return Err(IoError::field(
                path,
                &f.name,
                &f.value,
                format!("expected 3 vectors or `none`, found {}", items.len()),
            ));
        }
        for (axis, item) in items.iter().enumerate() {
            if item.eq_ignore_ascii_case("none") {
                continue;
            }
            let v = parse_vector(path, f, item)?;
            if robust_length(v) == 0.0 {
                return Err(IoError::field(
                    path,
                    &f.name,
                    &f.value,
                    format!("axis {axis} has a zero direction vector"),
                ));
            }
            steps[axis] = Some(v);
        }
    } else {
        for axis in 0..3 {
            if let Some(s) = spacings[axis] {
                let mut e = DVec3::ZERO;
                e[axis] = s;
                steps[axis] = Some(e);
            }
        }
    }

    let mut spacing = [1.0f64; 3];
    let mut cols: [Option<DVec3>; 3] = [None; 3];
    for axis in 0..3 {
        match steps[axis] {
            Some(v) => {
                let len = robust_length(v);
                spacing[axis] = len;
                // Exact for axis-aligned steps: then len == |component| exactly.
                cols[axis] = Some(v / len);
            }
            None => {
                spacing[axis] = spacings[axis].map(f64::abs).unwrap_or(1.0);
            }
        }
    }
    let direction = complete_basis(cols);

    let origin = match fields.get("spaceorigin") {
        Some(f) => parse_vector(path, f, &f.value)?.to_array(),
        None => [0.0; 3],
    };

    Grid::new(dims, spacing, origin, direction).map_err(|e| match (&e, dirs_field) {
        (CoreError::InvalidField { field, .. }, Some(f)) if field == "direction" => IoError::field(
            path,
            &f.name,
            &f.value,
            "axis directions must be mutually orthogonal \
                 (sheared grids are not supported)",
        ),
        (CoreError::InvalidField { field, .. }, _) if field.starts_with("spacing") => {
            let name = dirs_field.or(fields.get("spacings"));
            match name {
                Some(f) => IoError::field(path, &f.name, &f.value, e.to_string()),
                None => IoError::core(path, e),
            }
        }
        _ => IoError::core(path, e),
    })
}

/// The Euclidean length of `v` without overflow or underflow in the squares (spacings of 1e-160
/// or 1e200 round-trip): `m · |v / m|` with `m` the largest component magnitude. Exact for
/// axis-aligned vectors.
fn robust_length(v: DVec3) -> f64 {
    let m = v.abs().max_element();
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    m * (v / m).length()
}

/// Fills missing direction columns: each missing axis `c` gets the first of `e_c, e_{c+1},
/// e_{c+2}` that stays clearly independent after Gram–Schmidt against the columns already set.
fn complete_basis(cols: [Option<DVec3>; 3]) -> DMat3 {
    let mut out = [DVec3::ZERO; 3];
    let mut set = [false; 3];
    for axis in 0..3 {
        if let Some(c) = cols[axis] {
            out[axis] = c;
            set[axis] = true;
        }
    }
    for axis in 0..3 {
        if set[axis] {
            continue;
        }
        let mut chosen = None;
        for k in 0..3 {
            let mut v = DVec3::ZERO;
            v[(axis + k) % 3] = 1.0;
            for other in 0..3 {
                if set[other] {
                    v -= out[other] * out[other].dot(v);
                }
            }
            if v.length() > 0.1 {
                chosen = Some(v.normalize());
                break;
            }
        }
        // Three unit columns always leave one standard axis independent of the others, unless
        // the given ones are degenerate; Grid::new then rejects the matrix.
        out[axis] = chosen.unwrap_or(DVec3::ZERO);
        set[axis] = true;
    }
    DMat3::from_cols(out[0], out[1], out[2])
}

/// Writes `volume` as an attached-header NRRD (`NRRD0004`, little-endian, raw or gzip encoding).
///
/// The header records `space: left-posterior-superior` (volsplat's world frame, docs/design.md §3,
/// so that ITK and 3D Slicer place the volume where volsplat does), `sizes`, `space directions`
/// (column `c` of the
/// direction matrix times `spacing[c]`, world units) and `space origin` (world position of voxel
/// (0,0,0)), so [`read_nrrd`] restores the grid: exactly for axis-aligned directions (including
/// flips and permutations), and to within a few ulps for general rotations (the spacing is
/// recovered as a vector length). Numbers are written in shortest round-trip form. The file is
/// written atomically (temporary file in the same directory, then rename).
pub fn write_nrrd(path: impl AsRef<Path>, volume: &AnyVolume, gzip: bool) -> Result<()> {
    let path = path.as_ref();
    let grid = volume.grid();
    let ft = FileType::from_scalar(volume.scalar_type());
    let vec = |v: DVec3| format!("({:?},{:?},{:?})", v.x, v.y, v.z);
    let cols = grid.world_from_index_linear();
    let header = format!(
        "NRRD0004\n\
         # Written by volsplat-io {version}\n\
         type: {ty}\n\
         dimension: 3\n\
         space: left-posterior-superior\n\
         sizes: {nx} {ny} {nz}\n\
         space directions: {d0} {d1} {d2}\n\
         kinds: domain domain domain\n\
         endian: little\n\
         encoding: {enc}\n\
         space origin: {origin}\n\n",
        version = env!("CARGO_PKG_VERSION"),
        ty = ft.name(),
        nx = grid.dims[0],
        ny = grid.dims[1],
        nz = grid.dims[2],
        d0 = vec(cols.x_axis),
        d1 = vec(cols.y_axis),
        d2 = vec(cols.z_axis),
        enc = if gzip { "gzip" } else { "raw" },
        origin = vec(DVec3::from(grid.origin)),
    );
    write_atomic(path, |w| {
        w.write_all(header.as_bytes()).map_err(write_err(path))?;
        if gzip {
            let mut enc = flate2::write::GzEncoder::new(&mut *w, flate2::Compression::default());
            write_samples_le(&mut enc, volume).map_err(write_err(path))?;
            enc.finish().map_err(write_err(path))?;
        } else {
            write_samples_le(w, volume).map_err(write_err(path))?;
        }
        Ok(())
    })
}

#[cfg(test)]
pub(crate) mod tests;
