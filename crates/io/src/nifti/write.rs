//! Writing single-file NIfTI-1 volumes (`.nii`, `.nii.gz`): [`write_nifti`].
//!
//! The header is built field by field at the offsets of `nifti1.h` (as the reader parses it,
//! decision 0009); the geometry is written twice, as the `sform` and as the `qform`, both
//! `NIFTI_XFORM_SCANNER_ANAT` (code 1, what ITK writes), so that nibabel's `img.affine`,
//! `get_sform()` and `get_qform()` agree and every reader finds the same grid.

use super::has_suffix;
use crate::atomic::{write_atomic, write_err};
use crate::error::{IoError, Result};
use crate::payload::write_samples_le;
use std::io::Write;
use std::path::Path;
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{AnyVolume, Grid, ScalarType};

/// `NIFTI_XFORM_SCANNER_ANAT`: world coordinates in the scanner's frame (RAS+ in the file).
const XFORM_SCANNER_ANAT: i16 = 1;
/// `NIFTI_UNITS_MM`.
const UNITS_MM: u8 = 2;
/// The samples start after the 348-byte header and the 4-byte extension flag.
const VOX_OFFSET: usize = 352;

/// Writes `volume` as a single-file NIfTI-1, gzip-compressed when `gzip` (name it `.nii.gz`;
/// a `.nii.gz` path is always compressed). Atomic (a temporary file renamed over `path`).
///
/// - **Samples**: little-endian, in their own type: `datatype` 2 (uint8), 256 (int8),
///   512 (uint16), 4 (int16) or 16 (float32); `scl_slope` 1, `scl_inter` 0 (no scaling).
/// - **Geometry**: volsplat's world frame is LPS (docs/design.md §3, decision 0008) and NIfTI's is
///   RAS+, so x and y are negated: the affine is `diag(−1, −1, 1)·[D·diag(spacing) | origin]`.
///   It is written as the `sform` (`srow_x/y/z`, code 1) and as the `qform` (code 1):
///   `pixdim[1..=3]` the spacing, `qoffset` the origin, and the quaternion of the rotation
///   part; an improper direction (a reflection, determinant −1) is written with `qfac`
///   (`pixdim[0]`) = −1 and the third column negated, as `nifti_mat44_to_quatern` does.
///   NIfTI-1 stores these as float32, so they are rounded to float32 (the caller may note it:
///   [`float32_rounding`]).
/// - `xyzt_units` = mm (as ITK writes; volsplat keeps the world units of the file it read).
///
/// Errors: a grid axis longer than 32767 samples (NIfTI-1's `dim` is 16-bit), or geometry
/// outside the float32 range, are [`IoError::InvalidArgument`] naming the value.
pub fn write_nifti(path: impl AsRef<Path>, volume: &AnyVolume, gzip: bool) -> Result<()> {
    let path = path.as_ref();
    let header = header_bytes(path, volume.grid(), volume.scalar_type())?;
    let gzip = gzip || has_suffix(path, ".gz");
    write_atomic(path, |w| {
        if gzip {
            let mut enc = flate2::write::GzEncoder::new(&mut *w, flate2::Compression::default());
            enc.write_all(&header).map_err(write_err(path))?;
            write_samples_le(&mut enc, volume).map_err(write_err(path))?;
            enc.finish().map_err(write_err(path))?;
        } else {
            w.write_all(&header).map_err(write_err(path))?;
            write_samples_le(w, volume).map_err(write_err(path))?;
        }
        Ok(())
    })
}

/// The largest change (world units, and for the direction unitless) that rounding the grid's
/// spacing, origin and RAS affine to float32 makes; 0 when they are float32 numbers already.
pub fn float32_rounding(grid: &Grid) -> f64 {
    let (affine, origin) = ras_affine(grid);
    let round = |v: f64| (v - v as f32 as f64).abs();
    let mut worst: f64 = 0.0;
    for v in affine
        .to_cols_array()
        .iter()
        .chain(&origin.to_array())
        .chain(&grid.spacing)
    {
        worst = worst.max(round(*v));
    }
    worst
}

/// The RAS affine's linear part `diag(−1, −1, 1)·D·diag(spacing)` and its translation.
fn ras_affine(grid: &Grid) -> (DMat3, DVec3) {
    let f = DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0));
    (
        f * grid.world_from_index_linear(),
        f * DVec3::from(grid.origin),
    )
}

