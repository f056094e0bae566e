//! Issue 28 follow-ups through the engine, as the front ends render: NaN samples load and render
//! (decision 0030), MinIP and MIP through the splat list see every voxel they need, and an orbit
//! over the pole is a picture, not an error.

use std::sync::Arc;
use volsplat::core::glam::DVec3;
use volsplat::core::{AnyVolume, Grid, Orbit, Projection, TransferFunction, Volume};
use volsplat::{
    CameraSpec, Mode, Output, RenderRequest, Renderer, RendererChoice, Scene, TransferSpec,
    VolumeSource,
};

fn memory(v: impl Into<AnyVolume>) -> VolumeSource {
    VolumeSource::Memory(Arc::new(v.into()))
}

fn render(
    volume: VolumeSource,
    camera: CameraSpec,
    mode: Mode,
    renderer: RendererChoice,
    tf: TransferSpec,
) -> Output {
    let scene = Scene {
        volume,
        camera,
        transfer_function: tf,
        ..Scene::default()
    };
    let mut req = RenderRequest::new(scene, 64, 64);
    req.mode = mode;
    req.renderer = renderer;
    Renderer::new()
        .render(&req, &mut |_| true)
        .unwrap_or_else(|e| panic!("{mode:?} {renderer:?}: {e}"))
}

/// Largest colour channel of the picture: 0 is black.
fn brightest(out: &Output) -> f32 {
    out.image
        .pixels()
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .fold(0.0, f32::max)
}

/// 32³ voxels of 100 holding two 10³ cubes on the same rows: 0 at x 3..=12 and 250 at
/// x 19..=28 (y, z 11..=20).
fn two_cubes() -> Volume<f32> {
    let grid = Grid::with_dims([32; 3]).unwrap();
    let inside = |v: usize| (11..=20).contains(&v);
    Volume::from_fn(grid, |i, j, k| match (i, inside(j) && inside(k)) {
        (3..=12, true) => 0.0,
        (19..=28, true) => 250.0,
        _ => 100.0,
    })
    .unwrap()
}

/// The pixels of the reset view (looking down −z, +y up) whose rays pass through the cube
/// spanning voxel centres `x0..=x1` (y 11..=20) at least 2 voxels (the Gaussian's radius) in
/// from its faces: there every sample along the ray inside the cube reconstructs the cube's
/// value exactly.
fn interior_pixels(out: &Output, x0: f64, x1: f64) -> Vec<(usize, usize)> {
    let (w, h) = (out.image.width(), out.image.height());
    let proj = Projection::new(&out.camera, w, h).unwrap();
    let a = proj.raster_from_world(DVec3::new(x0 + 2.0, 13.0, 15.5));
    let b = proj.raster_from_world(DVec3::new(x1 - 2.0, 18.0, 15.5));
    let (xs, ys) = ((a.x.min(b.x), a.x.max(b.x)), (a.y.min(b.y), a.y.max(b.y)));
    let px: Vec<_> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
            cx >= xs.0 && cx <= xs.1 && cy >= ys.0 && cy <= ys.1
        })
        .collect();
    assert!(px.len() >= 16, "{} interior pixels", px.len());
    px
}

/// Issue 28 follow-up: MinIP through the splat list (`--splat-list --mode minip`) built the
/// list from the transfer function, so under the automatic window (the lowest values
/// transparent) it dropped the very voxels MinIP shows: the low cube's rays gave the
/// background, 100, instead of 0. MIP had the same flaw under a function that hides the
/// largest values. Closed form: along a ray through a cube's interior the minimum (maximum) of
/// the reconstruction is the cube's value where it is below (above) the background, else the
/// background's. The image-aligned slabs (`auto`), which sample every voxel, agree.
#[test]
fn minip_and_mip_through_the_splat_list_see_every_voxel() {
    let vol = memory(two_cubes());
    let reset = CameraSpec::Orbit(Orbit::default());
    // Opaque only between 50 and 150: the hot cube (250) and the cold one (0) are hidden.
    let band = TransferFunction {
        scalar_opacity: vec![
            [0.0, 0.0],
            [50.0, 0.0],
            [100.0, 0.8],
            [150.0, 0.0],
            [255.0, 0.0],
        ],
        ..TransferFunction::ramp(0.0, 255.0, 0.8)
    };
    for (mode, tf, cold, hot) in [
        (Mode::Minip, TransferSpec::Auto, 0.0, 100.0),
        (
            Mode::Minip,
            TransferSpec::Function(band.clone()),
            0.0,
            100.0,
        ),
        (Mode::Mip, TransferSpec::Auto, 100.0, 250.0),
        (
            Mode::Mip,
            TransferSpec::Function(band.clone()),
            100.0,
            250.0,
        ),
    ] {
        for renderer in [RendererChoice::SplatList, RendererChoice::Auto] {
            let out = render(vol.clone(), reset.clone(), mode, renderer, tf.clone());
            let v = out.values.as_ref().unwrap();
            for (x0, x1, want) in [(3.0, 12.0, cold), (19.0, 28.0, hot)] {
                for (x, y) in interior_pixels(&out, x0, x1) {
                    let got = v.get(x, y);
                    assert!(
                        (got - want).abs() < 0.5,
                        "{mode:?} {renderer:?} {tf:?}: pixel ({x}, {y}) is {got}, the {} \
                         along its ray is {want}",
                        if mode == Mode::Minip {
                            "minimum"
                        } else {
                            "maximum"
                        }
                    );
                }
            }
        }
    }
}

