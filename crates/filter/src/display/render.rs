//! The per-pixel loop of the Chapter 6 displays (Buchanan App. B) for both evaluators.

use super::continuous::{NodeGrids, integrate_continuous};
use super::filter::{PixelFilter, Sigma, TRUNC, composite_nodes, direct, triggers};
use super::project::{LineFilter, Projector, integrate_cells};
use super::volume::{DisplayVolume, PixelRay, Rays};
use super::{
    Attenuation, ControlPoints, DisplayImage, DisplayKind, DisplaySettings, DisplayStats,
    Evaluator, SearchRule, TransferCache,
};
use crate::error::{FilterError, Result};
use crate::nil::Cell;
use crate::nil::{
    DiscreteNilMap, LevelWeighting, NilSource, enclosing_cell, evaluate_cells,
    find_hierarchy_counted,
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
    /// Points the hierarchy root must enclose: triggers and the filters' line end points.
    bound: Vec<DVec3>,
    cells: Vec<Cell>,
    /// Hierarchy cells with their trigger counts.
    counted: Vec<(Cell, usize)>,
    moments: Vec<f64>,
    lines: Vec<LineFilter>,
    /// Control points per cell (projection).
    bs: Vec<Option<[f64; 64]>>,
    /// Cross-section nodes of the NIL line quadrature.
    cross: Vec<(f64, f64)>,
    /// A cell's raw moments (continuous patches, decision 0027).
    raw: Vec<f64>,
}

struct Pixel {
    fell_back: bool,
    value: f32,
    green: f32,
    scale: f64,
    channels: [f64; 4],
}

/// The checked inputs of one render: whether it evaluates by NIL maps, the NIL map's channel
/// count (1 without a transfer basis) and the transfer coefficients `b_l` the channels are
/// summed with (`[1]` for one channel, §4-4.3).
struct Inputs {
    uses_nil: bool,
    channels: usize,
    coeffs: Vec<f64>,
}

/// Checks the settings, the image size and that `map` fits `vol` and `s`: a NIL display needs
/// a map of this volume, a map with a transfer basis needs as many coefficients as functions
/// and cannot serve sample-and-filter.
fn check_inputs(
    vol: &DisplayVolume,
    map: Option<&DiscreteNilMap>,
    width: usize,
    height: usize,
    s: &DisplaySettings,
) -> Result<Inputs> {
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
    Ok(Inputs {
        uses_nil,
        channels,
        coeffs,
    })
}

/// What every pixel of one render shares: the volume, map and settings, the camera's rays and
/// the quantities derived from the settings once per render.
struct PixelKernel<'a> {
    vol: &'a DisplayVolume,
    map: Option<&'a DiscreteNilMap>,
    s: &'a DisplaySettings,
    proj: Projection,
    rays: Rays,
    /// The volume's unit length (world units per unit of the thesis's unit cube).
    unit: f64,
    /// `τ` per world unit.
    tau: f64,
    /// Sabella's attenuation: the linearised display's value is `1 − e^{−τX}` of the line
    /// integral `X` (`Attenuation::OpticalDepth`); `None` for the other displays.
    optical_tau: Option<f64>,
    /// Step of direct quadrature along a ray, world units.
    step: f64,
    /// Cross-section nodes of the screen filter's quadrature.
    cross: Vec<(f64, f64)>,
    projector: Option<&'a Projector>,
    /// Continuous patches (decision 0027): shared node values per level, built on first use.
    grids: Option<NodeGrids<'a>>,
    /// Screen depth of the slice plane (`DisplayKind::Slice`), raster units.
    slice_depths: f64,
    coeffs: Vec<f64>,
}

