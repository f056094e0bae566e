//! Out-of-core frames of OME-Zarr stores (issue 31 item 4; decision 0039): the level is read
//! in bricks of [`BRICK`]³ cells through a [`BrickCache`] of a byte budget, and drawn by the
//! image-aligned slabs ([`volsplat_splat::render_slabs_bricked`]), the same bits as the level
//! read whole. The level's per-brick ranges are read once per store, level and selection (one
//! pass over the bricks, in parallel, a few at a time) and give the empty-space skipping and
//! the value range without keeping the level.

use super::cache::{Cached, build_pool, cached, resolve_tf};
use super::draw::{forward, sheets_done, slab_stats};
use super::plan::{self, Classification, Draw};
use super::{Output, Renderer, check_finite, ms, report};
use crate::error::{EngineError, Result};
use crate::request::{Mode, RenderRequest};
use crate::scene::VolumeSource;
use crate::{Progress, Stage, Stats};
use std::sync::Arc;
use std::time::Instant;
use volsplat_core::{AnyVolume, Grid, ScalarType};
use volsplat_io::{ZarrSelection, ZarrSource, ZarrStore};
use volsplat_splat::{BrickCache, BrickGrid, CacheStats};

/// Cells per brick side of out-of-core frames: 64³ u16 bricks of 67³ voxels are 0.57 MiB,
/// so a budget of 256 MiB holds about 440 of them.
pub(super) const BRICK: usize = 64;

/// The share of the budget given to the cache's arena; the bricks read ahead (at most a quarter
/// of the slots, `volsplat_splat::slab`'s read-ahead) take the rest.
const ARENA_SHARE: f64 = 0.8;

/// The cache of one level of one store, at one budget.
pub(super) struct Paged {
    cache: AnyCache,
    bricks: Arc<BrickGrid>,
    grid: Grid,
    range: (f64, f64),
    /// The coarsest level read whole (for the automatic transfer function), where it is small.
    preview: Option<Arc<AnyVolume>>,
    notes: Vec<String>,
}

/// [`BrickCache`] of the level's sample type.
enum AnyCache {
    U8(BrickCache<u8>),
    I8(BrickCache<i8>),
    U16(BrickCache<u16>),
    I16(BrickCache<i16>),
    F32(BrickCache<f32>),
}

macro_rules! with_cache {
    ($c:expr, $v:ident => $body:expr) => {
        match $c {
            AnyCache::U8($v) => $body,
            AnyCache::I8($v) => $body,
            AnyCache::U16($v) => $body,
            AnyCache::I16($v) => $body,
            AnyCache::F32($v) => $body,
        }
    };
}

/// The largest coarse level read whole for the automatic transfer function, in samples.
const PREVIEW_SAMPLES: u64 = 16 << 20;

/// The coarse level is read whole only if it takes at most `budget / PREVIEW_SHARE` bytes.
const PREVIEW_SHARE: u64 = 16;

/// The scan's reads in flight hold at most `budget / SCAN_SHARE` bytes (it runs before the
/// cache's arena is allocated).
const SCAN_SHARE: u64 = 4;

/// Half the memory the system reports available, bytes (4 GiB where unknown).
fn auto_budget() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map(|kb| kb.saturating_mul(1024) / 2)
        .unwrap_or(4 << 30)
}

impl Renderer {
    /// The budget `source` is read under out of core, where it is: an OME-Zarr store's level
    /// with `request.memory` set, or too large for half the available memory.
    pub(super) fn paged_budget(
        &self,
        request: &RenderRequest,
        source: &VolumeSource,
    ) -> Result<Option<u64>> {
        let VolumeSource::File {
            path,
            raw: None,
            level,
            ..
        } = source
        else {
            return Ok(None);
        };
        if !ZarrStore::is_store(path) {
            return Ok(None);
        }
        if let Some(b) = request.memory {
            return Ok(Some(b));
        }
        let store = ZarrStore::open(path, &self.limits)?;
        let l = store.level(level.index().unwrap_or(0))?;
        let bytes =
            l.dims.iter().product::<u64>() * l.scalar_type.map_or(4, |t| t.size_bytes() as u64);
        let budget = auto_budget();
        Ok((bytes > budget).then_some(budget))
    }

