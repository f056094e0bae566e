//! Volume display as filtering: Buchanan Chapter 6 (§6-0 … §6-5, App. B) — Sabella's display,
//! the linearised display evaluated directly and with NIL maps, Gaussian slices, the maximum,
//! sample-and-filter, and transfer-function changes without rebuilding the map.
//!
//! Every display evaluates, per pixel, a 3-D filter `F` against the density field `ρ`
//! ([`DisplayVolume`]: per-voxel densities, trilinear or sample-and-hold, zero outside the box of
//! voxel centres). The NIL machinery is the crate's [`crate::nil`] (pyramid, Fig 4.19 hierarchy,
//! corrected level weight `2^{3γ}`, `D` maps); this module only supplies what §6-5 says a new
//! display needs: **trigger placement** and **the filter weight at a point**.
//!
//! | [`DisplayKind`] | value per pixel (dimensionless, about `[0, 1]`) | source |
//! |---|---|---|
//! | `Sabella` | `τ·I`, `I = ∫ e^{−τ∫ρ} ρ dt` (eq 3.1), `n × n` rays per pixel; green = mean of the per-ray maximum density (Plate 6.1) | §6-1 |
//! | `Maximum` | maximum density along the ray, `n × n` rays per pixel | §6-3 |
//! | `Linearised` | default ([`Attenuation::OpticalDepth`]): `1 − e^{−τX}`, `X = ∭Fρ` with `F = G_screen` along the whole ray (Sabella's value, decision 0027); [`Attenuation::UnitDensity`]: `τ·∭Fρ` with `F = G_screen · e^{−τ(t−t_a)}`, `t ≥ t_a`, `∬G_screen = 1` (eq 3.3 = 6.1) | §6-1 |
//! | `Slice` | `∭Fρ/∭F`, `F = G_screen · G(t − t_c; w)` (thick `w = 0.1`, thin `0.01`) | §6-2 |
//! | `Search` | density at the point the ray search picks (Plate 6.10) | §6-3 |
//! | `SampleFilter` | `½ + gain · (ρ̄_{σ₁} − ρ̄_{σ₂})`, a difference of Gaussians at the searched point | §6-3 |
//!
//! `Linearised`, `Slice` and `SampleFilter` are evaluated either directly (composite
//! Gauss–Legendre along the filter's lines, [`Evaluator::Direct`]) or with a NIL map
//! ([`Evaluator::Nil`]).
//!
//! ## Units and frames
//! Lengths (`τ`'s inverse, slice width, DoG σ's, trigger steps) are in *unit lengths*: the
//! largest world extent of the volume ([`DisplayVolume::unit`]), since the thesis normalises its
//! volume to the unit cube (A-17 below). The screen filter is a Gaussian with standard
//! deviation `screen_sigma_px` pixels, truncated at 3σ, over screen area (divided by `σ(t)²`
//! under perspective). Rays come from [`volsplat_core::Projection::ray`] through pixel centres
//! `(x + ½, y + ½)`, so orthographic and perspective cameras both work. Images: row 0 at the top.
//!
//! ## Decisions (open points A-15 …; decisions 0007, 0027; `docs/nil-display/report.md`)
//! - **Sabella's attenuation by default** (decision 0027, [`Attenuation`]): eq 3.1's integrand is
//!   an exact derivative, so Sabella's display is `1 − e^{−τX}` of the line integral `X`, a
//!   linear filter the NIL map evaluates without linearising. eq 6.1's unit density from the
//!   box's entry was 19 dB from Sabella's display on a 197×233×189 MRI.
//! - **Continuous patches** (decision 0027, [`NilDisplaySettings::continuous`]): the cells'
//!   projections of the data are averaged at shared nodes, so the tube of a pixel sees no jump
//!   at a cell face (no seams); crossed cells are at most
//!   [`NilDisplaySettings::max_cell_width`] filter widths wide; display values are clamped at
//!   zero.
//! - **Control points by projection** (decision 0007, [`ControlPoints::Project`], default): a
//!   patch's control points are the L² projection of the filter onto the patch space, not the
//!   filter's values at the Lagrange nodes (App. B). The thesis's rule misses a filter narrower
//!   than the cells, and its normalisation (eq 4.16) collapses: on the MRI at 160×120 it fell
//!   back on 60–99 % of the rays. With projection `Σ b·B̄` is the filter's exact integral over
//!   the cell, nothing collapses, and the error against direct quadrature falls strictly with
//!   patch order, tolerance and trigger density (test
//!   `nil_error_falls_with_order_tolerance_and_triggers`). The thesis's rule stays available
//!   ([`ControlPoints::Interpolate`]) for comparison.
//! - **One filter, two evaluators**: every filter is a set of straight lines through its
//!   cross-section (`quadrature.cross_nodes` per axis over `±3σ`) with a profile along them;
//!   each line is clipped to the box of voxel centres (eq 4.2: zero density outside) on its own.
//!   The direct evaluation integrates the data along those lines; the NIL evaluation integrates
//!   the patch basis along them (the projection moments). Their difference is the patch
//!   approximation alone, and on a constant volume they agree to rounding at every pixel.
//! - **Normalisation of eq 6.1** (A-17): the display is `τ` times eq 3.3 with a unit screen
//!   filter, so a constant density `ρ` over a length `L` shows `ρ(1 − e^{−τL})`. Every display
//!   value is `∭Fρ / K` with `K = ∭F` of the whole, unmasked filter (`1/τ` along the ray for
//!   the linearised display). Interpolated control points give the normalised average of
//!   eq 4.15, which is multiplied by `∭F_box / K` (the masked filter's share).
//! - **Sabella (A-18)**: eq 3.1 as written (plus the max channel). Its integrand is
//!   `d/dt(−e^{−τ∫ρ}/τ)`, so `τ·I = 1 − e^{−τ∫ρ}` exactly; the march is nevertheless written as
//!   the thesis's ray marcher (256 samples, 4×4 rays), exact for piecewise-constant density.
//! - **Outside the volume** (eq 4.2): every filter is masked to the box of voxel centres; the
//!   periodic texture behind the NIL map is padded by repeating the edge voxels
//!   ([`volume::PAD`]), so that a patch straddling a face sees no artificial ramp to zero.
//! - **Hierarchy root**: the smallest cell enclosing the triggers *and* the end points of the
//!   filter's clipped lines, so the hierarchy covers the whole masked filter (Fig 4.19 encloses
//!   the triggers only, which cut off the ends of the ray).
//! - **Triggers (A-15)**: Table 6.1's column is read as *trigger slices per unit length*
//!   (`trigger_steps`), with `trigger_width²` points per slice across `±2σ`; a hierarchy with
//!   `S` slices per unit length approximates the volume at about `S³` cells, matching the
//!   thesis's "levels of approximation 2³ … 16³".
//! - **Scale collapse (A-4)**, interpolated control points only: a collapsed NIL sum falls
//!   back to point-sampling the filter at the trigger points; such pixels are counted
//!   ([`DisplayStats::fallbacks`]) and flagged ([`DisplayImage::fallback`]).
//! - **DoG**: a zero-mean filter cannot be normalised (eq 4.16's denominator vanishes), so the
//!   difference of Gaussians is evaluated as the difference of two Gaussian averages on one
//!   hierarchy (σ's and the gain are not in the thesis; defaults `0.01, 0.02` unit lengths and
//!   gain 8).
//! - **Search**: the thesis takes the sample *closest* to `ρ₀`; the default here is the first
//!   crossing of `ρ₀` (linearly interpolated), the closest sample is [`SearchRule::Closest`].
//! - **Transfer functions** (§4-4.3, eq 4.24): a NIL map with a transfer basis stores `D` cells;
//!   per pixel the `N` channel averages are kept ([`TransferCache`]), so a new transfer
//!   function is `N` multiply-adds per pixel, without rebuilding the map or the hierarchies.

