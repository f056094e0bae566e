//! Engine, reader and core errors as the Python exceptions of `volsplat._errors`.
//!
//! | Rust error | Python exception |
//! |---|---|
//! | the OS refused to open, read or write a file; a path that is not a regular file | `FileError` (`OSError`, with `errno` when the OS gave one) |
//! | bad arguments, arrays, request fields, camera or transfer-function values, file contents | `InvalidInputError` (`ValueError`) |
//! | the progress callback returned `False` | `CancelledError` |
//! | non-finite output, a thread pool that could not start, a crash inside the renderer | `RenderError` (`RuntimeError`) |
//!
//! All four derive from `VolsplatError`. Ctrl-C raises Python's own `KeyboardInterrupt`.

use pyo3::prelude::*;
use pyo3::types::PyType;
use volsplat::EngineError;
use volsplat::io::IoError;

/// The exception classes, by name in `volsplat._errors`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// `InvalidInputError(VolsplatError, ValueError)`.
    Invalid,
    /// `FileError(VolsplatError, OSError)`.
    File,
    /// `CancelledError(VolsplatError)`.
    Cancelled,
    /// `RenderError(VolsplatError, RuntimeError)`.
    Render,
}

impl Kind {
    fn class_name(self) -> &'static str {
        match self {
            Kind::Invalid => "InvalidInputError",
            Kind::File => "FileError",
            Kind::Cancelled => "CancelledError",
            Kind::Render => "RenderError",
        }
    }
}

/// A Python exception of `kind` with `message`. If `volsplat._errors` cannot be imported (a
/// broken installation), falls back to the built-in class the kind derives from.
pub fn error(kind: Kind, message: impl Into<String>) -> PyErr {
    let message = message.into();
    Python::attach(|py| {
        let class = py
            .import("volsplat._errors")
            .and_then(|m| m.getattr(kind.class_name()))
            .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
        match class {
            Ok(class) => PyErr::from_type(class, message),
            Err(_) => match kind {
                Kind::Invalid => pyo3::exceptions::PyValueError::new_err(message),
                Kind::File => pyo3::exceptions::PyOSError::new_err(message),
                Kind::Cancelled | Kind::Render => {
                    pyo3::exceptions::PyRuntimeError::new_err(message)
                }
            },
        }
    })
}

/// `InvalidInputError(message)`.
pub fn invalid(message: impl Into<String>) -> PyErr {
    error(Kind::Invalid, message)
}

/// An `OSError` subclass carrying `errno` (so `e.errno` works as for built-in I/O errors).
fn file_error(errno: Option<i32>, message: String) -> PyErr {
    match errno {
        None => error(Kind::File, message),
        Some(n) => Python::attach(|py| {
            let class = py
                .import("volsplat._errors")
                .and_then(|m| m.getattr("FileError"))
                .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
            match class {
                Ok(class) => PyErr::from_type(class, (n, message)),
                Err(_) => pyo3::exceptions::PyOSError::new_err((n, message)),
            }
        }),
    }
}

/// A reader or writer error.
pub fn from_io(e: IoError) -> PyErr {
    let message = e.to_string();
    match &e {
        IoError::Os { error, .. } => file_error(error.raw_os_error(), message),
        IoError::NotAFile { .. } => error(Kind::File, message),
        _ => error(Kind::Invalid, message),
    }
}

/// An engine error.
pub fn from_engine(e: EngineError) -> PyErr {
    match e {
        EngineError::Io(e) => from_io(e),
        EngineError::Cancelled => error(Kind::Cancelled, "render cancelled"),
        e @ (EngineError::NonFinite { .. } | EngineError::Threads { .. }) => {
            error(Kind::Render, e.to_string())
        }
        e @ EngineError::SceneFile { .. } => {
            let message = e.to_string();
            if message.contains("cannot read") {
                error(Kind::File, message)
            } else {
                error(Kind::Invalid, message)
            }
        }
        e => {
            let message = e.to_string();
            // The splatting and filtering libraries have cancellation errors of their own; the
            // engine normally maps them to `Cancelled`, this catches any that slip through.
            if message == "render cancelled" {
                error(Kind::Cancelled, message)
            } else if message.starts_with("internal error") {
                error(Kind::Render, message)
            } else {
                error(Kind::Invalid, message)
            }
        }
    }
}

/// A core error (grid, camera, transfer function).
pub fn from_core(e: volsplat::core::CoreError) -> PyErr {
    error(Kind::Invalid, e.to_string())
}
