//! VTK-compatible cameras (docs/design.md §3).
//!
//! A [`Camera`] holds exactly the numbers a `vtkCamera` holds, so the same JSON file reproduces a
//! view in volsplat, VTK and ParaView. [`ViewFrame`] is the derived orthonormal camera frame and
//! [`OrthoProjection`] maps world points to raster (pixel) coordinates for a given image size.

use crate::error::{CoreError, Result};
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

fn default_view_angle() -> f64 {
    30.0
}
fn default_parallel_scale() -> f64 {
    1.0
}

/// A camera with VTK's semantics. All positions in world units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Eye position, world units.
    pub position: [f64; 3],
    /// The point looked at, world units; the image centre.
    pub focal_point: [f64; 3],
    /// Approximate up direction of the image (need not be orthogonal to the view direction).
    pub view_up: [f64; 3],
    /// Vertical field of view in degrees, in (0, 180); used by perspective projection. VTK's
    /// default is 30.
    #[serde(default = "default_view_angle")]
    pub view_angle: f64,
    /// `true` for an orthographic (parallel) projection.
    #[serde(default)]
    pub parallel_projection: bool,
    /// Orthographic only: half the image height in world units. VTK's default is 1.
    #[serde(default = "default_parallel_scale")]
    pub parallel_scale: f64,
}

impl Default for Camera {
    /// VTK's default camera: at (0,0,1) looking at the origin with +y up, perspective 30°.
    fn default() -> Self {
        Camera {
            position: [0.0, 0.0, 1.0],
            focal_point: [0.0; 3],
            view_up: [0.0, 1.0, 0.0],
            view_angle: 30.0,
            parallel_projection: false,
            parallel_scale: 1.0,
        }
    }
}

/// The orthonormal frame of a camera, in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewFrame {
    /// Eye position (world units).
    pub eye: DVec3,
    /// Focal point (world units).
    pub focal: DVec3,
    /// Unit vector to the right in the image.
    pub right: DVec3,
    /// Unit vector up in the image (view-up orthogonalised).
    pub up: DVec3,
    /// Unit direction of projection: from the eye towards the focal point (into the screen).
    pub forward: DVec3,
}

impl ViewFrame {
    /// `camera_from_world` rotation: rows are right, up and −forward (VTK camera coordinates,
    /// looking down −z).
    pub fn camera_from_world_rotation(&self) -> DMat3 {
        DMat3::from_cols(self.right, self.up, -self.forward).transpose()
    }
}

impl Camera {
    /// Checks every field: finite numbers, eye ≠ focal point, view-up not parallel to the view
    /// direction, `view_angle` in (0, 180), `parallel_scale` > 0.
    pub fn validate(&self) -> Result<()> {
        let fields: [(&str, &[f64; 3]); 3] = [
            ("position", &self.position),
            ("focal_point", &self.focal_point),
            ("view_up", &self.view_up),
        ];
        for (name, v) in fields {
            if v.iter().any(|x| !x.is_finite()) {
                return Err(CoreError::invalid(name, v, "must be three finite numbers"));
            }
        }
        let dop = DVec3::from(self.focal_point) - DVec3::from(self.position);
        if !dop.length().is_finite() {
            return Err(CoreError::invalid(
                "position",
                self.position,
                "lies too far from focal_point: their distance overflows (world units)",
            ));
        }
        if dop.length() < 1e-12 {
            return Err(CoreError::invalid(
                "position",
                self.position,
                "must differ from focal_point",
            ));
        }
        let up = DVec3::from(self.view_up);
        if up.length() < 1e-12 || dop.normalize().cross(up.normalize()).length() < 1e-9 {
            return Err(CoreError::invalid(
                "view_up",
                self.view_up,
                "must be non-zero and not parallel to the view direction",
            ));
        }
        if !(self.view_angle > 0.0 && self.view_angle < 180.0) {
            return Err(CoreError::invalid(
                "view_angle",
                self.view_angle,
                "must be in (0, 180) degrees",
            ));
        }
        if !(self.parallel_scale.is_finite() && self.parallel_scale > 0.0) {
            return Err(CoreError::invalid(
                "parallel_scale",
                self.parallel_scale,
                "must be a positive finite number (world units)",
            ));
        }
        Ok(())
    }

    /// The camera's orthonormal frame. Call [`Camera::validate`] first; degenerate cameras give
    /// NaNs.
    pub fn frame(&self) -> ViewFrame {
        let eye = DVec3::from(self.position);
        let focal = DVec3::from(self.focal_point);
        let forward = (focal - eye).normalize();
        let right = forward.cross(DVec3::from(self.view_up)).normalize();
        let up = right.cross(forward);
        ViewFrame {
            eye,
            focal,
            right,
            up,
            forward,
        }
    }

    /// VTK's `vtkRenderer::ResetCamera` for the given world bounds, starting from the default
    /// direction (looking down −z, +y up): the focal point at the bounds' centre, the eye at
    /// `radius / sin(view_angle/2)` along +z, `parallel_scale = radius`, where `radius` is half the
    /// bounds' diagonal.
    pub fn reset_to_bounds(lo: DVec3, hi: DVec3, parallel_projection: bool) -> Camera {
        let center = (lo + hi) * 0.5;
        let mut radius = (hi - lo).length();
        if radius == 0.0 {
            radius = 1.0;
        }
        radius *= 0.5;
        let view_angle = 30.0f64;
        let distance = radius / (view_angle.to_radians() * 0.5).sin();
        Camera {
            position: (center + DVec3::Z * distance).to_array(),
            focal_point: center.to_array(),
            view_up: [0.0, 1.0, 0.0],
            view_angle,
            parallel_projection,
            parallel_scale: radius,
        }
    }

