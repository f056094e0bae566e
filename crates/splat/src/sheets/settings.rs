//! The settings, statistics and progress types of the sheet renderer, shared by the splat-list
//! renderer and the image-aligned slabs, and the check of the settings.

use super::band::TILE;
use crate::aa::Antialias;
use crate::clip::ClipPlane;
use crate::error::{Result, SplatError};
use crate::footprint::FootprintSettings;
use crate::geometry::Order;
use std::time::Instant;
use volsplat_core::image::Rgba;
use volsplat_core::{Image, Kernel, ScalarImage};

/// What is computed along each view ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RenderMode {
    /// Emission–absorption compositing of classified, shaded samples (Westover's renderer).
    #[default]
    Composite,
    /// Maximum intensity projection of the reconstructed data (beyond the thesis).
    Mip,
    /// Minimum intensity projection of the reconstructed data.
    Minip,
    /// The line integral `∫ρ ds` of the reconstructed data, data units × world units.
    Xray,
}

/// How reconstruction and visibility are combined (Westover §3.8.1, §5.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Visibility {
    /// Sum each sheet's footprints in a sheet buffer, then composite the sheet (default).
    #[default]
    SheetBuffer,
    /// Composite every footprint directly (Westover 1989); bleeds, kept for comparison.
    EverySample,
    /// Image-aligned slabs, classified and shaded per pixel after reconstruction (Mueller &
    /// Crawfis 1998; Mueller, Möller & Crawfis 1999): [`crate::slab`]. Composite, MIP and MinIP;
    /// X-ray falls back to the sheet buffer, whose line integrals are exact.
    ImageAligned,
}

/// Everything that controls one render.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct RenderSettings {
    /// Image width, pixels (≥ 1).
    pub width: usize,
    /// Image height, pixels (≥ 1).
    pub height: usize,
    /// Ray function.
    pub mode: RenderMode,
    /// Sheet buffer or composite-every-sample (composite mode only).
    pub visibility: Visibility,
    /// Traversal order.
    pub order: Order,
    /// Reconstruction kernel (default: Westover's Gaussian σ = 0.6, radius 2).
    pub kernel: Kernel,
    /// Use every `subsample`-th voxel per axis (1, 2, 4, ...: successive refinement, §4.2.3).
    pub subsample: usize,
    /// Front-to-back composite only: pixels whose opacity reaches this value receive no further
    /// splats (early splat termination). `1.0` or more disables it. The default `1 − 2⁻²⁰`
    /// changes no pixel by more than 1e-6.
    pub opacity_cutoff: f32,
    /// Cull samples of zero opacity before reconstruction (Westover §5.2). Turning it off only
    /// costs time; the image is the same.
    pub cull_transparent: bool,
    /// Footprint table sizing.
    pub footprint: FootprintSettings,
    /// Scanlines per band of the parallel decomposition (fixed, so output does not depend on the
    /// thread count); a positive multiple of 4. The image-aligned slabs take at most 8 (their
    /// bands' work is uneven; their image does not depend on the band height).
    pub band_height: usize,
    /// Sheets classified together before the bands splat them.
    pub sheets_per_batch: usize,
    /// Use the CPU's vector instructions where they are detected at run time (AVX2 on x86-64, in
    /// the image-aligned slabs). `false` takes the scalar twins: the image is the same bits
    /// either way (the tests compare the two), only the speed differs. Default `true`.
    pub simd: bool,
    /// Anti-aliasing of footprints finer than a pixel (Swan et al. 1997; default
    /// [`Antialias::Swan`]). Changes nothing where every voxel spans at least a pixel.
    pub antialias: Antialias,
    /// Clipping planes (world frame; a crop box is six of them), cut smoothly by weighting each
    /// voxel with its kernel's share on the kept side ([`crate::clip`]). Empty: no clipping.
    pub clip: Vec<ClipPlane>,
    /// Image-aligned visibility only: slab thickness (plane spacing along the view), in units of
    /// the grid's smallest spacing, in [0.01, 16]; default [`crate::slab::DEFAULT_SLAB`].
    pub slab: f64,
    /// Image-aligned visibility, shaded composite: where the lights are evaluated
    /// ([`crate::normals::ShadeAt`]; default at every sample, the exact integral's order).
    pub shade_at: crate::normals::ShadeAt,
    /// Image-aligned visibility, composite through density tables (unshaded, or shaded at the
    /// voxels or at the samples; decision 0036): whether each slab is classified by the segment of the ray from the previous
    /// plane's sample to this one (pre-integrated classification, Engel, Kraus & Ertl 2001)
    /// instead of by its one sample ([`Preintegrate`]; default [`Preintegrate::Off`]).
    pub preintegrate: Preintegrate,
    /// X-ray only: what is integrated. `None` (default): the values as they are, `∫ ρ ds`.
    /// `Some(o)`: `∫ max(ρ + o, 0) ds`, data units shifted by `o` (finite) and clamped at zero
    /// before the kernel spreads them: with `o = 1000` on a CT in Hounsfield units, attenuation
    /// relative to air, `μ/μ_water · 1000` (a digitally reconstructed radiograph; air and
    /// padding below −1000 HU add nothing). See [`xray_weight`].
    pub xray_offset: Option<f32>,
    /// One brick's partial image of a sort-last render (issue 32, `volsplat::distributed`): draw
    /// only what belongs to the box of cells `[lo, hi)` (index units of the full-resolution grid,
    /// per axis). `None` (the default): everything.
    ///
    /// - Image-aligned slabs, composite, MIP and MinIP: the samples whose cell (the one its
    ///   trilinear interpolation reads) lies in the box; every sample keeps its global position,
    ///   slab factor and classification, so the bricks' partial images, composited front to back,
    ///   are the whole ray's, and the extreme of their MIPs (MinIPs) is the whole MIP (MinIP),
    ///   bit for bit. `lo` must be a multiple of 8 (the empty-space blocks) and `hi` too, or past
    ///   the last cell.
    /// - Sheet renderer and splat list, X-ray only: the voxels whose cell lies in the box, a
    ///   voxel's cell being the one of which it is the lower corner, `min(v, n − 2)` along an axis
    ///   of `n ≥ 2` voxels (the last voxel belongs to the last cell; 0 where `n = 1`). Every
    ///   voxel is drawn by exactly one box of a partition of the cells, so the boxes' X-rays sum
    ///   to the whole one (a line integral is linear in the voxels). Composite and MIP/MinIP are
    ///   refused there: a sheet buffer reconstructs a sheet from all its voxels before it is
    ///   composited or compared, which a partial sheet does not.
    pub owned_cells: Option<[[usize; 3]; 2]>,
}

