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
//! central differences (their "gradient splats", gathered at the sample; `Ctx::gradient_at`);
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
//! the bits do not depend on the CPU or the thread count): `Sampler8` locates the eight cells
//! and gathers their corners; unshaded composite classifies through a 1024-entry table and
//! composites into channel planes in the same pass (`composite_run_avx2` with
//! `PostSource`); shaded composite does the same with a table of the classifier's terms before
//! shading (`ShadeTable`), the cell's central differences gathered from the volume (the 4×4×4
//! block around the cell without its edges: twelve row reads, four of which also give the
//! sample) and the lights evaluated as masks (`ShadeSource`, `shade_light8`; cells on the
//! faces of the grid, whose differences are one-sided, take the scalar twin inside the same
//! rows); shaded at the voxels ([`ShadeAt::Voxels`], VTK's order, `crate::normals`), it reads
//! the cell's eight direction codes (four gathers, two codes per word) and their diffuse and
//! specular light from the frame's table (one gather per corner: two 16-bit halves per word)
//! and interpolates the light instead (`VoxelShadeSource`; every cell, faces included);
//! MIP/MinIP compare against one plane of values (`extreme_row_avx2`). Each group of
//! eight is first tested against its own cells' bricks, and skipped where none can contribute.
//! Tables that depend on more than the density (gradient-magnitude or depth indexing, a
//! modulation that is not a constant) take the per-sample classifier (`Ctx::band_plain`).
//!
//! # Code layout
//!
//! [`render_slabs`] checks the settings, places the planes and builds the tables; then:
//!
//! - `view`: the frame's rays in the volume's index space (`View`), walked per row of a plane
//!   in 32.32 fixed point (`Walk`);
//! - `march`: the march through the planes, band by band of the image, with the per-pixel
//!   code (`Ctx`) that is the scalar twin of every AVX2 kernel;
//! - `path`: each ray's path through a slab (the perspective path factor, the entry and exit
//!   depths that shorten its first and last slab);
//! - `tables`: the classification tables (`PostTable`, `ShadeTable`), their pre-integration
//!   and [`ring_risk`];
//! - `shade`: shading a sample (at the sample, `shaded_src`, or at the voxels) and the
//!   gradients of the reconstruction;
//! - `math`: the libm-free `log2` and `exp2` and the trilinear interpolation the twins share;
//! - `avx2` (x86-64 only): the kernels eight pixels at a time, each naming its scalar twin;
//! - `supersample`: the anti-aliasing of minified views ([`WHOLE_RAYS_FROM`]).

mod march;
mod math;
mod path;
mod shade;
mod supersample;
mod tables;
mod view;

#[cfg(target_arch = "x86_64")]
mod avx2;

pub(crate) use shade::shaded_src;
pub use supersample::WHOLE_RAYS_FROM;
pub(crate) use tables::ShadeTable;
pub use tables::{RING_RISK, ring_risk};

use crate::bricks::BrickGrid;
use crate::error::{Result, SplatError};
use crate::normals::{NormalField, ShadeAt, VoxelShading};
use crate::render::{
    Preintegrate, Progress, RenderMode, RenderSettings, RenderStats, Rendered, finish, ms, validate,
};
use march::{Counters, Ctx};
use rayon::prelude::*;
use std::time::Instant;
use supersample::{render_supersampled, supersampling};
use tables::PostTable;
use view::{View, drawn_geometry};
use volsplat_core::glam::DVec3;
use volsplat_core::image::Rgba;
use volsplat_core::{
    AnyVolume, Camera, CrioTables, FrameClassifier, Projection, Scalar, Volume, with_volume,
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
    let grid = volume.grid();
    check_settings(settings, grid.dims)?;
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
            (Some(t), _) => (t.values.iter().map(|v| v[3]).collect(), t.axis.scale),
            (None, Some(t)) => (t.rows.iter().map(|r| r[0]).collect(), t.axis.scale),
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
        (Some(t), _) if !preint => Some(bricks.active_in_table(&t.nonzero(), |x| t.axis.pos(x))),
        (None, Some(t)) if !preint || voxel_shading.is_none() => {
            Some(bricks.active_in_table(&t.nonzero(), |x| t.axis.pos(x)))
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

/// The settings [`render_slabs`] cannot draw, for a volume of `dims` voxels: those
/// [`validate`] refuses, X-ray, subsampling, back-to-front order, a slab thickness outside
/// `[0.01, 16]` and an empty volume.
fn check_settings(settings: &RenderSettings, dims: [usize; 3]) -> Result<()> {
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
    if dims.contains(&0) {
        return Err(SplatError::Setting {
            name: "volume",
            value: format!("{dims:?}"),
            expected: "at least one voxel per axis",
        });
    }
    Ok(())
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