    /// VTK's `Azimuth`: rotates the eye about the view-up vector centred at the focal point
    /// (degrees, counter-clockwise seen from the tip of view-up).
    pub fn azimuth(&mut self, degrees: f64) {
        let axis = DVec3::from(self.view_up).normalize();
        self.rotate_eye(axis, degrees);
    }

    /// VTK's `Elevation`: rotates the eye about the axis `−right` centred at the focal point
    /// (degrees; positive moves the eye up); call [`Camera::orthogonalize_view_up`] afterwards,
    /// as VTK users do.
    ///
    /// VTK (`vtkCamera::Elevation`, VTK 9) computes the new view with view-up turned with the
    /// eye, so the frame stays right-handed and unchanged in `right` at any angle, ±90° and
    /// over the top included; only `GetViewUp` still reports the old vector until
    /// `OrthogonalizeViewUp`. Here view-up is kept where it gives that same frame (the
    /// pictures are VTK's either way), and turned with the eye where it would not: at ±90°,
    /// where it lies along the new direction of projection (no frame at all), and beyond,
    /// where it would flip the picture.
    pub fn elevation(&mut self, degrees: f64) {
        let right = self.frame().right;
        let axis = -right;
        self.rotate_eye(axis, degrees);
        let up = DVec3::from(self.view_up);
        let forward = (DVec3::from(self.focal_point) - DVec3::from(self.position)).normalize();
        // The kept view-up gives VTK's frame when it leaves `right` where it was, clearly
        // (1e-3 of its length: away from the ±90° degeneracy, where rounding would decide).
        let keeps_frame = forward.cross(up).dot(right) > 1e-3 * up.length();
        if !keeps_frame {
            let rot = DMat3::from_axis_angle(axis, degrees.to_radians());
            self.view_up = (rot * up).to_array();
        }
    }

    /// VTK's `Roll`: rotates view-up about the direction of projection (degrees).
    pub fn roll(&mut self, degrees: f64) {
        let f = self.frame();
        let rot = DMat3::from_axis_angle(f.forward, -degrees.to_radians());
        self.view_up = (rot * DVec3::from(self.view_up)).to_array();
    }

    /// VTK's `OrthogonalizeViewUp`: replaces view-up by the frame's orthogonal up vector.
    pub fn orthogonalize_view_up(&mut self) {
        self.view_up = self.frame().up.to_array();
    }

    /// VTK's `Zoom`: divides `parallel_scale` (orthographic) or `view_angle` (perspective) by
    /// `factor` (> 0).
    pub fn zoom(&mut self, factor: f64) {
        if self.parallel_projection {
            self.parallel_scale /= factor;
        } else {
            self.view_angle /= factor;
        }
    }

    /// VTK's `Dolly`: moves the eye towards the focal point, dividing their distance by `factor`
    /// (> 1 moves closer). The focal point stays.
    pub fn dolly(&mut self, factor: f64) {
        let fp = DVec3::from(self.focal_point);
        let eye = DVec3::from(self.position);
        self.position = (fp + (eye - fp) / factor).to_array();
    }

    fn rotate_eye(&mut self, axis: DVec3, degrees: f64) {
        let fp = DVec3::from(self.focal_point);
        let rot = DMat3::from_axis_angle(axis, degrees.to_radians());
        self.position = (fp + rot * (DVec3::from(self.position) - fp)).to_array();
    }
}

/// Which projection a view change switches a camera to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProjectionKind {
    /// Parallel projection (`parallel_projection: true`).
    Orthographic,
    /// Perspective projection (`parallel_projection: false`).
    Perspective,
}

/// View changes applied to a camera in VTK's order, the maths behind "orbit the volume":
/// a projection switch and view angle first, then `Azimuth`, `Elevation`,
/// `OrthogonalizeViewUp` (when any rotation is given), `Roll`, `Zoom` and `Dolly`. Every field
/// is optional; an empty `Orbit` leaves a camera exactly as it is. Angles in degrees, factors
/// unitless.
///
/// [`Orbit::reset_camera`] starts from VTK's `ResetCamera` for a volume's bounds (looking down
/// −z, +y up; orthographic unless the orbit asks for perspective); [`Orbit::apply`] changes a
/// given camera (a saved view), so a camera file can be orbited like the reset view.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct Orbit {
    /// Degrees about the view-up axis (VTK's `Azimuth`).
    pub azimuth: Option<f64>,
    /// Degrees over the focal point (VTK's `Elevation`).
    pub elevation: Option<f64>,
    /// Degrees about the view direction (VTK's `Roll`).
    pub roll: Option<f64>,
    /// Magnification (VTK's `Zoom`: divides the parallel scale, or the view angle in
    /// perspective); > 0.
    pub zoom: Option<f64>,
    /// Divides the eye's distance to the focal point (VTK's `Dolly`; > 1 moves closer); > 0.
    pub dolly: Option<f64>,
    /// Vertical field of view in degrees, in (0, 180) (perspective). On the reset view the eye
    /// moves so that the volume's bounding sphere still fits, as VTK's `ResetCamera` places it.
    pub view_angle: Option<f64>,
    /// Switch to this projection. Switching a perspective camera to orthographic sets its
    /// parallel scale to the half-height of the perspective view at the focal point.
    pub projection: Option<ProjectionKind>,
    /// Start from an anatomical view of the patient frame (LPS) instead of VTK's default
    /// direction; the rotations then apply to it. Reset view only ([`Orbit::reset_camera`]);
    /// [`Orbit::apply`] turns the given camera to it, keeping its focal point and distance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub view: Option<AnatomicalView>,
}

