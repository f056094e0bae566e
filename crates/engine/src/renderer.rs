//! The reusable [`Renderer`]: one entry point for every renderer, keeping what does not change
//! between frames.

use crate::error::{EngineError, Result};
use crate::request::{
    AntialiasChoice, DensityChoice, KernelChoice, Mode, OrderChoice, RenderRequest, RendererChoice,
    VisibilityChoice, VolumeLevel,
};
use crate::scene::{TransferSpec, VolumeSource};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;
use volsplat_core::{
    AnyVolume, AutoTransfer, Camera, CrioTables, Image, Light, Preset, Projection, ScalarImage,
    TransferFunction,
};
use volsplat_filter::display::{DisplayVolume, build_map, render_display_with_progress};
use volsplat_filter::nil::DiscreteNilMap;
use volsplat_filter::texture::Reconstruction;
use volsplat_splat::list::{draw_depth_contour, k_distance, render_list_depth};
use volsplat_splat::refine::{RefinementStep, render_ladder};
use volsplat_splat::{
    BrickGrid, ExtractSettings, Pyramid, Rendered, SplatList, render_level,
    render_list_with_progress, render_with_progress,
};

/// Progress of a render, passed to the caller's callback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Fraction done, in [0, 1].
    pub fraction: f64,
    /// What is being done: `"load"`, `"classify"` (tables, splat list, display volume),
    /// `"render"` or `"done"`.
    pub stage: &'static str,
}

/// Which renderer actually drew an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum UsedRenderer {
    /// The dense orthographic sheet renderer.
    Dense,
    /// The sparse splat list.
    SplatList,
    /// Image-aligned, post-classified slabs (orthographic or perspective).
    Slab,
    /// Sabella's display.
    Sabella,
    /// A Chapter 6 display with NIL maps or direct quadrature.
    Nil,
}

/// Timings (milliseconds) and counters of one render: one type for every renderer. Fields a
/// renderer does not have are zero or absent.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Stats {
    /// The renderer that drew the image.
    pub renderer: Option<UsedRenderer>,
    /// `orthographic` or `perspective`.
    pub projection: &'static str,
    /// Loading or building the volume in this call (0 when the renderer kept it).
    pub load_ms: f64,
    /// Classification state built in this call: CRIO tables, splat list or display volume and
    /// NIL map (0 when kept from an earlier frame).
    pub prepare_ms: f64,
    /// Frame set-up of the splatting renderer: geometry, footprint table, classifier tables.
    pub setup_ms: f64,
    /// Transform + classification and shading (splatting).
    pub classify_ms: f64,
    /// Splatting into sheet buffers.
    pub splat_ms: f64,
    /// Compositing sheets.
    pub composite_ms: f64,
    /// The frame itself (excluding load and prepare).
    pub render_ms: f64,
    /// Everything in this call.
    pub total_ms: f64,
    /// Lattice points visited.
    pub voxels: u64,
    /// Samples splatted.
    pub splats: u64,
    /// Samples skipped because their footprint was already opaque.
    pub splats_terminated: u64,
    /// Perspective: splats clipped at the near plane.
    pub splats_clipped: u64,
    /// Splats widened by anti-aliasing.
    pub splats_widened: u64,
    /// Pixel updates (multiply–adds of one RGBA weight).
    pub pixel_updates: u64,
    /// Average pixels per splat.
    pub kernel_cost: f64,
    /// Kernel name.
    pub kernel: String,
    /// Anti-aliasing rule.
    pub antialias: &'static str,
    /// Image-aligned slabs, shaded composite: where the lights were evaluated, `voxels` (VTK's
    /// order) or `samples` (also where `voxels` was asked for but the transfer function depends
    /// on more than the density; decision 0019). Absent otherwise.
    pub shade_at: Option<&'static str>,
    /// Image-aligned slabs: rays per pixel and axis, area-averaged into each pixel, where the
    /// view is minified (anti-aliasing; decision 0020). Absent with one ray per pixel.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub supersampling: Option<f64>,
    /// Image-aligned slabs, composite: whether the slabs were classified by segment
    /// (pre-integrated; decision 0020). Absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preintegrated: Option<bool>,
    /// Image-aligned slabs, composite: how sharp the transfer function's steepest ramp is
    /// against the data (`volsplat_splat::slab::ring_risk`; `auto` pre-integrates above 4).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ring_risk: Option<f64>,
    /// Image-aligned slabs asked for a pyramid level (`quality.level` other than `full`): the
    /// level drawn, 0 for the full volume (decision 0031). Absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub level: Option<usize>,
    /// With `level`: the smallest spacing of the level drawn, world units (`auto` keeps it at
    /// most √2 × `focal_pixel`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub level_spacing: Option<f64>,
    /// With `level`: the size of a pixel at the focal point, world units.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub focal_pixel: Option<f64>,
    /// Sheets.
    pub sheets: usize,
    /// Sheet-normal axis, `i`, `j` or `k`.
    pub sheet_axis: &'static str,
    /// World path between sheets along the view.
    pub sheet_spacing: f64,
    /// Footprint table entries.
    pub footprint_entries: usize,
    /// Footprint sub-pixel phases per axis.
    pub footprint_phases: usize,
    /// Footprint half-extent, pixels.
    pub footprint_half_extent_px: [f64; 2],
    /// Worker threads.
    pub threads: usize,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Splat list: splats kept.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub list_splats: Option<usize>,
    /// Splat list: bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub list_bytes: Option<usize>,
    /// Splat list: extraction time (whenever it was built).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub list_build_ms: Option<f64>,
    /// Chapter 6 displays: per-stage timings and counters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub display: Option<DisplayStats>,
}

