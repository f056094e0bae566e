//! The subcommands: glue between arguments and the libraries.

use crate::args::*;
use crate::request::*;
use crate::say::say;
use crate::signals::Stop;
use anyhow::{Context, Result, anyhow, bail};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;
use volsplat::core::{Image, ScalarImage};
use volsplat::io::PngBitDepth;
use volsplat::{
    CameraSpec, Mode, RenderRequest, Renderer, TransferSpec, UsedRenderer, VolumeSource,
    default_ladder, renderer_name,
};

pub(crate) fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render(a) => render_cmd(*a),
        Command::Info(a) => info_cmd(a),
        Command::Presets => presets_cmd(),
        Command::Convert(a) => convert_cmd(a),
        Command::Phantom(a) => phantom_cmd(a),
        Command::Bench(a) => bench_cmd(*a),
        Command::View(a) => crate::view::view_cmd(*a),
        Command::BenchView(a) => crate::view::bench_view_cmd(*a),
        Command::Movie(a) => crate::movie::movie_cmd(*a),
        Command::TextureBench(a) => texture_bench_cmd(a),
        Command::DisplayBench(a) => crate::display::display_bench_cmd(*a),
        Command::AaFigures(a) => crate::aa_figures::aa_figures_cmd(a),
    }
}

pub(crate) fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 || n > 1024 {
            bail!("--threads must be in 1..=1024, got {n}");
        }
        b = b.num_threads(n);
    }
    Ok(b.build()?)
}

/// The image formats `render -o` writes, by extension (case-insensitive).
const OUTPUT_EXTENSIONS: &[&str] = volsplat::OUTPUT_EXTENSIONS;

/// Checks, before any work, that `path` (given with `flag`) can be written: not a folder, its
/// folder exists, and, if `extensions` is not empty, it ends in one of them.
pub(crate) fn check_output_path(path: &Path, flag: &str, extensions: &[&str]) -> Result<()> {
    if path.is_dir() {
        bail!("{flag} {}: is a folder; give a file name", path.display());
    }
    if !extensions.is_empty() {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        if !extensions.contains(&ext.as_str()) {
            let list: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
            bail!(
                "{flag} {}: unsupported extension; use {}",
                path.display(),
                list.join(" or ")
            );
        }
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        if dir.exists() {
            bail!(
                "{flag} {}: {} is not a folder",
                path.display(),
                dir.display()
            );
        }
        bail!(
            "{flag} {}: the folder {} does not exist",
            path.display(),
            dir.display()
        );
    }
    Ok(())
}

/// Non-finite values in what would be written: an image file must never hold NaN or infinity.
#[derive(Debug)]
pub(crate) struct NonFiniteOutput {
    /// The renderer or stage that produced the image.
    pub stage: String,
    /// Pixels with at least one non-finite value.
    pub count: usize,
    /// The file that was not written.
    pub path: PathBuf,
    /// Files this command had already written (ladder previews).
    pub written: Vec<PathBuf>,
}

impl std::fmt::Display for NonFiniteOutput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "internal error: the {} produced {} non-finite pixel{}; ",
            self.stage,
            self.count,
            if self.count == 1 { "" } else { "s" }
        )?;
        if self.written.is_empty() {
            write!(f, "nothing was written")
        } else {
            let list: Vec<String> = self
                .written
                .iter()
                .map(|p| p.display().to_string())
                .collect();
            write!(
                f,
                "{} was not written (the previews {} had been)",
                self.path.display(),
                list.join(", ")
            )
        }
    }
}

impl std::error::Error for NonFiniteOutput {}

/// A grey window `(lo, hi)` from `--window LO:HI` or `--wl LEVEL,WIDTH`, if one is given.
pub(crate) fn grey_window(o: &ImageOptions) -> Result<Option<(f32, f32)>> {
    let w = match (&o.window, &o.wl) {
        (Some(w), _) => {
            let [lo, hi] = pair(w, ':', "--window")?;
            (lo as f32, hi as f32, "--window")
        }
        (None, Some(wl)) => {
            let [level, width] = pair(wl, ',', "--wl")?.map(|v| v as f32);
            if width.is_nan() || width <= 0.0 {
                bail!("--wl {wl}: the width must be > 0");
            }
            (level - 0.5 * width, level + 0.5 * width, "--wl")
        }
        (None, None) => return Ok(None),
    };
    let (lo, hi, flag) = w;
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        bail!("{flag}: the window needs finite values with LO < HI, got {lo}:{hi}");
    }
    Ok(Some((lo, hi)))
}

/// Pixels of what would be written that hold a non-finite value: the line integrals if
/// `use_values`, otherwise the RGBA image (a pixel counts once however many channels are bad).
pub(crate) fn non_finite_pixels(
    image: &Image,
    values: Option<&ScalarImage>,
    use_values: bool,
) -> usize {
    match (values, use_values) {
        (Some(v), true) => v.values().iter().filter(|x| !x.is_finite()).count(),
        _ => image
            .pixels()
            .iter()
            .filter(|p| p.iter().any(|c| !c.is_finite()))
            .count(),
    }
}

