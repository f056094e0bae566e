//! The sheet renderer's own part: every lattice point of each sheet classified, and splatted through
//! the frame's footprint table (Westover 1991, Ch. 3–5).

use super::band::{
    BandState, SINK_LINE, SINK_OVER_BTF, SINK_OVER_FTB, SINK_SHEET, Sink, SpanCtx, Splat, TILE,
    deposit, div_band, scale_kept,
};
use super::driver::{SheetPass, drive};
use super::settings::{
    OwnedVoxels, Progress, RenderMode, RenderSettings, RenderStats, Rendered, refuse_image_aligned,
    validate, xray_weight,
};
use crate::clip::LatticeClip;
use crate::error::Result;
use crate::footprint::{FootprintTable, LocatedPlanes};
use crate::geometry::{Order, SplatGeometry};
use crate::gradient::{gradient_in, index_gradient_in};
use crate::mipcull::MipTiles;
use crate::row::deposit_row;
use crate::voxels::{Linear, Voxels};
use std::time::Instant;
use volsplat_core::crio::FrameClassifier;
use volsplat_core::glam::{Mat3, Vec3};
use volsplat_core::image::Rgba;
use volsplat_core::{
    AnyVolume, Camera, CrioTables, OrthoProjection, SampleInput, Scalar, ScalarType, Volume,
    with_volume,
};

#[derive(Default)]
struct SheetSplats {
    buckets: Vec<Vec<Splat>>,
    visited: u64,
    splatted: u64,
    skipped: u64,
}

/// Renders any volume; see [`render`].
pub fn render_any(
    volume: &AnyVolume,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
) -> Result<Rendered> {
    with_volume!(volume, v => render(v, camera, tables, settings))
}

/// Renders `volume` seen by the orthographic `camera`, classified and shaded by `tables`.
pub fn render<T: Scalar>(
    volume: &Volume<T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
) -> Result<Rendered> {
    render_with_progress(volume, camera, tables, settings, &mut |_| true)
}

/// Like [`render`], calling `progress` after each batch of sheets; returning `false` from it
/// cancels the render with [`crate::SplatError::Cancelled`]. [`crate::Visibility::ImageAligned`] is refused
/// with [`crate::SplatError::Setting`] (`visibility`) except in X-ray, which keeps the sheet buffer:
/// the slabs are [`crate::slab::render_slabs`], or [`crate::render_by_visibility`] to dispatch.
pub fn render_with_progress<T: Scalar>(
    volume: &Volume<T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    let t_start = Instant::now();
    refuse_image_aligned(settings)?;
    validate(settings)?;
    settings.kernel.validate()?;
    let proj = OrthoProjection::new(camera, settings.width, settings.height)?;
    let geom = SplatGeometry::new(volume.grid(), &proj, settings.subsample, settings.order)?;
    let table = FootprintTable::build(
        &settings.kernel,
        &geom,
        &settings.footprint,
        settings.antialias,
    )?;
    let owned = OwnedVoxels::new(settings, volume.grid().dims)?;
    let classifier = FrameClassifier::new(tables, &proj.frame, geom.sheet_spacing);
    let n_bands = settings.height.div_ceil(settings.band_height);
    let stats = RenderStats {
        sheets: geom.sheet_order.len(),
        sheet_axis: geom.sheet_axis,
        sheet_spacing: geom.sheet_spacing,
        footprint_entries: table.entry_count(),
        footprint_phases: table.phases,
        footprint_half_extent: table.half_extent,
        threads: rayon::current_num_threads(),
        ..RenderStats::default()
    };
    let make_pass = || Dense {
        classify: ClassifyContext::new(
            volume,
            &geom,
            (tables, &classifier),
            settings,
            &table,
            (n_bands, owned),
        ),
        bands: BandContext {
            table: &table,
            settings,
            band_h: settings.band_height,
        },
        terminate: settings.mode == RenderMode::Composite
            && settings.order == Order::FrontToBack
            && settings.opacity_cutoff < 1.0,
    };
    drive(
        make_pass,
        &geom.sheet_order,
        (settings, tables),
        (stats, t_start),
        progress,
    )
}

/// The sheet renderer's part of the sheet driver ([`SheetPass`]).
struct Dense<'a, T> {
    classify: ClassifyContext<'a, T>,
    bands: BandContext<'a>,
    /// Front-to-back early splat termination: classification skips samples over opaque tiles.
    terminate: bool,
}

impl<T: Scalar> SheetPass for Dense<'_, T> {
    type Sheet = SheetSplats;
    const NAME: &'static str = "sheet renderer";
    const IMAGE_BUFFER: &'static str = "the sheet renderer's image buffer";

    fn reads_opaque_tiles(&self) -> bool {
        self.terminate
    }

    fn classify_sheet(&self, sheet: usize, opaque: &[bool], out: &mut SheetSplats) {
        self.classify.classify_sheet(sheet, opaque, out);
    }

    fn tally(&self, c: &SheetSplats, stats: &mut RenderStats) -> Result<()> {
        stats.voxels += c.visited;
        stats.splats += c.splatted;
        stats.splats_terminated += c.skipped;
        Ok(())
    }

    fn splat_band(&self, b: usize, acc: &mut [Rgba], st: &mut BandState, sheet: &SheetSplats) {
        self.bands.process(b, acc, st, &sheet.buckets[b]);
    }
}

