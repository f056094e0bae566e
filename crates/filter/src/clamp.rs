//! Clamping: attenuating texture frequency components that would alias (thesis §4-1, §5-3;
//! Fig 4.11; Plates 5.2, 5.3; Table 5.1).
//!
//! A component of frequency vector `f` (cycles per texture unit) seen through a footprint with
//! half-axis vectors `a_q` (the `V_tan` box of [`crate::scene`]) has the dimensionless
//! *footprint frequency* `φ = sqrt(Σ_q (f·a_q)²)` (decision A-7): the number of cycles across
//! one half-width of the footprint, combined over its axes. The clamp factor `C(φ)` multiplies
//! the component; components with `C = 0` are skipped (thesis §5-3).

use crate::error::{Result, check_positive};
use crate::region::OrientedBox;
use crate::texture::SolidTexture;

/// `√6 / (2π)`: where Norton et al.'s two-term sinc approximation reaches zero.
pub const NORTON_PHI_MAX: f64 = 0.389_848_400_616_1;

/// The clamp function (thesis §4-1, Fig 4.11).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ClampKind {
    /// Perlin's step: `C = 1` if `φ < φ_max`, else 0 (Plate 5.2).
    Step,
    /// The thesis's quadratic: `C = max(0, 1 − (φ/φ_max)²)` (Plate 5.3).
    Quadratic,
    /// Norton, Rockwood & Skolmoski's box clamp extended to three footprint axes (thesis §4-1):
    /// `C = max(0, 1 − Σ_q (2π f·a_q)²/6)`, i.e. the quadratic with `φ_max = √6/(2π)`
    /// (the printed condition "< 1" and missing "+" are corrected, A-13). Ignores
    /// [`ClampSettings::phi_max`].
    Norton,
}

/// Clamp configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClampSettings {
    /// Which clamp function.
    pub kind: ClampKind,
    /// Largest footprint frequency `φ_max` (cycles per footprint half-width, > 0). The default
    /// 0.25 is Perlin's "maximum allowable frequency": the Nyquist frequency when one sample is
    /// taken per footprint diameter `2a` (`f = 1/(4a)`). (The box filter's first zero is at 0.5.)
    pub phi_max: f64,
}

impl Default for ClampSettings {
    fn default() -> Self {
        ClampSettings {
            kind: ClampKind::Step,
            phi_max: 0.25,
        }
    }
}

impl ClampSettings {
    /// Validates `phi_max`.
    pub fn validate(&self) -> Result<()> {
        check_positive("phi_max", self.phi_max)
    }

    /// The clamp factor `C(φ)` for footprint frequency `φ ≥ 0`, in `[0, 1]`.
    #[inline]
    pub fn factor(&self, phi: f64) -> f64 {
        match self.kind {
            ClampKind::Step => {
                if phi < self.phi_max {
                    1.0
                } else {
                    0.0
                }
            }
            ClampKind::Quadratic => (1.0 - (phi / self.phi_max).powi(2)).max(0.0),
            ClampKind::Norton => (1.0 - (phi / NORTON_PHI_MAX).powi(2)).max(0.0),
        }
    }
}

/// The clamped texture at the centre of a footprint box (its half-axes set `φ`).
pub fn clamped_sample(
    texture: &dyn SolidTexture,
    footprint: &OrientedBox,
    clamp: &ClampSettings,
) -> Result<f64> {
    texture.clamped_value(footprint.center, &footprint.axes, clamp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_clamp_values_f_b06() {
        let c = ClampSettings {
            kind: ClampKind::Quadratic,
            phi_max: 3.2,
        };
        assert_eq!(c.factor(0.0), 1.0);
        assert_eq!(c.factor(3.2), 0.0);
        assert!((c.factor(1.6) - 0.75).abs() < 1e-15);
        assert_eq!(c.factor(10.0), 0.0);
        let s = ClampSettings {
            kind: ClampKind::Step,
            phi_max: 3.2,
        };
        assert_eq!(s.factor(3.19), 1.0);
        assert_eq!(s.factor(3.2), 0.0);
        assert!((NORTON_PHI_MAX - 6f64.sqrt() / std::f64::consts::TAU).abs() < 1e-12);
    }

    #[test]
    fn norton_matches_box_for_small_footprints_f_b07() {
        use crate::texture::sinc;
        // For one plane wave the box average is sinc(2πφ) per axis; Norton is its 2-term series.
        let c = ClampSettings {
            kind: ClampKind::Norton,
            phi_max: 1.0,
        };
        for phi in [0.001, 0.01, 0.03] {
            let exact = sinc(std::f64::consts::TAU * phi);
            let err = (c.factor(phi) - exact).abs();
            assert!(err < 30.0 * phi.powi(4), "φ={phi}: {err}");
        }
    }
}
