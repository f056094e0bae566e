//! The error type of `volsplat-io`.
//!
//! Every variant carries the path of the file involved, and where it applies the header field (as
//! spelled in the file format), the offending value and byte counts, so that the message alone
//! tells a user what to fix. Messages are self-contained: the underlying error (from the OS,
//! `serde_json`, `png` or `volsplat-core`) is included in the text rather than chained as a
//! `source()`, so printing the error once prints everything.

use std::path::{Path, PathBuf};
use thiserror::Error;
use volsplat_core::CoreError;

/// Everything that can go wrong while reading or writing files.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum IoError {
    /// An operating-system I/O operation failed (open, read, write, rename, ...).
    #[error("{path}: {op} failed: {error}", path = .path.display())]
    Os {
        /// The file involved.
        path: PathBuf,
        /// What was being done, e.g. `open`, `read header`, `rename temporary file`.
        op: String,
        /// The OS error.
        error: std::io::Error,
    },
    /// A header line that cannot be parsed at all (no `field: value` form, bad magic, ...).
    #[error("{path}: line {line}: {reason}: {text:?}", path = .path.display())]
    Syntax {
        /// The header file.
        path: PathBuf,
        /// 1-based line number in the header.
        line: usize,
        /// The offending line (truncated to 200 characters).
        text: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A header field has a malformed or invalid value.
    #[error("{path}: field `{field}`: invalid value {value:?}: {reason}", path = .path.display())]
    Field {
        /// The header (or JSON) file.
        path: PathBuf,
        /// The field name as spelled in the file format (e.g. `sizes`, `space directions`).
        field: String,
        /// The offending value as written (truncated to 200 characters).
        value: String,
        /// Why it is invalid.
        reason: String,
    },
    /// A field's value is well-formed but names something this crate does not support.
    #[error(
        "{path}: field `{field}`: unsupported value {value:?}; supported: {supported}",
        path = .path.display()
    )]
    Unsupported {
        /// The header file.
        path: PathBuf,
        /// The field name as spelled in the file format (e.g. `type`, `encoding`).
        field: String,
        /// The value given.
        value: String,
        /// What is supported instead.
        supported: String,
    },
    /// A required header field is absent.
    #[error("{path}: missing required field `{field}`", path = .path.display())]
    MissingField {
        /// The header file.
        path: PathBuf,
        /// The field name as spelled in the file format.
        field: String,
    },
    /// The data ends before the header's sizes are satisfied.
    #[error(
        "{path}: {what} is truncated: expected {expected} {unit}, found {actual}",
        path = .path.display()
    )]
    Truncated {
        /// The data file.
        path: PathBuf,
        /// Which part is short (e.g. `raw payload starting at byte 312`, `gzip payload`).
        what: String,
        /// Amount needed (after decompression for compressed data).
        expected: u64,
        /// Amount available.
        actual: u64,
        /// Unit of `expected` and `actual`: `bytes`, or `values` for text payloads.
        unit: &'static str,
    },
    /// A file's size differs from what its description requires (headerless raw files).
    #[error(
        "{path}: size mismatch: expected {expected} bytes ({detail}), found {actual}",
        path = .path.display()
    )]
    SizeMismatch {
        /// The data file.
        path: PathBuf,
        /// Bytes required.
        expected: u64,
        /// Bytes present (a lower bound for compressed data that is too long).
        actual: u64,
        /// How `expected` was computed.
        detail: String,
    },
    /// A size declared by a file exceeds a limit of this crate; checked before allocating.
    #[error("{path}: {what} = {value} exceeds the limit {limit}", path = .path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What was being sized (e.g. `voxel count from field sizes`).
        what: String,
        /// The requested size.
        value: u128,
        /// The limit in force.
        limit: u128,
    },
    /// A compressed stream is corrupt.
    #[error("{path}: {what}: decompression failed: {error}", path = .path.display())]
    Decompress {
        /// The data file.
        path: PathBuf,
        /// Which stream (e.g. `gzip payload`).
        what: String,
        /// The decoder's error.
        error: std::io::Error,
    },
    /// A core type rejected the data (grid geometry, non-finite float samples, camera or
    /// transfer-function validation). The core message names the field.
    #[error("{path}: {error}", path = .path.display())]
    Core {
        /// The file.
        path: PathBuf,
        /// The core error.
        error: CoreError,
    },
    /// A JSON file could not be parsed or does not match the expected schema.
    #[error("{path}: {message}", path = .path.display())]
    Json {
        /// The JSON file.
        path: PathBuf,
        /// `serde_json`'s message, prefixed with the field where known.
        message: String,
    },
    /// A `.npy` file is malformed or not of the supported kind.
    #[error("{path}: not a supported .npy file: {reason}", path = .path.display())]
    Npy {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The PNG encoder failed.
    #[error("{path}: PNG encoding failed: {message}", path = .path.display())]
    Png {
        /// The output file.
        path: PathBuf,
        /// The encoder's message.
        message: String,
    },
    /// An argument given by the caller is invalid (empty image, `lo >= hi`, ...).
    #[error("{path}: invalid {what}: {reason}", path = .path.display())]
    InvalidArgument {
        /// The file that was to be written or read.
        path: PathBuf,
        /// The argument.
        what: String,
        /// Why it is invalid.
        reason: String,
    },
    /// A path that must be a regular file names a device, FIFO, socket or directory (reading
    /// `/dev/zero` or a FIFO could block or never end).
    #[error(
        "{path}: {what} is not a regular file ({kind}); refusing to read it",
        path = .path.display()
    )]
    NotAFile {
        /// The path.
        path: PathBuf,
        /// Which file it is (e.g. `data file`, `volume file`).
        what: String,
        /// What it is instead: `a directory`, or `a device, FIFO or socket`.
        kind: &'static str,
    },
    /// A file that a volume file names (a detached header's data file, the `.img` of a `.hdr`,
    /// a slice of a TIFF folder) lies outside the folder the read is confined to
    /// ([`crate::Limits::confine_to`]), after following symbolic links: it is not opened.
    #[error(
        "{path}: {what} `{value}` lies outside the folder this read is confined to, {folder}",
        path = .path.display(),
        folder = .folder.display()
    )]
    OutsideFolder {
        /// The file that names it (the header), or the file itself when it is a link.
        path: PathBuf,
        /// Which reference, with the header field as spelled in the format where one names it
        /// (e.g. ``field `ElementDataFile`: data file``, `image file`).
        what: String,
        /// The reference as written (the field's value; truncated to 200 characters).
        value: String,
        /// The folder the read is confined to, as the caller gave it.
        folder: PathBuf,
    },
    /// A DICOM file that is malformed or cannot be read (the message names the element, byte
    /// offset or frame where known).
    #[error("{path}: DICOM: {message}", path = .path.display())]
    Dicom {
        /// The file (or folder).
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A folder holds several DICOM series and none was chosen, or the one asked for is not
    /// there; `series` lists what the folder holds.
    #[error(
        "{path}: {reason}; series in the folder: {list}",
        path = .path.display(),
        list = crate::dicom::series_summary(.series)
    )]
    DicomSeries {
        /// The folder or file given.
        path: PathBuf,
        /// Why no series could be read.
        reason: String,
        /// Every image series found.
        series: Vec<crate::DicomSeries>,
    },
    /// A Zarr store or chunk could not be opened or decoded (the `zarrs` crate's message).
    #[error("{path}: Zarr: {what}: {message}", path = .path.display())]
    Zarr {
        /// The store (directory).
        path: PathBuf,
        /// What was being read, e.g. `level 1 (array \`1\`)`.
        what: String,
        /// The cause.
        message: String,
    },
    /// The file extension does not name a supported format.
    #[error(
        "{path}: unsupported file extension {extension:?}; supported: {supported}",
        path = .path.display()
    )]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
        /// The extension found (empty if none).
        extension: String,
        /// The supported extensions.
        supported: String,
    },
}

