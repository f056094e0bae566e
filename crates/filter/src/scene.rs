//! Texture scenes: a perspective camera over a textured plane running to the horizon, or a
//! textured sphere, and the per-pixel filter regions (thesis §4-2, Figs 4.12–4.15, Table 5.3).
//!
//! Scenes are modelled directly in texture space (one world unit = one texture unit). A pixel is
//! a circle of radius `½·pitch·spread` on the image plane (§3-1). For each pixel the scene gives
//! the ray hit, the **exact** projection of the circle onto the tangent plane at the hit (a conic
//! computed by pulling the circle back through the plane-to-screen homography), and from it:
//! - the ellipse (centre, semi-axis vectors) — its centre is not the hit point under
//!   perspective (Fig 4.15);
//! - `V_tan`: the rectangle enclosing the ellipse (aligned with its axes), extruded by `ε`
//!   symmetrically about the surface (decision A-8);
//! - `V_ray`: the square of half-width `ρ·z` perpendicular to the ray at the hit (`z` = depth
//!   of the hit along the view direction), extruded by `ε` *into* the object along the ray.
//!
//! Where the circle's projection is a parabola or hyperbola (the pixel straddles the horizon) or
//! the ellipse is larger than [`SceneSettings::max_footprint`], [`HorizonPolicy`] decides
//! (§4-2 footnote 2).

use crate::error::{FilterError, Result, check_positive};
use crate::region::{Ellipse, OrientedBox};
use glam::DVec3;
use volsplat_core::Camera;

/// The textured object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Surface {
    /// An infinite plane through `point` with unit `normal` (texture units).
    Plane {
        /// A point on the plane.
        point: DVec3,
        /// Plane normal (normalised on use).
        normal: DVec3,
    },
    /// A sphere (texture units).
    Sphere {
        /// Centre.
        center: DVec3,
        /// Radius (> 0).
        radius: f64,
    },
}

/// What to do where a pixel's projection is not a bounded ellipse of acceptable size
/// (thesis §4-2 footnote 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HorizonPolicy {
    /// Return the texture's known DC (average) value.
    DcValue,
    /// Use a large ellipse: semi-major [`SceneSettings::max_footprint`] along the projected ray
    /// direction, semi-minor the pixel's lateral size at the hit.
    LargeEllipse,
}

/// Scene description.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSettings {
    /// Perspective camera (VTK conventions; `view_angle` is the vertical field of view in
    /// degrees). Orthographic cameras are rejected.
    pub camera: Camera,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// The textured object.
    pub surface: Surface,
    /// Filter-width multiplier ("spread", Table 5.3): the pixel circle's radius is
    /// `½·pitch·spread`.
    pub spread: f64,
    /// Depth `ε` of `V_tan`/`V_ray` and of the EWA-3 ellipsoid, texture units (Table 5.3).
    pub epsilon: f64,
    /// Largest acceptable ellipse semi-major axis, texture units; beyond it
    /// [`SceneSettings::horizon`] applies.
    pub max_footprint: f64,
    /// Degenerate-footprint policy.
    pub horizon: HorizonPolicy,
    /// Grey value of pixels whose central ray misses the object.
    pub background: f64,
}

impl SceneSettings {
    /// The Chapter 5 test scene (Plate 5.1): a plane `z = 0.3` receding to the horizon, seen
    /// from height 1 at a grazing angle, `width × height` pixels.
    pub fn test_plane(width: usize, height: usize) -> Self {
        SceneSettings {
            camera: Camera {
                position: [0.0, 0.0, 1.3],
                focal_point: [0.0, 6.0, 0.3],
                view_up: [0.0, 0.0, 1.0],
                view_angle: 40.0,
                parallel_projection: false,
                parallel_scale: 1.0,
            },
            width,
            height,
            surface: Surface::Plane {
                point: DVec3::new(0.0, 0.0, 0.3),
                normal: DVec3::Z,
            },
            spread: 1.0,
            epsilon: 0.01,
            max_footprint: 64.0,
            horizon: HorizonPolicy::DcValue,
            background: 0.0,
        }
    }