mod continuous;
pub mod filter;
mod project;
mod render;
pub mod volume;

pub use volume::DisplayVolume;

use crate::error::{FilterError, Result};
use crate::nil::{DiscreteNilMap, DiscreteNilSettings, TransferBasis};
use volsplat_core::{Camera, Image, Rgba};

/// Which Chapter 6 display to draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DisplayKind {
    /// Sabella's density-emitter model (eq 3.1, Plates 6.1, 6.2).
    Sabella,
    /// Maximum density along the ray (§6-3).
    Maximum,
    /// The linearised display (eq 3.3 = 6.1; Plates 6.3–6.6).
    Linearised,
    /// A Gaussian slice at a depth (§6-2; Plates 6.8, 6.9).
    Slice,
    /// The density found by the ray search (Plate 6.10).
    Search,
    /// Search for `ρ₀`, then a difference-of-Gaussians filter there (Plates 6.11–6.14).
    SampleFilter,
}

/// How filter integrals are evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Evaluator {
    /// Composite Gauss–Legendre quadrature (the reference).
    Direct,
    /// NIL maps (§4-4, §6).
    Nil,
}

/// Ray search for the sample-and-filter display (§6-3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SearchRule {
    /// First crossing of `ρ₀` along the ray, linearly interpolated between samples.
    FirstCrossing,
    /// The sample whose density is closest to `ρ₀` (the thesis's rule; first on ties).
    Closest,
}

