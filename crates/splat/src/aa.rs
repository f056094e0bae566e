//! Anti-aliased footprints (Swan, Mueller, Möller, Shareef, Crawfis, Yagel 1997, §4.3–4.6; and,
//! for comparison, the EWA screen-space filter of Zwicker, Pfister, van Baar, Gross 2001).
//!
//! Every footprint in this crate is described on the screen by the symmetric 2×2 *lattice
//! metric* `Q` (lattice units² per pixel²): a ray through raster offset `δ` (pixels) passes the
//! kernel centre at lattice distance `ρ = √(δᵀQδ)`. Its eigenvalues `μ₁ ≥ μ₂` give the pixels per
//! lattice step along the principal screen directions, `1/√μᵢ`. Where a lattice step covers less
//! than a pixel, the screen samples the footprint below its Nyquist rate and splatting aliases
//! (Swan et al. §4.1–4.2).
//!
//! An anti-aliasing rule replaces `Q` by a wider `Q′ ≤ Q` and scales the footprint's weights by
//! `E = √(det Q′ / det Q)` so that each splat keeps its energy (eq. 5–8): the footprint's
//! integral over the screen is `∫F / √det Q`.
//!
//! - [`Antialias::Swan`] (eq. 3, 4, 8): the distance `k = s·D/p` at which one voxel maps to one
//!   pixel is where the finest projected lattice step is one pixel, `μ₁ = 1`. Beyond it
//!   (`μ₁ > 1`) the splat's radius grows by `d/k = √μ₁` and its energy by `(k/d)² = 1/μ₁`, i.e.
//!   `Q′ = Q/μ₁`, `E = 1/μ₁`. For cubic voxels in a perspective view `√μ₁ = d/k` exactly, with `d`
//!   the eye-space depth (the tangential direction of §4.6's Figure 6). In an orthographic view
//!   of a volume finer than the image the same rule applies with a constant `μ₁`. With
//!   anisotropic spacing the rule uses the finest projected step, so no direction aliases: the
//!   splat grows isotropically until its narrowest axis spans one pixel per voxel (the choice is
//!   recorded in `docs/decisions/0006-antialiasing.md`).
//! - [`Antialias::SwanPerpendicular`] (§4.6): the ray spacing measured perpendicular to the ray
//!   is `r′ ≈ r cos α`, so each principal axis is widened only as far as it needs: `μᵢ′ =
//!   min(μᵢ, 1)`. Off-axis, eq. 4 widens the radial direction `1/cos α` more than needed (1.15× at
//!   30°); this variant does not.
//! - [`Antialias::Ewa`] (Zwicker et al. 2001, eq. 19–21): the footprint's screen covariance
//!   `σ²Q⁻¹` (σ² the kernel's per-axis variance in lattice units²) is convolved with a
//!   unit-variance Gaussian pixel pre-filter: `Q′ = σ²(σ²Q⁻¹ + I)⁻¹`. It widens every splat,
//!   also those larger than a pixel (by a little), and grows smoothly instead of switching on
//!   at `k`.

use volsplat_core::Kernel;
use volsplat_core::glam::{DMat2, DVec2};

/// How footprints are widened where the volume is finer than the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Antialias {
    /// Standard splatting: footprints are the true projection, whatever their size.
    None,
    /// Swan et al. 1997 eq. 4 and 8 (default): beyond `k`, radius × `d/k`, energy × `(k/d)²`.
    #[default]
    Swan,
    /// Swan et al. 1997 §4.6: the perpendicular ray-spacing estimate, per principal axis.
    SwanPerpendicular,
    /// Zwicker et al. 2001 EWA: footprint covariance plus a unit pixel covariance.
    Ewa,
}

impl Antialias {
    /// Names accepted by [`Antialias::from_name`].
    pub const NAMES: &'static [&'static str] = &["swan", "swan-perpendicular", "ewa", "none"];

    /// Parses `swan`, `swan-perpendicular`, `ewa` or `none`.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "swan" => Antialias::Swan,
            "swan-perpendicular" | "perpendicular" => Antialias::SwanPerpendicular,
            "ewa" => Antialias::Ewa,
            "none" | "off" => Antialias::None,
            _ => return None,
        })
    }

    /// The short name.
    pub fn name(self) -> &'static str {
        match self {
            Antialias::None => "none",
            Antialias::Swan => "swan",
            Antialias::SwanPerpendicular => "swan-perpendicular",
            Antialias::Ewa => "ewa",
        }
    }
}

