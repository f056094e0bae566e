#![no_main]
//! Fuzz target: one DICOM file standing for its series (structure walk, dicom-object, pixel decoders).

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::with_file("x.dcm", data, |p| {
        let _ = volsplat_io::read_volume_with(p, &common::options());
    });
});
