//! The renderer (GIL released, Ctrl-C and progress callbacks served from the calling thread)
//! and its output.
//!
//! A render runs on a scoped worker thread (which uses the engine's own thread pool). The
//! calling thread waits for it with the GIL released, waking every `poll_interval` seconds to
//! run Python's signal handlers (`Ctrl-C` raises `KeyboardInterrupt` there, on the main thread)
//! and to hand the latest progress to the caller's callback. Either sets a flag that the
//! engine's progress callback returns, so the engine stops at its next progress report (after
//! the current batch of sheets). No Python code ever runs on the worker.

use crate::convert;
use crate::errors::{self, Kind, invalid};
use crate::volume::Volume;
use numpy::PyArray1;
use numpy::ndarray::{ArrayView2, ArrayView3};
use numpy::prelude::*;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;
use volsplat::core::{Camera, Image, ScalarImage, TransferFunction};
use volsplat::io::{PngBitDepth, PngSettings};
use volsplat::{EngineError, Mode, RenderRequest, Stats, VolumeSource};

/// Locks a mutex, recovering the data of a poisoned one (a panic elsewhere is reported by
/// whoever caught it; the data here is plain state).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    match m.lock() {
        Ok(g) => g,
        Err(p) => p.into_inner(),
    }
}

/// The request of `request_json` (the engine's `RenderRequest` JSON), with `volume` (if given)
/// as its volume. Unknown fields are errors naming their path (a Python caller wrote them).
pub fn parse_request(request_json: &str, volume: Option<&Volume>) -> PyResult<RenderRequest> {
    let mut value: serde_json::Value = serde_json::from_str(request_json)
        .map_err(|e| invalid(format!("render request: not valid JSON: {e}")))?;
    let Some(obj) = value.as_object_mut() else {
        return Err(invalid("render request: expected a JSON object"));
    };
    let scene = obj.entry("scene").or_insert_with(|| serde_json::json!({}));
    let Some(scene) = scene.as_object_mut() else {
        return Err(invalid("render request: `scene` must be an object"));
    };
    if volume.is_some() || !scene.contains_key("volume") {
        // A placeholder (replaced below), or the engine's demo phantom when there is no volume
        // (what the command line renders without an input).
        let demo = serde_json::to_value(VolumeSource::default())
            .map_err(|e| errors::error(Kind::Render, e.to_string()))?;
        scene.insert("volume".into(), demo);
    }
    let mut unknown = Vec::new();
    let mut track = |p: serde_ignored::Path<'_>| unknown.push(p.to_string().replace(".?", ""));
    let de = serde_ignored::Deserializer::new(value, &mut track);
    let mut req: RenderRequest = serde_path_to_error::deserialize(de).map_err(|e| {
        invalid(format!(
            "render request: {}: {}",
            field_path(e.path()),
            e.inner()
        ))
    })?;
    if !unknown.is_empty() {
        return Err(invalid(format!(
            "render request: unknown option{} {}",
            if unknown.len() == 1 { "" } else { "s" },
            unknown.join(", ")
        )));
    }
    if let Some(v) = volume {
        req.scene.volume = match &v.source {
            // A phantom renders as the command line renders it (its own transfer function).
            Some(s @ VolumeSource::Phantom { .. }) => s.clone(),
            _ => VolumeSource::Memory(Arc::clone(&v.data)),
        };
    }
    Ok(req)
}

/// A serde path as a scene file spells it (`quality.kernel`), without enum variant markers.
pub fn field_path(p: &serde_path_to_error::Path) -> String {
    let s = p.to_string().replace(".?", "");
    if s == "." || s.is_empty() {
        "(top level)".into()
    } else {
        s
    }
}

/// The request as JSON, its volume left out when it is in memory.
fn request_json(req: &RenderRequest) -> PyResult<String> {
    let mut r = req.clone();
    let memory = matches!(r.scene.volume, VolumeSource::Memory(_));
    if memory {
        r.scene.volume = VolumeSource::default();
    }
    let mut v = serde_json::to_value(&r).map_err(|e| errors::error(Kind::Render, e.to_string()))?;
    if memory && let Some(s) = v.get_mut("scene").and_then(|s| s.as_object_mut()) {
        s.remove("volume");
    }
    Ok(v.to_string())
}

