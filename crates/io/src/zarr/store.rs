//! An opened OME-Zarr store: its levels ([`ZarrLevel`]) and the region read
//! ([`ZarrStore::read_region`]) that the whole-level read, and a later brick source, are built
//! on.

use super::meta::{self, AxisKind, Multiscales};
use crate::error::{IoError, Result, clip};
use crate::limits::Limits;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use volsplat_core::glam::DMat3;
use volsplat_core::{AnyVolume, Grid, Scalar, ScalarType, Volume};
use zarrs::array::{Array, ArraySubset, ElementOwned};
use zarrs::filesystem::FilesystemStore;

/// How a level's stored samples become volsplat samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stored {
    /// Read as they are.
    Native(ScalarType),
    /// `int32`, read as `f32` (values above 2²⁴ in magnitude round).
    I32,
    /// `uint32`, read as `f32`.
    U32,
    /// `float64`, read as `f32` (rounded; values beyond the `f32` range are an error).
    F64,
    /// Anything else: listed, not readable.
    Unsupported,
}

/// One resolution level of an OME-Zarr store (`multiscales[0].datasets[i]`), as its metadata
/// describes it; no sample has been read.
#[derive(Debug, Clone, PartialEq)]
pub struct ZarrLevel {
    /// The array's path inside the store (`datasets[i].path`, e.g. `0`).
    pub path: String,
    /// The array's shape in store order (OME axes order: t, c, z, y, x or a subset).
    pub shape: Vec<u64>,
    /// The chunk shape in store order (for a sharded Zarr v3 array: the shard shape).
    pub chunks: Vec<u64>,
    /// The data type as the store names it (e.g. `uint16`, `float32`).
    pub data_type: String,
    /// The volsplat sample type the level reads as (`int32`, `uint32`, `float64` read as
    /// `f32`); `None` for a data type volsplat cannot read (reading it is an error).
    pub scalar_type: Option<ScalarType>,
    /// Samples along x, y, z (1 along z for a 2-D image).
    pub dims: [u64; 3],
    /// Distance between samples along x, y, z in mm (the OME `scale`, converted from the
    /// axes' units; 1 along a missing z).
    pub spacing: [f64; 3],
    /// World position (mm) of sample (0, 0, 0): the OME `translation`, converted likewise.
    pub origin: [f64; 3],
}

/// Which channel and time point of a multi-dimensional image ([`ZarrStore::read_region`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ZarrSelection {
    /// Index along the `channel` axis (0 where there is none).
    pub channel: usize,
    /// Index along the `time` axis (0 where there is none).
    pub timepoint: usize,
}

/// An opened OME-Zarr store (v0.4 on Zarr v2, v0.5 on Zarr v3; filesystem only): the
/// multiscales metadata parsed and checked, every level's array metadata opened. World
/// coordinates are the store's own (no anatomical frame: x, y, z as written, as for TIFF and
/// VTK files), in mm.
#[derive(Debug)]
pub struct ZarrStore {
    path: PathBuf,
    store: Arc<FilesystemStore>,
    /// `0.4`, `0.5`, ... as the metadata says.
    ome_version: String,
    /// 2 or 3.
    zarr_version: u8,
    /// Array dimension of x, y, z (`None`: a 2-D image has no z).
    spatial: [Option<usize>; 3],
    channel_axis: Option<usize>,
    time_axis: Option<usize>,
    ndim: usize,
    levels: Vec<ZarrLevel>,
    stored: Vec<Stored>,
    arrays: Vec<Array<FilesystemStore>>,
    notes: Vec<String>,
    limits: Limits,
}

