//! OME-Zarr multiscale images (issue 31; decision 0037): read any level of an OME-Zarr v0.4
//! (Zarr v2, `.zattrs`) or v0.5 (Zarr v3, `zarr.json`) store on the filesystem, and write a
//! v0.4 or v0.5 pyramid.
//!
//! Reading ([`read_zarr_with`], [`ZarrStore`], through the `zarrs` crate; codecs blosc, zstd,
//! gzip, sharding, crc32c, transpose):
//!
//! - **Layout.** The store's root group holds the `multiscales` (v0.4 `.zattrs`, v0.5
//!   `zarr.json` `attributes.ome`); a bioformats2raw root (`bioformats2raw.layout`, no
//!   multiscales) is read through its image `0`, with a note.
//! - **Axes.** The `axes` metadata (time, channel or custom, then 2 or 3 spatial axes ordered
//!   z, y, x) pick the volume: x, y, z are volsplat's i, j, k; [`ReadOptions::channel`] and
//!   [`ReadOptions::timepoint`] pick the entry of the channel and time axes (0 by default);
//!   custom axes must have one entry. A 2-D image (y, x) is a volume of one slice.
//! - **Geometry.** The level's `coordinateTransformations` (`scale`, then `translation`,
//!   then the multiscale's own, composed as the specification says) give the spacing and the
//!   origin (the world position of sample 0), converted to mm from the spatial axes' `unit`
//!   (`micrometer` × 0.001, `nanometer` × 10⁻⁶, ...; no unit: taken as mm, with a note). No
//!   anatomical frame: world x, y, z are the store's, the direction is the identity.
//! - **Samples.** `uint8`, `int8`, `uint16`, `int16`, `float32` as they are; `int32`,
//!   `uint32`, `float64` converted to `f32` as the NRRD reader does (a note says so); other
//!   types are an error naming the array and type. Missing chunks read as the fill value.
//! - **Trust.** The level's voxel count is checked against [`crate::Limits`] before
//!   allocating, chunk shapes too; dataset paths must stay inside the store; zero, negative
//!   or non-finite scales, missing multiscales, a level, channel or time point out of range
//!   and corrupt chunks are errors naming the store, field and value.
//!
//! Writing ([`write_zarr`] from a volume in memory, [`convert_to_zarr`] from a file,
//! [`ZarrWriteOptions`]): OME-Zarr 0.4 on Zarr v2 (blosc-zstd; the default) or 0.5 on Zarr v3
//! (zstd), cubic chunks (64 by default), levels by the renderer's own prefilter
//! ([`volsplat_core::Volume::halved`]) until one fits a chunk ([`pyramid_grids`]), written
//! slice by slice (uncompressed raw and NRRD files are streamed: memory bounded by about a
//! chunk's height of slices per level), into a temporary folder renamed at the end.
//!
//! [`ReadOptions::channel`]: crate::ReadOptions::channel
//! [`ReadOptions::timepoint`]: crate::ReadOptions::timepoint

mod chunks;
mod convert;
mod meta;
mod source;
mod store;
mod stream;
mod write;

pub use convert::{ConvertedZarr, convert_to_zarr};
pub use source::ZarrSource;
pub(crate) use store::is_zarr_store;
pub use store::{ZarrLevel, ZarrSelection, ZarrStore};
pub use write::{
    MAX_LEVELS, WrittenZarr, ZarrVersion, ZarrWriteOptions, check_zarr_output, pyramid_grids,
    write_zarr,
};

use crate::error::Result;
use crate::read::{LoadedVolume, ReadOptions};
use std::path::Path;

/// Reads one level of an OME-Zarr store with [`ReadOptions`]: `level` (0: full resolution),
/// `channel`, `timepoint`, `limits`. `frame`, `array` and `series` do not apply and are
/// refused (`timepoint` picks a time point). The result's `frames` is the number of time
/// points and `frame` the one read; notes say what the metadata implied.
pub fn read_zarr_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let path = path.as_ref();
    options.refuse_series(path)?;
    if options.array.is_some() {
        return Err(crate::IoError::invalid_argument(
            path,
            "array",
            "choosing an array applies to VTK .vti files only, not to OME-Zarr",
        ));
    }
    if options.frame != 0 {
        return Err(crate::IoError::invalid_argument(
            path,
            "frame",
            "an OME-Zarr store's time points are chosen with `timepoint`, not `frame`",
        ));
    }
    let store = ZarrStore::open(path, &options.limits)?;
    let level = options.level;
    let l = store.level(level)?.clone();
    let sel = ZarrSelection {
        channel: options.channel,
        timepoint: options.timepoint,
    };
    let volume = store.read_level(level, sel)?;
    let mut notes = store.notes().to_vec();
    if store.levels().len() > 1 || level > 0 {
        notes.push(format!(
            "level {level} of {} (array `{}`, {} × {} × {} samples)",
            store.levels().len(),
            l.path,
            l.dims[0],
            l.dims[1],
            l.dims[2]
        ));
    }
    notes.extend(store.conversion_note(level));
    if store.channels() > 1 {
        notes.push(format!(
            "channel {} of {}",
            options.channel,
            store.channels()
        ));
    }
    Ok(LoadedVolume {
        frames: store.timepoints() as usize,
        frame: options.timepoint,
        ..LoadedVolume::single(volume, &store.format(), notes)
    })
}

#[cfg(test)]
mod tests;
