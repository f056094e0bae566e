//! Choosing a volume reader by file name: [`read_volume`], [`read_volume_with`] and their
//! options and result.

use crate::error::{IoError, Result};
use crate::limits::Limits;
use crate::nifti::has_suffix;
use std::path::Path;
use volsplat_core::AnyVolume;

/// The file-name endings [`read_volume`] understands (without the leading dot; compare
/// case-insensitively with the end of the file name, so `nii.gz` matches `brain.NII.GZ`).
pub const VOLUME_EXTENSIONS: &[&str] = &[
    "nrrd", "nhdr", "mha", "mhd", "nii", "nii.gz", "hdr", "vti", "tif", "tiff", "dcm", "zarr",
];

const SUPPORTED: &str = ".nrrd, .nhdr, .mha, .mhd, .nii, .nii.gz, .hdr (+ .img), .vti, \
     .tif, .tiff, .dcm or any DICOM file, an OME-Zarr store (.zarr), a folder of DICOM or TIFF files (a headerless raw file: \
     give its layout with --raw-dims X,Y,Z, --raw-type and --raw-spacing)";

/// The volume file formats, as told by the file name (`#[non_exhaustive]`: more may come).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum VolumeFormat {
    /// NRRD, `.nrrd` or `.nhdr` ([`crate::read_nrrd`]).
    Nrrd,
    /// MetaImage, `.mha` or `.mhd` ([`crate::read_metaimage`]).
    MetaImage,
    /// NIfTI-1/-2, `.nii`, `.nii.gz`, `.hdr` ([`crate::read_nifti`]).
    Nifti,
    /// VTK XML image data, `.vti` ([`crate::read_vti`]).
    Vti,
    /// A multi-page TIFF, `.tif` / `.tiff` ([`crate::read_tiff`]).
    Tiff,
    /// A DICOM file, `.dcm` (its series is read: [`crate::read_dicom_with`]).
    Dicom,
    /// An OME-Zarr store, a directory `.zarr` ([`crate::read_zarr_with`]).
    Zarr,
}

impl VolumeFormat {
    /// The format named by `path`'s ending (case-insensitive), or `None`.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ends = |s: &str| has_suffix(path, s);
        Some(if ends(".nrrd") || ends(".nhdr") {
            VolumeFormat::Nrrd
        } else if ends(".mha") || ends(".mhd") {
            VolumeFormat::MetaImage
        } else if ends(".nii") || ends(".nii.gz") || ends(".hdr") || ends(".hdr.gz") {
            VolumeFormat::Nifti
        } else if ends(".vti") {
            VolumeFormat::Vti
        } else if ends(".tif") || ends(".tiff") {
            VolumeFormat::Tiff
        } else if ends(".dcm") {
            VolumeFormat::Dicom
        } else if ends(".zarr") {
            VolumeFormat::Zarr
        } else {
            return None;
        })
    }

    /// A short name for messages and `info` output (`NRRD`, `MetaImage`, `NIfTI`, `VTK image
    /// data`, `TIFF`, `DICOM`).
    pub fn name(self) -> &'static str {
        match self {
            VolumeFormat::Nrrd => "NRRD",
            VolumeFormat::MetaImage => "MetaImage",
            VolumeFormat::Nifti => "NIfTI",
            VolumeFormat::Vti => "VTK image data",
            VolumeFormat::Tiff => "TIFF",
            VolumeFormat::Dicom => "DICOM",
            VolumeFormat::Zarr => "OME-Zarr",
        }
    }
}

