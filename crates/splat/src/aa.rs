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
//! - [`Antialias::Area`]: the same resampling filter with the pixel pre-filter's variance
//!   reduced from 1 to that of a one-pixel box, `s = 1/12` px² per axis: `Q′ = σ²(σ²Q⁻¹ +
//!   I/12)⁻¹`, `E = √(det Q′/det Q)`. This is Zwicker et al. 2001's EWA low-pass (§5) scaled to
//!   a box, and Mip-Splatting's "2D Mip filter" chosen to mimic a one-pixel box (Yu, Chen,
//!   Huang, Sattler, Geiger, *Mip-Splatting: Alias-free 3D Gaussian Splatting*, CVPR 2024,
//!   §5.2). It approximates the pixel-area average that box-filtered supersampled references
//!   compute: Swan's rule widens a minified splat to a screen variance of `σ²` ≈ 0.36 px² per
//!   axis, far more than a pixel's 1/12, and on real data shown small is then worse than no
//!   anti-aliasing against such a reference (issue 12 item 4; `docs/design/pipeline.md` §4).
//!   At magnification it widens every splat's screen variance by exactly 1/12 px².

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
    /// The pixel's area: footprint covariance plus a one-pixel box's covariance, `I/12` (EWA's
    /// resampling filter with `s = 1/12`, Zwicker et al. 2001; Mip-Splatting's 2D Mip filter,
    /// Yu et al. CVPR 2024 §5.2).
    Area,
}

impl Antialias {
    /// Names accepted by [`Antialias::from_name`].
    pub const NAMES: &'static [&'static str] =
        &["swan", "swan-perpendicular", "ewa", "area", "none"];

    /// Parses `swan`, `swan-perpendicular`, `ewa`, `area` or `none`.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "swan" => Antialias::Swan,
            "swan-perpendicular" | "perpendicular" => Antialias::SwanPerpendicular,
            "ewa" => Antialias::Ewa,
            "area" => Antialias::Area,
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
            Antialias::Area => "area",
        }
    }
}

/// The screen-space variance, px² per axis, that [`Antialias::Area`] adds to a footprint: that
/// of a one-pixel box, `∫x²dx` over `[−½, ½]`.
pub const AREA_VARIANCE: f64 = 1.0 / 12.0;

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
/// units² (used by EWA and Area only; see [`footprint_variance`]).
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
        Antialias::Ewa => prefilter(m1, m2, e1, variance, 1.0),
        Antialias::Area => prefilter(m1, m2, e1, variance, AREA_VARIANCE),
    }
}

