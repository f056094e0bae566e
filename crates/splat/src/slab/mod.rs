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
//! # Speed (issue 12; decision 0016; measured in `docs/BENCHMARKS.md` §13, §15.3 and §18.5)
//!
//! Rows of a plane are processed eight pixels at a time where the CPU has AVX2 (runtime
//! detection; every kernel has a scalar twin doing the same f32 operations in the same order, so
//! the bits do not depend on the CPU or the thread count): `Sampler8` locates the eight cells
//! and gathers their corners; unshaded composite classifies through a 1024-entry table and
//! composites into channel planes in the same pass (`composite_run_avx2` with
//! `PostSource`); shaded composite does the same with a table of the classifier's terms before
//! shading (`ShadeTable`), the cell's central differences gathered from the volume (the 4×4×4
//! block around the cell without its edges: twelve row reads, four of which also give the
//! sample) and the lights evaluated as masks (`ShadeSource`, `shade_light8`; on the faces of
//! the grid the one-sided differences come from the cell's own rows, and only the cells by the
//! data's two ends take the scalar twin inside the same rows); shaded at the voxels ([`ShadeAt::Voxels`], VTK's order, `crate::normals`), it reads
//! the cell's eight direction codes (four gathers, two codes per word) and their diffuse and
//! specular light from the frame's table (one gather per corner: two 16-bit halves per word)
//! and interpolates the light instead (`VoxelShadeSource`; every cell, faces included);
//! MIP/MinIP compare against one plane of values (`extreme_row_avx2`). Each group of
//! eight is first tested against its own cells' bricks, and skipped where none can contribute.
//! Before that, composite marches only the planes and pixels of each row that can meet a
//! brick with opacity (`reach`: the active bricks projected into the image once per frame,
//! decision 0041).
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
//! - `reach`: the planes and pixels of each row that can meet a brick with opacity;
//! - `tables`: the classification tables (`PostTable`, `ShadeTable`), their pre-integration
//!   and [`ring_risk`];
//! - `shade`: shading a sample (at the sample, `shaded_src`, or at the voxels) and the
//!   gradients of the reconstruction;
//! - `math`: the libm-free `log2` and `exp2` and the trilinear interpolation the twins share;
//! - `avx2` (x86-64 only): the kernels eight pixels at a time, each naming its scalar twin;
//! - `supersample`: the anti-aliasing of minified views ([`WHOLE_RAYS_FROM`]).

mod bricked;
mod march;
mod math;
mod path;
mod reach;
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
use crate::normals::ShadeAt;
use crate::sheets::{
    Progress, RenderMode, RenderSettings, RenderStats, Rendered, finish, ms, validate,
};
use crate::voxels::{Linear, Vox};
use march::{Ctx, Frame};
use std::time::Instant;
use supersample::{render_supersampled, supersampling};
use tables::FrameTables;
use view::Planes;
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

/// The slab thickness the front ends use when none is asked for, in units of the smallest grid
/// spacing, for `mode` and `shading` (`None`: unshaded; else where the lights are evaluated):
/// [`DEFAULT_SLAB_COMPOSITE`] (1) for composite, unshaded (one voxel stays closer to the exact
/// integral than VTK's ray caster at half a voxel, at half the cost of [`DEFAULT_SLAB`]), shaded
/// at the voxels (the interpolated light changes no faster than the values) or shaded at the
/// samples (each slab lit twice, at ±¼ of its step: decision 0036); [`DEFAULT_SLAB`] (½) for
/// MIP and MinIP (a maximum sampled every voxel misses the peaks between samples). The
/// measurements behind each choice are in `docs/decisions/0017-slab-thickness-by-mode.md`, its
/// amendment for decision 0019, and decision 0036.
pub fn default_slab(mode: RenderMode, shading: Option<ShadeAt>) -> f64 {
    match (mode, shading) {
        (RenderMode::Composite, _) => DEFAULT_SLAB_COMPOSITE,
        _ => DEFAULT_SLAB,
    }
}

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
    let owned;
    let bricks = match bricks {
        Some(b) if b.volume_dims == volume.grid().dims => b,
        _ => {
            check_settings(settings, volume.grid().dims)?;
            owned = BrickGrid::build(volume);
            &owned
        }
    };
    render_slabs_in(
        &mut Access::Whole(volume),
        camera,
        tables,
        settings,
        bricks,
        progress,
    )
}

