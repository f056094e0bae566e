//! DICOM series (PS3.3 image objects stored as PS3.10 files), read with dicom-rs
//! (`dicom-object` parses; pixel data is decoded here): a folder of slices, a list of files, or
//! one file standing for its series. Decision 0012.
//!
//! # Which files
//!
//! - A **folder** is searched (and its sub-folders, up to 8 levels; symbolic links to folders
//!   are not followed) for DICOM files: files with `DICM` at byte 128 (PS3.10 §7.1), or at byte
//!   0 for files without a preamble. Other files are ignored (a note counts them), and so are
//!   DICOM objects that hold no image (no `Rows`/`Columns`: structured reports, presentation
//!   states, `DICOMDIR`).
//! - Images are grouped by **SeriesInstanceUID** (0020,000E). [`ReadOptions::series`] chooses
//!   one, by its UID or by its SeriesNumber (0020,0011) where that is unique; a folder holding
//!   several series with none chosen is an [`IoError::DicomSeries`] error listing each series
//!   with its description and slice count. [`list_dicom_series`] lists them.
//! - **One file** (`.dcm`, or any file with the DICOM magic) stands for its series: the series
//!   is read from the file's folder (not its sub-folders).
//!
//! # Geometry (PS3.3 §C.7.6.2.1.1, Image Plane Module; world frame LPS)
//!
//! DICOM's patient coordinate system is LPS, volsplat's world frame (DESIGN.md §3, decision
//! 0008), so nothing is converted.
//!
//! - ImageOrientationPatient (0020,0037) gives the row direction `r` (the direction of
//!   increasing column index, grid axis i) and the column direction `c` (increasing row index,
//!   axis j); the slice normal is `n = r × c`. The direction matrix is `[r, c, n]` (columns),
//!   orthonormalised; `r` and `c` must be unit vectors and perpendicular to within 1e-3.
//! - Slices are **sorted by ImagePositionPatient (0020,0032) projected on `n`**, increasing;
//!   never by file name or InstanceNumber. The origin is the first sorted slice's position (the
//!   centre of its first transmitted pixel, PS3.3 §C.7.6.2.1.1).
//! - The **spacing between slices** comes from those projections (their total extent over the
//!   number of gaps), not from SliceThickness (0018,0050), which is the thickness of the
//!   imaged slab and may differ (overlapping or gapped acquisitions); a note reports both.
//!   PixelSpacing (0028,0030) is `[row spacing (between rows, along j), column spacing (along
//!   i)]` (PS3.3 §10.7.1.3).
//! - **Errors**, each naming the files involved: slices of different Rows/Columns or pixel
//!   spacing (relative 1e-3); different orientations (a component differing by more than
//!   1e-3, e.g. a three-plane localizer); two slices at one position (several echoes, time
//!   points or stacks in one series); a **missing slice** (a gap that is a multiple of the
//!   median gap); **unequal gaps** (a gap differing from the median by more than
//!   [`GAP_TOLERANCE`] of it); **gantry tilt** or another shear (a slice's position off the
//!   stack axis through the first slice by more than a tenth of the smallest pixel spacing plus
//!   1e-3 of its distance along `n`; volsplat's grids are orthogonal).
//! - One slice: the slice spacing is SpacingBetweenSlices (0018,0088), else SliceThickness, else
//!   1 (with a note). A single image without position or orientation gets origin 0 and
//!   identity direction (with a note); several images without them are an error.
//!
//! # Enhanced multi-frame images (PS3.3 §C.7.6.16, Multi-frame Functional Groups)
//!
//! Enhanced CT/MR/PET and legacy converted enhanced images are read frame by frame: each
//! frame's PlanePositionSequence (0020,9113), PlaneOrientationSequence (0020,9116),
//! PixelMeasuresSequence (0028,9110) and PixelValueTransformationSequence (0028,9145) come from
//! the PerFrameFunctionalGroupsSequence (5200,9230) item, else the
//! SharedFunctionalGroupsSequence (5200,9229), else the top-level attributes; frames are then
//! sorted and checked like single-frame slices. Multi-frame images without per-frame positions
//! (cine, ultrasound, nuclear medicine) are an error. Frames at repeated positions (several
//! stacks or time points) are the error above.
//!
//! # Samples (PS3.3 §C.7.6.3, Image Pixel Module; PS3.3 §C.11.1.1, Modality LUT)
//!
//! - One sample per pixel, MONOCHROME1 or MONOCHROME2 (MONOCHROME1 is kept as stored, with a
//!   note: low values display bright); Bits Allocated 8, 16 or 32; the stored value is bits
//!   `HighBit − BitsStored + 1 ..= HighBit`, two's complement when PixelRepresentation is 1.
//! - RescaleSlope (0028,1053) and RescaleIntercept (0028,1052) are applied per slice:
//!   `value = stored · slope + intercept`. When every slope is 1, every intercept an integer and
//!   every slice at most 16 bits, values stay integers and the volume takes the first type that
//!   holds their range among the stored type, i16 and u16 (CT in Hounsfield units: i16); else
//!   it is f32 (a note says so; integers beyond 2²⁴ in magnitude lose precision).
//!
//! # Transfer syntaxes (PS3.5 §10, Annex A)
//!
//! Implicit VR little endian, explicit VR little and big endian, deflated explicit VR little
//! endian, encapsulated uncompressed, deflated image frames, RLE lossless (PS3.5 Annex G), and
//! JPEG baseline (process 1), extended (processes 2 & 4, 8-bit samples only) and lossless
//! (process 14, also selection value 1) through the pure-Rust `jpeg-decoder`. Others (JPEG-LS,
//! JPEG 2000, HTJ2K, JPEG XL, MPEG, 12-bit lossy JPEG) are an error naming the syntax.
//!
//! # Limits and malformed files
//!
//! Each file is read whole into memory, at most 4 bytes per voxel of the voxel limit plus 64
//! MiB, and its structure is checked before parsing (see `walk.rs`): every declared length
//! must lie within the file, sequences nest at most 32 deep. Rows × Columns × slices is checked
//! against [`crate::Limits`] before the volume is allocated; decoders never produce more than
//! one frame's samples. A truncated or corrupt file is an error naming the file.

mod pixels;
#[cfg(test)]
pub(crate) mod tests;
mod walk;

use crate::error::{IoError, Result};
use crate::limits::{Limits, checked_dims};
use crate::{LoadedVolume, ReadOptions};
use dicom_core::Tag;
use dicom_object::file::ReadPreamble;
use dicom_object::{InMemDicomObject, OpenFileOptions};
use pixels::{PixelCoding, PixelFormat};
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{AnyVolume, Grid, Volume};

/// Largest relative difference between a gap and the median gap between slices before the
/// stack is refused as unequally spaced (1 %).
pub const GAP_TOLERANCE: f64 = 0.01;

/// Folder levels searched below the folder given.
const MAX_DEPTH: usize = 8;
/// Bytes read first when only the header is needed.
const HEADER_PREFIX: u64 = 1 << 20;
/// Bytes allowed for elements other than pixel data in one file.
const OTHER_BYTES: u64 = 64 << 20;

