//! Perspective splatting and anti-aliasing (Swan et al. 1997): energy conservation, and
//! perspective correctness against the brute-force reference integrator and closed-form line
//! integrals. The aliasing and flicker measurements (orthographic minification, the
//! perspective checkerboard of Fig. 7a–b, a dolly) are tested in
//! `crates/studies/tests/antialias.rs`.

use volsplat_core::glam::DVec3;
use volsplat_core::phantom::{self, Blob, GaussianBlobs, Phantom};
use volsplat_core::{Camera, CrioTables, Grid, Projection, TransferFunction};
use volsplat_splat::list::k_distance;
use volsplat_splat::{
    Antialias, ExtractSettings, RenderMode, RenderSettings, SplatList, render_list,
};
use volsplat_testkit::metrics::{image_psnr, relative_l2};
use volsplat_testkit::reference::{ReferenceSettings, reference_composite};

fn blobs() -> GaussianBlobs {
    let b = |x: f64, y: f64, z: f64, sigma: f64, amplitude: f64| Blob {
        center: DVec3::new(x, y, z),
        sigma,
        amplitude,
    };
    GaussianBlobs::new(vec![
        b(0.0, 0.0, 0.0, 0.18, 1.0),
        b(0.3, 0.25, -0.2, 0.14, 0.8),
        b(-0.32, 0.2, 0.3, 0.12, 0.9),
        b(0.2, -0.35, 0.3, 0.13, 0.6),
    ])
}

fn perspective_camera(grid: &Grid, az: f64, el: f64, dolly: f64) -> Camera {
    let (lo, hi) = grid.bounds_world();
    let mut c = Camera::reset_to_bounds(lo, hi, false);
    c.azimuth(az);
    c.elevation(el);
    c.orthogonalize_view_up();
    c.dolly(dolly);
    c
}

#[test]
fn perspective_xray_matches_closed_form_line_integrals() {
    let p = blobs();
    let vol = phantom::sample(&p, [96; 3], 1).unwrap();
    let tables =
        CrioTables::from_transfer_function(&TransferFunction::ramp(0.0, 1.0, 1.0), 256).unwrap();
    let list = SplatList::build(&vol, &tables, &ExtractSettings::default()).unwrap();
    let cam = perspective_camera(vol.grid(), 35.0, 20.0, 1.4);
    let (w, h) = (120, 100);
    let s = RenderSettings {
        width: w,
        height: h,
        mode: RenderMode::Xray,
        ..RenderSettings::default()
    };
    let out = render_list(&list, &cam, &tables, &s).unwrap();
    let proj = Projection::new(&cam, w, h).unwrap();
    let mut exact = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let (o, d) = proj.ray(x as f64 + 0.5, y as f64 + 0.5);
            exact.push(p.line_integral(o, d).unwrap() as f32);
        }
    }
    let err = relative_l2(out.values.unwrap().values(), &exact);
    eprintln!("perspective X-ray vs closed form: {:.3} %", 100.0 * err);
    assert!(err < 0.01, "relative L2 {err}");
}

#[test]
fn perspective_composite_matches_the_reference_integrator() {
    let vol = phantom::sample(&blobs(), [64; 3], 1).unwrap();
    let tables = volsplat_testkit::fixtures::shaded_tables().unwrap();
    let list = SplatList::build(&vol, &tables, &ExtractSettings::default()).unwrap();
    let (w, h) = (128, 128);
    let mut report = Vec::new();
    for (az, el, dolly) in [(30.0, 20.0, 1.3), (-50.0, 35.0, 1.8)] {
        let cam = perspective_camera(vol.grid(), az, el, dolly);
        let proj = Projection::new(&cam, w, h).unwrap();
        // Voxels span more than a pixel here (no anti-aliasing takes effect).
        let k = k_distance(vol.grid(), 1, &proj).unwrap();
        let (_, hi) = vol.grid().bounds_world();
        let far = (DVec3::from(cam.position) - hi).length() + 2.0;
        assert!(far < k, "far {far} vs k {k}");
        let reference = reference_composite(&vol, &proj, &tables, &ReferenceSettings::default());
        let s = RenderSettings {
            width: w,
            height: h,
            ..RenderSettings::default()
        };
        let out = render_list(&list, &cam, &tables, &s).unwrap();
        assert_eq!(out.stats.splats_widened, 0);
        let psnr = image_psnr(&out.image, &reference);
        report.push(format!("az {az} el {el} dolly {dolly}: {psnr:.1} dB"));
        assert!(psnr >= 35.0, "{report:?}");
    }
    eprintln!("perspective composite vs reference: {}", report.join(", "));
}

#[test]
fn far_away_xray_keeps_its_energy_when_splats_grow() {
    // The blobs seen from far away: about 6 voxels per pixel.
    let p = blobs();
    let vol = phantom::sample(&p, [96; 3], 1).unwrap();
    let tables =
        CrioTables::from_transfer_function(&TransferFunction::ramp(0.0, 1.0, 1.0), 256).unwrap();
    let list = SplatList::build(&vol, &tables, &ExtractSettings::default()).unwrap();
    let cam = perspective_camera(vol.grid(), 20.0, 10.0, 0.25);
    let (w, h) = (64, 64);
    let proj = Projection::new(&cam, w, h).unwrap();
    let dist = (DVec3::from(cam.position) - DVec3::from(cam.focal_point)).length();
    // ∫∫ X dA over the image, with the pixel area at the blobs' distance.
    let energy = |aa: Antialias| {
        let s = RenderSettings {
            width: w,
            height: h,
            mode: RenderMode::Xray,
            antialias: aa,
            ..RenderSettings::default()
        };
        let out = render_list(&list, &cam, &tables, &s).unwrap();
        assert!(aa == Antialias::None || out.stats.splats_widened == out.stats.splats);
        let px = proj.pixel_size_at(dist);
        out.values
            .unwrap()
            .values()
            .iter()
            .map(|&v| v as f64)
            .sum::<f64>()
            * px
            * px
    };
    let cell: f64 = vol.grid().spacing.iter().product();
    let mass: f64 = vol.data().iter().map(|&v| v as f64).sum::<f64>() * cell;
    let (none, swan, ewa) = (
        energy(Antialias::None) / mass,
        energy(Antialias::Swan) / mass,
        energy(Antialias::Ewa) / mass,
    );
    eprintln!("far-away X-ray energy / mass: none {none:.4}, swan {swan:.4}, ewa {ewa:.4}");
    // The pixel area is taken at the focal distance; the blobs spread ±1 around it, a
    // second-order effect below 0.3 % here.
    assert!((swan - 1.0).abs() < 0.01, "swan {swan}");
    assert!((ewa - 1.0).abs() < 0.01, "ewa {ewa}");
}
