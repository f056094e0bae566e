//! Out-of-core bricks (issue 31 item 4; `docs/design/brick-seam.md` §2.3, §3 C7, §4): a
//! [`BrickCache`] holds the bricks of one level of a [`BrickSource`] in an arena of fixed slots
//! under a byte budget, least recently used bricks evicted, so that a frame reads only the
//! bricks it needs; [`scan_level`] reads a level once, brick by brick, for its skip-block
//! ranges ([`crate::BrickGrid::from_ranges8`]) and its finite range (decision 0030).
//!
//! Positions are index space of the level, as in [`volsplat_core::source`]. A brick's *index*
//! is `(b_k·d_j + b_j)·d_i + b_i` over [`BrickLayout::dims`] `d` ([`BrickCache::index`]).
//!
//! Determinism: reads run in parallel (rayon) but bricks are placed in brick index order,
//! slots are chosen from the cache's state alone (free slots lowest first, then least recently
//! used, lowest slot first), so the arena, the bases and the stats do not depend on the thread
//! count.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use rayon::prelude::*;
use volsplat_core::source::{Brick, BrickKey, BrickLayout, BrickSource, HALO};
use volsplat_core::{CoreError, NonFiniteSamples, Scalar};

use crate::error::{Result, SplatError, try_filled, try_zeroed};

/// No slot / no brick.
const NONE: u32 = u32::MAX;

/// Bytes of bricks read at once by one [`BrickCache::make_resident`] batch (a fixed number of
/// bricks, whatever the thread count, so that a failing read leaves the same state for any).
const BATCH_BYTES: usize = 64 << 20;

/// The share of the budget that one batch of reads may hold (`budget / READ_SHARE`): the
/// bricks a batch reads (and their decoding buffers, one brick per read in flight) come on top
/// of the arena and the read-ahead, so a batch is bounded by the budget, not only by
/// [`BATCH_BYTES`] (BENCHMARKS §31: 64 bricks of 0.57 MiB in flight under an 8 MiB budget).
const READ_SHARE: u64 = 16;

/// Bytes one brick read holds while it is in flight, as a multiple of its slot: the region read
/// from the source, the slot cut from it and a decoded chunk or two of the store (a store's
/// reader decodes whole chunks; 64³ chunks are about a slot each).
pub const READ_COST_SLOTS: u64 = 4;

/// Gives the whole free pages of the allocator's heaps back to the system (glibc's
/// `malloc_trim(0)`; nothing elsewhere). Brick reads allocate and free buffers of a slot or a
/// chunk (0.5–0.6 MiB for 64³ u16) on every thread, while the chunk faces cache keeps small
/// buffers that land between them; glibc serves such buffers from its per-thread heaps (its
/// mmap threshold rises to the size of the buffers freed) and the freed space between kept
/// buffers stays resident: +400 MiB over the budget's accounting on the 8 GiB benchmark at
/// 1 GiB (BENCHMARKS §33). Called every [`TRIM_EVERY`] bricks read ([`bricks_were_read`]):
/// it costs a walk of the free lists, and the pages given back are faulted in again.
fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        unsafe extern "C" {
            fn malloc_trim(pad: usize) -> std::ffi::c_int;
        }
        // SAFETY: `malloc_trim` takes no pointer and only returns free pages of glibc's heaps
        // to the system (madvise), under the allocator's own locks; the Rust global allocator
        // is glibc's malloc here (no `#[global_allocator]` in the library).
        unsafe {
            malloc_trim(0);
        }
    }
}

/// Bricks read (by every cache and scan of the process) between two
/// [`release_freed_memory`] calls.
const TRIM_EVERY: usize = 64;

/// Counts `n` bricks read (and freed) and gives the freed memory back each time the count
/// passes a multiple of [`TRIM_EVERY`].
fn bricks_were_read(n: usize) {
    static READ: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let before = READ.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
    if before / TRIM_EVERY != before.wrapping_add(n) / TRIM_EVERY {
        release_freed_memory();
    }
}

/// Counters of a [`BrickCache`] since it was made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Bricks read from the source ([`BrickSource::brick`] calls that succeeded, by
    /// [`BrickCache::make_resident`] and [`BrickCache::fetch`]).
    pub reads: u64,
    /// Requested bricks that were already resident (each distinct key of a
    /// [`BrickCache::make_resident`] call counts once).
    pub hits: u64,
    /// Resident bricks whose slot was given to another brick.
    pub evictions: u64,
    /// Decoded bytes read: `E³ · size_of::<T>()` per brick read (the slot, halo and padding
    /// included; a store's compressed bytes are not known here).
    pub bytes_read: u64,
    /// Bricks resident now.
    pub resident: usize,
    /// Slots in the arena.
    pub capacity: usize,
}

