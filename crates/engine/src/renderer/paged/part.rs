//! A sort-last rank's part of a file read in bricks (issue 32 item 2, decision 0038): an
//! OME-Zarr store's level ([`ZarrSource`]) or a NRRD file with a raw payload
//! ([`volsplat_io::nrrd::NrrdSource`]), opened as a brick source; only the bricks meeting the
//! rank's sort-last bricks are scanned for their ranges and ever read. In X-ray each
//! sort-last brick's voxels are copied out of them into a volume of their own and drawn by the
//! sheets or the splat list ([`Renderer::render_xray_part`]).

use super::{AnyCache, CHUNK_CACHE_SHARE, Paged, Part, arena_bytes, part_brick};
use crate::error::{EngineError, Result};
use crate::renderer::Renderer;
use crate::request::RenderRequest;
use crate::scene::{StoreLevel, VolumeSource};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicU64;
use std::time::Instant;
use volsplat_core::source::BrickSource;
use volsplat_core::{Grid, ScalarType};
use volsplat_io::nrrd::NrrdHeader;
use volsplat_io::{ZarrSelection, ZarrSource, ZarrStore};
use volsplat_splat::{BrickCache, bricks_meeting, scan_level_in};

/// The file a rank's part is read from, opened (metadata only).
pub(super) enum PartStore {
    /// An OME-Zarr store's level.
    Zarr {
        store: Arc<ZarrStore>,
        sel: ZarrSelection,
        level: usize,
    },
    /// A NRRD file with a raw payload (its one level).
    Nrrd(Box<NrrdHeader>),
}

impl PartStore {
    /// The store or NRRD file of `source`, where a rank's part of it can be read in bricks:
    /// an OME-Zarr store; a `.nrrd` or `.nhdr` file whose payload is raw (gzip and text
    /// payloads, frames, arrays and series other than the file's one volume are read whole,
    /// which reports what is wrong with them). `None` otherwise. Errors: a store or header
    /// that cannot be read.
    pub(super) fn open(
        source: &VolumeSource,
        limits: &volsplat_io::Limits,
    ) -> Result<Option<Self>> {
        let VolumeSource::File {
            path,
            raw: None,
            frame,
            array,
            series,
            level,
            channel,
            timepoint,
        } = source
        else {
            return Ok(None);
        };
        if ZarrStore::is_store(path) {
            return Ok(Some(PartStore::Zarr {
                store: Arc::new(ZarrStore::open(path, limits)?),
                sel: ZarrSelection {
                    channel: *channel,
                    timepoint: *timepoint,
                },
                level: level.index().unwrap_or(0),
            }));
        }
        let plain = *frame == 0
            && array.is_none()
            && series.is_none()
            && *level == StoreLevel::Index(0)
            && *channel == 0
            && *timepoint == 0;
        if !plain || !is_nrrd(path) {
            return Ok(None);
        }
        let header = NrrdHeader::open(path, limits)?;
        Ok(header.is_raw().then(|| PartStore::Nrrd(Box::new(header))))
    }

    /// Whether [`PartStore::open`] opens `source`: an OME-Zarr store (its metadata not read
    /// here), or a NRRD file whose header says its payload is raw.
    pub(super) fn readable(source: &VolumeSource, limits: &volsplat_io::Limits) -> Result<bool> {
        if let VolumeSource::File {
            path, raw: None, ..
        } = source
            && ZarrStore::is_store(path)
        {
            return Ok(true);
        }
        Ok(Self::open(source, limits)?.is_some())
    }

    /// The level's geometry.
    pub(super) fn grid(&self) -> Result<Grid> {
        match self {
            PartStore::Zarr { store, level, .. } => Ok(store.grid(*level)?),
            PartStore::Nrrd(h) => Ok(h.grid().clone()),
        }
    }

    /// The level's sample type.
    fn kind(&self) -> Result<ScalarType> {
        match self {
            PartStore::Zarr { store, level, .. } => {
                store.level(*level)?.scalar_type.ok_or_else(|| {
                    EngineError::request("volume", "the level's sample type cannot be rendered")
                })
            }
            PartStore::Nrrd(h) => Ok(h.scalar_type()),
        }
    }

    /// The level served in bricks.
    fn level(&self) -> usize {
        match self {
            PartStore::Zarr { level, .. } => *level,
            PartStore::Nrrd(_) => 0,
        }
    }
}

