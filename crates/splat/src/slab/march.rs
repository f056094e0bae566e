//! The march through the planes: each band of image rows through every plane, each pixel
//! sampled, classified and composited front to back (or compared, for MIP and MinIP). The
//! per-pixel code here is the scalar twin of the AVX2 kernels (`super::avx2`), which take the
//! runs of eight pixels where the CPU has AVX2.

#[cfg(target_arch = "x86_64")]
use super::avx2::{composite_run_avx2, extreme_row_avx2, sample_run_avx2};
use super::math::{exp2_neg, trilinear};
use super::path::boundary_factor;
use super::reach::{RowReach, row_reach};
use super::shade::{
    LIGHT_SHIFT, SEGMENT_LIGHT_AT, SEGMENT_SECOND_LIGHT, shade_opacity, shaded_src_two,
    voxel_shaded_src,
};
use super::simd_available;
use super::tables::{FrameTables, PostTable, ShadeTable};
use super::view::{FRAC, Planes, View, Walk, clip_linear};
use crate::bricks::BrickGrid;
use crate::error::{Result, SplatError};
use crate::normals::VoxelShading;
use crate::sheets::{Progress, RenderMode, RenderSettings};
use crate::voxels::{Vox, Voxels};
use rayon::prelude::*;
use volsplat_core::glam::{DVec3, Vec3};
use volsplat_core::image::{Rgba, over_front_to_back};
use volsplat_core::{FrameClassifier, SampleInput, Scalar};

/// Pixel-planes of a frame per active brick below which [`row_reach`] projects the box alone
/// instead of each brick ([`bricks_worth_projecting`]).
const PIXEL_PLANES_PER_BRICK: usize = 256;

/// Whether projecting each of `n_active` bricks into a `width × height` image across
/// `n_planes` planes can pay (≈ 0.1 µs a brick, about what 256 pixel-planes of the march
/// cost where nothing is drawn): a preview of a large volume projects only its box (measured:
/// a 384³ CT-like head at 64², 2.3 ms of reach for a 37 ms frame, decision 0041).
fn bricks_worth_projecting(n_active: usize, width: usize, height: usize, n_planes: usize) -> bool {
    let pixel_planes = (width as u128) * (height as u128) * (n_planes as u128);
    (n_active as u128) * (PIXEL_PLANES_PER_BRICK as u128) <= pixel_planes
}

/// The most rows of one band of the slabs' parallel decomposition (`RenderSettings::band_height`
/// caps it further; `docs/decisions/0016-image-aligned-post-classified-slabs.md`).
const SLAB_BAND_ROWS: usize = 8;

/// Bands per thread in the first group of a frame's bands, between two progress reports of the
/// slabs (the threads meet at each report; later groups grow towards [`GROUP_TIME`]).
const BANDS_PER_THREAD: usize = 8;

/// About how long a later group of bands may take ([`next_group`]): the threads wait for the
/// slowest band at the end of each group, and a caller hears of progress (and can cancel) only
/// between groups, so a group is made as long as a progress report can wait. Measured on
/// Colin27 shaded at 512², 2 threads: one group after the first saved 1.5 % against groups of
/// 16 bands (`docs/BENCHMARKS.md` §38).
const GROUP_TIME: std::time::Duration = std::time::Duration::from_millis(100);

/// The size of the group of bands after one of `n` bands (planned as `group`) took `took`: as
/// many bands as fit in [`GROUP_TIME`] at that rate, never fewer than `group` (bands of uneven
/// cost do not shrink it) nor more than 2²⁰.
fn next_group(group: usize, n: usize, took: std::time::Duration) -> usize {
    let per_band = took.as_secs_f64() / n.max(1) as f64;
    let fit = if per_band > 0.0 {
        (GROUP_TIME.as_secs_f64() / per_band).min((1u32 << 20) as f64) as usize
    } else {
        1 << 20
    };
    fit.max(group)
}

#[derive(Default, Clone, Copy)]
pub(super) struct Counters {
    /// Samples reconstructed.
    pub(super) samples: u64,
    /// Samples with non-zero opacity composited (or MIP samples compared).
    pub(super) visible: u64,
    /// Samples skipped because the pixel was opaque.
    pub(super) terminated: u64,
}

impl Counters {
    pub(super) fn add(self, o: Counters) -> Counters {
        Counters {
            samples: self.samples + o.samples,
            visible: self.visible + o.visible,
            terminated: self.terminated + o.terminated,
        }
    }
}

/// What a frame's march reads beside the voxels: the planes, the tables, the bricks' flags.
pub(super) struct Frame<'a> {
    pub(super) dims: [usize; 3],
    /// The upper corner of the box the rays cross, in the index space of the view
    /// ([`drawn_geometry`]): `n − 1`, or 1 along an axis of one sample (its voxel, `[0, 1]`
    /// there, shifted by half a voxel; every position on it reads the one sample).
    ///
    /// [`drawn_geometry`]: super::view::drawn_geometry
    pub(super) box_hi: [i64; 3],
    /// Largest cell index per axis (`max(n, 2) − 2`).
    pub(super) max_cell: [i64; 3],
    /// Sample eight pixels at a time with AVX2 (the CPU has it, and indices fit in i32).
    pub(super) simd: bool,
    /// Per index axis: the world direction of that axis divided by its spacing (a derivative
    /// per index step becomes a world gradient).
    pub(super) grad_to_world: [Vec3; 3],
    pub(super) bricks: &'a BrickGrid,
    /// Per brick, whether a sample in it can have opacity ([`FrameTables::active_bricks`]).
    pub(super) active: Vec<bool>,
    /// `active` as bytes, padded with three zero bytes (AVX2 gathers read 4 bytes).
    pub(super) active_bytes: Vec<u8>,
    /// MIP: each brick's maximum; MinIP: its minimum (empty otherwise): the one bound of
    /// `bricks.ranges` that the mode tests, in half the memory.
    pub(super) extreme_bounds: Vec<f32>,
    pub(super) skip_empty: bool,
    pub(super) view: View,
    pub(super) classifier: &'a FrameClassifier,
    /// Unshaded, density-indexed classification as one premultiplied table.
    pub(super) post: Option<&'a PostTable>,
    /// Shaded, density-indexed classification.
    pub(super) shaded: Option<&'a ShadeTable>,
    /// With `shaded`: the lights applied to every direction code, where the voxels are shaded
    /// ([`ShadeAt::Voxels`]), and the voxels' codes ([`NormalField::codes`]; empty otherwise).
    ///
    /// [`ShadeAt::Voxels`]: crate::normals::ShadeAt::Voxels
    /// [`NormalField::codes`]: crate::normals::NormalField::codes
    pub(super) voxel: Option<&'a VoxelShading>,
    pub(super) codes: &'a [u16],
    /// Pre-integrated classification of the segments between planes
    /// ([`RenderSettings::preintegrate`]).
    ///
    /// [`RenderSettings::preintegrate`]: crate::sheets::RenderSettings::preintegrate
    pub(super) preint: bool,
    pub(super) mode: RenderMode,
    pub(super) shade: bool,
    pub(super) cutoff: f32,
    pub(super) j0: i64,
    pub(super) n_planes: usize,
    /// The planes the composite march visits, `[first, end)`: all of them, or those that can
    /// meet a brick's cells ([`RenderSettings::owned_cells`]).
    ///
    /// [`RenderSettings::owned_cells`]: crate::sheets::RenderSettings::owned_cells
    pub(super) plane_range: (usize, usize),
    pub(super) delta: f64,
    pub(super) dmin: f64,
    pub(super) depth_scale: f64,
    pub(super) width: usize,
    pub(super) clip: Vec<(DVec3, f64)>,
    /// Composite: per image row, the planes and pixels that can meet a brick with opacity
    /// ([`row_reach`]); every plane and pixel for the other modes.
    pub(super) reach: RowReach,
}

