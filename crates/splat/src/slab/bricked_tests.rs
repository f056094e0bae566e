//! The slab march through resident bricks against the march through the whole volume: the
//! same bits in every mode, projection and kernel, whatever the brick size, the budget and the
//! thread count (docs/design/brick-seam.md §3, `bricked_equals_in_memory_bit_for_bit`).

use super::*;
use crate::cache::Fetched;
use crate::sheets::{Preintegrate, RenderMode, RenderSettings, Rendered, Visibility};
use crate::slab::{Access, render_slabs, render_slabs_in};
use crate::{Antialias, BrickGrid, ShadeAt};
use std::sync::Arc;
use volsplat_core::glam::DVec3;
use volsplat_core::phantom::{self, Blob, GaussianBlobs};
use volsplat_core::source::{BrickSource, InMemory};
use volsplat_core::{Camera, CrioTables, TransferFunction, Volume};
use volsplat_testkit::fixtures::orbit_camera;

/// Bricks made resident by copying them out of an in-memory volume: at most `capacity` at a
/// time, every call placing its keys from slot 0 (no reuse), so that a small capacity
/// exercises the grouping; `corrupt` adds a value to one slot position after each placement.
struct Copies<T: Scalar> {
    source: InMemory<T>,
    layout: BrickLayout,
    capacity: usize,
    arena: Vec<T>,
    bases: Vec<u32>,
    calls: usize,
    fetched: usize,
    /// Every brick placed so far.
    seen: std::collections::BTreeSet<BrickKey>,
    corrupt: Option<(BrickKey, usize, f64)>,
}

impl<T: Scalar> Copies<T> {
    fn new(volume: &Volume<T>, size: usize, capacity: usize) -> Self {
        let source = InMemory::new(Arc::new(volume.clone()), size).unwrap();
        let layout = source.layout(0).unwrap().clone();
        let n = layout.brick_count();
        Copies {
            capacity: capacity.min(n),
            arena: vec![T::from_f64(0.0); capacity.min(n) * layout.slot_len() + 4],
            bases: vec![0; n],
            source,
            layout,
            calls: 0,
            fetched: 0,
            seen: Default::default(),
            corrupt: None,
        }
    }
}

impl<T: Scalar> Resident<T> for Copies<T> {
    fn layout(&self) -> &BrickLayout {
        &self.layout
    }
    fn capacity(&self) -> usize {
        self.capacity
    }
    fn budget(&self) -> u64 {
        (self.capacity * self.layout.slot_len() * std::mem::size_of::<T>()) as u64
    }
    fn fetch(&self, keys: &[BrickKey]) -> Result<Vec<crate::cache::Fetched<T>>> {
        Ok(keys
            .iter()
            .map(|&k| {
                self.source.brick(k).map(|b| Fetched {
                    key: k,
                    data: b.data.clone(),
                })
            })
            .collect::<volsplat_core::Result<_>>()?)
    }
    fn make_resident_with(
        &mut self,
        keys: &[BrickKey],
        fetched: Vec<crate::cache::Fetched<T>>,
    ) -> Result<()> {
        assert!(keys.len() <= self.capacity, "more keys than slots");
        self.calls += 1;
        self.fetched += fetched.len();
        self.seen.extend(keys);
        self.bases.fill(0);
        // Poison the arena: a read of a brick not placed gives a wrong value, not a stale one.
        self.arena.fill(T::from_f64(1e6));
        let len = self.layout.slot_len();
        let d = self.layout.dims();
        for (slot, &key) in keys.iter().enumerate() {
            let data = match fetched.iter().find(|b| b.key == key) {
                Some(b) => b.data.clone(),
                None => self.source.brick(key)?.data.clone(),
            };
            self.arena[slot * len..(slot + 1) * len].copy_from_slice(&data);
            let b = key.b.map(|x| x as usize);
            self.bases[(b[2] * d[1] + b[1]) * d[0] + b[0]] = (slot * len) as u32;
            if let Some((k, at, by)) = self.corrupt
                && k == key
            {
                let v = self.arena[slot * len + at].to_f32();
                self.arena[slot * len + at] = T::from_f64(f64::from(v) + by);
            }
        }
        Ok(())
    }
    fn arena(&self) -> &[T] {
        &self.arena
    }
    fn bases(&self) -> &[u32] {
        &self.bases
    }
}

