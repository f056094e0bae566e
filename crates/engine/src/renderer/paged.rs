//! Out-of-core frames of OME-Zarr stores (issue 31 item 4; decision 0039): the level is read
//! in bricks of [`BRICK`]³ cells through a [`BrickCache`] of a byte budget, and drawn by the
//! image-aligned slabs ([`volsplat_splat::render_slabs_bricked`]), the same bits as the level
//! read whole. The level's per-brick ranges are read once per store, level and selection (one
//! pass over the bricks, in parallel, a few at a time) and give the empty-space skipping and
//! the value range without keeping the level.
//!
//! A sort-last rank's **part** (issue 32, decision 0038; [`part`]): a brick of a store or of a
//! NRRD file with a raw payload ([`Renderer::render_brick`]) reads only the cache bricks
//! meeting the rank's sort-last bricks
//! (their ranges scanned, `volsplat_splat::scan_level_in`; the cache
//! `BrickCache::restricted`), in bricks of the largest power of two (≤ [`BRICK`]) dividing the
//! sort-last brick, so no cache brick holds another rank's cells. The blocks outside the part
//! are kept out of every frame by `RenderSettings::owned_cells` (inactive in composite, a NaN
//! bound in MIP/MinIP), so the bricks never read are never sampled.

use super::cache::{Cached, build_pool, cached, resolve_tf};
use super::draw::{forward, sheets_done, slab_stats};
use super::plan::{self, Classification, Draw};
use super::{Output, Renderer, check_finite, ms, report};
use crate::error::{EngineError, Result};
use crate::request::{Mode, RenderRequest};
use crate::scene::VolumeSource;
use crate::{Progress, Stage, Stats};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;
use volsplat_core::{AnyVolume, Grid, ScalarType};
use volsplat_io::{ZarrSelection, ZarrSource, ZarrStore};
use volsplat_splat::{BrickCache, BrickGrid, CacheStats, LevelScan};

/// Cells per brick side of out-of-core frames: 64³ u16 bricks of 67³ voxels are 0.57 MiB,
/// so a budget of 256 MiB holds about 440 of them.
pub(super) const BRICK: usize = 64;

/// The share of the budget given to the cache's arena, less the skip-block grid
/// ([`arena_bytes`]). With the bricks read ahead (at most a quarter of the slots,
/// `volsplat_splat::slab`'s read-ahead: 0.16), the reads in flight (1/16) and the chunk faces
/// cache ([`CHUNK_CACHE_SHARE`]: 1/8) the cache's parts take 0.99 of the budget, the grid
/// included, so that the process stays within the budget plus its image buffers and the
/// allocator's slack (8 GiB store at 1 GiB: peak RSS 1.09 × the budget; 0.72 before gave
/// 1.19 × for 2 % less time; decision 0039, amendment 2).
const ARENA_SHARE: f64 = 0.64;

/// The chunk faces cache of the scan and the frames (one cache: the first frame finds the
/// faces the scan left) holds at most `budget / CHUNK_CACHE_SHARE` bytes
/// ([`ZarrSource::with_chunk_cache`]).
const CHUNK_CACHE_SHARE: u64 = 8;

/// The arena's bytes under `budget`: [`ARENA_SHARE`] of it less the skip-block grid `bricks`
/// (8 bytes per 8³ block: 0.78 % of a u16 level), which lives as long as the cache.
fn arena_bytes(budget: u64, bricks: &BrickGrid) -> u64 {
    let grid = (bricks.ranges.len() * std::mem::size_of::<[f32; 2]>()) as u64;
    ((budget as f64 * ARENA_SHARE) as u64).saturating_sub(grid)
}

