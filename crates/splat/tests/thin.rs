//! Thin volumes (issue 28 §1, `docs/decisions/0023-thin-volumes.md`): one, two and three samples
//! along an axis, through every renderer, against closed forms. A single slice (a 2-D image, one
//! DICOM slice, Swan's checkerboard) used to render black with the image-aligned slabs, the
//! front ends' default: their rays found no depth inside a box of zero thickness.
//!
//! What each renderer draws (decision 0023): the slabs, like the reference integrator and VTK's
//! ray casters, the box of voxel centres, an axis of one sample spanning its voxel (one spacing,
//! centred on the sample); the splatting renderers (Westover's sheets, the splat list) every
//! voxel's cell, each kernel integrating to one voxel along the ray. The two agree on a
//! one-sample axis; along an axis of `n ≥ 2` samples the splats cover one spacing more.
//! `crates/splat/tests/every_angle.rs` sweeps the view over thin volumes against the reference.

use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{Camera, CrioTables, Grid, Light, Scalar, TransferFunction, Volume};
use volsplat_splat::{
    Antialias, ExtractSettings, Preintegrate, RenderMode, RenderSettings, Rendered, ShadeAt,
    SplatList, Visibility, render, render_list, render_slabs,
};

/// Opacity per unit length of the constant transfer function.
const ALPHA: f64 = 0.3;
/// The constant volumes' value.
const RHO: f32 = 0.7;

/// Constant opacity [`ALPHA`] per world unit and colour (0.2, 0.6, 0.9) over `[0, 1]`.
fn constant_tables(shade: bool) -> CrioTables {
    let tf = TransferFunction {
        color: vec![[0.0, 0.2, 0.6, 0.9], [1.0, 0.2, 0.6, 0.9]],
        scalar_opacity: vec![[0.0, ALPHA], [1.0, ALPHA]],
        scalar_opacity_unit_distance: 1.0,
        shade,
        ambient: 1.0,
        diffuse: 0.0,
        specular: 0.0,
        ..TransferFunction::ramp(0.0, 1.0, 1.0)
    };
    // A white ambient light, so that the shaded table's colour is the transfer function's.
    let light = Light {
        ambient_color: [1.0; 3],
        ..Light::headlight()
    };
    CrioTables::from_transfer_function_lit(&tf, 1024, vec![light]).unwrap()
}

/// A 17 × 13 grid (spacing 1) with `n` samples of spacing `sz` along k, its first voxel centre
/// at `z0`.
fn thin_grid(n: usize, sz: f64, z0: f64) -> Grid {
    Grid::new([17, 13, n], [1.0, 1.0, sz], [0.0, 0.0, z0], DMat3::IDENTITY).unwrap()
}

fn constant<T: Scalar>(grid: &Grid, v: T) -> Volume<T> {
    Volume::from_fn(grid.clone(), |_, _, _| v).unwrap()
}

/// Looking at the grid's centre along −z turned by `tilt` degrees about y.
fn tilted_camera(grid: &Grid, tilt: f64, perspective: bool) -> Camera {
    let (lo, hi) = grid.drawn_bounds_world();
    let mut c = Camera::reset_to_bounds(lo, hi, !perspective);
    c.azimuth(tilt);
    c
}

/// The renderers of the front ends' `auto` choice and their options: the slabs at ½ and 1
/// voxel, pre-integrated, shaded at the voxels, and at 16 voxels (capped at the sheet's
/// thickness); and the splatting renderer for the projection.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Drawer {
    Slab(f64, Preintegrate, ShadeAt),
    Splat,
}

const SLABS: [Drawer; 5] = [
    Drawer::Slab(0.5, Preintegrate::Off, ShadeAt::Samples),
    Drawer::Slab(1.0, Preintegrate::Off, ShadeAt::Samples),
    Drawer::Slab(1.0, Preintegrate::On, ShadeAt::Samples),
    Drawer::Slab(1.0, Preintegrate::Off, ShadeAt::Voxels),
    Drawer::Slab(16.0, Preintegrate::Off, ShadeAt::Samples),
];

fn draw<T: Scalar>(
    vol: &Volume<T>,
    cam: &Camera,
    tables: &CrioTables,
    drawer: Drawer,
    mode: RenderMode,
    size: (usize, usize),
) -> Rendered {
    draw_simd(true, vol, cam, tables, drawer, mode, size)
}

