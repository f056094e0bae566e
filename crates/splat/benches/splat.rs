//! Criterion benchmarks of the splatting renderer.
//!
//! - `composite 256³→512² gaussian shaded/{1,2} threads`: Marschner–Lobb 256³ u8 with the
//!   transfer function of the VTK baseline script (research/anchors.md, Appendix A), shaded,
//!   orthographic, azimuth 30°, elevation 20°.
//! - `table-4.01/<resolution>/<kernel>`: Westover's Table 4.01 grid on a CT-like head of
//!   256×256×93 voxels with z spacing twice x/y, 512², three input resolutions (every 4th, 2nd,
//!   every voxel) × three kernels (single-point, nearest, Gaussian).
//! - `slab CT head 256x256x108 ct-skin/<size>² <level>`: the CT-like head phantom (i16 HU, as
//!   `volsplat phantom head --grid 256,256,108`), `ct-skin`, shaded at the voxels, image-aligned
//!   slabs, 2 threads, at 128², 256² and 512², the full level (minified views supersampled)
//!   against the pyramid level whose voxel is about a pixel (`auto_level`; decision 0031).
//!
//! Run: `cargo bench -p volsplat-splat --features bench --bench splat`. Numbers go to docs/BENCHMARKS.md.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::sync::Arc;
use volsplat_core::glam::DMat3;
use volsplat_core::phantom::{self, EllipsoidPhantom, MarschnerLobb, Phantom};
use volsplat_core::{Camera, CrioTables, Grid, Kernel, TransferFunction, Volume};
use volsplat_splat::{
    Pyramid, RenderSettings, ShadeAt, Visibility, auto_level, focal_pixel_size, render,
    render_level,
};

fn marschner_lobb_u8(n: usize) -> Volume<u8> {
    let f = phantom::sample(
        &MarschnerLobb {
            f_m: 6.0,
            alpha: 0.25,
        },
        [n; 3],
        1,
    )
    .expect("phantom");
    let grid = Grid::with_dims([n; 3]).expect("valid grid");
    let data = f
        .data()
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0) as u8)
        .collect();
    Volume::new(grid, data).expect("sizes match")
}

/// The VTK baseline's transfer function (anchors.md Appendix A) over [lo, hi].
pub fn vtk_baseline_tf(lo: f64, hi: f64) -> TransferFunction {
    TransferFunction {
        color: vec![
            [lo, 0.0, 0.0, 0.0],
            [hi * 0.5, 1.0, 0.5, 0.3],
            [hi, 1.0, 1.0, 1.0],
        ],
        scalar_opacity: vec![[lo, 0.0], [lo + 0.3 * (hi - lo), 0.0], [hi, 0.6]],
        shade: true,
        ..TransferFunction::ramp(lo, hi, 1.0)
    }
}

/// An orthographic view after VTK's reset, orbited (the tests' camera, `volsplat-testkit`).
fn orbit_camera(grid: &Grid, az: f64, el: f64) -> Camera {
    volsplat_testkit::fixtures::orbit_camera(grid, az, el, true)
}

fn composite_256(c: &mut Criterion) {
    let vol = marschner_lobb_u8(256);
    let (lo, hi) = vol.value_range();
    let tables =
        CrioTables::from_transfer_function(&vtk_baseline_tf(lo, hi), 4096).expect("valid tf");
    let cam = orbit_camera(vol.grid(), 30.0, 20.0);
    let settings = RenderSettings::default();
    let mut g = c.benchmark_group("composite 256³→512² gaussian shaded");
    g.sample_size(10);
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        g.bench_function(format!("{threads} threads"), |b| {
            b.iter(|| {
                pool.install(|| black_box(render(&vol, &cam, &tables, &settings).expect("render")))
            })
        });
    }
    g.finish();
}

fn table_4_01(c: &mut Criterion) {
    // CT-like head 256×256×93 with z spacing twice x/y (Westover §4.2.4).
    let head = EllipsoidPhantom::ct_head();
    let (lo, hi) = head.bounds();
    let ext = hi - lo;
    let grid = Grid::new(
        [256, 256, 93],
        [ext.x / 255.0, ext.y / 255.0, 2.0 * ext.x / 255.0],
        lo.to_array(),
        DMat3::IDENTITY,
    )
    .expect("valid grid");
    let vol = phantom::sample_on_grid(&head, &grid, 1).expect("phantom");
    let tables = CrioTables::from_transfer_function(
        &TransferFunction::preset("ct-bone", (-1000.0, 2000.0)).expect("preset"),
        4096,
    )
    .expect("valid tf");
    let cam = orbit_camera(vol.grid(), 20.0, 10.0);
    let mut g = c.benchmark_group("table-4.01 head 256x256x93→512²");
    g.sample_size(10);
    for sub in [4, 2, 1] {
        for (name, kernel) in [
            ("point", Kernel::SinglePoint),
            ("nearest", Kernel::Nearest),
            ("gaussian", Kernel::default()),
        ] {
            let s = {
                let mut s = RenderSettings::default();
                s.kernel = kernel;
                s.subsample = sub;
                s
            };
            g.bench_function(format!("every {sub}/{name}"), |b| {
                b.iter(|| black_box(render(&vol, &cam, &tables, &s).expect("render")))
            });
        }
    }
    g.finish();
}

fn slab_previews(c: &mut Criterion) {
    let vol = phantom::ct_head_volume([256, 256, 108]).expect("phantom");
    let grid = vol.grid().clone();
    let pyramid = Pyramid::new(Arc::new(vol.into()));
    let tables = CrioTables::from_transfer_function(
        &TransferFunction::preset("ct-skin", (-1024.0, 3071.0)).expect("preset"),
        4096,
    )
    .expect("valid tf");
    let cam = orbit_camera(&grid, 30.0, 15.0);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("pool");
    let bricks = volsplat_splat::BrickGrid::build(match &**pyramid.full() {
        volsplat_core::AnyVolume::I16(v) => v,
        _ => unreachable!("the head is i16"),
    });
    let mut g = c.benchmark_group("slab CT head 256x256x108 ct-skin");
    g.sample_size(10);
    for n in [128, 256, 512] {
        let auto = auto_level(
            focal_pixel_size(&cam, n, n).expect("camera"),
            pyramid.grids(),
        );
        // Levels are built once, outside the timing.
        pyramid.level(auto).expect("level");
        let s = {
            let mut s = RenderSettings::default();
            s.width = n;
            s.height = n;
            s.visibility = Visibility::ImageAligned;
            s.shade_at = ShadeAt::Voxels;
            s.slab = 1.0;
            s.opacity_cutoff = 1.0 - 255.0 / 32767.0;
            s.antialias = volsplat_splat::Antialias::Swan;
            s
        };
        for (name, level) in [("full", 0), ("auto", auto)] {
            g.bench_function(format!("{n}² {name} (level {level})"), |b| {
                b.iter(|| {
                    pool.install(|| {
                        black_box(
                            render_level(
                                &pyramid,
                                level,
                                &cam,
                                &tables,
                                &s,
                                Some(&bricks),
                                &mut |_| true,
                            )
                            .expect("render"),
                        )
                    })
                })
            });
        }
    }
    g.finish();
}

criterion_group!(benches, composite_256, table_4_01, slab_previews);
criterion_main!(benches);
