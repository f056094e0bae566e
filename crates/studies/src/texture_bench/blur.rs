//! The blur measurements: Plate 5.6 / Table 5.3's marble grid and Appendix C's motion blur.

use super::scoring::mse_8bit;
use super::{BenchImage, BlurRow, TextureBenchSettings, slug};
use crate::metrics::total_variation;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;
use volsplat_core::ScalarImage;
use volsplat_filter::Result;
use volsplat_filter::direct::{DirectSettings, QuadratureRule};
use volsplat_filter::filters::FilterKind;
use volsplat_filter::nil::{CosineNilMap, NilScratch, NilSettings, nil_filter_with};
use volsplat_filter::render::{RegionKind, Technique, render};
use volsplat_filter::scene::{Footprint, Scene, SceneSettings, Surface};
use volsplat_filter::texture::{CosineTexture, MarbleTexture, SolidTexture};

/// Plate 5.6 / Table 5.3: a marble sphere with box and Bartlett filters on `V_tan` (spread 1,
/// 2, 4; ε = 0.01) and a box on `V_ray` (ε = 0.025, 0.1, 0.2), by direct evaluation.
pub(super) fn marble_grid(
    settings: &TextureBenchSettings,
    blur: &mut Vec<BlurRow>,
    images: &mut Vec<BenchImage>,
) -> Result<()> {
    let marble = MarbleTexture::default_marble(settings.seed);
    let (w, h) = (
        settings.width.div_ceil(2).max(8),
        settings.height.div_ceil(2).max(8),
    );
    let cases: Vec<(String, f64, f64, FilterKind, RegionKind)> = [1.0, 2.0, 4.0]
        .iter()
        .flat_map(|&s| {
            [
                (
                    format!("marble box V_tan spread={s}"),
                    s,
                    0.01,
                    FilterKind::Box,
                    RegionKind::Tangent,
                ),
                (
                    format!("marble Bartlett V_tan spread={s}"),
                    s,
                    0.01,
                    FilterKind::Bartlett,
                    RegionKind::Tangent,
                ),
            ]
        })
        .chain([0.025, 0.1, 0.2].iter().map(|&e| {
            (
                format!("marble box V_ray eps={e}"),
                1.0,
                e,
                FilterKind::Box,
                RegionKind::Ray,
            )
        }))
        .collect();
    for (label, spread, eps, filter, region) in cases {
        let mut ss = SceneSettings::test_sphere(w, h);
        ss.spread = spread;
        ss.epsilon = eps;
        let scene = Scene::new(ss)?;
        let technique = Technique::Direct {
            settings: DirectSettings {
                rule: if region == RegionKind::Tangent {
                    QuadratureRule::Hybrid
                } else {
                    QuadratureRule::AdaptiveSimpson
                },
                filter,
                tolerance: settings.reference_tolerance,
                max_depth: 6,
            },
            region,
        };
        let r = render(&scene, &marble, &technique)?;
        blur.push(BlurRow {
            what: label.clone(),
            total_variation: total_variation(&r.image),
            mse_vs_unblurred: None,
            seconds: r.seconds,
        });
        images.push(BenchImage {
            name: format!("plate_5_6_{}", slug(&label)),
            caption: label,
            image: r.image,
        });
    }
    Ok(())
}

/// Appendix C: a plane rotating about the z axis by `θ`; the NIL filter
/// `F(p) = exp(−(R − |p_xy|)²/a)` with triggers laid along the arc (`n_s = 5`).
pub(super) fn motion_blur(
    settings: &TextureBenchSettings,
    tex: &CosineTexture,
    blur: &mut Vec<BlurRow>,
    images: &mut Vec<BenchImage>,
) -> Result<()> {
    let (w, h) = (
        settings.width.div_ceil(2).max(8),
        settings.height.div_ceil(2).max(8),
    );
    let mut ss = SceneSettings::test_plane(w, h);
    ss.camera.position = [0.0, -2.2, 2.5];
    ss.camera.focal_point = [0.0, 0.0, 0.3];
    ss.camera.view_up = [0.0, 1.0, 0.0];
    ss.surface = Surface::Plane {
        point: DVec3::new(0.0, 0.0, 0.3),
        normal: DVec3::Z,
    };
    let scene = Scene::new(ss)?;
    let map = CosineNilMap::build(tex, 2, 10)?;
    let nil = NilSettings {
        tolerance: 2,
        ..Default::default()
    };
    let n_s = 5usize;
    let thetas = [
        ("0", 0.0),
        ("pi/24", std::f64::consts::PI / 24.0),
        ("pi/12", std::f64::consts::PI / 12.0),
        ("pi/6", std::f64::consts::PI / 6.0),
    ];
    let mut baseline: Option<ScalarImage> = None;
    for (k, (name, theta)) in thetas.iter().enumerate() {
        let t = Instant::now();
        let values: Vec<f32> = (0..h)
            .into_par_iter()
            .flat_map_iter(|y| {
                let mut scratch = NilScratch::default();
                (0..w)
                    .map(|x| match scene.footprint(x, y) {
                        Footprint::Background => 0.0,
                        Footprint::Degenerate(_) => tex.mean() as f32,
                        Footprint::Hit(fp) => {
                            let cb = fp.hit;
                            let a = fp.ellipse.major();
                            let trig = arc_triggers(cb, a, n_s, *theta);
                            let r0 = (cb.x * cb.x + cb.y * cb.y).sqrt();
                            let f = |p: DVec3| {
                                let d = r0 - (p.x * p.x + p.y * p.y).sqrt();
                                (-(d * d) / a).exp()
                            };
                            let r = nil_filter_with(&map, &trig, &f, &nil, &mut scratch);
                            if r.collapsed {
                                tex.value(cb) as f32
                            } else {
                                r.value() as f32
                            }
                        }
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        let img = ScalarImage::from_values(w, h, values).unwrap_or_else(|| ScalarImage::new(w, h));
        let base = baseline.get_or_insert_with(|| img.clone());
        blur.push(BlurRow {
            what: format!("motion blur θ={name}"),
            total_variation: total_variation(&img),
            mse_vs_unblurred: mse_8bit(&img, base),
            seconds: t.elapsed().as_secs_f64(),
        });
        images.push(BenchImage {
            name: format!("plate_5_{}_motion_blur_{}", 13 + k, slug(name)),
            caption: format!("Motion blur, rotation {name}"),
            image: img,
        });
    }
    Ok(())
}

/// Appendix C `Lay_Down_Rotate_Points`: `n_s` angular steps of `θ/n_s` from `atan2(c_B)`,
/// `n_s` radial positions from `R − a` (stride `2a/n_s`, angular stagger `θ/n_s²`), three
/// depths `z ± 0.01` (the printed code uses absolute `z ∈ {−0.01, 0, 0.01}` on a `z = 0`
/// plane).
pub fn arc_triggers(cb: DVec3, a: f64, n_s: usize, theta: f64) -> Vec<DVec3> {
    let n = n_s.max(1);
    let rot_delta = theta / n as f64;
    let offset = rot_delta / n as f64;
    let start = cb.y.atan2(cb.x);
    let r0 = (cb.x * cb.x + cb.y * cb.y).sqrt();
    let mut out = Vec::with_capacity(3 * n * n);
    for i in 0..n {
        let angle = start + i as f64 * rot_delta;
        for j in 0..n {
            let len = r0 - a + 2.0 * a / n as f64 * j as f64;
            let (s, c) = (angle + j as f64 * offset).sin_cos();
            for dz in [-0.01, 0.0, 0.01] {
                out.push(DVec3::new(len * c, len * s, cb.z + dz));
            }
        }
    }
    out
}