/// The value an X-ray integrates for a sample of value `v` ([`RenderSettings::xray_offset`]):
/// `v`, or `max(v + o, 0)`.
#[inline(always)]
pub fn xray_weight(v: f32, offset: Option<f32>) -> f32 {
    match offset {
        Some(o) => (v + o).max(0.0),
        None => v,
    }
}

/// Pre-integrated classification in the image-aligned slabs ([`RenderSettings::preintegrate`];
/// `docs/decisions/0020-preintegration-for-sharp-ramps.md`). Pre-integration removes the rings
/// and popping that a transfer-function ramp much sharper than the data's steps leaves (a CT's
/// skin), but on noisy data the straight value path it assumes between two samples misses the
/// voxels' extremes, and a convex ramp then loses opacity (the decision has the measurements).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Preintegrate {
    /// One point per slab.
    #[default]
    Off,
    /// Every slab by its segment.
    On,
    /// By segment where the transfer function's steepest opacity ramp would change a slab's
    /// opacity by more than [`crate::slab::RING_RISK`] across a quarter of the data's value
    /// range ([`crate::slab::ring_risk`]), by point elsewhere.
    Auto,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 512,
            height: 512,
            mode: RenderMode::Composite,
            visibility: Visibility::SheetBuffer,
            order: Order::FrontToBack,
            kernel: Kernel::default(),
            subsample: 1,
            opacity_cutoff: 1.0 - 1.0 / (1u32 << 20) as f32,
            cull_transparent: true,
            footprint: FootprintSettings::default(),
            band_height: 32,
            sheets_per_batch: 8,
            simd: true,
            antialias: Antialias::default(),
            clip: Vec::new(),
            slab: crate::slab::DEFAULT_SLAB,
            shade_at: crate::normals::ShadeAt::Samples,
            preintegrate: Preintegrate::Off,
            xray_offset: None,
            owned_cells: None,
        }
    }
}

