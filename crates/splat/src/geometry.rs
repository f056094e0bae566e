//! Per-frame splatting geometry: the incremental view transform, sheet and traversal choice
//! (Westover 1991, §3.5–3.5.1), and the sheet spacing along the view.

use crate::error::{Result, SplatError};
use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{Grid, OrthoProjection};

/// Traversal direction through the sheets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Order {
    /// Nearest sheet first (Westover §3.8.1 FTB); allows early termination.
    #[default]
    FrontToBack,
    /// Farthest sheet first (Westover §3.8.1 BTF).
    BackToFront,
}

/// The lattice actually splatted for one frame: the volume's grid, possibly subsampled by
/// `stride` (successive refinement, Westover §4.2.3), seen through an orthographic projection.
#[derive(Debug, Clone)]
pub(crate) struct SplatGeometry {
    /// Subsampling stride (1 = every voxel, 2 = every 2nd voxel per axis, ...).
    pub stride: usize,
    /// Number of lattice points per axis after subsampling.
    pub dims: [usize; 3],
    /// `raster_from_lattice` linear part: column `c` is the (raster x px, raster y px, depth
    /// world units) displacement of one lattice step along axis `c`. Westover's ΔM (§3.5.1).
    pub jacobian: DMat3,
    /// Raster position (px, px, depth) of lattice point (0, 0, 0).
    pub origin_raster: DVec3,
    /// The sheet-normal axis (0 = i, 1 = j, 2 = k): the grid axis most nearly parallel to the view.
    pub sheet_axis: usize,
    /// The two in-sheet axes, fastest first (smaller |Δdepth| first).
    pub in_sheet_axes: [usize; 2],
    /// Lattice indices along the sheet axis in visiting order.
    pub sheet_order: Vec<usize>,
    /// For each in-sheet axis, whether it is traversed from its high end (so that samples go in
    /// the requested depth order inside a sheet, used by composite-every-sample).
    pub in_sheet_reversed: [bool; 2],
    /// World path length between consecutive sheets along a view ray (Δs > 0).
    pub sheet_spacing: f64,
    /// Smallest and largest depth (world units) of the lattice's eight corners.
    pub depth_range: (f64, f64),
    /// World units per pixel.
    pub pixel_size: f64,
    /// `|det|` of `world_from_lattice` (world volume per lattice cell).
    pub cell_volume: f64,
}

impl SplatGeometry {
    /// Computes the frame geometry for `grid` subsampled by `stride` under `proj`.
    pub(crate) fn new(
        grid: &Grid,
        proj: &OrthoProjection,
        stride: usize,
        order: Order,
    ) -> Result<Self> {
        if stride == 0 {
            return Err(SplatError::Setting {
                name: "subsample",
                value: "0".into(),
                expected: "a stride ≥ 1",
            });
        }
        let dims = grid.dims.map(|d| d.div_ceil(stride));
        let spacing = grid.spacing.map(|s| s * stride as f64);
        let world_from_lattice = grid.direction * DMat3::from_diagonal(DVec3::from(spacing));
        let raster_from_world = proj.raster_from_world_linear();
        let jacobian = raster_from_world * world_from_lattice;
        let origin_raster = proj.raster_from_world(DVec3::from(grid.origin));
        if !(jacobian.is_finite() && origin_raster.is_finite()) {
            return Err(SplatError::ExtremeView {
                step: jacobian.to_cols_array(),
            });
        }
        let forward = proj.frame.forward;
        // Sheet normal: the axis whose direction is most nearly parallel to the view, i.e. the
        // sheets closest to parallel with the image plane (Westover §3.5.1).
        let (sheet_axis, cos_a) = sheet_axis(&grid.direction, forward)?;
        let mut others: Vec<usize> = (0..3).filter(|&c| c != sheet_axis).collect();
        others.sort_by(|&a, &b| jacobian.col(a).z.abs().total_cmp(&jacobian.col(b).z.abs()));
        let in_sheet_axes = [others[0], others[1]];
        let ftb = order == Order::FrontToBack;
        // Depth grows along an axis when its Δdepth is positive; FTB then starts at index 0.
        let increasing = |axis: usize| (jacobian.col(axis).z >= 0.0) == ftb;
        let n = dims[sheet_axis];
        let sheet_order: Vec<usize> = if increasing(sheet_axis) {
            (0..n).collect()
        } else {
            (0..n).rev().collect()
        };
        let in_sheet_reversed = in_sheet_axes.map(|a| !increasing(a));
        let sheet_spacing = spacing[sheet_axis] / cos_a;
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for n in 0..8 {
            let p = DVec3::new(
                if n & 1 != 0 {
                    (dims[0] - 1) as f64
                } else {
                    0.0
                },
                if n & 2 != 0 {
                    (dims[1] - 1) as f64
                } else {
                    0.0
                },
                if n & 4 != 0 {
                    (dims[2] - 1) as f64
                } else {
                    0.0
                },
            );
            let d = (origin_raster + jacobian * p).z;
            lo = lo.min(d);
            hi = hi.max(d);
        }
        Ok(SplatGeometry {
            stride,
            dims,
            jacobian,
            origin_raster,
            sheet_axis,
            in_sheet_axes,
            sheet_order,
            in_sheet_reversed,
            sheet_spacing,
            depth_range: (lo, hi),
            pixel_size: proj.pixel_size,
            cell_volume: world_from_lattice.determinant().abs(),
        })
    }

