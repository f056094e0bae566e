//! The error type of the engine.

use std::path::PathBuf;
use thiserror::Error;

/// Everything that can go wrong between a [`crate::RenderRequest`] and an [`crate::Output`].
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum EngineError {
    /// Invalid camera, transfer function, grid or phantom parameters.
    #[error(transparent)]
    Core(#[from] volsplat_core::CoreError),
    /// A file could not be read or written.
    #[error(transparent)]
    Io(#[from] volsplat_io::IoError),
    /// The splatting renderers refused the request, or could not get the memory for a
    /// per-volume buffer ([`volsplat_splat::SplatError::OutOfMemory`]: "not enough memory for
    /// the normal field (N bytes)…"; see [`EngineError::is_out_of_memory`]).
    #[error(transparent)]
    Splat(#[from] volsplat_splat::SplatError),
    /// The Chapter 6 displays refused the request.
    #[error(transparent)]
    Filter(#[from] volsplat_filter::FilterError),
    /// A request field is out of range; the message names the field and the value.
    #[error("invalid request: {field}: {message}")]
    Request {
        /// The field, as written in a scene file (`quality.subsample`, `width`, …).
        field: String,
        /// What is wrong and what is accepted.
        message: String,
    },
    /// A scene file is not valid JSON or misses a required field.
    #[error("{}: {message}", path.display())]
    SceneFile {
        /// The file.
        path: PathBuf,
        /// The parser's message, naming the field.
        message: String,
    },
    /// The progress callback asked to stop.
    #[error("render cancelled")]
    Cancelled,
    /// A renderer produced non-finite pixels (an internal error, never written to a file).
    #[error("internal error: the {stage} produced {count} non-finite pixels")]
    NonFinite {
        /// The renderer that produced them.
        stage: String,
        /// How many pixels hold a NaN or an infinity.
        count: usize,
    },
    /// The thread pool could not be created.
    #[error("could not start {threads} worker threads: {message}")]
    Threads {
        /// Threads asked for.
        threads: usize,
        /// The system's reason.
        message: String,
    },
}

impl EngineError {
    /// Whether a buffer of the render could not be allocated (the system or an address-space
    /// limit refused it): front ends report it as such (Python raises `MemoryError`).
    pub fn is_out_of_memory(&self) -> bool {
        matches!(
            self,
            EngineError::Splat(volsplat_splat::SplatError::OutOfMemory { .. })
        )
    }

    /// A request error naming `field`.
    pub fn request(field: impl Into<String>, message: impl Into<String>) -> Self {
        EngineError::Request {
            field: field.into(),
            message: message.into(),
        }
    }
}

/// Result alias of the engine.
pub type Result<T> = std::result::Result<T, EngineError>;
