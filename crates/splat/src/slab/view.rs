//! The view set-up: the box the rays cross and the planes across it ([`Planes`]), the frame's
//! rays in the volume's index space (the point of each pixel on each plane, [`View`]), and the
//! rows of a plane walked in fixed point ([`Walk`]).

use crate::bricks::BRICK;
use crate::error::{Result, SplatError};
use crate::sheets::RenderSettings;
use volsplat_core::glam::DVec3;
use volsplat_core::{Grid, Projection};

/// Where the slabs of a frame lie: the planes parallel to the image, `Δ` apart at the eye
/// depths `d_j = Δ·j` (module docs of [`super`]), that cross the box the rays cross.
pub(super) struct Planes {
    /// The geometry the rays are set up in ([`drawn_geometry`]).
    pub(super) geo: Grid,
    /// The frame's rays in `geo`'s index space.
    pub(super) view: View,
    /// The slab thickness `Δ` (world units).
    pub(super) delta: f64,
    /// The first plane's number: plane `p` lies at the eye depth `(j0 + p)·Δ`.
    pub(super) j0: i64,
    /// The planes across the box (at most 2²⁴).
    pub(super) n_planes: usize,
    /// The eye depths of the box's nearest and farthest corners (world units).
    pub(super) dmin: f64,
    pub(super) dmax: f64,
}

impl Planes {
    /// The planes of a frame of `settings.width × settings.height` pixels seen through `proj`,
    /// `settings.slab` times `min_spacing` (the grid's smallest spacing) apart, capped at the
    /// thinnest extent of the box the rays cross; an error where more than 2²⁴ planes would
    /// cross the volume.
    pub(super) fn place(
        settings: &RenderSettings,
        proj: &Projection,
        grid: &Grid,
        min_spacing: f64,
    ) -> Result<Self> {
        // The box the rays cross: the voxel centres', an axis of one sample spanning its voxel
        // (decision 0023). No thicker slabs than the box's thinnest extent, so that a ray
        // through both of its widest faces meets a plane inside (a sheet one voxel thick under
        // `--slab 2` would otherwise fall between two planes and draw nothing); with slabs of
        // at most one voxel this never applies (every extent is a spacing or more).
        let geo = drawn_geometry(grid);
        let thinnest = (0..3)
            .map(|a| (geo.dims[a] - 1) as f64 * geo.spacing[a])
            .fold(f64::INFINITY, f64::min);
        let delta = (settings.slab * min_spacing).min(thinnest);
        // Depth range of the box the rays cross, and the planes inside it.
        let frame = proj.frame();
        let depths = geo
            .corners_world()
            .map(|c| (c - frame.eye).dot(frame.forward));
        let dmin = depths.iter().fold(f64::INFINITY, |m, &d| m.min(d));
        let dmax = depths.iter().fold(f64::NEG_INFINITY, |m, &d| m.max(d));
        let mut j0 = (dmin / delta).ceil();
        if matches!(proj, Projection::Perspective(_)) {
            j0 = j0.max(1.0); // planes in front of the eye only
        }
        let j1 = (dmax / delta).floor();
        let n_planes = if j1 >= j0 { (j1 - j0) as usize + 1 } else { 0 };
        if n_planes > 1 << 24 {
            return Err(SplatError::Setting {
                name: "slab",
                value: settings.slab.to_string(),
                expected: "fewer than 2^24 planes across the volume; use a thicker slab",
            });
        }
        let view = View::new(proj, &geo, settings.width, settings.height);
        Ok(Planes {
            geo,
            view,
            delta,
            j0: j0 as i64,
            n_planes,
            dmin,
            dmax,
        })
    }
}

/// The geometry the slabs' rays are set up in (`docs/decisions/0023-thin-volumes.md`): `grid`
/// itself where every axis has two samples or more; otherwise each axis of one sample becomes
/// two "samples" half a spacing either side of the real one (the origin moved back by half a
/// spacing), so the box of these centres, `[0, 1]` along that axis, is the voxel's extent
/// ([`volsplat_core::Grid::drawn_box_index`]). Only positions use it: the cells are clamped to
/// the real grid (`Ctx::max_cell`, 0 there) and the step to the next voxel along the axis is 0
/// (`Ctx::up`), so every position along the axis reads the one sample.
pub(super) fn drawn_geometry(grid: &Grid) -> Grid {
    let mut geo = grid.clone();
    for a in 0..3 {
        if grid.dims[a] == 1 {
            geo.dims[a] = 2;
            let back = grid.direction.col(a) * (0.5 * grid.spacing[a]);
            geo.origin = (DVec3::from(geo.origin) - back).to_array();
        }
    }
    geo
}

