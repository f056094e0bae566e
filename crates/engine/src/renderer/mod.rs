//! The reusable [`Renderer`]: one entry point for every renderer, keeping what does not change
//! between frames.
//!
//! A render is a plan (`plan.rs`: which renderer draws the request, and how; a pure function
//! whose rules are the table of `docs/architecture.md`, "Which renderer draws a request"), then
//! one draw step per renderer (`draw.rs`), each keeping its state in the caches of `cache.rs`
//! and reporting [`Stats`] converted from its library's counters (`stats.rs`).

mod cache;
mod draw;
mod overview;
mod paged;
mod plan;
mod ranges_sidecar;
mod stats;
mod store_level;

pub use overview::OutOfCoreSummary;
pub use stats::{DisplayStats, Progress, SheetAxis, Stage, Stats, UsedRenderer, renderer_name};

use crate::error::{EngineError, Result};
use crate::request::{Mode, RenderRequest};
use crate::scene::{StoreLevel, VolumeSource};
use cache::{
    AutoTf, Cached, DisplayKey, ListKey, Loaded, TablesKey, build_pool, cached, resolve_tf,
};
use draw::{Drawn, Frame};
use plan::{Classification, Draw, Plan};
use std::sync::Arc;
use std::time::Instant;
use volsplat_core::{AnyVolume, Camera, CrioTables, Image, ScalarImage, TransferFunction};
use volsplat_splat::refine::RefinementStep;
use volsplat_splat::{BrickGrid, Pyramid, Rendered, SplatList};

/// The result of a render.
#[derive(Debug, Clone)]
pub struct Output {
    /// Premultiplied linear RGBA, row 0 at the top. MIP/MinIP: the projected value through the
    /// transfer function; X-ray: grey scaled so the brightest pixel is 1.
    pub image: Image,
    /// X-ray line integrals (data units × world units; of `max(v + o, 0)` where
    /// `Scene::xray_density` gives an offset `o`, for CT `1000 × μ/μ_water × world units`:
    /// [`crate::xray`]) or MIP/MinIP values (data units; NaN where no sample covers the
    /// pixel); `None` in composite mode.
    pub values: Option<ScalarImage>,
    /// Timings and counters.
    pub stats: Stats,
    /// The camera actually used (world units).
    pub camera: Camera,
    /// The transfer function actually used (data units).
    pub transfer_function: TransferFunction,
    /// Warnings for the user (for example an option the chosen renderer does not use).
    pub warnings: Vec<String>,
    /// Information from the volume reader (frames available, spacing assumed, …), given with
    /// the frame that loaded the volume.
    pub notes: Vec<String>,
}

impl Output {
    /// Whether the output's float values are X-ray line integrals.
    pub fn is_xray(&self, request: &RenderRequest) -> bool {
        request.mode == Mode::Xray && self.values.is_some()
    }
}

/// A render of one rung of the successive-refinement ladder (Westover §4.2.3).
pub struct Preview<'a> {
    /// Which rung, 0 first.
    pub index: usize,
    /// Subsampling stride of this rung.
    pub subsample: usize,
    /// Its image and values.
    pub rendered: &'a Rendered,
}

/// A preview callback of [`Renderer::render_refined`].
type OnPreview<'a> = &'a mut (dyn FnMut(&Preview) -> Result<bool> + Send);

/// The successive-refinement ladder of [`Renderer::render_refined`]: its rungs and the
/// callback that receives all but the last.
struct Ladder<'a> {
    steps: &'a [RefinementStep],
    on_preview: OnPreview<'a>,
}

