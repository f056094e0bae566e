//! NIfTI-1 and NIfTI-2 volumes (<https://nifti.nimh.nih.gov/nifti-1>, `nifti2.h`): single files
//! (`.nii`, `.nii.gz`) and header/image pairs (`.hdr` + `.img` or `.img.gz`). Read by hand, not
//! with the `nifti` crate, which reads NIfTI-1 only (decision 0009).
//!
//! # What is read
//!
//! - Either byte order (detected from `sizeof_hdr`, 348 for NIfTI-1 and 540 for NIfTI-2); magic
//!   `n+1`/`ni1` or `n+2`/`ni2`. A `.hdr` without a NIfTI magic is read as Analyze 7.5: sizes,
//!   type and `pixdim` only (no orientation, no scaling).
//! - `dim`: `dim[0]` from 1 to 7; `dim[1..=3]` are the grid (missing axes are 1); the product
//!   of `dim[4..=dim[0]]` is the number of **frames** (volumes, e.g. time points). One frame is
//!   read (`frame`, default 0); asking for one past the end is an error stating how many there
//!   are.
//! - `datatype`: uint8, int8, uint16, int16 and float32 are read as they are; int32, uint32 and
//!   float64 are **converted to f32** (the rule of the NRRD reader: integers above 2²⁴ in
//!   magnitude lose precision; a double outside the f32 range is an error). Other types
//!   (complex, RGB, 64-bit integers) are rejected.
//! - `scl_slope`, `scl_inter`: a slope of 0 (or not finite) means no scaling, as in nibabel;
//!   otherwise `value · slope + inter` is computed in f64 and the volume becomes **f32** (unless
//!   slope 1 and intercept 0). A scaled value outside the f32 range is an error.
//! - Geometry, as nibabel and ITK choose it: the `sform` (`srow_x/y/z`) when `sform_code > 0`;
//!   else the `qform` (quaternion `quatern_b/c/d`, `qoffset_x/y/z`, `pixdim[1..=3]`, and `qfac`
//!   = `pixdim[0]`, −1 flipping k) when `qform_code > 0`; else `pixdim[1..=3]` alone with the
//!   the Analyze convention of nibabel's fallback affine (RAS `diag(−sx, sy, sz)`, x flipped,
//!   the grid centred on the world origin).
//!   A sheared `sform` (axes not orthogonal) falls back to the `qform` when there is one, with a
//!   note, and is an error otherwise.
//! - **World frame**: NIfTI's world is RAS+; it is converted to LPS (docs/design.md §3, decision
//!   0008) by negating x and y of the affine: `D' = diag(−1, −1, 1)·D`, `o' = diag(−1, −1, 1)·o`.
//! - Spatial units (`xyzt_units`) are kept as written, as nibabel does (no rescaling to mm); metres
//!   or micrometres draw a note.
//! - The samples start at `vox_offset` bytes into the `.nii` (after decompression for `.nii.gz`)
//!   or the `.img`; frame `f` starts `f · (frame bytes)` later.
//!
//! # Writing
//!
//! [`write_nifti`] writes single-file NIfTI-1 (`.nii`, `.nii.gz`): sform and qform (code 1) in
//! RAS converted from volsplat's LPS, samples in their own type, geometry rounded to float32.
//! See [`write_nifti`].
//!
//! # Limits
//!
//! The voxel count of one frame is checked against [`crate::Limits`] before anything is
//! allocated; raw payloads are checked against the file size; compressed payloads never inflate
//! past the needed size.

use crate::error::{IoError, Result};
use crate::limits::{checked_dims, checked_voxel_count};
use crate::payload::{ByteSkip, Encoding, FileType, PayloadSpec, read_payload};
use crate::{LoadedVolume, ReadOptions};
use flate2::read::MultiGzDecoder;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{AnyVolume, CoreError, Grid, Volume};

mod write;
pub use write::{float32_rounding, write_nifti};

const SUPPORTED_TYPES: &str = "2 (uint8), 256 (int8), 512 (uint16), 4 (int16), 16 (float32); \
     converted to float32: 8 (int32), 768 (uint32), 64 (float64)";

