//! Analytic phantoms: test volumes defined by formulas, with closed-form line integrals where
//! they exist. They are the CLI's built-in demo data and the ground truth of oracle tests.
//!
//! - [`Phantom`]: the interface: a density at any world point, the exact integral along a line,
//!   and a world box containing the support.
//! - [`GaussianBlobs`]: a sum of isotropic 3-D Gaussians (smooth; closed-form line integrals).
//! - [`EllipsoidPhantom`]: a sum of constant-density ellipsoids over a background constant
//!   (closed-form line integrals), with the 3-D modified Shepp–Logan phantom
//!   ([`EllipsoidPhantom::shepp_logan_3d`]) and a CT-like head in Hounsfield units
//!   ([`EllipsoidPhantom::ct_head`]).
//! - [`MarschnerLobb`]: the Marschner–Lobb test signal (no closed-form line integral).
//! - [`sample`], [`sample_on_grid`], [`ct_head_volume`]: turning a phantom into a [`Volume`].
//!
//! All coordinates are world coordinates (docs/design.md §3); densities are in the phantom's data
//! units, line integrals in data units × world units.

use crate::error::{CoreError, Result};
use crate::volume::{Grid, Volume};
use glam::{DMat3, DVec3};

/// An analytic volume: a scalar field over world space.
pub trait Phantom: Sync {
    /// The density at world point `p` (world units), in data units.
    fn density(&self, p: DVec3) -> f64;

    /// The exact integral `∫ density(origin + t·dir) dt` over all real `t` (origin in world
    /// units, `dir` a world direction; for a unit `dir` this is the integral over path length
    /// in data units × world units). `None` when the phantom has no closed form, or when `dir`
    /// is zero or not finite. Phantoms with a background constant integrate
    /// `density − background` (see [`EllipsoidPhantom`]).
    fn line_integral(&self, origin: DVec3, dir: DVec3) -> Option<f64>;

    /// A world-space box `(lo, hi)` (world units) containing the support of the phantom (for
    /// phantoms of unbounded support, the region where it is significant; see each type).
    fn bounds(&self) -> (DVec3, DVec3);

    /// Densities at the evenly spaced world points `start + n·step`, `n = 0 .. out.len()`
    /// (world units), written to `out` in data units. Equivalent to calling
    /// [`Phantom::density`] at each point; phantoms override it with faster row evaluation
    /// (used by [`sample_on_grid`]).
    fn density_row(&self, start: DVec3, step: DVec3, out: &mut [f64]) {
        for (n, v) in out.iter_mut().enumerate() {
            *v = self.density(start + step * n as f64);
        }
    }
}

fn valid_direction(dir: DVec3) -> bool {
    dir.is_finite() && dir.length_squared() > 0.0
}

// ---------------------------------------------------------------------------------------------
// Gaussian blobs
// ---------------------------------------------------------------------------------------------

/// One isotropic Gaussian: `amplitude · exp(−|p − center|² / (2σ²))`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blob {
    /// Centre, world coordinates (world units).
    pub center: DVec3,
    /// Standard deviation σ in world units (> 0).
    pub sigma: f64,
    /// Peak density at the centre, data units.
    pub amplitude: f64,
}

/// A sum of isotropic 3-D Gaussians. Smooth, band-limited in practice, and with closed-form
/// line integrals: the X-ray oracle for the splatting renderer.
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianBlobs {
    /// The Gaussians; their densities add.
    pub blobs: Vec<Blob>,
    /// The world box reported by [`Phantom::bounds`] (world units). A Gaussian has unbounded
    /// support; [`GaussianBlobs::new`] uses every blob's `center ± 4σ` (where the density has
    /// fallen to `e⁻⁸ ≈ 3.4·10⁻⁴` of the peak).
    pub bounds: (DVec3, DVec3),
}

impl GaussianBlobs {
    /// Blobs with bounds `center ± 4σ` around every blob (an empty list gives `[-1, 1]³`).
    pub fn new(blobs: Vec<Blob>) -> Self {
        let mut lo = DVec3::INFINITY;
        let mut hi = DVec3::NEG_INFINITY;
        for b in &blobs {
            let r = DVec3::splat(4.0 * b.sigma.abs());
            lo = lo.min(b.center - r);
            hi = hi.max(b.center + r);
        }
        if !(lo.is_finite() && hi.is_finite()) {
            lo = DVec3::splat(-1.0);
            hi = DVec3::splat(1.0);
        }
        GaussianBlobs {
            blobs,
            bounds: (lo, hi),
        }
    }

    /// The demo phantom: six blobs of different sizes (σ from 0.15 to 0.35) and amplitudes
    /// (0.5 to 1.0) in the box `[-1, 1]³` (world units), which is its [`Phantom::bounds`]. Every
    /// blob's `center ± σ` lies within `[-0.75, 0.75]³`; the density on the box faces is below
    /// 3 % of the largest amplitude (the field is truncated there when sampled).
    pub fn demo() -> Self {
        let b = |x: f64, y: f64, z: f64, sigma: f64, amplitude: f64| Blob {
            center: DVec3::new(x, y, z),
            sigma,
            amplitude,
        };
        GaussianBlobs {
            blobs: vec![
                b(0.00, 0.00, 0.00, 0.35, 0.5),
                b(0.40, 0.25, 0.10, 0.20, 0.8),
                b(-0.40, 0.30, -0.15, 0.22, 0.7),
                b(0.20, -0.50, 0.35, 0.15, 1.0),
                b(-0.30, -0.40, 0.45, 0.18, 0.9),
                b(0.30, 0.10, -0.30, 0.26, 0.6),
            ],
            bounds: (DVec3::splat(-1.0), DVec3::splat(1.0)),
        }
    }
}

impl Phantom for GaussianBlobs {
    fn density(&self, p: DVec3) -> f64 {
        self.blobs
            .iter()
            .map(|b| {
                let r2 = (p - b.center).length_squared();
                b.amplitude * (-r2 / (2.0 * b.sigma * b.sigma)).exp()
            })
            .sum()
    }

