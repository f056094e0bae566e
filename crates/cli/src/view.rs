//! `volsplat view`: the interactive viewer in a browser, and `volsplat bench-view`: its latency
//! replay. Only flags and the terminal here; the server is `volsplat-view`, the progressive
//! session `volsplat::session`.

use crate::args::{ImageOptions, InputArgs, RenderOptions, RendererArg, ViewArgs};
use crate::commands::{check_image_options, emit, explain, load_scene};
use crate::request::{build_request, reader_limits};
use crate::say::say;
use crate::signals::Stop;
use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use serde_json::json;
use std::path::PathBuf;
use std::time::Duration;
use volsplat::{RenderRequest, Renderer};
use volsplat_view::protocol::ServerMessage;
use volsplat_view::replay::{Client, Incoming, Recording, replay};
use volsplat_view::{Viewer, ViewerSettings};

/// Flags of `volsplat view`.
#[derive(Debug, Args)]
pub(crate) struct ViewCmdArgs {
    #[command(flatten)]
    pub input: InputArgs,
    #[command(flatten)]
    pub view: ViewArgs,
    #[command(flatten)]
    pub options: RenderOptions,
    #[command(flatten)]
    pub image: ImageOptions,
    #[command(flatten)]
    pub server: ServerArgs,
    /// Start from the request of a scene file (as the page's "save scene" or `render
    /// --save-scene` write it); flags given on the command line override its fields.
    #[arg(long, value_name = "FILE", help_heading = "Input")]
    pub scene: Option<PathBuf>,
    /// Don't open a browser; only print the URL.
    #[arg(long, help_heading = "Server")]
    pub no_browser: bool,
    /// Every flag given on the command line (filled in by `main`).
    #[arg(skip)]
    pub given: Vec<String>,
}

/// How the server listens and paces frames (`view` and `bench-view`).
#[derive(Debug, Args)]
#[command(next_help_heading = "Server")]
pub(crate) struct ServerArgs {
    /// Address to listen on. Anything but loopback (127.0.0.1, ::1) needs --allow-remote;
    /// prefer an SSH tunnel (`ssh -L 8080:127.0.0.1:PORT host`).
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// Port (default: a free one).
    #[arg(long, default_value_t = 0)]
    pub port: u16,
    /// Allow --host to be an address other machines can reach; every request still needs the
    /// token in the printed URL.
    #[arg(long)]
    pub allow_remote: bool,
    /// A folder whose volume files the page may list and open (read-only, by name; nothing
    /// outside it). Without INPUT the first of them that reads is shown.
    #[arg(long, value_name = "DIR")]
    pub data_dir: Option<PathBuf>,
    /// Frames per second to keep while dragging: previews are sized so that one takes
    /// 1/FPS s on this machine (measured, not guessed).
    #[arg(long, value_name = "FPS", default_value_t = 60.0)]
    pub target_fps: f64,
    /// Input-to-frame latency to keep while dragging, ms: previews also aim at a fifth of it
    /// less than half (frames of T ms give a 95th-percentile latency of about 2T).
    #[arg(long, value_name = "MS", default_value_t = 50.0)]
    pub target_latency: f64,
    /// JPEG quality of previews, 1..=100 (the final frame is always the lossless PNG).
    #[arg(long, value_name = "Q", default_value_t = volsplat_view::frames::DEFAULT_PREVIEW_QUALITY)]
    pub preview_quality: u8,
    /// Which volume previews draw: `full` the volume itself, one ray per pixel, with thicker
    /// slabs for the smallest previews; `auto` the level of the prefiltered pyramid whose
    /// voxel is about a preview pixel (fewer samples along each ray as well as fewer rays,
    /// but blurrier; decision 0031, docs/BENCHMARKS.md §22).
    #[arg(long, value_enum, value_name = "LEVEL", default_value = "full")]
    pub preview_level: PreviewLevelArg,
}

/// `--preview-level`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum PreviewLevelArg {
    /// The volume itself.
    Full,
    /// The pyramid level that fits the preview's pixels.
    Auto,
}