/// Reads a NIfTI-1 or NIfTI-2 volume (`.nii`, `.nii.gz`, or a `.hdr` with its `.img`), frame 0,
/// with default [`crate::Limits`]. World frame LPS (converted from NIfTI's RAS); see the
/// [module documentation](self).
pub fn read_nifti(path: impl AsRef<Path>) -> Result<AnyVolume> {
    read_nifti_with(path, &ReadOptions::default()).map(|l| l.volume)
}

/// Reads frame `options.frame` of a NIfTI-1 or NIfTI-2 volume; the result says how many frames
/// the file holds and carries notes (geometry source, scaling, conversions).
pub fn read_nifti_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let path = path.as_ref();
    options.refuse_series(path)?;
    options.refuse_array(path, "NIfTI")?;
    let limits = &options.limits;
    let gz_single = has_suffix(path, ".nii.gz");
    let is_hdr = has_suffix(path, ".hdr") || has_suffix(path, ".hdr.gz");
    let confine = crate::confine::Confinement::of(path, limits)?;
    crate::limits::require_regular_file(path, "header file")?;
    let bytes = read_prefix(path, has_suffix(path, ".gz"), 540)?;
    let h = Header::parse(path, &bytes, is_hdr)?;
    let mut notes = Vec::new();

    // Sizes and frames.
    let ndim = h.dim[0];
    if !(1..=7).contains(&ndim) {
        return Err(IoError::field(
            path,
            "dim[0]",
            &ndim.to_string(),
            "the number of dimensions must be 1 to 7",
        ));
    }
    let mut sizes = [1u64; 7];
    for (a, size) in sizes.iter_mut().enumerate().take(ndim as usize) {
        let d = h.dim[a + 1];
        if d < 1 {
            return Err(IoError::field(
                path,
                format!("dim[{}]", a + 1),
                &d.to_string(),
                "sizes must be ≥ 1",
            ));
        }
        *size = d as u64;
    }
    let dim_text = format!("{:?}", &h.dim[..=ndim as usize]);
    let dims = checked_dims(
        path,
        "dim",
        &dim_text,
        [sizes[0], sizes[1], sizes[2]],
        limits,
    )?;
    // Frames: the product of dim[4..]; checked (it only multiplies byte offsets).
    let frames = sizes[3..]
        .iter()
        .try_fold(1u64, |acc, &s| acc.checked_mul(s))
        .ok_or_else(|| IoError::field(path, "dim", &dim_text, "the number of frames overflows"))?;
    if options.frame as u64 >= frames {
        return Err(IoError::invalid_argument(
            path,
            "frame",
            format!(
                "frame {} requested, but the file holds {frames} frame{} (0 to {})",
                options.frame,
                if frames == 1 { "" } else { "s" },
                frames - 1
            ),
        ));
    }
    if frames > 1 {
        notes.push(format!(
            "{frames} frames (volumes) in the file; read frame {}",
            options.frame
        ));
    }

    let file_type = match h.datatype {
        2 => FileType::U8,
        256 => FileType::I8,
        512 => FileType::U16,
        4 => FileType::I16,
        16 => FileType::F32,
        8 => FileType::I32,
        768 => FileType::U32,
        64 => FileType::F64,
        other => {
            return Err(IoError::unsupported(
                path,
                "datatype",
                &other.to_string(),
                SUPPORTED_TYPES,
            ));
        }
    };
    if matches!(file_type, FileType::I32 | FileType::U32 | FileType::F64) {
        notes.push(format!(
            "samples of type {} converted to float32",
            file_type.name()
        ));
    }

    let grid = geometry(path, &h, dims, &mut notes)?;
    match h.space_units {
        1 => notes.push("spatial units: metres (xyzt_units); kept as written".into()),
        3 => notes.push("spatial units: micrometres (xyzt_units); kept as written".into()),
        _ => {}
    }

    // Where the samples are.
    let frame_voxels = checked_voxel_count(path, "dim", &dim_text, &sizes[..3], limits)?;
    let frame_bytes = frame_voxels * file_type.size_bytes() as u128;
    let vox_offset = h.vox_offset(path, is_hdr)?;
    let skip128 = vox_offset as u128 + frame_bytes * options.frame as u128;
    let skip = u64::try_from(skip128).map_err(|_| {
        IoError::field(
            path,
            "frame",
            &options.frame.to_string(),
            "offset overflows",
        )
    })?;
    let (data_path, gz) = if is_hdr {
        let img = image_path(path)?;
        if let Some(c) = &confine {
            let name = img.file_name().unwrap_or_default().to_string_lossy();
            c.check(path, "image file beside the .hdr", &name, &img)?;
        }
        let gz = has_suffix(&img, ".gz");
        (img, gz)
    } else {
        (path.to_path_buf(), gz_single)
    };
    let spec = PayloadSpec {
        data_path: &data_path,
        start: 0,
        line_skip: 0,
        byte_skip: ByteSkip::Bytes(skip),
        skip_field: "vox_offset",
        encoding: if gz { Encoding::Gzip } else { Encoding::Raw },
        file_type,
        big_endian: h.big_endian,
        exact: false,
    };
    let volume = read_payload(&spec, grid)?;
    let volume = apply_scaling(path, volume, &h, &mut notes)?;
    Ok(LoadedVolume {
        volume,
        format: h.version.name().into(),
        frames: frames as usize,
        frame: options.frame,
        arrays: Vec::new(),
        series: Vec::new(),
        series_uid: None,
        notes,
    })
}