/// Read-only state for classifying sheets.
struct ClassifyContext<'a, T> {
    /// Where the voxels' values are loaded from ([`Linear`]: the volume's samples).
    vox: Linear<'a, T>,
    dims_full: [usize; 3],
    /// Grid direction matrix (columns: world directions of the i, j, k axes).
    direction: Mat3,
    inv_spacing_full: [f32; 3],
    geom: &'a SplatGeometry,
    classifier: &'a FrameClassifier,
    mode: RenderMode,
    cull: bool,
    /// Composite culling of 8/16-bit volumes: whether each possible sample value (offset by
    /// `lut_offset`) has zero opacity, the same test as [`FrameClassifier::density_opacity`]
    /// made once per value instead of once per voxel (empty otherwise).
    zero_lut: Vec<bool>,
    lut_offset: i32,
    needs_gradient: bool,
    /// Shaded composite whose tables depend on the density alone: the slab renderer's table of
    /// the classifier's terms and its lighting ([`crate::slab::shaded_src`]), on the voxel's
    /// central differences in index units; `None` otherwise (the classifier).
    shade: Option<crate::slab::ShadeTable>,
    half_x: f32,
    half_y: f32,
    band_h: usize,
    n_bands: usize,
    width: usize,
    height: usize,
    depth_scale: f64,
    /// Clipping planes in lattice terms (empty: none).
    clip: LatticeClip,
    /// X-ray: the offset of [`RenderSettings::xray_offset`].
    xray_offset: Option<f32>,
    /// A brick's voxels only ([`RenderSettings::owned_cells`]; `None`: every voxel).
    owned: Option<OwnedVoxels>,
}