/// The request of `view`/`bench-view`: `render`'s flags (the output flags too: they decide
/// the picture the final frame and the screenshot hold) and `--scene`, and with only a
/// `--data-dir` its first volume.
fn view_request(
    input: &InputArgs,
    view: &ViewArgs,
    options: &RenderOptions,
    image: &ImageOptions,
    scene: Option<&std::path::Path>,
    given: &[String],
    data_dir: Option<&std::path::Path>,
) -> Result<RenderRequest> {
    let base = load_scene(scene)?;
    let mut req = build_request(
        input,
        view,
        options,
        Some(image),
        RendererArg::Auto,
        None,
        None,
        &given.iter().cloned().collect(),
        base,
    )?;
    if let Some(dir) = data_dir {
        volsplat_view::check_data_dir(dir).map_err(|e| anyhow::anyhow!("--data-dir {e}"))?;
    }
    let no_volume_given = input.input.is_none() && input.phantom.is_none() && scene.is_none();
    if let (Some(dir), true) = (data_dir, no_volume_given) {
        let names = volsplat_view::list_volumes(dir);
        let Some(first) = names.first() else {
            bail!(
                "--data-dir {}: no volume files there (extensions: {})",
                dir.display(),
                volsplat::io::VOLUME_EXTENSIONS.join(", ")
            );
        };
        req.scene.volume = volsplat::VolumeSource::File {
            path: dir.join(first),
            raw: None,
            frame: 0,
            array: None,
            series: None,
            level: volsplat::StoreLevel::Index(0),
            channel: 0,
            timepoint: 0,
        };
    }
    Ok(req)
}

/// Whether the image follows the page's view: unless `--size` or `--scene` (whose request has
/// its size) gives a size, as ParaView's and napari's views fill their window.
fn fit_view(scene: Option<&std::path::Path>, given: &[String]) -> bool {
    scene.is_none() && !given.iter().any(|g| g == "size")
}

fn viewer_settings(s: &ServerArgs, fit_view: bool) -> Result<ViewerSettings> {
    let mut settings = ViewerSettings {
        host: s.host.clone(),
        port: s.port,
        allow_remote: s.allow_remote,
        data_dir: s.data_dir.clone(),
        preview_quality: s.preview_quality,
        fit_view,
        ..ViewerSettings::default()
    };
    settings.session.target_fps = s.target_fps;
    settings.session.target_latency_ms = s.target_latency;
    settings.session.pyramid_previews = s.preview_level == PreviewLevelArg::Auto;
    Ok(settings)
}

pub(crate) fn view_cmd(a: ViewCmdArgs) -> Result<()> {
    check_image_options(&a.image)?;
    let req = view_request(
        &a.input,
        &a.view,
        &a.options,
        &a.image,
        a.scene.as_deref(),
        &a.given,
        a.server.data_dir.as_deref(),
    )?;
    // With only --data-dir, the first of its files that reads is shown (a file of the folder
    // that does not read is said and passed over; the page can still list it).
    let only_data_dir = a.input.input.is_none() && a.input.phantom.is_none() && a.scene.is_none();
    let candidates: Vec<std::path::PathBuf> = match (&a.server.data_dir, only_data_dir) {
        (Some(dir), true) => volsplat_view::list_volumes(dir)
            .iter()
            .map(|n| dir.join(n))
            .collect(),
        _ => Vec::new(),
    };
    let mut req = req;
    let mut label = req.scene.volume.label();
    let mut next = 1;
    let bar = crate::progress::Bar::spinner("loading", false);
    let viewer = loop {
        let bound = Viewer::bind(
            req.clone(),
            Renderer::with_limits(reader_limits(&a.input)?),
            viewer_settings(&a.server, fit_view(a.scene.as_deref(), &a.given))?,
        );
        match bound {
            Err(volsplat_view::ViewError::Engine(e)) if next < candidates.len() => {
                say!("note: {label}: {e}; showing the next file of --data-dir");
                if let volsplat::VolumeSource::File { path, .. } = &mut req.scene.volume {
                    *path = candidates[next].clone();
                }
                label = req.scene.volume.label();
                next += 1;
            }
            other => break other,
        }
    };
    bar.clear();
    let viewer = viewer
        .map_err(|e| match e {
            volsplat_view::ViewError::Engine(e) => explain(e),
            e => e.into(),
        })
        .with_context(|| format!("starting the viewer on {label}"))?;
    // Ctrl-C (SIGINT, SIGTERM, SIGHUP) is how a server ends: it stops cleanly, status 0; a
    // second signal ends the process at once (crate::signals).
    let signals = Stop::install()?;
    let stop = viewer.stop_handle();
    std::thread::Builder::new()
        .name("volsplat-view-signals".into())
        .spawn(move || {
            while signals.signal().is_none() {
                std::thread::sleep(Duration::from_millis(50));
            }
            stop.stop();
        })
        .context("starting the signal watcher")?;
    emit(&format!("open {}", viewer.url()))?;
    say!("viewing {label}; Ctrl-C stops the server");
    if !a.no_browser && !open_browser(viewer.url()) {
        say!("(no browser found to open; open the URL above, or use --no-browser)");
    }
    viewer.serve();
    say!("stopped");
    Ok(())
}