    /// Closed form: for a unit direction, `∫ A·exp(−|p(t) − c|²/2σ²) dt = A·σ·√(2π)·exp(−d²/2σ²)`
    /// with `d` the distance from the centre to the line (the Gaussian integral
    /// `∫ exp(−t²/2σ²) dt = σ√(2π)` along the line, times the perpendicular factor); a
    /// non-unit `dir` divides by `|dir|`.
    fn line_integral(&self, origin: DVec3, dir: DVec3) -> Option<f64> {
        if !valid_direction(dir) || !origin.is_finite() {
            return None;
        }
        let len = dir.length();
        let u = dir / len;
        let root_two_pi = (2.0 * std::f64::consts::PI).sqrt();
        Some(
            self.blobs
                .iter()
                .map(|b| {
                    let v = origin - b.center;
                    let perp = v - u * v.dot(u);
                    let d2 = perp.length_squared();
                    b.amplitude * b.sigma * root_two_pi * (-d2 / (2.0 * b.sigma * b.sigma)).exp()
                        / len
                })
                .sum(),
        )
    }

    fn bounds(&self) -> (DVec3, DVec3) {
        self.bounds
    }
}

// ---------------------------------------------------------------------------------------------
// Ellipsoids
// ---------------------------------------------------------------------------------------------

/// A solid ellipsoid of constant (additive) density.
///
/// A world point `p` is inside when `|diag(1/semi_axes) · rotationᵀ · (p − center)| ≤ 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    /// Centre, world coordinates (world units).
    pub center: DVec3,
    /// Semi-axis lengths along the ellipsoid's own axes, world units (each > 0).
    pub semi_axes: DVec3,
    /// Orientation: column `c` is the world direction of the ellipsoid's axis `c` (a rotation).
    pub rotation: DMat3,
    /// Density added inside the ellipsoid, data units (may be negative).
    pub density: f64,
}

impl Ellipsoid {
    /// An ellipsoid whose axes are the world axes.
    pub fn axis_aligned(center: DVec3, semi_axes: DVec3, density: f64) -> Self {
        Ellipsoid {
            center,
            semi_axes,
            rotation: DMat3::IDENTITY,
            density,
        }
    }

    /// The linear map from world displacements to the unit-sphere frame:
    /// `diag(1/semi_axes) · rotationᵀ`.
    fn sphere_from_world(&self) -> DMat3 {
        DMat3::from_diagonal(self.semi_axes.recip()) * self.rotation.transpose()
    }

    /// Whether world point `p` lies inside or on the ellipsoid.
    pub fn contains(&self, p: DVec3) -> bool {
        (self.sphere_from_world() * (p - self.center)).length_squared() <= 1.0
    }

    /// The parameter interval `[t0, t1]` where the line `origin + t·dir` (world units) is
    /// inside the ellipsoid, or `None` if it misses (or only touches). Solves the quadratic
    /// `|o' + t·d'|² = 1` in the unit-sphere frame via the closest approach to the centre,
    /// `t* = −o'·d'/|d'|²`, half-width `√((1 − |o' + t*·d'|²)/|d'|²)`.
    pub fn chord(&self, origin: DVec3, dir: DVec3) -> Option<(f64, f64)> {
        let m = self.sphere_from_world();
        let o = m * (origin - self.center);
        let d = m * dir;
        let a = d.length_squared();
        if !(a > 0.0 && a.is_finite()) {
            return None;
        }
        let t_mid = -o.dot(d) / a;
        let closest = o + d * t_mid;
        let h2 = (1.0 - closest.length_squared()) / a;
        if h2 > 0.0 {
            let h = h2.sqrt();
            Some((t_mid - h, t_mid + h))
        } else {
            None
        }
    }

    /// World-axis-aligned box `(lo, hi)` (world units) enclosing the ellipsoid: half extent
    /// along world axis `i` is `√(Σ_j (R_ij·s_j)²)`.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let r = self.rotation;
        let s = self.semi_axes;
        let half = DVec3::new(
            DVec3::new(r.x_axis.x * s.x, r.y_axis.x * s.y, r.z_axis.x * s.z).length(),
            DVec3::new(r.x_axis.y * s.x, r.y_axis.y * s.y, r.z_axis.y * s.z).length(),
            DVec3::new(r.x_axis.z * s.x, r.y_axis.z * s.y, r.z_axis.z * s.z).length(),
        );
        (self.center - half, self.center + half)
    }
}

/// A sum of constant-density ellipsoids over a background constant:
/// `density(p) = background + Σ { e.density : e contains p }`.
///
/// [`Phantom::line_integral`] returns the integral of `density − background`, i.e.
/// `Σ e.density × chord length` (the background would integrate to infinity), in data units ×
/// world units for a unit direction.
#[derive(Debug, Clone, PartialEq)]
pub struct EllipsoidPhantom {
    /// The ellipsoids; densities of overlapping ellipsoids add.
    pub ellipsoids: Vec<Ellipsoid>,
    /// Density outside every ellipsoid, data units (0 for Shepp–Logan, −1000 HU of air for the
    /// CT head). Not included in line integrals.
    pub background: f64,
    /// The world box (world units) reported by [`Phantom::bounds`]; it must contain every
    /// ellipsoid.
    pub bounds: (DVec3, DVec3),
}

impl EllipsoidPhantom {
    /// A phantom whose bounds are the smallest box enclosing every ellipsoid.
    pub fn new(ellipsoids: Vec<Ellipsoid>, background: f64) -> Self {
        let mut lo = DVec3::INFINITY;
        let mut hi = DVec3::NEG_INFINITY;
        for e in &ellipsoids {
            let (a, b) = e.bounds();
            lo = lo.min(a);
            hi = hi.max(b);
        }
        if !(lo.is_finite() && hi.is_finite()) {
            lo = DVec3::splat(-1.0);
            hi = DVec3::splat(1.0);
        }
        EllipsoidPhantom {
            ellipsoids,
            background,
            bounds: (lo, hi),
        }
    }

    /// Checks that every number is finite, every semi-axis positive and every rotation
    /// orthonormal (to 1e-6); errors name the ellipsoid.
    pub fn validate(&self) -> Result<()> {
        if !self.background.is_finite() {
            return Err(CoreError::invalid(
                "background",
                self.background,
                "must be finite",
            ));
        }
        for (n, e) in self.ellipsoids.iter().enumerate() {
            if !(e.center.is_finite() && e.density.is_finite()) {
                return Err(CoreError::invalid(
                    format!("ellipsoid[{n}]"),
                    e,
                    "centre and density must be finite",
                ));
            }
            if !(e.semi_axes.is_finite() && e.semi_axes.min_element() > 0.0) {
                return Err(CoreError::invalid(
                    format!("ellipsoid[{n}].semi_axes"),
                    e.semi_axes,
                    "must be positive finite lengths",
                ));
            }
            let gram = e.rotation.transpose() * e.rotation;
            let err = (gram - DMat3::IDENTITY)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            if !e.rotation.is_finite() || err >= 1e-6 {
                return Err(CoreError::invalid(
                    format!("ellipsoid[{n}].rotation"),
                    e.rotation.to_cols_array_2d(),
                    "must be orthonormal",
                ));
            }
        }
        Ok(())
    }