/// Views of the patient frame (volsplat's world frame is LPS: +x left, +y posterior, +z
/// superior; docs/design.md §3), as 3D Slicer's view buttons: the named side faces the viewer, the
/// head up (superior and inferior views: anterior up).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnatomicalView {
    /// From the front: eye at −y (anterior), +z up.
    Anterior,
    /// From behind: eye at +y, +z up.
    Posterior,
    /// From the patient's left: eye at +x, +z up.
    Left,
    /// From the patient's right: eye at −x, +z up.
    Right,
    /// From above: eye at +z, anterior (−y) up.
    Superior,
    /// From below: eye at −z, anterior (−y) up.
    Inferior,
}

impl AnatomicalView {
    /// Every view.
    pub const ALL: [AnatomicalView; 6] = [
        AnatomicalView::Anterior,
        AnatomicalView::Posterior,
        AnatomicalView::Left,
        AnatomicalView::Right,
        AnatomicalView::Superior,
        AnatomicalView::Inferior,
    ];

    /// The name, as scene files spell it: `anterior`, `posterior`, `left`, `right`, `superior`,
    /// `inferior`.
    pub fn name(self) -> &'static str {
        match self {
            AnatomicalView::Anterior => "anterior",
            AnatomicalView::Posterior => "posterior",
            AnatomicalView::Left => "left",
            AnatomicalView::Right => "right",
            AnatomicalView::Superior => "superior",
            AnatomicalView::Inferior => "inferior",
        }
    }

    /// A view by name, as the command line's `--view` and Python's `view=` take it (any case):
    /// the names of [`AnatomicalView::name`], their initials `A`, `P`, `L`, `R`, `S`, `I`, and
    /// `front`, `back`, `top`, `bottom`. An unknown name is an error listing the known ones.
    pub fn from_name(name: &str) -> Result<Self> {
        use AnatomicalView as V;
        Ok(match name.trim().to_ascii_lowercase().as_str() {
            "anterior" | "a" | "front" => V::Anterior,
            "posterior" | "p" | "back" => V::Posterior,
            "left" | "l" => V::Left,
            "right" | "r" => V::Right,
            "superior" | "s" | "top" => V::Superior,
            "inferior" | "i" | "bottom" => V::Inferior,
            _ => {
                return Err(CoreError::invalid(
                    "view",
                    name,
                    "expected anterior, posterior, left, right, superior or inferior (or A, P, \
                     L, R, S, I)",
                ));
            }
        })
    }

    /// The direction from the focal point to the eye and the view-up, world (LPS) unit vectors.
    pub fn eye_and_up(self) -> (DVec3, DVec3) {
        match self {
            AnatomicalView::Anterior => (-DVec3::Y, DVec3::Z),
            AnatomicalView::Posterior => (DVec3::Y, DVec3::Z),
            AnatomicalView::Left => (DVec3::X, DVec3::Z),
            AnatomicalView::Right => (-DVec3::X, DVec3::Z),
            AnatomicalView::Superior => (DVec3::Z, -DVec3::Y),
            AnatomicalView::Inferior => (-DVec3::Z, -DVec3::Y),
        }
    }

    /// Turns `camera` to this view about its focal point, keeping the distance and projection.
    pub fn orient(self, camera: &mut Camera) {
        let fp = DVec3::from(camera.focal_point);
        let dist = (DVec3::from(camera.position) - fp).length();
        let (eye, up) = self.eye_and_up();
        camera.position = (fp + eye * dist).to_array();
        camera.view_up = up.to_array();
    }
}

impl std::str::FromStr for AnatomicalView {
    type Err = CoreError;

    /// [`AnatomicalView::from_name`].
    fn from_str(s: &str) -> Result<Self> {
        AnatomicalView::from_name(s)
    }
}

