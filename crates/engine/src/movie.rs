//! Camera paths for movies: turntables about an axis, and keyframed flights interpolated
//! smoothly. A movie is many [`crate::RenderRequest`]s through one [`crate::Renderer`], each with
//! an explicit camera from here, so frames reuse the classification and splat list.
//!
//! Interpolation between keyframes (times in seconds):
//! - orientation: the camera frame's unit quaternions (consecutive ones in the same hemisphere,
//!   i.e. the shorter arc; Shoemake 1985, *Animating rotation with quaternion curves*) through the
//!   spline below component-wise, renormalised: continuous angular velocity, unlike piecewise
//!   slerp, and exact at the keys;
//! - focal point: a Catmull–Rom spline with non-uniform knots (tangent
//!   `(p₍ᵢ₊₁₎ − p₍ᵢ₋₁₎)/(t₍ᵢ₊₁₎ − t₍ᵢ₋₁₎)`, one-sided at the ends), evaluated in cubic Hermite form;
//! - distance from the focal point and `parallel_scale`: the same spline on their logarithms, so
//!   zooms are smooth in ratio and stay positive; `view_angle` on its value;
//! - transfer functions: linearly, point by point after resampling both onto the union of their
//!   control-point positions (colours, opacities and gradient opacities; shading coefficients
//!   linearly).
//!
//! World frame and units as everywhere in volsplat (VTK's: world units, degrees).

use crate::error::{EngineError, Result};
use crate::scene::{CameraSpec, Clipping, CropBox, PlaneSpec};
use serde::{Deserialize, Serialize};
use std::path::Path;
use volsplat_core::glam::{DMat3, DQuat, DVec3};
use volsplat_core::{Camera, Orbit, TransferFunction};

/// Most frames of one movie: 100 000 frames are 69 minutes at 24 frames per second, 100 s at
/// the largest frame rate, 1000. Checked before anything is allocated per frame.
pub const MAX_MOVIE_FRAMES: usize = 100_000;

/// The axis of a turntable.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TurnAxis {
    /// The camera's own view-up vector (VTK's `Azimuth`). After an elevation this axis is
    /// tilted with the camera, so the view wobbles against the scene; [`scene_up`] gives the
    /// axis a turntable usually wants.
    ViewUp,
    /// A direction in world coordinates (LPS for medical volumes: +x left, +y posterior,
    /// +z superior); need not be unit length, must not be zero.
    World(DVec3),
}

/// Rotates `camera` (eye and view-up) by `degrees` about `axis` through its focal point,
/// right-handed: for `axis` = view-up this is VTK's `Azimuth(degrees)`.
pub fn rotate_camera(camera: &Camera, axis: DVec3, degrees: f64) -> Camera {
    let mut c = camera.clone();
    if degrees == 0.0 {
        return c;
    }
    let rot = DMat3::from_axis_angle(axis.normalize(), degrees.to_radians());
    let fp = DVec3::from(c.focal_point);
    c.position = (fp + rot * (DVec3::from(c.position) - fp)).to_array();
    c.view_up = (rot * DVec3::from(c.view_up)).to_array();
    c
}

/// The cameras of a turntable of `frames` frames starting at `base`: frame `i` is `base` turned
/// by `i·degrees/frames` about `axis` when `degrees` is a whole number of turns (the loop closes
/// without repeating frame 0), else by `i·degrees/(frames − 1)` (a sweep that ends at
/// `degrees`). Frame 0 is `base` exactly.
pub fn turntable(
    base: &Camera,
    axis: TurnAxis,
    degrees: f64,
    frames: usize,
) -> Result<Vec<Camera>> {
    if frames == 0 {
        return Err(EngineError::request(
            "frames",
            "a movie needs at least one frame",
        ));
    }
    if frames > MAX_MOVIE_FRAMES {
        return Err(EngineError::request(
            "frames",
            format!("{frames} frames; a movie holds at most {MAX_MOVIE_FRAMES}"),
        ));
    }
    if !degrees.is_finite() {
        return Err(EngineError::request(
            "degrees",
            format!("the sweep must be a finite angle, got {degrees}"),
        ));
    }
    let axis = match axis {
        TurnAxis::ViewUp => DVec3::from(base.view_up),
        TurnAxis::World(a) => a,
    };
    if !(axis.is_finite() && axis.length() > 1e-12) {
        return Err(EngineError::request(
            "axis",
            format!("the turntable axis must be a non-zero direction, got {axis:?}"),
        ));
    }
    let turns = degrees / 360.0;
    let closed = degrees != 0.0 && (turns - turns.round()).abs() < 1e-9;
    let step = if closed || frames == 1 {
        degrees / frames as f64
    } else {
        degrees / (frames - 1) as f64
    };
    Ok((0..frames)
        .map(|i| rotate_camera(base, axis, step * i as f64))
        .collect())
}

