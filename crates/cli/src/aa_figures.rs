//! `volsplat aa-figures`: the anti-aliasing study of Swan et al. 1997 (Fig. 7 and §5), written
//! by `volsplat_studies::antialias::write_figures`. Flags only.

use crate::say::say;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// Arguments of `volsplat aa-figures`.
#[derive(Debug, Args)]
pub(crate) struct AaFiguresArgs {
    /// Output folder for README.md and the figures (created if missing).
    #[arg(short, long, default_value = "docs/figures")]
    pub out: PathBuf,
    /// Frames of the dolly used to measure flicker.
    #[arg(long, default_value_t = 60)]
    pub frames: usize,
    /// Folder holding `mri_brainsmall.nrrd`, `mri_colin27.nhdr` and `scenes/`, for the MRI
    /// minification table (rows whose data is missing are left out).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// `volsplat aa-figures`.
pub(crate) fn aa_figures_cmd(a: AaFiguresArgs) -> Result<()> {
    let settings = volsplat_studies::AaFiguresSettings {
        out: a.out,
        frames: a.frames,
        data: a.data,
    };
    let pool = crate::commands::thread_pool(a.threads)?;
    let bar = crate::progress::Bar::spinner("aa-figures", false);
    let written = pool.install(|| volsplat_studies::write_figures(&settings));
    bar.clear();
    let written = written?;
    say!("wrote {}", written.report.display());
    Ok(())
}