/// Writes an image (or the X-ray values) to `path` unless it holds non-finite values
/// ([`NonFiniteOutput`], naming `stage`; `written` lists the files already written), with the
/// request's mode and output options.
fn write_checked(
    path: &Path,
    image: &Image,
    values: Option<&ScalarImage>,
    req: &RenderRequest,
    stage: &str,
    written: &[PathBuf],
) -> Result<()> {
    let options = req.output.write_options().map_err(explain)?;
    let grey = volsplat::writes_values(values.is_some(), req.mode, options.window);
    let bad = match (grey, req.mode, values) {
        // MIP and MinIP values are NaN where no sample covers the pixel, by design.
        (true, Mode::Mip | Mode::Minip, Some(v)) => {
            v.values().iter().filter(|x| x.is_infinite()).count()
        }
        _ => non_finite_pixels(image, values, grey),
    };
    if bad > 0 {
        return Err(NonFiniteOutput {
            stage: stage.to_string(),
            count: bad,
            path: path.to_path_buf(),
            written: written.to_vec(),
        }
        .into());
    }
    volsplat::write_image(path, image, values, req.mode, &options)
        .map_err(explain)
        .with_context(|| format!("writing {}", path.display()))
}

/// The `--background` colour: three linear values in [0, 1].
pub(crate) fn background(o: &ImageOptions) -> Result<[f32; 3]> {
    let bg = triple::<f32>(&o.background, "--background")?;
    volsplat::write::check_background(bg)
        .map_err(|m| anyhow!("--background {}: {m}", o.background))?;
    Ok(bg)
}

pub(crate) fn png_bits(o: &ImageOptions) -> Result<PngBitDepth> {
    PngBitDepth::from_bits(o.bits as u32)
        .ok_or_else(|| anyhow!("--bit-depth must be 8 or 16, got {}", o.bits))
}

/// The checks of the image options that need neither a volume nor the request: their syntax
/// and ranges. Whether a grey window suits the mode is the request's check
/// (`RenderRequest::validate`, field `output.window`), made once a `--scene` file's mode and
/// the flags are resolved: `render --scene mip.json --wl …` needs no `--mode mip`.
pub(crate) fn check_image_options(o: &ImageOptions) -> Result<()> {
    png_bits(o)?;
    background(o)?;
    grey_window(o)?;
    Ok(())
}

/// The checks of `render` that need no volume: output paths, image size, PNG options. Run
/// before loading and rendering, which can take seconds.
fn check_render_args(a: &RenderArgs) -> Result<()> {
    check_output_path(&a.output, "-o", OUTPUT_EXTENSIONS)?;
    if let Some(p) = &a.view.save_camera {
        check_output_path(p, "--save-camera", &[])?;
    }
    if let Some(p) = &a.save_scene {
        check_output_path(p, "--save-scene", &["json"])?;
    }
    parse_image_size(&a.options.size, "--size")?;
    check_image_options(&a.image)?;
    let npy = a
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    if npy {
        let png_only: Vec<&str> = [
            ("bits", "--bit-depth"),
            ("srgb", "--srgb"),
            ("background", "--background"),
        ]
        .into_iter()
        .filter(|(id, _)| a.given.iter().any(|g| g == id))
        .map(|(_, flag)| flag)
        .collect();
        if !png_only.is_empty() {
            say!(
                "warning: {} only apply to PNG output; {} holds the float image as rendered \
                 (premultiplied, linear)",
                png_only.join(", "),
                a.output.display()
            );
        }
    }
    if let Some(c) = &a.draw_k {
        triple::<f32>(c, "--draw-k")?;
    }
    if !a.given_display_flags.is_empty() && a.renderer == RendererArg::Auto {
        say!(
            "warning: {} only apply to --renderer sabella|nil; the splatting renderer ignores them",
            a.given_display_flags.join(", ")
        );
    }
    if a.renderer != RendererArg::Auto {
        if a.options.mode != Mode::Composite {
            bail!(
                "--mode {:?}: the Chapter 6 displays (--renderer sabella|nil) have their own ray \
                 function; use --renderer auto for MIP, MinIP and X-ray",
                a.options.mode
            );
        }
        if !a.given_splat_flags.is_empty() {
            say!(
                "warning: {} only apply to --renderer auto; the {:?} display ignores them",
                a.given_splat_flags.join(", "),
                a.renderer
            );
        }
    }
    Ok(())
}

/// The request of a `--scene` file, its unknown fields printed as warnings.
pub(crate) fn load_scene(path: Option<&Path>) -> Result<Option<RenderRequest>> {
    let Some(p) = path else {
        return Ok(None);
    };
    let (req, warnings) = RenderRequest::load(p)?;
    for w in warnings {
        say!("warning: {w}");
    }
    Ok(Some(req))
}

/// [`check_render_args`], then the request of `a` ([`render_request_noted`]) and its notes,
/// unprinted: `volsplat_cli::render_flags`.
pub(crate) fn render_request_checked(a: &RenderArgs) -> Result<(RenderRequest, Vec<String>)> {
    check_render_args(a)?;
    render_request_noted(a)
}

/// The `given` ids of `a` plus the `--scene` request, translated into the engine's request.
fn render_request(a: &RenderArgs) -> Result<RenderRequest> {
    let (req, notes) = render_request_noted(a)?;
    if !a.quiet {
        for n in notes {
            say!("note: {n}");
        }
    }
    Ok(req)
}

/// The `given` ids of `a` plus the `--scene` request, translated into the engine's request,
/// and what the translation noted; validated before any volume is loaded.
fn render_request_noted(a: &RenderArgs) -> Result<(RenderRequest, Vec<String>)> {
    let base = load_scene(a.scene.as_deref())?;
    let (req, notes) = build_request_noted(
        &a.input,
        &a.view,
        &a.options,
        Some(&a.image),
        a.renderer,
        Some(&a.display),
        a.draw_k.as_deref(),
        &a.given.iter().cloned().collect(),
        base,
    )?;
    // Before the volume is loaded, which can take seconds.
    req.validate().map_err(explain)?;
    Ok((req, notes))
}

