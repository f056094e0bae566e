//! Shared by the fuzz targets: small limits, and the input written to a file in a folder of
//! its own (the readers take paths; DICOM reads the file's folder).

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Limits small enough that a valid-looking header cannot ask for much memory.
pub fn limits() -> volsplat_io::Limits {
    volsplat_io::Limits::default()
        .with_max_header_bytes(64 << 10)
        .with_max_voxels(1 << 20)
        .with_max_json_bytes(1 << 20)
        .with_max_xml_bytes(4 << 20)
}

/// The default voxel limit (2³⁴) with the small header and XML limits: a small input that
/// declares a large grid must still never allocate more than its payload backs, so that
/// `-malloc_limit_mb` turns any allocation sized from a header alone into a finding (issue 28
/// §2: a `.vti` LZ4 header declaring 2⁴⁰-byte blocks allocated 32 GiB).
pub fn wide_limits() -> volsplat_io::Limits {
    limits().with_max_voxels(volsplat_io::Limits::default().max_voxels)
}

pub fn wide_options() -> volsplat_io::ReadOptions {
    volsplat_io::ReadOptions::default().with_limits(wide_limits())
}

pub fn options() -> volsplat_io::ReadOptions {
    volsplat_io::ReadOptions::default().with_limits(limits())
}

fn dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("volsplat-fuzz-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("create the fuzz folder");
        d
    })
}

/// Writes `data` to `name` in the fuzz folder (the only file there) and calls `f` with its path.
pub fn with_file(name: &str, data: &[u8], f: impl FnOnce(&Path)) {
    let p = dir().join(name);
    std::fs::write(&p, data).expect("write the fuzz input");
    f(&p);
    let _ = std::fs::remove_file(&p);
}

/// Writes the files of a store (`(relative path, bytes)`, folders created) into a fresh folder
/// `name` of the fuzz folder, calls `f` with the folder's path, then removes it.
pub fn with_files(name: &str, files: &[(&str, &[u8])], f: impl FnOnce(&Path)) {
    let root = dir().join(name);
    let _ = std::fs::remove_dir_all(&root);
    for (rel, bytes) in files {
        let p = root.join(rel);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent).expect("create the store's folders");
        }
        std::fs::write(&p, bytes).expect("write the fuzz input");
    }
    f(&root);
    let _ = std::fs::remove_dir_all(&root);
}