/// Eigen-decomposition of a symmetric 2×2 matrix: `(μ₁, μ₂, e₁)` with `μ₁ ≥ μ₂` and `e₁` the unit
/// eigenvector of `μ₁` (`e₂` is `e₁` turned by 90°). A non-finite input gives non-finite
/// eigenvalues, which callers check.
///
/// The eigenvector is formed from the half-difference `d = (a − c)/2` and the discriminant
/// `r = √(d² + b²)` as `(d + r, b)` when `a ≥ c` and `(b, r − d)` otherwise: the component
/// `|d| + r ≥ r > 0` cannot cancel. (The textbook form `(a − μ₂, b)` cancels to `(0, 0)` when the
/// metric is isotropic to rounding, `a` one ulp above `c` with `b = 0`: the footprint became NaN
/// and whole images black at common orthographic views of cubic voxels; regression test
/// `nearly_isotropic_metric_has_a_unit_eigenvector` and `crates/splat/tests/every_angle.rs`.)
pub(crate) fn sym_eigen(q: DMat2) -> (f64, f64, DVec2) {
    let (a, b, c) = (q.col(0).x, 0.5 * (q.col(1).x + q.col(0).y), q.col(1).y);
    let mean = 0.5 * (a + c);
    let diff = 0.5 * (a - c);
    let disc = diff.hypot(b);
    let (l1, l2) = (mean + disc, mean - disc);
    let e1 = if disc.is_nan() || disc <= 0.0 {
        // Isotropic (or non-finite, reported through the eigenvalues): any unit vector.
        DVec2::X
    } else if diff >= 0.0 {
        unit(DVec2::new(diff + disc, b))
    } else {
        unit(DVec2::new(b, disc - diff))
    };
    (l1, l2, e1)
}

/// `v / |v|` without underflow for tiny `v` (one component is non-zero).
fn unit(v: DVec2) -> DVec2 {
    let v = v / v.x.abs().max(v.y.abs());
    v / v.length()
}

fn from_eigen(l1: f64, l2: f64, e1: DVec2) -> DMat2 {
    let e2 = DVec2::new(-e1.y, e1.x);
    let m = |u: DVec2, l: f64| DMat2::from_cols(u * (u.x * l), u * (u.y * l));
    m(e1, l1) + m(e2, l2)
}

/// Applies `rule` to the lattice metric `q`; returns the widened metric and the energy factor
/// `E = √(det Q′/det Q)` ≤ 1. `variance` is the kernel's per-axis footprint variance in lattice
/// units² (used by EWA only; see [`footprint_variance`]).
pub fn widen(rule: Antialias, q: DMat2, variance: f64) -> (DMat2, f64) {
    let (m1, m2, e1) = sym_eigen(q);
    if !(m2 > 0.0 && m1.is_finite()) {
        return (q, 1.0);
    }
    match rule {
        Antialias::None => (q, 1.0),
        Antialias::Swan => {
            if m1 <= 1.0 {
                (q, 1.0)
            } else {
                (q * (1.0 / m1), 1.0 / m1)
            }
        }
        Antialias::SwanPerpendicular => {
            let (n1, n2) = (m1.min(1.0), m2.min(1.0));
            if n1 == m1 && n2 == m2 {
                (q, 1.0)
            } else {
                (from_eigen(n1, n2, e1), ((n1 * n2) / (m1 * m2)).sqrt())
            }
        }
        Antialias::Ewa => {
            // Σ = σ²Q⁻¹ (pixels²); Σ′ = Σ + I; Q′ = σ²Σ′⁻¹: eigenvalues σ²/(σ²/μ + 1).
            let v = variance.max(1e-12);
            let f = |m: f64| v / (v / m + 1.0);
            let (n1, n2) = (f(m1), f(m2));
            (from_eigen(n1, n2, e1), ((n1 * n2) / (m1 * m2)).sqrt())
        }
    }
}

