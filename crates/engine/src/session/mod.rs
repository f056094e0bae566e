//! A progressive rendering session: input events in, frames out, for any front end (the web
//! viewer, a native window, a notebook).
//!
//! A [`Session`] holds the scene as a [`RenderRequest`] whose camera is explicit, applies
//! [`Event`]s to it (each checked first; a refused event changes nothing), and decides what to
//! render next ([`Session::next_job`]):
//!
//! - while input arrives, **previews** sized to a frame budget measured on this machine
//!   ([`PreviewPlan`]: a smaller image with one ray per pixel, thicker slabs when even the
//!   smallest image is too slow; a coarser volume level once the renderer has a pyramid),
//!   shown upscaled by the front end;
//! - at rest (pointer released, or no continuous input for
//!   [`SessionSettings::rest_delay_ms`]), the **final** frame: exactly
//!   [`Renderer::render`] of [`Session::request`], so it is bit for bit what
//!   `volsplat render --scene` draws from the saved request ([`Session::save`]).
//!
//! Every event that changes the scene bumps a generation counter; the progress callback of a
//! job ([`Session::keep_going`]) cancels a final frame as soon as the generation moves on, and a
//! preview once it is also older than a few budgets, so input never queues behind a render.
//! Measured frame times come back through [`Session::finished`] and size the next preview.
//!
//! A front end's loop:
//!
//! ```
//! use volsplat::session::{Event, JobOutcome, Session, SessionSettings, SystemClock};
//! use volsplat::{PhantomKind, RenderRequest, Renderer, Scene, VolumeSource};
//! use std::sync::Arc;
//!
//! let mut scene = Scene::default();
//! scene.volume = VolumeSource::Phantom { phantom: PhantomKind::Blobs, grid: Some(vec![24]) };
//! let mut renderer = Renderer::new();
//! let clock = Arc::new(SystemClock::new());
//! let request = RenderRequest::new(scene, 64, 64);
//! let mut session =
//!     Session::start(request, &mut renderer, SessionSettings::default(), clock).unwrap();
//! session.apply(Event::Interaction { active: true }).unwrap();
//! session.apply(Event::Orbit { dx: 10.0, dy: 0.0 }).unwrap();
//! let job = session.next_job().unwrap();
//! assert!(!job.is_final()); // a preview while the pointer is held
//! let out = session.run(&job, &mut renderer).unwrap();
//! session.finished(&job, JobOutcome::Rendered { ms: out.stats.total_ms });
//! session.apply(Event::Interaction { active: false }).unwrap();
//! let job = session.next_job().unwrap();
//! assert!(job.is_final()); // released: the full-quality frame
//! ```

mod event;
mod policy;
#[cfg(test)]
mod tests;

pub use event::{Event, MAX_DRAG_PX, ZOOM_FACTOR_RANGE};
pub use policy::{Clock, ManualClock, PreviewPlan, SessionSettings, SystemClock};

use crate::error::{EngineError, Result};
use crate::renderer::{Output, Progress, Renderer};
use crate::request::RenderRequest;
use crate::scene::CameraSpec;
use policy::{Budget, plan_cost};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use volsplat_core::{Camera, Grid, Orbit};

/// What a job renders.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JobKind {
    /// A reduced frame sized to the budget.
    Preview(PreviewPlan),
    /// The full-quality frame: [`Session::request`] exactly.
    Final,
}

/// One frame to render: the request and what it stands for.
#[derive(Debug, Clone)]
pub struct Job {
    /// Increasing number of the job within its session.
    pub id: u64,
    /// The scene generation it shows (see [`Session::generation`]).
    pub generation: u64,
    /// Preview or final.
    pub kind: JobKind,
    /// What to render; its `output` options (grey window, background, PNG encoding) are the
    /// ones its frame is shown and written with.
    pub request: RenderRequest,
    /// When the job was handed out, on the session's clock.
    pub started: Duration,
}

