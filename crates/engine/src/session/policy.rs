//! The session's timing: a [`Clock`], the [`PreviewPlan`] of a reduced frame, and the frame
//! budget kept by feedback from measured frame times.
//!
//! Westover's successive refinement (1991, §4.2.3) shows a coarse image at once and refines it
//! while the user waits; here the coarse image is sized so that it takes one frame interval on
//! this machine, whatever the machine: the preview's cost is measured after every frame and the
//! next preview's pixel count is corrected by the ratio of the budget to the measured time
//! (a multiplicative controller in the logarithm of the cost, with a dead band so the size does
//! not flicker).

use crate::request::{AntialiasChoice, Mode, RenderRequest, VolumeLevel};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// A monotonic clock: time since some fixed start. The session reads it for rest delays and
/// stale-preview limits; tests give it a [`ManualClock`].
pub trait Clock: Send + Sync {
    /// Time since the clock's start.
    fn now(&self) -> Duration;
}

/// The system's monotonic clock ([`Instant`]), counted from its creation.
#[derive(Debug, Clone, Copy)]
pub struct SystemClock {
    start: Instant,
}

impl SystemClock {
    /// A clock starting now.
    pub fn new() -> Self {
        SystemClock {
            start: Instant::now(),
        }
    }
}

impl Default for SystemClock {
    fn default() -> Self {
        SystemClock::new()
    }
}

impl Clock for SystemClock {
    fn now(&self) -> Duration {
        self.start.elapsed()
    }
}

/// A clock that moves only when told to ([`ManualClock::advance`]): for tests of a front end's
/// policy without sleeping.
#[derive(Debug, Default)]
pub struct ManualClock {
    now: Mutex<Duration>,
}

impl ManualClock {
    /// A clock at zero.
    pub fn new() -> Self {
        ManualClock::default()
    }

    /// Moves the clock forward by `ms` milliseconds.
    pub fn advance(&self, ms: f64) {
        let mut now = self.now.lock().unwrap_or_else(|e| e.into_inner());
        *now += Duration::from_secs_f64(ms.max(0.0) / 1e3);
    }
}

impl Clock for ManualClock {
    fn now(&self) -> Duration {
        *self.now.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// How a session paces its frames. Times in milliseconds.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct SessionSettings {
    /// Frames per second to keep while input arrives (default 60, the rate at which a
    /// browser sends pointer events): the frame budget is `1000 / target_fps` ms of render
    /// and encoding. Frames slower than the events come back to back and keep every core
    /// busy, so that encoding, transport and the page wait for the renderer (decision 0029;
    /// the measurements against 30 are in docs/BENCHMARKS.md §22).
    pub target_fps: f64,
    /// Share of the frame interval previews aim at (default 0.8), leaving the rest for
    /// transport and jitter.
    pub headroom: f64,
    /// Input-to-frame latency to keep while dragging, ms (default 50). Input arrives at any
    /// moment of the render in flight, waits for it, then for its own frame: the latency is
    /// about `T + U(0, T)` plus transport for frames of `T` ms, 1.95 T at the 95th
    /// percentile; previews aim at `T ≤ latency / 2.5`, which leaves a fifth of it for
    /// encoding, transport, decoding and a busy machine.
    pub target_latency_ms: f64,
    /// After a continuous event (a drag step, a wheel step) with no pointer held, wait this long
    /// for more before refining (default 120 ms). Discrete events (a button) refine at once.
    pub rest_delay_ms: f64,
    /// Smallest preview scale of the image's side (default 1/8); below it previews take thicker
    /// slabs instead.
    pub min_scale: f64,
    /// Slab thickness of previews smaller than half the view's side, in multiples of the final
    /// frame's (default 2; 1 keeps the final frame's): a small image still pays for every
    /// plane along the ray, so there the time is better spent on pixels (decision 0029
    /// measures the trade).
    pub preview_slab: f64,
    /// Thickest preview slab, in multiples of the final frame's (default 4).
    pub max_slab_factor: f64,
    /// A preview older than this many budgets is cancelled when newer input has arrived
    /// (default 3); younger previews finish, so a fast stream of input still sees frames.
    pub stale_preview_budgets: f64,
    /// Largest view, pixels per side, that [`Event::Resize`](super::Event::Resize) may ask
    /// for (default 4096).
    pub max_size: usize,
    /// Previews draw the prefiltered pyramid's level whose voxel is about a preview pixel
    /// ([`VolumeLevel::Auto`], decision 0031): their cost then falls faster than the pixel
    /// count, and previews keep the final frame's slabs. `false` (the default): the volume
    /// itself, one ray per pixel, with thicker slabs below half the side, whose previews
    /// measured closer to the final frame at equal frame rates (docs/BENCHMARKS.md §22,
    /// decision 0031): the level that `auto` picks is blurrier than the preview needs.
    pub pyramid_previews: bool,
}

impl Default for SessionSettings {
    fn default() -> Self {
        SessionSettings {
            target_fps: 60.0,
            headroom: 0.8,
            target_latency_ms: 50.0,
            rest_delay_ms: 120.0,
            min_scale: 0.125,
            preview_slab: 2.0,
            max_slab_factor: 4.0,
            stale_preview_budgets: 3.0,
            max_size: 4096,
            pyramid_previews: false,
        }
    }
}

impl SessionSettings {
    /// The frame budget, ms: one frame interval at [`SessionSettings::target_fps`].
    pub fn budget_ms(&self) -> f64 {
        1000.0 / self.target_fps
    }

