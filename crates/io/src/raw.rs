//! Headerless raw volumes: the caller describes the layout with a [`RawSpec`].

use crate::error::{IoError, Result};
use crate::limits::{Limits, checked_voxel_count};
use crate::payload::{ByteSkip, Encoding, FileType, PayloadSpec, read_payload};
use crate::{LoadedVolume, ReadOptions};
use std::path::Path;
use volsplat_core::glam::DMat3;
use volsplat_core::{AnyVolume, Grid, ScalarType};

/// The layout of a headerless raw volume file. Samples are stored i fastest, then j, then k, with
/// no padding; the grid is axis-aligned (identity direction).
#[derive(Debug, Clone, PartialEq)]
pub struct RawSpec {
    /// Number of samples along i, j, k (each ≥ 1).
    pub dims: [usize; 3],
    /// The sample type as stored.
    pub scalar_type: ScalarType,
    /// Distance between neighbouring samples along i, j, k, world units (each > 0).
    pub spacing: [f64; 3],
    /// World position of the centre of voxel (0,0,0), world units.
    pub origin: [f64; 3],
    /// `true` if multi-byte samples are big-endian (most significant byte first).
    pub big_endian: bool,
    /// Bytes to skip at the start of the file (of the decompressed stream for `.gz` files).
    pub header_bytes: u64,
}

impl RawSpec {
    /// A spec with unit spacing, zero origin, little-endian samples and no header.
    pub fn new(dims: [usize; 3], scalar_type: ScalarType) -> Self {
        RawSpec {
            dims,
            scalar_type,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            big_endian: false,
            header_bytes: 0,
        }
    }
}

/// Reads a headerless raw volume laid out as `spec` says.
///
/// The file's size must be exactly `header_bytes + dims.x·dims.y·dims.z·sample size`; any other
/// size is an error stating both numbers. Files whose name ends in `.gz` (any case) are
/// decompressed as gzip, and the *decompressed* size must match the same way (the stream is never
/// inflated past that size plus one byte). The voxel count is checked against
/// [`volsplat_core::volume::MAX_VOXELS`] and the grid validated before any sample memory is
/// allocated.
pub fn read_raw(path: impl AsRef<Path>, spec: &RawSpec) -> Result<AnyVolume> {
    read_raw_with(path, spec, &ReadOptions::default()).map(|l| l.volume)
}

/// [`read_raw`] with [`ReadOptions`]: its [`Limits`] (voxel count,
/// confinement) apply; a raw file holds one volume, so a `frame` other than 0, an `array` or a
/// `series` is an error. The result's format is `raw`, with no notes.
///
/// The layout `spec` is an argument of its own, before the options, rather than a field of
/// [`ReadOptions`]: no raw file can be read without it, and every field of [`ReadOptions`] has
/// a default that suits every reader (decision 0034).
pub fn read_raw_with(
    path: impl AsRef<Path>,
    spec: &RawSpec,
    options: &ReadOptions,
) -> Result<LoadedVolume> {
    let path = path.as_ref();
    options.refuse_all_but_limits(path, "raw")?;
    let volume = read_raw_file(path, spec, &options.limits)?;
    Ok(LoadedVolume::single(volume, "raw", Vec::new()))
}

/// Reads a raw file laid out as `spec` says, within `limits`.
fn read_raw_file(path: &Path, spec: &RawSpec, limits: &Limits) -> Result<AnyVolume> {
    let (payload, grid) = raw_payload(path, spec, limits)?;
    read_payload(&payload, grid)
}

/// The headerless raw file at `path` opened for reading one z slice at a time (`convert -o
/// X.zarr`), with its grid; `None` for a gzipped file (read it whole).
pub(crate) fn raw_slices(
    path: &Path,
    spec: &RawSpec,
    options: &ReadOptions,
) -> Result<Option<(crate::payload::RawSlices, Grid)>> {
    options.refuse_all_but_limits(path, "raw")?;
    let (payload, grid) = raw_payload(path, spec, &options.limits)?;
    if payload.encoding != Encoding::Raw {
        return Ok(None);
    }
    Ok(Some((
        crate::payload::RawSlices::open(&payload, &grid)?,
        grid,
    )))
}