/// The bricks of one level of a [`BrickSource`], held in an arena of at most a byte budget:
/// `capacity` slots of `E³` samples (`E = B + 3`, [`BrickLayout::extent`]), slot `s` at arena
/// offset `s·E³`, plus a few samples of padding so that a 4-byte read starting at the last
/// sample stays inside (the AVX2 gathers read 8- and 16-bit samples as 4-byte words). A frame
/// calls [`BrickCache::make_resident`] with the bricks it needs at a serial point, then reads
/// [`BrickCache::arena`] at [`BrickCache::bases`] (the `Slotted` addressing of the design's
/// §2.2); nothing moves until the next call.
pub struct BrickCache<T: Scalar> {
    source: Arc<dyn BrickSource<T>>,
    level: usize,
    layout: BrickLayout,
    slot_len: usize,
    budget: u64,
    capacity: usize,
    arena: Vec<T>,
    /// Per slot: the brick index it holds, or [`NONE`].
    owner: Vec<u32>,
    /// Per slot: the clock of the last call that asked for its brick.
    stamp: Vec<u64>,
    /// Per brick index: its slot, or [`NONE`].
    slot_of: Vec<u32>,
    /// Per brick index: `slot·E³` if resident, else 0.
    bases: Vec<u32>,
    clock: u64,
    reads: AtomicU64,
    bytes_read: AtomicU64,
    hits: u64,
    evictions: u64,
    /// Per brick index: whether it may be read ([`BrickCache::restricted`]); `None`: every
    /// brick.
    allowed: Option<Vec<bool>>,
    /// Bricks that may not be read.
    outside: usize,
    /// Slot buffers of bricks read ahead ([`BrickCache::fetch`]) and placed since, kept for
    /// the next read-ahead instead of allocated per read: at most as many as were read ahead
    /// at once (the read-ahead's share of the budget).
    spare: Mutex<Vec<Box<[T]>>>,
}

/// A brick read ahead by [`BrickCache::fetch`], not yet placed: its key and its `E³` slot
/// samples (i fastest, as [`Brick::data`]). Give it to [`BrickCache::make_resident_with`].
#[derive(Debug)]
pub struct Fetched<T> {
    /// Which brick.
    pub key: BrickKey,
    /// Its slot's samples.
    pub data: Box<[T]>,
}

impl<T: Scalar> std::fmt::Debug for BrickCache<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BrickCache")
            .field("level", &self.level)
            .field("layout", &self.layout)
            .field("budget", &self.budget)
            .field("stats", &self.stats())
            .finish_non_exhaustive()
    }
}

/// Padding samples after the last slot: a 4-byte read starting at the last sample stays inside.
fn padding<T>() -> usize {
    let size = std::mem::size_of::<T>();
    4usize.saturating_sub(size).div_ceil(size)
}

/// Slots of `slot_len` samples of `size` bytes (plus `pad` samples after the last) that
/// `budget` bytes hold, at most `bricks`, and at most what keeps the arena within
/// `i32::MAX − 8` samples.
fn slots(budget: u64, slot_len: usize, size: usize, pad: usize, bricks: usize) -> usize {
    let slot_bytes = (slot_len * size) as u64;
    let by_budget = budget.saturating_sub((pad * size) as u64) / slot_bytes;
    let by_offsets = (i32::MAX as usize - 8 - pad) / slot_len;
    usize::try_from(by_budget)
        .unwrap_or(usize::MAX)
        .min(by_offsets)
        .min(bricks)
}

/// Bricks of `slot_bytes` read at once so that `in_flight` bytes hold them while they are read
/// ([`READ_COST_SLOTS`] slots each): at least 1, at most 64 and [`BATCH_BYTES`].
fn per_batch(in_flight: u64, slot_bytes: u64) -> usize {
    let by_bytes = in_flight / (slot_bytes * READ_COST_SLOTS).max(1);
    let cap = (BATCH_BYTES as u64 / slot_bytes.max(1)).clamp(1, 64);
    by_bytes.clamp(1, cap) as usize
}

/// The layout of `level` of `source`, or an error naming the level.
fn layout_of<T: Scalar>(source: &dyn BrickSource<T>, level: usize) -> Result<BrickLayout> {
    source.layout(level).cloned().ok_or_else(|| {
        SplatError::Core(CoreError::invalid(
            "level",
            level,
            format!("the brick source has {} levels", source.levels().len()),
        ))
    })
}

/// Brick index of `b` over `dims`, i fastest.
fn index_in(dims: [usize; 3], b: [usize; 3]) -> usize {
    (b[2] * dims[1] + b[1]) * dims[0] + b[0]
}

impl<T: Scalar> BrickCache<T> {
    /// The bricks of `level` of `source`, held in an arena of at most `budget` bytes (the arena
    /// is allocated whole here, fallibly, as zero pages that the system maps when a slot is
    /// first written). Capacity: the slots the budget holds, at most the level's brick count,
    /// and at most what keeps the arena within `i32::MAX − 8` samples (the AVX2 gathers' i32
    /// offsets).
    ///
    /// Errors: [`SplatError::Budget`] naming the budget and the slot size if it holds no slot;
    /// a level the source lacks ([`SplatError::Core`]); [`SplatError::OutOfMemory`].
    pub fn new(source: Arc<dyn BrickSource<T>>, level: usize, budget: u64) -> Result<Self> {
        Self::make(source, level, budget, None)
    }

    /// A cache that reads only the bricks whose index is `allowed` (a sort-last rank's bricks,
    /// issue 32; [`bricks_meeting`]), with at most as many slots as there are allowed bricks.
    /// The others are never read: [`BrickCache::make_resident`] and [`BrickCache::fetch`]
    /// leave them out (their base stays 0, slot 0's memory), so a frame must never sample
    /// them (`RenderSettings::owned_cells` inside the allowed bricks), and
    /// [`BrickCache::capacity`] counts them as resident. Errors as [`BrickCache::new`]; an
    /// `allowed` of another length than the level's brick count.
    pub fn restricted(
        source: Arc<dyn BrickSource<T>>,
        level: usize,
        budget: u64,
        allowed: Vec<bool>,
    ) -> Result<Self> {
        Self::make(source, level, budget, Some(allowed))
    }