fn blobs() -> GaussianBlobs {
    let b = |x: f64, y: f64, z: f64, sigma: f64, amplitude: f64| Blob {
        center: DVec3::new(x, y, z),
        sigma,
        amplitude,
    };
    GaussianBlobs::new(vec![
        b(0.0, 0.0, 0.0, 0.2, 1.0),
        b(0.3, 0.25, -0.2, 0.14, 0.8),
        b(-0.32, 0.2, 0.3, 0.12, 0.9),
        b(0.2, -0.35, 0.3, 0.13, 0.6),
    ])
}

fn settings(w: usize, h: usize, mode: RenderMode) -> RenderSettings {
    RenderSettings {
        width: w,
        height: h,
        mode,
        visibility: Visibility::ImageAligned,
        antialias: Antialias::None,
        band_height: 8,
        ..Default::default()
    }
}

/// The frames compared, their transfer functions mapped from [0, 1] onto `[lo, hi]`:
/// (name, mode, tables, pre-integrate).
fn cases_in(lo: f64, hi: f64) -> Vec<(&'static str, RenderMode, CrioTables, Preintegrate)> {
    let mut base = volsplat_testkit::fixtures::shaded_transfer_function();
    let x = |v: f64| lo + v * (hi - lo);
    base.color.iter_mut().for_each(|p| p[0] = x(p[0]));
    base.scalar_opacity.iter_mut().for_each(|p| p[0] = x(p[0]));
    let unshaded = TransferFunction {
        shade: false,
        ..base.clone()
    };
    // Opacity by gradient magnitude: the per-sample classifier (`band_plain`).
    let by_gradient = TransferFunction {
        gradient_opacity: Some(vec![[0.0, 0.2], [0.5 * (hi - lo), 1.0]]),
        ..base.clone()
    };
    let t = |tf: &TransferFunction| CrioTables::from_transfer_function(tf, 1024).unwrap();
    vec![
        (
            "unshaded",
            RenderMode::Composite,
            t(&unshaded),
            Preintegrate::Off,
        ),
        (
            "unshaded preint",
            RenderMode::Composite,
            t(&unshaded),
            Preintegrate::On,
        ),
        ("shaded", RenderMode::Composite, t(&base), Preintegrate::Off),
        (
            "shaded preint",
            RenderMode::Composite,
            t(&base),
            Preintegrate::On,
        ),
        (
            "gradient opacity",
            RenderMode::Composite,
            t(&by_gradient),
            Preintegrate::Off,
        ),
        ("mip", RenderMode::Mip, t(&unshaded), Preintegrate::Off),
        ("minip", RenderMode::Minip, t(&unshaded), Preintegrate::Off),
    ]
}

fn cases() -> Vec<(&'static str, RenderMode, CrioTables, Preintegrate)> {
    cases_in(0.0, 1.0)
}

/// Pixels, values, and the counters where they are comparable (MIP and MinIP marched in
/// pieces of planes sample in another order, and pieces of columns narrow the rows' live
/// windows: `None`).
type Bits = (Vec<u32>, Option<Vec<u32>>, Option<[u64; 3]>);

fn bits(r: &Rendered) -> Bits {
    (
        r.image
            .pixels()
            .as_flattened()
            .iter()
            .map(|v| v.to_bits())
            .collect(),
        r.values
            .as_ref()
            .map(|v| v.values().iter().map(|x| x.to_bits()).collect()),
        (r.stats.split_groups == 0 && (r.values.is_none() || r.stats.pieced_groups == 0))
            .then_some([r.stats.voxels, r.stats.splats, r.stats.splats_terminated]),
    )
}

fn bricked<T: Scalar>(
    res: &mut Copies<T>,
    bricks: &BrickGrid,
    cam: &Camera,
    tables: &CrioTables,
    s: &RenderSettings,
) -> Result<Rendered> {
    render_slabs_in(
        &mut Access::Bricked(res),
        cam,
        tables,
        s,
        bricks,
        &mut |_| true,
    )
}