/// An engine error of a render worded for the command line, with `rendering LABEL` in front
/// unless the error names its file already (a volume that cannot be read).
pub(crate) fn render_error(e: volsplat::EngineError, label: &str) -> anyhow::Error {
    match e {
        volsplat::EngineError::Io(_) | volsplat::EngineError::SceneFile { .. } => explain(e),
        e => explain(e).context(format!("rendering {label}")),
    }
}

/// Writes one line to standard output. A closed pipe (`volsplat info f | head -1`) ends the
/// output quietly instead of panicking as `println!` does.
pub(crate) fn emit(line: &str) -> Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{line}").and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r.context("writing to standard output"),
    }
}

/// The command-line flag of a request field, for error messages.
fn flag_of(field: &str) -> Option<&'static str> {
    Some(match field {
        "k_contour" => "--draw-k",
        "width" | "height" => "--size",
        "mode" => "--mode",
        "renderer" => "--renderer",
        "threads" => "--threads",
        "memory" => "--memory",
        "quality.subsample" => "--subsample",
        "quality.opacity_cutoff" => "--opacity-cutoff",
        "quality.slab" => "--slab",
        "quality.list_threshold" => "--list-threshold",
        "volume.grid" => "--phantom-size",
        "display.dog_sigma" => "--dog-sigma",
        "scene.surface_enhance" => "--surface-enhance",
        "scene.depth_cue" => "--depth-cue",
        "scene.transfer_function" => "--tf/--preset",
        "scene.shading" => "--no-emission/--no-diffuse/--no-specular",
        "scene.clipping.crop" => "--crop/--crop-mm",
        "background" | "output.background" => "--background",
        "output.window" => "--window/--wl",
        "output.bit_depth" => "--bit-depth",
        "frames" => "--frames",
        "fps" => "--fps",
        "degrees" => "--degrees",
        "axis" => "--axis",
        f if f.starts_with("scene.clipping.planes") => "--clip-plane",
        f if f.starts_with("keyframes") || f.starts_with("frame ") => "--keyframes",
        f if f.starts_with("scene.lights") => "--light",
        _ => return None,
    })
}

/// An engine warning worded for the command line: an ignored option
/// ([`RenderRequest::ignored_options`], `scene.lights is ignored by mode xray: …`) names its flag
/// too (`--light (scene.lights) is ignored by --mode xray: …`).
pub(crate) fn cli_warning(w: &str) -> String {
    if let Some((field, rest)) = w.split_once(" is ignored by mode ")
        && let Some(flag) = flag_of(field)
    {
        return format!("{flag} ({field}) is ignored by --mode {rest}");
    }
    w.to_string()
}

/// An engine error worded for the command line: request fields name their flag too.
pub(crate) fn explain(e: volsplat::EngineError) -> anyhow::Error {
    match e {
        volsplat::EngineError::Request { field, message } => match flag_of(&field) {
            Some(flag) => anyhow!("{flag} ({field}): {message}"),
            None => anyhow!("{field}: {message}"),
        },
        e => e.into(),
    }
}

fn render_cmd(a: RenderArgs) -> Result<()> {
    let t0 = Instant::now();
    check_render_args(&a)?;
    let req = render_request(&a)?;
    let mut renderer = Renderer::with_limits(reader_limits(&a.input)?);
    let label = req.scene.volume.label();
    let mut written: Vec<PathBuf> = Vec::new();
    let stop = Stop::install()?;
    let out = if a.ladder {
        let ladder = default_ladder(req.quality.kernel.kernel());
        let quiet = a.quiet;
        let (output, stop) = (&a.output, &stop);
        let written = &mut written;
        renderer.render_refined(&req, &ladder, &mut |p| {
            let path = preview_path(output, p.subsample);
            let stage = format!(
                "splatting renderer (preview of every {}th voxel)",
                p.subsample
            );
            let out = p.rendered;
            write_checked(
                &path,
                &out.image,
                out.values.as_ref(),
                &req,
                &stage,
                written,
            )
            .map_err(|e| volsplat::EngineError::request("preview", format!("{e:#}")))?;
            written.push(path.clone());
            if !quiet {
                say!(
                    "preview {}: {} ({:.1} ms)",
                    p.index + 1,
                    path.display(),
                    out.stats.total_ms
                );
            }
            Ok(stop.signal().is_none())
        })
    } else {
        let bar = crate::progress::Bar::fraction("render", a.quiet);
        let out = renderer.render(&req, &mut |p| {
            bar.set_fraction(p.fraction, p.stage.as_str());
            stop.signal().is_none()
        });
        bar.clear();
        out
    };
    if stop.signal().is_some() {
        // Nothing of an interrupted render is kept: not even its whole previews.
        for p in &written {
            let _ = std::fs::remove_file(p);
        }
        stop.check(&format!(
            "stopped before writing {}{}",
            a.output.display(),
            if written.is_empty() {
                ""
            } else {
                " (its previews were removed)"
            }
        ))?;
    }
    let out = match out {
        Err(volsplat::EngineError::NonFinite { stage, count }) => {
            return Err(NonFiniteOutput {
                stage,
                count,
                path: a.output.clone(),
                written,
            }
            .into());
        }
        r => r.map_err(|e| render_error(e, &label))?,
    };
    if !a.quiet {
        for n in &out.notes {
            say!("note: {n}");
        }
    }
    for w in &out.warnings {
        if w.starts_with("k = ") {
            if !a.quiet {
                say!("{w}");
            }
        } else {
            say!("warning: {}", cli_warning(w));
        }
    }
    if out.camera.parallel_projection && a.view.view_angle.is_some() {
        say!(
            "warning: --view-angle has no effect on an orthographic camera{} (add --perspective)",
            match &a.view.camera {
                Some(p) => format!(" ({} has parallel_projection: true)", p.display()),
                None => String::new(),
            }
        );
    }
    if let Some(p) = &a.view.save_camera {
        volsplat::io::save_camera(p, &out.camera)?;
    }
    if let Some(p) = &a.save_scene {
        // The complete request that was rendered, with its camera and transfer function resolved
        // to objects in the camera- and transfer-function-file formats.
        let mut saved = req.clone();
        saved.scene.camera = CameraSpec::Explicit {
            camera: out.camera.clone(),
            orbit: volsplat::core::Orbit::default(),
        };
        // X-ray ignores the transfer function: the scene keeps `auto` rather than a function
        // that would draw an "ignored" warning when rendered again.
        if req.mode != Mode::Xray {
            saved.scene.transfer_function = TransferSpec::Function(out.transfer_function.clone());
        }
        saved.save(p)?;
    }
    let stage = renderer_name(out.stats.renderer.unwrap_or(UsedRenderer::Sheets));
    write_checked(
        &a.output,
        &out.image,
        out.values.as_ref(),
        &req,
        stage,
        &written,
    )?;
    if !a.quiet {
        say!(
            "wrote {} ({}×{}, {:.0} ms)",
            a.output.display(),
            req.width,
            req.height,
            t0.elapsed().as_secs_f64() * 1e3
        );
    }
    // A signal during the last writes: what was written is whole and kept.
    stop.check(&format!(
        "stopped after {} was written whole (kept)",
        a.output.display()
    ))?;
    if a.stats {
        emit(&serde_json::to_string(&out.stats)?)?;
    }
    Ok(())
}