impl Orbit {
    /// Checks that the given numbers are finite and in range; errors name the field.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("azimuth", self.azimuth),
            ("elevation", self.elevation),
            ("roll", self.roll),
        ] {
            if let Some(v) = v
                && !v.is_finite()
            {
                return Err(CoreError::invalid(
                    name,
                    v,
                    "must be a finite number of degrees",
                ));
            }
        }
        for (name, v) in [("zoom", self.zoom), ("dolly", self.dolly)] {
            if let Some(v) = v
                && !(v.is_finite() && v > 0.0)
            {
                return Err(CoreError::invalid(name, v, "must be a positive number"));
            }
        }
        if let Some(a) = self.view_angle
            && !(a > 0.0 && a < 180.0)
        {
            return Err(CoreError::invalid(
                "view_angle",
                a,
                "must be in (0, 180) degrees",
            ));
        }
        Ok(())
    }

    /// Whether the orbit changes nothing.
    pub fn is_identity(&self) -> bool {
        *self == Orbit::default()
    }

    /// VTK's reset camera for the world bounds `lo..hi` (see [`Camera::reset_to_bounds`]), in
    /// the orbit's projection (orthographic by default), then the orbit.
    pub fn reset_camera(&self, lo: DVec3, hi: DVec3) -> Result<Camera> {
        self.validate()?;
        let perspective = self.projection == Some(ProjectionKind::Perspective);
        let mut cam = Camera::reset_to_bounds(lo, hi, !perspective);
        if let Some(angle) = self.view_angle
            && angle != cam.view_angle
        {
            // VTK's ResetCamera places the eye at radius / sin(view_angle / 2).
            let fp = DVec3::from(cam.focal_point);
            let dist = cam.parallel_scale / (angle.to_radians() * 0.5).sin();
            cam.position = (fp + DVec3::Z * dist).to_array();
            cam.view_angle = angle;
        }
        if let Some(v) = self.view {
            v.orient(&mut cam);
        }
        self.rotate_and_scale(&mut cam)?;
        Ok(cam)
    }

    /// Applies the orbit to `camera` (a given view): projection switch, view angle, then the
    /// rotations, zoom and dolly. Errors if a number is out of range or the result is degenerate
    /// (a view-up along the direction of projection; every elevation, ±90° included, gives a
    /// valid camera, as VTK's `Elevation` and `OrthogonalizeViewUp` do).
    pub fn apply(&self, camera: &mut Camera) -> Result<()> {
        self.validate()?;
        match self.projection {
            Some(ProjectionKind::Perspective) => camera.parallel_projection = false,
            Some(ProjectionKind::Orthographic) if !camera.parallel_projection => {
                let (eye, focal) = (
                    DVec3::from(camera.position),
                    DVec3::from(camera.focal_point),
                );
                camera.parallel_scale =
                    (eye - focal).length() * (0.5 * camera.view_angle.to_radians()).tan();
                camera.parallel_projection = true;
            }
            _ => {}
        }
        if let Some(angle) = self.view_angle {
            camera.view_angle = angle;
        }
        if let Some(v) = self.view {
            v.orient(camera);
        }
        self.rotate_and_scale(camera)
    }

    fn rotate_and_scale(&self, cam: &mut Camera) -> Result<()> {
        if let Some(deg) = self.azimuth {
            cam.azimuth(deg);
        }
        if let Some(deg) = self.elevation {
            cam.elevation(deg);
        }
        if self.azimuth.is_some() || self.elevation.is_some() || self.roll.is_some() {
            cam.orthogonalize_view_up();
        }
        if let Some(deg) = self.roll {
            cam.roll(deg);
        }
        if let Some(zoom) = self.zoom {
            cam.zoom(zoom);
        }
        if let Some(dolly) = self.dolly {
            cam.dolly(dolly);
        }
        cam.validate()
    }
}

/// Orthographic projection of a camera onto a `width × height` raster.
///
/// Raster coordinates: x to the right, y down, row 0 at the top, pixel `(x, y)` centred at
/// `(x + 0.5, y + 0.5)`. Square pixels of [`OrthoProjection::pixel_size`] world units.
/// Depth is the distance along the direction of projection from the eye, in world units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrthoProjection {
    /// The camera frame.
    pub frame: ViewFrame,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// World units per pixel (`2·parallel_scale / height`).
    pub pixel_size: f64,
}

impl OrthoProjection {
    /// Builds the projection; errors if the camera is invalid, not orthographic, or the image
    /// is empty.
    pub fn new(camera: &Camera, width: usize, height: usize) -> Result<Self> {
        camera.validate()?;
        if !camera.parallel_projection {
            return Err(CoreError::invalid(
                "parallel_projection",
                false,
                "this renderer supports orthographic cameras only (set parallel_projection: true)",
            ));
        }
        check_size(width, height)?;
        Ok(OrthoProjection {
            frame: camera.frame(),
            width,
            height,
            pixel_size: 2.0 * camera.parallel_scale / height as f64,
        })
    }

    /// The 3×3 linear map from world displacements to (raster x, raster y, depth) displacements.
    pub fn raster_from_world_linear(&self) -> DMat3 {
        let inv = 1.0 / self.pixel_size;
        DMat3::from_cols(
            self.frame.right * inv,
            -self.frame.up * inv,
            self.frame.forward,
        )
        .transpose()
    }

    /// Raster position `(x, y)` in pixels and depth in world units of a world point.
    pub fn raster_from_world(&self, p_world: DVec3) -> DVec3 {
        let d = p_world - self.frame.focal;
        let inv = 1.0 / self.pixel_size;
        DVec3::new(
            self.width as f64 * 0.5 + d.dot(self.frame.right) * inv,
            self.height as f64 * 0.5 - d.dot(self.frame.up) * inv,
            (p_world - self.frame.eye).dot(self.frame.forward),
        )
    }

    /// World point on the image plane through the focal point at raster position `(x, y)`
    /// (pixels; pixel centres at half-integers).
    pub fn world_from_raster(&self, x: f64, y: f64) -> DVec3 {
        self.frame.focal
            + self.frame.right * ((x - self.width as f64 * 0.5) * self.pixel_size)
            + self.frame.up * ((self.height as f64 * 0.5 - y) * self.pixel_size)
    }
}

