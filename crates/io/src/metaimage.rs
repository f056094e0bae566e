//! MetaImage volumes (ITK/VTK `.mha` with the data attached, `.mhd` with a separate data file).
//!
//! # What is read
//!
//! `Key = Value` lines up to and including `ElementDataFile` (keys matched case-insensitively):
//! - `NDims` must be 3; `DimSize` gives the grid dimensions (i fastest).
//! - `ElementType`: `MET_UCHAR`, `MET_CHAR`, `MET_USHORT`, `MET_SHORT`, `MET_FLOAT` as is;
//!   `MET_INT`, `MET_UINT`, `MET_LONG`, `MET_ULONG` (4-byte) and `MET_DOUBLE` **converted to
//!   `f32`**. Others are rejected. `ElementNumberOfChannels` must be 1.
//! - `ElementSpacing` (or `ElementSize` if there is no spacing) gives the spacing, world units;
//!   `Offset` (or `Origin`, `Position`) the world position of voxel (0,0,0);
//!   `TransformMatrix` (or `Rotation`, `Orientation`) nine numbers whose consecutive triples are
//!   the world directions of the i, j and k axes (ITK's convention; columns of
//!   [`volsplat_core::Grid::direction`]), which must be orthonormal.
//!   `AnatomicalOrientation` is ignored: as for NRRD, world space is the file's space as written.
//! - `ElementByteOrderMSB` / `BinaryDataByteOrderMSB` (`True` = big-endian), `BinaryData`
//!   (`False` = decimal text), `CompressedData` (zlib or gzip stream, detected), `HeaderSize`
//!   (bytes to skip in the data file before the samples or the compressed stream; `-1` =
//!   samples at the end of the file, uncompressed only).
//! - `ElementDataFile`: `LOCAL` (data follow the header), or a file name relative to the header's
//!   directory; `LIST` and numbered file patterns are rejected.
//!
//! [`crate::write_metaimage`] writes `.mha` and `.mhd` (+ `.raw` / `.zraw`) as ITK does.
//!
//! Limits as for NRRD: header at most [`crate::MAX_HEADER_BYTES`], voxel count checked against
//! [`volsplat_core::volume::MAX_VOXELS`] before allocating, payload sizes checked.

use crate::confine::Confinement;
use crate::error::{IoError, Result, clip};
use crate::header::{
    Field, Fields, LineAction, normalize_words, parse_finite, parse_numbers, read_header, require,
    resolve_data_path,
};
use crate::limits::{Limits, checked_dims};
use crate::payload::{ByteSkip, Encoding, FileType, PayloadSpec, read_payload};
use crate::{LoadedVolume, ReadOptions};
use std::path::{Path, PathBuf};
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{AnyVolume, CoreError, Grid};

/// Reads a MetaImage volume (`.mha` or `.mhd`) with default [`ReadOptions`]. See the
/// [module documentation](self) for the keys understood, conversions and limits. Errors name
/// the file, the key and its value.
pub fn read_metaimage(path: impl AsRef<Path>) -> Result<AnyVolume> {
    read_metaimage_with(path, &ReadOptions::default()).map(|l| l.volume)
}

/// [`read_metaimage`] with [`ReadOptions`]: its [`Limits`] (header bytes, voxel count,
/// confinement) apply; a MetaImage file holds one volume, so a `frame` other than 0, an
/// `array` or a `series` is an error. The reader has no notes of its own.
pub fn read_metaimage_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let path = path.as_ref();
    options.refuse_all_but_limits(path, "MetaImage")?;
    let volume = read_metaimage_file(path, &options.limits)?;
    Ok(LoadedVolume::single(volume, "MetaImage", Vec::new()))
}

