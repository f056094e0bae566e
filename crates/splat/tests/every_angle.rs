//! Right at every angle (issue 17): sweeps of the view, not a few chosen cameras. The
//! image-aligned slabs of issue 16 get their own sweep at the end.
//!
//! Every azimuth 0–355° in 5° steps × elevations {−80, −45, 0, 30, 60, 85}, orthographic (the
//! dense sheet renderer) and perspective (the splat-list renderer), composite, MIP and X-ray,
//! with the image shape (square, wide, tall, odd) and the voxel spacing (1, 0.5, 2/63,
//! anisotropic) cycling so that every shape meets every spacing at many angles. Each image is
//! compared with an independent answer: X-ray with the closed-form line integrals of the
//! Gaussian-blob phantom the volume was sampled from, composite and MIP with the brute-force
//! reference ray integrator of `volsplat-testkit`. A proptest adds random cameras (roll, zoom,
//! odd angles and sizes).
//!
//! The phantom is smooth (σ ≥ 1.6 voxels) and lies well inside the grid, so the splatting kernel
//! and the reference's trilinear reconstruction agree closely; the bounds below are 1.4–1.8×
//! the worst error measured over the whole sweep (printed with `--nocapture`; every view with
//! `SWEEP_VERBOSE=1`), while a black, NaN or mirrored image is off by 30–100 % and a half-pixel
//! shift by about 15 %.

use proptest::prelude::*;
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::phantom::{self, Blob, GaussianBlobs};
use volsplat_core::{Camera, CrioTables, Grid, Projection, ScalarImage, TransferFunction, Volume};
use volsplat_splat::{
    ExtractSettings, RenderMode, RenderSettings, Rendered, SplatList, render, render_list,
};
use volsplat_testkit::metrics::{image_psnr, relative_l2};
use volsplat_testkit::reference::{
    ReferenceSettings, analytic_xray, reference_composite, reference_mip,
};

/// The four spacings of the sweep, with grid dimensions that give each a similar world extent
/// (about 23 units at spacing 1) so one blob layout fits all of them.
fn grids() -> Vec<(&'static str, Grid)> {
    let g = |dims: [usize; 3], spacing: [f64; 3]| {
        let origin = [-3.0, 5.0, 1.5];
        Grid::new(dims, spacing, origin, DMat3::IDENTITY).unwrap()
    };
    vec![
        ("spacing 1", g([24; 3], [1.0; 3])),
        ("spacing 0.5", g([24; 3], [0.5; 3])),
        ("spacing 2/63", g([24; 3], [2.0 / 63.0; 3])),
        ("spacing 0.8,1,1.25", g([30, 24, 19], [0.8, 1.0, 1.25])),
    ]
}

/// Smooth, asymmetric Gaussian blobs placed relative to the grid's world box: σ is 9–12 % of
/// the box (≥ 1.6 voxels on the coarsest axis) and every blob lies ≥ 3.3σ inside every face,
/// so the sampled volume holds all but ~1e-3 of each blob's line integral.
fn blobs_for(grid: &Grid) -> GaussianBlobs {
    let (lo, hi) = grid.bounds_world();
    let ext = hi - lo;
    let e = ext.min_element();
    let at = |fx: f64, fy: f64, fz: f64, s: f64, amplitude: f64| Blob {
        center: lo + ext * DVec3::new(fx, fy, fz),
        sigma: s * e,
        amplitude,
    };
    GaussianBlobs::new(vec![
        at(0.5, 0.5, 0.5, 0.12, 1.0),
        at(0.6, 0.44, 0.42, 0.09, 0.8),
        at(0.42, 0.6, 0.56, 0.09, 0.6),
    ])
}

fn volume_for(grid: &Grid) -> Volume<f32> {
    phantom::sample_on_grid(&blobs_for(grid), grid, 1).unwrap()
}

fn camera(grid: &Grid, az: f64, el: f64, roll: f64, zoom: f64, perspective: bool) -> Camera {
    let (lo, hi) = grid.bounds_world();
    let mut c = Camera::reset_to_bounds(lo, hi, !perspective);
    c.azimuth(az);
    c.elevation(el);
    c.orthogonalize_view_up();
    c.roll(roll);
    if perspective {
        c.view_angle /= zoom;
    } else {
        c.parallel_scale /= zoom;
    }
    c
}

/// Transfer function over the phantom's range: partly transparent and coloured, its opacity
/// unit distance scaled with the grid so that every spacing gives the same picture.
fn transfer_function(grid: &Grid) -> TransferFunction {
    let (lo, hi) = grid.bounds_world();
    let mut tf = TransferFunction::ramp(0.0, 1.1, 0.25);
    tf.color = vec![
        [0.0, 0.2, 0.3, 1.0],
        [0.5, 1.0, 0.6, 0.2],
        [1.1, 1.0, 1.0, 1.0],
    ];
    tf.scalar_opacity_unit_distance = (hi - lo).min_element() / 23.0;
    tf
}

/// [`transfer_function`]'s tables.
fn tables(grid: &Grid) -> CrioTables {
    CrioTables::from_transfer_function(&transfer_function(grid), 16).unwrap()
}

/// [`tables`] lit: ambient, diffuse and specular under the default headlight (the slab
/// renderer's shaded kernels).
fn shaded_tables(grid: &Grid) -> CrioTables {
    let tf = TransferFunction {
        shade: true,
        ambient: 0.2,
        diffuse: 0.7,
        specular: 0.3,
        ..transfer_function(grid)
    };
    CrioTables::from_transfer_function(&tf, 16).unwrap()
}

