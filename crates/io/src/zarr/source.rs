//! [`ZarrSource`]: the levels of an OME-Zarr store served brick by brick (the brick seam,
//! `docs/design/brick-seam.md` §4; issue 31 item 4), for a bounded cache that reads only the
//! bricks a frame needs.

use super::chunks::{Box3, FaceCache, copy_box};
use super::store::{ZarrSelection, ZarrStore};
use crate::error::{IoError, Result};
use std::marker::PhantomData;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use volsplat_core::source::{Brick, BrickKey, BrickLayout, BrickSource, HALO, pad_slot};
use volsplat_core::{Grid, Scalar, ScalarType};
use zarrs::array::ElementOwned;

/// A [`BrickSource`] over every level of an OME-Zarr store (one channel and time point, bricks
/// of `B` cells per side, halo 1): [`BrickSource::read_slot`] reads the brick's halo box
/// ([`BrickLayout::halo_voxels`], clamped to the level) chunk piece by chunk piece straight
/// into the slot and pads the slot's edge positions ([`volsplat_core::source::pad_slot`]), so
/// a brick holds the same samples as the brick of the level read whole
/// ([`ZarrStore::read_level`]) and served by [`volsplat_core::InMemory`];
/// [`BrickSource::brick`] is that slot with its ranges. Chunks absent from the store read as
/// the fill value.
/// [`BrickSource::whole`] is `None`: nothing is read whole.
///
/// **Chunk faces** ([`ZarrSource::with_chunk_cache`]): a brick's halo box overlaps up to 26
/// neighbouring chunks by a layer or two, and a chunk is decoded whole to read any part of
/// it; with a cache of the chunks' faces, a pass over a level decodes each chunk about once
/// instead of up to 27 times (decision 0039, amendment 1).
///
/// **Float levels** (decision 0030): a volume read whole replaces NaN and −∞ by the level's
/// lowest finite sample and +∞ by its highest. A brick cannot know those extremes, so a float
/// brick holding a non-finite sample is an error until the level's finite range is given
/// ([`ZarrSource::with_finite_range`], from a ranges scan of [`ZarrSource::as_stored`], e.g.
/// `volsplat_splat::cache::scan_level`); with it, bricks are replaced exactly as
/// [`volsplat_core::Volume::new`] replaces the whole level.
#[derive(Debug, Clone)]
pub struct ZarrSource<T> {
    store: Arc<ZarrStore>,
    selection: ZarrSelection,
    grids: Vec<Grid>,
    layouts: Vec<BrickLayout>,
    /// Per level: `[lowest, highest]` finite sample (data units), where given.
    finite: Vec<Option<[f32; 2]>>,
    /// Serve the samples as stored (non-finite floats kept), for a ranges scan.
    as_stored: bool,
    /// The faces of the chunks decoded last (shared by clones), if a cache was given.
    faces: Option<Arc<FaceCache<T>>>,
    /// Chunks decoded by brick reads (shared by clones).
    decodes: Arc<AtomicU64>,
    _sample: PhantomData<fn() -> T>,
}

impl<T: Scalar + ElementOwned> ZarrSource<T> {
    /// The levels of `store` (channel and time point `selection`) cut into bricks of `size`
    /// cells per side (a power of two and a multiple of 8, as [`BrickLayout::new`]); level `l`'s
    /// geometry is [`ZarrStore::grid`]`(l)`. Metadata only: no sample is read.
    ///
    /// Errors naming the store: a level whose samples do not read as `T`
    /// ([`volsplat_core::ScalarType`] of [`super::ZarrLevel::scalar_type`]), a channel or time
    /// point the store does not hold, a level beyond the limits, more than 256 levels, a bad
    /// brick size.
    pub fn new(store: Arc<ZarrStore>, selection: ZarrSelection, size: usize) -> Result<Self> {
        let path = store.path().to_path_buf();
        let n = store.levels().len();
        if n > usize::from(u8::MAX) + 1 {
            return Err(IoError::invalid_argument(
                &path,
                "levels",
                format!("the store holds {n} levels; a brick source serves at most 256"),
            ));
        }
        for (which, index, count) in [
            ("channel", selection.channel, store.channels()),
            ("timepoint", selection.timepoint, store.timepoints()),
        ] {
            if index as u64 >= count {
                return Err(IoError::invalid_argument(
                    &path,
                    which,
                    format!(
                        "{which} {index} requested, but the store holds {count} (0 to {})",
                        count - 1
                    ),
                ));
            }
        }
        let mut grids = Vec::with_capacity(n);
        let mut layouts = Vec::with_capacity(n);
        for (l, level) in store.levels().iter().enumerate() {
            if level.scalar_type != Some(T::TYPE) {
                return Err(IoError::invalid_argument(
                    &path,
                    "sample type",
                    format!(
                        "level {l} (array `{}`) holds {} samples, read as {}; a brick source of \
                         {} was asked for",
                        level.path,
                        level.data_type,
                        level.scalar_type.map_or("nothing", ScalarType::name),
                        T::TYPE.name()
                    ),
                ));
            }
            let grid = store.grid(l)?;
            let layout = BrickLayout::new(grid.clone(), l as u8, size)
                .map_err(|e| IoError::core(&path, e))?;
            grids.push(grid);
            layouts.push(layout);
        }
        Ok(ZarrSource {
            store,
            selection,
            grids,
            layouts,
            finite: vec![None; n],
            as_stored: false,
            faces: None,
            decodes: Arc::default(),
            _sample: PhantomData,
        })
    }

