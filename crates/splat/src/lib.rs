//! # volsplat-splat
//!
//! Westover's splatting (Westover 1991, *Splatting: a parallel, feed-forward volume rendering
//! algorithm*), Swan et al.'s anti-aliased perspective splat list (1997) and image-aligned
//! post-classified slabs (Mueller, Möller & Crawfis 1999), with the corrections recorded in
//! `docs/papers.md`. Which renderer the front ends choose, and why: `docs/architecture.md`.
//!
//! - [`sheets`], the sheet renderer (dense, orthographic): [`render()`] / [`render_any`]: one
//!   frame → [`Rendered`] (premultiplied image, optional float values, [`RenderStats`] per stage
//!   like Table 4.02), controlled by [`RenderSettings`] ([`RenderMode`] composite / MIP / MinIP /
//!   X-ray, [`Visibility`] sheet buffer or composite-every-sample, [`Order`] FTB/BTF, kernel,
//!   subsampling); [`render_with_progress`]: the same with a callback after each batch of sheets
//!   (successive refinement, §4.2.1), which can cancel.
//! - [`list`], the splat-list renderer (sparse, orthographic or perspective): [`SplatList`],
//!   [`render_list`]; it shares the sheet renderer's driver (batches, bands, threads).
//! - [`slab`], the image-aligned slabs: [`render_slabs`]. [`render_by_visibility`] dispatches
//!   between the sheet renderer and the slabs on [`RenderSettings::visibility`].
//! - [`refine`]: the preview ladder of subsampled renders with cheaper kernels (§4.2.2–4.2.4).
//! - `footprint` (internal): per-frame footprint tables with exact elliptical mapping (§3.7);
//!   [`FootprintSettings`] tunes them.
//! - `geometry` (internal): incremental view transform, sheet choice and traversal order (§3.5);
//!   [`Order`] is the traversal order.
//! - [`pyramid`]: prefiltered levels of a volume for previews ([`Pyramid`], [`render_level`],
//!   [`auto_level`]: the level whose voxel is about a pixel).
//!
//! Output is bit-identical for any rayon thread count.
#![deny(missing_docs)]

pub mod aa;
pub mod bricks;
pub mod cache;
pub mod clip;
mod dispatch;
pub mod error;
mod footprint;
mod geometry;
mod gradient;
pub mod list;
mod mipcull;
pub mod normals;
pub mod pyramid;
pub mod refine;
mod row;
pub mod sheets;
pub mod slab;
#[cfg(test)]
mod test_fixtures;
mod voxels;

pub use aa::Antialias;
pub use bricks::BrickGrid;
pub use cache::{
    BrickCache, CacheStats, Fetched, LevelScan, bricks_meeting, scan_level, scan_level_in,
};
pub use clip::ClipPlane;
pub use dispatch::render_by_visibility;
pub use error::{Result, SplatError};
pub use footprint::FootprintSettings;
pub use geometry::Order;
pub use list::{
    ExtractSettings, ListVoxels, SplatList, SplatRecord, render_list, render_list_with_progress,
};
pub use normals::ShadeAt;
pub use pyramid::{Pyramid, PyramidLevel, auto_level, focal_pixel_size, render_level};
pub use sheets::{
    Preintegrate, Progress, RenderMode, RenderSettings, RenderStats, Rendered, Visibility,
    extreme_picture, render, render_any, render_with_progress, xray_picture, xray_weight,
};
pub use slab::{render_slabs, render_slabs_any, render_slabs_bricked};
