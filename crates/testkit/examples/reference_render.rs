//! Renders a scene with the brute-force reference integrator (float arithmetic, trilinear
//! samples every `step` world units, interpolated voxel gradients; `testkit::reference`) and
//! writes the premultiplied RGBA image as `.npy`: an independent converged reference for
//! `bench/convergence.py`, free of the fixed-point rounding of VTK's ray caster.
//!
//! ```sh
//! cargo run --release -p volsplat-testkit --example reference_render -- \
//!     VOLUME CAMERA.json TF.json SIZE STEP_FRACTION SUPERSAMPLE OUT.npy [voxels]
//! ```
//! `STEP_FRACTION` is the step in units of the smallest spacing (e.g. 0.125); `SUPERSAMPLE`
//! is the number of rays per pixel and axis, box-averaged; `voxels` shades at the voxels
//! (VTK's order, `ReferenceSettings::shade_at_voxels`) instead of at the samples.

use volsplat_core::{CrioTables, Projection};
use volsplat_testkit::reference::{ReferenceSettings, reference_composite};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let shade_at_voxels = match a.get(8).map(String::as_str) {
        None => false,
        Some("voxels") if a.len() == 9 => true,
        _ => {
            return Err(
                "usage: VOLUME CAMERA TF SIZE STEP_FRACTION SUPERSAMPLE OUT.npy [voxels]".into(),
            );
        }
    };
    if a.len() < 8 {
        return Err(
            "usage: VOLUME CAMERA TF SIZE STEP_FRACTION SUPERSAMPLE OUT.npy [voxels]".into(),
        );
    }
    let vol = volsplat_io::read_volume(&a[1])?.to_f32();
    let (camera, _) = volsplat_io::load_camera(&a[2])?;
    let (tf, _) = volsplat_io::load_transfer_function(&a[3])?;
    let size: usize = a[4].parse()?;
    let fraction: f64 = a[5].parse()?;
    let supersample: usize = a[6].parse()?;
    let tables = CrioTables::from_transfer_function(&tf, volsplat_core::crio::DEFAULT_TABLE_LEN)?;
    let proj = Projection::new(&camera, size, size)?;
    let min_spacing = vol
        .grid()
        .spacing
        .iter()
        .fold(f64::INFINITY, |m, &s| m.min(s));
    let settings = ReferenceSettings {
        step: fraction * min_spacing,
        supersample,
        shade_at_voxels,
        ..ReferenceSettings::default()
    };
    let image = reference_composite(&vol, &proj, &tables, &settings);
    volsplat_io::write_npy_rgba(&a[7], &image)?;
    Ok(())
}