/// Whether `path`'s file name ends with `suffix` (ASCII case-insensitive).
pub(crate) fn has_suffix(path: &Path, suffix: &str) -> bool {
    path.file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .is_some_and(|n| n.ends_with(suffix))
}

/// The `.img` (or `.img.gz`) next to a `.hdr`, keeping the case of the extension.
fn image_path(hdr: &Path) -> Result<PathBuf> {
    let name = hdr
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let lower = name.to_ascii_lowercase();
    let (stem, gz) = if let Some(s) = lower.strip_suffix(".hdr.gz") {
        (&name[..s.len()], true)
    } else {
        (&name[..name.len() - 4], false)
    };
    let upper = name[stem.len()..].starts_with(".HDR");
    let ext = if upper { "IMG" } else { "img" };
    let mut candidates = vec![hdr.with_file_name(format!("{stem}.{ext}"))];
    let plain_gz = hdr.with_file_name(format!("{stem}.{ext}.gz"));
    if gz {
        candidates.insert(0, plain_gz);
    } else {
        candidates.push(plain_gz);
    }
    for c in &candidates {
        if c.exists() {
            return Ok(c.clone());
        }
    }
    // Named in full: the OS's "entity not found" alone does not say which file is missing.
    Err(IoError::Os {
        path: hdr.to_path_buf(),
        op: format!(
            "find the image file {} (or {}) holding this header's samples",
            candidates[0].display(),
            candidates[1].display()
        ),
        error: std::io::Error::new(
            std::io::ErrorKind::NotFound,
            "no such file; a NIfTI/Analyze .hdr header holds no samples: its .img file must lie \
             beside it with the same name",
        ),
    })
}

/// Reads up to `n` bytes from the start of `path` (decompressed when `gz`).
fn read_prefix(path: &Path, gz: bool, n: u64) -> Result<Vec<u8>> {
    let file = File::open(path).map_err(|e| IoError::os(path, "open", e))?;
    let mut out = Vec::new();
    let r: Box<dyn Read> = if gz {
        Box::new(MultiGzDecoder::new(file))
    } else {
        Box::new(file)
    };
    match r.take(n).read_to_end(&mut out) {
        Ok(_) => Ok(out),
        // A gzip stream shorter than the header: report what we have as truncated below.
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Ok(out),
        Err(e) if gz => Err(IoError::Decompress {
            path: path.to_path_buf(),
            what: "gzip stream (header)".into(),
            error: e,
        }),
        Err(e) => Err(IoError::os(path, "read header", e)),
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Version {
    Analyze,
    Nifti1,
    Nifti2,
}

impl Version {
    fn name(self) -> &'static str {
        match self {
            Version::Analyze => "Analyze 7.5",
            Version::Nifti1 => "NIfTI-1",
            Version::Nifti2 => "NIfTI-2",
        }
    }
}

/// The header fields used, widened to the NIfTI-2 types.
#[derive(Debug, Clone)]
struct Header {
    version: Version,
    big_endian: bool,
    dim: [i64; 8],
    datatype: i16,
    pixdim: [f64; 8],
    vox_offset: f64,
    scl_slope: f64,
    scl_inter: f64,
    qform_code: i32,
    sform_code: i32,
    quatern: [f64; 3],
    qoffset: [f64; 3],
    srow: [[f64; 4]; 3],
    /// Spatial units code (`xyzt_units & 7`): 1 metre, 2 mm, 3 µm, 0 unknown.
    space_units: i32,
}

/// Little- or big-endian field access into a header buffer.
struct Fields<'a> {
    b: &'a [u8],
    be: bool,
}

