//! The error type of `volsplat-splat`.

use thiserror::Error;
use volsplat_core::CoreError;

/// Everything that can go wrong while rendering.
#[derive(Debug, Error)]
pub enum SplatError {
    /// Invalid camera, transfer function, kernel or volume.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// Invalid render settings; the message names the setting.
    #[error("invalid render settings: {0}")]
    Settings(String),
    /// The progress callback asked to stop.
    #[error("render cancelled")]
    Cancelled,
}

/// Result alias for rendering.
pub type Result<T> = std::result::Result<T, SplatError>;