    /// What a preview's render and encoding aim at, ms: the smaller of
    /// [`SessionSettings::headroom`] × the budget and [`SessionSettings::target_latency_ms`]
    /// / 2.5.
    pub fn aim_ms(&self) -> f64 {
        (self.headroom * self.budget_ms()).min(self.target_latency_ms / 2.5)
    }

    /// Checks the numbers; errors name the field.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |f: &str, m: String| Err(crate::EngineError::request(f, m));
        if !(self.target_fps.is_finite() && (0.1..=1000.0).contains(&self.target_fps)) {
            return bad(
                "target_fps",
                format!("must be in [0.1, 1000], got {}", self.target_fps),
            );
        }
        if !(self.target_latency_ms.is_finite() && self.target_latency_ms >= 1.0) {
            return bad(
                "target_latency_ms",
                format!("must be ≥ 1, got {}", self.target_latency_ms),
            );
        }
        if !(self.headroom > 0.0 && self.headroom <= 1.0) {
            return bad(
                "headroom",
                format!("must be in (0, 1], got {}", self.headroom),
            );
        }
        if !(self.rest_delay_ms.is_finite() && self.rest_delay_ms >= 0.0) {
            return bad(
                "rest_delay_ms",
                format!("must be ≥ 0, got {}", self.rest_delay_ms),
            );
        }
        if !(self.min_scale > 0.0 && self.min_scale <= 1.0) {
            return bad(
                "min_scale",
                format!("must be in (0, 1], got {}", self.min_scale),
            );
        }
        if !(self.max_slab_factor.is_finite() && (1.0..=16.0).contains(&self.max_slab_factor)) {
            return bad(
                "max_slab_factor",
                format!("must be in [1, 16], got {}", self.max_slab_factor),
            );
        }
        if !(self.preview_slab.is_finite()
            && self.preview_slab >= 1.0
            && self.preview_slab <= self.max_slab_factor)
        {
            return bad(
                "preview_slab",
                format!(
                    "must be in [1, max_slab_factor = {}], got {}",
                    self.max_slab_factor, self.preview_slab
                ),
            );
        }
        if !(self.stale_preview_budgets.is_finite() && self.stale_preview_budgets >= 1.0) {
            return bad(
                "stale_preview_budgets",
                format!("must be ≥ 1, got {}", self.stale_preview_budgets),
            );
        }
        if !(16..=16384).contains(&self.max_size) {
            return bad(
                "max_size",
                format!("must be in 16..=16384, got {}", self.max_size),
            );
        }
        Ok(())
    }
}

