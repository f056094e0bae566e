//! Which planes and pixels of each image row can meet a brick with opacity ([`row_reach`]):
//! the composite march (`Ctx::band_post`) visits only those, instead of walking every row of
//! every plane and testing each group of pixels against the bricks.
//!
//! Each active brick (an 8³ block of cells of [`BrickGrid`] whose values can have opacity) is
//! projected into the image: its box in the view's index space, widened by [`WIDEN`] voxels,
//! goes to pixel columns, rows and eye depths through the inverse of the view's (affine, or
//! in perspective projective) map from `(x, y, d)` to index space ([`View::point`]); the rows
//! of the projection's bounding box take its columns and planes, widened by one row, column
//! and plane each side. A sample the march takes in an active brick lies within rounding
//! (far below [`WIDEN`]) of that brick's box, so its row, column and plane are inside the
//! brick's widened projection: skipping what lies outside every one is exact, and the picture
//! keeps its bits (the march's counters of samples skipped as opaque do not count the skipped
//! planes). `docs/decisions/0041-row-reach.md` records the measurements.

use super::view::View;
use crate::bricks::{BRICK, BrickGrid};
use rayon::prelude::*;
use volsplat_core::glam::{DMat3, DVec3};

/// Index-space margin (voxels) added around each brick's box before it is projected: many
/// times the f32 rounding of a sample's position (≈ 10⁻⁴ voxel for grids of a few thousand
/// voxels), far below a brick.
const WIDEN: f64 = 0.25;

/// Active bricks per rayon job of [`row_reach`] (each job merges into a table of its own).
const BRICKS_PER_JOB: usize = 4096;

/// Planes per chunk of [`RowReach::cols`]: a row's pixels are kept per chunk of planes, so that
/// the pixels a row meets at the front of an object are not those of its widest section.
pub(super) const PLANE_CHUNK: usize = 8;

/// The part of one image row that can meet an active brick: the planes `[first, end)` and the
/// pixels `[lo, hi]` (inclusive), the union over the bricks whose projection covers the row.
/// Empty where `first >= end` or `lo > hi`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Reach {
    pub(super) first: u32,
    pub(super) end: u32,
    pub(super) lo: i64,
    pub(super) hi: i64,
}

impl Reach {
    /// A row that meets no active brick.
    const NONE: Reach = Reach {
        first: u32::MAX,
        end: 0,
        lo: i64::MAX,
        hi: i64::MIN,
    };

    /// Every plane and pixel of a row.
    fn all(n_planes: usize, width: usize) -> Reach {
        Reach {
            first: 0,
            end: n_planes as u32,
            lo: 0,
            hi: width as i64 - 1,
        }
    }

    /// The union of the two (the hull of their plane and pixel ranges).
    fn merge(&mut self, o: &Reach) {
        self.first = self.first.min(o.first);
        self.end = self.end.max(o.end);
        self.lo = self.lo.min(o.lo);
        self.hi = self.hi.max(o.hi);
    }

    /// Whether plane `p` is past the row's last plane: the row has nothing left.
    #[inline]
    pub(super) fn done_at(&self, p: usize) -> bool {
        p >= self.end as usize
    }

    /// Whether plane `p` lies in the row's planes.
    #[inline]
    pub(super) fn has_plane(&self, p: usize) -> bool {
        p >= self.first as usize && p < self.end as usize
    }
}

/// The reach of every row of an image ([`row_reach`]): per row its planes and pixels
/// ([`Reach`]), and per row and chunk of [`PLANE_CHUNK`] planes the pixels that the bricks
/// meeting those planes cover.
pub(super) struct RowReach {
    pub(super) rows: Vec<Reach>,
    /// Row `y`, chunk `c`: pixels `[lo, hi]` at `cols[y·chunks + c]` (`lo > hi`: none).
    cols: Vec<(i32, i32)>,
    chunks: usize,
}

impl RowReach {
    /// Every plane and pixel of every row.
    pub(super) fn all(n_planes: usize, width: usize, height: usize) -> RowReach {
        RowReach {
            rows: vec![Reach::all(n_planes, width); height],
            cols: vec![(0, width as i32 - 1); height],
            chunks: 1,
        }
    }

    /// Nothing reached yet, for `height` rows and `n_planes` planes.
    fn none(n_planes: usize, height: usize) -> RowReach {
        let chunks = n_planes.div_ceil(PLANE_CHUNK).max(1);
        RowReach {
            rows: vec![Reach::NONE; height],
            cols: vec![(i32::MAX, i32::MIN); height * chunks],
            chunks,
        }
    }