const SHAPES: [(usize, usize); 4] = [(48, 48), (64, 40), (40, 64), (45, 37)];

#[derive(Default)]
struct Worst {
    xray: f64,
    mip: f64,
    composite_psnr: f64,
    shaded_psnr: f64,
    views: usize,
}

impl Worst {
    fn new() -> Self {
        Worst {
            composite_psnr: f64::INFINITY,
            shaded_psnr: f64::INFINITY,
            ..Default::default()
        }
    }
}

fn render_view(
    vol: &Volume<f32>,
    list: &SplatList,
    cam: &Camera,
    tables: &CrioTables,
    mode: RenderMode,
    (w, h): (usize, usize),
) -> Rendered {
    let s = {
        let mut s = RenderSettings::default();
        s.width = w;
        s.height = h;
        s.mode = mode;
        s
    };
    if cam.parallel_projection {
        render(vol, cam, tables, &s).unwrap()
    } else {
        render_list(list, cam, tables, &s).unwrap()
    }
}

fn values(r: &Rendered) -> &ScalarImage {
    r.values.as_ref().expect("values")
}

/// Renders one view in all three modes and compares each with its independent answer;
/// returns (X-ray relative L2 vs closed form, MIP relative RMSE vs reference, composite PSNR,
/// shaded composite PSNR: orthographic views only, where the sheets shade through the slab
/// kernel's table; +∞ otherwise).
fn check_view(
    grid: &Grid,
    vol: &Volume<f32>,
    list: &SplatList,
    cam: &Camera,
    shape: (usize, usize),
) -> (f64, f64, f64, f64) {
    let tables = tables(grid);
    let proj = Projection::new(cam, shape.0, shape.1).unwrap();
    let reference = ReferenceSettings {
        step: grid.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s)) / 4.0,
        supersample: 1,
        ..ReferenceSettings::default()
    };
    // X-ray against the closed form.
    let x = render_view(vol, list, cam, &tables, RenderMode::Xray, shape);
    let xv = values(&x).values();
    assert!(xv.iter().all(|v| v.is_finite() && *v >= 0.0));
    let exact = analytic_xray(&blobs_for(grid), &proj, 1).unwrap();
    let xray = relative_l2(xv, exact.values());
    // MIP against the reference integrator, where both cover the pixel; RMSE relative to the
    // phantom's peak.
    let m = render_view(vol, list, cam, &tables, RenderMode::Mip, shape);
    let refm = reference_mip(vol, &proj, &reference);
    let (mut se, mut n, mut covered) = (0.0f64, 0usize, 0usize);
    for (a, b) in values(&m).values().iter().zip(refm.values()) {
        assert!(!a.is_infinite());
        covered += b.is_finite() as usize;
        // Pixels at the silhouette of the grid box are covered by one and not the other.
        if a.is_finite() && b.is_finite() {
            se += ((a - b) as f64).powi(2);
            n += 1;
        }
    }
    assert!(n * 10 >= covered * 9, "MIP covers {n} of {covered} pixels");
    let mip = (se / n.max(1) as f64).sqrt() / 1.0;
    // Composite against the reference integrator.
    let c = render_view(vol, list, cam, &tables, RenderMode::Composite, shape);
    assert!(c.image.pixels().iter().flatten().all(|v| v.is_finite()));
    let refc = reference_composite(vol, &proj, &tables, &reference);
    let psnr = image_psnr(&c.image, &refc);
    let shaded = if cam.parallel_projection {
        let lit = shaded_tables(grid);
        let c = render_view(vol, list, cam, &lit, RenderMode::Composite, shape);
        image_psnr(&c.image, &reference_composite(vol, &proj, &lit, &reference))
    } else {
        f64::INFINITY
    };
    (xray, mip, psnr, shaded)
}

/// Bounds, 1.4–1.8× the worst measured over the sweeps (X-ray 0.072, MIP 0.027, composite
/// 42.4 dB, all on the anisotropic grid; spacing 1: 0.045, 0.014, 45 dB). The X-ray error is
/// the σ = 0.6-voxel kernel's blur of blobs only 1.6–2.8 voxels wide, not noise.
const XRAY_BOUND: f64 = 0.10;
const MIP_BOUND: f64 = 0.045;
const PSNR_BOUND: f64 = 38.0;
/// Shaded composite through the sheets (orthographic), which shade through the slab kernel's
/// table: worst measured 43.0 dB, bound as for unshaded composite.
const SHADED_PSNR_BOUND: f64 = 38.0;
/// Random cameras also zoom in up to 2× (the sweep does not), where the splatting kernel's blur
/// against the reference's trilinear reconstruction shows more: 37.8 dB was seen at azimuth
/// 102°, zoom 1.74 on the anisotropic grid (kept in `every_angle.proptest-regressions`). A
/// black or NaN image is below 10 dB.
const PROPTEST_PSNR_BOUND: f64 = 35.0;