/// Timings (milliseconds) and counters of a Chapter 6 display.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DisplayStats {
    /// NIL map construction (whenever it was built; 0 without a map).
    pub map_build_ms: f64,
    /// Trigger placement.
    pub trigger_ms: f64,
    /// Patch selection.
    pub hierarchy_ms: f64,
    /// NIL control points.
    pub control_points_ms: f64,
    /// Evaluation.
    pub evaluation_ms: f64,
    /// Ray search.
    pub search_ms: f64,
    /// Ray marching.
    pub march_ms: f64,
    /// Pixels.
    pub pixels: u64,
    /// Rays that hit the volume.
    pub rays: u64,
    /// Trigger points.
    pub triggers: u64,
    /// NIL patches used.
    pub patches: u64,
    /// NIL evaluations that fell back to point sampling.
    pub fallbacks: u64,
}

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

/// The overall fraction done when the render stage itself is `f` done: the render stage runs
/// from 0.2 to 1 (loading and classification before it), never past 1 by rounding.
fn render_fraction(f: f64) -> f64 {
    (0.2 + 0.8 * f).clamp(0.2, 1.0)
}

/// What a splat list is built from: the volume, the classification tables' key, the opacity
/// threshold's bits and the subsampling.
type ListKey = (VolumeSource, String, u32, usize);

/// A loaded volume and its reader's notes.
type LoadedState = (Arc<AnyVolume>, Vec<String>);

/// The Chapter 6 state kept between frames: densities, NIL map, and the map's build time (ms).
type DisplayState = (DisplayVolume, Option<DiscreteNilMap>, f64);

/// A preview callback of [`Renderer::render_refined`].
type OnPreview<'a> = &'a mut (dyn FnMut(&Preview) -> Result<bool> + Send);

struct Cached<K, V> {
    key: K,
    value: V,
}

