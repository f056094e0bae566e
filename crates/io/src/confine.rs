//! Confining a read to a folder ([`Limits::confine_to`]): a volume file that lies inside the
//! folder may open only files inside it. A viewer serving a folder to a page uses it, so that a
//! header placed there (`data file: /etc/…`, `ElementDataFile = ../secret.raw`, a `.img` or a
//! slice that is a symbolic link) cannot make it read and show a file elsewhere (decision 0033).
//!
//! Paths are compared after resolving `..` and symbolic links (`std::fs::canonicalize`). A file
//! that does not exist is judged by its folder (resolved) and name, so that the answer never
//! says whether a file outside exists. The check is made just before the file is opened; a
//! folder whose contents change between the check and the open (a writer racing the reader)
//! is outside what it guards against.

use crate::error::{IoError, Result, clip};
use crate::limits::Limits;
use std::path::{Path, PathBuf};

/// The folder one read is confined to.
#[derive(Debug, Clone)]
pub(crate) struct Confinement {
    /// The folder resolved (canonical), for comparisons.
    folder: PathBuf,
    /// The folder as the caller gave it, for messages.
    shown: PathBuf,
}

impl Confinement {
    /// The confinement of a read of `path` (a file or folder) under `limits`: `None` without a
    /// [`Limits::confine_to`] folder or when `path` lies outside it (the caller named that file
    /// itself); an error when `path` lies in the folder but is a symbolic link out of it.
    pub(crate) fn of(path: &Path, limits: &Limits) -> Result<Option<Confinement>> {
        let Some(shown) = &limits.confine_to else {
            return Ok(None);
        };
        let folder = shown
            .canonicalize()
            .map_err(|e| IoError::os(shown, "resolve the folder reads are confined to", e))?;
        let inside = |p: Option<&PathBuf>| p.is_some_and(|p| p.starts_with(&folder));
        let named = located(path);
        let real = path.canonicalize().ok();
        let (named_inside, real_inside) = (inside(named.as_ref()), inside(real.as_ref()));
        if !named_inside && !real_inside {
            return Ok(None);
        }
        let c = Confinement {
            folder,
            shown: shown.clone(),
        };
        if real.is_some() && !real_inside {
            return Err(c.outside(
                path,
                "volume file (a symbolic link)",
                &path.to_string_lossy(),
            ));
        }
        Ok(Some(c))
    }

    /// Whether `target` lies inside the folder (resolved; a missing file by its folder and
    /// name).
    pub(crate) fn contains(&self, target: &Path) -> bool {
        match target.canonicalize() {
            Ok(real) => real.starts_with(&self.folder),
            Err(_) => located(target).is_some_and(|p| p.starts_with(&self.folder)),
        }
    }

    /// `Ok` if `target`, named by `referrer` as `value` (`what`: which reference, e.g.
    /// ``field `data file`: data file``), lies inside the folder; else
    /// [`IoError::OutsideFolder`].
    pub(crate) fn check(
        &self,
        referrer: &Path,
        what: &str,
        value: &str,
        target: &Path,
    ) -> Result<()> {
        if self.contains(target) {
            Ok(())
        } else {
            Err(self.outside(referrer, what, value))
        }
    }

    fn outside(&self, referrer: &Path, what: &str, value: &str) -> IoError {
        IoError::OutsideFolder {
            path: referrer.to_path_buf(),
            what: what.to_string(),
            value: clip(value),
            folder: self.shown.clone(),
        }
    }
}

/// `path` with its folder resolved and its last component kept (a link stays a link), or
/// `None` when the folder does not resolve or the name is `..`.
fn located(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(parent.canonicalize().ok()?.join(name))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn confined(dir: &Path) -> Limits {
        Limits {
            confine_to: Some(dir.to_path_buf()),
            ..Limits::default()
        }
    }

    /// A folder `data` beside a file `secret.raw` (test fixture of every reader's confinement
    /// test): `secret.raw` and `data/inside.raw` hold `bytes`; on Unix `data/link.raw` is a
    /// symbolic link to `../secret.raw`. `limits` confine reads to `data`.
    pub(crate) struct Layout {
        pub(crate) root: tempfile::TempDir,
        pub(crate) data: PathBuf,
        pub(crate) secret: PathBuf,
        pub(crate) limits: Limits,
    }

    pub(crate) fn layout(bytes: &[u8]) -> Layout {
        let root = tempfile::tempdir().unwrap();
        let data = root.path().join("data");
        std::fs::create_dir(&data).unwrap();
        let secret = root.path().join("secret.raw");
        std::fs::write(&secret, bytes).unwrap();
        std::fs::write(data.join("inside.raw"), bytes).unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink("../secret.raw", data.join("link.raw")).unwrap();
        let limits = confined(&data);
        Layout {
            root,
            data,
            secret,
            limits,
        }
    }

    /// Asserts that `e` is the refusal of `value` named by `header`'s `field`.
    pub(crate) fn assert_outside(e: &IoError, header: &str, field: &str, value: &str, l: &Layout) {
        assert!(matches!(e, IoError::OutsideFolder { .. }), "{e}");
        let s = e.to_string();
        for part in [
            header,
            field,
            &format!("`{value}`"),
            "lies outside",
            &l.data.display().to_string(),
        ] {
            assert!(s.contains(part), "{part:?} missing from: {s}");
        }
    }

    #[test]
    fn files_outside_the_folder_are_not_confined_and_links_out_are_refused() {
        let root = tempfile::tempdir().unwrap();
        let data = root.path().join("data");
        std::fs::create_dir(&data).unwrap();
        std::fs::write(root.path().join("out.nrrd"), b"x").unwrap();
        std::fs::write(data.join("in.nrrd"), b"x").unwrap();
        let l = confined(&data);
        // Without a folder, or for a file outside it, nothing is confined.
        assert!(
            Confinement::of(&data.join("in.nrrd"), &Limits::default())
                .unwrap()
                .is_none()
        );
        assert!(
            Confinement::of(&root.path().join("out.nrrd"), &l)
                .unwrap()
                .is_none()
        );
        let c = Confinement::of(&data.join("in.nrrd"), &l).unwrap().unwrap();
        assert!(c.contains(&data.join("in.nrrd")));
        assert!(c.contains(&data.join("missing.raw")));
        assert!(!c.contains(&data.join("../out.nrrd")));
        assert!(!c.contains(&data.join("../missing.raw")));
        assert!(!c.contains(&root.path().join("no/such/folder.raw")));
        assert!(!c.contains(Path::new("/")));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(root.path().join("out.nrrd"), data.join("link.nrrd"))
                .unwrap();
            assert!(!c.contains(&data.join("link.nrrd")));
            let e = Confinement::of(&data.join("link.nrrd"), &l).unwrap_err();
            assert!(matches!(e, IoError::OutsideFolder { .. }), "{e}");
            let s = e.to_string();
            assert!(
                s.contains("symbolic link") && s.contains("link.nrrd"),
                "{s}"
            );
        }
    }
}
