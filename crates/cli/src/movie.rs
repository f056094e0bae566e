//! `volsplat movie`: a turntable or a keyframed camera flight, many requests through one
//! [`Renderer`] (library: `volsplat::movie` for the camera paths, `volsplat::io::movie` for the
//! files). Flags only.

use crate::args::{ImageOptions, InputArgs, RenderOptions, RendererArg, ViewArgs};
use crate::commands::{check_image_options, emit, explain, load_scene};
use crate::request::{build_request_noted, parse_image_size};
use crate::say::say;
use crate::signals::Stop;
use anyhow::{Context, Result, bail};
use clap::Args;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;
use volsplat::core::glam::DVec3;
use volsplat::io::{MovieSettings, MovieWriter};
use volsplat::movie::{
    Flight, FlightFrame, KeyframeFile, MAX_MOVIE_FRAMES, TurnAxis, scene_up, turntable,
};
use volsplat::{CameraSpec, Renderer, TransferSpec};

#[derive(Debug, Args)]
pub(crate) struct MovieArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Output: a folder (frame_0000.png …) or a file name with a zero-padded %04d (PNG frames),
    /// .gif, .png or .apng (animated PNG), or .mp4/.webm/.mkv/.mov/.avi (frames piped to
    /// ffmpeg, which must be on PATH). The movie replaces the last one whole at the end: a
    /// folder ends up holding exactly this movie's frames (earlier frames that the pattern
    /// names are removed), and an interrupted or failed movie leaves the last one as it was.
    #[arg(short, long, value_name = "OUT", help_heading = "Output")]
    pub output: PathBuf,
    #[command(flatten)]
    pub view: ViewArgs,
    #[command(flatten)]
    pub options: RenderOptions,
    #[command(flatten)]
    pub image: ImageOptions,
    /// Turntable: number of frames (at most 100000).
    #[arg(long, default_value_t = 72, help_heading = "Movie")]
    pub frames: usize,
    /// Turntable: degrees turned over the movie. A whole number of turns closes the loop
    /// without repeating frame 0; other angles sweep from 0 to this angle inclusive.
    #[arg(
        long,
        default_value_t = 360.0,
        allow_negative_numbers = true,
        help_heading = "Movie"
    )]
    pub degrees: f64,
    /// Turntable axis through the focal point: `up` (the scene's up: the view-up before
    /// --elevation and --roll, so every frame keeps the elevation), `view-up` (the tilted
    /// camera's own view-up, VTK's Azimuth), world `x`, `y`, `z` (or `-x` …), or patient `L`,
    /// `R`, `P`, `A`, `S`, `I` (volsplat's world frame is LPS: L = +x, P = +y, S = +z).
    #[arg(
        long,
        default_value = "up",
        allow_hyphen_values = true,
        help_heading = "Movie"
    )]
    pub axis: String,
    /// A camera flight instead of a turntable: a JSON file of timed keyframes (camera, orbit,
    /// transfer function and clipping; format in README.md, section "Files"). The whole flight
    /// is checked before the first frame (at most 100000 frames).
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with_all = ["frames", "degrees", "axis"],
        help_heading = "Movie"
    )]
    pub keyframes: Option<PathBuf>,
    /// Frames per second of the output (and of the keyframe timeline, unless the file sets it),
    /// in (0, 1000]. GIF stores delays in hundredths of a second (at most 100 fps; a warning
    /// says when the rate cannot be kept).
    #[arg(long, default_value_t = 24.0, help_heading = "Movie")]
    pub fps: f64,
    /// Start from the request of a scene file (as written by `render --save-scene`); flags given
    /// override its fields.
    #[arg(long, value_name = "FILE", help_heading = "Input")]
    pub scene: Option<PathBuf>,
    /// Print frame timings and counters as one JSON object on stdout.
    #[arg(long, help_heading = "Output")]
    pub stats: bool,
    /// Don't print progress, notes or what was written (warnings and errors are still printed).
    #[arg(short, long, help_heading = "Output")]
    pub quiet: bool,
    /// Every flag given on the command line (filled in by `main`).
    #[arg(skip)]
    pub given: Vec<String>,
}

/// The turntable axis of `--axis`: `None` for the scene's up ([`volsplat::movie::scene_up`]).
fn turn_axis(s: &str) -> Result<Option<TurnAxis>> {
    let (sign, name) = match s.strip_prefix('-') {
        Some(rest) => (-1.0, rest),
        None => (1.0, s.strip_prefix('+').unwrap_or(s)),
    };
    let axis = match name {
        "up" if sign > 0.0 => return Ok(None),
        "view-up" if sign > 0.0 => return Ok(Some(TurnAxis::ViewUp)),
        "x" | "L" => DVec3::X,
        "y" | "P" => DVec3::Y,
        "z" | "S" => DVec3::Z,
        "R" => -DVec3::X,
        "A" => -DVec3::Y,
        "I" => -DVec3::Z,
        _ => bail!(
            "--axis {s}: expected up, view-up, x, y, z, -x, -y, -z, or a patient direction L, R, \
             P, A, S, I"
        ),
    };
    Ok(Some(TurnAxis::World(axis * sign)))
}

