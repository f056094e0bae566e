//! The pyramid written one z slice at a time ([`Cascade`]): each level keeps the slices of
//! its current chunk row and the few fine slices its next level's filter needs, so memory is
//! bounded by about a chunk's height of slices per level, whatever the volume's depth.
//!
//! Each coarse slice is computed by [`Volume::halved_slice`] itself, on a small volume of the
//! (at most 4) fine slices its taps read, in the taps' order, so that its arithmetic is the
//! whole-volume call's, bit for bit (decision 0031's filter; decision 0037).

use super::write::zerr;
use crate::error::{IoError, Result};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use volsplat_core::{Grid, Scalar, Volume};
use zarrs::array::{Array, Element};
use zarrs::filesystem::FilesystemStore;

/// One level being written.
struct Level<T> {
    array: Array<FilesystemStore>,
    grid: Grid,
    /// Chunk edges along x, y, z (each at most the level's size).
    chunk: [usize; 3],
    /// Slices of the current chunk row, from `slab_k0`.
    slab: Vec<T>,
    slab_k0: usize,
    /// Slices received so far.
    received: usize,
    /// The axes the next level halves (`None` for the last level).
    axes: Option<[bool; 3]>,
    /// Recent slices kept for the next level's filter: (index, samples).
    window: VecDeque<(usize, Vec<T>)>,
    /// The next level's next slice to compute.
    next_m: usize,
    /// The next level's slice count.
    next_nz: usize,
}

/// Writes the levels of a pyramid slice by slice: [`Cascade::push`] level 0's slices in
/// order, then [`Cascade::finish`].
pub(super) struct Cascade<T> {
    path: PathBuf,
    levels: Vec<Level<T>>,
}

impl<T: Scalar + Element> Cascade<T> {
    /// A cascade over `arrays` (level `l`'s array on `grids[l]`), chunks of edge `chunk`.
    pub(super) fn new(
        path: &Path,
        arrays: Vec<Array<FilesystemStore>>,
        grids: &[Grid],
        chunk: usize,
    ) -> Self {
        let levels = arrays
            .into_iter()
            .enumerate()
            .map(|(l, array)| {
                let g = &grids[l];
                Level {
                    array,
                    grid: g.clone(),
                    chunk: g.dims.map(|n| n.min(chunk)),
                    slab: Vec::new(),
                    slab_k0: 0,
                    received: 0,
                    axes: grids.get(l + 1).map(|_| g.pyramid_axes()),
                    window: VecDeque::new(),
                    next_m: 0,
                    next_nz: grids.get(l + 1).map_or(0, |n| n.dims[2]),
                }
            })
            .collect();
        Cascade {
            path: path.to_path_buf(),
            levels,
        }
    }

    /// Level 0's next slice (`nx · ny` samples, x fastest).
    pub(super) fn push(&mut self, slice: Vec<T>) -> Result<()> {
        push(&self.path, &mut self.levels, slice)
    }

