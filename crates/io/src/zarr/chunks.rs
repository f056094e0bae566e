//! The thin faces of decoded chunks, kept for the halos of neighbouring bricks
//! ([`super::ZarrSource::with_chunk_cache`], decision 0039 amendment 1).
//!
//! A brick of `B` cells reads the voxels `[B·b − H, B·b + B + H]` of its level (halo `H` = 1,
//! `docs/design/brick-seam.md`). Where the store's chunks are the bricks' size (`convert`
//! writes 64³ chunks, the renderer's bricks are 64³ cells) that box is its own chunk plus the
//! `H` last layers of the chunks below it and the `H + 1` first layers of the chunks above it,
//! along each axis: up to 26 neighbouring chunks of which it needs a sliver. A chunk is stored
//! compressed whole, so reading a sliver decodes it whole: a pass over the level decoded each
//! chunk up to 27 times (BENCHMARKS §32). This cache keeps, for each chunk decoded, its six
//! faces ([`FACE_LOW`] layers at its low end and [`FACE_HIGH`] at its high end along each
//! axis: 3 · 3 layers of the chunk's 64 = 14 % of its samples), so the slivers of a chunk
//! already decoded are copied from its faces, and a pass decodes each chunk about once (at
//! most twice: once for a neighbour's halo before its own brick, once for its own brick).
//!
//! Bounded: the faces held take at most the capacity given (bytes, least recently used chunks
//! dropped first); one chunk is decoded by one thread at a time (the others wait for its
//! faces), so the bricks read in parallel by the cache never decode the same chunk twice at
//! once.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};

/// Layers a chunk's low face holds along each axis: the brick below it reads `H + 1` = 2.
pub(super) const FACE_LOW: usize = 2;
/// Layers a chunk's high face holds along each axis: the brick above it reads `H` = 1.
pub(super) const FACE_HIGH: usize = 1;

/// A box of samples of a level, `[lo, hi)` per axis (x, y, z: index space of the level),
/// held x fastest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Box3 {
    /// First sample per axis.
    pub(super) lo: [usize; 3],
    /// One past the last sample per axis.
    pub(super) hi: [usize; 3],
}

impl Box3 {
    /// Samples per axis.
    pub(super) fn dims(&self) -> [usize; 3] {
        std::array::from_fn(|a| self.hi[a] - self.lo[a])
    }

    /// Samples in the box.
    pub(super) fn len(&self) -> usize {
        self.dims().iter().product()
    }

    /// The box moved by `by` voxels along every axis.
    pub(super) fn shifted(self, by: usize) -> Box3 {
        Box3 {
            lo: self.lo.map(|x| x + by),
            hi: self.hi.map(|x| x + by),
        }
    }

    /// Whether `other` lies inside this box.
    pub(super) fn contains(&self, other: &Box3) -> bool {
        (0..3).all(|a| self.lo[a] <= other.lo[a] && other.hi[a] <= self.hi[a])
    }
}

/// Copies the samples of `piece` from `src` (the samples of box `from`, x fastest) into `dst`
/// (the samples of box `into`); `piece` lies inside both.
pub(super) fn copy_box<T: Copy>(src: &[T], from: Box3, dst: &mut [T], into: Box3, piece: Box3) {
    let (f, t) = (from.dims(), into.dims());
    let w = piece.hi[0] - piece.lo[0];
    for k in piece.lo[2]..piece.hi[2] {
        for j in piece.lo[1]..piece.hi[1] {
            let s =
                (piece.lo[0] - from.lo[0]) + f[0] * ((j - from.lo[1]) + f[1] * (k - from.lo[2]));
            let d =
                (piece.lo[0] - into.lo[0]) + t[0] * ((j - into.lo[1]) + t[1] * (k - into.lo[2]));
            dst[d..d + w].copy_from_slice(&src[s..s + w]);
        }
    }
}

/// The six face boxes of chunk `chunk`: along each axis its first [`FACE_LOW`] and last
/// [`FACE_HIGH`] layers (fewer where the chunk is thinner), the whole chunk across.
pub(super) fn face_boxes(chunk: Box3) -> [Box3; 6] {
    std::array::from_fn(|i| {
        let (a, high) = (i / 2, i % 2 == 1);
        let mut b = chunk;
        if high {
            b.lo[a] = chunk.hi[a].saturating_sub(FACE_HIGH).max(chunk.lo[a]);
        } else {
            b.hi[a] = (chunk.lo[a] + FACE_LOW).min(chunk.hi[a]);
        }
        b
    })
}