/// The frames of a movie, made one at a time.
enum Frames {
    /// A turntable's cameras (a few dozen bytes each).
    Turntable(Vec<volsplat::core::Camera>),
    /// A keyframed flight, interpolated per frame.
    Flight(Flight),
}

impl Frames {
    fn len(&self) -> usize {
        match self {
            Frames::Turntable(c) => c.len(),
            Frames::Flight(f) => f.len(),
        }
    }

    fn frame(&self, n: usize) -> FlightFrame {
        match self {
            Frames::Turntable(c) => FlightFrame {
                time: 0.0,
                camera: c[n].clone(),
                transfer_function: None,
                clipping: None,
            },
            Frames::Flight(f) => f.frame(n),
        }
    }
}

/// Every frame's camera, transfer function and clipping, checked whole before the first frame
/// is rendered: a keyframed flight, or a turntable about `axis` (`None`: the scene's up).
fn plan_frames(
    a: &MovieArgs,
    req: &volsplat::RenderRequest,
    renderer: &mut Renderer,
    keyframes: Option<&KeyframeFile>,
    axis: Option<TurnAxis>,
    grid: Option<&volsplat::core::Grid>,
) -> Result<Frames> {
    let camera = match grid {
        Some(g) => req
            .scene
            .camera
            .resolve(g.drawn_bounds_world())
            .map_err(explain)?,
        None => renderer.camera(req).map_err(explain)?,
    };
    Ok(match keyframes {
        Some(k) => {
            let tf = renderer.transfer_function(req).map_err(explain)?;
            Frames::Flight(
                Flight::new(k, &camera, &tf, &req.scene.clipping, a.fps).map_err(explain)?,
            )
        }
        None => {
            let axis = match axis {
                Some(axis) => axis,
                None => {
                    let bounds = match grid {
                        Some(g) => g.bounds_world(),
                        None => renderer.volume(&req.scene.volume)?.grid().bounds_world(),
                    };
                    TurnAxis::World(scene_up(&req.scene.camera, bounds).map_err(explain)?)
                }
            };
            Frames::Turntable(turntable(&camera, axis, a.degrees, a.frames).map_err(explain)?)
        }
    })
}

/// Says what a movie wrote (and removed), unless quiet.
fn say_written(
    files: &volsplat::io::movie::MovieFiles,
    frames: usize,
    w: usize,
    h: usize,
    t0: Instant,
) {
    let written = &files.written;
    let what = match written.as_slice() {
        [one] => one.display().to_string(),
        many => format!(
            "{} frames {} … {}",
            many.len(),
            many.first()
                .map(|p| p.display().to_string())
                .unwrap_or_default(),
            many.last()
                .map(|p| p.display().to_string())
                .unwrap_or_default()
        ),
    };
    say!(
        "wrote {what} ({frames} frames, {w}×{h}, {:.1} s)",
        t0.elapsed().as_secs_f64()
    );
    if let Some(first) = files.removed.first() {
        let n = files.removed.len();
        say!(
            "removed {n} frame{} of an earlier, longer movie ({} …)",
            if n == 1 { "" } else { "s" },
            first.display()
        );
    }
}

/// The checks of `movie` that need no volume.
fn check_movie_args(a: &MovieArgs) -> Result<(usize, usize)> {
    let size = parse_image_size(&a.options.size, "--size")?;
    check_image_options(&a.image)?;
    if a.keyframes.is_none() && !(1..=MAX_MOVIE_FRAMES).contains(&a.frames) {
        bail!(
            "--frames {}: a movie has 1 to {MAX_MOVIE_FRAMES} frames",
            a.frames
        );
    }
    if !(a.fps.is_finite() && a.fps > 0.0 && a.fps <= 1000.0) {
        bail!(
            "--fps {}: give a rate in (0, 1000] frames per second",
            a.fps
        );
    }
    Ok(size)
}

/// What a movie draws: the request (its camera, transfer function and clipping set per frame
/// by [`Setup::frame_request`]), the frames, and how they are written.
pub(crate) struct Setup {
    req: volsplat::RenderRequest,
    frames: Frames,
    pub(crate) settings: MovieSettings,
    /// MIP/MinIP's window over the values (`--window`), applied before writing.
    pub(crate) window: Option<(f32, f32)>,
    pub(crate) size: (usize, usize),
    pub(crate) notes: Vec<String>,
}

impl Setup {
    /// How many frames.
    pub(crate) fn len(&self) -> usize {
        self.frames.len()
    }

    /// The request of frame `n` (an explicit camera; the flight's transfer function and
    /// clipping where it has them).
    pub(crate) fn frame_request(&self, n: usize) -> volsplat::RenderRequest {
        let mut req = self.req.clone();
        let frame = self.frames.frame(n);
        if let Some(c) = frame.clipping {
            req.scene.clipping = c;
        }
        req.scene.camera = CameraSpec::Explicit {
            camera: frame.camera,
            orbit: volsplat::core::Orbit::default(),
        };
        if let Some(tf) = frame.transfer_function {
            req.scene.transfer_function = TransferSpec::Function(tf);
        }
        req
    }
}

