//! Tests of the brick cache and the ranges scan.

use super::*;
use crate::BrickGrid;
use std::sync::atomic::AtomicUsize;
use volsplat_core::{Grid, InMemory, Volume};

fn volume<T: Scalar>(dims: [usize; 3]) -> Arc<Volume<T>> {
    Arc::new(
        Volume::from_fn(Grid::with_dims(dims).unwrap(), |i, j, k| {
            T::from_f64(((i * 7 + j * 13 + k * 101) % 251) as f64 - 100.0)
        })
        .unwrap(),
    )
}

fn source<T: Scalar>(dims: [usize; 3], size: usize) -> Arc<dyn BrickSource<T>> {
    Arc::new(InMemory::new(volume::<T>(dims), size).unwrap())
}

fn key(b: [u32; 3]) -> BrickKey {
    BrickKey { level: 0, b }
}

fn all_keys(l: &BrickLayout) -> Vec<BrickKey> {
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

/// Bytes of one slot of B = 8 (E = 11) u16 bricks, and the padding after the arena.
const SLOT_U16_B8: u64 = 11 * 11 * 11 * 2;

/// Every resident brick's slot holds exactly its data; the bases of the others are 0.
fn assert_arena_holds_bricks<T: Scalar>(c: &BrickCache<T>, s: &dyn BrickSource<T>) {
    let e3 = c.layout().slot_len();
    let mut resident = 0;
    for k in all_keys(c.layout()) {
        let i = c.index(k.b.map(|x| x as usize));
        if c.is_resident(k) {
            let base = c.bases()[i] as usize;
            assert_eq!(base % e3, 0);
            assert!(
                c.arena()[base..base + e3] == *s.brick(k).unwrap().data,
                "{k:?}"
            );
            resident += 1;
        } else {
            assert_eq!(c.bases()[i], 0, "{k:?}");
        }
    }
    assert_eq!(resident, c.stats().resident);
}

#[test]
fn a_budget_of_exactly_n_slots_holds_n_bricks_and_the_arena_is_padded() {
    // 37 × 20 × 9 at B = 8: 5 × 3 × 1 bricks.
    let s = source::<u16>([37, 20, 9], 8);
    let pad = 2; // one u16 of padding: a 4-byte read at the last sample stays inside.
    for n in [1u64, 2, 5, 15] {
        let c = BrickCache::new(s.clone(), 0, n * SLOT_U16_B8 + pad).unwrap();
        assert_eq!(c.capacity(), n as usize);
        assert_eq!(c.arena().len(), n as usize * 1331 + 1);
        assert_eq!(c.arena_bytes(), n * SLOT_U16_B8 + pad);
        // One byte less: one slot less.
        if n > 1 {
            let c = BrickCache::new(s.clone(), 0, n * SLOT_U16_B8 + pad - 1).unwrap();
            assert_eq!(c.capacity(), n as usize - 1);
        }
    }
    // More than the level's bricks: capped at the brick count.
    let c = BrickCache::new(s.clone(), 0, 1 << 30).unwrap();
    assert_eq!(c.capacity(), 15);
    // u8 pads 3 samples, f32 none.
    let c = BrickCache::new(source::<u8>([37, 20, 9], 8), 0, 1 << 30).unwrap();
    assert_eq!(c.arena().len(), 15 * 1331 + 3);
    let c = BrickCache::new(source::<f32>([37, 20, 9], 8), 0, 1 << 30).unwrap();
    assert_eq!(c.arena().len(), 15 * 1331);
    // Less than one slot: a typed error naming the budget and the slot size.
    let e = BrickCache::new(s.clone(), 0, SLOT_U16_B8 + pad - 1).unwrap_err();
    assert!(
        matches!(e, SplatError::Budget { capacity: 0, needed: 1, slot_bytes, .. } if slot_bytes == SLOT_U16_B8),
        "{e}"
    );
    let text = e.to_string();
    assert!(
        text.contains(&format!("{}", SLOT_U16_B8 + pad - 1)) && text.contains("2662"),
        "{text}"
    );
    // A level the source lacks.
    let e = BrickCache::new(s, 1, 1 << 30).unwrap_err();
    assert!(e.to_string().contains("level"), "{e}");
}

#[test]
fn the_arena_stays_within_i32_offsets() {
    // B = 1024 u8: E³ = 1027³ ≈ 1.08 G samples: one slot fits under i32::MAX, two do not.
    let e3 = 1027usize.pow(3);
    assert_eq!(slots(1 << 40, e3, 1, 3, 3), 1);
    assert!(e3 + 3 <= i32::MAX as usize - 8);
    // B = 512 u16: E³ = 515³ ≈ 137 M samples: 15 slots, the 16th would pass i32::MAX.
    let e3 = 515usize.pow(3);
    let n = slots(u64::MAX, e3, 2, 1, 1000);
    let limit = i32::MAX as usize - 8;
    assert!(n * e3 < limit && (n + 1) * e3 + 1 > limit, "{n}");
    // The budget and the brick count bound it too.
    assert_eq!(slots(10 * 1331 * 2 + 1, 1331, 2, 1, 1000), 9);
    assert_eq!(slots(10 * 1331 * 2 + 2, 1331, 2, 1, 1000), 10);
    assert_eq!(slots(u64::MAX, 1331, 2, 1, 7), 7);
}

#[test]
fn least_recently_used_bricks_are_evicted_first_and_counted() {
    let s = source::<u16>([37, 20, 9], 8);
    let mut c = BrickCache::new(s.clone(), 0, 3 * SLOT_U16_B8 + 2).unwrap();
    let [a, b, d, e] = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]].map(key);
    c.make_resident(&[a]).unwrap();
    c.make_resident(&[b]).unwrap();
    c.make_resident(&[d]).unwrap();
    // Free slots are taken lowest first.
    for (k, slot) in [(a, 0), (b, 1), (d, 2)] {
        assert_eq!(c.bases()[c.index(k.b.map(|x| x as usize))], slot * 1331);
    }
    c.make_resident(&[a]).unwrap(); // a is now the most recent: b is the oldest.
    c.make_resident(&[e]).unwrap();
    assert!(!c.is_resident(b) && c.is_resident(a) && c.is_resident(d) && c.is_resident(e));
    assert_eq!(c.bases()[c.index([1, 0, 0])], 0);
    assert_eq!(c.bases()[c.index([3, 0, 0])], 1331, "e took b's slot");
    let st = c.stats();
    assert_eq!(
        (st.reads, st.hits, st.evictions, st.resident, st.capacity),
        (4, 1, 1, 3, 3)
    );
    assert_eq!(st.bytes_read, 4 * SLOT_U16_B8);
    // Next to evict: d (stamp 3), then a (4); a set that keeps d evicts a.
    c.make_resident(&[d, b]).unwrap();
    assert!(c.is_resident(d) && c.is_resident(b) && !c.is_resident(a) && c.is_resident(e));
    assert_eq!(c.stats().evictions, 2);
    // A set as large as the capacity replaces everything not in it.
    let set = [[0, 1, 0], [1, 1, 0], [2, 1, 0]].map(key);
    c.make_resident(&set).unwrap();
    assert!(set.iter().all(|&k| c.is_resident(k)));
    assert_eq!(c.stats().evictions, 5);
    assert_arena_holds_bricks(&c, &*s);
}

