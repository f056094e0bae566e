//! Image-aligned, post-classified slabs (issue 16): Mueller & Crawfis, *Eliminating popping
//! artifacts in sheet buffer-based splatting* (Visualization '98) for the slab structure, and
//! Mueller, Möller & Crawfis, *Splatting without the blur* (Visualization '99) for classifying
//! and shading per pixel after reconstruction.
//!
//! # What is computed
//!
//! The view volume is cut by planes parallel to the image plane, `Δ` world units apart, at the
//! eye depths `d_j = Δ·j` (anchored to the eye, so they do not follow the volume as it turns:
//! no popping when the sheet axis of Westover's sheets would switch), across the box of voxel
//! centres, an axis of one sample spanning its voxel (a single slice is one spacing thick;
//! `docs/decisions/0023-thin-volumes.md`). In each plane every pixel holds the reconstructed
//! scalar `ρ̂ = Σ_v ρ_v·h(p − v)` summed over the voxels `v` whose
//! kernel `h` reaches the pixel's point `p` on the plane (the kernel's section by the plane, as
//! in Mueller & Crawfis' slicing of each kernel by the slabs it overlaps). Then, per pixel
//! (Mueller, Möller & Crawfis §3): the transfer function classifies `ρ̂`; where it has opacity
//! and the lights need it, the gradient is the same kernel's reconstruction of the voxels'
//! central differences (their "gradient splats", gathered at the sample; [`Ctx::gradient_at`]);
//! the lights shade it with the same formula as the other renderers ([`FrameClassifier`]) (or,
//! with [`ShadeAt::Voxels`], each voxel's gradient is shaded and the light interpolated, the
//! order of VTK's ray caster: `crate::normals`), and the slab is composited front to
//! back with its opacity corrected for its thickness `Δ` (along the ray: `Δ/cos θ` in
//! perspective).
//!
//! # The kernel, and why the sum is gathered
//!
//! The kernel is the tent (trilinear) kernel `h(x) = Π_c max(0, 1 − |x_c|/s_c)`, separable on
//! the grid axes: the reconstruction VTK's ray caster and the reference integrator sample, and
//! the one whose sections are exact on anisotropic grids (docs/design/pipeline.md §2.3).
//! For this kernel the sum over the voxels whose sections cover a pixel is, term for term, the
//! trilinear interpolation of the eight voxels around `p`, so each plane is filled by
//! evaluating that sum at each pixel ("gathering") instead of rasterising each voxel's section
//! into the plane ("scattering"). The two give the same number; gathering reads each voxel a
//! few times instead of writing ≈ 8 s² pixels per voxel and plane (s pixels per voxel), needs
//! no normalisation by `Σw` (the tent's partition of unity is exact), and keeps each pixel's
//! arithmetic independent of every other pixel, so the image is bit-identical for any thread
//! count. The choice is recorded in `docs/decisions/0016-image-aligned-post-classified-slabs.md`.
//!
//! # Ray functions
//!
//! - Composite: as above; `opacity_cutoff` stops a pixel once its opacity reaches it.
//! - MIP/MinIP: the largest/smallest `ρ̂` over the planes (NaN where no plane meets the volume).
//! - X-ray is not drawn here: the sheet renderers' line integrals are exact (decision 0003).
//!
//! # Empty space
//!
//! [`BrickGrid`] bounds the values of every 8³ brick; a sample whose brick has no opacity under
//! the transfer function is not reconstructed, and in MIP a sample whose brick cannot exceed the
//! pixel's current maximum is skipped. Both skips are exact. Composite classified through a
//! density table, one point per slab, tests each brick against that very table's interpolation
//! ([`BrickGrid::active_in_table`]: a brick of pure background just below a ramp is skipped);
//! pre-integrated segments and the per-sample classifier keep the slack test of
//! [`BrickGrid::active`] (`docs/decisions/0031-prefiltered-pyramid-previews.md`).
//!
//! # Speed (issue 12; `docs/BENCHMARKS.md` §13)
//!
//! Rows of a plane are processed eight pixels at a time where the CPU has AVX2 (runtime
//! detection; every kernel has a scalar twin doing the same f32 operations in the same order, so
//! the bits do not depend on the CPU or the thread count): [`Sampler8`] locates the eight cells
//! and gathers their corners; unshaded composite classifies through a 1024-entry table and
//! composites into channel planes in the same pass ([`composite_run_avx2`] with
//! [`PostSource`]); shaded composite does the same with a table of the classifier's terms before
//! shading ([`ShadeTable`]), the cell's central differences gathered from the volume (the 4×4×4
//! block around the cell without its edges: twelve row reads, four of which also give the
//! sample) and the lights evaluated as masks ([`ShadeSource`], [`shade_light8`]; cells on the
//! faces of the grid, whose differences are one-sided, take the scalar twin inside the same
//! rows); shaded at the voxels ([`ShadeAt::Voxels`], VTK's order, `crate::normals`), it reads
//! the cell's eight direction codes (four gathers, two codes per word) and their diffuse and
//! specular light from the frame's table (one gather per corner: two 16-bit halves per word)
//! and interpolates the light instead ([`VoxelShadeSource`]; every cell, faces included);
//! MIP/MinIP compare against one plane of values ([`extreme_row_avx2`]). Each group of
//! eight is first tested against its own cells' bricks, and skipped where none can contribute.
//! Tables that depend on more than the density (gradient-magnitude or depth indexing, a
//! modulation that is not a constant) take the per-sample classifier ([`Ctx::band_plain`]).

use crate::bricks::{BRICK, BrickGrid};
use crate::error::{Result, SplatError};
use crate::normals::{NormalField, ShadeAt, VoxelShading};
use crate::render::{
    Preintegrate, Progress, RenderMode, RenderSettings, RenderStats, Rendered, finish, ms, validate,
};
use rayon::prelude::*;
use std::time::Instant;
use volsplat_core::glam::{DVec3, Vec3};
use volsplat_core::image::{Rgba, over_front_to_back};
use volsplat_core::{
    AnyVolume, Camera, CrioTables, FrameClassifier, Image, Projection, SampleInput, Scalar,
    ScalarImage, Volume, with_volume,
};

/// Slab thickness (plane spacing), in units of the smallest grid spacing, of
/// [`RenderSettings::default`] and of MIP, MinIP and shaded composite in the front ends
/// ([`default_slab`]): VTK's ray caster samples at half the smallest spacing too (its
/// `SampleDistance` in the comparisons of `docs/BENCHMARKS.md`).
pub const DEFAULT_SLAB: f64 = 0.5;

/// Slab thickness of unshaded composite in the front ends ([`default_slab`]), in units of the
/// smallest grid spacing: one voxel, as Mueller & Crawfis suggest.
pub const DEFAULT_SLAB_COMPOSITE: f64 = 1.0;

/// The slab thickness the front ends use when none is asked for
/// (`docs/decisions/0017-slab-thickness-by-mode.md`, amended by 0019), in units of the
/// smallest grid spacing, for `mode` and `shading` (`None`: unshaded; else where the lights are
/// evaluated): [`DEFAULT_SLAB_COMPOSITE`] (1) for unshaded composite, whose post-classified
/// slabs at one voxel still lie 7–13 dB closer to the exact integral than VTK's ray caster at
/// half a voxel, at half the cost of [`DEFAULT_SLAB`], and for composite shaded at the voxels
/// (the interpolated light changes no faster than the values: 44°→46° popping 1.06–1.08, and
/// 0.1–0.2 dB from half a voxel against the exact integral); [`DEFAULT_SLAB`] (½) for MIP and
/// MinIP (a maximum sampled every voxel misses peaks by up to half a voxel: 6 dB worse) and
/// for composite shaded at the samples (gradients change faster than values; the popping ratio
/// rises from 1.2 to 1.45 at one voxel).
pub fn default_slab(mode: RenderMode, shading: Option<ShadeAt>) -> f64 {
    match (mode, shading) {
        (RenderMode::Composite, None | Some(ShadeAt::Voxels)) => DEFAULT_SLAB_COMPOSITE,
        _ => DEFAULT_SLAB,
    }
}

/// The most rows of one band of the slabs' parallel decomposition (`RenderSettings::band_height`
/// caps it further). `docs/BENCHMARKS.md` §18.3.
const SLAB_BAND_ROWS: usize = 8;

/// Bands per thread between two progress reports of the slabs (the threads meet at each report).
const BANDS_PER_THREAD: usize = 8;

/// Renders any volume with image-aligned, post-classified slabs; see [`render_slabs`].
pub fn render_slabs_any(
    volume: &AnyVolume,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    bricks: Option<&BrickGrid>,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    with_volume!(volume, v => render_slabs(v, camera, tables, settings, bricks, progress))
}

/// Renders `volume` seen by `camera` (orthographic or perspective) with image-aligned,
/// post-classified slabs (module docs). `settings.slab` is the slab thickness in units of the
/// smallest grid spacing, capped at the thinnest extent of the box the rays cross (decision
/// 0023: an axis of one sample spans its voxel); `settings.mode` may not be X-ray. `bricks`
/// is the volume's brick grid if the caller keeps one across frames (built here otherwise).
/// `progress` is called after each group of image bands, with `sheets_done`/`sheets_total`
/// counting bands; returning `false` cancels with [`SplatError::Cancelled`].
pub fn render_slabs<T: Scalar>(
    volume: &Volume<T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    bricks: Option<&BrickGrid>,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    let t_start = Instant::now();
    validate(settings)?;
    if settings.mode == RenderMode::Xray {
        return Err(SplatError::Setting {
            name: "mode",
            value: "xray".into(),
            expected: "composite, mip or minip with image-aligned slabs (X-ray line integrals \
                       are exact in the sheet renderers)",
        });
    }
    if settings.subsample != 1 {
        return Err(SplatError::Setting {
            name: "subsample",
            value: settings.subsample.to_string(),
            expected: "1 with image-aligned slabs (subsampling is the sheet renderers' preview)",
        });
    }
    if settings.order != crate::geometry::Order::FrontToBack {
        return Err(SplatError::Setting {
            name: "order",
            value: "back to front".into(),
            expected: "front to back: image-aligned slabs composite front to back only",
        });
    }
    if !(settings.slab.is_finite() && (0.01..=16.0).contains(&settings.slab)) {
        return Err(SplatError::Setting {
            name: "slab",
            value: settings.slab.to_string(),
            expected: "a slab thickness in [0.01, 16] × the smallest voxel spacing",
        });
    }
    let grid = volume.grid();
    if grid.dims.contains(&0) {
        return Err(SplatError::Setting {
            name: "volume",
            value: format!("{:?}", grid.dims),
            expected: "at least one voxel per axis",
        });
    }
    let owned;
    let bricks = match bricks {
        Some(b) if b.volume_dims == grid.dims => b,
        _ => {
            owned = BrickGrid::build(volume);
            &owned
        }
    };
    let proj = Projection::new(camera, settings.width, settings.height)?;
    let frame = *proj.frame();
    let min_spacing = grid.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s));
    let ss = supersampling(settings, &proj, grid, min_spacing);
    if ss > 1.0 {
        return render_supersampled(volume, camera, tables, settings, Some(bricks), progress, ss);
    }
    // The box the rays cross: the voxel centres', an axis of one sample spanning its voxel
    // (decision 0023). No thicker slabs than the box's thinnest extent, so that a ray through
    // both of its widest faces meets a plane inside (a sheet one voxel thick under `--slab 2`
    // would otherwise fall between two planes and draw nothing); with slabs of at most one
    // voxel this never applies (every extent is a spacing or more).
    let geo = drawn_geometry(grid);
    let thinnest = (0..3)
        .map(|a| (geo.dims[a] - 1) as f64 * geo.spacing[a])
        .fold(f64::INFINITY, f64::min);
    let delta = (settings.slab * min_spacing).min(thinnest);
    let classifier = FrameClassifier::new(tables, &frame, delta);
    let composite = settings.mode == RenderMode::Composite;
    let shade = composite && classifier.needs_gradient;

    // Depth range of the box the rays cross, and the planes inside it.
    let depths = geo
        .corners_world()
        .map(|c| (c - frame.eye).dot(frame.forward));
    let dmin = depths.iter().fold(f64::INFINITY, |m, &d| m.min(d));
    let dmax = depths.iter().fold(f64::NEG_INFINITY, |m, &d| m.max(d));
    let perspective = matches!(proj, Projection::Perspective(_));
    let mut j0 = (dmin / delta).ceil();
    if perspective {
        j0 = j0.max(1.0); // planes in front of the eye only
    }
    let j1 = (dmax / delta).floor();
    let n_planes = if j1 >= j0 { (j1 - j0) as usize + 1 } else { 0 };
    if n_planes > 1 << 24 {
        return Err(SplatError::Setting {
            name: "slab",
            value: settings.slab.to_string(),
            expected: "fewer than 2^24 planes across the volume; use a thicker slab",
        });
    }
    let (w, h) = (settings.width, settings.height);
    let view = View::new(&proj, &geo, w, h);
    let post = (composite && !shade)
        .then(|| PostTable::new(tables, &classifier))
        .flatten();
    let grad_to_world = [0, 1, 2].map(|a| (grid.direction.col(a) / grid.spacing[a]).as_vec3());
    // Shaded composite through tables where the classification depends on the density alone;
    // the per-sample classifier otherwise.
    let shade_table = shade
        .then(|| ShadeTable::new(tables, &classifier, grad_to_world))
        .flatten();
    // Shading at the voxels (VTK's order; `crate::normals`): the voxels' direction codes, kept
    // with the brick grid across frames, and the frame's lights applied to every code.
    let owned_normals;
    let (voxel_shading, codes): (Option<VoxelShading>, &[u16]) = match &shade_table {
        Some(t) if settings.shade_at == ShadeAt::Voxels => {
            let field = match bricks.normals(volume)? {
                Some(f) => f,
                None => {
                    owned_normals = NormalField::build(volume)?;
                    &owned_normals
                }
            };
            (Some(VoxelShading::new(t)), field.codes())
        }
        _ => (None, &[]),
    };
    let risk = {
        let (alphas, scale): (Vec<f32>, f32) = match (&post, &shade_table) {
            (Some(t), _) => (t.values.iter().map(|v| v[3]).collect(), t.scale),
            (None, Some(t)) => (t.rows.iter().map(|r| r[0]).collect(), t.scale),
            _ => (Vec::new(), 0.0),
        };
        let (lo, hi) = bricks
            .ranges
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |a, r| {
                (a.0.min(r[0]), a.1.max(r[1]))
            });
        ring_risk(&alphas, scale, hi - lo)
    };
    let preint = match settings.preintegrate {
        Preintegrate::Off => false,
        Preintegrate::On => true,
        Preintegrate::Auto => risk > RING_RISK,
    };
    // Empty space: composite classified by a density table, one point per slab, skips the
    // bricks whose samples read only entries without opacity from that very table (exact,
    // `BrickGrid::active_in_table`); pre-integrated segments reach into the brick before, and
    // the per-sample classifier resamples the opacity table, so they keep the slack test.
    let table_active = match (&post, &shade_table) {
        (Some(t), _) if !preint => Some(bricks.active_in_table(&t.nonzero(), |x| t.pos(x))),
        (None, Some(t)) if !preint || voxel_shading.is_none() => {
            Some(bricks.active_in_table(&t.nonzero(), |x| t.pos(x)))
        }
        _ => None,
    };
    let active = table_active.unwrap_or_else(|| {
        bricks.active(
            &tables.opacity,
            (tables.opacity.hi - tables.opacity.lo) / 4095.0,
            false,
        )
    });
    let all_active = active.iter().all(|&a| a);
    let ctx = Ctx {
        data: volume.data(),
        dims: grid.dims,
        box_hi: geo.dims.map(|n| n as i64 - 1),
        max_cell: grid.dims.map(|n| n.max(2) as i64 - 2),
        simd: simd_available() && volume.data().len() < i32::MAX as usize,
        grad_to_world,
        stride: [1, grid.dims[0], grid.dims[0] * grid.dims[1]],
        up: [
            usize::from(grid.dims[0] > 1),
            usize::from(grid.dims[1] > 1) * grid.dims[0],
            usize::from(grid.dims[2] > 1) * grid.dims[0] * grid.dims[1],
        ],
        bricks,
        active: &active,
        active_bytes: active.iter().map(|&a| u8::from(a)).chain([0; 3]).collect(),
        extreme_bounds: match settings.mode {
            RenderMode::Mip => bricks.ranges.iter().map(|r| r[1]).collect(),
            RenderMode::Minip => bricks.ranges.iter().map(|r| r[0]).collect(),
            _ => Vec::new(),
        },
        skip_empty: composite && !all_active,
        view,
        classifier: &classifier,
        post: post.as_ref(),
        shaded: shade_table.as_ref(),
        voxel: voxel_shading.as_ref(),
        codes,
        preint,
        mode: settings.mode,
        shade,
        cutoff: settings.opacity_cutoff,
        j0: j0 as i64,
        n_planes,
        delta,
        dmin,
        depth_scale: if dmax > dmin {
            1.0 / (dmax - dmin)
        } else {
            0.0
        },
        width: w,
        clip: settings
            .clip
            .iter()
            .map(|p| {
                let n = DVec3::from(p.normal);
                (n, p.offset)
            })
            .collect(),
    };
    let init: Rgba = match settings.mode {
        RenderMode::Mip | RenderMode::Minip => [f32::NAN, 0.0, 0.0, 0.0],
        _ => [0.0; 4],
    };
    let mut acc = vec![init; w * h];
    // Bands of at most `SLAB_BAND_ROWS` rows: a band's work is very uneven here (a band through
    // an opaque object stops after a few planes, one beside it runs through the whole volume),
    // so many small bands balance the threads better than a few large ones. The image does not
    // depend on the band height (every pixel's arithmetic is its own).
    let band_h = settings.band_height.min(SLAB_BAND_ROWS);
    let n_bands = h.div_ceil(band_h);
    let mut stats = RenderStats {
        preintegrated: composite && preint && (post.is_some() || voxel_shading.is_some()),
        ring_risk: f64::from(risk),
        sheets: n_planes,
        sheet_axis: 3,
        sheet_spacing: delta,
        threads: rayon::current_num_threads(),
        ..RenderStats::default()
    };
    stats.setup_ms = ms(t_start);
    let t_render = Instant::now();
    // Bands handed to the threads between two progress reports: the threads wait for the
    // slowest band of a group, so a group holds several bands per thread.
    let group = (BANDS_PER_THREAD * rayon::current_num_threads()).max(2 * BANDS_PER_THREAD);
    let mut done = 0;
    let mut counters = Counters::default();
    let chunks: Vec<(usize, &mut [Rgba])> = acc.chunks_mut(band_h * w).enumerate().collect();
    let mut chunks = chunks.into_iter().peekable();
    while chunks.peek().is_some() {
        let batch: Vec<(usize, &mut [Rgba])> = chunks.by_ref().take(group).collect();
        let n = batch.len();
        let c = batch
            .into_par_iter()
            .map(|(b, rows)| ctx.band(b * band_h, rows))
            .reduce(Counters::default, Counters::add);
        counters = counters.add(c);
        done += n;
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
    stats.classify_ms = ms(t_render);
    stats.voxels = counters.samples;
    stats.splats = counters.visible;
    stats.pixel_updates = counters.visible;
    stats.splats_terminated = counters.terminated;
    let (image, values) = finish(acc, settings, tables, "image-aligned slab renderer")?;
    stats.total_ms = ms(t_start);
    Ok(Rendered {
        image,
        values,
        stats,
    })
}

/// The geometry the slabs' rays are set up in (`docs/decisions/0023-thin-volumes.md`): `grid`
/// itself where every axis has two samples or more; otherwise each axis of one sample becomes
/// two "samples" half a spacing either side of the real one (the origin moved back by half a
/// spacing), so the box of these centres, `[0, 1]` along that axis, is the voxel's extent
/// ([`volsplat_core::Grid::drawn_box_index`]). Only positions use it: the cells are clamped to
/// the real grid (`Ctx::max_cell`, 0 there) and the step to the next voxel along the axis is 0
/// (`Ctx::up`), so every position along the axis reads the one sample.
fn drawn_geometry(grid: &volsplat_core::Grid) -> volsplat_core::Grid {
    let mut geo = grid.clone();
    for a in 0..3 {
        if grid.dims[a] == 1 {
            geo.dims[a] = 2;
            let back = grid.direction.col(a) * (0.5 * grid.spacing[a]);
            geo.origin = (DVec3::from(geo.origin) - back).to_array();
        }
    }
    geo
}

/// Sub-pixel rays per pixel and axis for the anti-aliasing of minified views, from `r`, the
/// pixel's size at the volume's centre over the smallest voxel spacing: 1 where a voxel spans a
/// pixel (`r ≤ 1`, up to rounding) or with [`crate::aa::Antialias::None`]; `r` itself, a
/// fraction, below [`WHOLE_RAYS_FROM`], so that a pixel a few percent larger than a voxel costs
/// a few percent more rays, not 4× (a CT whose in-plane spacing is just under the pixel;
/// decision 0020); `⌈r⌉` (at most 4) from there on, each pixel the box average of
/// `⌈r⌉ × ⌈r⌉` rays, as before. Perspective views measure the pixel at the depth of the volume's
/// centre.
fn supersampling(
    settings: &RenderSettings,
    proj: &Projection,
    grid: &volsplat_core::Grid,
    min_spacing: f64,
) -> f64 {
    if settings.antialias == crate::aa::Antialias::None {
        return 1.0;
    }
    let frame = proj.frame();
    let depth = (grid.center_world() - frame.eye).dot(frame.forward);
    if (depth.is_nan() || depth <= 0.0) && matches!(proj, Projection::Perspective(_)) {
        return 1.0;
    }
    let ratio = proj.pixel_size_at(depth) / min_spacing;
    // A little slack so that one voxel per pixel, up to rounding, is not supersampled.
    if !(ratio.is_finite() && ratio > 1.0 + 1e-3) {
        1.0
    } else if ratio < WHOLE_RAYS_FROM {
        ratio
    } else {
        (ratio - 1e-3).ceil().min(4.0)
    }
}