/// The march of one frame: its [`Frame`] and where the voxels are loaded from (`V`:
/// [`Vox`]: an array in memory or resident bricks).
pub(super) struct Ctx<'a, T, V = Vox<'a, T>> {
    pub(super) f: &'a Frame<'a>,
    /// Where the voxels' values are loaded from.
    pub(super) vox: V,
    _t: std::marker::PhantomData<fn() -> T>,
}

impl<'a, T, V> std::ops::Deref for Ctx<'a, T, V> {
    type Target = Frame<'a>;

    #[inline(always)]
    fn deref(&self) -> &Frame<'a> {
        self.f
    }
}

impl<'a, T: Scalar, V: Voxels<T>> Ctx<'a, T, V> {
    /// The march of `frame` reading its voxels through `vox`.
    pub(super) fn new(frame: &'a Frame<'a>, vox: V) -> Self {
        Ctx {
            f: frame,
            vox,
            _t: std::marker::PhantomData,
        }
    }
}

impl<'a> Frame<'a> {
    /// The march of one frame of a volume of geometry `grid` under `settings`: through
    /// `planes`, classified by `classifier` through `tables`, skipping the bricks of `bricks`
    /// that `active` leaves out. `data_len`: the number of samples the addressing indexes
    /// (the AVX2 kernels need it below `i32::MAX`).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        grid: &volsplat_core::Grid,
        data_len: usize,
        settings: &RenderSettings,
        planes: Planes,
        tables: &'a FrameTables<'a>,
        classifier: &'a FrameClassifier,
        bricks: &'a BrickGrid,
        active: Vec<bool>,
    ) -> Self {
        let dims = grid.dims;
        let composite = settings.mode == RenderMode::Composite;
        let n_active = active.iter().filter(|&&a| a).count();
        let all_active = n_active == active.len();
        let box_hi = planes.geo.dims.map(|n| n as i64 - 1);
        let per_brick = !all_active
            && bricks_worth_projecting(n_active, settings.width, settings.height, planes.n_planes);
        let reach = if composite {
            row_reach(
                &planes.view,
                box_hi,
                bricks,
                per_brick.then_some(&active[..]),
                (planes.j0, planes.delta, planes.n_planes),
                settings.width,
                settings.height,
            )
        } else {
            RowReach::all(planes.n_planes, settings.width, settings.height)
        };
        Frame {
            dims,
            box_hi,
            max_cell: dims.map(|n| n.max(2) as i64 - 2),
            simd: settings.simd && simd_available() && data_len < i32::MAX as usize,
            grad_to_world: tables.grad_to_world,
            bricks,
            active_bytes: active.iter().map(|&a| u8::from(a)).chain([0; 3]).collect(),
            active,
            extreme_bounds: match settings.mode {
                RenderMode::Mip => bricks.ranges.iter().map(|r| r[1]).collect(),
                RenderMode::Minip => bricks.ranges.iter().map(|r| r[0]).collect(),
                _ => Vec::new(),
            },
            skip_empty: composite && !all_active,
            view: planes.view,
            classifier,
            post: tables.post.as_ref(),
            shaded: tables.shaded.as_ref(),
            voxel: tables.voxel.as_ref(),
            codes: tables.codes,
            preint: tables.preint,
            mode: settings.mode,
            shade: tables.shade,
            cutoff: settings.opacity_cutoff,
            j0: planes.j0,
            n_planes: planes.n_planes,
            plane_range: (0, planes.n_planes),
            delta: planes.delta,
            dmin: planes.dmin,
            depth_scale: if planes.dmax > planes.dmin {
                1.0 / (planes.dmax - planes.dmin)
            } else {
                0.0
            },
            width: settings.width,
            clip: settings
                .clip
                .iter()
                .map(|p| (DVec3::from(p.normal), p.offset))
                .collect(),
            reach,
        }
    }
}

