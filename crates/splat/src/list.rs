//! Sparse splat lists and the per-splat renderer: perspective splatting with anti-aliasing
//! (Swan, Mueller, Möller, Shareef, Crawfis, Yagel 1997, §3.3, §4.3–4.6, §5).
//!
//! **Splat lists** (§5, after Yagel et al.'s "splat renderer"): [`SplatList::build`] keeps the
//! voxels whose view-independent opacity (scalar opacity × gradient opacity) exceeds a
//! threshold, as a 2-D array of rows (one row per `(j, k)`, holding only the kept voxels of that
//! row, each with its lattice position, value and gradient). The list is traversed in either
//! order along any axis and reused for every frame while only the camera changes; empty space
//! is never visited again. Changing the transfer function needs a new list only if it makes
//! more voxels visible (the list records the threshold and the tables are re-applied per frame).
//!
//! **Per-splat footprints** (§3.3 conditions 1 and 2): each splat's footprint is the line
//! integral of the kernel along the ray from the eye through the voxel centre (a footprint
//! perpendicular to that ray), mapped to the screen by the local perspective Jacobian. With the
//! lattice metric of [`crate::aa`] this is exact for radial kernels: the ray through raster
//! offset `δ` passes the voxel at lattice distance `√(δᵀQδ)`, `Q = (z/f)²·Bᵀ(I − ĝĝᵀ)B` with `z`
//! the eye-space depth, `f` the focal length in pixels, `B = Λ[right, −up]` and `ĝ` the ray in
//! lattice space (`Λ = lattice_from_world`). The weight comes from the kernel's pre-integrated
//! radial table ([`volsplat_core::Kernel::line_integral_radial`]) scaled per splat: a generic table, scaled.
//! Condition 3 (every pixel's ray crossing the footprint perpendicularly) is not met, as in
//! Swan et al.'s implementation; the error is second order in the footprint's angular size.
//!
//! **Anti-aliasing**: per splat, [`crate::aa::widen`] (Swan's `d/k` rule, its §4.6 variant, or
//! EWA) on `Q`, so perspective views get a depth-dependent filter and orthographic views of a
//! volume finer than the image a constant one.
//!
//! **Visibility**: Westover's sheet buffers, with sheets perpendicular to the grid axis most
//! parallel to the view. Under perspective the sheets are visited by their distance from the
//! eye (`|(plane − eye)·axis|`), so a ray always meets them in order, including when the eye is
//! inside the volume. Splats whose centre is closer to the eye plane than the kernel's radius
//! (or behind it) are clipped, never drawn inverted.
//!
//! **Parallel and deterministic**: the sheet driver of [`mod@crate::sheets`] (batches of sheets,
//! bands of scanlines), which this renderer shares with the sheet renderer; output is
//! bit-identical for any thread count.

use crate::aa::{footprint_variance, widen};
use crate::clip::LatticeClip;
use crate::error::{Result, SplatError, try_filled, try_with_capacity};
use crate::footprint::metric_from;
use crate::geometry::{Order, sheet_axis};
use crate::gradient::gradient_in;
use crate::sheets::{
    BandState, OwnedVoxels, Progress, RenderMode, RenderSettings, RenderStats, Rendered, SINK_LINE,
    SINK_OVER_BTF, SINK_OVER_FTB, SINK_SHEET, SheetPass, SpanCtx, deposit, div_band, drive, ms,
    refuse_image_aligned, scale_kept, validate, xray_weight,
};
use crate::voxels::{Linear, Voxels};
use rayon::prelude::*;
use std::sync::OnceLock;
use std::time::Instant;
use volsplat_core::glam::{DMat2, DMat3, DVec3, Vec3};
use volsplat_core::image::Rgba;
use volsplat_core::{
    AnyVolume, Camera, CrioTables, FrameClassifier, Grid, Image, Projection, SampleInput, Scalar,
    ScalarImage, Volume, with_volume,
};

/// What the records of a splat list are, in out-of-memory errors.
const LIST_RECORDS: &str = "the splat list";

/// Which voxels a splat list keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ListVoxels {
    /// Those whose opacity under the tables exceeds [`ExtractSettings::threshold`]: what
    /// composite draws (and X-ray, whose tables are its weight, not the transfer function).
    #[default]
    Visible,
    /// Every voxel of the (subsampled) lattice, whatever the tables: MIP and MinIP project the
    /// data values and only then map the projection through the transfer function (VTK's
    /// order), so a voxel the function hides can still be the largest or smallest along a ray.
    /// Under the automatic window the lowest values are transparent: keeping only the visible
    /// voxels dropped the very minima MinIP shows.
    Every,
}

impl ListVoxels {
    /// The voxels a render in `mode` needs: [`ListVoxels::Every`] for MIP and MinIP,
    /// [`ListVoxels::Visible`] otherwise.
    pub fn for_mode(mode: RenderMode) -> Self {
        match mode {
            RenderMode::Mip | RenderMode::Minip => ListVoxels::Every,
            RenderMode::Composite | RenderMode::Xray => ListVoxels::Visible,
        }
    }
}

/// How a splat list is extracted.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct ExtractSettings {
    /// Keep voxels whose opacity exceeds this value, in `[0, 1)`: the transfer function's
    /// scalar opacity (per `opacity_unit_distance`) times its gradient opacity, at the largest
    /// depth-cue factor. `0` keeps every voxel that is not fully transparent, so the list renders
    /// exactly what the sheet renderer ([`crate::sheets`]) renders. Not used with [`ListVoxels::Every`].
    pub threshold: f32,
    /// Keep every `subsample`-th voxel per axis (≥ 1).
    pub subsample: usize,
    /// Which voxels to keep: by opacity, or every one (MIP, MinIP: [`ListVoxels::for_mode`]).
    pub voxels: ListVoxels,
}

impl Default for ExtractSettings {
    fn default() -> Self {
        ExtractSettings {
            threshold: 0.0,
            subsample: 1,
            voxels: ListVoxels::Visible,
        }
    }
}

impl ExtractSettings {
    /// The default settings for a render in `mode` ([`ListVoxels::for_mode`]).
    pub fn for_mode(mode: RenderMode) -> Self {
        ExtractSettings {
            voxels: ListVoxels::for_mode(mode),
            ..ExtractSettings::default()
        }
    }
}

