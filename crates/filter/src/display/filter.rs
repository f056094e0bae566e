//! Per-pixel 3-D display filters and their direct (quadrature) evaluation (Buchanan §6-1–§6-3,
//! eqs 3.3/6.1).
//!
//! Every filter is written in the pixel's ray frame: `t` the world distance along the central
//! ray, `(a, b)` the offsets perpendicular to it in units of the screen filter's standard
//! deviation `σ(t)` (world units; grows with depth under perspective). The screen filter is a
//! Gaussian truncated to the square `|a|, |b| ≤ 3` and divided by `σ(t)²`, i.e. a filter over
//! *screen* area as eq 6.1 writes it. Filters are masked to the box of voxel centres (the
//! density is zero outside it, eq 4.2).
//!
//! Evaluation goes through the filter's lines (`project::LineFilter`): the direct
//! evaluation (`direct`) integrates the data along each line clipped to the box; the NIL
//! evaluation projects the filter onto the patches with the same lines. Slices and balls
//! return `∭Fρ/∭F`; the linearised display returns `τ ∫∬ G e^{−τ(t−t_a)} ρ` with `∬G = 1`, and
//! the line integral returns `∬ G ∫ ρ dt` (Sabella's optical depth).

use super::volume::{DisplayVolume, PixelRay};
use crate::quadrature::gauss_legendre;
use glam::DVec3;

/// Half-width of the truncated Gaussians in standard deviations.
pub(crate) const TRUNC: f64 = 3.0;

/// Screen-filter scale: `σ(t) = a + b·t` (world units).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sigma {
    pub a: f64,
    pub b: f64,
}

impl Sigma {
    #[inline]
    pub(crate) fn at(&self, t: f64) -> f64 {
        (self.a + self.b * t).max(1e-12)
    }
}

/// A display filter around one pixel.
#[derive(Debug, Clone, Copy)]
pub(crate) enum PixelFilter {
    /// eq 6.1: screen Gaussian × `exp(−τ(t − t_a))` for `t ≥ t_a`; `tau` per world unit. Not
    /// cut at the exit `t_b`: the density is zero beyond it, and the uncut filter has the known
    /// integral `K = K_screen/τ` (eq 4.15).
    Linearised {
        ray: PixelRay,
        sigma: Sigma,
        tau: f64,
    },
    /// Sabella's display without linearisation (`Attenuation::OpticalDepth`): screen Gaussian ×
    /// 1 along every line of the tube, each clipped to the box on its own (so each line
    /// integrates its own whole segment, as each of Sabella's rays does). Its "integral" `K` is
    /// the screen filter's weight per unit length, so `∭Fρ/K` is the screen-filtered line
    /// integral `X = ∬G ∫ρ dt` (world units × density).
    LineIntegral { ray: PixelRay, sigma: Sigma },
    /// §6-2: screen Gaussian × Gaussian along the ray centred at `tc`, std `w` (world units),
    /// truncated at `±3w`.
    Slice {
        ray: PixelRay,
        sigma: Sigma,
        tc: f64,
        w: f64,
    },
    /// §6-3: isotropic Gaussian of std `s` (world units) at `c` (world), truncated to the cube
    /// `±3s` (one half of a difference of Gaussians).
    Ball { c: DVec3, s: f64 },
}

impl PixelFilter {
    /// Filter weight at a world point (not masked by the volume box).
    #[inline]
    pub(crate) fn weight(&self, p: DVec3) -> f64 {
        match *self {
            PixelFilter::Linearised { ray, sigma, tau } => {
                let rel = p - ray.o;
                let t = rel.dot(ray.d);
                if t < ray.ta {
                    return 0.0;
                }
                let s = sigma.at(t);
                let (a, b) = (rel.dot(ray.e1) / s, rel.dot(ray.e2) / s);
                if a.abs() > TRUNC || b.abs() > TRUNC {
                    return 0.0;
                }
                (-0.5 * (a * a + b * b) - tau * (t - ray.ta)).exp() / (s * s)
            }
            PixelFilter::LineIntegral { ray, sigma } => {
                let rel = p - ray.o;
                let t = rel.dot(ray.d);
                if t < ray.t_min {
                    return 0.0;
                }
                let s = sigma.at(t);
                let (a, b) = (rel.dot(ray.e1) / s, rel.dot(ray.e2) / s);
                if a.abs() > TRUNC || b.abs() > TRUNC {
                    return 0.0;
                }
                (-0.5 * (a * a + b * b)).exp() / (s * s)
            }
            PixelFilter::Slice { ray, sigma, tc, w } => {
                let rel = p - ray.o;
                let t = rel.dot(ray.d);
                let u = (t - tc) / w;
                if u.abs() > TRUNC {
                    return 0.0;
                }
                let s = sigma.at(t);
                let (a, b) = (rel.dot(ray.e1) / s, rel.dot(ray.e2) / s);
                if a.abs() > TRUNC || b.abs() > TRUNC {
                    return 0.0;
                }
                (-0.5 * (a * a + b * b + u * u)).exp() / (s * s)
            }
            PixelFilter::Ball { c, s } => {
                let q = (p - c) / s;
                if q.abs().max_element() > TRUNC {
                    return 0.0;
                }
                (-0.5 * q.length_squared()).exp()
            }
        }
    }

