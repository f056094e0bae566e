//! Sort-last rendering of a whole request ([`render_sort_last`]): the volume cut into bricks of
//! `brick` cells, each rank drawing its bricks' partial images through the engine
//! ([`Renderer::render_brick`]) and the ranks compositing them over the fixed tree.

use super::comm::Communicator;
use super::composite::{Combine, Pixels, composite_direct_send};
use super::tree::{BrickTree, Eye};
use super::{DistributedError, Result};
use crate::renderer::Renderer;
use crate::request::RenderRequest;
use volsplat_core::Image;
use volsplat_core::glam::DVec3;

/// Renders `request` sort-last among the ranks of `comm`: its volume is cut into bricks of
/// `brick` cells per side (a multiple of 8, the same on every rank: the cut does not depend on
/// the number of ranks), rank `r` draws the partial images of its run of the tree's bricks
/// with `renderer`, and the ranks composite them ([`composite_direct_send`]). Returns the image
/// on rank 0 (`None` on the others): the same bits for any number of ranks, and the
/// single-process render up to f32 reassociation where nothing is pre-integrated and no ray
/// reaches the opacity cutoff (decision 0038). Composite through the image-aligned slabs only.
/// Every rank still loads the whole volume (reading only a rank's bricks is the brick seam's
/// cache, not built yet). One ray per pixel (`quality.antialias` is taken as `none`): a
/// minified view's area averaging does not commute with compositing, so it would have to
/// composite the rays before averaging them, which is not built.
pub fn render_sort_last(
    comm: &dyn Communicator,
    renderer: &mut Renderer,
    request: &RenderRequest,
    brick: usize,
) -> Result<Option<Image>> {
    let mut request = request.clone();
    request.quality.antialias = crate::request::AntialiasChoice::None;
    let request = &request;
    if brick == 0 || !brick.is_multiple_of(8) {
        return Err(DistributedError::Setting(format!(
            "brick size {brick}: a positive multiple of 8 cells"
        )));
    }
    let engine = |e: crate::EngineError| DistributedError::Engine(e.to_string());
    let grid = renderer
        .volume(&request.scene.volume)
        .map_err(engine)?
        .grid()
        .clone();
    let camera = renderer.camera(request).map_err(engine)?;
    let cells = grid.dims.map(|d| d.saturating_sub(1).max(1));
    let tree = BrickTree::new(cells.map(|c| c.div_ceil(brick)), brick)
        .ok_or(DistributedError::Protocol("an empty brick grid"))?;
    let position = grid.index_from_world(DVec3::from(camera.position));
    let eye = if camera.parallel_projection {
        Eye::Direction((grid.index_from_world(DVec3::from(camera.focal_point)) - position).into())
    } else {
        Eye::Point(position.into())
    };
    let (w, h) = (request.width, request.height);
    let pixels = composite_direct_send(comm, &tree, eye, Combine::Over, (w, h), &mut |b| {
        let [nx, ny, _] = tree.dims;
        let at = [b % nx, b / nx % ny, b / (nx * ny)];
        let owned = [at.map(|a| a * brick), at.map(|a| (a + 1) * brick)];
        let out = renderer
            .render_brick(request, owned, &mut |_| true)
            .map_err(|e| DistributedError::Brick {
                brick: b,
                why: e.to_string(),
            })?;
        let p: Pixels = out.image.pixels().to_vec();
        Ok(p.iter().any(|px| px[3] > 0.0).then_some(p))
    })?;
    Ok(pixels.and_then(|p| Image::from_pixels(w, h, p)))
}