fn preview_path(output: &Path, subsample: usize) -> PathBuf {
    let stem = output.file_stem().and_then(|s| s.to_str()).unwrap_or("out");
    let ext = output.extension().and_then(|s| s.to_str()).unwrap_or("png");
    output.with_file_name(format!("{stem}.preview-s{subsample}.{ext}"))
}

/// The summary of an OME-Zarr level read out of core (`--memory`, or a level larger than half
/// the available memory), from its metadata and a bounded ranges scan, never read whole;
/// `None` for any other input (read whole by [`load_info`]).
fn info_out_of_core(a: &InfoArgs) -> Result<Option<volsplat::io::VolumeInfo>> {
    let source = volume_source(&a.input)?;
    let VolumeSource::File {
        path, raw: None, ..
    } = &source
    else {
        return Ok(None);
    };
    if a.input.raw_dims.is_some() || !volsplat::io::ZarrStore::is_store(path) {
        return Ok(None);
    }
    let limits = reader_limits(&a.input)?;
    let mut request = RenderRequest::new(
        volsplat::Scene {
            volume: source.clone(),
            ..volsplat::Scene::default()
        },
        1,
        1,
    );
    request.memory = a.memory;
    let mut renderer = Renderer::with_limits(limits.clone());
    let Some(volsplat::OutOfCoreSummary {
        grid,
        scalar_type: kind,
        value_range: range,
        note,
    }) = renderer
        .out_of_core_summary(&request)
        .map_err(|e| render_error(e, &source.label()))?
    else {
        return Ok(None);
    };
    let store = volsplat::io::ZarrStore::open(path, &limits)?;
    let notes = std::iter::once(
        "out of core: summarised from the store's metadata and its ranges, the level not read \
         whole"
            .to_string(),
    )
    .chain(note)
    .collect();
    Ok(Some(volsplat::io::VolumeInfo::from_grid(
        path,
        &store.format(),
        &grid,
        kind,
        range,
        (
            usize::try_from(store.timepoints()).unwrap_or(usize::MAX),
            a.input.timepoint,
        ),
        notes,
    )))
}

/// The volume of the input flags as read, with what the reader reported.
fn load_info(a: &InputArgs) -> Result<(String, volsplat::io::LoadedVolume)> {
    let limits = reader_limits(a)?;
    let source = volume_source(a)?;
    let label = source.label();
    if let (
        VolumeSource::File {
            path, raw: None, ..
        },
        false,
    ) = (&source, a.raw_dims.is_some())
    {
        let options = volsplat::io::ReadOptions::default()
            .with_limits(limits)
            .with_frame(a.frame)
            .with_array(a.array.clone())
            .with_series(a.series.clone())
            .with_level(level_number(a.zarr_level)?)
            .with_channel(a.channel)
            .with_timepoint(a.timepoint);
        let loaded = volsplat::io::read_volume_with(path, &options)?;
        return Ok((path.display().to_string(), loaded));
    }
    let (vol, notes) = source.load_with_limits(&limits)?;
    let format = match &source {
        VolumeSource::Phantom { .. } => "built-in",
        _ => "raw",
    };
    let loaded = volsplat::io::LoadedVolume {
        volume: std::sync::Arc::unwrap_or_clone(vol),
        format: format.into(),
        frames: 1,
        frame: 0,
        arrays: Vec::new(),
        series: Vec::new(),
        series_uid: None,
        notes,
    };
    Ok((label, loaded))
}