/// Result alias for this crate.
pub type Result<T> = std::result::Result<T, IoError>;

/// Truncates a string for inclusion in an error message.
pub(crate) fn clip(s: &str) -> String {
    const MAX: usize = 200;
    if s.chars().count() <= MAX {
        s.to_string()
    } else {
        let mut out: String = s.chars().take(MAX).collect();
        out.push('…');
        out
    }
}

impl IoError {
    pub(crate) fn os(path: &Path, op: impl Into<String>, error: std::io::Error) -> Self {
        IoError::Os {
            path: path.to_path_buf(),
            op: op.into(),
            error,
        }
    }

    pub(crate) fn field(
        path: &Path,
        field: impl Into<String>,
        value: &str,
        reason: impl Into<String>,
    ) -> Self {
        IoError::Field {
            path: path.to_path_buf(),
            field: field.into(),
            value: clip(value),
            reason: reason.into(),
        }
    }

    pub(crate) fn unsupported(
        path: &Path,
        field: impl Into<String>,
        value: &str,
        supported: impl Into<String>,
    ) -> Self {
        IoError::Unsupported {
            path: path.to_path_buf(),
            field: field.into(),
            value: clip(value),
            supported: supported.into(),
        }
    }

    pub(crate) fn missing(path: &Path, field: impl Into<String>) -> Self {
        IoError::MissingField {
            path: path.to_path_buf(),
            field: field.into(),
        }
    }

    pub(crate) fn core(path: &Path, error: CoreError) -> Self {
        IoError::Core {
            path: path.to_path_buf(),
            error,
        }
    }

    pub(crate) fn invalid_argument(
        path: &Path,
        what: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        IoError::InvalidArgument {
            path: path.to_path_buf(),
            what: what.into(),
            reason: reason.into(),
        }
    }
}
