//! Writing an OME-Zarr pyramid ([`write_zarr`]): OME-Zarr v0.4 on Zarr v2 (default) or v0.5
//! on Zarr v3, levels by the renderer's own 2× prefilter ([`volsplat_core::Volume::halved`]), written into a
//! temporary folder beside the target and renamed over it at the end.

use super::stream::Cascade;
use crate::error::{IoError, Result};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use volsplat_core::glam::DMat3;
use volsplat_core::{AnyVolume, Grid, Scalar, ScalarType};
use zarrs::array::{Array, Element};
use zarrs::filesystem::FilesystemStore;

/// Which OME-Zarr (and Zarr) version [`write_zarr`] writes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum ZarrVersion {
    /// OME-Zarr v0.4 on Zarr v2 (`.zgroup`, `.zattrs`, `.zarray`), chunks compressed by
    /// blosc (zstd inside, byte shuffle): read by `zarr` 2.x and 3.x, `ome-zarr-py`,
    /// napari, Fiji's N5/MoBIE readers and `zarrs` (decision 0037). The default.
    #[default]
    V2,
    /// OME-Zarr v0.5 on Zarr v3 (`zarr.json`), chunks compressed by the `zstd` codec: read
    /// by `zarr` 3.x and `zarrs`; not by `zarr` 2.x.
    V3,
}

/// How [`write_zarr`] writes (`#[non_exhaustive]`; build from [`ZarrWriteOptions::default`]).
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct ZarrWriteOptions {
    /// OME-Zarr / Zarr version; default [`ZarrVersion::V2`].
    pub version: ZarrVersion,
    /// Chunk edge in samples (chunks are cubes); default 64. The pyramid ends with the first
    /// level that fits in one chunk ([`pyramid_grids`]). 1 to 1024.
    pub chunk: usize,
    /// zstd compression level (1 to 22); default 5.
    pub zstd_level: i32,
}

impl Default for ZarrWriteOptions {
    fn default() -> Self {
        ZarrWriteOptions {
            version: ZarrVersion::V2,
            chunk: 64,
            zstd_level: 5,
        }
    }
}

impl ZarrWriteOptions {
    /// These options with [`ZarrWriteOptions::version`] set.
    pub fn with_version(mut self, version: ZarrVersion) -> Self {
        self.version = version;
        self
    }

    /// These options with [`ZarrWriteOptions::chunk`] set (samples per chunk edge).
    pub fn with_chunk(mut self, chunk: usize) -> Self {
        self.chunk = chunk;
        self
    }
}

/// What [`write_zarr`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct WrittenZarr {
    /// The levels' grids, full resolution first (as a reader of the store gets them).
    pub levels: Vec<Grid>,
    /// Notes for the user (what the format could not keep).
    pub notes: Vec<String>,
}

/// The most levels [`pyramid_grids`] makes (as the renderer's pyramid,
/// `volsplat_splat::pyramid::MAX_LEVELS`).
pub const MAX_LEVELS: usize = 16;

/// The grids of the pyramid [`write_zarr`] writes over `grid`: `grid` itself, then each level
/// halved ([`Grid::halved`]) along its [`Grid::pyramid_axes`] (as the renderer's in-memory
/// pyramid, `volsplat_splat::pyramid::level_grids`, so level `l` here is level `l` there),
/// ending after the first level whose every axis fits in one `chunk`, when no axis qualifies
/// for halving (fewer than 8 samples, or too coarse against the finest axis), or at
/// [`MAX_LEVELS`] levels.
pub fn pyramid_grids(grid: &Grid, chunk: usize) -> Vec<Grid> {
    grid.pyramid_grids(MAX_LEVELS, |g| g.dims.iter().all(|&n| n <= chunk))
}

pub(super) fn zerr(path: &Path, what: impl Into<String>, e: impl std::fmt::Display) -> IoError {
    IoError::Zarr {
        path: path.to_path_buf(),
        what: what.into(),
        message: e.to_string(),
    }
}

