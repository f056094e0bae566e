//! Writing a volume in the format its file name names: [`write_volume`], for `volsplat
//! convert` and any other front end.

use crate::error::{IoError, Result};
use crate::nifti::has_suffix;
use std::path::{Path, PathBuf};
use volsplat_core::AnyVolume;

/// The file-name endings [`write_volume`] writes (without the leading dot; compared
/// case-insensitively with the end of the file name).
pub const VOLUME_WRITE_EXTENSIONS: &[&str] = &["nrrd", "nii", "nii.gz", "mha", "mhd", "npy"];

const SUPPORTED: &str = ".nrrd, .nii, .nii.gz, .mha, .mhd (with a .raw or .zraw data file), \
     .npy (samples only)";

/// The formats [`write_volume`] writes, as told by the output's file name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum VolumeWriteFormat {
    /// `.nrrd`: NRRD with an attached header, `space: left-posterior-superior`
    /// ([`crate::write_nrrd`]).
    Nrrd,
    /// `.nii` or `.nii.gz`: single-file NIfTI-1, sform and qform in RAS
    /// ([`crate::write_nifti`]).
    Nifti,
    /// `.mha` or `.mhd`: MetaImage, LPS as ITK ([`crate::write_metaimage`]).
    MetaImage,
    /// `.npy`: the samples in their own type, shape (z, y, x); no geometry
    /// ([`crate::write_npy_volume`]).
    Npy,
}

impl VolumeWriteFormat {
    /// The format named by `path`'s ending (case-insensitive), or `None`.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ends = |s: &str| has_suffix(path, s);
        Some(if ends(".nrrd") {
            VolumeWriteFormat::Nrrd
        } else if ends(".nii") || ends(".nii.gz") {
            VolumeWriteFormat::Nifti
        } else if ends(".mha") || ends(".mhd") {
            VolumeWriteFormat::MetaImage
        } else if ends(".npy") {
            VolumeWriteFormat::Npy
        } else {
            return None;
        })
    }

    /// A short name for messages: `NRRD`, `NIfTI-1`, `MetaImage`, `.npy`.
    pub fn name(self) -> &'static str {
        match self {
            VolumeWriteFormat::Nrrd => "NRRD",
            VolumeWriteFormat::Nifti => "NIfTI-1",
            VolumeWriteFormat::MetaImage => "MetaImage",
            VolumeWriteFormat::Npy => ".npy",
        }
    }

    /// Whether the format records the grid's geometry (spacing, origin, direction); only
    /// `.npy` does not.
    pub fn keeps_geometry(self) -> bool {
        self != VolumeWriteFormat::Npy
    }
}

/// How [`write_volume`] writes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct VolumeWriteOptions {
    /// Compress the samples: NRRD `encoding: gzip`, MetaImage `CompressedData` (zlib; `.mhd`
    /// then writes a `.zraw` data file). `.nii.gz` is always compressed and `.nii` never, so
    /// this must be off for `.nii` (and `.npy`); with `.nii.gz` it changes nothing.
    pub compress: bool,
}

/// What [`write_volume`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WrittenVolume {
    /// The format written.
    pub format: VolumeWriteFormat,
    /// The files written: the path given first, then a detached data file (`.mhd`'s `.raw`).
    pub files: Vec<PathBuf>,
    /// Notes for the user: what the format does not keep (`.npy`: the geometry), float32
    /// rounding of the geometry (NIfTI). Print them as information.
    pub notes: Vec<String>,
}

/// The format `path` names, checked against `options` without touching the file system:
/// call it before reading a slow input, so that a bad output name fails first. Errors: an
/// ending that is not writable ([`IoError::UnsupportedFormat`], listing
/// [`VOLUME_WRITE_EXTENSIONS`]), or compression asked of `.nii` or `.npy`
/// ([`IoError::InvalidArgument`]).
pub fn volume_write_format(path: &Path, options: &VolumeWriteOptions) -> Result<VolumeWriteFormat> {
    let Some(format) = VolumeWriteFormat::from_path(path) else {
        return Err(IoError::UnsupportedFormat {
            path: path.to_path_buf(),
            extension: path
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default(),
            supported: SUPPORTED.into(),
        });
    };
    if options.compress {
        let refuse = match format {
            VolumeWriteFormat::Nifti if !has_suffix(path, ".gz") => {
                Some("a .nii file is not compressed; name it .nii.gz for a gzipped NIfTI")
            }
            VolumeWriteFormat::Npy => Some(".npy files are not compressed"),
            _ => None,
        };
        if let Some(reason) = refuse {
            return Err(IoError::invalid_argument(path, "compression", reason));
        }
    }
    Ok(format)
}