#[test]
fn repeated_keys_count_once_and_too_many_keys_are_a_budget_error() {
    let s = source::<u16>([37, 20, 9], 8);
    let mut c = BrickCache::new(s.clone(), 0, 2 * SLOT_U16_B8 + 2).unwrap();
    let [a, b, d] = [[0, 0, 0], [4, 2, 0], [2, 1, 0]].map(key);
    c.make_resident(&[a, b, a, b, b]).unwrap();
    let st = c.stats();
    assert_eq!((st.reads, st.hits, st.resident), (2, 0, 2));
    c.make_resident(&[b, b, a]).unwrap();
    assert_eq!(c.stats().hits, 2);
    let e = c.make_resident(&[a, b, d, a]).unwrap_err();
    assert!(
        matches!(
            e,
            SplatError::Budget {
                needed: 3,
                capacity: 2,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("3 bricks are needed"), "{e}");
    assert_eq!(c.stats().reads, 2, "nothing read");
    // Keys of another level or outside the level: errors naming the brick.
    for k in [
        BrickKey {
            level: 1,
            b: [0; 3],
        },
        key([5, 0, 0]),
    ] {
        let e = c.make_resident(&[k]).unwrap_err();
        assert!(
            matches!(e, SplatError::Core(CoreError::Brick { brick, .. }) if brick == k.b),
            "{e}"
        );
        assert!(c.fetch(&[k]).is_err());
    }
    assert_arena_holds_bricks(&c, &*s);
}

/// A source whose `brick` fails for one key and counts its calls.
struct Failing {
    inner: InMemory<u16>,
    bad: BrickKey,
    calls: AtomicUsize,
}

impl BrickSource<u16> for Failing {
    fn levels(&self) -> &[Grid] {
        self.inner.levels()
    }
    fn layout(&self, level: usize) -> Option<&BrickLayout> {
        self.inner.layout(level)
    }
    fn brick_range(&self, key: BrickKey) -> Option<[f32; 2]> {
        self.inner.brick_range(key)
    }
    fn brick(&self, key: BrickKey) -> volsplat_core::Result<Arc<Brick<u16>>> {
        self.calls.fetch_add(1, Ordering::Relaxed);
        if key == self.bad {
            return Err(key.error("test store: chunk 3 does not decode"));
        }
        self.inner.brick(key)
    }
}

#[test]
fn a_read_error_names_the_brick_and_leaves_the_cache_consistent() {
    let inner = InMemory::new(volume::<u16>([37, 20, 9]), 8).unwrap();
    let bad = key([2, 1, 0]);
    let s = Arc::new(Failing {
        inner,
        bad,
        calls: AtomicUsize::new(0),
    });
    let mut c = BrickCache::new(s.clone(), 0, 4 * SLOT_U16_B8 + 2).unwrap();
    let first = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]].map(key);
    c.make_resident(&first).unwrap();
    let before = c.stats();
    // The bad brick (index 7) is the first missing one in index order, alone in its batch (a
    // budget of 4 slots reads one brick at a time): the error comes before any is placed.
    let e = c
        .make_resident(&[key([0, 0, 0]), bad, key([3, 1, 0])])
        .unwrap_err();
    assert!(
        matches!(
            e,
            SplatError::Core(CoreError::Brick {
                level: 0,
                brick: [2, 1, 0],
                ..
            })
        ),
        "{e}"
    );
    assert!(e.to_string().contains("does not decode"), "{e}");
    assert!(!c.is_resident(bad) && !c.is_resident(key([3, 1, 0])));
    // Bricks are read straight into their slots, so the failed batch's one slot was emptied
    // first (the least recently used brick not asked for, lowest slot first: [1, 0, 0]) and
    // stays free; the brick asked for and the others stay resident with their data.
    assert!(!c.is_resident(key([1, 0, 0])));
    assert!(
        [[0, 0, 0], [2, 0, 0], [3, 0, 0]]
            .iter()
            .all(|&b| c.is_resident(key(b)))
    );
    let after = c.stats();
    assert_eq!(after.evictions, before.evictions + 1);
    assert_eq!(after.resident, 3);
    assert_arena_holds_bricks(&c, &*s);
    let e = c.fetch(&[bad]).unwrap_err();
    assert!(e.to_string().contains("brick [2, 1, 0]"), "{e}");
    // The cache still works.
    c.make_resident(&[key([4, 0, 0]), key([4, 1, 0])]).unwrap();
    assert_arena_holds_bricks(&c, &*s);
}

