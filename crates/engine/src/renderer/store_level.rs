//! Previews of a store read out of core (issue 31 item 5; decision 0039 amendment): a frame
//! that asks for a coarser level of the renderer's pyramid (`quality.level`, the viewer's
//! previews while the user moves) draws the store's own coarser level instead of building one
//! from the full level, which is not in memory. A store written by `volsplat convert` holds the
//! renderer's pyramid (decision 0037: level `l` of the store is level `l` of `splat::Pyramid`,
//! bit for bit), so the preview is the same picture as the in-memory one; other stores give
//! their own writer's levels, with the same geometry rules.

use super::Renderer;
use super::cache::cached;
use super::draw::{forward, sheets_done};
use crate::Progress;
use crate::error::{EngineError, Result};
use crate::scene::{StoreLevel, VolumeSource};
use std::sync::Arc;
use volsplat_core::{Camera, CrioTables, Grid};
use volsplat_io::ZarrStore;
use volsplat_splat::{BrickGrid, RenderSettings, Rendered};

/// A preview frame of a store's coarser level.
pub(super) struct StoreLevelFrame<'a> {
    /// The store and its level drawn at full resolution (`StoreLevel::Index`).
    pub(super) source: &'a VolumeSource,
    /// That level's grid: the camera and the box the preview is cut to.
    pub(super) full: &'a Grid,
    /// The renderer's pyramid level asked for (≥ 1).
    pub(super) level: usize,
    /// The out-of-core budget: the coarser level is read whole only if it fits in it.
    pub(super) budget: u64,
    pub(super) camera: &'a Camera,
    pub(super) tables: &'a CrioTables,
    /// The frame's settings (clipping, slab thickness in the drawn level's spacing).
    pub(super) settings: RenderSettings,
    pub(super) pool: &'a rayon::ThreadPool,
}

impl Renderer {
    /// Draws `f`: the store level `base + f.level` (the coarsest where the store has fewer),
    /// read whole, with one ray per pixel and cut to the full level's box, as
    /// `volsplat_splat::render_level` draws a pyramid level. Returns the picture and a note
    /// naming the level. Errors where that level does not fit the budget.
    pub(super) fn draw_store_level(
        &mut self,
        f: StoreLevelFrame<'_>,
        progress: &mut (dyn FnMut(&Progress) -> bool + Send),
    ) -> Result<(Rendered, String)> {
        let VolumeSource::File { path, level, .. } = f.source else {
            return Err(EngineError::request("volume", "not an OME-Zarr store"));
        };
        let base = level.index().unwrap_or(0);
        let store = ZarrStore::open(path, &self.limits)?;
        let drawn = (base + f.level).min(store.levels().len() - 1);
        let l = store.level(drawn)?;
        let bytes =
            l.dims.iter().product::<u64>() * l.scalar_type.map_or(4, |t| t.size_bytes() as u64);
        if bytes > f.budget {
            return Err(EngineError::request(
                "quality.level",
                format!(
                    "level {drawn} of the store ({} × {} × {}, {bytes} bytes) does not fit the \
                     memory budget of {} bytes; ask for a coarser level or a larger --memory",
                    l.dims[0], l.dims[1], l.dims[2], f.budget
                ),
            ));
        }
        let mut coarse = f.source.clone();
        if let VolumeSource::File { level, .. } = &mut coarse {
            *level = StoreLevel::Index(drawn);
        }
        let vol = Arc::clone(&self.load(&coarse)?.value.volume);
        let bricks = cached(&mut self.bricks, coarse.clone(), || {
            Ok(Arc::new(f.pool.install(
                || volsplat_core::with_volume!(&*vol, v => BrickGrid::build(v)),
            )))
        })?;
        let bricks = Arc::clone(bricks.value);
        let mut s = f.settings;
        if drawn != base {
            s.antialias = volsplat_splat::Antialias::None;
            let halved: [bool; 3] = std::array::from_fn(|a| vol.grid().dims[a] != f.full.dims[a]);
            s.clip
                .extend(volsplat_splat::pyramid::box_planes(f.full, halved));
        }
        let rendered = forward(progress, |fwd| {
            f.pool.install(|| {
                volsplat_splat::render_slabs_any(
                    &vol,
                    f.camera,
                    f.tables,
                    &s,
                    Some(&bricks),
                    &mut |p| fwd(sheets_done(p)),
                )
            })
        })?;
        let d = vol.grid().dims;
        let note = format!(
            "preview: level {drawn} of the store ({} × {} × {}), read whole, for the renderer's \
             level {}",
            d[0], d[1], d[2], f.level
        );
        Ok((rendered, note))
    }
}
