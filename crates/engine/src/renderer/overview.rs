//! What front ends ask of a volume besides frames (its grid, a volume for histograms),
//! answered without reading a store that is read out of core (decision 0039): its grid from
//! the metadata, its histogram from its coarsest level.

use super::Renderer;
use crate::error::{EngineError, Result};
use crate::request::RenderRequest;
use crate::scene::{StoreLevel, VolumeSource};
use std::sync::Arc;
use volsplat_core::{AnyVolume, Grid, ScalarType};
use volsplat_io::ZarrStore;

/// The most samples of a level read whole as an overview of a store read out of core.
const OVERVIEW_SAMPLES: u64 = 16 << 20;

/// What [`Renderer::out_of_core_summary`] knows of a store's level without reading it whole.
#[derive(Debug, Clone)]
pub struct OutOfCoreSummary {
    /// The level's grid (world frame and spacing in mm).
    pub grid: Grid,
    /// Its sample type.
    pub scalar_type: ScalarType,
    /// `[lo, hi]` of its samples (data units; a float level's finite samples).
    pub value_range: [f64; 2],
    /// Where the range came from (kept ranges, or a scan and where it was kept).
    pub note: Option<String>,
}

impl Renderer {
    /// For an OME-Zarr level that `request` would read out of core ([`RenderRequest::memory`],
    /// or a level larger than half the available memory): its grid (world frame, mm), sample
    /// type and value range `[lo, hi]` (data units; a float level's finite samples), from the
    /// store's metadata and its ranges kept in the user's cache folder, or else a ranges scan
    /// within the budget (kept for the next open), and a note saying which: nothing is read
    /// whole. `None` where the volume is read whole (ask [`Renderer::volume`]). For summaries
    /// such as `volsplat info` of a store larger than memory.
    pub fn out_of_core_summary(
        &mut self,
        request: &RenderRequest,
    ) -> Result<Option<OutOfCoreSummary>> {
        let (source, _) = self.concrete_source(request)?;
        let Some(budget) = self.paged_budget(request, &source, false)? else {
            return Ok(None);
        };
        let (grid, scalar_type) = self.volume_grid(request)?;
        let (value_range, note) = super::paged::store_level_range(&source, budget, &self.limits)?;
        Ok(Some(OutOfCoreSummary {
            grid,
            scalar_type,
            value_range,
            note,
        }))
    }

    /// The grid of `request`'s volume (world frame and spacing in mm, as the readers give it)
    /// and its sample type: for an OME-Zarr level read out of core ([`RenderRequest::memory`],
    /// or a level larger than half the available memory), from the store's metadata, with
    /// nothing read; otherwise the loaded volume's (loading it once).
    pub fn volume_grid(&mut self, request: &RenderRequest) -> Result<(Grid, ScalarType)> {
        let (source, _) = self.concrete_source(request)?;
        if self.paged_budget(request, &source, false)?.is_some()
            && let VolumeSource::File { path, level, .. } = &source
        {
            let store = ZarrStore::open(path, &self.limits)?;
            let l = level.index().unwrap_or(0);
            let kind = store.level(l)?.scalar_type.ok_or_else(|| {
                EngineError::request("volume", "the level's sample type cannot be rendered")
            })?;
            return Ok((store.grid(l)?, kind));
        }
        let vol = self.volume(&source)?;
        Ok((vol.grid().clone(), vol.scalar_type()))
    }

    /// A volume that stands for `request`'s in summaries (histograms, the transfer-function
    /// editor): the volume itself, or for an OME-Zarr level read out of core the store's coarsest
    /// level, read whole where it holds at most 16 M samples. An error naming `memory` where the
    /// store has no level that small.
    pub fn overview(&mut self, request: &RenderRequest) -> Result<Arc<AnyVolume>> {
        let (source, _) = self.concrete_source(request)?;
        if self.paged_budget(request, &source, false)?.is_none() {
            return self.volume(&source);
        }
        let VolumeSource::File { path, .. } = &source else {
            return self.volume(&source);
        };
        let store = ZarrStore::open(path, &self.limits)?;
        let coarsest = store.levels().len() - 1;
        let samples = store.levels()[coarsest].dims.iter().product::<u64>();
        if samples > OVERVIEW_SAMPLES {
            return Err(EngineError::request(
                "memory",
                format!(
                    "the store is read out of core and its coarsest level holds {samples} \
                     samples, too many to read whole for an overview (at most {OVERVIEW_SAMPLES}); \
                     convert it with `volsplat convert … -o X.zarr` to add coarser levels"
                ),
            ));
        }
        let mut coarse = source.clone();
        if let VolumeSource::File { level, .. } = &mut coarse {
            *level = StoreLevel::Index(coarsest);
        }
        self.volume(&coarse)
    }
}

impl Renderer {
    /// Reads the full level of the OME-Zarr store at `path` brick by brick once and keeps its
    /// ranges in the user's cache folder (decision 0039 item 7), so that its first out-of-core
    /// open needs no scan (`volsplat convert … -o X.zarr` calls it after writing). Returns the
    /// notes of the scan (where the ranges were kept, or why they could not be).
    pub fn keep_store_ranges(&mut self, path: &std::path::Path) -> Result<Vec<String>> {
        let source = VolumeSource::File {
            path: path.to_path_buf(),
            raw: None,
            frame: 0,
            array: None,
            series: None,
            level: StoreLevel::Index(0),
            channel: 0,
            timepoint: 0,
        };
        // The smallest arena: only the scan is wanted.
        let paged = super::paged::open_paged(&source, 8 << 20, &self.limits, None)?;
        Ok(paged.notes)
    }
}