/// `(datatype, bitpix)` of a sample type.
fn datatype(t: ScalarType) -> (i16, i16) {
    match t {
        ScalarType::U8 => (2, 8),
        ScalarType::I8 => (256, 8),
        ScalarType::U16 => (512, 16),
        ScalarType::I16 => (4, 16),
        ScalarType::F32 => (16, 32),
    }
}

/// The quaternion `(b, c, d)` and `qfac` of an orthonormal matrix `r` (nifti1_io.c,
/// `nifti_mat44_to_quatern`): a negative determinant gives `qfac = −1` with the third column
/// negated; the quaternion is that of the remaining rotation, with `a ≥ 0`.
pub(super) fn quaternion(r: DMat3) -> ([f64; 3], f64) {
    let (qfac, r) = if r.determinant() > 0.0 {
        (1.0, r)
    } else {
        (-1.0, DMat3::from_cols(r.x_axis, r.y_axis, -r.z_axis))
    };
    // r_ij: row i, column j (1-based, as in nifti1_io.c).
    let e = |i: usize, j: usize| r.col(j - 1)[i - 1];
    let (r11, r12, r13) = (e(1, 1), e(1, 2), e(1, 3));
    let (r21, r22, r23) = (e(2, 1), e(2, 2), e(2, 3));
    let (r31, r32, r33) = (e(3, 1), e(3, 2), e(3, 3));
    let trace1 = r11 + r22 + r33 + 1.0;
    let (a, mut b, mut c, mut d): (f64, f64, f64, f64);
    if trace1 > 0.5 {
        a = 0.5 * trace1.sqrt();
        b = 0.25 * (r32 - r23) / a;
        c = 0.25 * (r13 - r31) / a;
        d = 0.25 * (r21 - r12) / a;
    } else {
        let xd = 1.0 + r11 - (r22 + r33);
        let yd = 1.0 + r22 - (r11 + r33);
        let zd = 1.0 + r33 - (r11 + r22);
        if xd > 1.0 {
            b = 0.5 * xd.sqrt();
            c = 0.25 * (r12 + r21) / b;
            d = 0.25 * (r13 + r31) / b;
            a = 0.25 * (r32 - r23) / b;
        } else if yd > 1.0 {
            c = 0.5 * yd.sqrt();
            b = 0.25 * (r12 + r21) / c;
            d = 0.25 * (r23 + r32) / c;
            a = 0.25 * (r13 - r31) / c;
        } else {
            d = 0.5 * zd.sqrt();
            b = 0.25 * (r13 + r31) / d;
            c = 0.25 * (r23 + r32) / d;
            a = 0.25 * (r21 - r12) / d;
        }
        if a < 0.0 {
            (b, c, d) = (-b, -c, -d);
        }
    }
    ([b, c, d], qfac)
}

/// `(b, c, d)` as the float32 numbers to store. For a half turn (`a = 0`: the rotations that
/// flip two axes, such as LPS → RAS itself) the rounded components could leave
/// `1 − (b² + c² + d²)` a little above 0, and readers that take `a = √(1 − …)` (nibabel's
/// `fillpositive`) would find `a ≈ 2·10⁻⁴` and a qform off the sform by as much; the largest
/// component is then rounded away from 0 until the sum reaches 1 (readers treat a slightly
/// negative `1 − …` as `a = 0`: nibabel within 3 float32 epsilons, nifti1_io below 10⁻⁷).
fn storable_quaternion(q: [f64; 3]) -> [f32; 3] {
    let mut out = q.map(|v| v as f32);
    let sum = |o: &[f32; 3]| o.iter().map(|&v| v as f64 * v as f64).sum::<f64>();
    let a2 = 1.0 - q.iter().map(|v| v * v).sum::<f64>();
    if a2 > 1e-12 {
        return out;
    }
    let big = (0..3)
        .max_by(|&i, &j| out[i].abs().total_cmp(&out[j].abs()))
        .unwrap_or(0);
    for _ in 0..8 {
        if sum(&out) >= 1.0 {
            break;
        }
        let v = out[big];
        out[big] = f32::from_bits(v.to_bits() + 1).copysign(v);
    }
    out
}

