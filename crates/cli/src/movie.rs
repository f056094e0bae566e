//! `volsplat movie`: a turntable or a keyframed camera flight, many requests through one
//! [`Renderer`] (library: `volsplat::movie` for the camera paths, `volsplat::io::movie` for the
//! files). Flags only.

use crate::args::{ImageOptions, InputArgs, RenderOptions, RendererArg, ViewArgs};
use crate::commands::{check_image_options, emit, explain, load_scene};
use crate::request::{build_request, parse_image_size};
use anyhow::{Context, Result, bail};
use clap::Args;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;
use volsplat::core::glam::DVec3;
use volsplat::io::{MovieSettings, MovieWriter, PngBitDepth, PngSettings};
use volsplat::movie::{KeyframeFile, TurnAxis, flight, turntable};
use volsplat::{CameraSpec, Renderer, TransferSpec};

#[derive(Debug, Args)]
pub struct MovieArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Output: a folder or a pattern with %04d (PNG frames), .gif, .png or .apng (animated
    /// PNG), or .mp4/.webm/.mkv/.mov/.avi (frames piped to ffmpeg, which must be on PATH).
    #[arg(short, long, value_name = "OUT", help_heading = "Output")]
    pub output: PathBuf,
    #[command(flatten)]
    pub view: ViewArgs,
    #[command(flatten)]
    pub options: RenderOptions,
    #[command(flatten)]
    pub image: ImageOptions,
    /// Turntable: number of frames.
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
    /// Turntable axis through the focal point: `up` (the camera's view-up: VTK's azimuth),
    /// world `x`, `y`, `z` (or `-x` …), or patient `L`, `R`, `P`, `A`, `S`, `I` (volsplat's
    /// world frame is LPS: L = +x, P = +y, S = +z).
    #[arg(
        long,
        default_value = "up",
        allow_hyphen_values = true,
        help_heading = "Movie"
    )]
    pub axis: String,
    /// A camera flight instead of a turntable: a JSON file of timed keyframes (camera, orbit
    /// and transfer function; format in README.md, "Movies").
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with_all = ["frames", "degrees", "axis"],
        help_heading = "Movie"
    )]
    pub keyframes: Option<PathBuf>,
    /// Frames per second of the output (and of the keyframe timeline, unless the file sets it).
    #[arg(long, default_value_t = 24.0, help_heading = "Movie")]
    pub fps: f64,
    /// Start from the request of a scene file (as written by `render --save-scene`); flags given
    /// override its fields.
    #[arg(long, value_name = "FILE", help_heading = "Input")]
    pub scene: Option<PathBuf>,
    /// Print frame timings and counters as one JSON object on stdout.
    #[arg(long, help_heading = "Output")]
    pub stats: bool,
    /// Don't print progress or what was written (warnings and errors are still printed).
    #[arg(short, long, help_heading = "Output")]
    pub quiet: bool,
    /// Every flag given on the command line (filled in by `main`).
    #[arg(skip)]
    pub given: Vec<String>,
}

/// The turntable axis of `--axis`.
fn turn_axis(s: &str) -> Result<TurnAxis> {
    let (sign, name) = match s.strip_prefix('-') {
        Some(rest) => (-1.0, rest),
        None => (1.0, s.strip_prefix('+').unwrap_or(s)),
    };
    let axis = match name {
        "up" | "view-up" if sign > 0.0 => return Ok(TurnAxis::ViewUp),
        "x" | "L" => DVec3::X,
        "y" | "P" => DVec3::Y,
        "z" | "S" => DVec3::Z,
        "R" => -DVec3::X,
        "A" => -DVec3::Y,
        "I" => -DVec3::Z,
        _ => bail!(
            "--axis {s}: expected up, x, y, z, -x, -y, -z, or a patient direction L, R, P, A, S, I"
        ),
    };
    Ok(TurnAxis::World(axis * sign))
}