#[test]
fn fetched_bricks_are_placed_without_reading_again() {
    let s = source::<f32>([37, 20, 9], 8);
    let mut c = BrickCache::new(s.clone(), 0, 1 << 30).unwrap();
    c.make_resident(&[key([0, 0, 0])]).unwrap();
    let want = [[0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 2, 0]].map(key);
    let fetched = c.fetch(&want).unwrap();
    assert_eq!(
        fetched.iter().map(|b| b.key).collect::<Vec<_>>(),
        vec![key([1, 0, 0]), key([2, 2, 0])],
        "only the missing ones, once, in index order"
    );
    assert_eq!(c.stats().reads, 3);
    c.make_resident_with(&want, fetched).unwrap();
    let st = c.stats();
    assert_eq!((st.reads, st.hits, st.resident), (3, 1, 3));
    assert_arena_holds_bricks(&c, &*s);
    // A short brick is an error, nothing placed.
    let other = s.brick(key([3, 0, 0])).unwrap();
    let short = Fetched {
        key: other.key,
        data: other.data[1..].into(),
    };
    let e = c
        .make_resident_with(&[key([3, 0, 0])], vec![short])
        .unwrap_err();
    assert!(e.to_string().contains("samples"), "{e}");
    assert!(!c.is_resident(key([3, 0, 0])));
}

