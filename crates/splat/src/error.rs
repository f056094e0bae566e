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
    /// A render produced non-finite pixels: an internal error (a bug), reported instead of
    /// returning a picture that is silently wrong.
    #[error(
        "internal error: the {stage} produced {count} non-finite pixel values \
         (first at x = {x}, y = {y}); please report this with the command line"
    )]
    NonFinite {
        /// The renderer stage that produced them.
        stage: &'static str,
        /// How many values are NaN or infinite.
        count: usize,
        /// Column of the first one.
        x: usize,
        /// Row of the first one.
        y: usize,
    },
}

/// Result alias for rendering.
pub type Result<T> = std::result::Result<T, SplatError>;
