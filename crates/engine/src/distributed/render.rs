//! Sort-last rendering of a whole request ([`render_sort_last`]): the volume cut into bricks of
//! `brick` cells, each rank drawing its bricks' partial images through the engine
//! ([`Renderer::render_brick`]) and the ranks compositing them over the fixed tree.

use super::comm::Communicator;
use super::composite::{
    Combine, Pixels, Ready, composite_direct_send, exchange_ready, fail_direct_send,
};
use super::tree::{BrickTree, Eye};
use super::{DistributedError, Result};
use crate::Mode;
use crate::renderer::Renderer;
use crate::request::RenderRequest;
use volsplat_core::glam::DVec3;
use volsplat_core::{Image, ScalarImage};

/// The image of a sort-last render, on rank 0: what [`Renderer::render`] returns as
/// `Output::image` and `Output::values` for the same request (write both with
/// [`crate::write_image`]).
#[derive(Debug, Clone)]
pub struct SortLastImage {
    /// Composite: premultiplied RGBA. X-ray: the grey picture of the line integrals, scaled so
    /// that the largest is white ([`volsplat_splat::xray_picture`]). MIP/MinIP: the values
    /// classified by the request's tables ([`volsplat_splat::extreme_picture`]).
    pub image: Image,
    /// X-ray: the line integrals (data units × world units); MIP/MinIP: the projected values
    /// (data units, NaN where no sample); rows top to bottom; `None` in composite.
    pub values: Option<ScalarImage>,
}

