//! Criterion benches of the Chapter 6 displays (Buchanan Tables 6.1, 6.2): per-image time of
//! Sabella, the direct linearised display and its NIL approximation by patch order, and the NIL
//! map construction, with projected (decision 0007) and interpolated (thesis) control points,
//! on a smooth 32³ phantom at 48 × 48 pixels.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use volsplat_core::{Camera, Grid};
use volsplat_filter::display::{
    ControlPoints, DisplayKind, DisplaySettings, DisplayVolume, Evaluator, NilDisplaySettings,
    build_map, render_display,
};
use volsplat_filter::texture::Reconstruction;

fn phantom(n: usize) -> DisplayVolume {
    let grid = Grid::with_dims([n, n, n]).expect("grid");
    let c = (n - 1) as f64 / 2.0;
    let mut d = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let r2 = ((i as f64 - c).powi(2) + (j as f64 - c).powi(2) + (k as f64 - c).powi(2))
                    / (c * c);
                d.push((0.8 * (-3.0 * r2).exp() + 0.1 * ((i + 2 * j) as f64 * 0.4).sin()).max(0.0));
            }
        }
    }
    DisplayVolume::new(&grid, &d, Reconstruction::Trilinear).expect("volume")
}

fn benches(c: &mut Criterion) {
    let vol = phantom(32);
    let (lo, hi) = (
        volsplat_core::glam::DVec3::ZERO,
        volsplat_core::glam::DVec3::splat(31.0),
    );
    let cam = Camera::reset_to_bounds(lo, hi, true);
    let (w, h) = (48, 48);
    let mut g = c.benchmark_group("display 32³→48²");
    g.sample_size(10);
    let sab = DisplaySettings {
        kind: DisplayKind::Sabella,
        ..Default::default()
    };
    g.bench_function("sabella 4x4 rays, 256 samples", |b| {
        b.iter(|| render_display(&vol, None, &cam, w, h, black_box(&sab)).expect("render"))
    });
    let direct = DisplaySettings {
        evaluator: Evaluator::Direct,
        ..Default::default()
    };
    g.bench_function("linearised direct", |b| {
        b.iter(|| render_display(&vol, None, &cam, w, h, black_box(&direct)).expect("render"))
    });
    for m in 1..=3 {
        g.bench_function(format!("nil map build M={m}"), |b| {
            b.iter(|| build_map(&vol, m, None, 1 << 26).expect("map"))
        });
        let map = build_map(&vol, m, None, 1 << 26).expect("map");
        let s = DisplaySettings::default();
        g.bench_function(
            format!("linearised nil M={m} tol 2 steps 32 project"),
            |b| {
                b.iter(|| {
                    render_display(&vol, Some(&map), &cam, w, h, black_box(&s)).expect("render")
                })
            },
        );
        let si = DisplaySettings {
            nil: NilDisplaySettings {
                control: ControlPoints::Interpolate,
                ..Default::default()
            },
            ..Default::default()
        };
        g.bench_function(
            format!("linearised nil M={m} tol 2 steps 32 interpolate"),
            |b| {
                b.iter(|| {
                    render_display(&vol, Some(&map), &cam, w, h, black_box(&si)).expect("render")
                })
            },
        );
    }
    g.finish();
}

criterion_group!(display, benches);
criterion_main!(display);
