//! Min/max bricks for empty-space skipping (issue 12 item 2; the "min/max volume" of VTK's
//! `vtkFixedPointVolumeRayCastMapper`, whose cells are 4³ voxels).
//!
//! The volume is cut into cubes of [`BRICK`]³ cells. Brick `b` along an axis covers the voxel
//! indices `[B·b, B·b + B]`, *both ends included*: the cells whose lower corner lies in the
//! brick, with the far face shared with the next brick. A trilinear sample whose cell's lower
//! corner is voxel `i` (so it reads voxels `i` and `i + 1`) therefore lies in brick `i / B`
//! and its value lies in that brick's `[min, max]` (a convex combination of the eight corners).
//! This makes every skip below exact: it never skips a sample that could contribute.
//!
//! The grid is built once per volume (one pass, parallel) and kept by the engine's `Renderer`;
//! what depends on the transfer function is a bit per brick, rebuilt per frame in microseconds
//! ([`BrickGrid::active`]).

use rayon::prelude::*;
use volsplat_core::{LookupTable, Scalar, TableIndex, Volume};

/// Cells per brick side (a power of two).
pub const BRICK: usize = 8;
const SHIFT: u32 = BRICK.trailing_zeros();

/// Per-brick value ranges of one volume.
#[derive(Debug, Clone, PartialEq)]
pub struct BrickGrid {
    /// Bricks per axis: `ceil((n − 1) / B)`, at least 1.
    pub dims: [usize; 3],
    /// `[min, max]` of the voxels of each brick (data units), `i` fastest.
    pub ranges: Vec<[f32; 2]>,
    /// The volume dimensions this grid was built for.
    pub volume_dims: [usize; 3],
    /// The voxels' direction codes for shading at the voxels ([`crate::normals`]), built on
    /// first use ([`BrickGrid::normals`]) and kept with the grid, so a caller that keeps the
    /// grid across frames (the engine's `Renderer`) builds them once per volume.
    normals: std::sync::OnceLock<crate::normals::NormalField>,
}

impl BrickGrid {
    /// Scans `volume` once. Voxels that are NaN are ignored (a brick of NaNs has the empty range
    /// `[+∞, −∞]` and is never active).
    pub fn build<T: Scalar>(volume: &Volume<T>) -> Self {
        let n = volume.grid().dims;
        let dims = n.map(|d| d.saturating_sub(1).div_ceil(BRICK).max(1));
        let data = volume.data();
        let (nx, ny) = (n[0], n[1]);
        let ranges: Vec<[f32; 2]> = (0..dims[2])
            .into_par_iter()
            .flat_map_iter(|bk| {
                let mut slab = vec![[f32::INFINITY, f32::NEG_INFINITY]; dims[0] * dims[1]];
                let k_lo = bk * BRICK;
                let k_hi = (k_lo + BRICK).min(n[2] - 1);
                for k in k_lo..=k_hi {
                    for j in 0..ny {
                        // Rows j shared by two bricks (j = B·b) go to both.
                        let raw = j >> SHIFT;
                        let bj_lo = if j > 0 && j % BRICK == 0 {
                            raw - 1
                        } else {
                            raw
                        };
                        let bj_hi = raw.min(dims[1] - 1);
                        let row = &data[(k * ny + j) * nx..(k * ny + j + 1) * nx];
                        for (bi, chunk_start) in (0..dims[0]).map(|b| (b, b * BRICK)) {
                            let hi = (chunk_start + BRICK).min(nx - 1);
                            let (mut lo_v, mut hi_v) = (f32::INFINITY, f32::NEG_INFINITY);
                            for &v in &row[chunk_start..=hi] {
                                let v = v.to_f32();
                                lo_v = lo_v.min(v);
                                hi_v = hi_v.max(v);
                            }
                            for bj in bj_lo..=bj_hi {
                                let r = &mut slab[bj * dims[0] + bi];
                                r[0] = r[0].min(lo_v);
                                r[1] = r[1].max(hi_v);
                            }
                        }
                    }
                }
                slab
            })
            .collect();
        BrickGrid {
            dims,
            ranges,
            volume_dims: n,
            normals: std::sync::OnceLock::new(),
        }
    }

