//! The interactive viewer in the Python process (`volsplat.view`): the same server as
//! `volsplat view` (`volsplat-view`), on background threads of its own. Rendering and serving
//! never take the GIL; starting (which loads the volume) and stopping release it.

use crate::errors::{self, Kind, invalid};
use crate::render::parse_request;
use crate::volume::Volume;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Mutex;
use volsplat::{RenderRequest, VolumeSource};
use volsplat_view::{ViewError, Viewer, ViewerHandle, ViewerSettings};

fn from_view(e: ViewError) -> PyErr {
    match e {
        ViewError::Engine(e) => errors::from_engine(e),
        ViewError::Settings { field, message } => invalid(format!("{field}: {message}")),
        e => errors::error(Kind::Render, e.to_string()),
    }
}

/// A running viewer. Public API: `volsplat.Viewer` (`volsplat.view(...)`).
#[pyclass(frozen, module = "volsplat._volsplat")]
pub struct ViewerCore {
    handle: Mutex<Option<ViewerHandle>>,
    url: String,
    memory: bool,
}

#[pymethods]
impl ViewerCore {
    /// Starts a viewer on `request_json` (the engine's request; `volume` replaces its volume),
    /// listening on `host:port` (0: a free port). `srgb`, `bits`, `background` and `window`,
    /// where given, replace the request's output options (its `output`; a scene file's are
    /// kept otherwise); `fit_view`: the image follows the page's view instead of the
    /// request's size.
    #[new]
    #[pyo3(signature = (request_json, volume=None, *, host="127.0.0.1".to_string(), port=0,
        allow_remote=false, data_dir=None, target_fps=60.0, target_latency=50.0, srgb=None,
        bits=None, background=None, window=None, fit_view=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        request_json: &str,
        volume: Option<PyRef<'_, Volume>>,
        host: String,
        port: u16,
        allow_remote: bool,
        data_dir: Option<PathBuf>,
        target_fps: f64,
        target_latency: f64,
        srgb: Option<bool>,
        bits: Option<u32>,
        background: Option<[f32; 3]>,
        window: Option<(f32, f32)>,
        fit_view: bool,
    ) -> PyResult<Self> {
        let mut request = parse_request(request_json, volume.as_deref())?;
        let memory = matches!(request.scene.volume, VolumeSource::Memory(_));
        let output = &mut request.output;
        if let Some(bits) = bits {
            output.bit_depth = bits;
        }
        if let Some(srgb) = srgb {
            output.srgb = srgb;
        }
        if let Some(background) = background {
            output.background = background;
        }
        if let Some((lo, hi)) = window {
            output.window = Some([lo, hi]);
        }
        // Checked here so that a bad option is an error naming it, before any port is bound.
        request
            .output
            .validate(request.mode)
            .map_err(errors::from_engine)?;
        let mut settings = ViewerSettings {
            host,
            port,
            allow_remote,
            data_dir,
            fit_view,
            ..ViewerSettings::default()
        };
        settings.session.target_fps = target_fps;
        settings.session.target_latency_ms = target_latency;
        let handle = py
            .detach(|| {
                Viewer::bind(request, volsplat::Renderer::new(), settings).and_then(|v| v.spawn())
            })
            .map_err(from_view)?;
        Ok(ViewerCore {
            url: handle.url().to_string(),
            handle: Mutex::new(Some(handle)),
            memory,
        })
    }

    /// The page's URL with its token.
    #[getter]
    fn url(&self) -> String {
        self.url.clone()
    }

    /// Whether the server is running.
    #[getter]
    fn running(&self) -> bool {
        self.lock().is_some()
    }

    /// Tabs connected now (0 once closed).
    #[getter]
    fn tabs(&self) -> usize {
        self.lock().as_ref().map_or(0, |h| h.tabs())
    }

    /// The scene of the tab that changed last (the starting scene before any did), as the
    /// engine's request JSON (no `volume` when it is in memory; its output options included),
    /// and its grey window (the request's `output.window`).
    fn scene(&self) -> PyResult<(String, Option<(f32, f32)>)> {
        let guard = self.lock();
        let Some(h) = guard.as_ref() else {
            return Err(invalid("the viewer is closed"));
        };
        let request = h.scene();
        let window = request.output.window.map(|[lo, hi]| (lo, hi));
        Ok((request_json(&request, self.memory)?, window))
    }

    /// Stops the server: closes every tab and frees the port. Closing twice does nothing.
    fn close(&self, py: Python<'_>) {
        let handle = self.lock().take();
        if let Some(mut h) = handle {
            py.detach(move || h.stop());
        }
    }
}

impl ViewerCore {
    fn lock(&self) -> std::sync::MutexGuard<'_, Option<ViewerHandle>> {
        self.handle.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The request as JSON, its volume left out when it is in memory.
fn request_json(req: &RenderRequest, memory: bool) -> PyResult<String> {
    let mut r = req.clone();
    if memory {
        r.scene.volume = VolumeSource::default();
    }
    let mut v = serde_json::to_value(&r).map_err(|e| errors::error(Kind::Render, e.to_string()))?;
    if memory && let Some(s) = v.get_mut("scene").and_then(|s| s.as_object_mut()) {
        s.remove("volume");
    }
    Ok(v.to_string())
}