    /// Checks that every level received all its slices (and so was written whole).
    pub(super) fn finish(self) -> Result<()> {
        for (l, level) in self.levels.iter().enumerate() {
            if level.received != level.grid.dims[2] || !level.slab.is_empty() {
                return Err(IoError::invalid_argument(
                    &self.path,
                    "slices",
                    format!(
                        "level {l} received {} of its {} slices",
                        level.received, level.grid.dims[2]
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Adds `slice` to `levels[0]`: into its chunk row (written when full), then into the window
/// from which the next level's slices are computed and pushed, in order.
fn push<T: Scalar + Element>(path: &Path, levels: &mut [Level<T>], slice: Vec<T>) -> Result<()> {
    let Some((level, rest)) = levels.split_first_mut() else {
        return Ok(());
    };
    let [nx, ny, nz] = level.grid.dims;
    let k = level.received;
    if k >= nz || slice.len() != nx * ny {
        return Err(IoError::invalid_argument(
            path,
            "slice",
            format!(
                "slice {k} of {nz} with {} samples (expected {})",
                slice.len(),
                nx * ny
            ),
        ));
    }
    level.received += 1;
    level.slab.extend_from_slice(&slice);
    if level.received - level.slab_k0 == level.chunk[2] || level.received == nz {
        write_chunk_row(path, level)?;
    }
    let Some(axes) = level.axes else {
        return Ok(());
    };
    level.window.push_back((k, slice));
    while level.next_m < level.next_nz {
        let m = level.next_m;
        let taps: Vec<usize> = if axes[2] {
            (0..4)
                .map(|t| (2 * m + t).saturating_sub(2).min(nz - 1))
                .collect()
        } else {
            vec![m]
        };
        if taps.iter().any(|&i| i >= level.received) {
            break;
        }
        let coarse = coarse_slice(path, level, axes, &taps)?;
        level.next_m += 1;
        // Slices below the next coarse slice's first tap are no longer needed.
        let first = if axes[2] {
            (2 * level.next_m).saturating_sub(2)
        } else {
            level.next_m
        };
        while level.window.front().is_some_and(|(i, _)| *i < first) {
            level.window.pop_front();
        }
        push(path, rest, coarse)?;
    }
    Ok(())
}

/// The next level's slice whose z taps read fine slices `taps` (in tap order): one call of
/// [`Volume::halved_slice`] on a volume made of those slices.
fn coarse_slice<T: Scalar>(
    path: &Path,
    level: &Level<T>,
    axes: [bool; 3],
    taps: &[usize],
) -> Result<Vec<T>> {
    let [nx, ny, _] = level.grid.dims;
    let mut data = Vec::with_capacity(nx * ny * taps.len());
    for &i in taps {
        let Some((_, s)) = level.window.iter().find(|(j, _)| *j == i) else {
            return Err(IoError::invalid_argument(
                path,
                "slice",
                format!("fine slice {i} is no longer held"),
            ));
        };
        data.extend_from_slice(s);
    }
    let g = &level.grid;
    let grid = Grid::new([nx, ny, taps.len()], g.spacing, g.origin, g.direction)
        .map_err(|e| IoError::core(path, e))?;
    let part = Volume::new(grid, data).map_err(|e| IoError::core(path, e))?;
    // With 4 slices and k = 1 the z taps 2k − 2 … 2k + 1 are slices 0 … 3; unhalved, slice 0.
    let k = usize::from(axes[2]);
    let mx = if axes[0] { nx.div_ceil(2) + 1 } else { nx };
    let my = if axes[1] { ny.div_ceil(2) + 1 } else { ny };
    let mut out = vec![T::from_f64(0.0); mx * my];
    part.halved_slice(axes, k, &mut out);
    Ok(out)
}

/// Writes the chunks of `level`'s current chunk row (padded with the fill value 0 past the
/// level's edges) and empties it.
fn write_chunk_row<T: Scalar + Element>(path: &Path, level: &mut Level<T>) -> Result<()> {
    let [nx, ny, _] = level.grid.dims;
    let [cx, cy, cz] = level.chunk;
    let rows = level.slab.len() / (nx * ny);
    let zero = T::from_f64(0.0);
    let mut chunk = vec![zero; cx * cy * cz];
    let kz = (level.slab_k0 / cz) as u64;
    for by in 0..ny.div_ceil(cy) {
        for bx in 0..nx.div_ceil(cx) {
            chunk.fill(zero);
            let (x0, y0) = (bx * cx, by * cy);
            let xn = (nx - x0).min(cx);
            for z in 0..rows {
                for y in 0..(ny - y0).min(cy) {
                    let src = &level.slab[(z * ny + y0 + y) * nx + x0..][..xn];
                    let dst = (z * cy + y) * cx;
                    chunk[dst..dst + xn].copy_from_slice(src);
                }
            }
            level
                .array
                .store_chunk(&[kz, by as u64, bx as u64], &chunk[..])
                .map_err(|e| zerr(path, "write chunk", e))?;
        }
    }
    level.slab.clear();
    level.slab_k0 = level.received;
    Ok(())
}