/// How a preview is reduced from the final frame: the knobs that trade picture for time.
///
/// The knobs are the image scale (fewer rays), one ray per pixel (`antialias: none`: no
/// averaging of sub-pixel rays where the view is minified), the level of the volume's
/// prefiltered pyramid (decision 0031: with [`SessionSettings::pyramid_previews`], the level
/// whose voxel is about a preview pixel, so that a smaller preview also takes fewer samples
/// along each ray) and, without the pyramid, thicker slabs (fewer samples along each ray).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreviewPlan {
    /// Height of the preview over the height of the final frame, in (0, 1] (the width follows
    /// the aspect ratio).
    pub scale: f64,
    /// Preview width and height, pixels.
    pub size: (usize, usize),
    /// Slab thickness over the final frame's (≥ 1).
    pub slab_factor: f64,
    /// Anti-aliasing of the preview (`none`: one ray per pixel).
    pub antialias: AntialiasChoice,
    /// Which level of the prefiltered pyramid the preview draws ([`VolumeLevel::Auto`]: the
    /// level whose voxel is about a preview pixel; [`VolumeLevel::Full`]: the volume itself).
    pub level: VolumeLevel,
}

impl PreviewPlan {
    /// The request of this preview of `full`: its size, anti-aliasing and slab thickness.
    pub fn request(&self, full: &RenderRequest) -> RenderRequest {
        let mut r = full.clone();
        (r.width, r.height) = self.size;
        r.quality.antialias = self.antialias;
        r.quality.level = self.level;
        if self.slab_factor > 1.0 {
            let base = full.quality.slab.unwrap_or_else(|| default_slab_of(full));
            r.quality.slab = Some((base * self.slab_factor).clamp(0.01, 16.0));
        }
        r
    }
}

/// The slab thickness the renderer picks for `request` when none is given (decisions 0017,
/// 0019, 0036): 1 voxel for composite (unshaded, or lit at the voxels or at the samples), ½
/// for MIP and MinIP; a preview only scales it.
fn default_slab_of(request: &RenderRequest) -> f64 {
    match request.mode {
        Mode::Composite => volsplat_splat::slab::DEFAULT_SLAB_COMPOSITE,
        _ => volsplat_splat::slab::DEFAULT_SLAB,
    }
}

/// The preview's cost, in units of a full-size, full-thickness frame without anti-aliasing:
/// `scale² / slab_factor`. Costs run down to `min_scale²` with pyramid previews (whose cost
/// falls faster than the pixel count: the feedback absorbs it) and to
/// `min_scale² / max_slab_factor` without.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Budget {
    /// The next preview's cost share.
    cost: f64,
    /// Measured time of the final frame at the current size, ms (EWMA), if one was rendered.
    final_ms: Option<f64>,
}

/// Steps of the preview scale: the side is a multiple of 1/32 of the final frame's.
const SCALE_STEPS: f64 = 32.0;

/// Measured-to-aimed time ratios inside this band leave the preview's cost as it is.
const DEAD_BAND: (f64, f64) = (0.85, 1.15);

/// The largest change of the preview's cost after one frame (a factor either way).
const MAX_STEP: f64 = 2.0;

/// Exponent of the correction: less than 1 damps the loop against noisy frame times.
const GAIN: f64 = 0.75;

/// Weight of the newest final-frame time in its running average.
const FINAL_WEIGHT: f64 = 0.5;

impl Budget {
    /// A first guess: a quarter of the side, until a frame is measured.
    pub(crate) fn new() -> Self {
        Budget {
            cost: 1.0 / 16.0,
            final_ms: None,
        }
    }

    /// The measured final-frame time, ms, if any.
    pub(crate) fn final_ms(&self) -> Option<f64> {
        self.final_ms
    }

    /// The current cost share of the next preview.
    #[cfg(test)]
    pub(crate) fn cost(&self) -> f64 {
        self.cost
    }

    /// A budget at cost share `cost` (tests of the plan).
    #[cfg(test)]
    pub(crate) fn with_cost(cost: f64) -> Self {
        Budget {
            cost,
            final_ms: None,
        }
    }