/// What [`read_volume_with`] (and every `read_*_with` reader) should read, and within which
/// limits. Other crates build it from [`ReadOptions::default`] with the `with_*` methods (the
/// struct is `#[non_exhaustive]`: a new option is not a breaking change); its fields can be
/// read and set.
///
/// ```
/// let options = volsplat_io::ReadOptions::default()
///     .with_frame(1)
///     .with_limits(volsplat_io::Limits::default().with_max_voxels(1 << 20));
/// assert_eq!((options.frame, options.limits.max_voxels), (1, 1 << 20));
/// ```
#[derive(Debug, Clone, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct ReadOptions {
    /// Limits against untrusted input (header bytes, voxel count, ...).
    pub limits: Limits,
    /// Which volume of a file holding several (a 4-D NIfTI's time points, an ImageJ
    /// hyperstack's frames), from 0; default 0.
    /// Asking for a frame past the end is an error stating how many there are; a frame other
    /// than 0 of a single-volume format is an error too.
    pub frame: usize,
    /// The point-data array to read from a VTK `.vti` file (default: the active scalars, else
    /// the first array). Naming an array for another format is an error.
    pub array: Option<String>,
    /// The DICOM series to read from a folder holding several: its SeriesInstanceUID, or its
    /// SeriesNumber where that is unique (default: the only series, or the series of the file
    /// given). Naming a series for another format is an error.
    pub series: Option<String>,
    /// The resolution level of a multiscale (OME-Zarr) store, 0 (the default) being the full
    /// resolution. A level past the last is an error listing the levels; a level other than 0
    /// for another format is an error too.
    pub level: usize,
    /// The channel of a multi-channel OME-Zarr image (its `channel` axis), from 0; default 0.
    /// Out of range, or other than 0 for another format, is an error.
    pub channel: usize,
    /// The time point of an OME-Zarr image (its `time` axis), from 0; default 0. Out of
    /// range, or other than 0 for another format, is an error (4-D NIfTI and ImageJ
    /// hyperstacks choose theirs with [`ReadOptions::frame`]).
    pub timepoint: usize,
}

/// A volume as read, with what the file said about it.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedVolume {
    /// The samples and their grid (world frame LPS for anatomical files: decision 0008).
    pub volume: AnyVolume,
    /// The format as read, e.g. `NRRD`, `MetaImage`, `NIfTI-1`, `NIfTI-2`, `VTK image data`,
    /// `TIFF`.
    pub format: String,
    /// How many volumes (frames) the file holds; 1 for most files.
    pub frames: usize,
    /// Which frame was read (0-based).
    pub frame: usize,
    /// The point-data arrays in the file (VTK `.vti`); empty for other formats.
    pub arrays: Vec<String>,
    /// The image series found beside a DICOM series read (in its folder, or among the files
    /// given), ordered by SeriesNumber; empty for other formats.
    pub series: Vec<crate::DicomSeries>,
    /// The SeriesInstanceUID read (DICOM); `None` for other formats.
    pub series_uid: Option<String>,
    /// Notes for the user: conversions applied (RAS → LPS, type or scaling), where the geometry
    /// came from, defaults assumed. Never errors; print them as information.
    pub notes: Vec<String>,
}

impl ReadOptions {
    /// These options with `limits` in place of the current limits.
    pub fn with_limits(mut self, limits: Limits) -> Self {
        self.limits = limits;
        self
    }

    /// These options with [`ReadOptions::frame`] set (0-based).
    pub fn with_frame(mut self, frame: usize) -> Self {
        self.frame = frame;
        self
    }

    /// These options with [`ReadOptions::array`] set (a VTK point-data array's name; `None`:
    /// the active scalars, else the first array).
    pub fn with_array(mut self, array: Option<String>) -> Self {
        self.array = array;
        self
    }

    /// These options with [`ReadOptions::series`] set (a DICOM SeriesInstanceUID or a unique
    /// SeriesNumber; `None`: the only series, or the given file's).
    pub fn with_series(mut self, series: Option<String>) -> Self {
        self.series = series;
        self
    }

    /// These options with [`ReadOptions::level`] set (0: full resolution).
    pub fn with_level(mut self, level: usize) -> Self {
        self.level = level;
        self
    }

    /// These options with [`ReadOptions::channel`] set (0-based).
    pub fn with_channel(mut self, channel: usize) -> Self {
        self.channel = channel;
        self
    }

    /// These options with [`ReadOptions::timepoint`] set (0-based).
    pub fn with_timepoint(mut self, timepoint: usize) -> Self {
        self.timepoint = timepoint;
        self
    }