/// The per-axis variance of a kernel's footprint, lattice units²: `½∫ρ²F(ρ)d²ρ` for radial
/// kernels (F the line integral, unit mass), `∫x²h(x)dx` of the 1-D factor for separable ones.
/// Used as the kernel's covariance `σ²I` by the EWA rule.
pub fn footprint_variance(kernel: &Kernel) -> f64 {
    let n = 2000;
    let r = kernel.radius();
    if r <= 0.0 {
        return 1.0 / 12.0;
    }
    let h = r / n as f64;
    let mut num = 0.0;
    let mut den = 0.0;
    for i in 0..n {
        let x = (i as f64 + 0.5) * h;
        if kernel.is_radial() {
            let f = kernel.line_integral_radial(x).unwrap_or(0.0);
            num += x * x * f * x;
            den += f * x;
        } else {
            let f = kernel.eval_1d(x);
            num += x * x * f;
            den += f;
        }
    }
    if kernel.is_radial() {
        0.5 * num / den
    } else {
        num / den
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metric(l1: f64, l2: f64, angle: f64) -> DMat2 {
        from_eigen(l1, l2, DVec2::new(angle.cos(), angle.sin()))
    }

    /// Root cause of the black/NaN images at azimuth 30°/45° (issue 17): for cubic voxels an
    /// orthographic metric is isotropic up to rounding, e.g. `a` one ulp above `c` with `b = 0`.
    /// The textbook eigenvector `(a − μ₂, b)` then cancelled to `(0, 0)` and normalised to NaN.
    #[test]
    fn nearly_isotropic_metric_has_a_unit_eigenvector() {
        let mut cases = Vec::new();
        for base in [1e-6f64, 0.0123, 0.25, 1.0, 1.0 / 3.0, 7.77, 1e6] {
            let up = f64::from_bits(base.to_bits() + 1);
            let down = f64::from_bits(base.to_bits() - 1);
            for (a, c) in [
                (up, base),
                (base, up),
                (base, down),
                (down, base),
                (base, base),
            ] {
                for b in [0.0, 1e-300, -1e-300, base * 1e-17, -base * 1e-17] {
                    cases.push((a, b, c));
                }
            }
        }
        for (a, b, c) in cases {
            let q = DMat2::from_cols(DVec2::new(a, b), DVec2::new(b, c));
            let (m1, m2, e1) = sym_eigen(q);
            assert!(e1.is_finite(), "({a:e}, {b:e}, {c:e}): e1 = {e1}");
            assert!((e1.length() - 1.0).abs() < 1e-12);
            assert!(m1 >= m2 && (m1 - a.max(c)).abs() <= 1e-12 * a.abs().max(c.abs()));
            // Q e1 = μ₁ e1 to rounding.
            let r = q * e1 - e1 * m1;
            assert!(
                r.length() <= 1e-12 * m1.abs(),
                "({a:e}, {b:e}, {c:e}): residual {r}"
            );
        }
    }

    #[test]
    fn swan_scales_radius_by_d_over_k_and_energy_by_its_inverse_square() {
        // A lattice step of 1/3 pixel: d/k = 3.
        let q = metric(9.0, 9.0, 0.3);
        let (q2, e) = widen(Antialias::Swan, q, 0.36);
        assert!((e - 1.0 / 9.0).abs() < 1e-12);
        let (m1, m2, _) = sym_eigen(q2);
        assert!((m1 - 1.0).abs() < 1e-12 && (m2 - 1.0).abs() < 1e-12);
        // Before k nothing changes.
        let q = metric(0.5, 0.2, 1.0);
        assert_eq!(widen(Antialias::Swan, q, 0.36), (q, 1.0));
        assert_eq!(widen(Antialias::SwanPerpendicular, q, 0.36), (q, 1.0));
        // Anisotropic: the finest direction decides, the shape is kept.
        let q = metric(16.0, 4.0, 0.7);
        let (q2, e) = widen(Antialias::Swan, q, 0.36);
        let (m1, m2, _) = sym_eigen(q2);
        assert!((m1 - 1.0).abs() < 1e-12 && (m2 - 0.25).abs() < 1e-12);
        assert!((e - 1.0 / 16.0).abs() < 1e-12);
    }

    #[test]
    fn perpendicular_rule_widens_each_axis_only_as_needed() {
        let q = metric(16.0, 0.25, 0.4);
        let (q2, e) = widen(Antialias::SwanPerpendicular, q, 0.36);
        let (m1, m2, e1) = sym_eigen(q2);
        assert!((m1 - 1.0).abs() < 1e-12 && (m2 - 0.25).abs() < 1e-12);
        assert!((e1.dot(DVec2::new(0.4f64.cos(), 0.4f64.sin())).abs() - 1.0).abs() < 1e-12);
        assert!((e - 0.25).abs() < 1e-12);
    }

    #[test]
    fn ewa_adds_a_unit_pixel_variance_and_keeps_energy() {
        let v = 0.36;
        let q = metric(4.0, 1.0, 0.0);
        let (q2, e) = widen(Antialias::Ewa, q, v);
        // Screen variances: v/μ + 1.
        let (m1, m2, _) = sym_eigen(q2);
        assert!((v / m1 - (v / 4.0 + 1.0)).abs() < 1e-12);
        assert!((v / m2 - (v + 1.0)).abs() < 1e-12);
        assert!((e - ((m1 * m2) / 4.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn footprint_variances() {
        // Truncated Gaussian σ = 0.6, r = 2: σ²·E[r²; r < c]/(3·P(r < c)) of the χ₃ law with
        // c = r/σ, 0.346136 by independent quadrature (the 3-D variance equals the footprint's).
        let g = footprint_variance(&Kernel::default());
        assert!((g - 0.346136).abs() < 1e-4, "{g}");
        // Tent: ∫x²(1−|x|)dx = 1/6.
        let t = footprint_variance(&Kernel::Tent);
        assert!((t - 1.0 / 6.0).abs() < 1e-6, "{t}");
    }
}