impl Fields<'_> {
    fn bytes<const N: usize>(&self, at: usize) -> [u8; N] {
        let mut a = [0u8; N];
        a.copy_from_slice(&self.b[at..at + N]);
        if self.be {
            a.reverse();
        }
        a
    }
    fn i16(&self, at: usize) -> i16 {
        i16::from_le_bytes(self.bytes(at))
    }
    fn i32(&self, at: usize) -> i32 {
        i32::from_le_bytes(self.bytes(at))
    }
    fn i64(&self, at: usize) -> i64 {
        i64::from_le_bytes(self.bytes(at))
    }
    fn f32(&self, at: usize) -> f64 {
        f32::from_le_bytes(self.bytes(at)) as f64
    }
    fn f64(&self, at: usize) -> f64 {
        f64::from_le_bytes(self.bytes(at))
    }
}

impl Header {
    fn parse(path: &Path, b: &[u8], is_hdr: bool) -> Result<Header> {
        let truncated = |need: usize| IoError::Truncated {
            path: path.to_path_buf(),
            what: "NIfTI header".into(),
            expected: need as u64,
            actual: b.len() as u64,
            unit: "bytes",
        };
        if b.len() < 4 {
            return Err(truncated(348));
        }
        let le = i32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        let be = i32::from_be_bytes([b[0], b[1], b[2], b[3]]);
        let (size, big_endian) = match (le, be) {
            (348, _) | (540, _) => (le, false),
            (_, 348) | (_, 540) => (be, true),
            _ => {
                return Err(IoError::field(
                    path,
                    "sizeof_hdr",
                    &le.to_string(),
                    "not a NIfTI file (sizeof_hdr must be 348 for NIfTI-1 or 540 for NIfTI-2, \
                     in either byte order)",
                ));
            }
        };
        let size = size as usize;
        if b.len() < size {
            return Err(truncated(size));
        }
        let f = Fields { b, be: big_endian };
        if size == 540 {
            let magic = &b[4..8];
            if magic != b"n+2\0" && magic != b"ni2\0" {
                return Err(IoError::field(
                    path,
                    "magic",
                    &String::from_utf8_lossy(&b[4..12]),
                    "a 540-byte header must have the NIfTI-2 magic `n+2` or `ni2`",
                ));
            }
            let mut dim = [0i64; 8];
            let mut pixdim = [0f64; 8];
            for k in 0..8 {
                dim[k] = f.i64(16 + 8 * k);
                pixdim[k] = f.f64(104 + 8 * k);
            }
            let mut srow = [[0f64; 4]; 3];
            for (r, row) in srow.iter_mut().enumerate() {
                for (c, v) in row.iter_mut().enumerate() {
                    *v = f.f64(400 + 32 * r + 8 * c);
                }
            }
            return Ok(Header {
                version: Version::Nifti2,
                big_endian,
                dim,
                datatype: f.i16(12),
                pixdim,
                vox_offset: f.i64(168) as f64,
                scl_slope: f.f64(176),
                scl_inter: f.f64(184),
                qform_code: f.i32(344),
                sform_code: f.i32(348),
                quatern: [f.f64(352), f.f64(360), f.f64(368)],
                qoffset: [f.f64(376), f.f64(384), f.f64(392)],
                srow,
                space_units: f.i32(500) & 7,
            });
        }
        let magic = &b[344..348];
        let version = if magic == b"n+1\0" || magic == b"ni1\0" {
            Version::Nifti1
        } else if is_hdr && magic == [0, 0, 0, 0] {
            Version::Analyze
        } else {
            return Err(IoError::field(
                path,
                "magic",
                &String::from_utf8_lossy(magic),
                "a 348-byte header must have the NIfTI-1 magic `n+1` (single file) or `ni1` \
                 (.hdr/.img pair)",
            ));
        };
        let mut dim = [0i64; 8];
        let mut pixdim = [0f64; 8];
        for k in 0..8 {
            dim[k] = f.i16(40 + 2 * k) as i64;
            pixdim[k] = f.f32(76 + 4 * k);
        }
        let mut srow = [[0f64; 4]; 3];
        for (r, row) in srow.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = f.f32(280 + 16 * r + 4 * c);
            }
        }
        let nifti = version == Version::Nifti1;
        Ok(Header {
            version,
            big_endian,
            dim,
            datatype: f.i16(70),
            pixdim,
            vox_offset: f.f32(108),
            scl_slope: if nifti { f.f32(112) } else { 0.0 },
            scl_inter: if nifti { f.f32(116) } else { 0.0 },
            qform_code: if nifti { f.i16(252) as i32 } else { 0 },
            sform_code: if nifti { f.i16(254) as i32 } else { 0 },
            quatern: [f.f32(256), f.f32(260), f.f32(264)],
            qoffset: [f.f32(268), f.f32(272), f.f32(276)],
            srow,
            space_units: if nifti { (b[123] & 7) as i32 } else { 0 },
        })
    }

    /// `vox_offset` as a byte count: a whole number ≥ 0, and past the header in a single file.
    fn vox_offset(&self, path: &Path, is_hdr: bool) -> Result<u64> {
        let v = self.vox_offset;
        let header_len = if self.version == Version::Nifti2 {
            540.0
        } else {
            348.0
        };
        if !(v.is_finite() && v >= 0.0 && v.fract() == 0.0 && v < 9.0e15) {
            return Err(IoError::field(
                path,
                "vox_offset",
                &v.to_string(),
                "must be a whole number of bytes ≥ 0",
            ));
        }
        if !is_hdr && v < header_len {
            return Err(IoError::field(
                path,
                "vox_offset",
                &v.to_string(),
                format!(
                    "in a single-file NIfTI the samples start after the {header_len}-byte header"
                ),
            ));
        }
        Ok(v as u64)
    }
}