    fn make(
        source: Arc<dyn BrickSource<T>>,
        level: usize,
        budget: u64,
        allowed: Option<Vec<bool>>,
    ) -> Result<Self> {
        let layout = layout_of(&*source, level)?;
        let size = std::mem::size_of::<T>();
        let slot_len = layout.slot_len();
        let pad = padding::<T>();
        let slot_bytes = (slot_len * size) as u64;
        let count = layout.brick_count();
        let inside = match &allowed {
            Some(a) if a.len() != count => {
                return Err(SplatError::Core(CoreError::invalid(
                    "allowed bricks",
                    a.len(),
                    format!("one flag for each of the level's {count} bricks"),
                )));
            }
            Some(a) => a.iter().filter(|&&x| x).count().max(1),
            None => count,
        };
        let capacity = slots(budget, slot_len, size, pad, inside);
        if capacity == 0 {
            return Err(SplatError::Budget {
                budget,
                slot_bytes,
                capacity: 0,
                needed: 1,
            });
        }
        let outside = allowed
            .as_ref()
            .map_or(0, |a| a.iter().filter(|&&x| !x).count());
        Ok(BrickCache {
            arena: try_zeroed(capacity * slot_len + pad, "the brick cache's arena")?,
            owner: try_filled(capacity, NONE, "the brick cache's slot table")?,
            stamp: try_filled(capacity, 0, "the brick cache's slot table")?,
            slot_of: try_filled(count, NONE, "the brick cache's brick table")?,
            bases: try_filled(count, 0, "the brick cache's brick table")?,
            source,
            level,
            layout,
            slot_len,
            budget,
            capacity,
            clock: 0,
            reads: AtomicU64::new(0),
            bytes_read: AtomicU64::new(0),
            hits: 0,
            evictions: 0,
            allowed,
            outside,
            spare: Mutex::new(Vec::new()),
        })
    }

    /// The byte budget the arena was sized from.
    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// How the level is cut into bricks.
    pub fn layout(&self) -> &BrickLayout {
        &self.layout
    }

    /// The level served.
    pub fn level(&self) -> usize {
        self.level
    }

    /// The most bricks resident at once: the slots in the arena ([`CacheStats::capacity`]),
    /// plus, for a [`BrickCache::restricted`] cache, the bricks it never reads (which take no
    /// slot).
    pub fn capacity(&self) -> usize {
        self.capacity + self.outside
    }

    /// The index of brick `b` (brick coordinates, each below [`BrickLayout::dims`]): `(b_k·d_j +
    /// b_j)·d_i + b_i`, the order of [`BrickCache::bases`].
    pub fn index(&self, b: [usize; 3]) -> usize {
        index_in(self.layout.dims(), b)
    }

    /// The arena: [`BrickCache::capacity`] slots of `E³` samples (slot `s` at `s·E³`, i
    /// fastest, as [`Brick::data`]), then padding (a 4-byte read at the last sample stays
    /// inside). A resident brick's slot holds exactly its [`Brick::data`]; other slots hold
    /// stale or zero samples.
    pub fn arena(&self) -> &[T] {
        &self.arena
    }

    /// Per brick index ([`BrickCache::index`]): the arena offset `slot·E³` of its slot if it is
    /// resident, 0 otherwise (check [`BrickCache::is_resident`]: slot 0's brick has base 0 too).
    pub fn bases(&self) -> &[u32] {
        &self.bases
    }

    /// Whether brick `key` is resident (false for a key of another level or outside the level).
    pub fn is_resident(&self, key: BrickKey) -> bool {
        self.layout
            .check(key)
            .is_ok_and(|b| self.slot_of[self.index(b)] != NONE)
    }

    /// The counters since the cache was made.
    pub fn stats(&self) -> CacheStats {
        CacheStats {
            reads: self.reads.load(Ordering::Relaxed),
            hits: self.hits,
            evictions: self.evictions,
            bytes_read: self.bytes_read.load(Ordering::Relaxed),
            resident: self.owner.iter().filter(|&&o| o != NONE).count(),
            capacity: self.capacity,
        }
    }

    /// Bytes of the arena (slots and padding).
    pub fn arena_bytes(&self) -> u64 {
        (self.arena.len() * std::mem::size_of::<T>()) as u64
    }

    /// `keys` checked against the layout, with their brick indices, in index order (x fastest,
    /// as [`BrickCache::index`]) and deduplicated: the order bricks are read and placed in, so
    /// that consecutive reads share the store's chunks along x, then y (a row of bricks meets
    /// the same chunks of its y and z; with 2-D tiles, every brick of a layer the same tiles).
    fn plan(&self, keys: &[BrickKey]) -> Result<Vec<(BrickKey, usize)>> {
        let mut out = keys
            .iter()
            .map(|&k| Ok((k, self.index(self.layout.check(k)?))))
            .collect::<Result<Vec<_>>>()?;
        if let Some(allowed) = &self.allowed {
            out.retain(|&(_, i)| allowed[i]);
        }
        out.sort_unstable_by_key(|&(_, i)| i);
        out.dedup();
        Ok(out)
    }