/// The root metadata of a store: (attributes, zarr version, file read).
fn root_attributes(path: &Path, limits: &Limits) -> Result<(serde_json::Value, u8, PathBuf)> {
    let v3 = path.join("zarr.json");
    let v2 = path.join(".zattrs");
    let (file, version) = if v3.is_file() {
        (v3, 3)
    } else if v2.is_file() {
        (v2, 2)
    } else {
        return Err(IoError::missing(
            path,
            "zarr.json or .zattrs (OME-Zarr multiscales)",
        ));
    };
    let len = std::fs::metadata(&file)
        .map_err(|e| IoError::os(&file, "stat", e))?
        .len();
    let cap = limits.max_json_bytes.min(meta::MAX_METADATA_BYTES);
    if len > cap {
        return Err(IoError::TooLarge {
            path: file,
            what: "metadata file size in bytes".into(),
            value: len as u128,
            limit: cap as u128,
        });
    }
    let bytes = std::fs::read(&file).map_err(|e| IoError::os(&file, "read", e))?;
    let json: serde_json::Value = serde_json::from_slice(&bytes).map_err(|e| IoError::Json {
        path: file.clone(),
        message: e.to_string(),
    })?;
    let attrs = if version == 3 {
        if json.get("node_type").and_then(|t| t.as_str()) != Some("group") {
            return Err(IoError::field(
                &file,
                "node_type",
                &clip(
                    &json
                        .get("node_type")
                        .cloned()
                        .unwrap_or_default()
                        .to_string(),
                ),
                "the store's root must be a group holding the OME multiscales",
            ));
        }
        json.get("attributes").cloned().unwrap_or_default()
    } else {
        json
    };
    Ok((attrs, version, file))
}

/// Refuses a store, read under [`Limits::confine_to`], that holds a symbolic link leading
/// out of the confinement folder (the Zarr library opens chunk files by path; decision 0033).
/// Walks the store's real folders (links to folders are checked, not followed).
fn check_links(path: &Path, c: &crate::confine::Confinement) -> Result<()> {
    let mut stack = vec![path.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let entries = std::fs::read_dir(&dir).map_err(|e| IoError::os(&dir, "list folder", e))?;
        for e in entries {
            let e = e.map_err(|e| IoError::os(&dir, "list folder", e))?;
            let p = e.path();
            let kind = e.file_type().map_err(|e| IoError::os(&p, "stat", e))?;
            if kind.is_symlink() {
                let target = std::fs::read_link(&p).unwrap_or_default();
                c.check(
                    path,
                    "a symbolic link inside the store",
                    &format!("{} → {}", p.display(), target.display()),
                    &p,
                )?;
            } else if kind.is_dir() {
                stack.push(p);
            }
        }
    }
    Ok(())
}

/// Whether `path` is a directory that looks like an OME-Zarr store: its name ends in `.zarr`,
/// or it holds a `zarr.json` or `.zattrs` that mentions `multiscales`.
pub(crate) fn is_zarr_store(path: &Path) -> bool {
    if !path.is_dir() {
        return false;
    }
    if crate::nifti::has_suffix(path, ".zarr") || crate::nifti::has_suffix(path, ".ome.zarr") {
        return true;
    }
    ["zarr.json", ".zattrs"].iter().any(|f| {
        let p = path.join(f);
        std::fs::metadata(&p).is_ok_and(|m| m.is_file() && m.len() <= meta::MAX_METADATA_BYTES)
            && std::fs::read(&p)
                .is_ok_and(|b| b.windows(b"multiscales".len()).any(|w| w == b"multiscales"))
    })
}

impl ZarrStore {
    /// Whether `path` is a folder that looks like an OME-Zarr store (named `.zarr`, or
    /// holding a `zarr.json` / `.zattrs` that mentions `multiscales`), as the readers'
    /// dispatch decides. Opens nothing else.
    pub fn is_store(path: impl AsRef<Path>) -> bool {
        is_zarr_store(path.as_ref())
    }