/// Builds the grid in LPS from sform, qform or pixdim (module documentation).
fn geometry(path: &Path, h: &Header, dims: [usize; 3], notes: &mut Vec<String>) -> Result<Grid> {
    let pix = |a: usize| -> Result<f64> {
        let v = h.pixdim[a + 1];
        if v.is_finite() && v != 0.0 {
            Ok(v.abs())
        } else if dims[a] == 1 || h.sform_code > 0 {
            // Unused axis (or the sform gives the spacing): any value will do.
            Ok(1.0)
        } else {
            Err(IoError::field(
                path,
                format!("pixdim[{}]", a + 1),
                &v.to_string(),
                "voxel spacing must be a non-zero finite number",
            ))
        }
    };
    let qform = |notes: &mut Vec<String>| -> Result<(DMat3, [f64; 3], [f64; 3])> {
        let [b, c, d] = h.quatern;
        let spacing = [pix(0)?, pix(1)?, pix(2)?];
        if ![b, c, d].iter().chain(&h.qoffset).all(|v| v.is_finite()) {
            return Err(IoError::field(
                path,
                "quatern_b/c/d, qoffset_x/y/z",
                &format!("{:?} {:?}", h.quatern, h.qoffset),
                "must be finite",
            ));
        }
        // nifti1_io.c nifti_quatern_to_mat44.
        let (mut a, mut b, mut c, mut d) = (1.0 - (b * b + c * c + d * d), b, c, d);
        if a < 1e-7 {
            let s = 1.0 / (b * b + c * c + d * d).sqrt();
            b *= s;
            c *= s;
            d *= s;
            a = 0.0;
        } else {
            a = a.sqrt();
        }
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
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let dir = r * DMat3::from_diagonal(DVec3::new(1.0, 1.0, qfac));
        notes.push(format!(
            "geometry from the qform (qform_code {}, qfac {qfac})",
            h.qform_code
        ));
        Ok((dir, spacing, h.qoffset))
    };
    let (dir_ras, spacing, origin_ras) = if h.sform_code > 0 {
        let m = h.srow;
        if !m.iter().flatten().all(|v| v.is_finite()) {
            return Err(IoError::field(
                path,
                "srow_x/y/z",
                &format!("{m:?}"),
                "must be finite",
            ));
        }
        let cols = [0, 1, 2].map(|c| DVec3::new(m[0][c], m[1][c], m[2][c]));
        let lens = cols.map(|c| {
            let s = c.abs().max_element();
            if s == 0.0 { 0.0 } else { s * (c / s).length() }
        });
        let unit: Vec<DVec3> = cols
            .iter()
            .zip(lens)
            .map(|(c, l)| if l > 0.0 { *c / l } else { DVec3::ZERO })
            .collect();
        let dir = DMat3::from_cols(unit[0], unit[1], unit[2]);
        let orthonormal = lens.iter().all(|&l| l > 0.0)
            && (dir.transpose() * dir - DMat3::IDENTITY)
                .to_cols_array()
                .iter()
                .all(|v| v.abs() < 1e-4);
        if orthonormal {
            notes.push(format!(
                "geometry from the sform (sform_code {})",
                h.sform_code
            ));
            (dir, lens, [m[0][3], m[1][3], m[2][3]])
        } else if h.qform_code > 0 {
            notes.push(
                "the sform is sheared or degenerate (axes not orthogonal); used the qform".into(),
            );
            qform(notes)?
        } else {
            return Err(IoError::field(
                path,
                "srow_x/y/z",
                &format!("{m:?}"),
                "the sform's axes must be non-zero and mutually orthogonal \
                 (sheared grids are not supported), and there is no qform to fall back on",
            ));
        }
    } else if h.qform_code > 0 {
        qform(notes)?
    } else {
        notes.push(format!(
            "{}: no orientation in the file (qform_code and sform_code are 0); assumed the \
             Analyze convention (x flipped, grid centred on the origin), as nibabel",
            h.version.name()
        ));
        let s = [pix(0)?, pix(1)?, pix(2)?];
        // nibabel's `shape_zoom_affine` with `default_x_flip`: RAS affine diag(−sx, sy, sz),
        // origin −(n − 1)/2 · zoom per axis with the x zoom negated.
        let half = |a: usize| (dims[a] as f64 - 1.0) / 2.0 * s[a];
        (
            DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)),
            s,
            [half(0), -half(1), -half(2)],
        )
    };
    // RAS → LPS (decision 0008).
    let f = DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0));
    let dir = f * dir_ras;
    let origin = (f * DVec3::from(origin_ras)).to_array();
    Grid::new(dims, spacing, origin, dir).map_err(|e| match &e {
        CoreError::InvalidField { field, .. } if field == "direction" => IoError::field(
            path,
            "quatern_b/c/d",
            &format!("{:?}", h.quatern),
            "the quaternion does not give a rotation",
        ),
        _ => IoError::core(path, e),
    })
}