/// Every case through bricks of 8 and 16 cells, with room for every brick and with room for
/// little more than one band's, against the whole volume: the same image bits, values and
/// counters, with and without AVX2, from four eyes in both projections.
fn compare<T: Scalar>(volume: &Volume<T>, what: &str) {
    let grid = volume.grid();
    let bricks = BrickGrid::build(volume);
    let (lo, hi) = volume.value_range();
    for (name, mode, tables, preint) in cases_in(lo, hi) {
        for (az, el) in [(61.0, 17.0), (0.0, 0.0), (135.0, -40.0), (200.0, 80.0)] {
            for parallel in [true, false] {
                let cam = orbit_camera(grid, az, el, parallel);
                for simd in [true, false] {
                    let mut s = settings(70, 52, mode);
                    s.simd = simd;
                    s.preintegrate = preint;
                    s.shade_at = ShadeAt::Samples;
                    let want =
                        render_slabs(volume, &cam, &tables, &s, Some(&bricks), &mut |_| true)
                            .unwrap();
                    for size in [8, 16] {
                        for small in [false, true] {
                            // Room for every brick, or for little more than the largest
                            // band's set: many groups.
                            let capacity = if small {
                                band_need(volume, size, &cam, &tables, &s) + 1
                            } else {
                                usize::MAX
                            };
                            let mut res = Copies::new(volume, size, capacity);
                            let got = bricked(&mut res, &bricks, &cam, &tables, &s).unwrap();
                            same(
                                &bits(&got),
                                &bits(&want),
                                &format!(
                                    "{what} {name} az {az} el {el} parallel {parallel} \
                                     simd {simd} B {size} capacity {}",
                                    res.capacity
                                ),
                            );
                            if small && res.seen.len() > res.capacity {
                                assert!(res.calls > 1, "{what} {name}: one group only");
                            }
                        }
                    }
                }
            }
        }
    }
}

/// The first differing element of two frames' bits, named (a whole image in a message is
/// unreadable).
fn same(a: &Bits, b: &Bits, what: &str) {
    if let Some(i) = (0..a.0.len()).find(|&i| a.0.get(i) != b.0.get(i)) {
        panic!(
            "{what}: pixel channel {i} differs: {} against {}",
            a.0[i],
            b.0.get(i).copied().unwrap_or(0)
        );
    }
    assert_eq!(a.0.len(), b.0.len(), "{what}");
    if let (Some(x), Some(y)) = (&a.1, &b.1)
        && let Some(i) = (0..x.len()).find(|&i| x.get(i) != y.get(i))
    {
        panic!("{what}: value {i} differs");
    }
    assert_eq!(a.1.is_some(), b.1.is_some(), "{what}");
    if let (Some(x), Some(y)) = (a.2, b.2) {
        assert_eq!(x, y, "{what}: counters");
    }
}

/// The fewest slots a frame renders with: found by lowering the capacity until the render
/// refuses (one sample of one plane's bricks, since bands march in pieces of planes, columns
/// and rows; at most [`MIN_SLOTS`] here).
fn band_need<T: Scalar>(
    volume: &Volume<T>,
    size: usize,
    cam: &Camera,
    tables: &CrioTables,
    s: &RenderSettings,
) -> usize {
    least(volume, size, cam, tables, s, |r| r.is_ok())
}

/// The fewest slots a frame renders with without cutting a band into columns or rows (one
/// plane of one band's bricks).
fn plane_need<T: Scalar>(
    volume: &Volume<T>,
    size: usize,
    cam: &Camera,
    tables: &CrioTables,
    s: &RenderSettings,
) -> usize {
    least(volume, size, cam, tables, s, |r| {
        r.as_ref().is_ok_and(|r| r.stats.split_groups == 0)
    })
}