/// How the NIL control points of a patch are chosen (decision 0007).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ControlPoints {
    /// L² projection of the filter onto the patch space (default): the denominator of eq 4.15
    /// is the filter's exact integral over the cell, so it never collapses, and the error falls
    /// with patch order and cell size.
    Project,
    /// The thesis's rule (App. B): the filter's values at the Lagrange nodes, then the
    /// normalised eq 4.15 average. Collapses when the filter is narrower than the cells.
    Interpolate,
}

/// NIL parameters of a display (thesis §4-4.8, App. B).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NilDisplaySettings {
    /// Control-point rule.
    pub control: ControlPoints,
    /// Subdivision tolerance: cells with at most this many triggers are not split.
    pub tolerance: usize,
    /// Triggers per axis across the ray (`width²` per slice; `width³` for slices and DoG).
    pub trigger_width: usize,
    /// Trigger slices per unit length along the ray (linearised display).
    pub trigger_steps: f64,
    /// Lowest level `γ_min` (negative: sub-voxel cells computed on demand).
    pub gamma_min: i32,
    /// Scale-factor guard (decision A-4 of the texture crate).
    pub guard: f64,
    /// Support refinement (decision 0007): cells without triggers that the filter crosses are
    /// split down to the coarsest level holding triggers. Off reproduces Fig 4.19 as printed,
    /// whose trigger-less cells next to a ray stay large and blur its fringe.
    pub refine_support: bool,
    /// Continuous patches (decision 0027; projected control points, `M ≥ 2`): the data's
    /// per-cell projections are averaged at the nodes that cells of one level share, so the
    /// approximated density has no jumps at cell faces and the image no seams along projected
    /// cell boundaries. For the tube filters (linearised display, slices); the balls of the
    /// sample-and-filter display keep each cell's own fit (a difference of Gaussians measures
    /// edges, which the shared values blur). Off: each cell's own projection (decision 0007 as
    /// first written).
    pub continuous: bool,
    /// Largest cell a filter crosses, in multiples of the filter's narrowest cross-section
    /// (`6σ`: the screen Gaussian's or the ball's truncated width; decision 0027): crossed
    /// cells wider than that are split, like the support refinement, whatever their triggers.
    /// A patch much wider than the filter cannot follow it, and the tube then samples a fit
    /// of the data over the whole cell (blur, and seams along cell faces). `0`: no cap (the
    /// trigger hierarchy alone, Fig 4.19).
    pub max_cell_width: f64,
}

