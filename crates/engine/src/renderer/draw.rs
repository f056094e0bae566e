//! One draw step per renderer: each takes a [`Frame`] and the plan's part for it, fetches or
//! builds what it keeps in the [`Renderer`]'s caches, draws, and converts the library's
//! counters into [`Stats`].

use super::cache::{
    DisplayKey, DisplayState, ListKey, TablesKey, auto_map_budget, build_tables, cached,
    display_volume, map_size, xray_weight_tf,
};
use super::plan::SlabPlan;
use super::stats::{DisplayStats, Progress, SheetAxis, Stage, Stats};
use super::{Ladder, Preview, Renderer, ms, report};
use crate::error::{EngineError, Result};
use crate::request::{AntialiasChoice, Mode, RenderRequest, VisibilityChoice};
use std::sync::Arc;
use std::time::Instant;
use volsplat_core::{
    AnyVolume, Camera, CrioTables, Image, Projection, ScalarImage, TransferFunction,
};
use volsplat_filter::display::{
    DisplayKind, DisplayVolume, build_map, render_display_with_progress,
};
use volsplat_filter::nil::DiscreteNilMap;
use volsplat_splat::list::{draw_depth_contour, k_distance, render_list_depth};
use volsplat_splat::refine::render_ladder;
use volsplat_splat::{
    BrickGrid, ExtractSettings, ListVoxels, Pyramid, RenderSettings, Rendered, SplatList,
    Visibility, render_level, render_list_with_progress, render_with_progress,
};

/// What every draw step reads: the request and what was resolved for it.
pub(super) struct Frame<'a> {
    pub(super) request: &'a RenderRequest,
    pub(super) volume: &'a Arc<AnyVolume>,
    pub(super) camera: &'a Camera,
    /// The transfer function in force (data units).
    pub(super) tf: &'a TransferFunction,
    /// X-ray: the offset added to the data before integrating (`crate::xray`).
    pub(super) xray_offset: Option<f64>,
    pub(super) pool: &'a rayon::ThreadPool,
    /// When preparation (classification state) began.
    pub(super) t_prep: Instant,
    /// Whether the plan built the classification tables.
    pub(super) tables_fresh: bool,
    /// A brick's cells, where only they are drawn ([`super::Renderer::render_brick`]).
    pub(super) owned_cells: Option<[[usize; 3]; 2]>,
}

impl Frame<'_> {
    /// The preparation time, ms, where something was built in this call (`fresh` or the
    /// plan's tables); 0 where everything was kept.
    fn prepare_ms(&self, fresh: bool) -> f64 {
        if fresh || self.tables_fresh {
            ms(self.t_prep)
        } else {
            0.0
        }
    }
}

/// What a draw step returns.
pub(super) struct Drawn {
    pub(super) image: Image,
    pub(super) values: Option<ScalarImage>,
    pub(super) stats: Stats,
    pub(super) warnings: Vec<String>,
    pub(super) notes: Vec<String>,
}

impl Drawn {
    fn new(image: Image, values: Option<ScalarImage>, stats: Stats) -> Drawn {
        Drawn {
            image,
            values,
            stats,
            warnings: Vec::new(),
            notes: Vec::new(),
        }
    }
}

/// The overall fraction done when the render stage itself is `f` done: the render stage runs
/// from 0.2 to 1 (loading and classification before it), never past 1 by rounding.
pub(super) fn render_fraction(f: f64) -> f64 {
    (0.2 + 0.8 * f).clamp(0.2, 1.0)
}

/// The fraction of a splatting render done: sheets (or slab bands) finished of all.
pub(super) fn sheets_done(p: &volsplat_splat::Progress) -> f64 {
    p.sheets_done as f64 / p.sheets_total.max(1) as f64
}

/// Runs `draw`, handing it a callback that forwards the render stage's fraction done (in
/// [0, 1]) to the caller's `progress` as [`Stage::Render`]; a `false` from `progress` stops the
/// renderer and is [`EngineError::Cancelled`], whatever the renderer then returns.
pub(super) fn forward<R, E: Into<EngineError>>(
    progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    draw: impl FnOnce(&mut (dyn FnMut(f64) -> bool + Send)) -> std::result::Result<R, E>,
) -> Result<R> {
    let mut cancelled = false;
    let out = draw(&mut |f| {
        let go = progress(&Progress {
            fraction: render_fraction(f),
            stage: Stage::Render,
        });
        cancelled |= !go;
        go
    });
    if cancelled {
        return Err(EngineError::Cancelled);
    }
    out.map_err(Into::into)
}

impl Renderer {
    /// The classification tables of `request` with `tf`, and whether they were built now.
    pub(super) fn tables(
        &mut self,
        request: &RenderRequest,
        tf: &TransferFunction,
    ) -> Result<(Arc<CrioTables>, bool)> {
        let got = cached(&mut self.tables, TablesKey::new(request, tf), || {
            Ok(Arc::new(build_tables(request, tf)?))
        })?;
        Ok((Arc::clone(got.value), got.fresh))
    }

