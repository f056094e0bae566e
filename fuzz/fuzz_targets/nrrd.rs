#![no_main]
//! Fuzz target: NRRD headers and payloads (attached header, raw/gzip/ascii).

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::with_file("x.nrrd", data, |p| {
        let _ = volsplat_io::read_nrrd_with(p, &common::options());
        let _ = volsplat_io::read_nrrd_with(p, &common::wide_options());
    });
});
