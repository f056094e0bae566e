//! Reconstruction kernels (Westover 1991, §2.7–2.9, §4.2.2).
//!
//! Every kernel is defined in *index space* (one unit = one voxel step along each grid axis) and
//! normalised so that its 3-D integral is 1, hence a constant volume reconstructs to the constant.
//! The Gaussian is radial and truncated at `radius` (Westover's σ = 0.6, r = 2, "five samples
//! wide", §4.2.2, §5.4); the others are separable products of a 1-D kernel (the "correct" 3-D
//! extension, §2.8).

use crate::error::{CoreError, Result};
use glam::DVec3;
use std::f64::consts::PI;

/// A reconstruction kernel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kernel {
    /// Radial Gaussian `exp(−r²/2σ²)`, σ and the truncation radius in voxel units, renormalised
    /// after truncation to integrate to 1.
    Gaussian {
        /// Standard deviation, voxel units (> 0).
        sigma: f64,
        /// Truncation radius, voxel units (> 0).
        radius: f64,
    },
    /// Westover's single-point kernel: each sample lands on the one pixel nearest its projection.
    SinglePoint,
    /// Westover's nearest-neighbour kernel: each sample covers the pixels nearest to it within its
    /// sheet's lattice (the projected lattice cell around it).
    Nearest,
    /// Separable tent (linear interpolation), support ±1.
    Tent,
    /// Separable Mitchell–Netravali cubic with parameters (B, C), support ±2. B = 1, C = 0 is the
    /// cubic B-spline; B = 0, C = 0.5 is Catmull–Rom.
    MitchellNetravali {
        /// Blur parameter B.
        b: f64,
        /// Ringing parameter C.
        c: f64,
    },
}

impl Default for Kernel {
    /// Westover's Gaussian: σ = 0.6, radius 2.
    fn default() -> Self {
        Kernel::Gaussian {
            sigma: 0.6,
            radius: 2.0,
        }
    }
}