impl Job {
    /// Whether this is the full-quality frame.
    pub fn is_final(&self) -> bool {
        self.kind == JobKind::Final
    }
}

/// What became of a job ([`Session::finished`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JobOutcome {
    /// Its frame was rendered and handed to the user in `ms` milliseconds (render and
    /// encoding: the cost the budget is about).
    Rendered {
        /// Milliseconds.
        ms: f64,
    },
    /// It was cancelled (the scene moved on): nothing was shown.
    Cancelled,
    /// It failed (the front end reports the error): a failed final frame is not tried again
    /// until the scene changes.
    Failed,
}

/// The last frame shown (or settled) and its generation.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Delivered {
    generation: u64,
    is_final: bool,
}

/// A progressive rendering session (see the module docs).
pub struct Session {
    request: RenderRequest,
    home: Camera,
    grid: Grid,
    settings: SessionSettings,
    clock: Arc<dyn Clock>,
    generation: Arc<AtomicU64>,
    /// Bumped at every release of the pointer: a preview in flight then gives way to the final
    /// frame.
    releases: Arc<AtomicU64>,
    /// Set at a release after a drag: the screen shows a recent preview, so the final frame
    /// comes next even if no preview of the very latest scene was shown.
    refine_at_once: bool,
    interacting: bool,
    /// Clock time from which the session counts as at rest (no pointer held).
    rest_at: Duration,
    delivered: Option<Delivered>,
    /// The last request a frame of its own generation rendered from: where a refused render
    /// returns the scene to.
    rendered: Option<RenderRequest>,
    in_flight: Option<u64>,
    budget: Budget,
    next_id: u64,
}

impl std::fmt::Debug for Session {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("generation", &self.generation())
            .field("interacting", &self.interacting)
            .field("delivered", &self.delivered)
            .finish_non_exhaustive()
    }
}

impl Session {
    /// A session on `request`: loads its volume through `renderer` (kept there for the frames
    /// to come; a store read out of core: its metadata only) to resolve the camera, which becomes explicit and is the one
    /// [`Event::Reset`] returns to.
    pub fn start(
        request: RenderRequest,
        renderer: &mut Renderer,
        settings: SessionSettings,
        clock: Arc<dyn Clock>,
    ) -> Result<Session> {
        request.validate()?;
        let (grid, _) = renderer.volume_grid(&request)?;
        let camera = renderer.camera(&request)?;
        Session::new(request, camera, grid, settings, clock)
    }

    /// A session on `request` whose camera resolves to `camera` on a volume of `grid` (what
    /// [`Session::start`] finds by loading the volume).
    pub fn new(
        mut request: RenderRequest,
        camera: Camera,
        grid: Grid,
        settings: SessionSettings,
        clock: Arc<dyn Clock>,
    ) -> Result<Session> {
        settings.validate()?;
        camera.validate()?;
        request.scene.camera = explicit(camera.clone());
        request.validate()?;
        request.scene.clipping.world_planes(&grid)?;
        let now = clock.now();
        Ok(Session {
            request,
            home: camera,
            grid,
            settings,
            clock,
            generation: Arc::new(AtomicU64::new(1)),
            releases: Arc::new(AtomicU64::new(0)),
            refine_at_once: false,
            interacting: false,
            rest_at: now,
            delivered: None,
            rendered: None,
            in_flight: None,
            budget: Budget::new(),
            next_id: 1,
        })
    }

    /// The grid of the session's volume (world frame, mm): the full level's, also for a store
    /// read out of core.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The full-quality request of the current scene (camera explicit): what the final frame
    /// renders and [`Session::save`] writes, with the output options (grey window, background,
    /// PNG encoding) its frames are shown and written with.
    pub fn request(&self) -> &RenderRequest {
        &self.request
    }