fn info_cmd(a: InfoArgs) -> Result<()> {
    let info = match info_out_of_core(&a)? {
        Some(info) => info,
        None => {
            let (label, loaded) = load_info(&a.input)?;
            volsplat::io::VolumeInfo::new(Path::new(&label), &loaded)
        }
    };
    if a.json {
        return emit(&info.to_json_pretty());
    }
    let d = info.direction;
    emit(&format!("source:    {}", info.path))?;
    emit(&format!("format:    {}", info.format))?;
    emit(&format!("type:      {}", info.scalar_type))?;
    emit(&format!(
        "dims:      {} x {} x {} ({} voxels)",
        info.dims[0], info.dims[1], info.dims[2], info.voxels
    ))?;
    emit(&format!(
        "spacing:   {} {} {}",
        info.spacing[0], info.spacing[1], info.spacing[2]
    ))?;
    emit(&format!(
        "origin:    {} {} {}",
        info.origin[0], info.origin[1], info.origin[2]
    ))?;
    for (n, c) in ["i", "j", "k"].iter().enumerate() {
        emit(&format!(
            "axis {c}:    ({:.6}, {:.6}, {:.6})",
            d[0][n], d[1][n], d[2][n]
        ))?;
    }
    let [blo, bhi] = info.bounds;
    emit(&format!(
        "bounds:    ({:.3}, {:.3}, {:.3}) .. ({:.3}, {:.3}, {:.3})",
        blo[0], blo[1], blo[2], bhi[0], bhi[1], bhi[2]
    ))?;
    emit(&format!(
        "range:     {} .. {}",
        info.value_range[0], info.value_range[1]
    ))?;
    if info.frames > 1 {
        // An OME-Zarr store's frames are its time points.
        let flag = if info.levels.is_empty() {
            "--frame N"
        } else {
            "--timepoint N"
        };
        emit(&format!(
            "frames:    {} (reading {}; {flag})",
            info.frames, info.frame
        ))?;
    }
    if !info.levels.is_empty() {
        emit(&format!(
            "levels:    {} (--zarr-level N):",
            info.levels.len()
        ))?;
        for (n, l) in info.levels.iter().enumerate() {
            emit(&format!(
                "  {n}: {} x {} x {}, spacing {} {} {}, chunks {:?}, {} (array `{}`)",
                l.dims[0],
                l.dims[1],
                l.dims[2],
                l.spacing[0],
                l.spacing[1],
                l.spacing[2],
                l.chunks,
                l.data_type,
                l.path
            ))?;
        }
    }
    if !info.arrays.is_empty() {
        emit(&format!(
            "arrays:    {} (--array NAME)",
            info.arrays.join(", ")
        ))?;
    }
    if !info.series.is_empty() {
        emit(&format!(
            "series:    {} in the folder (--series UID|NUMBER):",
            info.series.len()
        ))?;
        for s in &info.series {
            let here = if info.series_uid.as_deref() == Some(s.uid.as_str()) {
                "*"
            } else {
                " "
            };
            emit(&format!("  {here} {s}"))?;
        }
    }
    // The reader's notes after what they are about.
    for n in &info.notes {
        emit(&format!("note:      {n}"))?;
    }
    Ok(())
}

/// `convert`: any readable volume to the format the output's name gives
/// (`volsplat::io::write_volume`: NRRD, NIfTI, MetaImage or .npy), geometry kept.
fn convert_cmd(a: ConvertArgs) -> Result<()> {
    let zarr = a.output.to_str().is_some_and(|p| {
        p.to_ascii_lowercase()
            .trim_end_matches('/')
            .ends_with(".zarr")
    });
    if zarr {
        return convert_to_zarr(a);
    }
    if a.chunk != 64 || a.zarr_version != 2 {
        bail!("--chunk and --zarr-version apply to .zarr outputs only");
    }
    check_output_path(&a.output, "-o", &[])?;
    let options = volsplat::io::VolumeWriteOptions { compress: a.gzip };
    volsplat::io::volume_write_format(&a.output, &options)?;
    let (label, loaded) = load_info(&a.input)?;
    let written = volsplat::io::write_volume(&a.output, &loaded.volume, &options)
        .with_context(|| format!("writing {}", a.output.display()))?;
    if !a.quiet {
        for n in loaded.notes.iter().chain(&written.notes) {
            say!("note: {n}");
        }
        let g = loaded.volume.grid();
        say!(
            "wrote {} ({} {}×{}×{} {}, from {label})",
            a.output.display(),
            loaded.format,
            g.dims[0],
            g.dims[1],
            g.dims[2],
            loaded.volume.scalar_type().name()
        );
    }
    Ok(())
}