    /// A slot buffer for a brick read ahead: a spare one, or a new one (fallibly).
    fn take_spare(&self, key: BrickKey) -> Result<Box<[T]>> {
        if let Some(b) = lock(&self.spare).pop() {
            return Ok(b);
        }
        let mut v = Vec::new();
        v.try_reserve_exact(self.slot_len)
            .map_err(|_| key.error("cannot allocate a slot for a brick read ahead"))?;
        v.resize(self.slot_len, T::from_f64(0.0));
        Ok(v.into_boxed_slice())
    }

    /// Keeps the slot buffer of a placed or dropped brick read ahead for the next read-ahead.
    fn give_spare(&self, data: Box<[T]>) {
        if data.len() == self.slot_len {
            lock(&self.spare).push(data);
        }
    }

    /// Reads the bricks of `keys` that are not resident (in parallel; duplicates read once),
    /// without placing them, in index order: for read-ahead on another thread while a frame
    /// reads the arena. Pass them to [`BrickCache::make_resident_with`], which keeps their
    /// buffers for the next call. Errors as [`BrickCache::make_resident`]'s reads.
    pub fn fetch(&self, keys: &[BrickKey]) -> Result<Vec<Fetched<T>>> {
        let missing: Vec<BrickKey> = self
            .plan(keys)?
            .into_iter()
            .filter(|&(_, i)| self.slot_of[i] == NONE)
            .map(|(k, _)| k)
            .collect();
        let mut out = Vec::with_capacity(missing.len());
        for batch in missing.chunks(self.per_batch()) {
            let mut bufs = batch
                .iter()
                .map(|&k| self.take_spare(k))
                .collect::<Result<Vec<_>>>()?;
            let mut dsts: Vec<&mut [T]> = bufs.iter_mut().map(|b| &mut **b).collect();
            let read = read_batch(
                &*self.source,
                (&self.reads, &self.bytes_read),
                batch,
                &mut dsts,
            );
            drop(dsts);
            if let Err(e) = read {
                bufs.into_iter().for_each(|b| self.give_spare(b));
                return Err(e);
            }
            out.extend(
                batch
                    .iter()
                    .zip(bufs)
                    .map(|(&key, data)| Fetched { key, data }),
            );
        }
        bricks_were_read(out.len());
        Ok(out)
    }

    /// Bricks read at once by [`BrickCache::fetch`] and [`BrickCache::make_resident_with`]:
    /// those whose reads hold at most `budget / READ_SHARE` bytes ([`per_batch`]), so that a
    /// batch (read in parallel, at most that many reads in flight) stays a small share of the
    /// budget whatever the thread count.
    fn per_batch(&self) -> usize {
        let slot_bytes = (self.slot_len * std::mem::size_of::<T>()) as u64;
        per_batch(self.budget / READ_SHARE, slot_bytes)
    }

    /// Makes the bricks of `keys` resident (duplicates count once): reads the missing ones from
    /// the source (in parallel, placed in index order), each into a free slot or, when none is
    /// left, the slot of the least recently used brick not in `keys`. Bases of evicted bricks
    /// become 0.
    ///
    /// Errors: [`SplatError::Budget`] if more distinct bricks are asked for than
    /// [`BrickCache::capacity`] (nothing read); a key outside the level or a failed read
    /// ([`SplatError::Core`] with [`CoreError::Brick`] naming level and brick). After a read
    /// error the cache is consistent: every brick marked resident holds its data (the bricks
    /// of batches read before the failure may have been placed; the failing batch's slots were
    /// emptied for its reads and stay free).
    pub fn make_resident(&mut self, keys: &[BrickKey]) -> Result<()> {
        self.make_resident_with(keys, Vec::new())
    }