/// Writes `volume` in the format named by `path`'s ending ([`VolumeWriteFormat::from_path`]):
/// `.nrrd` ([`crate::write_nrrd`]), `.nii` / `.nii.gz` ([`crate::write_nifti`]), `.mha` /
/// `.mhd` ([`crate::write_metaimage`]), `.npy` ([`crate::write_npy_volume`]). Every format but
/// `.npy` keeps the grid: NRRD and MetaImage exactly, in volsplat's LPS world frame; NIfTI
/// converted to its RAS frame and rounded to float32. Atomic, as every writer of this crate
/// (a `.mhd` and its data file as a pair). Errors as [`volume_write_format`], then the
/// writer's.
pub fn write_volume(
    path: impl AsRef<Path>,
    volume: &AnyVolume,
    options: &VolumeWriteOptions,
) -> Result<WrittenVolume> {
    let path = path.as_ref();
    let format = volume_write_format(path, options)?;
    let mut notes = Vec::new();
    let files = match format {
        VolumeWriteFormat::Nrrd => {
            crate::write_nrrd(path, volume, options.compress)?;
            vec![path.to_path_buf()]
        }
        VolumeWriteFormat::Nifti => {
            crate::write_nifti(path, volume, options.compress)?;
            let r = crate::nifti::float32_rounding(volume.grid());
            if r > 0.0 {
                notes.push(format!(
                    "NIfTI-1 stores the geometry as float32: spacing, origin and direction \
                     rounded by up to {r:.3e} (world units); NRRD and MetaImage keep them exactly"
                ));
            }
            vec![path.to_path_buf()]
        }
        VolumeWriteFormat::MetaImage => crate::write_metaimage(path, volume, options.compress)?,
        VolumeWriteFormat::Npy => {
            crate::write_npy_volume(path, volume)?;
            notes.push(
                ".npy keeps the samples, shape (z, y, x), but not the geometry (spacing, \
                 origin, direction); NRRD, NIfTI and MetaImage keep both"
                    .into(),
            );
            vec![path.to_path_buf()]
        }
    };
    Ok(WrittenVolume {
        format,
        files,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::glam::{DMat3, DVec3};
    use volsplat_core::{Grid, Volume};

    #[test]
    fn formats_by_name() {
        for (name, f) in [
            ("a.nrrd", Some(VolumeWriteFormat::Nrrd)),
            ("a.NII", Some(VolumeWriteFormat::Nifti)),
            ("a.nii.GZ", Some(VolumeWriteFormat::Nifti)),
            ("a.mha", Some(VolumeWriteFormat::MetaImage)),
            ("a.MHD", Some(VolumeWriteFormat::MetaImage)),
            ("a.npy", Some(VolumeWriteFormat::Npy)),
            ("a.gz", None),
            ("a.nhdr", None),
            ("a.png", None),
        ] {
            assert_eq!(VolumeWriteFormat::from_path(Path::new(name)), f, "{name}");
        }
        for ext in VOLUME_WRITE_EXTENSIONS {
            let p = format!("x.{ext}");
            assert!(VolumeWriteFormat::from_path(Path::new(&p)).is_some(), "{p}");
            // Every writable ending is also readable (.npy aside: samples only).
            if *ext != "npy" {
                assert!(
                    crate::VolumeFormat::from_path(Path::new(&p)).is_some(),
                    "{p}"
                );
            }
        }
        let e = volume_write_format(Path::new("out.png"), &VolumeWriteOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("\"png\"") && e.contains(".nii.gz") && e.contains(".mhd"),
            "{e}"
        );
        let gz = VolumeWriteOptions { compress: true };
        for bad in ["x.nii", "x.npy"] {
            let e = volume_write_format(Path::new(bad), &gz)
                .unwrap_err()
                .to_string();
            assert!(e.contains("compress") && e.contains(bad), "{e}");
        }
        for good in ["x.nii.gz", "x.nrrd", "x.mha", "x.mhd"] {
            volume_write_format(Path::new(good), &gz).unwrap();
        }
    }

    /// Each format through the dispatcher and back through `read_volume`: the same samples
    /// and grid (NIfTI to float32 precision), the files listed, the notes said.
    #[test]
    fn every_format_round_trips_through_read_volume() {
        let dir = tempfile::tempdir().unwrap();
        let d = DMat3::from_cols(-DVec3::Y, DVec3::X, DVec3::Z);
        let g = Grid::new([4, 3, 2], [0.5, 0.75, 2.0], [12.5, -7.0, 30.25], d).unwrap();
        let v: AnyVolume = Volume::new(
            g.clone(),
            (0..24).map(|i| i * 100 - 900).collect::<Vec<i16>>(),
        )
        .unwrap()
        .into();
        for (name, compress, files) in [
            ("a.nrrd", false, 1),
            ("b.nrrd", true, 1),
            ("c.nii", false, 1),
            ("d.nii.gz", false, 1),
            ("e.nii.gz", true, 1),
            ("f.mha", true, 1),
            ("g.mhd", false, 2),
        ] {
            let p = dir.path().join(name);
            let w = write_volume(&p, &v, &VolumeWriteOptions { compress }).unwrap();
            assert_eq!(w.files.len(), files, "{name}");
            assert!(w.notes.is_empty(), "{name}: {:?}", w.notes);
            let l = crate::read_volume_with(&p, &crate::ReadOptions::default()).unwrap();
            assert_eq!(l.volume, v, "{name}");
        }
        let p = dir.path().join("h.npy");
        let w = write_volume(&p, &v, &VolumeWriteOptions::default()).unwrap();
        assert_eq!(w.format, VolumeWriteFormat::Npy);
        assert!(w.notes[0].contains("not the geometry"), "{:?}", w.notes);
        // A spacing that is not a float32 number: NIfTI says it rounds.
        let g = Grid::new([2, 1, 1], [0.1, 1.0, 1.0], [0.0; 3], DMat3::IDENTITY).unwrap();
        let v: AnyVolume = Volume::new(g, vec![1u8, 2]).unwrap().into();
        let w = write_volume(dir.path().join("r.nii"), &v, &VolumeWriteOptions::default()).unwrap();
        assert!(
            w.notes.iter().any(|n| n.contains("float32")),
            "{:?}",
            w.notes
        );
    }
}
