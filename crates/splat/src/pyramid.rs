//! A resolution pyramid of prefiltered volumes for previews and minified views (docs/design.md §5,
//! "Multiresolution"; `docs/decisions/0031-prefiltered-pyramid-previews.md`).
//!
//! Level 0 is the volume itself; level `l + 1` halves the axes of level `l` that
//! [`Grid::pyramid_axes`] picks (those within twice the smallest spacing, so a CT's thick slices
//! wait until the in-plane spacing has caught up), after the binomial low-pass filter
//! [`volsplat_core::volume::PYRAMID_TAPS`] (`[1, 3, 3, 1] / 8`) along each of them
//! ([`Volume::halved`]). Each level is a volume with its own grid: spacing × 2 and the origin
//! half a fine spacing back along the halved axes (the filter's centre, in VTK's world
//! convention), its box covering the fine level's. A later out-of-core source reads the same
//! levels from disk (OME-Zarr multiscales); here they are built in memory, lazily, each once,
//! with their own [`BrickGrid`] (and, for shading at the voxels, its direction codes).
//!
//! Rendering a coarse level ([`render_level`]) is Westover's successive refinement applied to
//! the data: the transfer function classifies the level's prefiltered values (post-
//! classification, as mip-mapped volume renderers do), the slabs are as thick in units of the
//! level's spacing as at the full level (so their count halves with each level), the opacity is
//! corrected for that thickness as always (`scalar_opacity_unit_distance`, so the picture has
//! the full level's brightness), and each pixel takes one ray: the prefilter has done the
//! averaging that the full level's supersampling does ([`crate::slab`]'s anti-aliasing of
//! minified views). [`auto_level`] picks the level whose voxel is about a pixel.

use crate::bricks::BrickGrid;
use crate::clip::ClipPlane;
use crate::error::Result;
use crate::sheets::{Progress, RenderSettings, Rendered};
use rayon::prelude::*;
use std::sync::{Arc, Mutex};
use volsplat_core::glam::DVec3;
use volsplat_core::{AnyVolume, Camera, CrioTables, Grid, Projection, Scalar, Volume};

/// The most levels a pyramid holds, level 0 included (a 2¹⁵-sample axis ends near 2 samples).
pub const MAX_LEVELS: usize = 16;

/// [`auto_level`] takes the coarsest level whose smallest spacing is at most this many pixels
/// at the focal plane: √2, the nearest level in a log scale (OpenGL's `*_MIPMAP_NEAREST` level
/// choice, "the level whose voxel is about a pixel").
pub const AUTO_LEVEL_SLACK: f64 = std::f64::consts::SQRT_2;

/// The grids of the levels of a pyramid over `grid`: `grid` itself, then each level halved
/// ([`Grid::halved`]) along its [`Grid::pyramid_axes`] until no axis qualifies or
/// [`MAX_LEVELS`] are reached. Geometry only: no sample is read.
pub fn level_grids(grid: &Grid) -> Vec<Grid> {
    grid.pyramid_grids(MAX_LEVELS, |_| false)
}

/// The size of a pixel (world units) at the camera's focal point for a `width × height` image:
/// `2·parallel_scale / height` in orthographic views; in perspective, at the eye depth of the
/// focal point, `2·d·tan(view_angle / 2) / height`.
pub fn focal_pixel_size(camera: &Camera, width: usize, height: usize) -> Result<f64> {
    let proj = Projection::new(camera, width, height)?;
    let frame = proj.frame();
    let depth = (DVec3::from(camera.focal_point) - frame.eye).dot(frame.forward);
    Ok(proj.pixel_size_at(depth))
}

/// The pyramid level whose voxel is about a pixel: the coarsest level `l` of `grids`
/// ([`level_grids`]) whose smallest spacing is at most [`AUTO_LEVEL_SLACK`] × `pixel` (world
/// units, [`focal_pixel_size`]); 0 where even level 1's is larger, or where `pixel` is not a
/// positive finite number. A pure function of the camera (through `pixel`) and the grid.
pub fn auto_level(pixel: f64, grids: &[Grid]) -> usize {
    if !(pixel.is_finite() && pixel > 0.0) {
        return 0;
    }
    let min_spacing = |g: &Grid| g.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s));
    grids
        .iter()
        .rposition(|g| min_spacing(g) <= AUTO_LEVEL_SLACK * pixel)
        .unwrap_or(0)
}

/// One level of a [`Pyramid`]: the prefiltered volume on its own grid and its brick grid.
#[derive(Debug)]
pub struct PyramidLevel {
    /// The level's samples (the full volume's type) on the level's grid.
    pub volume: Arc<AnyVolume>,
    /// Its min/max bricks (and the direction codes for shading at the voxels, built on first
    /// use).
    pub bricks: Arc<BrickGrid>,
}