    /// Opens the store at `path` (a directory): parses the multiscales, opens each level's
    /// array metadata and checks shapes, chunk shapes, data types, scales and translations.
    /// Errors name the store, the metadata field and its value.
    pub fn open(path: impl AsRef<Path>, limits: &Limits) -> Result<Self> {
        let path = path.as_ref();
        match std::fs::metadata(path) {
            Err(e) => return Err(IoError::os(path, "open OME-Zarr store", e)),
            Ok(m) if !m.is_dir() => {
                return Err(IoError::invalid_argument(
                    path,
                    "OME-Zarr store",
                    "is a file; an OME-Zarr store is a folder",
                ));
            }
            Ok(_) => {}
        }
        if let Some(c) = crate::confine::Confinement::of(path, limits)? {
            check_links(path, &c)?;
        }
        let (attrs, zarr_version, file) = root_attributes(path, limits)?;
        // bioformats2raw's layout: the image is the group `0` below a root without
        // multiscales (https://ngff.openmicroscopy.org/0.4/#bf2raw).
        let multiscales = attrs.get("multiscales").is_some()
            || attrs
                .get("ome")
                .is_some_and(|o| o.get("multiscales").is_some());
        let layout = attrs.get("bioformats2raw.layout").or_else(|| {
            attrs
                .get("ome")
                .and_then(|o| o.get("bioformats2raw.layout"))
        });
        if !multiscales && layout.is_some() && path.join("0").is_dir() {
            let mut s = ZarrStore::open(path.join("0"), limits)?;
            s.notes.push(format!(
                "bioformats2raw layout: image 0 of {} read",
                path.display()
            ));
            return Ok(s);
        }
        let ms = meta::parse(&file, &attrs)?;
        let store = Arc::new(FilesystemStore::new(path).map_err(|e| IoError::Zarr {
            path: path.to_path_buf(),
            what: "open store".into(),
            message: e.to_string(),
        })?);
        let mut s = ZarrStore {
            path: path.to_path_buf(),
            store,
            ome_version: ms.version.clone(),
            zarr_version,
            spatial: [None; 3],
            channel_axis: None,
            time_axis: None,
            ndim: ms.axes.len(),
            levels: Vec::new(),
            stored: Vec::new(),
            arrays: Vec::new(),
            notes: Vec::new(),
            limits: limits.clone(),
        };
        s.map_axes(&file, &ms)?;
        for i in 0..ms.datasets.len() {
            s.open_level(&file, &ms, i)?;
        }
        Ok(s)
    }

    /// Finds x, y, z, channel and time among the axes; checks their order (time, channel or
    /// custom, then space; the spatial axes z, y, x with x last, so x varies fastest).
    fn map_axes(&mut self, file: &Path, ms: &Multiscales) -> Result<()> {
        let spatial: Vec<usize> = (0..ms.axes.len())
            .filter(|&a| ms.axes[a].kind == AxisKind::Space)
            .collect();
        let names: Vec<&str> = ms.axes.iter().map(|a| a.name.as_str()).collect();
        let bad = |reason: &str| {
            IoError::field(
                file,
                "multiscales[0].axes",
                &names.join(", "),
                reason.to_string(),
            )
        };
        if !(2..=3).contains(&spatial.len()) {
            return Err(bad("volsplat reads 2 or 3 spatial axes"));
        }
        if spatial
            .iter()
            .enumerate()
            .any(|(k, &a)| a != ms.axes.len() - spatial.len() + k)
        {
            return Err(bad(
                "the spatial axes must come last (OME order: time, channel, space)",
            ));
        }
        let expected: &[&str] = if spatial.len() == 3 {
            &["z", "y", "x"]
        } else {
            &["y", "x"]
        };
        let spatial_names: Vec<&str> = spatial.iter().map(|&a| names[a]).collect();
        let known = spatial_names.iter().all(|n| ["x", "y", "z"].contains(n));
        if known && spatial_names != expected {
            return Err(bad(
                "the spatial axes must be ordered z, y, x (x varying fastest)",
            ));
        }
        // x is the last axis, y the one before, z (if any) the one before that.
        let n = spatial.len();
        self.spatial[0] = Some(spatial[n - 1]);
        self.spatial[1] = Some(spatial[n - 2]);
        self.spatial[2] = (n == 3).then(|| spatial[0]);
        for (a, axis) in ms.axes.iter().enumerate() {
            let slot = match axis.kind {
                AxisKind::Time => &mut self.time_axis,
                AxisKind::Channel => &mut self.channel_axis,
                _ => continue,
            };
            if slot.is_some() {
                return Err(bad("at most one time and one channel axis"));
            }
            *slot = Some(a);
        }
        for (a, axis) in ms.axes.iter().enumerate() {
            if let Some(unit) = &axis.unit
                && axis.kind == AxisKind::Space
                && meta::mm_per_unit(unit).is_none()
            {
                self.notes.push(format!(
                    "axis {} has unit {unit:?}, which volsplat does not know: its scale is taken \
                     as mm unchanged",
                    names[a]
                ));
            }
        }
        let units: Vec<String> = spatial
            .iter()
            .filter_map(|&a| ms.axes[a].unit.clone())
            .collect();
        if units.is_empty() {
            self.notes
                .push("the spatial axes have no unit: scales taken as mm".to_string());
        } else if units.iter().any(|u| u != "millimeter") {
            self.notes.push(format!(
                "spatial units {} converted to mm",
                units.join(", ")
            ));
        }
        Ok(())
    }

