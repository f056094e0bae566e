//! Exact culling of MIP/MinIP splats that cannot change the projection (issue 12 item 2: "skip
//! … whose max cannot exceed the current pixel"; the bound is VTK's
//! `vtkFixedPointVolumeRayCastMapper::CheckMIPMinMaxVolumeFlag`, applied here per sheet and per
//! 4 × 4-pixel tile instead of per ray and per 4³-voxel cell).
//!
//! In a sheet, a pixel's candidate is the normalised reconstruction `Σ wᵢρᵢ / Σ wᵢ` over the splats
//! covering it, and it replaces the running maximum `a` only if it is larger
//! ([`crate::sheets::BandState::splat_sheet`]). With non-negative weights the candidate is a convex
//! combination of the `ρᵢ`, so it is at most `M = max ρᵢ` up to rounding: `|error| ≤ 2nε·max|ρᵢ|`
//! for `n` terms (Higham 2002, *Accuracy and Stability of Numerical Algorithms* §4.2, recursive
//! summation), about 10⁻⁵·max|ρᵢ| for the ≤ 100 splats that overlap a pixel in one sheet.
//!
//! So a tile is *dead* for a sheet when the largest splat value reaching it, plus a margin of
//! 10⁻⁴·max|ρᵢ|, is still below the smallest running maximum in it (NaN, not yet covered, is never
//! dead); or when every splat value reaching it is exactly zero and the running maxima are ≥ 0
//! (the candidate is then exactly ±0). A splat all of whose tiles are dead is skipped: the pixels
//! it would touch keep their maxima whatever it adds, and the other pixels never see it. Nothing
//! in the output changes, bit for bit. MinIP is the same on negated values.
//!
//! Kernels with negative lobes (weights < 0) break the convexity; the caller does not cull them.

use crate::footprint::FootprintTable;
use crate::sheets::{Splat, TILE};
use volsplat_core::image::Rgba;