    /// This source with a cache of decoded chunks' faces of at most `bytes` bytes (shared by
    /// its clones, [`ZarrSource::as_stored`] included): the slivers of neighbouring chunks
    /// that a brick's halo needs are copied from the faces of chunks decoded before (kept
    /// for the least recently used chunks first), so a pass over a level decodes each chunk
    /// about once (at most twice) instead of once per brick that touches it. Charge `bytes`
    /// to the memory budget: the cache holds at most that many bytes of faces (14 % of a 64³
    /// chunk each: 72 KiB for u16), plus one decoded chunk per thread while it is cut. 0
    /// turns the cache off (the default). The samples served are the same either way.
    pub fn with_chunk_cache(mut self, bytes: u64) -> Self {
        self.faces = (bytes > 0).then(|| Arc::new(FaceCache::new(bytes)));
        self
    }

    /// The byte capacity of the chunk faces cache ([`ZarrSource::with_chunk_cache`]; 0 for
    /// none).
    pub fn chunk_cache_bytes(&self) -> u64 {
        self.faces.as_ref().map_or(0, |f| f.capacity())
    }

    /// Chunks decoded so far by this source's brick reads and its clones' (each read of a
    /// store region inside one chunk counts one decode; a brick read without chunk edges
    /// counts one): for tests and benchmarks of the read path.
    pub fn chunk_decodes(&self) -> u64 {
        self.decodes.load(Ordering::Relaxed)
    }

    /// The store.
    pub fn store(&self) -> &Arc<ZarrStore> {
        &self.store
    }

    /// The channel and time point served.
    pub fn selection(&self) -> ZarrSelection {
        self.selection
    }

    /// This source with level `level`'s finite sample range `[lowest, highest]` (data units: the
    /// lowest and highest finite samples of the whole level, as a ranges scan of
    /// [`ZarrSource::as_stored`] finds them): NaN and −∞ samples of the level's bricks become
    /// `lowest`, +∞ become `highest` (decision 0030), as [`volsplat_core::Volume::new`] does for
    /// the level read whole. Errors (naming the store and `finite range`) for a level the store
    /// lacks, a bound that is not finite, or `lowest > highest`.
    pub fn with_finite_range(mut self, level: usize, range: [f32; 2]) -> Result<Self> {
        let path = self.store.path();
        if level >= self.layouts.len() {
            return Err(IoError::invalid_argument(
                path,
                "level",
                format!(
                    "level {level} requested, but the store holds {} levels",
                    self.layouts.len()
                ),
            ));
        }
        if !(range[0].is_finite() && range[1].is_finite() && range[0] <= range[1]) {
            return Err(IoError::invalid_argument(
                path,
                "finite range",
                format!("{range:?} for level {level}: must be two finite values, lowest ≤ highest"),
            ));
        }
        self.finite[level] = Some(range);
        Ok(self)
    }

    /// Level `level`'s finite sample range given by [`ZarrSource::with_finite_range`], if any.
    pub fn finite_range(&self, level: usize) -> Option<[f32; 2]> {
        self.finite.get(level).copied().flatten()
    }

    /// A copy of this source that serves the samples as stored: non-finite floats are kept
    /// (and so enter the bricks' ranges as ±∞; NaN is ignored by the ranges), never an error.
    /// For the ranges scan that finds each level's finite range, not for rendering.
    pub fn as_stored(&self) -> Self {
        ZarrSource {
            as_stored: true,
            ..self.clone()
        }
    }

    /// The chunk edges of `level` along x, y and z (samples; the spatial axes are the last
    /// ones, x last), or `None` where they are not known (fewer than three axes).
    fn chunk_edges(&self, level: usize) -> Option<[usize; 3]> {
        let c = &self.store.levels().get(level)?.chunks;
        let n = c.len();
        if n < 3 {
            return None;
        }
        let e = [c[n - 1], c[n - 2], c[n - 3]].map(|x| usize::try_from(x).unwrap_or(0));
        e.iter().all(|&x| x > 0).then_some(e)
    }

    /// Writes the box `whole` of `level` (index space) into `dst`, the samples of the box
    /// `into` (x fastest), both boxes and every piece shifted by `shift` voxels per axis (so
    /// that a slot's box, which starts `H` voxels before the level at a low face, has no
    /// negative corner), reading one chunk at a time: the box is cut at the level's chunk
    /// edges and each piece read on its own ([`ZarrStore::read_region`] of a piece inside one
    /// chunk decodes that chunk alone), so a brick's read holds one decoded chunk at a time
    /// instead of every chunk its halo box overlaps (up to 27 for bricks as large as the
    /// chunks) decoded in parallel; bricks are read in parallel by the cache instead
    /// (BENCHMARKS §31). With a chunk cache ([`ZarrSource::with_chunk_cache`]) a piece inside a
    /// chunk's faces is copied from them (the chunk decoded once for its faces), and a chunk
    /// decoded whole leaves its faces.
    fn read_by_chunks(
        &self,
        level: usize,
        whole: Box3,
        dst: &mut [T],
        into: Box3,
        shift: usize,
    ) -> Result<()> {
        let (lo, hi) = (whole.lo, whole.hi);
        let Some(edge) = self.chunk_edges(level) else {
            let v = self.read(level, lo, hi)?;
            copy_box(&v, whole.shifted(shift), dst, into, whole.shifted(shift));
            return Ok(());
        };
        // The cuts along each axis: lo, the chunk edges inside, hi.
        let cuts: [Vec<usize>; 3] = std::array::from_fn(|a| {
            let mut c = vec![lo[a]];
            let mut x = (lo[a] / edge[a] + 1) * edge[a];
            while x < hi[a] {
                c.push(x);
                x += edge[a];
            }
            c.push(hi[a]);
            c
        });
        let (cache, large) = self.chunk_policy(level, edge);
        for z in cuts[2].windows(2) {
            for y in cuts[1].windows(2) {
                for x in cuts[0].windows(2) {
                    let piece = Box3 {
                        lo: [x[0], y[0], z[0]],
                        hi: [x[1], y[1], z[1]],
                    };
                    let (from, v) = match cache {
                        Some(c) => self.read_cached(c, level, edge, large, piece)?,
                        None => (piece, Held::Own(self.read(level, piece.lo, piece.hi)?)),
                    };
                    copy_box(
                        v.samples(),
                        from.shifted(shift),
                        dst,
                        into,
                        piece.shifted(shift),
                    );
                }
            }
        }
        Ok(())
    }