/// One series found in a folder, for listings (`info`) and error messages.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct DicomSeries {
    /// SeriesInstanceUID (0020,000E).
    pub uid: String,
    /// SeriesNumber (0020,0011), if present.
    pub number: Option<i64>,
    /// SeriesDescription (0008,103E), empty if absent.
    pub description: String,
    /// Modality (0008,0060), e.g. `CT`, `MR`; empty if absent.
    pub modality: String,
    /// Number of images (frames of all its files): the slices of a volume.
    pub images: usize,
    /// Number of files.
    pub files: usize,
}

impl std::fmt::Display for DicomSeries {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.uid)?;
        if let Some(n) = self.number {
            write!(f, " (#{n})")?;
        }
        let desc = if self.description.is_empty() {
            "no description"
        } else {
            &self.description
        };
        write!(
            f,
            " {:?}, {}{}{} image{} in {} file{}",
            desc,
            self.modality,
            if self.modality.is_empty() { "" } else { ", " },
            self.images,
            if self.images == 1 { "" } else { "s" },
            self.files,
            if self.files == 1 { "" } else { "s" }
        )
    }
}

/// Reads the DICOM series at `path` (a folder holding one series, or one file of a series)
/// with default options. See the [module documentation](self).
pub fn read_dicom(path: impl AsRef<Path>) -> Result<AnyVolume> {
    read_dicom_with(path, &ReadOptions::default()).map(|l| l.volume)
}

/// Reads a DICOM series from a folder, or the series of one file (from the file's folder);
/// `options.series` chooses among several. The result carries every series found
/// ([`LoadedVolume::series`]) and the UID read ([`LoadedVolume::series_uid`]).
pub fn read_dicom_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let path = path.as_ref();
    if options.frame != 0 {
        return Err(IoError::invalid_argument(
            path,
            "frame",
            format!(
                "frame {} requested, but a DICOM series is read as one volume (frame 0)",
                options.frame
            ),
        ));
    }
    if path.is_dir() {
        let scan = scan_dir(path, MAX_DEPTH, &options.limits)?;
        read_scanned(path, scan, options.series.as_deref(), None, &options.limits)
    } else {
        let own = match read_header(path, &options.limits)? {
            Header::Image(h) => *h,
            Header::NotImage => {
                return Err(IoError::Dicom {
                    path: path.to_path_buf(),
                    message: "the file holds no image (no Rows/Columns)".into(),
                });
            }
            Header::NotDicom => return Err(not_dicom(path)),
        };
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let uid = own.series_uid.clone();
        // The file's own folder only, not its sub-folders.
        let mut scan = scan_dir(&dir, 0, &options.limits)?;
        if !scan.headers.iter().any(|h| h.path == own.path) {
            scan.headers.push(own);
        }
        read_scanned(
            path,
            scan,
            options.series.as_deref(),
            Some(&uid),
            &options.limits,
        )
    }
}

/// Reads a DICOM series from a list of files (every file must be DICOM); `options.series`
/// chooses when they hold several series. Messages name the first file.
pub fn read_dicom_files(files: &[PathBuf], options: &ReadOptions) -> Result<LoadedVolume> {
    let Some(first) = files.first() else {
        return Err(IoError::invalid_argument(
            Path::new(""),
            "files",
            "no DICOM files given",
        ));
    };
    if options.frame != 0 {
        return Err(IoError::invalid_argument(
            first,
            "frame",
            "a DICOM series is read as one volume (frame 0)",
        ));
    }
    let mut scan = Scan::default();
    for f in files {
        match read_header(f, &options.limits)? {
            Header::Image(h) => scan.headers.push(*h),
            Header::NotImage => scan.non_images += 1,
            Header::NotDicom => return Err(not_dicom(f)),
        }
    }
    read_scanned(
        first,
        scan,
        options.series.as_deref(),
        None,
        &options.limits,
    )
}

/// The image series in a folder (and its sub-folders), or in the folder of a DICOM file (not
/// its sub-folders), ordered by SeriesNumber then UID. Only headers are read.
pub fn list_dicom_series(path: impl AsRef<Path>, limits: &Limits) -> Result<Vec<DicomSeries>> {
    let path = path.as_ref();
    let (dir, depth) = if path.is_dir() {
        (path.to_path_buf(), MAX_DEPTH)
    } else {
        match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => (p.to_path_buf(), 0),
            _ => (PathBuf::from("."), 0),
        }
    };
    let scan = scan_dir(&dir, depth, limits)?;
    Ok(series_list(&group(&scan.headers)))
}

/// Whether `path` is a regular file starting like a DICOM file (`DICM` at byte 128, or at 0).
pub fn is_dicom_file(path: impl AsRef<Path>) -> bool {
    let path = path.as_ref();
    let Ok(meta) = std::fs::metadata(path) else {
        return false;
    };
    if !meta.is_file() {
        return false;
    }
    let mut head = Vec::new();
    match std::fs::File::open(path) {
        Ok(f) => {
            if f.take(132).read_to_end(&mut head).is_err() {
                return false;
            }
        }
        Err(_) => return false,
    }
    dicm_offset(&head).is_some()
}

/// Whether a folder holds a DICOM file (searched as [`read_dicom_with`] does, giving up after
/// 10 000 other files).
pub(crate) fn dir_has_dicom(dir: &Path) -> Result<bool> {
    let mut found = false;
    let mut seen = 0usize;
    visit(dir, 0, MAX_DEPTH, &mut |p| {
        seen += 1;
        if is_dicom_file(p) {
            found = true;
        }
        !found && seen < 10_000
    })?;
    Ok(found)
}

fn not_dicom(path: &Path) -> IoError {
    IoError::Dicom {
        path: path.to_path_buf(),
        message: "not a DICOM file (no `DICM` magic at byte 128 or 0; PS3.10 §7.1)".into(),
    }
}

fn dicm_offset(head: &[u8]) -> Option<usize> {
    if head.len() >= 132 && &head[128..132] == b"DICM" {
        Some(128)
    } else if head.len() >= 4 && &head[..4] == b"DICM" {
        Some(0)
    } else {
        None
    }
}

