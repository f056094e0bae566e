#![no_main]
//! Fuzz target: .npy float images.

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::with_file("x.npy", data, |p| {
        let _ = volsplat_io::read_npy_f32_with(p, &common::limits());
    });
});