/// Sample positions: the point of pixel `(x, y)` (centre) on the plane at eye depth `d` is
/// `P = eye + d·(f + u·r + v·u)` in perspective (`u, v` the pixel's tangent-plane offsets) and
/// `P = eye + d·f + x_w·r + y_w·u` in orthographic views; both are affine in `x` along a row,
/// so a row of a plane is a start and a step in index space.
pub(super) struct View {
    pub(super) perspective: bool,
    /// Index-space position of the eye, and the index-space images of the world axes.
    pub(super) eye_q: DVec3,
    pub(super) right_q: DVec3,
    pub(super) up_q: DVec3,
    pub(super) fwd_q: DVec3,
    /// World frame, for clipping planes.
    pub(super) eye: DVec3,
    pub(super) right_w: DVec3,
    pub(super) up_w: DVec3,
    pub(super) fwd_w: DVec3,
    /// Orthographic: world units per pixel. Perspective: 1 / focal length in pixels.
    pub(super) scale: f64,
    pub(super) half_w: f64,
    pub(super) half_h: f64,
}

impl View {
    pub(super) fn new(proj: &Projection, grid: &Grid, w: usize, h: usize) -> Self {
        let fr = proj.frame();
        let q0 = grid.index_from_world(DVec3::ZERO);
        let lin = |v: DVec3| grid.index_from_world(v) - q0;
        let (perspective, scale) = match proj {
            Projection::Ortho(p) => (false, p.pixel_size),
            Projection::Perspective(p) => (true, 1.0 / p.focal_px),
        };
        View {
            perspective,
            eye_q: grid.index_from_world(fr.eye),
            right_q: lin(fr.right),
            up_q: lin(fr.up),
            fwd_q: lin(fr.forward),
            eye: fr.eye,
            right_w: fr.right,
            up_w: fr.up,
            fwd_w: fr.forward,
            scale,
            half_w: w as f64 * 0.5,
            half_h: h as f64 * 0.5,
        }
    }

    /// Tangent-plane (perspective: per unit depth; orthographic: world) offsets of the centre
    /// of pixel `(x, y)` along right and up.
    #[inline]
    pub(super) fn offsets(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x + 0.5 - self.half_w) * self.scale,
            (self.half_h - y - 0.5) * self.scale,
        )
    }

    /// Index-space position of pixel `(0, y)` on the plane at depth `d`, and the step per pixel
    /// along the row.
    pub(super) fn row(&self, y: usize, d: f64) -> (DVec3, DVec3) {
        let (u0, v) = self.offsets(0.0, y as f64);
        if self.perspective {
            let start = self.eye_q + (self.fwd_q + self.right_q * u0 + self.up_q * v) * d;
            (start, self.right_q * (d * self.scale))
        } else {
            let start = self.eye_q + self.fwd_q * d + self.right_q * u0 + self.up_q * v;
            (start, self.right_q * self.scale)
        }
    }

    /// Index-space position of the point at pixel coordinates `(x, y)` (continuous: pixel
    /// `(i, j)`'s centre is `(i, j)`, as [`View::row`] places it) on the plane at depth `d`:
    /// affine in each of `x`, `y` and `d` (the bricks a band of rows needs, `super::bricked`).
    pub(super) fn point(&self, x: f64, y: f64, d: f64) -> DVec3 {
        let (u, v) = self.offsets(x, y);
        if self.perspective {
            self.eye_q + (self.fwd_q + self.right_q * u + self.up_q * v) * d
        } else {
            self.eye_q + self.fwd_q * d + self.right_q * u + self.up_q * v
        }
    }

    /// Row `y` of the plane at depth `d` of an image `width` pixels wide, walked in 32.32 fixed
    /// point through the box `[0, box_hi]` (index space): [`Ctx::walk`], which the march calls.
    ///
    /// [`Ctx::walk`]: super::march::Ctx::walk
    pub(super) fn walk(&self, y: usize, d: f64, width: usize, box_hi: [i64; 3]) -> Walk {
        let (start, step) = self.row(y, d);
        let mut r = (0, width as i64 - 1);
        for a in 0..3 {
            r = clip_linear(r, start[a], step[a], 0.0, box_hi[a] as f64);
        }
        let s = [0, 1, 2].map(|a| to_fixed(start[a]));
        let st = [0, 1, 2].map(|a| to_fixed(step[a]));
        let inside = |x: i64| {
            (0..3).all(|a| {
                let q = s[a] + x * st[a];
                q >= 0 && q <= box_hi[a] << FRAC
            })
        };
        while r.0 <= r.1 && !inside(r.0) {
            r.0 += 1;
        }
        while r.1 >= r.0 && !inside(r.1) {
            r.1 -= 1;
        }
        Walk {
            s,
            st,
            s32: [0, 1, 2].map(|a| start[a] as f32),
            st32: [0, 1, 2].map(|a| step[a] as f32),
            span: r,
        }
    }

    /// World position of pixel `(x, 0)`'s point at depth `d` and the world step per pixel along
    /// x (for clipping planes).
    pub(super) fn row_world(&self, y: usize, d: f64) -> (DVec3, DVec3) {
        let (u0, v) = self.offsets(0.0, y as f64);
        if self.perspective {
            (
                self.eye + (self.fwd_w + self.right_w * u0 + self.up_w * v) * d,
                self.right_w * (d * self.scale),
            )
        } else {
            (
                self.eye + self.fwd_w * d + self.right_w * u0 + self.up_w * v,
                self.right_w * self.scale,
            )
        }
    }
}

