//! Which renderer draws a request, and how: [`plan`], a pure function of the request, the
//! camera, the volume's grid and what the classification tables say (decisions 0016–0020 and
//! 0031 in `docs/decisions/`). Its rows, in the order they are tried (each row is a test below):
//!
//! | # | request | [`UsedRenderer`] | test |
//! |---|---|---|---|
//! | 1 | `renderer: "sabella"` | `Sabella` (clipping refused) | `row_1_2_displays` |
//! | 2 | `renderer: "nil"` | `Nil` (clipping refused) | `row_1_2_displays` |
//! | 3 | `renderer: "sheets"`, perspective | error (`renderer`) | `row_3_sheets_refuse_perspective` |
//! | 4 | `renderer: "sheets"`, `visibility: "image"`, not X-ray | `Slab` | `row_4_sheets_with_image_visibility_draw_slabs` |
//! | 5 | `renderer: "sheets"` otherwise | `Sheets` | `row_5_sheets` |
//! | 6 | `renderer: "splat_list"` | `SplatList`, either projection, any visibility | `row_6_splat_list` |
//! | 7 | `auto`, X-ray | `Sheets` orthographic, `SplatList` perspective (exact line integrals) | `row_7_xray_keeps_the_sheets` |
//! | 8 | `auto`, `visibility: "image"` | `Slab` whatever the options | `row_8_image_visibility` |
//! | 9 | `auto`, `visibility: "sheet"` or `"every"` | `Sheets` / `SplatList` by projection | `row_9_sheet_visibility` |
//! | 10 | `auto`, `visibility: "auto"`, an option only the sheets have: refinement ladder, `k_contour`, `subsample` > 1, `order: "btf"`, a kernel other than the Gaussian, `antialias: "swan-perpendicular"` or `"ewa"` | `Sheets` / `SplatList` by projection | `row_10_sheet_only_options` |
//! | 11 | `auto`, `visibility: "auto"`, shaded composite with `shade_at: "auto"` (the default) or `"voxels"` and a transfer function that depends on more than the density, which the slabs' kernel cannot light (decisions 0019, 0036) | `Sheets` / `SplatList` by projection | `row_11_voxel_lighting_beyond_the_slabs_keeps_the_sheets` |
//! | 12 | `auto`, `visibility: "auto"` otherwise: unshaded composite, composite lit at the samples (`shade_at: "auto"` with a transfer function of the density, lit twice per slab, decision 0036; or `"samples"`: the slabs light the samples themselves, issue 33), composite lit at the voxels, MIP, MinIP (decision 0016) | `Slab` | `row_12_auto_draws_slabs` |
//!
//! Then the checks: a refinement ladder needs `Sheets`, `k_contour` needs `SplatList`
//! (`checks_name_the_field`); `quality.level` above 0 with another renderer than `Slab` is a
//! warning (`level_is_the_slabs_alone`). A `Slab` plan ([`SlabPlan`]) also fixes where the
//! lights are evaluated (decisions 0019, 0036: [`shading`]), the slab thickness (`quality.slab`, else by mode:
//! decision 0017) and the pyramid level (decision 0031; `slab_plan_*` tests).

use super::stats::UsedRenderer;
use crate::error::{EngineError, Result};
use crate::request::{
    AntialiasChoice, KernelChoice, Mode, OrderChoice, RenderRequest, RendererChoice, ShadeAtChoice,
    VisibilityChoice, VolumeLevel,
};
use volsplat_core::{Camera, CrioTables, Grid, ProjectionKind};
use volsplat_filter::display::DisplayKind;
use volsplat_splat::ShadeAt;

/// What the classification tables say that the choice depends on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Classification {
    /// The tables shade (they need gradients).
    pub(crate) needs_gradient: bool,
    /// The classification depends on the density alone (no gradient-magnitude opacity or
    /// surface enhancement), so the voxels can be shaded before interpolation.
    pub(crate) density_only: bool,
}

impl From<&CrioTables> for Classification {
    fn from(t: &CrioTables) -> Classification {
        Classification {
            needs_gradient: t.needs_gradient(),
            density_only: t.density_only(),
        }
    }
}

/// How a request is drawn.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Plan {
    /// The renderer that draws it.
    pub(crate) renderer: UsedRenderer,
    /// The camera's projection.
    pub(crate) projection: ProjectionKind,
    /// What that renderer needs beyond the request.
    pub(crate) draw: Draw,
    /// Warnings for the user (an option the renderer does not use).
    pub(crate) warnings: Vec<String>,
}