/// The data type's names: (Zarr v2 `dtype`, Zarr v3 `data_type`).
fn dtype_names(t: ScalarType) -> (&'static str, &'static str) {
    match t {
        ScalarType::U8 => ("|u1", "uint8"),
        ScalarType::I8 => ("|i1", "int8"),
        ScalarType::U16 => ("<u2", "uint16"),
        ScalarType::I16 => ("<i2", "int16"),
        ScalarType::F32 => ("<f4", "float32"),
    }
}

/// A `.zarray` (v2) or array `zarr.json` (v3) for a (z, y, x) array of `dims` (x, y, z).
fn array_metadata(dims: [usize; 3], t: ScalarType, o: &ZarrWriteOptions) -> Value {
    let shape = [dims[2], dims[1], dims[0]];
    let chunks = shape.map(|n| n.min(o.chunk));
    let fill = if t == ScalarType::F32 {
        json!(0.0)
    } else {
        json!(0)
    };
    let (v2, v3) = dtype_names(t);
    match o.version {
        ZarrVersion::V2 => json!({
            "zarr_format": 2, "shape": shape, "chunks": chunks, "dtype": v2,
            "compressor": { "id": "blosc", "cname": "zstd", "clevel": o.zstd_level.clamp(0, 9),
                            "shuffle": 1, "blocksize": 0 },
            "fill_value": fill, "order": "C", "filters": null, "dimension_separator": "/"
        }),
        ZarrVersion::V3 => json!({
            "zarr_format": 3, "node_type": "array", "shape": shape, "data_type": v3,
            "chunk_grid": { "name": "regular", "configuration": { "chunk_shape": chunks } },
            "chunk_key_encoding": { "name": "default", "configuration": { "separator": "/" } },
            "fill_value": fill,
            "codecs": [
                { "name": "bytes", "configuration": { "endian": "little" } },
                { "name": "zstd", "configuration": { "level": o.zstd_level, "checksum": false } }
            ],
            "dimension_names": ["z", "y", "x"], "attributes": {}
        }),
    }
}

/// The OME `multiscales` entry for `grids` (axes z, y, x in mm).
fn multiscales(name: &str, grids: &[Grid], version: ZarrVersion) -> Value {
    let datasets: Vec<Value> = grids
        .iter()
        .enumerate()
        .map(|(l, g)| {
            json!({
                "path": l.to_string(),
                "coordinateTransformations": [
                    { "type": "scale", "scale": [g.spacing[2], g.spacing[1], g.spacing[0]] },
                    { "type": "translation",
                      "translation": [g.origin[2], g.origin[1], g.origin[0]] }
                ]
            })
        })
        .collect();
    let axes: Vec<Value> = ["z", "y", "x"]
        .iter()
        .map(|a| json!({ "name": a, "type": "space", "unit": "millimeter" }))
        .collect();
    let mut m = json!({
        "name": name,
        "axes": axes,
        "datasets": datasets,
        "type": "binomial [1, 3, 3, 1] / 8",
        "metadata": {
            "description": "each level halves the axes within twice the finest spacing after \
                the binomial low-pass [1, 3, 3, 1] / 8, as volsplat's in-memory pyramid",
            "method": "volsplat_core::Volume::halved",
            "version": env!("CARGO_PKG_VERSION")
        }
    });
    if version == ZarrVersion::V2 {
        m["version"] = json!("0.4");
    }
    m
}

fn write_json(path: &Path, file: &Path, v: &Value) -> Result<()> {
    let text = serde_json::to_vec_pretty(v).map_err(|e| zerr(path, "encode metadata", e))?;
    std::fs::write(file, text).map_err(|e| IoError::os(file, "write", e))
}

/// Writes the metadata of level `name`'s array (`dims`, x, y, z) into `dir/name` and opens
/// it.
fn create_level(
    path: &Path,
    store: &Arc<FilesystemStore>,
    dir: &Path,
    name: &str,
    dims: [usize; 3],
    t: ScalarType,
    o: &ZarrWriteOptions,
) -> Result<Array<FilesystemStore>> {
    let adir = dir.join(name);
    std::fs::create_dir_all(&adir).map_err(|e| IoError::os(&adir, "create folder", e))?;
    let meta = array_metadata(dims, t, o);
    let file = match o.version {
        ZarrVersion::V2 => adir.join(".zarray"),
        ZarrVersion::V3 => adir.join("zarr.json"),
    };
    write_json(path, &file, &meta)?;
    Array::open(store.clone(), &format!("/{name}"))
        .map_err(|e| zerr(path, format!("open written array `{name}`"), e))
}

