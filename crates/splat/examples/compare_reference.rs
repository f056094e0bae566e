//! Renders the demo head with the splatter and with the brute-force reference integrator, and
//! writes both as binary PPM files for side-by-side inspection (development aid).
//!
//! `cargo run --release -p volsplat-splat --example compare_reference -- OUT_DIR`

use std::io::Write;
use volsplat_core::phantom;
use volsplat_core::{Camera, CrioTables, Image, OrthoProjection, Projection, TransferFunction};
use volsplat_splat::{RenderSettings, render};
use volsplat_testkit::reference::{ReferenceSettings, reference_composite};

fn write_ppm(path: &std::path::Path, img: &Image) -> std::io::Result<()> {
    let mut f = std::fs::File::create(path)?;
    writeln!(f, "P6 {} {} 255", img.width(), img.height())?;
    let enc = |v: f32| {
        let v = v.clamp(0.0, 1.0);
        let s = if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0 + 0.5) as u8
    };
    for p in img.pixels() {
        f.write_all(&[enc(p[0]), enc(p[1]), enc(p[2])])?;
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    let preset = std::env::args().nth(2).unwrap_or_else(|| "ct-bone".into());
    let vol = phantom::ct_head_volume([128, 160, 144])?.to_f32();
    let (lo, hi) = vol.grid().bounds_world();
    let mut cam = Camera::reset_to_bounds(lo, hi, true);
    cam.azimuth(30.0);
    cam.elevation(15.0);
    cam.orthogonalize_view_up();
    let tables = CrioTables::from_transfer_function(
        &TransferFunction::preset(&preset, (-1000.0, 2000.0))?,
        4096,
    )?;
    let s = {
        let mut s = RenderSettings::default();
        s.width = 256;
        s.height = 256;
        s
    };
    let splat = render(&vol, &cam, &tables, &s)?;
    write_ppm(&out.join("splat.ppm"), &splat.image)?;
    let proj = OrthoProjection::new(&cam, 256, 256)?;
    let reference = reference_composite(
        &vol,
        &Projection::Ortho(proj),
        &tables,
        &ReferenceSettings::default(),
    );
    write_ppm(&out.join("reference.ppm"), &reference)?;
    let psnr = volsplat_testkit::metrics::image_psnr(&splat.image, &reference);
    println!("PSNR splat vs reference: {psnr:.2} dB");
    Ok(())
}
