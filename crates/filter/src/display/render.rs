//! The per-pixel loop of the Chapter 6 displays (Buchanan App. B) for both evaluators.

use super::filter::{PixelFilter, Sigma, composite_nodes, direct, triggers};
use super::volume::{DisplayVolume, PixelRay, Rays};
use super::{
    DisplayImage, DisplayKind, DisplaySettings, DisplayStats, Evaluator, SearchRule, TransferCache,
};
use crate::error::{FilterError, Result};
use crate::nil::Cell;
use crate::nil::{
    DiscreteNilMap, LevelWeighting, NilResult, NilSource, enclosing_cell, evaluate_cells,
    find_hierarchy,
};
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;
use volsplat_core::{Camera, Projection};

/// Largest image the displays accept (pixels per side).
const MAX_SIDE: usize = 16384;

#[derive(Default)]
struct Scratch {
    triggers: Vec<DVec3>,
    cells: Vec<Cell>,
    moments: Vec<f64>,
    /// Linearised display: where the central ray leaves the last kept cell (world `t`).
    t_end: f64,
}

struct Pixel {
    value: f32,
    green: f32,
    scale: f64,
    channels: [f64; 4],
}

pub(crate) fn render(
    vol: &DisplayVolume,
    map: Option<&DiscreteNilMap>,
    camera: &Camera,
    width: usize,
    height: usize,
    s: &DisplaySettings,
) -> Result<DisplayImage> {
    let start = Instant::now();
    s.validate()?;
    if !(1..=MAX_SIDE).contains(&width) || !(1..=MAX_SIDE).contains(&height) {
        return Err(FilterError::invalid(
            "image size",
            (width, height),
            "width and height must be in 1..=16384",
        ));
    }
    let uses_nil = s.evaluator == Evaluator::Nil
        && matches!(
            s.kind,
            DisplayKind::Linearised | DisplayKind::Slice | DisplayKind::SampleFilter
        );
    let channels = match (uses_nil, map) {
        (false, _) => 1,
        (true, None) => {
            return Err(FilterError::NotApplicable {
                technique: "NIL display".into(),
                reason: "no NIL map was given".into(),
            });
        }
        (true, Some(m)) => {
            if m.texture().dims() != vol.texture().dims() {
                return Err(FilterError::invalid(
                    "NIL map",
                    m.texture().dims(),
                    "was built from another volume",
                ));
            }
            m.channels()
        }
    };
    let coeffs: Vec<f64> = if channels > 1 {
        if s.kind == DisplayKind::SampleFilter {
            return Err(FilterError::NotApplicable {
                technique: "sample-and-filter".into(),
                reason: "needs a plain NIL map (no transfer basis)".into(),
            });
        }
        match &s.transfer {
            Some(b) if b.len() == channels => b.clone(),
            other => {
                return Err(FilterError::invalid(
                    "transfer coefficients",
                    other.as_ref().map_or(0, |b| b.len()),
                    format!("the NIL map has a transfer basis of {channels} functions"),
                ));
            }
        }
    } else {
        vec![1.0]
    };
    let proj = Projection::new(camera, width, height)?;
    let rays = Rays { proj };
    let sigma_of = |ray: &PixelRay| match proj {
        Projection::Ortho(_) => Sigma {
            a: s.screen_sigma_px * rays.pixel_size(ray, 1.0),
            b: 0.0,
        },
        Projection::Perspective(_) => Sigma {
            a: 0.0,
            b: s.screen_sigma_px * proj.pixel_size_at(1.0) * ray.cos,
        },
    };
    let unit = vol.unit();
    let tau = s.tau / unit;
    let step = s.quadrature.step * vol.min_spacing();
    let cross = composite_nodes(
        -super::filter::TRUNC,
        super::filter::TRUNC,
        s.quadrature.cross_nodes / 4,
        4,
    );
    let slice_depths = {
        let (lo, hi) = {
            let d = vol.dims().map(|n| (n - 1) as f64);
            let mut lo = f64::INFINITY;
            let mut hi = f64::NEG_INFINITY;
            for c in 0..8 {
                let p = DVec3::new(
                    if c & 1 == 1 { d[0] } else { 0.0 },
                    if c & 2 == 2 { d[1] } else { 0.0 },
                    if c & 4 == 4 { d[2] } else { 0.0 },
                );
                let depth = proj.raster_from_world(vol.world_from_index(p)).z;
                lo = lo.min(depth);
                hi = hi.max(depth);
            }
            (lo, hi)
        };
        lo + s.slice_depth * (hi - lo)
    };

    let pixel = |x: usize, y: usize, sc: &mut Scratch, st: &mut DisplayStats| -> Pixel {
        let mut px = Pixel {
            value: 0.0,
            green: 0.0,
            scale: 0.0,
            channels: [0.0; 4],
        };
        let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
        match s.kind {
            DisplayKind::Sabella | DisplayKind::Maximum => {
                let t0 = Instant::now();
                let n = s.supersample;
                let (mut inten, mut mx) = (0.0, 0.0);
                for sy in 0..n {
                    for sx in 0..n {
                        let fx = x as f64 + (sx as f64 + 0.5) / n as f64;
                        let fy = y as f64 + (sy as f64 + 0.5) / n as f64;
                        if let Some(ray) = rays.ray(vol, fx, fy) {
                            st.rays += 1;
                            let (i, m) = sabella_ray(vol, &ray, tau, s.samples_per_ray);
                            inten += i;
                            mx += m;
                        }
                    }
                }
                let k = (n * n) as f64;
                let (inten, mx) = (tau * inten / k, mx / k);
                (px.value, px.green) = match s.kind {
                    DisplayKind::Sabella => (inten as f32, mx as f32),
                    _ => (mx as f32, mx as f32),
                };
                st.march_s += t0.elapsed().as_secs_f64();
            }
            DisplayKind::Linearised | DisplayKind::Slice => {
                let Some(ray) = rays.ray(vol, cx, cy) else {
                    return px;
                };
                st.rays += 1;
                let sigma = sigma_of(&ray);
                let (filter, scale) = if s.kind == DisplayKind::Linearised {
                    (PixelFilter::Linearised { ray, sigma, tau }, 1.0)
                } else {
                    let tc = slice_depths / ray.cos.max(1e-12);
                    (
                        PixelFilter::Slice {
                            ray,
                            sigma,
                            tc,
                            w: s.slice_width * unit,
                        },
                        1.0,
                    )
                };
                let ch = match (s.evaluator, map) {
                    (Evaluator::Nil, Some(map)) => {
                        let f = |p: DVec3| filter.weight_index(vol, p);
                        let keep = (s.kind == DisplayKind::Linearised).then_some(&ray);
                        let r = nil_eval(vol, map, &filter, &[&f], keep, s, sc, st);
                        let (mut ch, fell_back) = r.into_iter().next().unwrap_or_default();
                        if s.kind == DisplayKind::Linearised {
                            // eq 4.15 with K = ∫F over the cells that meet the volume (the rest
                            // hold zero density): the exponential up to where the central ray
                            // leaves them (fall-back: up to the exit t_b).
                            let t_end = if fell_back {
                                ray.tb
                            } else {
                                sc.t_end.max(ray.tb)
                            };
                            let a = 1.0 - (-tau * (t_end - ray.ta)).exp();
                            ch.iter_mut().for_each(|c| *c *= a);
                        }
                        ch
                    }
                    _ => {
                        let t0 = Instant::now();
                        let v = direct(vol, &filter, step, &cross);
                        st.evaluation_s += t0.elapsed().as_secs_f64();
                        v.map_or_else(Vec::new, |v| vec![v])
                    }
                };
                px.scale = scale;
                for (o, c) in px.channels.iter_mut().zip(&ch) {
                    *o = *c;
                }
                let v: f64 = ch.iter().zip(&coeffs).map(|(c, b)| c * b).sum();
                px.value = (scale * v) as f32;
                px.green = px.value;
            }
            DisplayKind::Search | DisplayKind::SampleFilter => {
                let Some(ray) = rays.ray(vol, cx, cy) else {
                    return px;
                };
                st.rays += 1;
                let t0 = Instant::now();
                let hit = search(vol, &ray, s.rho0, s.search, s.samples_per_ray);
                st.search_s += t0.elapsed().as_secs_f64();
                let Some(t) = hit else {
                    return px;
                };
                let c = ray.o + ray.d * t;
                if s.kind == DisplayKind::Search {
                    px.value = vol.density(c) as f32;
                } else {
                    let f1 = PixelFilter::Ball {
                        c,
                        s: s.dog_sigma[0] * unit,
                    };
                    let f2 = PixelFilter::Ball {
                        c,
                        s: s.dog_sigma[1] * unit,
                    };
                    let (a, b) = match (s.evaluator, map) {
                        (Evaluator::Nil, Some(map)) => {
                            let w1 = |p: DVec3| f1.weight_index(vol, p);
                            let w2 = |p: DVec3| f2.weight_index(vol, p);
                            let r = nil_eval(vol, map, &f2, &[&w1, &w2], None, s, sc, st);
                            let g = |i: usize| r.get(i).and_then(|c| c.0.first()).copied();
                            (g(0), g(1))
                        }
                        _ => {
                            let t0 = Instant::now();
                            let a = direct(vol, &f1, step, &cross);
                            let b = direct(vol, &f2, step, &cross);
                            st.evaluation_s += t0.elapsed().as_secs_f64();
                            (a, b)
                        }
                    };
                    let resp = a.unwrap_or(0.0) - b.unwrap_or(0.0);
                    px.scale = resp;
                    px.value = (0.5 + s.dog_gain * resp).clamp(0.0, 1.0) as f32;
                }
                px.green = px.value;
            }
        }
        px
    };

    let rows: Vec<(Vec<Pixel>, DisplayStats)> = (0..height)
        .into_par_iter()
        .map(|y| {
            let mut sc = Scratch::default();
            let mut st = DisplayStats::default();
            let row = (0..width).map(|x| pixel(x, y, &mut sc, &mut st)).collect();
            (row, st)
        })
        .collect();
    let mut stats = DisplayStats::default();
    let n = width * height;
    let mut value = Vec::with_capacity(n);
    let mut green = Vec::with_capacity(n);
    let keep_channels = uses_nil && s.kind != DisplayKind::SampleFilter;
    let mut cache = TransferCache {
        channels,
        scale: Vec::with_capacity(if keep_channels { n } else { 0 }),
        values: Vec::with_capacity(if keep_channels { n * channels } else { 0 }),
    };
    for (row, st) in rows {
        stats.add(&st);
        for p in row {
            value.push(p.value);
            green.push(p.green);
            if keep_channels {
                cache.scale.push(p.scale);
                cache.values.extend_from_slice(&p.channels[..channels]);
            }
        }
    }
    stats.total_s = start.elapsed().as_secs_f64();
    stats.pixels = n as u64;
    Ok(DisplayImage {
        width,
        height,
        value,
        green: (s.kind == DisplayKind::Sabella).then_some(green),
        cache: keep_channels.then_some(cache),
        stats,
    })
}