    /// Opens level `i`'s array and records its shape, chunks, type and geometry.
    fn open_level(&mut self, file: &Path, ms: &Multiscales, i: usize) -> Result<()> {
        let d = &ms.datasets[i];
        let at = format!("multiscales[0].datasets[{i}]");
        let zerr = |what: String, e: &dyn std::fmt::Display| IoError::Zarr {
            path: self.path.clone(),
            what,
            message: e.to_string(),
        };
        let array = Array::open(self.store.clone(), &format!("/{}", d.path))
            .map_err(|e| zerr(format!("level {i}: open array `{}`", d.path), &e))?;
        let shape = array.shape().to_vec();
        if shape.len() != self.ndim {
            return Err(IoError::field(
                &self.path.join(&d.path),
                "shape",
                &format!("{shape:?}"),
                format!(
                    "has {} dimensions, but the multiscales name {} axes",
                    shape.len(),
                    self.ndim
                ),
            ));
        }
        if let Some(a) = shape.iter().position(|&n| n == 0) {
            return Err(IoError::field(
                &self.path.join(&d.path),
                "shape",
                &format!("{shape:?}"),
                format!("axis {} has no samples", ms.axes[a].name),
            ));
        }
        let chunks: Vec<u64> = array
            .chunk_shape(&vec![0; shape.len()])
            .map_err(|e| zerr(format!("level {i}: chunk shape"), &e))?
            .iter()
            .map(|c| c.get())
            .collect();
        let chunk_text = format!("{chunks:?}");
        crate::limits::checked_voxel_count(
            &self.path.join(&d.path),
            "chunks",
            &chunk_text,
            &chunks,
            &self.limits,
        )?;
        let dt = array.data_type();
        use zarrs::array::data_type as zdt;
        let stored = if dt.is::<zdt::UInt8DataType>() {
            Stored::Native(ScalarType::U8)
        } else if dt.is::<zdt::Int8DataType>() {
            Stored::Native(ScalarType::I8)
        } else if dt.is::<zdt::UInt16DataType>() {
            Stored::Native(ScalarType::U16)
        } else if dt.is::<zdt::Int16DataType>() {
            Stored::Native(ScalarType::I16)
        } else if dt.is::<zdt::Float32DataType>() {
            Stored::Native(ScalarType::F32)
        } else if dt.is::<zdt::Int32DataType>() {
            Stored::I32
        } else if dt.is::<zdt::UInt32DataType>() {
            Stored::U32
        } else if dt.is::<zdt::Float64DataType>() {
            Stored::F64
        } else {
            Stored::Unsupported
        };
        let scalar_type = match stored {
            Stored::Native(t) => Some(t),
            Stored::I32 | Stored::U32 | Stored::F64 => Some(ScalarType::F32),
            Stored::Unsupported => None,
        };
        let mut dims = [1u64; 3];
        let mut spacing = [1.0f64; 3];
        let mut origin = [0.0f64; 3];
        for (k, axis) in self.spatial.iter().enumerate() {
            let Some(a) = *axis else { continue };
            let unit = ms.axes[a].unit.as_deref();
            let mm = unit.and_then(meta::mm_per_unit).unwrap_or(1.0);
            dims[k] = shape[a];
            let s = d.scale[a];
            if s <= 0.0 {
                return Err(IoError::field(
                    file,
                    format!(
                        "{at}.coordinateTransformations scale[{a}] (axis {})",
                        ms.axes[a].name
                    ),
                    &s.to_string(),
                    "a spatial scale must be positive",
                ));
            }
            spacing[k] = s * mm;
            origin[k] = d.translation[a] * mm;
            if !(spacing[k].is_finite() && spacing[k] > 0.0 && origin[k].is_finite()) {
                return Err(IoError::field(
                    file,
                    format!("{at}.coordinateTransformations (axis {})", ms.axes[a].name),
                    &format!("scale {s}, translation {}", d.translation[a]),
                    "not a finite positive spacing in mm",
                ));
            }
        }
        self.levels.push(ZarrLevel {
            path: d.path.clone(),
            shape,
            chunks,
            data_type: dt.to_string(),
            scalar_type,
            dims,
            spacing,
            origin,
        });
        self.stored.push(stored);
        self.arrays.push(array);
        Ok(())
    }