impl Default for NilDisplaySettings {
    fn default() -> Self {
        NilDisplaySettings {
            control: ControlPoints::Project,
            tolerance: 2,
            trigger_width: 1,
            trigger_steps: 32.0,
            gamma_min: -1,
            guard: 1e-3,
            refine_support: true,
            continuous: true,
            max_cell_width: 1.5,
        }
    }
}

/// How the linearised display ([`DisplayKind::Linearised`]) attenuates light along the ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Attenuation {
    /// Sabella's own attenuation `e^{−τ∫ρ}` (eq 3.1), without linearisation (default,
    /// decision 0027): the emission density is the absorption density, so the integrand of
    /// eq 3.1 is `d/dt(−e^{−τ∫ρ}/τ)` and `τI = 1 − e^{−τX}` with `X = ∫ρ dt` along the ray. The
    /// display evaluates the linear filter `X = ∬G ∫ρ dt` (screen Gaussian × line integral)
    /// with NIL maps or quadrature and shows `1 − e^{−τX}`: Sabella's display up to the screen
    /// filter (a Gaussian before the exponential instead of Sabella's `n × n` rays after it).
    OpticalDepth,
    /// eq 3.3 = 6.1 as printed: attenuation `e^{−τ(t − t_a)}` from the ray's entry into the
    /// volume's box, i.e. unit density everywhere (the thesis's linearisation, Plates 6.3–6.6).
    /// Far darker than Sabella's display where the box holds empty space or low densities
    /// (decision 0027 measures it).
    UnitDensity,
}

/// Direct-evaluation parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadratureSettings {
    /// Panel length along the ray (and the DoG cube), in units of the smallest grid spacing.
    pub step: f64,
    /// Gauss–Legendre nodes per axis across the ray over `±3σ` (a multiple of 4): the filter's
    /// cross-section lines, shared by the direct evaluation and the NIL control points, so that
    /// their difference is the patch approximation alone. Default 4 (16 lines; decision 0027
    /// compares it with 8 per axis).
    pub cross_nodes: usize,
}

impl Default for QuadratureSettings {
    fn default() -> Self {
        QuadratureSettings {
            step: 0.5,
            cross_nodes: 4,
        }
    }
}

/// Settings of a display render.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplaySettings {
    /// The display.
    pub kind: DisplayKind,
    /// Direct or NIL evaluation (linearised, slice, sample-and-filter).
    pub evaluator: Evaluator,
    /// Attenuation `τ` per unit length (thesis: 3).
    pub tau: f64,
    /// Attenuation model of the linearised display.
    pub attenuation: Attenuation,
    /// Screen Gaussian standard deviation, pixels.
    pub screen_sigma_px: f64,
    /// Rays per pixel per axis for Sabella and the maximum (thesis: 4, i.e. 16 rays).
    pub supersample: usize,
    /// Samples per ray for Sabella, the maximum and the search (thesis: 256).
    pub samples_per_ray: usize,
    /// Slice depth in `[0, 1]`: 0 the nearest corner of the volume, 1 the farthest (depth along
    /// the direction of projection).
    pub slice_depth: f64,
    /// Slice standard deviation along the ray, unit lengths (thick 0.1, thin 0.01).
    pub slice_width: f64,
    /// Search density `ρ₀` (thesis: 0.14, 0.18).
    pub rho0: f64,
    /// Search rule.
    pub search: SearchRule,
    /// DoG standard deviations `[σ₁, σ₂]`, unit lengths, `σ₁ < σ₂`.
    pub dog_sigma: [f64; 2],
    /// DoG display gain: value `= ½ + gain·response`, clamped to `[0, 1]`.
    pub dog_gain: f64,
    /// NIL parameters.
    pub nil: NilDisplaySettings,
    /// Direct-evaluation parameters.
    pub quadrature: QuadratureSettings,
    /// Transfer coefficients `b_l` for a NIL map with a transfer basis (eq 4.24).
    pub transfer: Option<Vec<f64>>,
}

