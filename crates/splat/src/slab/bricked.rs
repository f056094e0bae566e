//! The slab march over resident bricks (docs/design/brick-seam.md §2.3, issue 31 item 4): the
//! bands of the image go in groups, as in [`Ctx::march_bands`]; before each group the bricks
//! its rays can sample are made resident (the serial point where a read may fail), and the
//! group marches reading them through [`Slotted`]. Every pixel's arithmetic is the in-memory
//! march's (cells, fractions and face tests from global indices; the same voxel values), so
//! the image is the same bits whatever the budget, the grouping or the thread count.
//!
//! **Which bricks a band needs.** The sample points of the rows `y0 … y1 − 1` on the planes
//! `first … last` are `P(x, y, d)`, affine in each of the pixel column `x`, the row `y` and
//! the depth `d` (`View::point`), so they lie in the convex hull of the eight points at the
//! ends of the three ranges, a hexahedron with planar faces (a frustum piece in perspective,
//! a parallelepiped in orthographic views). It is widened by half a pixel, half a plane and a
//! voxel each way (rounding of the f32 positions), and a brick is needed where its box of
//! cells meets it (no separating axis: the hull's bounds, its six faces, its edges crossed with
//! the grid axes). A sample's
//! cell is the floor of its position, clamped to the grid, so a sample at position `q` reads
//! the brick whose cells' box holds `q`; the halo holds the rest of its stencil. Composite
//! needs only bricks with an active 8³ block (the march samples no other: live lanes are in
//! active blocks, and the other lanes of an AVX2 group read slot 0 and are dropped); MIP and
//! MinIP sample every block.
//!
//! **Pieces, and the least budget.** Consecutive bands go together while their bricks over
//! every plane fit the cache. A band that does not fit marches in pieces ([`Planner::pieces`]):
//! the longest runs of planes whose bricks fit, and where even one plane of its rows does not
//! fit (a plane along the long axis of a volume wider than the image's bricks: one row of
//! bricks across the image, two high and two deep), its rows and columns are cut in two, again
//! and again, each half going on through the remaining planes. Columns are independent, and
//! each pixel meets its planes in order with its band's [`Carry`], so the bits are those of one
//! pass. The smallest piece, one pixel on one plane, spans along each index axis `a` at most
//! `L_a`: a pixel along the row and the column and a slab along the depth (after
//! supersampling, at that plane). Brick `b`'s cells widened by a voxel are
//! `[bB − 1, (b + 1)B + 1]`, so an interval of length `L` meets at most `2 + ⌊(L + 2)/B⌋` of
//! them: **two per axis, eight bricks in all, when every `L_a < B − 2`**. With the engine's
//! 64³ bricks that is every view whose (supersampled) pixel and slab span under 62 voxels, so
//! a budget of 8 slots draws every such frame (for u16, 8 × 601,526 bytes in the engine's
//! arena of 72 % of the budget less the skip-block grid: about 7 MiB). A smaller budget is refused with [`SplatError::Budget`] naming the
//! bricks one sample needs.

use super::march::{Carry, Counters, Ctx, Frame, Part};
use super::view::View;
use crate::error::{Result, SplatError};
use crate::sheets::{Progress, RenderMode, RenderSettings};
use crate::voxels::{Slotted, Vox};
use rayon::prelude::*;
use volsplat_core::Scalar;
use volsplat_core::glam::DVec3;
use volsplat_core::image::Rgba;
use volsplat_core::source::{BrickKey, BrickLayout};

/// The bricks of one level that a frame may read, made resident on demand: the brick cache
/// (`crate::cache::BrickCache`), or every brick at once in tests.
pub(crate) trait Resident<T>: Sync {
    /// How the level is cut into bricks.
    fn layout(&self) -> &BrickLayout;
    /// How many bricks can be resident at once.
    fn capacity(&self) -> usize;
    /// The memory budget the capacity comes from, bytes (for errors).
    fn budget(&self) -> u64;
    /// Reads the bricks of `keys` that are not resident, without placing them (read-ahead:
    /// called while a group marches, reading the arena).
    fn fetch(&self, keys: &[BrickKey]) -> Result<Vec<crate::cache::Fetched<T>>>;
    /// Makes every brick of `keys` (at most [`Resident::capacity`]) resident, placing the
    /// `fetched` ones and reading the rest.
    fn make_resident_with(
        &mut self,
        keys: &[BrickKey],
        fetched: Vec<crate::cache::Fetched<T>>,
    ) -> Result<()>;
    /// The slots, `E³` voxels each, padded so that a 4-byte read at the last voxel stays
    /// inside.
    fn arena(&self) -> &[T];
    /// Per brick of the layout (i fastest), its slot's first position in the arena (0 where
    /// not resident).
    fn bases(&self) -> &[u32];
}

