//! One call that picks the renderer from the settings' visibility, for callers that hold a
//! [`RenderSettings`] and want whichever renderer it names. It dispatches, openly; callers that
//! mean one renderer call it by name ([`crate::sheets::render`], [`crate::slab::render_slabs`]).
//! The front ends choose through the engine's renderer choice instead (decision 0016,
//! `docs/decisions/0016-image-aligned-post-classified-slabs.md`).

use crate::error::Result;
use crate::sheets::{Progress, RenderMode, RenderSettings, Rendered, Visibility};
use volsplat_core::{Camera, CrioTables, Scalar, Volume};

/// Renders `volume` with the renderer `settings.visibility` names: the image-aligned slabs
/// ([`crate::slab::render_slabs`], without a brick grid) for [`Visibility::ImageAligned`] in
/// composite, MIP and MinIP; the sheet renderer ([`crate::sheets::render_with_progress`],
/// orthographic only) for the sheet buffer, composite-every-sample, and X-ray (whose line
/// integrals the sheet buffer computes exactly). `progress` as for either.
pub fn render_by_visibility<T: Scalar>(
    volume: &Volume<T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    progress: &mut dyn FnMut(&Progress) -> bool,
) -> Result<Rendered> {
    if settings.visibility == Visibility::ImageAligned && settings.mode != RenderMode::Xray {
        crate::slab::render_slabs(volume, camera, tables, settings, None, progress)
    } else {
        crate::sheets::render_with_progress(volume, camera, tables, settings, progress)
    }
}