/// The faces of one decoded chunk: each face box with where its samples start, the samples of
/// all six in one allocation (fewer small buffers kept between the reads' large ones).
#[derive(Debug)]
pub(super) struct Faces<T> {
    boxes: [(Box3, usize); 6],
    samples: Vec<T>,
}

impl<T: Copy> Faces<T> {
    /// The faces of chunk `chunk` cut from its decoded samples `data` (x fastest).
    pub(super) fn of(chunk: Box3, data: &[T]) -> Self {
        let faces = face_boxes(chunk);
        let mut samples = Vec::with_capacity(faces.iter().map(Box3::len).sum());
        let f = chunk.dims();
        let boxes = faces.map(|b| {
            let start = samples.len();
            let w = b.hi[0] - b.lo[0];
            for k in b.lo[2]..b.hi[2] {
                for j in b.lo[1]..b.hi[1] {
                    let s = (b.lo[0] - chunk.lo[0])
                        + f[0] * ((j - chunk.lo[1]) + f[1] * (k - chunk.lo[2]));
                    samples.extend_from_slice(&data[s..s + w]);
                }
            }
            (b, start)
        });
        Faces { boxes, samples }
    }

    /// A whole chunk kept as its own "faces" (every box the chunk): for chunks larger than a
    /// brick, whose inner pieces serve several bricks ([`super::ZarrSource`]'s reads), so
    /// that a pass decodes such a chunk about once instead of once per brick meeting it.
    pub(super) fn whole(chunk: Box3, data: Vec<T>) -> Self {
        Faces {
            boxes: [(chunk, 0); 6],
            samples: data,
        }
    }

    /// What the cache keeps of chunk `chunk` decoded as `data`: the whole chunk where `whole`
    /// is asked for or where its faces would hold as many samples as it (chunks of 1–3 layers
    /// along an axis, such as 2-D tiles), else its faces.
    pub(super) fn kept(chunk: Box3, data: Vec<T>, whole: bool) -> Self {
        let faces: usize = face_boxes(chunk).iter().map(Box3::len).sum();
        if whole || faces >= chunk.len() {
            Faces::whole(chunk, data)
        } else {
            Faces::of(chunk, &data)
        }
    }

    /// The face holding `piece`, with its box, if one does.
    pub(super) fn find(&self, piece: &Box3) -> Option<(Box3, &[T])> {
        self.boxes
            .iter()
            .find(|(b, _)| b.contains(piece))
            .map(|&(b, start)| (b, &self.samples[start..start + b.len()]))
    }

    /// The box of the face holding `piece`, if one does.
    pub(super) fn find_box(&self, piece: &Box3) -> Option<Box3> {
        self.find(piece).map(|(b, _)| b)
    }

    /// Bytes held.
    pub(super) fn bytes(&self) -> u64 {
        (self.samples.len() * std::mem::size_of::<T>()) as u64
    }
}

/// A chunk: its level and its index along x, y, z in the level's chunk grid.
pub(super) type ChunkId = (usize, [usize; 3]);

/// One chunk's faces once decoded; the lock is held while the chunk is decoded.
type Slot<T> = Arc<Mutex<Option<Arc<Faces<T>>>>>;

struct Entry<T> {
    slot: Slot<T>,
    /// Bytes of the faces once decoded (0 before).
    bytes: u64,
    /// The cache's clock when last asked for.
    stamp: u64,
}

struct State<T> {
    map: HashMap<ChunkId, Entry<T>>,
    bytes: u64,
    clock: u64,
}

/// The faces of the chunks decoded most recently, at most `capacity` bytes of them (module
/// documentation). Shared by the clones of a source and their threads.
pub(super) struct FaceCache<T> {
    capacity: u64,
    state: Mutex<State<T>>,
}

impl<T> std::fmt::Debug for FaceCache<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = lock(&self.state);
        f.debug_struct("FaceCache")
            .field("capacity", &self.capacity)
            .field("chunks", &s.map.len())
            .field("bytes", &s.bytes)
            .finish()
    }
}