    /// The cache of `source`'s level under `budget`, opened (and its ranges read) once.
    fn paged(
        &mut self,
        source: &VolumeSource,
        budget: u64,
        pool: &rayon::ThreadPool,
    ) -> Result<super::cache::Fetched<'_, Paged>> {
        let limits = self.limits.clone();
        cached(&mut self.paged, (source.clone(), budget), || {
            pool.install(|| open_paged(source, budget, &limits))
        })
    }

    /// Renders `request` out of core from `source` (a store's level) under `budget`: the
    /// camera, value range and transfer function from the level's metadata and ranges, the
    /// plan that must draw with the image-aligned slabs at the level's full resolution.
    pub(super) fn render_paged(
        &mut self,
        request: &RenderRequest,
        source: &VolumeSource,
        budget: u64,
        level_note: Option<String>,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<Output> {
        let t0 = Instant::now();
        let threads = request.threads;
        let pool = Arc::clone(cached(&mut self.pool, threads, || build_pool(threads))?.value);
        let paged = self.paged(source, budget, &pool)?;
        let fresh = paged.fresh;
        let mut notes: Vec<String> = level_note.into_iter().collect();
        if fresh {
            notes.extend(paged.value.notes.iter().cloned());
        }
        let (grid, range) = (paged.value.grid.clone(), paged.value.range);
        let preview = paged.value.preview.clone();
        let load_ms = if fresh { ms(t0) } else { 0.0 };
        let camera = request.scene.camera.resolve(grid.drawn_bounds_world())?;
        if request.mode == Mode::Xray {
            return Err(refused(
                "X-ray (drawn by the sheet renderers, which read every voxel)",
            ));
        }
        let auto_needs_volume = matches!(
            request.scene.transfer_function,
            crate::scene::TransferSpec::Auto
        ) && request.mode == Mode::Composite;
        let vol = match preview {
            Some(v) => v,
            None if auto_needs_volume => {
                return Err(EngineError::request(
                    "transfer_function",
                    "an out-of-core store without a small coarse level needs a transfer \
                     function or a preset (the automatic one reads a whole level)",
                ));
            }
            // Not read: only the automatic composite function reads it.
            None => Arc::new(AnyVolume::U8(volsplat_core::Volume::from_fn(
                Grid::with_dims([1, 1, 1])?,
                |_, _, _| 0u8,
            )?)),
        };
        let resolved = resolve_tf(request, &vol, range, &mut self.auto_tf)?;
        let tf = resolved.tf;
        notes.extend(resolved.note);
        let mut warnings: Vec<String> = resolved.warning.into_iter().collect();
        warnings.extend(request.ignored_options());
        let t_prep = Instant::now();
        report(progress, 0.05, Stage::Classify)?;
        let (tables, tables_fresh) = self.tables(request, &tf)?;
        let plan = plan::plan(request, &camera, &grid, false, &mut || {
            Ok(Classification::from(&*tables))
        })?;
        warnings.extend(plan.warnings.iter().cloned());
        let Draw::Slabs(slabs) = &plan.draw else {
            return Err(refused("this renderer"));
        };
        if slabs.level != 0 {
            return Err(refused("a coarser renderer level (quality.level)"));
        }
        let mut settings = request.splat_settings();
        settings.clip = request.scene.clipping.world_planes(&grid)?;
        settings.slab = slabs.thickness;
        let prepare_ms = if fresh || tables_fresh {
            ms(t_prep)
        } else {
            0.0
        };
        report(progress, 0.2, Stage::Render)?;
        let paged = self
            .paged
            .as_mut()
            .map(|c| &mut c.value)
            .ok_or_else(|| EngineError::request("volume", "the store's cache was dropped"))?;
        let before = with_cache!(&paged.cache, c => c.stats());
        let bricks = Arc::clone(&paged.bricks);
        let rendered = forward(progress, |fwd| {
            pool.install(|| {
                with_cache!(&mut paged.cache, c => volsplat_splat::render_slabs_bricked(
                    c,
                    &bricks,
                    &camera,
                    &tables,
                    &settings,
                    &mut |p| fwd(sheets_done(p)),
                ))
            })
        })?;
        let after = with_cache!(&paged.cache, c => c.stats());
        notes.push(frame_note(&before, &after, budget));
        let composite = request.mode == Mode::Composite;
        let mut stats = Stats {
            prepare_ms,
            ..slab_stats(&rendered.stats, slabs, composite)
        };
        check_finite(
            &rendered.image,
            rendered.values.as_ref(),
            request.mode,
            plan.renderer,
        )?;
        stats.renderer = Some(plan.renderer);
        stats.projection = Some(plan.projection);
        stats.load_ms = load_ms;
        stats.width = request.width;
        stats.height = request.height;
        stats.total_ms = ms(t0);
        report(progress, 1.0, Stage::Done)?;
        Ok(Output {
            image: rendered.image,
            values: rendered.values,
            stats,
            camera,
            transfer_function: tf,
            warnings,
            notes,
        })
    }
}