/// Marches `frame` band group by band group, each group's bricks made resident in `res`
/// first (module docs); a group whose bricks exceed the budget marches in pieces, each
/// piece's bricks made resident in turn ([`Planner::pieces`]). The result is
/// [`Ctx::march_bands`]'s image (MIP and MinIP marched in pieces sample in another order, and
/// pieces of columns narrow the rows' live windows: the same pixels, other counters), and the
/// steps, the groups in pieces and the groups of those cut into columns or rows.
pub(super) fn march<T: Scalar>(
    frame: &Frame<'_>,
    res: &mut dyn Resident<T>,
    settings: &RenderSettings,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<(Vec<Rgba>, Counters, [usize; 3])> {
    let layout = res.layout().clone();
    let (w, h) = (settings.width, settings.height);
    let mut acc = vec![frame.acc_init(); w * h];
    let band_h = frame.band_rows(settings);
    let n_bands = h.div_ceil(band_h);
    let plan = Planner {
        frame,
        layout: &layout,
        needed: needed_bricks(frame, &layout),
        band_h,
        height: h,
        capacity: res.capacity(),
        budget: res.budget(),
        slot_bytes: (layout.slot_len() * std::mem::size_of::<T>()) as u64,
    };
    let groups = plan.groups(n_bands, frame.group_bands())?;
    let keys_of = |set: &[u32]| -> Vec<BrickKey> {
        set.iter().map(|&i| key_of(&layout, i as usize)).collect()
    };
    // Every (group, piece) in order, for the read-ahead.
    let steps: Vec<(usize, usize)> = groups
        .iter()
        .enumerate()
        .flat_map(|(g, group)| (0..group.pieces.len()).map(move |p| (g, p)))
        .collect();
    let ahead = (res.capacity() / 4).max(1);
    let mut counters = Counters::default();
    let mut rest: &mut [Rgba] = &mut acc;
    let mut done = 0;
    let mut fetched = Vec::new();
    let mut step = 0;
    for group in &groups {
        let (y0, y1) = group.rows;
        let (mine, tail) = std::mem::take(&mut rest).split_at_mut((y1 - y0) * w);
        rest = tail;
        // The group's units: its bands, or its rows where it marches in pieces (a piece may
        // hold some of its rows only), each with what its pieces carry to the next.
        let mut units: Vec<(usize, &mut [Rgba], Carry)> = mine
            .chunks_mut(group.unit * w)
            .enumerate()
            .map(|(i, px)| (y0 + i * group.unit, px, Carry::default()))
            .collect();
        for piece in &group.pieces {
            res.make_resident_with(&keys_of(&piece.bricks), std::mem::take(&mut fetched))?;
            step += 1;
            // Read-ahead of at most a quarter of the slots, so that the bricks read ahead and
            // the arena together stay within 1.25 × the arena (the rest of the next piece is
            // read when it is made resident).
            let next = steps.get(step).map(|&(g, p)| {
                let mut keys = keys_of(&groups[g].pieces[p].bricks);
                keys.truncate(ahead);
                keys
            });
            let ctx = Ctx::new(
                frame,
                Vox::Slotted(Slotted::new(res.arena(), res.bases(), &layout)),
            );
            let res_ref: &dyn Resident<T> = &*res;
            let (r0, r1) = piece.rows;
            let (c, read) = rayon::join(
                || {
                    units
                        .par_iter_mut()
                        .filter(|(y, px, _)| *y >= r0 && *y + px.len() / w <= r1)
                        .map(|(y, px, carry)| ctx.band_in(*y, px, piece.part, carry))
                        .reduce(Counters::default, Counters::add)
                },
                || next.map(|keys| res_ref.fetch(&keys)).transpose(),
            );
            fetched = read?.unwrap_or_default();
            counters = counters.add(c);
            // A group in pieces can take long (each piece reads its bricks): between its
            // pieces, the callback may cancel (the count of bands done is unchanged).
            if group.pieces.len() > 1
                && !progress(&Progress {
                    sheets_done: done,
                    sheets_total: n_bands,
                    accumulation: &[],
                })
            {
                return Err(SplatError::Cancelled);
            }
        }
        done += group.bands;
        if !progress(&Progress {
            sheets_done: done,
            sheets_total: n_bands,
            accumulation: &[],
        }) {
            return Err(SplatError::Cancelled);
        }
    }
    let pieced = groups.iter().filter(|g| g.pieces.len() > 1).count();
    // Groups with a band cut into columns or rows (not merely into bands).
    let on_edge = |y: usize| y.is_multiple_of(band_h) || y == h;
    let split = groups
        .iter()
        .filter(|g| {
            g.pieces
                .iter()
                .any(|p| p.part.cols != (0, w) || !on_edge(p.rows.0) || !on_edge(p.rows.1))
        })
        .count();
    Ok((acc, counters, [steps.len(), pieced, split]))
}

/// A run of consecutive bands (image rows `rows`, `[first, end)`) marched together, in
/// pieces; `unit` rows at a time (a band, or one row where it marches in pieces).
struct Group {
    bands: usize,
    rows: (usize, usize),
    unit: usize,
    pieces: Vec<Piece>,
}

/// The rows `[first, end)` of a group, the part of them marched ([`Part`]: columns and
/// planes), and the bricks (indices, i fastest, sorted) it needs.
struct Piece {
    rows: (usize, usize),
    part: Part,
    bricks: Vec<u32>,
}

/// How a frame's bands are cut into groups and pieces that fit the cache.
struct Planner<'p, 'a> {
    frame: &'p Frame<'a>,
    layout: &'p BrickLayout,
    needed: Vec<bool>,
    band_h: usize,
    height: usize,
    capacity: usize,
    budget: u64,
    slot_bytes: u64,
}

impl Planner<'_, '_> {
    /// The image rows of bands `[b0, b1)`.
    fn rows(&self, (b0, b1): (usize, usize)) -> (usize, usize) {
        (b0 * self.band_h, (b1 * self.band_h).min(self.height))
    }

    /// The bricks that the rows `rows` need on the part `part` of the image and planes.
    fn set(&self, rows: (usize, usize), part: Part) -> Vec<u32> {
        band_bricks(self.frame, self.layout, rows, part, &self.needed)
    }

    /// Every column of the image through the planes `planes`.
    fn whole(&self, planes: (usize, usize)) -> Part {
        Part {
            cols: (0, self.frame.width),
            planes,
        }
    }

    fn budget_error(&self, needed: usize) -> SplatError {
        SplatError::Budget {
            budget: self.budget,
            slot_bytes: self.slot_bytes,
            capacity: self.capacity,
            needed,
        }
    }

    /// Consecutive bands while their bricks over every plane fit together (at most
    /// `max_bands`); a band whose bricks alone do not fit marches in pieces
    /// ([`Planner::pieces`]), with as many bands beside it as there are threads (fewer where
    /// that is all the image has left). An error naming the budget where one sample of one
    /// plane needs more bricks than it holds.
    fn groups(&self, n_bands: usize, max_bands: usize) -> Result<Vec<Group>> {
        let all = self.whole(self.frame.plane_range);
        let mut groups = Vec::new();
        let mut b = 0;
        while b < n_bands {
            let mut set = self.set(self.rows((b, b + 1)), all);
            if set.len() <= self.capacity {
                let mut e = b + 1;
                while e < n_bands && e - b < max_bands {
                    let union = merge(&set, &self.set(self.rows((e, e + 1)), all));
                    if union.len() > self.capacity {
                        break;
                    }
                    set = union;
                    e += 1;
                }
                let rows = self.rows((b, e));
                groups.push(Group {
                    bands: e - b,
                    rows,
                    unit: self.band_h,
                    pieces: vec![Piece {
                        rows,
                        part: all,
                        bricks: set,
                    }],
                });
                b = e;
                continue;
            }
            let k = rayon::current_num_threads().clamp(1, n_bands - b);
            let rows = self.rows((b, b + k));
            let mut pieces = Vec::new();
            self.pieces(rows, all, &mut pieces)?;
            groups.push(Group {
                bands: k,
                rows,
                unit: 1,
                pieces,
            });
            b += k;
        }
        Ok(groups)
    }

    /// The rows `rows` of the image on `part` cut into pieces whose bricks fit, pushed onto
    /// `out` in an order that keeps each pixel's planes in order: the longest pieces of planes
    /// whose bricks fit (a binary search per piece); where even one plane does not fit, the
    /// rows and columns are cut in two ([`Planner::halves`]) and each half goes on from that
    /// plane in turn. A piece of one row, one column and one plane meets at most 8 bricks
    /// where a pixel and a slab span under `B − 2` voxels along each index axis (module docs),
    /// so any budget of 8 slots completes such a frame; an error naming the budget where even
    /// such a piece does not fit.
    fn pieces(&self, rows: (usize, usize), part: Part, out: &mut Vec<Piece>) -> Result<()> {
        let (mut p0, end) = part.planes;
        let cols = part.cols;
        let at = |planes| Part { cols, planes };
        while p0 < end {
            let one = self.set(rows, at((p0, p0 + 1)));
            if one.len() > self.capacity {
                let Some(halves) = self.halves(rows, cols) else {
                    return Err(self.budget_error(one.len()));
                };
                for (rows, cols) in halves {
                    let planes = (p0, end);
                    self.pieces(rows, Part { cols, planes }, out)?;
                }
                return Ok(());
            }
            // The longest piece from p0 that fits (the set grows with the piece).
            let (mut lo, mut hi) = (p0 + 1, end);
            let mut best = one;
            while lo < hi {
                let mid = (lo + hi).div_ceil(2);
                let s = self.set(rows, at((p0, mid)));
                if s.len() <= self.capacity {
                    lo = mid;
                    best = s;
                } else {
                    hi = mid - 1;
                }
            }
            out.push(Piece {
                rows,
                part: at((p0, lo)),
                bricks: best,
            });
            p0 = lo;
        }
        Ok(())
    }

    /// Rows `rows` and columns `cols` cut in two: the bands apart first (at a band's edge),
    /// then the columns, then the rows of one band; `None` for one pixel.
    #[allow(clippy::type_complexity)]
    fn halves(
        &self,
        (y0, y1): (usize, usize),
        (x0, x1): (usize, usize),
    ) -> Option<[((usize, usize), (usize, usize)); 2]> {
        let (ys, xs) = ((y0, y1), (x0, x1));
        if y1 - y0 > self.band_h {
            let mid = y0 + (y1 - y0).div_ceil(self.band_h) / 2 * self.band_h;
            Some([((y0, mid), xs), ((mid, y1), xs)])
        } else if x1 - x0 > 1 {
            let mid = x0 + (x1 - x0) / 2;
            Some([(ys, (x0, mid)), (ys, (mid, x1))])
        } else if y1 - y0 > 1 {
            let mid = y0 + (y1 - y0) / 2;
            Some([((y0, mid), xs), ((mid, y1), xs)])
        } else {
            None
        }
    }
}

/// The sorted union of two sorted lists.
fn merge(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        let x = match (a.get(i), b.get(j)) {
            (Some(&x), Some(&y)) if x == y => {
                i += 1;
                j += 1;
                x
            }
            (Some(&x), Some(&y)) if x < y => {
                i += 1;
                x
            }
            (Some(&x), None) => {
                i += 1;
                x
            }
            (_, Some(&y)) => {
                j += 1;
                y
            }
            (None, None) => unreachable!(),
        };
        out.push(x);
    }
    out
}

