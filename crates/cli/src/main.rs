//! `volsplat`: command-line volume rendering by splatting (the library's
//! `volsplat_cli::main_entry`).

fn main() -> std::process::ExitCode {
    volsplat_cli::main_entry()
}