/// The renderer-specific part of a [`Plan`].
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Draw {
    /// A Chapter 6 display of this kind.
    Display(DisplayKind),
    /// Image-aligned slabs.
    Slabs(SlabPlan),
    /// The dense sheets (or their successive-refinement ladder, where one was given).
    Sheets,
    /// The splat list.
    SplatList,
}

/// How the slabs draw a request.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SlabPlan {
    /// Where the lights are evaluated: `None` unshaded (decision 0019).
    pub(crate) shade_at: Option<ShadeAt>,
    /// Slab thickness, in units of the smallest grid spacing (decision 0017).
    pub(crate) thickness: f64,
    /// The pyramid level drawn, 0 for the full volume (decision 0031).
    pub(crate) level: usize,
    /// Reported in the stats where a level was asked for (`quality.level` not `full`).
    pub(crate) level_report: Option<LevelReport>,
}

/// The level the slabs drew, for the stats.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LevelReport {
    /// The smallest spacing of the level drawn, world units.
    pub(crate) spacing: f64,
    /// The size of a pixel at the focal point, world units.
    pub(crate) focal_pixel: f64,
}

/// The plan for `request` seen by `camera` over a volume on `grid`; `refine`: drawn by the
/// refinement ladder. `tables` is asked (at most once) only where the choice or the slab plan
/// depends on the classification; it may build and keep the tables. The rows of the module's
/// table, in order.
pub(crate) fn plan(
    request: &RenderRequest,
    camera: &Camera,
    grid: &Grid,
    refine: bool,
    tables: &mut dyn FnMut() -> Result<Classification>,
) -> Result<Plan> {
    let mut memo = None;
    let mut classification = || -> Result<Classification> {
        if let Some(c) = memo {
            return Ok(c);
        }
        let c = tables()?;
        memo = Some(c);
        Ok(c)
    };
    let projection = if camera.parallel_projection {
        ProjectionKind::Orthographic
    } else {
        ProjectionKind::Perspective
    };
    let renderer = choose(request, projection, refine, &mut classification)?;
    check(request, renderer, refine)?;
    let mut warnings = Vec::new();
    if matches!(request.quality.level, VolumeLevel::Level(n) if n > 0)
        && renderer != UsedRenderer::Slab
    {
        warnings.push(format!(
            "quality.level {} applies to the image-aligned slab renderer; the {} drew the full \
             volume",
            request.quality.level,
            renderer.name()
        ));
    }
    if matches!(renderer, UsedRenderer::Sheets | UsedRenderer::SplatList)
        && request.mode == Mode::Composite
        && request.quality.shade_at == ShadeAtChoice::Samples
        && classification()?.needs_gradient
    {
        warnings.push(format!(
            "shade_at samples: the {} lights each voxel before splatting, not the samples \
             between them; the image-aligned slabs light the samples (visibility image or auto)",
            renderer.name()
        ));
    }
    let draw = match renderer {
        UsedRenderer::Sabella | UsedRenderer::Nil => {
            Draw::Display(request.display.kind(request.renderer))
        }
        UsedRenderer::Slab => {
            let c = classification()?;
            Draw::Slabs(slab_plan(request, camera, grid, c, &mut warnings)?)
        }
        UsedRenderer::Sheets => Draw::Sheets,
        UsedRenderer::SplatList => Draw::SplatList,
    };
    Ok(Plan {
        renderer,
        projection,
        draw,
        warnings,
    })
}

