//! # volsplat-core
//!
//! The floor of the volsplat workspace: the types every other crate shares.
//!
//! - [`volume`]: [`Grid`] (dims, spacing, origin, direction; VTK's world space) and
//!   [`Volume<T>`] / [`AnyVolume`] for u8, i8, u16, i16 and f32 samples.
//! - [`camera`]: VTK-compatible [`Camera`], its [`ViewFrame`], and the [`OrthoProjection`] from
//!   world to raster coordinates.
//! - [`transfer`]: VTK-style [`TransferFunction`] files.
//! - [`presets`]: 3D Slicer's volume-rendering [`Preset`]s and the automatic transfer function
//!   fitted to a [`Histogram`] ([`AutoTransfer`]).
//! - [`crio`]: Westover's four CRIO tables, lights and shading, and the per-frame
//!   [`FrameClassifier`].
//! - [`kernel`]: reconstruction kernels (Gaussian, single-point, nearest, tent, Mitchell–Netravali,
//!   Crawfis–Max cubic splat).
//! - [`image`]: premultiplied RGBA [`Image`], [`ScalarImage`], and the *over* operators.
//! - [`phantom`]: analytic test volumes with closed-form line integrals (the built-in demo data).
//! - [`source`]: the brick seam: [`BrickSource`] (bricks of a fixed size with a one-voxel halo,
//!   per-brick ranges, pyramid levels), its [`BrickLayout`], and the in-memory [`InMemory`].
//! - [`scenes`]: synthetic stand-ins for the test scenes of Swan et al. 1997, Fig. 7
//!   (checkerboard sheet, terrain, confocal-like filaments) with matching transfer functions.
//!
//! Conventions (docs/design.md §3): world units are those of the data (usually mm); angles are degrees
//! at interfaces and radians inside; images have row 0 at the top and pixel centres at half
//! integers; colour is premultiplied.
#![deny(missing_docs)]

pub mod camera;
pub mod crio;
pub mod error;
pub mod image;
pub mod kernel;
pub mod phantom;
pub mod presets;
pub mod scenes;
pub mod source;
pub mod transfer;
pub mod volume;

pub use camera::{
    AnatomicalView, Camera, Orbit, OrthoProjection, PerspectiveProjection, Projection,
    ProjectionKind, ViewFrame,
};
pub use crio::{
    CrioTables, FrameClassifier, FrameLight, Light, LookupTable, SampleInput, Shading,
    SpecularColor, SurfaceTerms, TableIndex,
};
pub use error::{CoreError, Result};
pub use image::{Image, Rgba, ScalarImage};
pub use kernel::Kernel;
pub use presets::{AutoTransfer, BackgroundRule, Histogram, Preset};
pub use source::{Brick, BrickKey, BrickLayout, BrickSource, InMemory};
pub use transfer::TransferFunction;
pub use volume::{AnyVolume, Grid, NonFiniteSamples, Scalar, ScalarType, Volume};

/// Re-export of the linear-algebra crate used in public signatures.
pub use glam;