    /// A preview of cost share `cost` took `ms`: move the next cost towards `aim_ms`.
    pub(crate) fn preview_done(&mut self, cost: f64, ms: f64, aim_ms: f64, s: &SessionSettings) {
        if !(ms.is_finite() && ms > 0.0) {
            return;
        }
        let ratio = aim_ms / ms;
        if (DEAD_BAND.0..=DEAD_BAND.1).contains(&ratio) {
            return;
        }
        let step = ratio.clamp(1.0 / MAX_STEP, MAX_STEP).powf(GAIN);
        // Too fast: grow from the share kept if that is larger. The side moves in steps, so
        // the rendered plan's share can lie below the share kept; growing the rendered share
        // by a step that does not reach the next side would give the same plan for ever
        // (seen where the cost falls faster than the pixel count, as with pyramid previews).
        let base = if ratio > 1.0 {
            self.cost.max(cost)
        } else {
            cost
        };
        self.cost = (base * step)
            .clamp(cost / MAX_STEP, cost * MAX_STEP)
            .clamp(min_cost(s), 1.0);
    }

    /// A final frame took `ms`: remember it, and start previews, if they are not measured yet,
    /// at the share of it that fits `aim_ms`.
    pub(crate) fn final_done(&mut self, ms: f64, aim_ms: f64, s: &SessionSettings) {
        if !(ms.is_finite() && ms > 0.0) {
            return;
        }
        self.final_ms = Some(match self.final_ms {
            Some(old) => old + FINAL_WEIGHT * (ms - old),
            None => {
                self.cost = (aim_ms / ms).clamp(min_cost(s), 1.0);
                ms
            }
        });
    }

    /// The view's pixel count changed by `ratio`: a final frame's time scales with it.
    pub(crate) fn resized(&mut self, ratio: f64) {
        if let Some(ms) = &mut self.final_ms {
            *ms *= ratio;
        }
    }

    /// The plan of the next preview of a `width × height` frame. With pyramid previews: the
    /// side the cost share allows (down to [`SessionSettings::min_scale`]) at the level that
    /// fits it. Without: at least half the side with
    /// the final frame's slabs; below, [`SessionSettings::preview_slab`]-thick slabs and the
    /// side that the cost share then allows (down to [`SessionSettings::min_scale`]); below
    /// that, thicker slabs still (up to [`SessionSettings::max_slab_factor`]).
    pub(crate) fn plan(&self, width: usize, height: usize, s: &SessionSettings) -> PreviewPlan {
        let (min_scale, c) = (s.min_scale, self.cost);
        let (scale, slab_factor) = if s.pyramid_previews {
            // A coarser level thins the samples along the ray as it thins the pixels: the
            // side alone follows the budget.
            (c.sqrt(), 1.0)
        } else if c >= HALF_SIDE_COST {
            (c.sqrt(), 1.0)
        } else if c >= min_scale * min_scale / s.preview_slab {
            ((c * s.preview_slab).sqrt(), s.preview_slab)
        } else {
            let factor = (min_scale * min_scale / c).clamp(s.preview_slab, s.max_slab_factor);
            (min_scale, factor)
        };
        let scale = ((scale * SCALE_STEPS).floor() / SCALE_STEPS).clamp(min_scale, 1.0);
        // Keep the aspect ratio: the height sets the scale, the width follows it.
        let h = ((height as f64 * scale).round() as usize).clamp(1, height);
        let w = ((width as f64 * h as f64 / height as f64).round() as usize).clamp(1, width);
        PreviewPlan {
            scale: h as f64 / height as f64,
            size: (w, h),
            slab_factor,
            antialias: AntialiasChoice::None,
            level: if s.pyramid_previews {
                VolumeLevel::Auto
            } else {
                VolumeLevel::Full
            },
        }
    }
}

/// The cost share of a preview half the view's side with the final frame's slabs: below it,
/// previews take [`SessionSettings::preview_slab`]-thick slabs.
const HALF_SIDE_COST: f64 = 0.25;

/// The cost share of the smallest preview (thinnest-sampled without the pyramid).
fn min_cost(s: &SessionSettings) -> f64 {
    if s.pyramid_previews {
        // Previews keep the final frame's slabs: the smallest side is the floor.
        s.min_scale * s.min_scale
    } else {
        s.min_scale * s.min_scale / s.max_slab_factor
    }
}

/// The cost share of a plan: `scale² / slab_factor`.
pub(crate) fn plan_cost(plan: &PreviewPlan) -> f64 {
    plan.scale * plan.scale / plan.slab_factor
}