/// Whether `path` names a NRRD file (`.nrrd`, `.nhdr`, any case), as the readers choose it.
fn is_nrrd(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("nrrd") || e.eq_ignore_ascii_case("nhdr"))
}

/// A brick source of `store`'s level for the frames, its copy serving the samples as stored
/// (for the ranges scan), and the NRRD source's counter of bytes read from the file.
type Sources<T> = (
    Arc<dyn BrickSource<T>>,
    Arc<dyn BrickSource<T>>,
    Option<Arc<AtomicU64>>,
);

macro_rules! sources {
    ($t:ty, $store:expr, $brick:expr, $finite:expr, $budget:expr) => {{
        let sources: Sources<$t> = match $store {
            PartStore::Zarr { store, sel, level } => {
                // One chunk faces cache for the scan and the frames (its clones share it).
                let s = ZarrSource::<$t>::new(Arc::clone(store), *sel, $brick)?
                    .with_chunk_cache($budget / CHUNK_CACHE_SHARE);
                let s = match $finite {
                    Some(f) => s.with_finite_range(*level, f)?,
                    None => s,
                };
                (Arc::new(s.clone()), Arc::new(s.as_stored()), None)
            }
            PartStore::Nrrd(h) => {
                let s = h.source::<$t>($brick)?;
                let counter = s.bytes_read_counter();
                let s = match $finite {
                    Some(f) => s.with_finite_range(f)?,
                    None => s,
                };
                (Arc::new(s.clone()), Arc::new(s.as_stored()), Some(counter))
            }
        };
        sources
    }};
}

/// Opens a rank's part of `source`'s level under `budget`: the bricks meeting the boxes of
/// cells `region` scanned for their ranges (as stored, or with the level's finite range
/// `finite` replacing NaN and ±∞ where given: decision 0030), and a cache that reads no other
/// brick.
pub(super) fn open_part(
    source: &VolumeSource,
    budget: u64,
    limits: &volsplat_io::Limits,
    region: &[[[usize; 3]; 2]],
    finite: Option<[f32; 2]>,
) -> Result<Paged> {
    let t0 = Instant::now();
    let store = PartStore::open(source, limits)?.ok_or_else(|| {
        EngineError::request(
            "volume",
            "not an OME-Zarr store or a NRRD file with a raw payload",
        )
    })?;
    let (grid, kind, level) = (store.grid()?, store.kind()?, store.level());
    let brick = part_brick(region, grid.dims);
    macro_rules! open {
        ($t:ty, $variant:ident) => {{
            let (render, stored, counter) = sources!($t, &store, brick, finite, budget);
            // As stored (non-finite floats found, counted, and refused until the level's
            // finite range is shared: `check_part`), or replaced by the level's extremes.
            let scanned = if finite.is_some() { &render } else { &stored };
            let scan = scan_level_in(&**scanned, level, region)?;
            let counter = counter.map(|c| {
                let scanned = c.load(std::sync::atomic::Ordering::Relaxed);
                (c, scanned)
            });
            let allowed = bricks_meeting(&scan.layout, region);
            let bricks = Arc::new(scan.brick_grid()?);
            let range = scan.value_range();
            let cache =
                BrickCache::restricted(render, level, arena_bytes(budget, &bricks), allowed)?;
            let level_bytes =
                grid.dims.iter().product::<usize>() as u64 * std::mem::size_of::<$t>() as u64;
            (
                AnyCache::$variant(cache),
                bricks,
                range,
                scan,
                counter,
                level_bytes,
            )
        }};
    }
    let (cache, bricks, [lo, hi], scan, counter, level_bytes) = match kind {
        ScalarType::U8 => open!(u8, U8),
        ScalarType::I8 => open!(i8, I8),
        ScalarType::U16 => open!(u16, U16),
        ScalarType::I16 => open!(i16, I16),
        ScalarType::F32 => open!(f32, F32),
    };
    let capacity = with_cache!(&cache, c => c.stats().capacity);
    let note = format!(
        "out of core: level {level} ({} × {} × {}), a rank's part{}, in {} bricks of {brick}³ \
         cells, their ranges ready in {:.0} ms ({:.1} MiB read); a cache of {capacity} bricks",
        grid.dims[0],
        grid.dims[1],
        grid.dims[2],
        if matches!(store, PartStore::Nrrd(_)) {
            " of a NRRD file"
        } else {
            ""
        },
        scan.bricks,
        super::ms(t0),
        scan.bytes_read as f64 / (1u64 << 20) as f64,
    );
    Ok(Paged {
        cache,
        bricks,
        grid,
        range: (lo as f64, hi as f64),
        preview: None,
        // The NRRD reader's own notes (how the world frame was taken), as a whole read gives.
        notes: match &store {
            PartStore::Nrrd(h) => h.notes().iter().cloned().chain([note]).collect(),
            PartStore::Zarr { .. } => vec![note],
        },
        part: Some(Part {
            level_bricks: scan.layout.brick_count(),
            range_is_level: scan.read.iter().all(|&r| r),
            scan,
            brick,
            level_bytes,
            file_bytes: counter,
            earlier: (0, 0),
        }),
    })
}