impl<'a, T: Scalar> ClassifyContext<'a, T> {
    fn new(
        volume: &'a Volume<T>,
        geom: &'a SplatGeometry,
        (tables, classifier): (&CrioTables, &'a FrameClassifier),
        settings: &RenderSettings,
        table: &FootprintTable,
        (n_bands, owned): (usize, Option<OwnedVoxels>),
    ) -> Self {
        let grid = volume.grid();
        let (dlo, dhi) = geom.depth_range;
        let (lut_len, lut_offset) = match T::TYPE {
            ScalarType::U8 => (256, 0),
            ScalarType::I8 => (256, -128),
            ScalarType::U16 => (65536, 0),
            ScalarType::I16 => (65536, -32768),
            ScalarType::F32 => (0, 0),
        };
        let zero_lut = if settings.cull_transparent
            && settings.mode == RenderMode::Composite
            && classifier.density_opacity(0.0).is_some()
        {
            (0..lut_len)
                .map(|k| {
                    classifier
                        .density_opacity((k + lut_offset) as f32)
                        .is_some_and(|a| a.is_nan() || a <= 0.0)
                })
                .collect()
        } else {
            Vec::new()
        };
        let shade = (settings.mode == RenderMode::Composite && classifier.needs_gradient)
            .then(|| {
                let grad_to_world =
                    [0, 1, 2].map(|a| (grid.direction.col(a) / grid.spacing[a]).as_vec3());
                crate::slab::ShadeTable::new(tables, classifier, grad_to_world)
            })
            .flatten();
        ClassifyContext {
            zero_lut,
            lut_offset,
            shade,
            vox: Linear::new(volume),
            dims_full: grid.dims,
            direction: grid.direction.as_mat3(),
            inv_spacing_full: grid.spacing.map(|s| (1.0 / s) as f32),
            geom,
            classifier,
            mode: settings.mode,
            cull: settings.cull_transparent,
            needs_gradient: settings.mode == RenderMode::Composite && classifier.needs_gradient,
            half_x: table.half_extent[0] as f32 + 1.0,
            half_y: table.half_extent[1] as f32 + 1.0,
            band_h: settings.band_height,
            n_bands,
            width: settings.width,
            height: settings.height,
            depth_scale: if dhi > dlo { 1.0 / (dhi - dlo) } else { 0.0 },
            clip: LatticeClip::new(&settings.clip, grid, &settings.kernel, geom.stride),
            xray_offset: settings.xray_offset,
            owned,
        }
    }

    #[inline]
    fn gradient(&self, p: [usize; 3]) -> Vec3 {
        gradient_in(
            &self.vox,
            self.dims_full,
            self.inv_spacing_full,
            self.direction,
            p,
        )
    }

    /// Transform, cull and classify one sheet (Westover §3.5–3.6), routing each surviving splat
    /// to the bands its footprint touches. `opaque` is the tile map after the previous batch
    /// (empty when early termination is off): samples whose whole footprint lies in opaque tiles
    /// are skipped before classification, which can only skip what splatting would skip anyway.
    fn classify_sheet(&self, sheet: usize, opaque: &[bool], out: &mut SheetSplats) {
        let geom = self.geom;
        let [ua, va] = geom.in_sheet_axes;
        let sa = geom.sheet_axis;
        let (nu, nv) = (geom.dims[ua], geom.dims[va]);
        let stride = geom.stride;
        let ju = geom.jacobian.col(ua);
        let jv = geom.jacobian.col(va);
        let mut base = [0usize; 3];
        base[sa] = sheet;
        let sheet_origin = geom.raster_of(base);
        for b in &mut out.buckets {
            b.clear();
        }
        out.buckets.resize_with(self.n_bands, Vec::new);
        out.visited = (nu * nv) as u64;
        // A brick's partial image: the sheets, rows and voxels of its box only.
        let owns = |axis: usize, l: usize| self.owned.is_none_or(|o| o.owns(axis, l * stride));
        if !owns(sa, sheet) {
            (out.splatted, out.skipped) = (0, 0);
            return;
        }
        let (mut splatted, mut skipped) = (0u64, 0u64);
        let data = self.vox.data();
        let data_stride = self.vox.stride();
        let (su, sv) = (data_stride[ua] * stride, data_stride[va] * stride);
        let sheet_lin = data_stride[sa] * stride * sheet;
        let ds = geom.sheet_spacing as f32;
        let (hx, hy) = (self.half_x, self.half_y);
        let (w, h) = (self.width as f32, self.height as f32);
        let n_tiles = self.width.div_ceil(TILE);
        for vi in 0..nv {
            let v = if geom.in_sheet_reversed[1] {
                nv - 1 - vi
            } else {
                vi
            };
            // Incremental transform (Westover §3.5.1): one full position per row, then adds.
            if !owns(va, v) {
                continue;
            }
            let row = sheet_origin + jv * v as f64;
            let row_lin = sheet_lin + v * sv;
            for ui in 0..nu {
                let u = if geom.in_sheet_reversed[0] {
                    nu - 1 - ui
                } else {
                    ui
                };
                if !owns(ua, u) {
                    continue;
                }
                let lin = row_lin + u * su;
                let density = data[lin].to_f32();
                // Shade first (§5.2): cull zero opacity before anything else is computed.
                if self.cull && self.is_transparent(density) {
                    continue;
                }
                let p = row + ju * u as f64;
                let (x, y) = (p.x as f32, p.y as f32);
                // Footprint entirely off the image: nothing to do.
                if x + hx < 0.0 || y + hy < 0.0 || x - hx > w || y - hy > h {
                    continue;
                }
                let (b0, b1) = (
                    div_band((y - hy).max(0.0) as usize, self.band_h).min(self.n_bands - 1),
                    div_band((y + hy).min(h - 1.0) as usize, self.band_h).min(self.n_bands - 1),
                );
                if !opaque.is_empty() && self.under_opaque_tiles(opaque, n_tiles, (x, y), (w, h)) {
                    skipped += 1;
                    continue;
                }
                // Smooth clipping: the kernel's share on the kept side of every plane.
                let keep = if self.clip.is_empty() {
                    1.0
                } else {
                    let mut l = [0.0; 3];
                    l[sa] = (sheet * stride) as f64;
                    l[ua] = (u * stride) as f64;
                    l[va] = (v * stride) as f64;
                    let k = self.clip.weight(l) as f32;
                    if k <= 0.0 || (self.mode == RenderMode::Minip && k < 0.5) {
                        continue;
                    }
                    k
                };
                let at = || {
                    let mut l = [0usize; 3];
                    l[sa] = sheet * stride;
                    l[ua] = u * stride;
                    l[va] = v * stride;
                    l
                };
                let Some(mut value) = self.sample_value(density, at, p.z, ds) else {
                    continue;
                };
                if keep < 1.0 {
                    value = scale_kept(value, keep, self.mode);
                }
                splatted += 1;
                let s = Splat { x, y, v: value };
                for b in &mut out.buckets[b0..=b1] {
                    b.push(s);
                }
            }
        }
        out.splatted = splatted;
        out.skipped = skipped;
    }

    /// Whether a sample of `density` has zero opacity (composite) or zero X-ray weight, so that
    /// culling drops it before anything else is computed (Westover §5.2). MIP and MinIP keep
    /// every sample.
    #[inline(always)]
    fn is_transparent(&self, density: f32) -> bool {
        match self.mode {
            // 8/16-bit samples are integers in the table's range: the same test, looked up.
            RenderMode::Composite if !self.zero_lut.is_empty() => {
                self.zero_lut[(density as i32 - self.lut_offset) as usize]
            }
            RenderMode::Composite => self
                .classifier
                .density_opacity(density)
                .is_some_and(|a| a.is_nan() || a <= 0.0),
            RenderMode::Xray => xray_weight(density, self.xray_offset) == 0.0,
            _ => false,
        }
    }

    /// Whether the footprint at raster `(x, y)` (its half extents `half_x`, `half_y`) lies
    /// wholly in tiles of `opaque`, the image's map of opaque TILE × TILE tiles (`n_tiles` per
    /// row; its rows are the image's tile rows), on an image `w × h` pixels.
    #[inline(always)]
    fn under_opaque_tiles(
        &self,
        opaque: &[bool],
        n_tiles: usize,
        (x, y): (f32, f32),
        (w, h): (f32, f32),
    ) -> bool {
        let (hx, hy) = (self.half_x, self.half_y);
        let (t0, t1) = (
            ((x - hx).max(0.0) as usize / TILE).min(n_tiles - 1),
            ((x + hx).min(w - 1.0) as usize / TILE).min(n_tiles - 1),
        );
        let (r0, r1) = (
            ((y - hy).max(0.0) as usize) / TILE,
            ((y + hy).min(h - 1.0) as usize) / TILE,
        );
        (r0..=r1).all(|r| {
            opaque[r * n_tiles + t0..=r * n_tiles + t1]
                .iter()
                .all(|&o| o)
        })
    }

    /// The splat value of a sample of `density` at the full-resolution voxel `at()`, raster
    /// depth `z`, `ds` world units from the previous sheet along the view (Westover §3.6): its
    /// classified, shaded colour (composite), `ρ·Δs` (X-ray), or `[ρ, 1, 0, 0]` (MIP/MinIP).
    /// `None`: a composite sample the tables leave out, dropped when culling.
    #[inline(always)]
    fn sample_value(
        &self,
        density: f32,
        at: impl Fn() -> [usize; 3],
        z: f64,
        ds: f32,
    ) -> Option<Rgba> {
        let value: Rgba = match (self.mode, &self.shade) {
            (RenderMode::Composite, Some(t)) => {
                let g = index_gradient_in(&self.vox, self.dims_full, at());
                match crate::slab::shaded_src(t, density, g, 1.0, false) {
                    Some(c) => c,
                    None if self.cull => return None,
                    None => [0.0; 4],
                }
            }
            (RenderMode::Composite, None) => {
                let gradient = if self.needs_gradient {
                    self.gradient(at())
                } else {
                    Vec3::ZERO
                };
                let depth = ((z - self.geom.depth_range.0) * self.depth_scale) as f32;
                match self.classifier.classify(&SampleInput {
                    density,
                    gradient,
                    depth,
                }) {
                    Some(c) => c,
                    None if self.cull => return None,
                    None => [0.0; 4],
                }
            }
            (RenderMode::Xray, _) => [xray_weight(density, self.xray_offset) * ds, 0.0, 0.0, 0.0],
            (RenderMode::Mip | RenderMode::Minip, _) => [density, 1.0, 0.0, 0.0],
        };
        Some(value)
    }
}

struct BandContext<'a> {
    table: &'a FootprintTable,
    settings: &'a RenderSettings,
    band_h: usize,
}