/// Applies `scl_slope` / `scl_inter` (module documentation).
fn apply_scaling(
    path: &Path,
    volume: AnyVolume,
    h: &Header,
    notes: &mut Vec<String>,
) -> Result<AnyVolume> {
    let (slope, inter) = (h.scl_slope, h.scl_inter);
    if slope == 0.0 || !slope.is_finite() {
        return Ok(volume);
    }
    let inter = if inter.is_finite() { inter } else { 0.0 };
    if slope == 1.0 && inter == 0.0 {
        return Ok(volume);
    }
    let grid = volume.grid().clone();
    let src = volume.to_f32();
    let mut out = Vec::with_capacity(src.data().len());
    for (n, &x) in src.data().iter().enumerate() {
        let y = x as f64 * slope + inter;
        let y32 = y as f32;
        if !y32.is_finite() {
            return Err(IoError::field(
                path,
                "scl_slope, scl_inter",
                &format!("{slope}, {inter}"),
                format!("sample #{n} ({x}) scales to {y:e}, outside the float32 range"),
            ));
        }
        out.push(y32);
    }
    notes.push(format!(
        "samples scaled by scl_slope {slope} and scl_inter {inter} (now float32)"
    ));
    Volume::new(grid, out)
        .map(Into::into)
        .map_err(|e| IoError::core(path, e))
}

#[cfg(test)]
pub(crate) mod tests;