    /// The current camera (world units).
    pub fn camera(&self) -> &Camera {
        match &self.request.scene.camera {
            CameraSpec::Explicit { camera, .. } => camera,
            // `new` and every event keep the camera explicit.
            CameraSpec::Orbit(_) => &self.home,
        }
    }

    /// The session's settings.
    pub fn settings(&self) -> &SessionSettings {
        &self.settings
    }

    /// The scene's generation: bumped by every event that changes what is seen.
    pub fn generation(&self) -> u64 {
        self.generation.load(Ordering::Acquire)
    }

    /// Whether a drag is in progress ([`Event::Interaction`]).
    pub fn interacting(&self) -> bool {
        self.interacting
    }

    /// The measured time of a final frame at the current size, ms, once one was rendered.
    pub fn final_ms(&self) -> Option<f64> {
        self.budget.final_ms()
    }

    /// Writes the current request as a scene file (`volsplat render --scene FILE` renders it
    /// bit for bit as the final frame).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        self.request.save(path)
    }

    /// Applies one event. A refused event (a number out of range, a transfer function or crop
    /// box that does not check, a degenerate camera) is an error naming the field and changes
    /// nothing.
    pub fn apply(&mut self, event: Event) -> Result<()> {
        let continuous = event.is_continuous();
        if let Event::Interaction { active } = event {
            if self.interacting && !active {
                self.releases.fetch_add(1, Ordering::AcqRel);
                self.refine_at_once = true;
            }
            self.interacting = active;
            if !active {
                self.rest_at = self.clock.now();
            }
            return Ok(());
        }
        let mut next = self.request.clone();
        self.change(&mut next, event)?;
        next.validate()?;
        next.scene.clipping.world_planes(&self.grid)?;
        if next.width * next.height != self.request.width * self.request.height {
            let ratio = (next.width * next.height) as f64
                / (self.request.width * self.request.height) as f64;
            self.budget.resized(ratio);
        }
        if next != self.request {
            self.request = next;
            self.touch(continuous);
        }
        Ok(())
    }

    /// A new generation: the current frame is out of date.
    fn touch(&mut self, continuous: bool) {
        self.generation.fetch_add(1, Ordering::AcqRel);
        if !self.interacting {
            // A change made without a drag (a button, a wheel step) shows a preview first.
            self.refine_at_once = false;
        }
        let now = self.clock.now();
        self.rest_at = if continuous && !self.interacting {
            now + Duration::from_secs_f64(self.settings.rest_delay_ms / 1e3)
        } else {
            now
        };
    }

    /// `event` applied to a copy of the request.
    fn change(&self, next: &mut RenderRequest, event: Event) -> Result<()> {
        let (w, h) = (next.width, next.height);
        let mut camera = self.camera().clone();
        match event {
            Event::Orbit { dx, dy } => {
                check_drag(dx, dy)?;
                event::orbit(&mut camera, dx, dy, w, h);
            }
            Event::Pan { dx, dy } => {
                check_drag(dx, dy)?;
                event::pan(&mut camera, dx, dy, h);
            }
            Event::Zoom { factor } => {
                let (lo, hi) = ZOOM_FACTOR_RANGE;
                if !(factor.is_finite() && (lo..=hi).contains(&factor)) {
                    return Err(EngineError::request(
                        "zoom.factor",
                        format!("must be in [{lo}, {hi}], got {factor}"),
                    ));
                }
                event::zoom(&mut camera, factor);
            }
            Event::Roll { degrees } => {
                if !(degrees.is_finite() && degrees.abs() <= 3600.0) {
                    return Err(EngineError::request(
                        "roll.degrees",
                        format!("must be a finite angle within ±3600°, got {degrees}"),
                    ));
                }
                event::roll(&mut camera, degrees);
            }
            Event::SetView { view } => view.orient(&mut camera),
            Event::Reset {} => camera = self.home.clone(),
            Event::SetCamera { camera: c } => camera = c,
            Event::SetMode { mode } => {
                // A window made for MIP means nothing for X-ray's line integrals, and composite
                // takes none: dropped rather than refusing the mode.
                if !next.mode.shares_window_with(mode) {
                    next.output.window = None;
                }
                next.mode = mode;
            }
            Event::SetTransferFunction { transfer_function } => {
                if let crate::TransferSpec::Function(tf) = &transfer_function {
                    tf.clone().validate()?;
                }
                next.scene.transfer_function = transfer_function;
            }
            Event::SetWindow { window } => next.output.window = window,
            Event::SetCrop { crop } => next.scene.clipping.crop = crop,
            Event::SetClip { planes } => next.scene.clipping.planes = planes,
            Event::SetQuality { quality } => next.quality = quality,
            Event::Resize { width, height } => {
                let max = self.settings.max_size;
                if !(1..=max).contains(&width) || !(1..=max).contains(&height) {
                    return Err(EngineError::request(
                        "resize",
                        format!("width and height must be in 1..={max}, got {width}×{height}"),
                    ));
                }
                (next.width, next.height) = (width, height);
            }
            Event::Interaction { .. } => {}
        }
        camera.validate()?;
        next.scene.camera = explicit(camera);
        Ok(())
    }

    /// The next frame to render, or `None` when there is nothing to do now (the frame on
    /// screen is current, or the session waits for a rest; see [`Session::wake_at`]). At most
    /// one job is out at a time: until it is handed back with [`Session::finished`] this
    /// returns `None`.
    pub fn next_job(&mut self) -> Option<Job> {
        if self.in_flight.is_some() {
            return None;
        }
        let generation = self.generation();
        let now = self.clock.now();
        let delivered = self.delivered.filter(|d| d.generation == generation);
        if delivered.is_some_and(|d| d.is_final) {
            return None;
        }
        let resting = !self.interacting && now >= self.rest_at;
        let aim = self.aim_ms();
        let final_is_cheap = self.budget.final_ms().is_some_and(|ms| ms <= aim);
        let kind = if final_is_cheap || (resting && (delivered.is_some() || self.refine_at_once)) {
            JobKind::Final
        } else if delivered.is_none() {
            JobKind::Preview(self.plan())
        } else {
            // A preview of this generation is on screen; refine once at rest.
            return None;
        };
        let request = match &kind {
            JobKind::Final => self.request.clone(),
            JobKind::Preview(plan) => plan.request(&self.request),
        };
        let id = self.next_id;
        self.next_id += 1;
        self.in_flight = Some(id);
        Some(Job {
            id,
            generation,
            kind,
            request,
            started: now,
        })
    }

    /// When the session next has work without new input: the end of the rest delay after a
    /// preview of the current scene, on the session's clock. `None` when nothing waits.
    pub fn wake_at(&self) -> Option<Duration> {
        let generation = self.generation();
        let waiting = self
            .delivered
            .is_some_and(|d| d.generation == generation && !d.is_final);
        (waiting && !self.interacting && self.in_flight.is_none()).then_some(self.rest_at)
    }

    /// The plan of the next preview at the current size.
    pub fn plan(&self) -> PreviewPlan {
        self.budget
            .plan(self.request.width, self.request.height, &self.settings)
    }

    /// What previews aim at, ms ([`SessionSettings::aim_ms`]).
    fn aim_ms(&self) -> f64 {
        self.settings.aim_ms()
    }

    /// Hands a job back with what became of it. A rendered frame's measured time sizes the
    /// next preview, and the frame counts as shown for its generation; a failed final frame
    /// settles its generation (it is not tried again until the scene changes).
    ///
    /// Returns `true` when the scene went back: a job of the current scene failed (the
    /// renderer refused a combination of options that each checked alone, such as a
    /// perspective camera with a kernel only the orthographic sheets take, or ran out of
    /// memory) and an earlier scene of this session rendered, so the session returns to that
    /// one (a new generation) instead of failing on every later event. The front end then
    /// shows the restored state.
    pub fn finished(&mut self, job: &Job, outcome: JobOutcome) -> bool {
        if self.in_flight == Some(job.id) {
            self.in_flight = None;
        }
        let current = job.generation == self.generation();
        let aim = self.aim_ms();
        match (outcome, &job.kind) {
            (JobOutcome::Cancelled, _) => return false,
            (JobOutcome::Failed, _) if current => {
                if let Some(good) = self.rendered.clone().filter(|g| *g != self.request) {
                    self.request = good;
                    self.touch(false);
                    return true;
                }
            }
            (JobOutcome::Rendered { ms }, JobKind::Preview(plan)) => {
                self.budget
                    .preview_done(plan_cost(plan), ms, aim, &self.settings);
            }
            (JobOutcome::Rendered { ms }, JobKind::Final) => {
                if (job.request.width, job.request.height)
                    == (self.request.width, self.request.height)
                {
                    self.budget.final_done(ms, aim, &self.settings);
                }
            }
            (JobOutcome::Failed, _) => {}
        }
        if matches!(outcome, JobOutcome::Rendered { .. })
            && current
            && self.rendered.as_ref() != Some(&self.request)
        {
            self.rendered = Some(self.request.clone());
        }
        let newer = self
            .delivered
            .is_some_and(|d| d.generation > job.generation);
        if !newer {
            self.delivered = Some(Delivered {
                generation: job.generation,
                is_final: job.is_final(),
            });
        }
        false
    }

    /// The progress callback of `job`: `false` (cancel) once the scene has moved on — at once
    /// for a final frame, and for a preview once it has also run for
    /// [`SessionSettings::stale_preview_budgets`] budgets (a preview that is nearly done still
    /// shows the user something newer than the screen) — and for a preview when the pointer is
    /// released (the final frame follows at once and would wait for it).
    pub fn keep_going(&self, job: &Job) -> impl FnMut(&Progress) -> bool + Send + 'static {
        let generation = Arc::clone(&self.generation);
        let releases = Arc::clone(&self.releases);
        let released = self.releases.load(Ordering::Acquire);
        let clock = Arc::clone(&self.clock);
        let mine = job.generation;
        let preview = !job.is_final();
        let limit = match job.kind {
            JobKind::Final => Duration::ZERO,
            JobKind::Preview(_) => Duration::from_secs_f64(
                self.settings.budget_ms() * self.settings.stale_preview_budgets / 1e3,
            ),
        };
        let started = job.started;
        move |_| {
            if preview && releases.load(Ordering::Acquire) != released {
                return false;
            }
            generation.load(Ordering::Acquire) == mine
                || clock.now().saturating_sub(started) < limit
        }
    }

    /// Whether `job` still shows the current scene.
    pub fn is_current(&self, job: &Job) -> bool {
        job.generation == self.generation()
    }

    /// Renders `job` with `renderer`, cancelled as [`Session::keep_going`] says
    /// ([`EngineError::Cancelled`]). A final job is exactly `renderer.render(session.request())`.
    pub fn run(&self, job: &Job, renderer: &mut Renderer) -> Result<Output> {
        let mut go = self.keep_going(job);
        renderer.render(&job.request, &mut go)
    }
}

/// An explicit camera specification without view changes.
fn explicit(camera: Camera) -> CameraSpec {
    CameraSpec::Explicit {
        camera,
        orbit: Orbit::default(),
    }
}

fn check_drag(dx: f64, dy: f64) -> Result<()> {
    if !(dx.is_finite() && dy.is_finite() && dx.abs() <= MAX_DRAG_PX && dy.abs() <= MAX_DRAG_PX) {
        return Err(EngineError::request(
            "dx, dy",
            format!("a drag must be finite and within ±{MAX_DRAG_PX} pixels, got ({dx}, {dy})"),
        ));
    }
    Ok(())
}
