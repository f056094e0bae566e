//! # volsplat-testkit
//!
//! Dev-only test oracles for volsplat (docs/design.md §6.5: oracle tests before golden images).
//!
//! - [`reference`](mod@reference): the brute-force ray integrator for orthographic and
//!   perspective [`Projection`](volsplat_core::Projection)s — X-ray
//!   ([`reference_xray`]), MIP / MinIP ([`reference_mip`], [`reference_minip`]) and CRIO
//!   compositing ([`reference_composite`]) by marching each pixel's ray through the trilinear
//!   field — and the closed-form X-ray image of a phantom ([`analytic_xray`]). It shares no code
//!   with the splatting renderer beyond the core types and the CRIO classifier.
//! - [`metrics`](mod@metrics): the workspace's one image-metrics module: [`mse`], [`psnr`],
//!   [`relative_l2`], [`ssim_gray`], the 8-bit MSE and SNR of Buchanan's §5-2
//!   ([`mse_8bit`], [`snr_db`]), [`total_variation`], [`rms_rgb`], and helpers that turn a
//!   premultiplied [`Image`](volsplat_core::Image) into comparable channels
//!   ([`image_rgb_over`], [`image_psnr`], [`luminance`]).
//! - [`fixtures`](mod@fixtures): the shaded transfer function shared by the oracle tests.
//! - [`data`](mod@data): the shared test data (`shared/data`): its paths and an 8-bit NRRD
//!   reader for the crates below `volsplat-io`.
//! - [`phantom`](mod@phantom): re-export of [`volsplat_core::phantom`] (Gaussian blobs, the
//!   3-D Shepp–Logan phantom, a CT head, Marschner–Lobb; closed-form line integrals; sampling
//!   into volumes).
//!
//! Frames and units follow docs/design.md §3: world units are the volume's (usually mm), images have
//! row 0 at the top and pixel centres at half integers, colour is premultiplied. Everything is
//! deterministic: parallel loops (rayon, over image rows) compute each pixel independently.
#![deny(missing_docs)]

pub mod data;
pub mod emitter;
pub mod fixtures;
pub mod metrics;
pub mod reference;

pub use volsplat_core::phantom;

pub use metrics::{
    image_psnr, image_rgb_over, luminance, mse, mse_8bit, mse_8bit_where, psnr, relative_l2,
    rms_rgb, snr_db, ssim_gray, to_8bit, total_variation,
};
pub use reference::{
    Extent, ReferenceSettings, analytic_xray, ray_box_interval, ray_extent_interval,
    reference_composite, reference_minip, reference_mip, reference_xray, trilinear,
    voxel_gradients,
};
pub use volsplat_core::phantom::{
    Blob, Ellipsoid, EllipsoidPhantom, GaussianBlobs, MarschnerLobb, Phantom, ct_head_volume,
    sample, sample_on_grid,
};
