#![no_main]
//! Fuzz target: OME-Zarr stores (issue 31 item 7: hostile metadata, corrupt chunks). The input
//! is the store's files separated by `\n--\n`: Zarr v3 (`zarr.json`, `0/zarr.json`, chunk
//! `0/c/0/0/0`, `1/zarr.json`, chunk `1/c/0/0/0`) or, where the input starts with `2`, Zarr v2
//! (`.zattrs`, `.zgroup`, `0/.zarray`, chunk `0/0/0/0`, `1/.zarray`, chunk `1/0/0/0`;
//! the `/` separator our writer uses). The store
//! is opened, every level's geometry taken and read whole, and one brick read through the brick
//! source: every outcome must be a value or an error, never a panic, and no allocation may be
//! sized from the metadata alone (`-malloc_limit_mb`).

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use std::sync::Arc;
use volsplat_core::source::{BrickKey, BrickSource};
use volsplat_io::{ZarrSelection, ZarrSource, ZarrStore};

const V3: [&str; 5] = ["zarr.json", "0/zarr.json", "0/c/0/0/0", "1/zarr.json", "1/c/0/0/0"];
const V2: [&str; 6] = [".zattrs", ".zgroup", "0/.zarray", "0/0/0/0", "1/.zarray", "1/0/0/0"];

fn split(data: &[u8]) -> Vec<&[u8]> {
    let sep = b"\n--\n";
    let mut out = Vec::new();
    let mut rest = data;
    while let Some(at) = rest.windows(sep.len()).position(|w| w == sep) {
        out.push(&rest[..at]);
        rest = &rest[at + sep.len()..];
    }
    out.push(rest);
    out
}

fn exercise(path: &std::path::Path) {
    for limits in [common::limits(), common::wide_limits()] {
        let Ok(store) = ZarrStore::open(path, &limits) else {
            continue;
        };
        let sel = ZarrSelection::default();
        let store = Arc::new(store);
        for l in 0..store.levels().len() {
            let _ = store.grid(l);
            let _ = store.read_level(l, sel);
        }
        if let Ok(source) = ZarrSource::<u16>::new(Arc::clone(&store), sel, 8) {
            let _ = source.brick(BrickKey { level: 0, b: [0, 0, 0] });
        }
        if let Ok(source) = ZarrSource::<f32>::new(Arc::clone(&store), sel, 8) {
            let _ = source.as_stored().brick(BrickKey { level: 0, b: [0, 0, 0] });
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let (names, body): (&[&str], &[u8]) = match data.first() {
        Some(b'2') => (&V2, &data[1..]),
        _ => (&V3, data),
    };
    let files: Vec<(&str, &[u8])> = names.iter().copied().zip(split(body)).collect();
    common::with_files("x.zarr", &files, exercise);
});
