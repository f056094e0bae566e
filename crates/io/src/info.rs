//! A serialisable summary of a volume file, for `volsplat info --json`: [`VolumeInfo`],
//! [`volume_info`].

use crate::error::Result;
use crate::{DicomSeries, LoadedVolume, ReadOptions};
use serde::Serialize;
use std::path::Path;

/// The version of [`VolumeInfo`]'s JSON layout; raised when a field changes meaning or is
/// removed (adding fields keeps it).
pub const VOLUME_INFO_SCHEMA: u32 = 1;

/// What `info` reports about a volume, in world units (usually mm) and the world frame of
/// docs/design.md §3 (LPS for anatomical files, decision 0008). Serialises to stable JSON with
/// these field names; floats reload bit-exactly.
///
/// ```json
/// { "schema": 1, "path": "ct/", "format": "DICOM", "dims": [512, 512, 120],
///   "voxels": 31457280, "scalar_type": "i16", "spacing": [0.7, 0.7, 1.25],
///   "origin": [-180.0, -200.0, -310.5],
///   "direction": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
///   "bounds": [[-180.0, -200.0, -310.5], [177.7, 157.7, -161.75]],
///   "value_range": [-1024.0, 3071.0], "frames": 1, "frame": 0, "arrays": [],
///   "series_uid": "1.2.3", "series": [{ "uid": "1.2.3", "number": 3,
///   "description": "HEAD", "modality": "CT", "images": 120, "files": 120 }],
///   "notes": ["..."], "levels": [] }
/// ```
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VolumeInfo {
    /// [`VOLUME_INFO_SCHEMA`].
    pub schema: u32,
    /// The path as given.
    pub path: String,
    /// The format as read: `NRRD`, `MetaImage`, `NIfTI-1`, `NIfTI-2`, `Analyze 7.5`,
    /// `VTK image data`, `TIFF`, `DICOM`.
    pub format: String,
    /// Samples along i, j, k.
    pub dims: [usize; 3],
    /// The number of voxels, the product of `dims`.
    pub voxels: u64,
    /// Sample type as read: `u8`, `i8`, `u16`, `i16`, `f32`.
    pub scalar_type: String,
    /// Distance between samples along i, j, k.
    pub spacing: [f64; 3],
    /// World position of the centre of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// The 3×3 direction matrix **row by row**: `direction[r][c]` is row `r`, column `c`;
    /// column `c` is the world direction of grid axis `c`. Flattened, this is ITK's and
    /// SimpleITK's `GetDirection()` order.
    pub direction: [[f64; 3]; 3],
    /// Smallest and largest corner of the world bounding box of the voxel centres.
    pub bounds: [[f64; 3]; 2],
    /// Smallest and largest sample, in data units (after any rescaling).
    pub value_range: [f64; 2],
    /// Volumes (frames) in the file; 1 for most files.
    pub frames: usize,
    /// The frame read (0-based).
    pub frame: usize,
    /// Point-data arrays (VTK `.vti`); empty otherwise.
    pub arrays: Vec<String>,
    /// The DICOM SeriesInstanceUID read; absent (`null`) for other formats.
    pub series_uid: Option<String>,
    /// The DICOM image series found beside it; empty for other formats.
    pub series: Vec<DicomSeries>,
    /// Notes from the reader (conversions, assumptions, geometry source).
    pub notes: Vec<String>,
    /// The resolution levels of an OME-Zarr store, full resolution first; empty for other
    /// formats.
    pub levels: Vec<LevelInfo>,
}

/// One level of an OME-Zarr store in [`VolumeInfo::levels`] (from [`crate::ZarrLevel`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LevelInfo {
    /// The array's path inside the store.
    pub path: String,
    /// Samples along x, y, z.
    pub dims: [u64; 3],
    /// Distance between samples along x, y, z (mm).
    pub spacing: [f64; 3],
    /// World position (mm) of sample (0, 0, 0).
    pub origin: [f64; 3],
    /// The array's shape in store order (OME axes order, e.g. t, c, z, y, x).
    pub shape: Vec<u64>,
    /// The chunk (or shard) shape in store order.
    pub chunks: Vec<u64>,
    /// The data type as the store names it.
    pub data_type: String,
}

/// The levels of the OME-Zarr store at `path`, or none (not a store, or unreadable metadata:
/// the read reports that).
fn zarr_levels(path: &Path) -> Vec<LevelInfo> {
    if !crate::zarr::is_zarr_store(path) {
        return Vec::new();
    }
    let Ok(store) = crate::ZarrStore::open(path, &crate::Limits::default()) else {
        return Vec::new();
    };
    store
        .levels()
        .iter()
        .map(|l| LevelInfo {
            path: l.path.clone(),
            dims: l.dims,
            spacing: l.spacing,
            origin: l.origin,
            shape: l.shape.clone(),
            chunks: l.chunks.clone(),
            data_type: l.data_type.clone(),
        })
        .collect()
}

