//! The error type of `volsplat-core`.

use thiserror::Error;

/// Everything that can go wrong when building or validating core types.
///
/// Each variant names the offending field and value so that a caller can report it to a user
/// without further context.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CoreError {
    /// A field has a value outside its documented range.
    #[error("invalid {field}: {value} ({reason})")]
    InvalidField {
        /// The field name as the user sees it (e.g. `spacing[2]`, `view_up`).
        field: String,
        /// The offending value, formatted.
        value: String,
        /// Why it is invalid.
        reason: String,
    },
    /// A buffer does not have the length its header promises.
    #[error("data length {actual} does not match dims {dims:?} (expected {expected} samples)")]
    DataLength {
        /// Grid dimensions (x, y, z).
        dims: [usize; 3],
        /// Expected number of samples.
        expected: usize,
        /// Actual number of samples.
        actual: usize,
    },
    /// A size computation would overflow or exceed a limit.
    #[error("size too large: {what} = {value} exceeds the limit {limit}")]
    TooLarge {
        /// What was being sized.
        what: String,
        /// The requested size.
        value: u128,
        /// The limit in force.
        limit: u128,
    },
    /// A named preset does not exist.
    #[error("unknown {kind} `{name}`; known: {known}")]
    UnknownName {
        /// What kind of name (preset, kernel, ...).
        kind: String,
        /// The name given.
        name: String,
        /// Comma-separated list of valid names.
        known: String,
    },
    /// A brick of a [`crate::source::BrickSource`] could not be served: its key lies outside
    /// the level, or the store failed to read or decode it.
    #[error("level {level}, brick {brick:?}: {cause}")]
    Brick {
        /// Pyramid level (0 = full resolution).
        level: u8,
        /// Brick coordinates along i, j, k (bricks, not voxels).
        brick: [u32; 3],
        /// What went wrong, for a user.
        cause: String,
    },
}

impl CoreError {
    /// Shorthand for [`CoreError::InvalidField`].
    pub fn invalid(
        field: impl Into<String>,
        value: impl std::fmt::Debug,
        reason: impl Into<String>,
    ) -> Self {
        CoreError::InvalidField {
            field: field.into(),
            value: format!("{value:?}"),
            reason: reason.into(),
        }
    }
}

/// Result alias for core operations.
pub type Result<T> = std::result::Result<T, CoreError>;