fn sweep(perspective: bool) {
    let grids = grids();
    let vols: Vec<_> = grids.iter().map(|(_, g)| volume_for(g)).collect();
    let lists: Vec<_> = vols
        .iter()
        .zip(&grids)
        .map(|(v, (_, g))| SplatList::build(v, &tables(g), &ExtractSettings::default()).unwrap())
        .collect();
    let mut worst = Worst::new();
    let mut n = 0usize;
    for az in (0..360).step_by(5) {
        for el in [-80.0, -45.0, 0.0, 30.0, 60.0, 85.0] {
            // Cycle spacing and shape so that all 16 pairs occur, each at many angles.
            let gi = n % 4;
            let shape = SHAPES[(n / 4 + n) % 4];
            n += 1;
            let (name, grid) = &grids[gi];
            let cam = camera(grid, az as f64, el, 0.0, 1.0, perspective);
            let (x, m, p, ps) = check_view(grid, &vols[gi], &lists[gi], &cam, shape);
            let what = format!(
                "{} az {az} el {el} {name} {}×{}",
                if perspective { "perspective" } else { "ortho" },
                shape.0,
                shape.1
            );
            if std::env::var_os("SWEEP_VERBOSE").is_some() {
                eprintln!("{what}: {x:.4} {m:.4} {p:.1}");
            }
            assert!(x < XRAY_BOUND, "{what}: X-ray relative L2 {x:.4}");
            assert!(m < MIP_BOUND, "{what}: MIP relative RMSE {m:.4}");
            assert!(p > PSNR_BOUND, "{what}: composite PSNR {p:.1} dB");
            assert!(
                ps > SHADED_PSNR_BOUND,
                "{what}: shaded composite PSNR {ps:.1} dB"
            );
            worst.shaded_psnr = worst.shaded_psnr.min(ps);
            worst.xray = worst.xray.max(x);
            worst.mip = worst.mip.max(m);
            worst.composite_psnr = worst.composite_psnr.min(p);
            worst.views += 1;
        }
    }
    eprintln!(
        "{} sweep, {} views × 3 modes: worst X-ray rel. L2 {:.4}, MIP rel. RMSE {:.4}, \
         composite PSNR {:.1} dB, shaded composite PSNR {:.1} dB",
        if perspective {
            "perspective"
        } else {
            "orthographic"
        },
        worst.views,
        worst.xray,
        worst.mip,
        worst.composite_psnr,
        worst.shaded_psnr
    );
}

#[test]
fn orthographic_views_match_the_references_at_every_angle() {
    sweep(false);
}

#[test]
fn perspective_views_match_the_references_at_every_angle() {
    sweep(true);
}

