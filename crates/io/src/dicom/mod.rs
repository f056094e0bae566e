//! DICOM series (PS3.3 image objects stored as PS3.10 files), read with dicom-rs
//! (`dicom-object` parses; pixel data is decoded here): a folder of slices, a list of files, or
//! one file standing for its series. Decisions 0013 and 0026.
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
//!   is read from the file's folder (not its sub-folders). A file without SeriesInstanceUID is
//!   read alone.
//! - **One bad file never stops a scan** (issue 28). A file whose header cannot be read, or
//!   without SeriesInstanceUID, is skipped with a note naming it and why (five are named, then
//!   a count). A file of a known series that cannot be read (pixel data shorter than its image,
//!   a malformed attribute, frames without positions) fails that series only, with its own
//!   error, and not even that when a good file holds the same SOPInstanceUID. Copies of one
//!   instance (same SOPInstanceUID and geometry) are read once, the file given first; a
//!   `DICOMDIR` is recognised by its meta group and not parsed.
//!
//! # Geometry (PS3.3 §C.7.6.2.1.1, Image Plane Module; world frame LPS)
//!
//! DICOM's patient coordinate system is LPS, volsplat's world frame (docs/design.md §3, decision
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
//! sorted and checked like single-frame slices. A sequence with more items than frames uses the
//! first ones (a note says so). Classic multi-frame images placed by GridFrameOffsetVector
//! (3004,000C) (RT Dose, PS3.3 §C.8.8.3.2) are volumes too: frame k lies at
//! ImagePositionPatient + offset_k along the normal when the first offset is 0, else at z =
//! offset_k (axial frames only); DoseGridScaling (3004,000E) multiplies the values (into
//! DoseUnits). Multi-frame images without per-frame positions (cine, ultrasound, nuclear
//! medicine) are refused when scanned. Frames at repeated positions (several stacks or time
//! points) are the error above.
//!
//! # Samples (PS3.3 §C.7.6.3, Image Pixel Module; PS3.3 §C.11.1.1, Modality LUT)
//!
//! - One sample per pixel, MONOCHROME1 or MONOCHROME2 (MONOCHROME1 is kept as stored, with a
//!   note: low values display bright), or PALETTE COLOR with a grey palette (red, green and
//!   blue tables equal; values are mapped through it, PS3.3 §C.7.6.3.1.5). Colour images (RGB,
//!   YBR, colour palettes) are an error. Bits Allocated 1 (native syntaxes), 8, 16 or 32; the
//!   stored value is bits `HighBit − BitsStored + 1 ..= HighBit`, two's complement when
//!   PixelRepresentation is 1.
//! - RescaleSlope (0028,1053) and RescaleIntercept (0028,1052) are applied per slice:
//!   `value = stored · slope + intercept`. When every slope is 1, every intercept an integer and
//!   every slice at most 16 bits, values stay integers and the volume takes the first type that
//!   holds their range among the stored type, i16 and u16 (CT in Hounsfield units: i16); else
//!   it is f32 (a note says so; integers beyond 2²⁴ in magnitude lose precision).
//!
//! # Transfer syntaxes (PS3.5 §10, Annex A)
//!
//! Implicit VR little endian, explicit VR little and big endian, deflated explicit VR little
//! endian, encapsulated uncompressed, deflated image frames, RLE lossless (PS3.5 Annex G), JPEG
//! baseline (process 1), extended (processes 2 & 4, 8- and 12-bit samples), progressive 8-bit
//! and lossless (process 14, also selection value 1), JPEG-LS lossless and near-lossless,
//! JPEG 2000 lossless and lossy — all decoded by pure-Rust crates (`codecs.rs`, decision 0026).
//! HTJ2K, JPEG XL and video are an error naming the syntax. Attributes stored with VR UN are
//! read by their dictionary VR; a data set written in the other VR encoding than its meta
//! group declares is read as written (a note says so).
//!
//! # Limits and malformed files
//!
//! Each file is read whole into memory, at most 4 bytes per voxel of the voxel limit plus 64
//! MiB, and its structure is checked before parsing (see `walk.rs`): every declared length
//! must lie within the file, sequences nest at most 32 deep; a deflated data set inflates at
//! most to the image it declares plus 64 MiB. Pixel data shorter than the frames it must hold
//! is refused from the header. Rows × Columns × slices is checked against [`crate::Limits`];
//! the volume is allocated (fallibly) once the first frame has decoded; each codestream's own
//! header must match Rows, Columns and Samples per Pixel before its decoder runs, so decoders
//! never produce more than one frame's samples, and a panic inside a third-party decoder
//! becomes an error. A truncated or corrupt file is an error naming the file.