/// Renders the level that `cache` serves, seen by `camera`, with image-aligned,
/// post-classified slabs, reading the voxels through the cache (out of core, issue 31 item 4):
/// the bands of the image go in groups, and before each group the bricks its rays can sample
/// are made resident (the rest of the level is never read; the next group's bricks are read
/// while a group marches). `bricks` is the level's brick grid ([`crate::LevelScan::brick_grid`]).
/// The image is the same bits as [`render_slabs`] of the level read whole, for any budget that
/// holds one band's bricks and any thread count. Errors: those of [`render_slabs`]; a budget
/// below one band's bricks ([`SplatError::Budget`]); a brick that cannot be read
/// ([`SplatError::Core`] naming the level and brick); shading at the voxels
/// ([`RenderSettings::shade_at`] `Voxels`: the direction codes are a field of the whole volume).
pub fn render_slabs_bricked<T: Scalar>(
    cache: &mut crate::cache::BrickCache<T>,
    bricks: &BrickGrid,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    render_slabs_in(
        &mut Access::Bricked(cache),
        camera,
        tables,
        settings,
        bricks,
        progress,
    )
}

/// Where a frame reads its voxels: a volume in memory, or the resident bricks of a level
/// ([`bricked::Resident`], made resident band group by band group).
pub(crate) enum Access<'v, T> {
    Whole(&'v Volume<T>),
    Bricked(&'v mut dyn bricked::Resident<T>),
}

impl<T: Scalar> Access<'_, T> {
    fn grid(&self) -> &volsplat_core::Grid {
        match self {
            Access::Whole(v) => v.grid(),
            Access::Bricked(r) => r.layout().grid(),
        }
    }
}

/// [`render_slabs`] reading the voxels through `access`; `bricks` is the level's brick grid.
pub(crate) fn render_slabs_in<T: Scalar>(
    access: &mut Access<'_, T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    bricks: &BrickGrid,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    let t_start = Instant::now();
    let grid = access.grid().clone();
    check_settings(settings, grid.dims)?;
    if bricks.volume_dims != grid.dims {
        return Err(SplatError::Setting {
            name: "bricks",
            value: format!("{:?}", bricks.volume_dims),
            expected: "the brick grid of the volume rendered",
        });
    }
    let proj = Projection::new(camera, settings.width, settings.height)?;
    let min_spacing = grid.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s));
    let ss = supersampling(settings, &proj, &grid, min_spacing);
    if ss > 1.0 {
        return render_supersampled(access, camera, tables, settings, bricks, progress, ss);
    }
    // Set-up: the planes, the frame's classification, the bricks that can have opacity.
    let planes = Planes::place(settings, &proj, &grid, min_spacing)?;
    let classifier = FrameClassifier::new(tables, proj.frame(), planes.delta);
    let mut owned_normals = None;
    let whole = match access {
        Access::Whole(v) => Some(&**v),
        Access::Bricked(_) => None,
    };
    let frame_tables = FrameTables::build(
        &grid,
        whole,
        tables,
        &classifier,
        settings,
        bricks,
        &mut owned_normals,
    )?;
    let mut active = frame_tables.active_bricks(bricks, tables);
    if let Some(owned) = settings.owned_cells {
        keep_owned_blocks(&mut active, bricks, owned);
    }
    let mut stats = RenderStats {
        preintegrated: frame_tables.preintegrated(),
        ring_risk: f64::from(frame_tables.risk),
        sheets: planes.n_planes,
        sheet_axis: 3,
        sheet_spacing: planes.delta,
        threads: rayon::current_num_threads(),
        ..RenderStats::default()
    };
    let owned_planes = settings.owned_cells.map(|owned| {
        planes_meeting(
            owned,
            &grid,
            &proj,
            planes.j0,
            planes.delta,
            planes.n_planes,
        )
    });
    let data_len = match access {
        Access::Whole(v) => v.data().len(),
        Access::Bricked(r) => r.arena().len(),
    };
    let mut frame = Frame::new(
        &grid,
        data_len,
        settings,
        planes,
        &frame_tables,
        &classifier,
        bricks,
        active,
    );
    if let Some(range) = owned_planes {
        frame.plane_range = range;
        // MIP/MinIP: a NaN bound skips the blocks outside the box (`Ctx::extreme_one`).
        let mut mine = vec![true; frame.extreme_bounds.len()];
        keep_owned_blocks(&mut mine, bricks, settings.owned_cells.unwrap_or_default());
        mine.iter()
            .zip(&mut frame.extreme_bounds)
            .for_each(|(m, b)| *b = if *m { *b } else { f32::NAN });
    }
    stats.setup_ms = ms(t_start);
    // The march, band by band of the image.
    let t_render = Instant::now();
    let (acc, counters) = match access {
        Access::Whole(v) => {
            Ctx::new(&frame, Vox::Linear(Linear::new(v))).march_bands(settings, progress)?
        }
        Access::Bricked(r) => {
            let (acc, c, [steps, pieced, split]) =
                bricked::march(&frame, &mut **r, settings, progress)?;
            stats.brick_steps = steps;
            stats.pieced_groups = pieced;
            stats.split_groups = split;
            (acc, c)
        }
    };
    stats.classify_ms = ms(t_render);
    // The finish: counters into stats, the accumulation into the picture.
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

