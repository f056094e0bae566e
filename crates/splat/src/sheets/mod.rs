//! The sheet renderer: orthographic Westover splatting (Westover 1991, Ch. 3–5).
//!
//! Pipeline per frame (§3.3): transform → CRIO (classify + shade, culling zero opacity) →
//! reconstruct (footprint table) → visibility (sheet buffer or composite-every-sample), sheet by
//! sheet in front-to-back or back-to-front order.
//!
//! **Parallel and deterministic** (§4.3.2 "multiple independent sheet buffers";
//! `docs/architecture.md`, "Parallelism and determinism"): the image is cut into fixed bands of
//! [`RenderSettings::band_height`] scanlines (32 by default), each owning its slice of the sheet
//! buffer and of the accumulation buffer. Sheets are processed in batches of
//! [`RenderSettings::sheets_per_batch`] (8 by default): the sheets of a batch are classified in
//! parallel (one task per sheet, samples in a fixed order, each splat routed to the bands its
//! footprint touches), then the bands splat and composite the batch's sheets in parallel. Every
//! pixel therefore receives its contributions in the same order whatever the thread count, and
//! the output is bit-identical for any number of threads.
//!
//! This renderer draws [`Visibility::SheetBuffer`] and [`Visibility::EverySample`]; it refuses
//! [`Visibility::ImageAligned`] outside X-ray (the image-aligned slabs are
//! [`crate::slab::render_slabs`]; [`crate::render_by_visibility`] dispatches on the visibility).
//!
//! Where a pixel's colour is computed, step by step:
//! - `settings.rs`: [`RenderSettings`], [`RenderStats`], [`Rendered`], [`Progress`];
//! - `driver.rs`: the sheet driver (`drive`, trait `SheetPass`), shared with the splat-list
//!   renderer ([`crate::list`]): batches, bands, progress, the thread split, and the frame's end
//!   (`finish`: accumulation buffer → image);
//! - `dense.rs`: this renderer's part: each sheet's samples transformed, culled and classified
//!   (`ClassifyContext::classify_sheet`), then splatted through the frame's footprint table
//!   (`splat_block`, the internal `footprint` module);
//! - `band.rs`: a band's sheet buffer, the deposit of a weighted splat into a pixel (`deposit`),
//!   and the composite of the sheet buffer onto the accumulation buffer
//!   (`composite_band_sheet`, the *over* operator of Westover §3.8.1).

mod band;
mod dense;
mod driver;
mod settings;

pub(crate) use band::{
    BandState, SINK_LINE, SINK_OVER_BTF, SINK_OVER_FTB, SINK_SHEET, SpanCtx, Splat, TILE, deposit,
    div_band, scale_kept,
};
pub use dense::{render, render_any, render_with_progress};
pub(crate) use driver::{SheetPass, drive, finish};
pub use driver::{extreme_picture, xray_picture};
pub(crate) use settings::{OwnedVoxels, ms, refuse_image_aligned, validate};
pub use settings::{
    Preintegrate, Progress, RenderMode, RenderSettings, RenderStats, Rendered, Visibility,
    xray_weight,
};