/// The request, frames and writing settings of `movie`'s arguments `a`, checked whole before
/// the first frame. `sort_last`: the frames are drawn by sort-last ranks (`volsplat-mpi
/// movie`), so the grid comes from the store's metadata or the file's header where a rank reads
/// its part in bricks ([`Renderer::part_grid`]), not from the volume read whole.
pub(crate) fn movie_setup(
    a: &MovieArgs,
    renderer: &mut Renderer,
    sort_last: bool,
) -> Result<Setup> {
    let size = check_movie_args(a)?;
    let axis = turn_axis(&a.axis)?;
    let keyframes = a
        .keyframes
        .as_ref()
        .map(|p| KeyframeFile::load(p).map_err(explain))
        .transpose()?;
    let base = load_scene(a.scene.as_deref())?;
    let (req, notes) = build_request_noted(
        &a.input,
        &a.view,
        &a.options,
        Some(&a.image),
        RendererArg::Auto,
        None,
        None,
        &a.given.iter().cloned().collect(),
        base,
    )?;
    req.validate().map_err(explain)?;
    let grid = if sort_last {
        renderer.part_grid(&req).map_err(explain)?
    } else {
        None
    };
    let frames = plan_frames(a, &req, renderer, keyframes.as_ref(), axis, grid.as_ref())?;
    let fps = keyframes.as_ref().and_then(|k| k.fps).unwrap_or(a.fps);
    // The request's output options: the flags, or a `--scene` file's where none is given.
    let output = req.output.write_options().map_err(explain)?;
    let settings = MovieSettings {
        fps,
        png: output.png,
        ..MovieSettings::default()
    };
    Ok(Setup {
        req,
        frames,
        settings,
        window: output.window,
        size,
        notes,
    })
}

pub(crate) fn movie_cmd(a: MovieArgs) -> Result<()> {
    let t0 = Instant::now();
    let mut renderer = Renderer::with_limits(crate::request::reader_limits(&a.input)?);
    let setup = movie_setup(&a, &mut renderer, false)?;
    if !a.quiet {
        for n in &setup.notes {
            say!("note: {n}");
        }
    }
    let (w, h) = setup.size;
    let label = setup.req.scene.volume.label();
    let (settings, window) = (setup.settings.clone(), setup.window);
    let frames = &setup;
    let stop = Stop::install()?;
    // The writer's errors name the output.
    let mut writer = MovieWriter::create(&a.output, w, h, frames.len(), &settings)?;
    for warning in writer.warnings() {
        say!("warning: {warning}");
    }
    let count = frames.len();
    let bar = crate::progress::Bar::items(count as u64, "movie", a.quiet);
    let stopped = |n: usize| {
        format!(
            "stopped at frame {n} of {count} and removed what it had written; {} is as it was \
             before",
            a.output.display()
        )
    };
    let mut times = Vec::with_capacity(count);
    let mut last_stats = None;
    let mut first_ms = 0.0;
    for n in 0..count {
        stop.check(&stopped(n))?;
        let req = frames.frame_request(n);
        let out = match renderer.render(&req, &mut |_| stop.signal().is_none()) {
            Ok(out) => out,
            Err(e) => {
                // A signal first: ffmpeg may have died of the same Ctrl-C.
                stop.check(&stopped(n))?;
                return Err(explain(e)).with_context(|| format!("rendering frame {n} of {label}"));
            }
        };
        if n == 0 {
            first_ms = out.stats.total_ms;
            if !a.quiet {
                for note in &out.notes {
                    bar.println(&format!("note: {note}"));
                }
            }
            for warning in &out.warnings {
                bar.println(&format!(
                    "warning: {}",
                    crate::commands::cli_warning(warning)
                ));
            }
        }
        times.push(out.stats.render_ms);
        let image = match (&out.values, window) {
            (Some(values), Some((lo, hi))) => volsplat::windowed_image(values, lo, hi),
            _ => out.image.clone(),
        };
        if let Err(e) = writer.push(&image) {
            stop.check(&stopped(n))?;
            return Err(e).with_context(|| format!("frame {n}"));
        }
        last_stats = Some(out.stats);
        bar.inc();
    }
    stop.check(&stopped(count))?;
    let files = writer.finish()?;
    bar.clear();
    if !a.quiet {
        say_written(&files, times.len(), w, h, t0);
    }
    // A signal during the last writes: what was written is whole and kept.
    stop.check(&format!(
        "stopped after {} was written whole (kept)",
        a.output.display()
    ))?;
    if a.stats {
        let mut sorted = times.clone();
        sorted.sort_by(f64::total_cmp);
        let mut j = serde_json::to_value(last_stats.unwrap_or_default())?;
        j["input"] = json!(label);
        j["frames"] = json!(times.len());
        j["first_frame_ms"] = json!(first_ms);
        j["frames_ms"] = json!(times);
        j["median_frame_ms"] = json!(sorted[sorted.len() / 2]);
        j["total_s"] = json!(t0.elapsed().as_secs_f64());
        emit(&format!("{j}"))?;
    }
    Ok(())
}