    /// A textured sphere of radius 1 at the origin filling most of the view.
    pub fn test_sphere(width: usize, height: usize) -> Self {
        SceneSettings {
            camera: Camera {
                position: [0.0, -3.2, 1.0],
                focal_point: [0.0, 0.0, 0.0],
                view_up: [0.0, 0.0, 1.0],
                view_angle: 45.0,
                parallel_projection: false,
                parallel_scale: 1.0,
            },
            surface: Surface::Sphere {
                center: DVec3::ZERO,
                radius: 1.0,
            },
            ..SceneSettings::test_plane(width, height)
        }
    }
}

/// Everything a filter needs about one pixel that hits the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelFootprint {
    /// Where the pixel's central ray hits the surface (texture units).
    pub hit: DVec3,
    /// Unit outward surface normal at the hit.
    pub normal: DVec3,
    /// Unit ray direction (eye → hit).
    pub ray: DVec3,
    /// Depth of the hit along the camera's view direction (texture units).
    pub depth: f64,
    /// The pixel circle projected onto the tangent plane.
    pub ellipse: Ellipse,
    /// Tangent-plane box (opaque materials).
    pub v_tan: OrientedBox,
    /// Ray-aligned box (translucent materials).
    pub v_ray: OrientedBox,
    /// True if [`HorizonPolicy::LargeEllipse`] replaced a degenerate projection.
    pub substituted: bool,
}

/// The per-pixel outcome of [`Scene::footprint`].
// Returned by value once per pixel: boxing the large variant would cost an allocation each.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Footprint {
    /// The central ray misses the object: use [`SceneSettings::background`].
    Background,
    /// The projection is a parabola/hyperbola or too large and the policy is
    /// [`HorizonPolicy::DcValue`]: use the texture's mean. Carries the hit point.
    Degenerate(DVec3),
    /// A regular footprint.
    Hit(PixelFootprint),
}

/// A validated scene with its camera frame.
#[derive(Debug, Clone)]
pub struct Scene {
    settings: SceneSettings,
    eye: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    pitch: f64,
}