/// Perspective (pinhole) projection of a camera onto a `width × height` raster, with VTK's
/// semantics: `view_angle` is the vertical field of view; the image plane is perpendicular to
/// the direction of projection.
///
/// Raster coordinates as [`OrthoProjection`]. Depth is the eye-space distance along the
/// direction of projection (`z_e` of Swan et al. 1997, Fig. 1a), world units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerspectiveProjection {
    /// The camera frame.
    pub frame: ViewFrame,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Eye-to-screen distance in pixels: `(height/2) / tan(view_angle/2)`. This is `D/p` of
    /// Swan et al. 1997 eq. 3 (screen distance over pixel extent).
    pub focal_px: f64,
}

impl PerspectiveProjection {
    /// Builds the projection; errors if the camera is invalid, orthographic, or the image is
    /// empty.
    pub fn new(camera: &Camera, width: usize, height: usize) -> Result<Self> {
        camera.validate()?;
        if camera.parallel_projection {
            return Err(CoreError::invalid(
                "parallel_projection",
                true,
                "a perspective projection needs parallel_projection: false",
            ));
        }
        check_size(width, height)?;
        let half = (camera.view_angle.to_radians() * 0.5).tan();
        Ok(PerspectiveProjection {
            frame: camera.frame(),
            width,
            height,
            focal_px: height as f64 * 0.5 / half,
        })
    }

    /// Raster position `(x, y)` in pixels and eye-space depth (world units) of a world point.
    /// Points at depth ≤ 0 (at or behind the eye) give non-finite or mirrored raster positions:
    /// callers clip on depth first.
    pub fn raster_from_world(&self, p_world: DVec3) -> DVec3 {
        let d = p_world - self.frame.eye;
        let z = d.dot(self.frame.forward);
        let s = self.focal_px / z;
        DVec3::new(
            self.width as f64 * 0.5 + d.dot(self.frame.right) * s,
            self.height as f64 * 0.5 - d.dot(self.frame.up) * s,
            z,
        )
    }

    /// The 2×3 derivative of raster `(x, y)` with respect to the world position at `p_world`
    /// (pixels per world unit), as the first two rows of a 3×3 matrix whose third row is the
    /// derivative of depth (the direction of projection). Local affine approximation of the
    /// perspective map (Zwicker et al. 2001, §4.1).
    pub fn jacobian(&self, p_world: DVec3) -> DMat3 {
        let d = p_world - self.frame.eye;
        let z = d.dot(self.frame.forward);
        let (xr, yu) = (d.dot(self.frame.right), d.dot(self.frame.up));
        let f = self.focal_px;
        // x = W/2 + f·xr/z ; y = H/2 − f·yu/z.
        let row_x = self.frame.right * (f / z) - self.frame.forward * (f * xr / (z * z));
        let row_y = -self.frame.up * (f / z) + self.frame.forward * (f * yu / (z * z));
        DMat3::from_cols(row_x, row_y, self.frame.forward).transpose()
    }

    /// Unit direction (world) of the ray from the eye through raster point `(x, y)`.
    pub fn ray_direction(&self, x: f64, y: f64) -> DVec3 {
        let f = self.focal_px;
        (self.frame.forward + self.frame.right * ((x - self.width as f64 * 0.5) / f)
            - self.frame.up * ((y - self.height as f64 * 0.5) / f))
            .normalize()
    }
}

fn check_size(width: usize, height: usize) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(CoreError::invalid(
            "image size",
            (width, height),
            "must be non-zero",
        ));
    }
    Ok(())
}

/// Either projection, chosen by the camera's `parallel_projection` flag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Parallel projection.
    Ortho(OrthoProjection),
    /// Pinhole perspective.
    Perspective(PerspectiveProjection),
}

impl Projection {
    /// The projection the camera asks for.
    pub fn new(camera: &Camera, width: usize, height: usize) -> Result<Self> {
        Ok(if camera.parallel_projection {
            Projection::Ortho(OrthoProjection::new(camera, width, height)?)
        } else {
            Projection::Perspective(PerspectiveProjection::new(camera, width, height)?)
        })
    }

    /// The camera frame.
    pub fn frame(&self) -> &ViewFrame {
        match self {
            Projection::Ortho(p) => &p.frame,
            Projection::Perspective(p) => &p.frame,
        }
    }

    /// Image size `(width, height)` in pixels.
    pub fn size(&self) -> (usize, usize) {
        match self {
            Projection::Ortho(p) => (p.width, p.height),
            Projection::Perspective(p) => (p.width, p.height),
        }
    }

    /// Raster `(x, y)` in pixels and depth along the direction of projection from the eye
    /// (world units).
    pub fn raster_from_world(&self, p_world: DVec3) -> DVec3 {
        match self {
            Projection::Ortho(p) => p.raster_from_world(p_world),
            Projection::Perspective(p) => p.raster_from_world(p_world),
        }
    }

    /// Derivative of (raster x, raster y, depth) with respect to world position at `p_world`.
    pub fn jacobian(&self, p_world: DVec3) -> DMat3 {
        match self {
            Projection::Ortho(p) => p.raster_from_world_linear(),
            Projection::Perspective(p) => p.jacobian(p_world),
        }
    }

