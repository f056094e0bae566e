#![no_main]
//! Fuzz target: multi-page TIFF stacks.

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::with_file("x.tif", data, |p| {
        let _ = volsplat_io::read_tiff_with(p, &common::options());
    });
});