impl BandContext<'_> {
    /// Splats one sheet's samples into band `b` and composites them (Westover §3.8.1).
    fn process(&self, b: usize, acc: &mut [Rgba], st: &mut BandState, splats: &[Splat]) {
        if splats.is_empty() {
            return;
        }
        let mode = self.settings.mode;
        st.splat_sheet(
            self.settings,
            b * self.band_h,
            acc,
            |sink, span, target, mip| {
                let f = match sink.code() {
                    SINK_SHEET => splat_block::<SINK_SHEET>,
                    SINK_LINE => splat_block::<SINK_LINE>,
                    SINK_OVER_FTB => splat_block::<SINK_OVER_FTB>,
                    _ => splat_block::<SINK_OVER_BTF>,
                };
                // MIP/MinIP: skip the splats that cannot change the projection (exact;
                // crate::mipcull).
                let extreme = matches!(mode, RenderMode::Mip | RenderMode::Minip);
                let cull = extreme
                    && matches!(sink, Sink::Sheet)
                    && self.table.non_negative()
                    && crate::mipcull::enabled();
                if cull {
                    if mip.is_empty() {
                        *mip = MipTiles::new(span.rows as usize, span.width as usize);
                    }
                    let max = mode == RenderMode::Mip;
                    mip.prepare(self.table, splats, (span.y_lo, span.rows, span.width), max);
                    for (i, sp) in splats.iter().enumerate() {
                        if mip.skip(i) {
                            span.terminated += 1;
                        } else {
                            f(self.table, sp, span, target);
                        }
                    }
                } else {
                    for sp in splats {
                        f(self.table, sp, span, target);
                    }
                }
                cull
            },
        );
    }
}

/// The rows `[cy0, cy1)` of a `bw × bh` block placed at pixel `(px0, py0)` that fall in the
/// span's band, and the image columns `[xa, xb]` it may touch there; `None` if it misses.
struct BlockClip {
    cy0: i32,
    cy1: i32,
    xa: i32,
    xb: i32,
}

/// Clips a footprint block to the band of `span` ([`BlockClip`]).
#[inline(always)]
fn clip_block(px0: i32, py0: i32, bw: i32, bh: i32, span: &mut SpanCtx) -> Option<BlockClip> {
    let cy0 = (span.y_lo - py0).max(0);
    let cy1 = (span.y_lo + span.rows - py0).min(bh);
    if cy0 >= cy1 {
        return None;
    }
    let (xa, xb) = span.columns(
        px0,
        px0 + bw - 1,
        py0 + cy0 - span.y_lo,
        py0 + cy1 - span.y_lo,
    )?;
    Some(BlockClip { cy0, cy1, xa, xb })
}

/// Splats one sample (Westover §3.7.2, Fig 3.08): its phase's block of weights is deposited
/// over the pixels it covers, row by row within each row's non-zero span, clipped to the band.
#[inline(always)]
fn splat_block<const S: u8>(
    table: &FootprintTable,
    sp: &Splat,
    span: &mut SpanCtx,
    target: &mut [Rgba],
) {
    let blk = table.block();
    let (bw, bh) = (blk.width as i32, blk.height as i32);
    if S == SINK_SHEET
        && let Some(loc) = table.locate_planes(sp.x, sp.y)
    {
        return splat_planes(loc, bw, bh, sp, span, target);
    }
    let loc = table.locate(sp.x, sp.y);
    let (px0, py0) = (loc.x0, loc.y0);
    let Some(BlockClip { cy0, cy1, xa, xb }) = clip_block(px0, py0, bw, bh, span) else {
        return;
    };
    let (ca, cb) = ((xa - px0) as usize, (xb - px0 + 1) as usize);
    let w = span.width as usize;
    let v = &sp.v;
    let mut updates = 0usize;
    let blend = !loc.w10.is_empty();
    // The blend extrapolates where fx + fy > 1; `floor` keeps it ≥ 0 for non-negative kernels
    // (FootprintTable::locate).
    let (fx, fy, floor) = (loc.fx, loc.fy, loc.floor);
    for r in cy0 as usize..cy1 as usize {
        let (s0, s1) = loc.spans[r];
        let (c0, c1) = ((s0 as usize).max(ca), (s1 as usize).min(cb));
        if c0 >= c1 {
            continue;
        }
        let (i0, i1) = (r * bw as usize + c0, r * bw as usize + c1);
        // Both are ≥ 0 after clipping: the row is inside the band, column c0 inside the image.
        let start = (py0 + r as i32 - span.y_lo) as usize * w + (px0 + c0 as i32) as usize;
        let out = &mut target[start..start + (c1 - c0)];
        if blend {
            let (a, b, c) = (&loc.w00[i0..i1], &loc.w10[i0..i1], &loc.w01[i0..i1]);
            for (((px, &a), &b), &c) in out.iter_mut().zip(a).zip(b).zip(c) {
                deposit::<S>(px, (a + fx * (b - a) + fy * (c - a)).max(floor), v);
            }
        } else {
            for (px, &wt) in out.iter_mut().zip(&loc.w00[i0..i1]) {
                deposit::<S>(px, wt, v);
            }
        }
        updates += c1 - c0;
    }
    span.updates += updates as u64;
    span.tx0 = span.tx0.min(xa as usize);
    span.tx1 = span.tx1.max(xb as usize + 1);
}