/// Rows 1–12: the renderer.
fn choose(
    request: &RenderRequest,
    projection: ProjectionKind,
    refine: bool,
    classification: &mut dyn FnMut() -> Result<Classification>,
) -> Result<UsedRenderer> {
    let ortho = projection == ProjectionKind::Orthographic;
    let splatting = if ortho {
        UsedRenderer::Sheets
    } else {
        UsedRenderer::SplatList
    };
    Ok(match request.renderer {
        RendererChoice::Sabella => UsedRenderer::Sabella,
        RendererChoice::Nil => UsedRenderer::Nil,
        RendererChoice::Sheets if !ortho => {
            return Err(EngineError::request(
                "renderer",
                "the dense `sheets` renderer draws orthographic views only; use `auto` or \
                 `splat_list` for perspective",
            ));
        }
        RendererChoice::Sheets if image_slabs(request) => UsedRenderer::Slab,
        RendererChoice::Sheets => UsedRenderer::Sheets,
        RendererChoice::SplatList => UsedRenderer::SplatList,
        RendererChoice::Auto => match request.quality.visibility {
            _ if request.mode == Mode::Xray => splatting,
            VisibilityChoice::Image => UsedRenderer::Slab,
            VisibilityChoice::Sheet | VisibilityChoice::Every => splatting,
            VisibilityChoice::Auto if sheet_only_option(request, refine) => splatting,
            VisibilityChoice::Auto => {
                // Row 11: lit at the voxels or `auto` (the default) with tables that depend on
                // more than the density, which the slabs' kernel cannot light (their per-sample
                // classifier can, several times slower): the sheets, which classify and light
                // each voxel. Lights asked at the samples go to the slabs (row 12), the one
                // renderer that lights the samples themselves (issue 33: the sheets were further
                // from the exact integral than VTK).
                let c = classification()?;
                let voxels_beyond_the_slabs = request.mode == Mode::Composite
                    && request.quality.shade_at != ShadeAtChoice::Samples
                    && c.needs_gradient
                    && !c.density_only;
                if voxels_beyond_the_slabs {
                    splatting
                } else {
                    UsedRenderer::Slab
                }
            }
        },
    })
}

/// Visibility `image` outside X-ray (whose line integrals the sheets draw exactly): the slabs.
fn image_slabs(request: &RenderRequest) -> bool {
    request.quality.visibility == VisibilityChoice::Image && request.mode != Mode::Xray
}

/// Row 10: an option that only the sheet renderers have.
fn sheet_only_option(request: &RenderRequest, refine: bool) -> bool {
    let q = &request.quality;
    refine
        || request.k_contour.is_some()
        || q.subsample != 1
        || q.order != OrderChoice::Ftb
        || q.kernel != KernelChoice::Gaussian
        || matches!(
            q.antialias,
            AntialiasChoice::SwanPerpendicular | AntialiasChoice::Ewa
        )
}

/// What the renderer cannot do of what was asked.
fn check(request: &RenderRequest, renderer: UsedRenderer, refine: bool) -> Result<()> {
    if refine && renderer != UsedRenderer::Sheets {
        return Err(EngineError::request(
            "renderer",
            "successive refinement works with the dense orthographic sheet renderer only",
        ));
    }
    if request.k_contour.is_some() && renderer != UsedRenderer::SplatList {
        return Err(EngineError::request(
            "k_contour",
            "the line at distance k needs the splat-list renderer (perspective or splat_list)",
        ));
    }
    if matches!(renderer, UsedRenderer::Sabella | UsedRenderer::Nil)
        && !request.scene.clipping.is_empty()
    {
        return Err(EngineError::request(
            "scene.clipping",
            "cropping and clipping planes apply to the splatting renderers; the Chapter 6 \
             displays (sabella, nil) do not cut the volume",
        ));
    }
    Ok(())
}

/// Where the slab renderer evaluates the lights for these tables (decisions 0019, 0036):
/// `None` unshaded (no gradient needed), at the voxels where asked and the classification
/// depends on the density alone, at the samples otherwise: by the kernel, lit twice per slab,
/// for tables of the density (`auto`'s choice), by the per-sample classifier for the others.
pub(crate) fn shading(asked: ShadeAtChoice, c: Classification) -> Option<ShadeAt> {
    if !c.needs_gradient {
        None
    } else if asked == ShadeAtChoice::Voxels && c.density_only {
        Some(ShadeAt::Voxels)
    } else {
        Some(ShadeAt::Samples)
    }
}