/// Per-stage timings and counters of one render (Westover Table 4.02).
#[derive(Debug, Clone, Default, PartialEq)]
#[non_exhaustive]
pub struct RenderStats {
    /// Frame set-up: geometry, footprint table, classifier tables (ms).
    pub setup_ms: f64,
    /// Transform + CRIO (classification and shading) wall time (ms).
    pub classify_ms: f64,
    /// Splatting into sheet buffers (ms; the splat/composite phase's wall time split in
    /// proportion to the CPU time of each).
    pub splat_ms: f64,
    /// Compositing sheets onto the accumulation buffer (ms; see `splat_ms`).
    pub composite_ms: f64,
    /// Whole render excluding file loading (ms).
    pub total_ms: f64,
    /// Lattice points visited.
    pub voxels: u64,
    /// Samples that survived culling and were splatted.
    pub splats: u64,
    /// Samples skipped because their whole footprint was already opaque (composite), or because
    /// they cannot change the projection (MIP/MinIP, the `mipcull` module).
    pub splats_terminated: u64,
    /// Perspective only: splats clipped at the near plane (behind or too close to the eye).
    pub splats_clipped: u64,
    /// Splats whose footprint anti-aliasing widened (beyond `k`, Swan et al. 1997 §4.3).
    pub splats_widened: u64,
    /// Pixel updates (multiply–adds of one RGBA weight) — Westover's kernel cost (§4.2.2).
    pub pixel_updates: u64,
    /// Number of sheets.
    pub sheets: usize,
    /// Sheet-normal axis (0 = i, 1 = j, 2 = k).
    pub sheet_axis: usize,
    /// World path length between sheets along the view.
    pub sheet_spacing: f64,
    /// Footprint table entries.
    pub footprint_entries: usize,
    /// Footprint sub-pixel phases per axis.
    pub footprint_phases: usize,
    /// Footprint half-extent in pixels (x, y).
    pub footprint_half_extent: [f64; 2],
    /// Threads in the rayon pool that ran the render.
    pub threads: usize,
    /// Image-aligned slabs: rays per pixel and axis area-averaged into each pixel (anti-aliasing
    /// of minified views, [`crate::slab`]; a fraction where the pixel is a fraction larger than
    /// a voxel); 0 or 1 means one ray per pixel.
    pub supersampling: f64,
    /// Image-aligned slabs, composite: whether the slabs were classified by segment
    /// ([`Preintegrate`]).
    pub preintegrated: bool,
    /// Image-aligned slabs, composite through a density table: the frame's
    /// [`crate::slab::ring_risk`], which [`Preintegrate::Auto`] compares with
    /// [`crate::slab::RING_RISK`] (0 otherwise).
    pub ring_risk: f64,
    /// Out-of-core slab frames (`render_slabs_bricked`): the steps whose bricks were made
    /// resident, one per group of bands or per piece of a group's planes (0 in memory).
    pub brick_steps: usize,
    /// Of those, the groups whose planes were marched in more than one piece because their
    /// bricks exceeded the budget.
    pub pieced_groups: usize,
    /// Of the pieced groups, those also marched in pieces of columns or rows, because one
    /// plane of their bands met more bricks than the budget holds (the same pixels; the
    /// counters differ, as each piece narrows its rows' live windows apart).
    pub split_groups: usize,
}

impl RenderStats {
    /// Average pixels touched per splat.
    pub fn kernel_cost(&self) -> f64 {
        if self.splats == 0 {
            0.0
        } else {
            self.pixel_updates as f64 / self.splats as f64
        }
    }
}

/// The result of a render.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Premultiplied RGBA image (no background). For MIP/MinIP, the projected value mapped through
    /// the emission and opacity tables (as VTK does); for X-ray, grey scaled to the maximum.
    pub image: Image,
    /// X-ray line integrals (data units × world units) or MIP/MinIP values (data units; NaN where
    /// no sample covers the pixel). `None` in composite mode.
    pub values: Option<ScalarImage>,
    /// Timings and counters.
    pub stats: RenderStats,
}

/// State passed to a progress callback after each batch of sheets (Westover §4.2.1).
#[non_exhaustive]
pub struct Progress<'a> {
    /// Sheets finished so far.
    pub sheets_done: usize,
    /// Sheets in the frame.
    pub sheets_total: usize,
    /// The accumulation buffer so far (premultiplied; row-major, width × height). In X-ray mode
    /// channel 0 holds the partial line integral; in MIP/MinIP channel 0 holds the running
    /// extreme (NaN where not yet covered).
    pub accumulation: &'a [Rgba],
}

/// Errors for [`Visibility::ImageAligned`] outside X-ray, for the sheet renderer and the splat
/// list: image-aligned slabs are another renderer ([`crate::slab::render_slabs`];
/// [`crate::render_by_visibility`] dispatches on the visibility), never drawn behind the
/// caller's back, nor silently replaced by a sheet buffer. X-ray keeps the sheet buffer, whose
/// line integrals are exact (the fallback [`Visibility::ImageAligned`] documents).
pub(crate) fn refuse_image_aligned(settings: &RenderSettings) -> Result<()> {
    if settings.visibility == Visibility::ImageAligned && settings.mode != RenderMode::Xray {
        return Err(SplatError::Setting {
            name: "visibility",
            value: "ImageAligned".into(),
            expected: "SheetBuffer or EverySample: the sheet renderer and the splat list do not \
                       draw image-aligned slabs (render_slabs does; render_by_visibility \
                       dispatches on the visibility)",
        });
    }
    Ok(())
}