impl<'a, T: Scalar, V: Voxels<T>> Ctx<'a, T, V> {
    /// Marches the image of `settings.height` rows, band by band, through every plane: the
    /// bands go to the threads in groups, and `progress` is called after each group with
    /// `sheets_done`/`sheets_total` counting bands (`false` cancels with
    /// [`SplatError::Cancelled`]). Returns the accumulated pixels (MIP/MinIP: the extreme in
    /// the first channel, NaN where no plane met the volume) and the counters.
    pub(super) fn march_bands(
        &self,
        settings: &RenderSettings,
        progress: &mut dyn FnMut(&Progress) -> bool,
    ) -> Result<(Vec<Rgba>, Counters)> {
        let (w, h) = (settings.width, settings.height);
        let mut acc = vec![self.acc_init(); w * h];
        let band_h = self.band_rows(settings);
        let n_bands = h.div_ceil(band_h);
        let mut group = self.group_bands();
        let mut done = 0;
        let mut counters = Counters::default();
        let chunks: Vec<(usize, &mut [Rgba])> = acc.chunks_mut(band_h * w).enumerate().collect();
        let mut chunks = chunks.into_iter().peekable();
        while chunks.peek().is_some() {
            let batch: Vec<(usize, &mut [Rgba])> = chunks.by_ref().take(group).collect();
            let n = batch.len();
            let t = std::time::Instant::now();
            counters = counters.add(self.run_bands(batch, band_h));
            done += n;
            group = next_group(group, n, t.elapsed());
            // The accumulation of finished bands is only visible after the loop (the bands hold
            // it mutably); the callback gets the count.
            if !progress(&Progress {
                sheets_done: done,
                sheets_total: n_bands,
                accumulation: &[],
            }) {
                return Err(SplatError::Cancelled);
            }
        }
        Ok((acc, counters))
    }

    /// Marches the bands of `batch` (band index, its rows' pixels; `band_h` rows a band) in
    /// parallel.
    pub(super) fn run_bands(&self, batch: Vec<(usize, &mut [Rgba])>, band_h: usize) -> Counters {
        // One job per band: a band's cost is very uneven (empty rows cost nearly nothing), and
        // rayon's adaptive splitting would otherwise leave runs of bands to one thread.
        batch
            .into_par_iter()
            .with_max_len(1)
            .map(|(b, rows)| self.band(b * band_h, rows))
            .reduce(Counters::default, Counters::add)
    }
}

impl Frame<'_> {
    /// A pixel before the march: transparent black, or for MIP/MinIP NaN in the first
    /// channel (no plane met the volume yet).
    pub(super) fn acc_init(&self) -> Rgba {
        match self.mode {
            RenderMode::Mip | RenderMode::Minip => [f32::NAN, 0.0, 0.0, 0.0],
            _ => [0.0; 4],
        }
    }

    /// Rows per band: at most `SLAB_BAND_ROWS`. A band's work is very uneven here (a band
    /// through an opaque object stops after a few planes, one beside it runs through the whole
    /// volume), so many small bands balance the threads better than a few large ones. The
    /// image does not depend on the band height (every pixel's arithmetic is its own).
    pub(super) fn band_rows(&self, settings: &RenderSettings) -> usize {
        settings.band_height.min(SLAB_BAND_ROWS)
    }

    /// Bands handed to the threads between two progress reports: the threads wait for the
    /// slowest band of a group, so a group holds several bands per thread.
    pub(super) fn group_bands(&self) -> usize {
        (BANDS_PER_THREAD * rayon::current_num_threads()).max(2 * BANDS_PER_THREAD)
    }

    pub(super) fn depth(&self, plane: usize) -> f64 {
        (self.j0 + plane as i64) as f64 * self.delta
    }
}