enum WorkerError {
    Engine(EngineError),
    Panic(String),
}

#[derive(Default)]
struct SharedState {
    result: Option<Result<volsplat::Output, WorkerError>>,
    progress: Option<(f64, &'static str)>,
}

struct Shared {
    state: Mutex<SharedState>,
    done: Condvar,
    cancel: AtomicBool,
}

fn panic_message(payload: Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".into()
    }
}

/// The engine's reusable renderer. Public API: `volsplat.Renderer`.
#[pyclass(frozen, module = "volsplat._volsplat")]
pub struct RendererCore {
    inner: Mutex<volsplat::Renderer>,
    limits: volsplat::io::Limits,
}

impl RendererCore {
    /// Runs `f` on the engine renderer; a renderer poisoned by a crash starts afresh.
    fn with_renderer<R>(&self, f: impl FnOnce(&mut volsplat::Renderer) -> R) -> R {
        let mut guard = match self.inner.lock() {
            Ok(g) => g,
            Err(p) => {
                let mut g = p.into_inner();
                *g = volsplat::Renderer::with_limits(self.limits.clone());
                self.inner.clear_poison();
                g
            }
        };
        f(&mut guard)
    }
}

#[pymethods]
impl RendererCore {
    #[new]
    #[pyo3(signature = (*, max_voxels=None))]
    fn new(max_voxels: Option<u128>) -> Self {
        let mut limits = volsplat::io::Limits::default();
        if let Some(m) = max_voxels {
            limits.max_voxels = m;
        }
        RendererCore {
            inner: Mutex::new(volsplat::Renderer::with_limits(limits.clone())),
            limits,
        }
    }