/// The box of voxels an X-ray brick of cells `owned` draws (`[lo, lo + dims)`, index space of
/// a level of `n` voxels): the voxels whose cell (`min(v, n − 2)`, the cell of which a voxel is
/// the lower corner; [`volsplat_splat::RenderSettings::owned_cells`]) lies in the box, i.e.
/// `[lo, hi)`, and the far face `n − 1` too where the box holds the last cell. Errors (naming
/// `owned_cells`) for a box that draws no voxel.
pub(super) fn xray_box(owned: [[usize; 3]; 2], n: [usize; 3]) -> Result<([usize; 3], [usize; 3])> {
    let [lo, hi] = owned;
    let end: [usize; 3] = std::array::from_fn(|a| {
        if hi[a] >= n[a].saturating_sub(1) {
            n[a]
        } else {
            hi[a]
        }
    });
    if (0..3).any(|a| lo[a] >= end[a]) {
        return Err(EngineError::request(
            "owned_cells",
            format!("{lo:?}..{hi:?} holds no voxel of a level of {n:?}"),
        ));
    }
    Ok((lo, std::array::from_fn(|a| end[a] - lo[a])))
}

/// The voxels `[lo, lo + dims)` of `cache`'s level as a volume of their own: the cache bricks
/// holding them made resident (read where they are not: only bricks of the rank's part, which
/// a restricted cache never leaves), their samples copied row by row, on the level's grid
/// shifted to the box (the same spacing and direction, the origin at voxel `lo`, in f64).
fn sub_volume<T: volsplat_core::Scalar>(
    cache: &mut BrickCache<T>,
    lo: [usize; 3],
    dims: [usize; 3],
) -> Result<volsplat_core::Volume<T>> {
    let layout = cache.layout().clone();
    let grid = layout.grid().clone();
    let last: [usize; 3] = std::array::from_fn(|a| lo[a] + dims[a] - 1);
    // The cache bricks whose owned voxels hold the box: those of its first to last voxel.
    let (Some(first), Some(end)) = (layout.brick_of_voxel(lo), layout.brick_of_voxel(last)) else {
        return Err(EngineError::request(
            "owned_cells",
            "the brick lies outside the level",
        ));
    };
    let mut keys = Vec::new();
    for k in first.b[2]..=end.b[2] {
        for j in first.b[1]..=end.b[1] {
            for i in first.b[0]..=end.b[0] {
                keys.extend(layout.key([i as usize, j as usize, k as usize]));
            }
        }
    }
    cache.make_resident(&keys)?;
    let count = dims.iter().product::<usize>();
    let mut data: Vec<T> = Vec::new();
    data.try_reserve_exact(count).map_err(|_| {
        EngineError::request(
            "owned_cells",
            format!("cannot allocate a brick of {dims:?} voxels"),
        )
    })?;
    let (arena, bases) = (cache.arena(), cache.bases());
    for k in lo[2]..=last[2] {
        for j in lo[1]..=last[1] {
            let mut i = lo[0];
            while i <= last[0] {
                let key = layout.brick_of_voxel([i, j, k]).ok_or_else(|| {
                    EngineError::request("owned_cells", "a voxel outside the level")
                })?;
                // The run of this row inside the brick's owned voxels.
                let run_end = layout.owned_voxels(key)?[0].end.min(last[0] + 1);
                let at = layout.slot_index(key, [i, j, k]).ok_or_else(|| {
                    EngineError::request("owned_cells", "a voxel outside its brick's slot")
                })?;
                let base = bases[cache.index(key.b.map(|x| x as usize))] as usize + at;
                data.extend_from_slice(&arena[base..base + (run_end - i)]);
                i = run_end;
            }
        }
    }
    let origin = grid.world_from_index(volsplat_core::glam::DVec3::new(
        lo[0] as f64,
        lo[1] as f64,
        lo[2] as f64,
    ));
    let sub = Grid::new(dims, grid.spacing, origin.to_array(), grid.direction)?;
    Ok(volsplat_core::Volume::new(sub, data)?)
}