impl<T: Scalar, V: Voxels<T>> Ctx<'_, T, V> {
    /// Row `y` of the plane at depth `d` in 32.32 fixed-point index coordinates (VTK's ray
    /// caster steps in 15-bit fixed point): integer steps are exact, so a pixel's position is
    /// the same whichever pixels around it are skipped. The span holds the pixels whose point
    /// lies in the box the rays cross, `[0, box_hi]` (the voxel centres' box, decision 0023),
    /// checked in fixed point, so no clamping is needed below 0.
    pub(super) fn walk(&self, y: usize, d: f64) -> Walk {
        self.view.walk(y, d, self.width, self.box_hi)
    }

    /// The pixels of row `y` at depth `d` kept by every clipping plane.
    pub(super) fn clip_span(&self, y: usize, d: f64, r: (i64, i64)) -> (i64, i64) {
        if self.clip.is_empty() || r.0 > r.1 {
            return r;
        }
        let (p0, dp) = self.view.row_world(y, d);
        let mut r = r;
        for &(n, off) in &self.clip {
            r = clip_linear(r, n.dot(p0) + off, n.dot(dp), 0.0, f64::INFINITY);
        }
        r
    }

    /// Reconstructs the pixels `span` (within `walk.span`) of a row into `out` (NaN elsewhere
    /// and where the brick is skipped). Returns the number of samples reconstructed.
    ///
    /// Runs of pixels in active bricks are sampled at `s + x·st` (f32, per pixel, so a pixel's
    /// value does not depend on which pixels around it are skipped), eight at a time with AVX2
    /// where the CPU has it ([`sample_run_avx2`]) and one at a time otherwise; both do the same
    /// f32 operations in the same order, so they give the same bits.
    fn sample_row(&self, walk: &Walk, span: (i64, i64), out: &mut [f32]) -> u64 {
        out.fill(f32::NAN);
        let mut count = 0;
        let (lo, hi) = (span.0.max(walk.span.0), span.1.min(walk.span.1));
        self.for_each_run(walk, lo, hi, |a, b| {
            self.sample_run(walk, a, b, out);
            count += (b - a + 1) as u64;
        });
        count
    }

    /// Samples the pixels `a..=b` of a row (all inside the volume) into `out`.
    #[inline]
    fn sample_run(&self, walk: &Walk, a: usize, b: usize, out: &mut [f32]) {
        #[allow(unused_mut)]
        let mut x = a;
        #[cfg(target_arch = "x86_64")]
        if self.simd {
            // SAFETY: `simd` is set only when the CPU has AVX2 (`render_slabs`).
            x = unsafe { sample_run_avx2(self, walk, a, b, out) };
        }
        for (x, o) in out.iter_mut().enumerate().take(b + 1).skip(x) {
            *o = self.sample_scalar(walk, x);
        }
    }

    /// The cell of pixel `x` of a row and the fractions in it, from the row's f32 start and step:
    /// the scalar twin of [`Sampler8::locate`] and [`Cells8::fractions`].
    ///
    /// [`Sampler8::locate`]: super::avx2::sampler::Sampler8::locate
    /// [`Cells8::fractions`]: super::avx2::sampler::Cells8::fractions
    #[inline(always)]
    pub(super) fn cell_f32(&self, walk: &Walk, x: usize) -> ([usize; 3], [f32; 3]) {
        walk.cell_f32(x, self.max_cell)
    }

    /// The step from the samples of row `y` on the plane at depth `d` back to the plane before
    /// ([`RowCtx::back_s`], [`RowCtx::back_st`]): index units, at pixel `x` `back_s + x·back_st`.
    pub(super) fn back_step(&self, y: usize, d: f64, walk: &Walk) -> ([f32; 3], [f32; 3]) {
        let (s0, st0) = self.view.row(y, d - self.delta);
        (
            [0, 1, 2].map(|a| s0[a] as f32 - walk.s32[a]),
            [0, 1, 2].map(|a| st0[a] as f32 - walk.st32[a]),
        )
    }

    /// One sample at pixel `x`: the scalar twin of [`sample_run_avx2`].
    #[inline(always)]
    fn sample_scalar(&self, walk: &Walk, x: usize) -> f32 {
        let (c, f) = self.cell_f32(walk, x);
        self.sample_cell(c, f)
    }

    /// The trilinear sample in cell `c` at fractions `f`.
    #[inline(always)]
    fn sample_cell(&self, c: [usize; 3], f: [f32; 3]) -> f32 {
        trilinear(&self.vox, self.vox.cell_base(c), f)
    }

    /// Renders the band of image rows `[y0, y0 + rows.len()/width)` through every plane.
    pub(super) fn band(&self, y0: usize, acc: &mut [Rgba]) -> Counters {
        let part = Part {
            cols: (0, self.width),
            planes: self.plane_range,
        };
        self.band_in(y0, acc, part, &mut Carry::default())
    }

    /// Renders the pixels `part.cols` (`[first, end)`) of the band of image rows
    /// `[y0, y0 + rows.len()/width)` through the planes `part.planes` (within
    /// [`Frame::plane_range`]), continuing from what `acc` holds (the accumulation, or
    /// MIP/MinIP's extreme in channel 0) and `carry`: marching a band's planes in consecutive
    /// pieces gives the bits of marching them at once, and so does marching its columns apart
    /// or its rows as bands of their own (each pixel's arithmetic is its own). Out-of-core
    /// frames whose band meets more bricks than the budget holds: `super::bricked`. The
    /// counters of column pieces differ (a row's live window is narrowed per piece).
    pub(super) fn band_in(
        &self,
        y0: usize,
        acc: &mut [Rgba],
        part: Part,
        carry: &mut Carry,
    ) -> Counters {
        let w = self.width;
        let rows = acc.len() / w;
        match (self.post, self.shaded) {
            _ if self.mode != RenderMode::Composite => self.band_extreme(y0, rows, acc, part),
            (Some(t), _) => self.band_post(y0, rows, acc, Post::Table(t), part, carry),
            (None, Some(t)) => match self.voxel {
                Some(vs) => self.band_post(y0, rows, acc, Post::Voxel(t, vs), part, carry),
                None => self.band_post(y0, rows, acc, Post::Shaded(t), part, carry),
            },
            (None, None) => self.band_plain(y0, rows, acc, part, carry),
        }
    }

    /// The path factors and ray extents of the rows `[y0, y0 + rows)`, computed by the first
    /// piece of a band and kept in its `carry` for the next.
    fn paths<'c>(&self, y0: usize, rows: usize, paths: &'c mut Option<Paths>) -> &'c Paths {
        paths.get_or_insert_with(|| {
            let kf = self.path_factors(y0, rows);
            let (din, dout) = self.ray_extents(y0, rows);
            Paths { kf, din, dout }
        })
    }

    /// Unshaded composite through the post-classification table: each run of pixels in active
    /// bricks is sampled, classified and composited in one pass ([`composite_run_avx2`] eight
    /// pixels at a time where the CPU has AVX2, [`Ctx::composite_one`] otherwise and for the
    /// ends of runs; the same f32 operations in the same order, so the same bits). The band's
    /// accumulation is kept as four planes of channels while it is composited.
    fn band_post(
        &self,
        y0: usize,
        rows: usize,
        acc: &mut [Rgba],
        post: Post<'_>,
        Part { cols, planes }: Part,
        carry: &mut Carry,
    ) -> Counters {
        let w = self.width;
        let mut c = Counters::default();
        // Each row's pixels and planes that can meet a brick with opacity: the others are
        // skipped (exactly: `super::reach`).
        let reach = &self.reach.rows[y0..y0 + rows];
        let mut live: Vec<(i64, i64)> = reach
            .iter()
            .map(|r| (r.lo.max(cols.0 as i64), r.hi.min(cols.1 as i64 - 1)))
            .collect();
        let first = reach.iter().map(|r| r.first as usize).min().unwrap_or(0);
        let end = reach.iter().map(|r| r.end as usize).max().unwrap_or(0);
        let planes = (planes.0.max(first), planes.1.min(end));
        if planes.0 >= planes.1 || live.iter().all(|l| l.0 > l.1) {
            return c;
        }
        let channel = |ch: usize| acc.iter().map(|px| px[ch]).collect::<Vec<f32>>();
        let mut band = BandAcc {
            r: channel(0),
            g: channel(1),
            b: channel(2),
            a: channel(3),
        };
        let Carry { prev, stamp, paths } = carry;
        let Paths { kf, din, dout } = self.paths(y0, rows, paths);
        let half = (0.5 * self.delta) as f32;
        let preint = self.preint_for(post);
        if preint && prev.len() != rows * w {
            *prev = vec![0.0f32; rows * w];
            *stamp = vec![u32::MAX; rows * w];
        }
        for p in planes.0..planes.1 {
            let d = self.depth(p);
            let mut any_live = false;
            for (r, live_r) in live.iter_mut().enumerate() {
                let y = y0 + r;
                let o = r * w;
                if reach[r].done_at(p) {
                    continue;
                }
                let alpha = &band.a[o..o + w];
                let Some(lw) = shrink_live(live_r, self.cutoff, |x| alpha[x]) else {
                    continue;
                };
                any_live = true;
                if !reach[r].has_plane(p) {
                    continue;
                }
                let (c0, c1) = self.reach.cols(y, p);
                let (lw0, lw1) = (lw.0.max(c0), lw.1.min(c1));
                if lw0 > lw1 {
                    continue;
                }
                let walk = self.walk(y, d);
                let span = self.clip_span(y, d, walk.span);
                let (lo, hi) = (
                    span.0.max(lw0).max(walk.span.0),
                    span.1.min(lw1).min(walk.span.1),
                );
                if lo > hi {
                    continue;
                }
                // The step back to the plane before: where pre-integration lit at the voxels
                // lights a segment, and where the samples' two lights sit (decision 0036).
                let steps = match post {
                    Post::Voxel(..) => preint,
                    Post::Shaded(_) => true,
                    Post::Table(_) => false,
                };
                let (back_s, back_st) = if steps {
                    self.back_step(y, d, &walk)
                } else {
                    ([0.0; 3], [0.0; 3])
                };
                let mut row = RowCtx {
                    r: &mut band.r[o..o + w],
                    g: &mut band.g[o..o + w],
                    b: &mut band.b[o..o + w],
                    a: &mut band.a[o..o + w],
                    kf: &kf[o..o + w],
                    din: &din[o..o + w],
                    dout: &dout[o..o + w],
                    d: d as f32,
                    half,
                    prev: if preint { &mut prev[o..o + w] } else { &mut [] },
                    stamp: if preint {
                        &mut stamp[o..o + w]
                    } else {
                        &mut []
                    },
                    plane: p as u32,
                    back_s,
                    back_st,
                };
                let (a, b) = (lo as usize, hi as usize);
                #[allow(unused_mut)]
                let mut x = a;
                #[cfg(target_arch = "x86_64")]
                if self.simd {
                    // SAFETY: `simd` is set only when the CPU has AVX2 (`render_slabs`).
                    x = unsafe { composite_run_avx2(self, &walk, a, b, &mut row, post, &mut c) };
                }
                for x in x..=b {
                    self.composite_one(&walk, x, &mut row, post, &mut c);
                }
            }
            if !any_live {
                break;
            }
        }
        for (i, px) in acc.iter_mut().enumerate() {
            *px = [band.r[i], band.g[i], band.b[i], band.a[i]];
        }
        c
    }

    /// [`Ctx::composite_one`] for the pixels `x + l`, `l < n`, whose bit `l` of `lanes` is set:
    /// the lanes of an AVX2 group that its source cannot read. Out of line, so that the
    /// kernel's group loop stays small enough to be inlined whole (measured with perf: inlined,
    /// the shaded kernel lost 20 %).
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn composite_lanes(
        &self,
        walk: &Walk,
        x: usize,
        n: usize,
        lanes: i32,
        row: &mut RowCtx<'_>,
        post: Post<'_>,
        c: &mut Counters,
    ) {
        for l in 0..n {
            if lanes >> l & 1 == 1 {
                self.composite_one(walk, x + l, row, post, c);
            }
        }
    }

    /// Samples, classifies and composites pixel `x` of a row ([`Ctx::band_post`]): the scalar
    /// twin of [`composite_run_avx2`] (with `PostSource` unshaded, and with `ShadeSource` when
    /// `post` is shaded).
    #[inline(always)]
    pub(super) fn composite_one(
        &self,
        walk: &Walk,
        x: usize,
        row: &mut RowCtx<'_>,
        post: Post<'_>,
        c: &mut Counters,
    ) {
        if row.a[x] >= self.cutoff {
            c.terminated += 1;
            return;
        }
        let (cell, f) = self.cell_f32(walk, x);
        if !self.active[self.bricks.index(cell[0], cell[1], cell[2])] {
            return;
        }
        c.samples += 1;
        let rho = self.sample_cell(cell, f);
        let k = boundary_factor(row.kf[x], row.din[x], row.dout[x], row.d, row.half);
        let preint = self.preint_for(post);
        // Pre-integration: the density at the pixel's sample on the plane before, or this
        // sample's where there is none (the segment is then one point).
        let u = if preint {
            let u = if row.stamp[x] == row.plane {
                row.prev[x]
            } else {
                rho
            };
            row.prev[x] = rho;
            row.stamp[x] = row.plane + 1;
            u
        } else {
            rho
        };
        let corrected = preint || self.view.perspective || k != 1.0;
        let src = match post {
            Post::Table(t) if preint => Self::post_seg_src(t.segment(u, rho), k),
            Post::Table(t) => Self::post_src(t, rho, k, corrected),
            Post::Shaded(t) => {
                // Pre-integrated: the segment's entry, lit at ¼ and ¾ of the way back along it
                // (where it is more than one value); else the sample's, lit at ±¼ of the step.
                let (v, second) = if preint {
                    let second = if u != rho {
                        SEGMENT_SECOND_LIGHT
                    } else {
                        -LIGHT_SHIFT
                    };
                    (t.segment_entry(u, rho), second)
                } else {
                    (t.entry(rho), -LIGHT_SHIFT)
                };
                let [fa, fb] = light_fractions((row.back_s, row.back_st), x, f, second);
                let g = self.gradient_lerp(cell, [fa, fb]);
                shaded_src_two(t, v, g, k, corrected)
            }
            Post::Voxel(t, vs) => {
                let (v, (cell, f)) = if preint {
                    let v = t.segment_entry(u, rho);
                    // Lit at the segment's middle (`SEGMENT_LIGHT_AT`).
                    let h = match shade_opacity(&v, k, corrected) {
                        Some(_) if u != rho => SEGMENT_LIGHT_AT,
                        _ => 0.0,
                    };
                    (v, self.light_cell(walk, row, x, h))
                } else {
                    (t.entry(rho), (cell, f))
                };
                let base = self.vox.cell_base(cell);
                let [ux, uy, uz] = self.vox.up();
                let offs = [0, ux, uy, uy + ux, uz, uz + ux, uz + uy, uz + uy + ux];
                let codes = offs.map(|o| self.codes[base + o]);
                voxel_shaded_src(t, vs, v, &codes, f, k, corrected)
            }
        };
        let Some(src) = src else {
            return;
        };
        let tr = 1.0 - row.a[x];
        row.r[x] += tr * src[0];
        row.g[x] += tr * src[1];
        row.b[x] += tr * src[2];
        row.a[x] += tr * src[3];
        c.visible += 1;
    }

    /// The premultiplied colour of an unshaded sample of density `rho` with slab exponent `k`
    /// (`corrected`: `k ≠ 1` or perspective), or `None` where it has no opacity: the scalar
    /// twin of [`PostSource`]'s classification.
    ///
    /// [`PostSource`]: super::avx2::composite::PostSource
    #[inline(always)]
    fn post_src(t: &PostTable, rho: f32, k: f32, corrected: bool) -> Option<Rgba> {
        if corrected {
            // Colour and log-transmittance per table entry: the path correction is one exp2
            // (no log2, no division).
            Self::post_seg_src(t.lookup_in(&t.persp, rho), k)
        } else {
            let v = t.lookup(rho);
            if v[3] <= 0.0 || v[3].is_nan() {
                return None;
            }
            Some(v)
        }
    }

    /// The premultiplied colour of `[c_r, c_g, c_b, log2(1 − α)]` (a `persp` entry, or a
    /// segment's averages, [`PostTable::segment`]) with slab exponent `k`: `c·a` and
    /// `a = 1 − 2^(k·L)`, or `None` where `L ≥ 0` (no opacity; NaN neither).
    #[inline(always)]
    pub(super) fn post_seg_src([cr, cg, cb, l]: Rgba, k: f32) -> Option<Rgba> {
        // `l < 0` is false for NaN too.
        (l < 0.0).then(|| {
            let a = 1.0 - exp2_neg(k * l);
            [cr * a, cg * a, cb * a, a]
        })
    }

    /// Whether the samples of `post` are pre-integrated: asked for
    /// ([`RenderSettings::preintegrate`]); every density table pre-integrates (unshaded, shaded
    /// at the voxels, shaded at the samples).
    ///
    /// [`RenderSettings::preintegrate`]: crate::sheets::RenderSettings::preintegrate
    #[inline(always)]
    pub(super) fn preint_for(&self, _post: Post<'_>) -> bool {
        self.preint
    }

    /// Calls `f(a, b)` for the runs of pixels `lo..=hi` (inside `walk.span`) whose cells lie in
    /// active bricks, consecutive active runs merged (space leaping per row); the whole range
    /// when nothing is skipped.
    #[inline]
    fn for_each_run(&self, walk: &Walk, lo: i64, hi: i64, mut f: impl FnMut(usize, usize)) {
        if !self.skip_empty {
            if lo <= hi {
                f(lo as usize, hi as usize);
            }
            return;
        }
        let mut pending: Option<(usize, usize)> = None;
        self.brick_runs(walk, lo, hi, |x, end, brick| {
            if self.active[brick] {
                pending = Some(match pending {
                    Some((a, _)) => (a, end),
                    None => (x, end),
                });
            } else if let Some((a, b)) = pending.take() {
                f(a, b);
            }
        });
        if let Some((a, b)) = pending {
            f(a, b);
        }
    }

    /// Calls `f(a, b, brick)` for the runs of pixels `lo..=hi` (inside `walk.span`) whose cells
    /// lie in one brick, in order.
    #[inline]
    fn brick_runs(&self, walk: &Walk, lo: i64, hi: i64, mut f: impl FnMut(usize, usize, usize)) {
        // Per axis, the first pixel whose cell leaves the current brick along that axis: only
        // the axis (axes) just crossed is recomputed at the start of a run.
        let mut next = [i64::MIN; 3];
        let inv = walk.st.map(|v| {
            if v == 0 {
                0.0
            } else {
                1.0 / v.unsigned_abs() as f64
            }
        });
        let mut x = lo;
        while x <= hi {
            let q = walk.at(x);
            let (cell, _) = self.cell(q);
            let mut end = hi;
            for (a, next_a) in next.iter_mut().enumerate() {
                if *next_a <= x {
                    *next_a = x.saturating_add(walk.run_along(a, q[a], cell[a], inv[a]));
                }
                end = end.min(*next_a - 1);
            }
            let end = end.max(x);
            f(
                x as usize,
                end as usize,
                self.bricks.index(cell[0], cell[1], cell[2]),
            );
            x = end + 1;
        }
    }

    /// MIP (MinIP): the largest (smallest) reconstructed value over the planes, kept as one
    /// plane of values for the band. The planes go coarse to fine ([`coarse_to_fine`]; the
    /// extreme does not depend on their order): the early, sparse planes give each pixel a
    /// near-final extreme, and afterwards every group of pixels that its brick cannot beat is
    /// skipped (exact: a trilinear value lies in its brick's range). The others are sampled and
    /// compared eight at a time (`extreme_row_avx2`) or one at a time
    /// ([`Ctx::extreme_one`]); the samples are the same bits either way, so is their extreme.
    fn band_extreme(
        &self,
        y0: usize,
        rows: usize,
        acc: &mut [Rgba],
        Part {
            cols,
            planes: (first, end),
        }: Part,
    ) -> Counters {
        let w = self.width;
        let mip = self.mode == RenderMode::Mip;
        let mut c = Counters::default();
        let mut vals: Vec<f32> = acc.iter().map(|px| px[0]).collect();
        let planes = first..end;
        for p in coarse_to_fine(self.n_planes)
            .into_iter()
            .filter(|p| planes.contains(p))
        {
            let d = self.depth(p);
            for r in 0..rows {
                let y = y0 + r;
                let walk = self.walk(y, d);
                let span = self.clip_span(y, d, walk.span);
                let (lo, hi) = (
                    span.0.max(walk.span.0).max(cols.0 as i64),
                    span.1.min(walk.span.1).min(cols.1 as i64 - 1),
                );
                if lo > hi {
                    continue;
                }
                let row = &mut vals[r * w..(r + 1) * w];
                let (lo, hi) = (lo as usize, hi as usize);
                #[allow(unused_mut)]
                let mut x = lo;
                #[cfg(target_arch = "x86_64")]
                if self.simd {
                    // SAFETY: `simd` is set only when the CPU has AVX2 (`render_slabs`).
                    x = unsafe { extreme_row_avx2(self, &walk, lo, hi, row, mip, &mut c) };
                }
                for x in x..=hi {
                    self.extreme_one(&walk, x, row, mip, &mut c);
                }
            }
        }
        for (px, &v) in acc.iter_mut().zip(&vals) {
            px[0] = v;
        }
        c
    }

    /// Pixel `x` of a row ([`Ctx::band_extreme`]): skipped where its cell's brick cannot beat
    /// the pixel's extreme (exact: a trilinear value lies in its cell's brick's range), sampled
    /// and compared otherwise. The scalar twin of [`extreme_row_avx2`].
    #[inline(always)]
    fn extreme_one(&self, walk: &Walk, x: usize, row: &mut [f32], mip: bool, c: &mut Counters) {
        let (cell, f) = self.cell_f32(walk, x);
        let bound = self.extreme_bounds[self.bricks.index(cell[0], cell[1], cell[2])];
        let cur = row[x];
        if bound.is_nan() || !cur.is_nan() && if mip { bound <= cur } else { bound >= cur } {
            return;
        }
        c.samples += 1;
        let v = self.sample_cell(cell, f);
        if cur.is_nan() || (mip && v > cur) || (!mip && v < cur) {
            row[x] = v;
        }
    }

    /// Composite through the classifier (tables that depend on more than the density, shaded or
    /// not): each sample is classified, with its gradient where the lights or the tables need
    /// one, as soon as it is reconstructed.
    fn band_plain(
        &self,
        y0: usize,
        rows: usize,
        acc: &mut [Rgba],
        Part {
            cols,
            planes: (first, end),
        }: Part,
        carry: &mut Carry,
    ) -> Counters {
        let w = self.width;
        let mut c = Counters::default();
        let mut line = vec![f32::NAN; w];
        // Live window of each row (composite): pixels outside it are opaque (or in another
        // piece's columns).
        let mut live: Vec<(i64, i64)> = vec![(cols.0 as i64, cols.1 as i64 - 1); rows];
        let Paths { kf, din, dout } = self.paths(y0, rows, &mut carry.paths);
        let half = (0.5 * self.delta) as f32;
        for p in first..end {
            let d = self.depth(p);
            let depth01 = ((d - self.dmin) * self.depth_scale).clamp(0.0, 1.0) as f32;
            let mut any_live = false;
            for r in 0..rows {
                let y = y0 + r;
                let walk = self.walk(y, d);
                let mut span = self.clip_span(y, d, walk.span);
                let back = if self.shade {
                    self.back_step(y, d, &walk)
                } else {
                    ([0.0; 3], [0.0; 3])
                };
                let row_acc = &mut acc[r * w..(r + 1) * w];
                let Some(lw) = shrink_live(&mut live[r], self.cutoff, |x| row_acc[x][3]) else {
                    continue;
                };
                any_live = true;
                span = (span.0.max(lw.0), span.1.min(lw.1));
                if span.0 > span.1 {
                    continue;
                }
                c.samples += self.sample_row(&walk, span, &mut line);
                for x in span.0 as usize..=span.1 as usize {
                    let rho = line[x];
                    if rho.is_nan() {
                        continue;
                    }
                    let px = &mut row_acc[x];
                    if px[3] >= self.cutoff {
                        c.terminated += 1;
                        continue;
                    }
                    // The first and last samples of a ray stand for the path from where the
                    // ray enters (leaves) the volume or its clipping, not a whole slab: without
                    // this the cut faces step from plane to plane (wood grain).
                    let i = r * w + x;
                    let k = boundary_factor(kf[i], din[i], dout[i], d as f32, half);
                    if self.classifier.density_opacity(rho) == Some(0.0) {
                        continue;
                    }
                    let input = |gradient| SampleInput {
                        density: rho,
                        gradient,
                        depth: depth01,
                    };
                    let rgba = if self.shade {
                        // Lit twice, at ±¼ of the slab's step (decision 0036), as the kernel
                        // lights density tables: the two classifications averaged.
                        let (c, f) = self.cell_f32(&walk, x);
                        let [fa, fb] = light_fractions(back, x, f, -LIGHT_SHIFT);
                        let ga = self.classifier.classify(&input(self.gradient_at(c, fa)));
                        let gb = self.classifier.classify(&input(self.gradient_at(c, fb)));
                        match (ga, gb) {
                            (None, None) => None,
                            (a, b) => {
                                let (a, b) = (a.unwrap_or([0.0; 4]), b.unwrap_or([0.0; 4]));
                                Some(std::array::from_fn(|ch| (a[ch] + b[ch]) * 0.5))
                            }
                        }
                    } else {
                        self.classifier.classify(&input(Vec3::ZERO))
                    };
                    if let Some(rgba) = rgba {
                        let rgba = self.path_correct(rgba, k);
                        over_front_to_back(px, rgba);
                        c.visible += 1;
                    }
                }
            }
            if !any_live {
                break;
            }
        }
        c
    }

    /// The cell (lower corner) holding the fixed-point index position `q` (every component in
    /// `[0, box_hi]`, as [`Ctx::walk`] guarantees) and the fractions in it. On the last voxel
    /// plane the cell is the one below with fraction 1 (along an axis of one sample, cell 0).
    #[inline(always)]
    fn cell(&self, q: [i64; 3]) -> ([usize; 3], [f32; 3]) {
        let mut c = [0usize; 3];
        let mut f = [0.0f32; 3];
        for a in 0..3 {
            let i = (q[a] >> FRAC).min(self.max_cell[a]);
            c[a] = i as usize;
            f[a] = ((q[a] - (i << FRAC)) >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
        }
        (c, f)
    }
}

