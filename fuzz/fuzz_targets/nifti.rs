#![no_main]
//! Fuzz target: NIfTI-1/-2 .nii, and .nii.gz when the first byte is odd.

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (name, body) = match data.split_first() {
        Some((b, rest)) if b & 1 == 1 => ("x.nii.gz", rest),
        Some((_, rest)) => ("x.nii", rest),
        None => ("x.nii", data),
    };
    common::with_file(name, body, |p| {
        let o = common::options();
        let _ = volsplat_io::read_nifti_with(p, &o);
        let o = o.with_frame(1);
        let _ = volsplat_io::read_nifti_with(p, &o);
        let _ = volsplat_io::read_nifti_with(p, &common::wide_options());
    });
});