    /// The ray through raster point `(x, y)`: a world origin and a unit world direction. For
    /// perspective the origin is the eye; for orthographic views it is the point on the plane
    /// through the eye perpendicular to the direction of projection (volumes behind that plane
    /// are still in view, as in VTK, whose clipping range is reset to the data).
    pub fn ray(&self, x: f64, y: f64) -> (DVec3, DVec3) {
        match self {
            Projection::Ortho(p) => {
                let on_focal = p.world_from_raster(x, y);
                let back = (on_focal - p.frame.eye).dot(p.frame.forward);
                (on_focal - p.frame.forward * back, p.frame.forward)
            }
            Projection::Perspective(p) => (p.frame.eye, p.ray_direction(x, y)),
        }
    }

    /// Size of one pixel in world units at depth `depth` (world units from the eye along the
    /// direction of projection): constant for orthographic views, `depth / focal_px` for
    /// perspective.
    pub fn pixel_size_at(&self, depth: f64) -> f64 {
        match self {
            Projection::Ortho(p) => p.pixel_size,
            Projection::Perspective(p) => depth / p.focal_px,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera whose distance to the focal point overflows names the position, not the
    /// view-up vector (whose check would see a direction of infinities).
    #[test]
    fn an_overflowing_distance_blames_the_position() {
        let mut c = Camera::reset_to_bounds(DVec3::ZERO, DVec3::ONE, true);
        c.position = [1e308, 1e308, 1e308];
        c.focal_point = [-1e308, 0.0, 0.0];
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("position") && e.contains("overflows"), "{e}");
    }

    fn approx(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-9
    }

    #[test]
    fn reset_camera_matches_vtk() {
        let c = Camera::reset_to_bounds(DVec3::ZERO, DVec3::new(2.0, 2.0, 1.0), true);
        // radius = |(2,2,1)|/2 = 1.5, distance = 1.5 / sin 15°.
        assert!((c.parallel_scale - 1.5).abs() < 1e-12);
        let d = 1.5 / 15f64.to_radians().sin();
        assert!(approx(
            DVec3::from(c.position),
            DVec3::new(1.0, 1.0, 0.5 + d)
        ));
    }

    #[test]
    fn azimuth_and_elevation_rotate_like_vtk() {
        let mut c = Camera::reset_to_bounds(DVec3::splat(-1.0), DVec3::splat(1.0), true);
        let r = DVec3::from(c.position).length();
        c.azimuth(90.0);
        // Rotating (0,0,r) by +90° about +y gives (r,0,0).
        assert!(approx(DVec3::from(c.position), DVec3::new(r, 0.0, 0.0)));
        c.elevation(90.0);
        c.orthogonalize_view_up();
        assert!(approx(DVec3::from(c.position), DVec3::new(0.0, r, 0.0)));
        let f = c.frame();
        assert!(approx(f.forward, -DVec3::Y));
    }

    /// Issue 28 follow-up: an orbit with elevation exactly ±90 was an error (`view_up` NaN) and
    /// beyond 90 the picture was upside down against VTK's. The numbers are VTK 9.7.2's
    /// (`vtk` wheel): `vtkRenderer::ResetCamera((-1, 1, -2, 2, -0.5, 0.5))`, then `Azimuth(az)`
    /// (when not 0), `Elevation(el)`, `OrthogonalizeViewUp()`; `GetPosition()`, `GetViewUp()`
    /// printed with 17 digits (focal point the origin). By hand for (0, 90): the eye at
    /// `d = √21/2 / sin 15° = 8.8528…` on +z turns about −x by 90° to +y, and view-up (0, 1, 0)
    /// with it to (0, 0, −1).
    #[test]
    #[allow(clippy::excessive_precision, clippy::approx_constant)] // VTK's numbers as printed
    fn elevation_matches_vtk_at_and_beyond_the_poles() {
        let cases: [(f64, f64, [f64; 3], [f64; 3]); 8] = [
            (0.0, 90.0, [0.0, 8.8528564293648433, 0.0], [0.0, 0.0, -1.0]),
            (0.0, -90.0, [0.0, -8.8528564293648433, 0.0], [0.0, 0.0, 1.0]),
            (
                0.0,
                120.0,
                [0.0, 7.6667985638863536, -4.4264282146824199],
                [0.0, -0.49999999999999978, -0.86602540378443882],
            ),
            (
                30.0,
                90.0,
                [0.0, 8.8528564293648433, 0.0],
                [-0.49999999999999994, 0.0, -0.86602540378443871],
            ),
            (
                30.0,
                -90.0,
                [0.0, -8.8528564293648433, 0.0],
                [0.49999999999999994, 0.0, 0.86602540378443871],
            ),
            (
                25.0,
                89.9999,
                [
                    6.5299378553262954e-06,
                    8.8528564293513572,
                    1.4003496921821679e-05,
                ],
                [
                    -0.42261826174005579,
                    1.7453292521984453e-06,
                    -0.9063077870352696,
                ],
            ),
            (
                0.0,
                45.0,
                [0.0, 6.2599148140748069, 6.259914814074806],
                [0.0, 0.70710678118654746, -0.70710678118654757],
            ),
            (
                40.0,
                200.0,
                [-5.347326894349643, -3.0278552248129316, -6.3726960371168264],
                [
                    0.21984631039295416,
                    -0.93969262078590854,
                    0.26200263022938491,
                ],
            ),
        ];
        for (az, el, pos, up) in cases {
            let orbit = Orbit {
                azimuth: (az != 0.0).then_some(az),
                elevation: Some(el),
                ..Orbit::default()
            };
            let c = orbit
                .reset_camera(DVec3::new(-1.0, -2.0, -0.5), DVec3::new(1.0, 2.0, 0.5))
                .unwrap_or_else(|e| panic!("azimuth {az}, elevation {el}: {e}"));
            let (p, u) = (DVec3::from(c.position), DVec3::from(c.view_up));
            assert!(
                (p - DVec3::from(pos)).length() < 1e-9,
                "azimuth {az}, elevation {el}: position {p} vs VTK's {pos:?}"
            );
            assert!(
                (u - DVec3::from(up)).length() < 1e-9,
                "azimuth {az}, elevation {el}: view-up {u} vs VTK's {up:?}"
            );
        }
    }

    /// Every azimuth, then elevation ±90, on boxes of several shapes in both projections: a
    /// valid camera looking straight down (up), its view-up the old direction of projection
    /// (negated for −90): VTK's `Elevation(±90)` turns view-up with the eye (derivation: the
    /// rotation by 90° about −right takes up to −right × up = forward). Before the fix about one
    /// orbit in twenty (azimuth 36, 43, …) rounded to a view-up along the view: NaN.
    #[test]
    fn every_azimuth_then_the_poles_gives_a_valid_camera() {
        let boxes = [
            (DVec3::ZERO, DVec3::splat(31.0)),
            (DVec3::new(-1.0, -2.0, -0.5), DVec3::new(1.0, 2.0, 0.5)),
            (DVec3::ZERO, DVec3::new(83.0, 127.0, 127.0)),
            (DVec3::ZERO, DVec3::new(255.0, 255.0, 99.0)),
        ];
        for (lo, hi) in boxes {
            for az in 0..360 {
                let az = az as f64;
                let old_forward = -DVec3::new(az.to_radians().sin(), 0.0, az.to_radians().cos());
                for el in [90.0, -90.0] {
                    for projection in [ProjectionKind::Orthographic, ProjectionKind::Perspective] {
                        let o = Orbit {
                            azimuth: Some(az),
                            elevation: Some(el),
                            projection: Some(projection),
                            ..Orbit::default()
                        };
                        let tag = format!("{lo}..{hi}, azimuth {az}, elevation {el}");
                        let c = o
                            .reset_camera(lo, hi)
                            .unwrap_or_else(|e| panic!("{tag}: {e}"));
                        let f = c.frame();
                        assert!(
                            (f.forward + DVec3::Y * el.signum()).length() < 1e-9,
                            "{tag}"
                        );
                        let up = old_forward * el.signum();
                        assert!((DVec3::from(c.view_up) - up).length() < 1e-9, "{tag}");
                    }
                }
            }
        }
    }

    #[test]
    fn projection_centres_focal_point_and_flips_y() {
        let mut c = Camera::reset_to_bounds(DVec3::splat(-1.0), DVec3::splat(1.0), true);
        c.parallel_scale = 2.0;
        let p = OrthoProjection::new(&c, 200, 100).unwrap();
        let centre = p.raster_from_world(DVec3::ZERO);
        assert!((centre.x - 100.0).abs() < 1e-9 && (centre.y - 50.0).abs() < 1e-9);
        // +y world is up in the image, i.e. smaller raster y. Pixel size = 4/100.
        let up = p.raster_from_world(DVec3::new(0.0, 1.0, 0.0));
        assert!((up.y - 25.0).abs() < 1e-9);
        let w = p.world_from_raster(130.5, 20.5);
        let back = p.raster_from_world(w);
        assert!((back.x - 130.5).abs() < 1e-9 && (back.y - 20.5).abs() < 1e-9);
    }

    #[test]
    fn perspective_projection_matches_its_rays_and_jacobian() {
        let mut c = Camera::reset_to_bounds(DVec3::splat(-1.0), DVec3::splat(1.0), false);
        c.azimuth(25.0);
        c.elevation(-15.0);
        c.orthogonalize_view_up();
        let p = PerspectiveProjection::new(&c, 160, 120).unwrap();
        let proj = Projection::Perspective(p);
        // The focal point lands on the image centre.
        let centre = p.raster_from_world(DVec3::from(c.focal_point));
        assert!((centre.x - 80.0).abs() < 1e-9 && (centre.y - 60.0).abs() < 1e-9);
        // The top edge of the image is view_angle/2 above the axis.
        let f = p.frame;
        let top = f.eye + (f.forward + f.up * 15f64.to_radians().tan()) * 3.0;
        assert!(p.raster_from_world(top).y.abs() < 1e-9);
        // A point on the ray through (x, y) projects back to (x, y).
        for (x, y) in [(0.5, 0.5), (123.25, 77.5), (159.5, 3.0)] {
            let (o, d) = proj.ray(x, y);
            let q = p.raster_from_world(o + d * 4.2);
            assert!((q.x - x).abs() < 1e-9 && (q.y - y).abs() < 1e-9);
        }
        // The Jacobian matches central differences.
        let x0 = DVec3::new(0.3, -0.4, 0.2);
        let j = p.jacobian(x0);
        for a in 0..3 {
            let mut e = DVec3::ZERO;
            e[a] = 1e-6;
            let fd = (p.raster_from_world(x0 + e) - p.raster_from_world(x0 - e)) / 2e-6;
            let col = j.col(a);
            assert!((fd - col).length() < 1e-5, "axis {a}: {fd} vs {col}");
        }
        // Pixel size at the focal distance: the image height spans 2·d·tan(15°).
        let dist = (DVec3::from(c.position) - DVec3::from(c.focal_point)).length();
        let px = proj.pixel_size_at(dist);
        assert!((px * 120.0 - 2.0 * dist * 15f64.to_radians().tan()).abs() < 1e-9);
    }

    #[test]
    fn orthographic_rays_are_parallel_and_project_back() {
        let c = Camera::reset_to_bounds(DVec3::splat(-1.0), DVec3::splat(1.0), true);
        let proj = Projection::new(&c, 64, 48).unwrap();
        let (o, d) = proj.ray(10.5, 20.5);
        assert!((d - proj.frame().forward).length() < 1e-12);
        let q = proj.raster_from_world(o + d * 2.0);
        assert!((q.x - 10.5).abs() < 1e-9 && (q.y - 20.5).abs() < 1e-9);
        assert!((q.z - 2.0).abs() < 1e-9);
    }

    #[test]
    fn dolly_divides_the_distance() {
        let mut c = Camera::reset_to_bounds(DVec3::splat(-1.0), DVec3::splat(1.0), false);
        let d0 = (DVec3::from(c.position) - DVec3::from(c.focal_point)).length();
        c.dolly(2.0);
        let d1 = (DVec3::from(c.position) - DVec3::from(c.focal_point)).length();
        assert!((d0 / d1 - 2.0).abs() < 1e-12);
    }

    #[test]
    fn invalid_cameras_name_the_field() {
        let mut c = Camera {
            parallel_projection: true,
            ..Camera::default()
        };
        c.view_up = [0.0, 0.0, 1.0];
        assert!(c.validate().unwrap_err().to_string().contains("view_up"));
        let mut c = Camera {
            parallel_projection: true,
            ..Camera::default()
        };
        c.parallel_scale = -1.0;
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("parallel_scale")
        );
        let c = Camera::default();
        let e = OrthoProjection::new(&c, 10, 10).unwrap_err();
        assert!(e.to_string().contains("parallel_projection"));
    }

