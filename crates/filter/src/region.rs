//! Integration regions in texture space: oriented boxes and tangent-plane ellipses.
//!
//! All quantities are in *texture space* (the space in which a [`crate::texture::SolidTexture`]
//! is evaluated; the scenes of [`crate::scene`] are modelled directly in it, so one texture unit
//! is one world unit).

use glam::DVec3;

/// A rectangular parallelepiped `{ c + s·a₀ + t·a₁ + r·a₂ : s, t, r ∈ [−1, 1] }` (thesis §4-2,
/// Figs 4.12/4.13).
///
/// `axes` are the *half-extent* vectors (texture units), mutually orthogonal. The local
/// coordinates `(s, t, r) ∈ [−1, 1]³` are the frame in which the filters of
/// [`crate::filters`] are defined. For the tangent-plane box `V_tan`, `a₀`/`a₁` lie in the
/// tangent plane (major/minor ellipse axes) and `a₂` is the normal (`|a₂| = ε/2`); for the
/// ray-aligned box `V_ray`, `a₂` points along the ray into the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrientedBox {
    /// Centre, texture units.
    pub center: DVec3,
    /// Half-extent vectors, texture units; mutually orthogonal (a zero vector is allowed and
    /// makes the box flat along that axis).
    pub axes: [DVec3; 3],
}

impl OrientedBox {
    /// An axis-aligned box from its lower and upper corners (texture units).
    pub fn axis_aligned(lo: DVec3, hi: DVec3) -> Self {
        let h = (hi - lo) * 0.5;
        OrientedBox {
            center: (lo + hi) * 0.5,
            axes: [
                DVec3::new(h.x, 0.0, 0.0),
                DVec3::new(0.0, h.y, 0.0),
                DVec3::new(0.0, 0.0, h.z),
            ],
        }
    }

    /// The texture-space point at local coordinates `(s, t, r) ∈ [−1, 1]³`.
    #[inline]
    pub fn point(&self, s: f64, t: f64, r: f64) -> DVec3 {
        self.center + self.axes[0] * s + self.axes[1] * t + self.axes[2] * r
    }

    /// Local coordinates `(s, t, r)` of a texture-space point (inverse of [`Self::point`]);
    /// flat axes give 0.
    #[inline]
    pub fn local(&self, p: DVec3) -> DVec3 {
        let d = p - self.center;
        let c = |a: DVec3| {
            let l2 = a.length_squared();
            if l2 > 0.0 { d.dot(a) / l2 } else { 0.0 }
        };
        DVec3::new(c(self.axes[0]), c(self.axes[1]), c(self.axes[2]))
    }

    /// Volume in texture units³ (`8·|a₀||a₁||a₂|`).
    pub fn volume(&self) -> f64 {
        8.0 * self.axes[0].length() * self.axes[1].length() * self.axes[2].length()
    }

    /// Axis-aligned bounding box `(lo, hi)`, texture units.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let e = self.axes[0].abs() + self.axes[1].abs() + self.axes[2].abs();
        (self.center - e, self.center + e)
    }

    /// Largest half-extent, texture units.
    pub fn max_half_extent(&self) -> f64 {
        self.axes.iter().map(|a| a.length()).fold(0.0, f64::max)
    }
}

/// The projection of a circular pixel onto a tangent plane (thesis §4-2, §4-3): an ellipse
/// `{ c + x·a₀ + y·a₁ : x² + y² ≤ 1 }`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipse {
    /// Centre of the ellipse (texture units). Under perspective this is *not* the point hit by
    /// the pixel's central ray (thesis Fig 4.15).
    pub center: DVec3,
    /// Semi-axis vectors in the tangent plane, texture units: `axes[0]` is the major axis.
    pub axes: [DVec3; 2],
    /// Unit surface normal of the tangent plane.
    pub normal: DVec3,
}

impl Ellipse {
    /// Length of the major semi-axis, texture units.
    pub fn major(&self) -> f64 {
        self.axes[0].length()
    }

    /// Length of the minor semi-axis, texture units.
    pub fn minor(&self) -> f64 {
        self.axes[1].length()
    }

    /// Area, texture units² (`π·a·b`).
    pub fn area(&self) -> f64 {
        std::f64::consts::PI * self.major() * self.minor()
    }
}
