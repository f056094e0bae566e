//! Engine, reader and core errors as the Python exceptions of `volsplat._errors`.
//!
//! | Rust error | Python exception |
//! |---|---|
//! | the OS refused to open, read or write a file; a path that is not a regular file | `FileError` (`OSError`, with `errno` when the OS gave one) |
//! | bad arguments, arrays, request fields, camera or transfer-function values, file contents | `InvalidInputError` (`ValueError`) |
//! | the progress callback returned `False` | `CancelledError` |
//! | non-finite output, a thread pool that could not start, a crash inside the renderer | `RenderError` (`RuntimeError`) |
//! | the memory for a copy of the caller's data, for a file's samples, or for a render's per-volume buffers (normal field, splat list) could not be allocated | Python's own `MemoryError` |
//!
//! The first four derive from `VolsplatError`. Ctrl-C raises Python's own `KeyboardInterrupt`.
//!
//! Allocation failures. Every copy of user data in this module is allocated fallibly
//! (`Vec::try_reserve_exact`, [`try_copy`]) and fails as `MemoryError` naming the size, so that a
//! volume too big for the address space (`ulimit -v`, a container's limit) leaves the interpreter
//! running. Readers and the engine report one as an [`IoError::Os`] whose error kind is
//! [`std::io::ErrorKind::OutOfMemory`] (how `std` reports it), or with a message saying that
//! memory could not be allocated; both become `MemoryError` too (see [`is_out_of_memory`]).

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

/// `MemoryError`: `bytes` bytes for `what` could not be allocated.
pub fn out_of_memory(what: &str, bytes: usize) -> PyErr {
    pyo3::exceptions::PyMemoryError::new_err(format!(
        "cannot allocate {bytes} bytes ({:.2} GiB) for {what}: not enough memory or address \
         space (check `ulimit -v` and the container's memory limit)",
        bytes as f64 / (1u64 << 30) as f64
    ))
}

/// A copy of `src` in a new vector allocated fallibly (`MemoryError` naming `what` when the
/// memory cannot be had).
pub fn try_copy<T: Copy>(src: &[T], what: &str) -> PyResult<Vec<T>> {
    let mut v = try_with_capacity(src.len(), what)?;
    v.extend_from_slice(src);
    Ok(v)
}

/// An empty vector with room for `n` elements, allocated fallibly.
pub fn try_with_capacity<T>(n: usize, what: &str) -> PyResult<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)
        .map_err(|_| out_of_memory(what, n.saturating_mul(std::mem::size_of::<T>())))?;
    Ok(v)
}

/// Whether a reader or engine error reports an allocation failure: an OS-style error of kind
/// `OutOfMemory`, or a message saying memory could not be allocated.
pub fn is_out_of_memory(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(err) = cur {
        if let Some(io) = err.downcast_ref::<std::io::Error>()
            && io.kind() == std::io::ErrorKind::OutOfMemory
        {
            return true;
        }
        if let Some(IoError::Os { error, .. }) = err.downcast_ref::<IoError>()
            && error.kind() == std::io::ErrorKind::OutOfMemory
        {
            return true;
        }
        if err
            .downcast_ref::<std::collections::TryReserveError>()
            .is_some()
        {
            return true;
        }
        cur = err.source();
    }
    let m = e.to_string().to_ascii_lowercase();
    [
        "out of memory",
        "memory allocation",
        "cannot allocate",
        "could not allocate",
        "not enough memory",
    ]
    .iter()
    .any(|p| m.contains(p))
}

/// `MemoryError` with the reader's or engine's own message.
fn memory_error(message: String) -> PyErr {
    pyo3::exceptions::PyMemoryError::new_err(message)
}

/// A reader or writer error.
pub fn from_io(e: IoError) -> PyErr {
    let message = e.to_string();
    if is_out_of_memory(&e) {
        return memory_error(message);
    }
    match &e {
        IoError::Os { error, .. } => file_error(error.raw_os_error(), message),
        IoError::NotAFile { .. } => error(Kind::File, message),
        _ => error(Kind::Invalid, message),
    }
}

/// An engine error.
pub fn from_engine(e: EngineError) -> PyErr {
    if e.is_out_of_memory() || is_out_of_memory(&e) {
        return memory_error(e.to_string());
    }
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
    if is_out_of_memory(&e) {
        return memory_error(e.to_string());
    }
    error(Kind::Invalid, e.to_string())
}