/// One extracted voxel. Plain data (`repr(C)`, no pointers; docs/design.md §5), 24 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplatRecord {
    /// Lattice index `(i, j, k)` of the (possibly subsampled) lattice.
    pub ijk: [u16; 3],
    /// Reserved, zero.
    pub reserved: u16,
    /// Value in data units.
    pub density: f32,
    /// World-space gradient, data units per world unit (central differences, docs/design.md §4.4).
    pub gradient: [f32; 3],
}

/// The voxels of a volume worth splatting, as rows of splats (Swan et al. 1997 §5).
#[derive(Debug)]
pub struct SplatList {
    grid: Grid,
    stride: usize,
    dims: [usize; 3],
    records: Vec<SplatRecord>,
    /// Start of row `(j, k)` in `records` at `j + dims[1]·k`; one extra entry at the end.
    row_start: Vec<u32>,
    /// Built on first use: records grouped by `i` (permutation, and group starts).
    by_i: OnceLock<(Vec<u32>, Vec<u32>)>,
    threshold: f32,
    voxels_scanned: u64,
    build_ms: f64,
}

impl SplatList {
    /// Extracts the list from any volume; see [`SplatList::build`].
    pub fn build_any(volume: &AnyVolume, tables: &CrioTables, s: &ExtractSettings) -> Result<Self> {
        with_volume!(volume, v => Self::build(v, tables, s))
    }

    /// Extracts the voxels of `volume` whose opacity under `tables` exceeds `s.threshold`, or
    /// every voxel ([`ListVoxels::Every`]). Errors name a bad setting, or the memory the list
    /// could not get ([`SplatError::OutOfMemory`]).
    pub fn build<T: Scalar>(
        volume: &Volume<T>,
        tables: &CrioTables,
        s: &ExtractSettings,
    ) -> Result<Self> {
        let t0 = Instant::now();
        if !(s.threshold >= 0.0 && s.threshold < 1.0) {
            return Err(SplatError::Setting {
                name: "threshold",
                value: s.threshold.to_string(),
                expected: "a splat-list opacity threshold in [0, 1)",
            });
        }
        if s.subsample == 0 {
            return Err(SplatError::Setting {
                name: "subsample",
                value: "0".into(),
                expected: "a stride ≥ 1",
            });
        }
        let grid = volume.grid().clone();
        let stride = s.subsample;
        let dims = grid.dims.map(|d| d.div_ceil(stride));
        if dims.iter().any(|&d| d > u16::MAX as usize) {
            return Err(SplatError::ListTooLarge {
                what: format!(
                    "splat lists hold at most 65535 voxels per axis, the lattice is {dims:?}"
                ),
            });
        }
        let frame = Camera::default().frame();
        let classifier = FrameClassifier::new(tables, &frame, tables.opacity_unit_distance);
        // Read through `Voxels` (the brick seam, docs/design/brick-seam.md C4): today's
        // addressing; a bricked source would hand a `Slotted` here.
        let vox = Linear::new(volume);
        let direction = grid.direction.as_mat3();
        let inv_spacing = grid.spacing.map(|v| (1.0 / v) as f32);
        let full = grid.dims;
        let threshold = s.threshold;
        let every = s.voxels == ListVoxels::Every;
        let slices: Vec<Vec<SplatRecord>> = (0..dims[2])
            .into_par_iter()
            .map(|k| -> Result<Vec<SplatRecord>> {
                let mut out = Vec::new();
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        let p = [i * stride, j * stride, k * stride];
                        let density = vox.data()[vox.linear(p)].to_f32();
                        let opacity_at = |gradient: Vec3| {
                            let at = |depth: f32| {
                                classifier.opacity(&SampleInput {
                                    density,
                                    gradient,
                                    depth,
                                })
                            };
                            at(0.0).max(at(1.0))
                        };
                        // Cheap test first when the opacity table is density-indexed.
                        if !every
                            && classifier
                                .density_opacity(density)
                                .is_some_and(|a| a.is_nan() || a <= 0.0)
                        {
                            continue;
                        }
                        let gradient = gradient_in(&vox, full, inv_spacing, direction, p);
                        if !every {
                            let a = opacity_at(gradient);
                            if a.is_nan() || a <= threshold {
                                continue;
                            }
                        }
                        if out.len() == out.capacity() {
                            // Fallible growth (amortised doubling): the list of a large volume
                            // may not fit; that is an error, never an abort.
                            out.try_reserve(1).map_err(|_| {
                                SplatError::out_of_memory::<SplatRecord>(
                                    LIST_RECORDS,
                                    2 * out.len().max(4),
                                )
                            })?;
                        }
                        out.push(SplatRecord {
                            ijk: [i as u16, j as u16, k as u16],
                            reserved: 0,
                            density,
                            gradient: gradient.to_array(),
                        });
                    }
                }
                Ok(out)
            })
            .collect::<Result<_>>()?;
        let total: usize = slices.iter().map(Vec::len).sum();
        if total > u32::MAX as usize {
            return Err(SplatError::ListTooLarge {
                what: format!("{total} splats exceed the list's 2^32 limit"),
            });
        }
        let mut records = try_with_capacity(total, LIST_RECORDS)?;
        for sl in slices {
            records.extend(sl);
        }
        let mut row_start = try_filled(dims[1] * dims[2] + 1, 0u32, "the splat list's row index")?;
        for r in &records {
            row_start[r.ijk[1] as usize + dims[1] * r.ijk[2] as usize + 1] += 1;
        }
        for n in 1..row_start.len() {
            row_start[n] += row_start[n - 1];
        }
        Ok(SplatList {
            grid,
            stride,
            dims,
            records,
            row_start,
            by_i: OnceLock::new(),
            threshold,
            voxels_scanned: dims.iter().map(|&d| d as u64).product(),
            build_ms: ms(t0),
        })
    }

    /// Number of splats in the list.
    pub fn len(&self) -> usize {
        self.records.len()
    }

    /// Whether the list holds no splat.
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// The splats, ordered by `(k, j, i)`.
    pub fn records(&self) -> &[SplatRecord] {
        &self.records
    }

    /// Bytes held by the list (records, row index, and the per-`i` index if built).
    pub fn bytes(&self) -> usize {
        let by_i = self.by_i.get().map_or(0, |(p, s)| (p.len() + s.len()) * 4);
        self.records.len() * std::mem::size_of::<SplatRecord>() + self.row_start.len() * 4 + by_i
    }

    /// Lattice points examined when the list was built.
    pub fn voxels_scanned(&self) -> u64 {
        self.voxels_scanned
    }

    /// Wall time of [`SplatList::build`], ms.
    pub fn build_ms(&self) -> f64 {
        self.build_ms
    }

    /// The extraction threshold.
    pub fn threshold(&self) -> f32 {
        self.threshold
    }

    /// The full-resolution grid the list came from.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The lattice dimensions (after subsampling).
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// The records grouped by `i`, built on first use (4 bytes per splat; fallibly: the
    /// renderer calls this before the sheets perpendicular to `i` are visited).
    fn try_by_i(&self) -> Result<&(Vec<u32>, Vec<u32>)> {
        if let Some(b) = self.by_i.get() {
            return Ok(b);
        }
        let n = self.dims[0];
        let mut start = vec![0u32; n + 1];
        for r in &self.records {
            start[r.ijk[0] as usize + 1] += 1;
        }
        for i in 1..=n {
            start[i] += start[i - 1];
        }
        let mut next = start.clone();
        let mut perm = try_filled(self.records.len(), 0u32, "the splat list's index by i")?;
        for (idx, r) in self.records.iter().enumerate() {
            let slot = &mut next[r.ijk[0] as usize];
            perm[*slot as usize] = idx as u32;
            *slot += 1;
        }
        Ok(self.by_i.get_or_init(|| (perm, start)))
    }

    /// Calls `f` on every record of the lattice slice `c` perpendicular to `axis`, in storage
    /// order.
    fn for_each_in_slice(&self, axis: usize, c: usize, mut f: impl FnMut(&SplatRecord)) {
        let ny = self.dims[1];
        let range = |a: usize, b: usize| self.row_start[a] as usize..self.row_start[b] as usize;
        match axis {
            2 => self.records[range(c * ny, (c + 1) * ny)].iter().for_each(f),
            1 => {
                for k in 0..self.dims[2] {
                    self.records[range(c + k * ny, c + 1 + k * ny)]
                        .iter()
                        .for_each(&mut f);
                }
            }
            _ => match self.by_i.get() {
                Some((perm, start)) => {
                    for &idx in &perm[start[c] as usize..start[c + 1] as usize] {
                        f(&self.records[idx as usize]);
                    }
                }
                // The renderer builds the index first (`try_by_i`); without it, the same
                // records in the same order, by a scan.
                None => self
                    .records
                    .iter()
                    .filter(|r| r.ijk[0] as usize == c)
                    .for_each(f),
            },
        }
    }
}