/// Where the anti-aliasing of minified views ([`supersampling`]) turns from fractional rays per
/// pixel to whole ones: pixel sizes of 1.5 voxels and more take `⌈r⌉ × ⌈r⌉` rays.
pub const WHOLE_RAYS_FROM: f64 = 1.5;

/// The weights of the fine pixels `0..fine` that cover each of the coarse pixels `0..n` along
/// one axis, for fine pixels of `step` coarse pixels starting `offset` coarse pixels before the
/// coarse image's edge: per coarse pixel the first fine pixel and the fractions of the coarse
/// pixel that each fine pixel covers (summing to 1 where the fine image covers it).
fn area_weights(n: usize, fine: usize, step: f64, offset: f64) -> Vec<(usize, Vec<f32>)> {
    (0..n)
        .map(|x| {
            let (a, b) = (x as f64, x as f64 + 1.0);
            let first = (((a + offset) / step).floor().max(0.0) as usize).min(fine - 1);
            let mut w = Vec::new();
            let mut i = first;
            while i < fine {
                let (fa, fb) = (i as f64 * step - offset, (i + 1) as f64 * step - offset);
                if fa >= b {
                    break;
                }
                w.push((fb.min(b) - fa.max(a)).max(0.0) as f32);
                i += 1;
            }
            (first, w)
        })
        .collect()
}

/// [`render_slabs`] at `ss` times the size, filtered down ([`supersampling`]): for a whole `ss`,
/// each pixel the box average of its `ss × ss` rays; for a fraction, `⌈H·ss⌉` rows and as many
/// columns as keep the camera's aspect without narrowing the view, each pixel the mean of the
/// fine pixels over its area, weighted by the part of it each covers.
fn render_supersampled<T: Scalar>(
    volume: &Volume<T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    bricks: Option<&BrickGrid>,
    progress: &mut dyn FnMut(&Progress) -> bool,
    ss: f64,
) -> Result<Rendered> {
    if ss.fract() == 0.0 {
        return render_box_supersampled(
            volume,
            camera,
            tables,
            settings,
            bricks,
            progress,
            ss as usize,
        );
    }
    let (w, h) = (settings.width, settings.height);
    // The view's height spans the rows; its width is the aspect times that, so the fine pixels
    // are square of `h / fh` coarse pixels, and the fine image is centred on the coarse one.
    let fh = (h as f64 * ss - 1e-9).ceil() as usize;
    let step = h as f64 / fh as f64;
    let fw = ((w as f64 / step) - 1e-9).ceil() as usize;
    let fine = RenderSettings {
        width: fw,
        height: fh,
        antialias: crate::aa::Antialias::None,
        ..settings.clone()
    };
    validate(&fine)?;
    let out = render_slabs(volume, camera, tables, &fine, bricks, progress)?;
    let x_off = 0.5 * (fw as f64 * step - w as f64);
    let (wx, wy) = (
        area_weights(w, fw, step, x_off),
        area_weights(h, fh, step, 0.0),
    );
    let fine_px = out.image.pixels();
    let mut pixels = vec![[0.0f32; 4]; w * h];
    for (i, px) in pixels.iter_mut().enumerate() {
        let ((x0, cx), (y0, cy)) = (&wx[i % w], &wy[i / w]);
        let mut sum = [0.0f32; 4];
        for (dy, &ky) in cy.iter().enumerate() {
            let row = &fine_px[(y0 + dy) * fw + x0..][..cx.len()];
            for (p, &kx) in row.iter().zip(cx) {
                let k = ky * kx;
                for c in 0..4 {
                    sum[c] += k * p[c];
                }
            }
        }
        *px = sum;
    }
    // MIP/MinIP values: the weighted mean over the sub-pixel rays that met the volume (NaN if
    // none).
    let values = out.values.as_ref().map(|v| {
        let fv = v.values();
        let mut vals = vec![f32::NAN; w * h];
        for (i, val) in vals.iter_mut().enumerate() {
            let ((x0, cx), (y0, cy)) = (&wx[i % w], &wy[i / w]);
            let (mut sum, mut n) = (0.0f32, 0.0f32);
            for (dy, &ky) in cy.iter().enumerate() {
                let row = &fv[(y0 + dy) * fw + x0..][..cx.len()];
                for (&f, &kx) in row.iter().zip(cx) {
                    if !f.is_nan() && ky * kx > 0.0 {
                        sum += ky * kx * f;
                        n += ky * kx;
                    }
                }
            }
            if n > 0.0 {
                *val = sum / n;
            }
        }
        vals
    });
    let image = Image::from_pixels(w, h, pixels).unwrap_or_else(|| Image::new(w, h));
    let values = values.and_then(|v| ScalarImage::from_values(w, h, v));
    let mut stats = out.stats;
    stats.supersampling = ss;
    Ok(Rendered {
        image,
        values,
        stats,
    })
}

/// [`render_supersampled`] for a whole factor: `ss × ss` rays per pixel, box-averaged.
fn render_box_supersampled<T: Scalar>(
    volume: &Volume<T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    bricks: Option<&BrickGrid>,
    progress: &mut dyn FnMut(&Progress) -> bool,
    ss: usize,
) -> Result<Rendered> {
    let fine = RenderSettings {
        width: settings.width * ss,
        height: settings.height * ss,
        antialias: crate::aa::Antialias::None,
        ..settings.clone()
    };
    validate(&fine)?;
    let out = render_slabs(volume, camera, tables, &fine, bricks, progress)?;
    let (w, h) = (settings.width, settings.height);
    let fw = fine.width;
    let inv = 1.0 / (ss * ss) as f32;
    let mut pixels = vec![[0.0f32; 4]; w * h];
    let fine_px = out.image.pixels();
    for (i, px) in pixels.iter_mut().enumerate() {
        let (x, y) = (i % w, i / w);
        let mut sum = [0.0f32; 4];
        for sy in 0..ss {
            let row = &fine_px[(y * ss + sy) * fw + x * ss..][..ss];
            for p in row {
                for c in 0..4 {
                    sum[c] += p[c];
                }
            }
        }
        *px = sum.map(|v| v * inv);
    }
    // MIP/MinIP values: the mean over the sub-pixel rays that met the volume (NaN if none).
    let values = out.values.as_ref().map(|v| {
        let fv = v.values();
        let mut vals = vec![f32::NAN; w * h];
        for (i, val) in vals.iter_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            let (mut sum, mut n) = (0.0f32, 0u32);
            for sy in 0..ss {
                for &f in &fv[(y * ss + sy) * fw + x * ss..][..ss] {
                    if !f.is_nan() {
                        sum += f;
                        n += 1;
                    }
                }
            }
            if n > 0 {
                *val = sum / n as f32;
            }
        }
        vals
    });
    let image = Image::from_pixels(w, h, pixels).unwrap_or_else(|| Image::new(w, h));
    let values = values.and_then(|v| ScalarImage::from_values(w, h, v));
    let mut stats = out.stats;
    stats.supersampling = ss as f64;
    Ok(Rendered {
        image,
        values,
        stats,
    })
}

#[derive(Default, Clone, Copy)]
struct Counters {
    /// Samples reconstructed.
    samples: u64,
    /// Samples with non-zero opacity composited (or MIP samples compared).
    visible: u64,
    /// Samples skipped because the pixel was opaque.
    terminated: u64,
}

impl Counters {
    fn add(self, o: Counters) -> Counters {
        Counters {
            samples: self.samples + o.samples,
            visible: self.visible + o.visible,
            terminated: self.terminated + o.terminated,
        }
    }
}

/// Sample positions: the point of pixel `(x, y)` (centre) on the plane at eye depth `d` is
/// `P = eye + d·(f + u·r + v·u)` in perspective (`u, v` the pixel's tangent-plane offsets) and
/// `P = eye + d·f + x_w·r + y_w·u` in orthographic views; both are affine in `x` along a row,
/// so a row of a plane is a start and a step in index space.
struct View {
    perspective: bool,
    /// Index-space position of the eye, and the index-space images of the world axes.
    eye_q: DVec3,
    right_q: DVec3,
    up_q: DVec3,
    fwd_q: DVec3,
    /// World frame, for clipping planes.
    eye: DVec3,
    right_w: DVec3,
    up_w: DVec3,
    fwd_w: DVec3,
    /// Orthographic: world units per pixel. Perspective: 1 / focal length in pixels.
    scale: f64,
    half_w: f64,
    half_h: f64,
}

impl View {
    fn new(proj: &Projection, grid: &volsplat_core::Grid, w: usize, h: usize) -> Self {
        let fr = proj.frame();
        let q0 = grid.index_from_world(DVec3::ZERO);
        let lin = |v: DVec3| grid.index_from_world(v) - q0;
        let (perspective, scale) = match proj {
            Projection::Ortho(p) => (false, p.pixel_size),
            Projection::Perspective(p) => (true, 1.0 / p.focal_px),
        };
        View {
            perspective,
            eye_q: grid.index_from_world(fr.eye),
            right_q: lin(fr.right),
            up_q: lin(fr.up),
            fwd_q: lin(fr.forward),
            eye: fr.eye,
            right_w: fr.right,
            up_w: fr.up,
            fwd_w: fr.forward,
            scale,
            half_w: w as f64 * 0.5,
            half_h: h as f64 * 0.5,
        }
    }

    /// Tangent-plane (perspective: per unit depth; orthographic: world) offsets of the centre
    /// of pixel `(x, y)` along right and up.
    #[inline]
    fn offsets(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x + 0.5 - self.half_w) * self.scale,
            (self.half_h - y - 0.5) * self.scale,
        )
    }

    /// Index-space position of pixel `(0, y)` on the plane at depth `d`, and the step per pixel
    /// along the row.
    fn row(&self, y: usize, d: f64) -> (DVec3, DVec3) {
        let (u0, v) = self.offsets(0.0, y as f64);
        if self.perspective {
            let start = self.eye_q + (self.fwd_q + self.right_q * u0 + self.up_q * v) * d;
            (start, self.right_q * (d * self.scale))
        } else {
            let start = self.eye_q + self.fwd_q * d + self.right_q * u0 + self.up_q * v;
            (start, self.right_q * self.scale)
        }
    }

    /// World position of pixel `(x, 0)`'s point at depth `d` and the world step per pixel along
    /// x (for clipping planes).
    fn row_world(&self, y: usize, d: f64) -> (DVec3, DVec3) {
        let (u0, v) = self.offsets(0.0, y as f64);
        if self.perspective {
            (
                self.eye + (self.fwd_w + self.right_w * u0 + self.up_w * v) * d,
                self.right_w * (d * self.scale),
            )
        } else {
            (
                self.eye + self.fwd_w * d + self.right_w * u0 + self.up_w * v,
                self.right_w * self.scale,
            )
        }
    }
}

/// The pixels `x` in `[0, width)` with `lo ≤ a + x·b ≤ hi`, intersected with `range`.
fn clip_linear(range: (i64, i64), a: f64, b: f64, lo: f64, hi: f64) -> (i64, i64) {
    const SLACK: f64 = 1e-9;
    let (lo, hi) = (lo - SLACK, hi + SLACK);
    if b.abs() < 1e-300 {
        return if a >= lo && a <= hi { range } else { (0, -1) };
    }
    let (t0, t1) = ((lo - a) / b, (hi - a) / b);
    let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
    // The integers are the same as `ceil`'s and `floor`'s (a zero's sign does not matter here).
    let x0 = ceil_f64(t0).max(range.0 as f64);
    let x1 = floor_f64(t1).min(range.1 as f64);
    if x0 > x1 || !x0.is_finite() || !x1.is_finite() {
        (0, -1)
    } else {
        (x0 as i64, x1 as i64)
    }
}

struct Ctx<'a, T> {
    data: &'a [T],
    dims: [usize; 3],
    /// The upper corner of the box the rays cross, in the index space of the view
    /// ([`drawn_geometry`]): `n − 1`, or 1 along an axis of one sample (its voxel, `[0, 1]`
    /// there, shifted by half a voxel; every position on it reads the one sample).
    box_hi: [i64; 3],
    /// Largest cell index per axis (`max(n, 2) − 2`).
    max_cell: [i64; 3],
    /// Index strides per axis.
    stride: [usize; 3],
    /// Offset to the next voxel per axis (0 along an axis of one voxel).
    up: [usize; 3],
    /// Sample eight pixels at a time with AVX2 (the CPU has it, and indices fit in i32).
    simd: bool,
    /// Per index axis: the world direction of that axis divided by its spacing (a derivative
    /// per index step becomes a world gradient).
    grad_to_world: [Vec3; 3],
    bricks: &'a BrickGrid,
    active: &'a [bool],
    /// `active` as bytes, padded with three zero bytes (AVX2 gathers read 4 bytes).
    active_bytes: Vec<u8>,
    /// MIP: each brick's maximum; MinIP: its minimum (empty otherwise): the one bound of
    /// `bricks.ranges` that the mode tests, in half the memory.
    extreme_bounds: Vec<f32>,
    skip_empty: bool,
    view: View,
    classifier: &'a FrameClassifier,
    /// Unshaded, density-indexed classification as one premultiplied table.
    post: Option<&'a PostTable>,
    /// Shaded, density-indexed classification.
    shaded: Option<&'a ShadeTable>,
    /// With `shaded`: the lights applied to every direction code, where the voxels are shaded
    /// ([`ShadeAt::Voxels`]), and the voxels' codes ([`NormalField::codes`]; empty otherwise).
    voxel: Option<&'a VoxelShading>,
    codes: &'a [u16],
    /// Pre-integrated classification of the segments between planes
    /// ([`RenderSettings::preintegrate`]).
    preint: bool,
    mode: RenderMode,
    shade: bool,
    cutoff: f32,
    j0: i64,
    n_planes: usize,
    delta: f64,
    dmin: f64,
    depth_scale: f64,
    width: usize,
    clip: Vec<(DVec3, f64)>,
}