/// Renders [`RenderRequest`]s, keeping between calls what the next frame can reuse: the loaded
/// volume (per volume source), the classification tables (per transfer function, lights and
/// shading), the splat list (per tables, threshold and subsampling), the Chapter 6 display
/// volume and NIL map, and the thread pool. A second frame that changes only the camera costs
/// only the frame itself.
///
/// ```
/// use volsplat::{PhantomKind, RenderRequest, Renderer, Scene, VolumeSource};
/// use volsplat::core::Orbit;
///
/// let mut scene = Scene::default();
/// scene.volume = VolumeSource::Phantom { phantom: PhantomKind::Blobs, grid: Some(vec![32]) };
/// scene.camera = volsplat::CameraSpec::Orbit(Orbit { azimuth: Some(30.0), ..Orbit::default() });
/// let request = RenderRequest::new(scene, 64, 48);
/// let mut renderer = Renderer::new();
/// let out = renderer.render(&request, &mut |_| true).unwrap();
/// assert_eq!((out.image.width(), out.image.height()), (64, 48));
/// assert!(out.image.pixels().iter().any(|p| p[3] > 0.1)); // the blobs are visible
/// assert_eq!(out.image.get(0, 0), [0.0; 4]); // the corner is not
/// println!("{}", serde_json::to_string(&out.stats).unwrap()); // timings in ms
/// ```
#[derive(Default)]
pub struct Renderer {
    volume: Option<Cached<VolumeSource, Loaded>>,
    tables: Option<Cached<TablesKey, Arc<CrioTables>>>,
    list: Option<Cached<ListKey, Arc<SplatList>>>,
    /// Min/max bricks of the volume (image-aligned slabs' empty-space skipping).
    bricks: Option<Cached<VolumeSource, Arc<BrickGrid>>>,
    /// The volume's resolution pyramid (previews, `quality.level`), its levels built on first
    /// use.
    pyramid: Option<Cached<VolumeSource, Arc<Pyramid>>>,
    display: Option<Cached<DisplayKey, Arc<cache::DisplayState>>>,
    pool: Option<Cached<Option<usize>, Arc<rayon::ThreadPool>>>,
    /// The automatic transfer function and its description, per volume.
    auto_tf: Option<Cached<VolumeSource, AutoTf>>,
    /// The volume's value range (a pass over every voxel), per volume: (lowest, highest).
    range: Option<Cached<VolumeSource, (f64, f64)>>,
    /// An OME-Zarr level read out of core: its brick cache and ranges, per store level and
    /// budget ([`RenderRequest::memory`]).
    paged: paged::PagedSlot,
    limits: volsplat_io::Limits,
}

impl Renderer {
    /// A renderer with nothing cached and the readers' default limits.
    pub fn new() -> Self {
        Renderer::default()
    }

    /// A renderer whose file reads obey `limits` (largest header, voxel count, JSON and XML
    /// sizes; [`volsplat_io::Limits`]) instead of the defaults.
    pub fn with_limits(limits: volsplat_io::Limits) -> Self {
        Renderer {
            limits,
            ..Renderer::default()
        }
    }

    /// The reader limits in force.
    pub fn limits(&self) -> &volsplat_io::Limits {
        &self.limits
    }

    /// The volume of `source`, loaded once and kept while the source stays the same.
    pub fn volume(&mut self, source: &VolumeSource) -> Result<Arc<AnyVolume>> {
        Ok(Arc::clone(&self.load(source)?.value.volume))
    }

