#![no_main]
//! Fuzz target: MetaImage .mha (attached data, raw or zlib).

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::with_file("x.mha", data, |p| {
        let _ = volsplat_io::read_metaimage_with(p, &common::options());
        let _ = volsplat_io::read_metaimage_with(p, &common::wide_options());
    });
});