impl<T: Scalar> Ctx<'_, T> {
    fn depth(&self, plane: usize) -> f64 {
        (self.j0 + plane as i64) as f64 * self.delta
    }

    /// Row `y` of the plane at depth `d` in 32.32 fixed-point index coordinates (VTK's ray
    /// caster steps in 15-bit fixed point): integer steps are exact, so a pixel's position is
    /// the same whichever pixels around it are skipped. The span holds the pixels whose point
    /// lies in the box the rays cross, `[0, box_hi]` (the voxel centres' box, decision 0023),
    /// checked in fixed point, so no clamping is needed below 0.
    fn walk(&self, y: usize, d: f64) -> Walk {
        let (start, step) = self.view.row(y, d);
        let mut r = (0, self.width as i64 - 1);
        for a in 0..3 {
            r = clip_linear(r, start[a], step[a], 0.0, self.box_hi[a] as f64);
        }
        let s = [0, 1, 2].map(|a| to_fixed(start[a]));
        let st = [0, 1, 2].map(|a| to_fixed(step[a]));
        let inside = |x: i64| {
            (0..3).all(|a| {
                let q = s[a] + x * st[a];
                q >= 0 && q <= self.box_hi[a] << FRAC
            })
        };
        while r.0 <= r.1 && !inside(r.0) {
            r.0 += 1;
        }
        while r.1 >= r.0 && !inside(r.1) {
            r.1 -= 1;
        }
        Walk {
            s,
            st,
            s32: [0, 1, 2].map(|a| start[a] as f32),
            st32: [0, 1, 2].map(|a| step[a] as f32),
            span: r,
        }
    }

    /// The pixels of row `y` at depth `d` kept by every clipping plane.
    fn clip_span(&self, y: usize, d: f64, r: (i64, i64)) -> (i64, i64) {
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

    /// The cell of pixel `x` of a row and the fractions in it, from the row's f32 start and step
    /// (the positions [`sample_run_avx2`] computes lane by lane).
    #[inline(always)]
    fn cell_f32(&self, walk: &Walk, x: usize) -> ([usize; 3], [f32; 3]) {
        let xf = x as f32;
        let mut c = [0usize; 3];
        let mut f = [0.0f32; 3];
        for a in 0..3 {
            let q = walk.s32[a] + xf * walk.st32[a];
            let i = (q as i32).clamp(0, self.max_cell[a] as i32);
            c[a] = i as usize;
            f[a] = (q - i as f32).clamp(0.0, 1.0);
        }
        (c, f)
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
        trilinear(self.data, self.base(c), self.up, f)
    }

    /// Linear index of voxel `c`.
    #[inline(always)]
    fn base(&self, c: [usize; 3]) -> usize {
        c[0] + c[1] * self.stride[1] + c[2] * self.stride[2]
    }

    /// Renders the band of image rows `[y0, y0 + rows.len()/width)` through every plane.
    fn band(&self, y0: usize, acc: &mut [Rgba]) -> Counters {
        let w = self.width;
        let rows = acc.len() / w;
        match (self.post, self.shaded) {
            _ if self.mode != RenderMode::Composite => self.band_extreme(y0, rows, acc),
            (Some(t), _) => self.band_post(y0, rows, acc, Post::Table(t)),
            (None, Some(t)) => match self.voxel {
                Some(vs) => self.band_post(y0, rows, acc, Post::Voxel(t, vs)),
                None => self.band_post(y0, rows, acc, Post::Shaded(t)),
            },
            (None, None) => self.band_plain(y0, rows, acc),
        }
    }

    /// Unshaded composite through the post-classification table: each run of pixels in active
    /// bricks is sampled, classified and composited in one pass ([`composite_run_avx2`] eight
    /// pixels at a time where the CPU has AVX2, [`Ctx::composite_one`] otherwise and for the
    /// ends of runs; the same f32 operations in the same order, so the same bits). The band's
    /// accumulation is kept as four planes of channels while it is composited.
    fn band_post(&self, y0: usize, rows: usize, acc: &mut [Rgba], post: Post<'_>) -> Counters {
        let w = self.width;
        let mut c = Counters::default();
        let mut band = BandAcc {
            r: vec![0.0; rows * w],
            g: vec![0.0; rows * w],
            b: vec![0.0; rows * w],
            a: vec![0.0; rows * w],
        };
        let mut live: Vec<(i64, i64)> = vec![(0, w as i64 - 1); rows];
        let kf = self.path_factors(y0, rows);
        let (din, dout) = self.ray_extents(y0, rows);
        let half = (0.5 * self.delta) as f32;
        let preint = self.preint_for(post);
        let (mut prev, mut stamp) = if preint {
            (vec![0.0f32; rows * w], vec![u32::MAX; rows * w])
        } else {
            (Vec::new(), Vec::new())
        };
        for p in 0..self.n_planes {
            let d = self.depth(p);
            let mut any_live = false;
            for (r, live_r) in live.iter_mut().enumerate() {
                let y = y0 + r;
                let o = r * w;
                let Some(lw) = shrink_live_alpha(live_r, &band.a[o..o + w], self.cutoff) else {
                    continue;
                };
                any_live = true;
                let walk = self.walk(y, d);
                let span = self.clip_span(y, d, walk.span);
                let (lo, hi) = (
                    span.0.max(lw.0).max(walk.span.0),
                    span.1.min(lw.1).min(walk.span.1),
                );
                if lo > hi {
                    continue;
                }
                let (back_s, back_st) = if preint && matches!(post, Post::Voxel(..)) {
                    let (s0, st0) = self.view.row(y, d - self.delta);
                    (
                        [0, 1, 2].map(|a| s0[a] as f32 - walk.s32[a]),
                        [0, 1, 2].map(|a| st0[a] as f32 - walk.st32[a]),
                    )
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

    /// Samples, classifies and composites pixel `x` of a row ([`Ctx::band_post`]): the scalar
    /// twin of [`composite_run_avx2`] and, with `post` shaded, of [`shaded_run_avx2`].
    #[inline(always)]
    fn composite_one(
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
            Post::Shaded(t) => shaded_src(t, rho, self.gradient_lerp(cell, f), k, corrected),
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
                let base = self.base(cell);
                let [ux, uy, uz] = self.up;
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
    /// (`corrected`: `k ≠ 1` or perspective), or `None` where it has no opacity.
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

    /// Pre-integration shaded at the voxels: the cell and fractions where the segment of
    /// pixel `x` is lit, `q + h·(back_s + x·back_st)` with `q` the sample's position
    /// ([`Ctx::cell_f32`]) and `h` the fraction [`SEGMENT_LIGHT_AT`]; the scalar twin of
    /// [`VoxelShadeSource::light_cells`].
    #[inline(always)]
    fn light_cell(
        &self,
        walk: &Walk,
        row: &RowCtx<'_>,
        x: usize,
        h: f32,
    ) -> ([usize; 3], [f32; 3]) {
        let xf = x as f32;
        let mut c = [0usize; 3];
        let mut f = [0.0f32; 3];
        for a in 0..3 {
            let q = walk.s32[a] + xf * walk.st32[a];
            let q = q + h * (row.back_s[a] + xf * row.back_st[a]);
            let i = (q as i32).clamp(0, self.max_cell[a] as i32);
            c[a] = i as usize;
            f[a] = (q - i as f32).clamp(0.0, 1.0);
        }
        (c, f)
    }

    /// The premultiplied colour of `[c_r, c_g, c_b, log2(1 − α)]` (a `persp` entry, or a
    /// segment's averages, [`PostTable::segment`]) with slab exponent `k`: `c·a` and
    /// `a = 1 − 2^(k·L)`, or `None` where `L ≥ 0` (no opacity; NaN neither).
    #[inline(always)]
    fn post_seg_src([cr, cg, cb, l]: Rgba, k: f32) -> Option<Rgba> {
        // `l < 0` is false for NaN too.
        (l < 0.0).then(|| {
            let a = 1.0 - exp2_neg(k * l);
            [cr * a, cg * a, cb * a, a]
        })
    }

    /// Whether the samples of `post` are pre-integrated: asked for ([`RenderSettings::preintegrate`])
    /// and classified through a density table (unshaded, or shaded at the voxels; shading at
    /// the samples keeps one point per slab).
    #[inline(always)]
    fn preint_for(&self, post: Post<'_>) -> bool {
        self.preint && !matches!(post, Post::Shaded(_))
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
    /// compared eight at a time ([`extreme_run_avx2`]) or one at a time
    /// ([`Ctx::extreme_one`]); the samples are the same bits either way, so is their extreme.
    fn band_extreme(&self, y0: usize, rows: usize, acc: &mut [Rgba]) -> Counters {
        let w = self.width;
        let mip = self.mode == RenderMode::Mip;
        let mut c = Counters::default();
        let mut vals = vec![f32::NAN; rows * w];
        for p in coarse_to_fine(self.n_planes) {
            let d = self.depth(p);
            for r in 0..rows {
                let y = y0 + r;
                let walk = self.walk(y, d);
                let span = self.clip_span(y, d, walk.span);
                let (lo, hi) = (span.0.max(walk.span.0), span.1.min(walk.span.1));
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
        if !cur.is_nan() && if mip { bound <= cur } else { bound >= cur } {
            return;
        }
        c.samples += 1;
        let v = self.sample_cell(cell, f);
        if cur.is_nan() || (mip && v > cur) || (!mip && v < cur) {
            row[x] = v;
        }
    }

    /// The world gradient of the reconstruction at pixel `x` of a row (data units per world
    /// unit): the tent kernel's interpolation of the voxels' central differences (one-sided on
    /// the faces of the grid), i.e. gradient splats gathered at the sample, which is what VTK's
    /// ray caster and the reference integrator shade with. Computed only for samples with
    /// opacity.
    fn gradient_at(&self, walk: &Walk, x: usize) -> Vec3 {
        let (c, f) = self.cell_f32(walk, x);
        let mut g = [0.0f32; 3];
        for corner in 0..8usize {
            let mut w = 1.0f32;
            let mut p = [0usize; 3];
            for a in 0..3 {
                let up = corner >> a & 1 == 1;
                p[a] = c[a] + usize::from(up && self.dims[a] > 1);
                w *= if up { f[a] } else { 1.0 - f[a] };
            }
            if w == 0.0 {
                continue;
            }
            let here = p[0] + p[1] * self.stride[1] + p[2] * self.stride[2];
            for a in 0..3 {
                let n = self.dims[a];
                if n < 2 {
                    continue;
                }
                let (lo, hi, span) = if p[a] == 0 {
                    (here, here + self.stride[a], 1.0)
                } else if p[a] == n - 1 {
                    (here - self.stride[a], here, 1.0)
                } else {
                    (here - self.stride[a], here + self.stride[a], 2.0)
                };
                g[a] += w * (self.data[hi].to_f32() - self.data[lo].to_f32()) / span;
            }
        }
        self.grad_to_world[0] * g[0] + self.grad_to_world[1] * g[1] + self.grad_to_world[2] * g[2]
    }

    /// The voxels' central differences (one-sided on the faces of the grid, zero along an axis
    /// of one voxel), in data units per index step, interpolated trilinearly in cell `c` at
    /// fractions `f`: per axis, the same interpolation as [`Ctx::sample_cell`] of the
    /// differences at the cell's eight corners, each `(ρ(p + e) − ρ(p − e)) · ½` (one-sided:
    /// `(ρ(p + e) − ρ(p)) · 1`). The scalar twin of [`ShadeSource`]'s gradients (interior cells).
    #[inline(always)]
    fn gradient_lerp(&self, c: [usize; 3], f: [f32; 3]) -> [f32; 3] {
        let base = self.base(c);
        let [ux, uy, uz] = self.up;
        // Corner k of the cell is (k & 1, k >> 1 & 1, k >> 2) voxels from its lower corner.
        let offs = [0, ux, uy, uy + ux, uz, uz + ux, uz + uy, uz + uy + ux];
        let mut g = [0.0f32; 3];
        for (a, out) in g.iter_mut().enumerate() {
            let (n, s) = (self.dims[a], self.stride[a]);
            if n < 2 {
                continue;
            }
            let mut d = [0.0f32; 8];
            for (k, (dk, &o)) in d.iter_mut().zip(&offs).enumerate() {
                let p = c[a] + (k >> a & 1);
                let at = base + o;
                let v = |q: usize| self.data[q].to_f32();
                *dk = if p == 0 {
                    (v(at + s) - v(at)) * 1.0
                } else if p == n - 1 {
                    (v(at) - v(at - s)) * 1.0
                } else {
                    (v(at + s) - v(at - s)) * 0.5
                };
            }
            let c00 = lerp(d[0], d[1], f[0]);
            let c10 = lerp(d[2], d[3], f[0]);
            let c01 = lerp(d[4], d[5], f[0]);
            let c11 = lerp(d[6], d[7], f[0]);
            *out = lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2]);
        }
        g
    }

    /// Composite through the classifier (tables that depend on more than the density, shaded or
    /// not): each sample is classified, with its gradient where the lights or the tables need
    /// one, as soon as it is reconstructed.
    fn band_plain(&self, y0: usize, rows: usize, acc: &mut [Rgba]) -> Counters {
        let w = self.width;
        let mut c = Counters::default();
        let mut line = vec![f32::NAN; w];
        // Live window of each row (composite): pixels outside it are opaque.
        let mut live: Vec<(i64, i64)> = vec![(0, w as i64 - 1); rows];
        let kf = self.path_factors(y0, rows);
        let (din, dout) = self.ray_extents(y0, rows);
        let half = (0.5 * self.delta) as f32;
        for p in 0..self.n_planes {
            let d = self.depth(p);
            let depth01 = ((d - self.dmin) * self.depth_scale).clamp(0.0, 1.0) as f32;
            let mut any_live = false;
            for r in 0..rows {
                let y = y0 + r;
                let walk = self.walk(y, d);
                let mut span = self.clip_span(y, d, walk.span);
                let row_acc = &mut acc[r * w..(r + 1) * w];
                let Some(lw) = shrink_live(&mut live[r], row_acc, self.cutoff) else {
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
                    let gradient = if self.shade {
                        self.gradient_at(&walk, x)
                    } else {
                        Vec3::ZERO
                    };
                    let rgba = self.classifier.classify(&SampleInput {
                        density: rho,
                        gradient,
                        depth: depth01,
                    });
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

    /// Perspective: the slab's path along the ray through a pixel is `Δ·k`, `k = √(1 + u² + v²)`
    /// ([`Ctx::path_factors`]), so the opacity (corrected for `Δ`) becomes `1 − (1 − α)^k` and
    /// the colour scales with it. `k = 1` (orthographic) changes nothing.
    #[inline]
    fn path_correct(&self, rgba: Rgba, k: f32) -> Rgba {
        let a = rgba[3];
        if k == 1.0 || a <= 0.0 || a >= 1.0 {
            return rgba;
        }
        let a2 = 1.0 - exp2_neg(k * log2_unit(1.0 - a));
        let s = a2 / a;
        [rgba[0] * s, rgba[1] * s, rgba[2] * s, a2]
    }

    /// The eye depths `d_in` and `d_out` between which the ray of each pixel of the rows
    /// `[y0, y0 + rows)` lies in the box the rays cross (`box_hi`) and on the kept side of
    /// every clipping plane (`[+∞, −∞]` where it misses).
    fn ray_extents(&self, y0: usize, rows: usize) -> (Vec<f32>, Vec<f32>) {
        let v = &self.view;
        let mut din = Vec::with_capacity(rows * self.width);
        let mut dout = Vec::with_capacity(rows * self.width);
        let (mut entry_walk, mut exit_walk) = (None, None);
        for y in y0..y0 + rows {
            for x in 0..self.width {
                let (u, w) = v.offsets(x as f64, y as f64);
                // Index and world position at depth d: a + d·b.
                let (aq, bq, aw, bw) = if v.perspective {
                    (
                        v.eye_q,
                        v.fwd_q + v.right_q * u + v.up_q * w,
                        v.eye,
                        v.fwd_w + v.right_w * u + v.up_w * w,
                    )
                } else {
                    (
                        v.eye_q + v.right_q * u + v.up_q * w,
                        v.fwd_q,
                        v.eye + v.right_w * u + v.up_w * w,
                        v.fwd_w,
                    )
                };
                let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
                let mut cut = |a: f64, b: f64, min: f64, max: f64| {
                    // min ≤ a + d·b ≤ max
                    if b.abs() < 1e-300 {
                        if a < min || a > max {
                            lo = f64::INFINITY;
                        }
                    } else {
                        let (t0, t1) = ((min - a) / b, (max - a) / b);
                        lo = lo.max(t0.min(t1));
                        hi = hi.min(t0.max(t1));
                    }
                };
                for ax in 0..3 {
                    cut(aq[ax], bq[ax], 0.0, self.box_hi[ax] as f64);
                }
                for &(n, off) in &self.clip {
                    cut(n.dot(aw) + off, n.dot(bw), 0.0, f64::INFINITY);
                }
                let (a, b) = if lo <= hi {
                    (
                        self.snap_entry(y, x, lo, &mut entry_walk),
                        self.snap_exit(y, x, hi, &mut exit_walk),
                    )
                } else {
                    (f32::INFINITY, f32::NEG_INFINITY)
                };
                din.push(a);
                dout.push(b);
            }
        }
        (din, dout)
    }

    /// Whether pixel `x` of row `y` is sampled on plane `j` (an absolute plane number,
    /// depth `j·Δ`): the walk's own fixed-point test and clipping, memoised per row and plane
    /// in `memo`.
    fn sampled_on(&self, y: usize, x: usize, j: i64, memo: &mut SpanMemo) -> bool {
        let p = j - self.j0;
        if p < 0 || p >= self.n_planes as i64 {
            return false;
        }
        let span = match *memo {
            Some((my, mj, span)) if my == y && mj == j => span,
            _ => {
                let d = self.depth(p as usize);
                let walk = self.walk(y, d);
                let c = self.clip_span(y, d, walk.span);
                let span = (c.0.max(walk.span.0), c.1.min(walk.span.1));
                *memo = Some((y, j, span));
                span
            }
        };
        span.0 <= x as i64 && x as i64 <= span.1
    }

    /// The depth where the ray of pixel `(x, y)` enters the volume (`lo`, f64), as
    /// [`boundary_factor`] must see it: where `lo` lies on a plane to within rounding, whether
    /// that plane's sample is taken is the walk's fixed-point decision, and the depth handed on
    /// is moved (by the rounding, at most) so that the first plane sampled, and only it, takes
    /// the path from `lo`. Without this a plane on the entry face to rounding was left out by
    /// the walk while the next plane took only its own half slab: half a slab of path lost
    /// (`docs/BENCHMARKS.md` §17.3).
    fn snap_entry(&self, y: usize, x: usize, lo: f64, memo: &mut SpanMemo) -> f32 {
        let j = (lo / self.delta).round();
        if (lo - j * self.delta).abs() > self.snap_tolerance(lo) {
            return lo as f32;
        }
        let half = (0.5 * self.delta) as f32;
        // `boundary_factor`'s front of plane j + 1: the slab before it starts a ray there.
        let front_next = ((j + 1.0) * self.delta) as f32 - 2.0 * half;
        let din = lo as f32;
        if self.sampled_on(y, x, j as i64, memo) {
            din.min(front_next)
        } else if front_next < din {
            din
        } else {
            front_next.next_up()
        }
    }

    /// [`Ctx::snap_entry`] for the depth `hi` where the ray leaves the volume.
    fn snap_exit(&self, y: usize, x: usize, hi: f64, memo: &mut SpanMemo) -> f32 {
        let j = (hi / self.delta).round();
        if (hi - j * self.delta).abs() > self.snap_tolerance(hi) {
            return hi as f32;
        }
        let half = (0.5 * self.delta) as f32;
        let back_prev = ((j - 1.0) * self.delta) as f32 + 2.0 * half;
        let dout = hi as f32;
        if self.sampled_on(y, x, j as i64, memo) {
            dout.max(back_prev)
        } else if back_prev > dout {
            dout
        } else {
            back_prev.next_down()
        }
    }

    /// How near a plane an entry or exit depth `d` must lie for [`Ctx::snap_entry`] to ask the
    /// walk: well above the rounding of f32 depths and 32.32 positions, far below a slab.
    fn snap_tolerance(&self, d: f64) -> f64 {
        (1e-3 * self.delta).max(8.0 * f32::EPSILON as f64 * d.abs())
    }

    /// The path factor `k = √(1 + u² + v²)` of every pixel of the rows `[y0, y0 + rows)`: 1 in
    /// orthographic views.
    fn path_factors(&self, y0: usize, rows: usize) -> Vec<f32> {
        let w = self.width;
        if !self.view.perspective {
            return vec![1.0; rows * w];
        }
        let mut k = Vec::with_capacity(rows * w);
        for y in y0..y0 + rows {
            for x in 0..w {
                let (u, v) = self.view.offsets(x as f64, y as f64);
                k.push((1.0 + u * u + v * v).sqrt() as f32);
            }
        }
        k
    }
}

/// Narrows a row's window of live pixels (those below the opacity `cutoff`) from both ends;
/// `None` once every pixel of the row is opaque.
fn shrink_live(lw: &mut (i64, i64), row: &[Rgba], cutoff: f32) -> Option<(i64, i64)> {
    while lw.0 <= lw.1 && row[lw.0 as usize][3] >= cutoff {
        lw.0 += 1;
    }
    while lw.1 >= lw.0 && row[lw.1 as usize][3] >= cutoff {
        lw.1 -= 1;
    }
    (lw.0 <= lw.1).then_some(*lw)
}

/// Bits of fraction in the fixed-point index positions.
const FRAC: u32 = 32;

/// `⌊n / d⌋` for `n ≥ 0`, `d > 0`, given `inv = 1 / d`: estimated in f64 and corrected to the
/// exact integer (a 64-bit division costs several times as much, once per brick run).
#[inline(always)]
fn div_floor(n: i64, d: i64, inv: f64) -> i64 {
    let mut k = (n as f64 * inv) as i64;
    while k > 0 && k * d > n {
        k -= 1;
    }
    while (k + 1) * d <= n {
        k += 1;
    }
    k
}

#[inline]
fn to_fixed(v: f64) -> i64 {
    round_i64(v * (1u64 << FRAC) as f64)
}

/// `x.round() as i64` (half away from zero), without libm's `round` (a call on x86-64 without
/// SSE4.1): below 2⁵² the truncation and its remainder are exact, so the result is the same.
#[inline(always)]
fn round_i64(x: f64) -> i64 {
    if x.abs() < 4.5e15 {
        let t = x as i64;
        let f = x - t as f64;
        t + i64::from(f >= 0.5) - i64::from(f <= -0.5)
    } else {
        x.round() as i64
    }
}

/// `x.ceil()` up to the sign of a zero result, without libm ([`round_i64`]'s reason).
#[inline(always)]
fn ceil_f64(x: f64) -> f64 {
    if x.abs() < 4.5e15 {
        let t = x as i64 as f64;
        if t < x { t + 1.0 } else { t }
    } else {
        x.ceil()
    }
}

/// `x.floor()` up to the sign of a zero result, without libm ([`round_i64`]'s reason).
#[inline(always)]
fn floor_f64(x: f64) -> f64 {
    if x.abs() < 4.5e15 {
        let t = x as i64 as f64;
        if t > x { t - 1.0 } else { t }
    } else {
        x.floor()
    }
}

/// One row of one plane in fixed-point index coordinates ([`Ctx::walk`]).
struct Walk {
    s: [i64; 3],
    st: [i64; 3],
    /// The row's start and step as f32, for the samples themselves.
    s32: [f32; 3],
    st32: [f32; 3],
    /// Pixels inside the box the rays cross (empty when `span.0 > span.1`).
    span: (i64, i64),
}

impl Walk {
    /// How many pixels from the one at `q` (index `cell` along axis `a`) on keep their cells in
    /// the same brick along axis `a` (`i64::MAX` if the row does not move along it); `inv` is
    /// `1 / |st[a]|` ([`div_floor`]).
    #[inline(always)]
    fn run_along(&self, a: usize, q: i64, cell: usize, inv: f64) -> i64 {
        let st = self.st[a];
        let b0 = ((cell / BRICK) * BRICK) as i64;
        if st > 0 {
            // Steps k with q + k·st < (b0 + B) << FRAC.
            let room = ((b0 + BRICK as i64) << FRAC) - q;
            div_floor(room + st - 1, st, inv)
        } else if st < 0 {
            // Steps k with q + k·st ≥ b0 << FRAC, counting the pixel itself.
            let room = q - (b0 << FRAC);
            div_floor(room, -st, inv) + 1
        } else {
            i64::MAX
        }
    }

    #[inline(always)]
    fn at(&self, x: i64) -> [i64; 3] {
        [
            self.s[0] + x * self.st[0],
            self.s[1] + x * self.st[1],
            self.s[2] + x * self.st[2],
        ]
    }
}

/// Premultiplied RGBA per density for unshaded classification: [`FrameClassifier::classify`]
/// evaluated at the entries of its own fused table (so the entries agree with it exactly),
/// read with linear interpolation of the premultiplied values (interpolating colour and
/// opacity separately, as `classify` does, differs between entries by the product of the
/// two increments).
struct PostTable {
    /// Perspective: `[r, g, b, log2(1 − α)]` per entry (colour not premultiplied).
    persp: Vec<Rgba>,
    /// Entry `i` of `values` (of `persp`) followed by entry `min(i + 1, last)`: one 32-byte row
    /// per lookup for [`composite_run_avx2`].
    pairs: Vec<[f32; 8]>,
    persp_pairs: Vec<[f32; 8]>,
    /// Pre-integration ([`PostTable::segment`]): `[∫c_r·L, ∫c_g·L, ∫c_b·L, ∫L]` from the first
    /// entry to entry `i` (`L = log2(1 − α)`, `c` the colour of `persp`; integrals in entries,
    /// trapezoidal, summed in f64), and the same paired as `pairs`.
    integ: Vec<Rgba>,
    integ_pairs: Vec<[f32; 8]>,
    lo: f32,
    scale: f32,
    last: f32,
    values: Vec<Rgba>,
}

/// [`Preintegrate::Auto`] pre-integrates where [`ring_risk`] exceeds this: where the steepest
/// ramp of the transfer function takes a slab's opacity through more than 4 across a quarter of
/// the data's value range. Measured on the CT head phantom and the MRIs (decision 0020; PSNR
/// against the same renderer at ⅛ voxel, segment minus point): sharp skin ramps (risk 10–11)
/// +5.4 dB unshaded, +0.7 dB shaded; Slicer's CT-Soft-Tissue (79) +6 dB; CT-Air (1.3), CT-Skin
/// (1.5, shaded), CT-Muscle (1.2, shaded), CT-Bone (0.8) and the MRI scenes (0.2–0.3) lose 1–14
/// dB by segment; the built-in demo (2.2, shaded) would gain 5 dB but stays by point.
pub const RING_RISK: f32 = 4.0;

/// How much a slab's opacity can change across a quarter of the data's value range at the
/// steepest ramp of a density table: `max |α[i+1] − α[i]|·entries_per_unit·data_range/4`, with
/// `alphas` the table's opacities per slab at `entries_per_unit` entries per data unit and
/// `data_range` the data's `max − min` (data units). A quarter of the range stands for the value
/// step across a sharp boundary of the data (air to skin, soft tissue to bone); 0 for an empty
/// table or range.
pub fn ring_risk(alphas: &[f32], entries_per_unit: f32, data_range: f32) -> f32 {
    let steepest = alphas
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    let r = steepest * entries_per_unit * data_range * 0.25;
    if r.is_finite() { r } else { 0.0 }
}

/// The most negative `log2(1 − α)` that the pre-integration tables integrate (α = 1 − 2⁻²⁴,
/// opaque at f32 precision): a bound on the integrals, so that the difference of two of them
/// keeps its precision in f32 ([`integral_rows`]).
const SEGMENT_LOG_FLOOR: f32 = -24.0;

/// Segments shorter than this many table entries are classified at their middle value (the
/// table is linear there, so that is the segment's average up to a kink), longer ones through
/// the integral tables ([`PostTable::segment`], [`ShadeTable::segment_entry`]).
const SEGMENT_MIN_ENTRIES: f32 = 1.0;

/// The averages over the segment between table positions `tu` and `tv` ([`PostTable::segment`],
/// [`ShadeTable::segment_entry`]): shorter than [`SEGMENT_MIN_ENTRIES`], the entry at the
/// middle (`at(false, ·)`); else from the integral rows (`at(true, ·)`), `L̄ = Δ∫L / Δt` in slot
/// `L`, each other slot `Δ∫x·L / Δ∫L`, and 0 in slot `W` (where the rows hold `∫L`) if it is
/// not `L`. The post table integrates into slot 3 and returns `[c̄, L̄]` (`W = L = 3`); the
/// shade table integrates into slot 0 and returns `[0, ē, d̄, L̄]` (`W = 0`, `L = 7`).
#[inline(always)]
fn segment_average<const N: usize, const W: usize, const L: usize>(
    tu: f32,
    tv: f32,
    at: impl Fn(bool, f32) -> [f32; N],
) -> [f32; N] {
    let (w, l) = (W, L);
    let dt = tv - tu;
    if dt.abs() < SEGMENT_MIN_ENTRIES {
        return at(false, (tu + tv) * 0.5);
    }
    let (a, b) = (at(true, tu), at(true, tv));
    let dl = b[w] - a[w];
    let inv = 1.0 / dl;
    std::array::from_fn(|c| {
        if c == l {
            dl / dt
        } else if c == w {
            0.0
        } else {
            (b[c] - a[c]) * inv
        }
    })
}

/// Cumulative trapezoidal integrals over table entries of `rows` (`N` channels): channel `w` of
/// the result integrates the weight `max(row[w], SEGMENT_LOG_FLOOR)` (a `log2(1 − α)`), every
/// other channel `c` integrates `row[c]·weight`; entry 0 is zero. Summed in f64 and rounded once.
fn integral_rows<const N: usize>(rows: &[[f32; N]], w: usize) -> Vec<[f32; N]> {
    let weighted = |r: &[f32; N]| -> [f64; N] {
        let l = f64::from(r[w].max(SEGMENT_LOG_FLOOR));
        std::array::from_fn(|c| if c == w { l } else { f64::from(r[c]) * l })
    };
    let mut acc = [0.0f64; N];
    let mut out = Vec::with_capacity(rows.len());
    out.push([0.0f32; N]);
    for pair in rows.windows(2) {
        let (a, b) = (weighted(&pair[0]), weighted(&pair[1]));
        for c in 0..N {
            acc[c] += 0.5 * (a[c] + b[c]);
        }
        out.push(acc.map(|v| v as f32));
    }
    out
}

impl PostTable {
    const LEN: usize = 1024;

    fn new(tables: &CrioTables, classifier: &FrameClassifier) -> Option<Self> {
        use volsplat_core::TableIndex::Density;
        let idx = [
            tables.opacity.index,
            tables.emission.index,
            tables.reflection.index,
        ];
        if idx.iter().any(|&i| i != Density)
            || tables.modulation.values.len() != 1
            || classifier.needs_gradient
        {
            return None;
        }
        let (lo, hi) = table_range(tables);
        let n = if hi > lo { Self::LEN } else { 1 };
        let values: Vec<Rgba> = (0..n)
            .map(|k| {
                let x = if n == 1 {
                    lo
                } else {
                    lo + (hi - lo) * k as f32 / (n - 1) as f32
                };
                classifier
                    .classify(&SampleInput {
                        density: x,
                        gradient: Vec3::ZERO,
                        depth: 0.0,
                    })
                    .unwrap_or([0.0; 4])
            })
            .collect();
        // Perspective: un-premultiplied colour and log2(1 − α) (−126 for α = 1), so that
        // `1 − (1 − α)^k` is one exp2.
        let persp: Vec<Rgba> = values
            .iter()
            .map(|v: &Rgba| {
                let a = v[3];
                if a <= 0.0 {
                    [0.0; 4]
                } else {
                    let l = if a >= 1.0 {
                        -126.0
                    } else {
                        log2_unit(1.0 - a).max(-126.0)
                    };
                    [v[0] / a, v[1] / a, v[2] / a, l]
                }
            })
            .collect();
        let paired = |t: &[Rgba]| -> Vec<[f32; 8]> {
            (0..t.len())
                .map(|i| {
                    let (a, b) = (t[i], t[(i + 1).min(t.len() - 1)]);
                    [a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]]
                })
                .collect()
        };
        let (scale, last) = table_steps(lo, hi, n);
        let integ = integral_rows(&persp, 3);
        Some(PostTable {
            pairs: paired(&values),
            persp_pairs: paired(&persp),
            integ_pairs: paired(&integ),
            integ,
            persp,
            lo,
            scale,
            last,
            values,
        })
    }

    #[inline(always)]
    fn lookup(&self, x: f32) -> Rgba {
        self.lookup_in(&self.values, x)
    }

    /// Per entry, whether it has opacity in either form the kernels read (`values`' α > 0, or
    /// `persp`'s `log2(1 − α)` < 0; NaN counts), for [`BrickGrid::active_in_table`].
    fn nonzero(&self) -> Vec<bool> {
        self.values
            .iter()
            .zip(&self.persp)
            .map(|(v, p)| !(v[3] <= 0.0 && p[3] >= 0.0))
            .collect()
    }

    /// Linear interpolation in `values` (either table) at density `x`.
    #[inline(always)]
    fn lookup_in(&self, values: &[Rgba], x: f32) -> Rgba {
        Self::at(values, self.pos(x))
    }

    /// The table position of density `x`: `min(max((x − lo)·scale, 0), last)` (NaN → 0).
    #[inline(always)]
    fn pos(&self, x: f32) -> f32 {
        ((x - self.lo) * self.scale).max(0.0).min(self.last)
    }

    /// The pre-integrated classification of the segment of a ray whose density goes linearly
    /// from `u` (the previous plane) to `v` (this plane): `[c̄_r, c̄_g, c̄_b, L̄]` with `L̄` the
    /// mean of `L = log2(1 − α)` over the segment's densities and `c̄` the colour weighted by
    /// `L` (Engel, Kraus & Ertl 2001, with the self-attenuation inside the segment left out of
    /// the colour: `c̄ = ∫c·L / ∫L`, exact where the colour is constant). Segments shorter than
    /// [`SEGMENT_MIN_ENTRIES`] take the entry at their middle (`persp`). Where the segment has
    /// no opacity (`∫L = 0`) `L̄` is 0 and the colours 0/0 (NaN): it contributes nothing
    /// ([`Ctx::post_seg_src`], and the kernels' masks).
    #[inline(always)]
    fn segment(&self, u: f32, v: f32) -> Rgba {
        let at = |integ: bool, t| Self::at(if integ { &self.integ } else { &self.persp }, t);
        segment_average::<4, 3, 3>(self.pos(u), self.pos(v), at)
    }

    /// Linear interpolation in `values` at table position `t` (in `[0, last]`).
    #[inline(always)]
    fn at(values: &[Rgba], t: f32) -> Rgba {
        // t ∈ [0, last] (NaN maps to 0 through `max`), so the i32 conversion is exact.
        let i = t as i32 as usize;
        let f = t - i as f32;
        let a = values[i];
        let b = values[(i + 1).min(values.len() - 1)];
        [
            a[0] + f * (b[0] - a[0]),
            a[1] + f * (b[1] - a[1]),
            a[2] + f * (b[2] - a[2]),
            a[3] + f * (b[3] - a[3]),
        ]
    }
}

/// What the shaded kernel reads per sample ([`shaded_src`]): the classifier's terms before
/// shading ([`FrameClassifier::surface_terms`]) at 1024 densities, read with linear
/// interpolation like [`PostTable`], the lights of the frame, a table of the specular power, and
/// the matrix from the stored gradient field to world gradients.
pub(crate) struct ShadeTable {
    lo: f32,
    scale: f32,
    last: f32,
    /// `[α, e_r, e_g, e_b, d_r, d_g, d_b, log2(1 − α)]` per density (α step-corrected, `e` the
    /// emission `classify` adds, `d` the reflection colour; `log2(1 − α)` is −126 for `α = 1`),
    /// with the last entry repeated so that entry `i + 1` exists for every `i ≤ last`.
    rows: Vec<[f32; 8]>,
    /// Pre-integration ([`ShadeTable::segment_entry`]): `[∫L, ∫e·L, ∫d·L, 0]` from the first
    /// entry (as [`PostTable`]'s `integ`), the last entry repeated as in `rows`.
    integ: Vec<[f32; 8]>,
    /// `x^n` at `x = i / SPEC` for `i` in `0..=SPEC`, the last repeated (as `classify`'s own
    /// table of 4097 entries).
    spec_pow: Vec<f32>,
    lights: Vec<volsplat_core::FrameLight>,
    diffuse: bool,
    specular: bool,
    two_sided: bool,
    /// Constant specular colour, or `None` for the reflection colour.
    spec_color: Option<[f32; 3]>,
    /// Column `a`: the world gradient per unit of the index-space derivative along axis `a`
    /// (`Ctx::grad_to_world`).
    to_world: [[f32; 3]; 3],
}

impl ShadeTable {
    const LEN: usize = 1024;
    const SPEC: usize = 4096;

    /// `None` where the classifier's terms depend on more than the density (tables indexed by
    /// gradient magnitude or depth, a modulation that is not constant).
    pub(crate) fn new(
        tables: &CrioTables,
        classifier: &FrameClassifier,
        grad_to_world: [Vec3; 3],
    ) -> Option<Self> {
        let (lo, hi) = table_range(tables);
        classifier.surface_terms(lo)?;
        let n = if hi > lo { Self::LEN } else { 1 };
        let mut rows: Vec<[f32; 8]> = (0..n)
            .map(|k| {
                let x = if n == 1 {
                    lo
                } else {
                    lo + (hi - lo) * k as f32 / (n - 1) as f32
                };
                let t = classifier
                    .surface_terms(x)
                    .unwrap_or(volsplat_core::SurfaceTerms {
                        alpha: 0.0,
                        emission: [0.0; 3],
                        reflection: [0.0; 3],
                    });
                let a = t.alpha;
                let l = if a <= 0.0 {
                    0.0
                } else if a >= 1.0 {
                    -126.0
                } else {
                    log2_unit(1.0 - a).max(-126.0)
                };
                let [er, eg, eb] = t.emission;
                let [dr, dg, db] = t.reflection;
                [a, er, eg, eb, dr, dg, db, l]
            })
            .collect();
        rows.push(rows[n - 1]);
        // Integrate L (channel 7) and e·L, d·L; then store as [∫L, ∫e·L, ∫d·L, 0].
        let mut integ: Vec<[f32; 8]> = integral_rows(&rows[..n], 7)
            .into_iter()
            .map(|r| [r[7], r[1], r[2], r[3], r[4], r[5], r[6], 0.0])
            .collect();
        integ.push(integ[n - 1]);
        let sh = classifier.shading();
        let p = sh.specular_power as f64;
        let mut spec_pow: Vec<f32> = (0..=Self::SPEC)
            .map(|i| (i as f64 / Self::SPEC as f64).powf(p) as f32)
            .collect();
        spec_pow.push(spec_pow[Self::SPEC]);
        let (scale, last) = table_steps(lo, hi, n);
        Some(ShadeTable {
            lo,
            scale,
            last,
            rows,
            integ,
            spec_pow,
            lights: classifier.lights().to_vec(),
            diffuse: sh.diffuse,
            specular: sh.specular,
            two_sided: sh.two_sided,
            spec_color: match sh.specular_color {
                volsplat_core::SpecularColor::Constant(c) => Some(c),
                volsplat_core::SpecularColor::Reflection => None,
            },
            to_world: grad_to_world.map(|g| g.to_array()),
        })
    }

    /// Per entry of `rows`, whether it has opacity in either form the kernels read (α > 0, or
    /// `log2(1 − α)` < 0; NaN counts), for [`BrickGrid::active_in_table`].
    fn nonzero(&self) -> Vec<bool> {
        self.rows
            .iter()
            .map(|r| !(r[0] <= 0.0 && r[7] >= 0.0))
            .collect()
    }

    /// The entry at density `x`, linearly interpolated.
    #[inline(always)]
    fn entry(&self, x: f32) -> [f32; 8] {
        Self::at(&self.rows, self.pos(x))
    }

    /// The table position of density `x` (as [`PostTable::pos`]).
    #[inline(always)]
    fn pos(&self, x: f32) -> f32 {
        ((x - self.lo) * self.scale).max(0.0).min(self.last)
    }

    /// Row `t` of `rows` (a position in `[0, last]`), linearly interpolated.
    #[inline(always)]
    fn at(rows: &[[f32; 8]], t: f32) -> [f32; 8] {
        // t ∈ [0, last] (NaN maps to 0 through `max`), so the i32 conversion is exact.
        let i = t as i32 as usize;
        let f = t - i as f32;
        let (a, b) = (rows[i], rows[i + 1]);
        std::array::from_fn(|c| a[c] + f * (b[c] - a[c]))
    }

    /// The pre-integrated entry of the segment from density `u` (the previous plane) to `v`
    /// ([`PostTable::segment`]'s averages): `[0, ē, d̄, L̄]`, emission and reflection colours
    /// weighted by `L`. The opacity slot is 0: pre-integrated samples always take the
    /// path-corrected opacity `1 − 2^(k·L̄)` ([`shade_opacity`] with `corrected`).
    #[inline(always)]
    fn segment_entry(&self, u: f32, v: f32) -> [f32; 8] {
        let at = |integ: bool, t| Self::at(if integ { &self.integ } else { &self.rows }, t);
        segment_average::<8, 0, 7>(self.pos(u), self.pos(v), at)
    }

    /// The lights of the frame.
    pub(crate) fn lights(&self) -> &[volsplat_core::FrameLight] {
        &self.lights
    }

    /// Whether the diffuse and the specular terms apply, and whether lighting is two-sided.
    pub(crate) fn switches(&self) -> (bool, bool, bool) {
        (self.diffuse, self.specular, self.two_sided)
    }

    /// `x^n` for `x` in `(0, 1]`, linearly interpolated in the table.
    #[inline(always)]
    pub(crate) fn spec(&self, x: f32) -> f32 {
        let t = min_ps(max_ps(x * Self::SPEC as f32, 0.0), Self::SPEC as f32);
        let i = t as i32 as usize;
        let f = t - i as f32;
        let (a, b) = (self.spec_pow[i], self.spec_pow[i + 1]);
        a + f * (b - a)
    }
}

/// The premultiplied, shaded colour of a sample of density `rho` whose interpolated voxel
/// gradient is `g` ([`Ctx::gradient_lerp`], index units), with slab exponent `k`, or `None`
/// where it has no opacity: [`FrameClassifier::classify`]'s formula (emission, then per
/// light the diffuse term `d·c_L·(N·L)` and the specular term `s·c_L·(N·H)^n` where `N·L > 0`
/// (`|N·L|` two-sided), clamped to [0, 1], times the opacity), with the terms read from
/// [`ShadeTable`]. The scalar twin of [`shade_terms8`] and [`shade_light8`]: every operation in the same order, the
/// `if`s written as the kernel's masks (a term that does not apply adds `+0`) and the clamps
/// as `maxps`/`minps`, so the bits agree.
#[inline(always)]
pub(crate) fn shaded_src(
    t: &ShadeTable,
    rho: f32,
    g: [f32; 3],
    k: f32,
    corrected: bool,
) -> Option<Rgba> {
    let v = t.entry(rho);
    let a = shade_opacity(&v, k, corrected)?;
    let m = &t.to_world;
    let gw: [f32; 3] = std::array::from_fn(|i| m[0][i] * g[0] + m[1][i] * g[1] + m[2][i] * g[2]);
    let g2 = gw[0] * gw[0] + gw[1] * gw[1] + gw[2] * gw[2];
    let mut col = [v[1], v[2], v[3]];
    if (t.diffuse || t.specular) && g2 > 0.0 {
        let inv = 1.0 / g2.sqrt();
        let n = gw.map(|c| c * inv);
        for light in &t.lights {
            let (l, h, lc) = (light.l, light.h, light.color.to_array());
            let mut ndl = n[0] * l.x + n[1] * l.y + n[2] * l.z;
            let mut ndh = n[0] * h.x + n[1] * h.y + n[2] * h.z;
            if t.two_sided && ndl < 0.0 {
                ndl = -ndl;
                ndh = -ndh;
            }
            let lit = ndl > 0.0;
            if !lit {
                continue;
            }
            if t.diffuse {
                for ch in 0..3 {
                    col[ch] += v[4 + ch] * lc[ch] * ndl;
                }
            }
            if t.specular && ndh > 0.0 {
                let p = t.spec(ndh);
                for ch in 0..3 {
                    let s = t.spec_color.map_or(v[4 + ch], |c| c[ch]);
                    col[ch] += s * lc[ch] * p;
                }
            }
        }
    }
    Some(premultiplied(col, a))
}

/// The premultiplied, shaded colour of a sample with [`ShadeTable`] entry `v` (at its density,
/// [`ShadeTable::entry`], or its segment's, [`ShadeTable::segment_entry`]) lit at fractions `f`
/// in a cell whose eight corners (`x` fastest) have the direction codes `codes`, with slab
/// exponent `k`, or `None` where it has no opacity: shaded at the voxels ([`ShadeAt::Voxels`]):
/// the diffuse and specular light of each corner's code ([`VoxelShading`]) interpolated as
/// [`Ctx::sample_cell`] interpolates the values, then `e + d·D + s·S` per channel (emission `e`
/// and reflection colour `d` from `v`; `s` the specular colour), clamped to [0, 1], times the
/// opacity. The scalar twin of [`VoxelShadeSource`]: the same f32 operations
/// in the same order.
#[inline(always)]
fn voxel_shaded_src(
    t: &ShadeTable,
    vs: &VoxelShading,
    v: [f32; 8],
    codes: &[u16; 8],
    f: [f32; 3],
    k: f32,
    corrected: bool,
) -> Option<Rgba> {
    let a = shade_opacity(&v, k, corrected)?;
    let mut col = [v[1], v[2], v[3]];
    let (diffuse, specular, _) = t.switches();
    if diffuse || specular {
        // Per plane: the corners' diffuse and specular units interpolated, then scaled.
        let light = |p: usize| {
            let plane = vs.plane(p);
            let w = codes.map(|q| plane[q as usize]);
            let tri = |c: [f32; 8]| {
                let c00 = lerp(c[0], c[1], f[0]);
                let c10 = lerp(c[2], c[3], f[0]);
                let c01 = lerp(c[4], c[5], f[0]);
                let c11 = lerp(c[6], c[7], f[0]);
                lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2])
            };
            let d = tri(w.map(|w| (w & 0xffff) as i32 as f32));
            let s = tri(w.map(|w| (w >> 16) as i32 as f32));
            [d * vs.scale[p][0], s * vs.scale[p][1]]
        };
        let l = if vs.chromatic {
            [light(0), light(1), light(2)]
        } else {
            [light(0); 3]
        };
        if diffuse {
            for ch in 0..3 {
                col[ch] += v[4 + ch] * l[ch][0];
            }
        }
        if specular {
            for ch in 0..3 {
                let sc = t.spec_color.map_or(v[4 + ch], |c| c[ch]);
                col[ch] += sc * l[ch][1];
            }
        }
    }
    Some(premultiplied(col, a))
}

/// The opacity of a shaded sample from its [`ShadeTable`] entry `v`: path-corrected
/// (`1 − 2^(k·log2(1 − α))`) where `corrected`, else `α`; `None` where it has none (NaN entries
/// contribute nothing, as in the kernels' ordered comparisons): the scalar twin of
/// [`shade_terms8`]'s opacity.
#[inline(always)]
fn shade_opacity(v: &[f32; 8], k: f32, corrected: bool) -> Option<f32> {
    if corrected {
        (v[7] < 0.0).then(|| 1.0 - exp2_neg(k * v[7]))
    } else {
        (v[0] > 0.0).then_some(v[0])
    }
}

/// Pre-integration shaded at the voxels: where along its segment a slab is lit, as the fraction
/// of the way back from this plane's sample to the plane before's: the middle. A ramp that the
/// segment crosses is crossed anywhere along it with equal chance, and the middle is where the
/// segment's path is centred. Two better-founded placements were measured against it
/// (`docs/BENCHMARKS.md` §17.4, decision 0020's amendment): the visible centroid of an evenly
/// spread extinction (stop 24) lit opaque segments near their front, in the air before a sharp
/// ramp, and lost up to 1.1 dB to the middle; the centroid of a step in extinction between the
/// segment's two samples gained 0.4 dB over the middle on one scene `auto` pre-integrates and
/// nothing on the others, for 10–17 % of the frame.
const SEGMENT_LIGHT_AT: f32 = 0.5;

/// The shaded colour `col` clamped to [0, 1] (as `maxps`/`minps` clamp) and multiplied by the
/// opacity `a`: the premultiplied RGBA of a shaded sample.
#[inline(always)]
fn premultiplied(col: [f32; 3], a: f32) -> Rgba {
    let c = col.map(|c| min_ps(max_ps(c, 0.0), 1.0) * a);
    [c[0], c[1], c[2], a]
}

/// Entries per data unit and the last entry's index of a table of `n` entries spanning
/// `[lo, hi]` (a table of one entry: `(0, 0)`).
fn table_steps(lo: f32, hi: f32, n: usize) -> (f32, f32) {
    let scale = if n > 1 {
        (n - 1) as f32 / (hi - lo)
    } else {
        0.0
    };
    (scale, (n - 1) as f32)
}

/// The density range `[lo, hi]` that the density-indexed tables cover together.
fn table_range(tables: &CrioTables) -> (f32, f32) {
    let lo = tables
        .opacity
        .lo
        .min(tables.emission.lo)
        .min(tables.reflection.lo);
    let hi = tables
        .opacity
        .hi
        .max(tables.emission.hi)
        .max(tables.reflection.hi);
    (lo, hi)
}

/// `log2(y)` for `y` in `(0, 1]`: the exponent plus the series of `log2((1 + t)/(1 − t))`,
/// `t = (m − 1)/(m + 1) ∈ [0, 1/3)`, to `t⁹` (error below 2·10⁻⁶). Plain arithmetic, so every
/// platform gives the same bits (no libm).
#[inline(always)]
fn log2_unit(y: f32) -> f32 {
    let bits = y.to_bits();
    let e = ((bits >> 23) & 0xff) as i32 - 127;
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    let p = t
        * (2.885_39
            + t2 * (0.961_796_7 + t2 * (0.577_078 + t2 * (0.412_198_6 + t2 * 0.320_598_9))));
    e as f32 + p
}

/// `2^z` for `z ≤ 0` (0 below −126): `2^(i + ½)·2^f`, `f ∈ [−½, ½]`, with the Taylor series of
/// `2^f` to `f⁶` (relative error below 2·10⁻⁷). Plain arithmetic, as [`log2_unit`].
#[inline(always)]
fn exp2_neg(z: f32) -> f32 {
    if z.is_nan() || z < -126.0 {
        return 0.0;
    }
    // Truncation rounds towards zero, so for z ≤ 0, i ≥ z and z − i ∈ (−1, 0].
    let i = z as i32;
    let f = z - i as f32 + 0.5;
    let p = 1.0
        + f * (std::f32::consts::LN_2
            + f * (0.240_226_5
                + f * (0.055_504_1 + f * (0.009_618_13 + f * (0.001_333_36 + f * 0.000_154_04)))));
    // 2^(i − ½) = 2^i / √2; i ≥ −126, so 2^i is a normal number.
    f32::from_bits(((i + 127) as u32) << 23) * p * std::f32::consts::FRAC_1_SQRT_2
}

/// The trilinear interpolation of `data` (a grid with the volume's strides) in the cell whose
/// lower corner has linear index `base`, at fractions `f`; `up` is the offset to the next voxel
/// per axis. [`Sampler8::sample`] does the same operations in the same order.
#[inline(always)]
fn trilinear<U: Scalar>(data: &[U], base: usize, up: [usize; 3], f: [f32; 3]) -> f32 {
    let [ux, uy, uz] = up;
    let v = |o: usize| data[base + o].to_f32();
    let c00 = lerp(v(0), v(ux), f[0]);
    let c10 = lerp(v(uy), v(uy + ux), f[0]);
    let c01 = lerp(v(uz), v(uz + ux), f[0]);
    let c11 = lerp(v(uz + uy), v(uz + uy + ux), f[0]);
    lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2])
}

/// `max(x, lo)` as `maxps` computes it (`x > lo ? x : lo`, so NaN and −0 give `lo`), for the
/// scalar twins of the AVX2 kernels.
#[inline(always)]
fn max_ps(x: f32, lo: f32) -> f32 {
    if x > lo { x } else { lo }
}

/// `min(x, hi)` as `minps` computes it (`x < hi ? x : hi`).
#[inline(always)]
fn min_ps(x: f32, hi: f32) -> f32 {
    if x < hi { x } else { hi }
}

#[inline(always)]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + t * (b - a)
}

static FORCE_SCALAR: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Makes the slab renderer sample one pixel at a time even where the CPU has AVX2 (tests compare
/// the two paths bit for bit). Process-wide; the images do not change, only the speed.
#[doc(hidden)]
pub fn force_scalar_sampling(on: bool) {
    FORCE_SCALAR.store(on, std::sync::atomic::Ordering::Relaxed);
}

fn simd_available() -> bool {
    if FORCE_SCALAR.load(std::sync::atomic::Ordering::Relaxed) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The accumulation of a band of rows as four planes of channels ([`Ctx::band_post`]).
/// How [`Ctx::band_post`] classifies: through the unshaded table, or shaded.
#[derive(Clone, Copy)]
enum Post<'a> {
    Table(&'a PostTable),
    Shaded(&'a ShadeTable),
    /// Shaded at the voxels, interpolated ([`ShadeAt::Voxels`]).
    Voxel(&'a ShadeTable, &'a VoxelShading),
}

struct BandAcc {
    r: Vec<f32>,
    g: Vec<f32>,
    b: Vec<f32>,
    a: Vec<f32>,
}

/// One row of a band being composited through one plane: its channels, and per pixel the path
/// factor and the depths where the ray enters and leaves the volume ([`Ctx::band_post`]).
struct RowCtx<'a> {
    r: &'a mut [f32],
    g: &'a mut [f32],
    b: &'a mut [f32],
    a: &'a mut [f32],
    kf: &'a [f32],
    din: &'a [f32],
    dout: &'a [f32],
    /// The plane's eye depth and half the slab thickness (world units).
    d: f32,
    half: f32,
    /// Pre-integration ([`Ctx::preint`]): per pixel the density sampled at the last plane
    /// that sampled it, and that plane's index + 1 (`u32::MAX` before any), so that a sample
    /// knows whether its pixel was sampled on the plane just before; `plane` is this plane's
    /// index. Empty without pre-integration.
    prev: &'a mut [f32],
    stamp: &'a mut [u32],
    plane: u32,
    /// Pre-integration shaded at the voxels: the index-space step from this plane's sample of
    /// pixel `x` to the plane before's, `back_s + x·back_st` (f32; [`Ctx::light_cell`]).
    back_s: [f32; 3],
    back_st: [f32; 3],
}

/// The opacity exponent of the slab at depth `d` for a ray with path factor `kf` that lies in
/// the volume (and its clipping) between the eye depths `din` and `dout`: `kf`, except for the
/// first and last slab of the ray, which stand for the path from where the ray enters (leaves)
/// the volume, not a whole slab (without this the cut faces step from plane to plane: wood
/// grain).
#[inline(always)]
fn boundary_factor(kf: f32, din: f32, dout: f32, d: f32, half: f32) -> f32 {
    let lo_cut = d - 2.0 * half < din;
    let hi_cut = d + 2.0 * half > dout;
    if lo_cut || hi_cut {
        let lo = if lo_cut { din } else { d - half };
        let hi = if hi_cut { dout } else { d + half };
        kf * ((hi - lo) / (2.0 * half)).max(0.0)
    } else {
        kf
    }
}

/// The last walk [`Ctx::sampled_on`] made: its row, absolute plane number and sampled span.
type SpanMemo = Option<(usize, i64, (i64, i64))>;

/// `0..n` coarse to fine: every 16th, then the odd multiples of 8, of 4, of 2, and the odd
/// numbers; each number once.
fn coarse_to_fine(n: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).step_by(16).collect();
    for s in [8, 4, 2, 1] {
        order.extend((s..n).step_by(2 * s));
    }
    order
}

/// [`shrink_live`] on a row's opacity channel.
fn shrink_live_alpha(lw: &mut (i64, i64), alpha: &[f32], cutoff: f32) -> Option<(i64, i64)> {
    while lw.0 <= lw.1 && alpha[lw.0 as usize] >= cutoff {
        lw.0 += 1;
    }
    while lw.1 >= lw.0 && alpha[lw.1 as usize] >= cutoff {
        lw.1 -= 1;
    }
    (lw.0 <= lw.1).then_some(*lw)
}

/// Trilinear samples of one row of one plane, eight pixels at a time with AVX2: lane `l` does
/// exactly [`Ctx::sample_scalar`]'s f32 operations for pixel `x + l` (no fused multiply–add:
/// AVX2 without FMA), and reads the volume with `vpgatherdd`: 8-bit and 16-bit samples are
/// gathered as 32-bit words holding two corners along x and masked (sign-extended for signed
/// types), so a group whose last corner lies within 3 bytes of the end of the data is left to
/// the scalar path.
#[cfg(target_arch = "x86_64")]
struct Sampler8<T> {
    ptr: *const i32,
    kind: volsplat_core::ScalarType,
    small: bool,
    offs: [i32; 8],
    s: [std::arch::x86_64::__m256; 3],
    st: [std::arch::x86_64::__m256; 3],
    maxc: [std::arch::x86_64::__m256i; 3],
    sy: std::arch::x86_64::__m256i,
    sz: std::arch::x86_64::__m256i,
    last_ok: std::arch::x86_64::__m256i,
    /// Bits from a corner's sample to the next one's along x within a 32-bit word (8- and
    /// 16-bit samples): `8·ux` or `16·ux`.
    x_shift: std::arch::x86_64::__m128i,
    /// Bricks along x and y ([`Sampler8::bricks_of`]).
    bdims: [std::arch::x86_64::__m256i; 2],
    _t: std::marker::PhantomData<T>,
}

/// Eight lanes' index positions and cells ([`Sampler8::locate`]); the fractions in the cells
/// are computed only for groups that are sampled ([`Cells8::fractions`]).
#[cfg(target_arch = "x86_64")]
struct Cells8 {
    cell: [std::arch::x86_64::__m256i; 3],
    pos: [std::arch::x86_64::__m256; 3],
    /// The lanes' pixel columns as f32.
    xf: std::arch::x86_64::__m256,
}

#[cfg(target_arch = "x86_64")]
impl Cells8 {
    /// The fractions in the cells, clamped to [0, 1]: [`Ctx::cell_f32`] lane by lane.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn fractions(&self) -> [std::arch::x86_64::__m256; 3] {
        use std::arch::x86_64::*;
        let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
        let mut frac = [zero; 3];
        for (ax, f) in frac.iter_mut().enumerate() {
            let d = _mm256_sub_ps(self.pos[ax], _mm256_cvtepi32_ps(self.cell[ax]));
            *f = _mm256_min_ps(_mm256_max_ps(d, zero), one);
        }
        frac
    }
}

#[cfg(target_arch = "x86_64")]
impl<T: Scalar> Sampler8<T> {
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    unsafe fn new(ctx: &Ctx<'_, T>, walk: &Walk) -> Self {
        use std::arch::x86_64::*;
        let data = ctx.data;
        let bytes = std::mem::size_of::<T>();
        // Largest index whose 4-byte read stays inside the data.
        let safe_last = std::mem::size_of_val(data).saturating_sub(4) / bytes;
        let [ux, uy, uz] = ctx.up;
        Sampler8 {
            ptr: data.as_ptr() as *const i32,
            kind: T::TYPE,
            small: bytes < 4,
            offs: [0, ux, uy, uy + ux, uz, uz + ux, uz + uy, uz + uy + ux].map(|o| o as i32),
            s: walk.s32.map(|v| _mm256_set1_ps(v)),
            st: walk.st32.map(|v| _mm256_set1_ps(v)),
            maxc: ctx.max_cell.map(|m| _mm256_set1_epi32(m as i32)),
            sy: _mm256_set1_epi32(ctx.stride[1] as i32),
            sz: _mm256_set1_epi32(ctx.stride[2] as i32),
            last_ok: _mm256_set1_epi32(safe_last as i32),
            x_shift: _mm_cvtsi32_si128((8 * bytes * ux).min(32) as i32),
            bdims: [
                _mm256_set1_epi32(ctx.bricks.dims[0] as i32),
                _mm256_set1_epi32(ctx.bricks.dims[1] as i32),
            ],
            _t: std::marker::PhantomData,
        }
    }

    /// The samples of pixels `x..x + 8` (all of whose cells are clamped to the grid), or `None`
    /// where an 8/16-bit read would pass the end of the data.
    ///
    /// # Safety
    /// The CPU must support AVX2, and the sampler must have been made for this volume.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn at(&self, x: usize) -> Option<std::arch::x86_64::__m256> {
        // SAFETY: the caller's guarantees are these calls' own.
        unsafe { self.sample(&self.locate(x)) }
    }

    /// The cells of pixels `x..x + 8` (clamped to the grid) and the fractions in them:
    /// [`Ctx::cell_f32`] lane by lane.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn locate(&self, x: usize) -> Cells8 {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_ps();
        let izero = _mm256_setzero_si256();
        // x + lane as f32: exact (x < 2^24), equal to the scalar `x as f32`.
        let xf = _mm256_add_ps(
            _mm256_set1_ps(x as f32),
            _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
        );
        let mut cell = [izero; 3];
        let mut pos = [zero; 3];
        for ax in 0..3 {
            let q = _mm256_add_ps(self.s[ax], _mm256_mul_ps(xf, self.st[ax]));
            pos[ax] = q;
            cell[ax] = _mm256_min_epi32(
                _mm256_max_epi32(_mm256_cvttps_epi32(q), izero),
                self.maxc[ax],
            );
        }
        Cells8 { cell, pos, xf }
    }

    /// The brick (`BrickGrid::index`) of each lane's cell.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn bricks_of(&self, c: &Cells8) -> std::arch::x86_64::__m256i {
        use std::arch::x86_64::*;
        let bdims = self.bdims;
        const S: i32 = BRICK.trailing_zeros() as i32;
        let [i, j, k] = c.cell.map(|v| _mm256_srli_epi32::<S>(v));
        _mm256_add_epi32(
            _mm256_mullo_epi32(
                _mm256_add_epi32(_mm256_mullo_epi32(k, bdims[1]), j),
                bdims[0],
            ),
            i,
        )
    }

    /// The trilinear samples at located cells ([`Sampler8::locate`]), or `None` where an
    /// 8/16-bit read would pass the end of the data.
    ///
    /// # Safety
    /// The CPU must support AVX2, and the sampler must have been made for this volume.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample(&self, c: &Cells8) -> Option<std::arch::x86_64::__m256> {
        // SAFETY: the caller's guarantees are these calls' own.
        unsafe { self.sample_at(self.base_of(c), c.fractions()) }
    }

    /// The linear index of each lane's cell (its lower corner).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn base_of(&self, c: &Cells8) -> std::arch::x86_64::__m256i {
        use std::arch::x86_64::*;
        let cell = &c.cell;
        _mm256_add_epi32(
            cell[0],
            _mm256_add_epi32(
                _mm256_mullo_epi32(cell[1], self.sy),
                _mm256_mullo_epi32(cell[2], self.sz),
            ),
        )
    }

    /// Voxels `idx, idx + 1, …, idx + N − 1` of each lane as f32 (`N` = 2 or 4): one 32-bit
    /// gather for four 8-bit voxels, one per two 16-bit voxels, one per 32-bit voxel.
    ///
    /// # Safety
    /// The CPU must support AVX2; for every lane the voxels read must lie in the data, and for
    /// 8/16-bit samples the 4-byte word read at each gathered voxel too.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn gather_run<const N: usize>(
        &self,
        idx: std::arch::x86_64::__m256i,
    ) -> [std::arch::x86_64::__m256; N] {
        use std::arch::x86_64::*;
        use volsplat_core::ScalarType;
        let mut out = [_mm256_setzero_ps(); N];
        let ptr = self.ptr;
        // SAFETY (gathers): the caller guarantees the reads.
        match self.kind {
            ScalarType::U8 | ScalarType::I8 => {
                let w = unsafe { _mm256_i32gather_epi32::<1>(ptr, idx) };
                for (j, o) in out.iter_mut().enumerate() {
                    let v = if self.kind == ScalarType::U8 {
                        _mm256_and_si256(
                            _mm256_srlv_epi32(w, _mm256_set1_epi32(8 * j as i32)),
                            _mm256_set1_epi32(0xff),
                        )
                    } else {
                        _mm256_srai_epi32::<24>(_mm256_sllv_epi32(
                            w,
                            _mm256_set1_epi32(24 - 8 * j as i32),
                        ))
                    };
                    *o = _mm256_cvtepi32_ps(v);
                }
            }
            ScalarType::U16 | ScalarType::I16 => {
                for p in 0..N / 2 {
                    let at = _mm256_add_epi32(idx, _mm256_set1_epi32(2 * p as i32));
                    let w = unsafe { _mm256_i32gather_epi32::<2>(ptr, at) };
                    let (lo, hi) = if self.kind == ScalarType::U16 {
                        (
                            _mm256_and_si256(w, _mm256_set1_epi32(0xffff)),
                            _mm256_srli_epi32::<16>(w),
                        )
                    } else {
                        (
                            _mm256_srai_epi32::<16>(_mm256_slli_epi32::<16>(w)),
                            _mm256_srai_epi32::<16>(w),
                        )
                    };
                    out[2 * p] = _mm256_cvtepi32_ps(lo);
                    out[2 * p + 1] = _mm256_cvtepi32_ps(hi);
                }
            }
            ScalarType::F32 => {
                for (j, o) in out.iter_mut().enumerate() {
                    let at = _mm256_add_epi32(idx, _mm256_set1_epi32(j as i32));
                    *o = unsafe { _mm256_i32gather_ps::<4>(ptr as *const f32, at) };
                }
            }
        }
        out
    }

    /// Voxels `idx … idx + 3` ([`Sampler8::gather_run`]).
    ///
    /// # Safety
    /// As [`Sampler8::gather_run`].
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn gather4(&self, idx: std::arch::x86_64::__m256i) -> [std::arch::x86_64::__m256; 4] {
        // SAFETY: the caller's guarantees.
        unsafe { self.gather_run::<4>(idx) }
    }

    /// Voxels `idx` and `idx + 1` ([`Sampler8::gather_run`]).
    ///
    /// # Safety
    /// As [`Sampler8::gather_run`].
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn gather2(&self, idx: std::arch::x86_64::__m256i) -> [std::arch::x86_64::__m256; 2] {
        // SAFETY: the caller's guarantees.
        unsafe { self.gather_run::<2>(idx) }
    }

    /// The trilinear samples in the cells with linear indices `base` ([`Sampler8::base_of`]) at
    /// fractions `frac` ([`Cells8::fractions`]), or `None` where an 8/16-bit read would pass the
    /// end of the data.
    ///
    /// # Safety
    /// The CPU must support AVX2, and `base` must come from cells located by this sampler (or
    /// one with the same grid).
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample_at(
        &self,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<std::arch::x86_64::__m256> {
        use std::arch::x86_64::*;
        use volsplat_core::ScalarType;
        let top = _mm256_add_epi32(base, _mm256_set1_epi32(self.offs[7]));
        if self.small && _mm256_movemask_epi8(_mm256_cmpgt_epi32(top, self.last_ok)) != 0 {
            return None;
        }
        let ptr = self.ptr;
        let kind = self.kind;
        let shift = self.x_shift;
        // One 32-bit read per pair of corners along x: for 8- and 16-bit samples the voxel
        // `ux` further (the next byte or half-word, or the same one where the grid is one voxel
        // wide) lies in the same word, so four gathers fetch the eight corners; 32-bit samples
        // need one gather per corner.
        macro_rules! gather_pair {
            ($o:expr, $ox:expr) => {{
                let idx = _mm256_add_epi32(base, _mm256_set1_epi32($o));
                // SAFETY: every index is a voxel of the volume (cells are clamped to the grid), and
                // for 8/16-bit samples the 4-byte read ends inside the data (checked above).
                // The word's low sample and the one `shift` bits up, zero-extended under `mask`
                // or sign-extended from the top `bits` of the word.
                macro_rules! unsigned {
                    ($w:expr, $mask:expr) => {{
                        let (w, m) = ($w, _mm256_set1_epi32($mask));
                        (
                            _mm256_cvtepi32_ps(_mm256_and_si256(w, m)),
                            _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srl_epi32(w, shift), m)),
                        )
                    }};
                }
                macro_rules! signed {
                    ($w:expr, $bits:literal) => {{
                        let w = $w;
                        let hi = _mm256_srl_epi32(w, shift);
                        (
                            _mm256_cvtepi32_ps(_mm256_srai_epi32::<$bits>(_mm256_slli_epi32::<
                                $bits,
                            >(w))),
                            _mm256_cvtepi32_ps(_mm256_srai_epi32::<$bits>(_mm256_slli_epi32::<
                                $bits,
                            >(hi))),
                        )
                    }};
                }
                unsafe {
                    match kind {
                        ScalarType::U8 => unsigned!(_mm256_i32gather_epi32::<1>(ptr, idx), 0xff),
                        ScalarType::I8 => signed!(_mm256_i32gather_epi32::<1>(ptr, idx), 24),
                        ScalarType::U16 => unsigned!(_mm256_i32gather_epi32::<2>(ptr, idx), 0xffff),
                        ScalarType::I16 => signed!(_mm256_i32gather_epi32::<2>(ptr, idx), 16),
                        ScalarType::F32 => {
                            let p = ptr as *const f32;
                            (
                                _mm256_i32gather_ps::<4>(p, idx),
                                _mm256_i32gather_ps::<4>(
                                    p,
                                    _mm256_add_epi32(base, _mm256_set1_epi32($ox)),
                                ),
                            )
                        }
                    }
                }
            }};
        }
        macro_rules! lerp8 {
            ($a:expr, $b:expr, $t:expr) => {{
                let (a, b) = ($a, $b);
                _mm256_add_ps(a, _mm256_mul_ps($t, _mm256_sub_ps(b, a)))
            }};
        }
        let o = self.offs;
        let (v0, v1) = gather_pair!(o[0], o[1]);
        let (v2, v3) = gather_pair!(o[2], o[3]);
        let (v4, v5) = gather_pair!(o[4], o[5]);
        let (v6, v7) = gather_pair!(o[6], o[7]);
        let v = [v0, v1, v2, v3, v4, v5, v6, v7];
        let c00 = lerp8!(v[0], v[1], frac[0]);
        let c10 = lerp8!(v[2], v[3], frac[0]);
        let c01 = lerp8!(v[4], v[5], frac[0]);
        let c11 = lerp8!(v[6], v[7], frac[0]);
        Some(lerp8!(
            lerp8!(c00, c10, frac[1]),
            lerp8!(c01, c11, frac[1]),
            frac[2]
        ))
    }
}