    /// The cache slot of `source`'s volume, loading it where it holds another.
    fn load(&mut self, source: &VolumeSource) -> Result<cache::Fetched<'_, Loaded>> {
        let limits = &self.limits;
        cached(&mut self.volume, source.clone(), || {
            let (volume, notes) = source.load_with_limits(limits)?;
            Ok(Loaded { volume, notes })
        })
    }

    /// The value range of `source`'s volume `vol`, computed once per volume.
    fn range(&mut self, source: &VolumeSource, vol: &AnyVolume) -> Result<(f64, f64)> {
        Ok(*cached(&mut self.range, source.clone(), || Ok(vol.value_range()))?.value)
    }

    /// `request`'s volume source, with an OME-Zarr level `auto` ([`StoreLevel::Auto`]) made a
    /// level number, and a note saying which: the coarsest level whose smallest spacing is no
    /// larger than a pixel at the focal plane of the camera resolved against the store's full
    /// level (issue 31 item 5; metadata only, read again for each frame so that zooming in
    /// reads a finer level). Other sources as they are.
    fn concrete_source(&self, request: &RenderRequest) -> Result<(VolumeSource, Option<String>)> {
        let source = &request.scene.volume;
        let VolumeSource::File {
            path,
            raw: None,
            level: StoreLevel::Auto,
            ..
        } = source
        else {
            return Ok((source.clone(), None));
        };
        let store = volsplat_io::ZarrStore::open(path, &self.limits)?;
        let full = store.grid(0)?;
        let camera = request.scene.camera.resolve(full.drawn_bounds_world())?;
        let pixel = volsplat_splat::focal_pixel_size(&camera, request.width, request.height)?;
        let level = store.auto_level(pixel, 1.0);
        let mut concrete = source.clone();
        if let VolumeSource::File { level: l, .. } = &mut concrete {
            *l = StoreLevel::Index(level);
        }
        let spacing = store.levels()[level]
            .spacing
            .iter()
            .fold(f64::INFINITY, |m, &s| m.min(s));
        let note = format!(
            "OME-Zarr level auto: level {level} of {} (smallest spacing {spacing:.4} mm) for a \
             pixel of {pixel:.4} mm at the focal plane",
            store.levels().len()
        );
        Ok((concrete, Some(note)))
    }

    /// The camera `request` resolves to (loads the volume for its bounds if needed; a store
    /// read out of core: its metadata, [`Renderer::volume_grid`]).
    pub fn camera(&mut self, request: &RenderRequest) -> Result<Camera> {
        let (grid, _) = self.volume_grid(request)?;
        request.scene.camera.resolve(grid.drawn_bounds_world())
    }

    /// The transfer function `request` resolves to for its volume and mode.
    pub fn transfer_function(&mut self, request: &RenderRequest) -> Result<TransferFunction> {
        let (source, _) = self.concrete_source(request)?;
        let vol = self.volume(&source)?;
        let range = self.range(&source, &vol)?;
        Ok(resolve_tf(request, &vol, range, &mut self.auto_tf)?.tf)
    }

    /// Renders `request`. `progress` is called between stages and during the render (after
    /// each batch of sheets for the splatting renderers, about twenty times for the Chapter 6
    /// displays); returning `false` cancels with [`EngineError::Cancelled`]. The callback
    /// changes nothing in the image.
    pub fn render(
        &mut self,
        request: &RenderRequest,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<Output> {
        self.render_inner(request, progress, None, None)
    }

    /// Like [`Renderer::render`] with the dense sheet renderer's successive refinement
    /// (Westover §4.2.3): `ladder` rungs are rendered in order and all but the last are passed
    /// to `on_preview` (return `false` to stop). Orthographic sheets only.
    pub fn render_refined(
        &mut self,
        request: &RenderRequest,
        ladder: &[RefinementStep],
        on_preview: &mut (dyn FnMut(&Preview) -> Result<bool> + Send),
    ) -> Result<Output> {
        let ladder = Ladder {
            steps: ladder,
            on_preview,
        };
        self.render_inner(request, &mut |_| true, Some(ladder), None)
    }

    /// One brick's partial image of `request` for sort-last rendering
    /// ([`crate::distributed`]): only the samples whose cell lies in `owned_cells` (`[lo, hi)`,
    /// index units of the full level; [`volsplat_splat::RenderSettings::owned_cells`]) are
    /// drawn, each at its global position. The request must be drawn by the image-aligned
    /// slabs at the full level in composite, MIP and MinIP, or by the sheets or the splat list
    /// in X-ray (the voxels whose cell lies in the box; an error naming `renderer` otherwise).
    /// From an OME-Zarr store or a NRRD file with a raw payload only the bricks of the box are
    /// read (the rank's part opened by [`crate::distributed::render_sort_last`] where it holds
    /// the box); in X-ray the voxels the box draws are then drawn as a volume of their own, on
    /// the level's grid shifted to the box, with the camera and the X-ray offset of the level.
    pub fn render_brick(
        &mut self,
        request: &RenderRequest,
        owned_cells: [[usize; 3]; 2],
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<Output> {
        self.render_inner(request, progress, None, Some(owned_cells))
    }

    /// Loads, resolves the camera and transfer function, plans, draws with the planned
    /// renderer (only the cells of `owned`, where given), and checks the picture.
    fn render_inner(
        &mut self,
        request: &RenderRequest,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
        ladder: Option<Ladder<'_>>,
        owned: Option<[[usize; 3]; 2]>,
    ) -> Result<Output> {
        let t0 = Instant::now();
        request.validate()?;
        report(progress, 0.0, Stage::Load)?;
        let (source, level_note) = self.concrete_source(request)?;
        let source = &source;
        if let Some(budget) = self.paged_budget(request, source, owned.is_some())? {
            if ladder.is_some() {
                return Err(EngineError::request(
                    "memory",
                    "a store read out of core is drawn by the image-aligned slabs (not by a \
                     refinement ladder)",
                ));
            }
            if let (Mode::Xray, Some(o)) = (request.mode, owned) {
                return self.render_xray_part(request, source, budget, o, progress);
            }
            return self.render_paged(request, source, budget, level_note, owned, progress);
        }
        let loaded = self.load(source)?;
        let (vol, fresh_volume) = (Arc::clone(&loaded.value.volume), loaded.fresh);
        // The reader's notes come with the frame that loaded the volume.
        let mut notes = if fresh_volume {
            level_note
                .into_iter()
                .chain(loaded.value.notes.clone())
                .collect()
        } else {
            Vec::new()
        };
        let load_ms = if fresh_volume { ms(t0) } else { 0.0 };
        // The reset view frames the box the renderers draw: an axis of one sample is one
        // spacing thick (decision 0023), so a single slice or voxel is framed, not a plane or
        // a point.
        let camera = request
            .scene
            .camera
            .resolve(vol.grid().drawn_bounds_world())?;
        let range = self.range(source, &vol)?;
        let resolved = resolve_tf(request, &vol, range, &mut self.auto_tf)?;
        let tf = resolved.tf;
        notes.extend(resolved.note);
        // X-ray: what is integrated (CT in Hounsfield units relative to air; `crate::xray`).
        let (xray_offset, xray_note) = match request.mode {
            Mode::Xray => request.scene.xray_density.resolve(range),
            _ => (None, None),
        };
        if fresh_volume {
            notes.extend(xray_note);
        }
        let threads = request.threads;
        let pool = Arc::clone(cached(&mut self.pool, threads, || build_pool(threads))?.value);
        let mut warnings: Vec<String> = resolved.warning.into_iter().collect();
        warnings.extend(request.ignored_options());
        let t_prep = Instant::now();
        report(progress, 0.05, Stage::Classify)?;
        let (plan, tables_fresh) = self.plan(request, &camera, &vol, &tf, ladder.is_some())?;
        warnings.extend(plan.warnings);
        let frame = Frame {
            request,
            volume: &vol,
            camera: &camera,
            tf: &tf,
            xray_offset,
            pool: &pool,
            t_prep,
            tables_fresh,
            owned_cells: owned,
        };
        if owned.is_some() {
            let slabs_at_full = matches!(&plan.draw, Draw::Slabs(p) if p.level == 0);
            let voxels = matches!(&plan.draw, Draw::Sheets | Draw::SplatList);
            let drawn = match request.mode {
                Mode::Composite | Mode::Mip | Mode::Minip => slabs_at_full,
                Mode::Xray => voxels,
            };
            if !drawn {
                return Err(EngineError::request(
                    "renderer",
                    "a brick's partial image is drawn by the image-aligned slabs at the full \
                     level in composite, MIP and MinIP (visibility image or auto, quality.level \
                     full), or by the sheets or the splat list in X-ray (renderer auto)",
                ));
            }
        }
        let drawn = match &plan.draw {
            Draw::Display(kind) => self.draw_display(&frame, *kind, progress)?,
            Draw::Slabs(slabs) => self.draw_slabs(&frame, slabs, progress)?,
            Draw::Sheets => self.draw_sheets(&frame, ladder, progress)?,
            Draw::SplatList => self.draw_list(&frame, progress)?,
        };
        let Drawn {
            image,
            values,
            mut stats,
            warnings: drawn_warnings,
            notes: drawn_notes,
        } = drawn;
        warnings.extend(drawn_warnings);
        notes.extend(drawn_notes);
        check_finite(&image, values.as_ref(), request.mode, plan.renderer)?;
        notes.extend(black_xray_note(values.as_ref(), request));
        stats.renderer = Some(plan.renderer);
        stats.projection = Some(plan.projection);
        stats.load_ms = load_ms;
        stats.width = request.width;
        stats.height = request.height;
        stats.total_ms = ms(t0);
        report(progress, 1.0, Stage::Done)?;
        Ok(Output {
            image,
            values,
            stats,
            camera,
            transfer_function: tf,
            warnings,
            notes,
        })
    }

    /// The plan of `request` ([`plan::plan`]), and whether it built the classification tables
    /// (where the choice depends on them: they are kept for the draw step).
    fn plan(
        &mut self,
        request: &RenderRequest,
        camera: &Camera,
        vol: &AnyVolume,
        tf: &TransferFunction,
        refine: bool,
    ) -> Result<(Plan, bool)> {
        let mut fresh = false;
        let slot = &mut self.tables;
        let plan = plan::plan(request, camera, vol.grid(), refine, &mut || {
            let got = cached(slot, TablesKey::new(request, tf), || {
                Ok(Arc::new(cache::build_tables(request, tf)?))
            })?;
            fresh |= got.fresh;
            Ok(Classification::from(&**got.value))
        })?;
        Ok((plan, fresh))
    }
}

/// A picture with non-finite pixels (X-ray: values) is an internal error of `renderer`,
/// never written.
fn check_finite(
    image: &Image,
    values: Option<&ScalarImage>,
    mode: Mode,
    renderer: UsedRenderer,
) -> Result<()> {
    let bad = match (values, mode) {
        (Some(v), Mode::Xray) => v.values().iter().filter(|x| !x.is_finite()).count(),
        _ => image
            .pixels()
            .iter()
            .filter(|p| p.iter().any(|c| !c.is_finite()))
            .count(),
    };
    if bad > 0 {
        return Err(EngineError::NonFinite {
            stage: renderer.name().into(),
            count: bad,
        });
    }
    Ok(())
}

/// An X-ray without a window whose line integrals are all ≤ 0 writes a black PNG: a note says
/// why and what to give.
fn black_xray_note(values: Option<&ScalarImage>, request: &RenderRequest) -> Option<String> {
    let (Some(v), Mode::Xray, None) = (values, request.mode, request.output.window) else {
        return None;
    };
    let brightest = v.values().iter().copied().fold(f32::NEG_INFINITY, f32::max);
    (brightest <= 0.0 && !v.values().is_empty()).then(|| {
        format!(
            "X-ray: every line integral is ≤ 0 (the brightest is {brightest}): the PNG, scaled              from 0 to its brightest pixel, is black; give --window LO:HI, or an offset that              makes the data positive with --xray-offset"
        )
    })
}

/// Calls the progress callback; `false` from it is [`EngineError::Cancelled`].
fn report(
    progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    fraction: f64,
    stage: Stage,
) -> Result<()> {
    if progress(&Progress { fraction, stage }) {
        Ok(())
    } else {
        Err(EngineError::Cancelled)
    }
}

/// Milliseconds since `t`.
fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Renders without a [`Renderer`] (nothing kept): the one-shot convenience.
pub fn render_once(request: &RenderRequest) -> Result<Output> {
    Renderer::new().render(request, &mut |_| true)
}
