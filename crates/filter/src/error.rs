//! The error type of `volsplat-filter`.

use thiserror::Error;

/// Everything that can go wrong when configuring or running a filter.
///
/// Each variant names the offending parameter and value so that a CLI can report it without
/// further context.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FilterError {
    /// A parameter has a value outside its documented range.
    #[error("invalid {field}: {value} ({reason})")]
    InvalidParameter {
        /// The parameter name as the user sees it (e.g. `tolerance`, `dims[2]`).
        field: String,
        /// The offending value, formatted.
        value: String,
        /// Why it is invalid.
        reason: String,
    },
    /// A requested structure would exceed a size limit.
    #[error("size too large: {what} = {value} exceeds the limit {limit}")]
    TooLarge {
        /// What was being sized.
        what: String,
        /// The requested size.
        value: u128,
        /// The limit in force.
        limit: u128,
    },
    /// The technique cannot be applied to this texture (e.g. clamping a texture without a
    /// known spectrum, thesis §3-2).
    #[error("{technique} is not applicable: {reason}")]
    NotApplicable {
        /// The technique asked for.
        technique: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// The progress callback asked to stop.
    #[error("render cancelled")]
    Cancelled,
    /// An error from `volsplat-core` (camera validation, grids).
    #[error(transparent)]
    Core(#[from] volsplat_core::CoreError),
}

impl FilterError {
    /// Shorthand for [`FilterError::InvalidParameter`].
    pub fn invalid(
        field: impl Into<String>,
        value: impl std::fmt::Debug,
        reason: impl Into<String>,
    ) -> Self {
        FilterError::InvalidParameter {
            field: field.into(),
            value: format!("{value:?}"),
            reason: reason.into(),
        }
    }
}

/// Result alias for filter operations.
pub type Result<T> = std::result::Result<T, FilterError>;

/// Checks that `value` is finite and strictly positive.
pub(crate) fn check_positive(field: &str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(FilterError::invalid(
            field,
            value,
            "must be a positive finite number",
        ))
    }
}
