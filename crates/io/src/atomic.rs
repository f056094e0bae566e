//! Atomic file replacement: write a temporary file in the target's directory, then rename it over
//! the target. Readers never see a half-written file; on error the temporary file is removed and
//! an existing target is left untouched.

use crate::error::{IoError, Result};
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Creates a fresh temporary file next to `path` (same directory, so the final rename stays on one
/// file system).
fn create_temp(path: &Path) -> Result<(PathBuf, File)> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| IoError::invalid_argument(path, "output path", "has no file name"))?;
    let pid = std::process::id();
    let mut last_err = None;
    for _ in 0..16 {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(format!(".{name}.tmp-{pid}-{n}"));
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last_err = Some(e),
            Err(e) => return Err(IoError::os(path, "create temporary file", e)),
        }
    }
    Err(IoError::os(
        path,
        "create temporary file",
        last_err.unwrap_or_else(|| std::io::Error::other("no free temporary name")),
    ))
}

/// Fills a fresh temporary file next to `path` with `write`, then flushes, syncs and closes it;
/// returns its path. On error the temporary file is removed.
fn write_temp<F>(path: &Path, write: F) -> Result<PathBuf>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<()>,
{
    let (tmp, file) = create_temp(path)?;
    let result = (|| {
        let mut w = BufWriter::new(file);
        write(&mut w)?;
        w.flush().map_err(|e| IoError::os(path, "write", e))?;
        let file = w
            .into_inner()
            .map_err(|e| IoError::os(path, "write", e.into_error()))?;
        file.sync_all().map_err(|e| IoError::os(path, "sync", e))
    })();
    match result {
        Ok(()) => Ok(tmp),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// Renames a finished temporary file over `path`, removing it if the rename fails.
fn commit(tmp: &Path, path: &Path) -> Result<()> {
    std::fs::rename(tmp, path).map_err(|e| {
        // Best effort: the temporary file may not exist any more if the rename half-succeeded.
        let _ = std::fs::remove_file(tmp);
        IoError::os(path, "rename temporary file", e)
    })
}

/// Writes `path` atomically: `write` fills a buffered temporary file, which is flushed, synced and
/// renamed over `path`. On any error the temporary file is removed and `path` is unchanged.
pub(crate) fn write_atomic<F>(path: &Path, write: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<()>,
{
    let tmp = write_temp(path, write)?;
    commit(&tmp, path)
}

/// Writes a pair of files (a header and its data file) so that neither changes unless both
/// were written whole: both are written to temporary files first; then `data` is renamed into
/// place, then `header`, so that a reader finding the new header finds its new data. On an
/// error before the renames both temporary files are removed and both targets are unchanged.
pub(crate) fn write_atomic_pair<F, G>(
    data: &Path,
    write_data: F,
    header: &Path,
    write_header: G,
) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<()>,
    G: FnOnce(&mut BufWriter<File>) -> Result<()>,
{
    let data_tmp = write_temp(data, write_data)?;
    let header_tmp = match write_temp(header, write_header) {
        Ok(t) => t,
        Err(e) => {
            let _ = std::fs::remove_file(&data_tmp);
            return Err(e);
        }
    };
    if let Err(e) = commit(&data_tmp, data) {
        let _ = std::fs::remove_file(&header_tmp);
        return Err(e);
    }
    commit(&header_tmp, header)
}

/// Writes `bytes` to `path` atomically (a temporary file renamed over `path`): reports, Markdown,
/// any small file a tool produces.
pub fn write_bytes_atomic(path: impl AsRef<Path>, bytes: &[u8]) -> Result<()> {
    let path = path.as_ref();
    write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(bytes).map_err(write_err(path))
    })
}

/// Maps a write error inside [`write_atomic`]'s closure.
pub(crate) fn write_err(path: &Path) -> impl Fn(std::io::Error) -> IoError + '_ {
    move |e| IoError::os(path, "write", e)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn missing_directory_fails_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("no_such_dir").join("out.bin");
        let e =
            write_atomic(&target, |w| w.write_all(b"x").map_err(write_err(&target))).unwrap_err();
        assert!(e.to_string().contains("out.bin"), "{e}");
        assert!(!target.exists());
        assert!(entries(dir.path()).is_empty());
    }

    #[test]
    fn existing_file_is_replaced_whole() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.bin");
        std::fs::write(&target, vec![7u8; 1000]).unwrap();
        write_atomic(&target, |w| {
            w.write_all(b"short").map_err(write_err(&target))
        })
        .unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"short");
        assert_eq!(entries(dir.path()), vec!["out.bin".to_string()]);
    }

    #[test]
    fn failing_writer_keeps_old_content_and_removes_temp() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.bin");
        std::fs::write(&target, b"old").unwrap();
        let e = write_atomic(&target, |w| {
            w.write_all(b"partial").map_err(write_err(&target))?;
            Err(IoError::invalid_argument(&target, "test", "forced failure"))
        })
        .unwrap_err();
        assert!(e.to_string().contains("forced failure"));
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(entries(dir.path()), vec!["out.bin".to_string()]);
    }

    #[test]
    fn pair_changes_nothing_when_the_second_file_fails() {
        let dir = tempfile::tempdir().unwrap();
        let (data, header) = (dir.path().join("v.raw"), dir.path().join("v.mhd"));
        std::fs::write(&data, b"old data").unwrap();
        std::fs::write(&header, b"old header").unwrap();
        let e = write_atomic_pair(
            &data,
            |w| w.write_all(b"new data").map_err(write_err(&data)),
            &header,
            |_| Err(IoError::invalid_argument(&header, "test", "forced failure")),
        )
        .unwrap_err();
        assert!(e.to_string().contains("forced failure"));
        assert_eq!(std::fs::read(&data).unwrap(), b"old data");
        assert_eq!(std::fs::read(&header).unwrap(), b"old header");
        assert_eq!(
            entries(dir.path()),
            vec!["v.mhd".to_string(), "v.raw".to_string()]
        );
        write_atomic_pair(
            &data,
            |w| w.write_all(b"new data").map_err(write_err(&data)),
            &header,
            |w| w.write_all(b"new header").map_err(write_err(&header)),
        )
        .unwrap();
        assert_eq!(std::fs::read(&data).unwrap(), b"new data");
        assert_eq!(std::fs::read(&header).unwrap(), b"new header");
        assert_eq!(
            entries(dir.path()),
            vec!["v.mhd".to_string(), "v.raw".to_string()]
        );
    }
}