impl<'a> PixelKernel<'a> {
    /// The per-render quantities of `s` for `camera` at `width × height`; `projector` is the
    /// map's projection operator (borrowed by the continuous patches' node grids).
    fn new(
        vol: &'a DisplayVolume,
        map: Option<&'a DiscreteNilMap>,
        projector: Option<&'a Projector>,
        camera: &Camera,
        (width, height): (usize, usize),
        s: &'a DisplaySettings,
        coeffs: Vec<f64>,
    ) -> Result<Self> {
        let proj = Projection::new(camera, width, height)?;
        let rays = Rays { proj };
        let unit = vol.unit();
        let tau = s.tau / unit;
        let optical_tau = (s.kind == DisplayKind::Linearised
            && s.attenuation == Attenuation::OpticalDepth)
            .then_some(tau);
        let step = s.quadrature.step * vol.min_spacing();
        let cross = composite_nodes(-TRUNC, TRUNC, s.quadrature.cross_nodes / 4, 4);
        let grids = match (map, projector) {
            (Some(m), Some(p)) if s.nil.continuous && s.nil.control == ControlPoints::Project => {
                let exact0 = m.transfer().is_none()
                    && m.texture().reconstruction() == crate::texture::Reconstruction::Trilinear;
                Some(NodeGrids::new(
                    m,
                    p,
                    vol.dims().map(|n| (n - 1) as f64),
                    exact0,
                ))
            }
            _ => None,
        };
        let slice_depths = slice_depth(vol, &proj, s.slice_depth);
        Ok(PixelKernel {
            vol,
            map,
            s,
            proj,
            rays,
            unit,
            tau,
            optical_tau,
            step,
            cross,
            projector,
            grids,
            slice_depths,
            coeffs,
        })
    }

    /// The screen filter's scale along `ray`: constant in an orthographic view, growing with
    /// the distance in a perspective one.
    fn sigma_of(&self, ray: &PixelRay) -> Sigma {
        let s = self.s;
        match self.proj {
            Projection::Ortho(_) => Sigma {
                a: s.screen_sigma_px * self.rays.pixel_size(ray, 1.0),
                b: 0.0,
            },
            Projection::Perspective(_) => Sigma {
                a: 0.0,
                b: s.screen_sigma_px * self.proj.pixel_size_at(1.0) * ray.cos,
            },
        }
    }

    /// Fills the scratch's cross-section nodes on first use.
    fn prepare(&self, sc: &mut Scratch) {
        if sc.cross.is_empty() {
            sc.cross.clone_from(&self.cross);
        }
    }

    /// Pixel `(x, y)` of the display, its stats added to `st`.
    fn pixel(&self, x: usize, y: usize, sc: &mut Scratch, st: &mut DisplayStats) -> Pixel {
        let fallbacks_before = st.fallbacks;
        let mut px = Pixel {
            fell_back: false,
            value: 0.0,
            green: 0.0,
            scale: 0.0,
            channels: [0.0; 4],
        };
        let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
        match self.s.kind {
            DisplayKind::Sabella | DisplayKind::Maximum => self.marched(x, y, st, &mut px),
            DisplayKind::Linearised | DisplayKind::Slice => {
                if !self.filtered(cx, cy, sc, st, &mut px) {
                    return px;
                }
            }
            DisplayKind::Search | DisplayKind::SampleFilter => {
                if !self.searched(cx, cy, sc, st, &mut px) {
                    return px;
                }
            }
        }
        px.fell_back = st.fallbacks != fallbacks_before;
        px
    }

