//! The viewer's error type.

use thiserror::Error;

/// What can go wrong in the viewer's server.
#[derive(Debug, Error)]
pub enum ViewError {
    /// The engine refused the request or failed to render it.
    #[error(transparent)]
    Engine(#[from] volsplat::EngineError),
    /// A socket could not be opened, read or written.
    #[error("{what}: {source}")]
    Socket {
        /// What was being done (`binding 127.0.0.1:8080`).
        what: String,
        /// The system's error.
        source: std::io::Error,
    },
    /// The operating system's random source failed.
    #[error("no random numbers for the session token: {0}")]
    Random(String),
    /// The settings are inconsistent (a remote host without `allow_remote`, a data folder that
    /// is not a folder, …).
    #[error("{field}: {message}")]
    Settings {
        /// The setting, as the command line names it (`--host`).
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A preview or final frame could not be encoded.
    #[error("encoding a frame: {0}")]
    Encode(String),
}

impl ViewError {
    /// A socket error.
    pub fn socket(what: impl Into<String>, source: std::io::Error) -> Self {
        ViewError::Socket {
            what: what.into(),
            source,
        }
    }

    /// A settings error naming the setting.
    pub fn settings(field: impl Into<String>, message: impl Into<String>) -> Self {
        ViewError::Settings {
            field: field.into(),
            message: message.into(),
        }
    }
}

/// Result alias of the viewer.
pub type Result<T> = std::result::Result<T, ViewError>;