/// Samples pixels `a..=b` of a row eight at a time ([`Sampler8`]; the last group partly);
/// returns the first pixel not done (`b + 1`, or earlier where a group's reads would pass the
/// end of the data).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn sample_run_avx2<T: Scalar>(
    ctx: &Ctx<'_, T>,
    walk: &Walk,
    a: usize,
    b: usize,
    out: &mut [f32],
) -> usize {
    use std::arch::x86_64::*;
    // SAFETY (all calls below): the caller guarantees AVX2.
    let sampler = unsafe { Sampler8::new(ctx, walk) };
    let mut x = a;
    while x <= b {
        let Some(r) = (unsafe { sampler.at(x) }) else {
            break;
        };
        if x + 7 <= b {
            // SAFETY: x + 7 ≤ b < out.len().
            unsafe { _mm256_storeu_ps(out.as_mut_ptr().add(x), r) };
        } else {
            // The last, partial group: lanes past `b` sampled clamped cells (valid reads) and
            // are dropped here.
            let mut tmp = [0.0f32; 8];
            // SAFETY: tmp holds 8 floats.
            unsafe { _mm256_storeu_ps(tmp.as_mut_ptr(), r) };
            out[x..=b].copy_from_slice(&tmp[..=b - x]);
        }
        x += 8;
    }
    x
}