    /// `--view`: each anatomical view looks at the named side of an LPS volume with the head up,
    /// keeps the reset view's focal point and distance, and the rotations apply after it.
    #[test]
    fn anatomical_views_look_at_their_side_of_the_patient() {
        let (lo, hi) = (DVec3::new(-10.0, -20.0, -5.0), DVec3::new(30.0, 40.0, 25.0));
        let reset = Camera::reset_to_bounds(lo, hi, true);
        let dist = |c: &Camera| (DVec3::from(c.position) - DVec3::from(c.focal_point)).length();
        for v in AnatomicalView::ALL {
            let orbit = Orbit {
                view: Some(v),
                ..Orbit::default()
            };
            let c = orbit.reset_camera(lo, hi).unwrap();
            let f = c.frame();
            let (eye, up) = v.eye_and_up();
            assert!((f.forward + eye).length() < 1e-12, "{v:?}: {:?}", f.forward);
            assert!((f.up - up).length() < 1e-12, "{v:?}");
            assert_eq!(c.focal_point, reset.focal_point);
            assert!((dist(&c) - dist(&reset)).abs() < 1e-9);
        }
        // Anterior: facing the patient, the patient's left (+x) is on the image's right.
        let a = Orbit {
            view: Some(AnatomicalView::Anterior),
            ..Orbit::default()
        }
        .reset_camera(lo, hi)
        .unwrap();
        assert!((a.frame().right - DVec3::X).length() < 1e-12);
        // Azimuth 90 from anterior about +z (up) gives the left view.
        let turned = Orbit {
            view: Some(AnatomicalView::Anterior),
            azimuth: Some(90.0),
            ..Orbit::default()
        }
        .reset_camera(lo, hi)
        .unwrap();
        let left = Orbit {
            view: Some(AnatomicalView::Left),
            ..Orbit::default()
        }
        .reset_camera(lo, hi)
        .unwrap();
        assert!((turned.frame().forward - left.frame().forward).length() < 1e-9);
    }

    /// View names (the command line's `--view`, Python's `view=`): every name, initial and
    /// alias, in any case; the canonical name is the scene file's spelling.
    #[test]
    fn anatomical_views_by_name() {
        for v in AnatomicalView::ALL {
            let name = v.name();
            assert_eq!(AnatomicalView::from_name(name).unwrap(), v);
            assert_eq!(name.to_uppercase().parse::<AnatomicalView>().unwrap(), v);
            assert_eq!(AnatomicalView::from_name(&name[..1]).unwrap(), v);
            let json = serde_json::to_string(&v).unwrap();
            assert_eq!(json, format!("\"{name}\""));
        }
        for (alias, v) in [
            ("Front", AnatomicalView::Anterior),
            ("back", AnatomicalView::Posterior),
            ("TOP", AnatomicalView::Superior),
            ("bottom", AnatomicalView::Inferior),
        ] {
            assert_eq!(AnatomicalView::from_name(alias).unwrap(), v);
        }
        let e = AnatomicalView::from_name("sideways")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sideways") && e.contains("anterior"), "{e}");
    }
}