impl Default for DisplaySettings {
    fn default() -> Self {
        DisplaySettings {
            kind: DisplayKind::Linearised,
            evaluator: Evaluator::Nil,
            tau: 3.0,
            attenuation: Attenuation::OpticalDepth,
            screen_sigma_px: 0.5,
            supersample: 4,
            samples_per_ray: 256,
            slice_depth: 0.5,
            slice_width: 0.1,
            rho0: 0.18,
            search: SearchRule::FirstCrossing,
            dog_sigma: [0.01, 0.02],
            dog_gain: 8.0,
            nil: NilDisplaySettings::default(),
            quadrature: QuadratureSettings::default(),
            transfer: None,
        }
    }
}

fn check(field: &str, ok: bool, value: impl std::fmt::Debug, reason: &str) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(FilterError::invalid(field, value, reason))
    }
}

impl DisplaySettings {
    /// The linearised display as the thesis defines it, which were the defaults before decision
    /// 0027: eq 6.1's unit-density attenuation ([`Attenuation::UnitDensity`]), each NIL cell's
    /// own fit (no continuous patches), no cap on the crossed cells' width, and 8 × 8 lines
    /// across the screen filter; everything else as [`DisplaySettings::default`]. The plates of
    /// `volsplat display-bench` use it, and the tests that measure what decision 0027 changed.
    pub fn thesis() -> Self {
        let d = DisplaySettings::default();
        DisplaySettings {
            attenuation: Attenuation::UnitDensity,
            nil: NilDisplaySettings {
                continuous: false,
                max_cell_width: 0.0,
                ..d.nil
            },
            quadrature: QuadratureSettings {
                cross_nodes: 8,
                ..d.quadrature
            },
            ..d
        }
    }

    /// Validates every parameter.
    pub fn validate(&self) -> Result<()> {
        let fin = |x: f64| x.is_finite();
        check(
            "tau",
            fin(self.tau) && self.tau > 0.0 && self.tau <= 1e4,
            self.tau,
            "must be in (0, 1e4]",
        )?;
        check(
            "screen_sigma_px",
            fin(self.screen_sigma_px) && self.screen_sigma_px > 0.0 && self.screen_sigma_px <= 64.0,
            self.screen_sigma_px,
            "must be in (0, 64]",
        )?;
        check(
            "supersample",
            (1..=16).contains(&self.supersample),
            self.supersample,
            "must be in 1..=16",
        )?;
        check(
            "samples_per_ray",
            (2..=65536).contains(&self.samples_per_ray),
            self.samples_per_ray,
            "must be in 2..=65536",
        )?;
        check(
            "slice_depth",
            fin(self.slice_depth) && (0.0..=1.0).contains(&self.slice_depth),
            self.slice_depth,
            "must be in [0, 1]",
        )?;
        check(
            "slice_width",
            fin(self.slice_width) && self.slice_width > 1e-6 && self.slice_width <= 10.0,
            self.slice_width,
            "must be in (1e-6, 10] unit lengths",
        )?;
        check("rho0", fin(self.rho0), self.rho0, "must be finite")?;
        let [s1, s2] = self.dog_sigma;
        check(
            "dog_sigma",
            fin(s1) && fin(s2) && s1 > 1e-6 && s1 < s2 && s2 <= 1.0,
            self.dog_sigma,
            "needs 1e-6 < σ1 < σ2 ≤ 1 unit length",
        )?;
        check(
            "dog_gain",
            fin(self.dog_gain),
            self.dog_gain,
            "must be finite",
        )?;
        let n = &self.nil;
        check(
            "trigger_width",
            (1..=16).contains(&n.trigger_width),
            n.trigger_width,
            "must be in 1..=16",
        )?;
        check(
            "trigger_steps",
            fin(n.trigger_steps) && n.trigger_steps > 0.0 && n.trigger_steps <= 4096.0,
            n.trigger_steps,
            "must be in (0, 4096] per unit length",
        )?;
        check(
            "trigger count",
            (n.trigger_width * n.trigger_width) as f64 * n.trigger_steps <= 65536.0,
            (n.trigger_width, n.trigger_steps),
            "trigger_width² × trigger_steps must be at most 65536",
        )?;
        check(
            "tolerance",
            n.tolerance <= 1 << 20,
            n.tolerance,
            "must be at most 2^20",
        )?;
        check(
            "gamma_min",
            (-8..=20).contains(&n.gamma_min),
            n.gamma_min,
            "must be in -8..=20",
        )?;
        check(
            "max_cell_width",
            fin(n.max_cell_width) && (0.0..=1e6).contains(&n.max_cell_width),
            n.max_cell_width,
            "must be in [0, 1e6] filter widths (0: no cap)",
        )?;
        check(
            "guard",
            fin(n.guard) && (0.0..1.0).contains(&n.guard),
            n.guard,
            "must be in [0, 1)",
        )?;
        let q = &self.quadrature;
        check(
            "quadrature step",
            fin(q.step) && q.step >= 0.01 && q.step <= 64.0,
            q.step,
            "must be in [0.01, 64] grid spacings",
        )?;
        check(
            "cross_nodes",
            q.cross_nodes.is_multiple_of(4) && (4..=64).contains(&q.cross_nodes),
            q.cross_nodes,
            "must be a multiple of 4 in 4..=64",
        )?;
        if let Some(b) = &self.transfer {
            check(
                "transfer coefficients",
                !b.is_empty() && b.len() <= 4 && b.iter().all(|x| x.is_finite()),
                b,
                "need 1..=4 finite values",
            )?;
        }
        Ok(())
    }
}

