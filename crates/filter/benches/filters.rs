//! Criterion benchmarks: cost per pixel of each technique against footprint size, and NIL
//! pre-processing against texture size (thesis Tables 5.2, 5.5, 5.9, 5.10).
//!
//! `cargo bench -p volsplat-filter --features bench --bench filters`. Ids: `<technique>/<parameter>`, the
//! parameter being the footprint half-width in texture units (`fp=…`) or the texture size.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::DVec3;
use std::hint::black_box;
use std::time::Duration;
use volsplat_filter::clamp::{ClampKind, ClampSettings, clamped_sample};
use volsplat_filter::direct::{DirectSettings, QuadratureRule, filter_direct};
use volsplat_filter::ewa::{EwaSettings, EwaTable, EwaVariant, SampleCount, filter_ewa};
use volsplat_filter::filters::FilterKind;
use volsplat_filter::nil::{
    CosineNilMap, DiscreteNilMap, DiscreteNilSettings, NilScratch, NilSettings, nil_filter_box,
};
use volsplat_filter::region::{Ellipse, OrientedBox};
use volsplat_filter::scene::PixelFootprint;
use volsplat_filter::texture::{CosineTexture, DiscreteTexture, Reconstruction, SolidTexture};

/// A tangent-plane footprint on the plane z = 0.3: ellipse semi-axes `a` and `a/3`, ε = 0.01.
fn footprint(a: f64) -> PixelFootprint {
    let center = DVec3::new(0.37, 2.21, 0.3);
    let ellipse = Ellipse {
        center,
        axes: [DVec3::new(0.0, a, 0.0), DVec3::new(a / 3.0, 0.0, 0.0)],
        normal: DVec3::Z,
    };
    let v_tan = OrientedBox {
        center,
        axes: [ellipse.axes[0], ellipse.axes[1], DVec3::Z * 0.005],
    };
    PixelFootprint {
        hit: center,
        normal: DVec3::Z,
        ray: DVec3::new(0.0, 0.9, -0.3).normalize(),
        depth: 3.0,
        ellipse,
        v_tan,
        v_ray: v_tan,
        substituted: false,
    }
}

const SIZES: [f64; 3] = [0.01, 0.1, 1.0];

fn per_pixel(c: &mut Criterion) {
    let tex = CosineTexture::seeded(4, 1).expect("texture");
    let gauss = FilterKind::Gaussian { alpha: 2.0 };
    let mut g = c.benchmark_group("per-pixel");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    for &a in &SIZES {
        let fp = footprint(a);
        let id = |name: &str| BenchmarkId::new(name, format!("fp={a}"));
        g.bench_function(id("point"), |b| b.iter(|| tex.value(black_box(fp.hit))));
        for (name, kind) in [
            ("clamp step", ClampKind::Step),
            ("clamp quadratic", ClampKind::Quadratic),
        ] {
            let s = ClampSettings {
                kind,
                phi_max: 0.25,
            };
            g.bench_function(id(name), |b| {
                b.iter(|| clamped_sample(&tex, black_box(&fp.v_tan), &s))
            });
        }
        for (name, rule, filter) in [
            (
                "direct simpson box",
                QuadratureRule::AdaptiveSimpson,
                FilterKind::Box,
            ),
            (
                "direct gauss27 box",
                QuadratureRule::Gauss3,
                FilterKind::Box,
            ),
            (
                "direct hybrid75 box",
                QuadratureRule::Hybrid,
                FilterKind::Box,
            ),
            (
                "direct simpson gaussian",
                QuadratureRule::AdaptiveSimpson,
                gauss,
            ),
        ] {
            let s = DirectSettings {
                rule,
                filter,
                ..Default::default()
            };
            g.bench_function(id(name), |b| {
                b.iter(|| filter_direct(&tex, black_box(&fp.v_tan), &s))
            });
        }
        for n in [3usize, 11] {
            for (name, variant, count) in [
                ("ewa3 fixed", EwaVariant::Ewa3, SampleCount::Fixed),
                ("ewa3 adaptive", EwaVariant::Ewa3, SampleCount::Adaptive),
                ("ewa2 fixed", EwaVariant::Ewa2, SampleCount::Fixed),
            ] {
                let s = EwaSettings {
                    variant,
                    count,
                    max_samples: n,
                    ..Default::default()
                };
                let table = EwaTable::new(&s).expect("table");
                g.bench_function(id(&format!("{name} n={n}")), |b| {
                    b.iter(|| filter_ewa(&tex, black_box(&fp), 0.01, &s, &table))
                });
            }
        }
        for m in [1usize, 4] {
            let map = CosineNilMap::build(&tex, m, 10).expect("map");
            for tol in [10usize, 2] {
                let s = NilSettings {
                    tolerance: tol,
                    ..Default::default()
                };
                let mut scratch = NilScratch::default();
                g.bench_function(id(&format!("nil cosine M={m} tol={tol}")), |b| {
                    b.iter(|| nil_filter_box(&map, black_box(&fp.v_tan), gauss, &s, &mut scratch))
                });
            }
        }
    }
    g.finish();
}

fn nil_preprocessing(c: &mut Criterion) {
    let tex = CosineTexture::seeded(4, 1).expect("texture");
    let mut g = c.benchmark_group("nil-build");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(2));
    for m in [1usize, 4] {
        g.bench_function(
            BenchmarkId::new(format!("cosine 4x4x4 M={m}"), "gamma_max=10"),
            |b| b.iter(|| CosineNilMap::build(black_box(&tex), m, 10)),
        );
    }
    for (m, sizes) in [(1usize, &[16usize, 32, 64][..]), (4, &[16, 32][..])] {
        for &n in sizes {
            let d = DiscreteTexture::sample(
                &tex,
                [n, n, n],
                DVec3::ZERO,
                1.0 / n as f64,
                Reconstruction::Trilinear,
            )
            .expect("sample");
            let s = DiscreteNilSettings {
                order: m,
                ..Default::default()
            };
            g.bench_function(
                BenchmarkId::new(format!("discrete trilinear M={m}"), format!("{n}^3")),
                |b| b.iter(|| DiscreteNilMap::build(black_box(&d), &s)),
            );
        }
    }
    g.finish();
}

criterion_group!(benches, per_pixel, nil_preprocessing);
criterion_main!(benches);