/// The same sequence of calls gives the same arena, bases and stats for any thread count.
#[test]
fn thread_count_does_not_change_placement_or_stats() {
    let s = source::<i16>([70, 45, 20], 8);
    let l = s.layout(0).unwrap().clone();
    let keys = all_keys(&l);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut c = BrickCache::new(s.clone(), 0, 23 * 1331 * 2 + 2).unwrap();
            let mut state = 0x2545_F491_4F6C_DD1Du64;
            for _ in 0..40 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let n = 1 + (state % 23) as usize;
                let set: Vec<BrickKey> = (0..n)
                    .map(|m| keys[(state as usize / 7 + m * 5) % keys.len()])
                    .collect();
                c.make_resident(&set).unwrap();
            }
            (c.arena().to_vec(), c.bases().to_vec(), c.stats())
        })
    };
    let one = run(1);
    assert!(one.2.evictions > 0 && one.2.hits > 0, "{:?}", one.2);
    for threads in [2, 3, 4] {
        let t = run(threads);
        assert!(t.0 == one.0, "arena at {threads} threads");
        assert_eq!(t.1, one.1, "bases at {threads} threads");
        assert_eq!(t.2, one.2, "stats at {threads} threads");
    }
}

/// A source over samples as stored (non-finite floats kept): what a store serves through
/// `ZarrSource::as_stored`.
struct Raw<T> {
    data: Vec<T>,
    levels: [Grid; 1],
    layout: BrickLayout,
}

impl<T: Scalar> BrickSource<T> for Raw<T> {
    fn levels(&self) -> &[Grid] {
        &self.levels
    }
    fn layout(&self, level: usize) -> Option<&BrickLayout> {
        (level == 0).then_some(&self.layout)
    }
    fn brick_range(&self, _key: BrickKey) -> Option<[f32; 2]> {
        None
    }
    fn brick(&self, key: BrickKey) -> volsplat_core::Result<Arc<Brick<T>>> {
        let n = self.levels[0].dims;
        Brick::from_region(&self.layout, key, &self.data, [0; 3], n).map(Arc::new)
    }
}

/// The scan of the raw samples gives `BrickGrid::build` of the volume (non-finite samples
/// replaced by `Volume::new`), its range and its non-finite report.
fn assert_scan_equals_build<T: Scalar>(dims: [usize; 3], size: usize, raw: Vec<T>) {
    let grid = Grid::with_dims(dims).unwrap();
    let v = Volume::new(grid.clone(), raw.clone()).unwrap();
    let src = Raw {
        data: raw,
        levels: [grid.clone()],
        layout: BrickLayout::new(grid, 0, size).unwrap(),
    };
    let scan = scan_level(&src, 0).unwrap();
    let what = format!("{:?} {dims:?} B = {size}", T::TYPE);
    assert_eq!(scan.bricks, src.layout.brick_count(), "{what}");
    let built = BrickGrid::build(&v);
    let from = scan.brick_grid().unwrap();
    assert_eq!(from, built, "{what}");
    assert_eq!(scan.non_finite.as_ref(), v.non_finite(), "{what}");
    let (lo, hi) = v.value_range();
    assert_eq!(scan.value_range(), [lo as f32, hi as f32], "{what}");
    // Each brick's range is the union of its blocks; the in-memory bricks agree.
    let mem = InMemory::new(Arc::new(v), size).unwrap();
    for k in all_keys(&src.layout) {
        let i = index_in(src.layout.dims(), k.b.map(|x| x as usize));
        let b = mem.brick(k).unwrap();
        assert_eq!(scan.ranges8_of(i), &b.ranges8[..], "{what} {k:?}");
        assert_eq!(scan.ranges[i], b.range, "{what} {k:?}");
    }
}

