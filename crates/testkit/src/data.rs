//! The shared test data (`shared/data` beside the repository: two MRI volumes and VTK scenes)
//! for tests that use it when present and skip when absent. Only what the crates below
//! `volsplat-io` need: they cannot use its readers.

use std::path::{Path, PathBuf};
use std::process::Command;
use volsplat_core::{Grid, Volume};

/// The path of `name` in the shared test data folder (`shared/data` beside the repository's
/// root); the file may be absent.
pub fn shared_data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(name)
}

/// Reads an 8-bit NRRD of the shared test data (attached or detached header; raw encoding, or
/// gzip through the `gzip` program) on a unit grid (spacing, origin and direction are not read).
/// `None`, with a note on stderr, when the file or `gzip` is missing; panics on any other
/// surprise (a test's data must be what the test expects).
pub fn read_u8_nrrd(path: &Path) -> Option<Volume<u8>> {
    let shown = path.display();
    let bytes = std::fs::read(path)
        .map_err(|e| eprintln!("note: {shown}: {e}; skipping"))
        .ok()?;
    let end = bytes
        .windows(2)
        .position(|w| w == b"\n\n")
        .map_or(bytes.len(), |p| p + 2);
    let header = String::from_utf8_lossy(&bytes[..end]).to_string();
    let field = |name: &str| {
        header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{name}: ")))
            .map(str::trim)
    };
    assert_eq!(field("type"), Some("uint8"), "{shown}");
    let dims: Vec<usize> = field("sizes")?
        .split_whitespace()
        .map(|s| s.parse().unwrap())
        .collect();
    let data = match (field("encoding"), field("data file")) {
        (Some("raw"), None) => bytes[end..].to_vec(),
        (Some("gzip"), Some(file)) => {
            let out = Command::new("gzip")
                .arg("-dc")
                .arg(path.parent()?.join(file))
                .output()
                .map_err(|e| eprintln!("note: gzip: {e}; skipping {shown}"))
                .ok()?;
            assert!(out.status.success(), "gzip failed on {file}");
            out.stdout
        }
        other => panic!("{shown}: unexpected encoding {other:?}"),
    };
    Some(Volume::new(Grid::with_dims([dims[0], dims[1], dims[2]]).unwrap(), data).unwrap())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reader agrees with `volsplat-io`'s on both shared MRIs (attached raw and detached
    /// gzip); skipped when the data is absent.
    #[test]
    fn reads_the_shared_mris_as_volsplat_io_does() {
        for name in ["mri_brainsmall.nrrd", "mri_colin27.nhdr"] {
            let path = shared_data(name);
            let Some(ours) = read_u8_nrrd(&path) else {
                continue;
            };
            let io = volsplat_io::read_volume(&path).unwrap();
            let volsplat_core::AnyVolume::U8(theirs) = io else {
                panic!("{name}: not 8-bit");
            };
            assert_eq!(ours.grid().dims, theirs.grid().dims, "{name}");
            assert!(ours.data() == theirs.data(), "{name}: samples differ");
        }
    }
}