/// The EWA resampling filter (Zwicker et al. 2001, eq. 19–21) with a pixel pre-filter of variance
/// `s` px² per axis, for the metric with eigen-decomposition `(μ₁, μ₂, e₁)` and kernel variance
/// `variance`: `Σ = σ²Q⁻¹` (pixels²); `Σ′ = Σ + s·I`; `Q′ = σ²Σ′⁻¹`, eigenvalues
/// `σ²/(σ²/μ + s)`; `E = √(det Q′/det Q)`.
fn prefilter(m1: f64, m2: f64, e1: DVec2, variance: f64, s: f64) -> (DMat2, f64) {
    let v = variance.max(1e-12);
    let f = |m: f64| v / (v / m + s);
    let (n1, n2) = (f(m1), f(m2));
    (from_eigen(n1, n2, e1), ((n1 * n2) / (m1 * m2)).sqrt())
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

    /// The screen covariance `σ²Q′⁻¹` of an `area`-widened footprint is the true one plus
    /// `I/12` px², along the same principal axes, minified or magnified.
    #[test]
    fn area_adds_a_twelfth_pixel_variance() {
        for v in [0.346136, 1.0 / 6.0, 1.0] {
            for (l1, l2, angle) in [
                (9.0, 9.0, 0.3),
                (16.0, 0.25, 0.4),
                (4.0, 1.0, 0.0),
                (0.5, 0.2, 1.0),
                (1e-3, 1e-4, 2.5),
            ] {
                let q = metric(l1, l2, angle);
                let (q2, _) = widen(Antialias::Area, q, v);
                let (m1, m2, e1) = sym_eigen(q2);
                // μ′ is decreasing in the screen variance, so μ₁′ belongs to μ₁.
                for (mu, n) in [(l1, m1), (l2, m2)] {
                    let want = v / mu + 1.0 / 12.0;
                    assert!(
                        (v / n - want).abs() <= 1e-12 * want,
                        "σ² {v}, μ {mu}: {} vs {want}",
                        v / n
                    );
                }
                if l1 > l2 {
                    let axis = DVec2::new(angle.cos(), angle.sin());
                    assert!((e1.dot(axis).abs() - 1.0).abs() < 1e-12);
                }
                // The whole matrix: σ²Q′⁻¹ = σ²Q⁻¹ + I/12.
                let d = q2.inverse() * v - (q.inverse() * v + DMat2::IDENTITY / 12.0);
                let scale = v / l2;
                for c in [d.col(0), d.col(1)] {
                    assert!(c.abs().max_element() <= 1e-9 * scale, "{d}");
                }
            }
        }
    }

    /// Each splat keeps its energy: the weight factor is `E = √(det Q′/det Q)`, so the
    /// footprint's screen integral `E·∫F/√det Q′` equals the unwidened `∫F/√det Q`.
    #[test]
    fn area_keeps_energy() {
        for (l1, l2, angle) in [(9.0, 9.0, 0.3), (16.0, 0.25, 0.4), (0.5, 0.2, 1.0)] {
            let q = metric(l1, l2, angle);
            let (q2, e) = widen(Antialias::Area, q, 0.346136);
            assert!(e > 0.0 && e < 1.0, "{e}");
            let (dq, dq2) = (q.determinant(), q2.determinant());
            assert!((e * e * dq - dq2).abs() <= 1e-12 * dq2, "{e} {dq} {dq2}");
            assert!((e / dq2.sqrt() - 1.0 / dq.sqrt()).abs() <= 1e-12 / dq.sqrt());
        }
        // Minified 3× (μ = 9, σ² = 0.346): screen variance 0.0385 → 0.1218 px², E = 0.316,
        // against Swan's 1/9 (variance 0.346 px², nine times the area).
        let (_, e) = widen(Antialias::Area, metric(9.0, 9.0, 0.0), 0.346136);
        let want = (0.346136 / 9.0) / (0.346136 / 9.0 + 1.0 / 12.0);
        assert!((e - want).abs() < 1e-12, "{e} vs {want}");
        assert!(e > 2.5 / 9.0);
    }

    /// Where a voxel spans a pixel or more (`μ ≤ 1`) Swan's rule changes nothing; `area` adds
    /// the box's 1/12 px², at most `√(1 + 1/(12σ²))` in radius (1.113 for Westover's Gaussian),
    /// far less than EWA's unit pre-filter.
    #[test]
    fn area_at_magnification_widens_by_at_most_the_box_variance() {
        let v = footprint_variance(&Kernel::default());
        let max_radius = (1.0 + 1.0 / (12.0 * v)).sqrt();
        assert!((max_radius - 1.1133).abs() < 1e-3, "{max_radius}");
        for (l1, l2, angle) in [
            (1.0, 1.0, 0.0),
            (0.999, 0.3, 0.7),
            (0.5, 0.2, 1.0),
            (1.0 / 1.5f64.powi(2), 1.0 / 1.5f64.powi(2), 0.2),
            (0.01, 0.002, -0.4),
        ] {
            let q = metric(l1, l2, angle);
            let (q2, e) = widen(Antialias::Area, q, v);
            let (m1, m2, _) = sym_eigen(q2);
            for (mu, n) in [(l1, m1), (l2, m2)] {
                let (before, after) = (v / mu, v / n);
                assert!(after > before, "μ {mu}: {before} → {after}");
                assert!(after - before <= 1.0 / 12.0 + 1e-12, "μ {mu}");
                assert!((after / before).sqrt() <= max_radius + 1e-12, "μ {mu}");
            }
            assert!(e >= 1.0 / max_radius.powi(2) - 1e-12 && e < 1.0, "{e}");
            // EWA widens more, Swan not at all.
            let (_, e_ewa) = widen(Antialias::Ewa, q, v);
            assert!(e_ewa < e, "ewa {e_ewa} vs area {e}");
            assert_eq!(widen(Antialias::Swan, q, v), (q, 1.0));
        }
        // 1.5 px per voxel: σ² 0.78 → 0.86 px².
        let q = metric(1.0 / 2.25, 1.0 / 2.25, 0.0);
        let (q2, _) = widen(Antialias::Area, q, v);
        let (n, _, _) = sym_eigen(q2);
        assert!((v / n - (v * 2.25 + 1.0 / 12.0)).abs() < 1e-12);
    }

    #[test]
    fn names_round_trip() {
        for &name in Antialias::NAMES {
            let aa = Antialias::from_name(name).unwrap();
            assert_eq!(aa.name(), name);
        }
        assert_eq!(Antialias::from_name("area"), Some(Antialias::Area));
        assert_eq!(Antialias::from_name("box"), None);
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