impl VolumeInfo {
    /// Summarises a volume as read from `path` (for an OME-Zarr store, with its levels, read
    /// again from its metadata).
    pub fn new(path: &Path, loaded: &LoadedVolume) -> Self {
        let v = &loaded.volume;
        let (lo, hi) = v.value_range();
        let mut info = VolumeInfo::from_grid(
            path,
            &loaded.format,
            v.grid(),
            v.scalar_type(),
            [lo, hi],
            (loaded.frames, loaded.frame),
            loaded.notes.clone(),
        );
        info.arrays = loaded.arrays.clone();
        info.series_uid = loaded.series_uid.clone();
        info.series = loaded.series.clone();
        info
    }

    /// Summarises a volume known by its grid (world frame, mm), sample type and value range
    /// `[lo, hi]` (data units) without its samples: an OME-Zarr level larger than memory,
    /// whose range comes from a bounded ranges scan (`volsplat info`). `frames`: how many
    /// frames (time points) and which one; no arrays or series; the store's levels as
    /// [`VolumeInfo::new`] gives them.
    pub fn from_grid(
        path: &Path,
        format: &str,
        g: &volsplat_core::Grid,
        scalar_type: volsplat_core::ScalarType,
        [lo, hi]: [f64; 2],
        (frames, frame): (usize, usize),
        notes: Vec<String>,
    ) -> Self {
        let (blo, bhi) = g.bounds_world();
        let d = g.direction;
        let direction = [
            [d.x_axis.x, d.y_axis.x, d.z_axis.x],
            [d.x_axis.y, d.y_axis.y, d.z_axis.y],
            [d.x_axis.z, d.y_axis.z, d.z_axis.z],
        ];
        VolumeInfo {
            schema: VOLUME_INFO_SCHEMA,
            path: path.display().to_string(),
            format: format.to_string(),
            dims: g.dims,
            voxels: g.dims.iter().map(|&n| n as u64).product(),
            scalar_type: scalar_type.name().to_string(),
            spacing: g.spacing,
            origin: g.origin,
            direction,
            bounds: [blo.to_array(), bhi.to_array()],
            value_range: [lo, hi],
            frames,
            frame,
            arrays: Vec::new(),
            series_uid: None,
            series: Vec::new(),
            notes,
            levels: zarr_levels(path),
        }
    }

    /// Pretty-printed JSON (two-space indent, fields in the order above).
    pub fn to_json_pretty(&self) -> String {
        // Serialising plain numbers, strings and vectors cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }
}

/// Reads `path` with [`crate::read_volume_with`] and summarises it.
pub fn volume_info(path: impl AsRef<Path>, options: &ReadOptions) -> Result<VolumeInfo> {
    let path = path.as_ref();
    let loaded = crate::read_volume_with(path, options)?;
    Ok(VolumeInfo::new(path, &loaded))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_has_the_documented_fields() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.nrrd");
        std::fs::write(
            &p,
            b"NRRD0004\ntype: int16\ndimension: 3\nspace: RAS\nsizes: 2 1 1\n\
              space directions: (0,1,0) (1,0,0) (0,0,2)\nspace origin: (1,2,3)\n\
              endian: little\nencoding: raw\n\n\x05\x00\xfe\xff",
        )
        .unwrap();
        let info = volume_info(&p, &ReadOptions::default()).unwrap();
        assert_eq!(info.dims, [2, 1, 1]);
        assert_eq!(info.voxels, 2);
        assert_eq!(info.scalar_type, "i16");
        assert_eq!(info.value_range, [-2.0, 5.0]);
        assert_eq!(info.spacing, [1.0, 1.0, 2.0]);
        // RAS → LPS: origin (−1, −2, 3); i → −y (LPS of RAS +y), j → −x.
        assert_eq!(info.origin, [-1.0, -2.0, 3.0]);
        assert_eq!(
            info.direction,
            [[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        );
        let v: serde_json::Value = serde_json::from_str(&info.to_json_pretty()).unwrap();
        for k in [
            "schema",
            "path",
            "format",
            "dims",
            "voxels",
            "scalar_type",
            "spacing",
            "origin",
            "direction",
            "bounds",
            "value_range",
            "frames",
            "frame",
            "arrays",
            "series_uid",
            "series",
            "notes",
            "levels",
        ] {
            assert!(v.get(k).is_some(), "missing {k}");
        }
        assert_eq!(v["schema"], 1);
        assert_eq!(v["format"], "NRRD");
        assert!(v["series_uid"].is_null());
    }
}