/// The scene's up direction for a turntable: the view-up of `spec` resolved without its orbit's
/// elevation and roll (the reset view's up, an anatomical view's up, or a camera file's, after
/// any azimuth), for a volume whose world bounds are `bounds`. A turntable about it keeps the
/// camera's elevation: every frame sees the axis at the same angle, and frame 0 is the camera of
/// `spec` itself.
pub fn scene_up(spec: &CameraSpec, bounds: (DVec3, DVec3)) -> Result<DVec3> {
    let mut level = spec.clone();
    let orbit = match &mut level {
        CameraSpec::Orbit(o) => o,
        CameraSpec::Explicit { orbit, .. } => orbit,
    };
    orbit.elevation = None;
    orbit.roll = None;
    Ok(DVec3::from(level.resolve(bounds)?.view_up).normalize())
}

/// One keyframe of a camera flight.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Keyframe {
    /// Time in seconds from the start of the movie (≥ 0, strictly increasing over the file).
    pub time: f64,
    /// The camera at this time (VTK camera-file object). Default: the movie's base camera (the
    /// render flags' camera).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<Camera>,
    /// A view change applied to `camera` (or the base camera): azimuth, elevation, roll, zoom,
    /// dolly, as `render`'s flags.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orbit: Option<Orbit>,
    /// The transfer function at this time (VTK transfer-function object). Keyframes without one
    /// use the movie's transfer function.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transfer_function: Option<TransferFunction>,
    /// Cropping and clipping at this time (the scene-file object). Keyframes without one use the
    /// movie's. Between keyframes the box corners and plane coefficients move linearly; the two
    /// keyframes must have the same kind of clipping (a box in the same units or none, and the
    /// same number of planes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clipping: Option<Clipping>,
}

/// A keyframe file: `{"fps": 24, "keyframes": [{"time": 0, "orbit": {...}}, ...]}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyframeFile {
    /// Frames per second (default: the command's `--fps`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    /// At least two keyframes in increasing time.
    pub keyframes: Vec<Keyframe>,
}

impl KeyframeFile {
    /// Reads a keyframe file (JSON, at most 16 MiB), naming the file and the field on error.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let scene_err = |message: String| EngineError::SceneFile {
            path: path.to_path_buf(),
            message,
        };
        let meta = std::fs::metadata(path).map_err(|e| scene_err(e.to_string()))?;
        if meta.len() > volsplat_io::MAX_JSON_BYTES {
            return Err(scene_err(format!(
                "{} bytes; keyframe files are limited to {} bytes",
                meta.len(),
                volsplat_io::MAX_JSON_BYTES
            )));
        }
        let text = std::fs::read_to_string(path).map_err(|e| scene_err(e.to_string()))?;
        let file: KeyframeFile =
            serde_json::from_str(&text).map_err(|e| scene_err(e.to_string()))?;
        file.check().map_err(|e| scene_err(e.to_string()))?;
        Ok(file)
    }

    fn check(&self) -> Result<()> {
        if self.keyframes.len() < 2 {
            return Err(EngineError::request(
                "keyframes",
                format!(
                    "a flight needs at least two keyframes, got {}",
                    self.keyframes.len()
                ),
            ));
        }
        if let Some(f) = self.fps
            && !(f.is_finite() && f > 0.0 && f <= 1000.0)
        {
            return Err(EngineError::request(
                "fps",
                format!("must be in (0, 1000], got {f}"),
            ));
        }
        let mut last = f64::NEG_INFINITY;
        for (i, k) in self.keyframes.iter().enumerate() {
            if !(k.time.is_finite() && k.time >= 0.0 && k.time > last) {
                return Err(EngineError::request(
                    format!("keyframes[{i}].time"),
                    format!(
                        "times must be finite, ≥ 0 and increasing; got {} after {last}",
                        k.time
                    ),
                ));
            }
            last = k.time;
            if let Some(o) = &k.orbit {
                o.validate().map_err(|e| {
                    EngineError::request(format!("keyframes[{i}].orbit"), e.to_string())
                })?;
            }
            if let Some(c) = &k.camera {
                c.validate().map_err(|e| {
                    EngineError::request(format!("keyframes[{i}].camera"), e.to_string())
                })?;
            }
            if let Some(tf) = &k.transfer_function {
                tf.clone().validate().map_err(|e| {
                    EngineError::request(format!("keyframes[{i}].transfer_function"), e.to_string())
                })?;
            }
        }
        Ok(())
    }

    /// Duration in seconds (first to last keyframe).
    pub fn duration(&self) -> f64 {
        match (self.keyframes.first(), self.keyframes.last()) {
            (Some(a), Some(b)) => b.time - a.time,
            _ => 0.0,
        }
    }
}

/// A camera reduced to what is interpolated.
#[derive(Debug, Clone, Copy)]
struct CamKey {
    time: f64,
    focal: DVec3,
    log_distance: f64,
    rotation: DQuat,
    view_angle: f64,
    log_parallel_scale: f64,
}

/// A smooth camera path through keyframed cameras (see the module docs).
#[derive(Debug, Clone)]
pub struct CameraPath {
    keys: Vec<CamKey>,
    parallel_projection: bool,
}

/// The rotation whose columns are the camera's right, up and backward (−forward) vectors.
fn frame_rotation(c: &Camera) -> DQuat {
    let f = c.frame();
    DQuat::from_mat3(&DMat3::from_cols(f.right, f.up, -f.forward)).normalize()
}