/// The pyramid of one volume: its level grids at once, the levels' samples on first use
/// ([`Pyramid::level`]), each built once from the level before.
#[derive(Debug)]
pub struct Pyramid {
    full: Arc<AnyVolume>,
    grids: Vec<Grid>,
    /// Levels built so far (index 0 unused: level 0 is `full`, whose bricks the caller keeps).
    built: Mutex<Vec<Option<Arc<PyramidLevel>>>>,
}

impl Pyramid {
    /// The pyramid of `full`; builds nothing yet.
    pub fn new(full: Arc<AnyVolume>) -> Self {
        let grids = level_grids(full.grid());
        let built = Mutex::new(vec![None; grids.len()]);
        Pyramid { full, grids, built }
    }

    /// The volume the pyramid was made from (level 0).
    pub fn full(&self) -> &Arc<AnyVolume> {
        &self.full
    }

    /// The grids of every level, 0 first ([`level_grids`]).
    pub fn grids(&self) -> &[Grid] {
        &self.grids
    }

    /// How many levels there are, level 0 included.
    pub fn len(&self) -> usize {
        self.grids.len()
    }

    /// Never: a pyramid holds its full level at least.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Whether level `l` (clamped as in [`Pyramid::level`]) is ready: level 0 always, the others
    /// once built.
    pub fn is_built(&self, l: usize) -> bool {
        let l = l.min(self.grids.len() - 1);
        l == 0 || self.built.lock().unwrap_or_else(|e| e.into_inner())[l].is_some()
    }

    /// Level `l` (1 ≤ `l` < [`Pyramid::len`]; larger values give the coarsest level), built on
    /// the first call from level `l − 1` (itself built if needed), in parallel over the
    /// level's slices, and kept. Level 0 is [`Pyramid::full`] and is not built here: `None`.
    pub fn level(&self, l: usize) -> Result<Option<Arc<PyramidLevel>>> {
        let l = l.min(self.grids.len() - 1);
        if l == 0 {
            return Ok(None);
        }
        // Levels are built in order, holding the lock (a second caller waits for the first
        // one's level instead of building it again).
        let mut built = self.built.lock().unwrap_or_else(|e| e.into_inner());
        for m in 1..=l {
            if built[m].is_some() {
                continue;
            }
            let axes = self.grids[m - 1].pyramid_axes();
            let volume: AnyVolume = match &built[m - 1] {
                Some(prev) => halve_any(&prev.volume, axes)?,
                None => halve_any(&self.full, axes)?,
            };
            let bricks = volsplat_core::with_volume!(&volume, v => BrickGrid::build(v));
            built[m] = Some(Arc::new(PyramidLevel {
                volume: Arc::new(volume),
                bricks: Arc::new(bricks),
            }));
        }
        Ok(built[l].clone())
    }
}

/// [`Volume::halved`] on any sample type, one slice per task.
fn halve_any(v: &AnyVolume, axes: [bool; 3]) -> Result<AnyVolume> {
    Ok(volsplat_core::with_volume!(v, v => halve_parallel(v, axes)?.into()))
}

/// [`Volume::halved`] with the slices filtered in parallel (each slice's arithmetic is its own,
/// so the samples do not depend on the thread count).
fn halve_parallel<T: Scalar>(v: &Volume<T>, axes: [bool; 3]) -> Result<Volume<T>> {
    let grid = v.grid().halved(axes)?;
    let slice = grid.dims[0] * grid.dims[1];
    let mut data = crate::error::try_filled(
        grid.voxel_count(),
        v.data()[0],
        "a level of the resolution pyramid",
    )?;
    data.par_chunks_mut(slice)
        .enumerate()
        .for_each(|(k, out)| v.halved_slice(axes, k, out));
    Ok(Volume::new(grid, data)?)
}

/// The planes that keep the box the renderers draw of `grid` ([`Grid::drawn_box_index`]) along
/// `axes`: a coarse level's box reaches ½–1½ fine spacings past the full level's, repeating the
/// edge samples there, and these planes cut it back, so a preview covers what the full frame
/// covers.
pub fn box_planes(grid: &Grid, axes: [bool; 3]) -> Vec<ClipPlane> {
    let (lo, hi) = grid.drawn_box_index();
    let mut planes = Vec::new();
    for a in (0..3).filter(|&a| axes[a]) {
        let n = grid.direction.col(a);
        let mut at = |t: f64, sign: f64| {
            let mut p = lo;
            p[a] = t;
            let x = grid.world_from_index(p);
            planes.push(ClipPlane {
                normal: (n * sign).to_array(),
                offset: -(n * sign).dot(x),
            });
        };
        at(lo[a], 1.0);
        at(hi[a], -1.0);
    }
    planes
}