    /// As [`BrickCache::make_resident`], taking the bricks in `fetched` (from
    /// [`BrickCache::fetch`]) instead of reading them; bricks of `fetched` not asked for, or
    /// already resident, are dropped (their buffers kept for the next read-ahead). A fetched
    /// brick that is not the brick of its key at this level with a full slot is an error.
    ///
    /// Each batch's slots are chosen and their bricks evicted first; the missing bricks are
    /// then read straight into their slots in the arena (in parallel: disjoint slots), so no
    /// slot is allocated per read. After a failed batch its slots are free.
    pub fn make_resident_with(
        &mut self,
        keys: &[BrickKey],
        fetched: Vec<Fetched<T>>,
    ) -> Result<()> {
        let wanted = self.plan(keys)?;
        if wanted.len() > self.capacity {
            fetched.into_iter().for_each(|f| self.give_spare(f.data));
            return Err(SplatError::Budget {
                budget: self.budget,
                slot_bytes: (self.slot_len * std::mem::size_of::<T>()) as u64,
                capacity: self.capacity,
                needed: wanted.len(),
            });
        }
        self.clock += 1;
        let now = self.clock;
        let mut missing = Vec::new();
        for &(key, i) in &wanted {
            match self.slot_of[i] {
                NONE => missing.push((key, i)),
                s => {
                    self.stamp[s as usize] = now;
                    self.hits += 1;
                }
            }
        }
        // Free slots first (lowest first), then the least recently used (lowest slot first
        // among equals); the bricks asked for now carry `now` and are never victims.
        let mut victims: Vec<(u64, usize)> = (0..self.capacity)
            .filter(|&s| self.owner[s] == NONE || self.stamp[s] < now)
            .map(|s| {
                let age = if self.owner[s] == NONE {
                    0
                } else {
                    self.stamp[s] + 1
                };
                (age, s)
            })
            .collect();
        victims.sort_unstable();
        let mut victims = victims.into_iter().map(|(_, s)| s);
        let mut given: BTreeMap<BrickKey, Fetched<T>> = BTreeMap::new();
        for f in fetched {
            let i = self.layout.check(f.key).map(|b| self.index(b));
            if i.is_ok_and(|i| missing.binary_search_by_key(&i, |&(_, i)| i).is_ok()) {
                if let Some(old) = given.insert(f.key, f) {
                    self.give_spare(old.data);
                }
            } else {
                // Bricks given but not missing are dropped now, not at the end.
                self.give_spare(f.data);
            }
        }
        for batch in missing.chunks(self.per_batch()) {
            let mut slots = Vec::with_capacity(batch.len());
            for &(key, _) in batch {
                let Some(slot) = victims.next() else {
                    // Unreachable: wanted ≤ capacity leaves a victim for every missing brick.
                    return Err(key.error("no free slot in the brick cache").into());
                };
                self.evict(slot);
                slots.push(slot);
            }
            let taken: Vec<Option<Fetched<T>>> =
                batch.iter().map(|(key, _)| given.remove(key)).collect();
            // Each of the batch's (distinct) slots as its own mutable slice of the arena.
            let mut place: Vec<Option<&mut [T]>> = (0..batch.len()).map(|_| None).collect();
            let at: BTreeMap<usize, usize> =
                slots.iter().enumerate().map(|(p, &s)| (s, p)).collect();
            for (s, chunk) in self.arena.chunks_mut(self.slot_len).enumerate() {
                if let Some(&p) = at.get(&s) {
                    place[p] = Some(chunk);
                }
            }
            let (source, reads, bytes) = (&*self.source, &self.reads, &self.bytes_read);
            let slot_len = self.slot_len;
            // The bricks read ahead are copied into their slots; the others are read into
            // theirs, as one batch where the source reads batches (a store's shared chunks
            // decoded once), else one by one in parallel.
            let mut failed = None;
            let mut spares = Vec::new();
            let mut copies = Vec::new();
            let mut to_read = Vec::new();
            for ((&(key, _), dst), got) in batch.iter().zip(place).zip(taken) {
                match (dst, got) {
                    (None, got) => {
                        failed.get_or_insert(key.error("no slot in the arena").into());
                        spares.extend(got.map(|f| f.data));
                    }
                    (Some(dst), Some(f)) if f.key == key && f.data.len() == slot_len => {
                        copies.push((dst, f.data));
                    }
                    (Some(_), Some(f)) => {
                        failed.get_or_insert(SplatError::Core(key.error(format!(
                            "the brick source served brick {:?} of level {} with {} samples, \
                             where {slot_len} (E³) were expected",
                            f.key.b,
                            f.key.level,
                            f.data.len()
                        ))));
                        spares.push(f.data);
                    }
                    (Some(dst), None) => to_read.push((key, dst)),
                }
            }
            copies
                .par_iter_mut()
                .for_each(|(dst, data)| dst.copy_from_slice(data));
            spares.extend(copies.into_iter().map(|(_, data)| data));
            if failed.is_none() {
                let (keys, mut dsts): (Vec<BrickKey>, Vec<&mut [T]>) = to_read.into_iter().unzip();
                if let Err(e) = read_batch(source, (reads, bytes), &keys, &mut dsts) {
                    failed = Some(e);
                }
            }
            spares.into_iter().for_each(|d| self.give_spare(d));
            if let Some(e) = failed {
                // The batch's slots were emptied above and stay free.
                return Err(e);
            }
            for (&(_, i), &slot) in batch.iter().zip(&slots) {
                self.owner[slot] = i as u32;
                self.slot_of[i] = slot as u32;
                self.bases[i] = (slot * self.slot_len) as u32;
                self.stamp[slot] = now;
            }
        }
        bricks_were_read(missing.len());
        Ok(())
    }

    /// Empties `slot`, evicting its brick (its base becomes 0).
    fn evict(&mut self, slot: usize) {
        let old = self.owner[slot];
        if old != NONE {
            self.slot_of[old as usize] = NONE;
            self.bases[old as usize] = 0;
            self.evictions += 1;
            self.owner[slot] = NONE;
        }
    }
}

/// Locks `m`, whatever a panicking holder left (the guarded data stays consistent: a list
/// of buffers).
fn lock<X>(m: &Mutex<X>) -> std::sync::MutexGuard<'_, X> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Reads the bricks `keys` into `slots` (`keys[i]` into `slots[i]`) and counts them in
/// `reads` and `bytes`: as one batch where `source` reads batches
/// ([`BrickSource::read_slots`]), else one by one in parallel.
fn read_batch<T: Scalar>(
    source: &dyn BrickSource<T>,
    (reads, bytes): (&AtomicU64, &AtomicU64),
    keys: &[BrickKey],
    slots: &mut [&mut [T]],
) -> Result<()> {
    if keys.is_empty() {
        return Ok(());
    }
    match source.read_slots(keys, slots) {
        Some(r) => {
            r?;
            reads.fetch_add(keys.len() as u64, Ordering::Relaxed);
            let b: usize = slots.iter().map(|s| std::mem::size_of_val(&**s)).sum();
            bytes.fetch_add(b as u64, Ordering::Relaxed);
            Ok(())
        }
        None => keys
            .par_iter()
            .zip(slots.par_iter_mut())
            .try_for_each(|(&k, slot)| read_counted(source, reads, bytes, k, slot)),
    }
}