/// The distance `k = s·D/p` of Swan et al. eq. 3, in world units of eye-space depth, beyond
/// which a voxel covers less than a pixel: `s` the finest lattice spacing, `D/p` the focal length
/// in pixels. `None` for orthographic views (minification is then the same everywhere).
pub fn k_distance(grid: &Grid, stride: usize, proj: &Projection) -> Option<f64> {
    match proj {
        Projection::Ortho(_) => None,
        Projection::Perspective(p) => {
            let s = grid.spacing.iter().fold(f64::INFINITY, |m, &v| m.min(v)) * stride as f64;
            Some(s * p.focal_px)
        }
    }
}

/// A classified splat with its own footprint, on its way to the bands.
#[derive(Debug, Clone, Copy)]
struct PSplat {
    x: f32,
    y: f32,
    /// `ρ²/R²` = `a·dx² + 2b·dx·dy + c·dy²` (pixels).
    q: [f32; 3],
    /// Weight factor: `E / (|g|·Δs)` (or `E/|g|` for X-ray).
    w: f32,
    /// Half extents in pixels.
    hx: f32,
    hy: f32,
    v: Rgba,
}

#[derive(Default)]
struct SheetBuckets {
    buckets: Vec<Vec<PSplat>>,
    splatted: u64,
    clipped: u64,
    widened: u64,
    /// Bytes a bucket could not grow by (the sheet's classification stopped there).
    out_of_memory: Option<usize>,
}

const LIST_TABLE_LEN: usize = 1024;

/// What the classification step deposits.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Payload {
    /// Shaded colour (or the X-ray / MIP values).
    Shaded,
    /// Eye-space depth as colour, for [`render_list_depth`].
    Depth,
}

/// Read-only per-frame state.
struct Frame<'a> {
    list: &'a SplatList,
    proj: Projection,
    settings: &'a RenderSettings,
    classifier: FrameClassifier,
    payload: Payload,
    /// `world_from_lattice` (linear) and the origin.
    world_from_lattice: DMat3,
    origin: DVec3,
    lattice_from_world: DMat3,
    /// Lattice images of `right` and `−up` (perspective metric).
    r0: DVec3,
    r1: DVec3,
    /// Orthographic: the constant widened metric and weight factor.
    ortho: Option<([f32; 3], f32, [f32; 2])>,
    sheet_axis_dir: DVec3,
    sheet_spacing_lattice: f64,
    frame_spacing: f64,
    radius: f64,
    variance: f64,
    near: f64,
    depth_lo: f64,
    depth_scale: f64,
    table: Box<[f32; LIST_TABLE_LEN]>,
    band_h: usize,
    n_bands: usize,
    /// Clipping planes in lattice terms (empty: none).
    clip: LatticeClip,
    /// A brick's voxels only ([`RenderSettings::owned_cells`]; `None`: every voxel).
    owned: Option<OwnedVoxels>,
}

/// Renders a splat list seen by `camera` (orthographic or perspective); see the module docs.
/// `settings.kernel` must be radial (Gaussian or Crawfis–Max); `settings.subsample` is ignored
/// (the list fixes the lattice).
pub fn render_list(
    list: &SplatList,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
) -> Result<Rendered> {
    render_inner(list, camera, tables, settings, Payload::Shaded, &mut |_| {
        true
    })
}

/// Like [`render_list`], calling `progress` after each batch of sheets
/// (`settings.sheets_per_batch`); returning `false` from it cancels the render with
/// [`SplatError::Cancelled`]. The image does not depend on the batch size or on the callback.
pub fn render_list_with_progress(
    list: &SplatList,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    render_inner(list, camera, tables, settings, Payload::Shaded, progress)
}