    /// The store's directory.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The levels, full resolution first (`datasets` order).
    pub fn levels(&self) -> &[ZarrLevel] {
        &self.levels
    }

    /// The format for messages: `OME-Zarr 0.4 (Zarr v2)`.
    pub fn format(&self) -> String {
        format!(
            "OME-Zarr {} (Zarr v{})",
            self.ome_version, self.zarr_version
        )
    }

    /// Notes on what the metadata implied (units converted, assumed).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Entries along the channel axis (1 where there is none).
    pub fn channels(&self) -> u64 {
        self.channel_axis
            .and_then(|a| self.levels.first().map(|l| l.shape[a]))
            .unwrap_or(1)
    }

    /// Entries along the time axis (1 where there is none).
    pub fn timepoints(&self) -> u64 {
        self.time_axis
            .and_then(|a| self.levels.first().map(|l| l.shape[a]))
            .unwrap_or(1)
    }

    /// Level `level`, or an error naming the levels there are.
    pub fn level(&self, level: usize) -> Result<&ZarrLevel> {
        self.levels.get(level).ok_or_else(|| {
            IoError::invalid_argument(
                &self.path,
                "level",
                format!(
                    "level {level} requested, but the store holds {} levels (0 to {})",
                    self.levels.len(),
                    self.levels.len() - 1
                ),
            )
        })
    }

    /// A note where `level`'s samples are converted on reading (`int32 samples converted to
    /// f32`).
    pub(crate) fn conversion_note(&self, level: usize) -> Option<String> {
        let name = match self.stored.get(level)? {
            Stored::I32 => "int32",
            Stored::U32 => "uint32",
            Stored::F64 => "float64",
            _ => return None,
        };
        Some(format!(
            "{name} samples converted to f32 (integers beyond 2^24 and doubles round)"
        ))
    }