/// `convert … -o OUT.zarr`: an OME-Zarr pyramid of the volume (in memory: the volume is read
/// whole, then each level halved from the one before).
fn convert_to_zarr(a: ConvertArgs) -> Result<()> {
    let out = &a.output;
    if a.gzip {
        bail!(
            "-o {}: an OME-Zarr store is compressed with zstd; --gzip does not apply",
            out.display()
        );
    }
    let version = match a.zarr_version {
        2 => volsplat::io::ZarrVersion::V2,
        3 => volsplat::io::ZarrVersion::V3,
        v => bail!("--zarr-version {v}: expected 2 (OME-Zarr 0.4) or 3 (OME-Zarr 0.5)"),
    };
    volsplat::io::zarr::check_zarr_output(out)?;
    let options = volsplat::io::ZarrWriteOptions::default()
        .with_version(version)
        .with_chunk(a.chunk);
    let converted = match volume_source(&a.input)? {
        VolumeSource::File { path, raw, .. } => {
            let read = volsplat::io::ReadOptions::default()
                .with_limits(reader_limits(&a.input)?)
                .with_frame(a.input.frame)
                .with_array(a.input.array.clone())
                .with_series(a.input.series.clone())
                .with_level(level_number(a.input.zarr_level)?)
                .with_channel(a.input.channel)
                .with_timepoint(a.input.timepoint);
            let spec = match &raw {
                Some(r) => {
                    let mut spec = volsplat::io::RawSpec::new(
                        r.dims,
                        volsplat::core::ScalarType::from_name(&r.scalar_type)?,
                    );
                    spec.spacing = r.spacing;
                    spec.origin = r.origin;
                    spec.big_endian = r.big_endian;
                    spec.header_bytes = r.header_bytes;
                    Some(spec)
                }
                None => None,
            };
            let label = path.display().to_string();
            let c = volsplat::io::convert_to_zarr(&path, spec.as_ref(), &read, out, &options)
                .with_context(|| format!("writing {}", out.display()))?;
            (label, c)
        }
        _ => {
            let (label, loaded) = load_info(&a.input)?;
            let written = volsplat::io::write_zarr(out, &loaded.volume, &options)
                .with_context(|| format!("writing {}", out.display()))?;
            let mut notes = loaded.notes;
            notes.extend(written.notes.iter().cloned());
            let c = volsplat::io::ConvertedZarr {
                written,
                format: loaded.format,
                scalar_type: loaded.volume.scalar_type(),
                streamed: false,
                notes,
            };
            (label, c)
        }
    };
    let (label, c) = converted;
    // The full level's ranges, kept for the first out-of-core open (decision 0039); a failure
    // only costs that open a scan.
    let kept = volsplat::Renderer::with_limits(reader_limits(&a.input)?).keep_store_ranges(out);
    if !a.quiet {
        for n in &c.notes {
            say!("note: {n}");
        }
        match kept {
            Ok(notes) => notes
                .iter()
                .filter(|n| n.contains("ranges are kept") || n.contains("could not be kept"))
                .for_each(|n| say!("note: {n}")),
            Err(e) => say!("note: the level's ranges were not kept for out-of-core opens: {e}"),
        }
        let sizes: Vec<String> = c
            .written
            .levels
            .iter()
            .map(|g| format!("{}×{}×{}", g.dims[0], g.dims[1], g.dims[2]))
            .collect();
        say!(
            "wrote {} (OME-Zarr {}, {} levels: {}; {}, from {label}{})",
            out.display(),
            if a.zarr_version == 2 { "0.4" } else { "0.5" },
            c.written.levels.len(),
            sizes.join(", "),
            c.scalar_type.name(),
            if c.streamed {
                ", streamed slice by slice"
            } else {
                ""
            }
        );
    }
    Ok(())
}

/// `presets`: every built-in transfer function with its units and one line of description.
fn presets_cmd() -> Result<()> {
    use volsplat::core::Preset;
    use volsplat::core::presets::PRESET_ALIASES;
    let width = Preset::ALL
        .iter()
        .map(|p| p.name().len())
        .max()
        .unwrap_or(0);
    emit(
        "auto (default): from the volume's histogram: background transparent, opacity ramped over the foreground's percentiles",
    )?;
    for p in Preset::ALL {
        emit(&format!(
            "{:width$}  [{}] {}",
            p.name(),
            p.units(),
            p.description()
        ))?;
    }
    let aliases: Vec<String> = PRESET_ALIASES
        .iter()
        .map(|(a, p)| format!("{a} = {}", p.name()))
        .collect();
    emit(&format!("aliases: {}", aliases.join(", ")))?;
    emit(
        "Slicer presets are in absolute units (CT: Hounsfield) and are not rescaled to the data.",
    )?;
    Ok(())
}

fn phantom_cmd(a: PhantomArgs) -> Result<()> {
    if let Some(size) = &a.size {
        bail!(
            "phantom --size was renamed --grid (e.g. `--grid {size}`): --size means the image size \
             in render and bench"
        );
    }
    check_output_path(&a.output, "-o", &[])?;
    let grid = a
        .grid
        .as_deref()
        .map(|s| parse_grid(s, "--grid"))
        .transpose()?;
    let vol = volsplat::make_phantom(a.kind, grid.as_deref(), "--grid")?;
    volsplat::io::write_nrrd(&a.output, &vol, a.gzip)?;
    let g = vol.grid();
    say!(
        "wrote {} ({:?}, {} {:?})",
        a.output.display(),
        g.dims,
        vol.scalar_type().name(),
        g.spacing
    );
    Ok(())
}