/// The opacity-weighted eye-space depth (world units) of what [`render_list`] draws, per pixel:
/// `Σ Tα·z / Σ Tα` under front-to-back compositing; NaN where nothing is drawn. Used to draw
/// the line at distance `k` (Swan et al. Fig. 7a, c).
pub fn render_list_depth(
    list: &SplatList,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
) -> Result<ScalarImage> {
    let s = RenderSettings {
        mode: RenderMode::Composite,
        ..settings.clone()
    };
    let r = render_inner(list, camera, tables, &s, Payload::Depth, &mut |_| true)?;
    let (w, h) = (s.width, s.height);
    let values = r
        .image
        .pixels()
        .iter()
        .map(|p| if p[3] > 1e-3 { p[0] / p[3] } else { f32::NAN })
        .collect();
    ScalarImage::from_values(w, h, values).ok_or(SplatError::SizeMismatch {
        what: "depth image",
        got: (r.image.width(), r.image.height()),
        expected: (w, h),
    })
}

/// Paints `color` (premultiplied, opaque) on the pixels of `image` where `depth` crosses `k`
/// between 4-neighbours: the contour "line at distance k" of Swan et al. Fig. 7a. Errors if the
/// two images differ in size.
pub fn draw_depth_contour(
    image: &mut Image,
    depth: &ScalarImage,
    k: f32,
    color: [f32; 3],
) -> Result<()> {
    let (w, h) = (depth.width(), depth.height());
    if image.width() != w || image.height() != h {
        return Err(SplatError::SizeMismatch {
            what: "image",
            got: (image.width(), image.height()),
            expected: (w, h),
        });
    }
    let d = depth.values();
    let side = |v: f32| if v.is_nan() { None } else { Some(v >= k) };
    let mut mark = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let Some(a) = side(d[y * w + x]) else {
                continue;
            };
            // Mark the far side of each crossing, so the line is one pixel wide.
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if nx < w && ny < h && side(d[ny * w + nx]).is_some_and(|b| b != a) {
                    let far = if a { y * w + x } else { ny * w + nx };
                    mark[far] = true;
                }
            }
        }
    }
    let px = image.pixels_mut();
    for (p, &m) in px.iter_mut().zip(&mark) {
        if m {
            *p = [color[0], color[1], color[2], 1.0];
        }
    }
    Ok(())
}

fn render_inner(
    list: &SplatList,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    payload: Payload,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    let t_start = Instant::now();
    refuse_image_aligned(settings)?;
    validate(settings)?;
    settings.kernel.validate()?;
    if !settings.kernel.is_radial() {
        return Err(SplatError::KernelNotRadial {
            kernel: settings.kernel.name(),
        });
    }
    let (w, h) = (settings.width, settings.height);
    let proj = Projection::new(camera, w, h)?;
    let frame_v = *proj.frame();
    let grid = &list.grid;
    let stride = list.stride as f64;
    let spacing = DVec3::from(grid.spacing) * stride;
    let world_from_lattice = grid.direction * DMat3::from_diagonal(spacing);
    let lattice_from_world = world_from_lattice.inverse();
    let origin = DVec3::from(grid.origin);
    let fwd = frame_v.forward;
    let (axis, cos_axis) = sheet_axis(&grid.direction, fwd)?;
    if axis == 0 {
        list.try_by_i()?;
    }
    let axis_dir = grid.direction.col(axis);
    let frame_spacing = spacing[axis] / cos_axis;
    let n_sheets = list.dims[axis];
    let sheet_order = sheet_order(
        &proj,
        (origin, world_from_lattice.col(axis), axis_dir),
        n_sheets,
        settings.order,
    );
    let classifier = FrameClassifier::new(tables, &frame_v, frame_spacing);
    let radius = settings.kernel.radius();
    let variance = footprint_variance(&settings.kernel);
    // Near clip: the whole kernel support must lie in front of the eye plane.
    let near = match proj {
        Projection::Ortho(_) => f64::NEG_INFINITY,
        Projection::Perspective(_) => radius * spacing.max_element(),
    };
    let (dlo, dhi) = depth_range(list.dims, origin, world_from_lattice, &frame_v);
    let dlo = dlo.max(near);
    let table = radial_table(&settings.kernel, radius);
    let ortho = match proj {
        Projection::Ortho(p) => Some(ortho_metric(
            &p,
            lattice_from_world,
            settings,
            (radius, variance),
            frame_spacing,
        )),
        Projection::Perspective(_) => None,
    };
    let band_h = settings.band_height;
    let n_bands = h.div_ceil(band_h);
    let fr = Frame {
        list,
        proj,
        settings,
        classifier,
        payload,
        world_from_lattice,
        origin,
        lattice_from_world,
        r0: lattice_from_world * frame_v.right,
        r1: lattice_from_world * -frame_v.up,
        ortho,
        sheet_axis_dir: axis_dir,
        sheet_spacing_lattice: spacing[axis],
        frame_spacing,
        radius,
        variance,
        near,
        depth_lo: dlo,
        depth_scale: if dhi > dlo { 1.0 / (dhi - dlo) } else { 0.0 },
        table,
        band_h,
        n_bands,
        clip: LatticeClip::new(&settings.clip, &list.grid, &settings.kernel, list.stride),
        owned: OwnedVoxels::new(settings, list.grid.dims)?,
    };
    let stats = RenderStats {
        sheets: n_sheets,
        sheet_axis: axis,
        sheet_spacing: frame_spacing,
        footprint_entries: LIST_TABLE_LEN,
        footprint_phases: 0,
        threads: rayon::current_num_threads(),
        voxels: list.len() as u64,
        ..RenderStats::default()
    };
    drive(
        || ListPass { frame: fr, axis },
        &sheet_order,
        (settings, tables),
        (stats, t_start),
        progress,
    )
}

/// The sheet indices `0..n_sheets` in traversal order: by depth (orthographic) or by the
/// distance of the sheet's plane from the eye (perspective), front to back unless `order` says
/// otherwise. `(origin, step, axis_dir)`: the world position of sheet 0's lattice origin, the
/// world step from one sheet to the next, the sheet axis's unit world direction.
fn sheet_order(
    proj: &Projection,
    (origin, step, axis_dir): (DVec3, DVec3, DVec3),
    n_sheets: usize,
    order: Order,
) -> Vec<usize> {
    let frame_v = proj.frame();
    let key = |c: usize| {
        let plane = origin + step * c as f64;
        match proj {
            Projection::Ortho(_) => (plane - frame_v.eye).dot(frame_v.forward),
            Projection::Perspective(_) => (plane - frame_v.eye).dot(axis_dir).abs(),
        }
    };
    let mut sheet_order: Vec<usize> = (0..n_sheets).collect();
    sheet_order.sort_by(|&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));
    if order == Order::BackToFront {
        sheet_order.reverse();
    }
    sheet_order
}