impl Kernel {
    /// Names accepted by [`Kernel::from_name`].
    pub const NAMES: &'static [&'static str] = &[
        "gaussian",
        "point",
        "nearest",
        "tent",
        "bspline",
        "catmull-rom",
        "mitchell",
    ];

    /// Parses a kernel name (see [`Kernel::NAMES`]); `mitchell` is B = C = 1/3.
    pub fn from_name(name: &str) -> Result<Self> {
        Ok(match name {
            "gaussian" => Kernel::default(),
            "point" | "single-point" => Kernel::SinglePoint,
            "nearest" | "nearest-neighbour" | "nn" => Kernel::Nearest,
            "tent" | "linear" => Kernel::Tent,
            "bspline" | "b-spline" => Kernel::MitchellNetravali { b: 1.0, c: 0.0 },
            "catmull-rom" | "catmullrom" => Kernel::MitchellNetravali { b: 0.0, c: 0.5 },
            "mitchell" => Kernel::MitchellNetravali {
                b: 1.0 / 3.0,
                c: 1.0 / 3.0,
            },
            _ => {
                return Err(CoreError::UnknownName {
                    kind: "kernel".into(),
                    name: name.into(),
                    known: Self::NAMES.join(", "),
                });
            }
        })
    }

    /// A short name for reports.
    pub fn name(&self) -> String {
        match *self {
            Kernel::Gaussian { sigma, radius } => format!("gaussian(σ={sigma},r={radius})"),
            Kernel::SinglePoint => "point".into(),
            Kernel::Nearest => "nearest".into(),
            Kernel::Tent => "tent".into(),
            Kernel::MitchellNetravali { b, c } if b == 1.0 && c == 0.0 => "bspline".into(),
            Kernel::MitchellNetravali { b, c } if b == 0.0 && c == 0.5 => "catmull-rom".into(),
            Kernel::MitchellNetravali { b, c } => format!("mitchell(B={b:.3},C={c:.3})"),
        }
    }

    /// Checks the parameters.
    pub fn validate(&self) -> Result<()> {
        if let Kernel::Gaussian { sigma, radius } = *self
            && !(sigma.is_finite() && sigma > 0.0 && radius.is_finite() && radius > 0.0)
        {
            return Err(CoreError::invalid(
                "gaussian kernel",
                (sigma, radius),
                "σ and radius must be > 0",
            ));
        }
        if let Kernel::MitchellNetravali { b, c } = *self
            && !(b.is_finite() && c.is_finite())
        {
            return Err(CoreError::invalid(
                "mitchell kernel",
                (b, c),
                "B and C must be finite",
            ));
        }
        Ok(())
    }

    /// Support radius in voxel units: the kernel is zero for `|x|` beyond it along each axis
    /// (separable) or for `‖x‖` beyond it (radial).
    pub fn radius(&self) -> f64 {
        match *self {
            Kernel::Gaussian { radius, .. } => radius,
            Kernel::SinglePoint => 0.0,
            Kernel::Nearest => 0.5,
            Kernel::Tent => 1.0,
            Kernel::MitchellNetravali { .. } => 2.0,
        }
    }

    /// Whether the kernel is radially symmetric in index space.
    pub fn is_radial(&self) -> bool {
        matches!(self, Kernel::Gaussian { .. })
    }

    /// The 1-D factor of a separable kernel at `x` (voxel units); integrates to 1.
    /// For the Gaussian, the untruncated, unnormalised profile `exp(−x²/2σ²)`.
    pub fn eval_1d(&self, x: f64) -> f64 {
        let ax = x.abs();
        match *self {
            Kernel::Gaussian { sigma, .. } => (-x * x / (2.0 * sigma * sigma)).exp(),
            Kernel::SinglePoint | Kernel::Nearest => {
                if ax < 0.5 {
                    1.0
                } else if ax == 0.5 {
                    0.5
                } else {
                    0.0
                }
            }
            Kernel::Tent => (1.0 - ax).max(0.0),
            Kernel::MitchellNetravali { b, c } => mitchell_netravali(ax, b, c),
        }
    }

    /// The 3-D kernel at index-space offset `p`, normalised to unit integral.
    pub fn eval_3d(&self, p: DVec3) -> f64 {
        match *self {
            Kernel::Gaussian { sigma, radius } => {
                let r2 = p.length_squared();
                if r2 > radius * radius {
                    0.0
                } else {
                    (-r2 / (2.0 * sigma * sigma)).exp() / gaussian_ball_mass(sigma, radius)
                }
            }
            _ => self.eval_1d(p.x) * self.eval_1d(p.y) * self.eval_1d(p.z),
        }
    }

    /// Radial kernels only: the integral of the normalised 3-D kernel along a straight line at
    /// distance `rho` (voxel units) from its centre, in index-space length units. Closed form for
    /// the truncated Gaussian: `e^(−ρ²/2σ²) · σ√(2π) · erf(√(r²−ρ²)/(σ√2)) / mass`.
    /// Returns `None` for separable kernels.
    pub fn line_integral_radial(&self, rho: f64) -> Option<f64> {
        match *self {
            Kernel::Gaussian { sigma, radius } => {
                if rho >= radius {
                    return Some(0.0);
                }
                let half = (radius * radius - rho * rho).sqrt();
                let v = (-rho * rho / (2.0 * sigma * sigma)).exp()
                    * sigma
                    * (2.0 * PI).sqrt()
                    * erf(half / (sigma * std::f64::consts::SQRT_2));
                Some(v / gaussian_ball_mass(sigma, radius))
            }
            _ => None,
        }
    }
}

/// The Mitchell–Netravali BC cubic at `x ≥ 0` (Westover §2.7, after Mitchell & Netravali 1988).
pub fn mitchell_netravali(x: f64, b: f64, c: f64) -> f64 {
    let x2 = x * x;
    let x3 = x2 * x;
    let v = if x < 1.0 {
        (12.0 - 9.0 * b - 6.0 * c) * x3 + (-18.0 + 12.0 * b + 6.0 * c) * x2 + (6.0 - 2.0 * b)
    } else if x < 2.0 {
        (-b - 6.0 * c) * x3
            + (6.0 * b + 30.0 * c) * x2
            + (-12.0 * b - 48.0 * c) * x
            + (8.0 * b + 24.0 * c)
    } else {
        0.0
    };
    v / 6.0
}

/// Integral of `exp(−r²/2σ²)` over the ball of radius `radius` in 3-D:
/// `(2πσ²)^{3/2} · (erf(t/√2) − √(2/π)·t·e^{−t²/2})` with `t = radius/σ`.
pub fn gaussian_ball_mass(sigma: f64, radius: f64) -> f64 {
    let t = radius / sigma;
    let chi3 = erf(t / std::f64::consts::SQRT_2) - (2.0 / PI).sqrt() * t * (-t * t / 2.0).exp();
    (2.0 * PI * sigma * sigma).powf(1.5) * chi3
}