/// eq 3.1 along one ray with `k` midpoint samples, exact for a density constant on each
/// segment: `I += T·(1 − e^{−τρΔ})/τ`, `T ← T·e^{−τρΔ}`. Returns `(I, max ρ)`; `I` in world
/// units (`τ·I` is dimensionless, in `[0, 1)`).
pub(crate) fn sabella_ray(vol: &DisplayVolume, ray: &PixelRay, tau: f64, k: usize) -> (f64, f64) {
    let len = ray.tb - ray.ta;
    let h = len / k as f64;
    let (mut trans, mut inten, mut mx) = (1.0f64, 0.0f64, 0.0f64);
    for j in 0..k {
        let t = ray.ta + (j as f64 + 0.5) * h;
        let rho = vol.density(ray.o + ray.d * t);
        mx = mx.max(rho);
        let a = (-tau * rho * h).exp();
        inten += trans * (1.0 - a) / tau;
        trans *= a;
    }
    (inten, mx)
}

/// §6-3 search: the parameter `t` (world units) where the density along the ray meets `rho0`.
fn search(
    vol: &DisplayVolume,
    ray: &PixelRay,
    rho0: f64,
    rule: SearchRule,
    k: usize,
) -> Option<f64> {
    let len = ray.tb - ray.ta;
    let h = len / k as f64;
    let t_of = |j: usize| ray.ta + (j as f64 + 0.5) * h;
    let rho = |j: usize| vol.density(ray.o + ray.d * t_of(j));
    match rule {
        SearchRule::FirstCrossing => {
            let mut prev = rho(0) - rho0;
            if prev == 0.0 {
                return Some(t_of(0));
            }
            for j in 1..k {
                let cur = rho(j) - rho0;
                if cur == 0.0 || (cur > 0.0) != (prev > 0.0) {
                    let f = prev / (prev - cur);
                    return Some(t_of(j - 1) + f * h);
                }
                prev = cur;
            }
            None
        }
        SearchRule::Closest => {
            let mut best = (f64::INFINITY, None);
            for j in 0..k {
                let d = (rho(j) - rho0).abs();
                if d < best.0 {
                    best = (d, Some(t_of(j)));
                }
            }
            best.1
        }
    }
}