    /// The 3-D modified Shepp–Logan head phantom in `[-1, 1]³` (world units, background 0).
    ///
    /// Geometry: the ten ellipsoids of the 3-D head phantom of Kak & Slaney, *Principles of
    /// Computerized Tomographic Imaging* (1988), §3.2, p. 102 (with the book's errata),
    /// each rotated by φ about the z axis (its first semi-axis along `(cos φ, sin φ, 0)`).
    /// Densities: the "modified" high-contrast values (Toft 1996, as extended to 3-D by Yu, Ye &
    /// Wang, SPIE 5535, 2004): 1.0, −0.8, −0.2, −0.2, 0.2, 0.2, 0.1, 0.1, 0.2, −0.2, instead of
    /// the original 2.0, −0.98, −0.02, … . The density at the centre is `1.0 − 0.8 = 0.2`
    /// ([`SHEPP_LOGAN_CENTER_DENSITY`]); values lie in [0, 1].
    pub fn shepp_logan_3d() -> Self {
        // a, b, c, x0, y0, z0, φ (degrees), density
        const TABLE: [[f64; 8]; 10] = [
            [0.6900, 0.920, 0.900, 0.00, 0.000, 0.000, 0.0, 1.0],
            [0.6624, 0.874, 0.880, 0.00, 0.000, 0.000, 0.0, -0.8],
            [0.4100, 0.160, 0.210, -0.22, 0.000, -0.250, 108.0, -0.2],
            [0.3100, 0.110, 0.220, 0.22, 0.000, -0.250, 72.0, -0.2],
            [0.2100, 0.250, 0.500, 0.00, 0.350, -0.250, 0.0, 0.2],
            [0.0460, 0.046, 0.046, 0.00, 0.100, -0.250, 0.0, 0.2],
            [0.0460, 0.023, 0.020, -0.08, -0.650, -0.250, 0.0, 0.1],
            [0.0460, 0.023, 0.020, 0.06, -0.650, -0.250, 90.0, 0.1],
            [0.0560, 0.040, 0.100, 0.06, -0.105, 0.625, 90.0, 0.2],
            [0.0560, 0.056, 0.100, 0.00, 0.100, 0.625, 0.0, -0.2],
        ];
        let ellipsoids = TABLE
            .iter()
            .map(|r| Ellipsoid {
                center: DVec3::new(r[3], r[4], r[5]),
                semi_axes: DVec3::new(r[0], r[1], r[2]),
                rotation: DMat3::from_rotation_z(r[6].to_radians()),
                density: r[7],
            })
            .collect();
        EllipsoidPhantom {
            ellipsoids,
            background: 0.0,
            bounds: (DVec3::splat(-1.0), DVec3::splat(1.0)),
        }
    }

    /// A CT-like head in Hounsfield units (HU) and millimetres, of this project's own design.
    ///
    /// Orientation (patient frame = world frame): +x is the head's left-right axis, +y is
    /// superior (top of the head), +z is anterior (the face looks towards +z), so VTK's default
    /// camera (looking down −z with +y up) sees the face. The head is about 156 × 196 × 176 mm
    /// (x × y × z) around the origin; [`Phantom::bounds`] is `[-90, 90] × [-110, 110] ×
    /// [-100, 100]` mm. Values (the ellipsoid densities add over the −1000 HU background):
    ///
    /// | structure | HU | geometry: centre; semi-axes (mm) |
    /// |---|---|---|
    /// | air (background) | −1000 | |
    /// | scalp, face, soft tissue | 40 | (0, 0, 0); (78, 98, 88) |
    /// | skull vault (shell between two ellipsoids, 7 mm) | 1000 | (0, 18, −8); outer (70, 68, 75), inner (63, 61, 68) |
    /// | brain | 35 | inside the inner skull ellipsoid |
    /// | lateral ventricles | 5 | (±9, 24, −10); (5, 9, 24) |
    /// | orbital fat | −90 | (±31, 2, 65); (14, 13, 13) |
    /// | eyes (vitreous) | 10 | (±31, 2, 66.5); radius 11 |
    /// | nose: soft-tissue shell over an air cavity | 40 / −1000 | nose ≈ (0, −15, 85); (11.7, 14.7, 13.2), tip at z ≈ 98 |
    /// | mandible: chin, two bodies, two rami | 1000 (1960 where pieces overlap) | chin (0, −70, 46); (20, 8, 8) |
    ///
    /// Where the orbits reach into the skull the bone reads 870 HU (970 HU with the eye). No
    /// value lies below −1000 HU; the unit test `ct_head_takes_only_intended_values` checks
    /// that only these values occur.
    pub fn ct_head() -> Self {
        let v = DVec3::new;
        let aa = Ellipsoid::axis_aligned;
        let soft = 1040.0; // air −1000 → soft tissue +40
        let bone = 960.0; // soft tissue +40 → bone +1000
        let skull_c = v(0.0, 18.0, -8.0);
        let envelope = v(78.0, 98.0, 88.0);
        let (nose, cavity) = nose_and_cavity(envelope, soft);
        let mut e = vec![
            // Scalp and soft tissue envelope: 40 HU.
            aa(DVec3::ZERO, envelope, soft),
            // Skull: outer ellipsoid adds bone, inner removes it again and leaves brain (35 HU).
            aa(skull_c, v(70.0, 68.0, 75.0), bone),
            aa(skull_c, v(63.0, 61.0, 68.0), -965.0),
            // Nose (soft tissue) and nasal cavity (air): see `nose_and_cavity`.
            nose,
            cavity,
            // Mandible: chin.
            aa(v(0.0, -70.0, 46.0), v(20.0, 8.0, 8.0), bone),
        ];
        for side in [-1.0f64, 1.0] {
            // Lateral ventricles: 5 HU in 35 HU brain.
            e.push(aa(v(9.0 * side, 24.0, -10.0), v(5.0, 9.0, 24.0), -30.0));
            // Orbital fat (−90 HU) and the eye (10 HU) inside it.
            e.push(aa(v(31.0 * side, 2.0, 65.0), v(14.0, 13.0, 13.0), -130.0));
            e.push(aa(v(31.0 * side, 2.0, 66.5), DVec3::splat(11.0), 100.0));
            // Mandible bodies, running from the chin back and out to the angle of the jaw.
            e.push(Ellipsoid {
                center: v(30.0 * side, -66.0, 20.0),
                semi_axes: v(6.0, 8.0, 30.0),
                rotation: DMat3::from_rotation_y((-40.0f64 * side).to_radians()),
                density: bone,
            });
            // Mandible rami, rising from the angle towards the skull base.
            e.push(aa(v(46.0 * side, -48.0, -6.0), v(5.0, 17.0, 9.0), bone));
        }
        EllipsoidPhantom {
            ellipsoids: e,
            background: -1000.0,
            bounds: (v(-90.0, -110.0, -100.0), v(90.0, 110.0, 100.0)),
        }
    }
}