/// An 8×8 transpose: lane `l` of output `c` is element `c` of input row `l`.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn transpose8(r: [std::arch::x86_64::__m256; 8]) -> [std::arch::x86_64::__m256; 8] {
    use std::arch::x86_64::*;
    let t0 = _mm256_unpacklo_ps(r[0], r[1]);
    let t1 = _mm256_unpackhi_ps(r[0], r[1]);
    let t2 = _mm256_unpacklo_ps(r[2], r[3]);
    let t3 = _mm256_unpackhi_ps(r[2], r[3]);
    let t4 = _mm256_unpacklo_ps(r[4], r[5]);
    let t5 = _mm256_unpackhi_ps(r[4], r[5]);
    let t6 = _mm256_unpacklo_ps(r[6], r[7]);
    let t7 = _mm256_unpackhi_ps(r[6], r[7]);
    let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
    let u1 = _mm256_shuffle_ps::<0xee>(t0, t2);
    let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
    let u3 = _mm256_shuffle_ps::<0xee>(t1, t3);
    let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
    let u5 = _mm256_shuffle_ps::<0xee>(t4, t6);
    let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
    let u7 = _mm256_shuffle_ps::<0xee>(t5, t7);
    [
        _mm256_permute2f128_ps::<0x20>(u0, u4),
        _mm256_permute2f128_ps::<0x20>(u1, u5),
        _mm256_permute2f128_ps::<0x20>(u2, u6),
        _mm256_permute2f128_ps::<0x20>(u3, u7),
        _mm256_permute2f128_ps::<0x31>(u0, u4),
        _mm256_permute2f128_ps::<0x31>(u1, u5),
        _mm256_permute2f128_ps::<0x31>(u2, u6),
        _mm256_permute2f128_ps::<0x31>(u3, u7),
    ]
}

