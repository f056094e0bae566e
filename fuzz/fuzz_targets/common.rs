//! Shared by the fuzz targets: small limits, and the input written to a file in a folder of
//! its own (the readers take paths; DICOM reads the file's folder).

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Limits small enough that a valid-looking header cannot ask for much memory.
pub fn limits() -> volsplat_io::Limits {
    volsplat_io::Limits {
        max_header_bytes: 64 << 10,
        max_voxels: 1 << 20,
        max_json_bytes: 1 << 20,
        max_xml_bytes: 4 << 20,
    }
}

pub fn options() -> volsplat_io::ReadOptions {
    volsplat_io::ReadOptions {
        limits: limits(),
        ..Default::default()
    }
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