    /// Refuses a [`ReadOptions::level`], [`ReadOptions::channel`] or
    /// [`ReadOptions::timepoint`] other than 0 for a reader of anything but OME-Zarr (`format`
    /// names the reader's format in the message).
    pub(crate) fn refuse_multiscale(&self, path: &Path, format: &str) -> Result<()> {
        for (what, value) in [
            ("level", self.level),
            ("channel", self.channel),
            ("timepoint", self.timepoint),
        ] {
            if value != 0 {
                return Err(IoError::invalid_argument(
                    path,
                    what,
                    format!(
                        "{what} {value} requested: choosing a {what} applies to OME-Zarr \
                         stores only, not to {format}"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Refuses [`ReadOptions::series`] for a reader of anything but DICOM.
    pub(crate) fn refuse_series(&self, path: &Path) -> Result<()> {
        if self.series.is_some() {
            return Err(IoError::invalid_argument(
                path,
                "series",
                "choosing a series applies to DICOM folders and files only",
            ));
        }
        Ok(())
    }

    /// Refuses [`ReadOptions::array`] for a reader of anything but VTK `.vti` (`format` names
    /// the reader's format in the message), and the OME-Zarr options
    /// ([`ReadOptions::refuse_multiscale`]).
    pub(crate) fn refuse_array(&self, path: &Path, format: &str) -> Result<()> {
        self.refuse_multiscale(path, format)?;
        if self.array.is_some() {
            return Err(IoError::invalid_argument(
                path,
                "array",
                format!("choosing an array applies to VTK .vti files only, not to {format}"),
            ));
        }
        Ok(())
    }

    /// Refuses a [`ReadOptions::frame`] other than 0 for a file that holds one volume.
    pub(crate) fn refuse_frame(&self, path: &Path) -> Result<()> {
        if self.frame != 0 {
            return Err(IoError::invalid_argument(
                path,
                "frame",
                format!(
                    "frame {} requested, but the file holds 1 frame (0)",
                    self.frame
                ),
            ));
        }
        Ok(())
    }

    /// Refuses every option but the limits: for the readers of one volume without named
    /// arrays or series (NRRD, MetaImage, raw).
    pub(crate) fn refuse_all_but_limits(&self, path: &Path, format: &str) -> Result<()> {
        self.refuse_series(path)?;
        self.refuse_array(path, format)?;
        self.refuse_frame(path)
    }
}

impl LoadedVolume {
    /// One volume of a single-volume format, with no arrays or series.
    pub(crate) fn single(volume: AnyVolume, format: &str, notes: Vec<String>) -> Self {
        LoadedVolume {
            volume,
            format: format.into(),
            frames: 1,
            frame: 0,
            arrays: Vec::new(),
            series: Vec::new(),
            series_uid: None,
            notes,
        }
    }
}

/// Reads a volume, choosing the format by the file name (case-insensitive): `.nrrd`, `.nhdr`
/// ([`crate::read_nrrd`]), `.mha`, `.mhd` ([`crate::read_metaimage`]), `.nii`, `.nii.gz`, `.hdr`
/// ([`crate::read_nifti`]), `.vti` ([`crate::read_vti`]), `.tif`, `.tiff`
/// ([`crate::read_tiff`]); a folder holding `.tif`/`.tiff` files is a stack of slices
/// ([`crate::read_tiff_dir`]); a folder holding DICOM files, a `.dcm` file, or a file of
/// another name that starts like a DICOM file is a DICOM series ([`crate::read_dicom_with`]);
/// a folder named `.zarr`, or holding a `zarr.json` / `.zattrs` with OME multiscales, is an
/// OME-Zarr store ([`crate::read_zarr_with`]).
/// Headerless raw files need a [`crate::RawSpec`]: use [`crate::read_raw`]. Any other ending,
/// or another folder, is an error listing the supported ones.
pub fn read_volume(path: impl AsRef<Path>) -> Result<AnyVolume> {
    read_volume_with(path, &ReadOptions::default()).map(|l| l.volume)
}

/// [`read_volume`] with [`ReadOptions`] (limits, frame, VTK array, DICOM series); the result
/// also carries the format, the number of frames, the DICOM series found and notes (among them
/// the float samples that were NaN or infinite and what they became,
/// [`volsplat_core::NonFiniteSamples`]).
pub fn read_volume_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let mut loaded = read_any(path.as_ref(), options)?;
    loaded.notes.extend(loaded.volume.non_finite_note());
    Ok(loaded)
}

/// [`read_volume_with`] by format, before the notes every format shares. Each reader refuses
/// the options that do not apply to its format.
fn read_any(path: &Path, options: &ReadOptions) -> Result<LoadedVolume> {
    if crate::zarr::is_zarr_store(path) {
        return crate::zarr::read_zarr_with(path, options);
    }
    if path.is_dir() && crate::tiff_stack::tiff_files(path)?.is_empty() {
        if crate::dicom::dir_has_dicom(path)? {
            return crate::dicom::read_dicom_with(path, options);
        }
    } else if path.is_dir() {
        return crate::tiff_stack::read_tiff_dir(path, options);
    }
    let Some(format) = VolumeFormat::from_path(path) else {
        if path.is_dir() {
            return Err(IoError::NotAFile {
                path: path.to_path_buf(),
                what: "volume file".into(),
                kind: "a directory with no .tif/.tiff slices and no DICOM files",
            });
        }
        if crate::dicom::is_dicom_file(path) {
            return crate::dicom::read_dicom_with(path, options);
        }
        return Err(IoError::UnsupportedFormat {
            path: path.to_path_buf(),
            extension: path
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default(),
            supported: SUPPORTED.into(),
        });
    };
    match format {
        VolumeFormat::Nrrd => crate::read_nrrd_with(path, options),
        VolumeFormat::MetaImage => crate::read_metaimage_with(path, options),
        VolumeFormat::Nifti => crate::read_nifti_with(path, options),
        VolumeFormat::Vti => crate::read_vti_with(path, options),
        VolumeFormat::Tiff => crate::read_tiff_with(path, options),
        VolumeFormat::Dicom => crate::dicom::read_dicom_with(path, options),
        VolumeFormat::Zarr => crate::read_zarr_with(path, options),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_by_name() {
        for (name, f) in [
            ("a.nrrd", Some(VolumeFormat::Nrrd)),
            ("a.NHDR", Some(VolumeFormat::Nrrd)),
            ("a.mha", Some(VolumeFormat::MetaImage)),
            ("a.nii", Some(VolumeFormat::Nifti)),
            ("a.Nii.Gz", Some(VolumeFormat::Nifti)),
            ("a.hdr", Some(VolumeFormat::Nifti)),
            ("a.vti", Some(VolumeFormat::Vti)),
            ("a.tif", Some(VolumeFormat::Tiff)),
            ("a.TIFF", Some(VolumeFormat::Tiff)),
            ("a.raw.gz", None),
            ("a.gz", None),
        ] {
            assert_eq!(VolumeFormat::from_path(Path::new(name)), f, "{name}");
        }
        for ext in VOLUME_EXTENSIONS {
            let p = format!("x.{ext}");
            assert!(VolumeFormat::from_path(Path::new(&p)).is_some(), "{p}");
        }
    }

    #[test]
    fn options_that_do_not_apply_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.nrrd");
        std::fs::write(
            &p,
            b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 1 1\nencoding: raw\n\n\x01\x02",
        )
        .unwrap();
        let l = read_volume_with(&p, &ReadOptions::default()).unwrap();
        assert_eq!((l.format.as_str(), l.frames, l.frame), ("NRRD", 1, 0));
        let o = ReadOptions {
            frame: 1,
            ..ReadOptions::default()
        };
        let e = read_volume_with(&p, &o).unwrap_err().to_string();
        assert!(e.contains("frame 1") && e.contains("v.nrrd"), "{e}");
        let o = ReadOptions {
            array: Some("density".into()),
            ..ReadOptions::default()
        };
        let e = read_volume_with(&p, &o).unwrap_err().to_string();
        assert!(e.contains("array") && e.contains(".vti"), "{e}");
        let e = read_volume(dir.path()).unwrap_err().to_string();
        assert!(e.contains("directory"), "{e}");
    }

    /// Issue 28 follow-up: a NaN background (SPM, nibabel's `resampled_anat_moved.nii`) made
    /// the file unreadable; now every format reads it, NaN taken as the lowest finite value,
    /// and says so in its notes.
    #[test]
    fn nan_samples_are_read_and_noted_for_every_format() {
        let dir = tempfile::tempdir().unwrap();
        let nan = f32::NAN;
        let samples = [nan, 2.0, nan, 5.0];
        let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
        let nrrd = dir.path().join("v.nrrd");
        let mut file =
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 4 1 1\nencoding: raw\nendian: little\n\n"
                .to_vec();
        file.extend_from_slice(&bytes);
        std::fs::write(&nrrd, file).unwrap();
        let h = crate::nifti::tests::Hdr::new(&[4, 1, 1], 16);
        let nii = dir.path().join("v.nii");
        std::fs::write(&nii, h.file(&bytes)).unwrap();
        let text = dir.path().join("t.nrrd");
        std::fs::write(
            &text,
            "NRRD0004\ntype: float\ndimension: 3\nsizes: 4 1 1\nencoding: text\n\nnan 2 NaN 5\n",
        )
        .unwrap();
        for p in [&nrrd, &nii, &text] {
            let l = read_volume_with(p, &ReadOptions::default()).unwrap();
            assert_eq!(
                l.volume.to_f32().data(),
                &[2.0, 2.0, 2.0, 5.0],
                "{}",
                p.display()
            );
            let note = "2 samples were NaN, taken as the lowest finite value 2";
            assert!(
                l.notes.iter().any(|n| n == note),
                "{}: {:?}",
                p.display(),
                l.notes
            );
        }
    }

    /// Issue 30 item 4: every reader has the one shape `read_*_with(path, &ReadOptions) ->
    /// LoadedVolume`, refuses the options its format cannot honour itself (as the dispatcher
    /// did for it), and reports format and notes as through the dispatcher.
    #[test]
    fn every_reader_has_one_shape_and_refuses_what_does_not_apply() {
        let dir = tempfile::tempdir().unwrap();
        let nrrd = dir.path().join("v.nrrd");
        std::fs::write(
            &nrrd,
            b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 1 1\nencoding: raw\n\n\x01\x02",
        )
        .unwrap();
        let mha = dir.path().join("v.mha");
        let mut bytes = b"ObjectType = Image\nNDims = 3\nDimSize = 2 1 1\n\
            ElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
            .to_vec();
        bytes.extend([1u8, 2]);
        std::fs::write(&mha, bytes).unwrap();
        let raw = dir.path().join("v.raw");
        std::fs::write(&raw, [1u8, 2]).unwrap();
        let spec = crate::RawSpec::new([2, 1, 1], volsplat_core::ScalarType::U8);
        type Reader<'a> = Box<dyn Fn(&ReadOptions) -> Result<LoadedVolume> + 'a>;
        let readers: [(&str, Reader); 3] = [
            ("NRRD", Box::new(|o| crate::read_nrrd_with(&nrrd, o))),
            (
                "MetaImage",
                Box::new(|o| crate::read_metaimage_with(&mha, o)),
            ),
            ("raw", Box::new(|o| crate::read_raw_with(&raw, &spec, o))),
        ];
        for (format, read) in &readers {
            let l = read(&ReadOptions::default()).unwrap();
            assert_eq!(l.format, *format);
            assert_eq!((l.frames, l.frame), (1, 0));
            assert_eq!(l.volume.to_f32().data(), &[1.0, 2.0], "{format}");
            let small = Limits {
                max_voxels: 1,
                ..Limits::default()
            };
            let e = read(&ReadOptions::default().with_limits(small)).unwrap_err();
            assert!(
                e.to_string().contains("exceeds the limit 1"),
                "{format}: {e}"
            );
            let o = ReadOptions {
                frame: 1,
                ..ReadOptions::default()
            };
            let e = read(&o).unwrap_err().to_string();
            assert!(e.contains("frame 1") && e.contains("holds 1 frame"), "{e}");
            let o = ReadOptions {
                array: Some("a".into()),
                ..ReadOptions::default()
            };
            let e = read(&o).unwrap_err().to_string();
            assert!(
                e.contains(&format!(".vti files only, not to {format}")),
                "{e}"
            );
            let o = ReadOptions {
                series: Some("1".into()),
                ..ReadOptions::default()
            };
            let e = read(&o).unwrap_err().to_string();
            assert!(e.contains("series applies to DICOM"), "{e}");
        }
        // Through the dispatcher, the same volume and notes as from the reader.
        for p in [&nrrd, &mha] {
            let direct = match VolumeFormat::from_path(p) {
                Some(VolumeFormat::Nrrd) => crate::read_nrrd_with(p, &ReadOptions::default()),
                _ => crate::read_metaimage_with(p, &ReadOptions::default()),
            }
            .unwrap();
            assert_eq!(
                read_volume_with(p, &ReadOptions::default()).unwrap(),
                direct
            );
        }
        // The NRRD reader's own note (no `space` field) comes with its result.
        let l = crate::read_nrrd_with(&nrrd, &ReadOptions::default()).unwrap();
        assert!(
            l.notes.iter().any(|n| n.contains("no `space` field")),
            "{:?}",
            l.notes
        );
    }

    /// Issue 30 item 4: `ReadOptions` is `#[non_exhaustive]`; the `with_*` methods set each
    /// field and nothing else.
    #[test]
    fn read_options_builders_set_one_field_each() {
        let limits = Limits::default().with_max_voxels(5);
        let o = ReadOptions::default()
            .with_frame(2)
            .with_array(Some("a".into()))
            .with_series(Some("7".into()))
            .with_limits(limits.clone());
        assert_eq!(
            o,
            ReadOptions {
                limits,
                frame: 2,
                array: Some("a".into()),
                series: Some("7".into()),
                level: 0,
                channel: 0,
                timepoint: 0,
            }
        );
        let z = ReadOptions::default()
            .with_level(2)
            .with_channel(1)
            .with_timepoint(3);
        assert_eq!((z.level, z.channel, z.timepoint), (2, 1, 3));
        assert_eq!(
            z.with_level(0).with_channel(0).with_timepoint(0),
            ReadOptions::default()
        );
        let back = o.with_array(None).with_series(None).with_frame(0);
        assert_eq!(back.limits.max_voxels, 5);
        assert_eq!(back.with_limits(Limits::default()), ReadOptions::default());
    }

    #[test]
    fn nifti_through_the_dispatcher() {
        let dir = tempfile::tempdir().unwrap();
        let h = crate::nifti::tests::Hdr::new(&[2, 1, 1, 2], 2);
        let p = dir.path().join("b.nii");
        std::fs::write(&p, h.file(&[1, 2, 3, 4])).unwrap();
        let o = ReadOptions {
            frame: 1,
            ..ReadOptions::default()
        };
        let l = read_volume_with(&p, &o).unwrap();
        assert_eq!(l.format, "NIfTI-1");
        assert_eq!((l.frames, l.frame), (2, 1));
        assert_eq!(l.volume.to_f32().data(), &[3.0, 4.0]);
        assert_eq!(read_volume(&p).unwrap().to_f32().data(), &[1.0, 2.0]);
    }
}

/// Corrupted files never panic (a small, deterministic fuzz pass over each reader; the
/// `fuzz/` targets of issue 13 go further).
#[cfg(test)]
mod corruption {
    use super::*;
    use std::io::Write;

    fn mutations(seed: u64, valid: &[u8], n: usize) -> Vec<Vec<u8>> {
        let mut state = seed | 1;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        (0..n)
            .map(|k| {
                let mut b = valid.to_vec();
                match k % 4 {
                    0 => b.truncate(rnd() as usize % (valid.len() + 1)),
                    1 => {
                        for _ in 0..1 + rnd() % 8 {
                            let i = rnd() as usize % b.len();
                            b[i] = rnd() as u8;
                        }
                    }
                    2 => {
                        // Overwrite a random 8-byte run with an extreme value.
                        let i = rnd() as usize % b.len();
                        let v = [0xFFu8, 0x7F, 0x80, 0x00][rnd() as usize % 4];
                        for x in b.iter_mut().skip(i).take(8) {
                            *x = v;
                        }
                    }
                    _ => {
                        let i = rnd() as usize % b.len();
                        b.insert(i, rnd() as u8);
                    }
                }
                b
            })
            .collect()
    }

    fn gz(data: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    /// One small valid file of each volume format (written in `dir` where a writer needs a
    /// file).
    fn valid_files(dir: &Path) -> Vec<(&'static str, Vec<u8>)> {
        let mut valid: Vec<(&str, Vec<u8>)> = Vec::new();
        let mut h = crate::nifti::tests::Hdr::new(&[3, 2, 2, 2], 4);
        h.qform_code = 1;
        h.quatern = [0.1, 0.2, 0.3];
        h.slope = 2.0;
        valid.push(("a.nii", h.file(&[1u8; 48])));
        let mut h2 = h.clone();
        h2.v2 = true;
        h2.vox_offset = 544.0;
        h2.sform_code = 1;
        h2.srow = [
            [2.0, 0.0, 0.0, 1.0],
            [0.0, 3.0, 0.0, 2.0],
            [0.0, 0.0, 4.0, 3.0],
        ];
        valid.push(("b.nii", h2.file(&[2u8; 48])));
        valid.push(("c.nii.gz", gz(&h.file(&[1u8; 48]))));
        valid.push((
            "d.nrrd",
            b"NRRD0004\ntype: short\ndimension: 3\nspace: RAS\nsizes: 2 2 2\n\
              space directions: (1,0,0) (0,2,0) (0,0,3)\nendian: little\nencoding: raw\n\n"
                .iter()
                .copied()
                .chain([7u8; 16])
                .collect(),
        ));
        let data: Vec<u8> = (0..12u32).flat_map(|i| (i as f32).to_le_bytes()).collect();
        let z = {
            let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
            e.write_all(&data).unwrap();
            e.finish().unwrap()
        };
        let mut header = Vec::new();
        for w in [1u32, 48, 48, z.len() as u32] {
            header.extend(w.to_le_bytes());
        }
        let mut vti = b"<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" \
            header_type=\"UInt32\" compressor=\"vtkZLibDataCompressor\"><ImageData \
            WholeExtent=\"0 2 0 1 0 1\" Origin=\"0 0 0\" Spacing=\"1 1 1\"><Piece \
            Extent=\"0 2 0 1 0 1\"><PointData><DataArray type=\"Float32\" Name=\"a\" \
            format=\"appended\" offset=\"0\"/></PointData></Piece></ImageData>\
            <AppendedData encoding=\"raw\">_"
            .to_vec();
        vti.extend(&header);
        vti.extend(&z);
        vti.extend(b"</AppendedData></VTKFile>");
        valid.push(("e.vti", vti));
        let tif = dir.join("valid.tif");
        {
            let f = std::fs::File::create(&tif).unwrap();
            let mut enc = tiff::encoder::TiffEncoder::new(f).unwrap();
            for k in 0..3u16 {
                enc.write_image::<tiff::encoder::colortype::Gray16>(4, 3, &[k; 12])
                    .unwrap();
            }
        }
        valid.push(("f.tif", std::fs::read(&tif).unwrap()));
        let _ = std::fs::remove_file(&tif);
        let mut ct = crate::dicom::tests::Slice::ct(0.0, 0);
        valid.push(("g.dcm", ct.bytes("1.2.3.1")));
        ct.ts = crate::dicom::tests::RLE;
        valid.push(("h.dcm", ct.bytes("1.2.3.2")));
        valid
    }

    #[test]
    fn corrupted_files_are_errors_or_volumes_never_panics() {
        let dir = tempfile::tempdir().unwrap();
        let valid = valid_files(dir.path());
        for (seed, (name, bytes)) in valid.iter().enumerate() {
            // DICOM files stand for their folder's series: one file per folder.
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            read_volume(&p).unwrap_or_else(|e| panic!("valid {name}: {e}"));
            for (k, m) in mutations(seed as u64 + 17, bytes, 300).iter().enumerate() {
                std::fs::write(&p, m).unwrap();
                let o = ReadOptions {
                    frame: k % 2,
                    ..ReadOptions::default()
                };
                // Either outcome is fine; a panic fails the test.
                let _ = read_volume_with(&p, &o);
            }
        }
    }

    /// Seeds for the cargo-fuzz targets (`fuzz/seeds/<target>/`): `VOLSPLAT_FUZZ_SEEDS=fuzz/seeds
    /// cargo test -p volsplat-io write_fuzz_seeds -- --ignored`.
    #[test]
    #[ignore]
    fn write_fuzz_seeds() {
        let Some(root) = std::env::var_os("VOLSPLAT_FUZZ_SEEDS") else {
            return;
        };
        let root = std::path::PathBuf::from(root);
        let tmp = tempfile::tempdir().unwrap();
        let target = |name: &str| {
            let ext = name.rsplit_once('.').map(|(_, e)| e).unwrap_or("");
            match ext {
                "nii" | "gz" => "nifti",
                "nrrd" => "nrrd",
                "vti" => "vti",
                "tif" => "tiff",
                "dcm" => "dicom",
                _ => "other",
            }
        };
        let mut all = valid_files(tmp.path());
        all.push((
            "i.mha",
            b"ObjectType = Image\nNDims = 3\nDimSize = 2 2 1\nElementSpacing = 1 2 3\n\
              ElementType = MET_SHORT\nElementDataFile = LOCAL\n"
                .iter()
                .copied()
                .chain([1u8; 8])
                .collect(),
        ));
        use crate::dicom::tests as dt;
        for (name, ts) in [
            ("j.dcm", dt::JPEG_BASELINE),
            ("k.dcm", dt::DEFLATED),
            ("l.dcm", dt::IMPLICIT_LE),
            ("m.dcm", dt::EXPLICIT_BE),
        ] {
            let mut s = dt::Slice::ct(0.0, 0);
            s.ts = ts;
            if ts == dt::JPEG_BASELINE {
                s.bits = 8;
                s.values = (0..12).map(|p| p * 20).collect();
            }
            all.push((name, s.bytes("1.2.3.9")));
        }
        for (name, mut bytes) in all {
            let t = if name.ends_with(".mha") {
                "metaimage"
            } else {
                target(name)
            };
            if t == "nifti" {
                // The nifti target's first byte chooses .nii.gz (odd) or .nii (even).
                bytes.insert(0, u8::from(name.ends_with(".gz")));
            }
            let d = root.join(t);
            std::fs::create_dir_all(&d).unwrap();
            std::fs::write(d.join(name), bytes).unwrap();
        }
        let npy = tmp.path().join("a.npy");
        crate::write_npy_scalar(&npy, &volsplat_core::ScalarImage::new(3, 2)).unwrap();
        let d = root.join("npy");
        std::fs::create_dir_all(&d).unwrap();
        std::fs::copy(&npy, d.join("a.npy")).unwrap();
        for (t, name, text) in [
            (
                "camera",
                "c.json",
                r#"{ "position": [394.4, 802.9, 284.5], "focal_point": [122.0, 122.0, 80.25],
                  "view_up": [0, 0, 1], "parallel_projection": true, "parallel_scale": 194.1,
                  "view_angle": 30.0 }"#,
            ),
            (
                "transfer_function",
                "t.json",
                r#"{ "color": [[-1024, 0, 0, 0], [400, 1.0, 0.9, 0.75], [3071, 1, 1, 1]],
                  "scalar_opacity": [[-1024, 0.0], [400, 0.3], [3071, 0.9]],
                  "gradient_opacity": [[0, 1.0], [500, 1.0]],
                  "scalar_opacity_unit_distance": 1.0, // comment
                  "shade": false, "ambient": 0.1, "diffuse": 0.7, "specular": 0.2,
                  "specular_power": 10.0 }"#,
            ),
        ] {
            let d = root.join(t);
            std::fs::create_dir_all(&d).unwrap();
            std::fs::write(d.join(name), text).unwrap();
        }
    }
}