fn samples<T: Scalar>(dims: [usize; 3]) -> Vec<T> {
    let n = dims.iter().product::<usize>();
    (0..n)
        .map(|s| T::from_f64(((s * 7919) % 509) as f64 - 200.0))
        .collect()
}

#[test]
fn grids_from_scanned_bricks_equal_grids_built_from_the_volume() {
    for dims in [
        [37, 20, 9],
        [64, 64, 64],
        [1, 5, 9],
        [2, 2, 2],
        [129, 17, 3],
    ] {
        for size in [8, 16, 64] {
            assert_scan_equals_build::<u8>(dims, size, samples(dims));
            assert_scan_equals_build::<i8>(dims, size, samples(dims));
            assert_scan_equals_build::<u16>(dims, size, samples(dims));
            assert_scan_equals_build::<i16>(dims, size, samples(dims));
            assert_scan_equals_build::<f32>(dims, size, samples(dims));
            // Floats with NaN, +∞ and −∞ (some on brick seams and block faces).
            let mut f = samples::<f32>(dims);
            let n = f.len();
            for (at, v) in [
                (0, f32::NAN),
                (n / 2, f32::INFINITY),
                (n - 1, f32::NEG_INFINITY),
                (8.min(n - 1), f32::NAN),
                ((dims[0] * 16).min(n - 1), f32::INFINITY),
            ] {
                f[at] = v;
            }
            assert_scan_equals_build::<f32>(dims, size, f);
        }
    }
}

#[test]
fn a_level_without_finite_samples_and_a_failed_read_are_errors() {
    let dims = [9, 3, 2];
    let grid = Grid::with_dims(dims).unwrap();
    let src = Raw {
        data: vec![f32::NAN; 54],
        levels: [grid.clone()],
        layout: BrickLayout::new(grid, 0, 8).unwrap(),
    };
    let e = scan_level(&src, 0).unwrap_err();
    assert!(
        e.to_string().contains("no sample of level 0 is finite"),
        "{e}"
    );
    let inner = InMemory::new(volume::<u16>([37, 20, 9]), 8).unwrap();
    let bad = key([3, 2, 0]);
    let s = Failing {
        inner,
        bad,
        calls: AtomicUsize::new(0),
    };
    let e = scan_level(&s, 0).unwrap_err();
    assert!(
        matches!(
            e,
            SplatError::Core(CoreError::Brick {
                brick: [3, 2, 0],
                ..
            })
        ),
        "{e}"
    );
    assert!(scan_level(&s, 1).is_err());
}

#[test]
fn scans_read_each_brick_once_for_any_thread_count() {
    let inner = InMemory::new(volume::<u16>([70, 45, 20]), 8).unwrap();
    let s = Failing {
        inner,
        bad: key([99, 0, 0]),
        calls: AtomicUsize::new(0),
    };
    let mut first = None;
    for threads in [1, 2, 3] {
        s.calls.store(0, Ordering::Relaxed);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let scan = pool.install(|| scan_level(&s, 0)).unwrap();
        assert_eq!(s.calls.load(Ordering::Relaxed), 9 * 6 * 3);
        assert_eq!(scan.bytes_read, 9 * 6 * 3 * SLOT_U16_B8);
        match &first {
            None => first = Some(scan),
            Some(f) => assert_eq!(&scan, f, "{threads} threads"),
        }
    }
}

/// A source that counts the reads in flight at once (each read lasts a few milliseconds, so
/// that parallel reads overlap) and keeps the most.
struct InFlight {
    inner: InMemory<u16>,
    now: AtomicUsize,
    most: AtomicUsize,
}

