//! # volsplat-py
//!
//! The compiled half of the Python package `volsplat` (module `volsplat._volsplat`): the
//! volume type with its numpy conversions, the renderer that releases the GIL and can be
//! interrupted, the render output, and thin calls into the engine's readers and writers. The
//! pythonic API (keyword arguments, `Camera`, `TransferFunction`, `Scene`, `Image`) is the pure
//! Python layer in `python/volsplat/`, which talks to this module in the engine's own JSON
//! formats (a `RenderRequest`, a camera, a transfer function), so that a scene saved from
//! Python is byte for byte what `volsplat render --save-scene` writes.
//!
//! Nothing here panics on user input: errors become the exceptions of `volsplat._errors`
//! (`InvalidInputError` is a `ValueError`, `FileError` an `OSError`, …; see [`errors`]).
#![deny(missing_docs)]

mod convert;
mod errors;
mod files;
mod render;
mod view;
mod volume;

use pyo3::prelude::*;

/// The extension module `volsplat._volsplat`.
#[pymodule]
fn _volsplat(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<volume::Volume>()?;
    m.add_class::<render::RendererCore>()?;
    m.add_class::<render::Output>()?;
    m.add_class::<view::ViewerCore>()?;
    m.add_function(wrap_pyfunction!(volume::load, m)?)?;
    m.add_function(wrap_pyfunction!(volume::phantom, m)?)?;
    m.add_function(wrap_pyfunction!(files::load_camera, m)?)?;
    m.add_function(wrap_pyfunction!(files::save_camera, m)?)?;
    m.add_function(wrap_pyfunction!(files::check_camera_spec, m)?)?;
    m.add_function(wrap_pyfunction!(files::anatomical_view, m)?)?;
    m.add_function(wrap_pyfunction!(files::load_transfer_function, m)?)?;
    m.add_function(wrap_pyfunction!(files::save_transfer_function, m)?)?;
    m.add_function(wrap_pyfunction!(files::check_transfer_function, m)?)?;
    m.add_function(wrap_pyfunction!(files::preset_transfer_function, m)?)?;
    m.add_function(wrap_pyfunction!(files::load_scene, m)?)?;
    m.add_function(wrap_pyfunction!(files::save_scene, m)?)?;
    m.add_function(wrap_pyfunction!(files::check_request, m)?)?;
    m.add(
        "PRESETS",
        volsplat::core::TransferFunction::PRESETS.to_vec(),
    )?;
    m.add(
        "VOLUME_EXTENSIONS",
        volsplat::io::VOLUME_EXTENSIONS.to_vec(),
    )?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