    /// Reads `[lo, hi)` of `level` from the store (one decode per chunk it meets; counted).
    fn read(&self, level: usize, lo: [usize; 3], hi: [usize; 3]) -> Result<Vec<T>> {
        self.decodes.fetch_add(1, Ordering::Relaxed);
        self.store.read_region::<T>(
            level,
            self.selection,
            lo.map(|x| x as u64),
            hi.map(|x| x as u64),
        )
    }

    /// How chunks of `level` (of `edge` samples per side) go through the chunk faces cache:
    /// the cache, where a chunk decoded whole takes at most an eighth of it (a shard, for
    /// sharded arrays), and whether chunks are kept whole. A chunk larger than a brick along
    /// some axis serves several bricks' inner pieces: the cache keeps it whole where it holds
    /// the chunks that a row of bricks read in index order (x fastest) meets, so that the next
    /// rows find them (BENCHMARKS §36: fewer thrash and decode more than the faces); other
    /// chunks leave their faces.
    fn chunk_policy(&self, level: usize, edge: [usize; 3]) -> (Option<&FaceCache<T>>, bool) {
        let bytes = (edge.iter().product::<usize>() * std::mem::size_of::<T>()) as u64;
        let layout = &self.layouts[level];
        let row = row_chunks(self.grids[level].dims, edge, layout.extent());
        let large = edge.iter().any(|&e| e > layout.size())
            && self
                .faces
                .as_deref()
                .is_some_and(|c| bytes.saturating_mul(row) <= c.capacity());
        let cache = self
            .faces
            .as_deref()
            .filter(|c| bytes.saturating_mul(8) <= c.capacity());
        (cache, large)
    }

    /// The samples holding `piece` (inside one chunk of `level`, whose chunks have `edge`
    /// samples per side), with their box, through the chunk faces cache `cache`
    /// ([`ZarrSource::chunk_for`]).
    fn read_cached(
        &self,
        cache: &FaceCache<T>,
        level: usize,
        edge: [usize; 3],
        large: bool,
        piece: Box3,
    ) -> Result<(Box3, Held<T>)> {
        let c: [usize; 3] = std::array::from_fn(|a| piece.lo[a] / edge[a]);
        Ok(
            match self.chunk_for(Some(cache), level, edge, large, c, &[piece])? {
                Chunk::Faces(f) => {
                    let b = f.find_box(&piece).ok_or_else(|| {
                        IoError::invalid_argument(
                            self.store.path(),
                            "chunk",
                            format!("level {level} chunk {c:?}: no face holds {piece:?}"),
                        )
                    })?;
                    (b, Held::Faces(f, piece))
                }
                Chunk::Own(b, v) => (b, Held::Own(v)),
            },
        )
    }

    /// What the `pieces` of chunk `c` of `level` (chunks of `edge` samples per side) are
    /// copied from: with the chunk faces cache `cache`, for `large` chunks (larger than a
    /// brick) the whole chunk, kept (decoded once while it is held); otherwise the chunk's
    /// faces where every piece lies in one of them (the chunk decoded for its faces if they
    /// are not held), else the chunk decoded whole, whose faces are then kept. Without a cache,
    /// the chunk decoded whole.
    fn chunk_for(
        &self,
        cache: Option<&FaceCache<T>>,
        level: usize,
        edge: [usize; 3],
        large: bool,
        c: [usize; 3],
        pieces: &[Box3],
    ) -> Result<Chunk<T>> {
        let n = self.grids[level].dims;
        let chunk = Box3 {
            lo: std::array::from_fn(|a| c[a] * edge[a]),
            hi: std::array::from_fn(|a| ((c[a] + 1) * edge[a]).min(n[a])),
        };
        let decode = || -> Result<(Box3, Vec<T>)> {
            let v = self.read(level, chunk.lo, chunk.hi)?;
            if v.len() != chunk.len() {
                return Err(IoError::invalid_argument(
                    self.store.path(),
                    "chunk",
                    format!(
                        "level {level} chunk {c:?} read {} samples, not {}",
                        v.len(),
                        chunk.len()
                    ),
                ));
            }
            Ok((chunk, v))
        };
        let Some(cache) = cache else {
            let (_, v) = decode()?;
            return Ok(Chunk::Own(chunk, v));
        };
        if large {
            return Ok(Chunk::Faces(cache.faces((level, c), true, decode)?));
        }
        let faces = super::chunks::face_boxes(chunk);
        let thin = pieces.iter().all(|p| faces.iter().any(|f| f.contains(p)));
        if thin {
            let f = cache.faces((level, c), false, decode)?;
            if pieces.iter().all(|p| f.find_box(p).is_some()) {
                return Ok(Chunk::Faces(f));
            }
        }
        let (_, v) = decode()?;
        cache.offer((level, c), chunk, &v);
        Ok(Chunk::Own(chunk, v))
    }