/// The cache of one level of one store, at one budget.
pub(super) struct Paged {
    cache: AnyCache,
    bricks: Arc<BrickGrid>,
    grid: Grid,
    range: (f64, f64),
    /// The coarsest level read whole (for the automatic transfer function), where it is small.
    preview: Option<Arc<AnyVolume>>,
    pub(super) notes: Vec<String>,
    /// A sort-last rank's part ([`Region`]): its scan, to give the bricks it did not read the
    /// level's range ([`Renderer::set_rank_range`]); `None` for a whole level.
    part: Option<Part>,
}

/// What a sort-last rank's part of a level knows of itself.
struct Part {
    scan: LevelScan,
    /// Whether `range` is the level's ([`Renderer::set_rank_range`]), not only the part's.
    range_is_level: bool,
    /// Cells per brick of the part's cache.
    brick: usize,
    /// The level's bricks and decoded bytes, had it been read whole.
    level_bricks: usize,
    level_bytes: u64,
    /// A NRRD file's count of the bytes its bricks read from it, and its value once the
    /// ranges scan was done.
    file_bytes: Option<(Arc<std::sync::atomic::AtomicU64>, u64)>,
    /// Bytes scanned and read from the file by an earlier open of the part (before the level's
    /// finite range was known, [`Renderer::set_rank_range`]).
    earlier: (u64, u64),
}

/// The boxes of cells (`[lo, hi)`, index space of the level) whose bricks a sort-last rank
/// reads; the cache of a store's level is keyed by it (`None`: the whole level).
type Region = Option<Vec<[[usize; 3]; 2]>>;

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