/// The eye-space depth range (world units along the view) of the lattice's eight corners.
fn depth_range(
    dims: [usize; 3],
    origin: DVec3,
    world_from_lattice: DMat3,
    frame_v: &volsplat_core::ViewFrame,
) -> (f64, f64) {
    let (mut dlo, mut dhi) = (f64::INFINITY, f64::NEG_INFINITY);
    for n in 0..8 {
        let corner = |bit: usize, d: usize| if n & bit != 0 { (d - 1) as f64 } else { 0.0 };
        let p = DVec3::new(corner(1, dims[0]), corner(2, dims[1]), corner(4, dims[2]));
        let z = (origin + world_from_lattice * p - frame_v.eye).dot(frame_v.forward);
        dlo = dlo.min(z);
        dhi = dhi.max(z);
    }
    (dlo, dhi)
}

/// The kernel's pre-integrated radial profile ([`volsplat_core::Kernel::line_integral_radial`])
/// tabulated in `ρ²/R²` over `[0, 1]`, `R` = `radius`.
fn radial_table(kernel: &volsplat_core::Kernel, radius: f64) -> Box<[f32; LIST_TABLE_LEN]> {
    Box::new(std::array::from_fn(|n| {
        let t = n as f64 / (LIST_TABLE_LEN - 1) as f64;
        kernel
            .line_integral_radial(radius * t.sqrt())
            .unwrap_or(0.0) as f32
    }))
}

/// Orthographic views: every splat's footprint metric, widened by the anti-aliasing, and its
/// weight factor, the same for the whole frame ([`pack`]ed; see the module docs).
fn ortho_metric(
    p: &volsplat_core::OrthoProjection,
    lattice_from_world: DMat3,
    settings: &RenderSettings,
    (radius, variance): (f64, f64),
    frame_spacing: f64,
) -> ([f32; 3], f32, [f32; 2]) {
    let j_inv = p.raster_from_world_linear().inverse();
    let (b0, b1, g) = (
        lattice_from_world * j_inv.col(0),
        lattice_from_world * j_inv.col(1),
        lattice_from_world * p.frame.forward,
    );
    let q = metric_from(b0, b1, g);
    let (q2, e) = widen(settings.antialias, q, variance);
    let scale = if settings.mode == RenderMode::Xray {
        e / g.length()
    } else {
        e / (g.length() * frame_spacing)
    };
    pack(q2, radius, scale)
}

/// The splat-list renderer's part of the sheet driver ([`SheetPass`]): sheets along `axis`.
struct ListPass<'a> {
    frame: Frame<'a>,
    axis: usize,
}

impl SheetPass for ListPass<'_> {
    type Sheet = SheetBuckets;
    const NAME: &'static str = "splat-list renderer";
    const IMAGE_BUFFER: &'static str = "the splat list's image buffer";

    fn reads_opaque_tiles(&self) -> bool {
        false
    }

    fn classify_sheet(&self, sheet: usize, _opaque: &[bool], out: &mut SheetBuckets) {
        self.frame.classify_sheet(self.axis, sheet, out);
    }

    fn tally(&self, c: &SheetBuckets, stats: &mut RenderStats) -> Result<()> {
        if let Some(bytes) = c.out_of_memory {
            return Err(SplatError::OutOfMemory {
                what: "the splat list's sheet buffers",
                bytes,
            });
        }
        stats.splats += c.splatted;
        stats.splats_clipped += c.clipped;
        stats.splats_widened += c.widened;
        Ok(())
    }

    fn splat_band(&self, b: usize, acc: &mut [Rgba], st: &mut BandState, sheet: &SheetBuckets) {
        self.frame.process(b, acc, st, &sheet.buckets[b]);
    }
}

/// Packs a metric for the band loops: coefficients of `ρ²/R²`, the weight factor and the half
/// extents `R·√(Q⁻¹)ᵢᵢ` in pixels.
fn pack(q: DMat2, radius: f64, scale: f64) -> ([f32; 3], f32, [f32; 2]) {
    let (a, b, c) = (q.col(0).x, 0.5 * (q.col(1).x + q.col(0).y), q.col(1).y);
    let det = (a * c - b * b).max(1e-300);
    let r2 = radius * radius;
    (
        [(a / r2) as f32, (b / r2) as f32, (c / r2) as f32],
        scale as f32,
        [
            (radius * (c / det).sqrt()) as f32,
            (radius * (a / det).sqrt()) as f32,
        ],
    )
}