    /// Replaces the non-finite samples of brick `key`'s slot (float levels) by level
    /// `level`'s finite range, or errors (the cause, for the brick's error) if there are some
    /// and no range was given (counted over the slot's interior, each voxel once).
    fn replace_non_finite(
        &self,
        level: usize,
        layout: &BrickLayout,
        key: BrickKey,
        slot: &mut [T],
    ) -> std::result::Result<(), String> {
        if T::TYPE != ScalarType::F32 || self.as_stored {
            return Ok(());
        }
        if slot.iter().all(|v| v.to_f32().is_finite()) {
            return Ok(());
        }
        let Some([lo, hi]) = self.finite[level] else {
            let e = layout.extent();
            let inner = layout.slot_interior(key).map_err(|e| e.to_string())?;
            let mut bad = 0;
            for z in inner[2].clone() {
                for y in inner[1].clone() {
                    let row = (z * e + y) * e;
                    bad += slot[row + inner[0].start..row + inner[0].end]
                        .iter()
                        .filter(|v| !v.to_f32().is_finite())
                        .count();
                }
            }
            return Err(format!(
                "{bad} samples of the brick's box are NaN or infinite, which become the level's \
                 finite extremes (decision 0030); scan the level's ranges first (a brick-by-brick \
                 pass, e.g. volsplat_splat::cache::scan_level over ZarrSource::as_stored) and give \
                 ZarrSource::with_finite_range its finite range"
            ));
        };
        let (lo, hi) = (T::from_f64(f64::from(lo)), T::from_f64(f64::from(hi)));
        for v in slot.iter_mut() {
            let x = v.to_f32();
            if x.is_nan() || x == f32::NEG_INFINITY {
                *v = lo;
            } else if x == f32::INFINITY {
                *v = hi;
            }
        }
        Ok(())
    }
}

/// The chunks (of `edge` samples per side, on a level of `dims` voxels) that a row of bricks
/// along x meets, each brick's box `extent` voxels per side: every chunk along x, and along y
/// and z those a box of `extent` voxels can meet (`⌈extent / edge⌉ + 1`, at most the level's).
fn row_chunks(dims: [usize; 3], edge: [usize; 3], extent: usize) -> u64 {
    (0..3)
        .map(|a| {
            let all = dims[a].div_ceil(edge[a]).max(1);
            if a == 0 {
                all
            } else {
                (extent.div_ceil(edge[a]) + 1).min(all)
            }
        })
        .product::<usize>() as u64
}

/// What a chunk's pieces are copied from ([`ZarrSource::chunk_for`]): faces held by the
/// cache (or the whole chunk kept there), or the chunk decoded (its box and samples).
enum Chunk<T> {
    Faces(Arc<super::chunks::Faces<T>>),
    Own(Box3, Vec<T>),
}

impl<T: Copy> Chunk<T> {
    /// The box and samples holding `piece`.
    fn holding(&self, piece: &Box3) -> Option<(Box3, &[T])> {
        match self {
            Chunk::Faces(f) => f.find(piece),
            Chunk::Own(b, v) => b.contains(piece).then_some((*b, &v[..])),
        }
    }
}

/// Samples a piece is copied from: a chunk decoded for it, or the faces of a chunk (kept
/// alive by the `Arc` while they are copied; the piece names the face).
enum Held<T> {
    Own(Vec<T>),
    Faces(Arc<super::chunks::Faces<T>>, Box3),
}

impl<T: Copy> Held<T> {
    fn samples(&self) -> &[T] {
        match self {
            Held::Own(v) => v,
            Held::Faces(f, piece) => f.find(piece).map_or(&[], |(_, v)| v),
        }
    }
}
impl<T: Scalar + ElementOwned> BrickSource<T> for ZarrSource<T> {
    fn levels(&self) -> &[Grid] {
        &self.grids
    }

    fn layout(&self, level: usize) -> Option<&BrickLayout> {
        self.layouts.get(level)
    }

    /// Unknown without reading the store: always `None`.
    fn brick_range(&self, _key: BrickKey) -> Option<[f32; 2]> {
        None
    }

    fn brick(&self, key: BrickKey) -> volsplat_core::Result<Arc<Brick<T>>> {
        let layout = self.layout_or_error(key)?;
        let mut slot = Vec::new();
        slot.try_reserve_exact(layout.slot_len())
            .map_err(|_| key.error("cannot allocate the brick's slot"))?;
        slot.resize(layout.slot_len(), T::from_f64(0.0));
        self.read_slot(key, &mut slot)?;
        Brick::from_slot(layout, key, slot.into_boxed_slice()).map(Arc::new)
    }

    /// The brick's halo box read chunk piece by chunk piece straight into the slot's interior
    /// ([`BrickLayout::slot_interior`]), the edge positions padded ([`pad_slot`]), non-finite
    /// floats replaced: [`BrickSource::brick`]'s slot, with no region allocated.
    fn read_slot(&self, key: BrickKey, slot: &mut [T]) -> volsplat_core::Result<()> {
        let level = usize::from(key.level);
        let layout = self.layout_or_error(key)?;
        layout.check_slot_len(key, slot.len())?;
        let halo = layout.halo_voxels(key)?;
        let whole = Box3 {
            lo: halo.clone().map(|r| r.start),
            hi: halo.map(|r| r.end),
        };
        // The slot's box, shifted by H: voxel B·b − H + l sits at B·b + l.
        let b = layout.check(key)?;
        let e = layout.extent();
        let into = Box3 {
            lo: b.map(|x| x * layout.size()),
            hi: b.map(|x| x * layout.size() + e),
        };
        self.read_by_chunks(level, whole, slot, into, HALO)
            .map_err(|e| key.error(e.to_string()))?;
        pad_slot(layout, key, slot)?;
        self.replace_non_finite(level, layout, key, slot)
            .map_err(|cause| key.error(format!("{}: {cause}", self.store.path().display())))
    }

