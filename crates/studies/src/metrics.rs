//! The image metrics of every study: `volsplat-testkit`'s metrics module, re-exported (one
//! implementation in the workspace, shared with the tests; decision 0011).
//!
//! The studies use [`mse_8bit`], [`mse_8bit_where`] and [`snr_db`] (Buchanan's §5-2 MSE and SNR
//! on 8-bit levels), [`total_variation`] (a blur measure) and [`rms_rgb`] (masked RMS over the
//! RGB channels of premultiplied images); [`mse`], [`psnr`], [`relative_l2`] and [`ssim_gray`]
//! compare data values.

pub use volsplat_testkit::metrics::*;