impl CameraPath {
    /// A path through `cameras` at `times` (seconds, increasing). Every camera must have the
    /// same projection (a path cannot morph orthographic into perspective).
    pub fn new(times: &[f64], cameras: &[Camera]) -> Result<Self> {
        if times.len() != cameras.len() || cameras.is_empty() {
            return Err(EngineError::request(
                "keyframes",
                "a camera path needs as many times as cameras, and at least one",
            ));
        }
        let parallel = cameras[0].parallel_projection;
        let mut keys: Vec<CamKey> = Vec::with_capacity(cameras.len());
        for (i, (c, &t)) in cameras.iter().zip(times).enumerate() {
            c.validate().map_err(|e| {
                EngineError::request(format!("keyframes[{i}].camera"), e.to_string())
            })?;
            if c.parallel_projection != parallel {
                return Err(EngineError::request(
                    format!("keyframes[{i}].camera.parallel_projection"),
                    "every keyframe must use the same projection as the first",
                ));
            }
            let f = c.frame();
            let mut rotation = frame_rotation(c);
            // Shorter arc: keep consecutive quaternions in the same hemisphere.
            if let Some(prev) = keys.last()
                && prev.rotation.dot(rotation) < 0.0
            {
                rotation = -rotation;
            }
            keys.push(CamKey {
                time: t,
                focal: f.focal,
                log_distance: (f.focal - f.eye).length().ln(),
                rotation,
                view_angle: c.view_angle,
                log_parallel_scale: c.parallel_scale.ln(),
            });
        }
        Ok(CameraPath {
            keys,
            parallel_projection: parallel,
        })
    }

    /// The camera at time `t` (seconds; clamped to the keyframes' span). At a keyframe's time
    /// the camera is that keyframe's (up to rounding).
    pub fn sample(&self, t: f64) -> Camera {
        let k = &self.keys;
        let n = k.len();
        let (i, u) = if n == 1 || t <= k[0].time {
            (0, 0.0)
        } else if t >= k[n - 1].time {
            (n - 2, 1.0)
        } else {
            // The last key at or before t (binary search; t is inside the span here).
            let i = k
                .partition_point(|key| key.time <= t)
                .saturating_sub(1)
                .min(n - 2);
            (i, (t - k[i].time) / (k[i + 1].time - k[i].time))
        };
        let j = (i + 1).min(n - 1);
        // Cubic Hermite between keys i and j with Catmull–Rom tangents for non-uniform times.
        let hermite = |get: &dyn Fn(&CamKey) -> [f64; 4]| -> [f64; 4] {
            if i == j {
                return get(&k[i]);
            }
            let tangent = |idx: usize| -> [f64; 4] {
                let (a, b) = (idx.saturating_sub(1), (idx + 1).min(n - 1));
                let (pa, pb) = (get(&k[a]), get(&k[b]));
                let dt = k[b].time - k[a].time;
                std::array::from_fn(|c| (pb[c] - pa[c]) / dt)
            };
            let h = k[j].time - k[i].time;
            let (u2, u3) = (u * u, u * u * u);
            let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
            let h10 = u3 - 2.0 * u2 + u;
            let h01 = -2.0 * u3 + 3.0 * u2;
            let h11 = u3 - u2;
            let (p0, p1, m0, m1) = (get(&k[i]), get(&k[j]), tangent(i), tangent(j));
            std::array::from_fn(|c| {
                p0[c] * h00 + m0[c] * (h10 * h) + p1[c] * h01 + m1[c] * (h11 * h)
            })
        };
        let focal = hermite(&|c| [c.focal.x, c.focal.y, c.focal.z, 0.0]);
        let focal = DVec3::new(focal[0], focal[1], focal[2]);
        let scalars = hermite(&|c| [c.log_distance, c.view_angle, c.log_parallel_scale, 0.0]);
        // Orientation: the same spline on the (hemisphere-aligned) quaternion components, then
        // normalised — a rotation spline with continuous angular velocity that passes through
        // every key exactly (piecewise slerp jumps in speed at the keys).
        let q = hermite(&|c| c.rotation.to_array());
        let rotation = DQuat::from_array(q).normalize();
        let m = DMat3::from_quat(rotation);
        let (up, back) = (m.col(1), m.col(2));
        let distance = scalars[0].exp();
        Camera {
            position: (focal + back * distance).to_array(),
            focal_point: focal.to_array(),
            view_up: up.to_array(),
            view_angle: scalars[1].clamp(1e-3, 179.0),
            parallel_projection: self.parallel_projection,
            parallel_scale: scalars[2].exp(),
        }
    }
}

/// Piecewise-linear rows resampled at `xs` (constant beyond the ends).
fn resample<const M: usize>(rows: &[[f64; M]], xs: &[f64]) -> Vec<[f64; M]> {
    xs.iter()
        .map(|&x| volsplat_core::transfer::interpolate_rows(rows, x))
        .collect()
}

fn union_x<const M: usize>(a: &[[f64; M]], b: &[[f64; M]]) -> Vec<f64> {
    let mut xs: Vec<f64> = a.iter().chain(b).map(|r| r[0]).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    xs
}