/// Reads a MetaImage file within `limits`.
///
/// The steps: the header's `Key = Value` lines (up to `ElementDataFile`), the grid's size
/// (checked against the voxel limit), the samples' type, byte order and encoding, the grid,
/// `HeaderSize`, where the data lie; then the payload.
fn read_metaimage_file(path: &Path, limits: &Limits) -> Result<AnyVolume> {
    let confine = Confinement::of(path, limits)?;
    let header = read_header(path, limits.max_header_bytes, |_, line| {
        let is_data_file = line
            .split_once('=')
            .is_some_and(|(k, _)| k.trim().eq_ignore_ascii_case("ElementDataFile"));
        if is_data_file {
            LineAction::KeepAndEnd
        } else {
            LineAction::Keep
        }
    })?;
    let fields = parse_fields(path, &header.lines)?;
    if !header.terminated {
        return Err(IoError::missing(path, "ElementDataFile"));
    }
    let dims = parse_dims(path, &fields, limits)?;
    let samples = Samples::parse(path, &fields)?;
    let grid = geometry(path, &fields, dims)?;
    let (header_skip, from_end) = header_size(path, &fields, samples.encoding)?;
    let (data_path, start) = data_location(path, &fields, confine.as_ref(), header.end)?;
    let spec = PayloadSpec {
        data_path: &data_path,
        // MetaIO skips HeaderSize bytes of the file itself, before any decompression.
        start: start.saturating_add(header_skip),
        line_skip: 0,
        byte_skip: if from_end {
            ByteSkip::FromEnd
        } else {
            ByteSkip::Bytes(0)
        },
        skip_field: "HeaderSize",
        encoding: samples.encoding,
        file_type: samples.file_type,
        big_endian: samples.big_endian,
        exact: false,
    };
    read_payload(&spec, grid)
}

/// The header's keys, by lower-case name.
/// The `Key = Value` lines of the header (blank lines and `#` comments skipped); a key given
/// twice is an error naming both lines.
fn parse_fields(path: &Path, lines: &[(usize, String)]) -> Result<Fields> {
    let mut fields = Fields::new();
    for (n, text) in lines {
        let t = text.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let Some((k, v)) = t.split_once('=') else {
            return Err(IoError::Syntax {
                path: path.to_path_buf(),
                line: *n,
                text: clip(text),
                reason: "expected `Key = Value` (is this a MetaImage file? the header must end \
                         with an `ElementDataFile` line)"
                    .into(),
            });
        };
        let name = k.trim().to_string();
        let canon = name.to_ascii_lowercase();
        if let Some(prev) = fields.get(&canon) {
            return Err(IoError::Syntax {
                path: path.to_path_buf(),
                line: *n,
                text: clip(text),
                reason: format!("key `{name}` given twice (first on line {})", prev.line),
            });
        }
        fields.insert(
            canon,
            Field {
                line: *n,
                name,
                value: v.trim().to_string(),
            },
        );
    }
    Ok(fields)
}

/// `ObjectType` (must be `Image` if given), `NDims` (must be 3) and `DimSize`, checked against
/// the voxel limit; `ElementNumberOfChannels` must be 1.
fn parse_dims(path: &Path, fields: &Fields, limits: &Limits) -> Result<[usize; 3]> {
    if let Some(f) = fields.get("objecttype")
        && !f.value.eq_ignore_ascii_case("image")
    {
        return Err(IoError::unsupported(path, &f.name, &f.value, "Image"));
    }
    let nd = require(path, fields, "ndims", "NDims")?;
    if nd.value.trim() != "3" {
        return Err(IoError::field(
            path,
            &nd.name,
            &nd.value,
            "only 3-D volumes are supported (NDims must be 3)",
        ));
    }
    let ds = require(path, fields, "dimsize", "DimSize")?;
    let sizes: [u64; 3] = parse_numbers(path, &ds.name, &ds.value, "a whole number ≥ 1", |t| {
        t.parse::<u64>().ok().filter(|&v| v > 0)
    })?;
    let dims = checked_dims(path, &ds.name, &ds.value, sizes, limits)?;
    if let Some(f) = fields.get("elementnumberofchannels")
        && f.value.trim() != "1"
    {
        return Err(IoError::unsupported(
            path,
            &f.name,
            &f.value,
            "1 (scalar volumes only)",
        ));
    }
    Ok(dims)
}

