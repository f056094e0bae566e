//! The one sheet driver (Westover §4.3.2, "multiple independent sheet buffers"): batches of
//! sheets, bands of scanlines, progress and the thread split, shared by the sheet renderer
//! (`dense.rs`) and the splat-list renderer ([`crate::list`]), which supply only their
//! per-sheet classification and per-band splatting through [`SheetPass`] (as pbrt-v4's
//! `ImageTileIntegrator::Render` drives each integrator's `Li`). Also the frame's end: the
//! accumulation buffer turned into the picture ([`finish`]).
//!
//! Per batch of `sheets_per_batch` sheets, in the traversal order: the sheets are classified in
//! parallel (one task per sheet, each routing its splats to the bands their footprints touch),
//! then the bands splat and composite the batch's sheets in parallel, each band its sheets in
//! order; then `progress` sees the accumulation buffer. Every pixel receives its contributions
//! in the same order whatever the thread count, so the output is bit-identical for any number
//! of threads.

use super::band::BandState;
use super::settings::{Progress, RenderMode, RenderSettings, RenderStats, Rendered, ms};
use crate::error::{Result, SplatError, try_filled};
use rayon::prelude::*;
use std::time::Instant;
use volsplat_core::image::Rgba;
use volsplat_core::{CrioTables, Image, ScalarImage};

/// What a sheet renderer supplies to [`drive`]: its classification of one sheet and its
/// splatting of one sheet's splats into one band.
pub(crate) trait SheetPass: Sync {
    /// One classified sheet: its splats bucketed by band, and its counters.
    type Sheet: Default + Send + Sync;
    /// The renderer's name in errors about its output.
    const NAME: &'static str;
    /// Its accumulation buffer's name in out-of-memory errors.
    const IMAGE_BUFFER: &'static str;
    /// Whether [`SheetPass::classify_sheet`] reads the map of opaque tiles (front-to-back early
    /// splat termination); when not, the driver passes an empty map.
    fn reads_opaque_tiles(&self) -> bool;
    /// Transforms, culls and classifies sheet `sheet` (an index along the sheet axis) into
    /// `out`, routing each splat to the bands its footprint touches. `opaque`: the image's
    /// 4 × 4-pixel tiles that reached the opacity cutoff after the previous batch, row-major
    /// (empty unless [`SheetPass::reads_opaque_tiles`]).
    fn classify_sheet(&self, sheet: usize, opaque: &[bool], out: &mut Self::Sheet);
    /// Adds a classified sheet's counters to `stats`; an error (a bucket that could not grow)
    /// stops the render.
    fn tally(&self, sheet: &Self::Sheet, stats: &mut RenderStats) -> Result<()>;
    /// Splats `sheet`'s splats of band `band` into the band's state and composites them onto
    /// `acc`, the band's rows of the accumulation buffer.
    fn splat_band(&self, band: usize, acc: &mut [Rgba], state: &mut BandState, sheet: &Self::Sheet);
}

/// Renders the frame: `sheet_order` (sheet indices in traversal order) through the pass that
/// `make_pass` builds once the frame's buffers are allocated (this order of allocations keeps
/// the allocator's large blocks where the renderer had them: measured, building the pass first
/// cost about 1,000 more page faults per 512² frame), in batches and bands of `settings`, calling `progress` after each batch (`false` cancels with
/// [`SplatError::Cancelled`]). `stats` arrives with the frame's set-up counters filled in and
/// `t_start` the frame's start; the driver adds the timings and counters of the passes.
pub(crate) fn drive<P: SheetPass>(
    make_pass: impl FnOnce() -> P,
    sheet_order: &[usize],
    (settings, tables): (&RenderSettings, &CrioTables),
    (mut stats, t_start): (RenderStats, Instant),
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    let (w, h) = (settings.width, settings.height);
    let band_h = settings.band_height;
    let n_bands = h.div_ceil(band_h);
    let init: Rgba = match settings.mode {
        RenderMode::Mip | RenderMode::Minip => [f32::NAN, 0.0, 0.0, 0.0],
        _ => [0.0; 4],
    };
    let mut acc = try_filled(w * h, init, P::IMAGE_BUFFER)?;
    let mut bands: Vec<BandState> = (0..n_bands)
        .map(|b| BandState::new(band_h.min(h - b * band_h), w))
        .collect();
    let pass = &make_pass();
    stats.setup_ms = ms(t_start);
    let batch = settings.sheets_per_batch;
    let opaque_tiles = pass.reads_opaque_tiles();
    let mut opaque: Vec<bool> = Vec::new();
    let mut slots: Vec<P::Sheet> = (0..batch).map(|_| P::Sheet::default()).collect();
    let mut done = 0;
    for sheets in sheet_order.chunks(batch) {
        let t0 = Instant::now();
        if opaque_tiles {
            opaque.clear();
            for b in &bands {
                opaque.extend_from_slice(&b.opaque_tiles);
            }
        }
        let classified = &mut slots[..sheets.len()];
        classified
            .par_iter_mut()
            .zip(sheets.par_iter())
            .for_each(|(slot, &s)| pass.classify_sheet(s, &opaque, slot));
        stats.classify_ms += ms(t0);
        for c in classified.iter() {
            pass.tally(c, &mut stats)?;
        }
        let t1 = Instant::now();
        let classified = &*classified;
        acc.par_chunks_mut(band_h * w)
            .zip(bands.par_iter_mut())
            .enumerate()
            .for_each(|(b, (acc_band, state))| {
                for sheet in classified {
                    pass.splat_band(b, acc_band, state, sheet);
                }
            });
        stats.splat_ms += ms(t1); // split below
        done += sheets.len();
        let p = Progress {
            sheets_done: done,
            sheets_total: sheet_order.len(),
            accumulation: &acc,
        };
        if !progress(&p) {
            return Err(SplatError::Cancelled);
        }
    }
    // Split the splat/composite phase's wall time in proportion to the CPU time of each stage.
    let (splat_cpu, comp_cpu) = bands
        .iter()
        .fold((0.0, 0.0), |(s, c), b| (s + b.splat_s, c + b.composite_s));
    let phase_ms = stats.splat_ms;
    let total_cpu = splat_cpu + comp_cpu;
    if total_cpu > 0.0 {
        stats.splat_ms = phase_ms * splat_cpu / total_cpu;
        stats.composite_ms = phase_ms * comp_cpu / total_cpu;
    }
    stats.pixel_updates = bands.iter().map(|b| b.pixel_updates).sum();
    stats.splats_terminated += bands.iter().map(|b| b.terminated).sum::<u64>();
    let (image, values) = finish(acc, settings, tables, P::NAME)?;
    stats.total_ms = ms(t_start);
    Ok(Rendered {
        image,
        values,
        stats,
    })
}