    /// Raster position (px, px, depth) of lattice point `p` (direct, not incremental).
    pub(crate) fn raster_of(&self, p: [usize; 3]) -> DVec3 {
        self.origin_raster + self.jacobian * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
    }
}

/// The sheet axis for a view along `forward` (world frame): the grid axis whose direction (a
/// column of `direction`) is most nearly parallel to the view, so that the sheets are the
/// closest to parallel with the image plane (Westover §3.5.1; the lower axis on a tie), with
/// `|cos|` of its angle to the view. [`SplatError::DegenerateView`] when no axis has a
/// component along the view. The sheet renderer and the splat list both choose their sheets here.
pub(crate) fn sheet_axis(direction: &DMat3, forward: DVec3) -> Result<(usize, f64)> {
    let cosines = [0, 1, 2].map(|c| direction.col(c).dot(forward).abs());
    let axis = (0..3)
        .max_by(|&a, &b| cosines[a].total_cmp(&cosines[b]).then(b.cmp(&a)))
        .unwrap_or(2);
    let cos = cosines[axis];
    if cos.is_nan() || cos <= 1e-9 {
        return Err(SplatError::DegenerateView);
    }
    Ok((axis, cos))
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::Camera;
    use volsplat_core::glam::DVec3;

    fn proj(az: f64, el: f64) -> OrthoProjection {
        let mut c = Camera::reset_to_bounds(DVec3::ZERO, DVec3::splat(31.0), true);
        c.azimuth(az);
        c.elevation(el);
        c.orthogonalize_view_up();
        OrthoProjection::new(&c, 64, 64).unwrap()
    }

    /// F-W5: sheet depths are strictly monotone in the requested direction, for many views.
    #[test]
    fn sheet_depths_are_monotone_in_the_requested_order() {
        let grid = Grid::new([8, 9, 10], [1.0, 1.5, 0.7], [0.0; 3], DMat3::IDENTITY).unwrap();
        for az in (0..360).step_by(23) {
            for el in [-80.0, -45.0, -10.0, 0.0, 30.0, 60.0, 85.0] {
                let p = proj(az as f64, el);
                for order in [Order::FrontToBack, Order::BackToFront] {
                    let g = SplatGeometry::new(&grid, &p, 1, order).unwrap();
                    let depth = |s: usize| {
                        let mut idx = [0usize; 3];
                        idx[g.sheet_axis] = s;
                        g.raster_of(idx).z
                    };
                    for w in g.sheet_order.windows(2) {
                        let (d0, d1) = (depth(w[0]), depth(w[1]));
                        match order {
                            Order::FrontToBack => assert!(d1 >= d0, "az {az} el {el}"),
                            Order::BackToFront => assert!(d1 <= d0, "az {az} el {el}"),
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn sheet_spacing_is_the_path_between_sheets() {
        // Looking straight down −z at a grid with z spacing 2: Δs = 2.
        let grid = Grid::new([4, 4, 4], [1.0, 1.0, 2.0], [0.0; 3], DMat3::IDENTITY).unwrap();
        let g = SplatGeometry::new(&grid, &proj(0.0, 0.0), 1, Order::FrontToBack).unwrap();
        assert_eq!(g.sheet_axis, 2);
        assert!((g.sheet_spacing - 2.0).abs() < 1e-12);
        // Rotated 30° about y: the ray crosses the z-sheets obliquely, Δs = 2 / cos 30°.
        let g = SplatGeometry::new(&grid, &proj(30.0, 0.0), 1, Order::FrontToBack).unwrap();
        assert!((g.sheet_spacing - 2.0 / 30f64.to_radians().cos()).abs() < 1e-9);
        // Subsampling by 2 doubles the spacing and halves the lattice.
        let g2 = SplatGeometry::new(&grid, &proj(30.0, 0.0), 2, Order::FrontToBack).unwrap();
        assert!((g2.sheet_spacing - 2.0 * g.sheet_spacing).abs() < 1e-9);
        assert_eq!(g2.dims, [2, 2, 2]);
    }

    /// F-W4: incremental positions match direct transformation.
    #[test]
    fn incremental_positions_match_direct_ones() {
        let grid = Grid::new(
            [64, 64, 64],
            [0.9, 1.1, 1.7],
            [3.0, -2.0, 5.0],
            DMat3::from_rotation_x(0.4),
        )
        .unwrap();
        let g = SplatGeometry::new(&grid, &proj(37.0, 21.0), 1, Order::FrontToBack).unwrap();
        let step = g.jacobian.col(0);
        let mut p = g.raster_of([0, 17, 33]);
        for i in 0..64 {
            let direct = g.raster_of([i, 17, 33]);
            assert!((p - direct).length() < 1e-9);
            p += step;
        }
    }
}