/// Timings (seconds, summed over all threads) and counters of one display render — the
/// analogue of Table 6.2's breakdown (map construction is timed by the caller:
/// [`DiscreteNilMap::build_seconds`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DisplayStats {
    /// Trigger placement.
    pub trigger_s: f64,
    /// Patch selection: enclosing cell and Fig 4.19 subdivision.
    pub hierarchy_s: f64,
    /// NIL control points: the filter's lines, their moments and the projection (decision
    /// 0007); with interpolated control points only the line set-up (the node values are then
    /// part of `evaluation_s`).
    pub control_s: f64,
    /// Evaluation: patch integration `Σ b·C` (NIL) or quadrature (direct).
    pub evaluation_s: f64,
    /// Ray search (sample-and-filter).
    pub search_s: f64,
    /// Ray marching (Sabella, maximum).
    pub march_s: f64,
    /// Wall-clock time of the whole render.
    pub total_s: f64,
    /// Pixels.
    pub pixels: u64,
    /// Rays that hit the volume.
    pub rays: u64,
    /// Trigger points placed.
    pub triggers: u64,
    /// NIL patches (hierarchy cells) used.
    pub patches: u64,
    /// NIL evaluations whose scale factor collapsed (fell back to point sampling).
    pub fallbacks: u64,
}

impl DisplayStats {
    fn add(&mut self, o: &DisplayStats) {
        self.trigger_s += o.trigger_s;
        self.hierarchy_s += o.hierarchy_s;
        self.control_s += o.control_s;
        self.evaluation_s += o.evaluation_s;
        self.search_s += o.search_s;
        self.march_s += o.march_s;
        self.rays += o.rays;
        self.triggers += o.triggers;
        self.patches += o.patches;
        self.fallbacks += o.fallbacks;
    }
}

/// Per-pixel NIL channel averages kept for transfer-function changes (eq 4.24, §6-4): the
/// display value of coefficients `b` is `max(0, scale · Σ_l b_l · channel_l)`, or with
/// Sabella's attenuation `1 − e^{−τ·max(0, scale · Σ_l b_l · channel_l)}`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferCache {
    /// Channels per pixel `N`.
    pub channels: usize,
    /// `Some(τ)` (per world unit) when the channels are line integrals to be shown as
    /// `1 − e^{−τX}` ([`Attenuation::OpticalDepth`]); `None` when they are shown as they are.
    pub tau: Option<f64>,
    /// Per-pixel scale (1 for the linearised display and slices).
    pub scale: Vec<f64>,
    /// Channel averages, pixel-major (`N` per pixel).
    pub values: Vec<f64>,
}