/// The error function, to about 1e-15 absolute (series for |x| < 2.5, continued fraction above).
pub fn erf(x: f64) -> f64 {
    let ax = x.abs();
    let v = if ax < 2.5 {
        // Maclaurin series: erf x = 2/√π Σ (−1)^n x^(2n+1) / (n! (2n+1)).
        let mut term = ax;
        let mut sum = ax;
        let x2 = ax * ax;
        let mut n = 0.0;
        while term.abs() > 1e-17 * sum.abs() {
            n += 1.0;
            term *= -x2 / n;
            sum += term / (2.0 * n + 1.0);
            if n > 200.0 {
                break;
            }
        }
        2.0 / PI.sqrt() * sum
    } else {
        // erfc x = e^{−x²}/√π · 1/(x + 1/2/(x + 1/(x + 3/2/(x + ...)))) (Lentz-free backward sum).
        let mut f = 0.0;
        for k in (1..60).rev() {
            f = (k as f64 / 2.0) / (ax + f);
        }
        1.0 - (-ax * ax).exp() / PI.sqrt() / (ax + f)
    };
    if x < 0.0 { -v } else { v }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erf_matches_reference_values() {
        // Values from Abramowitz & Stegun Table 7.1.
        for (x, e) in [
            (0.5, 0.520_499_877_813_046_5),
            (1.0, 0.842_700_792_949_714_9),
            (2.0, 0.995_322_265_018_952_7),
            (3.0, 0.999_977_909_503_001_4),
        ] {
            assert!((erf(x) - e).abs() < 1e-13, "erf({x}) = {}", erf(x));
            assert!((erf(-x) + e).abs() < 1e-13);
        }
    }

    #[test]
    fn westover_gaussian_is_five_samples_wide() {
        // exp(−4/0.72) = 0.00387 < 0.004 (Westover §4.2.2).
        let k = Kernel::default();
        assert!((k.eval_1d(2.0) - 0.003_866).abs() < 1e-5);
        assert!(k.eval_1d(2.0) < 0.004);
    }

    /// Integrates the 3-D kernel on a fine midpoint grid.
    fn integral_3d(k: &Kernel) -> f64 {
        let r = k.radius() + 0.1;
        let n = 100;
        let h = 2.0 * r / n as f64;
        let mut s = 0.0;
        for a in 0..n {
            for b in 0..n {
                for c in 0..n {
                    let p = DVec3::new(a as f64 + 0.5, b as f64 + 0.5, c as f64 + 0.5) * h
                        - DVec3::splat(r);
                    s += k.eval_3d(p);
                }
            }
        }
        s * h * h * h
    }

    #[test]
    fn kernels_integrate_to_one() {
        for k in [
            Kernel::default(),
            Kernel::Tent,
            Kernel::MitchellNetravali { b: 1.0, c: 0.0 },
            Kernel::MitchellNetravali { b: 0.0, c: 0.5 },
        ] {
            let i = integral_3d(&k);
            assert!((i - 1.0).abs() < 3e-3, "{}: {i}", k.name());
        }
    }

    #[test]
    fn bc_cubics_are_partitions_of_unity() {
        for (b, c) in [(1.0, 0.0), (0.0, 0.5), (1.0 / 3.0, 1.0 / 3.0)] {
            let k = Kernel::MitchellNetravali { b, c };
            for t in 0..50 {
                let x = t as f64 / 50.0;
                let s: f64 = (-3..=3).map(|n| k.eval_1d(x - n as f64)).sum();
                assert!((s - 1.0).abs() < 1e-12, "B={b} C={c} x={x}: {s}");
            }
        }
        let cr = Kernel::MitchellNetravali { b: 0.0, c: 0.5 };
        assert_eq!(cr.eval_1d(0.0), 1.0);
        assert!(cr.eval_1d(1.0).abs() < 1e-15);
    }

    #[test]
    fn gaussian_line_integral_matches_quadrature() {
        let k = Kernel::default();
        for rho in [0.0, 0.3, 1.0, 1.7, 1.99] {
            // Midpoint rule over the chord inside the support, where the integrand is smooth.
            let half = (4.0f64 - rho * rho).sqrt() * (1.0 - 1e-12);
            let n = 20000;
            let h = 2.0 * half / n as f64;
            let q: f64 = (0..n)
                .map(|i| k.eval_3d(DVec3::new(rho, 0.0, -half + (i as f64 + 0.5) * h)) * h)
                .sum();
            let a = k.line_integral_radial(rho).unwrap();
            assert!((a - q).abs() < 1e-6 * a.max(1e-3), "rho={rho}: {a} vs {q}");
        }
        assert_eq!(k.line_integral_radial(2.5), Some(0.0));
        assert_eq!(Kernel::Tent.line_integral_radial(0.0), None);
    }

    #[test]
    fn names_round_trip_and_unknown_fails() {
        for n in Kernel::NAMES {
            Kernel::from_name(n).unwrap().validate().unwrap();
        }
        assert!(
            Kernel::from_name("sinc")
                .unwrap_err()
                .to_string()
                .contains("gaussian")
        );
    }
}