mod codecs;
mod header;
mod pixels;
mod series;
#[cfg(test)]
pub(crate) mod tests;
#[cfg(test)]
mod tests_robust;
mod walk;

use crate::error::{IoError, Result};
use crate::limits::{Limits, checked_dims};
use crate::{LoadedVolume, ReadOptions};
use dicom_core::Tag;
use dicom_object::file::ReadPreamble;
use dicom_object::{InMemDicomObject, OpenFileOptions};
use header::{BrokenFile, FileHeader, Header, read_header};
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
    options.refuse_array(path, "DICOM")?;
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
    crate::confine::Confinement::of(path, &options.limits)?;
    if path.is_dir() {
        let scan = scan_dir(path, MAX_DEPTH, &options.limits);
        read_scanned(path, scan, options.series.as_deref(), None, &options.limits)
    } else {
        let own = match read_header(path, &options.limits)? {
            Header::Image(h) => *h,
            Header::Broken(b) => return Err(b.error),
            Header::NotImage => {
                return Err(IoError::Dicom {
                    path: path.to_path_buf(),
                    message: "the file holds no image (no Rows/Columns)".into(),
                });
            }
            Header::NotDicom => return Err(not_dicom(path)),
        };
        let uid = own.series_uid.clone();
        if uid.is_empty() {
            // No series to look for: the file alone.
            let mut scan = Scan::default();
            scan.notes.push(format!(
                "no {}: the file is read alone, without its folder",
                header::SERIES_UID.label()
            ));
            scan.headers.push(own);
            return read_scanned(path, scan, None, Some(""), &options.limits);
        }
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        // The file's own folder only, not its sub-folders.
        let mut scan = scan_dir(&dir, 0, &options.limits);
        scan.given = Some(own.path.clone());
        scan.headers.retain(|h| !same_file(&h.path, &own.path));
        scan.headers.insert(0, own);
        read_scanned(
            path,
            scan,
            options.series.as_deref(),
            Some(&uid),
            &options.limits,
        )
    }
}

/// Whether two paths name one file (the given path and its folder's listing may differ in
/// spelling).
fn same_file(a: &Path, b: &Path) -> bool {
    a == b
        || matches!(
            (std::fs::canonicalize(a), std::fs::canonicalize(b)),
            (Ok(x), Ok(y)) if x == y
        )
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
    options.refuse_array(first, "DICOM")?;
    if options.frame != 0 {
        return Err(IoError::invalid_argument(
            first,
            "frame",
            "a DICOM series is read as one volume (frame 0)",
        ));
    }
    let mut scan = Scan::default();
    for f in files {
        crate::confine::Confinement::of(f, &options.limits)?;
        match read_header(f, &options.limits)? {
            Header::Image(h) => scan.headers.push(*h),
            Header::Broken(b) => scan.broken.push(*b),
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
    let scan = scan_dir(&dir, depth, limits);
    if let Some(e) = scan.error {
        return Err(e);
    }
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
    /// Files of a known series that cannot be read: an error when their series is read (unless
    /// a good file holds the same instance), a note otherwise.
    broken: Vec<BrokenFile>,
    /// DICOM files whose header cannot be read at all (series unknown), with why.
    skipped: Vec<(PathBuf, IoError)>,
    /// Files that are not DICOM.
    ignored: usize,
    /// DICOM files without an image.
    non_images: usize,
    /// The folder could not be listed.
    error: Option<IoError>,
    /// The file given, when one was (it wins over copies of its instance).
    given: Option<PathBuf>,
    /// Notes from the scan itself.
    notes: Vec<String>,
}

/// Scans a folder's DICOM files. A file that cannot be read never stops the scan (issue 28):
/// it is kept as broken (its series known) or skipped, and only fails the read of its series.
/// When the read is confined to a folder ([`Limits::confine_to`]), files that lead out of it
/// (symbolic links) are not read, and a note says how many.
fn scan_dir(dir: &Path, max_depth: usize, limits: &Limits) -> Scan {
    let mut scan = Scan::default();
    let confine = match crate::confine::Confinement::of(dir, limits) {
        Ok(c) => c,
        Err(e) => {
            scan.error = Some(e);
            return scan;
        }
    };
    let mut outside = 0usize;
    let r = visit(dir, 0, max_depth, &mut |p| {
        if confine.as_ref().is_some_and(|c| !c.contains(p)) {
            outside += 1;
            return true;
        }
        match read_header(p, limits) {
            Ok(Header::Image(h)) if h.series_uid.is_empty() => scan.skipped.push((
                p.to_path_buf(),
                IoError::missing(p, header::SERIES_UID.label()),
            )),
            Ok(Header::Image(h)) => scan.headers.push(*h),
            Ok(Header::Broken(b)) if b.series.is_empty() => scan.skipped.push((b.path, b.error)),
            Ok(Header::Broken(b)) => scan.broken.push(*b),
            Ok(Header::NotImage) => scan.non_images += 1,
            Ok(Header::NotDicom) => scan.ignored += 1,
            Err(e) => scan.skipped.push((p.to_path_buf(), e)),
        }
        true
    });
    if let Err(e) = r {
        scan.error = Some(e);
    }
    if let (Some(folder), true) = (&limits.confine_to, outside > 0) {
        scan.notes.push(format!(
            "{outside} file(s) leading out of {} (symbolic links) were not read: reads there \
             are confined to it",
            folder.display()
        ));
    }
    scan
}

/// The most files named one by one in a note.
const LISTED: usize = 5;

/// "a.dcm (why); b.dcm (why); and 3 more".
fn list_files<'a>(items: impl Iterator<Item = (&'a Path, String)>) -> String {
    let all: Vec<(&Path, String)> = items.collect();
    let mut parts: Vec<String> = all
        .iter()
        .take(LISTED)
        .map(|(p, why)| format!("{} ({why})", header::file_name(p)))
        .collect();
    if all.len() > LISTED {
        parts.push(format!("and {} more", all.len() - LISTED));
    }
    parts.join("; ")
}