    /// The grid of a level cut by `layout`, from its bricks' 8³-block ranges: `ranges8` holds
    /// [`volsplat_core::Brick::ranges8`] of every brick, `(B/8)³` per brick, bricks in index
    /// order (`(b_k·d_j + b_j)·d_i + b_i` over [`BrickLayout::dims`], as
    /// [`crate::cache::LevelScan::ranges8`]). Block `g` of the grid is block `g mod (B/8)` of
    /// brick `g div (B/8)`: both cover the voxels `[8g, 8g + 8]` clamped to the level, so the
    /// grid equals [`BrickGrid::build`] of the level read whole (min and max are exact and
    /// order-free; only the sign of a zero bound may differ, which `==` does not see).
    ///
    /// Errors ([`crate::SplatError::Core`], naming `ranges8`) if `ranges8` is not `(B/8)³` per
    /// brick of the layout.
    ///
    /// [`BrickLayout::dims`]: volsplat_core::BrickLayout::dims
    pub fn from_ranges8(
        layout: &volsplat_core::BrickLayout,
        ranges8: &[[f32; 2]],
    ) -> crate::Result<Self> {
        let per = layout.blocks_per_brick();
        let per3 = per * per * per;
        if ranges8.len() != layout.brick_count() * per3 {
            return Err(volsplat_core::CoreError::invalid(
                "ranges8",
                ranges8.len(),
                format!(
                    "must hold {per3} block ranges for each of the level's {} bricks",
                    layout.brick_count()
                ),
            )
            .into());
        }
        let n = layout.grid().dims;
        let dims = n.map(|d| d.saturating_sub(1).div_ceil(BRICK).max(1));
        let bd = layout.dims();
        let mut ranges =
            crate::error::try_with_capacity(dims.iter().product(), "the skip-block ranges")?;
        for gk in 0..dims[2] {
            for gj in 0..dims[1] {
                for gi in 0..dims[0] {
                    let g = [gi, gj, gk];
                    let b: [usize; 3] = std::array::from_fn(|a| g[a] / per);
                    let q: [usize; 3] = std::array::from_fn(|a| g[a] % per);
                    let brick = (b[2] * bd[1] + b[1]) * bd[0] + b[0];
                    ranges.push(ranges8[brick * per3 + (q[2] * per + q[1]) * per + q[0]]);
                }
            }
        }
        Ok(BrickGrid {
            dims,
            ranges,
            volume_dims: n,
            normals: std::sync::OnceLock::new(),
        })
    }

    /// The direction codes of `volume`'s voxels ([`crate::normals::NormalField`]), built on the
    /// first call and kept; `None` if the grid was not built for a volume of this shape (or the
    /// kept field was built for other axes or spacings), in which case the caller builds its own.
    /// Errors if the field cannot be allocated ([`crate::SplatError::OutOfMemory`]).
    pub fn normals<T: Scalar>(
        &self,
        volume: &Volume<T>,
    ) -> crate::Result<Option<&crate::normals::NormalField>> {
        let grid = volume.grid();
        if grid.dims != self.volume_dims {
            return Ok(None);
        }
        let f = match self.normals.get() {
            Some(f) => f,
            None => {
                let built = crate::normals::NormalField::build(volume)?;
                self.normals.get_or_init(|| built)
            }
        };
        Ok(f.fits(grid).then_some(f))
    }