/// A fresh temporary folder beside `path`.
fn temp_dir(path: &Path) -> Result<PathBuf> {
    let parent = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| IoError::invalid_argument(path, "output path", "has no file name"))?;
    for n in 0..64 {
        let tmp = parent.join(format!(".{name}.tmp-{}-{n}", std::process::id()));
        match std::fs::create_dir(&tmp) {
            Ok(()) => return Ok(tmp),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(IoError::os(path, "create temporary folder", e)),
        }
    }
    Err(IoError::os(
        path,
        "create temporary folder",
        std::io::Error::other("no free temporary name"),
    ))
}

/// Puts the finished folder `tmp` at `path`: renamed over it; an existing store at `path` is
/// first renamed aside and removed after (a regular file at `path` is an error, left alone).
fn commit_dir(tmp: &Path, path: &Path) -> Result<()> {
    match std::fs::symlink_metadata(path) {
        Err(_) => {
            std::fs::rename(tmp, path).map_err(|e| IoError::os(path, "rename temporary folder", e))
        }
        Ok(m) if m.is_dir() => {
            let old = tmp.with_extension("old");
            std::fs::rename(path, &old)
                .map_err(|e| IoError::os(path, "move the existing store aside", e))?;
            if let Err(e) = std::fs::rename(tmp, path) {
                let _ = std::fs::rename(&old, path);
                return Err(IoError::os(path, "rename temporary folder", e));
            }
            let _ = std::fs::remove_dir_all(&old);
            Ok(())
        }
        Ok(_) => Err(IoError::NotAFile {
            path: path.to_path_buf(),
            what: "output OME-Zarr store".into(),
            kind: "an existing file that is not a folder; refusing to replace it",
        }),
    }
}

/// Checks that [`write_zarr`] may write `path`: absent (its parent folder existing), or a
/// folder holding a Zarr store (`.zgroup`, `.zattrs` or `zarr.json`), which is replaced. A
/// regular file, or a folder without Zarr metadata, is refused (nothing is replaced that a
/// user might want to keep). Callers may run it before a slow read.
pub fn check_zarr_output(path: impl AsRef<Path>) -> Result<()> {
    let path = path.as_ref();
    match std::fs::symlink_metadata(path) {
        Err(_) => {
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
                && !dir.is_dir()
            {
                return Err(IoError::invalid_argument(
                    path,
                    "output path",
                    format!("the folder {} does not exist", dir.display()),
                ));
            }
            Ok(())
        }
        Ok(m) if m.is_dir() => {
            if [".zgroup", ".zattrs", "zarr.json"]
                .iter()
                .any(|f| path.join(f).is_file())
            {
                Ok(())
            } else {
                Err(IoError::invalid_argument(
                    path,
                    "output path",
                    "is a folder that is not an OME-Zarr store; refusing to replace it",
                ))
            }
        }
        Ok(_) => Err(IoError::NotAFile {
            path: path.to_path_buf(),
            what: "output OME-Zarr store".into(),
            kind: "an existing file that is not a folder; refusing to replace it",
        }),
    }
}

