#![no_main]
//! Fuzz target: transfer-function JSON files (then the lookup tables).

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::with_file("tf.json", data, |p| {
        if let Ok((tf, _)) = volsplat_io::load_transfer_function_with(p, &common::limits()) {
            // What a render does next: the CRIO tables, and lookups at extreme values.
            let _ = volsplat_core::crio::CrioTables::from_transfer_function(&tf, 256);
            for x in [f64::MIN, -1e300, -1.0, 0.0, 0.5, 1e300, f64::MAX, f64::NAN] {
                let _ = (tf.color_at(x), tf.opacity_at(x), tf.gradient_opacity_at(x));
            }
        }
    });
});
