//! `volsplat`: command-line volume rendering by splatting.
//!
//! Thin by design: parse, validate, call the libraries, map errors to exit codes
//! (0 success, 1 failure, 2 usage error from clap, 128 + N stopped by signal N: 130 for SIGINT,
//! 143 for SIGTERM).

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

fn main() -> std::process::ExitCode {
    let matches = args::Cli::command().get_matches();
    let mut cli = args::Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
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