/// Locks `m`, a poisoned lock taken as it is (its data stays consistent: every update is
/// made whole under the lock).
fn lock<X>(m: &Mutex<X>) -> MutexGuard<'_, X> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl<T: Copy> FaceCache<T> {
    /// An empty cache holding at most `capacity` bytes of faces.
    pub(super) fn new(capacity: u64) -> Self {
        FaceCache {
            capacity,
            state: Mutex::new(State {
                map: HashMap::new(),
                bytes: 0,
                clock: 0,
            }),
        }
    }

    /// The most bytes held.
    pub(super) fn capacity(&self) -> u64 {
        self.capacity
    }

    /// Bytes held now.
    #[cfg(test)]
    pub(super) fn bytes(&self) -> u64 {
        lock(&self.state).bytes
    }

    /// The slot of chunk `id`, made if absent, marked as used now.
    fn slot(&self, id: ChunkId) -> Slot<T> {
        let mut s = lock(&self.state);
        s.clock += 1;
        let now = s.clock;
        let e = s.map.entry(id).or_insert_with(|| Entry {
            slot: Arc::default(),
            bytes: 0,
            stamp: now,
        });
        e.stamp = now;
        Arc::clone(&e.slot)
    }

    /// Records that chunk `id`'s faces (of `bytes`) are in its slot, and drops the least
    /// recently used chunks' faces until the cache holds at most its capacity.
    fn charge(&self, id: ChunkId, bytes: u64) {
        let mut s = lock(&self.state);
        let Some(e) = s.map.get_mut(&id) else {
            return;
        };
        let old = std::mem::replace(&mut e.bytes, bytes);
        s.bytes = s.bytes - old + bytes;
        while s.bytes > self.capacity {
            let victim = s
                .map
                .iter()
                .filter(|(k, e)| **k != id && e.bytes > 0)
                .min_by_key(|(_, e)| e.stamp)
                .map(|(k, _)| *k);
            // The chunk just decoded goes only if it alone is over the capacity.
            let v = victim.unwrap_or(id);
            if let Some(e) = s.map.remove(&v) {
                s.bytes -= e.bytes;
            }
            if v == id {
                break;
            }
        }
    }

    /// Forgets chunk `id` (its decoding failed), unless its faces are there.
    fn forget_pending(&self, id: ChunkId) {
        let mut s = lock(&self.state);
        if s.map.get(&id).is_some_and(|e| e.bytes == 0) {
            s.map.remove(&id);
        }
    }

    /// Chunk `id`'s faces: those held, or those of `decode()` (the chunk's box and samples),
    /// decoded by one thread while the others asking for the same chunk wait; with `whole`,
    /// the whole chunk is kept ([`Faces::whole`]).
    pub(super) fn faces<E>(
        &self,
        id: ChunkId,
        whole: bool,
        decode: impl FnOnce() -> Result<(Box3, Vec<T>), E>,
    ) -> Result<Arc<Faces<T>>, E> {
        let slot = self.slot(id);
        let mut held = lock(&slot);
        if let Some(f) = held.as_ref() {
            return Ok(Arc::clone(f));
        }
        let (chunk, data) = match decode() {
            Ok(d) => d,
            Err(e) => {
                drop(held);
                self.forget_pending(id);
                return Err(e);
            }
        };
        let faces = Arc::new(Faces::kept(chunk, data, whole));
        *held = Some(Arc::clone(&faces));
        drop(held);
        self.charge(id, faces.bytes());
        Ok(faces)
    }

    /// Keeps the faces of chunk `id`, decoded whole by a caller (box `chunk`, samples
    /// `data`), unless they are held already or being decoded.
    pub(super) fn offer(&self, id: ChunkId, chunk: Box3, data: &[T]) {
        let slot = self.slot(id);
        let Ok(mut held) = slot.try_lock() else {
            return;
        };
        if held.is_some() {
            return;
        }
        let faces = Faces::kept(chunk, data.to_vec(), false);
        let bytes = faces.bytes();
        *held = Some(Arc::new(faces));
        drop(held);
        self.charge(id, bytes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk_data(b: Box3) -> Vec<u32> {
        let d = b.dims();
        (0..b.len())
            .map(|i| {
                let (x, y, z) = (i % d[0], i / d[0] % d[1], i / (d[0] * d[1]));
                ((b.lo[0] + x) + 1000 * (b.lo[1] + y) + 1_000_000 * (b.lo[2] + z)) as u32
            })
            .collect()
    }

    /// A chunk whose faces would hold as many samples as it (2-D tiles, 1–3 layers thick) is
    /// kept whole, and any piece of it is found; a thick chunk keeps its faces.
    #[test]
    fn thin_chunks_are_kept_whole() {
        let tile = Box3 {
            lo: [0, 0, 5],
            hi: [64, 32, 6],
        };
        let f = Faces::kept(tile, chunk_data(tile), false);
        assert_eq!(f.bytes(), (tile.len() * 4) as u64);
        let piece = Box3 {
            lo: [10, 3, 5],
            hi: [40, 30, 6],
        };
        let (b, v) = f.find(&piece).unwrap();
        assert_eq!(b, tile);
        assert_eq!(v, &chunk_data(tile)[..]);
        let cube = Box3 {
            lo: [0; 3],
            hi: [16; 3],
        };
        let f = Faces::kept(cube, chunk_data(cube), false);
        assert!(f.bytes() < (cube.len() * 4) as u64);
        let inner = Box3 {
            lo: [4; 3],
            hi: [12; 3],
        };
        assert!(
            f.find(&inner).is_none(),
            "a thick chunk's middle is in no face"
        );
        assert!(
            Faces::kept(cube, chunk_data(cube), true)
                .find(&inner)
                .is_some()
        );
    }

    #[test]
    fn faces_hold_the_chunk_slivers_a_halo_needs() {
        let chunk = Box3 {
            lo: [8, 16, 0],
            hi: [16, 20, 8],
        };
        let data = chunk_data(chunk);
        let f = Faces::of(chunk, &data);
        // 2 low + 1 high layers per axis.
        assert_eq!(
            f.bytes(),
            4 * ((2 + 1) * 4 * 8 + (2 + 1) * 8 * 8 + (2 + 1) * 8 * 4)
        );
        // A low sliver of two layers along y, a high sliver of one along z, an edge, a corner.
        for piece in [
            Box3 {
                lo: [8, 16, 0],
                hi: [16, 18, 8],
            },
            Box3 {
                lo: [9, 16, 7],
                hi: [15, 20, 8],
            },
            Box3 {
                lo: [15, 16, 0],
                hi: [16, 18, 8],
            },
            Box3 {
                lo: [15, 19, 7],
                hi: [16, 20, 8],
            },
        ] {
            let (b, v) = f.find(&piece).unwrap();
            let mut got = vec![0u32; piece.len()];
            copy_box(v, b, &mut got, piece, piece);
            assert_eq!(got, chunk_data(piece), "{piece:?}");
        }
        // Three layers along x, or one layer in the middle: not a face.
        for piece in [
            Box3 {
                lo: [8, 16, 0],
                hi: [11, 20, 8],
            },
            Box3 {
                lo: [8, 16, 4],
                hi: [16, 20, 5],
            },
        ] {
            assert!(f.find(&piece).is_none(), "{piece:?}");
        }
    }

    #[test]
    fn the_cache_stays_within_its_capacity_and_decodes_once_per_chunk() {
        let chunk = |c: usize| Box3 {
            lo: [8 * c, 0, 0],
            hi: [8 * c + 8, 8, 8],
        };
        let per = Faces::kept(chunk(0), chunk_data(chunk(0)), false).bytes();
        let cache = FaceCache::<u32>::new(3 * per);
        let decodes = std::sync::atomic::AtomicUsize::new(0);
        let get = |c: usize| {
            cache
                .faces::<()>((0, [c, 0, 0]), false, || {
                    decodes.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    Ok((chunk(c), chunk_data(chunk(c))))
                })
                .unwrap()
        };
        for c in 0..3 {
            get(c);
            get(c);
        }
        assert_eq!(decodes.load(std::sync::atomic::Ordering::Relaxed), 3);
        assert_eq!(cache.bytes(), 3 * per);
        // A fourth drops the least recently used (chunk 1 after chunk 0 is asked again).
        get(0);
        get(3);
        assert_eq!(cache.bytes(), 3 * per);
        get(0);
        get(2);
        assert_eq!(decodes.load(std::sync::atomic::Ordering::Relaxed), 4);
        get(1);
        assert_eq!(decodes.load(std::sync::atomic::Ordering::Relaxed), 5);
        assert!(cache.bytes() <= 3 * per);
        // A failed decode leaves nothing behind and is retried.
        assert!(cache.faces((0, [9, 0, 0]), false, || Err("bad")).is_err());
        get(9);
        assert_eq!(decodes.load(std::sync::atomic::Ordering::Relaxed), 6);
        // Threads asking for the same chunk at once decode it once.
        let cache = FaceCache::<u32>::new(100 * per);
        let decodes = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(|| {
                    for c in 0..20 {
                        cache
                            .faces::<()>((0, [c, 0, 0]), false, || {
                                decodes.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                                Ok((chunk(c), chunk_data(chunk(c))))
                            })
                            .unwrap();
                    }
                });
            }
        });
        assert_eq!(decodes.load(std::sync::atomic::Ordering::Relaxed), 20);
    }
}