/// Renders `request` sort-last among the ranks of `comm`: its volume is cut into bricks of
/// `brick` cells per side (a multiple of 8, the same on every rank: the cut does not depend on
/// the number of ranks), rank `r` draws the partial images of its run of the tree's bricks
/// with `renderer`, and the ranks composite them ([`composite_direct_send`]). Returns the image
/// on rank 0 (`None` on the others): the same bits for any number of ranks.
///
/// - **Composite** (`over`, front to back), through the image-aligned slabs: the
///   single-process render up to f32 reassociation where nothing is pre-integrated and no ray
///   reaches the opacity cutoff (decision 0038). One ray per pixel (`quality.antialias` is
///   taken as `none`): a minified view's area averaging does not commute with compositing, so
///   it would have to composite the rays before averaging them, which is not built.
/// - **X-ray** (sum), through the sheets (orthographic) or the splat list (perspective): each
///   brick draws the voxels of its cells (the last brick along an axis also the far face), so
///   the sum is the single-process X-ray up to f32 reassociation, anti-aliasing included (a
///   footprint is linear in its voxel).
/// - **MIP and MinIP** (the larger or smaller value, NaN where no sample), through the
///   image-aligned slabs: each brick draws the samples of its cells, so the extreme over the
///   bricks is the single-process projection **bit for bit** (max and min are exact); rank 0
///   classifies it with the request's tables ([`volsplat_splat::extreme_picture`]).
///
/// **Reading.** From an OME-Zarr store or a NRRD file with a raw payload (every mode) each
/// rank reads only the bricks of its part ([`crate::Renderer::rank_reads`] counts
/// them): the grid and camera come from the store's metadata or the file's header, the ranges
/// scan reads only the bricks meeting the rank's sort-last bricks
/// (`volsplat_splat::scan_level_in`), and the frames read them through a cache that never reads
/// another. The ranks share their parts' value ranges in a set-up round, so presets, the
/// projections' automatic window and the pre-integration test see the level's range: the
/// image is the bits of the same sort-last render from the volume in memory. They share their
/// parts' finite ranges too: a part holding NaN or ±∞ floats replaces them by the union's
/// extremes (decision 0030), as the level read whole does. In X-ray each brick's voxels (those
/// of its cells, and the far face for the last brick along an axis) are copied out of the
/// part's bricks into a volume on the level's grid shifted to the box and drawn by the sheets
/// or the splat list as any volume in memory, with the camera resolved from the level's grid
/// and the X-ray offset from the level's range: each brick's partial image depends only on
/// the brick, so the image is the same bits for any number of ranks, and the single-process
/// X-ray up to f32 reassociation and the f64 rounding of a voxel's position (124–138 dB in
/// `store_tests`). Refused on every rank alike: the automatic composite transfer function (a
/// histogram of the whole level). Gzip or text NRRD payloads and other files: every rank
/// reads the volume whole.
///
/// A rank that cannot set up (its volume unreadable, a bad setting) still takes its part in
/// the set-up round, sending its error, so every rank returns [`DistributedError::Rank`]
/// naming the lowest failing rank and nobody waits.
pub fn render_sort_last(
    comm: &dyn Communicator,
    renderer: &mut Renderer,
    request: &RenderRequest,
    brick: usize,
) -> Result<Option<SortLastImage>> {
    let mut request = request.clone();
    if request.mode != Mode::Xray {
        // One ray per pixel: a minified view's supersampling averages rays, which commutes
        // with neither `over` nor the extremes.
        request.quality.antialias = crate::request::AntialiasChoice::None;
    }
    let request = &request;
    // Set-up: the tree, and the rank's part of a store (only its bricks scanned); then the
    // set-up round, which shares a failure or the parts' value ranges.
    let set = set_up(renderer, request, brick).and_then(|s| {
        let region = rank_region(&s.0, comm.rank(), comm.size());
        let part = renderer
            .open_rank_part(request, &region)
            .map_err(|e| DistributedError::Engine(e.to_string()))?;
        Ok((s, part))
    });
    let mine = match &set {
        Ok((_, part)) => Ok(Ready {
            range: part.and_then(|p| p.range),
            finite: part.and_then(|p| p.finite),
            non_finite: part.is_some_and(|p| p.non_finite),
        }),
        Err(e) => Err(e.to_string()),
    };
    let all = exchange_ready(comm, mine)?;
    let ((tree, eye, combine), part) = set?;
    if part.is_some() {
        share_range(comm, renderer, request, &all)?;
    }
    let (w, h) = (request.width, request.height);
    let pixels = composite_direct_send(comm, &tree, eye, combine, (w, h), &mut |b| {
        let [nx, ny, _] = tree.dims;
        let at = [b % nx, b / nx % ny, b / (nx * ny)];
        let owned = [at.map(|a| a * brick), at.map(|a| (a + 1) * brick)];
        let out = renderer
            .render_brick(request, owned, &mut |_| true)
            .map_err(|e| DistributedError::Brick {
                brick: b,
                why: e.to_string(),
            })?;
        let p: Pixels = match (combine, &out.values) {
            (Combine::Over, _) => out.image.pixels().to_vec(),
            (_, Some(v)) => v.values().iter().map(|&x| [x, 0.0, 0.0, 0.0]).collect(),
            (_, None) => {
                return Err(DistributedError::Brick {
                    brick: b,
                    why: "a projection without its values".into(),
                });
            }
        };
        let drawn = |px: &[f32; 4]| match combine {
            Combine::Over => px[3] > 0.0,
            Combine::Sum => px[0] != 0.0,
            Combine::Max | Combine::Min => !px[0].is_nan(),
        };
        Ok(p.iter().any(drawn).then_some(p))
    })?;
    let Some(pixels) = pixels else {
        return Ok(None);
    };
    let bad = || DistributedError::Protocol("an image of the wrong size");
    let values = || pixels.iter().map(|p| p[0]).collect();
    let (image, values) = match combine {
        Combine::Over => (Image::from_pixels(w, h, pixels).ok_or_else(bad)?, None),
        Combine::Sum => {
            let (image, values) = volsplat_splat::xray_picture(w, h, values());
            (image, Some(values.ok_or_else(bad)?))
        }
        Combine::Max | Combine::Min => {
            let engine = |e: crate::EngineError| DistributedError::Engine(e.to_string());
            let tables = match renderer.rank_frame_tables(request).map_err(engine)? {
                Some(t) => t,
                None => renderer.frame_tables(request).map_err(engine)?,
            };
            let (image, values) = volsplat_splat::extreme_picture(w, h, values(), &tables);
            (image, Some(values.ok_or_else(bad)?))
        }
    };
    Ok(Some(SortLastImage { image, values }))
}