/// Rows `idx + off` of a table of 32-byte rows, transposed ([`transpose8`]): lane `l` of output
/// `c` is element `c` of row `idx[l] + off`.
///
/// # Safety
/// The CPU must support AVX2, and every `idx[l] + off` must be a row of `rows`.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn rows8(rows: &[[f32; 8]], idx: &[i32; 8], off: usize) -> [std::arch::x86_64::__m256; 8] {
    use std::arch::x86_64::*;
    let base = rows.as_ptr();
    let mut r = [_mm256_setzero_ps(); 8];
    for l in 0..8 {
        // SAFETY: the caller guarantees the rows exist.
        r[l] = unsafe { _mm256_loadu_ps(base.add(idx[l] as usize + off) as *const f32) };
    }
    transpose8(r)
}

/// Linear interpolation at positions `pos` (clamped to `[0, last]`) in a table of entries of
/// eight channels, lane by lane: `(i, f)` from `pos`, then `row_i + f·(row_{i+1} − row_i)` per
/// channel. With `paired`, row `i` holds entry `i` in its first four floats and entry `i + 1` in
/// its last four (four channels, one load per lane); otherwise entry `i + 1` is the next row.
///
/// # Safety
/// The CPU must support AVX2; the rows read must exist (`i ≤ last`, and `i + 1` too unless
/// `paired`).
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn interp8(
    rows: &[[f32; 8]],
    pos: std::arch::x86_64::__m256,
    paired: bool,
) -> [std::arch::x86_64::__m256; 8] {
    use std::arch::x86_64::*;
    let i = _mm256_cvttps_epi32(pos);
    let f = _mm256_sub_ps(pos, _mm256_cvtepi32_ps(i));
    let mut idx = [0i32; 8];
    // SAFETY: idx holds 8 i32; the rows' existence is the caller's guarantee.
    unsafe { _mm256_storeu_si256(idx.as_mut_ptr() as *mut __m256i, i) };
    let mut out = unsafe { rows8(rows, &idx, 0) };
    if paired {
        for ch in 0..4 {
            let (p, q) = (out[ch], out[ch + 4]);
            out[ch] = _mm256_add_ps(p, _mm256_mul_ps(f, _mm256_sub_ps(q, p)));
        }
    } else {
        let next = unsafe { rows8(rows, &idx, 1) };
        for ch in 0..8 {
            let (p, q) = (out[ch], next[ch]);
            out[ch] = _mm256_add_ps(p, _mm256_mul_ps(f, _mm256_sub_ps(q, p)));
        }
    }
    out
}

/// The skeleton of the composite kernels: pixels `a..=b` of a row, eight at a time, skipping
/// groups that are opaque or whose cells' bricks have no opacity, sampling the volume
/// ([`Sampler8`]), computing each lane's slab exponent (`boundary_factor`) and compositing what
/// `src` returns front to back into the row's channel planes: lane `l` does exactly
/// [`Ctx::composite_one`]'s f32 operations for pixel `x + l`; the classification `src`
/// ([`Source8::src`]) gives the premultiplied colours and the lanes that contribute. Groups go
/// in chunks of four, sampled first and classified after, so that the gathers' cache misses
/// overlap (`docs/BENCHMARKS.md` §15.3: 9–15 % of the frame). Returns the first pixel not done (`b + 1`, or earlier
/// where a group's reads would pass the end of the data, or the last pixels of the row where a
/// group would pass it: those are left to the scalar twin).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn composite_groups_avx2<T: Scalar>(
    ctx: &Ctx<'_, T>,
    walk: &Walk,
    sampler: &Sampler8<T>,
    (a, b): (usize, usize),
    row: &mut RowCtx<'_>,
    (post, src): (Post<'_>, &impl Source8<T>),
    c: &mut Counters,
) -> usize {
    use std::arch::x86_64::*;
    // SAFETY (all intrinsics and calls below): the caller guarantees AVX2; loads and stores
    // are of pixels x..x + 8 ≤ the row's length.
    // One byte per brick, padded so that a 4-byte read at the last brick stays inside.
    let active_bytes = ctx.active_bytes.as_ptr() as *const i32;
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let cutoff = _mm256_set1_ps(ctx.cutoff);
    let d = row.d;
    let two_half = 2.0 * row.half;
    let front = _mm256_set1_ps(d - two_half);
    let back = _mm256_set1_ps(d + two_half);
    let d_minus = _mm256_set1_ps(d - row.half);
    let d_plus = _mm256_set1_ps(d + row.half);
    let two_half_v = _mm256_set1_ps(two_half);
    let persp = ctx.view.perspective;
    let preint = ctx.preint_for(post);
    let this_plane = _mm256_set1_epi32(row.plane as i32);
    let next_stamp = _mm256_set1_epi32(row.plane.wrapping_add(1) as i32);
    let mut x = a;
    // Groups are taken in chunks: first each group of the chunk is tested and sampled, then each
    // is classified and composited. The gathers of a chunk's groups then do not wait on one
    // another's classification, so their cache misses overlap; every pixel still gets exactly
    // the operations of the one-group-at-a-time loop (the groups hold different pixels).
    const CHUNK: usize = 4;
    struct Sampled<P> {
        x: usize,
        ar: __m256,
        live: __m256,
        frac: [__m256; 3],
        u: __m256,
        rho: __m256,
        pre: P,
    }
    let mut chunk: [Option<Sampled<_>>; CHUNK] = std::array::from_fn(|_| None);
    // The last group of the run may be partial: its lanes past `b` are masked (they read
    // clamped cells, valid reads, and store what they loaded).
    loop {
        let mut filled = 0;
        // Set where a group's reads would pass the end of the data: the run stops there.
        let mut stop = None;
        while filled < CHUNK && x <= b && x + 8 <= row.a.len() {
            let n = (b - x + 1).min(8);
            let in_run = first_lanes(n);
            let ar = unsafe { _mm256_loadu_ps(row.a.as_ptr().add(x)) };
            let live = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(ar, cutoff), in_run);
            let live_bits = _mm256_movemask_ps(live);
            if live_bits == 0 {
                c.terminated += n as u64;
                x += 8;
                continue;
            }
            let cells = unsafe { sampler.locate(x) };
            // Lanes whose cell's brick has no opacity under the transfer function contribute
            // nothing: not sampled where a whole group is in such bricks.
            let active = if ctx.skip_empty {
                // (One flag read where the group lies in one brick instead of the gather was
                // measured: no gain on the CT, 5 % slower on Colin27.)
                let brick = unsafe { sampler.bricks_of(&cells) };
                let flags = unsafe { _mm256_i32gather_epi32::<1>(active_bytes, brick) };
                _mm256_castsi256_ps(_mm256_cmpgt_epi32(
                    _mm256_and_si256(flags, _mm256_set1_epi32(0xff)),
                    _mm256_setzero_si256(),
                ))
            } else {
                _mm256_castsi256_ps(_mm256_set1_epi32(-1))
            };
            c.terminated += u64::from(n as u32 - lanes(live_bits));
            let live = _mm256_and_ps(live, active);
            let live_bits = _mm256_movemask_ps(live);
            if live_bits == 0 {
                x += 8;
                continue;
            }
            if unsafe { src.scalar_lanes(&cells, live) } {
                // The scalar twin takes the group's live lanes (the others are counted above or
                // contribute nothing); its pixels are none of the chunk's.
                for l in 0..n {
                    if live_bits >> l & 1 == 1 {
                        ctx.composite_one(walk, x + l, row, post, c);
                    }
                }
                x += 8;
                continue;
            }
            let base = unsafe { sampler.base_of(&cells) };
            let frac = unsafe { cells.fractions() };
            let Some((rho, pre)) = (unsafe { src.sample(&cells, base, frac) }) else {
                stop = Some(x);
                break;
            };
            c.samples += u64::from(lanes(live_bits));
            // Pre-integration: the densities of the plane before where these pixels were sampled
            // there, then this plane's (in the lanes sampled) for the next ([`Ctx::composite_one`]).
            let u = if preint {
                // SAFETY: x + 8 ≤ the row's length, and `prev`, `stamp` are as long as it.
                let pp = unsafe { row.prev.as_mut_ptr().add(x) };
                let sp = unsafe { row.stamp.as_mut_ptr().add(x) } as *mut __m256i;
                let (pv, st) = unsafe { (_mm256_loadu_ps(pp), _mm256_loadu_si256(sp)) };
                let have = _mm256_castsi256_ps(_mm256_cmpeq_epi32(st, this_plane));
                unsafe {
                    _mm256_storeu_ps(pp, _mm256_blendv_ps(pv, rho, live));
                    _mm256_storeu_si256(
                        sp,
                        _mm256_castps_si256(_mm256_blendv_ps(
                            _mm256_castsi256_ps(st),
                            _mm256_castsi256_ps(next_stamp),
                            live,
                        )),
                    );
                }
                _mm256_blendv_ps(rho, pv, have)
            } else {
                rho
            };
            chunk[filled] = Some(Sampled {
                x,
                ar,
                live,
                frac,
                u,
                rho,
                pre,
            });
            filled += 1;
            x += 8;
        }
        for g in chunk.iter_mut().take(filled) {
            let Some(Sampled {
                x,
                ar,
                live,
                frac,
                u,
                rho,
                pre,
            }) = g.take()
            else {
                continue;
            };
            // The slab's exponent (`boundary_factor`, lane by lane).
            let kf = unsafe { _mm256_loadu_ps(row.kf.as_ptr().add(x)) };
            let din = unsafe { _mm256_loadu_ps(row.din.as_ptr().add(x)) };
            let dout = unsafe { _mm256_loadu_ps(row.dout.as_ptr().add(x)) };
            let lo_cut = _mm256_cmp_ps::<_CMP_LT_OQ>(front, din);
            let hi_cut = _mm256_cmp_ps::<_CMP_GT_OQ>(back, dout);
            let cut = _mm256_or_ps(lo_cut, hi_cut);
            let k = if _mm256_movemask_ps(cut) == 0 {
                kf
            } else {
                let l = _mm256_blendv_ps(d_minus, din, lo_cut);
                let h = _mm256_blendv_ps(d_plus, dout, hi_cut);
                let q = _mm256_max_ps(_mm256_div_ps(_mm256_sub_ps(h, l), two_half_v), zero);
                _mm256_blendv_ps(kf, _mm256_mul_ps(kf, q), cut)
            };
            // Lanes that take the path-corrected form.
            let corrected = if persp || preint {
                _mm256_castsi256_ps(_mm256_set1_epi32(-1))
            } else {
                _mm256_cmp_ps::<_CMP_NEQ_UQ>(k, one)
            };
            let (src, contributes) = unsafe { src.src(&pre, frac, u, rho, k, corrected) };
            let mask = _mm256_and_ps(contributes, live);
            let bits = _mm256_movemask_ps(mask);
            if bits != 0 {
                c.visible += u64::from(lanes(bits));
                let tr = _mm256_sub_ps(one, ar);
                let chans: [&mut [f32]; 4] = [&mut *row.r, &mut *row.g, &mut *row.b, &mut *row.a];
                for (ch, plane) in chans.into_iter().enumerate() {
                    let p = unsafe { plane.as_mut_ptr().add(x) };
                    let old = unsafe { _mm256_loadu_ps(p) };
                    // Masked lanes add a zero (of either sign), which leaves every value an
                    // accumulation can hold (never −0) bit for bit, so the store needs no blend
                    // (a blended store compiles to `vmaskmovps`, slow on AMD).
                    let add = _mm256_mul_ps(tr, _mm256_and_ps(src[ch], mask));
                    unsafe { _mm256_storeu_ps(p, _mm256_add_ps(old, add)) };
                }
            }
        }
        if let Some(at) = stop {
            return at;
        }
        if filled == 0 {
            return x;
        }
    }
}

/// Composite of pixels `a..=b` of a row, eight at a time ([`composite_groups_avx2`]), classified
/// unshaded through the post table ([`PostSource`]) or shaded ([`ShadeSource`]).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn composite_run_avx2<T: Scalar>(
    ctx: &Ctx<'_, T>,
    walk: &Walk,
    a: usize,
    b: usize,
    row: &mut RowCtx<'_>,
    post: Post<'_>,
    c: &mut Counters,
) -> usize {
    use std::arch::x86_64::*;
    // SAFETY (all calls): the caller guarantees AVX2.
    let sampler = unsafe { Sampler8::new(ctx, walk) };
    match post {
        Post::Table(t) => unsafe {
            let src = PostSource {
                t,
                sampler: &sampler,
                preint: ctx.preint_for(post),
            };
            composite_groups_avx2(ctx, walk, &sampler, (a, b), row, (post, &src), c)
        },
        // Central differences need a voxel each side of a cell: grids under 4 voxels on an axis
        // have no interior cell, and take the scalar twin.
        Post::Shaded(_) if ctx.dims.iter().any(|&n| n < 4) => a,
        Post::Voxel(t, vs) => {
            let src = VoxelShadeSource {
                t,
                vs,
                sampler: &sampler,
                codes: ctx.codes.as_ptr() as *const i32,
                x_shift: _mm_cvtsi32_si128(16 * ctx.up[0] as i32),
                preint: ctx.preint_for(post),
                back_s: row.back_s.map(|v| _mm256_set1_ps(v)),
                back_st: row.back_st.map(|v| _mm256_set1_ps(v)),
            };
            unsafe { composite_groups_avx2(ctx, walk, &sampler, (a, b), row, (post, &src), c) }
        }
        Post::Shaded(t) => {
            let src = ShadeSource {
                t,
                sampler: &sampler,
                inner_max: ctx.dims.map(|n| _mm256_set1_epi32(n as i32 - 3)),
                safe_base: _mm256_set1_epi32((1 + ctx.stride[1] + ctx.stride[2]) as i32),
            };
            unsafe { composite_groups_avx2(ctx, walk, &sampler, (a, b), row, (post, &src), c) }
        }
    }
}

/// The sampling and classification of a group of eight samples for [`composite_groups_avx2`].
#[cfg(target_arch = "x86_64")]
trait Source8<T> {
    /// What [`Source8::sample`] read that [`Source8::src`] uses again.
    type Pre;

    /// Whether a lane of `live` must take the scalar twin (the kernel cannot read what it
    /// needs there).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    unsafe fn scalar_lanes(&self, cells: &Cells8, live: std::arch::x86_64::__m256) -> bool;

    /// The trilinear samples in `cells` (linear indices `base`, fractions `frac`), as
    /// [`Sampler8::sample_at`] computes them, or `None` where a read would pass the end of the
    /// data.
    ///
    /// # Safety
    /// The CPU must support AVX2; the cells must be the volume's, and no live lane may need
    /// the scalar twin ([`Source8::scalar_lanes`]).
    unsafe fn sample(
        &self,
        cells: &Cells8,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<(std::arch::x86_64::__m256, Self::Pre)>;

    /// The premultiplied colours of the samples `rho` at fractions `frac` with slab exponents
    /// `k`, and the mask of lanes that contribute; `corrected` is the mask of lanes whose
    /// opacity takes the path correction (perspective, `k ≠ 1`, or pre-integration). `u`:
    /// the densities at the pixels' samples on the plane before (`rho` where there are none),
    /// read by the sources that pre-integrate ([`Ctx::preint_for`]).
    ///
    /// # Safety
    /// The CPU must support AVX2; `pre` must come from [`Source8::sample`].
    unsafe fn src(
        &self,
        pre: &Self::Pre,
        frac: [std::arch::x86_64::__m256; 3],
        u: std::arch::x86_64::__m256,
        rho: std::arch::x86_64::__m256,
        k: std::arch::x86_64::__m256,
        corrected: std::arch::x86_64::__m256,
    ) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256);
}

/// Unshaded classification through the post table: lane `l` does exactly [`Ctx::post_src`]'s
/// f32 operations (table lookups with paired rows, the path correction with the same polynomial
/// `exp2`).
#[cfg(target_arch = "x86_64")]
struct PostSource<'a, T> {
    t: &'a PostTable,
    sampler: &'a Sampler8<T>,
    /// Classify the segment from `u` to `rho` ([`post_segment8`]).
    preint: bool,
}

