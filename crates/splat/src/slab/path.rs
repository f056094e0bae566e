//! Each ray's path through the slabs: the perspective path factor, and the depths where the
//! ray enters and leaves the volume, which shorten its first and last slab.

use super::march::Ctx;
use super::math::{exp2_neg, log2_unit};
use crate::voxels::Voxels;
use volsplat_core::Scalar;
use volsplat_core::image::Rgba;

impl<T: Scalar, V: Voxels<T>> Ctx<'_, T, V> {
    /// Perspective: the slab's path along the ray through a pixel is `Δ·k`, `k = √(1 + u² + v²)`
    /// ([`Ctx::path_factors`]), so the opacity (corrected for `Δ`) becomes `1 − (1 − α)^k` and
    /// the colour scales with it. `k = 1` (orthographic) changes nothing.
    #[inline]
    pub(super) fn path_correct(&self, rgba: Rgba, k: f32) -> Rgba {
        let a = rgba[3];
        if k == 1.0 || a <= 0.0 || a >= 1.0 {
            return rgba;
        }
        let a2 = 1.0 - exp2_neg(k * log2_unit(1.0 - a));
        let s = a2 / a;
        [rgba[0] * s, rgba[1] * s, rgba[2] * s, a2]
    }

    /// The eye depths `d_in` and `d_out` between which the ray of each pixel of the rows
    /// `[y0, y0 + rows)` lies in the box the rays cross (`box_hi`) and on the kept side of
    /// every clipping plane (`[+∞, −∞]` where it misses, and outside the row's reach, whose
    /// pixels are not sampled).
    pub(super) fn ray_extents(&self, y0: usize, rows: usize) -> (Vec<f32>, Vec<f32>) {
        let v = &self.view;
        let mut din = Vec::with_capacity(rows * self.width);
        let mut dout = Vec::with_capacity(rows * self.width);
        let (mut entry_walk, mut exit_walk) = (None, None);
        for y in y0..y0 + rows {
            // Only the pixels that can meet a brick with opacity are sampled (`super::reach`).
            let (lo, hi) = self
                .reach
                .rows
                .get(y)
                .map_or((0, self.width as i64 - 1), |r| (r.lo, r.hi));
            for x in 0..self.width {
                if (x as i64) < lo || (x as i64) > hi {
                    din.push(f32::INFINITY);
                    dout.push(f32::NEG_INFINITY);
                    continue;
                }
                let (u, w) = v.offsets(x as f64, y as f64);
                // Index and world position at depth d: a + d·b.
                let (aq, bq, aw, bw) = if v.perspective {
                    (
                        v.eye_q,
                        v.fwd_q + v.right_q * u + v.up_q * w,
                        v.eye,
                        v.fwd_w + v.right_w * u + v.up_w * w,
                    )
                } else {
                    (
                        v.eye_q + v.right_q * u + v.up_q * w,
                        v.fwd_q,
                        v.eye + v.right_w * u + v.up_w * w,
                        v.fwd_w,
                    )
                };
                let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
                let mut cut = |a: f64, b: f64, min: f64, max: f64| {
                    // min ≤ a + d·b ≤ max
                    if b.abs() < 1e-300 {
                        if a < min || a > max {
                            lo = f64::INFINITY;
                        }
                    } else {
                        let (t0, t1) = ((min - a) / b, (max - a) / b);
                        lo = lo.max(t0.min(t1));
                        hi = hi.min(t0.max(t1));
                    }
                };
                for ax in 0..3 {
                    cut(aq[ax], bq[ax], 0.0, self.box_hi[ax] as f64);
                }
                for &(n, off) in &self.clip {
                    cut(n.dot(aw) + off, n.dot(bw), 0.0, f64::INFINITY);
                }
                let (a, b) = if lo <= hi {
                    (
                        self.snap_entry(y, x, lo, &mut entry_walk),
                        self.snap_exit(y, x, hi, &mut exit_walk),
                    )
                } else {
                    (f32::INFINITY, f32::NEG_INFINITY)
                };
                din.push(a);
                dout.push(b);
            }
        }
        (din, dout)
    }

    /// Whether pixel `x` of row `y` is sampled on plane `j` (an absolute plane number,
    /// depth `j·Δ`): the walk's own fixed-point test and clipping, memoised per row and plane
    /// in `memo`.
    fn sampled_on(&self, y: usize, x: usize, j: i64, memo: &mut SpanMemo) -> bool {
        let p = j - self.j0;
        if p < 0 || p >= self.n_planes as i64 {
            return false;
        }
        let span = match *memo {
            Some((my, mj, span)) if my == y && mj == j => span,
            _ => {
                let d = self.depth(p as usize);
                let walk = self.walk(y, d);
                let c = self.clip_span(y, d, walk.span);
                let span = (c.0.max(walk.span.0), c.1.min(walk.span.1));
                *memo = Some((y, j, span));
                span
            }
        };
        span.0 <= x as i64 && x as i64 <= span.1
    }

    /// The depth where the ray of pixel `(x, y)` enters the volume (`lo`, f64), as
    /// [`boundary_factor`] must see it: where `lo` lies on a plane to within rounding, whether
    /// that plane's sample is taken is the walk's fixed-point decision, and the depth handed on
    /// is moved (by the rounding, at most) so that the first plane sampled, and only it, takes
    /// the path from `lo`. Without this a plane on the entry face to rounding was left out by
    /// the walk while the next plane took only its own half slab: half a slab of path lost
    /// (`docs/BENCHMARKS.md` §17.3).
    fn snap_entry(&self, y: usize, x: usize, lo: f64, memo: &mut SpanMemo) -> f32 {
        let j = (lo / self.delta).round();
        if (lo - j * self.delta).abs() > self.snap_tolerance(lo) {
            return lo as f32;
        }
        let half = (0.5 * self.delta) as f32;
        // `boundary_factor`'s front of plane j + 1: the slab before it starts a ray there.
        let front_next = ((j + 1.0) * self.delta) as f32 - 2.0 * half;
        let din = lo as f32;
        if self.sampled_on(y, x, j as i64, memo) {
            din.min(front_next)
        } else if front_next < din {
            din
        } else {
            front_next.next_up()
        }
    }

    /// [`Ctx::snap_entry`] for the depth `hi` where the ray leaves the volume.
    fn snap_exit(&self, y: usize, x: usize, hi: f64, memo: &mut SpanMemo) -> f32 {
        let j = (hi / self.delta).round();
        if (hi - j * self.delta).abs() > self.snap_tolerance(hi) {
            return hi as f32;
        }
        let half = (0.5 * self.delta) as f32;
        let back_prev = ((j - 1.0) * self.delta) as f32 + 2.0 * half;
        let dout = hi as f32;
        if self.sampled_on(y, x, j as i64, memo) {
            dout.max(back_prev)
        } else if back_prev > dout {
            dout
        } else {
            back_prev.next_down()
        }
    }

    /// How near a plane an entry or exit depth `d` must lie for [`Ctx::snap_entry`] to ask the
    /// walk: well above the rounding of f32 depths and 32.32 positions, far below a slab.
    fn snap_tolerance(&self, d: f64) -> f64 {
        (1e-3 * self.delta).max(8.0 * f32::EPSILON as f64 * d.abs())
    }

    /// The path factor `k = √(1 + u² + v²)` of every pixel of the rows `[y0, y0 + rows)`: 1 in
    /// orthographic views.
    pub(super) fn path_factors(&self, y0: usize, rows: usize) -> Vec<f32> {
        let w = self.width;
        if !self.view.perspective {
            return vec![1.0; rows * w];
        }
        let mut k = Vec::with_capacity(rows * w);
        for y in y0..y0 + rows {
            for x in 0..w {
                let (u, v) = self.view.offsets(x as f64, y as f64);
                k.push((1.0 + u * u + v * v).sqrt() as f32);
            }
        }
        k
    }
}

/// The opacity exponent of the slab at depth `d` for a ray with path factor `kf` that lies in
/// the volume (and its clipping) between the eye depths `din` and `dout`: `kf`, except for the
/// first and last slab of the ray, which stand for the path from where the ray enters (leaves)
/// the volume, not a whole slab (without this the cut faces step from plane to plane: wood
/// grain). The scalar twin of `Run::slab_exponents` (`avx2/composite.rs`).
#[inline(always)]
pub(super) fn boundary_factor(kf: f32, din: f32, dout: f32, d: f32, half: f32) -> f32 {
    let lo_cut = d - 2.0 * half < din;
    let hi_cut = d + 2.0 * half > dout;
    if lo_cut || hi_cut {
        let lo = if lo_cut { din } else { d - half };
        let hi = if hi_cut { dout } else { d + half };
        kf * ((hi - lo) / (2.0 * half)).max(0.0)
    } else {
        kf
    }
}

/// The last walk [`Ctx::sampled_on`] made: its row, absolute plane number and sampled span.
type SpanMemo = Option<(usize, i64, (i64, i64))>;