impl InFlight {
    fn new(dims: [usize; 3]) -> Self {
        InFlight {
            inner: InMemory::new(volume::<u16>(dims), 8).unwrap(),
            now: AtomicUsize::new(0),
            most: AtomicUsize::new(0),
        }
    }
}

impl BrickSource<u16> for InFlight {
    fn levels(&self) -> &[Grid] {
        self.inner.levels()
    }
    fn layout(&self, level: usize) -> Option<&BrickLayout> {
        self.inner.layout(level)
    }
    fn brick_range(&self, key: BrickKey) -> Option<[f32; 2]> {
        self.inner.brick_range(key)
    }
    fn brick(&self, key: BrickKey) -> volsplat_core::Result<Arc<Brick<u16>>> {
        let n = self.now.fetch_add(1, Ordering::SeqCst) + 1;
        self.most.fetch_max(n, Ordering::SeqCst);
        std::thread::sleep(std::time::Duration::from_millis(3));
        self.now.fetch_sub(1, Ordering::SeqCst);
        self.inner.brick(key)
    }
}

/// Reads in flight are bounded by the budget, whatever the thread count: under a budget whose
/// sixteenth holds less than one brick's read, the cache reads one brick at a time (it read
/// up to 64 at once, one per thread, before), and with a large budget reads do run in
/// parallel. The scan reads at most the bricks its `in_flight` bytes hold.
#[test]
fn reads_in_flight_are_bounded_by_the_budget() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .unwrap();
    let dims = [70, 45, 20]; // 9 × 6 × 3 bricks of 8.
    let read_all = |budget: u64, ahead: bool| {
        let s = Arc::new(InFlight::new(dims));
        let keys = all_keys(s.layout(0).unwrap());
        let mut c = BrickCache::new(s.clone(), 0, budget).unwrap();
        let n = c.capacity().min(keys.len());
        pool.install(|| {
            if ahead {
                let fetched = c.fetch(&keys[..n]).unwrap();
                c.make_resident_with(&keys[..n], fetched).unwrap();
            } else {
                c.make_resident(&keys[..n]).unwrap();
            }
        });
        assert_eq!(c.stats().resident, n);
        assert_arena_holds_bricks(&c, &*s);
        s.most.load(Ordering::SeqCst)
    };
    // 20 slots: a sixteenth of the budget is under one read (4 slots).
    for ahead in [false, true] {
        assert_eq!(read_all(20 * SLOT_U16_B8 + 2, ahead), 1, "ahead {ahead}");
        // 64 × 4 slots per sixteenth: all four threads read at once.
        assert!(read_all(1 << 30, ahead) > 1, "ahead {ahead}");
    }
    let scan_most = |in_flight: u64| {
        let s = InFlight::new(dims);
        let scan = pool
            .install(|| scan_level_within(&s, 0, in_flight))
            .unwrap();
        assert_eq!(scan, pool.install(|| scan_level(&s, 0)).unwrap());
        s.most.store(0, Ordering::SeqCst);
        pool.install(|| scan_level_within(&s, 0, in_flight))
            .unwrap();
        s.most.load(Ordering::SeqCst)
    };
    assert_eq!(scan_most(0), 1);
    assert!(scan_most(2 * READ_COST_SLOTS * SLOT_U16_B8) <= 2);
    assert!(scan_most(u64::MAX) > 1);
}

#[test]
fn from_ranges8_refuses_a_wrong_length() {
    let l = BrickLayout::new(Grid::with_dims([37, 20, 9]).unwrap(), 0, 16).unwrap();
    let e = BrickGrid::from_ranges8(&l, &[[0.0, 1.0]; 7]).unwrap_err();
    assert!(e.to_string().contains("ranges8"), "{e}");
    assert!(BrickGrid::from_ranges8(&l, &[[0.0, 1.0]; 48]).is_ok());
}