/// The least capacity (a binary search) whose bricked render passes `ok` (which must hold
/// from some capacity on, and for every brick).
fn least<T: Scalar>(
    volume: &Volume<T>,
    size: usize,
    cam: &Camera,
    tables: &CrioTables,
    s: &RenderSettings,
    ok: impl Fn(&Result<Rendered>) -> bool,
) -> usize {
    let bricks = BrickGrid::build(volume);
    let n = Copies::new(volume, size, 1).layout.brick_count();
    let (mut lo, mut hi) = (0, n); // hi works (every brick), lo = 0 only for empty frames.
    while lo + 1 < hi {
        let mid = (lo + hi) / 2;
        let mut r = Copies::new(volume, size, mid.max(1));
        r.capacity = mid;
        if ok(&bricked(&mut r, &bricks, cam, tables, s)) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// Minified views are drawn with several rays per pixel (`supersample`, a whole and a
/// fractional factor): through bricks too, the same bits.
#[test]
fn supersampled_minified_views_are_the_same_bits() {
    let f = phantom::sample(&blobs(), [61, 57, 49], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    for (name, mode, tables, preint) in cases() {
        for (w, h) in [(20, 16), (27, 23)] {
            let cam = orbit_camera(f.grid(), 40.0, 25.0, w == 20);
            let mut s = settings(w, h, mode);
            s.antialias = Antialias::Swan;
            s.preintegrate = preint;
            let want = render_slabs(&f, &cam, &tables, &s, Some(&bricks), &mut |_| true).unwrap();
            assert!(want.stats.supersampling > 1.0, "{name}: not minified");
            let mut res = Copies::new(&f, 16, band_need(&f, 16, &cam, &tables, &s) + 1);
            let got = bricked(&mut res, &bricks, &cam, &tables, &s).unwrap();
            same(&bits(&got), &bits(&want), &format!("{name} {w}×{h}"));
        }
    }
}

#[test]
fn bricked_equals_in_memory_bit_for_bit() {
    // Odd sizes (edge bricks partly outside), an axis of one voxel and one of two.
    for dims in [[37, 29, 23], [30, 1, 27], [2, 26, 21]] {
        let f = phantom::sample(&blobs(), dims, 1).unwrap();
        compare(&f, &format!("f32 {dims:?}"));
        let grid = f.grid().clone();
        let u16s = Volume::new(
            grid.clone(),
            f.data().iter().map(|&v| (v * 60000.0) as u16).collect(),
        )
        .unwrap();
        compare(&u16s, &format!("u16 {dims:?}"));
    }
    let f = phantom::sample(&blobs(), [33, 35, 31], 1).unwrap();
    let grid = f.grid().clone();
    let i8s = Volume::new(
        grid.clone(),
        f.data()
            .iter()
            .map(|&v| (v * 250.0 - 120.0) as i8)
            .collect(),
    )
    .unwrap();
    compare(&i8s, "i8");
}

/// The same bits for 1 and 3 threads through bricks (the grouping does not follow the
/// threads' count, and each pixel's arithmetic is its own).
#[test]
fn bricked_frames_do_not_depend_on_the_thread_count() {
    let f = phantom::sample(&blobs(), [41, 38, 36], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    for (name, mode, tables, preint) in cases() {
        let cam = orbit_camera(f.grid(), 33.0, 21.0, false);
        let mut s = settings(90, 77, mode);
        s.preintegrate = preint;
        let capacity = band_need(&f, 8, &cam, &tables, &s) + 3;
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut res = Copies::new(&f, 8, capacity);
                    bits(&bricked(&mut res, &bricks, &cam, &tables, &s).unwrap())
                })
        };
        same(&run(1), &run(3), name);
    }
}

/// The test above is worth something only if a wrong voxel in a brick shows: one voxel on
/// the far face of a brick inside the object, raised, changes the picture (unshaded: its
/// cells' samples; shaded: also the differences of the next brick's cells, read through its
/// halo from its own slot, so the copy there is what they read).
#[test]
fn a_wrong_voxel_in_one_slot_changes_the_picture() {
    let f = phantom::sample(&blobs(), [40, 40, 40], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    let cam = orbit_camera(f.grid(), 20.0, 10.0, true);
    for (name, mode, tables, preint) in cases() {
        if mode == RenderMode::Minip {
            // Its rays reach the background's zeros, and every block whose minimum cannot
            // beat that is skipped exactly: no wrong value inside the object can show.
            continue;
        }
        let mut s = settings(64, 64, mode);
        s.preintegrate = preint;
        let want = render_slabs(&f, &cam, &tables, &s, Some(&bricks), &mut |_| true).unwrap();
        let mut res = Copies::new(&f, 16, usize::MAX);
        let e = res.layout.extent();
        // Brick (1, 1, 1) owns voxels 16 … 32; its slot position of voxel (20, 20, 20).
        let at = 5 + 5 * e + 5 * e * e;
        res.corrupt = Some((res.layout.key([1, 1, 1]).unwrap(), at, 40.0));
        let got = bricked(&mut res, &bricks, &cam, &tables, &s).unwrap();
        assert!(
            bits(&got) != bits(&want),
            "{name}: a wrong voxel went unseen"
        );
    }
}

/// Room for fewer bricks than one band needs, but for one plane of it: the band marches its
/// planes in pieces, each piece's bricks made resident in turn; the same picture (composite:
/// the same counters too; MIP and MinIP sample the pieces in another order, so only their
/// extremes are compared).
#[test]
fn bands_larger_than_the_budget_march_in_pieces_with_the_same_bits() {
    let f = phantom::sample(&blobs(), [45, 41, 38], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    let mut pieced = 0;
    for (name, mode, tables, preint) in cases() {
        for (az, parallel) in [(35.0, true), (120.0, false)] {
            let cam = orbit_camera(f.grid(), az, 27.0, parallel);
            let mut s = settings(60, 44, mode);
            s.preintegrate = preint;
            let want = render_slabs(&f, &cam, &tables, &s, Some(&bricks), &mut |_| true).unwrap();
            let need = plane_need(&f, 8, &cam, &tables, &s);
            for capacity in [need, need + 3] {
                let mut res = Copies::new(&f, 8, capacity);
                let got = bricked(&mut res, &bricks, &cam, &tables, &s).unwrap();
                assert_eq!(got.stats.split_groups, 0, "{name}: a band was cut");
                pieced += got.stats.pieced_groups;
                same(
                    &bits(&got),
                    &bits(&want),
                    &format!("{name} az {az} capacity {capacity}"),
                );
            }
        }
    }
    assert!(pieced > 10, "only {pieced} groups were marched in pieces");
}

/// The bricks one sample of one plane can need where a pixel and a slab span under `B − 2`
/// voxels along each index axis (`Planner::pieces`): two per axis.
const MIN_SLOTS: usize = 8;

/// The view of the 8 GiB benchmark that was refused (BENCHMARKS §32, issue 31 item 4): along
/// z, across a volume long in x, one plane of one 8-row band meets a row of bricks across the
/// image, two or three high and two deep (here 8 × 3 × 2), more than the budget holds. It
/// failed with `SplatError::Budget` before bands were cut into columns; now the band's
/// columns (and rows, if need be) march apart, each column's planes in order with their
/// carry: the in-memory bits in every mode, both projections, AVX2 on and off, 1 and 3
/// threads, at room for 12 bricks and at the stated minimum, [`MIN_SLOTS`].
#[test]
fn a_plane_of_a_band_above_the_budget_marches_in_columns_with_the_same_bits() {
    let f = phantom::sample(&blobs(), [64, 24, 40], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    let pool = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let pools = [pool(1), pool(3)];
    for (name, mode, tables, preint) in cases() {
        for parallel in [true, false] {
            let cam = orbit_camera(f.grid(), 0.0, 0.0, parallel);
            for simd in [true, false] {
                let mut s = settings(96, 40, mode);
                s.simd = simd;
                s.preintegrate = preint;
                let want =
                    render_slabs(&f, &cam, &tables, &s, Some(&bricks), &mut |_| true).unwrap();
                let plane = plane_need(&f, 8, &cam, &tables, &s);
                assert!(plane > 12, "{name}: one plane of a band needs only {plane}");
                for capacity in [12, MIN_SLOTS] {
                    for pool in &pools {
                        let got = pool.install(|| {
                            let mut res = Copies::new(&f, 8, capacity);
                            bricked(&mut res, &bricks, &cam, &tables, &s).unwrap()
                        });
                        let what = format!(
                            "{name} parallel {parallel} simd {simd} capacity {capacity} \
                             threads {}",
                            pool.current_num_threads()
                        );
                        assert!(got.stats.split_groups > 0, "{what}: no band was cut");
                        same(&bits(&got), &bits(&want), &what);
                    }
                }
            }
        }
    }
}

/// A frame whose bands march in many pieces can be cancelled between two pieces, not only
/// after the whole group: the callback's `false` after the first piece stops the frame with
/// `Cancelled` after one step.
#[test]
fn a_frame_in_pieces_can_be_cancelled_between_pieces() {
    let f = phantom::sample(&blobs(), [64, 24, 40], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    let (_, mode, tables, _) = cases().remove(0);
    let cam = orbit_camera(f.grid(), 0.0, 0.0, true);
    let s = settings(96, 40, mode);
    let mut res = Copies::new(&f, 8, MIN_SLOTS);
    let mut calls = 0;
    let e = render_slabs_in(
        &mut Access::Bricked(&mut res),
        &cam,
        &tables,
        &s,
        &bricks,
        &mut |_| {
            calls += 1;
            false
        },
    )
    .unwrap_err();
    assert!(matches!(e, SplatError::Cancelled), "{e}");
    assert_eq!(
        (calls, res.calls),
        (1, 1),
        "(callbacks, steps made resident)"
    );
}

/// [`MIN_SLOTS`] is enough from any eye (the bound of `Planner::pieces`), in both
/// projections, for a frame that samples every brick on its rays (MIP) and for one that
/// pre-integrates (a carry between pieces): the in-memory bits.
#[test]
fn the_stated_minimum_budget_renders_every_view() {
    let f = phantom::sample(&blobs(), [37, 29, 23], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    let mut all = cases();
    let picked = [all.remove(5), all.remove(1)]; // MIP, unshaded pre-integrated.
    for (name, mode, tables, preint) in picked {
        for (az, el) in [(61.0, 17.0), (135.0, -40.0), (200.0, 80.0), (10.0, 45.0)] {
            for parallel in [true, false] {
                let cam = orbit_camera(f.grid(), az, el, parallel);
                let mut s = settings(70, 52, mode);
                s.preintegrate = preint;
                let want =
                    render_slabs(&f, &cam, &tables, &s, Some(&bricks), &mut |_| true).unwrap();
                for size in [8, 16] {
                    let mut res = Copies::new(&f, size, MIN_SLOTS);
                    let got = bricked(&mut res, &bricks, &cam, &tables, &s).unwrap();
                    same(
                        &bits(&got),
                        &bits(&want),
                        &format!("{name} az {az} el {el} parallel {parallel} B {size}"),
                    );
                }
            }
        }
    }
}

/// Room for fewer bricks than one sample of one plane needs is an error naming the memory
/// budget and the bricks needed (at most [`MIN_SLOTS`]), not a wrong picture or a panic.
#[test]
fn a_budget_below_one_samples_bricks_is_an_error_naming_memory() {
    let f = phantom::sample(&blobs(), [40, 40, 40], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    let cam = orbit_camera(f.grid(), 20.0, 10.0, true);
    let (_, mode, tables, _) = cases().remove(5); // MIP reads every brick on its rays.
    let s = settings(64, 64, mode);
    for capacity in [1, MIN_SLOTS - 1] {
        let mut res = Copies::new(&f, 8, capacity);
        let e = bricked(&mut res, &bricks, &cam, &tables, &s).unwrap_err();
        let SplatError::Budget { needed, .. } = e else {
            panic!("capacity {capacity}: {e}");
        };
        assert!(
            needed > capacity && needed <= MIN_SLOTS,
            "capacity {capacity}: {needed} needed"
        );
        let text = e.to_string();
        assert!(text.contains("memory budget"), "{e}");
        assert!(
            text.contains(&format!("but {needed} bricks are needed")),
            "{e}"
        );
    }
}

/// Shading at the voxels needs the voxels' direction codes, a field of the whole volume: a
/// bricked frame refuses it by name.
#[test]
fn shading_at_the_voxels_is_refused_for_bricks() {
    let f = phantom::sample(&blobs(), [20, 20, 20], 1).unwrap();
    let bricks = BrickGrid::build(&f);
    let cam = orbit_camera(f.grid(), 20.0, 10.0, true);
    let (_, mode, tables, _) = cases().remove(2);
    let mut s = settings(32, 32, mode);
    s.shade_at = ShadeAt::Voxels;
    let mut res = Copies::new(&f, 8, usize::MAX);
    let e = bricked(&mut res, &bricks, &cam, &tables, &s).unwrap_err();
    assert!(
        matches!(
            e,
            SplatError::Setting {
                name: "shade_at",
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn merge_is_the_sorted_union() {
    assert_eq!(merge(&[1, 3, 5], &[2, 3, 6]), vec![1, 2, 3, 5, 6]);
    assert_eq!(merge(&[], &[2]), vec![2]);
    assert_eq!(merge(&[4], &[]), vec![4]);
}