/// The pixels `x` in `[0, width)` with `lo ≤ a + x·b ≤ hi`, intersected with `range`.
pub(super) fn clip_linear(range: (i64, i64), a: f64, b: f64, lo: f64, hi: f64) -> (i64, i64) {
    const SLACK: f64 = 1e-9;
    let (lo, hi) = (lo - SLACK, hi + SLACK);
    if b.abs() < 1e-300 {
        return if a >= lo && a <= hi { range } else { (0, -1) };
    }
    let (t0, t1) = ((lo - a) / b, (hi - a) / b);
    let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
    // The integers are the same as `ceil`'s and `floor`'s (a zero's sign does not matter here).
    let x0 = ceil_f64(t0).max(range.0 as f64);
    let x1 = floor_f64(t1).min(range.1 as f64);
    if x0 > x1 || !x0.is_finite() || !x1.is_finite() {
        (0, -1)
    } else {
        (x0 as i64, x1 as i64)
    }
}

/// Bits of fraction in the fixed-point index positions.
pub(super) const FRAC: u32 = 32;

/// `⌊n / d⌋` for `n ≥ 0`, `d > 0`, given `inv = 1 / d`: estimated in f64 and corrected to the
/// exact integer (a 64-bit division costs several times as much, once per brick run).
#[inline(always)]
fn div_floor(n: i64, d: i64, inv: f64) -> i64 {
    let mut k = (n as f64 * inv) as i64;
    while k > 0 && k * d > n {
        k -= 1;
    }
    while (k + 1) * d <= n {
        k += 1;
    }
    k
}

#[inline]
pub(super) fn to_fixed(v: f64) -> i64 {
    round_i64(v * (1u64 << FRAC) as f64)
}

/// `x.round() as i64` (half away from zero), without libm's `round` (a call on x86-64 without
/// SSE4.1): below 2⁵² the truncation and its remainder are exact, so the result is the same.
#[inline(always)]
fn round_i64(x: f64) -> i64 {
    if x.abs() < 4.5e15 {
        let t = x as i64;
        let f = x - t as f64;
        t + i64::from(f >= 0.5) - i64::from(f <= -0.5)
    } else {
        x.round() as i64
    }
}

/// `x.ceil()` up to the sign of a zero result, without libm ([`round_i64`]'s reason).
#[inline(always)]
fn ceil_f64(x: f64) -> f64 {
    if x.abs() < 4.5e15 {
        let t = x as i64 as f64;
        if t < x { t + 1.0 } else { t }
    } else {
        x.ceil()
    }
}

/// `x.floor()` up to the sign of a zero result, without libm ([`round_i64`]'s reason).
#[inline(always)]
fn floor_f64(x: f64) -> f64 {
    if x.abs() < 4.5e15 {
        let t = x as i64 as f64;
        if t > x { t - 1.0 } else { t }
    } else {
        x.floor()
    }
}