/// [`draw`], with the slabs' AVX2 kernels (`simd`) or their scalar twins.
fn draw_simd<T: Scalar>(
    simd: bool,
    vol: &Volume<T>,
    cam: &Camera,
    tables: &CrioTables,
    drawer: Drawer,
    mode: RenderMode,
    (w, h): (usize, usize),
) -> Rendered {
    let base = {
        let mut s = RenderSettings::default();
        s.width = w;
        s.height = h;
        s.mode = mode;
        s.antialias = Antialias::None;
        s.simd = simd;
        s
    };
    match drawer {
        Drawer::Slab(slab, preintegrate, shade_at) => {
            let s = {
                let mut s = base;
                s.visibility = Visibility::ImageAligned;
                s.slab = slab;
                s.preintegrate = preintegrate;
                s.shade_at = shade_at;
                s
            };
            render_slabs(vol, cam, tables, &s, None, &mut |_| true).unwrap()
        }
        Drawer::Splat if cam.parallel_projection => render(vol, cam, tables, &base).unwrap(),
        Drawer::Splat => {
            let list = SplatList::build(vol, tables, &ExtractSettings::default()).unwrap();
            render_list(&list, cam, tables, &base).unwrap()
        }
    }
}

/// A constant sheet of 1, 2 and 3 samples along k, seen face-on and 35° off its normal, both
/// projections: the centre pixel's ray crosses `t / cos θ` world units of it, `t` the drawn
/// thickness (slabs: one spacing for one sample, `(n − 1)` spacings otherwise; splats: `n`
/// spacings), so composite is `1 − (1 − α)^(t / cos θ)` in the transfer function's colour,
/// MIP and MinIP are the value, and X-ray (splats) is `ρ·t / cos θ`. The thin axis' spacing
/// differs from the others' (1.5 against 1), so one spacing means its own.
#[test]
fn constant_thin_volumes_match_closed_forms() {
    let (plain, lit) = (constant_tables(false), constant_tables(true));
    let size = (33, 27);
    let centre = (size.1 / 2) * size.0 + size.0 / 2;
    let mut report = Vec::new();
    for n in 1..=3usize {
        let sz = 1.5;
        let grid = thin_grid(n, sz, 4.0);
        let vol = constant(&grid, RHO);
        for tilt in [0.0f64, 35.0] {
            for perspective in [false, true] {
                let cam = tilted_camera(&grid, tilt, perspective);
                let cos = tilt.to_radians().cos();
                for drawer in SLABS.into_iter().chain([Drawer::Splat]) {
                    let t = match drawer {
                        Drawer::Slab(..) => (n.max(2) - 1) as f64 * sz,
                        Drawer::Splat => n as f64 * sz,
                    };
                    let path = t / cos;
                    let what = format!(
                        "{n} samples, tilt {tilt}, {}, {drawer:?}",
                        if perspective { "perspective" } else { "ortho" }
                    );
                    let tables = match drawer {
                        Drawer::Slab(_, _, ShadeAt::Voxels) => &lit,
                        _ => &plain,
                    };
                    let img = draw(&vol, &cam, tables, drawer, RenderMode::Composite, size).image;
                    let p = img.pixels()[centre];
                    let a = 1.0 - (1.0 - ALPHA).powf(path);
                    // Splats: the kernel's footprint normalisation (decision 0003), measured
                    // ≤ 0.0015.
                    let tol = if drawer == Drawer::Splat { 0.004 } else { 2e-4 };
                    report.push(format!("{what}: α {:.5} vs {a:.5}", p[3]));
                    assert!((p[3] as f64 - a).abs() < tol, "{what}: α {} vs {a}", p[3]);
                    for (c, k) in [0.2, 0.6, 0.9].into_iter().enumerate() {
                        assert!(
                            (p[c] as f64 - k * p[3] as f64).abs() < 2e-3,
                            "{what}: {p:?}"
                        );
                    }
                    for mode in [RenderMode::Mip, RenderMode::Minip] {
                        let r = draw(&vol, &cam, &plain, drawer, mode, size);
                        let v = r.values.as_ref().unwrap().values()[centre];
                        assert!((v - RHO).abs() < 1e-5, "{what}: {mode:?} {v}");
                    }
                    if drawer == Drawer::Splat {
                        let r = draw(&vol, &cam, &plain, drawer, RenderMode::Xray, size);
                        let v = r.values.as_ref().unwrap().values()[centre] as f64;
                        let x = RHO as f64 * path;
                        report.push(format!("{what}: X-ray {v:.4} vs {x:.4}"));
                        assert!((v - x).abs() < 0.005 * x, "{what}: X-ray {v} vs {x}");
                    }
                }
            }
        }
    }
    if std::env::var_os("THIN_VERBOSE").is_some() {
        eprintln!("{}", report.join("\n"));
    }
}