mod part;

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
    ///
    /// A sort-last brick (`owned`) of a store or of a NRRD file with a raw payload is always
    /// read in bricks (at `request.memory`, or half the available memory); in X-ray its voxels
    /// are then drawn as a sub-volume (`Renderer::render_xray_part`, decision 0038).
    pub(super) fn paged_budget(
        &self,
        request: &RenderRequest,
        source: &VolumeSource,
        owned: bool,
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
        if owned {
            // A store, or a NRRD file with a raw payload (its header read, no sample).
            return Ok(part::PartStore::readable(source, &self.limits)?
                .then(|| request.memory.unwrap_or_else(auto_budget)));
        }
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

    /// The cache of `source`'s level under `budget`, opened (and its ranges read) once: the
    /// whole level (`owned` `None`), or a sort-last rank's part holding the box `owned` (the
    /// part opened by [`Renderer::open_rank_part`] where it holds the box, else the box alone).
    fn paged(
        &mut self,
        source: &VolumeSource,
        budget: u64,
        request_memory: Option<u64>,
        owned: Option<[[usize; 3]; 2]>,
        pool: &rayon::ThreadPool,
    ) -> Result<super::cache::Fetched<'_, Paged>> {
        let limits = self.limits.clone();
        // A rank's part is kept at the budget it was opened with (an automatic budget follows
        // the memory available, which changes from call to call).
        let (budget, region): (u64, Region) = match (owned, &self.paged) {
            (None, _) => (budget, None),
            (Some(o), Some(c))
                if c.key.0 == *source
                    && (c.key.1 == budget || request_memory.is_none())
                    && c.key.2.as_ref().is_some_and(|r| r.contains(&o)) =>
            {
                (c.key.1, c.key.2.clone())
            }
            (Some(o), _) => (budget, Some(vec![o])),
        };
        let key = (source.clone(), budget, region.clone());
        cached(&mut self.paged, key, || {
            pool.install(|| open_paged(source, budget, &limits, region.as_deref()))
        })
    }

    /// The grid of `request`'s volume where a sort-last rank reads it in bricks (an OME-Zarr
    /// store's level or a NRRD file with a raw payload), from the store's
    /// metadata or the file's header (no voxel read); `None` where the volume is read whole.
    pub fn part_grid(&self, request: &RenderRequest) -> Result<Option<Grid>> {
        let (source, _) = self.concrete_source(request)?;
        if self.paged_budget(request, &source, true)?.is_none() {
            return Ok(None);
        }
        part::PartStore::open(&source, &self.limits)?
            .map(|s| s.grid())
            .transpose()
    }

    /// Opens a sort-last rank's part of `request`'s volume for reading in bricks, where it is
    /// read so (an OME-Zarr store or a NRRD file with a raw payload): the bricks
    /// meeting the boxes of cells `region` (the rank's sort-last bricks) are scanned for their
    /// ranges and no other brick is ever read. Returns the part's value range, its finite
    /// range and whether it holds non-finite floats, or `None` where the volume is read whole. The part's range is not the level's: give
    /// the level's with [`Renderer::set_rank_range`] before rendering where the picture
    /// depends on it.
    pub(crate) fn open_rank_part(
        &mut self,
        request: &RenderRequest,
        region: &[[[usize; 3]; 2]],
    ) -> Result<Option<crate::distributed::RankPart>> {
        let (source, _) = self.concrete_source(request)?;
        let Some(budget) = self.paged_budget(request, &source, true)? else {
            return Ok(None);
        };
        let threads = request.threads;
        let pool = Arc::clone(cached(&mut self.pool, threads, || build_pool(threads))?.value);
        let limits = self.limits.clone();
        let key = (source.clone(), budget, Some(region.to_vec()));
        let got = cached(&mut self.paged, key, || {
            pool.install(|| open_paged(&source, budget, &limits, Some(region)))
        })?;
        let Some(part) = &got.value.part else {
            return Ok(None);
        };
        let range = part.scan.value_range();
        Ok(Some(crate::distributed::RankPart {
            range: (range[0] <= range[1]).then_some(range),
            finite: part.scan.finite,
            non_finite: part.scan.non_finite.is_some(),
        }))
    }

    /// Gives the rank's part opened by [`Renderer::open_rank_part`] the level's value range
    /// `range` (data units; the union of every rank's part's range): the value range of its
    /// frames (presets, the projections' automatic ramp) and the range of the blocks it did
    /// not read (the slabs' automatic pre-integration test folds every block's range), so
    /// that its frames are those of the level read whole.
    ///
    /// A part holding NaN or ±∞ floats is opened again with the level's finite range `finite`
    /// (the union of every part's finite range: decision 0030 replaces NaN and −∞ by the
    /// level's lowest finite sample, +∞ by its highest), its bricks scanned again as replaced,
    /// so that its bricks and block ranges are those of the level read whole; an error where
    /// `finite` is `None`.
    pub(crate) fn set_rank_range(
        &mut self,
        request: &RenderRequest,
        range: [f32; 2],
        finite: Option<[f32; 2]>,
    ) -> Result<()> {
        let nf = self
            .paged
            .as_ref()
            .and_then(|c| c.value.part.as_ref())
            .is_some_and(|p| p.scan.non_finite.is_some());
        if nf {
            self.reopen_part(request, finite)?;
        }
        let Some(paged) = self.paged.as_mut().map(|c| &mut c.value) else {
            return Ok(());
        };
        let Some(part) = paged.part.as_mut() else {
            return Ok(());
        };
        part.scan.fill_unread(range);
        paged.bricks = Arc::new(part.scan.brick_grid()?);
        paged.range = (range[0] as f64, range[1] as f64);
        part.range_is_level = true;
        Ok(())
    }

    /// The rank's part opened again with the level's finite range `finite` (its non-finite
    /// floats replaced), under the same key; the old cache dropped first.
    fn reopen_part(&mut self, request: &RenderRequest, finite: Option<[f32; 2]>) -> Result<()> {
        let Some(finite) = finite else {
            return Err(EngineError::request(
                "volume",
                "the rank's bricks hold NaN or infinite samples and no rank read a finite one",
            ));
        };
        let Some(old) = self.paged.take() else {
            return Ok(());
        };
        let (source, budget, region) = old.key;
        let earlier = old.value.part.as_ref().map_or((0, 0), |p| {
            let file = p
                .file_bytes
                .as_ref()
                .map_or(0, |c| c.0.load(Ordering::Relaxed));
            (p.earlier.0 + p.scan.bytes_read, p.earlier.1 + file)
        });
        drop(old.value);
        let Some(boxes) = region.as_deref() else {
            return Ok(());
        };
        let threads = request.threads;
        let pool = Arc::clone(cached(&mut self.pool, threads, || build_pool(threads))?.value);
        let limits = self.limits.clone();
        let mut value =
            pool.install(|| part::open_part(&source, budget, &limits, boxes, Some(finite)))?;
        if let Some(p) = value.part.as_mut() {
            p.earlier = earlier;
        }
        self.paged = Some(Cached {
            key: (source, budget, region),
            value,
        });
        Ok(())
    }

    /// What this renderer read of a sort-last rank's part of a store or NRRD file: the bricks
    /// of its ranges scan and of its frames, against the level read whole; `None` where no
    /// part is open (the volume was read whole).
    pub fn rank_reads(&self) -> Option<crate::distributed::RankReads> {
        let paged = &self.paged.as_ref()?.value;
        let part = paged.part.as_ref()?;
        Some(crate::distributed::RankReads {
            brick: part.brick,
            region_bricks: part.scan.read.iter().filter(|&&r| r).count(),
            level_bricks: part.level_bricks,
            scan_bytes: part.earlier.0 + part.scan.bytes_read,
            frames: with_cache!(&paged.cache, c => c.stats()),
            level_bytes: part.level_bytes,
            scan_file_bytes: part.file_bytes.as_ref().map(|c| part.earlier.1 + c.1),
            frame_file_bytes: part
                .file_bytes
                .as_ref()
                .map(|c| c.0.load(Ordering::Relaxed) - c.1),
        })
    }

    /// The classification tables of `request` drawn from the rank's part of a store (rank 0
    /// classifies the composited MIP/MinIP with them), or `None` where no part is open.
    pub(crate) fn rank_frame_tables(
        &mut self,
        request: &RenderRequest,
    ) -> Result<Option<Arc<volsplat_core::CrioTables>>> {
        let Some((range, preview)) = self
            .paged
            .as_ref()
            .filter(|c| c.value.part.is_some())
            .map(|c| (c.value.range, c.value.preview.clone()))
        else {
            return Ok(None);
        };
        let vol = match preview {
            Some(v) => v,
            None => placeholder()?,
        };
        let tf = resolve_tf(request, &vol, range, &mut self.auto_tf)?.tf;
        Ok(Some(self.tables(request, &tf)?.0))
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
        owned: Option<[[usize; 3]; 2]>,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<Output> {
        let t0 = Instant::now();
        let threads = request.threads;
        let pool = Arc::clone(cached(&mut self.pool, threads, || build_pool(threads))?.value);
        let paged = self.paged(source, budget, request.memory, owned, &pool)?;
        if let Some(part) = &paged.value.part {
            check_part(request, part)?;
        }
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
            None => placeholder()?,
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
        let mut settings = request.splat_settings();
        settings.clip = request.scene.clipping.world_planes(&grid)?;
        settings.slab = slabs.thickness;
        settings.owned_cells = owned;
        let prepare_ms = if fresh || tables_fresh {
            ms(t_prep)
        } else {
            0.0
        };
        report(progress, 0.2, Stage::Render)?;
        let rendered = if slabs.level != 0 {
            // A preview (`quality.level`): the store's own coarser level, read whole.
            let level = super::store_level::StoreLevelFrame {
                source,
                full: &grid,
                level: slabs.level,
                budget,
                camera: &camera,
                tables: &tables,
                settings,
                pool: &pool,
            };
            let (rendered, note) = self.draw_store_level(level, progress)?;
            notes.push(note);
            rendered
        } else {
            self.draw_paged(
                budget,
                (&camera, &tables, &settings),
                &pool,
                &mut notes,
                progress,
            )?
        };
        finish(
            Finished {
                rendered,
                plan: &plan,
                slabs,
                request,
                prepare_ms,
                load_ms,
                t0,
            },
            (camera, tf, warnings, notes),
            progress,
        )
    }

    /// Draws a frame of the store's level through the brick cache, noting what it read and
    /// whether bands were drawn in pieces.
    fn draw_paged(
        &mut self,
        budget: u64,
        (camera, tables, settings): (
            &volsplat_core::Camera,
            &volsplat_core::CrioTables,
            &volsplat_splat::RenderSettings,
        ),
        pool: &rayon::ThreadPool,
        notes: &mut Vec<String>,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<volsplat_splat::Rendered> {
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
                    camera,
                    tables,
                    settings,
                    &mut |p| fwd(sheets_done(p)),
                ))
            })
        })?;
        let after = with_cache!(&paged.cache, c => c.stats());
        notes.push(frame_note(&before, &after, budget));
        if rendered.stats.pieced_groups > 0 {
            notes.push(format!(
                "out of core: {} groups of bands met more bricks than the budget holds and were \
                 drawn in pieces of planes ({} steps in all)",
                rendered.stats.pieced_groups, rendered.stats.brick_steps
            ));
        }
        if rendered.stats.split_groups > 0 {
            notes.push(format!(
                "out of core: in {} of those groups one plane of a band met more bricks than the \
                 budget holds, so the band was drawn in pieces of columns or rows too (a larger \
                 --memory reads fewer bricks again)",
                rendered.stats.split_groups
            ));
        }
        Ok(rendered)
    }
}