impl Frame<'_> {
    fn classify_sheet(&self, axis: usize, c: usize, out: &mut SheetBuckets) {
        for b in &mut out.buckets {
            b.clear();
        }
        out.buckets.resize_with(self.n_bands, Vec::new);
        out.splatted = 0;
        out.clipped = 0;
        out.widened = 0;
        out.out_of_memory = None;
        let s = self.settings;
        let (w, h) = (s.width as f32, s.height as f32);
        let mode = s.mode;
        let frame = *self.proj.frame();
        let needs_gradient = mode == RenderMode::Composite && self.classifier.needs_gradient;
        let stride = self.list.stride as f64;
        // A brick's partial image: the slices and voxels of its box only.
        let ls = self.list.stride;
        if self.owned.is_some_and(|o| !o.owns(axis, c * ls)) {
            return;
        }
        self.list.for_each_in_slice(axis, c, |r| {
            if out.out_of_memory.is_some() {
                return;
            }
            if let Some(o) = &self.owned
                && !o.owns_voxel(r.ijk.map(|l| l as usize * ls))
            {
                return;
            }
            let lattice = DVec3::new(r.ijk[0] as f64, r.ijk[1] as f64, r.ijk[2] as f64);
            // Smooth clipping: the kernel's share on the kept side of every plane.
            let keep = if self.clip.is_empty() {
                1.0
            } else {
                let k = self.clip.weight((lattice * stride).to_array()) as f32;
                if k <= 0.0 || (mode == RenderMode::Minip && k < 0.5) {
                    return;
                }
                k
            };
            let p = self.origin + self.world_from_lattice * lattice;
            let d = p - frame.eye;
            let z = d.dot(frame.forward);
            let ((q, wt, [hx, hy]), ray_ratio) = match (&self.ortho, &self.proj) {
                (Some(o), _) => (*o, 1.0),
                (None, Projection::Perspective(pp)) => {
                    if z.is_nan() || z <= self.near {
                        out.clipped += 1;
                        return;
                    }
                    // Jacobian inverse in closed form: a pixel step is right·z/f (x) or −up·z/f
                    // (y) at constant depth; the ray is d.
                    let zf = z / pp.focal_px;
                    let g = self.lattice_from_world * d;
                    let len = d.length();
                    let g_len = g.length() / len;
                    let q = metric_from(self.r0 * zf, self.r1 * zf, g);
                    let (q2, e) = widen(s.antialias, q, self.variance);
                    if e < 1.0 {
                        out.widened += 1;
                    }
                    // Path between sheets along this ray (Δs), and its ratio to the frame's.
                    let cos = (d.dot(self.sheet_axis_dir) / len).abs().max(1e-6);
                    let ds = self.sheet_spacing_lattice / cos;
                    let scale = if mode == RenderMode::Xray {
                        e / g_len
                    } else {
                        e / (g_len * ds)
                    };
                    (pack(q2, self.radius, scale), ds / self.frame_spacing)
                }
                (None, Projection::Ortho(_)) => return,
            };
            let raster = self.proj.raster_from_world(p);
            let (x, y) = (raster.x as f32, raster.y as f32);
            if !(x + hx >= 0.0 && y + hy >= 0.0 && x - hx <= w && y - hy <= h) {
                return;
            }
            let v: Rgba = match mode {
                RenderMode::Composite => {
                    let gradient = if needs_gradient {
                        Vec3::from(r.gradient)
                    } else {
                        Vec3::ZERO
                    };
                    let depth = ((z - self.depth_lo) * self.depth_scale).clamp(0.0, 1.0) as f32;
                    let Some(mut v) = self.classifier.classify(&SampleInput {
                        density: r.density,
                        gradient,
                        depth,
                    }) else {
                        return;
                    };
                    // Opacity for this ray's own path between sheets (perspective only).
                    if (ray_ratio - 1.0).abs() > 1e-4 && v[3] < 1.0 {
                        let a = 1.0 - (1.0 - v[3]).powf(ray_ratio as f32);
                        let k = a / v[3];
                        v = [v[0] * k, v[1] * k, v[2] * k, a];
                    }
                    if self.payload == Payload::Depth {
                        let zz = z as f32 * v[3];
                        v = [zz, zz, zz, v[3]];
                    }
                    v
                }
                RenderMode::Xray => [xray_weight(r.density, s.xray_offset), 0.0, 0.0, 0.0],
                RenderMode::Mip | RenderMode::Minip => [r.density, 1.0, 0.0, 0.0],
            };
            let v = if keep < 1.0 {
                scale_kept(v, keep, mode)
            } else {
                v
            };
            out.splatted += 1;
            let (b0, b1) = (
                div_band((y - hy).max(0.0) as usize, self.band_h).min(self.n_bands - 1),
                div_band((y + hy).min(h - 1.0).max(0.0) as usize, self.band_h)
                    .min(self.n_bands - 1),
            );
            let sp = PSplat {
                x,
                y,
                q,
                w: wt,
                hx,
                hy,
                v,
            };
            for b in &mut out.buckets[b0..=b1] {
                // Fallible growth: a sheet of a large list (every voxel, for MIP) may not fit.
                if b.len() == b.capacity() && b.try_reserve(1).is_err() {
                    let bytes = 2 * b.len().max(4) * std::mem::size_of::<PSplat>();
                    out.out_of_memory = Some(bytes);
                    return;
                }
                b.push(sp);
            }
        });
    }

    /// Splats one sheet's splats into band `b` and composites them (Westover §3.8.1).
    fn process(&self, b: usize, acc: &mut [Rgba], st: &mut BandState, splats: &[PSplat]) {
        if splats.is_empty() {
            return;
        }
        st.splat_sheet(
            self.settings,
            b * self.band_h,
            acc,
            |sink, span, target, _| {
                let f = match sink.code() {
                    SINK_SHEET => splat_one::<SINK_SHEET>,
                    SINK_LINE => splat_one::<SINK_LINE>,
                    SINK_OVER_FTB => splat_one::<SINK_OVER_FTB>,
                    _ => splat_one::<SINK_OVER_BTF>,
                };
                for sp in splats {
                    f(&self.table, sp, span, target);
                }
                false
            },
        );
    }
}

