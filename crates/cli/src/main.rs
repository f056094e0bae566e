//! `volsplat`: command-line volume rendering by splatting.
//!
//! Thin by design: parse, validate, call the libraries, map errors to exit codes
//! (0 success, 1 failure, 2 usage error from clap).

mod aa_figures;
mod args;
mod commands;
mod display;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = args::Cli::parse();
    match commands::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