pub fn movie_cmd(a: MovieArgs) -> Result<()> {
    let t0 = Instant::now();
    let (w, h) = parse_image_size(&a.options.size, "--size")?;
    check_image_options(&a.image, a.options.mode)?;
    let axis = turn_axis(&a.axis)?;
    let keyframes = a
        .keyframes
        .as_ref()
        .map(|p| KeyframeFile::load(p).map_err(explain))
        .transpose()?;
    if keyframes.is_none() && a.frames == 0 {
        bail!("--frames must be ≥ 1");
    }
    let base = load_scene(a.scene.as_deref())?;
    let mut req = build_request(
        &a.input,
        &a.view,
        &a.options,
        RendererArg::Splat,
        None,
        None,
        &a.given.iter().cloned().collect(),
        base,
    )?;
    let mut renderer = Renderer::with_limits(crate::request::reader_limits(&a.input)?);
    let label = req.scene.volume.label();
    let camera = renderer.camera(&req).map_err(explain)?;
    let tf = renderer.transfer_function(&req).map_err(explain)?;
    // Every frame: its camera, and its transfer function and clipping if the keyframes change
    // them.
    let frames: Vec<volsplat::movie::FlightFrame> = match &keyframes {
        Some(k) => flight(k, &camera, &tf, &req.scene.clipping, a.fps).map_err(explain)?,
        None => turntable(&camera, axis, a.degrees, a.frames)
            .map_err(explain)?
            .into_iter()
            .map(|camera| volsplat::movie::FlightFrame {
                time: 0.0,
                camera,
                transfer_function: None,
                clipping: None,
            })
            .collect(),
    };
    let fps = keyframes.as_ref().and_then(|k| k.fps).unwrap_or(a.fps);
    let settings = MovieSettings {
        fps,
        png: PngSettings {
            bits: PngBitDepth::from_bits(a.image.bits as u32).unwrap_or(PngBitDepth::Eight),
            srgb: a.image.srgb,
            background: crate::request::triple::<f32>(&a.image.background, "--background")?,
        },
        ..MovieSettings::default()
    };
    let mut writer = MovieWriter::create(&a.output, w, h, frames.len(), &settings)
        .with_context(|| format!("writing {}", a.output.display()))?;
    let bar = crate::progress::Bar::items(frames.len() as u64, "movie", a.quiet);
    let mut times = Vec::with_capacity(frames.len());
    let mut last_stats = None;
    let mut first_ms = 0.0;
    for (n, frame) in frames.into_iter().enumerate() {
        let (cam, frame_tf) = (frame.camera, frame.transfer_function);
        if let Some(c) = frame.clipping {
            req.scene.clipping = c;
        }
        req.scene.camera = CameraSpec::Explicit {
            camera: cam,
            orbit: volsplat::core::Orbit::default(),
        };
        if let Some(tf) = frame_tf {
            req.scene.transfer_function = TransferSpec::Function(tf);
        }
        let out = renderer
            .render(&req, &mut |_| true)
            .map_err(explain)
            .with_context(|| format!("rendering frame {n} of {label}"))?;
        if n == 0 {
            first_ms = out.stats.total_ms;
            for note in &out.notes {
                if !a.quiet {
                    bar.println(&format!("note: {note}"));
                }
            }
        }
        for warning in &out.warnings {
            if n == 0 {
                bar.println(&format!("warning: {warning}"));
            }
        }
        times.push(out.stats.render_ms);
        let image = match (&out.values, crate::commands::grey_window(&a.image)?) {
            (Some(values), Some((lo, hi))) => volsplat::windowed_image(values, lo, hi),
            _ => out.image.clone(),
        };
        writer
            .push(&image)
            .with_context(|| format!("writing frame {n} to {}", a.output.display()))?;
        last_stats = Some(out.stats);
        bar.inc();
    }
    let written = writer
        .finish()
        .with_context(|| format!("writing {}", a.output.display()))?;
    bar.clear();
    if !a.quiet {
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
        eprintln!(
            "wrote {what} ({} frames, {w}×{h}, {:.1} s)",
            times.len(),
            t0.elapsed().as_secs_f64()
        );
    }
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