    /// Sabella's display and the maximum (§6-1, eq 3.1): `supersample²` rays through pixel
    /// `(x, y)`, each marched by [`sabella_ray`], averaged.
    fn marched(&self, x: usize, y: usize, st: &mut DisplayStats, px: &mut Pixel) {
        let (s, tau) = (self.s, self.tau);
        let t0 = Instant::now();
        let n = s.supersample;
        let (mut inten, mut mx) = (0.0, 0.0);
        for sy in 0..n {
            for sx in 0..n {
                let fx = x as f64 + (sx as f64 + 0.5) / n as f64;
                let fy = y as f64 + (sy as f64 + 0.5) / n as f64;
                if let Some(ray) = self.rays.ray(self.vol, fx, fy) {
                    st.rays += 1;
                    let (i, m) = sabella_ray(self.vol, &ray, tau, s.samples_per_ray);
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

    /// The linearised display (eq 6.1) and slices (§6-2) at the pixel centre `(cx, cy)`: the
    /// pixel's tube filter evaluated by NIL maps or direct quadrature, its channels summed with
    /// the transfer coefficients. `false` if the ray misses the volume (the pixel stays blank).
    fn filtered(
        &self,
        cx: f64,
        cy: f64,
        sc: &mut Scratch,
        st: &mut DisplayStats,
        px: &mut Pixel,
    ) -> bool {
        let (vol, s) = (self.vol, self.s);
        let Some(ray) = self.rays.ray(vol, cx, cy) else {
            return false;
        };
        st.rays += 1;
        let sigma = self.sigma_of(&ray);
        let (filter, scale) = if s.kind == DisplayKind::Linearised {
            match s.attenuation {
                Attenuation::UnitDensity => (
                    PixelFilter::Linearised {
                        ray,
                        sigma,
                        tau: self.tau,
                    },
                    1.0,
                ),
                Attenuation::OpticalDepth => (PixelFilter::LineIntegral { ray, sigma }, 1.0),
            }
        } else {
            let tc = self.slice_depths / ray.cos.max(1e-12);
            (
                PixelFilter::Slice {
                    ray,
                    sigma,
                    tc,
                    w: s.slice_width * self.unit,
                },
                1.0,
            )
        };
        let ch = match (s.evaluator, self.map, self.projector) {
            (Evaluator::Nil, Some(map), Some(proj)) => {
                self.prepare(sc);
                nil_eval(
                    vol,
                    map,
                    proj,
                    self.grids.as_ref(),
                    &filter,
                    &[&filter],
                    s,
                    sc,
                    st,
                )
                .pop()
                .unwrap_or_default()
            }
            _ => {
                let t0 = Instant::now();
                let v = direct(vol, &filter, self.step, &self.cross);
                st.evaluation_s += t0.elapsed().as_secs_f64();
                v.map_or_else(Vec::new, |v| vec![v])
            }
        };
        px.scale = scale;
        for (o, c) in px.channels.iter_mut().zip(&ch) {
            *o = *c;
        }
        // A density is never negative, nor is a display of one: the clamp catches what
        // a patch of order M ≥ 3 (or discontinuous patches) can still overshoot.
        let v = (scale * ch.iter().zip(&self.coeffs).map(|(c, b)| c * b).sum::<f64>()).max(0.0);
        px.value = match self.optical_tau {
            Some(tau) => 1.0 - (-tau * v).exp(),
            None => v,
        } as f32;
        px.green = px.value;
        true
    }

    /// Search and sample-and-filter (§6-3) at the pixel centre `(cx, cy)`: the density where
    /// the ray meets `ρ₀`, or the difference of Gaussians there (NIL or direct). `false` if the
    /// ray misses the volume or never meets `ρ₀` (the pixel stays blank).
    fn searched(
        &self,
        cx: f64,
        cy: f64,
        sc: &mut Scratch,
        st: &mut DisplayStats,
        px: &mut Pixel,
    ) -> bool {
        let (vol, s) = (self.vol, self.s);
        let Some(ray) = self.rays.ray(vol, cx, cy) else {
            return false;
        };
        st.rays += 1;
        let t0 = Instant::now();
        let hit = search(vol, &ray, s.rho0, s.search, s.samples_per_ray);
        st.search_s += t0.elapsed().as_secs_f64();
        let Some(t) = hit else {
            return false;
        };
        let c = ray.o + ray.d * t;
        if s.kind == DisplayKind::Search {
            px.value = vol.density(c) as f32;
        } else {
            let f1 = PixelFilter::Ball {
                c,
                s: s.dog_sigma[0] * self.unit,
            };
            let f2 = PixelFilter::Ball {
                c,
                s: s.dog_sigma[1] * self.unit,
            };
            let (a, b) = match (s.evaluator, self.map, self.projector) {
                (Evaluator::Nil, Some(map), Some(proj)) => {
                    self.prepare(sc);
                    let r = nil_eval(
                        vol,
                        map,
                        proj,
                        self.grids.as_ref(),
                        &f2,
                        &[&f1, &f2],
                        s,
                        sc,
                        st,
                    );
                    let g = |i: usize| r.get(i).and_then(|c| c.first()).copied();
                    (g(0), g(1))
                }
                _ => {
                    let t0 = Instant::now();
                    let a = direct(vol, &f1, self.step, &self.cross);
                    let b = direct(vol, &f2, self.step, &self.cross);
                    st.evaluation_s += t0.elapsed().as_secs_f64();
                    (a, b)
                }
            };
            let resp = a.unwrap_or(0.0) - b.unwrap_or(0.0);
            px.scale = resp;
            px.value = (0.5 + s.dog_gain * resp).clamp(0.0, 1.0) as f32;
        }
        px.green = px.value;
        true
    }
}

/// Raster depth of the slice plane: `fraction` of the way from the nearest to the farthest
/// corner of the volume's box of voxel centres.
fn slice_depth(vol: &DisplayVolume, proj: &Projection, fraction: f64) -> f64 {
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
    lo + fraction * (hi - lo)
}

/// The Chapter 6 display of `vol` seen by `camera` at `width × height` (App. B): checks the
/// inputs, computes every pixel ([`PixelKernel::pixel`]) in parallel row blocks that report to
/// `progress`, and gathers the image, the NIL fallbacks, the transfer cache and the stats.
pub(crate) fn render(
    vol: &DisplayVolume,
    map: Option<&DiscreteNilMap>,
    camera: &Camera,
    width: usize,
    height: usize,
    s: &DisplaySettings,
    progress: &mut dyn FnMut(f64) -> bool,
) -> Result<DisplayImage> {
    let start = Instant::now();
    let Inputs {
        uses_nil,
        channels,
        coeffs,
    } = check_inputs(vol, map, width, height, s)?;
    let projector = map.map(|m| Projector::new(*m.basis()));
    let kernel = PixelKernel::new(
        vol,
        map,
        projector.as_ref(),
        camera,
        (width, height),
        s,
        coeffs,
    )?;
    let rows = render_rows(&kernel, width, height, progress)?;
    let keep_channels = uses_nil && s.kind != DisplayKind::SampleFilter;
    let cache = TransferCache {
        channels,
        tau: kernel.optical_tau,
        scale: Vec::new(),
        values: Vec::new(),
    };
    let mut image = gather(
        rows,
        width,
        height,
        s,
        uses_nil,
        keep_channels.then_some(cache),
    );
    image.stats.total_s = start.elapsed().as_secs_f64();
    Ok(image)
}

/// Every pixel's value and the stats of each row, rows in blocks so that `progress` hears from
/// the render about 20 times; every pixel is computed independently, so the blocks change
/// nothing in the image.
fn render_rows(
    kernel: &PixelKernel<'_>,
    width: usize,
    height: usize,
    progress: &mut dyn FnMut(f64) -> bool,
) -> Result<Vec<(Vec<Pixel>, DisplayStats)>> {
    let block = (height / 20).max(4 * rayon::current_num_threads()).max(1);
    let mut rows: Vec<(Vec<Pixel>, DisplayStats)> = Vec::with_capacity(height);
    for y0 in (0..height).step_by(block) {
        let y1 = (y0 + block).min(height);
        rows.par_extend((y0..y1).into_par_iter().map(|y| {
            let mut sc = Scratch::default();
            let mut st = DisplayStats::default();
            let row = (0..width)
                .map(|x| kernel.pixel(x, y, &mut sc, &mut st))
                .collect();
            (row, st)
        }));
        if !progress(y1 as f64 / height as f64) {
            return Err(FilterError::Cancelled);
        }
    }
    Ok(rows)
}

/// The display image of the rendered rows: values (and Sabella's maximum as `green`), the
/// fallback flags of a NIL display, the channels into `cache` where it is kept (§6-4), the
/// stats summed in row order (`total_s` left for the caller).
fn gather(
    rows: Vec<(Vec<Pixel>, DisplayStats)>,
    width: usize,
    height: usize,
    s: &DisplaySettings,
    uses_nil: bool,
    mut cache: Option<TransferCache>,
) -> DisplayImage {
    let mut stats = DisplayStats::default();
    let n = width * height;
    let mut value = Vec::with_capacity(n);
    let mut green = Vec::with_capacity(n);
    let mut fallback = Vec::with_capacity(if uses_nil { n } else { 0 });
    if let Some(c) = &mut cache {
        c.scale.reserve_exact(n);
        c.values.reserve_exact(n * c.channels);
    }
    for (row, st) in rows {
        stats.add(&st);
        for p in row {
            value.push(p.value);
            green.push(p.green);
            if uses_nil {
                fallback.push(p.fell_back);
            }
            if let Some(c) = &mut cache {
                c.scale.push(p.scale);
                c.values.extend_from_slice(&p.channels[..c.channels]);
            }
        }
    }
    stats.pixels = n as u64;
    DisplayImage {
        width,
        height,
        value,
        green: (s.kind == DisplayKind::Sabella).then_some(green),
        cache,
        fallback,
        stats,
    }
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

/// NIL evaluation of several filters on one hierarchy (App. B steps 3–7). The hierarchy comes
/// from the triggers of `shape` (Fig 4.19) under a root that encloses the triggers and every
/// filter's masked support. Control points by projection (decision 0007: `Σ_cells Σ b·C / K`)
/// or, as the thesis, by interpolation (the normalised eq 4.15 average times `∭F_box / K`,
/// falling back to point-sampling at the triggers when its scale collapses, decision A-4).
/// Returns per filter the channel values `∭ F ρ_l / ∭ F` (the filter's full integral `K`).
#[allow(clippy::too_many_arguments)] // the two functions §6-5 swaps, plus buffers
fn nil_eval(
    vol: &DisplayVolume,
    map: &DiscreteNilMap,
    proj: &Projector,
    grids: Option<&NodeGrids<'_>>,
    shape: &PixelFilter,
    filters: &[&PixelFilter],
    s: &DisplaySettings,
    sc: &mut Scratch,
    st: &mut DisplayStats,
) -> Vec<Vec<f64>> {
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
    sc.lines.resize_with(filters.len(), LineFilter::default);
    sc.bound.clear();
    sc.bound.extend_from_slice(&sc.triggers);
    for (lf, f) in sc.lines.iter_mut().zip(filters) {
        lf.set(vol, f, &sc.cross);
        lf.endpoints(&mut sc.bound);
    }
    let t2 = Instant::now();
    st.control_s += (t2 - t1).as_secs_f64();
    let root = hierarchy(vol, map, filters, s, sc);
    let t3 = Instant::now();
    st.hierarchy_s += (t3 - t2).as_secs_f64();
    st.patches += sc.cells.len() as u64;
    let channels = map.channels();
    let mut out = Vec::with_capacity(filters.len());
    for (lf, f) in sc.lines.iter().zip(filters) {
        let mut num = vec![0.0; channels];
        if root.is_none() || lf.k_box <= 0.0 {
            out.push(num);
            continue;
        }
        match s.nil.control {
            ControlPoints::Project => {
                let tc = Instant::now();
                // Continuous patches need the filter's moments, discontinuous ones its control
                // points (`b = G⁻¹ m`); constant patches (M = 1) share no nodes.
                // Balls (the difference of Gaussians) keep each cell's own fit: they measure
                // the data's edges, which the shared node values blur (decision 0027).
                let tube = !matches!(shape, PixelFilter::Ball { .. });
                let continuous = grids.filter(|_| tube && map.basis().order() > 1);
                sc.bs.clear();
                for cell in &sc.cells {
                    let mut b = [0.0; 64];
                    let hit = if continuous.is_some() {
                        proj.moments(lf, cell, &mut b)
                    } else {
                        proj.control_points(lf, cell, &mut b)
                    };
                    sc.bs.push(hit.then_some(b));
                }
                let ti = Instant::now();
                st.control_s += (ti - tc).as_secs_f64();
                let ok = if let Some(g) = continuous {
                    integrate_continuous(g, &sc.cells, &sc.bs, &mut sc.raw, &mut num)
                } else {
                    integrate_cells(map, &sc.cells, &sc.bs, &mut sc.moments, &mut num)
                };
                if !ok {
                    st.fallbacks += 1;
                    num = point_sampled(vol, map, &sc.triggers, &|p| LineFilter::masked(vol, f, p));
                    num.iter_mut().for_each(|x| *x *= lf.k_box);
                }
                num.iter_mut().for_each(|x| *x /= lf.k_full);
                st.evaluation_s += ti.elapsed().as_secs_f64();
            }
            ControlPoints::Interpolate => {
                let ti = Instant::now();
                let w = |p: DVec3| LineFilter::masked(vol, f, p);
                let r = evaluate_cells(
                    map,
                    &sc.cells,
                    &w,
                    LevelWeighting::CellVolume,
                    s.nil.guard,
                    &mut sc.moments,
                );
                num = match r {
                    Some(r) => r.channels,
                    None => {
                        st.fallbacks += 1;
                        point_sampled(vol, map, &sc.triggers, &w)
                    }
                };
                let k = lf.k_box / lf.k_full;
                num.iter_mut().for_each(|x| *x *= k);
                st.evaluation_s += ti.elapsed().as_secs_f64();
            }
        }
        out.push(num);
    }
    out
}

/// The cells of one NIL evaluation into `sc.cells`: Fig 4.19's hierarchy of `sc.triggers` under
/// the smallest cell enclosing `sc.bound`, with the support refinement (decision 0007) and the
/// size cap (decision 0027). Returns the root (`None`: no cell within `γ_max` encloses them).
fn hierarchy(
    vol: &DisplayVolume,
    map: &DiscreteNilMap,
    filters: &[&PixelFilter],
    s: &DisplaySettings,
    sc: &mut Scratch,
) -> Option<Cell> {
    sc.cells.clear();
    sc.counted.clear();
    let root = enclosing_cell(&sc.bound, s.nil.gamma_min, map.gamma_max())?;
    find_hierarchy_counted(
        &sc.triggers,
        root,
        s.nil.tolerance,
        s.nil.gamma_min,
        &mut sc.counted,
    );
    // Support refinement (decision 0007): a cell without triggers that the filter crosses
    // is split down to the coarsest level that holds triggers; split parts the filter
    // does not cross are dropped (they carry no weight).
    let g_ref = sc
        .counted
        .iter()
        .filter(|c| c.1 > 0)
        .map(|c| c.0.gamma)
        .max();
    // Size cap (decision 0027): no crossed cell wider than `max_cell_width` times the
    // narrowest filter's cross-section (index units along the coarsest axis), and none
    // finer than a voxel for the cap's sake: a cell of level ≤ 0 lies in one voxel cell,
    // where the data is already in the patch space.
    let cap = (s.nil.max_cell_width > 0.0).then(|| {
        let w = filters
            .iter()
            .map(|f| f.min_width())
            .fold(f64::INFINITY, f64::min);
        let side = s.nil.max_cell_width * w / vol.max_spacing();
        (side.log2().floor() as i32).max(0).max(s.nil.gamma_min)
    });
    for &(cell, n) in &sc.counted {
        let mut target = cell.gamma;
        if let Some(g) = g_ref
            && s.nil.refine_support
            && n == 0
        {
            target = target.min(g);
        }
        if let Some(c) = cap {
            target = target.min(c);
        }
        if target < cell.gamma {
            refine(cell, target, &sc.lines, &mut sc.cells);
        } else {
            sc.cells.push(cell);
        }
    }
    Some(root)
}

/// Splits `cell` into its descendants of level `g` that a filter line crosses.
fn refine(cell: Cell, g: i32, lines: &[LineFilter], out: &mut Vec<Cell>) {
    if !lines.iter().any(|l| l.hits(&cell)) {
        return;
    }
    if cell.gamma <= g {
        out.push(cell);
        return;
    }
    for c in 0..8i64 {
        let child = Cell {
            gamma: cell.gamma - 1,
            index: [
                2 * cell.index[0] + (c & 1),
                2 * cell.index[1] + ((c >> 1) & 1),
                2 * cell.index[2] + (c >> 2),
            ],
        };
        refine(child, g, lines, out);
    }
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