/// How the samples are stored: `ElementType`, the byte order and the encoding.
struct Samples {
    file_type: FileType,
    /// `ElementByteOrderMSB` (or `BinaryDataByteOrderMSB`) is true.
    big_endian: bool,
    /// Raw, text (`BinaryData = False`) or compressed (`CompressedData = True`).
    encoding: Encoding,
}

impl Samples {
    /// The keys `ElementType`, `ElementByteOrderMSB` / `BinaryDataByteOrderMSB`, `BinaryData`
    /// and `CompressedData`, checked.
    fn parse(path: &Path, fields: &Fields) -> Result<Self> {
        let et = require(path, fields, "elementtype", "ElementType")?;
        let file_type = match et.value.trim().to_ascii_uppercase().as_str() {
            "MET_UCHAR" => FileType::U8,
            "MET_CHAR" => FileType::I8,
            "MET_USHORT" => FileType::U16,
            "MET_SHORT" => FileType::I16,
            "MET_FLOAT" => FileType::F32,
            "MET_INT" | "MET_LONG" => FileType::I32,
            "MET_UINT" | "MET_ULONG" => FileType::U32,
            "MET_DOUBLE" => FileType::F64,
            _ => {
                return Err(IoError::unsupported(
                    path,
                    &et.name,
                    &et.value,
                    "MET_UCHAR, MET_CHAR, MET_USHORT, MET_SHORT, MET_FLOAT; converted to float: \
                     MET_INT, MET_UINT, MET_LONG, MET_ULONG, MET_DOUBLE",
                ));
            }
        };
        let get = |k: &str| fields.get(k);
        let boolean = |f: &Field| -> Result<bool> {
            match normalize_words(&f.value).as_str() {
                "true" | "1" => Ok(true),
                "false" | "0" => Ok(false),
                _ => Err(IoError::field(
                    path,
                    &f.name,
                    &f.value,
                    "must be True or False",
                )),
            }
        };
        let big_endian = match get("elementbyteordermsb").or(get("binarydatabyteordermsb")) {
            Some(f) => boolean(f)?,
            None => false,
        };
        let binary = match get("binarydata") {
            Some(f) => boolean(f)?,
            None => true,
        };
        let compressed = match get("compresseddata") {
            Some(f) => boolean(f)?,
            None => false,
        };
        let encoding = match (binary, compressed) {
            (true, false) => Encoding::Raw,
            (true, true) => Encoding::ZlibOrGzip,
            (false, false) => Encoding::Ascii,
            (false, true) => {
                return Err(IoError::unsupported(
                    path,
                    "CompressedData",
                    "True",
                    "uncompressed text data only (BinaryData = False with CompressedData = True)",
                ));
            }
        };
        Ok(Samples {
            file_type,
            big_endian,
            encoding,
        })
    }
}

/// `HeaderSize`: the bytes of the data file to skip, and whether the samples are the file's
/// last bytes (`-1`, uncompressed binary data only).
fn header_size(path: &Path, fields: &Fields, encoding: Encoding) -> Result<(u64, bool)> {
    let (header_skip, from_end) = match fields.get("headersize") {
        Some(f) => match f.value.trim().parse::<i64>() {
            Ok(-1) => (0u64, true),
            Ok(v) if v >= 0 => (v as u64, false),
            _ => {
                return Err(IoError::field(
                    path,
                    &f.name,
                    &f.value,
                    "must be a whole number ≥ 0, or -1 for data at the end of the file",
                ));
            }
        },
        None => (0, false),
    };
    if from_end && encoding != Encoding::Raw {
        return Err(IoError::field(
            path,
            "HeaderSize",
            "-1",
            "-1 (data at the end of the file) is only allowed for uncompressed binary data",
        ));
    }
    Ok((header_skip, from_end))
}