fn lerp_rows<const M: usize>(a: &[[f64; M]], b: &[[f64; M]], u: f64) -> Vec<[f64; M]> {
    let xs = union_x(a, b);
    let (ra, rb) = (resample(a, &xs), resample(b, &xs));
    ra.iter()
        .zip(&rb)
        .map(|(p, q)| {
            let mut r = *p;
            for c in 1..M {
                r[c] = p[c] + (q[c] - p[c]) * u;
            }
            r
        })
        .collect()
}

/// The transfer function a fraction `u` ∈ [0, 1] of the way from `a` to `b` (see the module
/// docs). `u = 0` gives `a`'s curves resampled (the same function), `u = 1` gives `b`'s.
pub fn lerp_transfer_function(
    a: &TransferFunction,
    b: &TransferFunction,
    u: f64,
) -> TransferFunction {
    let u = u.clamp(0.0, 1.0);
    let mix = |x: f64, y: f64| x + (y - x) * u;
    let gradient_opacity = match (&a.gradient_opacity, &b.gradient_opacity) {
        (None, None) => None,
        (ga, gb) => {
            let one = vec![[0.0, 1.0]];
            Some(lerp_rows(
                ga.as_ref().unwrap_or(&one),
                gb.as_ref().unwrap_or(&one),
                u,
            ))
        }
    };
    TransferFunction {
        color: lerp_rows(&a.color, &b.color, u),
        scalar_opacity: lerp_rows(&a.scalar_opacity, &b.scalar_opacity, u),
        gradient_opacity,
        scalar_opacity_unit_distance: mix(
            a.scalar_opacity_unit_distance,
            b.scalar_opacity_unit_distance,
        ),
        shade: if u < 0.5 { a.shade } else { b.shade },
        ambient: mix(a.ambient, b.ambient),
        diffuse: mix(a.diffuse, b.diffuse),
        specular: mix(a.specular, b.specular),
        specular_power: mix(a.specular_power, b.specular_power),
    }
}

/// One frame of a keyframed movie: its time, camera and transfer function (`None`: the movie's
/// own).
#[derive(Debug, Clone)]
pub struct FlightFrame {
    /// Seconds from the first keyframe.
    pub time: f64,
    /// The camera.
    pub camera: Camera,
    /// The transfer function, when the keyframes set one.
    pub transfer_function: Option<TransferFunction>,
    /// The clipping, when the keyframes set one.
    pub clipping: Option<Clipping>,
}

/// The clipping a fraction `u` ∈ [0, 1] of the way from `a` to `b`: corners and plane
/// coefficients linearly. Errors (naming `field`) if the two differ in kind.
pub fn lerp_clipping(a: &Clipping, b: &Clipping, u: f64, field: &str) -> Result<Clipping> {
    let mix = |x: f64, y: f64| x + (y - x) * u;
    let mix3 = |x: [f64; 3], y: [f64; 3]| [mix(x[0], y[0]), mix(x[1], y[1]), mix(x[2], y[2])];
    let crop = match (&a.crop, &b.crop) {
        (None, None) => None,
        (Some(p), Some(q)) if p.units == q.units => Some(CropBox {
            min: mix3(p.min, q.min),
            max: mix3(p.max, q.max),
            units: p.units,
        }),
        _ => {
            return Err(EngineError::request(
                field,
                "consecutive keyframes need the same kind of crop box (both none, or both in \
                 the same units) to move between them",
            ));
        }
    };
    if a.planes.len() != b.planes.len() {
        return Err(EngineError::request(
            field,
            format!(
                "consecutive keyframes need the same number of clipping planes ({} and {})",
                a.planes.len(),
                b.planes.len()
            ),
        ));
    }
    let planes = a
        .planes
        .iter()
        .zip(&b.planes)
        .map(|(p, q)| PlaneSpec {
            normal: mix3(p.normal, q.normal),
            offset: mix(p.offset, q.offset),
        })
        .collect();
    Ok(Clipping { crop, planes })
}

/// A nested error's text without the outer "invalid request: " (`scene.clipping.crop: axis 0: …`).
fn inner(e: EngineError) -> String {
    match e {
        EngineError::Request { field, message } => format!("{field}: {message}"),
        e => e.to_string(),
    }
}