/// Slabs thicker than the sheet: a one-voxel sheet under `--slab 16` (capped at the sheet's
/// thickness, decision 0023) is drawn face-on wherever it lies between the planes, where it
/// used to fall between two planes at most offsets and draw nothing.
#[test]
fn slabs_thicker_than_the_sheet_still_draw_it() {
    let tables = constant_tables(false);
    let a = 1.0 - (1.0 - ALPHA).powf(0.8);
    for z0 in [0.0, 0.13, 0.4, 0.77, 1.9, 5.55] {
        let grid = thin_grid(1, 0.8, z0);
        let vol = constant(&grid, RHO);
        let cam = tilted_camera(&grid, 0.0, false);
        for slab in [1.0, 2.0, 16.0] {
            let drawer = Drawer::Slab(slab, Preintegrate::Off, ShadeAt::Samples);
            let r = draw(&vol, &cam, &tables, drawer, RenderMode::Composite, (20, 16));
            let p = r.image.pixels()[8 * 20 + 10];
            assert!(r.stats.sheets >= 1, "z0 {z0} slab {slab}: no plane");
            assert!(
                (p[3] as f64 - a).abs() < 2e-4,
                "z0 {z0} slab {slab}: α {} vs {a}",
                p[3]
            );
        }
    }
}

/// A one-voxel sheet seen exactly edge-on (its normal along the image rows): a line one spacing
/// (2 world units here, 3.1 pixels) thick. The slabs draw the pixels whose centre lies within
/// half a spacing of the sample's plane, each with the opacity of the sheet's 16-unit length,
/// and nothing else; the splats blur the line by their kernel but keep its X-ray integral
/// (ρ × the sheet's volume, summed over the pixels). Nothing is NaN.
#[test]
fn a_sheet_seen_edge_on_is_a_line_one_voxel_thick() {
    let tables = constant_tables(false);
    // 17 × 13 voxels of spacing 1 in-plane; along k one sample of spacing 2 at z = 3.
    let grid = Grid::new(
        [17, 13, 1],
        [1.0, 1.0, 2.0],
        [0.0, 0.0, 3.0],
        DMat3::IDENTITY,
    )
    .unwrap();
    let vol = constant(&grid, RHO);
    // Looking along −x at the sheet's centre, y up: image x runs along world −z, and one pixel
    // is 0.64 units (pixel centres 0.32 and 0.96 units from the sheet's plane are inside it).
    let (w, h) = (30, 25);
    let cam = Camera {
        position: [40.0, 6.0, 3.0],
        focal_point: [8.0, 6.0, 3.0],
        view_up: [0.0, 1.0, 0.0],
        view_angle: 30.0,
        parallel_projection: true,
        parallel_scale: 8.0,
    };
    let px = 16.0 / h as f64;
    let a_line = 1.0 - (1.0 - ALPHA).powf(16.0);
    for drawer in SLABS {
        let tables = match drawer {
            Drawer::Slab(_, _, ShadeAt::Voxels) => constant_tables(true),
            _ => tables.clone(),
        };
        let img = draw(&vol, &cam, &tables, drawer, RenderMode::Composite, (w, h)).image;
        assert!(img.pixels().iter().flatten().all(|v| v.is_finite()));
        let row = &img.pixels()[(h / 2) * w..(h / 2 + 1) * w];
        for (x, p) in row.iter().enumerate() {
            // World z of the pixel's centre.
            let z = 3.0 - (x as f64 + 0.5 - w as f64 / 2.0) * px;
            let inside = (z - 3.0).abs() < 1.0 - 1e-6;
            let expect = if inside { a_line } else { 0.0 };
            assert!(
                (p[3] as f64 - expect).abs() < 1e-3,
                "{drawer:?}: pixel {x} (z {z:.2}) α {} vs {expect}",
                p[3]
            );
        }
    }
    let x = draw(&vol, &cam, &tables, Drawer::Splat, RenderMode::Xray, (w, h));
    let v = x.values.as_ref().unwrap().values();
    assert!(v.iter().all(|v| v.is_finite()));
    let sum: f64 = v.iter().map(|&v| v as f64).sum::<f64>() * px * px;
    let mass = RHO as f64 * 17.0 * 13.0 * 2.0;
    assert!((sum - mass).abs() < 0.01 * mass, "X-ray Σ {sum} vs {mass}");
    let c = draw(
        &vol,
        &cam,
        &tables,
        Drawer::Splat,
        RenderMode::Composite,
        (w, h),
    );
    let centre = c.image.pixels()[(h / 2) * w + w / 2];
    // The kernel spreads each voxel across the line (σ 0.6 voxel = 1.9 pixels), so its middle
    // keeps 97 % of the sheet's opacity, not all of it.
    assert!(
        centre[3] as f64 > 0.95 && centre[3] as f64 <= a_line,
        "{centre:?}"
    );
}