/// The nose and nasal cavity of [`EllipsoidPhantom::ct_head`], built so that additive densities
/// leave no stray values where they meet the soft-tissue envelope `E` (semi-axes `envelope`,
/// centred at the origin, density `soft`).
///
/// In coordinates scaled by `1/envelope` the envelope is the unit sphere; the nose `N` and the
/// cavity `P` are spheres too (ellipsoids with the envelope's axis ratios in world), centred on
/// one ray `n̂` at distances `d` and `p` with radii `s` and `r`. Two such spheres meet on a
/// circle in the plane `x·n̂ = h`, `h = (1 + d² − s²)/(2d)`, radius `ρ = √(1 − h²)`; choosing
/// `r = √((h − p)² + ρ²)` puts P's surface through the same circle. With `0 < p < d`, P
/// contains `N ∩ E` and `P \ E ⊂ N`, so `E + N − P` takes only the values 0 (air), 1 (tissue):
/// the nose is a tissue shell outside the face, the cavity is air.
fn nose_and_cavity(envelope: DVec3, soft: f64) -> (Ellipsoid, Ellipsoid) {
    let n = DVec3::new(0.0, -0.156, 0.988).normalize(); // anterior, slightly inferior
    let (d, s, p): (f64, f64, f64) = (0.98, 0.15, 0.90);
    let h = (1.0 + d * d - s * s) / (2.0 * d);
    let r = ((h - p).powi(2) + (1.0 - h * h)).sqrt();
    (
        Ellipsoid::axis_aligned(envelope * n * d, envelope * s, soft),
        Ellipsoid::axis_aligned(envelope * n * p, envelope * r, -soft),
    )
}

/// The density of [`EllipsoidPhantom::shepp_logan_3d`] at the origin (data units).
pub const SHEPP_LOGAN_CENTER_DENSITY: f64 = 0.2;

impl Phantom for EllipsoidPhantom {
    fn density(&self, p: DVec3) -> f64 {
        self.background
            + self
                .ellipsoids
                .iter()
                .filter(|e| e.contains(p))
                .map(|e| e.density)
                .sum::<f64>()
    }

    /// `Σ e.density × chord length` (Kak & Slaney 1988, §3.1, the projection of an ellipse,
    /// generalised to ellipsoids); the background is not included.
    fn line_integral(&self, origin: DVec3, dir: DVec3) -> Option<f64> {
        if !valid_direction(dir) || !origin.is_finite() {
            return None;
        }
        Some(
            self.ellipsoids
                .iter()
                .filter_map(|e| e.chord(origin, dir).map(|(t0, t1)| e.density * (t1 - t0)))
                .sum(),
        )
    }

    fn bounds(&self) -> (DVec3, DVec3) {
        self.bounds
    }

