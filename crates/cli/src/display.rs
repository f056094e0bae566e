//! `render --renderer sabella|nil` and `display-bench`: Buchanan's Chapter 6 volume displays
//! (library: `volsplat_filter::display`; report: `volsplat_studies::display_bench`). Flags only.

use anyhow::Result;
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use volsplat::{AttenuationChoice, ControlChoice, DensityChoice, DisplayChoice};

/// Options of the Chapter 6 displays (ignored by the splatting renderer).
#[derive(Debug, Args)]
#[command(next_help_heading = "Research (Chapter 6 displays)")]
pub(crate) struct DisplayArgs {
    /// Chapter 6 display drawn by `--renderer nil`.
    #[arg(long, value_enum, default_value = "linearised", hide_short_help = true)]
    pub display: DisplayChoice,
    /// Evaluate by direct quadrature instead of NIL maps.
    #[arg(long, hide_short_help = true)]
    pub direct: bool,
    /// Density: the transfer function's scalar opacity (`tf`) or the data value normalised to
    /// its range (`data`, as the thesis's [0, 1] densities).
    #[arg(long, value_enum, default_value = "tf", hide_short_help = true)]
    pub density: DensityChoice,
    /// Attenuation τ per unit length (unit = largest extent of the volume).
    #[arg(long, default_value_t = 3.0, hide_short_help = true)]
    pub tau: f64,
    /// Screen Gaussian standard deviation, pixels.
    #[arg(long, default_value_t = 0.5, hide_short_help = true)]
    pub screen_sigma: f64,
    /// Rays per pixel per axis (Sabella, max).
    #[arg(long, default_value_t = 4, hide_short_help = true)]
    pub supersample: usize,
    /// Samples per ray (Sabella, max, search).
    #[arg(long, default_value_t = 256, hide_short_help = true)]
    pub samples_per_ray: usize,
    /// NIL patch order: 1 constant, 2 linear, 3 quadratic, 4 cubic.
    #[arg(long, default_value_t = 2, hide_short_help = true)]
    pub patch_order: usize,
    /// NIL subdivision tolerance (triggers per cell).
    #[arg(long, default_value_t = 2, hide_short_help = true)]
    pub tolerance: usize,
    /// NIL control points: `project` (L² projection of the filter, decision 0007) or
    /// `interpolate` (the thesis's filter values at the Lagrange nodes).
    #[arg(long, value_enum, default_value = "project", hide_short_help = true)]
    pub control_points: ControlChoice,
    /// NIL triggers per axis across the ray (default: 1 for the linearised display, 3 for
    /// slices and sample-filter, whose triggers fill a box).
    #[arg(long, hide_short_help = true)]
    pub trigger_width: Option<usize>,
    /// NIL trigger slices per unit length along the ray.
    #[arg(long, default_value_t = 32.0, hide_short_help = true)]
    pub trigger_steps: f64,
    /// Lowest NIL level γ_min (negative = sub-voxel cells).
    #[arg(long, default_value_t = -1, allow_negative_numbers = true, hide_short_help = true)]
    pub gamma_min: i32,
    /// Slice depth in [0, 1] (0 = nearest corner of the volume, 1 = farthest).
    #[arg(long, default_value_t = 0.5, hide_short_help = true)]
    pub slice_depth: f64,
    /// Slice standard deviation along the ray, unit lengths (thick 0.1, thin 0.01).
    #[arg(long, default_value_t = 0.1, hide_short_help = true)]
    pub slice_width: f64,
    /// Search density ρ₀ (sample-filter, search).
    #[arg(long, default_value_t = 0.18, hide_short_help = true)]
    pub rho0: f64,
    /// Use the sample closest to ρ₀ (thesis) instead of the first crossing.
    #[arg(long, hide_short_help = true)]
    pub closest: bool,
    /// DoG standard deviations σ1,σ2 in unit lengths.
    #[arg(long, default_value = "0.01,0.02", hide_short_help = true)]
    pub dog_sigma: String,
    /// DoG display gain (value = ½ + gain·response).
    #[arg(long, default_value_t = 8.0, hide_short_help = true)]
    pub dog_gain: f64,
    /// Largest NIL map, in stored f64 values (8 bytes each). 0 (default): half the available
    /// memory; a volume whose map would not fit is averaged down until it does (a note says so).
    #[arg(long, default_value_t = 0, hide_short_help = true)]
    pub max_map_values: usize,
    /// Sabella's colours: grey (the default: the intensity in every channel, as the NIL
    /// displays write theirs, so that the two compare channel for channel), or with
    /// `--grey=false` the thesis's Plate 6.1 colouring (red = intensity, green = maximum
    /// density).
    #[arg(
        long,
        value_name = "true|false",
        default_value_t = true,
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "true",
        action = clap::ArgAction::Set,
        hide_short_help = true
    )]
    pub grey: bool,
    /// The linearised display's attenuation: `optical-depth` (Sabella's own, `1 − e^{−τX}` of the
    /// line integral; decision 0027) or `unit-density` (eq 6.1 as printed: unit density from the
    /// volume's box, the thesis's Plates 6.3–6.6).
    #[arg(
        long,
        value_enum,
        default_value = "optical-depth",
        hide_short_help = true
    )]
    pub attenuation: AttenuationChoice,
    /// NIL continuous patches (decision 0027): neighbouring cells' fits averaged where they meet,
    /// so the image has no seams along cell faces; `--continuous-patches=false` fits each cell
    /// alone (decision 0007 as first written).
    #[arg(
        long,
        value_name = "true|false",
        default_value_t = true,
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "true",
        action = clap::ArgAction::Set,
        hide_short_help = true
    )]
    pub continuous_patches: bool,
    /// Largest NIL cell a filter crosses, in multiples of the filter's width (6σ); 0: no cap
    /// (the thesis's trigger hierarchy alone).
    #[arg(long, default_value_t = 1.5, hide_short_help = true)]
    pub max_cell_width: f64,
}