#[test]
fn a_scan_of_a_region_reads_only_its_bricks_and_agrees_with_the_whole_scan_there() {
    // 70 × 45 × 20 voxels in bricks of 8 cells: 9 × 6 × 3 bricks. The region: cells
    // [16, 40) × [8, 44) × [0, 19) (the last upper bound past the last cell), two boxes.
    let inner = InMemory::new(volume::<u16>([70, 45, 20]), 8).unwrap();
    let whole = scan_level(&inner, 0).unwrap();
    let region = [[[16, 8, 0], [32, 44, 19]], [[32, 8, 0], [40, 44, 19]]];
    // A brick outside the region fails to read: the scan must never ask for it.
    let s = Failing {
        inner,
        bad: key([0, 0, 0]),
        calls: AtomicUsize::new(0),
    };
    let wanted = bricks_meeting(&whole.layout, &region);
    let expected: Vec<usize> = (0..wanted.len()).filter(|&i| wanted[i]).collect();
    // b_i in 2..5, b_j in 1..6 (cells 8..44 meet bricks 1..=5), b_k in 0..3.
    assert_eq!(expected.len(), 3 * 5 * 3);
    let mut scan = scan_level_in(&s, 0, &region).unwrap();
    assert_eq!(s.calls.load(Ordering::Relaxed), 45);
    assert_eq!(scan.bricks, 45);
    assert_eq!(scan.bytes_read, 45 * SLOT_U16_B8);
    assert_eq!(scan.read, wanted);
    for (i, &w) in wanted.iter().enumerate() {
        if w {
            assert_eq!(scan.ranges8_of(i), whole.ranges8_of(i), "brick {i}");
            assert_eq!(scan.ranges[i], whole.ranges[i]);
        } else {
            assert!(scan.ranges8_of(i).iter().all(|r| r[0] > r[1]), "brick {i}");
        }
    }
    let part = scan.value_range();
    assert!(part[0] >= whole.value_range()[0] && part[1] <= whole.value_range()[1]);
    scan.fill_unread(whole.value_range());
    assert_eq!(scan.value_range(), whole.value_range());
    let g = scan.brick_grid().unwrap();
    let fold = g
        .ranges
        .iter()
        .fold([f32::INFINITY, f32::NEG_INFINITY], |a, r| {
            [a[0].min(r[0]), a[1].max(r[1])]
        });
    assert_eq!(fold, whole.value_range());
    assert!(whole.read.iter().all(|&r| r));
}

#[test]
fn a_restricted_cache_reads_only_its_bricks_and_counts_the_others_as_resident() {
    let inner = InMemory::new(volume::<u16>([37, 20, 9]), 8).unwrap();
    let bad = key([0, 0, 0]);
    let s = Arc::new(Failing {
        inner,
        bad,
        calls: AtomicUsize::new(0),
    });
    let layout = s.layout(0).unwrap().clone();
    // Bricks 5 × 3 × 1; allowed: cells [16, 36) × [0, 19): b_i 2..5, every b_j.
    let allowed = bricks_meeting(&layout, &[[[16, 0, 0], [36, 19, 8]]]);
    assert_eq!(allowed.iter().filter(|&&a| a).count(), 9);
    let wrong = BrickCache::restricted(s.clone(), 0, 1 << 30, vec![true; 3]).unwrap_err();
    assert!(wrong.to_string().contains("allowed bricks"), "{wrong}");
    let mut c = BrickCache::restricted(s.clone(), 0, 1 << 30, allowed.clone()).unwrap();
    // Slots for the allowed bricks only, however large the budget.
    assert_eq!(c.stats().capacity, 9);
    assert_eq!(c.capacity(), 15);
    // Every brick asked for: only the allowed ones are read (the bad one is not).
    c.make_resident(&all_keys(&layout)).unwrap();
    assert_eq!(s.calls.load(Ordering::Relaxed), 9);
    let st = c.stats();
    assert_eq!(
        (st.reads, st.resident, st.bytes_read),
        (9, 9, 9 * SLOT_U16_B8)
    );
    for k in all_keys(&layout) {
        let i = c.index(k.b.map(|x| x as usize));
        assert_eq!(c.is_resident(k), allowed[i], "{k:?}");
    }
    assert!(c.fetch(&[bad]).unwrap().is_empty());
    assert_eq!(s.calls.load(Ordering::Relaxed), 9);
    assert_arena_holds_bricks(&c, &*s);
}
