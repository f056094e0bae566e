//! `volsplat`: command-line volume rendering by splatting (the binary's `main` calls
//! [`main_entry`]).
//!
//! Thin by design: parse, validate, call the libraries, map errors to exit codes
//! (0 success, 1 failure, 2 usage error from clap, 128 + N stopped by signal N: 130 for SIGINT,
//! 143 for SIGTERM). A library as well, for one reason: other front ends that draw a request
//! their own way take `volsplat render`'s flags exactly as it reads them ([`render_flags`]:
//! `volsplat-mpi render FILE [render flags] -o OUT`, issue 32 item 2).

mod aa_figures;
mod args;
mod commands;
mod display;
mod movie;
mod progress;
mod request;
mod say;
mod signals;
mod view;

use clap::{CommandFactory, FromArgMatches};

/// Which flags the command line gave (`given`: clap ids whose value came from the command line,
/// for the commands that merge flags over a scene file), filled into `cli` from `matches`.
fn fill_given(cli: &mut args::Cli, matches: &clap::ArgMatches) {
    let given = |m: &clap::ArgMatches| -> Vec<String> {
        m.ids()
            .filter(|id| {
                m.value_source(id.as_str()) == Some(clap::parser::ValueSource::CommandLine)
            })
            .map(|id| id.as_str().to_string())
            .collect()
    };
    if let (args::Command::Bench(b), Some(("bench", m))) = (&mut cli.command, matches.subcommand())
    {
        b.given = given(m);
    }
    if let (args::Command::Movie(b), Some(("movie", m))) = (&mut cli.command, matches.subcommand())
    {
        b.given = given(m);
    }
    match (&mut cli.command, matches.subcommand()) {
        (args::Command::View(v), Some(("view", m))) => v.given = given(m),
        (args::Command::BenchView(v), Some(("bench-view", m))) => v.given = given(m),
        _ => {}
    }
    if let (args::Command::Render(r), Some(("render", m))) =
        (&mut cli.command, matches.subcommand())
    {
        r.given = given(m);
        r.given_display_flags = display::given_flags(m);
        r.given_splat_flags = args::SPLAT_ONLY_FLAGS
            .iter()
            .filter(|(id, _)| m.value_source(id) == Some(clap::parser::ValueSource::CommandLine))
            .map(|(_, flag)| flag.to_string())
            .collect();
    }
}

/// The `volsplat` command: parses the process's arguments, runs the command, and returns the
/// exit status (module docs).
pub fn main_entry() -> std::process::ExitCode {
    let matches = args::Cli::command().get_matches();
    let mut cli = args::Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    fill_given(&mut cli, &matches);
    match commands::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            if let Some(stopped) = e.downcast_ref::<signals::Interrupted>() {
                say::line(&stopped.to_string());
                return std::process::ExitCode::from(stopped.status());
            }
            if let Some(internal) = e.downcast_ref::<commands::NonFiniteOutput>() {
                // Already worded as "internal error: …".
                say::line(&internal.to_string());
            } else {
                say::line(&format!("error: {e:#}"));
            }
            std::process::ExitCode::FAILURE
        }
    }
}

/// `volsplat COMMAND argv…` parsed as the binary parses it (usage errors as clap words them),
/// with the flags given on the command line recorded.
fn parse_command(command: &str, argv: &[String]) -> anyhow::Result<args::Cli> {
    let full = ["volsplat", command]
        .into_iter()
        .map(String::from)
        .chain(argv.iter().cloned());
    let matches = args::Cli::command()
        .try_get_matches_from(full)
        .map_err(|e| anyhow::anyhow!("{}", e.render()))?;
    let mut cli = args::Cli::from_arg_matches(&matches).map_err(|e| anyhow::anyhow!("{e}"))?;
    fill_given(&mut cli, &matches);
    Ok(cli)
}

/// `volsplat render`'s flags translated as `volsplat render` translates them ([`render_flags`]).
#[derive(Debug)]
pub struct RenderFlags {
    /// The engine's request (scene, image size in pixels, mode, quality, output options).
    pub request: volsplat::RenderRequest,
    /// The output file (`-o`; its extension chooses PNG, NPY, …, as `volsplat render`'s).
    pub output: std::path::PathBuf,
    /// What the translation noted (`note: …` lines of `volsplat render`), not printed here.
    pub notes: Vec<String>,
    /// `--quiet` was given.
    pub quiet: bool,
}

/// Parses `argv` (the arguments after `volsplat render`: INPUT, the camera, transfer-function,
/// quality and output flags, `-o OUT`, `--scene S.json`, …) with `volsplat render`'s own parser
/// and checks, and translates them into the engine's request exactly as `volsplat render`
/// does, without loading the volume or drawing. For front ends that draw the request their
/// own way (`volsplat-mpi render`). Errors: a usage error (clap's message, `--help` included),
/// an output path or option `volsplat render` refuses, a scene file that cannot be read, a
/// request the engine refuses.
pub fn render_flags(argv: &[String]) -> anyhow::Result<RenderFlags> {
    let args::Command::Render(a) = parse_command("render", argv)?.command else {
        anyhow::bail!("not a render command");
    };
    let (request, notes) = commands::render_request_checked(&a)?;
    Ok(RenderFlags {
        request,
        output: a.output.clone(),
        notes,
        quiet: a.quiet,
    })
}