/// `x` for a message: as is up to 1e12, in scientific notation above (`1e300`, not 301 digits).
fn short(x: f64) -> String {
    if x.abs() < 1e12 {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// A keyframed flight, frame by frame: [`Flight::new`] checks the whole flight before anything
/// is rendered, and [`Flight::frame`] interpolates one frame when it is needed, so memory does
/// not grow with the number of frames (two 1000-point transfer functions over 100 000 frames
/// would otherwise hold gigabytes).
///
/// Frame `n` is at time `t₀ + n/fps`, up to the last keyframe. Keyframe cameras default to the
/// movie's base camera (then their orbit is applied), keyframe transfer functions and clipping
/// to the movie's.
#[derive(Debug, Clone)]
pub struct Flight {
    times: Vec<f64>,
    cameras: Vec<Camera>,
    path: CameraPath,
    /// Every keyframe's transfer function, when any keyframe sets one.
    tfs: Option<Vec<TransferFunction>>,
    /// Every keyframe's clipping, when any keyframe sets one.
    clips: Option<Vec<Clipping>>,
    fps: f64,
    count: usize,
}

impl Flight {
    /// The flight of `file` from the base camera, transfer function and clipping, at the file's
    /// frame rate or else `fps` (in (0, 1000]). Errors (naming the keyframe or the frame and its
    /// time) if the file is invalid, the flight has more than [`MAX_MOVIE_FRAMES`] frames, two
    /// consecutive keyframes' clippings differ in kind, or any frame's camera or clipping is
    /// invalid (a crop box turned inside out, a plane whose normal passes through zero): the
    /// whole flight is checked before the first frame is rendered.
    pub fn new(
        file: &KeyframeFile,
        base: &Camera,
        base_tf: &TransferFunction,
        base_clipping: &Clipping,
        fps: f64,
    ) -> Result<Flight> {
        file.check()?;
        let fps = file.fps.unwrap_or(fps);
        if !(fps.is_finite() && fps > 0.0 && fps <= 1000.0) {
            return Err(EngineError::request(
                "fps",
                format!("must be in (0, 1000], got {fps}"),
            ));
        }
        // Counted in floating point, so that a duration of 1e300 s is refused rather than
        // wrapping to zero frames.
        let frames = (file.duration() * fps + 1e-9).floor() + 1.0;
        if frames.is_nan() || frames > MAX_MOVIE_FRAMES as f64 {
            return Err(EngineError::request(
                "keyframes",
                format!(
                    "the flight lasts {} s, {} frames at {fps} fps; a movie holds at most \
                     {MAX_MOVIE_FRAMES} frames (shorten it or lower the frame rate)",
                    short(file.duration()),
                    short(frames)
                ),
            ));
        }
        let mut cameras = Vec::with_capacity(file.keyframes.len());
        for (i, k) in file.keyframes.iter().enumerate() {
            let mut c = k.camera.clone().unwrap_or_else(|| base.clone());
            if let Some(o) = &k.orbit {
                o.apply(&mut c).map_err(|e| {
                    EngineError::request(format!("keyframes[{i}].orbit"), e.to_string())
                })?;
            }
            cameras.push(c);
        }
        let times: Vec<f64> = file.keyframes.iter().map(|k| k.time).collect();
        let path = CameraPath::new(&times, &cameras)?;
        let tfs = file
            .keyframes
            .iter()
            .any(|k| k.transfer_function.is_some())
            .then(|| {
                file.keyframes
                    .iter()
                    .map(|k| {
                        k.transfer_function
                            .clone()
                            .unwrap_or_else(|| base_tf.clone())
                    })
                    .collect::<Vec<_>>()
            });
        let clips = file
            .keyframes
            .iter()
            .any(|k| k.clipping.is_some())
            .then(|| {
                file.keyframes
                    .iter()
                    .map(|k| k.clipping.clone().unwrap_or_else(|| base_clipping.clone()))
                    .collect::<Vec<_>>()
            });
        if let Some(clips) = &clips {
            for (i, c) in clips.iter().enumerate() {
                c.validate().map_err(|e| {
                    EngineError::request(format!("keyframes[{i}].clipping"), inner(e))
                })?;
            }
            for i in 0..clips.len() - 1 {
                lerp_clipping(
                    &clips[i],
                    &clips[i + 1],
                    0.5,
                    &format!("keyframes[{}].clipping", i + 1),
                )?;
            }
        }
        let flight = Flight {
            times,
            cameras,
            path,
            tfs,
            clips,
            fps,
            count: frames as usize,
        };
        flight.check_frames()?;
        Ok(flight)
    }

    /// Checks every frame's camera and clipping. Transfer functions need no check: a blend of
    /// two valid functions is valid (positions are the union of theirs, every value a convex
    /// combination of values in range).
    fn check_frames(&self) -> Result<()> {
        for n in 0..self.count {
            let t = self.time(n);
            let at = |what: &str| format!("frame {n} (t = {t:.3} s) {what}");
            self.camera(t)
                .validate()
                .map_err(|e| EngineError::request(at("camera"), e.to_string()))?;
            if let Some(c) = self.clipping(t)? {
                c.validate().map_err(|e| {
                    EngineError::request(
                        at("clipping"),
                        format!("{} (the keyframes' clippings move linearly)", inner(e)),
                    )
                })?;
            }
        }
        Ok(())
    }

    /// Number of frames (1..=[`MAX_MOVIE_FRAMES`]).
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether the flight has no frames (never: it has at least one).
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Frames per second.
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// The absolute time of frame `n`, seconds.
    fn time(&self, n: usize) -> f64 {
        self.times[0] + n as f64 / self.fps
    }

    /// The keyframe segment `i` holding time `t` and the fraction `u` ∈ [0, 1] of the way
    /// through it.
    fn segment(&self, t: f64) -> (usize, f64) {
        let times = &self.times;
        // Binary search: a flight may have many keyframes and many frames.
        let i = times
            .partition_point(|&kt| kt <= t)
            .saturating_sub(1)
            .min(times.len() - 2);
        let u = ((t - times[i]) / (times[i + 1] - times[i])).clamp(0.0, 1.0);
        (i, u)
    }

    fn camera(&self, t: f64) -> Camera {
        // Keyframe times land exactly on their keyframe camera.
        match self
            .times
            .binary_search_by(|kt| kt.partial_cmp(&t).unwrap_or(std::cmp::Ordering::Less))
        {
            Ok(i) => self.cameras[i].clone(),
            Err(_) => self.path.sample(t),
        }
    }

    fn clipping(&self, t: f64) -> Result<Option<Clipping>> {
        let Some(clips) = &self.clips else {
            return Ok(None);
        };
        let (i, u) = self.segment(t);
        lerp_clipping(&clips[i], &clips[i + 1], u, "keyframes").map(Some)
    }

    /// Frame `n` (clamped to the last frame): its time, camera, and transfer function and
    /// clipping when the keyframes set them.
    pub fn frame(&self, n: usize) -> FlightFrame {
        let n = n.min(self.count - 1);
        let t = self.time(n);
        let transfer_function = self.tfs.as_ref().map(|tfs| {
            let (i, u) = self.segment(t);
            if u == 0.0 {
                tfs[i].clone()
            } else {
                lerp_transfer_function(&tfs[i], &tfs[i + 1], u)
            }
        });
        // Consecutive clippings were checked to be of one kind in `new`.
        let clipping = self.clipping(t).ok().flatten();
        FlightFrame {
            time: t - self.times[0],
            camera: self.camera(t),
            transfer_function,
            clipping,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::reset_to_bounds(DVec3::splat(-1.0), DVec3::splat(1.0), false)
    }

    #[test]
    fn a_turntable_about_view_up_is_vtks_azimuth_and_closes_the_loop() {
        let base = cam();
        let frames = turntable(&base, TurnAxis::ViewUp, 360.0, 8).unwrap();
        assert_eq!(frames.len(), 8);
        assert_eq!(frames[0], base);
        for (i, f) in frames.iter().enumerate() {
            let mut a = base.clone();
            a.azimuth(45.0 * i as f64);
            for c in 0..3 {
                assert!((f.position[c] - a.position[c]).abs() < 1e-9, "{i}");
            }
        }
        // A partial sweep ends at its angle.
        let sweep = turntable(&base, TurnAxis::ViewUp, 90.0, 4).unwrap();
        let mut end = base.clone();
        end.azimuth(90.0);
        let last = sweep.last().unwrap();
        assert!((DVec3::from(last.position) - DVec3::from(end.position)).length() < 1e-9);
    }

    #[test]
    fn a_turntable_about_a_world_axis_keeps_the_distance_and_turns_view_up() {
        let base = cam();
        let frames = turntable(&base, TurnAxis::World(DVec3::X), 360.0, 4).unwrap();
        let d0 = (DVec3::from(base.position) - DVec3::from(base.focal_point)).length();
        for f in &frames {
            let d = (DVec3::from(f.position) - DVec3::from(f.focal_point)).length();
            assert!((d - d0).abs() < 1e-9);
            // view-up stays perpendicular to the view direction.
            let fr = f.frame();
            assert!(fr.forward.dot(DVec3::from(f.view_up)).abs() < 1e-9);
        }
        // A quarter turn about +x takes the eye from +z to −y (right-handed).
        let eye = DVec3::from(frames[1].position) - DVec3::from(frames[1].focal_point);
        assert!(eye.y < -0.99 * d0, "{eye:?}");
        assert!(turntable(&base, TurnAxis::World(DVec3::ZERO), 360.0, 4).is_err());
        assert!(turntable(&base, TurnAxis::ViewUp, 360.0, 0).is_err());
    }

    #[test]
    fn a_camera_path_passes_through_its_keys_and_moves_smoothly() {
        let a = cam();
        let mut b = a.clone();
        b.azimuth(90.0);
        b.zoom(2.0);
        let mut c = b.clone();
        c.elevation(40.0);
        c.orthogonalize_view_up();
        let path = CameraPath::new(&[0.0, 1.0, 3.0], &[a.clone(), b.clone(), c.clone()]).unwrap();
        for (t, want) in [(0.0, &a), (1.0, &b), (3.0, &c)] {
            let got = path.sample(t);
            let d = DVec3::from(got.position) - DVec3::from(want.position);
            assert!(d.length() < 1e-9, "t = {t}: {d:?}");
            assert!((got.view_angle - want.view_angle).abs() < 1e-9);
        }
        // Smooth: the eye's step between samples changes little from one step to the next.
        let eyes: Vec<DVec3> = (0..=300)
            .map(|n| DVec3::from(path.sample(n as f64 * 0.01).position))
            .collect();
        let steps: Vec<DVec3> = eyes.windows(2).map(|w| w[1] - w[0]).collect();
        let worst = steps
            .windows(2)
            .map(|w| (w[1] - w[0]).length())
            .fold(0.0, f64::max);
        let typical = steps.iter().map(|s| s.length()).fold(0.0, f64::max);
        assert!(worst < 0.2 * typical, "{worst} vs {typical}");
        // The distance to the focal point stays between the keys' (no overshoot for equal keys).
        let d = |c: &Camera| (DVec3::from(c.position) - DVec3::from(c.focal_point)).length();
        for n in 0..=30 {
            let s = path.sample(n as f64 * 0.1);
            assert!((d(&s) - d(&a)).abs() < 1e-6, "{}", d(&s));
        }
    }

    #[test]
    fn transfer_functions_blend_point_by_point() {
        let mut a = TransferFunction::ramp(0.0, 100.0, 1.0);
        a.scalar_opacity = vec![[0.0, 0.0], [100.0, 1.0]];
        let mut b = a.clone();
        b.scalar_opacity = vec![[50.0, 0.0], [60.0, 0.5]];
        let m = lerp_transfer_function(&a, &b, 0.5);
        for x in [0.0, 25.0, 50.0, 55.0, 60.0, 80.0, 100.0] {
            let want = 0.5 * (a.opacity_at(x) + b.opacity_at(x));
            assert!((m.opacity_at(x) - want).abs() < 1e-12, "{x}");
        }
        let e = lerp_transfer_function(&a, &b, 0.0);
        for x in [0.0, 33.0, 100.0] {
            assert_eq!(e.opacity_at(x), a.opacity_at(x));
        }
    }

    #[test]
    fn keyframe_files_are_checked() {
        let bad = KeyframeFile {
            fps: None,
            keyframes: vec![
                Keyframe {
                    time: 1.0,
                    camera: None,
                    orbit: None,
                    transfer_function: None,
                    clipping: None,
                },
                Keyframe {
                    time: 0.5,
                    camera: None,
                    orbit: None,
                    transfer_function: None,
                    clipping: None,
                },
            ],
        };
        let e = bad.check().unwrap_err().to_string();
        assert!(e.contains("keyframes[1].time"), "{e}");
        let ok = KeyframeFile {
            fps: Some(10.0),
            keyframes: vec![
                Keyframe {
                    time: 0.0,
                    camera: None,
                    orbit: None,
                    transfer_function: None,
                    clipping: None,
                },
                Keyframe {
                    time: 2.0,
                    camera: None,
                    orbit: Some(Orbit {
                        azimuth: Some(90.0),
                        ..Orbit::default()
                    }),
                    transfer_function: None,
                    clipping: None,
                },
            ],
        };
        let base = cam();
        let flight = Flight::new(
            &ok,
            &base,
            &TransferFunction::ramp(0.0, 100.0, 1.0),
            &Clipping::default(),
            24.0,
        )
        .unwrap();
        assert_eq!(flight.len(), 21);
        assert_eq!(flight.frame(0).camera, base);
        let mut end = base.clone();
        end.azimuth(90.0);
        let last = &flight.frame(20).camera;
        assert!((DVec3::from(last.position) - DVec3::from(end.position)).length() < 1e-9);
        assert!((0..21).all(|n| flight.frame(n).transfer_function.is_none()));
    }

    fn key(time: f64) -> Keyframe {
        Keyframe {
            time,
            camera: None,
            orbit: None,
            transfer_function: None,
            clipping: None,
        }
    }

    fn fly(keys: Vec<Keyframe>, fps: f64) -> Result<Flight> {
        let file = KeyframeFile {
            fps: None,
            keyframes: keys,
        };
        Flight::new(
            &file,
            &cam(),
            &TransferFunction::ramp(0.0, 100.0, 1.0),
            &Clipping::default(),
            fps,
        )
    }

    /// Issue 28: a last keyframe at 1e300 s wrapped the frame count to 0; now the count is
    /// compared in floating point and refused with the cap named.
    #[test]
    fn an_endless_flight_is_refused_not_wrapped() {
        for (end, fps) in [
            (1e300, 24.0),
            (f64::MAX / 2.0, 1000.0),
            (100_000.0 / 24.0, 24.0),
        ] {
            let e = fly(vec![key(0.0), key(end)], fps).unwrap_err().to_string();
            assert!(e.contains("at most 100000 frames"), "{end}: {e}");
        }
        // Just under the cap is fine and reports its length.
        let f = fly(vec![key(0.0), key(99_999.0 / 1000.0)], 1000.0).unwrap();
        assert_eq!(f.len(), MAX_MOVIE_FRAMES);
        assert!(turntable(&cam(), TurnAxis::ViewUp, 360.0, MAX_MOVIE_FRAMES + 1).is_err());
    }

    /// Issue 28: two 1000-point transfer functions over many frames were blended for every
    /// frame up front (3.6 GB at 1000 fps over 999 s). The flight keeps the keyframes' functions
    /// only and blends one frame when asked; each blend equals the pointwise mix.
    #[test]
    fn transfer_functions_are_blended_per_frame_not_stored() {
        let big = |shift: f64| {
            let mut tf = TransferFunction::ramp(0.0, 1000.0, 1.0);
            tf.scalar_opacity = (0..1000)
                .map(|i| [i as f64 + shift, ((i as f64 * 0.37).sin() * 0.5 + 0.5)])
                .collect();
            tf
        };
        let (a, b) = (big(0.0), big(0.5));
        let mut k0 = key(0.0);
        k0.transfer_function = Some(a.clone());
        let mut k1 = key(99.0);
        k1.transfer_function = Some(b.clone());
        let e = fly(
            vec![k0.clone(), {
                let mut k = k1.clone();
                k.time = 999.0;
                k
            }],
            1000.0,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("at most 100000 frames"), "{e}");
        let f = fly(vec![k0, k1], 1000.0).unwrap();
        assert_eq!(f.len(), 99_001);
        assert_eq!(f.tfs.as_ref().map(Vec::len), Some(2));
        let mid = f.frame(49_500).transfer_function.unwrap();
        for x in [0.0, 10.25, 499.5, 998.0] {
            let want = 0.5 * (a.opacity_at(x) + b.opacity_at(x));
            assert!((mid.opacity_at(x) - want).abs() < 1e-9, "{x}");
        }
        assert_eq!(f.frame(0).transfer_function.unwrap(), a);
    }

    /// Issue 28: a crop box inverted at a later keyframe, or planes whose normals pass through
    /// zero between two keyframes, used to fail at that frame after the earlier ones were
    /// written; the whole flight is checked first, naming the keyframe or the frame.
    #[test]
    fn a_flight_is_checked_whole_before_the_first_frame() {
        let boxed = |min: f64, max: f64| Clipping {
            crop: Some(CropBox {
                min: [min; 3],
                max: [max; 3],
                units: crate::scene::CropUnits::Voxels,
            }),
            planes: Vec::new(),
        };
        let mut keys = vec![key(0.0), key(1.0), key(2.0)];
        keys[0].clipping = Some(boxed(0.0, 10.0));
        keys[1].clipping = Some(boxed(2.0, 8.0));
        keys[2].clipping = Some(boxed(9.0, 1.0));
        let e = fly(keys, 24.0).unwrap_err().to_string();
        assert!(
            e.contains("keyframes[2].clipping") && e.contains("min ≤ max"),
            "{e}"
        );
        let plane = |nx: f64| Clipping {
            crop: None,
            planes: vec![PlaneSpec {
                normal: [nx, 0.0, 0.0],
                offset: 0.0,
            }],
        };
        let mut keys = vec![key(0.0), key(2.0)];
        keys[0].clipping = Some(plane(1.0));
        keys[1].clipping = Some(plane(-1.0));
        let e = fly(keys, 24.0).unwrap_err().to_string();
        // Halfway, at frame 24 (t = 1 s), the normal is zero.
        assert!(e.contains("frame 24 (t = 1.000 s) clipping"), "{e}");
        assert!(e.contains("non-zero normal"), "{e}");
        // Too many planes in a keyframe.
        let mut keys = vec![key(0.0), key(1.0)];
        keys[1].clipping = Some(Clipping {
            crop: None,
            planes: vec![
                PlaneSpec {
                    normal: [1.0, 0.0, 0.0],
                    offset: 0.0
                };
                crate::scene::MAX_CLIP_PLANES + 1
            ],
        });
        keys[0].clipping = keys[1].clipping.clone();
        let e = fly(keys, 24.0).unwrap_err().to_string();
        assert!(
            e.contains("keyframes[0].clipping") && e.contains("at most 64"),
            "{e}"
        );
    }

    /// Issue 28: the README's turntable (`--elevation 20`) turned about the tilted camera's
    /// view-up and wobbled. About the scene's up, every frame keeps the elevation, and frame k
    /// is the camera that `azimuth(k·step)` then `elevation(20)` gives.
    #[test]
    fn a_turntable_about_the_scene_up_keeps_the_elevation() {
        let bounds = (DVec3::new(-1.0, -2.0, -3.0), DVec3::new(2.0, 1.0, 0.5));
        let orbit = |az: f64| Orbit {
            azimuth: Some(az),
            elevation: Some(20.0),
            ..Orbit::default()
        };
        let spec = CameraSpec::Orbit(orbit(10.0));
        let base = spec.resolve(bounds).unwrap();
        let up = scene_up(&spec, bounds).unwrap();
        assert!((up - DVec3::Y).length() < 1e-12, "{up:?}");
        let frames = turntable(&base, TurnAxis::World(up), 360.0, 8).unwrap();
        assert_eq!(frames[0], base);
        let elevation = |c: &Camera| {
            let f = c.frame();
            (-f.forward).dot(up).asin().to_degrees()
        };
        for (k, f) in frames.iter().enumerate() {
            assert!((elevation(f) - 20.0).abs() < 1e-9, "{k}: {}", elevation(f));
            let want = CameraSpec::Orbit(orbit(10.0 + 45.0 * k as f64))
                .resolve(bounds)
                .unwrap();
            let d = DVec3::from(f.position) - DVec3::from(want.position);
            let u = DVec3::from(f.view_up) - DVec3::from(want.view_up);
            assert!(d.length() < 1e-9 && u.length() < 1e-9, "{k}: {d:?} {u:?}");
        }
        // About the camera's own (tilted) view-up the elevation wobbles: what the fix removed.
        let wobbly = turntable(&base, TurnAxis::ViewUp, 360.0, 8).unwrap();
        let spread = wobbly
            .iter()
            .map(elevation)
            .fold((f64::MAX, f64::MIN), |(lo, hi), e| (lo.min(e), hi.max(e)));
        assert!(spread.1 - spread.0 > 10.0, "{spread:?}");
    }
}