/// The payload of a headerless raw file and its grid, checked.
fn raw_payload<'a>(
    path: &'a Path,
    spec: &RawSpec,
    limits: &Limits,
) -> Result<(PayloadSpec<'a>, Grid)> {
    crate::confine::Confinement::of(path, limits)?;
    let dims_text = format!("{:?}", spec.dims);
    checked_voxel_count(
        path,
        "dims",
        &dims_text,
        &spec.dims.map(|d| d as u64),
        limits,
    )?;
    let grid = Grid::new(spec.dims, spec.spacing, spec.origin, DMat3::IDENTITY)
        .map_err(|e| IoError::core(path, e))?;
    let gz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    let payload = PayloadSpec {
        data_path: path,
        start: 0,
        line_skip: 0,
        byte_skip: ByteSkip::Bytes(spec.header_bytes),
        skip_field: "header_bytes",
        encoding: if gz { Encoding::Gzip } else { Encoding::Raw },
        file_type: FileType::from_scalar(spec.scalar_type),
        big_endian: spec.big_endian,
        exact: true,
    };
    Ok((payload, grid))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;
    use volsplat_core::Volume;

    fn gz(data: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    #[test]
    fn every_type_both_endians_with_header_and_gzip() {
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::new(
            [3, 2, 2],
            [0.5, 1.0, 2.5],
            [1.0, -2.0, 3.0],
            DMat3::IDENTITY,
        )
        .unwrap();
        let vals: Vec<f64> = (0..12).map(|i| i as f64 * 3.0 - 11.0).collect();
        for st in [
            ScalarType::U8,
            ScalarType::I8,
            ScalarType::U16,
            ScalarType::I16,
            ScalarType::F32,
        ] {
            for big in [false, true] {
                let mut bytes = vec![0xEE; 7]; // header
                let expect: AnyVolume = match st {
                    ScalarType::U8 => {
                        let v: Vec<u8> = vals.iter().map(|&x| (x + 11.0) as u8).collect();
                        bytes.extend(&v);
                        Volume::new(grid.clone(), v).unwrap().into()
                    }
                    ScalarType::I8 => {
                        let v: Vec<i8> = vals.iter().map(|&x| x as i8).collect();
                        bytes.extend(v.iter().map(|&x| x as u8));
                        Volume::new(grid.clone(), v).unwrap().into()
                    }
                    ScalarType::U16 => {
                        let v: Vec<u16> =
                            vals.iter().map(|&x| (x * 100.0 + 5000.0) as u16).collect();
                        for x in &v {
                            bytes.extend(if big {
                                x.to_be_bytes()
                            } else {
                                x.to_le_bytes()
                            });
                        }
                        Volume::new(grid.clone(), v).unwrap().into()
                    }
                    ScalarType::I16 => {
                        let v: Vec<i16> = vals.iter().map(|&x| (x * 100.0) as i16).collect();
                        for x in &v {
                            bytes.extend(if big {
                                x.to_be_bytes()
                            } else {
                                x.to_le_bytes()
                            });
                        }
                        Volume::new(grid.clone(), v).unwrap().into()
                    }
                    ScalarType::F32 => {
                        let v: Vec<f32> = vals.iter().map(|&x| x as f32 * 0.1).collect();
                        for x in &v {
                            bytes.extend(if big {
                                x.to_be_bytes()
                            } else {
                                x.to_le_bytes()
                            });
                        }
                        Volume::new(grid.clone(), v).unwrap().into()
                    }
                };
                let spec = RawSpec {
                    dims: [3, 2, 2],
                    scalar_type: st,
                    spacing: [0.5, 1.0, 2.5],
                    origin: [1.0, -2.0, 3.0],
                    big_endian: big,
                    header_bytes: 7,
                };
                let p = dir.path().join("v.raw");
                std::fs::write(&p, &bytes).unwrap();
                assert_eq!(read_raw(&p, &spec).unwrap(), expect, "{st:?} big={big}");
                let p = dir.path().join("v.raw.GZ");
                std::fs::write(&p, gz(&bytes)).unwrap();
                assert_eq!(read_raw(&p, &spec).unwrap(), expect, "{st:?} big={big} gz");
            }
        }
    }

    #[test]
    fn size_must_match_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let mut spec = RawSpec::new([4, 4, 4], ScalarType::U16);
        spec.header_bytes = 10;
        let p = dir.path().join("v.raw");
        for (len, want) in [
            (
                137,
                "expected 138 bytes (10 header bytes + 128 sample bytes), found 137",
            ),
            (
                139,
                "expected 138 bytes (10 header bytes + 128 sample bytes), found 139",
            ),
            (5, "expected 138 bytes"),
        ] {
            std::fs::write(&p, vec![0u8; len]).unwrap();
            let e = read_raw(&p, &spec).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains("v.raw"), "{e}");
        }
        std::fs::write(&p, vec![0u8; 138]).unwrap();
        assert!(read_raw(&p, &spec).is_ok());

        let p = dir.path().join("v.raw.gz");
        std::fs::write(&p, gz(&[0u8; 137])).unwrap();
        let e = read_raw(&p, &spec).unwrap_err().to_string();
        assert!(e.contains("expected 128 bytes, found 127"), "{e}");
        std::fs::write(&p, gz(&[0u8; 139])).unwrap();
        let e = read_raw(&p, &spec).unwrap_err().to_string();
        assert!(
            e.contains("expected 138 bytes") && e.contains("found 139"),
            "{e}"
        );
        std::fs::write(&p, gz(&[0u8; 5])).unwrap();
        let e = read_raw(&p, &spec).unwrap_err().to_string();
        assert!(e.contains("header_bytes") && e.contains("truncated"), "{e}");
        let z = gz(&[3u8; 138]);
        std::fs::write(&p, &z[..z.len() / 2]).unwrap();
        assert!(read_raw(&p, &spec).is_err());
    }

    #[test]
    fn invalid_specs_are_rejected_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.raw");
        std::fs::write(&p, [0u8; 8]).unwrap();
        let mut spec = RawSpec::new([2, 2, 2], ScalarType::U8);
        spec.spacing[1] = -1.0;
        let e = read_raw(&p, &spec).unwrap_err().to_string();
        assert!(e.contains("spacing[1]") && e.contains("v.raw"), "{e}");
        let spec = RawSpec::new([100_000, 100_000, 100_000], ScalarType::F32);
        let e = read_raw(&p, &spec).unwrap_err().to_string();
        assert!(e.contains("exceeds the limit"), "{e}");
        // Fuzzing regression (issue 13): dims whose product overflows even u128.
        let spec = RawSpec::new([1 << 63, 1 << 63, 4], ScalarType::U8);
        let small = Limits {
            max_voxels: 7,
            ..Limits::default()
        };
        let spec2 = RawSpec::new([2, 2, 2], ScalarType::U8);
        let small = ReadOptions::default().with_limits(small);
        let e = read_raw_with(&p, &spec2, &small).unwrap_err().to_string();
        assert!(e.contains("exceeds the limit 7"), "{e}");
        let e = read_raw(&p, &spec).unwrap_err().to_string();
        assert!(
            e.contains("`dims`") && e.contains("exceeds the limit"),
            "{e}"
        );
        let spec = RawSpec::new([usize::MAX; 3], ScalarType::F32);
        assert!(read_raw(&p, &spec).is_err());
        let spec = RawSpec::new([2048, 2048, 2048], ScalarType::U8);
        let e = read_raw(&p, &spec).unwrap_err().to_string();
        assert!(e.contains("expected 8589934592 bytes"), "{e}");
        let spec = RawSpec::new([0, 2, 2], ScalarType::U8);
        assert!(
            read_raw(&p, &spec)
                .unwrap_err()
                .to_string()
                .contains("dims[0]")
        );
        let spec = RawSpec::new([2, 2, 2], ScalarType::U8);
        let e = read_raw(dir.path().join("none.raw"), &spec).unwrap_err();
        assert!(e.to_string().contains("none.raw"), "{e}");
    }
}