    /// The pixels `[lo, hi]` of row `y` that can meet an active brick on plane `p` (within the
    /// row's [`Reach`]; `lo > hi` where none).
    #[inline]
    pub(super) fn cols(&self, y: usize, p: usize) -> (i64, i64) {
        let c = if self.chunks == 1 { 0 } else { p / PLANE_CHUNK };
        let (lo, hi) = self.cols[y * self.chunks + c.min(self.chunks - 1)];
        (i64::from(lo), i64::from(hi))
    }

    /// Merges `o`, of the same shape, into `self`.
    fn merge(&mut self, o: &RowReach) {
        self.rows
            .iter_mut()
            .zip(&o.rows)
            .for_each(|(a, b)| a.merge(b));
        self.cols.iter_mut().zip(&o.cols).for_each(|(a, b)| {
            a.0 = a.0.min(b.0);
            a.1 = a.1.max(b.1);
        });
    }
}

/// The planes and pixels of each row of a `width × height` image that can meet the bricks of
/// `bricks` flagged in `active` (every brick where `active` is `None`: the whole box then, one
/// projection), for planes at the eye depths `(j0 + p)·delta`, `p < n_planes`, seen through
/// `view` across the box `[0, box_hi]` (index space). Where the view's map cannot be inverted
/// (a degenerate camera), every row reaches everything.
#[allow(clippy::too_many_arguments)]
pub(super) fn row_reach(
    view: &View,
    box_hi: [i64; 3],
    bricks: &BrickGrid,
    active: Option<&[bool]>,
    (j0, delta, n_planes): (i64, f64, usize),
    width: usize,
    height: usize,
) -> RowReach {
    let m = DMat3::from_cols(view.right_q, view.up_q, view.fwd_q);
    let det = m.determinant();
    if n_planes == 0 || !det.is_finite() || det.abs() < 1e-300 || delta.is_nan() || delta <= 0.0 {
        return RowReach::all(n_planes, width, height);
    }
    let proj = Projector {
        view,
        inv: m.inverse(),
        j0,
        delta,
        n_planes,
        width,
        height,
    };
    let hi = box_hi.map(|h| h as f64);
    let Some(active) = active else {
        let mut reach = RowReach::none(n_planes, height);
        proj.add_box(DVec3::ZERO, DVec3::from(hi), &mut reach);
        return reach;
    };
    let [nx, ny, _] = bricks.dims;
    let brick_box = |i: usize| {
        let b = [i % nx, i / nx % ny, i / (nx * ny)];
        let lo = b.map(|c| (c * BRICK) as f64);
        let top = [0, 1, 2].map(|a| (lo[a] + BRICK as f64).min(hi[a]));
        (DVec3::from(lo), DVec3::from(top))
    };
    let ids: Vec<usize> = (0..active.len()).filter(|&i| active[i]).collect();
    ids.par_chunks(BRICKS_PER_JOB)
        .map(|chunk| {
            let mut reach = RowReach::none(n_planes, height);
            for &i in chunk {
                let (lo, top) = brick_box(i);
                proj.add_box(lo, top, &mut reach);
            }
            reach
        })
        .reduce(
            || RowReach::none(n_planes, height),
            |mut a, b| {
                a.merge(&b);
                a
            },
        )
}

/// The inverse of the view's map from pixel coordinates and depth to index space.
struct Projector<'a> {
    view: &'a View,
    /// The inverse of `[right_q | up_q | fwd_q]`: index-space offsets from the eye to
    /// `(u, v, d)` (orthographic) or `(u·d, v·d, d)` (perspective).
    inv: DMat3,
    j0: i64,
    delta: f64,
    n_planes: usize,
    width: usize,
    height: usize,
}