    /// Renders `request_json` (a `RenderRequest`; its volume is `volume` when given).
    #[pyo3(signature = (request_json, volume=None, progress=None, poll_interval=0.05))]
    fn render(
        &self,
        py: Python<'_>,
        request_json: &str,
        volume: Option<PyRef<'_, Volume>>,
        progress: Option<Bound<'_, PyAny>>,
        poll_interval: f64,
    ) -> PyResult<Output> {
        let req = parse_request(request_json, volume.as_deref())?;
        drop(volume);
        if !(poll_interval.is_finite() && poll_interval > 0.0) {
            return Err(invalid(format!(
                "poll_interval must be a positive number of seconds, got {poll_interval}"
            )));
        }
        let poll = Duration::from_secs_f64(poll_interval.min(1.0));
        let shared = Shared {
            state: Mutex::new(SharedState::default()),
            done: Condvar::new(),
            cancel: AtomicBool::new(false),
        };
        let mut pending: Option<PyErr> = None;
        let result = std::thread::scope(|s| {
            s.spawn(|| {
                let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    self.with_renderer(|r| {
                        r.render(&req, &mut |p| {
                            lock(&shared.state).progress = Some((p.fraction, p.stage.as_str()));
                            !shared.cancel.load(Ordering::Relaxed)
                        })
                    })
                }));
                let r = match r {
                    Ok(r) => r.map_err(WorkerError::Engine),
                    Err(payload) => Err(WorkerError::Panic(panic_message(payload))),
                };
                lock(&shared.state).result = Some(r);
                shared.done.notify_all();
            });
            loop {
                let (result, latest) = py.detach(|| {
                    let mut st = lock(&shared.state);
                    if st.result.is_none() {
                        st = match shared.done.wait_timeout(st, poll) {
                            Ok((g, _)) => g,
                            Err(p) => p.into_inner().0,
                        };
                    }
                    (st.result.take(), st.progress.take())
                });
                if let Some(r) = result {
                    break (r, latest);
                }
                if pending.is_some() {
                    continue;
                }
                if let Err(e) = py.check_signals() {
                    shared.cancel.store(true, Ordering::Relaxed);
                    pending = Some(e);
                    continue;
                }
                if let (Some(cb), Some((f, stage))) = (&progress, latest) {
                    match cb.call1((f, stage)) {
                        Ok(v) => {
                            if !v.is_none() && !v.is_truthy().unwrap_or(true) {
                                shared.cancel.store(true, Ordering::Relaxed);
                                pending = Some(errors::error(
                                    Kind::Cancelled,
                                    "render cancelled by the progress callback",
                                ));
                            }
                        }
                        Err(e) => {
                            shared.cancel.store(true, Ordering::Relaxed);
                            pending = Some(e);
                        }
                    }
                }
            }
        });
        if let Some(e) = pending {
            return Err(e);
        }
        let (result, latest) = result;
        let out = match result {
            Ok(out) => out,
            Err(WorkerError::Engine(e)) => return Err(errors::from_engine(e)),
            Err(WorkerError::Panic(m)) => {
                return Err(errors::error(
                    Kind::Render,
                    format!("internal error: the renderer crashed: {m}"),
                ));
            }
        };
        if let (Some(cb), Some((f, stage))) = (&progress, latest) {
            cb.call1((f, stage))?;
        }
        Ok(Output {
            mode: req.mode,
            request: req,
            image: out.image,
            values: out.values,
            stats: out.stats,
            camera: out.camera,
            transfer_function: out.transfer_function,
            warnings: out.warnings,
            notes: out.notes,
        })
    }

    /// The camera (JSON, camera-file format) that `request_json` resolves to.
    #[pyo3(signature = (request_json, volume=None))]
    fn camera(
        &self,
        py: Python<'_>,
        request_json: &str,
        volume: Option<PyRef<'_, Volume>>,
    ) -> PyResult<String> {
        let req = parse_request(request_json, volume.as_deref())?;
        drop(volume);
        let cam = py
            .detach(|| self.with_renderer(|r| r.camera(&req)))
            .map_err(errors::from_engine)?;
        serde_json::to_string(&cam).map_err(|e| errors::error(Kind::Render, e.to_string()))
    }

    /// The transfer function (JSON, transfer-function-file format) `request_json` resolves to.
    #[pyo3(signature = (request_json, volume=None))]
    fn transfer_function(
        &self,
        py: Python<'_>,
        request_json: &str,
        volume: Option<PyRef<'_, Volume>>,
    ) -> PyResult<String> {
        let req = parse_request(request_json, volume.as_deref())?;
        drop(volume);
        let tf = py
            .detach(|| self.with_renderer(|r| r.transfer_function(&req)))
            .map_err(errors::from_engine)?;
        serde_json::to_string(&tf).map_err(|e| errors::error(Kind::Render, e.to_string()))
    }

    /// Forgets everything kept between frames (volume, tables, splat list, thread pool).
    fn clear(&self, py: Python<'_>) {
        py.detach(|| {
            self.with_renderer(|r| *r = volsplat::Renderer::with_limits(self.limits.clone()))
        });
    }
}

/// The result of one render. Public API: `volsplat.Image` wraps it.
#[pyclass(frozen, module = "volsplat._volsplat")]
pub struct Output {
    request: RenderRequest,
    mode: Mode,
    image: Image,
    values: Option<ScalarImage>,
    stats: Stats,
    camera: Camera,
    transfer_function: TransferFunction,
    warnings: Vec<String>,
    notes: Vec<String>,
}

/// Code value of a linear value in [0, 1] (clamped; NaN → 0) at 8 bits, as the PNG writer
/// computes it.
fn quantize8(v: f64, srgb: bool) -> u8 {
    let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
    let v = if srgb {
        volsplat::io::srgb_encode(v)
    } else {
        v
    };
    (v * 255.0).round().clamp(0.0, 255.0) as u8
}

static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

fn parse_bits(bits: u32) -> PyResult<PngBitDepth> {
    PngBitDepth::from_bits(bits).ok_or_else(|| invalid(format!("bits must be 8 or 16, got {bits}")))
}

fn check_background(bg: [f32; 3]) -> PyResult<[f32; 3]> {
    if bg.iter().all(|c| c.is_finite()) {
        Ok(bg)
    } else {
        Err(invalid(format!(
            "background must be three finite numbers (linear RGB), got {bg:?}"
        )))
    }
}