fn cached<K: PartialEq, V>(
    slot: &mut Option<Cached<K, V>>,
    key: K,
    build: impl FnOnce() -> Result<V>,
) -> Result<(&V, bool)> {
    // Take the old value out first, so a rebuild never holds two copies in memory.
    let (entry, fresh) = match slot.take() {
        Some(c) if c.key == key => (c, false),
        _ => (
            Cached {
                key,
                value: build()?,
            },
            true,
        ),
    };
    Ok((&slot.insert(entry).value, fresh))
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
    volume: Option<Cached<VolumeSource, LoadedState>>,
    tables: Option<Cached<String, Arc<CrioTables>>>,
    list: Option<Cached<ListKey, Arc<SplatList>>>,
    /// Min/max bricks of the volume (image-aligned slabs' empty-space skipping).
    bricks: Option<Cached<VolumeSource, Arc<BrickGrid>>>,
    /// The volume's resolution pyramid (previews, `quality.level`), its levels built on first
    /// use.
    pyramid: Option<Cached<VolumeSource, Arc<Pyramid>>>,
    display: Option<Cached<(VolumeSource, String), Arc<DisplayState>>>,
    pool: Option<Cached<Option<usize>, Arc<rayon::ThreadPool>>>,
    /// The automatic transfer function and its description, per volume (keyed by address).
    auto_tf: Option<Cached<VolumeSource, (TransferFunction, String)>>,
    /// The volume's value range (a pass over every voxel), per volume.
    range: Option<Cached<VolumeSource, (f64, f64)>>,
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
        Ok(Arc::clone(
            &cached(&mut self.volume, source.clone(), || {
                source.load_with_limits(&self.limits)
            })?
            .0
            .0,
        ))
    }

    /// The camera `request` resolves to (loads the volume for its bounds if needed).
    pub fn camera(&mut self, request: &RenderRequest) -> Result<Camera> {
        let vol = self.volume(&request.scene.volume)?;
        request
            .scene
            .camera
            .resolve(vol.grid().drawn_bounds_world())
    }

    /// The transfer function `request` resolves to for its volume and mode.
    pub fn transfer_function(&mut self, request: &RenderRequest) -> Result<TransferFunction> {
        let vol = self.volume(&request.scene.volume)?;
        let range = *cached(&mut self.range, request.scene.volume.clone(), || {
            Ok(vol.value_range())
        })?
        .0;
        Ok(resolve_tf(request, &vol, range, &mut self.auto_tf)?.0)
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
        self.render_inner(request, progress, None)
    }

    /// Like [`Renderer::render`] with the dense renderer's successive refinement (Westover
    /// §4.2.3): `ladder` rungs are rendered in order and all but the last are passed to
    /// `on_preview` (return `false` to stop). Orthographic dense rendering only.
    pub fn render_refined(
        &mut self,
        request: &RenderRequest,
        ladder: &[RefinementStep],
        on_preview: &mut (dyn FnMut(&Preview) -> Result<bool> + Send),
    ) -> Result<Output> {
        self.render_inner(request, &mut |_| true, Some((ladder, on_preview)))
    }

    fn render_inner(
        &mut self,
        request: &RenderRequest,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
        ladder: Option<(&[RefinementStep], OnPreview<'_>)>,
    ) -> Result<Output> {
        let t0 = Instant::now();
        request.validate()?;
        report(progress, 0.0, "load")?;
        let vol_was_cached = self
            .volume
            .as_ref()
            .is_some_and(|c| c.key == request.scene.volume);
        let vol = self.volume(&request.scene.volume)?;
        let load_ms = if vol_was_cached { 0.0 } else { ms(t0) };
        let mut notes = match (&self.volume, vol_was_cached) {
            (Some(c), false) => c.value.1.clone(),
            _ => Vec::new(),
        };
        // The reset view frames the box the renderers draw: an axis of one sample is one
        // spacing thick (decision 0023), so a single slice or voxel is framed, not a plane or
        // a point.
        let camera = request
            .scene
            .camera
            .resolve(vol.grid().drawn_bounds_world())?;
        let range = *cached(&mut self.range, request.scene.volume.clone(), || {
            Ok(vol.value_range())
        })?
        .0;
        let (tf, tf_warning, tf_note) = resolve_tf(request, &vol, range, &mut self.auto_tf)?;
        notes.extend(tf_note);
        // X-ray: what is integrated (CT in Hounsfield units relative to air; `crate::xray`).
        let (xray_offset, xray_note) = match request.mode {
            Mode::Xray => request.scene.xray_density.resolve(range),
            _ => (None, None),
        };
        if !vol_was_cached {
            notes.extend(xray_note);
        }
        let threads = request.threads;
        let pool = Arc::clone(
            cached(&mut self.pool, threads, || {
                let mut b = rayon::ThreadPoolBuilder::new();
                if let Some(n) = threads {
                    b = b.num_threads(n);
                }
                b.build().map(Arc::new).map_err(|e| EngineError::Threads {
                    threads: threads.unwrap_or(0),
                    message: e.to_string(),
                })
            })?
            .0,
        );
        let mut warnings: Vec<String> = tf_warning.into_iter().collect();
        warnings.extend(request.ignored_options());
        let t_prep = Instant::now();
        report(progress, 0.05, "classify")?;
        // Decision 0016: `auto` draws unshaded composite, MIP and MinIP with image-aligned slabs
        // and keeps Westover's sheets where the slabs do not (yet) match VTK as well.
        let mut early_fresh = false;
        let slab = request.mode != Mode::Xray
            && match request.quality.visibility {
                VisibilityChoice::Image => true,
                VisibilityChoice::Auto => {
                    // Options that only the sheet renderers have keep them.
                    let q = &request.quality;
                    let plain = request.renderer == RendererChoice::Auto
                        && ladder.is_none()
                        && request.k_contour.is_none()
                        && q.subsample == 1
                        && q.order == OrderChoice::Ftb
                        && q.kernel == KernelChoice::Gaussian
                        && !matches!(
                            q.antialias,
                            AntialiasChoice::SwanPerpendicular | AntialiasChoice::Ewa
                        );
                    plain && {
                        let (tables, fresh) =
                            cached(&mut self.tables, tables_key(request, &tf), || {
                                Ok(Arc::new(build_tables(request, &tf)?))
                            })?;
                        early_fresh = fresh;
                        // Shaded composite where the voxels can be shaded (decision 0019).
                        request.mode != Mode::Composite
                            || !tables.needs_gradient()
                            || slab_shading(&request.quality, tables)
                                == Some(volsplat_splat::ShadeAt::Voxels)
                    }
                }
                VisibilityChoice::Sheet | VisibilityChoice::Every => false,
            };
        let renderer = match request.renderer {
            RendererChoice::Auto if slab => UsedRenderer::Slab,
            RendererChoice::Auto if camera.parallel_projection => UsedRenderer::Dense,
            RendererChoice::Auto | RendererChoice::SplatList => UsedRenderer::SplatList,
            RendererChoice::Splat => {
                if !camera.parallel_projection {
                    return Err(EngineError::request(
                        "renderer",
                        "the dense `splat` renderer draws orthographic views only; use `auto` \
                         or `splat_list` for perspective",
                    ));
                }
                UsedRenderer::Dense
            }
            RendererChoice::Sabella => UsedRenderer::Sabella,
            RendererChoice::Nil => UsedRenderer::Nil,
        };
        if ladder.is_some() && renderer != UsedRenderer::Dense {
            return Err(EngineError::request(
                "renderer",
                "successive refinement works with the dense orthographic renderer only",
            ));
        }
        if request.k_contour.is_some() && renderer != UsedRenderer::SplatList {
            return Err(EngineError::request(
                "k_contour",
                "the line at distance k needs the splat-list renderer (perspective or splat_list)",
            ));
        }
        // `auto` asks for the level that fits where there is a pyramid, and quietly means the
        // full volume where there is none (previews ask for it whatever the renderer).
        if matches!(request.quality.level, VolumeLevel::Level(n) if n > 0)
            && renderer != UsedRenderer::Slab
        {
            warnings.push(format!(
                "quality.level {} applies to the image-aligned slab renderer; the {} drew the \
                 full volume",
                request.quality.level,
                renderer_name(renderer)
            ));
        }
        let projection = if camera.parallel_projection {
            "orthographic"
        } else {
            "perspective"
        };
        let (w, h) = (request.width, request.height);
        let mut stats;
        let (image, values) = match renderer {
            UsedRenderer::Sabella | UsedRenderer::Nil => {
                if !request.scene.clipping.is_empty() {
                    return Err(EngineError::request(
                        "scene.clipping",
                        "cropping and clipping planes apply to the splatting renderers; the \
                         Chapter 6 displays (sabella, nil) do not cut the volume",
                    ));
                }
                let d = &request.display;
                let kind = d.kind(request.renderer);
                let key = (
                    request.scene.volume.clone(),
                    serde_json::json!({
                        "tf": &tf, "density": d.density,
                        "map": d.needs_map(kind).then_some(d.patch_order),
                        "max": d.max_map_values,
                    })
                    .to_string(),
                );
                let mut budget_note = None;
                let (dv, fresh) = cached(&mut self.display, key, || {
                    let mut dv = display_volume(&vol, &tf, d.density, 1)?;
                    let tm = Instant::now();
                    let map = if d.needs_map(kind) {
                        let budget = if d.max_map_values == 0 {
                            auto_map_budget()
                        } else {
                            d.max_map_values
                        };
                        // Average the volume down until its map fits the budget.
                        let need = |dv: &DisplayVolume| {
                            DiscreteNilMap::values_needed_for(
                                dv.texture().dims(),
                                d.patch_order,
                                None,
                                1,
                            )
                        };
                        let full = need(&dv);
                        let mut factor = 1;
                        while need(&dv) > budget as u128 {
                            factor += 1;
                            if factor > 16 {
                                return Err(EngineError::request(
                                    "display.max_map_values",
                                    format!(
                                        "even a 16× coarser volume needs a NIL map larger than \
                                         the budget of {budget} values; raise it"
                                    ),
                                ));
                            }
                            dv = display_volume(&vol, &tf, d.density, factor)?;
                        }
                        if factor > 1 {
                            let g = vol.grid().dims;
                            budget_note = Some(format!(
                                "NIL map: the full {}×{}×{} volume needs {}, over the budget of \
                                 {}; built from a {factor}× coarser volume ({}). Raise the \
                                 budget (display.max_map_values, --max-map-values) for full \
                                 resolution",
                                g[0],
                                g[1],
                                g[2],
                                map_size(full),
                                map_size(budget as u128),
                                map_size(need(&dv)),
                            ));
                        }
                        Some(pool.install(|| build_map(&dv, d.patch_order, None, budget))?)
                    } else {
                        None
                    };
                    Ok(Arc::new((dv, map, ms(tm))))
                })?;
                notes.extend(budget_note);
                let dv = Arc::clone(dv);
                let prepare_ms = if fresh { ms(t_prep) } else { 0.0 };
                report(progress, 0.2, "render")?;
                let t_r = Instant::now();
                let settings = d.settings(kind);
                let mut cancelled = false;
                let img = pool.install(|| {
                    render_display_with_progress(
                        &dv.0,
                        dv.1.as_ref(),
                        &camera,
                        w,
                        h,
                        &settings,
                        &mut |f| {
                            let go = progress(&Progress {
                                fraction: render_fraction(f),
                                stage: "render",
                            });
                            cancelled |= !go;
                            go
                        },
                    )
                });
                if cancelled {
                    return Err(EngineError::Cancelled);
                }
                let img = img?;
                let s = img.stats;
                stats = Stats {
                    prepare_ms,
                    render_ms: ms(t_r),
                    threads: pool.current_num_threads(),
                    display: Some(DisplayStats {
                        map_build_ms: dv.2,
                        trigger_ms: s.trigger_s * 1e3,
                        hierarchy_ms: s.hierarchy_s * 1e3,
                        control_points_ms: s.control_s * 1e3,
                        evaluation_ms: s.evaluation_s * 1e3,
                        search_ms: s.search_s * 1e3,
                        march_ms: s.march_s * 1e3,
                        pixels: s.pixels,
                        rays: s.rays,
                        triggers: s.triggers,
                        patches: s.patches,
                        fallbacks: s.fallbacks,
                    }),
                    ..Stats::default()
                };
                (img.to_image(d.grey), None)
            }
            UsedRenderer::Slab => {
                let (tables, fresh_tables) =
                    cached(&mut self.tables, tables_key(request, &tf), || {
                        Ok(Arc::new(build_tables(request, &tf)?))
                    })?;
                let fresh_tables = fresh_tables || early_fresh;
                let tables = Arc::clone(tables);
                let (bricks, fresh_bricks) =
                    cached(&mut self.bricks, request.scene.volume.clone(), || {
                        Ok(Arc::new(pool.install(
                            || volsplat_core::with_volume!(&*vol, v => BrickGrid::build(v)),
                        )))
                    })?;
                let bricks = Arc::clone(bricks);
                let mut settings = request.splat_settings();
                settings.clip = request.scene.clipping.world_planes(vol.grid())?;
                settings.slab = request.quality.slab.unwrap_or_else(|| {
                    volsplat_splat::slab::default_slab(
                        settings.mode,
                        slab_shading(&request.quality, &tables),
                    )
                });
                // The pyramid level (decision 0031): the full volume unless asked; coarse levels
                // are built here, once per volume, so that their cost counts as preparation.
                let asked = request.quality.level;
                let (level, focal_pixel) = slab_level(asked, &vol, &camera, w, h)?;
                let pyramid = Arc::clone(
                    cached(&mut self.pyramid, request.scene.volume.clone(), || {
                        Ok(Arc::new(Pyramid::new(Arc::clone(&vol))))
                    })?
                    .0,
                );
                let built = !pyramid.is_built(level);
                if built {
                    pool.install(|| pyramid.level(level))?;
                }
                let level = level.min(pyramid.len() - 1);
                if let VolumeLevel::Level(n) = asked
                    && usize::from(n) > level
                {
                    warnings.push(format!(
                        "quality.level {n}: the volume's pyramid ends at level {level}; drew \
                         level {level}"
                    ));
                }
                let prepare_ms = if fresh_tables || fresh_bricks || built {
                    ms(t_prep)
                } else {
                    0.0
                };
                report(progress, 0.2, "render")?;
                let mut cancelled = false;
                let out = pool.install(|| {
                    render_level(
                        &pyramid,
                        level,
                        &camera,
                        &tables,
                        &settings,
                        Some(&bricks),
                        &mut |p| {
                            let f = render_fraction(
                                p.sheets_done as f64 / p.sheets_total.max(1) as f64,
                            );
                            let go = progress(&Progress {
                                fraction: f,
                                stage: "render",
                            });
                            cancelled |= !go;
                            go
                        },
                    )
                });
                if cancelled {
                    return Err(EngineError::Cancelled);
                }
                let rendered = out?;
                let s = &rendered.stats;
                stats = Stats {
                    prepare_ms,
                    render_ms: s.total_ms,
                    setup_ms: s.setup_ms,
                    classify_ms: s.classify_ms,
                    voxels: s.voxels,
                    splats: s.splats,
                    splats_terminated: s.splats_terminated,
                    pixel_updates: s.pixel_updates,
                    kernel: "tent".into(),
                    antialias: if s.supersampling > 1.0 {
                        "area"
                    } else {
                        "none"
                    },
                    supersampling: (s.supersampling > 1.0).then_some(s.supersampling),
                    sheets: s.sheets,
                    sheet_axis: "view",
                    sheet_spacing: s.sheet_spacing,
                    shade_at: match slab_shading(&request.quality, &tables) {
                        _ if settings.mode != volsplat_splat::RenderMode::Composite => None,
                        Some(volsplat_splat::ShadeAt::Voxels) => Some("voxels"),
                        Some(volsplat_splat::ShadeAt::Samples) => Some("samples"),
                        None => None,
                    },
                    preintegrated: (settings.mode == volsplat_splat::RenderMode::Composite)
                        .then_some(s.preintegrated),
                    ring_risk: (settings.mode == volsplat_splat::RenderMode::Composite)
                        .then_some(s.ring_risk),
                    threads: s.threads,
                    level: (!asked.is_full()).then_some(level),
                    level_spacing: (!asked.is_full()).then(|| {
                        let g = &pyramid.grids()[level];
                        g.spacing.iter().fold(f64::INFINITY, |m, &v| m.min(v))
                    }),
                    focal_pixel: (!asked.is_full()).then_some(focal_pixel),
                    ..Stats::default()
                };
                (rendered.image, rendered.values)
            }
            UsedRenderer::Dense | UsedRenderer::SplatList => {
                // X-ray ignores the transfer function; its tables only tell the splat list which
                // voxels to keep: those whose X-ray weight is not zero.
                let table_tf = match request.mode {
                    Mode::Xray => xray_weight_tf(xray_offset),
                    _ => tf.clone(),
                };
                let (tables, fresh_tables) =
                    cached(&mut self.tables, tables_key(request, &table_tf), || {
                        Ok(Arc::new(build_tables(request, &table_tf)?))
                    })?;
                let fresh_tables = fresh_tables || early_fresh;
                let tables = Arc::clone(tables);
                let mut settings = request.splat_settings();
                settings.clip = request.scene.clipping.world_planes(vol.grid())?;
                settings.xray_offset = xray_offset.map(|o| o as f32);
                let mut fresh = fresh_tables;
                let rendered = if renderer == UsedRenderer::SplatList {
                    let q = &request.quality;
                    let voxels = volsplat_splat::ListVoxels::for_mode(settings.mode);
                    let key = (
                        request.scene.volume.clone(),
                        format!("{}{:?}", tables_key(request, &table_tf), voxels),
                        q.list_threshold.to_bits(),
                        q.subsample,
                    );
                    let (list, fresh_list) = cached(&mut self.list, key, || {
                        pool.install(|| {
                            Ok(Arc::new(SplatList::build_any(
                                &vol,
                                &tables,
                                &ExtractSettings {
                                    threshold: q.list_threshold,
                                    subsample: q.subsample,
                                    voxels,
                                },
                            )?))
                        })
                    })?;
                    let list = Arc::clone(list);
                    fresh |= fresh_list;
                    let prepare_ms = if fresh { ms(t_prep) } else { 0.0 };
                    report(progress, 0.2, "render")?;
                    let mut cancelled = false;
                    let out = pool.install(|| {
                        render_list_with_progress(&list, &camera, &tables, &settings, &mut |p| {
                            let f = render_fraction(
                                p.sheets_done as f64 / p.sheets_total.max(1) as f64,
                            );
                            let go = progress(&Progress {
                                fraction: f,
                                stage: "render",
                            });
                            cancelled |= !go;
                            go
                        })
                    });
                    if cancelled {
                        return Err(EngineError::Cancelled);
                    }
                    let mut out = out?;
                    if let Some(color) = request.k_contour {
                        let proj = Projection::new(&camera, w, h)?;
                        match k_distance(vol.grid(), q.subsample, &proj) {
                            Some(k) => {
                                let depth = pool.install(|| {
                                    render_list_depth(&list, &camera, &tables, &settings)
                                })?;
                                draw_depth_contour(&mut out.image, &depth, k as f32, color)?;
                                warnings
                                    .push(format!("k = s·D/p = {k:.4} world units from the eye"));
                            }
                            None => warnings.push(format!(
                                "k_contour: orthographic view, no distance k (every voxel covers \
                                 {:.3} pixels)",
                                vol.grid()
                                    .spacing
                                    .iter()
                                    .fold(f64::INFINITY, |m, &v| m.min(v))
                                    / proj.pixel_size_at(1.0)
                            )),
                        }
                    }
                    stats = Stats {
                        prepare_ms,
                        list_splats: Some(list.len()),
                        list_bytes: Some(list.bytes()),
                        list_build_ms: Some(list.build_ms()),
                        ..Stats::default()
                    };
                    out
                } else {
                    let prepare_ms = if fresh { ms(t_prep) } else { 0.0 };
                    report(progress, 0.2, "render")?;
                    stats = Stats {
                        prepare_ms,
                        ..Stats::default()
                    };
                    match ladder {
                        Some((steps, on_preview)) => {
                            let last = steps.len().saturating_sub(1);
                            let mut err = None;
                            let out = pool.install(|| {
                                volsplat_core::with_volume!(&*vol, v => render_ladder(
                                    v, &camera, &tables, &settings, steps,
                                    &mut |n, r| {
                                        if n >= last {
                                            return true;
                                        }
                                        let p = Preview { index: n, subsample: steps[n].subsample, rendered: r };
                                        match on_preview(&p) {
                                            Ok(go) => go,
                                            Err(e) => {
                                                err = Some(e);
                                                false
                                            }
                                        }
                                    }
                                ))
                            });
                            if let Some(e) = err {
                                return Err(e);
                            }
                            out?
                        }
                        None => {
                            let mut cancelled = false;
                            let out = pool.install(|| {
                                volsplat_core::with_volume!(&*vol, v => render_with_progress(
                                    v, &camera, &tables, &settings,
                                    &mut |p| {
                                        let f = render_fraction(
                                            p.sheets_done as f64 / p.sheets_total.max(1) as f64,
                                        );
                                        let go = progress(&Progress { fraction: f, stage: "render" });
                                        cancelled |= !go;
                                        go
                                    }
                                ))
                            });
                            if cancelled {
                                return Err(EngineError::Cancelled);
                            }
                            out?
                        }
                    }
                };
                let s = &rendered.stats;
                stats.render_ms = s.total_ms;
                stats.setup_ms = s.setup_ms;
                stats.classify_ms = s.classify_ms;
                stats.splat_ms = s.splat_ms;
                stats.composite_ms = s.composite_ms;
                stats.voxels = s.voxels;
                stats.splats = s.splats;
                stats.splats_terminated = s.splats_terminated;
                stats.splats_clipped = s.splats_clipped;
                stats.splats_widened = s.splats_widened;
                stats.pixel_updates = s.pixel_updates;
                stats.kernel_cost = s.kernel_cost();
                stats.kernel = settings.kernel.name();
                stats.antialias = settings.antialias.name();
                stats.sheets = s.sheets;
                stats.sheet_axis = ["i", "j", "k"].get(s.sheet_axis).copied().unwrap_or("?");
                stats.sheet_spacing = s.sheet_spacing;
                stats.footprint_entries = s.footprint_entries;
                stats.footprint_phases = s.footprint_phases;
                stats.footprint_half_extent_px = s.footprint_half_extent;
                stats.threads = s.threads;
                (rendered.image, rendered.values)
            }
        };
        let bad = match (&values, request.mode) {
            (Some(v), Mode::Xray) => v.values().iter().filter(|x| !x.is_finite()).count(),
            _ => image
                .pixels()
                .iter()
                .filter(|p| p.iter().any(|c| !c.is_finite()))
                .count(),
        };
        if bad > 0 {
            return Err(EngineError::NonFinite {
                stage: renderer_name(renderer).into(),
                count: bad,
            });
        }
        if let (Some(v), Mode::Xray, None) = (&values, request.mode, request.output.window) {
            let brightest = v.values().iter().copied().fold(f32::NEG_INFINITY, f32::max);
            if brightest <= 0.0 && !v.values().is_empty() {
                notes.push(format!(
                    "X-ray: every line integral is ≤ 0 (the brightest is {brightest}): the PNG, \
                     scaled from 0 to its brightest pixel, is black; give --window LO:HI, or an \
                     offset that makes the data positive with --xray-offset"
                ));
            }
        }
        stats.renderer = Some(renderer);
        stats.projection = projection;
        stats.load_ms = load_ms;
        stats.width = w;
        stats.height = h;
        stats.total_ms = ms(t0);
        report(progress, 1.0, "done")?;
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
}

/// The pyramid level the slabs draw for `asked` (decision 0031) and the pixel size at the focal
/// point (world units): 0 for the full level; `auto` the level whose voxel is about a pixel
/// ([`volsplat_splat::auto_level`], from the level grids alone: nothing is built to choose).
fn slab_level(
    asked: VolumeLevel,
    vol: &AnyVolume,
    camera: &Camera,
    w: usize,
    h: usize,
) -> Result<(usize, f64)> {
    let pixel = volsplat_splat::focal_pixel_size(camera, w, h)?;
    let level = match asked {
        VolumeLevel::Full => 0,
        VolumeLevel::Level(n) => usize::from(n),
        VolumeLevel::Auto => {
            volsplat_splat::auto_level(pixel, &volsplat_splat::pyramid::level_grids(vol.grid()))
        }
    };
    Ok((level, pixel))
}

/// Calls the progress callback; `false` from it is [`EngineError::Cancelled`].
fn report(
    progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    fraction: f64,
    stage: &'static str,
) -> Result<()> {
    if progress(&Progress { fraction, stage }) {
        Ok(())
    } else {
        Err(EngineError::Cancelled)
    }
}

/// Where the slab renderer will evaluate the lights for these tables: `None` unshaded (no
/// gradient needed), [`ShadeAt::Voxels`](volsplat_splat::ShadeAt::Voxels) where asked and the
/// classification depends on the density alone, at the samples otherwise (the slab renderer's
/// per-sample classifier).
fn slab_shading(q: &crate::Quality, tables: &CrioTables) -> Option<volsplat_splat::ShadeAt> {
    use volsplat_splat::ShadeAt;
    if !tables.needs_gradient() {
        None
    } else if q.shade_at == crate::ShadeAtChoice::Voxels && tables.density_only() {
        Some(ShadeAt::Voxels)
    } else {
        Some(ShadeAt::Samples)
    }
}

/// The renderer's name in messages.
pub fn renderer_name(r: UsedRenderer) -> &'static str {
    match r {
        UsedRenderer::Dense => "splatting renderer",
        UsedRenderer::SplatList => "splat-list renderer",
        UsedRenderer::Slab => "image-aligned slab renderer",
        UsedRenderer::Sabella => "Sabella display",
        UsedRenderer::Nil => "NIL renderer",
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The transfer function for `request` on `vol` (see [`TransferSpec::Auto`]).
/// The transfer function of `request` for `vol` (whose value range is `range`): the scene's, a
/// preset, or the automatic choice (see [`TransferSpec::Auto`]). `auto` caches the histogram rule per volume; the
/// returned strings are a warning (a preset that misses the data) and a note (what the
/// automatic rule found), each given when the function is first made.
fn resolve_tf(
    request: &RenderRequest,
    vol: &Arc<AnyVolume>,
    range: (f64, f64),
    auto: &mut Option<Cached<VolumeSource, (TransferFunction, String)>>,
) -> Result<(TransferFunction, Option<String>, Option<String>)> {
    let scene = match &request.scene.volume {
        VolumeSource::Phantom { phantom, .. } => phantom.scene_transfer_function(),
        _ => None,
    };
    let (mut warning, mut note) = (None, None);
    let mut tf = match &request.scene.transfer_function {
        TransferSpec::Function(tf) => tf.clone(),
        TransferSpec::Preset(preset) => {
            warning = preset.range_warning(range);
            preset.transfer_function(range)
        }
        TransferSpec::Auto => match scene {
            Some(tf) => tf,
            None if matches!(request.mode, Mode::Mip | Mode::Minip | Mode::Xray) => {
                // Projections without a transfer function: an opaque grey window over the data
                // (constant data: the unit below the value, which then shows white). X-ray does
                // not use it (`xray_weight_tf`): it is what `--save-scene` records.
                let (lo, hi) = if range.1 > range.0 {
                    range
                } else {
                    (range.0 - 1.0, range.0)
                };
                TransferFunction::ramp(lo, hi, 1.0)
            }
            None if request.scene.volume.is_demo_head() => Preset::CtSkin.transfer_function(range),
            None => {
                // The histogram rule reads the whole volume: once per volume.
                // Keyed by the source, never by the volume's address, which a later volume may
                // reuse; a `Memory` source holds its volume alive.
                let key = request.scene.volume.clone();
                let (entry, fresh) = cached(auto, key, || {
                    let a = AutoTransfer::from_volume(vol);
                    Ok((a.transfer_function.clone(), a.describe()))
                })?;
                if fresh {
                    note = Some(entry.1.clone());
                }
                entry.0.clone()
            }
        },
    };
    tf.validate()?;
    Ok((tf, warning, note))
}

/// The tables of an X-ray (which ignores the transfer function): opacity 1 wherever the X-ray
/// weight (`volsplat_splat::xray_weight`) is not zero, 0 where it is, so that the splat list
/// keeps exactly the voxels that add to the integral (a transfer function made the list drop
/// the voxels it hid, air and soft tissue alike). With an offset `o`: 0 up to `−o`, 1 from
/// `−o + δ` on; raw: 0 at 0 only. `δ` is far below any data step (10⁻³ of the offset, 10⁻⁶
/// raw); a value inside it keeps its voxel, which adds (almost) nothing.
fn xray_weight_tf(offset: Option<f64>) -> TransferFunction {
    let points = match offset {
        Some(o) => {
            let d = 1e-3 * o.abs().max(1.0);
            vec![[-o, 0.0], [-o + d, 1.0]]
        }
        None => vec![[-1e-6, 1.0], [0.0, 0.0], [1e-6, 1.0]],
    };
    let (lo, hi) = (points[0][0], points[points.len() - 1][0]);
    TransferFunction {
        color: vec![[lo, 1.0, 1.0, 1.0], [hi, 1.0, 1.0, 1.0]],
        scalar_opacity: points,
        ..TransferFunction::ramp(lo, hi, 1.0)
    }
}

/// The key of the classification tables: everything they are built from.
fn tables_key(request: &RenderRequest, tf: &TransferFunction) -> String {
    let s = &request.scene;
    serde_json::json!({
        "tf": tf, "lights": s.lights, "shading": s.shading,
        "surface": s.surface_enhance, "depth": s.depth_cue,
    })
    .to_string()
}

fn build_tables(request: &RenderRequest, tf: &TransferFunction) -> Result<CrioTables> {
    let s = &request.scene;
    let lights = if s.lights.is_empty() {
        vec![Light::headlight()]
    } else {
        s.lights
            .iter()
            .enumerate()
            .map(|(n, l)| l.to_light(&format!("scene.lights[{n}]")))
            .collect::<Result<Vec<_>>>()?
    };
    let mut tables =
        CrioTables::from_transfer_function_lit(tf, volsplat_core::crio::DEFAULT_TABLE_LEN, lights)?;
    tables.shading.emission &= s.shading.emission;
    tables.shading.diffuse &= s.shading.diffuse;
    tables.shading.specular &= s.shading.specular;
    if let Some([lo, hi]) = s.surface_enhance {
        tables = tables.with_surface_enhancement(lo, hi)?;
    }
    if let Some([near, far]) = s.depth_cue {
        tables = tables.with_depth_cue(near, far)?;
    }
    Ok(tables)
}

/// Densities of a volume for the Chapter 6 displays: the transfer function's scalar opacity
/// or the data normalised to its range.
/// The densities of the Chapter 6 displays for `vol`, averaged over `factor`³ blocks (1: as
/// is; the last block of an axis averages what it holds; the grid keeps its direction, with
/// spacing × `factor` and the origin at the first block's centre).
fn display_volume(
    vol: &AnyVolume,
    tf: &TransferFunction,
    density: DensityChoice,
    factor: usize,
) -> Result<DisplayVolume> {
    let f = vol.to_f32();
    let (lo, hi) = vol.value_range();
    let span = if hi > lo { hi - lo } else { 1.0 };
    let d: Vec<f64> = match density {
        DensityChoice::Tf => f.data().iter().map(|&v| tf.opacity_at(v as f64)).collect(),
        DensityChoice::Data => f.data().iter().map(|&v| (v as f64 - lo) / span).collect(),
    };
    if factor <= 1 {
        return Ok(DisplayVolume::new(f.grid(), &d, Reconstruction::Trilinear)?);
    }
    let g = f.grid();
    let [nx, ny, nz] = g.dims;
    let dims = g.dims.map(|n| n.div_ceil(factor).max(2));
    let mut sum = vec![0.0f64; dims[0] * dims[1] * dims[2]];
    let mut count = vec![0u32; sum.len()];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let c = [
                    (x / factor).min(dims[0] - 1),
                    (y / factor).min(dims[1] - 1),
                    (z / factor).min(dims[2] - 1),
                ];
                let i = c[0] + dims[0] * (c[1] + dims[1] * c[2]);
                sum[i] += d[x + nx * (y + ny * z)];
                count[i] += 1;
            }
        }
    }
    let avg: Vec<f64> = sum
        .iter()
        .zip(&count)
        .map(|(&s, &n)| if n > 0 { s / n as f64 } else { 0.0 })
        .collect();
    let half = (factor as f64 - 1.0) * 0.5;
    let offset = g.direction
        * volsplat_core::glam::DVec3::new(
            half * g.spacing[0],
            half * g.spacing[1],
            half * g.spacing[2],
        );
    let origin = (volsplat_core::glam::DVec3::from(g.origin) + offset).to_array();
    let grid = volsplat_core::Grid::new(
        dims,
        g.spacing.map(|s| s * factor as f64),
        origin,
        g.direction,
    )?;
    Ok(DisplayVolume::new(&grid, &avg, Reconstruction::Trilinear)?)
}

/// A NIL map size for messages: values and bytes (8 per value).
fn map_size(values: u128) -> String {
    let bytes = values as f64 * 8.0;
    let (b, unit) = if bytes >= 1e9 {
        (bytes / 1e9, "GB")
    } else {
        (bytes / 1e6, "MB")
    };
    format!("{values} values ({b:.1} {unit})")
}

/// Half the memory the system reports available, in f64 values (2 GiB where unknown).
fn auto_map_budget() -> usize {
    let available = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map(|kb| kb.saturating_mul(1024))
        .unwrap_or(4 << 30);
    (available / 2 / 8).min(usize::MAX as u64) as usize
}

/// Renders without a [`Renderer`] (nothing kept): the one-shot convenience.
pub fn render_once(request: &RenderRequest) -> Result<Output> {
    Renderer::new().render(request, &mut |_| true)
}