/// An error's message without the file name it starts with (the list names the file).
fn reason(e: &IoError, path: &Path) -> String {
    let t = e.to_string();
    let prefix = format!("{}: ", path.display());
    t.strip_prefix(&prefix).map_or(t.clone(), str::to_string)
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
    mut scan: Scan,
    want: Option<&str>,
    default_uid: Option<&str>,
    limits: &Limits,
) -> Result<LoadedVolume> {
    if let Some(e) = scan.error.take() {
        return Err(e);
    }
    let headers = std::mem::take(&mut scan.headers);
    let groups = group(&headers);
    let list = series_list(&groups);
    // A series asked for (or the only one) whose files are all broken: the first one's error.
    if groups.is_empty() {
        let only = scan.broken.first().map(|b| b.series.clone());
        let target = want
            .map(str::trim)
            .map(str::to_string)
            .or_else(|| only.filter(|u| scan.broken.iter().all(|b| &b.series == u)));
        if let Some(k) = target.as_deref().and_then(|u| broken_of(&scan, u)) {
            return Err(scan.broken.swap_remove(k).error);
        }
        let mut message = format!(
            "no DICOM images found ({} DICOM files without images, {} other files",
            scan.non_images, scan.ignored
        );
        let unreadable = unreadable_list(&scan, None);
        if !unreadable.is_empty() {
            message.push_str(&format!("; unreadable: {unreadable}"));
        }
        message.push(')');
        return Err(IoError::Dicom {
            path: path.to_path_buf(),
            message,
        });
    }
    let uid = choose_series(path, &groups, &list, want, default_uid).map_err(|e| {
        match want.map(str::trim).and_then(|u| broken_of(&scan, u)) {
            Some(k) => scan.broken.swap_remove(k).error,
            None => e,
        }
    })?;
    let Some(members) = groups.get(&uid) else {
        return Err(IoError::DicomSeries {
            path: path.to_path_buf(),
            reason: format!("no series with UID {uid:?}"),
            series: list,
        });
    };
    let mut notes = std::mem::take(&mut scan.notes);
    // A broken file of this series fails it, unless a good file holds the same instance.
    let good_sops: std::collections::BTreeSet<&str> =
        members.iter().map(|h| h.sop_uid.as_str()).collect();
    let (mine, others): (Vec<BrokenFile>, Vec<BrokenFile>) = std::mem::take(&mut scan.broken)
        .into_iter()
        .partition(|b| b.series == uid);
    scan.broken = others;
    let (copies, bad): (Vec<BrokenFile>, Vec<BrokenFile>) = mine
        .into_iter()
        .partition(|b| !b.sop.is_empty() && good_sops.contains(b.sop.as_str()));
    if let Some(b) = bad.into_iter().next() {
        return Err(b.error);
    }
    if !copies.is_empty() {
        notes.push(format!(
            "skipped {} unreadable cop{} of an instance read from another file: {}",
            copies.len(),
            if copies.len() == 1 { "y" } else { "ies" },
            list_files(
                copies
                    .iter()
                    .map(|b| (b.path.as_path(), reason(&b.error, &b.path)))
            )
        ));
    }
    let files = distinct_instances(members, scan.given.as_deref(), &mut notes);
    if let Some(s) = list.iter().find(|s| s.uid == uid) {
        notes.insert(0, format!("DICOM series {s}"));
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
    let unreadable = unreadable_list(&scan, Some(&uid));
    if !unreadable.is_empty() {
        notes.push(format!(
            "skipped {} unreadable DICOM file(s) not of this series: {unreadable}",
            scan.skipped.len() + scan.broken.len()
        ));
    }
    let volume = series::read_series(&files, limits, &mut notes)?;
    let mut seen = std::collections::BTreeSet::new();
    notes.retain(|n| seen.insert(n.clone()));
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

/// The first broken file of series `uid`.
fn broken_of(scan: &Scan, uid: &str) -> Option<usize> {
    scan.broken.iter().position(|b| b.series == uid)
}

/// The skipped and broken files (those of `except`'s series left out) as a list with reasons.
fn unreadable_list(scan: &Scan, except: Option<&str>) -> String {
    let skipped = scan
        .skipped
        .iter()
        .map(|(p, e)| (p.as_path(), reason(e, p)));
    let broken = scan
        .broken
        .iter()
        .filter(|b| Some(b.series.as_str()) != except)
        .map(|b| (b.path.as_path(), reason(&b.error, &b.path)));
    list_files(skipped.chain(broken))
}

/// One file per SOPInstanceUID (copies of an instance in several transfer syntaxes are one
/// image, not two slices at one position): the file given wins, else the first by path. A
/// file sharing the given file's UID is that instance (UIDs are unique, PS3.5 §9); others are
/// merged only when they are copies (same size, frames and geometry), else all kept (and
/// then checked as slices).
fn distinct_instances<'a>(
    members: &[&'a FileHeader],
    given: Option<&Path>,
    notes: &mut Vec<String>,
) -> Vec<&'a FileHeader> {
    let mut by_sop: BTreeMap<&str, usize> = BTreeMap::new();
    let mut out: Vec<&FileHeader> = Vec::with_capacity(members.len());
    let mut dropped = Vec::new();
    for &h in members {
        if h.sop_uid.is_empty() {
            out.push(h);
            continue;
        }
        let copy = |k: usize| {
            let o: &FileHeader = out[k];
            let is_given = |f: &FileHeader| given.is_some_and(|g| g == f.path);
            is_given(o)
                || is_given(h)
                || (o.rows, o.cols, o.frames, &o.geom) == (h.rows, h.cols, h.frames, &h.geom)
        };
        match by_sop.get(h.sop_uid.as_str()).copied().filter(|&k| copy(k)) {
            None => {
                by_sop.insert(&h.sop_uid, out.len());
                out.push(h);
            }
            Some(k) => {
                let keep_new = given.is_some_and(|g| g == h.path);
                let (kept, gone) = if keep_new { (h, out[k]) } else { (out[k], h) };
                out[k] = kept;
                dropped.push((gone.path.as_path(), header::file_name(&kept.path)));
            }
        }
    }
    if !dropped.is_empty() {
        notes.push(format!(
            "skipped {} cop{} of an instance read from another file (same SOPInstanceUID): {}",
            dropped.len(),
            if dropped.len() == 1 { "y" } else { "ies" },
            list_files(dropped.into_iter().map(|(p, k)| (p, format!("as {k}"))))
        ));
    }
    out
}

/// The series to read: the one asked for (UID, or a unique SeriesNumber), else the given
/// file's, else the only one.
fn choose_series(
    path: &Path,
    groups: &BTreeMap<String, Vec<&FileHeader>>,
    list: &[DicomSeries],
    want: Option<&str>,
    default_uid: Option<&str>,
) -> Result<String> {
    let no_such = |w: &str| IoError::DicomSeries {
        path: path.to_path_buf(),
        reason: format!("no series with UID or number {w:?}"),
        series: list.to_vec(),
    };
    match want {
        Some(w) => {
            let w = w.trim();
            if groups.contains_key(w) {
                return Ok(w.to_string());
            }
            let Ok(n) = w.parse::<i64>() else {
                return Err(no_such(w));
            };
            let hits: Vec<&DicomSeries> = list.iter().filter(|s| s.number == Some(n)).collect();
            match hits.as_slice() {
                [one] => Ok(one.uid.clone()),
                [] => Err(no_such(w)),
                _ => Err(IoError::DicomSeries {
                    path: path.to_path_buf(),
                    reason: format!("several series have number {n}; choose one by its UID"),
                    series: list.to_vec(),
                }),
            }
        }
        None => match default_uid {
            Some(u) => Ok(u.to_string()),
            None if groups.len() == 1 => Ok(list[0].uid.clone()),
            None => Err(IoError::DicomSeries {
                path: path.to_path_buf(),
                reason: format!(
                    "{} DICOM series found; choose one by its UID or number (`--series`)",
                    groups.len()
                ),
                series: list.to_vec(),
            }),
        },
    }
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