/// The process's peak resident memory (`VmHWM` of `/proc/self/status`), in KiB; `None` where the
/// system does not report it.
fn peak_rss_kb() -> Option<u64> {
    std::fs::read_to_string("/proc/self/status")
        .ok()?
        .lines()
        .find(|l| l.starts_with("VmHWM:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

/// `bench`: the same request path as `render`, one [`Renderer`] for every frame, the camera
/// turned by `--orbit` degrees of azimuth between frames.
fn bench_cmd(a: BenchArgs) -> Result<()> {
    if !(1..=volsplat::movie::MAX_MOVIE_FRAMES).contains(&a.frames) {
        bail!(
            "--frames {}: bench times 1 to {} frames",
            a.frames,
            volsplat::movie::MAX_MOVIE_FRAMES
        );
    }
    let base = load_scene(a.scene.as_deref())?;
    let mut req = build_request(
        &a.input,
        &a.view,
        &a.options,
        None,
        RendererArg::Auto,
        None,
        None,
        &a.given.iter().cloned().collect(),
        base,
    )?;
    let mut renderer = Renderer::with_limits(reader_limits(&a.input)?);
    let label = req.scene.volume.label();
    let bar = crate::progress::Bar::items(a.frames as u64 + 1, "bench", false);
    // Warm-up: loads and classifies.
    let first = renderer.render(&req, &mut |_| true).map_err(explain)?;
    bar.inc();
    let mut camera = first.camera.clone();
    let step = a.orbit.unwrap_or(360.0 / a.frames as f64);
    let mut times = Vec::with_capacity(a.frames);
    let mut last = None;
    for _ in 0..a.frames {
        camera.azimuth(step);
        req.scene.camera = CameraSpec::Explicit {
            camera: camera.clone(),
            orbit: volsplat::core::Orbit::default(),
        };
        let out = renderer.render(&req, &mut |_| true).map_err(explain)?;
        bar.inc();
        times.push(out.stats.render_ms);
        last = Some(out);
    }
    bar.clear();
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    // The grid only: a store read out of core is never read whole here.
    let (grid, kind) = renderer.volume_grid(&req)?;
    let mut j = serde_json::to_value(last.map(|o| o.stats).unwrap_or_default())?;
    j["input"] = json!(label);
    j["first_frame_ms"] = json!(first.stats.total_ms);
    j["first_frame_load_ms"] = json!(first.stats.load_ms);
    j["first_frame_prepare_ms"] = json!(first.stats.prepare_ms);
    j["volume_bytes"] = json!(grid.voxel_count() * kind.size_bytes());
    j["frames_ms"] = json!(times);
    j["median_ms"] = json!(median);
    if let Some(kb) = peak_rss_kb() {
        j["peak_rss_kb"] = json!(kb);
    }
    j["min_ms"] = json!(sorted[0]);
    j["max_ms"] = json!(sorted[sorted.len() - 1]);
    emit(&format!("{j}"))?;
    Ok(())
}

fn texture_bench_cmd(a: TextureBenchArgs) -> Result<()> {
    use volsplat_studies::TextureBenchSettings;
    let settings = match a.size {
        TextureBenchSize::Quick => TextureBenchSettings::quick(),
        TextureBenchSize::Default => TextureBenchSettings::default(),
        TextureBenchSize::Thesis => TextureBenchSettings::thesis_size(),
    };
    let pool = thread_pool(a.threads)?;
    let bar = crate::progress::Bar::spinner("texture-bench", false);
    let written = pool.install(|| volsplat_studies::texture_bench::write_folder(&settings, &a.out));
    bar.clear();
    let written = written?;
    emit(&written.markdown)?;
    say!(
        "wrote {} and {} images to {}",
        written.report.display(),
        written.images,
        a.out.display()
    );
    Ok(())
}

/// `--zarr-level` as a number: `auto` needs a camera, which `info` and `convert` have not.
fn level_number(level: volsplat::StoreLevel) -> Result<usize> {
    level.index().ok_or_else(|| {
        anyhow::anyhow!(
            "--zarr-level auto is chosen from the camera when rendering; info and convert take a \
             level number (`volsplat info STORE` lists them)"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn render_args(extra: &[&str]) -> RenderArgs {
        let mut argv = vec!["volsplat", "render"];
        argv.extend_from_slice(extra);
        match Cli::try_parse_from(argv).unwrap().command {
            Command::Render(a) => *a,
            other => panic!("{other:?}"),
        }
    }

    /// Issue 29 follow-up: the checks made before the scene file is read no longer test a
    /// window against the `--mode` flag's default (composite); a bad window is still refused.
    #[test]
    fn a_window_is_not_checked_against_the_mode_flags_default() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.png");
        let out = out.to_str().unwrap();
        check_render_args(&render_args(&[
            "--scene", "mip.json", "--wl", "1,2", "-o", out,
        ]))
        .unwrap();
        let e = check_render_args(&render_args(&["--wl", "1,-2", "-o", out])).unwrap_err();
        assert!(e.to_string().contains("width must be > 0"), "{e}");
        let e = check_render_args(&render_args(&["--window", "3:1", "-o", out])).unwrap_err();
        assert!(e.to_string().contains("LO < HI"), "{e}");
    }

    struct Out {
        image: Image,
        values: Option<ScalarImage>,
    }

    fn rendered(w: usize, h: usize) -> Out {
        let mut image = Image::new(w, h);
        for p in image.pixels_mut() {
            *p = [0.25, 0.5, 0.75, 1.0];
        }
        Out {
            image,
            values: None,
        }
    }

    #[test]
    fn image_size_is_wxh_or_a_single_number() {
        assert_eq!(parse_image_size("640x480", "--size").unwrap(), (640, 480));
        assert_eq!(parse_image_size("64X48", "--size").unwrap(), (64, 48));
        assert_eq!(parse_image_size("512", "--size").unwrap(), (512, 512));
        assert_eq!(parse_image_size(" 7 ", "--size").unwrap(), (7, 7));
        for bad in [
            "", "x", "12by4", "12x", "x12", "1.5", "-3", "3x4x5", "0", "16385", "4x0",
        ] {
            let e = parse_image_size(bad, "--size").unwrap_err().to_string();
            assert!(
                e.contains("--size") && e.contains(&format!("`{bad}`")),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn output_paths_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let ok = dir.path().join("a.PNG");
        check_output_path(&ok, "-o", OUTPUT_EXTENSIONS).unwrap();
        check_output_path(Path::new("relative.npy"), "-o", OUTPUT_EXTENSIONS).unwrap();
        let e = check_output_path(&dir.path().join("a.tif"), "-o", OUTPUT_EXTENSIONS)
            .unwrap_err()
            .to_string();
        assert!(e.contains("a.tif") && e.contains(".png or .npy"), "{e}");
        let e = check_output_path(Path::new("noext"), "-o", OUTPUT_EXTENSIONS)
            .unwrap_err()
            .to_string();
        assert!(e.contains("noext") && e.contains(".png or .npy"), "{e}");
        let missing = dir.path().join("no-such-folder");
        let e = check_output_path(&missing.join("a.png"), "-o", OUTPUT_EXTENSIONS)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("folder {} does not exist", missing.display())),
            "{e}"
        );
        let e = check_output_path(dir.path(), "-o", OUTPUT_EXTENSIONS)
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a folder"), "{e}");
        // A file where the folder should be.
        let file = dir.path().join("plain");
        std::fs::write(&file, b"x").unwrap();
        let e = check_output_path(&file.join("cam.json"), "--save-camera", &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--save-camera") && e.contains("is not a folder"),
            "{e}"
        );
        check_output_path(&dir.path().join("cam.json"), "--save-camera", &[]).unwrap();
    }

    #[test]
    fn non_finite_pixels_are_counted_in_what_would_be_written() {
        let mut out = rendered(4, 3);
        assert_eq!(non_finite_pixels(&out.image, out.values.as_ref(), false), 0);
        out.image.pixels_mut()[1][2] = f32::NAN;
        out.image.pixels_mut()[5] = [f32::INFINITY, f32::NAN, 0.0, f32::NEG_INFINITY];
        assert_eq!(non_finite_pixels(&out.image, out.values.as_ref(), false), 2);
        // X-ray output writes the line integrals, not the RGBA image.
        let mut v = vec![1.0f32; 12];
        v[7] = f32::NAN;
        out.values = Some(ScalarImage::from_values(4, 3, v).unwrap());
        assert_eq!(non_finite_pixels(&out.image, out.values.as_ref(), true), 1);
        assert_eq!(non_finite_pixels(&out.image, out.values.as_ref(), false), 2);
    }

    #[test]
    fn non_finite_images_are_not_written() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a.png", "a.npy"] {
            let path = dir.path().join(name);
            let req = RenderRequest::new(volsplat::Scene::default(), 5, 4);
            let mut out = rendered(5, 4);
            out.image.pixels_mut()[3][0] = f32::NAN;
            out.image.pixels_mut()[9][3] = f32::INFINITY;
            let e = write_checked(
                &path,
                &out.image,
                out.values.as_ref(),
                &req,
                "splatting renderer",
                &[],
            )
            .unwrap_err();
            assert_eq!(
                e.to_string(),
                "internal error: the splatting renderer produced 2 non-finite pixels; nothing \
                 was written"
            );
            assert!(e.downcast_ref::<NonFiniteOutput>().is_some());
            assert!(!path.exists(), "{name} was written");
            assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
            // The same image made finite is written.
            out.image.pixels_mut()[3][0] = 0.0;
            out.image.pixels_mut()[9][3] = 1.0;
            write_checked(
                &path,
                &out.image,
                out.values.as_ref(),
                &req,
                "splatting renderer",
                &[],
            )
            .unwrap();
            assert!(path.exists());
            std::fs::remove_file(&path).unwrap();
        }
        // X-ray: the line integrals are checked, and a ladder's earlier previews are named.
        let path = dir.path().join("x.npy");
        let mut out = rendered(2, 2);
        out.values = Some(ScalarImage::from_values(2, 2, vec![0.0, f32::NAN, 1.0, 2.0]).unwrap());
        let preview = dir.path().join("x.preview-s4.npy");
        let mut req = RenderRequest::new(volsplat::Scene::default(), 2, 2);
        req.mode = Mode::Xray;
        let e = write_checked(
            &path,
            &out.image,
            out.values.as_ref(),
            &req,
            "splatting renderer",
            std::slice::from_ref(&preview),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("1 non-finite pixel;")
                && e.contains(&format!("{} was not written", path.display()))
                && e.contains(&preview.display().to_string()),
            "{e}"
        );
        assert!(!path.exists());
    }

    #[test]
    fn display_bench_needs_an_input_inside_or_outside_the_repository() {
        // No default volume: the old default pointed outside the repository (issue 11).
        let err = Cli::try_parse_from(["volsplat", "display-bench"]).unwrap_err();
        assert_eq!(err.kind(), clap::error::ErrorKind::MissingRequiredArgument);
        let cli = Cli::try_parse_from(["volsplat", "display-bench", "--input", "v.nrrd"]).unwrap();
        match cli.command {
            Command::DisplayBench(a) => {
                assert_eq!(a.input, PathBuf::from("v.nrrd"));
                assert_eq!(a.out, PathBuf::from("docs/nil-display"));
            }
            other => panic!("{other:?}"),
        }
    }
}