/// The views of issue 17's report on a constant volume (spacing 1 and 0.5, 128²): composite
/// was black and X-ray NaN at azimuths 30, 45 and 55. A constant slab of density ρ seen along
/// an axis-aligned or oblique ray has the line integral ρ·(chord through the box).
#[test]
fn constant_volume_is_right_at_the_reported_angles() {
    for spacing in [1.0, 0.5] {
        let grid = Grid::new([64; 3], [spacing; 3], [0.0; 3], DMat3::IDENTITY).unwrap();
        let vol = Volume::from_fn(grid.clone(), |_, _, _| 1.0f32).unwrap();
        let tables = tables(&grid);
        for az in [0.0, 15.0, 30.0, 45.0, 55.0, 60.0, 90.0] {
            let cam = camera(&grid, az, 0.0, 0.0, 1.0, false);
            let s = {
                let mut s = RenderSettings::default();
                s.width = 128;
                s.height = 128;
                s.mode = RenderMode::Xray;
                s
            };
            let out = render(&vol, &cam, &tables, &s).unwrap();
            let v = values(&out);
            // The centre pixel's ray crosses the box of voxel centres horizontally at angle az
            // to the z axis; the kernel adds about one voxel of blur at entry and exit, so the
            // splatted integral equals the chord through the box widened by half a voxel on each
            // face: length (63 + 1)·spacing / cos(az') with az' folded into [0°, 45°].
            let a = (az % 90.0f64).to_radians();
            let a = if a > std::f64::consts::FRAC_PI_4 {
                std::f64::consts::FRAC_PI_2 - a
            } else {
                a
            };
            let expect = 64.0 * spacing / a.cos();
            let got = v.get(64, 64) as f64;
            eprintln!("spacing {spacing} az {az}: {got} vs {expect}");
            assert!(
                (got - expect).abs() < 0.03 * expect,
                "spacing {spacing} az {az}: centre line integral {got}, expected {expect}"
            );
            let s = {
                let mut s = s;
                s.mode = RenderMode::Composite;
                s
            };
            let img = render(&vol, &cam, &tables, &s).unwrap().image;
            let centre = img.pixels()[64 * 128 + 64];
            assert!(centre[3] > 0.99, "spacing {spacing} az {az}: {centre:?}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Random cameras: any azimuth, elevation, roll and zoom, any small image shape.
    #[test]
    fn random_cameras_match_the_references(
        az in 0.0f64..360.0,
        el in -89.0f64..89.0,
        roll in -180.0f64..180.0,
        zoom in 0.8f64..2.0,
        w in 40usize..96,
        h in 40usize..96,
        gi in 0usize..4,
        perspective in any::<bool>(),
    ) {
        let grids = grids();
        let (_, grid) = &grids[gi];
        let vol = volume_for(grid);
        let list = SplatList::build(&vol, &tables(grid), &ExtractSettings::default()).unwrap();
        let cam = camera(grid, az, el, roll, zoom, perspective);
        let (x, m, p, _) = check_view(grid, &vol, &list, &cam, (w, h));
        prop_assert!(x < XRAY_BOUND, "X-ray relative L2 {}", x);
        prop_assert!(m < MIP_BOUND, "MIP relative RMSE {}", m);
        prop_assert!(p > PROPTEST_PSNR_BOUND, "composite PSNR {}", p);
    }
}

/// Image-aligned slabs (issue 16) over the same kind of sweep: every 15° of azimuth × the six
/// elevations, both projections, the shapes and spacings cycling as above; composite and MIP
/// against the reference integrator (X-ray goes to the exact sheet renderers, swept above).
/// The slabs sample the reference's own trilinear field, so the bounds are far tighter than the
/// splatting ones: worst measured 57.2 dB composite (both projections) and MIP relative RMSE
/// 0.0044 / 0.0057 (orthographic / perspective); bounds 50 dB (2.3× the RMS error) and 0.009.
///
/// Composite is also rendered at the front ends' default for it, one-voxel slabs
/// (`DEFAULT_SLAB_COMPOSITE`, decision 0017), against the same reference: bound
/// [`SLAB_1_PSNR_BOUND`].
fn sweep_slabs(perspective: bool) -> (f64, f64) {
    let grids = grids();
    let vols: Vec<_> = grids.iter().map(|(_, g)| volume_for(g)).collect();
    let (mut worst_psnr, mut worst_mip) = (f64::INFINITY, 0.0f64);
    let mut worst_thick = f64::INFINITY;
    let mut worst_pre = f64::INFINITY;
    let mut worst_shaded = f64::INFINITY;
    let mut worst_voxels = f64::INFINITY;
    let mut n = 0usize;
    for az in (0..360).step_by(15) {
        for el in [-80.0, -45.0, 0.0, 30.0, 60.0, 85.0] {
            let gi = n % 4;
            let shape = SHAPES[(n / 4 + n) % 4];
            n += 1;
            let (name, grid) = &grids[gi];
            let vol = &vols[gi];
            let cam = camera(grid, az as f64, el, 0.0, 1.0, perspective);
            let tables = tables(grid);
            let proj = Projection::new(&cam, shape.0, shape.1).unwrap();
            let reference = ReferenceSettings {
                step: grid.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s)) / 4.0,
                supersample: 1,
                ..ReferenceSettings::default()
            };
            // One ray per pixel, as the reference casts them (the anti-aliasing of minified
            // views, which averages a pixel's area, is `slab.rs`'s `minified_views…` test).
            let s = |mode| {
                let mut s = RenderSettings::default();
                s.width = shape.0;
                s.height = shape.1;
                s.mode = mode;
                s.visibility = volsplat_splat::Visibility::ImageAligned;
                s.antialias = volsplat_splat::Antialias::None;
                s
            };
            let what = format!(
                "slabs {} az {az} el {el} {name} {}×{}",
                if perspective { "perspective" } else { "ortho" },
                shape.0,
                shape.1
            );
            let c = volsplat_splat::render_slabs(
                vol,
                &cam,
                &tables,
                &s(RenderMode::Composite),
                None,
                &mut |_| true,
            )
            .unwrap();
            let refc = reference_composite(vol, &proj, &tables, &reference);
            let p = image_psnr(&c.image, &refc);
            let thick = {
                let mut s = s(RenderMode::Composite);
                s.slab = volsplat_splat::slab::DEFAULT_SLAB_COMPOSITE;
                s
            };
            let c1 = volsplat_splat::render_slabs(vol, &cam, &tables, &thick, None, &mut |_| true)
                .unwrap();
            let p1 = image_psnr(&c1.image, &refc);
            assert!(
                p1 > SLAB_1_PSNR_BOUND,
                "{what}: one-voxel composite PSNR {p1:.1} dB"
            );
            worst_thick = worst_thick.min(p1);
            // The same by segment (pre-integrated, decision 0020).
            let pre = {
                let mut s = thick.clone();
                s.preintegrate = volsplat_splat::Preintegrate::On;
                s
            };
            let cp = volsplat_splat::render_slabs(vol, &cam, &tables, &pre, None, &mut |_| true)
                .unwrap();
            let pp = image_psnr(&cp.image, &refc);
            assert!(
                pp > SLAB_1_PSNR_BOUND,
                "{what}: one-voxel pre-integrated composite PSNR {pp:.1} dB"
            );
            worst_pre = worst_pre.min(pp);
            // Shaded composite (the AVX2 kernel's central differences and lights) at the
            // half-voxel slabs the front ends use for it.
            let lit = shaded_tables(grid);
            let cs = volsplat_splat::render_slabs(
                vol,
                &cam,
                &lit,
                &s(RenderMode::Composite),
                None,
                &mut |_| true,
            )
            .unwrap();
            let ps = image_psnr(
                &cs.image,
                &reference_composite(vol, &proj, &lit, &reference),
            );
            assert!(
                ps > SLAB_SHADED_PSNR_BOUND,
                "{what}: shaded composite PSNR {ps:.1} dB"
            );
            worst_shaded = worst_shaded.min(ps);
            // Shaded at the voxels (VTK's order) at one voxel, the front ends' default for
            // shaded composite (decision 0019), against the reference in the same order.
            let at_voxels = {
                let mut s = s(RenderMode::Composite);
                s.slab = volsplat_splat::slab::DEFAULT_SLAB_COMPOSITE;
                s.shade_at = volsplat_splat::ShadeAt::Voxels;
                s
            };
            let cv = volsplat_splat::render_slabs(vol, &cam, &lit, &at_voxels, None, &mut |_| true)
                .unwrap();
            let voxel_reference = ReferenceSettings {
                shade_at_voxels: true,
                ..reference
            };
            let pv = image_psnr(
                &cv.image,
                &reference_composite(vol, &proj, &lit, &voxel_reference),
            );
            assert!(
                pv > SLAB_VOXELS_PSNR_BOUND,
                "{what}: composite shaded at the voxels PSNR {pv:.1} dB"
            );
            worst_voxels = worst_voxels.min(pv);
            let m = volsplat_splat::render_slabs(
                vol,
                &cam,
                &tables,
                &s(RenderMode::Mip),
                None,
                &mut |_| true,
            )
            .unwrap();
            let refm = reference_mip(vol, &proj, &reference);
            let (mut se, mut k, mut covered) = (0.0f64, 0usize, 0usize);
            for (a, b) in values(&m).values().iter().zip(refm.values()) {
                covered += b.is_finite() as usize;
                if a.is_finite() && b.is_finite() {
                    se += ((a - b) as f64).powi(2);
                    k += 1;
                }
            }
            assert!(
                k * 10 >= covered * 9,
                "{what}: MIP covers {k} of {covered} pixels"
            );
            let mip = (se / k.max(1) as f64).sqrt();
            if std::env::var_os("SWEEP_VERBOSE").is_some() {
                eprintln!("{what}: {mip:.5} {p:.1}");
            }
            assert!(p > SLAB_PSNR_BOUND, "{what}: composite PSNR {p:.1} dB");
            assert!(mip < SLAB_MIP_BOUND, "{what}: MIP relative RMSE {mip:.5}");
            worst_psnr = worst_psnr.min(p);
            worst_mip = worst_mip.max(mip);
        }
    }
    eprintln!(
        "slab sweep ({}), {n} views: worst composite PSNR {worst_psnr:.1} dB (one-voxel slabs \
         {worst_thick:.1} dB, pre-integrated {worst_pre:.1} dB, shaded {worst_shaded:.1} dB, \
         shaded at the voxels \
         {worst_voxels:.1} dB), MIP rel. RMSE {worst_mip:.5}",
        if perspective {
            "perspective"
        } else {
            "orthographic"
        }
    );
    (worst_psnr, worst_mip)
}

const SLAB_PSNR_BOUND: f64 = 50.0;
/// One-voxel slabs against the same reference (one ray per pixel, as the reference): worst
/// measured 66.1 dB (orthographic) and 66.5 dB (perspective) by point, 58.2 and 58.5 dB by
/// segment (the straight value path between planes misses the curvature of these smooth blobs
/// under a smooth ramp, decision 0020); a slab-thickness correction off by the factor 2 costs
/// far more than the margin.
const SLAB_1_PSNR_BOUND: f64 = 50.0;
const SLAB_MIP_BOUND: f64 = 0.009;
/// Shaded composite at half-voxel slabs against the reference integrator (which shades the same
/// interpolated central differences at ¼-voxel steps): worst measured 54.0 dB (orthographic) and
/// 55.1 dB (perspective) over the 288 views.
const SLAB_SHADED_PSNR_BOUND: f64 = 48.0;
/// Composite shaded at the voxels, one-voxel slabs, against the reference integrator shading in
/// the same order (each ¼-voxel sample classified with its cell's eight voxel gradients and
/// blended): worst measured 58.2 dB (orthographic) and 54.9 dB (perspective) over the 288 views.
const SLAB_VOXELS_PSNR_BOUND: f64 = 50.0;

#[test]
fn image_aligned_slabs_match_the_references_at_every_angle() {
    sweep_slabs(false);
    sweep_slabs(true);
}

// ---------------------------------------------------------------------------------------------
// Thin volumes (issue 28 §1, `docs/decisions/0023-thin-volumes.md`): one, two and three samples
// along one axis (a single slice, a 2-D image, Swan's checkerboard), each axis in turn, swept
// like the volumes above (every 15° of azimuth × six elevations from −90° to 90°, so that many
// views are edge-on to the sheet) through every renderer and mode, both projections, against
// the reference integrator. Before decision 0023 the image-aligned slabs drew a one-sample axis
// black (no plane inside a box of zero thickness) and the reference integrated nothing there.

/// The thin grids: for each axis, 1, 2 and 3 samples along it (spacing 2, 1 and 0.5: a
/// one-sample axis is one spacing thick whatever the spacing), 18–22 samples on the others
/// with spacings 1, 0.8 and 1.25; the grids thin along k are rotated.
fn thin_grids() -> Vec<(String, Grid)> {
    let mut out = Vec::new();
    for axis in 0..3 {
        for n in 1..=3usize {
            let mut dims = [20, 18, 22];
            let mut spacing = [1.0, 0.8, 1.25];
            dims[axis] = n;
            spacing[axis] = [2.0, 1.0, 0.5][n - 1];
            let direction = if axis == 2 {
                DMat3::from_rotation_y(0.3) * DMat3::from_rotation_x(-0.2)
            } else {
                DMat3::IDENTITY
            };
            let grid = Grid::new(dims, spacing, [-3.0, 5.0, 1.5], direction).unwrap();
            out.push((format!("{} × {n}", ["i", "j", "k"][axis]), grid));
        }
    }
    out
}

/// Blobs in the middle of the thin grid's drawn box (decision 0023), sized by its smallest
/// in-plane extent (σ 10–14 % of it, ≥ 2.9σ inside every in-plane face), so the thin axis cuts
/// them through their centres.
fn thin_blobs(grid: &Grid) -> GaussianBlobs {
    let (lo, hi) = grid.drawn_box_index();
    let ext = hi - lo;
    let e = (0..3)
        .filter(|&a| grid.dims[a] > 3)
        .map(|a| ext[a] * grid.spacing[a])
        .fold(f64::INFINITY, f64::min);
    let at = |f: [f64; 3], s: f64, amplitude: f64| {
        let mut q = lo + ext * DVec3::from(f);
        for a in 0..3 {
            if grid.dims[a] <= 3 {
                q[a] = 0.5 * (lo[a] + hi[a]);
            }
        }
        Blob {
            center: grid.world_from_index(q),
            sigma: s * e,
            amplitude,
        }
    };
    GaussianBlobs::new(vec![
        at([0.5, 0.5, 0.5], 0.14, 1.0),
        at([0.62, 0.42, 0.4], 0.1, 0.8),
        at([0.4, 0.6, 0.58], 0.1, 0.6),
    ])
}

/// The thin sweep's transfer function: [`transfer_function`]'s colours with an opacity unit
/// of one world unit, so a sheet one or two units thick is clearly visible face-on and still
/// translucent.
fn thin_tables(shade: bool) -> CrioTables {
    let mut tf = TransferFunction::ramp(0.0, 1.1, 0.6);
    tf.color = vec![
        [0.0, 0.2, 0.3, 1.0],
        [0.5, 1.0, 0.6, 0.2],
        [1.1, 1.0, 1.0, 1.0],
    ];
    tf.scalar_opacity_unit_distance = 1.0;
    if shade {
        tf.shade = true;
        tf.ambient = 0.2;
        tf.diffuse = 0.7;
        tf.specular = 0.3;
    }
    CrioTables::from_transfer_function(&tf, 16).unwrap()
}

/// The front ends' reset view of the thin grid (the drawn bounds: a one-sample axis one
/// spacing thick), then the orbit.
fn thin_camera(grid: &Grid, az: f64, el: f64, perspective: bool) -> Camera {
    let (lo, hi) = grid.drawn_bounds_world();
    let mut c = Camera::reset_to_bounds(lo, hi, !perspective);
    c.azimuth(az);
    c.elevation(el);
    c.orthogonalize_view_up();
    c
}

fn alpha_mass(img: &volsplat_core::Image) -> f64 {
    img.pixels().iter().map(|p| p[3] as f64).sum()
}

/// RMSE of `a` against `b` over the pixels both cover (relative to the data's peak, 1), and
/// the share of `b`'s covered pixels that `a` covers too.
fn extreme_error(a: &ScalarImage, b: &ScalarImage) -> (f64, f64) {
    let (mut se, mut n, mut covered) = (0.0f64, 0usize, 0usize);
    for (x, y) in a.values().iter().zip(b.values()) {
        assert!(!x.is_infinite());
        covered += y.is_finite() as usize;
        if x.is_finite() && y.is_finite() {
            se += ((x - y) as f64).powi(2);
            n += 1;
        }
    }
    (
        (se / n.max(1) as f64).sqrt(),
        n as f64 / covered.max(1) as f64,
    )
}

/// The worst of one measure over a sweep, and where it was.
struct Worst1 {
    value: f64,
    at: String,
    larger_is_worse: bool,
}

impl Worst1 {
    fn new(larger_is_worse: bool) -> Self {
        Worst1 {
            value: if larger_is_worse {
                f64::NEG_INFINITY
            } else {
                f64::INFINITY
            },
            at: String::new(),
            larger_is_worse,
        }
    }

    fn see(&mut self, v: f64, at: &str) {
        assert!(!v.is_nan(), "{at}: NaN");
        if (self.larger_is_worse && v > self.value) || (!self.larger_is_worse && v < self.value) {
            self.value = v;
            self.at = at.to_string();
        }
    }
}

/// Every measure of the thin sweep, by name: (bound, worst). Composite is checked by PSNR
/// against the reference and by the ratio of the image's total opacity Σα to the reference's
/// (a sheet missing edge-on costs little PSNR, all of Σα); X-ray by relative L2 and by the
/// ratio of the image's sums (what the sheet holds: the voxels' thickness).
struct ThinChecks {
    checks: Vec<(&'static str, f64, Worst1)>,
}

impl ThinChecks {
    fn new(bounds: &[(&'static str, f64, bool)]) -> Self {
        ThinChecks {
            checks: bounds
                .iter()
                .map(|&(name, bound, larger_is_worse)| (name, bound, Worst1::new(larger_is_worse)))
                .collect(),
        }
    }

    fn see(&mut self, name: &str, v: f64, at: &str) {
        let Some((_, bound, w)) = self.checks.iter_mut().find(|c| c.0 == name) else {
            panic!("no check {name}");
        };
        w.see(v, at);
        let bad = if w.larger_is_worse {
            v > *bound
        } else {
            v < *bound
        };
        assert!(!bad, "{at}: {name} {v:.4} (bound {bound})");
    }

    fn report(&self, what: &str) {
        for (name, bound, w) in &self.checks {
            eprintln!(
                "{what}: {name:>28} worst {:.4} (bound {bound}) at {}",
                w.value, w.at
            );
        }
    }
}

/// Bounds of the thin sweep, with the worst measured over both projections in brackets
/// (`SWEEP_VERBOSE=1` prints every view). "Edge" views see the sheet within 17° of edge-on
/// (|forward · thin axis| < 0.3): the splatting kernel (σ 0.6 voxel) blurs the line one voxel
/// thick that they show over a few pixels, where the reference draws it sharp (the splatting
/// model, as at every face of every volume; its X-ray integral is kept), and the reference,
/// even at 3 × 3 rays per pixel, aliases that line by a few percent.
const THIN_BOUNDS: [(&str, f64, bool); 19] = [
    // Slabs against the reference over the voxel centres' box (one voxel on a one-sample axis).
    ("slab ½ composite dB", 50.0, false),        // 56.7
    ("slab 1 composite dB", 39.0, false),        // 43.2
    ("slab 1 pre-integrated dB", 35.0, false),   // 38.4
    ("slab ½ shaded dB", 46.0, false),           // 50.0
    ("slab 1 shaded at voxels dB", 45.0, false), // 48.9
    ("slab Σα error", 0.03, true),               // 0.022
    ("slab MIP/MinIP RMSE", 0.04, true),         // 0.027
    // Rays that cross the box between two planes (its faces' silhouette) get no sample, as in
    // every volume; seen obliquely, a thin volume has more of them.
    ("slab MIP/MinIP uncovered", 0.15, true), // 0.098
    // The splatting renderers (dense sheets orthographic, the splat list in perspective)
    // against the reference over the voxels' cells.
    ("sheet composite dB", 28.0, false),       // 30.9
    ("sheet composite dB, edge", 20.0, false), // 23.0
    ("sheet Σα / reference", 0.8, false),      // 0.88
    ("sheet MIP/MinIP RMSE", 0.15, true),      // 0.098
    ("sheet MIP/MinIP RMSE, edge", 0.4, true), // 0.255
    // Splatted MIP shows a pixel where the kernels' weights reach ½ (`composite_band_sheet`).
    ("sheet MIP/MinIP covered", 0.6, false),        // 0.72
    ("sheet MIP/MinIP covered, edge", 0.35, false), // 0.46
    ("sheet X-ray rel. L2", 0.25, true),            // 0.174
    ("sheet X-ray rel. L2, edge", 0.7, true),       // 0.471
    // The sum of the X-ray image: the sheet's thickness (one spacing per sample) at any angle.
    ("sheet X-ray Σ error", 0.003, true),     // 0.0005
    ("sheet X-ray Σ error, edge", 0.1, true), // 0.061
];

fn thin_sweep(perspective: bool) {
    use volsplat_splat::{Antialias, Preintegrate, ShadeAt, Visibility, render_slabs};
    use volsplat_testkit::reference::{Extent, reference_minip, reference_xray};
    let grids = thin_grids();
    let vols: Vec<_> = grids
        .iter()
        .map(|(_, g)| phantom::sample_on_grid(&thin_blobs(g), g, 1).unwrap())
        .collect();
    let (plain, lit) = (thin_tables(false), thin_tables(true));
    let lists: Vec<_> = vols
        .iter()
        .map(|v| SplatList::build(v, &plain, &ExtractSettings::default()).unwrap())
        .collect();
    let verbose = std::env::var_os("SWEEP_VERBOSE").is_some();
    let mut checks = ThinChecks::new(&THIN_BOUNDS);
    let mut n = 0usize;
    for az in (0..360).step_by(15) {
        for el in [-90.0, -60.0, -20.0, 0.0, 45.0, 90.0] {
            let gi = n % grids.len();
            let shape = SHAPES[(n / grids.len() + n) % 4];
            n += 1;
            let (name, grid) = &grids[gi];
            let vol = &vols[gi];
            let cam = thin_camera(grid, az as f64, el, perspective);
            let proj = Projection::new(&cam, shape.0, shape.1).unwrap();
            let thin_axis = (0..3).min_by_key(|&a| grid.dims[a]).unwrap_or(0);
            let facing = cam.frame().forward.dot(grid.direction.col(thin_axis)).abs();
            let edge = if facing < 0.3 { ", edge" } else { "" };
            let what = format!(
                "thin {} az {az} el {el} {name} {}×{} (facing {facing:.2})",
                if perspective { "perspective" } else { "ortho" },
                shape.0,
                shape.1
            );
            let min_spacing = grid.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s));
            let centres = ReferenceSettings {
                step: min_spacing / 8.0,
                ..ReferenceSettings::default()
            };
            // 3 × 3 rays per pixel, so that the reference does not alias the line a sheet shows
            // edge-on (the splatting renderers are area-filtered by their kernel).
            let cells = ReferenceSettings {
                extent: Extent::Cells,
                supersample: 3,
                ..centres
            };
            let base = {
                let mut s = RenderSettings::default();
                s.width = shape.0;
                s.height = shape.1;
                s
            };
            let slab = |mode, slab, pre, shade_at| {
                let mut s = base.clone();
                s.mode = mode;
                s.visibility = Visibility::ImageAligned;
                s.antialias = Antialias::None;
                s.slab = slab;
                s.preintegrate = pre;
                s.shade_at = shade_at;
                s
            };
            let finite = |r: &Rendered, who: &str| {
                assert!(
                    r.image.pixels().iter().flatten().all(|v| !v.is_infinite()),
                    "{what}: {who}: infinite pixels"
                );
                if r.values.is_none() {
                    assert!(
                        r.image.pixels().iter().flatten().all(|v| v.is_finite()),
                        "{what}: {who}: NaN pixels"
                    );
                }
            };
            let slabs = |tables: &CrioTables, s: &RenderSettings| {
                let r = render_slabs(vol, &cam, tables, s, None, &mut |_| true).unwrap();
                finite(&r, "slabs");
                r
            };
            let sheets = |tables: &CrioTables, list: &SplatList, mode| {
                let s = {
                    let mut s = base.clone();
                    s.mode = mode;
                    s
                };
                let r = if perspective {
                    render_list(list, &cam, tables, &s).unwrap()
                } else {
                    render(vol, &cam, tables, &s).unwrap()
                };
                finite(&r, "sheets");
                r
            };
            let mut line = String::new();
            // Composite through the slabs.
            let composite = RenderMode::Composite;
            let ref_plain = reference_composite(vol, &proj, &plain, &centres);
            let ref_lit = reference_composite(vol, &proj, &lit, &centres);
            let voxel_order = ReferenceSettings {
                shade_at_voxels: true,
                ..centres
            };
            let ref_voxels = reference_composite(vol, &proj, &lit, &voxel_order);
            let m0 = alpha_mass(&ref_plain);
            assert!(m0 > 0.5, "{what}: the reference draws nothing ({m0})");
            for (check, tables, s, reference) in [
                (
                    "slab ½ composite dB",
                    &plain,
                    slab(composite, 0.5, Preintegrate::Off, ShadeAt::Samples),
                    &ref_plain,
                ),
                (
                    "slab 1 composite dB",
                    &plain,
                    slab(composite, 1.0, Preintegrate::Off, ShadeAt::Samples),
                    &ref_plain,
                ),
                (
                    "slab 1 pre-integrated dB",
                    &plain,
                    slab(composite, 1.0, Preintegrate::On, ShadeAt::Samples),
                    &ref_plain,
                ),
                (
                    "slab ½ shaded dB",
                    &lit,
                    slab(composite, 0.5, Preintegrate::Off, ShadeAt::Samples),
                    &ref_lit,
                ),
                (
                    "slab 1 shaded at voxels dB",
                    &lit,
                    slab(composite, 1.0, Preintegrate::Off, ShadeAt::Voxels),
                    &ref_voxels,
                ),
            ] {
                let img = slabs(tables, &s).image;
                let p = image_psnr(&img, reference);
                let mass = (alpha_mass(&img) / alpha_mass(reference) - 1.0).abs();
                line += &format!(" {p:.1}/{mass:.3}");
                checks.see(check, p, &what);
                checks.see("slab Σα error", mass, &what);
            }
            // Composite through the sheets.
            let ref_cells = reference_composite(vol, &proj, &plain, &cells);
            let c = sheets(&plain, &lists[gi], composite);
            let p = image_psnr(&c.image, &ref_cells);
            let ratio = alpha_mass(&c.image) / alpha_mass(&ref_cells);
            line += &format!(" sheets {p:.1}/{ratio:.3}");
            checks.see(&format!("sheet composite dB{edge}"), p, &what);
            checks.see("sheet Σα / reference", ratio, &what);
            if !perspective {
                // Shaded, orthographic (the dense sheets shade through the slab kernel's table).
                let lit_cells = reference_composite(vol, &proj, &lit, &cells);
                let img = render(vol, &cam, &lit, &base).unwrap().image;
                let p = image_psnr(&img, &lit_cells);
                line += &format!(" shaded {p:.1}");
                checks.see(&format!("sheet composite dB{edge}"), p, &what);
            }
            // MIP and MinIP.
            for (mode, f) in [
                (RenderMode::Mip, reference_mip as fn(_, _, _) -> _),
                (RenderMode::Minip, reference_minip),
            ] {
                let s = slabs(
                    &plain,
                    &slab(mode, 0.5, Preintegrate::Off, ShadeAt::Samples),
                );
                let (e, cover) = extreme_error(values(&s), &f(vol, &proj, &centres));
                checks.see("slab MIP/MinIP RMSE", e, &what);
                checks.see("slab MIP/MinIP uncovered", 1.0 - cover, &what);
                let r = sheets(&plain, &lists[gi], mode);
                let (e2, cover2) = extreme_error(values(&r), &f(vol, &proj, &cells));
                checks.see(&format!("sheet MIP/MinIP RMSE{edge}"), e2, &what);
                checks.see(&format!("sheet MIP/MinIP covered{edge}"), cover2, &what);
                line += &format!(" {mode:?} {e:.4}/{e2:.4} ({cover2:.2})");
            }
            // X-ray (the sheets only), against the reference over the voxels' cells.
            let x = sheets(&plain, &lists[gi], RenderMode::Xray);
            let xv = values(&x).values();
            assert!(xv.iter().all(|v| v.is_finite()), "{what}: X-ray not finite");
            let xr = reference_xray(vol, &proj, &cells);
            let xe = relative_l2(xv, xr.values());
            let sum = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>();
            let xs = (sum(xv) / sum(xr.values()) - 1.0).abs();
            checks.see(&format!("sheet X-ray rel. L2{edge}"), xe, &what);
            checks.see(&format!("sheet X-ray Σ error{edge}"), xs, &what);
            line += &format!(" xray {xe:.4}/{xs:.4}");
            if verbose {
                eprintln!("{what}:{line}");
            }
        }
    }
    checks.report(&format!(
        "thin sweep ({}, {n} views)",
        if perspective {
            "perspective"
        } else {
            "orthographic"
        }
    ));
}

#[test]
fn thin_volumes_match_the_reference_at_every_angle() {
    thin_sweep(false);
    thin_sweep(true);
}