/// Reads brick `key` from `source` into `slot` and counts it in `reads` and `bytes`
/// (`E³ · size_of::<T>()`).
fn read_counted<T: Scalar>(
    source: &dyn BrickSource<T>,
    reads: &AtomicU64,
    bytes: &AtomicU64,
    key: BrickKey,
    slot: &mut [T],
) -> Result<()> {
    source.read_slot(key, slot)?;
    reads.fetch_add(1, Ordering::Relaxed);
    bytes.fetch_add(std::mem::size_of_val(slot) as u64, Ordering::Relaxed);
    Ok(())
}

/// What [`scan_level`] learnt of a level: per-brick and per-8³-block ranges (after the
/// replacement of non-finite floats, decision 0030, so that they equal the ranges of the level
/// read whole into a [`volsplat_core::Volume`]), the finite range and what was not finite.
#[derive(Debug, Clone, PartialEq)]
pub struct LevelScan {
    /// How the level was cut.
    pub layout: BrickLayout,
    /// `[min, max]` (data units) of each brick's 8³ blocks ([`Brick::ranges8`]): `(B/8)³` per
    /// brick, bricks in index order ([`BrickCache::index`]); `[+∞, −∞]` for blocks beyond the
    /// level.
    pub ranges8: Vec<[f32; 2]>,
    /// `[min, max]` (data units) of each brick's owned voxels ([`Brick::range`]), in index order.
    pub ranges: Vec<[f32; 2]>,
    /// `[lowest, highest]` finite sample of the level (data units); `None` if no sample is
    /// finite. For a float store, what [`BrickSource`]s replace NaN and ±∞ by.
    pub finite: Option<[f32; 2]>,
    /// The non-finite samples of the level (each voxel counted once) and what they become, as
    /// [`volsplat_core::Volume::non_finite`] reports them for the level read whole; `None` if
    /// every sample is finite (always for integer types, and for a source that already
    /// replaced them).
    pub non_finite: Option<NonFiniteSamples>,
    /// Bricks read (every brick of the level once by [`scan_level`]; those of the region by
    /// [`scan_level_in`]).
    pub bricks: usize,
    /// Decoded bytes read (`E³ · size_of::<T>()` per brick).
    pub bytes_read: u64,
    /// Per brick (index order): whether it was read (all by [`scan_level`]).
    pub read: Vec<bool>,
}

impl LevelScan {
    /// The 8³-block ranges of brick index `i` ([`BrickCache::index`]); empty if `i` is not a
    /// brick of the level.
    pub fn ranges8_of(&self, i: usize) -> &[[f32; 2]] {
        let per = self.layout.blocks_per_brick().pow(3);
        self.ranges8.get(i * per..(i + 1) * per).unwrap_or(&[])
    }

    /// `[min, max]` of the level (data units, after replacement): the union of
    /// [`LevelScan::ranges`].
    pub fn value_range(&self) -> [f32; 2] {
        self.ranges
            .iter()
            .fold([f32::INFINITY, f32::NEG_INFINITY], |r, q| {
                [r[0].min(q[0]), r[1].max(q[1])]
            })
    }

    /// Gives every block of the bricks not read ([`scan_level_in`]) the range `range` (data
    /// units): a sort-last rank's scan, where `range` is the level's (the union of the ranks'
    /// [`LevelScan::value_range`]s), so that what folds every block's range (the slabs'
    /// ring-risk test for automatic pre-integration) sees the level's range. Blocks outside
    /// the rank's boxes of cells must stay inactive by other means
    /// (`RenderSettings::owned_cells`): they now look like data.
    pub fn fill_unread(&mut self, range: [f32; 2]) {
        let per = self.layout.blocks_per_brick().pow(3);
        for (i, &read) in self.read.iter().enumerate() {
            if !read {
                self.ranges[i] = range;
                if let Some(blocks) = self.ranges8.get_mut(i * per..(i + 1) * per) {
                    blocks.fill(range);
                }
            }
        }
    }

    /// The level's skip-block grid, equal to [`crate::BrickGrid::build`] of the level read
    /// whole ([`crate::BrickGrid::from_ranges8`]).
    pub fn brick_grid(&self) -> Result<crate::BrickGrid> {
        crate::BrickGrid::from_ranges8(&self.layout, &self.ranges8)
    }
}

/// What one brick told the scan.
struct BrickSummary {
    ranges8: Box<[[f32; 2]]>,
    /// Per block, where the brick held non-finite samples: (NaN or −∞ inside, +∞ inside); the
    /// block's range in `ranges8` is then over its finite samples only.
    flags: Option<Vec<(bool, bool)>>,
    nan: usize,
    pos_inf: usize,
    neg_inf: usize,
}