/// Tests switch culling off to compare against the plain loop.
static ENABLED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Whether culling is on (always, outside tests).
#[inline]
pub(crate) fn enabled() -> bool {
    ENABLED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Switches culling on or off (tests only).
#[cfg(test)]
pub(crate) fn set_enabled(on: bool) {
    ENABLED.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// Relative margin of the bound (see the module documentation).
const MARGIN: f32 = 1e-4;

/// Per band: each tile's smallest running extreme (in "key" space: the value for MIP, its negation
/// for MinIP), and scratch for one sheet.
///
/// A splat is filed under its *origin tile*, the tile of the first pixel of its footprint block
/// (clipped to the band and the image); its block then lies within `dx × dy` tiles from there.
/// Dilating the per-origin maxima by that window bounds what reaches each tile, and eroding the
/// dead flags by the same window tells, per origin tile, whether every tile a splat filed there
/// can reach is dead: one lookup per splat. Both over-approximate the reach, so culling stays
/// exact and only skips a little less.
#[derive(Debug, Default)]
pub(crate) struct MipTiles {
    /// Smallest key of the accumulation buffer per tile; −∞ where any pixel is NaN.
    floor: Vec<f32>,
    hi: Vec<f32>,
    lo: Vec<f32>,
    tmp: Vec<f32>,
    /// Per tile, then (after [`MipTiles::prepare`]) per origin tile: dead.
    dead: Vec<bool>,
    row_ok: Vec<bool>,
    /// Per splat of the current sheet: its origin tile, or `u32::MAX` when its block misses the
    /// band (nothing to draw).
    origin: Vec<u32>,
    /// Tiles per row and per column.
    n_tx: usize,
    n_ty: usize,
}

#[inline(always)]
fn key(v: f32, max: bool) -> f32 {
    if max { v } else { -v }
}

/// `out[t] = op(v[t − d ..= t])` along rows (`step` 1, `len` n_tx) or columns (`step` n_tx).
fn window_back(
    v: &[f32],
    out: &mut [f32],
    (n_tx, n_ty): (usize, usize),
    d: usize,
    along_x: bool,
    max: bool,
) {
    for ty in 0..n_ty {
        for tx in 0..n_tx {
            let (lo, step, i) = if along_x {
                (tx.saturating_sub(d), 1, tx)
            } else {
                (ty.saturating_sub(d), n_tx, ty)
            };
            let base = if along_x { ty * n_tx } else { tx };
            let mut m = v[base + i * step];
            for j in lo..i {
                let x = v[base + j * step];
                if (max && x > m) || (!max && x < m) {
                    m = x;
                }
            }
            out[ty * n_tx + tx] = m;
        }
    }
}

impl MipTiles {
    /// Whether [`MipTiles::new`] has not sized it yet.
    pub(crate) fn is_empty(&self) -> bool {
        self.floor.is_empty()
    }

    /// Tiles for a band of `rows` scanlines of a `w`-pixel image, with nothing covered yet.
    pub(crate) fn new(rows: usize, w: usize) -> Self {
        let (n_tx, n_ty) = (w.div_ceil(TILE), rows.div_ceil(TILE));
        let n = n_tx * n_ty;
        MipTiles {
            floor: vec![f32::NEG_INFINITY; n],
            hi: vec![f32::NEG_INFINITY; n],
            lo: vec![f32::INFINITY; n],
            tmp: vec![0.0; n],
            dead: vec![false; n],
            row_ok: vec![false; n],
            origin: Vec::new(),
            n_tx,
            n_ty,
        }
    }

    /// Pass 1 over one sheet's splats for band rows `y_lo..y_lo + rows`: each splat's origin
    /// tile (its footprint block clipped to the band and the image, as the splat loop clips it)
    /// and, per origin tile, whether every tile its splats can reach is dead.
    pub(crate) fn prepare(
        &mut self,
        table: &FootprintTable,
        splats: &[Splat],
        (y_lo, rows, w): (i32, i32, i32),
        max: bool,
    ) {
        let blk = table.block();
        let (bw, bh) = (blk.width as i32, blk.height as i32);
        // A block starting anywhere in a tile ends at most this many tiles further on.
        let (dx, dy) = ((bw as usize + 2) / TILE, (bh as usize + 2) / TILE);
        self.hi.fill(f32::NEG_INFINITY);
        self.lo.fill(f32::INFINITY);
        self.origin.clear();
        let n_tx = self.n_tx;
        for sp in splats {
            let (px0, py0) = table.origin(sp.x, sp.y);
            let (r0, r1) = ((py0 - y_lo).max(0), (py0 + bh - y_lo).min(rows));
            let (c0, c1) = (px0.max(0), (px0 + bw).min(w));
            if r0 >= r1 || c0 >= c1 {
                self.origin.push(u32::MAX);
                continue;
            }
            let t = (r0 as usize / TILE) * n_tx + c0 as usize / TILE;
            self.origin.push(t as u32);
            let k = key(sp.v[0], max);
            // NaN values poison their tiles (never dead).
            let (khi, klo) = if k.is_nan() {
                (f32::INFINITY, f32::NEG_INFINITY)
            } else {
                (k, k)
            };
            if khi > self.hi[t] {
                self.hi[t] = khi;
            }
            if klo < self.lo[t] {
                self.lo[t] = klo;
            }
        }
        let dims = (self.n_tx, self.n_ty);
        // What reaches tile t: the origins within (dx, dy) tiles before it.
        window_back(&self.hi, &mut self.tmp, dims, dx, true, true);
        window_back(&self.tmp, &mut self.hi, dims, dy, false, true);
        window_back(&self.lo, &mut self.tmp, dims, dx, true, false);
        window_back(&self.tmp, &mut self.lo, dims, dy, false, false);
        for (((d, &h), &l), &f) in self
            .dead
            .iter_mut()
            .zip(&self.hi)
            .zip(&self.lo)
            .zip(&self.floor)
        {
            let margin = MARGIN * h.abs().max(l.abs());
            *d = h + margin < f || (h == 0.0 && l == 0.0 && f >= 0.0);
        }
        // Per origin tile: every tile within (dx, dy) after it is dead (off the map counts as
        // dead: no pixel there). Erosion = the dilation of "alive", forwards.
        let (n_tx, n_ty) = dims;
        let (dead, row_ok) = (&mut self.dead, &mut self.row_ok);
        for ty in 0..n_ty {
            let row = &dead[ty * n_tx..(ty + 1) * n_tx];
            for tx in 0..n_tx {
                row_ok[ty * n_tx + tx] = row[tx..=(tx + dx).min(n_tx - 1)].iter().all(|&d| d);
            }
        }
        for ty in 0..n_ty {
            let end = (ty + dy).min(n_ty - 1);
            for tx in 0..n_tx {
                dead[ty * n_tx + tx] = (ty..=end).all(|y| row_ok[y * n_tx + tx]);
            }
        }
    }

    /// Whether splat `i` of the prepared sheet can be skipped: its block misses the band, or
    /// every tile it can reach is dead.
    #[inline]
    pub(crate) fn skip(&self, i: usize) -> bool {
        match self.origin[i] {
            u32::MAX => true,
            t => self.dead[t as usize],
        }
    }

    /// Recomputes the floors of the tiles over columns `tx0..tx1` after the band's accumulation
    /// buffer `acc` (`w` wide) changed there.
    pub(crate) fn refresh(
        &mut self,
        acc: &[Rgba],
        w: usize,
        (tx0, tx1): (usize, usize),
        max: bool,
    ) {
        let rows = acc.len() / w;
        for ty in 0..rows.div_ceil(TILE) {
            let (y0, y1) = (ty * TILE, ((ty + 1) * TILE).min(rows));
            for tx in tx0 / TILE..=(tx1 - 1) / TILE {
                let (c0, c1) = (tx * TILE, ((tx + 1) * TILE).min(w));
                let mut f = f32::INFINITY;
                'tile: for y in y0..y1 {
                    for p in &acc[y * w + c0..y * w + c1] {
                        let k = key(p[0], max);
                        if k.is_nan() {
                            f = f32::NEG_INFINITY;
                            break 'tile;
                        }
                        if k < f {
                            f = k;
                        }
                    }
                }
                self.floor[ty * self.n_tx + tx] = f;
            }
        }
    }
}