pub(crate) fn validate(s: &RenderSettings) -> Result<()> {
    let bad = |name: &'static str, value: String, expected: &'static str| {
        Err(SplatError::Setting {
            name,
            value,
            expected,
        })
    };
    if s.width == 0 || s.height == 0 || (s.width as u128) * (s.height as u128) > 1 << 28 {
        return bad(
            "width × height",
            format!("{} × {}", s.width, s.height),
            "each side ≥ 1 and at most 2^28 pixels in all",
        );
    }
    if s.subsample == 0 {
        return bad("subsample", "0".into(), "a stride ≥ 1");
    }
    if s.band_height == 0 || !s.band_height.is_multiple_of(TILE) {
        return bad(
            "band_height",
            s.band_height.to_string(),
            "a positive multiple of 4 rows",
        );
    }
    if s.sheets_per_batch == 0 {
        return bad("sheets_per_batch", "0".into(), "≥ 1");
    }
    if s.opacity_cutoff.is_nan() || s.opacity_cutoff <= 0.0 {
        return bad(
            "opacity_cutoff",
            s.opacity_cutoff.to_string(),
            "an opacity > 0 (VTK stops rays at 0.9922)",
        );
    }
    if s.xray_offset.is_some_and(|o| !o.is_finite()) {
        return bad(
            "xray_offset",
            format!("{:?}", s.xray_offset),
            "a finite offset in data units (1000 for CT in Hounsfield units)",
        );
    }
    if s.footprint.max_entries == 0 {
        return bad("footprint.max_entries", "0".into(), "≥ 1");
    }
    if s.footprint.max_phases == 0 {
        return bad("footprint.max_phases", "0".into(), "≥ 1");
    }
    if let Some(p) = s.clip.iter().find(|p| !p.is_valid()) {
        return bad(
            "clip",
            format!("normal {:?}, offset {}", p.normal, p.offset),
            "a plane needs a finite, non-zero normal and a finite offset",
        );
    }
    Ok(())
}

/// The voxels a voxel-driven renderer (the sheets, the splat list) draws for
/// [`RenderSettings::owned_cells`]: voxel `v` along axis `a` belongs to cell
/// `min(v, n_a − 2)`, and is drawn where that cell lies in `[lo, hi)` on every axis.
#[derive(Debug, Clone, Copy)]
pub(crate) struct OwnedVoxels {
    lo: [usize; 3],
    hi: [usize; 3],
    /// Per axis, the cell of the last voxel: `n − 2` (0 where `n < 2`).
    last_cell: [usize; 3],
}

impl OwnedVoxels {
    /// The restriction of `settings` for a volume of `dims` voxels (full resolution): `None`
    /// where every voxel is drawn. Errors (naming `owned_cells`) outside X-ray or for an empty
    /// box.
    pub(crate) fn new(settings: &RenderSettings, dims: [usize; 3]) -> Result<Option<Self>> {
        let Some([lo, hi]) = settings.owned_cells else {
            return Ok(None);
        };
        if settings.mode != RenderMode::Xray || (0..3).any(|a| lo[a] >= hi[a]) {
            return Err(SplatError::Setting {
                name: "owned_cells",
                value: format!("{lo:?}..{hi:?} ({:?})", settings.mode),
                expected: "X-ray and a non-empty box in the sheet renderer and the splat list \
                           (composite is the image-aligned slabs'; a sheet buffer does not \
                           composite partial sheets)",
            });
        }
        Ok(Some(OwnedVoxels {
            lo,
            hi,
            last_cell: dims.map(|n| n.saturating_sub(2)),
        }))
    }

    /// Whether voxel index `v` (full resolution) along `axis` lies in the box.
    #[inline(always)]
    pub(crate) fn owns(&self, axis: usize, v: usize) -> bool {
        let c = v.min(self.last_cell[axis]);
        c >= self.lo[axis] && c < self.hi[axis]
    }

    /// Whether the voxel `ijk` (full resolution) lies in the box.
    #[inline(always)]
    pub(crate) fn owns_voxel(&self, ijk: [usize; 3]) -> bool {
        (0..3).all(|a| self.owns(a, ijk[a]))
    }
}

pub(crate) fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