/// Opens `url` in the desktop's browser, without waiting for it. `false` where there is no
/// desktop (no display on Linux) or no opener.
fn open_browser(url: &str) -> bool {
    use std::process::{Command, Stdio};
    let (program, args): (&str, Vec<&str>) = if cfg!(target_os = "macos") {
        ("open", vec![url])
    } else if cfg!(windows) {
        ("cmd", vec!["/C", "start", "", url])
    } else {
        let desktop = ["DISPLAY", "WAYLAND_DISPLAY"]
            .iter()
            .any(|v| std::env::var_os(v).is_some_and(|x| !x.is_empty()));
        if !desktop {
            return false;
        }
        ("xdg-open", vec![url])
    };
    Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .is_ok()
}

/// Which recordings `bench-view` replays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum ReplayChoice {
    /// A 10-second orbit drag at 60 events a second.
    Orbit,
    /// A 5-second transfer-function drag at 60 events a second.
    Tf,
    /// Both, one after the other, each on a fresh tab.
    Both,
}

/// Flags of `volsplat bench-view`.
#[derive(Debug, Args)]
pub(crate) struct BenchViewArgs {
    #[command(flatten)]
    pub input: InputArgs,
    #[command(flatten)]
    pub view: ViewArgs,
    #[command(flatten)]
    pub options: RenderOptions,
    #[command(flatten)]
    pub image: ImageOptions,
    #[command(flatten)]
    pub server: ServerArgs,
    /// Start from a scene file's request; flags given override its fields.
    #[arg(long, value_name = "FILE", help_heading = "Input")]
    pub scene: Option<PathBuf>,
    /// The recorded input to replay.
    #[arg(long, value_enum, default_value = "both")]
    pub replay: ReplayChoice,
    /// Every flag given on the command line (filled in by `main`).
    #[arg(skip)]
    pub given: Vec<String>,
}

/// `bench-view`: starts the viewer in this process, replays recorded input over a WebSocket
/// as the page would send it, and prints one JSON object (docs/BENCHMARKS.md).
pub(crate) fn bench_view_cmd(a: BenchViewArgs) -> Result<()> {
    check_image_options(&a.image)?;
    let req = view_request(
        &a.input,
        &a.view,
        &a.options,
        &a.image,
        a.scene.as_deref(),
        &a.given,
        a.server.data_dir.as_deref(),
    )?;
    let label = req.scene.volume.label();
    let (width, height) = (req.width, req.height);
    // The replay measures the request's own size (--size, default 512²).
    let settings = viewer_settings(&a.server, false)?;
    let budget_ms = settings.session.budget_ms();
    let aim_ms = settings.session.aim_ms();
    let handle = Viewer::bind(
        req,
        Renderer::with_limits(reader_limits(&a.input)?),
        settings,
    )
    .map_err(|e| match e {
        volsplat_view::ViewError::Engine(e) => explain(e),
        e => e.into(),
    })?
    .spawn()?;
    let recordings = match a.replay {
        ReplayChoice::Orbit => vec![Recording::Orbit],
        ReplayChoice::Tf => vec![Recording::TransferFunction],
        ReplayChoice::Both => vec![Recording::Orbit, Recording::TransferFunction],
    };
    let mut reports = Vec::new();
    for r in recordings {
        say!("replaying {} s of {r:?} input…", r.seconds());
        let mut client = Client::connect(handle.local_addr(), &handle.token(), None)
            .map_err(anyhow::Error::msg)?;
        let tf = first_frame(&mut client).map_err(anyhow::Error::msg)?;
        let report = replay(&mut client, r, &tf).map_err(anyhow::Error::msg)?;
        reports.push(serde_json::to_value(&report)?);
    }
    emit(
        &json!({
            "input": label,
            "width": width,
            "height": height,
            "budget_ms": budget_ms,
            "preview_aim_ms": aim_ms,
            "preview_level": if a.server.preview_level == PreviewLevelArg::Auto { "auto" } else { "full" },
            "cores": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            "replays": reports,
        })
        .to_string(),
    )?;
    Ok(())
}

/// Waits for the first final frame of a new tab and returns the transfer function in use
/// (the state message that carries it comes with the tab's first frame).
fn first_frame(
    client: &mut Client,
) -> std::result::Result<volsplat::core::TransferFunction, String> {
    let mut tf = None;
    let mut done = false;
    client.wait_for(Duration::from_secs(600), |m| {
        match m {
            Incoming::Text(ServerMessage::State(s)) if s.transfer_function.is_some() => {
                tf = s.transfer_function.clone();
            }
            Incoming::Frame(h, _) if h.quality == "final" => done = true,
            _ => {}
        }
        (done && tf.is_some()).then_some(())
    })?;
    tf.ok_or_else(|| "no transfer function".into())
}