/// Where a sample lit at the samples is lit twice (decision 0036): the fractions
/// `f + ¼·s` and `f + second·s` in its own cell (extrapolated where they leave it), with
/// `s = back_s + x·back_st` the step from pixel `x`'s sample back to the plane before, in index
/// units; `second` is `−¼` (the slab around the sample: [`LIGHT_SHIFT`]) or `¾` (a
/// pre-integrated segment: [`SEGMENT_SECOND_LIGHT`]). The scalar twin of
/// `ShadeSource::light_fractions` (`avx2/shade.rs`).
#[inline(always)]
pub(super) fn light_fractions(
    (back_s, back_st): ([f32; 3], [f32; 3]),
    x: usize,
    f: [f32; 3],
    second: f32,
) -> [[f32; 3]; 2] {
    let xf = x as f32;
    let step: [f32; 3] = std::array::from_fn(|a| back_s[a] + xf * back_st[a]);
    [
        std::array::from_fn(|a| f[a] + step[a] * LIGHT_SHIFT),
        std::array::from_fn(|a| f[a] + step[a] * second),
    ]
}

/// Narrows a row's window of live pixels (those whose opacity `alpha(x)` is below `cutoff`)
/// from both ends; `None` once every pixel of the row is opaque.
#[inline]
fn shrink_live(
    lw: &mut (i64, i64),
    cutoff: f32,
    alpha: impl Fn(usize) -> f32,
) -> Option<(i64, i64)> {
    while lw.0 <= lw.1 && alpha(lw.0 as usize) >= cutoff {
        lw.0 += 1;
    }
    while lw.1 >= lw.0 && alpha(lw.1 as usize) >= cutoff {
        lw.1 -= 1;
    }
    (lw.0 <= lw.1).then_some(*lw)
}

