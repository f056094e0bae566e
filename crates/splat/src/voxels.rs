//! Where the kernels load voxel values from (docs/design/brick-seam.md §2.2, commit C2).
//!
//! The scalar kernels compute a sample's cell, fractions and face tests from **global** index
//! coordinates of the level; only *where* a voxel's value is loaded from goes through
//! [`Voxels`]. [`Linear`] is today's addressing of one in-memory volume, `p·[1, nx, nx·ny]` into
//! `Volume::data()`, so a kernel monomorphised over it computes exactly what it computed before
//! the seam. A bricked addressing (`Slotted`, commit C6) will place each brick in a slot of an
//! arena with the same interface.

use volsplat_core::{Scalar, Volume};

/// An addressing of the voxels of one level: positions in [`Voxels::data`] of voxels given by
/// their global index `p = (i, j, k)`, `0 ≤ p < dims`.
///
/// Two anchors exist because a bricked addressing may hold a voxel on a brick's face in two
/// slots: [`Voxels::cell_base`] anchors the stencils of a cell (its eight corners, and their
/// central differences), [`Voxels::linear`] those centred on one voxel. From either anchor the
/// neighbours lie at `± stride()[a]` and the cell's upper corners at `up()[a]`.
pub(crate) trait Voxels<T>: Sync {
    /// Position in [`Voxels::data`] of voxel `p` (global index), anchoring a stencil centred on
    /// it (`p ± 1` per axis, within the level).
    fn linear(&self, p: [usize; 3]) -> usize;

    /// Position in [`Voxels::data`] of the lower corner of cell `c` (global index, each
    /// component at most `max(n, 2) − 2`), anchoring the cell's stencils (voxels `c − 1 … c + 2`
    /// per axis, within the level).
    fn cell_base(&self, c: [usize; 3]) -> usize;

    /// Offset from a voxel to the next along each axis (in [`Voxels::data`] positions). A
    /// reference, so that indexing it by a run-time axis loads one stride (a returned array
    /// was copied whole: +2 % instructions in the shaded slabs, measured with cachegrind).
    fn stride(&self) -> &[usize; 3];

    /// Offset from a cell's lower corner to its upper corner along each axis: the stride, or 0
    /// along an axis of one voxel (whose one degenerate cell reads its voxel twice; decision
    /// 0023).
    fn up(&self) -> [usize; 3];

    /// What the positions index.
    fn data(&self) -> &[T];
}

/// Today's addressing: voxel `p` at `p·[1, nx, nx·ny]` in the volume's samples.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Linear<'a, T> {
    data: &'a [T],
    stride: [usize; 3],
    up: [usize; 3],
}

impl<'a, T: Scalar> Linear<'a, T> {
    /// The addressing of `volume`'s samples.
    pub(crate) fn new(volume: &'a Volume<T>) -> Self {
        Linear::from_parts(volume.data(), volume.grid().dims)
    }

    /// The addressing of `data`, the samples of a grid of `dims` voxels, i fastest
    /// (`data.len()` is `dims.x·dims.y·dims.z`, as [`Volume::data`]).
    #[inline(always)]
    pub(crate) fn from_parts(data: &'a [T], dims: [usize; 3]) -> Self {
        debug_assert_eq!(data.len(), dims.iter().product::<usize>());
        Linear {
            data,
            stride: [1, dims[0], dims[0] * dims[1]],
            up: [
                usize::from(dims[0] > 1),
                usize::from(dims[1] > 1) * dims[0],
                usize::from(dims[2] > 1) * dims[0] * dims[1],
            ],
        }
    }
}

impl<T: Scalar> Voxels<T> for Linear<'_, T> {
    #[inline(always)]
    fn linear(&self, p: [usize; 3]) -> usize {
        p[0] + p[1] * self.stride[1] + p[2] * self.stride[2]
    }

    #[inline(always)]
    fn cell_base(&self, c: [usize; 3]) -> usize {
        self.linear(c)
    }

    #[inline(always)]
    fn stride(&self) -> &[usize; 3] {
        &self.stride
    }

    #[inline(always)]
    fn up(&self) -> [usize; 3] {
        self.up
    }

    #[inline(always)]
    fn data(&self) -> &[T] {
        self.data
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::Grid;

    #[test]
    fn linear_addresses_every_voxel_as_the_volume_does() {
        for dims in [[5, 4, 3], [1, 4, 3], [5, 1, 1], [1, 1, 1]] {
            let v = Volume::from_fn(Grid::with_dims(dims).unwrap(), |i, j, k| {
                (i + 10 * j + 100 * k) as u16
            })
            .unwrap();
            let l = Linear::new(&v);
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        assert_eq!(l.data()[l.linear([i, j, k])], v.get(i, j, k));
                        assert_eq!(l.cell_base([i, j, k]), l.linear([i, j, k]));
                    }
                }
            }
            // The next voxel along each axis, or the same one along an axis of one voxel.
            for a in 0..3 {
                let mut q = [0; 3];
                q[a] = usize::from(dims[a] > 1);
                assert_eq!(
                    l.data()[l.up()[a]],
                    v.get(q[0], q[1], q[2]),
                    "{dims:?} axis {a}"
                );
                if dims[a] > 1 {
                    assert_eq!(l.stride()[a], l.up()[a]);
                }
            }
        }
    }
}