impl Projector<'_> {
    /// Merges the rows, pixels and planes that the box `[lo, hi]` (index space, widened by
    /// [`WIDEN`]) can meet into `reach`.
    fn add_box(&self, lo: DVec3, hi: DVec3, reach: &mut RowReach) {
        let (lo, hi) = (lo - DVec3::splat(WIDEN), hi + DVec3::splat(WIDEN));
        let v = self.view;
        let mut t = [DVec3::ZERO; 8];
        for (c, t) in t.iter_mut().enumerate() {
            let p = DVec3::new(
                if c & 1 == 1 { hi.x } else { lo.x },
                if c & 2 == 2 { hi.y } else { lo.y },
                if c & 4 == 4 { hi.z } else { lo.z },
            );
            *t = self.inv * (p - v.eye_q);
        }
        let dmin = t.iter().fold(f64::INFINITY, |m, t| m.min(t.z));
        let dmax = t.iter().fold(f64::NEG_INFINITY, |m, t| m.max(t.z));
        let first =
            ((dmin / self.delta).floor() as i64 - self.j0 - 1).clamp(0, self.n_planes as i64);
        let end = ((dmax / self.delta).ceil() as i64 - self.j0 + 2).clamp(0, self.n_planes as i64);
        if first >= end {
            return;
        }
        // Pixel coordinates of the corners (pixel (i, j)'s centre is (i, j): `View::offsets`).
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        // In perspective a box reaching the eye's plane projects without bound.
        let unbounded = v.perspective && dmin <= 0.0;
        if !unbounded {
            for t in &t {
                let (u, w) = if v.perspective {
                    (t.x / t.z, t.y / t.z)
                } else {
                    (t.x, t.y)
                };
                let x = u / v.scale + v.half_w - 0.5;
                let y = v.half_h - 0.5 - w / v.scale;
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
        let clamp_px = |a: f64, n: usize| a.clamp(-1.0, n as f64) as i64;
        let (cols, span) = if unbounded || !(x0.is_finite() && x1.is_finite()) {
            ((0, self.width as i64 - 1), (0, self.height as i64 - 1))
        } else if !(y0.is_finite() && y1.is_finite()) {
            return;
        } else {
            (
                (
                    clamp_px(x0.floor() - 1.0, self.width).max(0),
                    clamp_px(x1.ceil() + 1.0, self.width).min(self.width as i64 - 1),
                ),
                (
                    clamp_px(y0.floor() - 1.0, self.height).max(0),
                    clamp_px(y1.ceil() + 1.0, self.height).min(self.height as i64 - 1),
                ),
            )
        };
        if cols.0 > cols.1 || span.0 > span.1 {
            return;
        }
        let this = Reach {
            first: first as u32,
            end: end as u32,
            lo: cols.0,
            hi: cols.1,
        };
        let (c0, c1) = (
            first as usize / PLANE_CHUNK,
            (end as usize - 1) / PLANE_CHUNK,
        );
        let n = reach.chunks;
        for y in span.0 as usize..=span.1 as usize {
            reach.rows[y].merge(&this);
            for c in &mut reach.cols[y * n + c0..=y * n + c1] {
                c.0 = c.0.min(cols.0 as i32);
                c.1 = c.1.max(cols.1 as i32);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::view::Planes;
    use super::*;
    use crate::sheets::{RenderMode, RenderSettings, Visibility};
    use volsplat_core::glam::DMat3;
    use volsplat_core::{Grid, Projection, Volume};
    use volsplat_testkit::fixtures::orbit_camera;

    /// The planes of a composite `w × h` frame of `grid` seen by `camera` (one-voxel slabs).
    fn planes_for(grid: &Grid, camera: &volsplat_core::Camera, w: usize, h: usize) -> Planes {
        let settings = RenderSettings {
            width: w,
            height: h,
            mode: RenderMode::Composite,
            visibility: Visibility::ImageAligned,
            ..Default::default()
        };
        let proj = Projection::new(camera, w, h).unwrap();
        let min_spacing = grid.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s));
        Planes::place(&settings, &proj, grid, min_spacing).unwrap()
    }

    /// Every sample the march would take in an active brick (the walk's span of every row of
    /// every plane, each pixel's f32 cell as the march locates it) lies in its row's reach:
    /// the planes and pixels skipped hold none. Orbits of orthographic and perspective views
    /// (zoomed in and out, the eye inside the volume), odd image shapes, anisotropic and
    /// rotated grids, grids of one or two samples along an axis, sparse and single active
    /// bricks. Also checks that the reach skips something, so that the test would notice a
    /// reach of everything.
    #[test]
    fn every_sample_in_an_active_brick_lies_in_its_rows_reach() {
        let rot = DMat3::from_rotation_y(0.4) * DMat3::from_rotation_x(-0.3);
        let grids = [
            Grid::new(
                [37, 29, 23],
                [0.7, 1.0, 1.9],
                [3.0, -2.0, 1.0],
                DMat3::IDENTITY,
            ),
            Grid::new([26, 41, 19], [1.0, 0.8, 1.3], [0.0; 3], rot),
            Grid::new([40, 1, 30], [1.0, 2.0, 0.9], [0.0; 3], DMat3::IDENTITY),
            Grid::new([2, 33, 17], [1.5, 1.0, 1.0], [0.0; 3], DMat3::IDENTITY),
        ]
        .map(|g| g.unwrap());
        let (mut checked, mut skipped, mut row_planes, mut narrowed) = (0u64, 0u64, 0u64, 0u64);
        for grid in &grids {
            let volume = Volume::from_fn(grid.clone(), |_, _, _| 0u8).unwrap();
            let bricks = BrickGrid::build(&volume);
            let n = bricks.ranges.len();
            let patterns: Vec<Vec<bool>> = vec![
                (0..n).map(|i| (i * 7 + i / 3) % 5 == 0).collect(),
                (0..n).map(|i| i == n / 2).collect(),
                (0..n).map(|i| i % 2 == 1).collect(),
            ];
            for (view_no, (az, el, parallel, zoom, (w, h))) in [
                (0.0, 0.0, true, 1.0, (64, 48)),
                (33.0, 21.0, true, 1.0, (31, 77)),
                (91.0, -47.0, true, 2.5, (50, 50)),
                (200.0, 80.0, true, 0.4, (40, 23)),
                (17.0, 12.0, false, 1.0, (64, 48)),
                (140.0, -65.0, false, 1.8, (37, 52)),
                (271.0, 3.0, false, 6.0, (48, 48)),
            ]
            .into_iter()
            .enumerate()
            {
                let mut camera = orbit_camera(grid, az, el, parallel);
                camera.zoom(zoom);
                if view_no == 6 {
                    // The eye inside the volume.
                    camera.dolly(4.0);
                }
                let planes = planes_for(grid, &camera, w, h);
                let box_hi = planes.geo.dims.map(|n| n as i64 - 1);
                let max_cell = grid.dims.map(|n| n.max(2) as i64 - 2);
                for active in &patterns {
                    let reach = row_reach(
                        &planes.view,
                        box_hi,
                        &bricks,
                        Some(active),
                        (planes.j0, planes.delta, planes.n_planes),
                        w,
                        h,
                    );
                    for (y, r) in reach.rows.iter().enumerate() {
                        for p in 0..planes.n_planes {
                            let cols = reach.cols(y, p);
                            row_planes += 1;
                            let d = (planes.j0 + p as i64) as f64 * planes.delta;
                            let walk = planes.view.walk(y, d, w, box_hi);
                            let mut any = false;
                            for x in walk.span.0.max(0)..=walk.span.1 {
                                let (c, _) = walk.cell_f32(x as usize, max_cell);
                                if !active[bricks.index(c[0], c[1], c[2])] {
                                    continue;
                                }
                                any = true;
                                checked += 1;
                                assert!(
                                    r.has_plane(p)
                                        && r.lo <= x
                                        && x <= r.hi
                                        && cols.0 <= x
                                        && x <= cols.1,
                                    "grid {:?}, view {view_no}, row {y}, plane {p}, pixel \
                                     {x}: a sample in active brick of cell {c:?} outside \
                                     the row's reach {r:?}, {cols:?}",
                                    grid.dims
                                );
                            }
                            if !any && !r.has_plane(p) {
                                skipped += 1;
                            }
                            if r.has_plane(p) {
                                let span = (cols.0.max(r.lo), cols.1.min(r.hi));
                                narrowed += u64::from(span.0 > r.lo || span.1 < r.hi);
                            }
                        }
                    }
                }
            }
        }
        eprintln!(
            "reach test: {checked} samples checked, {skipped} of {row_planes} row-planes \
             skipped, {narrowed} narrowed by their chunk"
        );
        assert!(checked > 10_000, "{checked} samples in active bricks");
        assert!(
            skipped > row_planes / 10,
            "{skipped} of {row_planes} row-planes skipped"
        );
        assert!(narrowed > row_planes / 20, "{narrowed} row-planes narrowed");
    }

    /// Without active flags the reach is the box's: every row the box covers, and only those
    /// for a box seen small in the middle of the image.
    #[test]
    fn the_whole_box_reaches_the_rows_it_covers() {
        let grid = Grid::new([20, 20, 20], [1.0; 3], [0.0; 3], DMat3::IDENTITY).unwrap();
        let volume = Volume::from_fn(grid.clone(), |_, _, _| 0u8).unwrap();
        let bricks = BrickGrid::build(&volume);
        let mut camera = orbit_camera(&grid, 30.0, 20.0, true);
        camera.zoom(0.3);
        let (w, h) = (80, 60);
        let planes = planes_for(&grid, &camera, w, h);
        let box_hi = planes.geo.dims.map(|n| n as i64 - 1);
        let reach = row_reach(
            &planes.view,
            box_hi,
            &bricks,
            None,
            (planes.j0, planes.delta, planes.n_planes),
            w,
            h,
        );
        let covered: Vec<usize> = (0..h)
            .filter(|&y| {
                (0..planes.n_planes).any(|p| {
                    let d = (planes.j0 + p as i64) as f64 * planes.delta;
                    let s = planes.view.walk(y, d, w, box_hi).span;
                    s.0 <= s.1
                })
            })
            .collect();
        assert!(!covered.is_empty() && covered.len() < h / 2, "{covered:?}");
        for (y, r) in reach.rows.iter().enumerate() {
            let inside = covered.contains(&y);
            let reached = r.first < r.end && r.lo <= r.hi;
            assert!(!inside || reached, "row {y} is covered but not reached");
            // The widening adds at most three rows each side (a row, a quarter voxel, and the
            // corner rows the planes pass between).
            let near = covered.iter().any(|&c| (c as i64 - y as i64).abs() <= 3);
            assert!(
                near || !reached,
                "row {y} is reached far from the box: {covered:?} {r:?}"
            );
        }
    }
}