/// Renders level `level` of `pyramid` with image-aligned slabs ([`crate::render_slabs`]).
/// Level 0 is the full volume with `settings` as given (`bricks`: the full volume's brick grid
/// if the caller keeps one). A coarse level takes one ray per pixel (`antialias` none: the
/// prefilter did the averaging), its own brick grid, and the clipping planes of `settings` plus
/// those that cut its box back to the full level's ([`box_planes`]); `settings.slab` is in
/// units of the level's smallest spacing, so the slabs are as many voxels thick as at level 0,
/// and the opacity is corrected for their thickness in world units as always. `level` past
/// the coarsest draws the coarsest.
pub fn render_level(
    pyramid: &Pyramid,
    level: usize,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    bricks: Option<&BrickGrid>,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    let Some(lv) = pyramid.level(level)? else {
        return crate::render_slabs_any(pyramid.full(), camera, tables, settings, bricks, progress);
    };
    let full = pyramid.full().grid();
    let mut s = settings.clone();
    s.antialias = crate::aa::Antialias::None;
    let halved: [bool; 3] = std::array::from_fn(|a| lv.volume.grid().dims[a] != full.dims[a]);
    s.clip.extend(box_planes(full, halved));
    crate::render_slabs_any(&lv.volume, camera, tables, &s, Some(&lv.bricks), progress)
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::glam::DMat3;

    fn ct_grid() -> Grid {
        Grid::new(
            [256, 256, 108],
            [0.706, 0.863, 1.869],
            [-90.0, -110.0, -100.0],
            DMat3::IDENTITY,
        )
        .unwrap()
    }

    #[test]
    fn level_grids_halve_until_no_axis_is_long_enough() {
        let g = level_grids(&ct_grid());
        let dims: Vec<[usize; 3]> = g.iter().map(|g| g.dims).collect();
        assert_eq!(
            dims,
            vec![
                [256, 256, 108],
                [129, 129, 108],
                [66, 66, 55],
                [34, 34, 29],
                [18, 18, 16],
                [10, 10, 9],
                [6, 6, 6],
            ]
        );
        // Each level's box covers the one before.
        for w in g.windows(2) {
            let (lo0, hi0) = w[0].bounds_world();
            let (lo1, hi1) = w[1].bounds_world();
            assert!(
                lo1.cmple(lo0).all() && hi1.cmpge(hi0).all(),
                "{:?}",
                w[1].dims
            );
        }
    }

    /// The CT-like head at 512² (pixel 0.68 mm), 256² and 128²: level 0, 1 and 2, each level's
    /// voxel about a pixel; and the rule in pixels, for any camera.
    #[test]
    fn auto_level_takes_the_level_whose_voxel_is_about_a_pixel() {
        let grids = level_grids(&ct_grid());
        let mut cam =
            Camera::reset_to_bounds(grids[0].bounds_world().0, grids[0].bounds_world().1, true);
        cam.parallel_scale = 173.78;
        let at = |cam: &Camera, n: usize| auto_level(focal_pixel_size(cam, n, n).unwrap(), &grids);
        assert_eq!([at(&cam, 512), at(&cam, 256), at(&cam, 128)], [0, 1, 2]);
        // A wider image of the same height: the same pixel, the same level.
        assert_eq!(
            auto_level(focal_pixel_size(&cam, 1024, 256).unwrap(), &grids),
            1
        );
        // The boundary: level 1's smallest spacing (1.412 mm) within √2 pixels.
        let s1 = 2.0 * 0.706;
        assert_eq!(auto_level(s1 / AUTO_LEVEL_SLACK * 1.001, &grids), 1);
        assert_eq!(auto_level(s1 / AUTO_LEVEL_SLACK * 0.999, &grids), 0);
        // Far out: the coarsest level; bad pixels: the full level.
        assert_eq!(auto_level(1e6, &grids), grids.len() - 1);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(auto_level(bad, &grids), 0);
        }
        // Perspective: the pixel at the focal point, so dollying in picks finer levels.
        let mut p = cam.clone();
        p.parallel_projection = false;
        let far = at(&p, 128);
        p.dolly(4.0);
        assert!(
            at(&p, 128) < far,
            "dolly in: level {} from {far}",
            at(&p, 128)
        );
    }

    #[test]
    fn box_planes_keep_the_full_box() {
        let rot = DMat3::from_rotation_z(0.4) * DMat3::from_rotation_x(0.3);
        let g = Grid::new([20, 16, 9], [0.5, 0.7, 1.1], [3.0, -2.0, 1.0], rot).unwrap();
        let planes = box_planes(&g, [true, false, true]);
        assert_eq!(planes.len(), 4);
        let keeps = |i: f64, j: f64, k: f64| {
            let x = g.world_from_index(DVec3::new(i, j, k));
            planes
                .iter()
                .all(|p| DVec3::from(p.normal).dot(x) + p.offset >= -1e-9)
        };
        assert!(keeps(0.0, 0.0, 0.0) && keeps(19.0, 15.0, 8.0) && keeps(7.0, 40.0, 3.0));
        assert!(!keeps(-0.1, 3.0, 3.0) && !keeps(19.1, 3.0, 3.0) && !keeps(3.0, 3.0, 8.2));
    }
}