/// The `--flags` of [`DisplayArgs`] given explicitly on the command line in `matches`.
pub(crate) fn given_flags(matches: &clap::ArgMatches) -> Vec<String> {
    let cmd = DisplayArgs::augment_args(clap::Command::new("display"));
    cmd.get_arguments()
        .filter(|arg| {
            matches.value_source(arg.get_id().as_str())
                == Some(clap::parser::ValueSource::CommandLine)
        })
        .map(|arg| format!("--{}", arg.get_long().unwrap_or(arg.get_id().as_str())))
        .collect()
}

/// Report size of `display-bench`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum BenchSize {
    /// 80×60 pixels on the volume downsampled ×2 (seconds).
    Quick,
    /// 160×120 pixels on the volume downsampled ×2 (the thesis also reduced its data set).
    Default,
    /// 320×240 pixels (the thesis's plate size) on the full volume (minutes).
    Full,
}

/// Arguments of `volsplat display-bench`.
#[derive(Debug, Args)]
pub(crate) struct DisplayBenchArgs {
    /// Volume file (required; any format `render` reads). The committed report
    /// `docs/nil-display/report.md` uses the MRI `mri_brainsmall.nrrd`, which is not in the
    /// repository.
    #[arg(long)]
    pub input: PathBuf,
    /// Output folder for report.md and the plates.
    #[arg(long, default_value = "docs/nil-display")]
    pub out: PathBuf,
    /// Report size.
    #[arg(long, value_enum, default_value = "default")]
    pub size: BenchSize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// `volsplat display-bench`: the Chapter 6 report (plates and timings), written by
/// `volsplat_studies::display_bench`; prints the report.
pub(crate) fn display_bench_cmd(a: DisplayBenchArgs) -> Result<()> {
    use volsplat_studies::{DisplayBenchSettings, DisplayBenchSize};
    let settings = DisplayBenchSettings {
        input: a.input,
        out: a.out,
        size: match a.size {
            BenchSize::Quick => DisplayBenchSize::Quick,
            BenchSize::Default => DisplayBenchSize::Default,
            BenchSize::Full => DisplayBenchSize::Full,
        },
    };
    let pool = crate::commands::thread_pool(a.threads)?;
    let bar = crate::progress::Bar::spinner("display-bench", false);
    let written = pool.install(|| volsplat_studies::display_bench::run(&settings));
    bar.clear();
    let written = written?;
    crate::commands::emit(&written.markdown)
}