/// The summary of `brick` (as served: non-finite samples kept).
fn summarise<T: Scalar>(layout: &BrickLayout, brick: &Brick<T>) -> Result<BrickSummary> {
    if brick.data.iter().all(|v| v.to_f32().is_finite()) {
        return Ok(BrickSummary {
            ranges8: brick.ranges8.clone(),
            flags: None,
            nan: 0,
            pos_inf: 0,
            neg_inf: 0,
        });
    }
    let key = brick.key;
    let s = layout.slot_strides();
    let at = |x: usize, y: usize, z: usize| brick.data[x + y * s[1] + z * s[2]].to_f32();
    let per = layout.blocks_per_brick().pow(3);
    let mut ranges8 = Vec::with_capacity(per);
    let mut flags = Vec::with_capacity(per);
    for q in 0..per {
        let mut r = [f32::INFINITY, f32::NEG_INFINITY];
        let (mut low, mut high) = (false, false);
        if let Some(span) = layout.block_span(key, q)? {
            for z in span[2].clone() {
                for y in span[1].clone() {
                    for x in span[0].clone() {
                        let v = at(x, y, z);
                        if v.is_finite() {
                            r = [r[0].min(v), r[1].max(v)];
                        } else if v == f32::INFINITY {
                            high = true;
                        } else {
                            low = true;
                        }
                    }
                }
            }
        }
        ranges8.push(r);
        flags.push((low, high));
    }
    // Counts over the voxels this brick alone owns: [B·b, B·b + B), and the level's last voxel
    // in the last brick along each axis.
    let own = layout.owned_voxels(key)?;
    let base = key.b.map(|b| b as usize * layout.size());
    let last = layout.dims();
    let span: [std::ops::Range<usize>; 3] = std::array::from_fn(|a| {
        let end = if key.b[a] as usize + 1 == last[a] {
            own[a].end
        } else {
            own[a].end - 1
        };
        own[a].start - base[a] + HALO..end - base[a] + HALO
    });
    let (mut nan, mut pos_inf, mut neg_inf) = (0, 0, 0);
    for z in span[2].clone() {
        for y in span[1].clone() {
            for x in span[0].clone() {
                let v = at(x, y, z);
                if v.is_nan() {
                    nan += 1;
                } else if v == f32::INFINITY {
                    pos_inf += 1;
                } else if v == f32::NEG_INFINITY {
                    neg_inf += 1;
                }
            }
        }
    }
    Ok(BrickSummary {
        ranges8: ranges8.into_boxed_slice(),
        flags: Some(flags),
        nan,
        pos_inf,
        neg_inf,
    })
}

/// [`scan_level_within`] with reads in flight bounded by the thread count alone (two bricks
/// per thread at most).
pub fn scan_level<T: Scalar>(source: &dyn BrickSource<T>, level: usize) -> Result<LevelScan> {
    scan_level_within(source, level, u64::MAX)
}

/// Reads every brick of `level` of `source` once, in parallel batches of two bricks per thread
/// and at most the bricks whose reads `in_flight` bytes hold ([`READ_COST_SLOTS`] slots each,
/// at least one brick: give a share of a memory budget), and returns the level's ranges
/// ([`LevelScan`]). Serve the samples as stored (e.g. `ZarrSource::as_stored` for a float
/// store): non-finite samples are found and counted, and the ranges are those after their
/// replacement by the level's finite extremes (NaN and −∞ the lowest, +∞ the highest;
/// decision 0030), so they equal the ranges of the level read whole. The result does not
/// depend on the thread count.
///
/// Errors: a level the source lacks; a failed read (the brick's [`CoreError::Brick`]); a
/// level with non-finite samples and no finite one (as [`volsplat_core::Volume::new`]).
pub fn scan_level_within<T: Scalar>(
    source: &dyn BrickSource<T>,
    level: usize,
    in_flight: u64,
) -> Result<LevelScan> {
    let layout = layout_of(source, level)?;
    let every = vec![true; layout.brick_count()];
    scan_bricks(source, layout, &every, in_flight)
}

/// Per brick of `layout` (index order, [`BrickCache::index`]): whether its box of cells
/// `[B·b, B·b + B)` meets one of the boxes of cells `region` (`[lo, hi)` each, index space of
/// the level; an upper bound past the last cell reaches it).
pub fn bricks_meeting(layout: &BrickLayout, region: &[[[usize; 3]; 2]]) -> Vec<bool> {
    let d = layout.dims();
    let size = layout.size();
    (0..layout.brick_count())
        .map(|i| {
            let b = [i % d[0], i / d[0] % d[1], i / (d[0] * d[1])];
            region
                .iter()
                .any(|[lo, hi]| (0..3).all(|a| b[a] * size < hi[a] && lo[a] < (b[a] + 1) * size))
        })
        .collect()
}

/// [`scan_level`] of the bricks that meet the boxes of cells `region` ([`bricks_meeting`])
/// only: a sort-last rank's part of a level (issue 32), the rest never read. The bricks read
/// have the ranges [`scan_level`] gives them; the others have empty ranges (`[+∞, −∞]`, no
/// block active) until [`LevelScan::fill_unread`] gives them the level's range, and
/// [`LevelScan::read`] says which were read. `finite` and `non_finite` are those of the bricks
/// read (a float level's replacement values are the *level's* finite extremes, which a part
/// does not know: a caller must refuse or exchange them where `non_finite` is `Some`).
pub fn scan_level_in<T: Scalar>(
    source: &dyn BrickSource<T>,
    level: usize,
    region: &[[[usize; 3]; 2]],
) -> Result<LevelScan> {
    let layout = layout_of(source, level)?;
    let wanted = bricks_meeting(&layout, region);
    scan_bricks(source, layout, &wanted, u64::MAX)
}