    /// Index of the brick holding the cell whose lower corner is voxel `(i, j, k)`.
    #[inline(always)]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        ((k >> SHIFT) * self.dims[1] + (j >> SHIFT)) * self.dims[0] + (i >> SHIFT)
    }

    /// One flag per brick: whether any value in its range has non-zero `opacity` (the table as
    /// [`LookupTable::lookup`] reads it: linear between entries, clamped at the ends). The test
    /// reads the entries around the range, widened by `slack` data units each side, so a
    /// classifier that resamples the table (as `FrameClassifier`'s fused table does) is covered.
    /// A table not indexed by density makes every brick active. With `dilate`, a brick is also
    /// active when one of its 26 neighbours is (shading reads neighbouring samples).
    pub fn active(&self, opacity: &LookupTable<1>, slack: f32, dilate: bool) -> Vec<bool> {
        if opacity.index != TableIndex::Density {
            return vec![true; self.ranges.len()];
        }
        let vals = &opacity.values;
        let n = vals.len();
        // prefix[i] = number of non-zero entries among 0..i.
        let mut prefix = Vec::with_capacity(n + 1);
        prefix.push(0u32);
        for v in vals {
            let last = *prefix.last().unwrap_or(&0);
            prefix.push(last + u32::from(v[0] > 0.0 || v[0].is_nan()));
        }
        let scale = if n > 1 && opacity.hi > opacity.lo {
            (n - 1) as f32 / (opacity.hi - opacity.lo)
        } else {
            0.0
        };
        let pos = |x: f32| (x - opacity.lo) * scale;
        let mut flags: Vec<bool> = self
            .ranges
            .iter()
            .map(|&[lo, hi]| {
                if lo > hi || lo.is_nan() || hi.is_nan() {
                    return false;
                }
                let a = pos(lo - slack).floor();
                let b = pos(hi + slack).ceil();
                let last = (n - 1) as f32;
                let i0 = a.clamp(0.0, last) as usize;
                let i1 = b.clamp(0.0, last) as usize;
                prefix[i1 + 1] > prefix[i0]
            })
            .collect();
        if dilate {
            let src = flags.clone();
            let [bx, by, bz] = self.dims;
            for k in 0..bz {
                for j in 0..by {
                    for i in 0..bx {
                        let idx = (k * by + j) * bx + i;
                        if src[idx] {
                            continue;
                        }
                        'search: for dk in k.saturating_sub(1)..=(k + 1).min(bz - 1) {
                            for dj in j.saturating_sub(1)..=(j + 1).min(by - 1) {
                                for di in i.saturating_sub(1)..=(i + 1).min(bx - 1) {
                                    if src[(dk * by + dj) * bx + di] {
                                        flags[idx] = true;
                                        break 'search;
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        flags
    }

    /// One flag per brick: whether a trilinear sample in it can have opacity through a table
    /// read the way the slab kernels read theirs: at position `pos(x)` (monotone in `x`,
    /// clamped to the table) by linear interpolation between entries `⌊t⌋` and `⌊t⌋ + 1` with
    /// weight `t − ⌊t⌋`, where `nonzero[i]` says whether entry `i` has opacity (NaN counts as
    /// opacity). Exact for the tables' own interpolation: a brick whose eight-corner samples
    /// all map between two entries without opacity is inactive, however close its range lies
    /// to a ramp, where [`BrickGrid::active`] keeps a slack of table entries around it. A brick
    /// of one value `c` reads exactly the table at `pos(c)` (every trilinear combination of
    /// equal corners is `c` in f32); other ranges are widened by 2⁻¹⁹ of their magnitude, above
    /// the rounding of three nested f32 linear interpolations (at most a few units in the last
    /// place).
    pub fn active_in_table(&self, nonzero: &[bool], pos: impl Fn(f32) -> f32) -> Vec<bool> {
        let n = nonzero.len();
        if n == 0 {
            return vec![false; self.ranges.len()];
        }
        let mut prefix = Vec::with_capacity(n + 1);
        prefix.push(0u32);
        for &z in nonzero {
            let last = *prefix.last().unwrap_or(&0);
            prefix.push(last + u32::from(z));
        }
        let last = (n - 1) as f32;
        self.ranges
            .iter()
            .map(|&[lo, hi]| {
                if lo > hi || lo.is_nan() || hi.is_nan() {
                    return false;
                }
                let (a, b) = if lo == hi {
                    (lo, hi)
                } else {
                    let eps = lo.abs().max(hi.abs()) * f32::EPSILON * 16.0 + f32::MIN_POSITIVE;
                    (lo - eps, hi + eps)
                };
                let (ta, tb) = (pos(a), pos(b));
                if ta.is_nan() || tb.is_nan() {
                    return true;
                }
                let i0 = ta.floor().clamp(0.0, last) as usize;
                let i1 = tb.ceil().clamp(0.0, last) as usize;
                prefix[i1 + 1] > prefix[i0]
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::Grid;

    fn vol(dims: [usize; 3], f: impl Fn(usize, usize, usize) -> f32) -> Volume<f32> {
        Volume::from_fn(Grid::with_dims(dims).unwrap(), f).unwrap()
    }

    #[test]
    fn every_cell_value_lies_in_its_brick_range() {
        let dims = [19, 17, 9];
        let v = vol(dims, |i, j, k| ((i * 7 + j * 13 + k * 31) % 23) as f32);
        let g = BrickGrid::build(&v);
        assert_eq!(g.dims, [3, 2, 1]);
        for k in 0..dims[2] - 1 {
            for j in 0..dims[1] - 1 {
                for i in 0..dims[0] - 1 {
                    let [lo, hi] = g.ranges[g.index(i, j, k)];
                    for c in 0..8 {
                        let x = v.get(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2));
                        assert!(lo <= x && x <= hi, "cell {i},{j},{k} corner {c}");
                    }
                }
            }
        }
    }

    #[test]
    fn ranges_are_tight() {
        let v = vol([17, 9, 9], |i, _, _| i as f32);
        let g = BrickGrid::build(&v);
        assert_eq!(g.ranges[0], [0.0, 8.0]);
        assert_eq!(g.ranges[1], [8.0, 16.0]);
    }

    #[test]
    fn activity_follows_the_opacity_table() {
        let v = vol([17, 9, 9], |i, _, _| i as f32);
        let g = BrickGrid::build(&v);
        // Opacity zero below 10, positive from 12: brick 0 ([0, 8]) is empty, brick 1 is not.
        let table = LookupTable::from_fn(TableIndex::Density, 0.0, 16.0, 17, |x| {
            [if x >= 12.0 { 0.5 } else { 0.0 }]
        });
        assert_eq!(g.active(&table, 0.0, false), vec![false, true]);
        assert_eq!(g.active(&table, 0.0, true), vec![true, true]);
        // A ramp starting between 8 and 9 (entries 8 = 0, 9 > 0): interpolation makes values just
        // above 8 non-zero, and brick 0's range ends at 8 exactly, so it stays empty.
        let ramp =
            LookupTable::from_fn(TableIndex::Density, 0.0, 16.0, 17, |x| [(x - 8.0).max(0.0)]);
        assert_eq!(g.active(&ramp, 0.0, false), vec![false, true]);
        assert_eq!(g.active(&ramp, 0.5, false), vec![true, true]);
    }

    #[test]
    fn table_activity_is_exact_at_an_entry() {
        // Brick 0 holds only 0; brick 1 holds 0 and 16; brick 2 only 16.
        let v = vol([25, 9, 9], |i, _, _| if i <= 8 { 0.0 } else { 16.0 });
        let g = BrickGrid::build(&v);
        assert_eq!(g.dims, [3, 1, 1]);
        // Entries at 0, 1, …, 16: opacity from entry 1 on. Value 0 reads entry 0 alone.
        let nonzero: Vec<bool> = (0..17).map(|i| i >= 1).collect();
        let pos = |x: f32| x.clamp(0.0, 16.0);
        assert_eq!(g.active_in_table(&nonzero, pos), vec![false, true, true]);
        // The slack test cannot tell brick 0 from a brick that reaches into the ramp.
        let table = LookupTable::from_fn(TableIndex::Density, 0.0, 16.0, 17, |x| {
            [if x >= 1.0 { 0.5 } else { 0.0 }]
        });
        assert_eq!(g.active(&table, 0.01, false), vec![true, true, true]);
        // Opacity only above 16 (past the table): nothing is active; only at entry 0 (below
        // the data's range start): brick 0 and brick 1, whose range starts there.
        let none = vec![false; 17];
        assert_eq!(g.active_in_table(&none, pos), vec![false; 3]);
        let first: Vec<bool> = (0..17).map(|i| i == 0).collect();
        assert_eq!(g.active_in_table(&first, pos), vec![true, true, false]);
        // A range a hair wide around an entry reaches the neighbours of that entry.
        let near = vol([9, 9, 9], |i, _, _| if i == 0 { 3.0 } else { 3.0 + 1e-3 });
        let g = BrickGrid::build(&near);
        let only4: Vec<bool> = (0..17).map(|i| i == 4).collect();
        assert_eq!(g.active_in_table(&only4, pos), vec![true]);
        let only2: Vec<bool> = (0..17).map(|i| i == 2).collect();
        assert_eq!(g.active_in_table(&only2, pos), vec![true]);
        let only5: Vec<bool> = (0..17).map(|i| i == 5).collect();
        assert_eq!(g.active_in_table(&only5, pos), vec![false]);
    }
}