#[cfg(target_arch = "x86_64")]
impl<T: Scalar> Source8<T> for PostSource<'_, T> {
    type Pre = ();

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn scalar_lanes(&self, _: &Cells8, _: std::arch::x86_64::__m256) -> bool {
        false
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample(
        &self,
        _: &Cells8,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<(std::arch::x86_64::__m256, ())> {
        // SAFETY: the caller's guarantees.
        Some((unsafe { self.sampler.sample_at(base, frac) }?, ()))
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn src(
        &self,
        _: &(),
        _: [std::arch::x86_64::__m256; 3],
        u: std::arch::x86_64::__m256,
        rho: std::arch::x86_64::__m256,
        k: std::arch::x86_64::__m256,
        corrected: std::arch::x86_64::__m256,
    ) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        let t = self.t;
        let zero = _mm256_setzero_ps();
        let one = _mm256_set1_ps(1.0);
        if self.preint {
            // Every lane is path-corrected ([`Ctx::post_seg_src`]).
            // SAFETY: the caller guarantees AVX2.
            let v = unsafe { post_segment8(t, u, rho) };
            let l = v[3];
            let ok = _mm256_cmp_ps::<_CMP_LT_OQ>(l, zero);
            let a = _mm256_sub_ps(one, exp2_neg8(_mm256_mul_ps(k, l)));
            let src = [
                _mm256_mul_ps(v[0], a),
                _mm256_mul_ps(v[1], a),
                _mm256_mul_ps(v[2], a),
                a,
            ];
            return (src, ok);
        }
        let pos = table_pos8(rho, t.lo, t.scale, t.last);
        let corrected_bits = _mm256_movemask_ps(corrected);
        let mut src = [zero; 4];
        let mut contributes = _mm256_setzero_ps();
        // SAFETY (interp8): positions are clamped to [0, last], rows of the paired tables.
        if corrected_bits != 0xff {
            let v = unsafe { interp8(&t.pairs, pos, true) };
            src = [v[0], v[1], v[2], v[3]];
            contributes = _mm256_cmp_ps::<_CMP_GT_OQ>(v[3], zero);
        }
        if corrected_bits != 0 {
            let v = unsafe { interp8(&t.persp_pairs, pos, true) };
            let l = v[3];
            let ok = _mm256_cmp_ps::<_CMP_LT_OQ>(l, zero);
            let a = _mm256_sub_ps(one, exp2_neg8(_mm256_mul_ps(k, l)));
            src[0] = _mm256_blendv_ps(src[0], _mm256_mul_ps(v[0], a), corrected);
            src[1] = _mm256_blendv_ps(src[1], _mm256_mul_ps(v[1], a), corrected);
            src[2] = _mm256_blendv_ps(src[2], _mm256_mul_ps(v[2], a), corrected);
            src[3] = _mm256_blendv_ps(src[3], a, corrected);
            contributes = _mm256_blendv_ps(contributes, ok, corrected);
        }
        (src, contributes)
    }
}

/// Shaded classification ([`shade8`]) with the voxels' central differences gathered from the
/// volume itself and interpolated in the sample's cell: lane `l` does exactly
/// [`Ctx::gradient_lerp`]'s and [`shaded_src`]'s f32 operations. A cell's differences read
/// the 4×4×4 block around it without its edges: four rows of four voxels along x through the
/// cell's own four (y, z) corners, and eight rows of two beside them (the rows one before and two
/// after along y and z). So only interior cells (one voxel from every face) are read here;
/// lanes on the faces take the scalar twin, whose differences are one-sided there.
#[cfg(target_arch = "x86_64")]
struct ShadeSource<'a, T> {
    t: &'a ShadeTable,
    sampler: &'a Sampler8<T>,
    /// `n − 3` per axis: the largest interior cell.
    inner_max: [std::arch::x86_64::__m256i; 3],
    /// The linear index of cell (1, 1, 1), read in place of lanes that are not interior (their
    /// results are dropped).
    safe_base: std::arch::x86_64::__m256i,
}

#[cfg(target_arch = "x86_64")]
impl<T: Scalar> ShadeSource<'_, T> {
    /// The mask of lanes whose cell is interior (between 1 and `n − 3` on every axis).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn interior(&self, cells: &Cells8) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_si256();
        let mut m = _mm256_set1_epi32(-1);
        for ax in 0..3 {
            let c = cells.cell[ax];
            let inside = _mm256_andnot_si256(
                _mm256_cmpgt_epi32(c, self.inner_max[ax]),
                _mm256_cmpgt_epi32(c, zero),
            );
            m = _mm256_and_si256(m, inside);
        }
        _mm256_castsi256_ps(m)
    }
}

#[cfg(target_arch = "x86_64")]
impl<T: Scalar> Source8<T> for ShadeSource<'_, T> {
    /// The rows' first voxels (`base` with lanes that are not interior moved to cell
    /// (1, 1, 1)) and `c[j][k]`: voxels x − 1 … x + 2 of row (y + j, z + k).
    type Pre = (
        std::arch::x86_64::__m256i,
        [[[std::arch::x86_64::__m256; 4]; 2]; 2],
    );

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn scalar_lanes(&self, cells: &Cells8, live: std::arch::x86_64::__m256) -> bool {
        use std::arch::x86_64::*;
        _mm256_movemask_ps(_mm256_andnot_ps(self.interior(cells), live)) != 0
    }

    /// The sample from the four central rows (the cell's corners are their voxels x and
    /// x + 1), which the differences read again.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample(
        &self,
        cells: &Cells8,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<(std::arch::x86_64::__m256, Self::Pre)> {
        use std::arch::x86_64::*;
        let base = _mm256_blendv_epi8(
            self.safe_base,
            base,
            _mm256_castps_si256(self.interior(cells)),
        );
        let s = self.sampler;
        let first = _mm256_sub_epi32(base, _mm256_set1_epi32(1));
        let (y1, z1) = (_mm256_add_epi32(first, s.sy), _mm256_add_epi32(first, s.sz));
        // SAFETY: interior cells (or cell (1, 1, 1)): voxels x − 1 … x + 2 of rows y, y + 1 and
        // z, z + 1 lie in the volume.
        let c = unsafe {
            [
                [s.gather4(first), s.gather4(z1)],
                [s.gather4(y1), s.gather4(_mm256_add_epi32(y1, s.sz))],
            ]
        };
        // Sampler8::sample_at's interpolation of the corners (voxels x and x + 1 of each row).
        let c00 = lerp8(c[0][0][1], c[0][0][2], frac[0]);
        let c10 = lerp8(c[1][0][1], c[1][0][2], frac[0]);
        let c01 = lerp8(c[0][1][1], c[0][1][2], frac[0]);
        let c11 = lerp8(c[1][1][1], c[1][1][2], frac[0]);
        let rho = lerp8(lerp8(c00, c10, frac[1]), lerp8(c01, c11, frac[1]), frac[2]);
        Some((rho, (base, c)))
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn src(
        &self,
        pre: &Self::Pre,
        frac: [std::arch::x86_64::__m256; 3],
        _: std::arch::x86_64::__m256,
        rho: std::arch::x86_64::__m256,
        k: std::arch::x86_64::__m256,
        corrected: std::arch::x86_64::__m256,
    ) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        let pos = table_pos8(rho, self.t.lo, self.t.scale, self.t.last);
        // SAFETY: positions are clamped to [0, last], and row last + 1 exists.
        let v = unsafe { interp8(&self.t.rows, pos, false) };
        let (v, a, contributes) = shade_terms8(v, k, corrected);
        if _mm256_movemask_ps(contributes) == 0 {
            return ([_mm256_setzero_ps(); 4], contributes);
        }
        let (base, c) = pre;
        let s = self.sampler;
        let (sy, sz) = (s.sy, s.sz);
        let (ny, nz) = (_mm256_sub_epi32(*base, sy), _mm256_sub_epi32(*base, sz));
        let (y2, z2) = (
            _mm256_add_epi32(*base, _mm256_add_epi32(sy, sy)),
            _mm256_add_epi32(*base, _mm256_add_epi32(sz, sz)),
        );
        // SAFETY: as in `sample`; a 4-byte read starting in these rows ends in the data (the
        // last row read is (y + 2, z + 1) or (y + 1, z + 2), never the grid's last row).
        let (yo, zo) = unsafe {
            (
                // yo[0][k]: row (y − 1, z + k); yo[1][k]: row (y + 2, z + k); voxels x, x + 1.
                [
                    [s.gather2(ny), s.gather2(_mm256_add_epi32(ny, sz))],
                    [s.gather2(y2), s.gather2(_mm256_add_epi32(y2, sz))],
                ],
                // zo[j][0]: row (y + j, z − 1); zo[j][1]: row (y + j, z + 2).
                [
                    [s.gather2(nz), s.gather2(z2)],
                    [
                        s.gather2(_mm256_add_epi32(nz, sy)),
                        s.gather2(_mm256_add_epi32(z2, sy)),
                    ],
                ],
            )
        };
        let half = _mm256_set1_ps(0.5);
        // The differences along each axis at corner (dx, dy, dz), as `Ctx::gradient_lerp`.
        let mut d = [[[[_mm256_setzero_ps(); 2]; 2]; 2]; 3];
        for dy in 0..2 {
            for dz in 0..2 {
                for dx in 0..2 {
                    let r = &c[dy][dz];
                    let (hi_y, lo_y) = if dy == 0 {
                        (c[1][dz][dx + 1], yo[0][dz][dx])
                    } else {
                        (yo[1][dz][dx], c[0][dz][dx + 1])
                    };
                    let (hi_z, lo_z) = if dz == 0 {
                        (c[dy][1][dx + 1], zo[dy][0][dx])
                    } else {
                        (zo[dy][1][dx], c[dy][0][dx + 1])
                    };
                    d[0][dz][dy][dx] = _mm256_mul_ps(_mm256_sub_ps(r[dx + 2], r[dx]), half);
                    d[1][dz][dy][dx] = _mm256_mul_ps(_mm256_sub_ps(hi_y, lo_y), half);
                    d[2][dz][dy][dx] = _mm256_mul_ps(_mm256_sub_ps(hi_z, lo_z), half);
                }
            }
        }
        let mut g = [_mm256_setzero_ps(); 3];
        for (ax, out) in g.iter_mut().enumerate() {
            let e = &d[ax];
            let c00 = lerp8(e[0][0][0], e[0][0][1], frac[0]);
            let c10 = lerp8(e[0][1][0], e[0][1][1], frac[0]);
            let c01 = lerp8(e[1][0][0], e[1][0][1], frac[0]);
            let c11 = lerp8(e[1][1][0], e[1][1][1], frac[0]);
            *out = lerp8(lerp8(c00, c10, frac[1]), lerp8(c01, c11, frac[1]), frac[2]);
        }
        (shade_light8(self.t, &v, a, contributes, g), contributes)
    }
}

/// Shaded composite at the voxels ([`ShadeAt::Voxels`]) for [`composite_groups_avx2`]: the
/// sample as [`Sampler8::sample_at`], the classifier's terms from [`ShadeTable`]
/// ([`shade_terms8`]), the eight corners' direction codes (four 32-bit gathers, two codes
/// each along x), their diffuse and specular light gathered from [`VoxelShading`] and
/// interpolated; lane by lane the f32 operations of [`voxel_shaded_src`]. Every cell can be
/// read (the codes hold the faces' one-sided differences), so no lane needs the scalar twin.
#[cfg(target_arch = "x86_64")]
struct VoxelShadeSource<'a, T> {
    t: &'a ShadeTable,
    vs: &'a VoxelShading,
    sampler: &'a Sampler8<T>,
    /// The codes ([`NormalField::codes`], padded by one code so that a 4-byte read at the
    /// last voxel stays inside).
    codes: *const i32,
    /// Bits from a corner's code to the next one's along x in a 32-bit word: `16·ux`.
    x_shift: std::arch::x86_64::__m128i,
    /// Classify the segment from `u` to `rho` ([`shade_segment8`]) and light it at its middle
    /// ([`VoxelShadeSource::light_cells`]).
    preint: bool,
    /// [`RowCtx::back_s`], [`RowCtx::back_st`] broadcast.
    back_s: [std::arch::x86_64::__m256; 3],
    back_st: [std::arch::x86_64::__m256; 3],
}

#[cfg(target_arch = "x86_64")]
impl<T: Scalar> VoxelShadeSource<'_, T> {
    /// [`Ctx::light_cell`] on eight lanes: the linear indices and fractions of the cells
    /// where the segments are lit, `h` of the way back from the samples at `pos`.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn light_cells(
        &self,
        pos: &[std::arch::x86_64::__m256; 3],
        xf: std::arch::x86_64::__m256,
        h: std::arch::x86_64::__m256,
    ) -> (std::arch::x86_64::__m256i, [std::arch::x86_64::__m256; 3]) {
        use std::arch::x86_64::*;
        let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
        let izero = _mm256_setzero_si256();
        let mut cell = [izero; 3];
        let mut frac = [zero; 3];
        for a in 0..3 {
            let step = _mm256_add_ps(self.back_s[a], _mm256_mul_ps(xf, self.back_st[a]));
            let q = _mm256_add_ps(pos[a], _mm256_mul_ps(h, step));
            cell[a] = _mm256_min_epi32(
                _mm256_max_epi32(_mm256_cvttps_epi32(q), izero),
                self.sampler.maxc[a],
            );
            let d = _mm256_sub_ps(q, _mm256_cvtepi32_ps(cell[a]));
            frac[a] = _mm256_min_ps(_mm256_max_ps(d, zero), one);
        }
        // SAFETY: the caller guarantees AVX2.
        let base = unsafe {
            self.sampler.base_of(&Cells8 {
                cell,
                pos: *pos,
                xf,
            })
        };
        (base, frac)
    }

    /// The diffuse and specular light of plane `p` at the corners' codes `q` (`x` fastest),
    /// interpolated and scaled ([`voxel_shaded_src`]'s operations).
    ///
    /// # Safety
    /// The CPU must support AVX2; every code must be below [`crate::normals::CODES`].
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn light8(
        &self,
        p: usize,
        q: &[std::arch::x86_64::__m256i; 8],
        frac: [std::arch::x86_64::__m256; 3],
    ) -> [std::arch::x86_64::__m256; 2] {
        use std::arch::x86_64::*;
        let plane = self.vs.plane(p).as_ptr() as *const i32;
        let mask = _mm256_set1_epi32(0xffff);
        // SAFETY: codes are u16, and a plane holds CODES = 2^16 words.
        let w: [__m256i; 8] =
            std::array::from_fn(|k| unsafe { _mm256_i32gather_epi32::<4>(plane, q[k]) });
        let tri = |c: [__m256; 8]| {
            let c00 = lerp8(c[0], c[1], frac[0]);
            let c10 = lerp8(c[2], c[3], frac[0]);
            let c01 = lerp8(c[4], c[5], frac[0]);
            let c11 = lerp8(c[6], c[7], frac[0]);
            lerp8(lerp8(c00, c10, frac[1]), lerp8(c01, c11, frac[1]), frac[2])
        };
        let d = tri(w.map(|w| _mm256_cvtepi32_ps(_mm256_and_si256(w, mask))));
        let s = tri(w.map(|w| _mm256_cvtepi32_ps(_mm256_srli_epi32::<16>(w))));
        let [sd, ss] = self.vs.scale[p];
        [
            _mm256_mul_ps(d, _mm256_set1_ps(sd)),
            _mm256_mul_ps(s, _mm256_set1_ps(ss)),
        ]
    }
}

#[cfg(target_arch = "x86_64")]
impl<T: Scalar> Source8<T> for VoxelShadeSource<'_, T> {
    /// The cells' linear indices, the samples' positions and the pixel columns.
    type Pre = (
        std::arch::x86_64::__m256i,
        [std::arch::x86_64::__m256; 3],
        std::arch::x86_64::__m256,
    );

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn scalar_lanes(&self, _: &Cells8, _: std::arch::x86_64::__m256) -> bool {
        false
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample(
        &self,
        cells: &Cells8,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<(std::arch::x86_64::__m256, Self::Pre)> {
        // SAFETY: the caller's guarantees are sample_at's.
        unsafe { self.sampler.sample_at(base, frac) }.map(|rho| (rho, (base, cells.pos, cells.xf)))
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn src(
        &self,
        pre: &Self::Pre,
        frac: [std::arch::x86_64::__m256; 3],
        u: std::arch::x86_64::__m256,
        rho: std::arch::x86_64::__m256,
        k: std::arch::x86_64::__m256,
        corrected: std::arch::x86_64::__m256,
    ) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        // SAFETY (both): the caller guarantees AVX2; positions are clamped to [0, last], and
        // row last + 1 exists.
        let v = if self.preint {
            unsafe { shade_segment8(self.t, u, rho) }
        } else {
            let pos = table_pos8(rho, self.t.lo, self.t.scale, self.t.last);
            unsafe { interp8(&self.t.rows, pos, false) }
        };
        let (v, a, contributes) = shade_terms8(v, k, corrected);
        if _mm256_movemask_ps(contributes) == 0 {
            return ([_mm256_setzero_ps(); 4], contributes);
        }
        let mut col = [v[1], v[2], v[3]];
        let (diffuse, specular, _) = self.t.switches();
        if diffuse || specular {
            let (base, frac) = if self.preint {
                // Lanes that contribute and whose segment is not one value (`SEGMENT_LIGHT_AT`).
                let mid = _mm256_and_ps(_mm256_cmp_ps::<_CMP_NEQ_UQ>(u, rho), contributes);
                let h = _mm256_and_ps(_mm256_set1_ps(SEGMENT_LIGHT_AT), mid);
                // SAFETY: the caller guarantees AVX2.
                unsafe { self.light_cells(&pre.1, pre.2, h) }
            } else {
                (pre.0, frac)
            };
            let base = &base;
            let o = self.sampler.offs;
            let mask = _mm256_set1_epi32(0xffff);
            let mut q = [_mm256_setzero_si256(); 8];
            for pair in 0..4 {
                let idx = _mm256_add_epi32(*base, _mm256_set1_epi32(o[2 * pair]));
                // SAFETY: `idx` is a voxel of the volume (cells are clamped to the grid), and
                // the codes hold one more u16 than the volume has voxels.
                let w = unsafe { _mm256_i32gather_epi32::<2>(self.codes, idx) };
                q[2 * pair] = _mm256_and_si256(w, mask);
                q[2 * pair + 1] = _mm256_and_si256(_mm256_srl_epi32(w, self.x_shift), mask);
            }
            // SAFETY (light8): codes are u16.
            let l = if self.vs.chromatic {
                [0, 1, 2].map(|p| unsafe { self.light8(p, &q, frac) })
            } else {
                [unsafe { self.light8(0, &q, frac) }; 3]
            };
            if diffuse {
                for ch in 0..3 {
                    col[ch] = _mm256_add_ps(col[ch], _mm256_mul_ps(v[4 + ch], l[ch][0]));
                }
            }
            if specular {
                for ch in 0..3 {
                    let sc = match self.t.spec_color {
                        Some(c) => _mm256_set1_ps(c[ch]),
                        None => v[4 + ch],
                    };
                    col[ch] = _mm256_add_ps(col[ch], _mm256_mul_ps(sc, l[ch][1]));
                }
            }
        }
        (premultiplied8(col, a), contributes)
    }
}

/// `(p₀q₀ + p₁q₁) + p₂q₂` on eight lanes (the order of the scalar twins' dot products).
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn dot8(
    p: [std::arch::x86_64::__m256; 3],
    q: [std::arch::x86_64::__m256; 3],
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_add_ps(
        _mm256_add_ps(_mm256_mul_ps(p[0], q[0]), _mm256_mul_ps(p[1], q[1])),
        _mm256_mul_ps(p[2], q[2]),
    )
}

/// `v` broadcast to eight lanes per component.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn splat3(v: [f32; 3]) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::*;
    [
        _mm256_set1_ps(v[0]),
        _mm256_set1_ps(v[1]),
        _mm256_set1_ps(v[2]),
    ]
}

/// A table position on eight lanes, `min(max((ρ − lo)·scale, 0), last)` (NaN → 0), as the
/// scalar lookups compute it ([`PostTable::lookup_in`], [`ShadeTable::entry`]).
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn table_pos8(
    rho: std::arch::x86_64::__m256,
    lo: f32,
    scale: f32,
    last: f32,
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let t = _mm256_mul_ps(
        _mm256_sub_ps(rho, _mm256_set1_ps(lo)),
        _mm256_set1_ps(scale),
    );
    _mm256_min_ps(_mm256_max_ps(t, _mm256_setzero_ps()), _mm256_set1_ps(last))
}

/// `p + f·(q − p)` on eight lanes ([`lerp`]).
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn lerp8(
    p: std::arch::x86_64::__m256,
    q: std::arch::x86_64::__m256,
    f: std::arch::x86_64::__m256,
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_add_ps(p, _mm256_mul_ps(f, _mm256_sub_ps(q, p)))
}

/// Which lanes of a segment from table position `tu` to `tv` take the middle entry (shorter
/// than [`SEGMENT_MIN_ENTRIES`]), the middle position, and `tv − tu`.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn segment_split8(
    tu: std::arch::x86_64::__m256,
    tv: std::arch::x86_64::__m256,
) -> (
    std::arch::x86_64::__m256,
    std::arch::x86_64::__m256,
    std::arch::x86_64::__m256,
) {
    use std::arch::x86_64::*;
    let dt = _mm256_sub_ps(tv, tu);
    let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), dt);
    let short = _mm256_cmp_ps::<_CMP_LT_OQ>(abs, _mm256_set1_ps(SEGMENT_MIN_ENTRIES));
    let mid = _mm256_mul_ps(_mm256_add_ps(tu, tv), _mm256_set1_ps(0.5));
    (short, mid, dt)
}

/// [`segment_average`] on eight lanes: the same f32 operations, the branch as a blend;
/// `mid_rows` and `integ` are the table's entry rows and integral rows, `paired` as
/// [`interp8`] reads them.
///
/// # Safety
/// The CPU must support AVX2; for every position in `[0, last]` the rows [`interp8`] reads must
/// exist in both tables.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn segment_average8<const N: usize, const W: usize, const L: usize>(
    (lo, scale, last): (f32, f32, f32),
    u: std::arch::x86_64::__m256,
    v: std::arch::x86_64::__m256,
    mid_rows: &[[f32; 8]],
    integ: &[[f32; 8]],
    paired: bool,
) -> [std::arch::x86_64::__m256; N] {
    use std::arch::x86_64::*;
    let (w, l) = (W, L);
    let tu = table_pos8(u, lo, scale, last);
    let tv = table_pos8(v, lo, scale, last);
    let (short, mid, dt) = segment_split8(tu, tv);
    let bits = _mm256_movemask_ps(short);
    let zero = _mm256_setzero_ps();
    let mut out = [zero; N];
    // SAFETY (interp8): the caller's guarantee.
    if bits != 0 {
        let m = unsafe { interp8(mid_rows, mid, paired) };
        out = std::array::from_fn(|c| m[c]);
    }
    if bits != 0xff {
        let a = unsafe { interp8(integ, tu, paired) };
        let b = unsafe { interp8(integ, tv, paired) };
        let dl = _mm256_sub_ps(b[w], a[w]);
        let inv = _mm256_div_ps(_mm256_set1_ps(1.0), dl);
        for (c, o) in out.iter_mut().enumerate() {
            let seg = if c == l {
                _mm256_div_ps(dl, dt)
            } else if c == w {
                zero
            } else {
                _mm256_mul_ps(_mm256_sub_ps(b[c], a[c]), inv)
            };
            *o = _mm256_blendv_ps(seg, *o, short);
        }
    }
    out
}