/// One row of one plane in fixed-point index coordinates ([`Ctx::walk`]).
///
/// [`Ctx::walk`]: super::march::Ctx::walk
pub(super) struct Walk {
    pub(super) s: [i64; 3],
    pub(super) st: [i64; 3],
    /// The row's start and step as f32, for the samples themselves.
    pub(super) s32: [f32; 3],
    pub(super) st32: [f32; 3],
    /// Pixels inside the box the rays cross (empty when `span.0 > span.1`).
    pub(super) span: (i64, i64),
}

impl Walk {
    /// The cell of pixel `x` of the row (clamped to `[0, max_cell]` per axis) and the fractions
    /// in it, from the row's f32 start and step: [`Ctx::cell_f32`], the scalar twin of
    /// [`Sampler8::locate`] and [`Cells8::fractions`].
    ///
    /// [`Ctx::cell_f32`]: super::march::Ctx::cell_f32
    /// [`Sampler8::locate`]: super::avx2::sampler::Sampler8::locate
    /// [`Cells8::fractions`]: super::avx2::sampler::Cells8::fractions
    #[inline(always)]
    pub(super) fn cell_f32(&self, x: usize, max_cell: [i64; 3]) -> ([usize; 3], [f32; 3]) {
        let xf = x as f32;
        let mut c = [0usize; 3];
        let mut f = [0.0f32; 3];
        for a in 0..3 {
            let q = self.s32[a] + xf * self.st32[a];
            let i = (q as i32).clamp(0, max_cell[a] as i32);
            c[a] = i as usize;
            f[a] = (q - i as f32).clamp(0.0, 1.0);
        }
        (c, f)
    }

    /// How many pixels from the one at `q` (index `cell` along axis `a`) on keep their cells in
    /// the same brick along axis `a` (`i64::MAX` if the row does not move along it); `inv` is
    /// `1 / |st[a]|` ([`div_floor`]).
    #[inline(always)]
    pub(super) fn run_along(&self, a: usize, q: i64, cell: usize, inv: f64) -> i64 {
        let st = self.st[a];
        let b0 = ((cell / BRICK) * BRICK) as i64;
        if st > 0 {
            // Steps k with q + k·st < (b0 + B) << FRAC.
            let room = ((b0 + BRICK as i64) << FRAC) - q;
            div_floor(room + st - 1, st, inv)
        } else if st < 0 {
            // Steps k with q + k·st ≥ b0 << FRAC, counting the pixel itself.
            let room = q - (b0 << FRAC);
            div_floor(room, -st, inv) + 1
        } else {
            i64::MAX
        }
    }

    #[inline(always)]
    pub(super) fn at(&self, x: i64) -> [i64; 3] {
        [
            self.s[0] + x * self.st[0],
            self.s[1] + x * self.st[1],
            self.s[2] + x * self.st[2],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The libm-free roundings give libm's integers for every kind of input: halves either
    /// side of zero, fractions just beside them, the ends of the fast path, huge and
    /// non-finite values.
    #[test]
    fn roundings_without_libm_match_libm() {
        let mut xs = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            4.4e15 + 0.5,
            -4.4e15 - 0.5,
            4.5e15,
            9.3e18,
            -9.3e18,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..100_000 {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let m = (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            let e = (seed & 63) as i32 - 10;
            xs.push(m * 2f64.powi(e));
            xs.push((m * 1e6).round() * 0.5);
        }
        for x in xs {
            assert_eq!(round_i64(x), x.round() as i64, "round {x}");
            assert_eq!(ceil_f64(x) as i64, x.ceil() as i64, "ceil {x}");
            assert_eq!(floor_f64(x) as i64, x.floor() as i64, "floor {x}");
            assert_eq!(ceil_f64(x).is_nan(), x.is_nan());
            if x.is_finite() {
                assert_eq!(ceil_f64(x), x.ceil(), "ceil {x}");
                assert_eq!(floor_f64(x), x.floor(), "floor {x}");
            }
        }
    }

    #[test]
    fn div_floor_is_exact() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..200_000 {
            let n = (next() >> (20 + next() % 40)) as i64;
            let d = ((next() >> (24 + next() % 38)) as i64).max(1);
            assert_eq!(div_floor(n, d, 1.0 / d as f64), n / d, "{n} / {d}");
        }
        for (n, d) in [(0, 1), (7, 7), (1 << 45, 3), ((1 << 45) - 1, 1 << 20)] {
            assert_eq!(div_floor(n, d, 1.0 / d as f64), n / d);
        }
    }
}
