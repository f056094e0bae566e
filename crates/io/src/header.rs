//! Reading a text header at the start of a file, with a size limit, plus small parsing helpers
//! shared by the NRRD and MetaImage readers.

use crate::error::{IoError, Result};
use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Largest text header accepted by the NRRD and MetaImage readers, in bytes (1 MiB). Real headers
/// are a few hundred bytes; the limit keeps a binary file given by mistake from being scanned
/// (and buffered) whole.
pub const MAX_HEADER_BYTES: usize = 1 << 20;

/// What the line classifier decides for each header line.
pub(crate) enum LineAction {
    /// Keep the line and go on.
    Keep,
    /// The header ends before this line (NRRD's blank line); the data start after it.
    EndBefore,
    /// Keep this line; the header ends after it (MetaImage's `ElementDataFile`).
    KeepAndEnd,
}

/// A header split into lines.
pub(crate) struct HeaderText {
    /// `(1-based line number, text without the line terminator)`.
    pub(crate) lines: Vec<(usize, String)>,
    /// Byte offset just past the header (where attached data start).
    pub(crate) end: u64,
    /// Whether the header was ended by the classifier (`false`: it ran to the end of the file).
    pub(crate) terminated: bool,
}

/// Reads lines from the start of `path` until `classify` ends the header or the file ends.
/// Errors if the header is longer than `max_bytes`, or if `path` is not a regular file.
pub(crate) fn read_header(
    path: &Path,
    max_bytes: usize,
    mut classify: impl FnMut(usize, &str) -> LineAction,
) -> Result<HeaderText> {
    crate::limits::require_regular_file(path, "header file")?;
    let file = File::open(path).map_err(|e| IoError::os(path, "open", e))?;
    let mut prefix = Vec::new();
    file.take(max_bytes as u64 + 1)
        .read_to_end(&mut prefix)
        .map_err(|e| IoError::os(path, "read header", e))?;
    let capped = prefix.len() > max_bytes;
    let mut lines = Vec::new();
    let mut pos = 0usize;
    let mut line_no = 0usize;
    while pos < prefix.len() {
        line_no += 1;
        let (text_end, next) = match prefix[pos..].iter().position(|&b| b == b'\n') {
            Some(p) => (pos + p, pos + p + 1),
            None if capped => {
                return Err(header_too_large(path, max_bytes));
            }
            None => (prefix.len(), prefix.len()),
        };
        if next > max_bytes {
            return Err(header_too_large(path, max_bytes));
        }
        let mut raw = &prefix[pos..text_end];
        if let Some(stripped) = raw.strip_suffix(b"\r") {
            raw = stripped;
        }
        let text = String::from_utf8_lossy(raw).into_owned();
        match classify(line_no, &text) {
            LineAction::Keep => lines.push((line_no, text)),
            LineAction::EndBefore => {
                return Ok(HeaderText {
                    lines,
                    end: next as u64,
                    terminated: true,
                });
            }
            LineAction::KeepAndEnd => {
                lines.push((line_no, text));
                return Ok(HeaderText {
                    lines,
                    end: next as u64,
                    terminated: true,
                });
            }
        }
        pos = next;
    }
    Ok(HeaderText {
        lines,
        end: prefix.len() as u64,
        terminated: false,
    })
}

fn header_too_large(path: &Path, max_bytes: usize) -> IoError {
    IoError::TooLarge {
        path: path.to_path_buf(),
        what: "header size in bytes (no end of header found)".into(),
        value: max_bytes as u128 + 1,
        limit: max_bytes as u128,
    }
}

/// Resolves a data-file name from a header relative to the header's directory.
pub(crate) fn resolve_data_path(header: &Path, name: &str) -> PathBuf {
    let name = Path::new(name);
    if name.is_absolute() {
        return name.to_path_buf();
    }
    match header.parent() {
        Some(dir) => dir.join(name),
        None => name.to_path_buf(),
    }
}

/// Parses exactly `N` whitespace-separated numbers with `parse`; errors name `field` and say
/// that a bad token "is not {what}" (e.g. `what` = "a whole number ≥ 1").
pub(crate) fn parse_numbers<T, const N: usize>(
    path: &Path,
    field: &str,
    value: &str,
    what: &str,
    parse: impl Fn(&str) -> Option<T>,
) -> Result<[T; N]>
where
    T: Copy + Default,
{
    let tokens: Vec<&str> = value.split_whitespace().collect();
    if tokens.len() != N {
        return Err(IoError::field(
            path,
            field,
            value,
            format!("expected {N} values, found {}", tokens.len()),
        ));
    }
    let mut out = [T::default(); N];
    for (o, t) in out.iter_mut().zip(&tokens) {
        *o = parse(t)
            .ok_or_else(|| IoError::field(path, field, value, format!("`{t}` is not {what}")))?;
    }
    Ok(out)
}

/// Parses a finite decimal number.
pub(crate) fn parse_finite(t: &str) -> Option<f64> {
    t.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Lower-cases and collapses runs of whitespace to one space.
pub(crate) fn normalize_words(s: &str) -> String {
    s.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .to_ascii_lowercase()
}

/// One `key: value` (NRRD) or `Key = Value` (MetaImage) line of a header.
pub(crate) struct Field {
    /// The line number, 1-based, for messages.
    pub(crate) line: usize,
    /// The key as written (trimmed), for messages.
    pub(crate) name: String,
    /// The value, trimmed.
    pub(crate) value: String,
}

/// A header's fields by canonical (lower-case or normalised) key.
pub(crate) type Fields = HashMap<String, Field>;

/// The field `canon` (canonical key), or an error saying that `name` is missing from `path`.
pub(crate) fn require<'f>(
    path: &Path,
    fields: &'f Fields,
    canon: &str,
    name: &str,
) -> Result<&'f Field> {
    fields
        .get(canon)
        .ok_or_else(|| IoError::missing(path, name))
}