/// Reads the bricks of `layout` that are `wanted` (per index), in parallel batches of two per
/// thread and at most the bricks whose reads `in_flight` bytes hold ([`READ_COST_SLOTS`] slots
/// each, at least one), and folds them into a [`LevelScan`] (the others empty).
fn scan_bricks<T: Scalar>(
    source: &dyn BrickSource<T>,
    layout: BrickLayout,
    wanted: &[bool],
    in_flight: u64,
) -> Result<LevelScan> {
    let d = layout.dims();
    let keys: Vec<BrickKey> = (0..layout.brick_count())
        .filter(|&i| wanted.get(i).copied().unwrap_or(false))
        .filter_map(|i| layout.key([i % d[0], i / d[0] % d[1], i / (d[0] * d[1])]))
        .collect();
    let slot_bytes = (layout.slot_len() * std::mem::size_of::<T>()) as u64;
    let by_bytes = in_flight / (slot_bytes * READ_COST_SLOTS).max(1);
    let batch = usize::try_from(by_bytes)
        .unwrap_or(usize::MAX)
        .clamp(1, 2 * rayon::current_num_threads().max(1));
    // The block ranges go into the level's vector (one allocation: 8 bytes per 8³ block, 64
    // MiB for an 8 GiB u16 level); the summaries keep only counts and flags.
    let per3 = layout.blocks_per_brick().pow(3);
    let mut ranges8 = try_filled(
        layout.brick_count() * per3,
        [f32::INFINITY, f32::NEG_INFINITY],
        "the scan's block ranges",
    )?;
    let empty = || BrickSummary {
        ranges8: Box::default(),
        flags: None,
        nan: 0,
        pos_inf: 0,
        neg_inf: 0,
    };
    let mut summaries: Vec<BrickSummary> = (0..layout.brick_count()).map(|_| empty()).collect();
    let mut bytes_read = 0u64;
    let index = |k: &BrickKey| index_in(d, k.b.map(|x| x as usize));
    for chunk in keys.chunks(batch) {
        let part = chunk
            .par_iter()
            .map(|&k| {
                let brick = source.brick(k)?;
                if brick.key != k || brick.data.len() != layout.slot_len() {
                    return Err(k
                        .error("the brick source served another brick or a short slot")
                        .into());
                }
                let bytes = (brick.data.len() * std::mem::size_of::<T>()) as u64;
                Ok((summarise(&layout, &brick)?, bytes))
            })
            .collect::<Result<Vec<_>>>()?;
        bricks_were_read(chunk.len());
        for ((mut s, b), k) in part.into_iter().zip(chunk) {
            bytes_read += b;
            let i = index(k);
            ranges8[i * per3..(i + 1) * per3].copy_from_slice(&s.ranges8);
            s.ranges8 = Box::default();
            summaries[i] = s;
        }
    }
    let read_count = keys.len();
    let read = (0..layout.brick_count())
        .map(|i| wanted.get(i).copied().unwrap_or(false))
        .collect();
    finish_scan(layout, ranges8, summaries, bytes_read, read, read_count)
}

/// Folds the bricks' summaries (in index order) and their block ranges `ranges8` into the
/// level's scan: the finite range, then the blocks holding non-finite samples widened by what
/// those become (in place).
fn finish_scan(
    layout: BrickLayout,
    mut ranges8: Vec<[f32; 2]>,
    summaries: Vec<BrickSummary>,
    bytes_read: u64,
    read: Vec<bool>,
    read_count: usize,
) -> Result<LevelScan> {
    let fold = |r: [f32; 2], q: &[f32; 2]| [r[0].min(q[0]), r[1].max(q[1])];
    let empty = [f32::INFINITY, f32::NEG_INFINITY];
    let lohi = ranges8.iter().fold(empty, fold);
    let finite = (lohi[0] <= lohi[1]).then_some(lohi);
    let (nan, pos_inf, neg_inf) = summaries.iter().fold((0, 0, 0), |c, s| {
        (c.0 + s.nan, c.1 + s.pos_inf, c.2 + s.neg_inf)
    });
    let non_finite = if nan + pos_inf + neg_inf == 0 {
        None
    } else {
        let Some([lowest, highest]) = finite else {
            return Err(CoreError::invalid(
                "samples",
                format!("{nan} NaN, {pos_inf} +inf and {neg_inf} -inf"),
                format!(
                    "no sample of level {} is finite, so it holds no value to draw",
                    layout.level()
                ),
            )
            .into());
        };
        Some(NonFiniteSamples {
            nan,
            pos_inf,
            neg_inf,
            lowest,
            highest,
        })
    };
    let per3 = layout.blocks_per_brick().pow(3);
    let mut ranges = Vec::with_capacity(summaries.len());
    for (s, brick) in summaries.iter().zip(ranges8.chunks_mut(per3)) {
        if let (Some(flags), Some(nf)) = (&s.flags, &non_finite) {
            for (r, &(low, high)) in brick.iter_mut().zip(flags) {
                if low {
                    *r = fold(*r, &[nf.lowest, nf.lowest]);
                }
                if high {
                    *r = fold(*r, &[nf.highest, nf.highest]);
                }
            }
        }
        ranges.push(brick.iter().fold(empty, fold));
    }
    Ok(LevelScan {
        ranges8,
        ranges,
        finite,
        non_finite,
        bricks: read_count,
        bytes_read,
        read,
        layout,
    })
}

#[cfg(test)]
mod tests;