/// Turns the accumulation buffer into the output image and values, after checking that every
/// value the caller will see is finite (MIP/MinIP values may be NaN where nothing covers the
/// pixel, by definition). `stage` names the renderer in the error.
pub(crate) fn finish(
    acc: Vec<Rgba>,
    settings: &RenderSettings,
    tables: &CrioTables,
    stage: &'static str,
) -> Result<(Image, Option<ScalarImage>)> {
    let w = settings.width;
    let bad = |p: &Rgba| match settings.mode {
        RenderMode::Composite => p.iter().any(|c| !c.is_finite()),
        RenderMode::Xray => !p[0].is_finite(),
        RenderMode::Mip | RenderMode::Minip => p[0].is_infinite(),
    };
    if let Some(first) = acc.iter().position(bad) {
        return Err(SplatError::NonFinite {
            stage,
            count: acc.iter().filter(|p| bad(p)).count(),
            x: first % w,
            y: first / w,
        });
    }
    Ok(finish_unchecked(acc, settings, tables))
}

fn finish_unchecked(
    acc: Vec<Rgba>,
    settings: &RenderSettings,
    tables: &CrioTables,
) -> (Image, Option<ScalarImage>) {
    let (w, h) = (settings.width, settings.height);
    match settings.mode {
        RenderMode::Composite => {
            let img = Image::from_pixels(w, h, acc).unwrap_or_else(|| Image::new(w, h));
            (img, None)
        }
        RenderMode::Xray => xray_picture(w, h, acc.iter().map(|p| p[0]).collect()),
        RenderMode::Mip | RenderMode::Minip => {
            extreme_picture(w, h, acc.iter().map(|p| p[0]).collect(), tables)
        }
    }
}

/// The picture of an X-ray whose line integrals are `values` (`width × height`, rows top to
/// bottom, data units × world units): grey, scaled so that the largest value is white (0 and
/// below black), opaque; returned with the values themselves (`None` if their count is not
/// `width × height`). What the sheet renderer and the splat list return in X-ray, for callers
/// that sum partial X-rays themselves (a sort-last render, `volsplat::distributed`).
pub fn xray_picture(width: usize, height: usize, values: Vec<f32>) -> (Image, Option<ScalarImage>) {
    let (w, h) = (width, height);
    let max = values.iter().fold(0.0f32, |m, &v| m.max(v));
    let k = if max > 0.0 { 1.0 / max } else { 0.0 };
    let pixels = values.iter().map(|&v| {
        let g = (v * k).clamp(0.0, 1.0);
        [g, g, g, 1.0]
    });
    let img = Image::from_pixels(w, h, pixels.collect()).unwrap_or_else(|| Image::new(w, h));
    (img, ScalarImage::from_values(w, h, values))
}

/// The picture of a MIP or MinIP whose projected values are `values` (`width × height`, rows
/// top to bottom, data units; NaN where no sample): each value classified by `tables`
/// (premultiplied RGBA, colour and opacity clamped to [0, 1]; transparent where NaN); returned
/// with the values themselves (`None` if their count is not `width × height`). What every
/// renderer returns in MIP/MinIP, for callers that take the extreme of partial projections
/// themselves (a sort-last render, `volsplat::distributed`).
pub fn extreme_picture(
    width: usize,
    height: usize,
    values: Vec<f32>,
    tables: &CrioTables,
) -> (Image, Option<ScalarImage>) {
    let (w, h) = (width, height);
    let pixels = values
        .iter()
        .map(|&v| {
            if v.is_nan() {
                return [0.0; 4];
            }
            let c = tables.emission.lookup(v);
            let a = tables.opacity.lookup(v)[0].clamp(0.0, 1.0);
            [
                c[0].clamp(0.0, 1.0) * a,
                c[1].clamp(0.0, 1.0) * a,
                c[2].clamp(0.0, 1.0) * a,
                a,
            ]
        })
        .collect();
    let img = Image::from_pixels(w, h, pixels).unwrap_or_else(|| Image::new(w, h));
    (img, ScalarImage::from_values(w, h, values))
}