/// The key of brick index `i` (i fastest over `layout.dims()`).
fn key_of(layout: &BrickLayout, i: usize) -> BrickKey {
    let d = layout.dims();
    BrickKey {
        level: layout.level(),
        b: [i % d[0], i / d[0] % d[1], i / (d[0] * d[1])].map(|x| x as u32),
    }
}

/// Per brick (i fastest): whether the frame can sample it. Composite skipping empty space
/// samples only the active 8³ blocks ([`Frame::active`]); the other modes sample all.
fn needed_bricks(frame: &Frame<'_>, layout: &BrickLayout) -> Vec<bool> {
    let d = layout.dims();
    let n = d[0] * d[1] * d[2];
    if frame.mode != RenderMode::Composite || !frame.skip_empty {
        return vec![true; n];
    }
    let per = layout.size() / crate::bricks::BRICK;
    let bd = frame.bricks.dims;
    let mut needed = vec![false; n];
    for (q, &on) in frame.active.iter().enumerate() {
        if on {
            let blk = [q % bd[0], q / bd[0] % bd[1], q / (bd[0] * bd[1])];
            let b = blk.map(|x| x / per);
            needed[(b[2] * d[1] + b[1]) * d[0] + b[0]] = true;
        }
    }
    needed
}

/// The bricks (indices, sorted) whose cells the pixels `part.cols` of the rows `[y0, y1)` can
/// sample on the planes `part.planes` (module docs), among those `needed`.
fn band_bricks(
    frame: &Frame<'_>,
    layout: &BrickLayout,
    (y0, y1): (usize, usize),
    part: Part,
    needed: &[bool],
) -> Vec<u32> {
    let ((x0, x1), (first, end)) = (part.cols, part.planes);
    if first >= end || y0 >= y1 || x0 >= x1 {
        return Vec::new();
    }
    let hull = Hull::new(
        &frame.view,
        (x0 as f64 - 0.5, x1 as f64 - 0.5),
        (y0 as f64 - 0.5, y1 as f64 - 0.5),
        (
            frame.depth(first) - 0.5 * frame.delta,
            frame.depth(end - 1) + 0.5 * frame.delta,
        ),
    );
    let d = layout.dims();
    let size = layout.size() as f64;
    // The bricks within the hull's bounds (widened by a voxel), then each against its faces.
    let range: [(usize, usize); 3] = std::array::from_fn(|a| {
        let lo = ((hull.lo[a] - 1.0) / size).floor().max(0.0);
        let hi = ((hull.hi[a] + 1.0) / size).floor();
        if hi < 0.0 || lo >= d[a] as f64 {
            return (1, 0);
        }
        (lo as usize, (hi as usize).min(d[a] - 1))
    });
    let mut out = Vec::new();
    for bk in range[2].0..=range[2].1 {
        for bj in range[1].0..=range[1].1 {
            for bi in range[0].0..=range[0].1 {
                let i = (bk * d[1] + bj) * d[0] + bi;
                if !needed[i] {
                    continue;
                }
                let b = [bi, bj, bk];
                let lo = DVec3::from(b.map(|x| x as f64 * size - 1.0));
                let hi = DVec3::from(b.map(|x| (x + 1) as f64 * size + 1.0));
                if hull.meets_box(lo, hi) {
                    out.push(i as u32);
                }
            }
        }
    }
    out
}

