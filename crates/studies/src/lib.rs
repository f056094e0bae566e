//! # volsplat-studies
//!
//! Paper reproductions and benchmarks-as-reports for volsplat (not published): the code behind
//! the report commands of the `volsplat` binary, kept out of the libraries and the binary.
//!
//! - [`texture_bench`]: Buchanan's Chapter 5 evaluation of solid-texture filters (Tables
//!   5.1–5.11, Plates 5.1–5.16, Appendix C) → `volsplat texture-bench`, `docs/texture-bench/`.
//! - [`display_bench`]: Buchanan's Chapter 6 volume displays (Plates 6.1–6.14, Tables 6.1–6.2)
//!   timed against splatting → `volsplat display-bench`, `docs/nil-display/`.
//! - [`antialias`]: Swan et al. 1997's anti-aliasing measurements and Fig. 7 →
//!   `volsplat aa-figures`, `docs/figures/`.
//! - [`metrics`]: the image metrics (a re-export of `volsplat-testkit`'s, decision 0011).
//!
//! Each report function runs on the current rayon thread pool (the caller chooses the thread
//! count with `ThreadPool::install`), writes its files into a folder and returns [`Written`].
//! What the reports found is discussed in `docs/` (e.g. `docs/texture-bench/findings.md`).
#![deny(missing_docs)]

pub mod antialias;
pub mod display_bench;
pub mod metrics;
pub mod texture_bench;

pub use antialias::{AaFiguresSettings, write_figures};
pub use display_bench::{DisplayBenchSettings, DisplayBenchSize};
pub use texture_bench::{TextureBenchReport, TextureBenchSettings, run_texture_bench};

use std::path::PathBuf;

/// What a report function wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    /// The Markdown report's path (`report.md` or `README.md` in the output folder).
    pub report: PathBuf,
    /// The report's Markdown text.
    pub markdown: String,
    /// The number of images written beside it.
    pub images: usize,
}