/// Thin volumes are bit-identical for any thread count and with or without AVX2, in every mode
/// of the slabs (an oblique view of 8- and 16-bit and float sheets of 1, 2 and 3 samples).
#[test]
fn thin_slabs_are_deterministic() {
    let run = |threads: usize, f: &(dyn Fn() -> Vec<Rendered> + Sync)| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(f)
    };
    for n in 1..=3usize {
        let grid = Grid::new(
            [23, 19, n],
            [0.9, 1.1, 1.7],
            [1.0, -2.0, 0.5],
            DMat3::from_rotation_x(0.4),
        )
        .unwrap();
        let f = |i: usize, j: usize, k: usize| ((i * 7 + j * 13 + k * 29) % 61) as f32 / 60.0;
        let vol_f = Volume::from_fn(grid.clone(), f).unwrap();
        let vol_u8 = Volume::from_fn(grid.clone(), |i, j, k| (f(i, j, k) * 255.0) as u8).unwrap();
        let vol_i16 = Volume::from_fn(grid.clone(), |i, j, k| (f(i, j, k) * 900.0) as i16).unwrap();
        let mut cam = tilted_camera(&grid, 50.0, true);
        cam.elevation(20.0);
        cam.orthogonalize_view_up();
        let mut tf = TransferFunction::ramp(0.0, 1.0, 0.8);
        tf.shade = true;
        let lit = CrioTables::from_transfer_function(&tf, 1024).unwrap();
        let plain = constant_tables(false);
        let all_with = |simd: bool| {
            let mut out = Vec::new();
            for mode in [RenderMode::Composite, RenderMode::Mip, RenderMode::Minip] {
                for drawer in SLABS {
                    out.push(draw_simd(
                        simd,
                        &vol_f,
                        &cam,
                        &plain,
                        drawer,
                        mode,
                        (41, 35),
                    ));
                }
            }
            for drawer in SLABS {
                out.push(draw_simd(
                    simd,
                    &vol_f,
                    &cam,
                    &lit,
                    drawer,
                    RenderMode::Composite,
                    (41, 35),
                ));
                out.push(draw_simd(
                    simd,
                    &vol_u8,
                    &cam,
                    &plain,
                    drawer,
                    RenderMode::Composite,
                    (41, 35),
                ));
                out.push(draw_simd(
                    simd,
                    &vol_i16,
                    &cam,
                    &plain,
                    drawer,
                    RenderMode::Mip,
                    (41, 35),
                ));
            }
            out
        };
        let all = || all_with(true);
        let one = run(1, &all);
        let three = run(3, &all);
        let scalar = run(2, &|| all_with(false));
        for (k, ((a, b), c)) in one.iter().zip(&three).zip(&scalar).enumerate() {
            let bits = |r: &Rendered| {
                let mut v: Vec<u32> = r
                    .image
                    .pixels()
                    .iter()
                    .flatten()
                    .map(|x| x.to_bits())
                    .collect();
                if let Some(s) = &r.values {
                    v.extend(s.values().iter().map(|x| x.to_bits()));
                }
                v
            };
            assert!(
                a.stats.voxels > 0,
                "{n} samples, render {k}: nothing sampled"
            );
            assert_eq!(bits(a), bits(b), "{n} samples, render {k}: 1 vs 3 threads");
            assert_eq!(bits(a), bits(c), "{n} samples, render {k}: AVX2 vs scalar");
        }
    }
}

/// The front ends' reset view frames a single slice (its drawn bounds are one spacing thick,
/// decision 0023) and a single voxel (a cube), where the bounds of the voxel centres are a
/// plane and a point.
#[test]
fn the_reset_view_frames_single_slices_and_voxels() {
    let one = Grid::new([1, 1, 1], [2.0, 3.0, 4.0], [5.0, 6.0, 7.0], DMat3::IDENTITY).unwrap();
    let (lo, hi) = one.drawn_bounds_world();
    assert_eq!(lo, DVec3::new(4.0, 4.5, 5.0));
    assert_eq!(hi, DVec3::new(6.0, 7.5, 9.0));
    let vol = constant(&one, RHO);
    let tables = constant_tables(false);
    for drawer in SLABS.into_iter().chain([Drawer::Splat]) {
        for perspective in [false, true] {
            let cam = tilted_camera(&one, 30.0, perspective);
            let r = draw(&vol, &cam, &tables, drawer, RenderMode::Composite, (16, 16));
            let covered = r.image.pixels().iter().filter(|p| p[3] > 0.1).count();
            assert!(
                covered > 16,
                "{drawer:?} perspective {perspective}: one voxel covers {covered} pixels"
            );
        }
    }
}
