//! A sort-last rank's part of a file read in bricks (issue 32 item 2, decision 0038): an
//! OME-Zarr store's level ([`ZarrSource`]) or a NRRD file with a raw payload
//! ([`volsplat_io::nrrd::NrrdSource`]), opened as a brick source; only the bricks meeting the
//! rank's sort-last bricks are scanned for their ranges and ever read.

use super::{AnyCache, CHUNK_CACHE_SHARE, Paged, Part, arena_bytes, part_brick};
use crate::error::{EngineError, Result};
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