/// Writes `volume` as an OME-Zarr pyramid at `path` (a folder, by convention named `.zarr`):
/// level 0 the volume itself, then the levels of [`pyramid_grids`], each computed from the one
/// before by [`volsplat_core::Volume::halved`], the renderer's own prefilter, so that level `l` of the store
/// holds the same samples (bit for bit) and grid as level `l` of the renderer's in-memory
/// pyramid. Axes z, y, x (`space`, `millimeter`), each level's `scale` its spacing and
/// `translation` its origin (world coordinates of sample 0). A direction other than the
/// identity cannot be stored (OME-Zarr 0.4/0.5 have no rotation): the axis-aligned grid is
/// written and a note says so. The store is written into a temporary folder beside `path`
/// and renamed over it at the end; on error it is removed and `path` is untouched.
pub fn write_zarr(
    path: impl AsRef<Path>,
    volume: &AnyVolume,
    options: &ZarrWriteOptions,
) -> Result<WrittenZarr> {
    let path = path.as_ref();
    let (grid, notes) = prepare(path, volume.grid(), options)?;
    let grids = pyramid_grids(&grid, options.chunk);
    in_temp_dir(path, |tmp| {
        volsplat_core::with_volume!(volume, v => {
            let slice = v.grid().dims[0] * v.grid().dims[1];
            let data = v.data();
            write_levels(path, tmp, &grids, options, &mut |k| {
                Ok(data[k * slice..(k + 1) * slice].to_vec())
            })
        })
    })?;
    Ok(WrittenZarr {
        levels: grids,
        notes,
    })
}

/// Checks the options and the output path; the grid to write (axis-aligned: a rotation is
/// dropped, with a note).
pub(super) fn prepare(
    path: &Path,
    g: &Grid,
    options: &ZarrWriteOptions,
) -> Result<(Grid, Vec<String>)> {
    if !(1..=1024).contains(&options.chunk) {
        return Err(IoError::invalid_argument(
            path,
            "chunk",
            format!(
                "{} samples per chunk edge; 1 to 1024 are accepted",
                options.chunk
            ),
        ));
    }
    if !(1..=22).contains(&options.zstd_level) {
        return Err(IoError::invalid_argument(
            path,
            "zstd level",
            format!("{}; 1 to 22 are accepted", options.zstd_level),
        ));
    }
    check_zarr_output(path)?;
    let mut notes = Vec::new();
    if g.direction != DMat3::IDENTITY {
        notes.push(
            "the volume's direction matrix is not the identity; OME-Zarr stores no rotation, so \
             the store holds its axis-aligned grid (same spacing and origin)"
                .to_string(),
        );
    }
    let aligned = Grid::new(g.dims, g.spacing, g.origin, DMat3::IDENTITY)
        .map_err(|e| IoError::core(path, e))?;
    Ok((aligned, notes))
}

/// Runs `write` on a fresh temporary folder beside `path`, then puts it at `path`
/// ([`commit_dir`]); on error the folder is removed and `path` is untouched.
pub(super) fn in_temp_dir(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let tmp = temp_dir(path)?;
    let result = write(&tmp).and_then(|()| commit_dir(&tmp, path));
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}

/// Writes the group metadata and every level of `grids` into `dir`, level 0's slices coming
/// from `next_slice(k)` (`k` = 0, 1, … in order; `nx · ny` samples, x fastest), the others
/// computed slice by slice ([`Cascade`]).
pub(super) fn write_levels<T: Scalar + Element>(
    path: &Path,
    dir: &Path,
    grids: &[Grid],
    o: &ZarrWriteOptions,
    next_slice: &mut dyn FnMut(usize) -> Result<Vec<T>>,
) -> Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().trim_end_matches(".zarr").to_string())
        .unwrap_or_default();
    let ms = multiscales(&name, grids, o.version);
    match o.version {
        ZarrVersion::V2 => {
            write_json(path, &dir.join(".zgroup"), &json!({ "zarr_format": 2 }))?;
            write_json(path, &dir.join(".zattrs"), &json!({ "multiscales": [ms] }))?;
        }
        ZarrVersion::V3 => {
            let root = json!({
                "zarr_format": 3, "node_type": "group",
                "attributes": { "ome": { "version": "0.5", "multiscales": [ms] } }
            });
            write_json(path, &dir.join("zarr.json"), &root)?;
        }
    }
    let store = Arc::new(FilesystemStore::new(dir).map_err(|e| zerr(path, "open store", e))?);
    let arrays = grids
        .iter()
        .enumerate()
        .map(|(l, g)| create_level(path, &store, dir, &l.to_string(), g.dims, T::TYPE, o))
        .collect::<Result<Vec<_>>>()?;
    let mut cascade = Cascade::<T>::new(path, arrays, grids, o.chunk);
    for k in 0..grids[0].dims[2] {
        cascade.push(next_slice(k)?)?;
    }
    cascade.finish()
}