impl Output {
    /// Writes the image as the command line writes `-o path` (PNG or `.npy` by extension): the
    /// engine's one writer, [`volsplat::write_image`].
    fn write(&self, path: &Path, png: &PngSettings, window: Option<(f32, f32)>) -> PyResult<()> {
        let options = volsplat::WriteOptions {
            png: png.clone(),
            window,
        };
        volsplat::write_image(path, &self.image, self.values.as_ref(), self.mode, &options)
            .map_err(errors::from_engine)
    }
}

/// The PNG settings and grey window of `save` / `png_bytes`.
fn image_options(
    mode: Mode,
    srgb: Option<bool>,
    bits: u32,
    background: [f32; 3],
    window: Option<(f32, f32)>,
) -> PyResult<(PngSettings, Option<(f32, f32)>)> {
    let defaults = PngSettings::default();
    let png = PngSettings {
        bits: parse_bits(bits)?,
        srgb: srgb.unwrap_or(defaults.srgb),
        background: check_background(background)?,
    };
    if let Some((lo, hi)) = window {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(invalid(format!(
                "window: needs finite values with lo < hi, got ({lo}, {hi})"
            )));
        }
        if mode == Mode::Composite {
            return Err(invalid(
                "window: a grey window applies to mode \"mip\", \"minip\" and \"xray\"; \
                 composite images take their colours from the transfer function",
            ));
        }
    }
    Ok((png, window))
}

