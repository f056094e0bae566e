//! `render --renderer sabella|nil`: Buchanan's Chapter 6 volume displays.
//!
//! Placeholder: the options and the dispatch are filled in by the NIL-display work (issue 5).

use crate::args::RenderArgs;
use anyhow::{Result, bail};
use clap::Args;
use volsplat_core::{AnyVolume, Camera, Image, TransferFunction};

/// Options of the Chapter 6 displays (ignored by the splatting renderer).
#[derive(Debug, Args)]
pub struct DisplayArgs {}

/// Renders with the display chosen by `--renderer`; returns the premultiplied image and a JSON
/// object of timings for `--stats`.
pub fn render_display(
    a: &RenderArgs,
    _vol: &AnyVolume,
    _camera: &Camera,
    _tf: &TransferFunction,
    _width: usize,
    _height: usize,
) -> Result<(Image, serde_json::Value)> {
    bail!("--renderer {:?} is not available yet", a.renderer)
}

/// Arguments of `volsplat display-bench`.
#[derive(Debug, Args)]
pub struct DisplayBenchArgs {}

/// `volsplat display-bench`: the Chapter 6 report (plates and timings).
pub fn display_bench_cmd(_a: DisplayBenchArgs) -> Result<()> {
    bail!("display-bench is not available yet")
}