/// A drawn out-of-core frame and what its stats are made from.
struct Finished<'a> {
    rendered: volsplat_splat::Rendered,
    plan: &'a plan::Plan,
    slabs: &'a plan::SlabPlan,
    request: &'a RenderRequest,
    prepare_ms: f64,
    load_ms: f64,
    t0: Instant,
}

/// The frame's output: the picture checked, the stats, the resolved camera and transfer
/// function, warnings and notes.
fn finish(
    f: Finished<'_>,
    (camera, tf, warnings, notes): (
        volsplat_core::Camera,
        volsplat_core::TransferFunction,
        Vec<String>,
        Vec<String>,
    ),
    progress: &mut (dyn FnMut(&Progress) -> bool + Send),
) -> Result<Output> {
    let Finished {
        rendered,
        plan,
        slabs,
        request,
        prepare_ms,
        load_ms,
        t0,
    } = f;
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

/// A volume read whole to stand in where none is read (only the automatic composite transfer
/// function reads one, and a rank's part refuses it).
fn placeholder() -> Result<Arc<AnyVolume>> {
    Ok(Arc::new(AnyVolume::U8(volsplat_core::Volume::from_fn(
        Grid::with_dims([1, 1, 1])?,
        |_, _, _| 0u8,
    )?)))
}

/// What a sort-last rank's part of a store cannot draw as the level read whole would: a float
/// level with NaN or ±∞ before the level's finite range is known (they become the *level's*
/// finite extremes, which [`Renderer::set_rank_range`] gives), the automatic composite transfer function (a histogram of the whole level), and a
/// preset or automatic range before the level's range is known ([`Renderer::set_rank_range`]).
fn check_part(request: &RenderRequest, part: &Part) -> Result<()> {
    if let Some(nf) = &part.scan.non_finite {
        return Err(EngineError::request(
            "volume",
            format!(
                "a rank's bricks hold {} NaN and {} infinite samples, which become the whole \
                 level's finite extremes (decision 0030): a brick rendered alone does not know \
                 them (render through distributed::render_sort_last, which shares them)",
                nf.nan,
                nf.pos_inf + nf.neg_inf
            ),
        ));
    }
    let spec = &request.scene.transfer_function;
    let auto = matches!(spec, crate::scene::TransferSpec::Auto);
    if auto && request.mode == Mode::Composite {
        return Err(EngineError::request(
            "transfer_function",
            "a sort-last rank reading only its bricks needs a transfer function or a preset in \
                 composite (the automatic one is a histogram of the whole volume; `volsplat render \
                 --save-scene` records the function it used)",
        ));
    }
    let needs_range = !matches!(spec, crate::scene::TransferSpec::Function(_));
    if needs_range && !part.range_is_level {
        return Err(EngineError::request(
            "transfer_function",
            "a brick rendered alone from a store knows only its own value range: a preset or \
                 the automatic projection window needs the level's (render through \
                 distributed::render_sort_last, which shares it, or give a transfer function)",
        ));
    }
    Ok(())
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

/// The level's brick source of samples `$t` (bricks of `$brick` cells, with the chunk faces
/// cache of `$budget / CHUNK_CACHE_SHARE`, shared by the scan and the frames) and its ranges:
/// kept from an earlier open, or scanned within `$budget / SCAN_SHARE` and kept
/// ([`scan_or_kept`], whose note comes along). A macro, as `ZarrSource` needs zarrs' element
/// trait, which the engine does not name.
macro_rules! source_and_scan {
    ($t:ty, ($store:expr, $path:expr), ($level:expr, $sel:expr), $kind:expr, $brick:expr, $budget:expr) => {{
        let source = ZarrSource::<$t>::new(Arc::clone($store), $sel, $brick)?
            .with_chunk_cache($budget / CHUNK_CACHE_SHARE);
        let layout = volsplat_core::source::BrickSource::layout(&source, $level)
            .cloned()
            .ok_or_else(|| EngineError::request("volume.level", "no such level"))?;
        let (scan, note) = scan_or_kept(&layout, ($store, $path), ($level, $sel), $kind, || {
            Ok(volsplat_splat::cache::scan_level_within(
                &source.as_stored(),
                $level,
                $budget / SCAN_SHARE,
            )?)
        })?;
        (source, scan, note)
    }};
}

/// Opens the store of `source`, reads its level's ranges once, and makes the cache; a
/// sort-last rank's part (`region`: its boxes of cells) is opened by [`part::open_part`].
pub(super) fn open_paged(
    source: &VolumeSource,
    budget: u64,
    limits: &volsplat_io::Limits,
    region: Option<&[[[usize; 3]; 2]]>,
) -> Result<Paged> {
    if let Some(r) = region {
        return part::open_part(source, budget, limits, r, None);
    }
    let t0 = Instant::now();
    let (path, store, level, sel, kind) = open_store_level(source, limits)?;
    let grid = store.grid(level)?;
    let sidecar_note;
    let brick = BRICK;
    macro_rules! open {
        ($t:ty, $variant:ident) => {{
            let (source, scan, kept) =
                source_and_scan!($t, (&store, path), (level, sel), kind, brick, budget);
            sidecar_note = kept;
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
            let cache = BrickCache::new(Arc::new(source), level, arena_bytes(budget, &bricks))?;
            let note = format!(
                "out of core: level {level} ({} × {} × {}) in {} bricks of {brick}³ cells, \
                 their ranges ready in {:.0} ms ({:.1} MiB read); a cache of {} bricks",
                grid.dims[0],
                grid.dims[1],
                grid.dims[2],
                scanned,
                ms(t0),
                scan_bytes as f64 / (1u64 << 20) as f64,
                cache.stats().capacity
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
        notes: std::iter::once(note).chain(sidecar_note).collect(),
        part: None,
    })
}

/// Cells per brick of a rank's part: the largest power of two (at most [`BRICK`], at least 8)
/// that divides every bound of the boxes `region` inside the level (of `dims` voxels), so that
/// the bricks meeting a box hold no cell outside it.
fn part_brick(region: &[[[usize; 3]; 2]], dims: [usize; 3]) -> usize {
    let cells = dims.map(|d| d.saturating_sub(1).max(1));
    let mut shift = BRICK.trailing_zeros();
    for [lo, hi] in region {
        for a in 0..3 {
            for v in [lo[a], hi[a]] {
                if v > 0 && v < cells[a] {
                    shift = shift.min(v.trailing_zeros());
                }
            }
        }
    }
    (1usize << shift).max(8)
}

/// The level's ranges: kept from an earlier open of the same unchanged level
/// ([`super::ranges_sidecar`]), else read brick by brick and kept for the next open. The note
/// says which, or why they could not be kept.
fn scan_or_kept(
    layout: &volsplat_core::source::BrickLayout,
    (store, path): (&ZarrStore, &std::path::Path),
    (level, sel): (usize, ZarrSelection),
    kind: ScalarType,
    scan: impl FnOnce() -> Result<volsplat_splat::LevelScan>,
) -> Result<(volsplat_splat::LevelScan, Option<String>)> {
    let array = path.join(&store.levels()[level].path);
    let fp = super::ranges_sidecar::Fingerprint::of(
        path,
        &array,
        (level, sel.channel, sel.timepoint),
        layout,
        kind.name(),
    );
    if let Some(scan) = fp.as_ref().and_then(|f| f.load(layout)) {
        return Ok((
            scan,
            Some("out of core: the level's ranges were kept from an earlier open".into()),
        ));
    }
    let scan = scan()?;
    let note = fp.map(|f| match f.save(&scan) {
        Ok(p) => format!("out of core: the level's ranges are kept in {} for the next open", p.display()),
        Err(e) => format!("out of core: the level's ranges could not be kept ({e}); the next open reads them again"),
    });
    Ok((scan, note))
}

/// The OME-Zarr store of `source` opened (metadata only): its path, the store, the level, the
/// channel and time point, and the level's sample type.
fn open_store_level<'s>(
    source: &'s VolumeSource,
    limits: &volsplat_io::Limits,
) -> Result<(
    &'s std::path::Path,
    Arc<ZarrStore>,
    usize,
    ZarrSelection,
    ScalarType,
)> {
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
    let store = Arc::new(ZarrStore::open(path, limits)?);
    let level = level.index().unwrap_or(0);
    let sel = ZarrSelection {
        channel: *channel,
        timepoint: *timepoint,
    };
    let kind = store.level(level)?.scalar_type.ok_or_else(|| {
        EngineError::request("volume", "the level's sample type cannot be rendered")
    })?;
    Ok((path, store, level, sel, kind))
}

/// The value range `[lo, hi]` (data units; the finite samples of a float level) of the store
/// level of `source`, from its ranges kept in the user's cache folder or else a ranges scan
/// that holds at most `budget / SCAN_SHARE` bytes of bricks at once (and keeps them for the
/// next open), without a cache or the level read whole; what it did, as a note.
pub(super) fn store_level_range(
    source: &VolumeSource,
    budget: u64,
    limits: &volsplat_io::Limits,
) -> Result<([f64; 2], Option<String>)> {
    let (path, store, level, sel, kind) = open_store_level(source, limits)?;
    macro_rules! range {
        ($t:ty) => {{
            let (_, scan, note) =
                source_and_scan!($t, (&store, path), (level, sel), kind, BRICK, budget);
            let [lo, hi] = scan.value_range();
            ([f64::from(lo), f64::from(hi)], note)
        }};
    }
    Ok(match kind {
        ScalarType::U8 => range!(u8),
        ScalarType::I8 => range!(i8),
        ScalarType::U16 => range!(u16),
        ScalarType::I16 => range!(i16),
        ScalarType::F32 => range!(f32),
    })
}

/// The cache slot of out-of-core levels: one store level and budget at a time.
pub(super) type PagedSlot = Option<Cached<(VolumeSource, u64, Region), Paged>>;