impl Scene {
    /// Validates the settings (camera, sizes, positive spread/ε/max footprint, surface).
    pub fn new(settings: SceneSettings) -> Result<Self> {
        settings.camera.validate()?;
        if settings.camera.parallel_projection {
            return Err(FilterError::invalid(
                "camera.parallel_projection",
                true,
                "texture scenes need a perspective camera",
            ));
        }
        if settings.width == 0 || settings.height == 0 || settings.width * settings.height > 1 << 26
        {
            return Err(FilterError::invalid(
                "width×height",
                (settings.width, settings.height),
                "must be non-zero and at most 2^26 pixels",
            ));
        }
        check_positive("spread", settings.spread)?;
        check_positive("epsilon", settings.epsilon)?;
        check_positive("max_footprint", settings.max_footprint)?;
        if !settings.background.is_finite() {
            return Err(FilterError::invalid(
                "background",
                settings.background,
                "must be finite",
            ));
        }
        match settings.surface {
            Surface::Plane { point, normal } => {
                if !point.is_finite() || !normal.is_finite() || normal.length() < 1e-12 {
                    return Err(FilterError::invalid(
                        "plane",
                        (point, normal),
                        "needs a finite point and non-zero normal",
                    ));
                }
            }
            Surface::Sphere { center, radius } => {
                if !center.is_finite() {
                    return Err(FilterError::invalid(
                        "sphere.center",
                        center,
                        "must be finite",
                    ));
                }
                check_positive("sphere.radius", radius)?;
            }
        }
        let f = settings.camera.frame();
        let pitch =
            2.0 * (0.5 * settings.camera.view_angle.to_radians()).tan() / settings.height as f64;
        Ok(Scene {
            eye: f.eye,
            right: f.right,
            up: f.up,
            forward: f.forward,
            pitch,
            settings,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &SceneSettings {
        &self.settings
    }

    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.settings.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.settings.height
    }

    /// Pixel pitch on the image plane at unit distance from the eye (radians, small-angle).
    pub fn pitch(&self) -> f64 {
        self.pitch
    }

    /// Image-plane coordinates `(X, Y)` (unit distance from the eye) of raster point `(px, py)`
    /// (pixel centres at half-integers, row 0 at the top).
    fn image_plane(&self, px: f64, py: f64) -> (f64, f64) {
        let w = self.settings.width as f64;
        let h = self.settings.height as f64;
        ((px - 0.5 * w) * self.pitch, (0.5 * h - py) * self.pitch)
    }

    /// Intersects the ray `eye + λ·d` with the surface; returns `(λ, hit, unit normal)`.
    fn intersect(&self, d: DVec3) -> Option<(f64, DVec3, DVec3)> {
        match self.settings.surface {
            Surface::Plane { point, normal } => {
                let n = normal.normalize();
                let denom = n.dot(d);
                if denom.abs() < 1e-15 {
                    return None;
                }
                let lambda = n.dot(point - self.eye) / denom;
                if lambda <= 0.0 || !lambda.is_finite() {
                    return None;
                }
                let n = if denom > 0.0 { -n } else { n };
                Some((lambda, self.eye + d * lambda, n))
            }
            Surface::Sphere { center, radius } => {
                let oc = self.eye - center;
                let a = d.dot(d);
                let b = oc.dot(d);
                let c = oc.dot(oc) - radius * radius;
                let disc = b * b - a * c;
                if disc < 0.0 {
                    return None;
                }
                let sq = disc.sqrt();
                let lambda = if (-b - sq) / a > 0.0 {
                    (-b - sq) / a
                } else {
                    (-b + sq) / a
                };
                if lambda <= 0.0 {
                    return None;
                }
                let p = self.eye + d * lambda;
                Some((lambda, p, (p - center) / radius))
            }
        }
    }

    /// The footprint of pixel `(x, y)` (column, row; row 0 at the top).
    pub fn footprint(&self, x: usize, y: usize) -> Footprint {
        self.footprint_at(x as f64 + 0.5, y as f64 + 0.5)
    }

    /// The footprint of a pixel centred at raster point `(px, py)`.
    pub fn footprint_at(&self, px: f64, py: f64) -> Footprint {
        let (xc, yc) = self.image_plane(px, py);
        let d = self.forward + self.right * xc + self.up * yc;
        let Some((lambda, hit, normal)) = self.intersect(d) else {
            return Footprint::Background;
        };
        let rho = 0.5 * self.pitch * self.settings.spread;
        let depth = lambda; // d·forward = 1, so λ is the depth along the view direction.
        let ray = d.normalize();
        let eps = self.settings.epsilon;
        // V_ray: square ⟂ ray of half-width ρ·depth, extruded by ε into the object.
        let (b1, b2) = orthonormal_pair(ray);
        let half = rho * depth;
        let v_ray = OrientedBox {
            center: hit + ray * (0.5 * eps),
            axes: [b1 * half, b2 * half, ray * (0.5 * eps)],
        };
        let ellipse = match self.project_circle(hit, normal, xc, yc, rho) {
            Some(e) if e.major() <= self.settings.max_footprint => Some(e),
            _ => None,
        };
        let (ellipse, substituted) = match (ellipse, self.settings.horizon) {
            (Some(e), _) => (e, false),
            (None, HorizonPolicy::DcValue) => return Footprint::Degenerate(hit),
            (None, HorizonPolicy::LargeEllipse) => {
                let along = ray - normal * ray.dot(normal);
                let major = if along.length() > 1e-12 {
                    along.normalize()
                } else {
                    b1
                };
                let minor = normal.cross(major).normalize();
                (
                    Ellipse {
                        center: hit,
                        axes: [major * self.settings.max_footprint, minor * half],
                        normal,
                    },
                    true,
                )
            }
        };
        let v_tan = OrientedBox {
            center: ellipse.center,
            axes: [ellipse.axes[0], ellipse.axes[1], normal * (0.5 * eps)],
        };
        Footprint::Hit(PixelFootprint {
            hit,
            normal,
            ray,
            depth,
            ellipse,
            v_tan,
            v_ray,
            substituted,
        })
    }

    /// Exact projection of the image-plane circle `(X − xc)² + (Y − yc)² ≤ ρ²` onto the tangent
    /// plane at `hit` (decision A-9: the conic `Q(a,b) = L₁² + L₂² − ρ²L₃² ≤ 0` with linear
    /// forms `L` of the tangent-plane coordinates). `None` unless `Q` is an ellipse.
    fn project_circle(
        &self,
        hit: DVec3,
        normal: DVec3,
        xc: f64,
        yc: f64,
        rho: f64,
    ) -> Option<Ellipse> {
        let (e1, e2) = orthonormal_pair(normal);
        let delta = hit - self.eye;
        let g = [
            self.right - self.forward * xc,
            self.up - self.forward * yc,
            self.forward,
        ];
        let w = [1.0, 1.0, -rho * rho];
        let (mut a, mut b, mut c, mut d, mut e, mut f0) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for q in 0..3 {
            let (u, v, k) = (g[q].dot(e1), g[q].dot(e2), g[q].dot(delta));
            a += w[q] * u * u;
            b += w[q] * u * v;
            c += w[q] * v * v;
            d += w[q] * u * k;
            e += w[q] * v * k;
            f0 += w[q] * k * k;
        }
        let det = a * c - b * b;
        let scale = (a * a + c * c + 2.0 * b * b).sqrt();
        if det.is_nan() || det <= 1e-12 * scale * scale || a <= 0.0 {
            return None;
        }
        let a0 = (-d * c + e * b) / det;
        let b0 = (-e * a + d * b) / det;
        let k = -(f0 + d * a0 + e * b0);
        if k.is_nan() || k <= 0.0 {
            return None;
        }
        // Eigen-decomposition of [[a, b], [b, c]].
        let tr = 0.5 * (a + c);
        let dd = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let (l_small, l_big) = (tr - dd, tr + dd);
        if l_small <= 0.0 {
            return None;
        }
        let v_small = if b.abs() > 1e-300 * scale {
            let v = (b, l_small - a);
            let n = (v.0 * v.0 + v.1 * v.1).sqrt();
            (v.0 / n, v.1 / n)
        } else if a <= c {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        let major_dir = e1 * v_small.0 + e2 * v_small.1;
        let minor_dir = normal.cross(major_dir);
        let center = hit + e1 * a0 + e2 * b0;
        let axes = [
            major_dir * (k / l_small).sqrt(),
            minor_dir * (k / l_big).sqrt(),
        ];
        if !center.is_finite() || !axes[0].is_finite() || !axes[1].is_finite() {
            return None;
        }
        Some(Ellipse {
            center,
            axes,
            normal,
        })
    }
}

/// Two unit vectors completing `n` (unit) to an orthonormal frame.
pub(crate) fn orthonormal_pair(n: DVec3) -> (DVec3, DVec3) {
    let helper = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let a = n.cross(helper).normalize();
    (a, n.cross(a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn facing_scene(tilt_deg: f64) -> Scene {
        // Camera on the z axis looking down at the plane z = 0, plane tilted about x.
        let t = tilt_deg.to_radians();
        Scene::new(SceneSettings {
            camera: Camera {
                position: [0.0, 0.0, 5.0],
                focal_point: [0.0, 0.0, 0.0],
                view_up: [0.0, 1.0, 0.0],
                view_angle: 20.0,
                parallel_projection: false,
                parallel_scale: 1.0,
            },
            width: 101,
            height: 101,
            surface: Surface::Plane {
                point: DVec3::ZERO,
                normal: DVec3::new(0.0, t.sin(), t.cos()),
            },
            ..SceneSettings::test_plane(101, 101)
        })
        .unwrap()
    }

    #[test]
    fn facing_plane_gives_circle_f_b04() {
        let s = facing_scene(0.0);
        let Footprint::Hit(fp) = s.footprint(50, 50) else {
            panic!("centre pixel must hit")
        };
        let r = 0.5 * s.pitch() * 5.0;
        assert!(
            (fp.ellipse.major() - r).abs() < 1e-9 * r,
            "{} vs {r}",
            fp.ellipse.major()
        );
        assert!((fp.ellipse.minor() - r).abs() < 1e-9 * r);
        assert!((fp.ellipse.center - fp.hit).length() < 1e-9);
        // V_ray in-plane extent = pixel diameter at the hit.
        assert!((fp.v_ray.axes[0].length() - r).abs() < 1e-12);
        assert!((fp.v_ray.axes[2].length() - 0.005).abs() < 1e-15);
    }

    #[test]
    fn tilted_plane_axis_ratio_f_b04() {
        for deg in [30.0, 60.0] {
            let s = facing_scene(deg);
            let Footprint::Hit(fp) = s.footprint(50, 50) else {
                panic!()
            };
            let ratio = fp.ellipse.major() / fp.ellipse.minor();
            let expect = 1.0 / f64::cos(f64::to_radians(deg));
            assert!(
                (ratio - expect).abs() < 1e-3 * expect,
                "{deg}: {ratio} vs {expect}"
            );
        }
    }

    #[test]
    fn ellipse_is_exact_projection_of_circle() {
        // Points on the ellipse boundary must project back onto the pixel circle.
        let s = Scene::new(SceneSettings::test_plane(64, 48)).unwrap();
        for (x, y) in [(10usize, 40usize), (32, 30), (60, 25)] {
            let Footprint::Hit(fp) = s.footprint(x, y) else {
                panic!("({x},{y})")
            };
            let (xc, yc) = s.image_plane(x as f64 + 0.5, y as f64 + 0.5);
            let rho = 0.5 * s.pitch();
            for k in 0..8 {
                let th = k as f64 * 0.785;
                let p = fp.ellipse.center
                    + fp.ellipse.axes[0] * th.cos()
                    + fp.ellipse.axes[1] * th.sin();
                let dv = p - s.eye;
                let z = dv.dot(s.forward);
                let (px, py) = (dv.dot(s.right) / z, dv.dot(s.up) / z);
                let r = ((px - xc).powi(2) + (py - yc).powi(2)).sqrt();
                assert!(
                    (r - rho).abs() < 1e-6 * rho,
                    "pixel ({x},{y}) k={k}: {r} vs {rho}"
                );
            }
        }
    }

    #[test]
    fn horizon_is_degenerate_and_sky_is_background() {
        let mut set = SceneSettings::test_plane(64, 48);
        set.max_footprint = 1e9;
        let s = Scene::new(set.clone()).unwrap();
        let mut degenerate = 0;
        let mut background = 0;
        let mut hits = 0;
        for y in 0..48 {
            for x in 0..64 {
                match s.footprint(x, y) {
                    Footprint::Background => background += 1,
                    Footprint::Degenerate(_) => degenerate += 1,
                    Footprint::Hit(fp) => {
                        hits += 1;
                        // Footprints grow towards the horizon (rows above).
                        assert!(fp.ellipse.major() > 0.0);
                    }
                }
            }
        }
        assert!(
            background > 0 && hits > 0 && degenerate > 0,
            "{background} {degenerate} {hits}"
        );
        set.horizon = HorizonPolicy::LargeEllipse;
        let s = Scene::new(set).unwrap();
        let n_sub = (0..64)
            .flat_map(|x| (0..48).map(move |y| (x, y)))
            .filter(|&(x, y)| matches!(s.footprint(x, y), Footprint::Hit(fp) if fp.substituted))
            .count();
        assert_eq!(n_sub, degenerate);
    }

    #[test]
    fn boxes_scale_with_spread_and_epsilon_f_b05() {
        let mut set = SceneSettings::test_plane(64, 48);
        let base = Scene::new(set.clone()).unwrap();
        set.spread = 2.0;
        set.epsilon = 0.04;
        let wide = Scene::new(set).unwrap();
        let (Footprint::Hit(a), Footprint::Hit(b)) =
            (base.footprint(20, 40), wide.footprint(20, 40))
        else {
            panic!()
        };
        let ratio = b.v_tan.axes[0].length() / a.v_tan.axes[0].length();
        // Perspective: a doubled circle projects to slightly more than a doubled ellipse.
        assert!((ratio - 2.0).abs() < 0.02, "{ratio}");
        assert!((b.v_tan.axes[2].length() / a.v_tan.axes[2].length() - 4.0).abs() < 1e-12);
        assert!((b.v_ray.axes[0].length() / a.v_ray.axes[0].length() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn sphere_hits() {
        let s = Scene::new(SceneSettings::test_sphere(32, 24)).unwrap();
        let Footprint::Hit(fp) = s.footprint(16, 12) else {
            panic!()
        };
        assert!((fp.hit.length() - 1.0).abs() < 1e-12);
        assert!(fp.normal.dot(fp.ray) < 0.0);
        assert_eq!(s.footprint(0, 0), Footprint::Background);
    }
}