    /// The level whose voxel is about `pixel` (mm, the size of a pixel at the focal plane):
    /// the coarsest level whose smallest spacing is at most `slack · pixel`, 0 where none
    /// coarser qualifies or `pixel` is not a positive finite number. With `slack` √2 this is
    /// the renderer's own rule for its in-memory pyramid (`volsplat_splat::auto_level`,
    /// decision 0031), so a store written by [`crate::write_zarr`] gives the same level; with
    /// 1, the coarsest level whose finest voxel is no larger than a pixel. Metadata only.
    pub fn auto_level(&self, pixel: f64, slack: f64) -> usize {
        if !(pixel.is_finite() && pixel > 0.0) {
            return 0;
        }
        let min = |l: &ZarrLevel| l.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s));
        self.levels
            .iter()
            .rposition(|l| min(l) <= slack * pixel)
            .unwrap_or(0)
    }

    /// The per-dimension ranges (store order) of a region of `level`: spatial `[lo, hi)`
    /// (x, y, z), the selected channel and time point, index 0 of other axes. Checks every
    /// index against the shape.
    fn ranges(
        &self,
        level: usize,
        sel: ZarrSelection,
        lo: [u64; 3],
        hi: [u64; 3],
    ) -> Result<Vec<std::ops::Range<u64>>> {
        let l = self.level(level)?;
        for k in 0..3 {
            if !(lo[k] < hi[k] && hi[k] <= l.dims[k]) {
                return Err(IoError::invalid_argument(
                    &self.path,
                    "region",
                    format!(
                        "[{lo:?}, {hi:?}) is empty or outside level {level}'s samples {:?}",
                        l.dims
                    ),
                ));
            }
        }
        let mut ranges: Vec<_> = (0..self.ndim).map(|_| 0..1).collect();
        for (which, axis, index) in [
            ("channel", self.channel_axis, sel.channel),
            ("timepoint", self.time_axis, sel.timepoint),
        ] {
            let n = axis.map_or(1, |a| l.shape[a]);
            if index as u64 >= n {
                return Err(IoError::invalid_argument(
                    &self.path,
                    which,
                    format!(
                        "{which} {index} requested, but the store holds {n} (0 to {})",
                        n - 1
                    ),
                ));
            }
            if let Some(a) = axis {
                ranges[a] = index as u64..index as u64 + 1;
            }
        }
        for (a, r) in ranges.iter().enumerate() {
            let is_sel = Some(a) == self.channel_axis
                || Some(a) == self.time_axis
                || self.spatial.contains(&Some(a));
            if !is_sel && l.shape[a] != 1 {
                return Err(IoError::unsupported(
                    &self.path,
                    format!("multiscales[0].axes[{a}]"),
                    &format!("a custom axis of {} entries", l.shape[a]),
                    "custom (non-space, non-time, non-channel) axes of size 1",
                ));
            }
            debug_assert!(r.end <= l.shape[a]);
        }
        for (k, axis) in self.spatial.iter().enumerate() {
            if let Some(a) = *axis {
                ranges[a] = lo[k]..hi[k];
            }
        }
        Ok(ranges)
    }

    /// Reads the axis-aligned region `[lo, hi)` (voxel indices along x, y, z of `level`) of
    /// the selected channel and time point into a buffer, x varying fastest, then y, then z
    /// (volsplat's layout). `T` must be the level's [`ZarrLevel::scalar_type`]. The sample
    /// count is checked against the store's [`Limits`] before anything is allocated; chunks
    /// absent from the store read as the array's fill value (Zarr specification); a chunk
    /// that cannot be decoded is an error naming the store, the level and the cause.
    pub fn read_region<T: Scalar + ElementOwned>(
        &self,
        level: usize,
        sel: ZarrSelection,
        lo: [u64; 3],
        hi: [u64; 3],
    ) -> Result<Vec<T>> {
        let ranges = self.ranges(level, sel, lo, hi)?;
        let l = &self.levels[level];
        let sizes: Vec<u64> = (0..3).map(|k| hi[k] - lo[k]).collect();
        crate::limits::checked_voxel_count(
            &self.path,
            "shape",
            &format!("level {level} region {sizes:?}"),
            &sizes,
            &self.limits,
        )?;
        let wrong_type = || {
            IoError::invalid_argument(
                &self.path,
                "sample type",
                format!(
                    "level {level} (array `{}`) holds {} samples, read as {}; {} was asked for",
                    l.path,
                    l.data_type,
                    l.scalar_type.map_or("nothing", |t| t.name()),
                    T::TYPE.name()
                ),
            )
        };
        let subset = ArraySubset::new_with_ranges(&ranges);
        let array = &self.arrays[level];
        let zerr = |e: zarrs::array::ArrayError| IoError::Zarr {
            path: self.path.clone(),
            what: format!("level {level} (array `{}`)", l.path),
            message: e.to_string(),
        };
        let stored = self.stored[level];
        match stored {
            Stored::Unsupported => Err(IoError::unsupported(
                &self.path.join(&l.path),
                "data_type",
                &l.data_type,
                "uint8, int8, uint16, int16, float32 (int32, uint32 and float64 read as float32)",
            )),
            Stored::Native(t) if t == T::TYPE => {
                array.retrieve_array_subset::<Vec<T>>(&subset).map_err(zerr)
            }
            _ if T::TYPE != ScalarType::F32 => Err(wrong_type()),
            Stored::I32 => {
                let v = array
                    .retrieve_array_subset::<Vec<i32>>(&subset)
                    .map_err(zerr)?;
                Ok(v.into_iter().map(|x| T::from_f64(x as f64)).collect())
            }
            Stored::U32 => {
                let v = array
                    .retrieve_array_subset::<Vec<u32>>(&subset)
                    .map_err(zerr)?;
                Ok(v.into_iter().map(|x| T::from_f64(x as f64)).collect())
            }
            Stored::F64 => {
                let v = array
                    .retrieve_array_subset::<Vec<f64>>(&subset)
                    .map_err(zerr)?;
                if let Some(x) = v
                    .iter()
                    .find(|x| x.is_finite() && x.abs() > f32::MAX as f64)
                {
                    return Err(IoError::field(
                        &self.path.join(&l.path),
                        "data_type",
                        "float64",
                        format!("sample {x:e} lies outside the float32 range"),
                    ));
                }
                Ok(v.into_iter().map(T::from_f64).collect())
            }
            Stored::Native(_) => Err(wrong_type()),
        }
    }

    /// The grid of `level` (dims checked against the limits), identity direction.
    pub fn grid(&self, level: usize) -> Result<Grid> {
        let l = self.level(level)?;
        let dims = crate::limits::checked_dims(
            &self.path,
            "shape",
            &format!("level {level} (array `{}`) {:?}", l.path, l.shape),
            l.dims,
            &self.limits,
        )?;
        Grid::new(dims, l.spacing, l.origin, DMat3::IDENTITY)
            .map_err(|e| IoError::core(&self.path, e))
    }

    /// Reads the whole of `level` (the selected channel and time point) as a volume, through
    /// [`ZarrStore::read_region`].
    pub fn read_level(&self, level: usize, sel: ZarrSelection) -> Result<AnyVolume> {
        let grid = self.grid(level)?;
        let l = &self.levels[level];
        let hi = l.dims;
        fn typed<T: Scalar + ElementOwned>(
            s: &ZarrStore,
            level: usize,
            sel: ZarrSelection,
            hi: [u64; 3],
            grid: Grid,
        ) -> Result<Volume<T>> {
            let data = s.read_region::<T>(level, sel, [0; 3], hi)?;
            Volume::new(grid, data).map_err(|e| IoError::core(&s.path, e))
        }
        Ok(match l.scalar_type {
            Some(ScalarType::U8) => typed::<u8>(self, level, sel, hi, grid)?.into(),
            Some(ScalarType::I8) => typed::<i8>(self, level, sel, hi, grid)?.into(),
            Some(ScalarType::U16) => typed::<u16>(self, level, sel, hi, grid)?.into(),
            Some(ScalarType::I16) => typed::<i16>(self, level, sel, hi, grid)?.into(),
            // F32 and the converted types; None reports the unsupported type.
            _ => typed::<f32>(self, level, sel, hi, grid)?.into(),
        })
    }
}