/// The 352 bytes before the samples: the NIfTI-1 header and a zero extension flag.
fn header_bytes(path: &Path, grid: &Grid, t: ScalarType) -> Result<Vec<u8>> {
    for (a, &n) in grid.dims.iter().enumerate() {
        if n > i16::MAX as usize {
            return Err(IoError::invalid_argument(
                path,
                "volume size",
                format!(
                    "axis {a} has {n} samples; NIfTI-1 allows at most 32767 per axis \
                     (write .nrrd or .mha instead)"
                ),
            ));
        }
    }
    let (linear, origin) = ras_affine(grid);
    let (quat, qfac) =
        quaternion(DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)) * grid.direction);
    let mut b = vec![0u8; VOX_OFFSET];
    let f32_at = |b: &mut Vec<u8>, at: usize, name: &str, v: f64| -> Result<()> {
        let x = v as f32;
        if !x.is_finite() {
            return Err(IoError::invalid_argument(
                path,
                "volume geometry",
                format!("{name} = {v:e} is outside the float32 range NIfTI-1 stores"),
            ));
        }
        b[at..at + 4].copy_from_slice(&x.to_le_bytes());
        Ok(())
    };
    let i16_at =
        |b: &mut Vec<u8>, at: usize, v: i16| b[at..at + 2].copy_from_slice(&v.to_le_bytes());
    b[0..4].copy_from_slice(&348i32.to_le_bytes());
    let dims = [
        3,
        grid.dims[0] as i16,
        grid.dims[1] as i16,
        grid.dims[2] as i16,
        1,
        1,
        1,
        1,
    ];
    for (k, &d) in dims.iter().enumerate() {
        i16_at(&mut b, 40 + 2 * k, d);
    }
    let (code, bitpix) = datatype(t);
    i16_at(&mut b, 70, code);
    i16_at(&mut b, 72, bitpix);
    let pixdim = [
        qfac,
        grid.spacing[0],
        grid.spacing[1],
        grid.spacing[2],
        1.0,
        1.0,
        1.0,
        1.0,
    ];
    for (k, &p) in pixdim.iter().enumerate() {
        f32_at(&mut b, 76 + 4 * k, &format!("pixdim[{k}]"), p)?;
    }
    f32_at(&mut b, 108, "vox_offset", VOX_OFFSET as f64)?;
    f32_at(&mut b, 112, "scl_slope", 1.0)?;
    b[123] = UNITS_MM;
    let descrip = format!("volsplat-io {}", env!("CARGO_PKG_VERSION"));
    let n = descrip.len().min(79);
    b[148..148 + n].copy_from_slice(&descrip.as_bytes()[..n]);
    i16_at(&mut b, 252, XFORM_SCANNER_ANAT);
    i16_at(&mut b, 254, XFORM_SCANNER_ANAT);
    for (k, &q) in storable_quaternion(quat).iter().enumerate() {
        f32_at(&mut b, 256 + 4 * k, "quatern_b/c/d", q as f64)?;
    }
    for (k, &o) in origin.to_array().iter().enumerate() {
        f32_at(&mut b, 268 + 4 * k, "qoffset (origin)", o)?;
    }
    for r in 0..3 {
        for c in 0..3 {
            f32_at(
                &mut b,
                280 + 16 * r + 4 * c,
                "srow (spacing × direction)",
                linear.col(c)[r],
            )?;
        }
        f32_at(&mut b, 280 + 16 * r + 12, "srow (origin)", origin[r])?;
    }
    b[344..348].copy_from_slice(b"n+1\0");
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ReadOptions;

    /// The reader's quaternion → matrix (nifti1_io.c `nifti_quatern_to_mat44`: `a² < 1e-7`
    /// is a 180° turn, `a = 0` with `(b, c, d)` normalised), for checking.
    fn rotation(q: [f64; 3], qfac: f64) -> DMat3 {
        let [mut b, mut c, mut d] = q;
        let a2 = 1.0 - (b * b + c * c + d * d);
        let a = if a2 < 1e-7 {
            let s = (b * b + c * c + d * d).sqrt();
            (b, c, d) = (b / s, c / s, d / s);
            0.0
        } else {
            a2.sqrt()
        };
        let r = DMat3::from_cols(
            DVec3::new(
                a * a + b * b - c * c - d * d,
                2.0 * (b * c + a * d),
                2.0 * (b * d - a * c),
            ),
            DVec3::new(
                2.0 * (b * c - a * d),
                a * a + c * c - b * b - d * d,
                2.0 * (c * d + a * b),
            ),
            DVec3::new(
                2.0 * (b * d + a * c),
                2.0 * (c * d - a * b),
                a * a + d * d - c * c - b * b,
            ),
        );
        r * DMat3::from_diagonal(DVec3::new(1.0, 1.0, qfac))
    }

    fn rot(axis: DVec3, degrees: f64) -> DMat3 {
        DMat3::from_axis_angle(axis.normalize(), degrees.to_radians())
    }

    /// Rotations and reflections of every kind, including the near-180° turns that take the
    /// "trickier" branches of `nifti_mat44_to_quatern`: the quaternion reproduces the matrix.
    #[test]
    fn quaternion_reproduces_every_orthonormal_matrix() {
        let flip = |m: DMat3, c: usize| {
            let mut cols = [m.x_axis, m.y_axis, m.z_axis];
            cols[c] = -cols[c];
            DMat3::from_cols(cols[0], cols[1], cols[2])
        };
        let mut cases = vec![
            DMat3::IDENTITY,
            DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)),
            DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)),
            DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)),
            DMat3::from_cols(DVec3::Y, DVec3::Z, DVec3::X),
            DMat3::from_cols(DVec3::Z, -DVec3::X, -DVec3::Y),
        ];
        for (axis, deg) in [
            (DVec3::X, 180.0),
            (DVec3::Y, 180.0),
            (DVec3::Z, 180.0),
            (DVec3::new(1.0, 1.0, 0.0), 180.0),
            (DVec3::new(1.0, 2.0, 3.0), 179.0),
            (DVec3::new(-1.0, 0.5, 0.2), 30.0),
            (DVec3::new(0.3, -0.2, 1.0), 100.0),
        ] {
            let r = rot(axis, deg);
            cases.push(r);
            cases.push(flip(r, 0));
            cases.push(flip(r, 2));
        }
        for m in cases {
            let (q, qfac) = quaternion(m);
            assert_eq!(qfac, m.determinant().signum(), "{m}");
            let back = rotation(q, qfac);
            let err = (back - m)
                .to_cols_array()
                .iter()
                .map(|v| v.abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-12, "{m} -> {q:?} {qfac} -> {back} ({err})");
        }
    }

    /// Half turns keep `a = 0` after rounding to float32: `1 − (b² + c² + d²)` of the stored
    /// numbers is at most 0 and above nibabel's threshold (−3 float32 epsilons).
    #[test]
    fn half_turns_store_a_zero_real_part() {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        for r in [
            DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)),
            DMat3::from_cols(DVec3::Y, DVec3::X, -DVec3::Z),
            rot(DVec3::new(1.0, 1.0, 0.0), 180.0),
            rot(DVec3::new(1.0, 1.0, 1.0), 180.0),
            DMat3::from_cols(
                DVec3::new(0.0, s, s),
                DVec3::new(s, -0.5, 0.5),
                DVec3::new(s, 0.5, -0.5),
            ),
        ] {
            let (q, _) = quaternion(r);
            let stored = storable_quaternion(q);
            let w2 = 1.0 - stored.iter().map(|&v| v as f64 * v as f64).sum::<f64>();
            assert!(
                w2 <= 0.0 && w2 > -3.0 * f32::EPSILON as f64,
                "{r}: {stored:?} {w2}"
            );
        }
        // A quarter turn is left as rounded.
        let (q, _) = quaternion(rot(DVec3::Z, 90.0));
        assert_eq!(storable_quaternion(q), q.map(|v| v as f32));
    }

    fn grid(direction: DMat3) -> Grid {
        Grid::new([3, 4, 2], [0.5, 1.25, 2.0], [-10.5, 3.0, 7.25], direction).unwrap()
    }

    fn volumes(g: &Grid) -> Vec<AnyVolume> {
        crate::test_volumes::every_type(g, 0.25)
    }

    /// Every sample type, `.nii` and `.nii.gz`, axis-aligned (flips included) and oblique
    /// grids: volsplat's reader gives back the samples, and the grid (exactly where the
    /// numbers are float32 numbers, to float32 precision otherwise).
    #[test]
    fn round_trip_through_the_reader() {
        let dir = tempfile::tempdir().unwrap();
        let directions = [
            DMat3::IDENTITY,
            DMat3::from_diagonal(DVec3::new(-1.0, 1.0, -1.0)),
            DMat3::from_cols(DVec3::Y, -DVec3::X, DVec3::Z),
            rot(DVec3::new(0.2, 1.0, -0.4), 37.0),
            rot(DVec3::new(1.0, 0.0, 1.0), 180.0)
                * DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)),
        ];
        for (k, d) in directions.iter().enumerate() {
            let g = grid(*d);
            for v in volumes(&g) {
                for name in ["v.nii", "v.nii.gz"] {
                    let p = dir.path().join(name);
                    write_nifti(&p, &v, false).unwrap();
                    let l = super::super::read_nifti_with(&p, &ReadOptions::default()).unwrap();
                    assert_eq!(l.volume.scalar_type(), v.scalar_type(), "{k} {name}");
                    assert_eq!(l.volume.to_f32().data(), v.to_f32().data(), "{k} {name}");
                    let r = l.volume.grid();
                    assert_eq!(r.dims, g.dims);
                    let tol = if k < 3 { 0.0 } else { 1e-6 };
                    for a in 0..3 {
                        assert!(
                            (r.spacing[a] - g.spacing[a]).abs() <= tol * 4.0,
                            "{k}: {r:?}"
                        );
                        assert!(
                            (r.origin[a] - g.origin[a]).abs() <= tol * 16.0,
                            "{k}: {r:?}"
                        );
                    }
                    let err = (r.direction - g.direction)
                        .to_cols_array()
                        .iter()
                        .map(|v| v.abs())
                        .fold(0.0, f64::max);
                    assert!(err <= tol, "{k}: {err}");
                    assert!(l.notes.iter().any(|n| n.contains("sform")), "{:?}", l.notes);
                }
            }
        }
    }

    /// The header's fields at their `nifti1.h` offsets: the values nibabel reads.
    #[test]
    fn header_fields() {
        let g = grid(DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)));
        let b = header_bytes(Path::new("x.nii"), &g, ScalarType::I16).unwrap();
        let i16_at = |at: usize| i16::from_le_bytes([b[at], b[at + 1]]);
        let f32_at = |at: usize| f32::from_le_bytes(b[at..at + 4].try_into().unwrap());
        assert_eq!(i32::from_le_bytes(b[0..4].try_into().unwrap()), 348);
        assert_eq!(
            [i16_at(40), i16_at(42), i16_at(44), i16_at(46)],
            [3, 3, 4, 2]
        );
        assert_eq!((i16_at(70), i16_at(72)), (4, 16));
        assert_eq!(f32_at(76), -1.0, "qfac: the direction is a reflection");
        assert_eq!([f32_at(80), f32_at(84), f32_at(88)], [0.5, 1.25, 2.0]);
        assert_eq!((f32_at(108), f32_at(112), f32_at(116)), (352.0, 1.0, 0.0));
        assert_eq!((i16_at(252), i16_at(254)), (1, 1));
        // RAS: x and y negated; srow_x = (−0.5, 0, 0, 10.5), srow_z = (0, 0, −2, 7.25).
        assert_eq!(
            [f32_at(280), f32_at(284), f32_at(288), f32_at(292)],
            [-0.5, 0.0, 0.0, 10.5]
        );
        assert_eq!(
            [f32_at(312), f32_at(316), f32_at(320), f32_at(324)],
            [0.0, 0.0, -2.0, 7.25]
        );
        assert_eq!([f32_at(268), f32_at(272), f32_at(276)], [10.5, -3.0, 7.25]);
        assert_eq!(&b[344..348], b"n+1\0");
        assert_eq!(b.len(), 352);
    }

    #[test]
    fn too_large_for_nifti_1_is_an_error() {
        let g = Grid::new([40000, 1, 1], [1.0; 3], [0.0; 3], DMat3::IDENTITY).unwrap();
        let e = header_bytes(Path::new("x.nii"), &g, ScalarType::U8)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.nii") && e.contains("40000") && e.contains("32767"),
            "{e}"
        );
        let g = Grid::new([2, 1, 1], [1e300, 1.0, 1.0], [0.0; 3], DMat3::IDENTITY).unwrap();
        let e = header_bytes(Path::new("x.nii"), &g, ScalarType::U8)
            .unwrap_err()
            .to_string();
        assert!(e.contains("float32"), "{e}");
        assert!(float32_rounding(&grid(DMat3::IDENTITY)) == 0.0);
        let g = Grid::new([2, 1, 1], [0.1, 1.0, 1.0], [0.0; 3], DMat3::IDENTITY).unwrap();
        assert!(float32_rounding(&g) > 1e-9);
    }
}