/// NIL evaluation of several filters on one hierarchy (the hierarchy comes from the triggers
/// of `shape`): Fig 4.19 then the normalised, level-weighted sum (eqs 4.13–4.16, 4.32
/// corrected). Falls back to point-sampling the filter at the triggers when the scale factor
/// collapses (decision A-4). Returns per filter the channel averages and whether it fell back.
#[allow(clippy::too_many_arguments)] // the two functions §6-5 swaps, plus buffers
fn nil_eval(
    vol: &DisplayVolume,
    map: &DiscreteNilMap,
    shape: &PixelFilter,
    filters: &[&dyn Fn(DVec3) -> f64],
    keep_box: Option<&PixelRay>,
    s: &DisplaySettings,
    sc: &mut Scratch,
    st: &mut DisplayStats,
) -> Vec<(Vec<f64>, bool)> {
    let t0 = Instant::now();
    triggers(
        vol,
        shape,
        s.nil.trigger_width,
        s.nil.trigger_steps,
        &mut sc.triggers,
    );
    let t1 = Instant::now();
    st.trigger_s += (t1 - t0).as_secs_f64();
    st.triggers += sc.triggers.len() as u64;
    sc.cells.clear();
    let root = enclosing_cell(&sc.triggers, s.nil.gamma_min, map.gamma_max());
    if let Some(root) = root {
        find_hierarchy(
            &sc.triggers,
            root,
            s.nil.tolerance,
            s.nil.gamma_min,
            &mut sc.cells,
        );
    }
    if let Some(ray) = keep_box {
        // Keep the cells that meet the box of voxel centres (the others hold zero density)
        // and find where the central ray leaves them.
        let hi = vol.dims().map(|n| (n - 1) as f64);
        sc.cells.retain(|c| {
            let h = c.size();
            (0..3).all(|a| h * c.index[a] as f64 <= hi[a] && h * (c.index[a] + 1) as f64 >= 0.0)
        });
        let q0 = vol.index_from_world(ray.o);
        let dq = vol.index_from_world(ray.o + ray.d) - q0;
        sc.t_end = f64::NEG_INFINITY;
        for c in &sc.cells {
            let h = c.size();
            let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
            for a in 0..3 {
                let (lo, up) = (h * c.index[a] as f64, h * (c.index[a] + 1) as f64);
                if dq[a].abs() < 1e-300 {
                    if q0[a] < lo || q0[a] > up {
                        t1 = f64::NEG_INFINITY;
                    }
                    continue;
                }
                let (ta, tb) = ((lo - q0[a]) / dq[a], (up - q0[a]) / dq[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
            if t1 >= t0 {
                sc.t_end = sc.t_end.max(t1);
            }
        }
    }
    let t2 = Instant::now();
    st.hierarchy_s += (t2 - t1).as_secs_f64();
    st.patches += sc.cells.len() as u64;
    let mut out = Vec::with_capacity(filters.len());
    for f in filters {
        let r: Option<NilResult> = if root.is_some() {
            evaluate_cells(
                map,
                &sc.cells,
                *f,
                LevelWeighting::CellVolume,
                s.nil.guard,
                &mut sc.moments,
            )
        } else {
            None
        };
        out.push(match r {
            Some(r) => (r.channels, false),
            None => {
                st.fallbacks += 1;
                (point_sampled(vol, map, &sc.triggers, *f), true)
            }
        });
    }
    st.evaluation_s += t2.elapsed().as_secs_f64();
    out
}

/// Fallback (decision A-4): `Σ F(p) ρ_l(p) / Σ F(p)` over the trigger points.
fn point_sampled(
    vol: &DisplayVolume,
    map: &DiscreteNilMap,
    triggers: &[DVec3],
    f: &dyn Fn(DVec3) -> f64,
) -> Vec<f64> {
    let n = map.channels();
    let mut num = vec![0.0; n];
    let mut den = 0.0;
    for &p in triggers {
        let w = f(p);
        if w == 0.0 {
            continue;
        }
        let v = vol.density_index(p);
        den += w;
        match map.transfer() {
            None => num[0] += w * v,
            Some(tb) => {
                for (l, x) in num.iter_mut().enumerate() {
                    *x += w * tb.eval(l, v);
                }
            }
        }
    }
    if den > 0.0 {
        num.iter_mut().for_each(|x| *x /= den);
    }
    num
}
