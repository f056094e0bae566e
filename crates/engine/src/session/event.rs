//! Input events of a [`Session`](super::Session) and the camera moves they make.
//!
//! Mouse-driven moves follow VTK's `vtkInteractorStyleTrackballCamera` (the style ParaView and
//! 3D Slicer's 3-D views use), so a drag turns the volume as it turns there:
//! - rotate: `Azimuth(−dx · 20 / width · 10)`, `Elevation(dy · 20 / height · 10)` in degrees
//!   (`dy` down-positive here, up-positive in VTK's display coordinates), then
//!   `OrthogonalizeViewUp`;
//! - pan: the focal point and the eye move together so that the point under the cursor on the
//!   focal plane follows it;
//! - zoom: `parallel_scale / factor` (orthographic) or `Dolly(factor)` (perspective);
//! - roll: `Roll(degrees)` about the direction of projection.
//!
//! Distances are image pixels of the full-quality frame (x right, y down); angles degrees.

use crate::request::{Mode, Quality};
use crate::scene::{CropBox, PlaneSpec, TransferSpec};
use serde::{Deserialize, Serialize};
use volsplat_core::glam::DVec3;
use volsplat_core::{AnatomicalView, Camera};

/// Largest drag or pan, in pixels, that one event may carry.
pub const MAX_DRAG_PX: f64 = 1.0e5;

/// Smallest and largest zoom factor of one event.
pub const ZOOM_FACTOR_RANGE: (f64, f64) = (1.0e-3, 1.0e3);

/// One input to a [`Session`](super::Session). Every event is checked before it changes
/// anything: an event the session refuses leaves its scene as it was.
///
/// As JSON (the web viewer's protocol): `{"type": "orbit", "dx": 4, "dy": -2}`, with the
/// variant name in `snake_case` under `type` and unknown fields refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Event {
    /// Turn the camera about the focal point by a drag of `dx`, `dy` image pixels (x right,
    /// y down), as VTK's trackball camera does.
    Orbit {
        /// Horizontal drag, pixels (right positive).
        dx: f64,
        /// Vertical drag, pixels (down positive).
        dy: f64,
    },
    /// Move the eye and focal point so the focal plane follows a drag of `dx`, `dy` pixels.
    Pan {
        /// Horizontal drag, pixels (right positive).
        dx: f64,
        /// Vertical drag, pixels (down positive).
        dy: f64,
    },
    /// Magnify by `factor` (> 1 closer): orthographic `parallel_scale / factor`, perspective
    /// VTK's `Dolly(factor)`.
    Zoom {
        /// Magnification, in [`ZOOM_FACTOR_RANGE`].
        factor: f64,
    },
    /// Turn the image about the direction of projection (VTK's `Roll`), degrees.
    Roll {
        /// Degrees, counter-clockwise on screen.
        degrees: f64,
    },
    /// Turn to an anatomical view of the patient frame (LPS) about the focal point, keeping
    /// distance, zoom and projection (3D Slicer's A, P, L, R, S, I buttons).
    SetView {
        /// Which side faces the viewer.
        view: AnatomicalView,
    },
    /// Back to the camera the session started with. (A struct variant, `{"type": "reset"}`,
    /// so that unknown fields are refused as for every other event.)
    Reset {},
    /// A given camera (world units; the camera-file format).
    SetCamera {
        /// The camera.
        camera: Camera,
    },
    /// The ray function. A grey window is kept only where it means the same in the new mode
    /// (between MIP and MinIP; [`Mode::shares_window_with`]), and dropped otherwise.
    SetMode {
        /// Composite, MIP, MinIP or X-ray.
        mode: Mode,
    },
    /// The transfer function: a preset, `auto`, or points (the transfer-function-file format).
    SetTransferFunction {
        /// The new transfer function.
        transfer_function: TransferSpec,
    },
    /// The grey window of MIP, MinIP and X-ray frames (the request's `output.window`),
    /// `[lo, hi]` in the values' units (data units; X-ray: data units × world units), or `None`
    /// for the default mapping (MIP and MinIP through the transfer function, X-ray 0 to its
    /// brightest pixel).
    SetWindow {
        /// `[lo, hi]` with `lo < hi`, or `None`.
        window: Option<[f32; 2]>,
    },
    /// The crop box (`None`: no crop).
    SetCrop {
        /// The box.
        crop: Option<CropBox>,
    },
    /// The clipping planes (empty: none).
    SetClip {
        /// Planes in the world frame.
        planes: Vec<PlaneSpec>,
    },
    /// The full-quality settings.
    SetQuality {
        /// Quality of the final frame.
        quality: Quality,
    },
    /// The size of the view in pixels (of the full-quality frame).
    Resize {
        /// Width, pixels.
        width: usize,
        /// Height, pixels.
        height: usize,
    },
    /// A pointer is held (`true`, a drag starts) or released (`false`): while held the session
    /// sends previews only; at release it refines at once.
    Interaction {
        /// Whether a drag is in progress.
        active: bool,
    },
}

impl Event {
    /// Whether the event is one step of a continuous gesture (a drag or a wheel): without a held
    /// pointer the session waits for a short rest after it before refining, so that a run of
    /// wheel steps is not refined step by step.
    pub fn is_continuous(&self) -> bool {
        matches!(
            self,
            Event::Orbit { .. }
                | Event::Pan { .. }
                | Event::Zoom { .. }
                | Event::Roll { .. }
                | Event::SetWindow { .. }
        )
    }
}

/// VTK's trackball rotation for a drag of `dx`, `dy` pixels on a `width × height` view.
pub(crate) fn orbit(camera: &mut Camera, dx: f64, dy: f64, width: usize, height: usize) {
    // vtkInteractorStyleTrackballCamera::Rotate: delta = −20 / size, MotionFactor 10; VTK's
    // display y is up, ours down.
    let azimuth = -dx * 20.0 / width as f64 * 10.0;
    let elevation = dy * 20.0 / height as f64 * 10.0;
    camera.azimuth(azimuth);
    camera.elevation(elevation);
    camera.orthogonalize_view_up();
}

/// World units per pixel on the focal plane of `camera` in a view `height` pixels high.
pub(crate) fn focal_plane_pixel(camera: &Camera, height: usize) -> f64 {
    let half_height = if camera.parallel_projection {
        camera.parallel_scale
    } else {
        let distance = (DVec3::from(camera.position) - DVec3::from(camera.focal_point)).length();
        distance * (0.5 * camera.view_angle.to_radians()).tan()
    };
    2.0 * half_height / height as f64
}

/// Moves eye and focal point so that the focal plane follows a drag of `dx`, `dy` pixels.
pub(crate) fn pan(camera: &mut Camera, dx: f64, dy: f64, height: usize) {
    let f = camera.frame();
    let px = focal_plane_pixel(camera, height);
    // The scene follows the cursor: the camera moves the other way (y down on screen).
    let motion = (-dx * f.right + dy * f.up) * px;
    camera.position = (DVec3::from(camera.position) + motion).to_array();
    camera.focal_point = (DVec3::from(camera.focal_point) + motion).to_array();
}

/// VTK's trackball zoom: `parallel_scale / factor`, or `Dolly(factor)` in perspective.
pub(crate) fn zoom(camera: &mut Camera, factor: f64) {
    if camera.parallel_projection {
        camera.parallel_scale /= factor;
    } else {
        camera.dolly(factor);
    }
}

/// VTK's `Roll`, then `OrthogonalizeViewUp`.
pub(crate) fn roll(camera: &mut Camera, degrees: f64) {
    camera.roll(degrees);
    camera.orthogonalize_view_up();
}