    /// The bricks' halo boxes read chunk by chunk: each chunk that some of the batch's boxes
    /// meet is decoded (or found in the chunk faces cache) once, and its pieces copied into
    /// every slot that needs them (chunks in parallel); then each slot is padded and its
    /// non-finite floats replaced, as [`BrickSource::read_slot`]. `None` for a batch of several
    /// levels or a level without a 3-D chunk grid.
    fn read_slots(
        &self,
        keys: &[BrickKey],
        slots: &mut [&mut [T]],
    ) -> Option<volsplat_core::Result<()>> {
        let level = usize::from(keys.first()?.level);
        if keys.iter().any(|k| usize::from(k.level) != level) || keys.len() != slots.len() {
            return None;
        }
        let edge = self.chunk_edges(level)?;
        if self.chunk_policy(level, edge).1 {
            return None;
        }
        Some(self.read_batch(level, edge, keys, slots))
    }
}

impl<T: Scalar + ElementOwned> ZarrSource<T> {
    /// [`BrickSource::read_slots`] for bricks of one `level` whose chunks have `edge` samples
    /// per side.
    fn read_batch(
        &self,
        level: usize,
        edge: [usize; 3],
        keys: &[BrickKey],
        slots: &mut [&mut [T]],
    ) -> volsplat_core::Result<()> {
        use rayon::prelude::*;
        use std::collections::BTreeMap;
        use std::sync::Mutex;
        let Some(&first) = keys.first() else {
            return Ok(());
        };
        let layout = self.layout_or_error(first)?;
        let e = layout.extent();
        // Per brick: the slot's box shifted by H; per chunk met: the (brick, piece) pairs.
        let mut into = Vec::with_capacity(keys.len());
        let mut by_chunk: BTreeMap<[usize; 3], Vec<(usize, Box3)>> = BTreeMap::new();
        for (i, (&key, slot)) in keys.iter().zip(slots.iter()).enumerate() {
            layout.check_slot_len(key, slot.len())?;
            let b = layout.check(key)?;
            let halo = layout.halo_voxels(key)?;
            into.push(Box3 {
                lo: b.map(|x| x * layout.size()),
                hi: b.map(|x| x * layout.size() + e),
            });
            let c0: [usize; 3] = std::array::from_fn(|a| halo[a].start / edge[a]);
            let c1: [usize; 3] = std::array::from_fn(|a| (halo[a].end - 1) / edge[a]);
            for cz in c0[2]..=c1[2] {
                for cy in c0[1]..=c1[1] {
                    for cx in c0[0]..=c1[0] {
                        let c = [cx, cy, cz];
                        let piece = Box3 {
                            lo: std::array::from_fn(|a| halo[a].start.max(c[a] * edge[a])),
                            hi: std::array::from_fn(|a| halo[a].end.min((c[a] + 1) * edge[a])),
                        };
                        by_chunk.entry(c).or_default().push((i, piece));
                    }
                }
            }
        }
        let (cache, large) = self.chunk_policy(level, edge);
        let dst: Vec<Mutex<&mut [T]>> = slots.iter_mut().map(|s| Mutex::new(&mut **s)).collect();
        let chunks: Vec<_> = by_chunk.into_iter().collect();
        chunks.par_iter().try_for_each(|(c, pieces)| {
            let boxes: Vec<Box3> = pieces.iter().map(|&(_, p)| p).collect();
            let name = |e: IoError| keys[pieces[0].0].error(e.to_string());
            let got = self
                .chunk_for(cache, level, edge, large, *c, &boxes)
                .map_err(name)?;
            for &(i, piece) in pieces {
                let (from, v) = got.holding(&piece).ok_or_else(|| {
                    keys[i].error(format!("chunk {c:?} does not hold the piece {piece:?}"))
                })?;
                let mut slot = dst[i].lock().unwrap_or_else(|p| p.into_inner());
                copy_box(
                    v,
                    from.shifted(HALO),
                    &mut slot,
                    into[i],
                    piece.shifted(HALO),
                );
            }
            Ok::<(), volsplat_core::CoreError>(())
        })?;
        drop(dst);
        slots
            .par_iter_mut()
            .zip(keys.par_iter())
            .try_for_each(|(slot, &key)| {
                pad_slot(layout, key, slot)?;
                self.replace_non_finite(level, layout, key, slot)
                    .map_err(|cause| key.error(format!("{}: {cause}", self.store.path().display())))
            })
    }
}