/// [`PostTable::segment`] on eight lanes ([`segment_average8`]).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn post_segment8(
    t: &PostTable,
    u: std::arch::x86_64::__m256,
    v: std::arch::x86_64::__m256,
) -> [std::arch::x86_64::__m256; 4] {
    // SAFETY: the paired tables have a row per position in [0, last].
    unsafe {
        segment_average8::<4, 3, 3>(
            (t.lo, t.scale, t.last),
            u,
            v,
            &t.persp_pairs,
            &t.integ_pairs,
            true,
        )
    }
}

/// [`ShadeTable::segment_entry`] on eight lanes ([`segment_average8`]).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn shade_segment8(
    t: &ShadeTable,
    u: std::arch::x86_64::__m256,
    v: std::arch::x86_64::__m256,
) -> [std::arch::x86_64::__m256; 8] {
    // SAFETY: both tables repeat their last row, so row last + 1 exists.
    unsafe { segment_average8::<8, 0, 7>((t.lo, t.scale, t.last), u, v, &t.rows, &t.integ, false) }
}

/// The first half of [`shaded_src`] on eight lanes, from the table's entries `v` (at the
/// samples, or of the segments, [`shade_segment8`]): the opacity (path-corrected in the
/// `corrected` lanes) and the mask of lanes that contribute.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn shade_terms8(
    v: [std::arch::x86_64::__m256; 8],
    k: std::arch::x86_64::__m256,
    corrected: std::arch::x86_64::__m256,
) -> (
    [std::arch::x86_64::__m256; 8],
    std::arch::x86_64::__m256,
    std::arch::x86_64::__m256,
) {
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let corrected_bits = _mm256_movemask_ps(corrected);
    let mut a = v[0];
    let mut contributes = _mm256_cmp_ps::<_CMP_GT_OQ>(v[0], zero);
    if corrected_bits != 0 {
        let ac = _mm256_sub_ps(one, exp2_neg8(_mm256_mul_ps(k, v[7])));
        a = _mm256_blendv_ps(a, ac, corrected);
        let ok = _mm256_cmp_ps::<_CMP_LT_OQ>(v[7], zero);
        contributes = _mm256_blendv_ps(contributes, ok, corrected);
    }
    (v, a, contributes)
}

/// The second half of [`shaded_src`] on eight lanes (the conditions as masks): the
/// premultiplied colours from the entries `v` and opacity `a` of [`shade_terms8`] and the
/// interpolated index-space gradients `g`.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn shade_light8(
    t: &ShadeTable,
    v: &[std::arch::x86_64::__m256; 8],
    a: std::arch::x86_64::__m256,
    contributes: std::arch::x86_64::__m256,
    g: [std::arch::x86_64::__m256; 3],
) -> [std::arch::x86_64::__m256; 4] {
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let [m0, m1, m2] = t.to_world;
    let (m0, m1, m2) = (splat3(m0), splat3(m1), splat3(m2));
    // World gradient, component i: (m0ᵢ·g₀ + m1ᵢ·g₁) + m2ᵢ·g₂.
    let gw = [
        dot8([m0[0], m1[0], m2[0]], g),
        dot8([m0[1], m1[1], m2[1]], g),
        dot8([m0[2], m1[2], m2[2]], g),
    ];
    let g2 = dot8(gw, gw);
    let mut col = [v[1], v[2], v[3]];
    let lit = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(g2, zero), contributes);
    if (t.diffuse || t.specular) && _mm256_movemask_ps(lit) != 0 {
        let inv = _mm256_div_ps(one, _mm256_sqrt_ps(g2));
        let n = [
            _mm256_mul_ps(gw[0], inv),
            _mm256_mul_ps(gw[1], inv),
            _mm256_mul_ps(gw[2], inv),
        ];
        let sign = _mm256_set1_ps(-0.0);
        let spec_max = _mm256_set1_ps(ShadeTable::SPEC as f32);
        for light in &t.lights {
            let lc = splat3(light.color.to_array());
            let mut ndl = dot8(n, splat3(light.l.to_array()));
            let mut ndh = dot8(n, splat3(light.h.to_array()));
            if t.two_sided {
                let flip = _mm256_cmp_ps::<_CMP_LT_OQ>(ndl, zero);
                ndl = _mm256_blendv_ps(ndl, _mm256_xor_ps(ndl, sign), flip);
                ndh = _mm256_blendv_ps(ndh, _mm256_xor_ps(ndh, sign), flip);
            }
            let dm = _mm256_and_ps(lit, _mm256_cmp_ps::<_CMP_GT_OQ>(ndl, zero));
            if _mm256_movemask_ps(dm) == 0 {
                continue;
            }
            if t.diffuse {
                for ch in 0..3 {
                    let term = _mm256_mul_ps(_mm256_mul_ps(v[4 + ch], lc[ch]), ndl);
                    col[ch] = _mm256_add_ps(col[ch], _mm256_and_ps(term, dm));
                }
            }
            let sm = _mm256_and_ps(dm, _mm256_cmp_ps::<_CMP_GT_OQ>(ndh, zero));
            if t.specular && _mm256_movemask_ps(sm) != 0 {
                // ShadeTable::spec, lane by lane (masked lanes clamp to a valid entry and are
                // dropped by the mask).
                let s = _mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(ndh, spec_max), zero), spec_max);
                let i = _mm256_cvttps_epi32(s);
                let f = _mm256_sub_ps(s, _mm256_cvtepi32_ps(i));
                let tab = t.spec_pow.as_ptr();
                // SAFETY: i ∈ [0, SPEC], and spec_pow has SPEC + 2 entries.
                let (p0, p1) = unsafe {
                    (
                        _mm256_i32gather_ps::<4>(tab, i),
                        _mm256_i32gather_ps::<4>(tab.add(1), i),
                    )
                };
                let p = _mm256_add_ps(p0, _mm256_mul_ps(f, _mm256_sub_ps(p1, p0)));
                for ch in 0..3 {
                    let sc = match t.spec_color {
                        Some(c) => _mm256_set1_ps(c[ch]),
                        None => v[4 + ch],
                    };
                    let term = _mm256_mul_ps(_mm256_mul_ps(sc, lc[ch]), p);
                    col[ch] = _mm256_add_ps(col[ch], _mm256_and_ps(term, sm));
                }
            }
        }
    }
    premultiplied8(col, a)
}

/// The shaded colour `col` clamped to [0, 1] and multiplied by the opacity `a`, on eight lanes
/// ([`premultiplied`]'s operations).
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn premultiplied8(
    col: [std::arch::x86_64::__m256; 3],
    a: std::arch::x86_64::__m256,
) -> [std::arch::x86_64::__m256; 4] {
    use std::arch::x86_64::*;
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    let c = col.map(|c| _mm256_mul_ps(_mm256_min_ps(_mm256_max_ps(c, zero), one), a));
    [c[0], c[1], c[2], a]
}

/// MIP (`mip`) or MinIP over pixels `lo..=hi` of a row, eight at a time: each lane's cell is
/// located first, and a group none of whose pixels its cells' bricks can beat (a brick's maximum
/// (minimum) no larger (smaller) than the pixel's extreme) is not sampled; the others are
/// sampled ([`Sampler8`]) and each open lane keeps the larger (smaller) value, as
/// [`Ctx::extreme_one`] does (a NaN pixel, not yet reached, takes the sample). Returns the first
/// pixel not done (`hi + 1`, or the last pixels of the row where a group would pass it).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn extreme_row_avx2<T: Scalar>(
    ctx: &Ctx<'_, T>,
    walk: &Walk,
    lo: usize,
    hi: usize,
    row: &mut [f32],
    mip: bool,
    c: &mut Counters,
) -> usize {
    use std::arch::x86_64::*;
    // SAFETY (all intrinsics and calls below): the caller guarantees AVX2; loads and stores
    // are of pixels x..x + 8 ≤ the row's length; brick indices come from cells clamped to the
    // grid, so they index `extreme_bounds`.
    let sampler = unsafe { Sampler8::new(ctx, walk) };
    let bounds = ctx.extreme_bounds.as_ptr();
    let mut x = lo;
    // As in `composite_groups_avx2`: a chunk of groups is tested and sampled, then compared, so
    // that the gathers' cache misses overlap; each pixel gets the same operations.
    const CHUNK: usize = 4;
    let mut chunk = [(
        0usize,
        _mm256_setzero_ps(),
        _mm256_setzero_ps(),
        _mm256_setzero_ps(),
    ); CHUNK];
    loop {
        let mut filled = 0;
        let mut stop = false;
        while filled < CHUNK && x <= hi && x + 8 <= row.len() {
            let in_row = first_lanes((hi - x + 1).min(8));
            let cur = unsafe { _mm256_loadu_ps(row.as_ptr().add(x)) };
            let cells = unsafe { sampler.locate(x) };
            let brick = unsafe { sampler.bricks_of(&cells) };
            let bound = unsafe { _mm256_i32gather_ps::<4>(bounds, brick) };
            let unset = _mm256_and_ps(_mm256_cmp_ps::<_CMP_UNORD_Q>(cur, cur), in_row);
            let open = _mm256_and_ps(
                if mip {
                    _mm256_cmp_ps::<_CMP_LT_OQ>(cur, bound)
                } else {
                    _mm256_cmp_ps::<_CMP_GT_OQ>(cur, bound)
                },
                in_row,
            );
            let todo = _mm256_movemask_ps(_mm256_or_ps(unset, open));
            if todo == 0 {
                x += 8;
                continue;
            }
            let Some(v) = (unsafe { sampler.sample(&cells) }) else {
                stop = true;
                break;
            };
            c.samples += u64::from(lanes(todo));
            chunk[filled] = (x, cur, v, _mm256_or_ps(unset, open));
            // `unset` is kept apart from `open` below through `cur` (NaN where unset).
            filled += 1;
            x += 8;
        }
        for &(gx, cur, v, todo) in &chunk[..filled] {
            let better = if mip {
                _mm256_cmp_ps::<_CMP_GT_OQ>(v, cur)
            } else {
                _mm256_cmp_ps::<_CMP_LT_OQ>(v, cur)
            };
            // Lanes whose brick cannot beat them keep their value even where rounding put a
            // sample an ulp beyond the brick's range: the scalar twin does not sample them.
            // An unset lane (NaN) is in `todo` and takes the sample; a set lane in `todo` is
            // open and takes it where it is better.
            let unset = _mm256_cmp_ps::<_CMP_UNORD_Q>(cur, cur);
            let take = _mm256_and_ps(todo, _mm256_or_ps(unset, better));
            let p = unsafe { row.as_mut_ptr().add(gx) };
            unsafe { _mm256_storeu_ps(p, _mm256_blendv_ps(cur, v, take)) };
        }
        if stop || filled == 0 {
            return x;
        }
    }
}

/// A mask of the first `n` (≤ 8) of eight lanes: the pixels of a partial last group that belong
/// to the run.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn first_lanes(n: usize) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_castsi256_ps(_mm256_cmpgt_epi32(
        _mm256_set1_epi32(n as i32),
        _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
    ))
}

/// The number of lanes set in an 8-lane `movemask`: a table, as `popcnt` is not part of AVX2
/// (and not detected here).
#[inline(always)]
fn lanes(bits: i32) -> u32 {
    const POP: [u8; 256] = {
        let mut t = [0u8; 256];
        let mut i = 0;
        while i < 256 {
            t[i] = (i as u32).count_ones() as u8;
            i += 1;
        }
        t
    };
    u32::from(POP[(bits & 0xff) as usize])
}

/// [`exp2_neg`] on eight lanes, with the same operations in the same order.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn exp2_neg8(z: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let bad = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_UNORD_Q>(z, z),
        _mm256_cmp_ps::<_CMP_LT_OQ>(z, _mm256_set1_ps(-126.0)),
    );
    let i = _mm256_cvttps_epi32(z);
    let f = _mm256_add_ps(_mm256_sub_ps(z, _mm256_cvtepi32_ps(i)), _mm256_set1_ps(0.5));
    let c = |v: f32| _mm256_set1_ps(v);
    let mut p = _mm256_mul_ps(f, c(0.000_154_04));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(0.001_333_36), p));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(0.009_618_13), p));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(0.055_504_1), p));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(0.240_226_5), p));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(std::f32::consts::LN_2), p));
    p = _mm256_add_ps(c(1.0), p);
    let pow = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(_mm256_add_epi32(
        i,
        _mm256_set1_epi32(127),
    )));
    let r = _mm256_mul_ps(_mm256_mul_ps(pow, p), c(std::f32::consts::FRAC_1_SQRT_2));
    _mm256_andnot_ps(bad, r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The libm-free roundings give libm's integers for every kind of input: halves either
    /// side of zero, fractions just beside them, the ends of the fast path, huge and
    /// non-finite values.
    #[test]
    fn roundings_without_libm_match_libm() {
        let mut xs = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            4.4e15 + 0.5,
            -4.4e15 - 0.5,
            4.5e15,
            9.3e18,
            -9.3e18,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..100_000 {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let m = (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            let e = (seed & 63) as i32 - 10;
            xs.push(m * 2f64.powi(e));
            xs.push((m * 1e6).round() * 0.5);
        }
        for x in xs {
            assert_eq!(round_i64(x), x.round() as i64, "round {x}");
            assert_eq!(ceil_f64(x) as i64, x.ceil() as i64, "ceil {x}");
            assert_eq!(floor_f64(x) as i64, x.floor() as i64, "floor {x}");
            assert_eq!(ceil_f64(x).is_nan(), x.is_nan());
            if x.is_finite() {
                assert_eq!(ceil_f64(x), x.ceil(), "ceil {x}");
                assert_eq!(floor_f64(x), x.floor(), "floor {x}");
            }
        }
    }

    #[test]
    fn div_floor_is_exact() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..200_000 {
            let n = (next() >> (20 + next() % 40)) as i64;
            let d = ((next() >> (24 + next() % 38)) as i64).max(1);
            assert_eq!(div_floor(n, d, 1.0 / d as f64), n / d, "{n} / {d}");
        }
        for (n, d) in [(0, 1), (7, 7), (1 << 45, 3), ((1 << 45) - 1, 1 << 20)] {
            assert_eq!(div_floor(n, d, 1.0 / d as f64), n / d);
        }
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

    /// A post table over `[0, n − 1]` (one entry per data unit) from `persp` entries.
    fn post_table(persp: Vec<Rgba>) -> PostTable {
        let n = persp.len();
        let (scale, last) = table_steps(0.0, (n - 1) as f32, n);
        let integ = integral_rows(&persp, 3);
        PostTable {
            pairs: Vec::new(),
            persp_pairs: Vec::new(),
            integ_pairs: Vec::new(),
            values: Vec::new(),
            persp,
            integ,
            lo: 0.0,
            scale,
            last,
        }
    }

    /// [`PostTable::segment`] against the averages of the interpolated table computed by brute
    /// force (10⁵ points per segment): `L̄` the mean of `L`, `c̄` the `L`-weighted mean colour, for
    /// segments up and down the table across a sharp ramp and a colour step, and the middle
    /// entry for segments shorter than one entry (one point where `u = v`).
    #[test]
    fn segments_average_the_table() {
        let n = 64;
        let persp: Vec<Rgba> = (0..n)
            .map(|i| {
                let l = match i {
                    0..20 => 0.0,
                    20..24 => -0.75 * (i - 19) as f32,
                    _ => -3.0 - 0.01 * i as f32,
                };
                let c = if i < 30 {
                    [0.9, 0.2, 0.1]
                } else {
                    [0.3, 0.6, 1.0]
                };
                [c[0], c[1], c[2], l]
            })
            .collect();
        let t = post_table(persp);
        let brute = |u: f32, v: f32| -> Rgba {
            let m = 100_000;
            let (mut sl, mut sc) = (0.0f64, [0.0f64; 3]);
            for k in 0..m {
                let x = u + (v - u) * (k as f32 + 0.5) / m as f32;
                let e = t.lookup_in(&t.persp, x);
                sl += f64::from(e[3]);
                for c in 0..3 {
                    sc[c] += f64::from(e[c]) * f64::from(e[3]);
                }
            }
            let c = sc.map(|c| if sl != 0.0 { (c / sl) as f32 } else { 0.0 });
            [c[0], c[1], c[2], (sl / m as f64) as f32]
        };
        for (u, v) in [
            (10.0, 30.0),
            (30.0, 10.0),
            (18.3, 24.9),
            (21.2, 22.7),
            (0.0, 63.0),
            (25.5, 40.25),
        ] {
            let (s, b) = (t.segment(u, v), brute(u, v));
            for c in 0..4 {
                assert!(
                    (s[c] - b[c]).abs() < 0.01 * b[3].abs().max(0.1),
                    "segment {u}..{v}, channel {c}: {} vs {}",
                    s[c],
                    b[c]
                );
            }
        }
        // Shorter than one entry: the middle entry, exactly; one value: that entry.
        assert_eq!(t.segment(21.2, 21.9), t.lookup_in(&t.persp, 21.55));
        assert_eq!(t.segment(22.5, 22.5), t.lookup_in(&t.persp, 22.5));
        // No opacity over the segment: L̄ = 0 (colours 0/0, NaN), which contributes nothing.
        assert_eq!(t.segment(3.0, 12.0)[3], 0.0);
        assert!(Ctx::<f32>::post_seg_src(t.segment(3.0, 12.0), 1.0).is_none());
    }

    /// The area weights of the fractional anti-aliasing: every coarse pixel inside the fine
    /// image gets weights summing to 1, each the overlap of a fine pixel with it; a whole
    /// factor gives `ss` equal weights.
    #[test]
    fn area_weights_cover_each_pixel_once() {
        for (n, ss) in [(7usize, 1.26f64), (50, 1.037), (33, 1.49), (16, 2.0)] {
            let fine = (n as f64 * ss - 1e-9).ceil() as usize;
            let step = n as f64 / fine as f64;
            for offset in [0.0, 0.5 * (fine as f64 * step - n as f64), 0.3 * step] {
                for (x, (first, w)) in area_weights(n, fine, step, offset).iter().enumerate() {
                    let sum: f32 = w.iter().sum();
                    let covered = (x as f64 + 1.0 + offset) <= fine as f64 * step + 1e-9;
                    if covered {
                        assert!((sum - 1.0).abs() < 1e-5, "n {n} ss {ss} x {x}: {sum}");
                    }
                    for (k, &wk) in w.iter().enumerate() {
                        let i = (first + k) as f64;
                        let (a, b) = (i * step - offset, (i + 1.0) * step - offset);
                        let exact = (b.min(x as f64 + 1.0) - a.max(x as f64)).max(0.0);
                        assert!((f64::from(wk) - exact).abs() < 1e-6);
                    }
                }
            }
        }
        let w = area_weights(4, 8, 0.5, 0.0);
        assert!(
            w.iter()
                .enumerate()
                .all(|(x, (f, k))| *f == 2 * x && k == &[0.5, 0.5])
        );
    }

    #[test]
    fn ring_risk_scales_with_the_steepest_step() {
        // 0 → 0.5 over 5 entries of 0.1 data unit each, data range 40: 0.1/entry · 10
        // entries/unit · 10 = 10.
        let alphas = [0.0, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.5];
        assert!((ring_risk(&alphas, 10.0, 40.0) - 10.0).abs() < 1e-4);
        assert_eq!(ring_risk(&[0.3; 16], 10.0, 40.0), 0.0);
        assert_eq!(ring_risk(&[], 10.0, 40.0), 0.0);
        assert_eq!(ring_risk(&alphas, 10.0, f32::INFINITY), 0.0);
    }

    #[test]
    fn fast_log2_and_exp2_are_accurate() {
        let mut worst_log = 0.0f64;
        let mut worst_exp = 0.0f64;
        for n in 1..=100_000 {
            let y = n as f32 / 100_000.0;
            let e = (log2_unit(y) as f64 - (y as f64).log2()).abs();
            worst_log = worst_log.max(e);
            let z = -(n as f32) / 2_000.0; // down to −50
            let exact = (z as f64).exp2();
            let r = (exp2_neg(z) as f64 - exact).abs() / exact;
            worst_exp = worst_exp.max(r);
        }
        assert!(worst_log < 3e-6, "log2 error {worst_log}");
        assert!(worst_exp < 5e-7, "exp2 relative error {worst_exp}");
        assert!((exp2_neg(0.0) - 1.0).abs() < 1e-6);
        assert_eq!(exp2_neg(-200.0), 0.0);
        assert_eq!(exp2_neg(f32::NAN), 0.0);
    }
}