/// The slab thickness, lights and pyramid level of a `Slab` plan; a level beyond the volume's
/// pyramid is drawn at its coarsest, with a warning.
fn slab_plan(
    request: &RenderRequest,
    camera: &Camera,
    grid: &Grid,
    c: Classification,
    warnings: &mut Vec<String>,
) -> Result<SlabPlan> {
    let shade_at = shading(request.quality.shade_at, c);
    let thickness = request
        .quality
        .slab
        .unwrap_or_else(|| volsplat_splat::slab::default_slab(request.mode.splat_mode(), shade_at));
    // The level (decision 0031), from the level grids alone: nothing is built to choose. `auto`
    // is the level whose voxel is about a pixel at the focal point.
    let asked = request.quality.level;
    let focal_pixel = volsplat_splat::focal_pixel_size(camera, request.width, request.height)?;
    let grids = volsplat_splat::pyramid::level_grids(grid);
    let wanted = match asked {
        VolumeLevel::Full => 0,
        VolumeLevel::Level(n) => usize::from(n),
        VolumeLevel::Auto => volsplat_splat::auto_level(focal_pixel, &grids),
    };
    let level = wanted.min(grids.len() - 1);
    if let VolumeLevel::Level(n) = asked
        && usize::from(n) > level
    {
        warnings.push(format!(
            "quality.level {n}: the volume's pyramid ends at level {level}; drew level {level}"
        ));
    }
    let level_report = (!asked.is_full()).then(|| LevelReport {
        spacing: grids[level]
            .spacing
            .iter()
            .fold(f64::INFINITY, |m, &v| m.min(v)),
        focal_pixel,
    });
    Ok(SlabPlan {
        shade_at,
        thickness,
        level,
        level_report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Scene;

    const UNSHADED: Classification = Classification {
        needs_gradient: false,
        density_only: true,
    };
    const SHADED: Classification = Classification {
        needs_gradient: true,
        density_only: true,
    };
    const SHADED_BY_GRADIENT: Classification = Classification {
        needs_gradient: true,
        density_only: false,
    };

    fn grid() -> Grid {
        Grid::with_dims([64, 64, 64]).unwrap()
    }

    fn camera(perspective: bool) -> Camera {
        let (lo, hi) = grid().bounds_world();
        let mut c = Camera::reset_to_bounds(lo, hi, !perspective);
        c.view_angle = 30.0;
        c
    }

    fn request() -> RenderRequest {
        RenderRequest::new(Scene::default(), 64, 64)
    }

    /// The plan with tables classified as `c`, and how often the tables were asked.
    fn plan_with(
        r: &RenderRequest,
        perspective: bool,
        refine: bool,
        c: Classification,
    ) -> (Result<Plan>, usize) {
        let mut asked = 0;
        let p = plan(r, &camera(perspective), &grid(), refine, &mut || {
            asked += 1;
            Ok(c)
        });
        (p, asked)
    }

    fn used(r: &RenderRequest, perspective: bool, c: Classification) -> UsedRenderer {
        plan_with(r, perspective, false, c).0.unwrap().renderer
    }

    fn field(e: EngineError) -> String {
        match e {
            EngineError::Request { field, .. } => field,
            e => panic!("not a request error: {e}"),
        }
    }

    #[test]
    fn row_1_2_displays() {
        for (choice, want) in [
            (RendererChoice::Sabella, UsedRenderer::Sabella),
            (RendererChoice::Nil, UsedRenderer::Nil),
        ] {
            let mut r = request();
            r.renderer = choice;
            for perspective in [false, true] {
                let (p, asked) = plan_with(&r, perspective, false, SHADED);
                let p = p.unwrap();
                assert_eq!(p.renderer, want);
                assert_eq!(p.draw, Draw::Display(r.display.kind(choice)));
                assert_eq!(asked, 0, "a display builds no CRIO tables");
            }
            r.scene.clipping.planes.push(crate::PlaneSpec {
                normal: [0.0, 0.0, 1.0],
                offset: 0.0,
            });
            let e = plan_with(&r, false, false, SHADED).0.unwrap_err();
            assert_eq!(field(e), "scene.clipping");
        }
    }

    #[test]
    fn row_3_sheets_refuse_perspective() {
        let mut r = request();
        r.renderer = RendererChoice::Sheets;
        for visibility in [VisibilityChoice::Auto, VisibilityChoice::Image] {
            r.quality.visibility = visibility;
            let e = plan_with(&r, true, false, SHADED).0.unwrap_err();
            assert_eq!(field(e), "renderer");
        }
    }

    #[test]
    fn row_4_sheets_with_image_visibility_draw_slabs() {
        let mut r = request();
        r.renderer = RendererChoice::Sheets;
        r.quality.visibility = VisibilityChoice::Image;
        assert_eq!(used(&r, false, SHADED), UsedRenderer::Slab);
        r.mode = Mode::Xray;
        assert_eq!(used(&r, false, SHADED), UsedRenderer::Sheets);
    }

    #[test]
    fn row_5_sheets() {
        let mut r = request();
        r.renderer = RendererChoice::Sheets;
        for visibility in [
            VisibilityChoice::Auto,
            VisibilityChoice::Sheet,
            VisibilityChoice::Every,
        ] {
            r.quality.visibility = visibility;
            let (p, asked) = plan_with(&r, false, false, UNSHADED);
            let p = p.unwrap();
            assert_eq!(p.renderer, UsedRenderer::Sheets);
            assert_eq!(p.draw, Draw::Sheets);
            assert_eq!(p.projection, ProjectionKind::Orthographic);
            assert_eq!(asked, 0);
        }
    }

    #[test]
    fn row_6_splat_list() {
        let mut r = request();
        r.renderer = RendererChoice::SplatList;
        for visibility in [VisibilityChoice::Auto, VisibilityChoice::Image] {
            r.quality.visibility = visibility;
            for perspective in [false, true] {
                assert_eq!(used(&r, perspective, UNSHADED), UsedRenderer::SplatList);
            }
        }
        let p = plan_with(&r, true, false, UNSHADED).0.unwrap();
        assert_eq!(p.projection, ProjectionKind::Perspective);
        assert_eq!(p.draw, Draw::SplatList);
    }

    #[test]
    fn row_7_xray_keeps_the_sheets() {
        let mut r = request();
        r.mode = Mode::Xray;
        for visibility in [VisibilityChoice::Auto, VisibilityChoice::Image] {
            r.quality.visibility = visibility;
            assert_eq!(used(&r, false, UNSHADED), UsedRenderer::Sheets);
            assert_eq!(used(&r, true, UNSHADED), UsedRenderer::SplatList);
        }
    }

    #[test]
    fn row_8_image_visibility() {
        let mut r = request();
        r.quality.visibility = VisibilityChoice::Image;
        r.quality.kernel = KernelChoice::Nearest;
        r.quality.shade_at = ShadeAtChoice::Samples;
        for mode in [Mode::Composite, Mode::Mip, Mode::Minip] {
            r.mode = mode;
            for perspective in [false, true] {
                assert_eq!(used(&r, perspective, SHADED), UsedRenderer::Slab);
            }
        }
    }

    #[test]
    fn row_9_sheet_visibility() {
        let mut r = request();
        for visibility in [VisibilityChoice::Sheet, VisibilityChoice::Every] {
            r.quality.visibility = visibility;
            assert_eq!(used(&r, false, UNSHADED), UsedRenderer::Sheets);
            assert_eq!(used(&r, true, UNSHADED), UsedRenderer::SplatList);
        }
    }

    #[test]
    fn row_10_sheet_only_options() {
        let base = request();
        let mut cases: Vec<RenderRequest> = Vec::new();
        let mut r = base.clone();
        r.quality.subsample = 2;
        cases.push(r);
        let mut r = base.clone();
        r.quality.order = OrderChoice::Btf;
        cases.push(r);
        let mut r = base.clone();
        r.quality.kernel = KernelChoice::Nearest;
        cases.push(r);
        for aa in [AntialiasChoice::SwanPerpendicular, AntialiasChoice::Ewa] {
            let mut r = base.clone();
            r.quality.antialias = aa;
            cases.push(r);
        }
        for r in &cases {
            let (p, asked) = plan_with(r, false, false, UNSHADED);
            assert_eq!(p.unwrap().renderer, UsedRenderer::Sheets, "{:?}", r.quality);
            assert_eq!(asked, 0, "the sheets are chosen without the tables");
            assert_eq!(used(r, true, UNSHADED), UsedRenderer::SplatList);
        }
        // The ladder: the sheets (orthographic), and the other rules still refuse it.
        let p = plan_with(&base, false, true, UNSHADED).0.unwrap();
        assert_eq!(p.draw, Draw::Sheets);
        // `k_contour`: the splat list in perspective.
        let mut r = base.clone();
        r.k_contour = Some([1.0, 0.0, 0.0]);
        assert_eq!(used(&r, true, UNSHADED), UsedRenderer::SplatList);
        // Anti-aliasing the slabs also have keeps them.
        for aa in [
            AntialiasChoice::Area,
            AntialiasChoice::None,
            AntialiasChoice::Swan,
        ] {
            let mut r = base.clone();
            r.quality.antialias = aa;
            assert_eq!(used(&r, false, UNSHADED), UsedRenderer::Slab, "{aa:?}");
        }
    }

    #[test]
    fn row_11_voxel_lighting_beyond_the_slabs_keeps_the_sheets() {
        let mut r = request();
        for at in [ShadeAtChoice::Auto, ShadeAtChoice::Voxels] {
            r.quality.shade_at = at;
            assert_eq!(used(&r, false, SHADED_BY_GRADIENT), UsedRenderer::Sheets);
            assert_eq!(used(&r, true, SHADED_BY_GRADIENT), UsedRenderer::SplatList);
            // Tables of the density: the slabs (row 12).
            assert_eq!(used(&r, false, SHADED), UsedRenderer::Slab);
        }
        // Lights asked at the samples: the slabs light them (row 12), whatever the tables.
        r.quality.shade_at = ShadeAtChoice::Samples;
        for tables in [SHADED, SHADED_BY_GRADIENT] {
            assert_eq!(used(&r, false, tables), UsedRenderer::Slab);
            assert_eq!(used(&r, true, tables), UsedRenderer::Slab);
        }
        r.quality.shade_at = ShadeAtChoice::Voxels;
        // MIP and MinIP are unlit: the slabs whatever the tables.
        r.mode = Mode::Mip;
        assert_eq!(used(&r, false, SHADED_BY_GRADIENT), UsedRenderer::Slab);
    }

    #[test]
    fn row_12_auto_draws_slabs() {
        let mut r = request();
        // `auto` lights the samples where the kernel can (decision 0036), `voxels` the voxels.
        for (c, at, shade_at) in [
            (UNSHADED, ShadeAtChoice::Auto, None),
            (SHADED, ShadeAtChoice::Auto, Some(ShadeAt::Samples)),
            (SHADED, ShadeAtChoice::Voxels, Some(ShadeAt::Voxels)),
        ] {
            r.quality.shade_at = at;
            for perspective in [false, true] {
                let (p, asked) = plan_with(&r, perspective, false, c);
                let p = p.unwrap();
                assert_eq!(p.renderer, UsedRenderer::Slab);
                assert_eq!(asked, 1, "the tables are classified once");
                let Draw::Slabs(s) = p.draw else {
                    panic!("{:?}", p.draw)
                };
                assert_eq!(s.shade_at, shade_at);
            }
        }
        for mode in [Mode::Mip, Mode::Minip] {
            let mut r = request();
            r.mode = mode;
            assert_eq!(used(&r, false, SHADED), UsedRenderer::Slab);
        }
    }

    #[test]
    fn checks_name_the_field() {
        // A ladder with anything but the sheets.
        let mut r = request();
        r.quality.visibility = VisibilityChoice::Image;
        let e = plan_with(&r, false, true, UNSHADED).0.unwrap_err();
        assert_eq!(field(e), "renderer");
        let e = plan_with(&request(), true, true, UNSHADED).0.unwrap_err();
        assert_eq!(field(e), "renderer");
        // `k_contour` with the sheets (orthographic).
        let mut r = request();
        r.k_contour = Some([1.0, 0.0, 0.0]);
        let e = plan_with(&r, false, false, UNSHADED).0.unwrap_err();
        assert_eq!(field(e), "k_contour");
    }

    #[test]
    fn level_is_the_slabs_alone() {
        let mut r = request();
        r.quality.level = VolumeLevel::Level(1);
        r.quality.visibility = VisibilityChoice::Sheet;
        let p = plan_with(&r, false, false, UNSHADED).0.unwrap();
        assert_eq!(p.warnings.len(), 1);
        assert!(
            p.warnings[0].contains("sheet renderer drew the full volume"),
            "{:?}",
            p.warnings
        );
        r.quality.level = VolumeLevel::Auto;
        assert!(
            plan_with(&r, false, false, UNSHADED)
                .0
                .unwrap()
                .warnings
                .is_empty()
        );
    }

    /// Lights asked at the samples where the sheets or the splat list draw (visibility
    /// `sheet`, or an option only they have) are not silently lit at the voxels: a warning
    /// says so and names the renderer that lights the samples. Unshaded, MIP, or lit at the
    /// voxels: nothing to say.
    #[test]
    fn samples_lit_by_the_sheets_are_said() {
        let mut r = request();
        r.quality.shade_at = ShadeAtChoice::Samples;
        r.quality.visibility = VisibilityChoice::Sheet;
        for perspective in [false, true] {
            let p = plan_with(&r, perspective, false, SHADED).0.unwrap();
            assert_eq!(p.warnings.len(), 1, "{:?}", p.warnings);
            assert!(
                p.warnings[0].starts_with("shade_at samples: the ")
                    && p.warnings[0].contains("image-aligned slabs light the samples"),
                "{:?}",
                p.warnings
            );
        }
        let quiet = |r: &RenderRequest, c| plan_with(r, false, false, c).0.unwrap().warnings;
        assert!(quiet(&r, UNSHADED).is_empty());
        let mut mip = r.clone();
        mip.mode = Mode::Mip;
        assert!(quiet(&mip, SHADED).is_empty());
        let mut voxels = r.clone();
        voxels.quality.shade_at = ShadeAtChoice::Voxels;
        assert!(quiet(&voxels, SHADED).is_empty());
        let mut slabs = r.clone();
        slabs.quality.visibility = VisibilityChoice::Auto;
        assert!(quiet(&slabs, SHADED).is_empty());
    }

    fn slab_plan_of(r: &RenderRequest, c: Classification) -> (SlabPlan, Vec<String>) {
        let p = plan_with(r, false, false, c).0.unwrap();
        match p.draw {
            Draw::Slabs(s) => (s, p.warnings),
            d => panic!("{d:?}"),
        }
    }

    /// Decisions 0017, 0019 and 0036: one voxel for composite (unshaded, shaded at the voxels
    /// or at the samples, the latter lit twice per slab), half a voxel for MIP and MinIP; an
    /// explicit thickness wins.
    #[test]
    fn slab_plan_thickness_by_mode() {
        let mut r = request();
        r.quality.visibility = VisibilityChoice::Image;
        assert_eq!(slab_plan_of(&r, UNSHADED).0.thickness, 1.0);
        assert_eq!(slab_plan_of(&r, SHADED).0.thickness, 1.0);
        let (s, _) = slab_plan_of(&r, SHADED_BY_GRADIENT);
        assert_eq!((s.thickness, s.shade_at), (1.0, Some(ShadeAt::Samples)));
        r.mode = Mode::Mip;
        assert_eq!(slab_plan_of(&r, UNSHADED).0.thickness, 0.5);
        r.quality.slab = Some(2.0);
        assert_eq!(slab_plan_of(&r, UNSHADED).0.thickness, 2.0);
    }

    /// Decision 0031: the full volume unless asked; a level beyond the pyramid is its coarsest,
    /// with a warning; `auto` the level whose voxel is about a pixel; reported unless `full`.
    #[test]
    fn slab_plan_levels() {
        let mut r = request();
        let (s, w) = slab_plan_of(&r, UNSHADED);
        assert_eq!((s.level, s.level_report, w.len()), (0, None, 0));
        let levels = volsplat_splat::pyramid::level_grids(&grid()).len();
        r.quality.level = VolumeLevel::Level(1);
        let (s, w) = slab_plan_of(&r, UNSHADED);
        assert_eq!((s.level, w.len()), (1, 0));
        assert_eq!(s.level_report.unwrap().spacing, 2.0);
        r.quality.level = VolumeLevel::Level(40);
        let (s, w) = slab_plan_of(&r, UNSHADED);
        assert_eq!(s.level, levels - 1);
        assert!(w[0].contains("pyramid ends at level"), "{w:?}");
        // 64 voxels across a 16-pixel image: a pixel is about four voxels, so `auto` draws
        // level 2 (spacing 4 ≤ √2 × pixel).
        r.width = 16;
        r.height = 16;
        r.quality.level = VolumeLevel::Auto;
        let (s, _) = slab_plan_of(&r, UNSHADED);
        let report = s.level_report.unwrap();
        assert_eq!(
            s.level,
            volsplat_splat::auto_level(
                report.focal_pixel,
                &volsplat_splat::pyramid::level_grids(&grid())
            )
        );
        assert!(s.level >= 1, "{s:?}");
        r.quality.level = VolumeLevel::Level(0);
        assert_eq!(slab_plan_of(&r, UNSHADED).0.level_report, None);
    }
}