/// The convex hull of the sample points of a band (module docs): its bounds and its six
/// faces as outward planes `n·p ≤ c`.
struct Hull {
    lo: DVec3,
    hi: DVec3,
    faces: Vec<(DVec3, f64)>,
    /// The separating axes of the hull's edges against the box's (the cross products of each
    /// edge direction with each grid axis), with the hull's extent along each: with the faces
    /// and the bounds, the whole separating-axis test of two convex solids.
    edges: Vec<(DVec3, f64, f64)>,
}

impl Hull {
    /// The hull of `view.point(x, y, d)` over the three ranges.
    fn new(view: &View, xs: (f64, f64), ys: (f64, f64), ds: (f64, f64)) -> Self {
        let pick = |r: (f64, f64), hi: bool| if hi { r.1 } else { r.0 };
        // Corner `c`: bit 0 picks x, bit 1 y, bit 2 d.
        let corner: [DVec3; 8] = std::array::from_fn(|c| {
            view.point(
                pick(xs, c & 1 == 1),
                pick(ys, c & 2 == 2),
                pick(ds, c & 4 == 4),
            )
        });
        let lo = corner.iter().fold(DVec3::INFINITY, |m, p| m.min(*p));
        let hi = corner.iter().fold(DVec3::NEG_INFINITY, |m, p| m.max(*p));
        let centre = corner.iter().fold(DVec3::ZERO, |s, p| s + *p) / 8.0;
        let mut faces = Vec::with_capacity(6);
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for side in [0, 1] {
                let at = |bu: usize, bv: usize| corner[side << axis | bu << u | bv << v];
                let p0 = at(0, 0);
                let n = (at(1, 0) - p0).cross(at(0, 1) - p0);
                let len = n.length();
                if !(len > 0.0 && len.is_finite()) {
                    continue; // A degenerate face bounds nothing; the others still do.
                }
                let mut n = n / len;
                if n.dot(centre - p0) > 0.0 {
                    n = -n;
                }
                faces.push((n, n.dot(p0)));
            }
        }
        // Edge directions: along x (bit 0) and y (bit 1) they are parallel (the right and up
        // of the view); along the depth (bit 2) the four rays differ in perspective.
        let mut dirs = vec![corner[1] - corner[0], corner[2] - corner[0]];
        dirs.extend((0..4).map(|c| corner[c | 4] - corner[c]));
        let mut edges = Vec::with_capacity(18);
        for d in dirs {
            for g in [DVec3::X, DVec3::Y, DVec3::Z] {
                let axis = d.cross(g);
                // A degenerate axis (or a NaN one) separates nothing: skipped.
                let big = axis
                    .length_squared()
                    .partial_cmp(&(1e-18 * d.length_squared()));
                if big != Some(std::cmp::Ordering::Greater) {
                    continue;
                }
                let (lo, hi) = corner
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |m, p| {
                        let t = axis.dot(*p);
                        (m.0.min(t), m.1.max(t))
                    });
                edges.push((axis, lo, hi));
            }
        }
        Hull {
            lo,
            hi,
            faces,
            edges,
        }
    }

    /// Whether the box `[lo, hi]` meets the hull: no separating axis among the hull's bounds,
    /// its faces and its edges crossed with the grid axes (the separating-axis theorem; the
    /// hull and the box were both widened, so rounding cannot drop a brick that is met).
    fn meets_box(&self, lo: DVec3, hi: DVec3) -> bool {
        if (0..3).any(|a| hi[a] < self.lo[a] || lo[a] > self.hi[a]) {
            return false;
        }
        let faces = self.faces.iter().all(|&(n, c)| {
            // The box's corner furthest against the normal.
            let p = DVec3::new(
                if n.x < 0.0 { hi.x } else { lo.x },
                if n.y < 0.0 { hi.y } else { lo.y },
                if n.z < 0.0 { hi.z } else { lo.z },
            );
            n.dot(p) <= c
        });
        let (centre, half) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
        faces
            && self.edges.iter().all(|&(axis, a, b)| {
                let c = axis.dot(centre);
                let r = axis.abs().dot(half);
                c + r >= a && c - r <= b
            })
    }
}

impl<T: Scalar> Resident<T> for crate::cache::BrickCache<T> {
    fn layout(&self) -> &BrickLayout {
        crate::cache::BrickCache::layout(self)
    }
    fn capacity(&self) -> usize {
        crate::cache::BrickCache::capacity(self)
    }
    fn budget(&self) -> u64 {
        crate::cache::BrickCache::budget(self)
    }
    fn fetch(&self, keys: &[BrickKey]) -> Result<Vec<crate::cache::Fetched<T>>> {
        crate::cache::BrickCache::fetch(self, keys)
    }
    fn make_resident_with(
        &mut self,
        keys: &[BrickKey],
        fetched: Vec<crate::cache::Fetched<T>>,
    ) -> Result<()> {
        crate::cache::BrickCache::make_resident_with(self, keys, fetched)
    }
    fn arena(&self) -> &[T] {
        crate::cache::BrickCache::arena(self)
    }
    fn bases(&self) -> &[u32] {
        crate::cache::BrickCache::bases(self)
    }
}

#[cfg(test)]
#[path = "bricked_tests.rs"]
mod tests;