/// How [`Ctx::band_post`] classifies: through the unshaded table, or shaded.
#[derive(Clone, Copy)]
pub(super) enum Post<'a> {
    Table(&'a PostTable),
    Shaded(&'a ShadeTable),
    /// Shaded at the voxels, interpolated ([`ShadeAt::Voxels`]).
    ///
    /// [`ShadeAt::Voxels`]: crate::normals::ShadeAt::Voxels
    Voxel(&'a ShadeTable, &'a VoxelShading),
}

/// Which part of a band [`Ctx::band_in`] marches: the pixels `cols` (`[first, end)`) of each
/// of its rows through the planes `planes` (`[first, end)`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Part {
    pub(super) cols: (usize, usize),
    pub(super) planes: (usize, usize),
}

/// What a band's composite keeps between pieces of its planes ([`Ctx::band_in`]) beside its
/// accumulation: pre-integration's densities and stamps of the last plane each pixel was
/// sampled on (empty until the first piece that pre-integrates), and the band's path factors
/// and ray extents (computed by its first piece).
#[derive(Default)]
pub(super) struct Carry {
    prev: Vec<f32>,
    stamp: Vec<u32>,
    paths: Option<Paths>,
}

/// Per pixel of a band (row-major): the path factor and the depths where the ray enters and
/// leaves the volume ([`Ctx::path_factors`], [`Ctx::ray_extents`]).
struct Paths {
    kf: Vec<f32>,
    din: Vec<f32>,
    dout: Vec<f32>,
}

