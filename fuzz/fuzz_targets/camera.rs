#![no_main]
//! Fuzz target: camera JSON files.

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::with_file("camera.json", data, |p| {
        if let Ok((camera, _)) = volsplat_io::load_camera_with(p, &common::limits()) {
            // What a render does next: the projection for a small image.
            let _ = volsplat_core::camera::OrthoProjection::new(&camera, 64, 48);
            let _ = volsplat_core::camera::PerspectiveProjection::new(&camera, 64, 48);
        }
    });
});
