#![no_main]
//! Fuzz target: VTK XML image data (ascii, base64, appended, zlib).

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::with_file("x.vti", data, |p| {
        let _ = volsplat_io::read_vti_with(p, &common::options());
        let _ = volsplat_io::read_vti_with(p, &common::wide_options());
    });
});