/// The accumulation of a band of rows as four planes of channels ([`Ctx::band_post`]).
struct BandAcc {
    r: Vec<f32>,
    g: Vec<f32>,
    b: Vec<f32>,
    a: Vec<f32>,
}

/// One row of a band being composited through one plane: its channels, and per pixel the path
/// factor and the depths where the ray enters and leaves the volume ([`Ctx::band_post`]).
pub(super) struct RowCtx<'a> {
    pub(super) r: &'a mut [f32],
    pub(super) g: &'a mut [f32],
    pub(super) b: &'a mut [f32],
    pub(super) a: &'a mut [f32],
    pub(super) kf: &'a [f32],
    pub(super) din: &'a [f32],
    pub(super) dout: &'a [f32],
    /// The plane's eye depth and half the slab thickness (world units).
    pub(super) d: f32,
    pub(super) half: f32,
    /// Pre-integration ([`Ctx::preint`]): per pixel the density sampled at the last plane
    /// that sampled it, and that plane's index + 1 (`u32::MAX` before any), so that a sample
    /// knows whether its pixel was sampled on the plane just before; `plane` is this plane's
    /// index. Empty without pre-integration.
    pub(super) prev: &'a mut [f32],
    pub(super) stamp: &'a mut [u32],
    pub(super) plane: u32,
    /// Pre-integration shaded at the voxels: the index-space step from this plane's sample of
    /// pixel `x` to the plane before's, `back_s + x·back_st` (f32; [`Ctx::light_cell`]).
    pub(super) back_s: [f32; 3],
    pub(super) back_st: [f32; 3],
}

