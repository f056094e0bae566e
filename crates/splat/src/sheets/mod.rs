//! The sheet renderer: orthographic Westover splatting (Westover 1991, Ch. 3–5).
//!
//! Pipeline per frame (§3.3): transform → CRIO (classify + shade, culling zero opacity) →
//! reconstruct (footprint table) → visibility (sheet buffer or composite-every-sample), sheet by
//! sheet in front-to-back or back-to-front order.
//!
//! **Parallel and deterministic** (§4.3.2 "multiple independent sheet buffers", docs/design.md §4.6):
//! the image is cut into fixed bands of scanlines, each owning its slice of the sheet buffer and
//! of the accumulation buffer. Sheets are processed in batches: the sheets of a batch are
//! classified in parallel (one thread per sheet, samples in a fixed order, each splat routed to
//! the bands its footprint touches), then the bands splat and composite the batch's sheets in
//! parallel. Every pixel therefore receives its contributions in the same order whatever the
//! thread count, and the output is bit-identical for any number of threads.
//!
//! Files: `settings` (the settings, statistics and progress types), `band` (a band's
//! sheet buffer and the deposit of weighted splats into it), `driver` (the frame's end: the
//! accumulation buffer turned into the picture), `dense` (the dense renderer: per-sheet
//! classification of the whole lattice and the footprint-table splat loops).

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
pub use settings::{
    Preintegrate, Progress, RenderMode, RenderSettings, RenderStats, Rendered, Visibility,
    xray_weight,
};
pub(crate) use settings::{ms, validate};