/// Restricts `active` (one flag per 8³ block of cells, [`BrickGrid::index`]) to the blocks in
/// the box of cells `[lo, hi)` ([`RenderSettings::owned_cells`], checked by [`check_settings`]):
/// the slab march skips the others cell by cell, in the scalar path and the kernels alike, so
/// each sample is drawn by exactly the one box that holds its cell.
fn keep_owned_blocks(active: &mut [bool], bricks: &BrickGrid, [lo, hi]: [[usize; 3]; 2]) {
    let [nx, ny, _] = bricks.dims;
    for (b, flag) in active.iter_mut().enumerate() {
        let block = [b % nx, b / nx % ny, b / (nx * ny)];
        let inside = (0..3).all(|a| block[a] * 8 >= lo[a] && block[a] * 8 < hi[a]);
        *flag &= inside;
    }
}

/// The planes (indices from the first, `j0`, `delta` apart along the view) that can meet the
/// box of cells `[lo, hi)` of `grid`, `[first, end)` clamped to the `n` planes: those between
/// the box's nearest and farthest corner, one more each side. The others hold none of the box's
/// samples, so skipping them changes no bit of a brick's partial image and saves the march
/// through them.
fn planes_meeting(
    [lo, hi]: [[usize; 3]; 2],
    grid: &volsplat_core::Grid,
    proj: &Projection,
    j0: i64,
    delta: f64,
    n: usize,
) -> (usize, usize) {
    let frame = proj.frame();
    let top = grid.dims.map(|d| d.saturating_sub(1).max(1));
    let hi = [0, 1, 2].map(|a| hi[a].min(top[a]));
    let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
    for corner in 0..8 {
        let p = volsplat_core::glam::DVec3::from(
            [0, 1, 2].map(|a| (if corner >> a & 1 == 1 { hi[a] } else { lo[a] }) as f64),
        );
        let d = (grid.world_from_index(p) - frame.eye).dot(frame.forward);
        dmin = dmin.min(d);
        dmax = dmax.max(d);
    }
    let first = ((dmin / delta).floor() as i64 - j0 - 1).clamp(0, n as i64) as usize;
    let end = ((dmax / delta).ceil() as i64 - j0 + 2).clamp(0, n as i64) as usize;
    (first, end.max(first))
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
    if let Some([lo, hi]) = settings.owned_cells {
        let cells = dims.map(|n| n.saturating_sub(1).max(1));
        let fits = (0..3)
            .all(|a| lo[a] % 8 == 0 && lo[a] < hi[a] && (hi[a] % 8 == 0 || hi[a] >= cells[a]));
        if !fits {
            return Err(SplatError::Setting {
                name: "owned_cells",
                value: format!("{lo:?}..{hi:?} ({:?})", settings.mode),
                expected: "a box of cells whose bounds are multiples of 8 (the upper \
                           one may pass the last cell)",
            });
        }
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

/// Whether this CPU runs the AVX2 kernels (detected at run time; [`RenderSettings::simd`]
/// can decline them).
fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