/// Calls `f` on each regular file below `dir` (sorted, hidden entries skipped; sub-folders down
/// to `max_depth` levels, symbolic links to folders not followed) until it returns false.
fn visit(
    dir: &Path,
    depth: usize,
    max_depth: usize,
    f: &mut dyn FnMut(&Path) -> bool,
) -> Result<bool> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| IoError::os(dir, "list folder", e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            !p.file_name()
                .map(|n| n.to_string_lossy().starts_with('.'))
                .unwrap_or(true)
        })
        .collect();
    entries.sort();
    for p in entries {
        let Ok(meta) = std::fs::symlink_metadata(&p) else {
            continue;
        };
        if meta.is_dir() {
            if depth < max_depth && !visit(&p, depth + 1, max_depth, f)? {
                return Ok(false);
            }
        } else if (meta.is_file() || (meta.file_type().is_symlink() && p.is_file())) && !f(&p) {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Headers found by a scan.
#[derive(Default)]
struct Scan {
    headers: Vec<FileHeader>,
    /// Files that are not DICOM.
    ignored: usize,
    /// DICOM files without an image.
    non_images: usize,
}

fn scan_dir(dir: &Path, max_depth: usize, limits: &Limits) -> Result<Scan> {
    let mut scan = Scan::default();
    let mut error = None;
    visit(dir, 0, max_depth, &mut |p| {
        match read_header(p, limits) {
            Ok(Header::Image(h)) => scan.headers.push(*h),
            Ok(Header::NotImage) => scan.non_images += 1,
            Ok(Header::NotDicom) => scan.ignored += 1,
            Err(e) => {
                error = Some(e);
                return false;
            }
        }
        true
    })?;
    if let Some(e) = error {
        return Err(e);
    }
    Ok(scan)
}

fn group(headers: &[FileHeader]) -> BTreeMap<String, Vec<&FileHeader>> {
    let mut g: BTreeMap<String, Vec<&FileHeader>> = BTreeMap::new();
    for h in headers {
        g.entry(h.series_uid.clone()).or_default().push(h);
    }
    g
}

fn series_list(groups: &BTreeMap<String, Vec<&FileHeader>>) -> Vec<DicomSeries> {
    let mut v: Vec<DicomSeries> = groups
        .iter()
        .map(|(uid, hs)| {
            let first = hs[0];
            DicomSeries {
                uid: uid.clone(),
                number: first.series_number,
                description: first.description.clone(),
                modality: first.modality.clone(),
                images: hs.iter().map(|h| h.frames as usize).sum(),
                files: hs.len(),
            }
        })
        .collect();
    v.sort_by(|a, b| {
        (a.number.unwrap_or(i64::MAX), &a.uid).cmp(&(b.number.unwrap_or(i64::MAX), &b.uid))
    });
    v
}

/// Chooses a series and reads it.
fn read_scanned(
    path: &Path,
    scan: Scan,
    want: Option<&str>,
    default_uid: Option<&str>,
    limits: &Limits,
) -> Result<LoadedVolume> {
    let groups = group(&scan.headers);
    let list = series_list(&groups);
    if groups.is_empty() {
        return Err(IoError::Dicom {
            path: path.to_path_buf(),
            message: format!(
                "no DICOM images found ({} DICOM files without images, {} other files)",
                scan.non_images, scan.ignored
            ),
        });
    }
    let uid: String = match want {
        Some(w) => {
            let w = w.trim();
            if groups.contains_key(w) {
                w.to_string()
            } else if let Ok(n) = w.parse::<i64>() {
                let hits: Vec<&DicomSeries> = list.iter().filter(|s| s.number == Some(n)).collect();
                match hits.as_slice() {
                    [one] => one.uid.clone(),
                    [] => {
                        return Err(IoError::DicomSeries {
                            path: path.to_path_buf(),
                            reason: format!("no series with UID or number {w:?}"),
                            series: list,
                        });
                    }
                    _ => {
                        return Err(IoError::DicomSeries {
                            path: path.to_path_buf(),
                            reason: format!(
                                "several series have number {n}; choose one by its UID"
                            ),
                            series: list,
                        });
                    }
                }
            } else {
                return Err(IoError::DicomSeries {
                    path: path.to_path_buf(),
                    reason: format!("no series with UID or number {w:?}"),
                    series: list,
                });
            }
        }
        None => match default_uid {
            Some(u) => u.to_string(),
            None if groups.len() == 1 => list[0].uid.clone(),
            None => {
                return Err(IoError::DicomSeries {
                    path: path.to_path_buf(),
                    reason: format!(
                        "{} DICOM series found; choose one by its UID or number (`--series`)",
                        groups.len()
                    ),
                    series: list,
                });
            }
        },
    };
    let Some(files) = groups.get(&uid) else {
        return Err(IoError::DicomSeries {
            path: path.to_path_buf(),
            reason: format!("no series with UID {uid:?}"),
            series: list,
        });
    };
    let mut notes = Vec::new();
    if let Some(s) = list.iter().find(|s| s.uid == uid) {
        notes.push(format!("DICOM series {s}"));
    }
    if groups.len() > 1 {
        notes.push(format!(
            "{} other series in the folder (see the series list)",
            groups.len() - 1
        ));
    }
    if scan.ignored > 0 {
        notes.push(format!("{} non-DICOM files ignored", scan.ignored));
    }
    if scan.non_images > 0 {
        notes.push(format!(
            "{} DICOM files without images ignored",
            scan.non_images
        ));
    }
    let volume = read_series(files, limits, &mut notes)?;
    Ok(LoadedVolume {
        volume,
        format: "DICOM".into(),
        frames: 1,
        frame: 0,
        arrays: Vec::new(),
        series: list,
        series_uid: Some(uid),
        notes,
    })
}

// ---------------------------------------------------------------------------------------------
// Headers

/// An attribute: tag and keyword, for lookups and messages.
#[derive(Debug, Clone, Copy)]
struct Attr(u16, u16, &'static str);

impl Attr {
    fn tag(self) -> Tag {
        Tag(self.0, self.1)
    }
    fn label(self) -> String {
        format!("{} ({:04X},{:04X})", self.2, self.0, self.1)
    }
}

const SOP_CLASS: Attr = Attr(0x0008, 0x0016, "SOPClassUID");
const MODALITY: Attr = Attr(0x0008, 0x0060, "Modality");
const SERIES_DESCRIPTION: Attr = Attr(0x0008, 0x103E, "SeriesDescription");
const SLICE_THICKNESS: Attr = Attr(0x0018, 0x0050, "SliceThickness");
const SPACING_BETWEEN: Attr = Attr(0x0018, 0x0088, "SpacingBetweenSlices");
const GANTRY_TILT: Attr = Attr(0x0018, 0x1120, "GantryDetectorTilt");
const SERIES_UID: Attr = Attr(0x0020, 0x000E, "SeriesInstanceUID");
const SERIES_NUMBER: Attr = Attr(0x0020, 0x0011, "SeriesNumber");
const IPP: Attr = Attr(0x0020, 0x0032, "ImagePositionPatient");
const IOP: Attr = Attr(0x0020, 0x0037, "ImageOrientationPatient");
const SAMPLES: Attr = Attr(0x0028, 0x0002, "SamplesPerPixel");
const PHOTOMETRIC: Attr = Attr(0x0028, 0x0004, "PhotometricInterpretation");
const FRAMES: Attr = Attr(0x0028, 0x0008, "NumberOfFrames");
const ROWS: Attr = Attr(0x0028, 0x0010, "Rows");
const COLUMNS: Attr = Attr(0x0028, 0x0011, "Columns");
const PIXEL_SPACING: Attr = Attr(0x0028, 0x0030, "PixelSpacing");
const BITS_ALLOCATED: Attr = Attr(0x0028, 0x0100, "BitsAllocated");
const BITS_STORED: Attr = Attr(0x0028, 0x0101, "BitsStored");
const HIGH_BIT: Attr = Attr(0x0028, 0x0102, "HighBit");
const PIXEL_REPRESENTATION: Attr = Attr(0x0028, 0x0103, "PixelRepresentation");
const INTERCEPT: Attr = Attr(0x0028, 0x1052, "RescaleIntercept");
const SLOPE: Attr = Attr(0x0028, 0x1053, "RescaleSlope");
const SHARED_GROUPS: Attr = Attr(0x5200, 0x9229, "SharedFunctionalGroupsSequence");
const PER_FRAME_GROUPS: Attr = Attr(0x5200, 0x9230, "PerFrameFunctionalGroupsSequence");
const PLANE_POSITION: Attr = Attr(0x0020, 0x9113, "PlanePositionSequence");
const PLANE_ORIENTATION: Attr = Attr(0x0020, 0x9116, "PlaneOrientationSequence");
const PIXEL_MEASURES: Attr = Attr(0x0028, 0x9110, "PixelMeasuresSequence");
const VALUE_TRANSFORM: Attr = Attr(0x0028, 0x9145, "PixelValueTransformationSequence");
const FLOAT_PIXEL_DATA: Attr = Attr(0x7FE0, 0x0008, "FloatPixelData");
const DOUBLE_PIXEL_DATA: Attr = Attr(0x7FE0, 0x0009, "DoubleFloatPixelData");

/// The geometry and value transform of one frame, as found (validated later).
#[derive(Debug, Clone, PartialEq)]
struct FrameGeom {
    ipp: Option<[f64; 3]>,
    iop: Option<[f64; 6]>,
    /// PixelSpacing as stored: [between rows, between columns].
    pixel_spacing: Option<[f64; 2]>,
    slope: f64,
    intercept: f64,
}

/// What a scan keeps of one image file.
#[derive(Debug, Clone)]
struct FileHeader {
    path: PathBuf,
    series_uid: String,
    series_number: Option<i64>,
    description: String,
    modality: String,
    ts_uid: String,
    ts_name: String,
    rows: u16,
    cols: u16,
    samples: Option<u16>,
    photometric: String,
    bits_allocated: Option<u16>,
    bits_stored: Option<u16>,
    high_bit: Option<u16>,
    pixel_representation: Option<u16>,
    float_pixels: bool,
    frames: u32,
    geom: Vec<FrameGeom>,
    thickness: Option<f64>,
    spacing_between: Option<f64>,
    tilt: Option<f64>,
    enhanced: bool,
}

enum Header {
    Image(Box<FileHeader>),
    NotImage,
    NotDicom,
}

/// The most bytes of one DICOM file read into memory.
fn file_cap(limits: &Limits) -> u64 {
    let px = limits.voxel_limit().saturating_mul(4);
    u64::try_from(px)
        .unwrap_or(u64::MAX)
        .saturating_add(OTHER_BYTES)
}

/// A file's bytes from its `DICM` magic on.
struct Loaded {
    bytes: Vec<u8>,
    /// Whether the whole file was read (not a prefix).
    whole: bool,
    /// Where `DICM` starts in the file (128, or 0 without a preamble).
    offset: u64,
}

/// Reads `path` from its `DICM` magic on: the first `prefix` bytes, or all of it. `None` when
/// the file does not start like a DICOM file.
fn load(path: &Path, limits: &Limits, prefix: Option<u64>) -> Result<Option<Loaded>> {
    crate::limits::require_regular_file(path, "DICOM file")?;
    let f = std::fs::File::open(path).map_err(|e| IoError::os(path, "open", e))?;
    let len = f
        .metadata()
        .map_err(|e| IoError::os(path, "stat", e))?
        .len();
    let cap = file_cap(limits);
    let want = match prefix {
        Some(p) if p < len => p,
        _ => {
            if len > cap {
                return Err(IoError::TooLarge {
                    path: path.to_path_buf(),
                    what: "DICOM file size in bytes (4 bytes per voxel of the voxel limit + 64 \
                           MiB)"
                        .into(),
                    value: len as u128,
                    limit: cap as u128,
                });
            }
            len
        }
    };
    let mut bytes = Vec::new();
    f.take(want)
        .read_to_end(&mut bytes)
        .map_err(|e| IoError::os(path, "read", e))?;
    let Some(off) = dicm_offset(&bytes) else {
        return Ok(None);
    };
    let whole = (bytes.len() as u64) >= len;
    bytes.drain(..off);
    Ok(Some(Loaded {
        bytes,
        whole,
        offset: off as u64,
    }))
}

/// An error's message with its sources (dicom-rs errors keep the cause in `source()`).
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    let mut n = 0;
    while let Some(c) = cur {
        let t = c.to_string();
        if !s.contains(&t) {
            s.push_str(": ");
            s.push_str(&t);
        }
        cur = c.source();
        n += 1;
        if n > 8 {
            break;
        }
    }
    s
}

type DicomFile = dicom_object::FileDicomObject<InMemDicomObject>;

/// Checks and parses DICOM bytes (from `DICM` on).
fn parse(
    path: &Path,
    loaded: &Loaded,
    header_only: bool,
    limits: &Limits,
) -> Result<(DicomFile, walk::Walked)> {
    let bytes = &loaded.bytes[..];
    let walked = walk::walk(path, bytes, loaded.offset, header_only, file_cap(limits))?;
    let mut opts = OpenFileOptions::new().read_preamble(ReadPreamble::Never);
    if header_only {
        opts = opts.read_until(dicom_dictionary_std::tags::PIXEL_DATA);
    }
    let obj = opts.from_reader(bytes).map_err(|e| IoError::Dicom {
        path: path.to_path_buf(),
        message: chain(&e),
    })?;
    Ok((obj, walked))
}

/// Reads and parses a file's header (all but the pixel data).
fn read_header(path: &Path, limits: &Limits) -> Result<Header> {
    let Some(first) = load(path, limits, Some(HEADER_PREFIX))? else {
        return Ok(Header::NotDicom);
    };
    let parsed = match parse(path, &first, true, limits) {
        Ok(p) => p,
        Err(_) if !first.whole => {
            let Some(all) = load(path, limits, None)? else {
                return Ok(Header::NotDicom);
            };
            parse(path, &all, true, limits)?
        }
        Err(e) => return Err(e),
    };
    header_of(path, &parsed.0, &parsed.1)
}

fn elem_text(obj: &InMemDicomObject, a: Attr) -> Option<String> {
    let e = obj.get(a.tag())?;
    let s = e.to_str().ok()?;
    let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    Some(s.to_string())
}

fn text_or_empty(obj: &InMemDicomObject, a: Attr) -> String {
    elem_text(obj, a).unwrap_or_default()
}

/// A multi-valued decimal attribute of exactly `n` finite numbers; `None` when absent or empty.
fn numbers(path: &Path, obj: &InMemDicomObject, a: Attr, n: usize) -> Result<Option<Vec<f64>>> {
    let Some(t) = elem_text(obj, a) else {
        return Ok(None);
    };
    if t.is_empty() {
        return Ok(None);
    }
    let mut v = Vec::with_capacity(n);
    for part in t.split('\\') {
        let x: f64 = part.trim().parse().map_err(|_| {
            IoError::field(path, a.label(), &t, format!("{:?} is not a number", part))
        })?;
        if !x.is_finite() {
            return Err(IoError::field(path, a.label(), &t, "values must be finite"));
        }
        v.push(x);
    }
    if v.len() != n {
        return Err(IoError::field(
            path,
            a.label(),
            &t,
            format!("{n} values expected, found {}", v.len()),
        ));
    }
    Ok(Some(v))
}

fn number(path: &Path, obj: &InMemDicomObject, a: Attr) -> Result<Option<f64>> {
    Ok(numbers(path, obj, a, 1)?.map(|v| v[0]))
}

fn integer(path: &Path, obj: &InMemDicomObject, a: Attr) -> Result<Option<i64>> {
    let Some(t) = elem_text(obj, a) else {
        return Ok(None);
    };
    if t.is_empty() {
        return Ok(None);
    }
    t.parse::<i64>()
        .map(Some)
        .map_err(|_| IoError::field(path, a.label(), &t, "not an integer"))
}

fn u16_attr(path: &Path, obj: &InMemDicomObject, a: Attr) -> Result<Option<u16>> {
    match integer(path, obj, a)? {
        None => Ok(None),
        Some(v) => u16::try_from(v)
            .map(Some)
            .map_err(|_| IoError::field(path, a.label(), &v.to_string(), "must be 0 to 65535")),
    }
}

/// The first item of sequence `a` in `obj`.
fn item(obj: &InMemDicomObject, a: Attr) -> Option<&InMemDicomObject> {
    obj.get(a.tag())?.items()?.first()
}

/// Geometry and value transform of a frame from functional-group items (PS3.3 §C.7.6.16):
/// per-frame item first, then shared, then the top level.
fn frame_geom(
    path: &Path,
    top: &InMemDicomObject,
    per: Option<&InMemDicomObject>,
    shared: Option<&InMemDicomObject>,
) -> Result<FrameGeom> {
    let lookup = |seq: Attr| -> Option<&InMemDicomObject> {
        per.and_then(|p| item(p, seq))
            .or_else(|| shared.and_then(|s| item(s, seq)))
    };
    let from = |seq: Attr, a: Attr, n: usize| -> Result<Option<Vec<f64>>> {
        if let Some(it) = lookup(seq)
            && let Some(v) = numbers(path, it, a, n)?
        {
            return Ok(Some(v));
        }
        numbers(path, top, a, n)
    };
    let ipp = from(PLANE_POSITION, IPP, 3)?.map(|v| [v[0], v[1], v[2]]);
    let iop = from(PLANE_ORIENTATION, IOP, 6)?.map(|v| [v[0], v[1], v[2], v[3], v[4], v[5]]);
    let ps = from(PIXEL_MEASURES, PIXEL_SPACING, 2)?.map(|v| [v[0], v[1]]);
    if let Some(p) = ps
        && !(p[0] > 0.0 && p[1] > 0.0)
    {
        return Err(IoError::field(
            path,
            PIXEL_SPACING.label(),
            &format!("{}\\{}", p[0], p[1]),
            "spacings must be positive",
        ));
    }
    let slope = from(VALUE_TRANSFORM, SLOPE, 1)?.map_or(1.0, |v| v[0]);
    let intercept = from(VALUE_TRANSFORM, INTERCEPT, 1)?.map_or(0.0, |v| v[0]);
    Ok(FrameGeom {
        ipp,
        iop,
        pixel_spacing: ps,
        slope,
        intercept,
    })
}

fn header_of(path: &Path, obj: &DicomFile, walked: &walk::Walked) -> Result<Header> {
    let top: &InMemDicomObject = obj;
    let sop = elem_text(top, SOP_CLASS)
        .unwrap_or_else(|| obj.meta().media_storage_sop_class_uid().to_string());
    let sop = sop.trim_end_matches('\0');
    // DICOMDIR (Media Storage Directory Storage) and other objects without an image.
    if sop == "1.2.840.10008.1.3.10" {
        return Ok(Header::NotImage);
    }
    let (Some(rows), Some(cols)) = (u16_attr(path, top, ROWS)?, u16_attr(path, top, COLUMNS)?)
    else {
        return Ok(Header::NotImage);
    };
    if rows == 0 || cols == 0 {
        return Err(IoError::field(
            path,
            "Rows/Columns (0028,0010/0011)",
            &format!("{rows}/{cols}"),
            "must be at least 1",
        ));
    }
    let series_uid = elem_text(top, SERIES_UID)
        .filter(|s| !s.is_empty())
        .ok_or_else(|| IoError::missing(path, SERIES_UID.label()))?;
    let frames = match integer(path, top, FRAMES)? {
        None => 1,
        Some(n) if (1..=i64::from(u32::MAX)).contains(&n) => n as u32,
        Some(n) => {
            return Err(IoError::field(
                path,
                FRAMES.label(),
                &n.to_string(),
                "must be at least 1",
            ));
        }
    };
    let shared = item(top, SHARED_GROUPS);
    let per_frame = top.get(PER_FRAME_GROUPS.tag()).and_then(|e| e.items());
    let enhanced = per_frame.is_some() || shared.is_some();
    let mut geom = Vec::new();
    if let Some(items) = per_frame {
        if items.len() != frames as usize {
            return Err(IoError::field(
                path,
                PER_FRAME_GROUPS.label(),
                &format!("{} items", items.len()),
                format!("one item per frame expected ({frames} frames)"),
            ));
        }
        for it in items {
            geom.push(frame_geom(path, top, Some(it), shared)?);
        }
    } else {
        let g = frame_geom(path, top, None, shared)?;
        if frames > 1 {
            // Without per-frame positions all frames would share one position: refused when
            // the series is read (several frames at one position), listed meanwhile.
            geom = vec![g; frames.min(1 << 16) as usize];
        } else {
            geom.push(g);
        }
    }
    Ok(Header::Image(Box::new(FileHeader {
        path: path.to_path_buf(),
        series_uid,
        series_number: integer(path, top, SERIES_NUMBER).ok().flatten(),
        description: text_or_empty(top, SERIES_DESCRIPTION),
        modality: text_or_empty(top, MODALITY),
        ts_uid: walked.ts_uid.clone(),
        ts_name: walked.ts_name.clone(),
        rows,
        cols,
        samples: u16_attr(path, top, SAMPLES)?,
        photometric: text_or_empty(top, PHOTOMETRIC),
        bits_allocated: u16_attr(path, top, BITS_ALLOCATED)?,
        bits_stored: u16_attr(path, top, BITS_STORED)?,
        high_bit: u16_attr(path, top, HIGH_BIT)?,
        pixel_representation: u16_attr(path, top, PIXEL_REPRESENTATION)?,
        float_pixels: top.get(FLOAT_PIXEL_DATA.tag()).is_some()
            || top.get(DOUBLE_PIXEL_DATA.tag()).is_some(),
        frames,
        geom,
        thickness: number(path, top, SLICE_THICKNESS).ok().flatten(),
        spacing_between: number(path, top, SPACING_BETWEEN).ok().flatten(),
        tilt: number(path, top, GANTRY_TILT).ok().flatten(),
        enhanced,
    })))
}

impl FileHeader {
    /// The validated pixel layout (PS3.3 §C.7.6.3.1).
    fn pixel_format(&self) -> Result<PixelFormat> {
        let p = &self.path;
        if self.float_pixels {
            return Err(IoError::unsupported(
                p,
                FLOAT_PIXEL_DATA.label(),
                "present",
                "integer PixelData (7FE0,0010)",
            ));
        }
        let spp = self.samples.unwrap_or(1);
        if spp != 1 {
            return Err(IoError::unsupported(
                p,
                SAMPLES.label(),
                &spp.to_string(),
                "1 (grayscale)",
            ));
        }
        let pi = self.photometric.as_str();
        if !(pi.is_empty() || pi == "MONOCHROME1" || pi == "MONOCHROME2") {
            return Err(IoError::unsupported(
                p,
                PHOTOMETRIC.label(),
                pi,
                "MONOCHROME1, MONOCHROME2",
            ));
        }
        let ba = self
            .bits_allocated
            .ok_or_else(|| IoError::missing(p, BITS_ALLOCATED.label()))?;
        if !matches!(ba, 8 | 16 | 32) {
            return Err(IoError::unsupported(
                p,
                BITS_ALLOCATED.label(),
                &ba.to_string(),
                "8, 16, 32",
            ));
        }
        let bs = self.bits_stored.unwrap_or(ba);
        if bs == 0 || bs > ba {
            return Err(IoError::field(
                p,
                BITS_STORED.label(),
                &bs.to_string(),
                format!("must be 1 to BitsAllocated ({ba})"),
            ));
        }
        let hb = self.high_bit.unwrap_or(bs - 1);
        if hb + 1 < bs || hb >= ba {
            return Err(IoError::field(
                p,
                HIGH_BIT.label(),
                &hb.to_string(),
                format!(
                    "must be BitsStored − 1 ({}) to BitsAllocated − 1 ({})",
                    bs - 1,
                    ba - 1
                ),
            ));
        }
        let signed = match self.pixel_representation.unwrap_or(0) {
            0 => false,
            1 => true,
            v => {
                return Err(IoError::field(
                    p,
                    PIXEL_REPRESENTATION.label(),
                    &v.to_string(),
                    "must be 0 (unsigned) or 1 (two's complement)",
                ));
            }
        };
        Ok(PixelFormat {
            rows: self.rows,
            cols: self.cols,
            bits_allocated: ba,
            bits_stored: bs,
            high_bit: hb,
            signed,
        })
    }

    fn coding(&self, encapsulated: bool) -> Result<PixelCoding> {
        let big = self.ts_uid == "1.2.840.10008.1.2.2";
        PixelCoding::of(&self.ts_uid, big, encapsulated).ok_or_else(|| {
            IoError::unsupported(
                &self.path,
                "TransferSyntaxUID (0002,0010)",
                &format!("{} ({})", self.ts_uid, self.ts_name),
                "implicit/explicit VR little endian, explicit VR big endian, deflated, \
                 encapsulated uncompressed, deflated image frames, RLE lossless, JPEG baseline, \
                 JPEG extended (8-bit), JPEG lossless; not JPEG-LS, JPEG 2000, HTJ2K, JPEG XL \
                 or video (no pure-Rust decoder is built in)",
            )
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Series geometry and samples

/// One slice: a frame of a file, with its checked geometry.
#[derive(Debug, Clone)]
struct Slice<'a> {
    file: &'a FileHeader,
    frame: u32,
    geom: &'a FrameGeom,
    /// Position along the normal.
    s: f64,
}

fn unit(v: DVec3) -> Option<DVec3> {
    let l = v.length();
    (l.is_finite() && l > 0.0).then(|| v / l)
}

fn describe(sl: &Slice<'_>) -> String {
    let name = sl.file.path.display().to_string();
    if sl.file.frames > 1 {
        format!("{name} frame {}", sl.frame)
    } else {
        name
    }
}

/// Geometry of the sorted stack: grid, and the slices in order.
fn read_series(
    files: &[&FileHeader],
    limits: &Limits,
    notes: &mut Vec<String>,
) -> Result<AnyVolume> {
    let first = files[0];
    let fpath = &first.path;
    let mut slices: Vec<Slice<'_>> = Vec::new();
    for f in files {
        if f.frames > 1 && !f.enhanced {
            return Err(IoError::unsupported(
                &f.path,
                FRAMES.label(),
                &f.frames.to_string(),
                "1, or enhanced multi-frame images with per-frame positions \
                 (PerFrameFunctionalGroupsSequence, PS3.3 §C.7.6.16)",
            ));
        }
        for (k, g) in f.geom.iter().enumerate() {
            slices.push(Slice {
                file: f,
                frame: k as u32,
                geom: g,
                s: 0.0,
            });
        }
    }
    // Same size.
    for sl in &slices {
        if (sl.file.rows, sl.file.cols) != (first.rows, first.cols) {
            return Err(IoError::field(
                &sl.file.path,
                "Rows/Columns (0028,0010/0011)",
                &format!("{}/{}", sl.file.rows, sl.file.cols),
                format!(
                    "slices of different sizes in one series: {} has {}/{}",
                    fpath.display(),
                    first.rows,
                    first.cols
                ),
            ));
        }
    }
    let n = slices.len();
    let g0 = slices[0].geom;
    // Pixel spacing.
    let ps = match g0.pixel_spacing {
        Some(p) => p,
        None => {
            notes.push("no PixelSpacing (0028,0030): pixel spacing 1 assumed".into());
            [1.0, 1.0]
        }
    };
    for sl in &slices {
        let p = sl.geom.pixel_spacing.unwrap_or([1.0, 1.0]);
        if (p[0] - ps[0]).abs() > 1e-3 * ps[0] || (p[1] - ps[1]).abs() > 1e-3 * ps[1] {
            return Err(IoError::field(
                &sl.file.path,
                PIXEL_SPACING.label(),
                &format!("{}\\{}", p[0], p[1]),
                format!(
                    "slices of different pixel spacing in one series: {} has {}\\{}",
                    describe(&slices[0]),
                    ps[0],
                    ps[1]
                ),
            ));
        }
    }
    let has_geometry = slices
        .iter()
        .all(|s| s.geom.ipp.is_some() && s.geom.iop.is_some());
    let (origin, direction, dz, order) = if !has_geometry {
        if n > 1 {
            let bad = slices
                .iter()
                .find(|s| s.geom.ipp.is_none() || s.geom.iop.is_none())
                .map(describe)
                .unwrap_or_default();
            return Err(IoError::Dicom {
                path: fpath.clone(),
                message: format!(
                    "{bad} has no {} or {}: slices cannot be ordered (file names and \
                     InstanceNumber are not used; PS3.3 §C.7.6.2)",
                    IPP.label(),
                    IOP.label()
                ),
            });
        }
        notes.push(format!(
            "no {} / {}: origin 0, identity direction",
            IPP.label(),
            IOP.label()
        ));
        (
            DVec3::ZERO,
            DMat3::IDENTITY,
            single_spacing(first, notes),
            vec![0],
        )
    } else {
        stack_geometry(&mut slices, ps, notes)?
    };
    let sorted: Vec<&Slice<'_>> = order.iter().map(|&i| &slices[i]).collect();

    // Grid and limits.
    let dims = checked_dims(
        fpath,
        "Columns × Rows × slices",
        &format!("{} × {} × {}", first.cols, first.rows, n),
        [first.cols as u64, first.rows as u64, n as u64],
        limits,
    )?;
    let grid = Grid::new(dims, [ps[1], ps[0], dz], origin.to_array(), direction)
        .map_err(|e| IoError::core(fpath, e))?;

    // Value type.
    let mut formats = BTreeMap::new();
    for f in files {
        formats.insert(f.path.as_path(), f.pixel_format()?);
    }
    let integral = sorted.iter().all(|s| {
        s.geom.slope == 1.0
            && s.geom.intercept.fract() == 0.0
            && s.geom.intercept.abs() <= 1e9
            && formats
                .get(s.file.path.as_path())
                .is_some_and(|f| f.bits_allocated <= 16)
    });
    let rescaled = sorted
        .iter()
        .any(|s| s.geom.slope != 1.0 || s.geom.intercept != 0.0);
    if rescaled {
        let (a, b) = (sorted[0].geom.slope, sorted[0].geom.intercept);
        let same = sorted
            .iter()
            .all(|s| s.geom.slope == a && s.geom.intercept == b);
        notes.push(if same {
            format!("RescaleSlope {a} and RescaleIntercept {b} applied: value = stored · slope + intercept")
        } else {
            "RescaleSlope/RescaleIntercept applied per slice (they differ between slices)".into()
        });
    }
    let names: std::collections::BTreeSet<&str> =
        files.iter().map(|f| f.ts_name.as_str()).collect();
    notes.push(format!(
        "transfer syntax: {}",
        names.into_iter().collect::<Vec<_>>().join(", ")
    ));
    if files.iter().any(|f| f.photometric == "MONOCHROME1") {
        notes.push(
            "MONOCHROME1: low values display bright; samples kept as stored (after rescale)".into(),
        );
    }

    // Decode, file by file (each file parsed once), into the sorted positions.
    let plane = first.rows as usize * first.cols as usize;
    let mut slot_of: BTreeMap<(&Path, u32), usize> = BTreeMap::new();
    for (k, s) in sorted.iter().enumerate() {
        slot_of.insert((s.file.path.as_path(), s.frame), k);
    }
    let total = dims[0] * dims[1] * dims[2];
    let mut ints: Vec<i32> = Vec::new();
    let mut floats: Vec<f32> = Vec::new();
    if integral {
        ints = vec![0; total];
    } else {
        floats = vec![0.0; total];
    }
    let mut buf: Vec<i64> = Vec::with_capacity(plane);
    for f in files {
        let Some(loaded) = load(&f.path, limits, None)? else {
            return Err(not_dicom(&f.path));
        };
        let (obj, _) = parse(&f.path, &loaded, false, limits)?;
        drop(loaded);
        let fmt = formats
            .get(f.path.as_path())
            .copied()
            .ok_or_else(|| not_dicom(&f.path))?;
        let encapsulated = matches!(
            obj.get(dicom_dictionary_std::tags::PIXEL_DATA)
                .map(|e| e.value()),
            Some(dicom_core::value::Value::PixelSequence(_))
        );
        let coding = f.coding(encapsulated)?;
        for (frame, g) in f.geom.iter().enumerate() {
            let frame = frame as u32;
            let Some(&k) = slot_of.get(&(f.path.as_path(), frame)) else {
                continue;
            };
            pixels::decode_frame(&f.path, &obj, coding, &fmt, f.frames, frame, &mut buf)?;
            if buf.len() != plane {
                return Err(IoError::Dicom {
                    path: f.path.clone(),
                    message: format!(
                        "frame {frame} decoded to {} samples, {plane} expected",
                        buf.len()
                    ),
                });
            }
            let dst = k * plane..(k + 1) * plane;
            if integral {
                let icpt = g.intercept as i64;
                for (d, &v) in ints[dst].iter_mut().zip(&buf) {
                    // |v| < 2³², |icpt| ≤ 1e9: fits i64; clamped into i32 (never reached for
                    // ≤ 16-bit samples).
                    *d = (v + icpt).clamp(i32::MIN as i64, i32::MAX as i64) as i32;
                }
            } else {
                for (d, &v) in floats[dst].iter_mut().zip(&buf) {
                    let x = v as f64 * g.slope + g.intercept;
                    if !(x.is_finite() && x.abs() <= f32::MAX as f64) {
                        return Err(IoError::field(
                            &f.path,
                            SLOPE.label(),
                            &format!("{} (intercept {})", g.slope, g.intercept),
                            format!("stored value {v} rescales to {x}, outside the f32 range"),
                        ));
                    }
                    *d = x as f32;
                }
            }
        }
    }
    if !integral {
        if !rescaled || sorted.iter().any(|s| s.geom.slope.fract() == 0.0) {
            notes.push("samples stored as f32".into());
        }
        let big = floats.iter().any(|v| v.abs() > (1 << 24) as f32);
        if big && rescaled {
            notes.push("values beyond 2²⁴ in magnitude are rounded to f32".into());
        }
        return Volume::new(grid, floats)
            .map(AnyVolume::from)
            .map_err(|e| IoError::core(fpath, e));
    }
    let (lo, hi) = ints
        .iter()
        .fold((i32::MAX, i32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    let stored = formats
        .get(fpath.as_path())
        .map(|f| match (f.bits_allocated, f.signed) {
            (8, false) => volsplat_core::ScalarType::U8,
            (8, true) => volsplat_core::ScalarType::I8,
            (_, false) => volsplat_core::ScalarType::U16,
            (_, true) => volsplat_core::ScalarType::I16,
        })
        .unwrap_or(volsplat_core::ScalarType::I16);
    use volsplat_core::ScalarType as St;
    let fits = |t: St| match t {
        St::U8 => lo >= 0 && hi <= u8::MAX as i32,
        St::I8 => lo >= i8::MIN as i32 && hi <= i8::MAX as i32,
        St::U16 => lo >= 0 && hi <= u16::MAX as i32,
        St::I16 => lo >= i16::MIN as i32 && hi <= i16::MAX as i32,
        St::F32 => true,
    };
    let chosen = [stored, St::I16, St::U16]
        .into_iter()
        .find(|&t| fits(t))
        .unwrap_or(St::F32);
    let core = |e| IoError::core(fpath, e);
    Ok(match chosen {
        St::U8 => AnyVolume::from(
            Volume::new(grid, ints.into_iter().map(|v| v as u8).collect()).map_err(core)?,
        ),
        St::I8 => AnyVolume::from(
            Volume::new(grid, ints.into_iter().map(|v| v as i8).collect()).map_err(core)?,
        ),
        St::U16 => AnyVolume::from(
            Volume::new(grid, ints.into_iter().map(|v| v as u16).collect()).map_err(core)?,
        ),
        St::I16 => AnyVolume::from(
            Volume::new(grid, ints.into_iter().map(|v| v as i16).collect()).map_err(core)?,
        ),
        St::F32 => {
            notes.push(format!(
                "values {lo} … {hi} fit no 16-bit type: stored as f32"
            ));
            AnyVolume::from(
                Volume::new(grid, ints.into_iter().map(|v| v as f32).collect()).map_err(core)?,
            )
        }
    })
}

/// Slice spacing of a single image: SpacingBetweenSlices, else SliceThickness, else 1.
fn single_spacing(f: &FileHeader, notes: &mut Vec<String>) -> f64 {
    if let Some(s) = f.spacing_between.filter(|s| *s > 0.0) {
        notes.push(format!(
            "one slice: slice spacing {s} from {}",
            SPACING_BETWEEN.label()
        ));
        s
    } else if let Some(s) = f.thickness.filter(|s| *s > 0.0) {
        notes.push(format!(
            "one slice: slice spacing {s} from {}",
            SLICE_THICKNESS.label()
        ));
        s
    } else {
        notes.push("one slice: slice spacing 1 assumed".into());
        1.0
    }
}

/// Orientation, sorting and spacing checks (PS3.3 §C.7.6.2.1.1). Returns the origin, the
/// direction, the slice spacing and the slice order.
fn stack_geometry(
    slices: &mut [Slice<'_>],
    ps: [f64; 2],
    notes: &mut Vec<String>,
) -> Result<(DVec3, DMat3, f64, Vec<usize>)> {
    let g0 = slices[0].geom;
    let first = &slices[0];
    let iop = g0.iop.unwrap_or([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    let iop_text = format!(
        "{}\\{}\\{}\\{}\\{}\\{}",
        iop[0], iop[1], iop[2], iop[3], iop[4], iop[5]
    );
    let r_raw = DVec3::new(iop[0], iop[1], iop[2]);
    let c_raw = DVec3::new(iop[3], iop[4], iop[5]);
    let bad_iop = |why: &str| IoError::field(&first.file.path, IOP.label(), &iop_text, why);
    if (r_raw.length() - 1.0).abs() > 1e-3 || (c_raw.length() - 1.0).abs() > 1e-3 {
        return Err(bad_iop(
            "the row and column direction cosines must be unit vectors",
        ));
    }
    if r_raw.dot(c_raw).abs() > 1e-3 {
        return Err(bad_iop(
            "the row and column directions must be perpendicular",
        ));
    }
    let r = unit(r_raw).ok_or_else(|| bad_iop("not a direction"))?;
    let c = unit(c_raw - c_raw.dot(r) * r).ok_or_else(|| bad_iop("not a direction"))?;
    let nrm = r.cross(c);
    // Same orientation everywhere.
    for sl in slices.iter() {
        let o = sl.geom.iop.unwrap_or(iop);
        if o.iter().zip(&iop).any(|(a, b)| (a - b).abs() > 1e-3) {
            return Err(IoError::field(
                &sl.file.path,
                IOP.label(),
                &format!("{}\\{}\\{}\\{}\\{}\\{}", o[0], o[1], o[2], o[3], o[4], o[5]),
                format!(
                    "slices of different orientations in one series ({} has {iop_text}); a \
                     localizer or a multi-planar series cannot be one volume",
                    describe(first)
                ),
            ));
        }
    }
    for sl in slices.iter_mut() {
        let p = sl.geom.ipp.unwrap_or([0.0; 3]);
        sl.s = DVec3::from(p).dot(nrm);
    }
    let mut order: Vec<usize> = (0..slices.len()).collect();
    order.sort_by(|&a, &b| slices[a].s.total_cmp(&slices[b].s));
    let pos = |i: usize| DVec3::from(slices[i].geom.ipp.unwrap_or([0.0; 3]));
    let origin = pos(order[0]);
    let direction = DMat3::from_cols(r, c, nrm);
    let n = order.len();
    if n == 1 {
        let dz = single_spacing(slices[0].file, notes);
        return Ok((origin, direction, dz, order));
    }
    let gaps: Vec<f64> = order
        .windows(2)
        .map(|w| slices[w[1]].s - slices[w[0]].s)
        .collect();
    let mut sorted_gaps = gaps.clone();
    sorted_gaps.sort_by(f64::total_cmp);
    let median = sorted_gaps[sorted_gaps.len() / 2];
    let min_px = ps[0].min(ps[1]);
    // Duplicates: positions closer than 1e-3 of a pixel... or of the median gap.
    let same_tol = (1e-3 * median.max(min_px)).max(1e-6);
    for (k, &g) in gaps.iter().enumerate() {
        if g <= same_tol {
            let (a, b) = (&slices[order[k]], &slices[order[k + 1]]);
            return Err(IoError::field(
                &b.file.path,
                IPP.label(),
                &fmt3(pos(order[k + 1])),
                format!(
                    "{} and {} lie at the same position along the slice normal: several \
                     acquisitions (echoes, time points, stacks) in one series",
                    describe(a),
                    describe(b)
                ),
            ));
        }
    }
    for (k, &g) in gaps.iter().enumerate() {
        if (g - median).abs() > GAP_TOLERANCE * median {
            let (a, b) = (&slices[order[k]], &slices[order[k + 1]]);
            let m = (g / median).round();
            let reason = if m >= 2.0 && (g - m * median).abs() <= GAP_TOLERANCE * median {
                format!(
                    "missing slice{}: {} slice{} between {} (at {:.4}) and {} (at {:.4}) along \
                     the normal; the other slices are {:.4} apart",
                    if m > 2.0 { "s" } else { "" },
                    m - 1.0,
                    if m > 2.0 { "s" } else { "" },
                    describe(a),
                    a.s,
                    describe(b),
                    b.s,
                    median
                )
            } else {
                format!(
                    "unequal gaps between slices: {} and {} are {:.4} apart along the normal, \
                     the median gap is {:.4} (tolerance {} %)",
                    describe(a),
                    describe(b),
                    g,
                    median,
                    GAP_TOLERANCE * 100.0
                )
            };
            return Err(IoError::field(
                &b.file.path,
                IPP.label(),
                &fmt3(pos(order[k + 1])),
                reason,
            ));
        }
    }
    // Gantry tilt / shear: positions off the axis through the first slice along the normal.
    let p0 = origin;
    for &i in &order[1..] {
        let d = pos(i) - p0;
        let along = d.dot(nrm);
        let off = (d - along * nrm).length();
        if off > 0.1 * min_px + 1e-3 * along.abs() {
            let sl = &slices[i];
            let angle = (off / along.abs().max(f64::MIN_POSITIVE))
                .atan()
                .to_degrees();
            let tilt = sl
                .file
                .tilt
                .map(|t| format!("; {} is {t}", GANTRY_TILT.label()))
                .unwrap_or_default();
            return Err(IoError::field(
                &sl.file.path,
                IPP.label(),
                &fmt3(pos(i)),
                format!(
                    "gantry tilt or sheared stack: {} lies {off:.4} off the axis through the \
                     first slice along the slice normal ({angle:.2}° tilt{tilt}); \
                     volsplat's grids are orthogonal, resample the series first",
                    describe(sl)
                ),
            ));
        }
    }
    let dz = (slices[order[n - 1]].s - slices[order[0]].s) / (n - 1) as f64;
    let thick = slices[0]
        .file
        .thickness
        .map(|t| format!(" (SliceThickness {t})"))
        .unwrap_or_default();
    notes.push(format!(
        "{n} slices sorted by ImagePositionPatient along the slice normal; spacing between \
         slices {dz:.6} from their positions{thick}"
    ));
    Ok((origin, direction, dz, order))
}

fn fmt3(v: DVec3) -> String {
    format!("{}\\{}\\{}", v.x, v.y, v.z)
}

/// The series as one line for messages: `uid (#n) "description", CT, 120 images in 120 files;
/// …`.
pub(crate) fn series_summary(series: &[DicomSeries]) -> String {
    if series.is_empty() {
        return "none".into();
    }
    series
        .iter()
        .map(|s| s.to_string())
        .collect::<Vec<_>>()
        .join("; ")
}