    /// Row evaluation by chords: each ellipsoid covers an interval of the row, found with
    /// [`Ellipsoid::chord`]. Agrees with [`Phantom::density`] except possibly for points within
    /// rounding error of an ellipsoid's surface.
    fn density_row(&self, start: DVec3, step: DVec3, out: &mut [f64]) {
        out.fill(self.background);
        let n = out.len();
        if n == 0 {
            return;
        }
        if !valid_direction(step) {
            let v = self.density(start);
            out.fill(v);
            return;
        }
        for e in &self.ellipsoids {
            let Some((t0, t1)) = e.chord(start, step) else {
                continue;
            };
            let first = t0.ceil().max(0.0);
            let last = t1.floor().min((n - 1) as f64);
            if first.is_nan() || last.is_nan() || first > last {
                continue;
            }
            for v in &mut out[first as usize..=last as usize] {
                *v += e.density;
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Marschner–Lobb
// ---------------------------------------------------------------------------------------------

/// The Marschner–Lobb test signal on `[-1, 1]³` (world units; values in [0, 1]):
///
/// ```text
/// ρ(r) = cos(2π f_M cos(π r / 2))
/// density(x, y, z) = (1 − sin(π z / 2) + α (1 + ρ(√(x² + y²)))) / (2 (1 + α))
/// ```
///
/// (Marschner & Lobb, "An evaluation of reconstruction filters for volume rendering",
/// Proc. IEEE Visualization '94, §4, eq. 1.) It has no closed-form line integral.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarschnerLobb {
    /// Frequency `f_M` of the radial oscillation (cycles; the paper uses 6).
    pub f_m: f64,
    /// Amplitude `α` of the radial oscillation (the paper uses 0.25).
    pub alpha: f64,
}

impl Default for MarschnerLobb {
    /// The paper's parameters: `f_M = 6`, `α = 0.25`.
    fn default() -> Self {
        MarschnerLobb {
            f_m: 6.0,
            alpha: 0.25,
        }
    }
}

impl Phantom for MarschnerLobb {
    fn density(&self, p: DVec3) -> f64 {
        use std::f64::consts::PI;
        let r = (p.x * p.x + p.y * p.y).sqrt();
        let rho = (2.0 * PI * self.f_m * (PI * r / 2.0).cos()).cos();
        (1.0 - (PI * p.z / 2.0).sin() + self.alpha * (1.0 + rho)) / (2.0 * (1.0 + self.alpha))
    }

    fn line_integral(&self, _origin: DVec3, _dir: DVec3) -> Option<f64> {
        None
    }

    fn bounds(&self) -> (DVec3, DVec3) {
        (DVec3::splat(-1.0), DVec3::splat(1.0))
    }
}

// ---------------------------------------------------------------------------------------------
// Built-in phantoms by name
// ---------------------------------------------------------------------------------------------

/// Names accepted by [`builtin`].
pub const BUILTIN_NAMES: &[&str] = &["shepp-logan", "ct-head", "marschner-lobb", "blobs"];

/// A built-in phantom by name: `shepp-logan` ([`EllipsoidPhantom::shepp_logan_3d`]), `ct-head`
/// ([`EllipsoidPhantom::ct_head`]), `marschner-lobb` ([`MarschnerLobb::default`]) or `blobs`
/// ([`GaussianBlobs::demo`]).
pub fn builtin(name: &str) -> Result<Box<dyn Phantom>> {
    Ok(match name.trim().to_ascii_lowercase().as_str() {
        "shepp-logan" | "shepp_logan" => Box::new(EllipsoidPhantom::shepp_logan_3d()),
        "ct-head" | "ct_head" | "head" => Box::new(EllipsoidPhantom::ct_head()),
        "marschner-lobb" | "marschner_lobb" | "ml" => Box::new(MarschnerLobb::default()),
        "blobs" | "gaussian-blobs" => Box::new(GaussianBlobs::demo()),
        _ => {
            return Err(CoreError::UnknownName {
                kind: "phantom".into(),
                name: name.into(),
                known: BUILTIN_NAMES.join(", "),
            });
        }
    })
}

// ---------------------------------------------------------------------------------------------
// Sampling
// ---------------------------------------------------------------------------------------------

/// Largest per-axis supersampling factor accepted by [`sample_on_grid`].
pub const MAX_SUPERSAMPLE: usize = 16;

/// The grid whose voxel centres span `bounds` exactly: per axis, spacing
/// `(hi − lo)/(dims − 1)` world units and origin `lo`, identity direction. An axis with a single
/// sample gets spacing 1 and its sample at the middle of the bounds.
///
/// Errors if a dimension is zero, the voxel count is too large, or the bounds are not finite
/// with `hi > lo` on every axis that has more than one sample.
pub fn grid_spanning(bounds: (DVec3, DVec3), dims: [usize; 3]) -> Result<Grid> {
    let (lo, hi) = bounds;
    if !(lo.is_finite() && hi.is_finite()) {
        return Err(CoreError::invalid(
            "bounds",
            bounds,
            "must be finite world coordinates",
        ));
    }
    let mut spacing = [1.0; 3];
    let mut origin = [0.0; 3];
    for a in 0..3 {
        if dims[a] == 1 {
            origin[a] = 0.5 * (lo[a] + hi[a]);
        } else {
            spacing[a] = (hi[a] - lo[a]) / (dims[a].max(2) - 1) as f64;
            origin[a] = lo[a];
        }
    }
    Grid::new(dims, spacing, origin, DMat3::IDENTITY)
}

/// Samples a phantom on the grid spanning its bounds ([`grid_spanning`]), averaging
/// `supersample³` points per voxel cell (see [`sample_on_grid`]). Values in the phantom's data
/// units.
pub fn sample<P: Phantom + ?Sized>(
    p: &P,
    dims: [usize; 3],
    supersample: usize,
) -> Result<Volume<f32>> {
    let grid = grid_spanning(p.bounds(), dims)?;
    sample_on_grid(p, &grid, supersample)
}

/// Samples a phantom on an arbitrary grid. With `supersample = n > 1`, each voxel's value is the
/// mean of the density at `n³` points evenly spread over its cell (index offsets
/// `(m + ½)/n − ½`, `m = 0 … n−1`, per axis, mapped to world by the grid); `n = 1` samples the
/// voxel centres. Axes with a single sample are not supersampled (their cell is taken to be
/// flat). Single-threaded.
///
/// Errors if `supersample` is 0 or above [`MAX_SUPERSAMPLE`], or a density is not finite.
pub fn sample_on_grid<P: Phantom + ?Sized>(
    p: &P,
    grid: &Grid,
    supersample: usize,
) -> Result<Volume<f32>> {
    let data = sample_values(p, grid, supersample, |v| v as f32)?;
    Volume::new(grid.clone(), data)
}

/// Shared sampler: the voxel values (mean densities, f64) converted by `convert`, `i` fastest.
/// Errors on a bad `supersample`, a failed allocation or a non-finite density.
fn sample_values<P: Phantom + ?Sized, T>(
    p: &P,
    grid: &Grid,
    supersample: usize,
    convert: impl Fn(f64) -> T,
) -> Result<Vec<T>> {
    if !(1..=MAX_SUPERSAMPLE).contains(&supersample) {
        return Err(CoreError::invalid(
            "supersample",
            supersample,
            format!("must be between 1 and {MAX_SUPERSAMPLE}"),
        ));
    }
    let [nx, ny, nz] = grid.dims;
    let offsets = |a: usize| -> Vec<f64> {
        if grid.dims[a] == 1 {
            vec![0.0]
        } else {
            (0..supersample)
                .map(|m| (m as f64 + 0.5) / supersample as f64 - 0.5)
                .collect()
        }
    };
    let (ox, oy, oz) = (offsets(0), offsets(1), offsets(2));
    let weight = 1.0 / (ox.len() * oy.len() * oz.len()) as f64;
    let step = grid.world_from_index_linear().x_axis;
    let count = grid.voxel_count();
    let mut values = Vec::new();
    values
        .try_reserve_exact(count)
        .map_err(|_| CoreError::TooLarge {
            what: "sampled phantom (bytes)".into(),
            value: (count as u128) * std::mem::size_of::<T>() as u128,
            limit: isize::MAX as u128,
        })?;
    let mut row = vec![0.0f64; nx];
    let mut acc = vec![0.0f64; nx];
    for k in 0..nz {
        for j in 0..ny {
            acc.fill(0.0);
            for &dz in &oz {
                for &dy in &oy {
                    for &dx in &ox {
                        let start =
                            grid.world_from_index(DVec3::new(dx, j as f64 + dy, k as f64 + dz));
                        p.density_row(start, step, &mut row);
                        for (a, v) in acc.iter_mut().zip(&row) {
                            *a += v;
                        }
                    }
                }
            }
            for (i, a) in acc.iter().enumerate() {
                let v = a * weight;
                if !v.is_finite() {
                    return Err(CoreError::invalid(
                        format!("phantom density at voxel ({i}, {j}, {k})"),
                        v,
                        "must be finite",
                    ));
                }
                values.push(convert(v));
            }
        }
    }
    Ok(values)
}

/// The CT head ([`EllipsoidPhantom::ct_head`]) sampled over its bounds with 2³ supersampling
/// and rounded to whole Hounsfield units (clamped to the i16 range). World units mm.
pub fn ct_head_volume(dims: [usize; 3]) -> Result<Volume<i16>> {
    let head = EllipsoidPhantom::ct_head();
    let grid = grid_spanning(head.bounds(), dims)?;
    let mut data = sample_values(&head, &grid, 2, |v| v as f32)?;
    // A scanner's point-spread function: without it the hard ellipsoid edges terrace into
    // contour-line artefacts under any renderer (box-filtered supersampling alone is not
    // band-limited enough). σ = 0.7 voxel, about the in-plane resolution of clinical CT.
    gaussian_blur(&mut data, grid.dims, [0.7; 3]);
    let data = data
        .into_iter()
        .map(|v| v.round().clamp(i16::MIN as f32, i16::MAX as f32) as i16)
        .collect();
    Volume::new(grid, data)
}

/// Separable Gaussian blur of samples laid out `i` fastest on a `dims` grid, in place.
/// `sigma` per axis in voxels (0 skips an axis); the kernel is truncated at 3σ, normalised, and
/// the border is clamped (edge samples repeat).
pub fn gaussian_blur(data: &mut [f32], dims: [usize; 3], sigma: [f64; 3]) {
    let [nx, ny, nz] = dims;
    if data.len() != nx * ny * nz {
        return;
    }
    let strides = [1, nx, nx * ny];
    for axis in 0..3 {
        let s = sigma[axis];
        let n = dims[axis];
        if s <= 0.0 || n < 2 {
            continue;
        }
        let r = (3.0 * s).ceil() as isize;
        let mut k: Vec<f32> = (-r..=r)
            .map(|t| (-(t * t) as f64 / (2.0 * s * s)).exp() as f32)
            .collect();
        let sum: f32 = k.iter().sum();
        k.iter_mut().for_each(|v| *v /= sum);
        let stride = strides[axis];
        let mut line = vec![0f32; n];
        // Every line along `axis`: its start index runs over the other two axes.
        let (a, b) = match axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        for q in 0..dims[b] {
            for p in 0..dims[a] {
                let start = p * strides[a] + q * strides[b];
                for (t, l) in line.iter_mut().enumerate() {
                    *l = data[start + t * stride];
                }
                for t in 0..n as isize {
                    let mut acc = 0.0f32;
                    for (m, &w) in k.iter().enumerate() {
                        let u = (t + m as isize - r).clamp(0, n as isize - 1) as usize;
                        acc += w * line[u];
                    }
                    data[start + t as usize * stride] = acc;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaussian_blur_preserves_constants_and_mass() {
        let dims = [9, 7, 5];
        let mut c = vec![3.5f32; 9 * 7 * 5];
        gaussian_blur(&mut c, dims, [0.7, 1.0, 0.5]);
        assert!(c.iter().all(|v| (v - 3.5).abs() < 1e-5));
        // Away from the border (≥ 3σ) the blur conserves mass.
        let dims = [9, 9, 9];
        let centre = 4 + 9 * (4 + 9 * 4);
        let mut d = vec![0f32; 729];
        d[centre] = 1.0;
        gaussian_blur(&mut d, dims, [0.7, 0.7, 0.7]);
        let total: f32 = d.iter().sum();
        assert!((total - 1.0).abs() < 1e-5, "{total}");
        assert!(d[centre] < 0.5);
    }

    /// Composite midpoint rule over [-r, r] with `n` points.
    fn quadrature(p: &dyn Phantom, origin: DVec3, dir: DVec3, r: f64, n: usize, bg: f64) -> f64 {
        let h = 2.0 * r / n as f64;
        (0..n)
            .map(|i| p.density(origin + dir * (-r + (i as f64 + 0.5) * h)) - bg)
            .sum::<f64>()
            * h
    }

    fn lines() -> Vec<(DVec3, DVec3)> {
        vec![
            (DVec3::ZERO, DVec3::Z),
            (
                DVec3::new(0.1, -0.2, 0.05),
                DVec3::new(1.0, 2.0, 3.0).normalize(),
            ),
            (
                DVec3::new(-0.3, 0.4, 0.2),
                DVec3::new(-0.7, 0.1, 0.4).normalize(),
            ),
            (
                DVec3::new(0.2, -0.6, -0.25),
                DVec3::new(0.3, 0.05, -1.0).normalize(),
            ),
            (
                DVec3::new(0.0, 0.1, 0.625),
                DVec3::new(1.0, 1.0, 0.2).normalize(),
            ),
        ]
    }

    #[test]
    fn gaussian_line_integrals_match_quadrature() {
        let p = GaussianBlobs::demo();
        for (o, d) in lines() {
            let exact = p.line_integral(o, d).unwrap();
            let num = quadrature(&p, o, d, 8.0, 20_000, 0.0);
            assert!(
                (exact - num).abs() < 1e-9 * exact.max(1.0),
                "{exact} vs {num}"
            );
        }
        // A line far from every blob, and a non-unit direction (∫ dt scales by 1/|dir|).
        let miss = p
            .line_integral(DVec3::new(5.0, 5.0, 0.0), DVec3::Z)
            .unwrap();
        assert!(miss < 1e-30, "{miss}");
        let (o, d) = lines()[1];
        let half = p.line_integral(o, d * 2.0).unwrap();
        assert!((half - 0.5 * p.line_integral(o, d).unwrap()).abs() < 1e-12);
        assert!(p.line_integral(o, DVec3::ZERO).is_none());
    }

    #[test]
    fn single_blob_integral_is_amplitude_sigma_root_two_pi() {
        let p = GaussianBlobs::new(vec![Blob {
            center: DVec3::new(1.0, 2.0, 3.0),
            sigma: 0.5,
            amplitude: 2.0,
        }]);
        let through = p
            .line_integral(DVec3::new(1.0, 2.0, -7.0), DVec3::Z)
            .unwrap();
        let expect = 2.0 * 0.5 * (2.0 * std::f64::consts::PI).sqrt();
        assert!((through - expect).abs() < 1e-12);
        let off = p
            .line_integral(DVec3::new(1.5, 2.0, 0.0), -DVec3::Z)
            .unwrap();
        assert!((off - expect * (-0.5f64).exp()).abs() < 1e-12);
        let (lo, hi) = p.bounds();
        assert_eq!(lo, DVec3::new(-1.0, 0.0, 1.0));
        assert_eq!(hi, DVec3::new(3.0, 4.0, 5.0));
    }

    #[test]
    fn demo_blobs_fit_the_box() {
        let p = GaussianBlobs::demo();
        assert_eq!(p.blobs.len(), 6);
        let peak = p.blobs.iter().map(|b| b.amplitude).fold(0.0, f64::max);
        for b in &p.blobs {
            assert!((0.15..=0.35).contains(&b.sigma) && (0.5..=1.0).contains(&b.amplitude));
            assert!(b.center.abs().max_element() + b.sigma <= 0.75 + 1e-12);
        }
        // Density on the faces of [-1, 1]³ is small.
        let n = 41;
        for a in 0..3 {
            for s in [-1.0, 1.0] {
                for i in 0..n {
                    for j in 0..n {
                        let u = -1.0 + 2.0 * i as f64 / (n - 1) as f64;
                        let v = -1.0 + 2.0 * j as f64 / (n - 1) as f64;
                        let mut q = [u, v, s];
                        q.rotate_right(a);
                        let d = p.density(DVec3::from(q));
                        assert!(d < 0.03 * peak, "{q:?}: {d}");
                    }
                }
            }
        }
    }

    #[test]
    fn ellipsoid_line_integrals_match_quadrature() {
        let p = EllipsoidPhantom::shepp_logan_3d();
        p.validate().unwrap();
        for (o, d) in lines() {
            let exact = p.line_integral(o, d).unwrap();
            let num = quadrature(&p, o, d, 2.0, 400_000, 0.0);
            assert!((exact - num).abs() < 2e-4, "{o} {d}: {exact} vs {num}");
        }
        let miss = p
            .line_integral(DVec3::new(0.0, 0.99, 0.99), DVec3::X)
            .unwrap();
        assert_eq!(miss, 0.0);
        // The z axis crosses only the two outer ellipsoids: 2·0.9·1.0 − 2·0.88·0.8.
        let c = p.line_integral(DVec3::ZERO, DVec3::Z).unwrap();
        assert!((c - (1.8 - 1.408)).abs() < 1e-12, "{c}");
    }

    #[test]
    fn head_line_integrals_exclude_the_background() {
        let p = EllipsoidPhantom::ct_head();
        p.validate().unwrap();
        let cases = [
            (
                DVec3::new(0.0, 10.0, 0.0),
                DVec3::new(0.2, 0.1, 1.0).normalize(),
            ),
            (
                DVec3::new(20.0, -30.0, 10.0),
                DVec3::new(1.0, -0.3, 0.5).normalize(),
            ),
            (DVec3::new(0.0, -14.0, 80.0), DVec3::X),
        ];
        for (o, d) in cases {
            let exact = p.line_integral(o, d).unwrap();
            let num = quadrature(&p, o, d, 200.0, 400_000, -1000.0);
            assert!((exact - num).abs() < 0.05 * 1040.0, "{exact} vs {num}");
            assert!(
                (exact - num).abs() < 1e-4 * exact.abs() + 20.0,
                "{exact} vs {num}"
            );
        }
        assert_eq!(
            p.line_integral(DVec3::new(89.0, 0.0, 0.0), DVec3::Y),
            Some(0.0)
        );
    }

    #[test]
    fn shepp_logan_values() {
        let p = EllipsoidPhantom::shepp_logan_3d();
        assert!((p.density(DVec3::ZERO) - SHEPP_LOGAN_CENTER_DENSITY).abs() < 1e-12);
        assert_eq!(p.density(DVec3::splat(0.95)), 0.0);
        // Skull: between the outer and the inner ellipsoid on the y axis.
        assert!((p.density(DVec3::new(0.0, 0.9, 0.0)) - 1.0).abs() < 1e-12);
        // Sampled range is [0, 1].
        let v = sample(&p, [48, 48, 48], 1).unwrap();
        let (lo, hi) = v.value_range();
        assert!(lo >= -1e-6 && hi <= 1.0 + 1e-6, "{lo} {hi}");
        // Ellipsoid 3's long axis is along (cos 108°, sin 108°, 0): a point 0.3 along it is
        // inside, a point 0.3 along the perpendicular is not.
        let e = p.ellipsoids[2];
        let axis = DVec3::new(108f64.to_radians().cos(), 108f64.to_radians().sin(), 0.0);
        assert!(e.contains(e.center + axis * 0.3));
        assert!(!e.contains(e.center + axis.cross(DVec3::Z) * 0.3));
    }

    #[test]
    fn ct_head_values() {
        let p = EllipsoidPhantom::ct_head();
        let hu = |x: f64, y: f64, z: f64| p.density(DVec3::new(x, y, z));
        assert_eq!(hu(85.0, 0.0, 0.0), -1000.0);
        assert_eq!(hu(0.0, 0.0, 95.0), -1000.0);
        assert_eq!(hu(0.0, 0.0, 0.0), 35.0); // brain
        assert_eq!(hu(0.0, 18.0 + 64.5, -8.0), 1000.0); // skull vault
        assert_eq!(hu(66.5, 18.0, -8.0), 1000.0); // skull side
        assert_eq!(hu(0.0, 18.0, 63.5), 1000.0); // forehead
        assert_eq!(hu(9.0, 24.0, -10.0), 5.0); // ventricle
        assert_eq!(hu(31.0, 2.0, 66.5), 10.0); // eye
        assert_eq!(hu(-31.0, 2.0, 66.5), 10.0);
        assert_eq!(hu(44.0, 2.0, 65.0), -90.0); // orbital fat beside the eye
        assert_eq!(hu(0.0, -16.8, 95.6), 40.0); // nose tip
        assert_eq!(hu(0.0, -12.2, 69.5), -1000.0); // nasal cavity
        assert_eq!(hu(0.0, -60.0, 20.0), 40.0); // soft tissue of the face
        assert_eq!(hu(0.0, -70.0, 46.0), 1000.0); // chin
        assert_eq!(hu(0.0, 97.0, 0.0), 40.0); // scalp at the vertex
    }

    /// Every point of the head takes one of the intended values: the design's ellipsoids nest
    /// where they must (skull in the scalp, nose inside its cavity, ventricles in the brain).
    #[test]
    fn ct_head_takes_only_intended_values() {
        let p = EllipsoidPhantom::ct_head();
        let allowed = [
            -1000.0, 40.0, 1000.0, 35.0, 5.0, -90.0, 10.0, // tissues
            870.0, 970.0,  // bone where the orbit reaches it
            1960.0, // two mandible pieces
        ];
        let v = sample(&p, [139, 171, 155], 1).unwrap();
        let mut seen = std::collections::BTreeMap::<i64, usize>::new();
        for &x in v.data() {
            *seen.entry(x.round() as i64).or_default() += 1;
        }
        for (&value, &count) in &seen {
            assert!(
                allowed.contains(&(value as f64)),
                "unexpected {value} HU at {count} voxels: {seen:?}"
            );
        }
        for must in [-1000, 40, 1000, 35, 5, -90, 10] {
            assert!(seen.contains_key(&must), "{must} missing: {seen:?}");
        }
    }

    #[test]
    fn marschner_lobb_values() {
        let p = MarschnerLobb::default();
        // ρ(0) = cos(12π) = 1: (1 − 0 + 0.25·2)/2.5.
        assert!((p.density(DVec3::ZERO) - 0.6).abs() < 1e-12);
        assert!(p.line_integral(DVec3::ZERO, DVec3::Z).is_none());
        let v = sample(&p, [41, 41, 41], 1).unwrap();
        let (lo, hi) = v.value_range();
        assert!(lo >= -1e-6 && hi <= 1.0 + 1e-6);
    }

    #[test]
    fn sampled_grid_spans_the_bounds() {
        let p = EllipsoidPhantom::ct_head();
        let v = sample(&p, [19, 23, 21], 1).unwrap();
        let (lo, hi) = v.grid().bounds_world();
        let (blo, bhi) = p.bounds();
        assert!((lo - blo).abs().max_element() < 1e-9 && (hi - bhi).abs().max_element() < 1e-9);
        assert_eq!(v.grid().spacing, [10.0, 10.0, 10.0]);
        // Point sampling equals density() at the voxel centres.
        for (i, j, k) in [(9, 11, 10), (3, 4, 17), (0, 0, 0), (12, 20, 15)] {
            let w = v
                .grid()
                .world_from_index(DVec3::new(i as f64, j as f64, k as f64));
            assert_eq!(v.get(i, j, k), p.density(w) as f32);
        }
    }

    #[test]
    fn sampling_handles_flat_axes_and_rejects_bad_sizes() {
        let p = EllipsoidPhantom::shepp_logan_3d();
        let v = sample(&p, [33, 33, 1], 3).unwrap();
        assert_eq!(v.grid().spacing[2], 1.0);
        assert_eq!(v.grid().origin[2], 0.0);
        let mid = v.get(16, 16, 0);
        assert!((mid - 0.2).abs() < 1e-6);
        let line = sample(&p, [1, 1, 1], 2).unwrap();
        assert_eq!(line.data(), &[0.2]);
        assert!(sample(&p, [0, 4, 4], 1).is_err());
        assert!(sample(&p, [4, 4, 4], 0).is_err());
        assert!(sample(&p, [4, 4, 4], 1000).is_err());
        assert!(sample(&p, [1 << 20, 1 << 20, 1 << 20], 1).is_err());
    }

    #[test]
    fn supersampling_averages_over_the_cell() {
        // A slab x ≥ 0 sampled on a grid with a voxel centred on its face sees half coverage.
        struct HalfSpace;
        impl Phantom for HalfSpace {
            fn density(&self, p: DVec3) -> f64 {
                if p.x >= 0.0 { 1.0 } else { 0.0 }
            }
            fn line_integral(&self, _: DVec3, _: DVec3) -> Option<f64> {
                None
            }
            fn bounds(&self) -> (DVec3, DVec3) {
                (DVec3::splat(-1.0), DVec3::splat(1.0))
            }
        }
        let v = sample(&HalfSpace, [5, 3, 3], 4).unwrap();
        assert_eq!(v.get(2, 1, 1), 0.5);
        assert_eq!(v.get(1, 1, 1), 0.0);
        assert_eq!(v.get(3, 1, 1), 1.0);
    }

    #[test]
    fn row_evaluation_matches_point_evaluation() {
        let p = EllipsoidPhantom::shepp_logan_3d();
        let start = DVec3::new(-1.0, 0.013, -0.247);
        let step = DVec3::new(0.0173, 0.0011, 0.0007);
        let mut row = vec![0.0; 117];
        p.density_row(start, step, &mut row);
        for (n, v) in row.iter().enumerate() {
            assert_eq!(*v, p.density(start + step * n as f64), "n = {n}");
        }
    }

    #[test]
    fn bad_phantoms_give_errors_not_panics() {
        let mut p = EllipsoidPhantom::shepp_logan_3d();
        p.ellipsoids[3].semi_axes.y = 0.0;
        assert!(
            p.validate()
                .unwrap_err()
                .to_string()
                .contains("ellipsoid[3]")
        );
        let mut p = EllipsoidPhantom::shepp_logan_3d();
        p.ellipsoids[0].rotation = DMat3::from_diagonal(DVec3::splat(2.0));
        assert!(p.validate().is_err());
        let nan = GaussianBlobs::new(vec![Blob {
            center: DVec3::ZERO,
            sigma: 0.0,
            amplitude: 1.0,
        }]);
        let e = sample_on_grid(&nan, &Grid::with_dims([3, 3, 3]).unwrap(), 1).unwrap_err();
        assert!(e.to_string().contains("phantom density"), "{e}");
        for name in BUILTIN_NAMES {
            let p = builtin(name).unwrap();
            assert!(sample(p.as_ref(), [5, 6, 7], 2).is_ok(), "{name}");
        }
    }

    #[test]
    fn ct_head_volume_is_rounded_hu() {
        // 2.4 mm voxels: the 7 mm skull survives the σ = 0.7-voxel scanner blur as bone.
        let v = ct_head_volume([75, 91, 83]).unwrap();
        let (lo, hi) = v.value_range();
        assert_eq!(lo, -1000.0);
        assert!(hi >= 800.0, "{hi}");
        assert_eq!(v.get(0, 0, 0), -1000);
        assert!(builtin("ct-head").is_ok() && builtin("nope").is_err());
    }
}