/// [`splat_block`] into a sheet buffer with a blending table: the same pixels, weights and
/// order of additions, row by row through [`crate::row::deposit_row`].
#[inline(always)]
fn splat_planes(
    loc: LocatedPlanes,
    bw: i32,
    bh: i32,
    sp: &Splat,
    span: &mut SpanCtx,
    target: &mut [Rgba],
) {
    let (px0, py0) = (loc.x0, loc.y0);
    let Some(BlockClip { cy0, cy1, xa, xb }) = clip_block(px0, py0, bw, bh, span) else {
        return;
    };
    let (ca, cb) = ((xa - px0) as usize, (xb - px0 + 1) as usize);
    let (w, bw) = (span.width as usize, bw as usize);
    let mut updates = 0usize;
    // Both are ≥ 0 after clipping: the rows are inside the band, column `px0 + ca` inside the
    // image.
    let mut row_start = (py0 + cy0 - span.y_lo) as usize * w + (px0 + ca as i32) as usize;
    let mut block_row = cy0 as usize * bw;
    for &(s0, s1) in &loc.spans[cy0 as usize..cy1 as usize] {
        let (c0, c1) = ((s0 as usize).max(ca), (s1 as usize).min(cb));
        if c0 < c1 {
            let i0 = block_row + c0;
            let start = row_start + (c0 - ca);
            deposit_row(
                &mut target[start..start + (c1 - c0)],
                &loc.a[i0..],
                &loc.dx[i0..],
                &loc.dy[i0..],
                loc.fx,
                loc.fy,
                loc.floor,
                &sp.v,
            );
            updates += c1 - c0;
        }
        row_start += w;
        block_row += bw;
    }
    span.updates += updates as u64;
    span.tx0 = span.tx0.min(xa as usize);
    span.tx1 = span.tx1.max(xb as usize + 1);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::footprint::PhaseBlock;
    use crate::{SplatError, Visibility};
    use volsplat_core::glam::DMat3;
    use volsplat_core::{Grid, TransferFunction};
    use volsplat_core::{Image, Kernel};

    fn camera_for(grid: &Grid, az: f64, el: f64, roll: f64) -> Camera {
        let mut c = volsplat_testkit::fixtures::orbit_camera(grid, az, el, true);
        c.roll(roll);
        c
    }

    use crate::test_fixtures::{smooth_volume, tables};

    /// A table that gives every splat weight 0.5 on its base pixel.
    fn half_weight_table() -> FootprintTable {
        FootprintTable::from_raw(
            [0.0, 0.0],
            vec![0.5],
            PhaseBlock {
                kx0: 0,
                ky0: 0,
                width: 1,
                height: 1,
            },
        )
    }

    /// Westover Fig 5.02: two opaque red samples each weighing 0.5 at a pixel over blue.
    #[test]
    fn fig_5_02_sheet_buffer_vs_every_sample() {
        let table = half_weight_table();
        let red = Splat {
            x: 0.5,
            y: 0.5,
            v: [1.0, 0.0, 0.0, 1.0],
        };
        for (vis, expect) in [
            (Visibility::SheetBuffer, [1.0, 0.0, 0.0]),
            (Visibility::EverySample, [0.75, 0.0, 0.25]),
        ] {
            let settings = RenderSettings {
                width: 1,
                height: 1,
                visibility: vis,
                ..RenderSettings::default()
            };
            let ctx = BandContext {
                table: &table,
                settings: &settings,
                band_h: 16,
            };
            let mut acc = vec![[0.0f32; 4]];
            let mut st = BandState {
                sheet: vec![[0.0; 4]],
                opaque_tiles: vec![false],
                pixel_updates: 0,
                terminated: 0,
                splat_s: 0.0,
                composite_s: 0.0,
                mip: MipTiles::default(),
            };
            ctx.process(0, &mut acc, &mut st, &[red, red]);
            let img = Image::from_pixels(1, 1, acc)
                .unwrap()
                .over_background([0.0, 0.0, 1.0]);
            let p = img.get(0, 0);
            for c in 0..3 {
                assert!((p[c] - expect[c]).abs() < 1e-6, "{vis:?}: {p:?}");
            }
        }
    }

    /// A constant one-voxel-thick sheet reconstructs the constant within 1 % (Gaussian σ = 0.6,
    /// r = 2), for axis-aligned and oblique views, scale 1 and 2.
    #[test]
    fn constant_sheet_reconstructs_the_constant() {
        let grid = Grid::new([40, 40, 1], [1.0, 1.0, 1.0], [0.0; 3], DMat3::IDENTITY).unwrap();
        let vol = Volume::new(grid.clone(), vec![1.0f32; 1600]).unwrap();
        for (az, el, roll, zoom) in [
            (0.0, 0.0, 0.0, 1.0),
            (20.0, 15.0, 33.0, 1.0),
            (0.0, 0.0, 45.0, 2.0),
        ] {
            let mut cam = camera_for(&grid, az, el, roll);
            cam.parallel_scale = 10.0 / zoom;
            let settings = RenderSettings {
                width: 64,
                height: 64,
                mode: RenderMode::Mip,
                ..RenderSettings::default()
            };
            // Sheet sum of weights: use X-ray on a single sheet divided by Δs.
            let xr = RenderSettings {
                mode: RenderMode::Xray,
                ..settings.clone()
            };
            let tf = CrioTables::from_transfer_function(&TransferFunction::ramp(0.0, 1.0, 1.0), 16)
                .unwrap();
            let out = render(&vol, &cam, &tf, &xr).unwrap();
            let ds = out.stats.sheet_spacing as f32;
            let vals = out.values.unwrap();
            let (mut lo, mut hi) = (f32::MAX, f32::MIN);
            for y in 24..40 {
                for x in 24..40 {
                    let v = vals.get(x, y) / ds;
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            eprintln!("constant sheet, view {az},{el},{roll} zoom {zoom}: [{lo}, {hi}]");
            assert!(
                lo > 0.99 && hi < 1.01,
                "view {az},{el},{roll} zoom {zoom}: [{lo}, {hi}]"
            );
        }
    }

    /// A single voxel's X-ray image is its integrated kernel: the footprint at the pixel
    /// centres, and its total equals density × voxel volume / pixel area.
    #[test]
    fn single_voxel_yields_the_integrated_kernel() {
        let grid = Grid::new([5, 5, 5], [1.0, 1.0, 2.0], [0.0; 3], DMat3::IDENTITY).unwrap();
        let mut data = vec![0.0f32; 125];
        data[grid.linear_index(2, 2, 2)] = 3.0;
        let vol = Volume::new(grid.clone(), data).unwrap();
        let mut cam = camera_for(&grid, 35.0, 25.0, 10.0);
        cam.parallel_scale = 4.0;
        let settings = RenderSettings {
            width: 48,
            height: 48,
            mode: RenderMode::Xray,
            ..RenderSettings::default()
        };
        let tf =
            CrioTables::from_transfer_function(&TransferFunction::ramp(0.0, 1.0, 1.0), 16).unwrap();
        let out = render(&vol, &cam, &tf, &settings).unwrap();
        let vals = out.values.unwrap();
        let pix = 8.0 / 48.0;
        let total: f64 = vals.values().iter().map(|&v| v as f64).sum::<f64>() * pix * pix;
        let expect = 3.0 * 2.0; // density × voxel volume (1·1·2)
        assert!(
            (total - expect).abs() < 0.01 * expect,
            "total {total} vs {expect}"
        );
        // Peak against the closed form: ρ · L(0) / |g| where the ray through the centre.
        let proj = OrthoProjection::new(&cam, 48, 48).unwrap();
        let geom = SplatGeometry::new(&grid, &proj, 1, Order::FrontToBack).unwrap();
        let f = crate::footprint::FootprintFunction::new(
            &Kernel::default(),
            &geom,
            crate::aa::Antialias::None,
        );
        let c = geom.raster_of([2, 2, 2]);
        let mut max_err = 0.0f64;
        for y in 0..48 {
            for x in 0..48 {
                let expect = 3.0
                    * geom.sheet_spacing
                    * f.exact_weight(x as f64 + 0.5 - c.x, y as f64 + 0.5 - c.y);
                max_err = max_err.max((vals.get(x, y) as f64 - expect).abs());
            }
        }
        let peak = vals.values().iter().fold(0.0f32, |m, &v| m.max(v)) as f64;
        assert!(max_err < 0.03 * peak, "max error {max_err} vs peak {peak}");
    }

    #[test]
    fn ftb_equals_btf_and_threads_do_not_change_bits() {
        let vol = smooth_volume(24);
        let cam = camera_for(vol.grid(), 30.0, 20.0, 0.0);
        let t = tables();
        for vis in [Visibility::SheetBuffer, Visibility::EverySample] {
            let s = RenderSettings {
                width: 64,
                height: 48,
                visibility: vis,
                opacity_cutoff: 1.0,
                ..RenderSettings::default()
            };
            let ftb = render(&vol, &cam, &t, &s).unwrap().image;
            let btf = render(
                &vol,
                &cam,
                &t,
                &RenderSettings {
                    order: Order::BackToFront,
                    ..s.clone()
                },
            )
            .unwrap()
            .image;
            let d = ftb
                .pixels()
                .iter()
                .zip(btf.pixels())
                .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs()))
                .fold(0.0f32, f32::max);
            if vis == Visibility::SheetBuffer {
                assert!(d <= 1e-5, "sheet buffer FTB vs BTF differ by {d}");
            }
            let mut images = Vec::new();
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                images.push(pool.install(|| render(&vol, &cam, &t, &s).unwrap().image));
            }
            assert!(
                images.windows(2).all(|w| w[0] == w[1]),
                "{vis:?}: thread count changed the image"
            );
        }
    }

    #[test]
    fn early_termination_changes_nothing_visible() {
        let vol = smooth_volume(24);
        let mut cam = camera_for(vol.grid(), 30.0, 20.0, 0.0);
        cam.parallel_scale = 6.0;
        let mut tf = TransferFunction::ramp(0.0, 1.0, 1.0);
        tf.scalar_opacity = vec![[0.0, 0.0], [0.05, 1.0]];
        let t = CrioTables::from_transfer_function(&tf, 256).unwrap();
        let s = RenderSettings {
            width: 64,
            height: 64,
            ..RenderSettings::default()
        };
        let with = render(&vol, &cam, &t, &s).unwrap();
        let without = render(
            &vol,
            &cam,
            &t,
            &RenderSettings {
                opacity_cutoff: 1.0,
                ..s
            },
        )
        .unwrap();
        assert!(
            with.stats.splats_terminated > 0,
            "nothing was terminated early"
        );
        for (a, b) in with.image.pixels().iter().zip(without.image.pixels()) {
            for c in 0..4 {
                assert!((a[c] - b[c]).abs() <= 2e-6, "{a:?} vs {b:?}");
            }
        }
    }

    /// F-W13: culling zero-opacity samples changes the splat count, not the image.
    #[test]
    fn culling_is_invisible() {
        let vol = smooth_volume(20);
        let cam = camera_for(vol.grid(), 10.0, 50.0, 0.0);
        let t = tables();
        let s = RenderSettings {
            width: 40,
            height: 40,
            ..RenderSettings::default()
        };
        let a = render(&vol, &cam, &t, &s).unwrap();
        let b = render(
            &vol,
            &cam,
            &t,
            &RenderSettings {
                cull_transparent: false,
                ..s
            },
        )
        .unwrap();
        assert_eq!(a.image, b.image);
        assert!(a.stats.splats < b.stats.splats);
        let nonzero = vol.data().iter().filter(|&&v| v > 0.0).count() as u64;
        assert_eq!(a.stats.splats, nonzero);
        assert_eq!(b.stats.splats, vol.data().len() as u64);
    }

    /// 8- and 16-bit volumes cull through a table of the possible values; it makes the same
    /// decisions as the per-voxel test of float volumes: the same samples as f32 give the same
    /// picture and the same splat count, for each integer type, with opacity starting inside
    /// the types' ranges.
    #[test]
    fn integer_culling_table_decides_as_the_float_test() {
        use volsplat_core::AnyVolume;
        let f = smooth_volume(18);
        let grid = f.grid().clone();
        // Few levels, so that every value near the threshold occurs many times.
        let q = |off: f32| f.data().iter().map(move |&v| (v * 20.0 + off).round());
        let volumes = [
            AnyVolume::U8(Volume::new(grid.clone(), q(0.0).map(|v| v as u8).collect()).unwrap()),
            AnyVolume::I8(Volume::new(grid.clone(), q(-10.0).map(|v| v as i8).collect()).unwrap()),
            AnyVolume::U16(
                Volume::new(grid.clone(), q(300.0).map(|v| v as u16).collect()).unwrap(),
            ),
            AnyVolume::I16(
                Volume::new(grid.clone(), q(-300.0).map(|v| v as i16).collect()).unwrap(),
            ),
        ];
        let cam = camera_for(&grid, 20.0, 35.0, 0.0);
        let s = RenderSettings {
            width: 36,
            height: 36,
            visibility: Visibility::SheetBuffer,
            ..RenderSettings::default()
        };
        for vol in &volumes {
            let (lo, hi) = vol.value_range();
            // Zero opacity up to an integer in the middle of the range, positive from there on.
            let t0 = (0.5 * (lo + hi)).floor();
            let tf = volsplat_core::TransferFunction {
                scalar_opacity: vec![[lo, 0.0], [t0, 0.0], [hi, 0.8]],
                ..volsplat_core::TransferFunction::ramp(lo, hi, 0.8)
            };
            let t = CrioTables::from_transfer_function(&tf, 4096).unwrap();
            let a = render_any(vol, &cam, &t, &s).unwrap();
            let b = render(&vol.to_f32(), &cam, &t, &s).unwrap();
            assert_eq!(a.image, b.image, "{:?}", vol.scalar_type());
            assert_eq!(a.stats.splats, b.stats.splats, "{:?}", vol.scalar_type());
            assert!(
                0 < a.stats.splats && a.stats.splats < a.stats.voxels,
                "{:?}",
                vol.scalar_type()
            );
        }
    }

    /// F-W32: progress after every batch; FTB opacity never decreases; the last equals the image.
    #[test]
    fn progress_reports_monotone_partial_images() {
        let vol = smooth_volume(20);
        let cam = camera_for(vol.grid(), 0.0, 0.0, 0.0);
        let t = tables();
        let s = RenderSettings {
            width: 32,
            height: 32,
            sheets_per_batch: 1,
            ..RenderSettings::default()
        };
        let mut calls = 0;
        let mut last: Vec<Rgba> = vec![[0.0; 4]; 32 * 32];
        let out = render_with_progress(&vol, &cam, &t, &s, &mut |p| {
            calls += 1;
            for (a, b) in p.accumulation.iter().zip(&last) {
                assert!(a[3] >= b[3]);
            }
            last = p.accumulation.to_vec();
            true
        })
        .unwrap();
        assert_eq!(calls, 20);
        assert_eq!(out.image.pixels(), &last[..]);
        let cancelled = render_with_progress(&vol, &cam, &t, &s, &mut |p| p.sheets_done < 5);
        assert!(matches!(cancelled, Err(SplatError::Cancelled)));
    }

    /// F-W33: subsampling by 2 and 4 visits 8× and 64× fewer samples.
    #[test]
    fn subsampling_reduces_samples() {
        let vol = smooth_volume(32);
        let cam = camera_for(vol.grid(), 0.0, 0.0, 0.0);
        let t = tables();
        let counts: Vec<u64> = [1, 2, 4]
            .iter()
            .map(|&sub| {
                let s = RenderSettings {
                    width: 32,
                    height: 32,
                    subsample: sub,
                    ..RenderSettings::default()
                };
                render(&vol, &cam, &t, &s).unwrap().stats.voxels
            })
            .collect();
        assert_eq!(counts, vec![32768, 4096, 512]);
    }

    /// F-W29: an all-transparent volume gives exactly the background.
    #[test]
    fn transparent_volume_is_background() {
        let grid = Grid::with_dims([8, 8, 8]).unwrap();
        let vol = Volume::new(grid.clone(), vec![0u8; 512]).unwrap();
        let cam = camera_for(&grid, 10.0, 10.0, 0.0);
        let out = render(
            &vol,
            &cam,
            &tables(),
            &RenderSettings {
                width: 16,
                height: 16,
                ..RenderSettings::default()
            },
        )
        .unwrap();
        assert!(out.image.pixels().iter().all(|p| *p == [0.0; 4]));
        assert_eq!(out.stats.splats, 0);
    }

    /// F-W25: kernel cost per splat grows from single-point to nearest to Gaussian; at scale 2,
    /// axis-aligned, single-point touches 1 pixel and the Gaussian at most 9×9.
    #[test]
    fn kernel_costs_follow_the_thesis() {
        let grid = Grid::with_dims([16, 16, 16]).unwrap();
        let vol = Volume::new(grid.clone(), vec![200u8; 4096]).unwrap();
        let mut cam = camera_for(&grid, 0.0, 0.0, 0.0);
        cam.parallel_scale = 16.0; // 64 px for 32 world units: scale 2
        let cost = |k: Kernel| {
            let s = RenderSettings {
                width: 64,
                height: 64,
                kernel: k,
                opacity_cutoff: 1.0,
                ..RenderSettings::default()
            };
            render(&vol, &cam, &tables(), &s)
                .unwrap()
                .stats
                .kernel_cost()
        };
        let (p, n, g) = (
            cost(Kernel::SinglePoint),
            cost(Kernel::Nearest),
            cost(Kernel::default()),
        );
        assert_eq!(p, 1.0);
        assert!(n > 3.0 && n <= 9.0, "nearest {n}");
        assert!(g > 50.0 && g <= 81.0, "gaussian {g}");
    }

    #[test]
    fn bad_settings_are_errors() {
        let vol = smooth_volume(4);
        let cam = camera_for(vol.grid(), 0.0, 0.0, 0.0);
        for s in [
            RenderSettings {
                width: 0,
                ..RenderSettings::default()
            },
            RenderSettings {
                subsample: 0,
                ..RenderSettings::default()
            },
            RenderSettings {
                kernel: Kernel::Gaussian {
                    sigma: -1.0,
                    radius: 2.0,
                },
                ..RenderSettings::default()
            },
        ] {
            assert!(render(&vol, &cam, &tables(), &s).is_err());
        }
        let persp = Camera {
            parallel_projection: false,
            ..cam
        };
        let e = render(&vol, &persp, &tables(), &RenderSettings::default()).unwrap_err();
        assert!(e.to_string().contains("parallel_projection"), "{e}");
    }

    /// The sheet renderer refuses image-aligned slabs instead of handing the frame to the slab
    /// renderer behind the caller's back; `render_by_visibility` dispatches, openly, to the same
    /// bits as each renderer called by name; X-ray keeps its exact sheet buffer.
    #[test]
    fn image_aligned_is_refused_and_dispatched_only_by_name() {
        let vol = smooth_volume(12);
        let cam = camera_for(vol.grid(), 20.0, 10.0, 0.0);
        let t = tables();
        let slabs = RenderSettings {
            width: 24,
            height: 24,
            visibility: Visibility::ImageAligned,
            ..RenderSettings::default()
        };
        for mode in [RenderMode::Composite, RenderMode::Mip, RenderMode::Minip] {
            let s = RenderSettings {
                mode,
                ..slabs.clone()
            };
            let e = render(&vol, &cam, &t, &s).unwrap_err();
            assert!(
                matches!(
                    e,
                    SplatError::Setting {
                        name: "visibility",
                        ..
                    }
                ),
                "{mode:?}: {e}"
            );
            assert!(e.to_string().contains("render_slabs"), "{e}");
            let by_name = crate::render_slabs(&vol, &cam, &t, &s, None, &mut |_| true).unwrap();
            let dispatched =
                crate::render_by_visibility(&vol, &cam, &t, &s, &mut |_| true).unwrap();
            assert_eq!(
                by_name.image.pixels(),
                dispatched.image.pixels(),
                "{mode:?}"
            );
        }
        let sheet = RenderSettings {
            visibility: Visibility::SheetBuffer,
            ..slabs.clone()
        };
        let dispatched =
            crate::render_by_visibility(&vol, &cam, &t, &sheet, &mut |_| true).unwrap();
        assert_eq!(
            dispatched.image.pixels(),
            render(&vol, &cam, &t, &sheet).unwrap().image.pixels()
        );
        let xray = |visibility| RenderSettings {
            mode: RenderMode::Xray,
            visibility,
            ..slabs.clone()
        };
        let a = render(&vol, &cam, &t, &xray(Visibility::ImageAligned)).unwrap();
        let b = render(&vol, &cam, &t, &xray(Visibility::SheetBuffer)).unwrap();
        assert_eq!(a.values.unwrap().values(), b.values.unwrap().values());
    }

    /// MIP/MinIP culling (crate::mipcull) changes no bit of the values or the image, on a noisy
    /// volume (values that tie, rise and fall) from several views and at several sizes.
    #[test]
    fn mip_culling_is_exact() {
        let n = 24;
        let grid = Grid::with_dims([n, n, n]).unwrap();
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let vol = Volume::from_fn(grid.clone(), |i, j, k| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let noise = (seed >> 40) as f32 / (1u64 << 24) as f32;
            let c = (n as f32 - 1.0) / 2.0;
            let r =
                ((i as f32 - c).powi(2) + (j as f32 - c).powi(2) + (k as f32 - c).powi(2)).sqrt();
            // Air (exact zeros) outside, a noisy shell and a bright core inside.
            if r > c {
                0.0
            } else if r < 4.0 {
                2.0
            } else {
                noise * 0.5 + (i % 3) as f32 * 0.25
            }
        })
        .unwrap();
        let t = tables();
        for mode in [RenderMode::Mip, RenderMode::Minip] {
            for (az, el, size) in [(0.0, 0.0, 40), (30.0, 20.0, 64), (-50.0, 35.0, 97)] {
                let settings = RenderSettings {
                    width: size,
                    height: size,
                    mode,
                    ..RenderSettings::default()
                };
                let cam = camera_for(&grid, az, el, 10.0);
                let culled = render(&vol, &cam, &t, &settings).unwrap();
                crate::mipcull::set_enabled(false);
                let plain = render(&vol, &cam, &t, &settings).unwrap();
                crate::mipcull::set_enabled(true);
                let bits = |r: &Rendered| {
                    let v: Vec<u32> = r
                        .values
                        .as_ref()
                        .unwrap()
                        .values()
                        .iter()
                        .map(|x| x.to_bits())
                        .collect();
                    let p: Vec<u32> = r
                        .image
                        .pixels()
                        .iter()
                        .flatten()
                        .map(|x| x.to_bits())
                        .collect();
                    (v, p)
                };
                assert_eq!(
                    bits(&culled),
                    bits(&plain),
                    "{mode:?} az {az} el {el} size {size}"
                );
                if mode == RenderMode::Mip && size == 97 {
                    assert!(culled.stats.pixel_updates < plain.stats.pixel_updates);
                }
            }
        }
    }
}