impl TransferCache {
    /// The display for transfer coefficients `b` (`N` values) without re-evaluating anything.
    pub fn apply(&self, b: &[f64]) -> Result<Vec<f32>> {
        if b.len() != self.channels || b.iter().any(|x| !x.is_finite()) {
            return Err(FilterError::invalid(
                "transfer coefficients",
                b,
                format!("need {} finite values", self.channels),
            ));
        }
        Ok(self
            .scale
            .iter()
            .zip(self.values.chunks_exact(self.channels))
            .map(|(s, c)| {
                let v = (s * c.iter().zip(b).map(|(x, y)| x * y).sum::<f64>()).max(0.0);
                match self.tau {
                    Some(tau) => (1.0 - (-tau * v).exp()) as f32,
                    None => v as f32,
                }
            })
            .collect())
    }
}

/// A rendered display.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Display value per pixel (row 0 at the top), dimensionless (see [`DisplayKind`]).
    pub value: Vec<f32>,
    /// Sabella only: mean maximum density per pixel (the thesis's green channel).
    pub green: Option<Vec<f32>>,
    /// NIL linearised/slice renders: channel averages for transfer-function changes.
    pub cache: Option<TransferCache>,
    /// NIL renders: per pixel (row 0 at the top), whether a NIL evaluation fell back to
    /// point-sampling (see [`DisplayStats::fallbacks`]); empty for other renders.
    pub fallback: Vec<bool>,
    /// Timings and counters.
    pub stats: DisplayStats,
}

impl DisplayImage {
    /// An opaque premultiplied RGBA image: grey `value`, or for Sabella the thesis's colouring
    /// (red = intensity, green = maximum density) unless `grey`.
    pub fn to_image(&self, grey: bool) -> Image {
        let px: Vec<Rgba> = self
            .value
            .iter()
            .enumerate()
            .map(|(i, &v)| match (&self.green, grey) {
                (Some(g), false) => [v, g[i], 0.0, 1.0],
                _ => [v, v, v, 1.0],
            })
            .collect();
        Image::from_pixels(self.width, self.height, px)
            .unwrap_or_else(|| Image::new(self.width, self.height))
    }
}

/// Builds the NIL map of a display volume: patch order `m` (1 = constant … 4 = cubic), an
/// optional transfer basis (then the volume's densities are the transfer function's input),
/// and a cap on stored values (errors with [`FilterError::TooLarge`] above it).
pub fn build_map(
    vol: &DisplayVolume,
    m: usize,
    transfer: Option<TransferBasis>,
    max_values: usize,
) -> Result<DiscreteNilMap> {
    DiscreteNilMap::build(
        vol.texture(),
        &DiscreteNilSettings {
            order: m,
            gamma_max: None,
            transfer,
            max_values,
        },
    )
}

/// Renders a display of `vol` seen by `camera` at `width × height` pixels. `map` is required
/// for NIL evaluation of the linearised, slice and sample-and-filter displays and must have
/// been built from `vol` ([`build_map`]). Rows run in parallel (rayon); every pixel is computed
/// independently, so the image is the same for any thread count.
pub fn render_display(
    vol: &DisplayVolume,
    map: Option<&DiscreteNilMap>,
    camera: &Camera,
    width: usize,
    height: usize,
    settings: &DisplaySettings,
) -> Result<DisplayImage> {
    render::render(vol, map, camera, width, height, settings, &mut |_| true)
}

/// Like [`render_display`], calling `progress` with the fraction of rows done (in `(0, 1]`)
/// about twenty times; returning `false` cancels with [`FilterError::Cancelled`]. The image does
/// not depend on the callback.
pub fn render_display_with_progress(
    vol: &DisplayVolume,
    map: Option<&DiscreteNilMap>,
    camera: &Camera,
    width: usize,
    height: usize,
    settings: &DisplaySettings,
    progress: &mut dyn FnMut(f64) -> bool,
) -> Result<DisplayImage> {
    render::render(vol, map, camera, width, height, settings, progress)
}