impl Renderer {
    /// An X-ray brick's partial image (`owned`: its cells) from a sort-last rank's part of a
    /// store or a NRRD file with a raw payload (decision 0038): the voxels the brick draws
    /// ([`xray_box`]) read from the part's bricks, and the X-ray of that sub-volume drawn by
    /// the sheets or the splat list as any volume in memory, with the camera resolved from
    /// the level's grid (an explicit camera: an orbit or the reset view frame the whole
    /// level, not the brick), the offset of `xray_density` resolved from the level's range
    /// (shared by the ranks: [`Renderer::set_rank_range`]), and a crop box in voxels moved
    /// to the brick's indices. Every other choice of the sheets and the splat list depends on
    /// the grid's spacing and direction and on the camera, never on the volume's size or
    /// origin (sheet axis and spacing, footprints, anti-aliasing, kernel, the plan's row 7),
    /// so each voxel is drawn as in the whole volume, up to the f64 rounding of its position
    /// (`origin + D·S·(lo + i)` against `(origin + D·S·lo) + D·S·i`).
    pub(in crate::renderer) fn render_xray_part(
        &mut self,
        request: &RenderRequest,
        source: &VolumeSource,
        budget: u64,
        owned: [[usize; 3]; 2],
        progress: &mut (dyn FnMut(&crate::Progress) -> bool + Send),
    ) -> Result<crate::renderer::Output> {
        let threads = request.threads;
        let pool = Arc::clone(
            crate::renderer::cache::cached(&mut self.pool, threads, || {
                crate::renderer::cache::build_pool(threads)
            })?
            .value,
        );
        let fetched = self.paged(source, budget, request.memory, Some(owned), &pool)?;
        let part_notes = if fetched.fresh {
            fetched.value.notes.clone()
        } else {
            Vec::new()
        };
        let paged = self
            .paged
            .as_mut()
            .map(|c| &mut c.value)
            .ok_or_else(|| EngineError::request("volume", "the part's cache was dropped"))?;
        if let Some(part) = &paged.part {
            super::check_part(request, part)?;
            if request.scene.xray_density.is_auto() && !part.range_is_level {
                return Err(EngineError::request(
                    "xray_density",
                    "a brick rendered alone from a store knows only its own value range: the \
                     automatic X-ray offset needs the level's (render through \
                     distributed::render_sort_last, which shares it, or give an offset)",
                ));
            }
        }
        let grid = paged.grid.clone();
        let camera = request.scene.camera.resolve(grid.drawn_bounds_world())?;
        let (offset, _) = request.scene.xray_density.resolve(paged.range);
        let (lo, dims) = xray_box(owned, grid.dims)?;
        let cache = &mut paged.cache;
        let sub = pool.install(|| -> Result<volsplat_core::AnyVolume> {
            use volsplat_core::AnyVolume as V;
            Ok(match cache {
                AnyCache::U8(c) => V::U8(sub_volume(c, lo, dims)?),
                AnyCache::I8(c) => V::I8(sub_volume(c, lo, dims)?),
                AnyCache::U16(c) => V::U16(sub_volume(c, lo, dims)?),
                AnyCache::I16(c) => V::I16(sub_volume(c, lo, dims)?),
                AnyCache::F32(c) => V::F32(sub_volume(c, lo, dims)?),
            })
        })?;
        let mut brick = request.clone();
        brick.scene.volume = VolumeSource::Memory(Arc::new(sub));
        brick.scene.camera = crate::CameraSpec::Explicit {
            camera,
            orbit: Default::default(),
        };
        brick.scene.xray_density = match offset {
            Some(o) => crate::xray::XrayDensity::Offset(o),
            None => crate::xray::XrayDensity::Raw,
        };
        if let Some(crop) = &mut brick.scene.clipping.crop
            && crop.units == crate::scene::CropUnits::Voxels
        {
            for (a, &l) in lo.iter().enumerate() {
                crop.min[a] -= l as f64;
                crop.max[a] -= l as f64;
            }
        }
        let mut out = self.render_inner(&brick, progress, None, None)?;
        out.notes.splice(0..0, part_notes);
        Ok(out)
    }
}