#[pymethods]
impl Output {
    /// Premultiplied linear RGBA, float32 (height, width, 4), row 0 at the top (read-only
    /// zero-copy view).
    #[getter]
    fn rgba<'py>(slf: Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let this = slf.get();
        let (w, h) = (this.image.width(), this.image.height());
        let flat = this.image.pixels().as_flattened();
        let view = ArrayView3::from_shape((h, w, 4), flat)
            .map_err(|e| errors::error(Kind::Render, format!("internal error: {e}")))?;
        // SAFETY: the pixels belong to the frozen `Output`, never mutated, kept alive as base.
        let arr =
            unsafe { numpy::PyArray3::<f32>::borrow_from_array(&view, slf.clone().into_any()) };
        let kwargs = PyDict::new(slf.py());
        kwargs.set_item("write", false)?;
        arr.call_method("setflags", (), Some(&kwargs))?;
        Ok(arr.into_any())
    }

    /// X-ray line integrals or MIP/MinIP values, float32 (height, width); `None` for
    /// composite renders (read-only zero-copy view).
    #[getter]
    fn values<'py>(slf: Bound<'py, Self>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let this = slf.get();
        let Some(v) = &this.values else {
            return Ok(None);
        };
        let view = ArrayView2::from_shape((v.height(), v.width()), v.values())
            .map_err(|e| errors::error(Kind::Render, format!("internal error: {e}")))?;
        // SAFETY: as for `rgba`.
        let arr =
            unsafe { numpy::PyArray2::<f32>::borrow_from_array(&view, slf.clone().into_any()) };
        let kwargs = PyDict::new(slf.py());
        kwargs.set_item("write", false)?;
        arr.call_method("setflags", (), Some(&kwargs))?;
        Ok(Some(arr.into_any()))
    }

    #[getter]
    fn width(&self) -> usize {
        self.image.width()
    }

    #[getter]
    fn height(&self) -> usize {
        self.image.height()
    }

    #[getter]
    fn mode<'py>(&self, py: Python<'py>) -> PyResult<Py<PyAny>> {
        convert::to_py(py, &self.mode)
    }

    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Py<PyAny>> {
        convert::to_py(py, &self.stats)
    }

    #[getter]
    fn camera_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.camera).map_err(|e| errors::error(Kind::Render, e.to_string()))
    }

    #[getter]
    fn transfer_function_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.transfer_function)
            .map_err(|e| errors::error(Kind::Render, e.to_string()))
    }

    /// The request as rendered, with the camera and transfer function resolved to objects, as
    /// `volsplat render --save-scene` writes it (JSON; no `volume` when it is in memory).
    #[getter]
    fn scene_json(&self) -> PyResult<String> {
        let mut r = self.request.clone();
        r.scene.camera = volsplat::CameraSpec::Explicit {
            camera: self.camera.clone(),
            orbit: volsplat::core::Orbit::default(),
        };
        r.scene.transfer_function =
            volsplat::TransferSpec::Function(self.transfer_function.clone());
        request_json(&r)
    }

    /// The request as given (JSON; no `volume` when it is in memory).
    #[getter]
    fn request_json(&self) -> PyResult<String> {
        request_json(&self.request)
    }

    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    #[getter]
    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }

    /// Writes `.png` or `.npy` as `volsplat render -o path` does (see `volsplat.Image.save`).
    #[pyo3(signature = (path, *, srgb=None, bits=8, background=[0.0, 0.0, 0.0], window=None))]
    fn save(
        &self,
        py: Python<'_>,
        path: PathBuf,
        srgb: Option<bool>,
        bits: u32,
        background: [f32; 3],
        window: Option<(f32, f32)>,
    ) -> PyResult<()> {
        let (png, window) = image_options(self.mode, srgb, bits, background, window)?;
        py.detach(|| self.write(&path, &png, window))
    }

    /// The PNG file `save` would write, as bytes.
    #[pyo3(signature = (*, srgb=None, bits=8, background=[0.0, 0.0, 0.0], window=None))]
    fn png_bytes<'py>(
        &self,
        py: Python<'py>,
        srgb: Option<bool>,
        bits: u32,
        background: [f32; 3],
        window: Option<(f32, f32)>,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let (png, window) = image_options(self.mode, srgb, bits, background, window)?;
        let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("volsplat-py-{}-{n}.png", std::process::id()));
        let bytes = py.detach(|| {
            self.write(&path, &png, window)?;
            let b = std::fs::read(&path).map_err(|e| {
                errors::from_io(volsplat::io::IoError::Os {
                    path: path.clone(),
                    op: "read".into(),
                    error: e,
                })
            });
            let _ = std::fs::remove_file(&path);
            b
        })?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// Whether `srgb=None` means sRGB-encoded PNGs (the writer's and command line's default).
    #[getter]
    fn default_srgb(&self) -> bool {
        PngSettings::default().srgb
    }

    /// 8-bit pixels, quantised as the PNG writer quantises. Without a `background`,
    /// (height, width, 4) RGBA: premultiplied colour (which is the image over black, the PNG
    /// writer's default) or, with `premultiplied=False`, straight colour; alpha linear. With a
    /// `background` (linear RGB), (height, width, 3) composited over it. `srgb=True` encodes
    /// colour with the sRGB curve.
    #[pyo3(signature = (*, srgb=false, background=None, premultiplied=true))]
    fn to_uint8<'py>(
        &self,
        py: Python<'py>,
        srgb: bool,
        background: Option<[f32; 3]>,
        premultiplied: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (w, h) = (self.image.width(), self.image.height());
        let px = self.image.pixels();
        let (channels, data) = match background {
            Some(bg) => {
                let bg = check_background(bg)?;
                let mut out = errors::try_with_capacity(px.len() * 3, "the 8-bit pixels")?;
                for p in px {
                    let t = 1.0 - p[3] as f64;
                    for (c, b) in p.iter().zip(bg) {
                        out.push(quantize8(*c as f64 + t * b as f64, srgb));
                    }
                }
                (3, out)
            }
            None => {
                let mut out = errors::try_with_capacity(px.len() * 4, "the 8-bit pixels")?;
                for p in px {
                    let a = p[3] as f64;
                    for c in &p[..3] {
                        let v = match (premultiplied, a > 0.0) {
                            // Over black: `c + (1 − a)·0`, as the PNG writer computes it.
                            (true, _) => *c as f64,
                            (false, true) => *c as f64 / a,
                            (false, false) => 0.0,
                        };
                        out.push(quantize8(v, srgb));
                    }
                    out.push(quantize8(a, false));
                }
                (4, out)
            }
        };
        let arr = PyArray1::from_vec(py, data);
        Ok(arr.reshape([h, w, channels])?.into_any())
    }
}
