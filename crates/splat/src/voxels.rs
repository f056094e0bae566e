//! Where the kernels load voxel values from (docs/design/brick-seam.md §2.2, commit C2).
//!
//! The scalar kernels compute a sample's cell, fractions and face tests from **global** index
//! coordinates of the level; only *where* a voxel's value is loaded from goes through
//! [`Voxels`]. [`Linear`] is today's addressing of one in-memory volume, `p·[1, nx, nx·ny]` into
//! `Volume::data()`, so a kernel monomorphised over it computes exactly what it computed before
//! the seam. A bricked addressing (`Slotted`, commit C6) will place each brick in a slot of an
//! arena with the same interface.

use volsplat_core::source::{BrickLayout, HALO};
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

    /// The slot table of a bricked addressing ([`Slotted`]), `None` for one array
    /// ([`Linear`]): the AVX2 kernels locate each lane's brick with it.
    fn slots(&self) -> Option<Slots<'_>> {
        None
    }
}

/// How [`Slotted`] places bricks, for the AVX2 kernels: a cell `c` of brick `b = c >> shift`
/// has its lower corner at `bases[(b_k·bdims_j + b_j)·bdims_i + b_i] + Σ ((c & mask) + H)·[1, E, E²]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Slots<'a> {
    /// Per brick of the level (i fastest): the position of its slot's first voxel in
    /// [`Voxels::data`] (0 for a brick that is not resident: slot 0, a valid read whose values
    /// no live lane uses).
    pub(crate) bases: &'a [u32],
    /// `log2 B`.
    pub(crate) shift: u32,
    /// Bricks per axis.
    pub(crate) bdims: [usize; 3],
    /// `E = B + 3`: voxels per slot side.
    pub(crate) e: usize,
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

/// A bricked addressing (docs/design/brick-seam.md §2.2): the resident bricks of one level,
/// each a slot of `E³` voxels (`E = B + 1 + 2H`, [`BrickLayout::extent`]) in one arena, placed by
/// a table of slot bases per brick. Voxel `p`, read as a corner of cell `c` (`p = c` or `c + 1`
/// per axis, and their neighbours `± 1`), is at `bases[brick(c)] + Σ ((c & (B − 1)) + H + δ)·[1, E, E²]`;
/// the halo of one voxel holds every stencil the kernels read around a cell, so no sample reads
/// two bricks. Only resident bricks may be read by samples that are used; others read slot 0.
///
/// [`BrickLayout::extent`]: volsplat_core::source::BrickLayout::extent
#[derive(Debug, Clone, Copy)]
pub(crate) struct Slotted<'a, T> {
    arena: &'a [T],
    slots: Slots<'a>,
    mask: usize,
    stride: [usize; 3],
    up: [usize; 3],
}

impl<'a, T: Scalar> Slotted<'a, T> {
    /// The addressing of `arena` (slots of `layout.extent()³` voxels, i fastest) through
    /// `bases` (one per brick of `layout`, i fastest, each `slot·E³`).
    pub(crate) fn new(arena: &'a [T], bases: &'a [u32], layout: &BrickLayout) -> Self {
        let e = layout.extent();
        let bdims = layout.dims();
        debug_assert_eq!(bases.len(), bdims.iter().product::<usize>());
        let dims = layout.grid().dims;
        let stride = [1, e, e * e];
        Slotted {
            arena,
            slots: Slots {
                bases,
                shift: layout.shift(),
                bdims,
                e,
            },
            mask: layout.size() - 1,
            stride,
            up: [0, 1, 2].map(|a| usize::from(dims[a] > 1) * stride[a]),
        }
    }

    #[inline(always)]
    fn slot(&self, b: [usize; 3]) -> usize {
        let d = self.slots.bdims;
        self.slots.bases[(b[2] * d[1] + b[1]) * d[0] + b[0]] as usize
    }
}

impl<T: Scalar> Voxels<T> for Slotted<'_, T> {
    #[inline(always)]
    fn linear(&self, p: [usize; 3]) -> usize {
        let sh = self.slots.shift;
        let b: [usize; 3] = std::array::from_fn(|a| (p[a] >> sh).min(self.slots.bdims[a] - 1));
        let mut at = self.slot(b);
        for a in 0..3 {
            at += (p[a] - (b[a] << sh) + HALO) * self.stride[a];
        }
        at
    }

    #[inline(always)]
    fn cell_base(&self, c: [usize; 3]) -> usize {
        let sh = self.slots.shift;
        let mut at = self.slot(c.map(|x| x >> sh));
        for (&ca, &s) in c.iter().zip(&self.stride) {
            at += ((ca & self.mask) + HALO) * s;
        }
        at
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
        self.arena
    }

    fn slots(&self) -> Option<Slots<'_>> {
        Some(self.slots)
    }
}

/// The addressing a frame's march is compiled for: [`Linear`] or [`Slotted`], chosen at run
/// time (one branch per voxel address, always taken the same way in a frame). One type, not
/// a type parameter of the march: the AVX2 kernels compiled twice (once per addressing) were
/// no longer inlined into one another, and a shaded frame spent 17 % of its time moving their
/// 600-byte groups of samples (`memmove`, measured with perf on Colin27; +25 % per frame).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Vox<'a, T> {
    /// One array in memory.
    Linear(Linear<'a, T>),
    /// Resident bricks.
    Slotted(Slotted<'a, T>),
}

impl<T: Scalar> Voxels<T> for Vox<'_, T> {
    #[inline(always)]
    fn linear(&self, p: [usize; 3]) -> usize {
        match self {
            Vox::Linear(l) => l.linear(p),
            Vox::Slotted(s) => s.linear(p),
        }
    }

    #[inline(always)]
    fn cell_base(&self, c: [usize; 3]) -> usize {
        match self {
            Vox::Linear(l) => l.cell_base(c),
            Vox::Slotted(s) => s.cell_base(c),
        }
    }

    #[inline(always)]
    fn stride(&self) -> &[usize; 3] {
        match self {
            Vox::Linear(l) => l.stride(),
            Vox::Slotted(s) => s.stride(),
        }
    }

    #[inline(always)]
    fn up(&self) -> [usize; 3] {
        match self {
            Vox::Linear(l) => l.up(),
            Vox::Slotted(s) => s.up(),
        }
    }

    #[inline(always)]
    fn data(&self) -> &[T] {
        match self {
            Vox::Linear(l) => l.data(),
            Vox::Slotted(s) => s.data(),
        }
    }

    fn slots(&self) -> Option<Slots<'_>> {
        match self {
            Vox::Linear(_) => None,
            Vox::Slotted(s) => s.slots(),
        }
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