/// The error for what an out-of-core frame cannot draw.
fn refused(what: &str) -> EngineError {
    EngineError::request(
        "renderer",
        format!(
            "{what} cannot read a store in bricks: out-of-core frames are drawn by the \
             image-aligned slabs at the level's full resolution (composite, MIP or MinIP; \
             visibility image or auto, quality.level full); lower the level (--zarr-level) \
             or leave out --memory to read the level whole"
        ),
    )
}

/// What a frame read: bricks, bytes, evictions, against the budget.
fn frame_note(before: &CacheStats, after: &CacheStats, budget: u64) -> String {
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    format!(
        "out of core: {} bricks read ({:.1} MiB), {} evicted, {} of {} resident, under a \
         budget of {:.0} MiB",
        after.reads - before.reads,
        mib(after.bytes_read - before.bytes_read),
        after.evictions - before.evictions,
        after.resident,
        after.capacity,
        mib(budget)
    )
}

/// Opens the store of `source`, reads its level's ranges once, and makes the cache.
fn open_paged(source: &VolumeSource, budget: u64, limits: &volsplat_io::Limits) -> Result<Paged> {
    let VolumeSource::File {
        path,
        level,
        channel,
        timepoint,
        ..
    } = source
    else {
        return Err(EngineError::request("volume", "not an OME-Zarr store"));
    };
    let t0 = Instant::now();
    let store = Arc::new(ZarrStore::open(path, limits)?);
    let level = level.index().unwrap_or(0);
    let sel = ZarrSelection {
        channel: *channel,
        timepoint: *timepoint,
    };
    let grid = store.grid(level)?;
    let kind = store.level(level)?.scalar_type.ok_or_else(|| {
        EngineError::request("volume", "the level's sample type cannot be rendered")
    })?;
    let arena = (budget as f64 * ARENA_SHARE) as u64;
    macro_rules! open {
        ($t:ty, $variant:ident) => {{
            let source = ZarrSource::<$t>::new(Arc::clone(&store), sel, BRICK)?;
            let scan = volsplat_splat::cache::scan_level_within(
                &source.as_stored(),
                level,
                budget / SCAN_SHARE,
            )?;
            let source = match scan.finite {
                Some([lo, hi]) if scan.non_finite.is_some() => {
                    source.with_finite_range(level, [lo, hi])?
                }
                _ => source,
            };
            let bricks = Arc::new(scan.brick_grid()?);
            let [lo, hi] = scan.value_range();
            let (scanned, scan_bytes) = (scan.bricks, scan.bytes_read);
            // Dropped before the arena is allocated: the block ranges are 0.8 % of the level.
            drop(scan);
            let cache = BrickCache::new(Arc::new(source), level, arena)?;
            let note = format!(
                "out of core: level {level} ({} × {} × {}) in {} bricks of {BRICK}³ cells, \
                 their ranges read once in {:.0} ms ({:.1} MiB); a cache of {} bricks",
                grid.dims[0],
                grid.dims[1],
                grid.dims[2],
                scanned,
                ms(t0),
                scan_bytes as f64 / (1u64 << 20) as f64,
                cache.capacity()
            );
            (
                AnyCache::$variant(cache),
                bricks,
                (lo as f64, hi as f64),
                note,
            )
        }};
    }
    let (cache, bricks, range, note) = match kind {
        ScalarType::U8 => open!(u8, U8),
        ScalarType::I8 => open!(i8, I8),
        ScalarType::U16 => open!(u16, U16),
        ScalarType::I16 => open!(i16, I16),
        ScalarType::F32 => open!(f32, F32),
    };
    // The coarsest level, read whole where it is small: the automatic transfer function's
    // histogram.
    let coarsest = store.levels().len() - 1;
    let samples = store.levels()[coarsest].dims.iter().product::<u64>();
    let small =
        samples <= PREVIEW_SAMPLES && samples * kind.size_bytes() as u64 <= budget / PREVIEW_SHARE;
    let preview = if small {
        Some(Arc::new(store.read_level(coarsest, sel)?))
    } else {
        None
    };
    Ok(Paged {
        cache,
        bricks,
        grid,
        range,
        preview,
        notes: vec![note],
    })
}

/// The cache slot of out-of-core levels: one store level and budget at a time.
pub(super) type PagedSlot = Option<Cached<(VolumeSource, u64), Paged>>;