    /// The narrowest cross-section of the filter inside the volume's box, world units: the
    /// width `2·3σ` of the truncated screen Gaussian at the ray's entry (σ grows with depth
    /// under perspective), or of the ball.
    pub(crate) fn min_width(&self) -> f64 {
        match *self {
            PixelFilter::Linearised { ray, sigma, .. }
            | PixelFilter::LineIntegral { ray, sigma }
            | PixelFilter::Slice { ray, sigma, .. } => 2.0 * TRUNC * sigma.at(ray.ta),
            PixelFilter::Ball { s, .. } => 2.0 * TRUNC * s,
        }
    }

    /// Weight at an index-space point.
    #[inline]
    pub(crate) fn weight_index(&self, vol: &DisplayVolume, p_index: DVec3) -> f64 {
        self.weight(vol.world_from_index(p_index))
    }
}

/// Composite Gauss–Legendre nodes over `[lo, hi]`: `panels × n` (node, weight) pairs.
pub(crate) fn composite_nodes(lo: f64, hi: f64, panels: usize, n: usize) -> Vec<(f64, f64)> {
    let (xi, wi) = gauss_legendre(n);
    let h = (hi - lo) / panels as f64;
    let mut out = Vec::with_capacity(panels * n);
    for p in 0..panels {
        let c = lo + (p as f64 + 0.5) * h;
        for (x, w) in xi.iter().zip(wi) {
            out.push((c + 0.5 * h * x, 0.5 * h * w));
        }
    }
    out
}

/// Direct evaluation of `∭ F ρ / ∭ F` (the reference for the NIL approximations): the filter's
/// cross-section lines (`cross` nodes per axis) each clipped to the box of voxel centres and
/// integrated along their own length ([`super::project::LineFilter::direct`]). `None` if the
/// filter misses the volume.
pub(crate) fn direct(
    vol: &DisplayVolume,
    filter: &PixelFilter,
    step: f64,
    cross: &[(f64, f64)],
) -> Option<f64> {
    let mut lf = super::project::LineFilter::default();
    lf.set(vol, filter, cross);
    lf.direct(vol, step)
}

/// Trigger points for a filter, in index space (thesis §4-4.8 and App. B step 3):
/// linearised — `width²` points per slice across `±2σ(t)`, slices every `1/steps` unit
/// lengths along `[t_a, t_b]`; slice — `width³` points in `±2σ × ±2w`; ball — `width³` points in
/// the cube `±2s` (all cell-centred grids). Points outside the box of voxel centres are
/// dropped: the filter is zero there, and negative coordinates would defeat the dyadic root
/// search (no cell holds both signs of a coordinate).
pub(crate) fn triggers(
    vol: &DisplayVolume,
    filter: &PixelFilter,
    width: usize,
    steps: f64,
    out: &mut Vec<DVec3>,
) {
    out.clear();
    let mut push = |p_world: DVec3| {
        let q = vol.index_from_world(p_world);
        if vol.inside(q) {
            out.push(q);
        }
    };
    let grid = |i: usize, n: usize| -2.0 + 4.0 * (i as f64 + 0.5) / n as f64;
    match *filter {
        PixelFilter::Linearised { ray, sigma, .. } | PixelFilter::LineIntegral { ray, sigma } => {
            let len = ray.tb - ray.ta;
            let k = ((len * steps / vol.unit()).ceil().max(1.0)) as usize;
            for j in 0..k {
                let t = ray.ta + (j as f64 + 0.5) * len / k as f64;
                let s = sigma.at(t);
                for bi in 0..width {
                    for ai in 0..width {
                        let p = ray.o
                            + ray.d * t
                            + (ray.e1 * grid(ai, width) + ray.e2 * grid(bi, width)) * s;
                        push(p);
                    }
                }
            }
        }
        PixelFilter::Slice { ray, sigma, tc, w } => {
            for ti in 0..width {
                let t = tc + grid(ti, width) * w;
                let s = sigma.at(t);
                for bi in 0..width {
                    for ai in 0..width {
                        let p = ray.o
                            + ray.d * t
                            + (ray.e1 * grid(ai, width) + ray.e2 * grid(bi, width)) * s;
                        push(p);
                    }
                }
            }
        }
        PixelFilter::Ball { c, s } => {
            for zi in 0..width {
                for yi in 0..width {
                    for xi in 0..width {
                        let p =
                            c + DVec3::new(grid(xi, width), grid(yi, width), grid(zi, width)) * s;
                        push(p);
                    }
                }
            }
        }
    }
}