/// Where the samples lie: after the header (`ElementDataFile = LOCAL`, from `header_end`), or
/// in the named data file beside the header (inside the confinement folder, if any).
fn data_location(
    path: &Path,
    fields: &Fields,
    confine: Option<&Confinement>,
    header_end: u64,
) -> Result<(PathBuf, u64)> {
    let df = require(path, fields, "elementdatafile", "ElementDataFile")?;
    if df.value.eq_ignore_ascii_case("LOCAL") {
        return Ok((path.to_path_buf(), header_end));
    }
    let first = df.value.split_whitespace().next().unwrap_or("");
    if first.eq_ignore_ascii_case("LIST") || df.value.contains('%') || df.value.is_empty() {
        return Err(IoError::unsupported(
            path,
            &df.name,
            &df.value,
            "LOCAL or a single data file name (LIST and file patterns are not supported)",
        ));
    }
    let data = resolve_data_path(path, &df.value);
    if let Some(c) = confine {
        c.check(
            path,
            &format!("field `{}`: data file", df.name),
            &df.value,
            &data,
        )?;
    }
    Ok((data, 0))
}

fn geometry(path: &Path, fields: &Fields, dims: [usize; 3]) -> Result<Grid> {
    let first = |keys: &[&str]| keys.iter().find_map(|k| fields.get(*k));
    let spacing = match first(&["elementspacing", "elementsize"]) {
        Some(f) => parse_numbers(path, &f.name, &f.value, "a positive finite number", |t| {
            parse_finite(t).filter(|&v| v > 0.0)
        })?,
        None => [1.0; 3],
    };
    let origin = match first(&["offset", "origin", "position"]) {
        Some(f) => parse_numbers(path, &f.name, &f.value, "a finite number", parse_finite)?,
        None => [0.0; 3],
    };
    let matrix = first(&["transformmatrix", "rotation", "orientation"]);
    let direction = match matrix {
        Some(f) => {
            let m: [f64; 9] =
                parse_numbers(path, &f.name, &f.value, "a finite number", parse_finite)?;
            DMat3::from_cols(
                DVec3::new(m[0], m[1], m[2]),
                DVec3::new(m[3], m[4], m[5]),
                DVec3::new(m[6], m[7], m[8]),
            )
        }
        None => DMat3::IDENTITY,
    };
    Grid::new(dims, spacing, origin, direction).map_err(|e| match (&e, matrix) {
        (CoreError::InvalidField { field, .. }, Some(f)) if field == "direction" => IoError::field(
            path,
            &f.name,
            &f.value,
            "axis directions must be orthonormal (sheared grids are not supported)",
        ),
        _ => IoError::core(path, e),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;
    use volsplat_core::{ScalarType, Volume};

    fn file(dir: &Path, name: &str, header: &str, data: &[u8]) -> PathBuf {
        let p = dir.join(name);
        let mut bytes = header.as_bytes().to_vec();
        bytes.extend_from_slice(data);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn zlib(data: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    const BASE: &str = "ObjectType = Image\nNDims = 3\nDimSize = 2 3 2\nElementType = MET_SHORT\n";

    fn expected() -> (Vec<i16>, Vec<u8>, Vec<u8>) {
        let v: Vec<i16> = (0..12).map(|i| i * 300 - 1500).collect();
        let le = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        let be = v.iter().flat_map(|x| x.to_be_bytes()).collect();
        (v, le, be)
    }

    #[test]
    fn reads_local_detached_compressed_and_oriented() {
        let dir = tempfile::tempdir().unwrap();
        let (v, le, be) = expected();
        let h = format!(
            "{BASE}BinaryData = True\nBinaryDataByteOrderMSB = False\n\
             ElementSpacing = 0.5 1 2\nOffset = 1 2 3\n\
             TransformMatrix = 0 1 0 -1 0 0 0 0 1\nElementDataFile = LOCAL\n"
        );
        let vol = read_metaimage(file(dir.path(), "a.mha", &h, &le)).unwrap();
        let g = vol.grid();
        assert_eq!(g.spacing, [0.5, 1.0, 2.0]);
        assert_eq!(g.origin, [1.0, 2.0, 3.0]);
        assert_eq!(g.direction, DMat3::from_cols(DVec3::Y, -DVec3::X, DVec3::Z));
        let expect_grid = g.clone();
        let expect: AnyVolume = Volume::new(expect_grid.clone(), v.clone()).unwrap().into();
        assert_eq!(vol, expect);

        // Big-endian, zlib-compressed, attached.
        let h2 = h
            .replace("ByteOrderMSB = False", "ByteOrderMSB = True")
            .replace(
                "BinaryData = True\n",
                "BinaryData = True\nCompressedData = True\n",
            );
        let vol = crate::read_volume(file(dir.path(), "b.mha", &h2, &zlib(&be))).unwrap();
        assert_eq!(vol, expect);

        // Detached data file with HeaderSize, and with HeaderSize = -1.
        let mut raw = vec![9u8; 5];
        raw.extend_from_slice(&le);
        std::fs::write(dir.path().join("c.raw"), &raw).unwrap();
        for hs in ["5", "-1"] {
            let h3 = h.replace(
                "ElementDataFile = LOCAL",
                &format!("HeaderSize = {hs}\nElementDataFile = c.raw"),
            );
            let vol = crate::read_volume(file(dir.path(), "c.mhd", &h3, b"")).unwrap();
            assert_eq!(vol, expect, "HeaderSize {hs}");
        }

        // Text data; MET_DOUBLE converted to f32.
        let h4 = "NDims = 3\nDimSize = 2 1 1\nElementType = MET_DOUBLE\nBinaryData = False\n\
                  ElementDataFile = LOCAL\n";
        let vol = read_metaimage(file(dir.path(), "d.mha", h4, b"1.5 -2\n")).unwrap();
        assert_eq!(vol.scalar_type(), ScalarType::F32);
        assert_eq!(vol.to_f32().data(), &[1.5, -2.0]);
    }

    /// Fuzzing regression (issue 13): overflowing `DimSize` products were accepted.
    #[test]
    fn overflowing_dimsize_is_an_error_naming_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let h = "NDims = 3\nDimSize = 9223372036854775808 9223372036854775808 4\n\
                 ElementType = MET_UCHAR\nElementDataFile = LOCAL\n";
        let e = read_metaimage(file(dir.path(), "o.mha", h, &[0; 8]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`DimSize`") && e.contains("exceeds the limit"),
            "{e}"
        );
    }

    #[test]
    #[cfg(unix)]
    fn device_data_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let h =
            "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = /dev/zero\n";
        let e = read_metaimage(file(dir.path(), "d.mhd", h, b""))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/dev/zero") && e.contains("not a regular file"),
            "{e}"
        );
    }

    #[test]
    fn errors_name_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let (_, le, _) = expected();
        let ok = format!("{BASE}ElementDataFile = LOCAL\n");
        assert!(read_metaimage(file(dir.path(), "ok.mha", &ok, &le)).is_ok());
        let cases: Vec<(String, &str)> = vec![
            (ok.replace("NDims = 3", "NDims = 2"), "`NDims`"),
            (
                ok.replace("NDims = 3\n", ""),
                "missing required field `NDims`",
            ),
            (ok.replace("DimSize = 2 3 2\n", ""), "`DimSize`"),
            (
                ok.replace("DimSize = 2 3 2", "DimSize = 2 x 2"),
                "`DimSize`",
            ),
            (
                ok.replace("DimSize = 2 3 2", "DimSize = 100000 100000 100000"),
                "exceeds the limit",
            ),
            (ok.replace("MET_SHORT", "MET_LONG_LONG"), "`ElementType`"),
            (ok.replace("ElementType = MET_SHORT\n", ""), "`ElementType`"),
            (
                ok.replace("ElementDataFile = LOCAL", "ElementDataFile = LIST"),
                "`ElementDataFile`",
            ),
            (
                ok.replace(
                    "ElementDataFile = LOCAL",
                    "ElementDataFile = s%03d.raw 1 5 1",
                ),
                "`ElementDataFile`",
            ),
            (
                ok.replace("ElementDataFile = LOCAL\n", ""),
                "`ElementDataFile`",
            ),
            (format!("ElementSpacing = 1 0 1\n{ok}"), "`ElementSpacing`"),
            (format!("Offset = 1 2\n{ok}"), "`Offset`"),
            (
                format!("TransformMatrix = 1 0 0 1 1 0 0 0 1\n{ok}"),
                "`TransformMatrix`",
            ),
            (format!("CompressedData = maybe\n{ok}"), "`CompressedData`"),
            (
                format!("ElementNumberOfChannels = 3\n{ok}"),
                "`ElementNumberOfChannels`",
            ),
            (format!("ObjectType = Mesh\n{}", &ok[19..]), "`ObjectType`"),
            (format!("just some words\n{ok}"), "line 1"),
            (
                format!("CompressedData = True\nHeaderSize = -1\n{ok}"),
                "`HeaderSize`",
            ),
        ];
        for (h, want) in &cases {
            let p = file(dir.path(), "bad.mha", h, &le);
            let e = read_metaimage(&p).unwrap_err().to_string();
            assert!(
                e.contains(want) && e.contains("bad.mha"),
                "want {want:?} in: {e}"
            );
        }
        // Truncated raw and compressed payloads.
        let p = file(dir.path(), "bad.mha", &ok, &le[..20]);
        let e = read_metaimage(&p).unwrap_err().to_string();
        assert!(e.contains("expected 24 bytes, found 20"), "{e}");
        let h = format!("CompressedData = True\n{ok}");
        let p = file(dir.path(), "bad.mha", &h, &zlib(&le[..20]));
        let e = read_metaimage(&p).unwrap_err().to_string();
        assert!(e.contains("expected 24 bytes, found 20"), "{e}");
    }
}

#[cfg(test)]
mod confinement {
    use super::*;
    use crate::confine::tests::{assert_outside, layout};

    /// Issue 29 item 5: a `.mhd` in a folder the read is confined to cannot read a data file
    /// outside it.
    #[test]
    fn confined_reads_refuse_data_files_outside_the_folder() {
        let l = layout(&[1, 2, 3, 4]);
        let secret = l.secret.display().to_string();
        let mut cases = vec![
            ("inside.raw", true),
            ("../secret.raw", false),
            (secret.as_str(), false),
        ];
        if cfg!(unix) {
            cases.push(("link.raw", false));
        }
        for (value, inside) in cases {
            let p = l.data.join("escape.mhd");
            std::fs::write(
                &p,
                format!(
                    "ObjectType = Image\nNDims = 3\nDimSize = 2 2 1\nElementType = MET_UCHAR\n\
                     ElementDataFile = {value}\n"
                ),
            )
            .unwrap();
            let v = read_metaimage(&p).unwrap_or_else(|e| panic!("{value}: {e}"));
            assert_eq!(v.to_f32().data(), &[1.0, 2.0, 3.0, 4.0], "{value}");
            let r = read_metaimage_with(&p, &ReadOptions::default().with_limits(l.limits.clone()))
                .map(|l| l.volume);
            if inside {
                assert_eq!(r.unwrap().to_f32().data(), &[1.0, 2.0, 3.0, 4.0], "{value}");
            } else {
                let e = r.unwrap_err();
                assert_outside(&e, "escape.mhd", "`ElementDataFile`", value, &l);
            }
        }
    }
}
