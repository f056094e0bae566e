//! Filter kernels over an integration region (thesis §4-2, Plates 5.4–5.6; eq 6.1, §6-3, App. C).
//!
//! Filters are defined in the local coordinates `(s, t, r) ∈ [−1, 1]³` of an
//! [`OrientedBox`](crate::region::OrientedBox): `s, t` span the footprint (for `V_tan` the
//! tangent-plane ellipse's major/minor directions scaled by its semi-axes × spread), `r` the
//! depth (normal for `V_tan`, along the ray for `V_ray`). Decision A-10: every filter is a box
//! along `r` and separable in `s, t`; the Gaussian is 2-D in the footprint plane.

use crate::error::{Result, check_positive};

/// A filter shape over the local box coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FilterKind {
    /// `F = 1` over the box.
    Box,
    /// Bartlett (tent): `F = (1 − |s|)(1 − |t|)`.
    Bartlett,
    /// Truncated Gaussian `F = exp(−α (s² + t²))`; `α = 1/(2σ²)` with `σ` in units of the
    /// half-extent (default `α = 2`, i.e. `σ = ½`).
    Gaussian {
        /// Exponent `α > 0`.
        alpha: f64,
    },
}

impl Default for FilterKind {
    fn default() -> Self {
        FilterKind::Gaussian { alpha: 2.0 }
    }
}

impl FilterKind {
    /// Checks parameters (`alpha > 0`).
    pub fn validate(&self) -> Result<()> {
        match *self {
            FilterKind::Gaussian { alpha } => check_positive("alpha", alpha),
            _ => Ok(()),
        }
    }

    /// Short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            FilterKind::Box => "box",
            FilterKind::Bartlett => "Bartlett",
            FilterKind::Gaussian { .. } => "Gaussian",
        }
    }

    /// The 1-D factor along `s` or `t` (the filter is `f(s)·f(t)` inside the box).
    #[inline]
    pub fn factor(&self, x: f64) -> f64 {
        if x.abs() > 1.0 {
            return 0.0;
        }
        match *self {
            FilterKind::Box => 1.0,
            FilterKind::Bartlett => 1.0 - x.abs(),
            FilterKind::Gaussian { alpha } => (-alpha * x * x).exp(),
        }
    }

    /// The filter weight at local coordinates; 0 outside `[−1, 1]³`.
    #[inline]
    pub fn weight(&self, s: f64, t: f64, r: f64) -> f64 {
        if r.abs() > 1.0 {
            return 0.0;
        }
        self.factor(s) * self.factor(t)
    }

    /// Radial profile `w(ρ²)` for EWA (thesis Def 17), if the filter is radially symmetric in
    /// `(s, t)`: only the Gaussian, `exp(−α ρ²)`.
    pub fn radial_profile(&self) -> Option<impl Fn(f64) -> f64 + use<>> {
        match *self {
            FilterKind::Gaussian { alpha } => Some(move |r2: f64| (-alpha * r2).exp()),
            _ => None,
        }
    }

    /// Mean of `f(x)` over `[−1, 1]` (so the mean of `F` over the box is its square).
    pub fn mean_factor(&self) -> f64 {
        match *self {
            FilterKind::Box => 1.0,
            FilterKind::Bartlett => 0.5,
            FilterKind::Gaussian { .. } => {
                // Composite 5-point Gauss on [0, 1] (smooth integrand): far below 1e-12.
                crate::quadrature::composite_gauss_1d(&|x| self.factor(x), 0.0, 1.0, 32, 5)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filter_means() {
        // ∫_0^1 e^{-2x²} dx = √(π/8)·erf(√2) with erf(√2) = 0.954499736103642.
        let g = FilterKind::Gaussian { alpha: 2.0 };
        let exact = (std::f64::consts::PI / 8.0).sqrt() * 0.954_499_736_103_642;
        assert!((g.mean_factor() - exact).abs() < 1e-12);
        assert_eq!(FilterKind::Bartlett.weight(0.5, -0.5, 0.0), 0.25);
        assert_eq!(FilterKind::Box.weight(0.5, 0.5, 1.5), 0.0);
        assert!(FilterKind::Box.radial_profile().is_none());
        let p = g.radial_profile().unwrap();
        assert!((p(0.25) - g.weight(0.5, 0.0, 0.0)).abs() < 1e-15);
    }
}