/// The tree over the request's bricks, where the eye is in the volume's index space, and how
/// the partial images combine.
fn set_up(
    renderer: &mut Renderer,
    request: &RenderRequest,
    brick: usize,
) -> Result<(BrickTree, Eye, Combine)> {
    if brick == 0 || !brick.is_multiple_of(8) {
        return Err(DistributedError::Setting(format!(
            "brick size {brick}: a positive multiple of 8 cells"
        )));
    }
    let combine = match request.mode {
        Mode::Composite => Combine::Over,
        Mode::Xray => Combine::Sum,
        Mode::Mip => Combine::Max,
        Mode::Minip => Combine::Min,
    };
    let engine = |e: crate::EngineError| DistributedError::Engine(e.to_string());
    // A store read in bricks: the grid and the camera from its metadata, no voxel read.
    let (grid, camera) = match renderer.part_grid(request).map_err(engine)? {
        Some(grid) => {
            let camera = request
                .scene
                .camera
                .resolve(grid.drawn_bounds_world())
                .map_err(|e| DistributedError::Engine(e.to_string()))?;
            (grid, camera)
        }
        None => {
            let grid = renderer
                .volume(&request.scene.volume)
                .map_err(engine)?
                .grid()
                .clone();
            (grid, renderer.camera(request).map_err(engine)?)
        }
    };
    let cells = grid.dims.map(|d| d.saturating_sub(1).max(1));
    let tree = BrickTree::new(cells.map(|c| c.div_ceil(brick)), brick)
        .ok_or(DistributedError::Protocol("an empty brick grid"))?;
    let position = grid.index_from_world(DVec3::from(camera.position));
    let eye = if camera.parallel_projection {
        Eye::Direction((grid.index_from_world(DVec3::from(camera.focal_point)) - position).into())
    } else {
        Eye::Point(position.into())
    };
    Ok((tree, eye, combine))
}

/// The boxes of cells (`[lo, hi)`, index space) of rank `rank`'s run of the tree's bricks
/// ([`BrickTree::rank_leaves`]): the only bricks it reads of a store.
pub(super) fn rank_region(tree: &BrickTree, rank: usize, size: usize) -> Vec<[[usize; 3]; 2]> {
    let (a, b) = tree.rank_leaves(rank, size);
    let [nx, ny, _] = tree.dims;
    tree.leaves[a..b]
        .iter()
        .map(|&i| {
            let at = [i % nx, i / nx % ny, i / (nx * ny)];
            [at.map(|x| x * tree.brick), at.map(|x| (x + 1) * tree.brick)]
        })
        .collect()
}

/// After the set-up round, with every rank's part ([`Ready`] in `all`): gives its part the
/// level's value range and finite range, the unions of the parts' (exact: min and max; the
/// parts' owned voxels cover the level). A part holding NaN or ±∞ floats replaces them by the
/// level's finite extremes (decision 0030), as the level read whole does. A rank that fails to
/// take them stops every rank in the image exchange ([`fail_direct_send`]).
fn share_range(
    comm: &dyn Communicator,
    renderer: &mut Renderer,
    request: &RenderRequest,
    all: &[Ready],
) -> Result<()> {
    let union = |ranges: &mut dyn Iterator<Item = [f32; 2]>| {
        let r = ranges.fold([f32::INFINITY, f32::NEG_INFINITY], |a, r| {
            [a[0].min(r[0]), a[1].max(r[1])]
        });
        (r[0] <= r[1]).then_some(r)
    };
    let range = union(&mut all.iter().filter_map(|r| r.range));
    let finite = union(&mut all.iter().filter_map(|r| r.finite));
    let Some(range) = range else {
        return Err(fail_direct_send(comm, "no rank read a sample".into()));
    };
    renderer
        .set_rank_range(request, range, finite)
        .map_err(|e| fail_direct_send(comm, e.to_string()))
}
