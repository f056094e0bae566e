//! # volsplat
//!
//! The crate to depend on: one render request in, one picture out, whichever renderer draws it.
//! Front ends (the `volsplat` command, a Python package, a movie writer, a viewer) build a
//! [`RenderRequest`] and hand it to a [`Renderer`]; nothing else needs to know which library
//! does what.
//!
//! - [`Scene`]: what is seen. The [`VolumeSource`] (a file, a built-in [`PhantomKind`], or a
//!   volume in memory), the [`CameraSpec`] (VTK's reset view or a given VTK camera, then an
//!   [`Orbit`](volsplat_core::Orbit) of azimuth, elevation, roll, zoom, dolly), the
//!   [`TransferSpec`], lights and shading switches.
//! - [`RenderRequest`]: how. Image size in pixels, [`Mode`] (composite, MIP, MinIP, X-ray),
//!   [`RendererChoice`], [`Quality`] of the splatting renderers, [`DisplayOptions`] of the
//!   Chapter 6 displays, threads. It is one JSON file ([`RenderRequest::load`] /
//!   [`RenderRequest::save`]) whose camera and transfer function are objects in the formats of
//!   the README's camera and transfer-function files.
//! - [`Renderer`]: built once, `render(&request, progress) -> Output`. It keeps the volume,
//!   classification tables, splat list, display volume and NIL map while the request leaves
//!   them unchanged, so a frame that only moves the camera costs only the frame.
//! - [`Output`]: the premultiplied linear RGBA image, the X-ray or MIP values, one [`Stats`]
//!   (milliseconds), and the camera and transfer function actually used.
//! - [`session::Session`]: progressive rendering for interactive front ends: input events in,
//!   previews sized to a measured frame budget while input arrives, the exact `render` frame at
//!   rest, stale frames cancelled.
//!
//! World space, cameras and transfer functions follow VTK (see `docs/architecture.md`):
//! world units (usually mm), angles in degrees, opacity per `scalar_opacity_unit_distance`.
//! Output does not depend on the thread count.
#![deny(missing_docs)]

pub mod demo;
pub mod distributed;
pub mod error;
pub mod movie;
pub mod output;
pub mod renderer;
pub mod request;
pub mod scene;
pub mod session;
pub mod write;
pub mod xray;

pub use error::{EngineError, Result};
pub use output::OutputOptions;
pub use renderer::{
    DisplayStats, OutOfCoreSummary, Output, Preview, Progress, Renderer, SheetAxis, Stage, Stats,
    UsedRenderer, render_once, renderer_name,
};
pub use request::{
    AntialiasChoice, AttenuationChoice, ControlChoice, DEFAULT_OPACITY_CUTOFF, DensityChoice,
    DisplayChoice, DisplayOptions, KernelChoice, Mode, OrderChoice, PreintegrateChoice, Quality,
    RenderRequest, RendererChoice, ShadeAtChoice, VisibilityChoice, VolumeLevel,
};
pub use scene::{
    CameraSpec, Clipping, CropBox, CropUnits, LightSpec, PhantomKind, PlaneSpec, RawLayout, Scene,
    ShadingTerms, StoreLevel, TransferSpec, VolumeSource, make_phantom,
};

pub use write::{
    OUTPUT_EXTENSIONS, WriteOptions, encode_png, windowed_image, write_image, writes_values,
};
pub use xray::XrayDensity;

/// The libraries underneath, for callers that need their types (cameras, volumes, images).
pub use volsplat_core as core;
/// Buchanan's filters and Chapter 6 displays, whose settings
/// ([`DisplayOptions::settings`]) the engine's API hands out.
pub use volsplat_filter as filter;
/// Readers and writers (volumes, PNG, `.npy`, camera and transfer-function files).
pub use volsplat_io as io;
/// The splatting renderers, whose settings ([`RenderRequest::splat_settings`]) and images
/// ([`Preview::rendered`]) the engine's API hands out.
pub use volsplat_splat as splat;
/// A splatting renderer's image, values and statistics ([`Preview::rendered`]).
pub use volsplat_splat::Rendered;
/// Successive-refinement ladders for [`Renderer::render_refined`].
pub use volsplat_splat::refine::{RefinementStep, default_ladder};