/// Deposits one splat's footprint over the pixel centres it covers within the band: weight
/// `w·F(ρ)` with `F` the kernel's pre-integrated radial table (linear interpolation in `ρ²`).
#[inline(always)]
fn splat_one<const S: u8>(
    table: &[f32; LIST_TABLE_LEN],
    sp: &PSplat,
    span: &mut SpanCtx,
    target: &mut [Rgba],
) {
    // Pixel centres (x + ½) within the half extents.
    let x0 = (sp.x - sp.hx - 0.5).ceil() as i32;
    let x1 = (sp.x + sp.hx - 0.5).floor() as i32;
    let y0 = ((sp.y - sp.hy - 0.5).ceil() as i32).max(span.y_lo);
    let y1 = ((sp.y + sp.hy - 0.5).floor() as i32).min(span.y_lo + span.rows - 1);
    if y0 > y1 || x1 < 0 || x0 >= span.width {
        return;
    }
    let Some((xa, xb)) = span.columns(x0, x1, y0 - span.y_lo, y1 + 1 - span.y_lo) else {
        return;
    };
    let [a, b, c] = sp.q;
    let last = (LIST_TABLE_LEN - 1) as f32;
    let w = span.width as usize;
    let mut updates = 0u64;
    // The loops below compute exactly what the per-pixel definition does (same f32 operations
    // in the same order), with less bookkeeping: `px as f32 + 0.5` is carried as a float (exact:
    // integers below 2²⁴), the table index is truncated through i32 (`u` lies in [0, 1023]),
    // and the row is sliced once, so no bounds are checked per pixel.
    let (xa, xb) = (xa as usize, xb as usize);
    for py in y0..=y1 {
        let dy = py as f32 + 0.5 - sp.y;
        let row = (py - span.y_lo) as usize * w;
        let (by, cy) = (2.0 * b * dy, c * dy * dy);
        let out = &mut target[row + xa..=row + xb];
        let mut centre = xa as f32 + 0.5;
        for px in out {
            let dx = centre - sp.x;
            centre += 1.0;
            let t = (a * dx + by) * dx + cy;
            if t < 1.0 {
                // `max(t, 0)` without `f32::max`'s NaN handling (t < 1 excludes NaN; a zero's
                // sign cannot change the weight).
                let u = if t > 0.0 { t } else { 0.0 } * last;
                let i = (u as i32 as usize).min(LIST_TABLE_LEN - 2);
                let f = u - i as f32;
                let (t0, t1) = (table[i], table[i + 1]);
                let v = t0 + f * (t1 - t0);
                deposit::<S>(px, sp.w * v, &sp.v);
                updates += 1;
            }
        }
    }
    span.updates += updates;
    span.tx0 = span.tx0.min(xa);
    span.tx1 = span.tx1.max(xb + 1);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aa::Antialias;
    use crate::sheets::render;

    use crate::test_fixtures::{smooth_volume, tables};

    use volsplat_testkit::fixtures::orbit_camera as camera;

    fn max_abs_diff(a: &Image, b: &Image) -> f32 {
        a.pixels()
            .iter()
            .zip(b.pixels())
            .flat_map(|(p, q)| (0..4).map(move |c| (p[c] - q[c]).abs()))
            .fold(0.0, f32::max)
    }

    /// Image-aligned visibility is refused outside X-ray, as by the sheet renderer (the slabs
    /// are another renderer), and not silently drawn as a sheet buffer; X-ray keeps the sheet
    /// buffer's exact line integrals, the same bits either way.
    #[test]
    fn image_aligned_is_refused_not_replaced() {
        let vol = smooth_volume(16);
        let t = tables();
        let list =
            SplatList::build(&vol, &t, &ExtractSettings::for_mode(RenderMode::Xray)).unwrap();
        let cam = camera(vol.grid(), 30.0, 20.0, false);
        let mut s = RenderSettings {
            width: 24,
            height: 24,
            visibility: crate::Visibility::ImageAligned,
            ..RenderSettings::default()
        };
        for mode in [RenderMode::Composite, RenderMode::Mip, RenderMode::Minip] {
            s.mode = mode;
            match render_list(&list, &cam, &t, &s) {
                Err(SplatError::Setting { name, .. }) => assert_eq!(name, "visibility"),
                other => panic!("{mode:?}: {:?}", other.map(|_| ())),
            }
        }
        s.mode = RenderMode::Xray;
        let image = render_list(&list, &cam, &t, &s).unwrap();
        s.visibility = crate::Visibility::SheetBuffer;
        let sheet = render_list(&list, &cam, &t, &s).unwrap();
        assert_eq!(image.values, sheet.values);
    }

    #[test]
    fn list_keeps_exactly_the_visible_voxels() {
        let vol = smooth_volume(24);
        let t = tables();
        let list = SplatList::build(&vol, &t, &ExtractSettings::default()).unwrap();
        let nonzero = vol.data().iter().filter(|&&v| v > 0.0).count();
        // The ramp's opacity is zero only at 0.
        assert_eq!(list.len(), nonzero);
        // Rows are sorted by (k, j, i) and the row index covers them.
        for w in list.records().windows(2) {
            let key = |r: &SplatRecord| (r.ijk[2], r.ijk[1], r.ijk[0]);
            assert!(key(&w[0]) < key(&w[1]));
        }
        // Every slice along every axis holds exactly the records with that coordinate, in the
        // same order with and without the index by i.
        let mut orders = Vec::new();
        for built in [false, true] {
            if built {
                list.try_by_i().unwrap();
            }
            let mut order = Vec::new();
            for axis in 0..3 {
                let mut seen = 0;
                for c in 0..list.dims()[axis] {
                    list.for_each_in_slice(axis, c, |r| {
                        assert_eq!(r.ijk[axis] as usize, c);
                        seen += 1;
                        order.push(r.ijk);
                    });
                }
                assert_eq!(seen, list.len());
            }
            orders.push(order);
        }
        assert_eq!(orders[0], orders[1]);
        let thin = SplatList::build(
            &vol,
            &t,
            &ExtractSettings {
                threshold: 0.3,
                ..ExtractSettings::default()
            },
        )
        .unwrap();
        assert!(thin.len() < list.len() && !thin.is_empty());
        assert_eq!(std::mem::size_of::<SplatRecord>(), 24);
        assert!(
            SplatList::build(
                &vol,
                &t,
                &ExtractSettings {
                    threshold: 1.0,
                    ..ExtractSettings::default()
                }
            )
            .is_err()
        );
    }

    /// MIP and MinIP lists keep every voxel ([`ListVoxels::for_mode`]): the ramp hides the
    /// zeros, which a visible-voxel list drops and an every-voxel list keeps, with their values
    /// and gradients as the visible list has them.
    #[test]
    fn every_voxel_lists_keep_what_the_tables_hide() {
        let vol = smooth_volume(20);
        let t = tables();
        let visible = SplatList::build(&vol, &t, &ExtractSettings::default()).unwrap();
        let every =
            SplatList::build(&vol, &t, &ExtractSettings::for_mode(RenderMode::Minip)).unwrap();
        assert_eq!(every.len(), vol.data().len());
        assert!(visible.len() < every.len());
        let by_ijk: std::collections::HashMap<[u16; 3], &SplatRecord> =
            every.records().iter().map(|r| (r.ijk, r)).collect();
        for r in visible.records() {
            assert_eq!(by_ijk[&r.ijk], r);
        }
        for mode in [RenderMode::Mip, RenderMode::Minip] {
            assert_eq!(ListVoxels::for_mode(mode), ListVoxels::Every);
        }
        for mode in [RenderMode::Composite, RenderMode::Xray] {
            assert_eq!(ListVoxels::for_mode(mode), ListVoxels::Visible);
        }
    }

    #[test]
    fn orthographic_list_render_matches_the_dense_renderer() {
        let vol = smooth_volume(32);
        let t = tables();
        let list = SplatList::build(&vol, &t, &ExtractSettings::default()).unwrap();
        for mode in [RenderMode::Composite, RenderMode::Xray, RenderMode::Mip] {
            let s = RenderSettings {
                width: 96,
                height: 80,
                mode,
                antialias: Antialias::None,
                ..RenderSettings::default()
            };
            let cam = camera(vol.grid(), 30.0, 20.0, true);
            let dense = render(&vol, &cam, &t, &s).unwrap();
            let sparse = render_list(&list, &cam, &t, &s).unwrap();
            let diff = match (&dense.values, &sparse.values) {
                (Some(a), Some(b)) => {
                    let max = a.values().iter().fold(0.0f32, |m, v| m.max(v.abs()));
                    a.values()
                        .iter()
                        .zip(b.values())
                        .filter(|(x, y)| !(x.is_nan() && y.is_nan()))
                        .map(|(x, y)| (x - y).abs() / max)
                        .fold(0.0, f32::max)
                }
                _ => max_abs_diff(&dense.image, &sparse.image),
            };
            // The sheet renderer's phase table (first-order blend) vs the exact per-pixel
            // footprint: within the table's documented ±0.3 % ripple. MIP divides by the
            // sheet's coverage, which amplifies it at the silhouette (coverage ≈ ½).
            let bound = if mode == RenderMode::Mip { 0.04 } else { 0.01 };
            assert!(diff < bound, "{mode:?}: {diff}");
            assert_eq!(sparse.stats.voxels, list.len() as u64);
        }
    }

    #[test]
    fn threads_do_not_change_bits_and_orders_agree() {
        let vol = smooth_volume(28);
        let t = tables();
        let list = SplatList::build(&vol, &t, &ExtractSettings::default()).unwrap();
        let mut cam = camera(vol.grid(), 40.0, -25.0, false);
        cam.dolly(1.6);
        let s = RenderSettings {
            width: 72,
            height: 64,
            ..RenderSettings::default()
        };
        let run = |n: usize, s: &RenderSettings| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
                .install(|| render_list(&list, &cam, &t, s).unwrap())
        };
        let a = run(1, &s);
        let b = run(3, &s);
        assert_eq!(a.image.pixels(), b.image.pixels());
        let btf = run(
            2,
            &RenderSettings {
                order: Order::BackToFront,
                ..s.clone()
            },
        );
        assert!(max_abs_diff(&a.image, &btf.image) < 1e-4);
    }

    #[test]
    fn the_eye_inside_the_volume_clips_instead_of_inverting() {
        let vol = smooth_volume(24);
        let t = tables();
        let list = SplatList::build(&vol, &t, &ExtractSettings::default()).unwrap();
        let (lo, hi) = vol.grid().bounds_world();
        let mut cam = Camera::reset_to_bounds(lo, hi, false);
        // Eye at the centre of the volume, looking along −z.
        let c = (lo + hi) * 0.5;
        cam.position = c.to_array();
        cam.focal_point = (c - DVec3::Z).to_array();
        let s = RenderSettings {
            width: 64,
            height: 64,
            ..RenderSettings::default()
        };
        let r = render_list(&list, &cam, &t, &s).unwrap();
        assert!(r.stats.splats_clipped > list.len() as u64 / 3);
        assert!(r.image.pixels().iter().flatten().all(|v| v.is_finite()));
        // Only the half in front of the eye is drawn: the image is not empty.
        assert!(r.image.pixels().iter().any(|p| p[3] > 0.01));
        // Looking the other way sees the other half, and the two differ (the blob is
        // off-centre).
        cam.focal_point = (c + DVec3::Z).to_array();
        let back = render_list(&list, &cam, &t, &s).unwrap();
        assert!(max_abs_diff(&r.image, &back.image) > 0.01);
    }

    #[test]
    fn orthographic_minification_conserves_x_ray_energy_with_swan() {
        // 64³ blob seen at 12 × 12 pixels: about 7 voxels per pixel.
        let vol = smooth_volume(64);
        let t = tables();
        let list = SplatList::build(&vol, &t, &ExtractSettings::default()).unwrap();
        let cam = camera(vol.grid(), 17.0, 11.0, true);
        let mass: f64 = vol.data().iter().map(|&v| v as f64).sum();
        let energy = |aa: Antialias| {
            let s = RenderSettings {
                width: 12,
                height: 12,
                mode: RenderMode::Xray,
                antialias: aa,
                ..RenderSettings::default()
            };
            let r = render_list(&list, &cam, &t, &s).unwrap();
            let proj = Projection::new(&cam, 12, 12).unwrap();
            let px = proj.pixel_size_at(1.0);
            let sum: f64 = r.values.unwrap().values().iter().map(|&v| v as f64).sum();
            sum * px * px / mass
        };
        let swan = energy(Antialias::Swan);
        let ewa = energy(Antialias::Ewa);
        let area = energy(Antialias::Area);
        assert!((swan - 1.0).abs() < 0.01, "swan {swan}");
        assert!((ewa - 1.0).abs() < 0.01, "ewa {ewa}");
        assert!((area - 1.0).abs() < 0.01, "area {area}");
        // The sheet renderer applies the same rule through its footprint table.
        let s = RenderSettings {
            width: 12,
            height: 12,
            mode: RenderMode::Xray,
            ..RenderSettings::default()
        };
        let r = render(&vol, &cam, &t, &s).unwrap();
        let px = Projection::new(&cam, 12, 12).unwrap().pixel_size_at(1.0);
        let dense: f64 = r
            .values
            .unwrap()
            .values()
            .iter()
            .map(|&v| v as f64)
            .sum::<f64>()
            * px
            * px;
        assert!((dense / mass - 1.0).abs() < 0.01, "dense {}", dense / mass);
        let s = RenderSettings {
            antialias: Antialias::Area,
            ..s
        };
        let r = render(&vol, &cam, &t, &s).unwrap();
        let sum: f64 = r.values.unwrap().values().iter().map(|&v| v as f64).sum();
        let dense_area = sum * px * px / mass;
        assert!((dense_area - 1.0).abs() < 0.01, "dense area {dense_area}");
    }

    #[test]
    fn depth_contour_marks_the_k_line() {
        let depth = ScalarImage::from_values(
            4,
            3,
            vec![
                1.0,
                1.0,
                3.0,
                3.0, //
                1.0,
                2.0,
                3.0,
                3.0, //
                f32::NAN,
                1.0,
                1.0,
                3.0,
            ],
        )
        .unwrap();
        let mut img = Image::new(4, 3);
        draw_depth_contour(&mut img, &depth, 2.5, [1.0, 0.0, 0.0]).unwrap();
        assert!(draw_depth_contour(&mut Image::new(3, 3), &depth, 2.5, [0.0; 3]).is_err());
        let marked: Vec<bool> = img.pixels().iter().map(|p| p[3] == 1.0).collect();
        assert_eq!(
            marked,
            vec![
                false, false, true, false, false, false, true, false, false, false, false, true
            ]
        );
    }
}
