//! Camera, transfer-function and scene files through the engine's own readers and writers (the
//! command line's), and validation of the objects the Python layer builds.

use crate::errors::{self, Kind, invalid};
use crate::render::parse_request;
use pyo3::prelude::*;
use std::path::PathBuf;
use volsplat::core::{Camera, TransferFunction};
use volsplat::{CameraSpec, RenderRequest};

fn to_json<T: serde::Serialize>(v: &T) -> PyResult<String> {
    serde_json::to_string(v).map_err(|e| errors::error(Kind::Render, e.to_string()))
}

/// Parses `text` as `T`; unknown fields are errors naming their path.
fn parse_strict<T: serde::de::DeserializeOwned>(text: &str, what: &str) -> PyResult<T> {
    let mut unknown = Vec::new();
    let de = &mut serde_json::Deserializer::from_str(text);
    let mut track = |p: serde_ignored::Path<'_>| unknown.push(p.to_string().replace(".?", ""));
    let de = serde_ignored::Deserializer::new(de, &mut track);
    let v: T = serde_path_to_error::deserialize(de).map_err(|e| {
        invalid(format!(
            "{what}: {}: {}",
            crate::render::field_path(e.path()),
            e.inner()
        ))
    })?;
    if !unknown.is_empty() {
        return Err(invalid(format!(
            "{what}: unknown field{} {}",
            if unknown.len() == 1 { "" } else { "s" },
            unknown.join(", ")
        )));
    }
    Ok(v)
}

/// Reads a camera file: `(camera JSON, warnings)`.
#[pyfunction]
pub fn load_camera(py: Python<'_>, path: PathBuf) -> PyResult<(String, Vec<String>)> {
    let (cam, warnings) = py
        .detach(|| volsplat::io::load_camera(&path))
        .map_err(errors::from_io)?;
    Ok((to_json(&cam)?, warnings))
}

/// Writes a camera file (camera JSON) atomically.
#[pyfunction]
pub fn save_camera(py: Python<'_>, path: PathBuf, camera_json: &str) -> PyResult<()> {
    let cam: Camera = parse_strict(camera_json, "camera")?;
    cam.validate().map_err(errors::from_core)?;
    py.detach(|| volsplat::io::save_camera(&path, &cam))
        .map_err(errors::from_io)
}

/// The scene-file name of an anatomical view given as the command line's `--view` takes it
/// (`"A"`, `"front"`, `"Anterior"` → `"anterior"`).
#[pyfunction]
pub fn anatomical_view(name: &str) -> PyResult<&'static str> {
    volsplat::core::AnatomicalView::from_name(name)
        .map(|v| v.name())
        .map_err(errors::from_core)
}

/// Checks a camera specification (the scene file's `camera` object) and returns it normalised.
#[pyfunction]
pub fn check_camera_spec(spec_json: &str) -> PyResult<String> {
    let spec: CameraSpec = parse_strict(spec_json, "camera")?;
    match &spec {
        CameraSpec::Orbit(o) => o.validate().map_err(errors::from_core)?,
        CameraSpec::Explicit { camera, orbit } => {
            camera.validate().map_err(errors::from_core)?;
            orbit.validate().map_err(errors::from_core)?;
        }
    }
    to_json(&spec)
}

/// Reads a transfer-function file, volsplat's or a ParaView colour-map preset file (`name`
/// picks a preset), with the command line's reader: `(function JSON, warnings)`.
#[pyfunction]
#[pyo3(signature = (path, name=None))]
pub fn load_transfer_function(
    py: Python<'_>,
    path: PathBuf,
    name: Option<String>,
) -> PyResult<(String, Vec<String>)> {
    let limits = volsplat::io::Limits::default();
    let (tf, warnings) = py
        .detach(|| volsplat::io::load_transfer_function_named(&path, name.as_deref(), &limits))
        .map_err(errors::from_io)?;
    Ok((to_json(&tf)?, warnings))
}

/// Writes a transfer-function file atomically.
#[pyfunction]
pub fn save_transfer_function(py: Python<'_>, path: PathBuf, tf_json: &str) -> PyResult<()> {
    let mut tf: TransferFunction = parse_strict(tf_json, "transfer function")?;
    tf.validate().map_err(errors::from_core)?;
    py.detach(|| volsplat::io::save_transfer_function(&path, &tf))
        .map_err(errors::from_io)
}

/// Checks a transfer function (errors name the field and point) and returns it with VTK's
/// defaults filled in.
#[pyfunction]
pub fn check_transfer_function(tf_json: &str) -> PyResult<String> {
    let mut tf: TransferFunction = parse_strict(tf_json, "transfer function")?;
    tf.validate().map_err(errors::from_core)?;
    to_json(&tf)
}

/// A preset over a data range, as JSON.
#[pyfunction]
pub fn preset_transfer_function(name: &str, lo: f64, hi: f64) -> PyResult<String> {
    if !(lo.is_finite() && hi.is_finite()) {
        return Err(invalid(format!(
            "data_range must be two finite numbers, got ({lo}, {hi})"
        )));
    }
    let mut tf = TransferFunction::preset(name, (lo, hi)).map_err(errors::from_core)?;
    tf.validate().map_err(errors::from_core)?;
    to_json(&tf)
}

/// Reads a scene file (a `RenderRequest`, as `volsplat render --save-scene` writes it):
/// `(request JSON, warnings)`; unknown fields are warnings as on the command line.
#[pyfunction]
pub fn load_scene(py: Python<'_>, path: PathBuf) -> PyResult<(String, Vec<String>)> {
    let (req, warnings) = py
        .detach(|| RenderRequest::load(&path))
        .map_err(errors::from_engine)?;
    Ok((to_json(&req)?, warnings))
}

/// Writes a scene file (the request must name its volume by file or phantom).
#[pyfunction]
pub fn save_scene(py: Python<'_>, path: PathBuf, request_json: &str) -> PyResult<()> {
    let req = parse_request(request_json, None)?;
    py.detach(|| req.save(&path)).map_err(errors::from_engine)
}

/// Checks the fields of a request that need no volume (errors name the field as in a scene
/// file) and returns it normalised (every default written out).
#[pyfunction]
pub fn check_request(request_json: &str) -> PyResult<String> {
    let req = parse_request(request_json, None)?;
    req.validate().map_err(errors::from_engine)?;
    to_json(&req)
}