/// `volsplat movie`'s flags translated as `volsplat movie` translates them ([`movie_flags`]):
/// the frames' requests, and how they are written.
pub struct MovieFlags {
    setup: movie::Setup,
    /// The output (`-o`: a folder or `%04d` pattern of PNG frames, `.gif`, `.png`/`.apng`, or a
    /// video through ffmpeg), as `volsplat movie`'s.
    pub output: std::path::PathBuf,
    /// The frames' size in pixels (width, height).
    pub size: (usize, usize),
    /// Frames per second and code values of the output.
    pub settings: volsplat::io::MovieSettings,
    /// MIP/MinIP's window over the values (`--window`, data units), applied before writing.
    pub window: Option<(f32, f32)>,
    /// What the translation noted, not printed here.
    pub notes: Vec<String>,
    /// `--quiet` was given.
    pub quiet: bool,
}

impl MovieFlags {
    /// How many frames.
    pub fn len(&self) -> usize {
        self.setup.len()
    }

    /// Whether there is no frame (never, for flags `volsplat movie` accepts).
    pub fn is_empty(&self) -> bool {
        self.setup.len() == 0
    }

    /// The request of frame `n` (`0 ≤ n < len`): an explicit camera, and the flight's transfer
    /// function and clipping where it has them, as `volsplat movie` draws it.
    pub fn frame_request(&self, n: usize) -> volsplat::RenderRequest {
        self.setup.frame_request(n)
    }
}

/// Parses `argv` (the arguments after `volsplat movie`) with `volsplat movie`'s own parser and
/// checks, and plans its frames (turntable or keyframed flight) as `volsplat movie` does, for
/// sort-last ranks that draw each frame (`volsplat-mpi movie`): the volume's grid comes from
/// the store's metadata or the raw NRRD's header where a rank reads its part in bricks
/// ([`volsplat::Renderer::part_grid`]), so planning reads no voxel there; elsewhere `renderer`
/// reads the volume. Errors as [`render_flags`], and a keyframe file that cannot be read.
pub fn movie_flags(
    argv: &[String],
    renderer: &mut volsplat::Renderer,
) -> anyhow::Result<MovieFlags> {
    let args::Command::Movie(a) = parse_command("movie", argv)?.command else {
        anyhow::bail!("not a movie command");
    };
    let setup = movie::movie_setup(&a, renderer, true)?;
    Ok(MovieFlags {
        output: a.output.clone(),
        size: setup.size,
        settings: setup.settings.clone(),
        window: setup.window,
        notes: setup.notes.clone(),
        quiet: a.quiet,
        setup,
    })
}

#[cfg(test)]
mod tests {
    use super::render_flags;

    fn argv(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    /// `render_flags` reads `volsplat render`'s flags as `volsplat render` does: the request it
    /// gives is the one `--save-scene` records for the same flags, read back.
    #[test]
    fn render_flags_translate_as_volsplat_render_does() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("s.json");
        let out = dir.path().join("x.png");
        let flags = format!(
            "--phantom shepp-logan --phantom-size 24 --mode mip --azimuth 30 --elevation 15 \
             --size 64x48 --save-scene {} -q -o {}",
            scene.display(),
            out.display()
        );
        let got = render_flags(&argv(&flags)).unwrap();
        assert_eq!(got.output, out);
        assert!(got.quiet);
        assert_eq!((got.request.width, got.request.height), (64, 48));
        assert_eq!(got.request.mode, volsplat::Mode::Mip);
        // The same flags through the binary's path (`main_entry`'s): the scene file it saves.
        use clap::{CommandFactory, FromArgMatches};
        let full = ["volsplat".to_string(), "render".to_string()]
            .into_iter()
            .chain(argv(&flags));
        let matches = crate::args::Cli::command()
            .try_get_matches_from(full)
            .unwrap();
        let mut cli = crate::args::Cli::from_arg_matches(&matches).unwrap();
        crate::fill_given(&mut cli, &matches);
        crate::commands::run(cli).unwrap();
        assert!(out.exists());
        // `--save-scene` records the resolved request (explicit camera and transfer function):
        // it must draw the same picture as the request `render_flags` gave.
        let (saved, _) = volsplat::RenderRequest::load(&scene).unwrap();
        let mut r = volsplat::Renderer::new();
        let bits = |req: &volsplat::RenderRequest, r: &mut volsplat::Renderer| {
            let out = r.render(req, &mut |_| true).unwrap();
            let v = out.values.expect("a MIP's values");
            v.values().iter().map(|x| x.to_bits()).collect::<Vec<u32>>()
        };
        let want = bits(&saved, &mut r);
        assert!(
            want.iter().any(|&b| b != 0),
            "a blank picture tests nothing"
        );
        assert_eq!(bits(&got.request, &mut r), want);
    }

    #[test]
    fn render_flags_refuse_what_volsplat_render_refuses() {
        let e = render_flags(&argv("--bogus -o x.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("--bogus"), "{e}");
        let e = render_flags(&argv("--size 64")).unwrap_err().to_string();
        assert!(e.contains("--output"), "{e}");
        let e = render_flags(&argv("-o x.bmp")).unwrap_err().to_string();
        assert!(e.contains("x.bmp"), "{e}");
    }
}