/// `0..n` coarse to fine: every 16th, then the odd multiples of 8, of 4, of 2, and the odd
/// numbers; each number once.
fn coarse_to_fine(n: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).step_by(16).collect();
    for s in [8, 4, 2, 1] {
        order.extend((s..n).step_by(2 * s));
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bricks are projected one by one only where the frame's pixel-planes outnumber them
    /// enough: 512² × 441 planes (the CT of §38) with 14,336 active bricks does, a 64² preview of
    /// 384³ voxels (110,592 bricks) does not.
    #[test]
    fn bricks_are_projected_where_it_pays() {
        assert!(bricks_worth_projecting(14_336, 512, 512, 441));
        assert!(!bricks_worth_projecting(110_592, 64, 64, 600));
        assert!(bricks_worth_projecting(0, 1, 1, 0));
        assert!(!bricks_worth_projecting(usize::MAX, usize::MAX, 1, 1));
    }

    /// Later groups hold as many bands as fit in `GROUP_TIME` at the first group's rate, never
    /// fewer than planned, and a group that took no measurable time does not overflow.
    #[test]
    fn groups_grow_to_the_time_a_report_may_wait() {
        use std::time::Duration;
        // 16 bands in 10 ms: 0.625 ms a band, 160 in 100 ms.
        assert_eq!(next_group(16, 16, Duration::from_millis(10)), 160);
        // Slow bands: never below the planned group.
        assert_eq!(next_group(16, 16, Duration::from_secs(2)), 16);
        assert_eq!(next_group(16, 3, Duration::ZERO), 1 << 20);
        assert_eq!(next_group(16, 0, Duration::from_nanos(1)), 1 << 20);
    }

    #[test]
    fn coarse_to_fine_visits_every_plane_once() {
        for n in [0, 1, 2, 15, 16, 17, 100, 613] {
            let mut order = coarse_to_fine(n);
            if n > 32 {
                assert_eq!(&order[..3], &[0, 16, 32]);
            }
            order.sort_unstable();
            assert_eq!(order, (0..n).collect::<Vec<_>>(), "n = {n}");
        }
    }
}