/// A float volume: a smooth blob in a sphere, NaN outside (SPM's and nibabel's masked images).
fn nan_background() -> Volume<f32> {
    let grid = Grid::new([24, 20, 16], [1.0, 1.2, 1.5], [0.0; 3], Default::default()).unwrap();
    let c = DVec3::new(11.5, 9.5, 7.5);
    let data: Vec<f32> = (0..24 * 20 * 16)
        .map(|n| {
            let p = DVec3::new((n % 24) as f64, ((n / 24) % 20) as f64, (n / 480) as f64);
            let r = ((p - c) / DVec3::new(11.0, 9.0, 7.0)).length();
            if r > 1.0 {
                f32::NAN
            } else {
                (50.0 + 200.0 * (1.0 - r * r)) as f32
            }
        })
        .collect();
    Volume::new(grid, data).unwrap()
}

/// Issue 28 follow-up: a volume with a NaN background (a file nibabel, ITK, Slicer and napari
/// read) was refused. It renders in every mode and renderer, never NaN, never black but for
/// MinIP (which shows the background: what NaN became), and the render's notes say so.
#[test]
fn a_nan_background_renders_and_the_notes_say_so() {
    let vol = nan_background();
    let r = *vol.non_finite().unwrap();
    assert!(r.nan > 1000 && r.lowest > 49.0, "{r:?}");
    let vol = memory(vol);
    for mode in [Mode::Composite, Mode::Mip, Mode::Minip, Mode::Xray] {
        for renderer in [RendererChoice::Auto, RendererChoice::SplatList] {
            let out = render(
                vol.clone(),
                CameraSpec::Orbit(Orbit {
                    azimuth: Some(30.0),
                    elevation: Some(20.0),
                    ..Orbit::default()
                }),
                mode,
                renderer,
                TransferSpec::Auto,
            );
            let tag = format!("{mode:?} {renderer:?}");
            if mode == Mode::Minip {
                // Every ray crosses the background, now the lowest value: MinIP shows it, as
                // for the same volume with a background of 50 (decision 0030).
                let v = out.values.as_ref().unwrap();
                let (w, h) = (v.width(), v.height());
                assert!((v.get(w / 2, h / 2) - r.lowest).abs() < 0.5, "{tag}");
            } else {
                assert!(brightest(&out) > 0.05, "{tag}: black");
            }
            assert!(
                out.image.pixels().iter().flatten().all(|c| c.is_finite()),
                "{tag}: NaN pixels"
            );
            let note = format!("taken as the lowest finite value {}", r.lowest);
            assert!(
                out.notes.iter().any(|n| n.contains(&note)),
                "{tag}: {:?}",
                out.notes
            );
        }
    }
}

/// Issue 28 follow-up: `--azimuth 36 --elevation 90` (about one orbit in twenty with an
/// elevation of ±90) was an error ("invalid view_up: NaN"); VTK's
/// `Elevation(90)` then `OrthogonalizeViewUp` looks down from above with view-up turned with
/// the eye. It renders, from above, with that view-up.
#[test]
fn an_orbit_over_the_pole_renders() {
    let vol = memory(two_cubes());
    // After azimuth a the direction of projection is −(sin a, 0, cos a): the new view-up
    // (negated for −90). Azimuth 36 rounded to a view-up along the view.
    for (azimuth, elevation) in [(0.0, 90.0), (0.0, -90.0), (36.0, 90.0), (43.0, -90.0)] {
        let a = f64::to_radians(azimuth);
        let up = -DVec3::new(a.sin(), 0.0, a.cos()) * f64::signum(elevation);
        let out = render(
            vol.clone(),
            CameraSpec::Orbit(Orbit {
                azimuth: Some(azimuth),
                elevation: Some(elevation),
                ..Orbit::default()
            }),
            Mode::Mip,
            RendererChoice::Auto,
            TransferSpec::Auto,
        );
        let f = out.camera.frame();
        assert!((f.forward - DVec3::Y * -elevation.signum()).length() < 1e-9);
        assert!((f.up - up).length() < 1e-9, "{elevation}: up {}", f.up);
        assert!(brightest(&out) > 0.05, "{elevation}: black");
    }
}