    /// The tables `request` classifies with (its resolved transfer function), cached as a
    /// frame's: what rank 0 of a sort-last MIP/MinIP classifies the extreme values by
    /// ([`crate::distributed::render_sort_last`]).
    pub(crate) fn frame_tables(&mut self, request: &RenderRequest) -> Result<Arc<CrioTables>> {
        let tf = self.transfer_function(request)?;
        Ok(self.tables(request, &tf)?.0)
    }

    /// A Chapter 6 display of `kind` (Sabella's or a NIL-map display).
    pub(super) fn draw_display(
        &mut self,
        f: &Frame,
        kind: DisplayKind,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<Drawn> {
        let d = &f.request.display;
        let key = DisplayKey {
            volume: f.request.scene.volume.clone(),
            tf: f.tf.clone(),
            density: d.density,
            map_order: d.needs_map(kind).then_some(d.patch_order),
            max_map_values: d.max_map_values,
        };
        let mut budget_note = None;
        let got = cached(&mut self.display, key, || {
            Ok(Arc::new(display_state(f, kind, &mut budget_note)?))
        })?;
        let state = Arc::clone(got.value);
        let prepare_ms = f.prepare_ms(got.fresh);
        report(progress, 0.2, Stage::Render)?;
        let t_r = Instant::now();
        let settings = d.settings(kind);
        let (w, h) = (f.request.width, f.request.height);
        let img = forward(progress, |fwd| {
            f.pool.install(|| {
                render_display_with_progress(
                    &state.volume,
                    state.map.as_ref(),
                    f.camera,
                    w,
                    h,
                    &settings,
                    fwd,
                )
            })
        })?;
        let stats = Stats {
            prepare_ms,
            render_ms: ms(t_r),
            threads: f.pool.current_num_threads(),
            display: Some(DisplayStats {
                map_build_ms: state.map_build_ms,
                ..DisplayStats::from(&img.stats)
            }),
            ..Stats::default()
        };
        let mut drawn = Drawn::new(img.to_image(d.grey), None, stats);
        drawn.notes.extend(budget_note);
        Ok(drawn)
    }

    /// Image-aligned slabs (decisions 0016–0020) of the plan's pyramid level (0031), with the
    /// volume's bricks skipping empty space.
    pub(super) fn draw_slabs(
        &mut self,
        f: &Frame,
        plan: &SlabPlan,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<Drawn> {
        let (tables, fresh_tables) = self.tables(f.request, f.tf)?;
        let source = &f.request.scene.volume;
        let vol = f.volume;
        let bricks = cached(&mut self.bricks, source.clone(), || {
            Ok(Arc::new(f.pool.install(
                || volsplat_core::with_volume!(&**vol, v => BrickGrid::build(v)),
            )))
        })?;
        let fresh_bricks = bricks.fresh;
        let bricks = Arc::clone(bricks.value);
        let mut settings = f.request.splat_settings();
        settings.clip = f.request.scene.clipping.world_planes(vol.grid())?;
        settings.slab = plan.thickness;
        settings.owned_cells = f.owned_cells;
        // Coarse levels are built here, once per volume, so that their cost counts as
        // preparation.
        let pyramid = Arc::clone(
            cached(&mut self.pyramid, source.clone(), || {
                Ok(Arc::new(Pyramid::new(Arc::clone(vol))))
            })?
            .value,
        );
        let built = !pyramid.is_built(plan.level);
        if built {
            f.pool.install(|| pyramid.level(plan.level))?;
        }
        let prepare_ms = f.prepare_ms(fresh_tables || fresh_bricks || built);
        report(progress, 0.2, Stage::Render)?;
        let rendered = forward(progress, |fwd| {
            f.pool.install(|| {
                render_level(
                    &pyramid,
                    plan.level,
                    f.camera,
                    &tables,
                    &settings,
                    Some(&bricks),
                    &mut |p| fwd(sheets_done(p)),
                )
            })
        })?;
        let composite = f.request.mode == Mode::Composite;
        let stats = Stats {
            prepare_ms,
            ..slab_stats(&rendered.stats, plan, composite)
        };
        Ok(Drawn::new(rendered.image, rendered.values, stats))
    }

    /// The tables and settings of the splatting renderers (sheets and splat list), and whether
    /// the tables were built now. X-ray ignores the transfer function: its tables only tell the
    /// splat list which voxels to keep, those whose X-ray weight is not zero.
    fn splat_setup(
        &mut self,
        f: &Frame,
    ) -> Result<(Arc<CrioTables>, TablesKey, bool, RenderSettings)> {
        let table_tf = match f.request.mode {
            Mode::Xray => xray_weight_tf(f.xray_offset),
            _ => f.tf.clone(),
        };
        let (tables, fresh) = self.tables(f.request, &table_tf)?;
        let mut settings = f.request.splat_settings();
        settings.clip = f.request.scene.clipping.world_planes(f.volume.grid())?;
        settings.xray_offset = f.xray_offset.map(|o| o as f32);
        settings.owned_cells = f.owned_cells;
        // The sheets draw sheet-buffer visibility; `image` reaches them only where they draw
        // what the slabs do not (X-ray, or the splat list asked for by name).
        if f.request.quality.visibility == VisibilityChoice::Image {
            settings.visibility = Visibility::SheetBuffer;
        }
        Ok((
            tables,
            TablesKey::new(f.request, &table_tf),
            fresh,
            settings,
        ))
    }

    /// Westover's dense orthographic sheets, or the successive-refinement `ladder` of them.
    pub(super) fn draw_sheets(
        &mut self,
        f: &Frame,
        ladder: Option<Ladder<'_>>,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<Drawn> {
        let (tables, _, fresh, settings) = self.splat_setup(f)?;
        let prepare_ms = f.prepare_ms(fresh);
        report(progress, 0.2, Stage::Render)?;
        let vol = f.volume;
        let rendered = match ladder {
            Some(ladder) => draw_ladder(f, &tables, &settings, ladder)?,
            None => forward(progress, |fwd| {
                f.pool.install(|| {
                    volsplat_core::with_volume!(&**vol, v => render_with_progress(
                        v, f.camera, &tables, &settings, &mut |p| fwd(sheets_done(p))
                    ))
                })
            })?,
        };
        let stats = Stats {
            prepare_ms,
            ..splatting_stats(&rendered, &settings)
        };
        Ok(Drawn::new(rendered.image, rendered.values, stats))
    }

    /// The sparse splat list (built once per tables, threshold and subsampling), and the line
    /// at distance k where asked.
    pub(super) fn draw_list(
        &mut self,
        f: &Frame,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<Drawn> {
        let (tables, tables_key, mut fresh, settings) = self.splat_setup(f)?;
        let q = &f.request.quality;
        let voxels = ListVoxels::for_mode(settings.mode);
        let key = ListKey {
            volume: f.request.scene.volume.clone(),
            tables: tables_key,
            voxels,
            threshold: q.list_threshold.to_bits(),
            subsample: q.subsample,
        };
        let got = cached(&mut self.list, key, || {
            f.pool.install(|| {
                Ok(Arc::new(SplatList::build_any(f.volume, &tables, &{
                    let mut e = ExtractSettings::default();
                    e.threshold = q.list_threshold;
                    e.subsample = q.subsample;
                    e.voxels = voxels;
                    e
                })?))
            })
        })?;
        let list = Arc::clone(got.value);
        fresh |= got.fresh;
        let prepare_ms = f.prepare_ms(fresh);
        report(progress, 0.2, Stage::Render)?;
        let mut out = forward(progress, |fwd| {
            f.pool.install(|| {
                render_list_with_progress(&list, f.camera, &tables, &settings, &mut |p| {
                    fwd(sheets_done(p))
                })
            })
        })?;
        let mut warnings = Vec::new();
        if let Some(color) = f.request.k_contour {
            warnings.push(k_contour(
                f,
                &list,
                &tables,
                &settings,
                &mut out.image,
                color,
            )?);
        }
        let stats = Stats {
            prepare_ms,
            list_splats: Some(list.len()),
            list_bytes: Some(list.bytes()),
            list_build_ms: Some(list.build_ms()),
            ..splatting_stats(&out, &settings)
        };
        let mut drawn = Drawn::new(out.image, out.values, stats);
        drawn.warnings = warnings;
        Ok(drawn)
    }
}

/// The NIL-map display state of a frame: the display volume and, where the display evaluates
/// one, its NIL map, averaged down until the map fits the budget (decision 0015;
/// `budget_note` says so).
fn display_state(
    f: &Frame,
    kind: DisplayKind,
    budget_note: &mut Option<String>,
) -> Result<DisplayState> {
    let d = &f.request.display;
    let vol = f.volume;
    let mut dv = display_volume(vol, f.tf, d.density, 1)?;
    let tm = Instant::now();
    if !d.needs_map(kind) {
        return Ok(DisplayState {
            volume: dv,
            map: None,
            map_build_ms: ms(tm),
        });
    }
    let budget = if d.max_map_values == 0 {
        auto_map_budget()
    } else {
        d.max_map_values
    };
    let need = |dv: &DisplayVolume| {
        DiscreteNilMap::values_needed_for(dv.texture().dims(), d.patch_order, None, 1)
    };
    let full = need(&dv);
    let mut factor = 1;
    while need(&dv) > budget as u128 {
        factor += 1;
        if factor > 16 {
            return Err(EngineError::request(
                "display.max_map_values",
                format!(
                    "even a 16× coarser volume needs a NIL map larger than the budget of \
                     {budget} values; raise it"
                ),
            ));
        }
        dv = display_volume(vol, f.tf, d.density, factor)?;
    }
    if factor > 1 {
        let g = vol.grid().dims;
        *budget_note = Some(format!(
            "NIL map: the full {}×{}×{} volume needs {}, over the budget of {}; built from a \
             {factor}× coarser volume ({}). Raise the budget (display.max_map_values, \
             --max-map-values) for full resolution",
            g[0],
            g[1],
            g[2],
            map_size(full),
            map_size(budget as u128),
            map_size(need(&dv)),
        ));
    }
    let map = f
        .pool
        .install(|| build_map(&dv, d.patch_order, None, budget))?;
    Ok(DisplayState {
        volume: dv,
        map: Some(map),
        map_build_ms: ms(tm),
    })
}

/// The refinement ladder's rungs (Westover §4.2.3), each passed to the preview callback but
/// the last; the callback's `false` stops, its error is returned.
fn draw_ladder(
    f: &Frame,
    tables: &CrioTables,
    settings: &RenderSettings,
    ladder: Ladder<'_>,
) -> Result<Rendered> {
    let Ladder { steps, on_preview } = ladder;
    let last = steps.len().saturating_sub(1);
    let mut err = None;
    let vol = f.volume;
    let out = f.pool.install(|| {
        volsplat_core::with_volume!(&**vol, v => render_ladder(
            v, f.camera, tables, settings, steps,
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
    Ok(out?)
}

/// Draws the line at distance k = s·D/p from the eye (Swan et al. 1997 §5) onto `image`;
/// the warning that says where it is, or why there is none (orthographic views).
fn k_contour(
    f: &Frame,
    list: &SplatList,
    tables: &CrioTables,
    settings: &RenderSettings,
    image: &mut Image,
    color: [f32; 3],
) -> Result<String> {
    let (w, h) = (f.request.width, f.request.height);
    let q = &f.request.quality;
    let proj = Projection::new(f.camera, w, h)?;
    let grid = f.volume.grid();
    Ok(match k_distance(grid, q.subsample, &proj) {
        Some(k) => {
            let depth = f
                .pool
                .install(|| render_list_depth(list, f.camera, tables, settings))?;
            draw_depth_contour(image, &depth, k as f32, color)?;
            format!("k = s·D/p = {k:.4} world units from the eye")
        }
        None => format!(
            "k_contour: orthographic view, no distance k (every voxel covers {:.3} pixels)",
            grid.spacing.iter().fold(f64::INFINITY, |m, &v| m.min(v)) / proj.pixel_size_at(1.0)
        ),
    })
}

/// The stats of the splatting renderers (sheets and splat list): the library's counters, and
/// the kernel and anti-aliasing rule of the settings.
fn splatting_stats(rendered: &Rendered, settings: &RenderSettings) -> Stats {
    Stats {
        kernel: settings.kernel.name(),
        antialias: Some(settings.antialias.into()),
        ..Stats::from(&rendered.stats)
    }
}

/// The stats of the slabs: their counters (no footprints, no separate splat and composite
/// times: a sample is classified and composited where it is taken), the tent reconstruction,
/// area anti-aliasing where the view is minified (decision 0020), and the plan's lights and
/// level. Where the lights were evaluated, pre-integration and ring risk are composite's.
pub(super) fn slab_stats(
    s: &volsplat_splat::RenderStats,
    plan: &SlabPlan,
    composite: bool,
) -> Stats {
    let supersampled = s.supersampling > 1.0;
    Stats {
        render_ms: s.total_ms,
        setup_ms: s.setup_ms,
        classify_ms: s.classify_ms,
        voxels: s.voxels,
        splats: s.splats,
        splats_terminated: s.splats_terminated,
        pixel_updates: s.pixel_updates,
        kernel: "tent".into(),
        antialias: Some(if supersampled {
            AntialiasChoice::Area
        } else {
            AntialiasChoice::None
        }),
        supersampling: supersampled.then_some(s.supersampling),
        sheets: s.sheets,
        sheet_axis: Some(SheetAxis::View),
        sheet_spacing: s.sheet_spacing,
        shade_at: plan.shade_at.filter(|_| composite).map(Into::into),
        preintegrated: composite.then_some(s.preintegrated),
        ring_risk: composite.then_some(s.ring_risk),
        threads: s.threads,
        level: plan.level_report.map(|_| plan.level),
        level_spacing: plan.level_report.map(|r| r.spacing),
        focal_pixel: plan.level_report.map(|r| r.focal_pixel),
        ..Stats::default()
    }
}