impl<T: Scalar + ElementOwned> ZarrSource<T> {
    /// Level `key.level`'s layout, or the brick's error naming the store's level count.
    fn layout_or_error(&self, key: BrickKey) -> volsplat_core::Result<&BrickLayout> {
        self.layouts.get(usize::from(key.level)).ok_or_else(|| {
            key.error(format!(
                "the store {} holds {} levels",
                self.store.path().display(),
                self.layouts.len()
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zarr::{ZarrVersion, ZarrWriteOptions, write_zarr};
    use crate::{Limits, ZarrStore};
    use std::path::{Path, PathBuf};
    use volsplat_core::glam::DMat3;
    use volsplat_core::{AnyVolume, CoreError, InMemory, Volume};

    /// Distinct-ish samples of every type: `f(i, j, k)` in `T`'s range.
    fn volume<T: Scalar>(dims: [usize; 3]) -> Volume<T> {
        let grid = Grid::new(dims, [0.5; 3], [1.0, -2.0, 3.0], DMat3::IDENTITY).unwrap();
        Volume::from_fn(grid, |i, j, k| {
            T::from_f64(((i * 7 + j * 13 + k * 101) % 251) as f64 - 100.0)
        })
        .unwrap()
    }

    fn write(dir: &Path, v: AnyVolume, chunk: usize, version: ZarrVersion) -> PathBuf {
        let p = dir.join(format!("s{chunk}.zarr"));
        let o = ZarrWriteOptions::default()
            .with_chunk(chunk)
            .with_version(version);
        write_zarr(&p, &v, &o).unwrap();
        p
    }

    fn keys(l: &BrickLayout) -> Vec<BrickKey> {
        let d = l.dims();
        let mut out = Vec::new();
        for k in 0..d[2] {
            for j in 0..d[1] {
                for i in 0..d[0] {
                    out.push(l.key([i, j, k]).unwrap());
                }
            }
        }
        out
    }

    /// Every brick of levels 0 and 1 equals the brick of the level read whole, served in memory.
    fn assert_bricks_equal_whole<T: Scalar + ElementOwned>(
        store: &Arc<ZarrStore>,
        source: &ZarrSource<T>,
        size: usize,
    ) -> usize {
        let mut n = 0;
        for level in 0..2 {
            // The level read whole, as `ZarrStore::read_level` reads it.
            let d = store.levels()[level].dims;
            let data = store
                .read_region::<T>(level, ZarrSelection::default(), [0; 3], d)
                .unwrap();
            let whole = Volume::new(store.grid(level).unwrap(), data).unwrap();
            let mem = InMemory::new(Arc::new(whole), size).unwrap();
            let l = source.layout(level).unwrap();
            assert_eq!(l.grid(), mem.layout(0).unwrap().grid());
            assert_eq!(l.dims(), mem.layout(0).unwrap().dims());
            for key in keys(l) {
                let got = source.brick(key).unwrap();
                let want = mem.brick(BrickKey { level: 0, ..key }).unwrap();
                assert_eq!(got.key, key);
                assert!(got.data == want.data, "level {level} {key:?} B = {size}");
                assert_eq!(got.ranges8, want.ranges8, "level {level} {key:?}");
                assert_eq!(got.range, want.range, "level {level} {key:?}");
                n += 1;
            }
        }
        assert!(source.whole(0).unwrap().is_none());
        n
    }

    fn every_brick_equals_the_in_memory_brick<T: Scalar + ElementOwned>()
    where
        AnyVolume: From<Volume<T>>,
    {
        let dir = tempfile::tempdir().unwrap();
        for (chunk, version) in [(16, ZarrVersion::V2), (32, ZarrVersion::V3)] {
            let p = write(dir.path(), volume::<T>([45, 37, 34]).into(), chunk, version);
            let store = Arc::new(ZarrStore::open(&p, &Limits::default()).unwrap());
            assert!(store.levels().len() >= 2, "{chunk}");
            for size in [8, 16, 64] {
                let s =
                    ZarrSource::<T>::new(store.clone(), ZarrSelection::default(), size).unwrap();
                assert_eq!(s.levels().len(), store.levels().len());
                let n = assert_bricks_equal_whole(&store, &s, size);
                assert!(n >= 2, "{n}");
                // Through a chunk faces cache: too small for the 32³ chunks of f32 (read
                // piece by piece), holding a few chunks' faces, holding them all.
                for bytes in [256 << 10, 64 << 10, 8 << 20] {
                    let c = s.clone().with_chunk_cache(bytes);
                    assert_eq!(c.chunk_cache_bytes(), bytes);
                    assert_eq!(assert_bricks_equal_whole(&store, &c, size), n);
                }
            }
        }
    }

    /// A u16 store of `dims` in chunks of `chunk` samples in `dir`, and its source in bricks of
    /// 16 cells.
    fn u16_source(dir: &Path, dims: [usize; 3], chunk: usize) -> (Arc<ZarrStore>, ZarrSource<u16>) {
        let p = write(dir, volume::<u16>(dims).into(), chunk, ZarrVersion::V2);
        let store = Arc::new(ZarrStore::open(&p, &Limits::default()).unwrap());
        let s = ZarrSource::<u16>::new(store.clone(), ZarrSelection::default(), 16).unwrap();
        (store, s)
    }

    /// Chunk decodes of a pass over every brick of an 80 × 64 × 80 u16 level (bricks of 16
    /// cells: 100), in batches of 8 read by `threads` threads, with chunks of `chunk` samples
    /// and a chunk cache of `cache` bytes; and the level's chunk count.
    fn decodes_of_a_pass(chunk: usize, cache: u64, threads: usize) -> (u64, usize) {
        let dir = tempfile::tempdir().unwrap();
        let dims = [80, 64, 80];
        let (store, s) = u16_source(dir.path(), dims, chunk);
        let s = s.with_chunk_cache(cache);
        let all = keys(s.layout(0).unwrap());
        assert_eq!(all.len(), 100);
        let chunks = dims.iter().map(|d| d.div_ceil(chunk)).product();
        for batch in all.chunks(8) {
            std::thread::scope(|scope| {
                for t in 0..threads {
                    let s = &s;
                    scope.spawn(move || {
                        for key in batch.iter().skip(t).step_by(threads) {
                            s.brick(*key).unwrap();
                        }
                    });
                }
            });
        }
        // And the bricks are those of the level read whole.
        let before = s.chunk_decodes();
        assert_bricks_equal_whole(&store, &s, 16);
        assert!(s.chunk_decodes() > before);
        (before, chunks)
    }

    #[test]
    fn a_pass_over_a_level_decodes_each_chunk_at_most_twice_through_the_chunk_cache() {
        // Without the cache: once per brick that meets the chunk (27 for most).
        let (n, chunks) = decodes_of_a_pass(16, 0, 1);
        assert!(n >= 8 * chunks as u64, "{n} decodes of {chunks} chunks");
        // With a cache holding three planes of chunks' faces and a row (65 × 4.5 KiB: a
        // brick's halo meets the planes below, at and above it), or all of them, on one
        // thread or four.
        for (cache, threads) in [(320 << 10, 1), (320 << 10, 4), (64 << 20, 4)] {
            let (n, chunks) = decodes_of_a_pass(16, cache, threads);
            assert!(
                n <= 2 * chunks as u64,
                "{n} decodes of {chunks} chunks, cache {cache}, {threads} threads"
            );
            assert!(n >= chunks as u64, "{n}");
        }
    }

    /// Chunks larger than the bricks (32³ chunks, bricks of 16 cells: each chunk holds the
    /// inner pieces of 8 bricks and the halos of more) are kept whole: a pass decodes each
    /// about once, instead of once per brick meeting it.
    #[test]
    fn chunks_larger_than_bricks_are_decoded_about_once_per_pass() {
        let (n, chunks) = decodes_of_a_pass(32, 0, 1);
        assert_eq!(chunks, 18);
        assert!(n >= 8 * chunks as u64, "{n} decodes of {chunks} chunks");
        let none = n;
        // 64 KiB chunks, 3 along x: a cache of 16 holds every chunk (measured: each decoded
        // once), one of 12 the 3 × 2 × 2 chunks a row of bricks meets; one of 4 is not used (a
        // chunk may take at most an eighth of the cache).
        for (cache, threads, most) in [(1 << 20, 1, 2), (1 << 20, 4, 2), (768 << 10, 1, 2)] {
            let (n, chunks) = decodes_of_a_pass(32, cache, threads);
            assert!(
                n <= most * chunks as u64,
                "{n} decodes of {chunks} chunks, cache {cache}, {threads} threads"
            );
            assert!(n >= chunks as u64, "{n}");
        }
        let (n, _) = decodes_of_a_pass(32, 256 << 10, 1);
        assert_eq!(n, none, "a cache of 4 chunks is not used");
    }

    /// A batch read (`read_slots`) gives every brick's slot, as `brick()` does one by one, and
    /// decodes each chunk the batch meets once (no cache), for chunks smaller than, equal to
    /// and larger than the bricks, on ordinary levels and on thin ones (axes of one or two
    /// voxels, where every slot is mostly padding).
    #[test]
    fn a_batch_read_decodes_each_chunk_once_and_gives_the_bricks_slots() {
        let cases = [8, 16, 32].into_iter().map(|c| (c, [40, 30, 36])).chain([
            (8, [1, 2, 19]),
            (16, [17, 1, 33]),
            (32, [2, 40, 1]),
        ]);
        for (chunk, dims) in cases {
            let dir = tempfile::tempdir().unwrap();
            let (_, s) = u16_source(dir.path(), dims, chunk);
            let l = s.layout(0).unwrap().clone();
            let all = keys(&l);
            let mut bufs = vec![vec![0u16; l.slot_len()]; all.len()];
            let mut slots: Vec<&mut [u16]> = bufs.iter_mut().map(|b| &mut b[..]).collect();
            let before = s.chunk_decodes();
            s.read_slots(&all, &mut slots).unwrap().unwrap();
            let chunks: u64 = dims.iter().map(|d| d.div_ceil(chunk) as u64).product();
            assert_eq!(s.chunk_decodes() - before, chunks, "chunk {chunk} {dims:?}");
            for (k, b) in all.iter().zip(&bufs) {
                assert_eq!(
                    **b,
                    *s.brick(*k).unwrap().data,
                    "chunk {chunk} {dims:?} {k:?}"
                );
            }
            // A short slot is an error naming the brick.
            let mut short = [0u16; 5];
            let e = s
                .read_slots(&all[..1], &mut [&mut short[..]])
                .unwrap()
                .unwrap_err();
            assert!(e.to_string().contains("slot"), "{e}");
        }
    }

    #[test]
    fn zarr_bricks_equal_in_memory_bricks_u8() {
        every_brick_equals_the_in_memory_brick::<u8>();
    }

    #[test]
    fn zarr_bricks_equal_in_memory_bricks_i16() {
        every_brick_equals_the_in_memory_brick::<i16>();
    }

    #[test]
    fn zarr_bricks_equal_in_memory_bricks_u16() {
        every_brick_equals_the_in_memory_brick::<u16>();
    }

    #[test]
    fn zarr_bricks_equal_in_memory_bricks_f32() {
        every_brick_equals_the_in_memory_brick::<f32>();
    }

    /// Writes `values` at voxels `at` (x, y, z) of level `level`, through zarrs.
    fn poke(p: &Path, level: usize, at: &[([u64; 3], f32)]) {
        let store = Arc::new(zarrs::filesystem::FilesystemStore::new(p).unwrap());
        let a = zarrs::array::Array::open(store, &format!("/{level}")).unwrap();
        for &([x, y, z], v) in at {
            let s = zarrs::array::ArraySubset::new_with_ranges(&[z..z + 1, y..y + 1, x..x + 1]);
            a.store_array_subset(&s, &[v][..]).unwrap();
        }
    }

    #[test]
    fn float_bricks_with_nan_and_infinities_equal_the_replaced_whole_level() {
        let dir = tempfile::tempdir().unwrap();
        for (chunk, version) in [(16, ZarrVersion::V2), (32, ZarrVersion::V3)] {
            let p = write(
                dir.path(),
                volume::<f32>([45, 37, 34]).into(),
                chunk,
                version,
            );
            // NaN, +∞ and −∞ on level 0, a NaN on level 1 (on a brick seam at B = 8 and 16).
            poke(
                &p,
                0,
                &[
                    ([3, 4, 5], f32::NAN),
                    ([16, 8, 0], f32::INFINITY),
                    ([44, 36, 33], f32::NEG_INFINITY),
                ],
            );
            poke(&p, 1, &[([8, 8, 8], f32::NAN)]);
            let store = Arc::new(ZarrStore::open(&p, &Limits::default()).unwrap());
            // The finite range of each level, found by hand from the samples as stored.
            let finite = |l: usize| {
                let d = store.levels()[l].dims;
                let raw = store
                    .read_region::<f32>(l, ZarrSelection::default(), [0; 3], d)
                    .unwrap();
                assert!(
                    raw.iter().any(|x| !x.is_finite()),
                    "level {l} holds non-finite"
                );
                raw.iter()
                    .filter(|x| x.is_finite())
                    .fold([f32::INFINITY, f32::NEG_INFINITY], |r, &x| {
                        [r[0].min(x), r[1].max(x)]
                    })
            };
            for size in [8, 16, 64] {
                let plain =
                    ZarrSource::<f32>::new(store.clone(), ZarrSelection::default(), size).unwrap();
                // Without the range: the bricks holding them are errors naming the brick and the
                // scan; the others read.
                let l0 = plain.layout(0).unwrap().clone();
                let bad = l0.brick_of_voxel([3, 4, 5]).unwrap();
                let e = plain.brick(bad).unwrap_err();
                assert!(
                    matches!(e, CoreError::Brick { level: 0, brick, .. } if brick == bad.b),
                    "{e}"
                );
                let text = e.to_string();
                assert!(
                    text.contains("scan") && text.contains(".zarr") && text.contains("level 0"),
                    "{text}"
                );
                let far = l0.brick_of_voxel([30, 30, 30]).unwrap();
                if far != bad {
                    plain.brick(far).unwrap();
                }
                // As stored: the NaN is there.
                let raw = plain.as_stored().brick(bad).unwrap();
                assert!(raw.data[l0.slot_index(bad, [3, 4, 5]).unwrap()].is_nan());
                let s = plain
                    .clone()
                    .with_finite_range(0, finite(0))
                    .unwrap()
                    .with_finite_range(1, finite(1))
                    .unwrap();
                assert_bricks_equal_whole(&store, &s, size);
                // Bad ranges are refused.
                for r in [[1.0, 0.0], [f32::NAN, 1.0], [0.0, f32::INFINITY]] {
                    let e = plain.clone().with_finite_range(0, r).unwrap_err();
                    assert!(e.to_string().contains("finite range"), "{e}");
                }
                assert!(plain.clone().with_finite_range(9, [0.0, 1.0]).is_err());
            }
        }
    }

    #[test]
    fn a_deleted_chunk_reads_as_the_fill_value() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            dir.path(),
            volume::<u16>([40, 20, 20]).into(),
            16,
            ZarrVersion::V2,
        );
        // Chunk (z 0, y 0, x 1): voxels x 16..32, y 0..16, z 0..16.
        std::fs::remove_file(p.join("0/0/0/1")).unwrap();
        let store = Arc::new(ZarrStore::open(&p, &Limits::default()).unwrap());
        let s = ZarrSource::<u16>::new(store.clone(), ZarrSelection::default(), 8).unwrap();
        assert_bricks_equal_whole(&store, &s, 8);
        let l = s.layout(0).unwrap();
        let key = l.brick_of_voxel([20, 5, 5]).unwrap();
        let b = s.brick(key).unwrap();
        assert_eq!(b.data[l.slot_index(key, [20, 5, 5]).unwrap()], 0);
        assert_ne!(b.data[l.slot_index(key, [15, 5, 5]).unwrap()], 0);
    }

    #[test]
    fn a_corrupt_chunk_is_an_error_naming_level_brick_and_store() {
        for version in [ZarrVersion::V2, ZarrVersion::V3] {
            let dir = tempfile::tempdir().unwrap();
            let p = write(dir.path(), volume::<i16>([40, 20, 20]).into(), 16, version);
            let chunk = match version {
                ZarrVersion::V2 => p.join("1/0/0/0"),
                _ => p.join("1/c/0/0/0"),
            };
            let mut bytes = std::fs::read(&chunk).unwrap();
            bytes.truncate(bytes.len() / 2);
            bytes.extend([0xA5; 7]);
            std::fs::write(&chunk, &bytes).unwrap();
            let store = Arc::new(ZarrStore::open(&p, &Limits::default()).unwrap());
            let s = ZarrSource::<i16>::new(store, ZarrSelection::default(), 8).unwrap();
            let key = s.layout(1).unwrap().key([0, 0, 0]).unwrap();
            let e = s.brick(key).unwrap_err();
            assert!(
                matches!(
                    e,
                    CoreError::Brick {
                        level: 1,
                        brick: [0, 0, 0],
                        ..
                    }
                ),
                "{e}"
            );
            let text = e.to_string();
            assert!(
                text.contains("s16.zarr") && text.contains("level 1"),
                "{text}"
            );
            // Level 0 reads.
            for key in keys(s.layout(0).unwrap()) {
                s.brick(key).unwrap();
            }
        }
    }

    #[test]
    fn wrong_types_selections_and_keys_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            dir.path(),
            volume::<u16>([20, 12, 10]).into(),
            8,
            ZarrVersion::V2,
        );
        let store = Arc::new(ZarrStore::open(&p, &Limits::default()).unwrap());
        let e = ZarrSource::<u8>::new(store.clone(), ZarrSelection::default(), 8).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("sample type") && text.contains("uint16"),
            "{text}"
        );
        let sel = ZarrSelection {
            channel: 1,
            timepoint: 0,
        };
        let e = ZarrSource::<u16>::new(store.clone(), sel, 8).unwrap_err();
        assert!(e.to_string().contains("channel 1"), "{e}");
        let e = ZarrSource::<u16>::new(store.clone(), ZarrSelection::default(), 12).unwrap_err();
        assert!(e.to_string().contains("brick size"), "{e}");
        let s = ZarrSource::<u16>::new(store.clone(), ZarrSelection::default(), 8).unwrap();
        let n = store.levels().len() as u8;
        for key in [
            BrickKey {
                level: n,
                b: [0; 3],
            },
            BrickKey {
                level: 0,
                b: [9, 0, 0],
            },
        ] {
            let e = s.brick(key).unwrap_err();
            assert!(matches!(e, CoreError::Brick { .. }), "{e}");
        }
        assert!(s.layout(n as usize).is_none());
        assert!(
            s.brick_range(BrickKey {
                level: 0,
                b: [0; 3]
            })
            .is_none()
        );
    }
}
