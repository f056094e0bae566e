//! What the command-line tests share (ripgrep's `tests/util.rs`): running the binary built for
//! the tests and reading what it printed. Each test file takes what it needs (`mod util;`), so
//! some files leave some helpers unused.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// Runs the `volsplat` binary of this build with `args` and waits for it.
pub(crate) fn volsplat(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volsplat"))
        .args(args)
        .output()
        .expect("the volsplat binary runs")
}

/// What a run printed on stderr (lossy UTF-8).
pub(crate) fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// What a run printed on stdout (lossy UTF-8).
pub(crate) fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The float32 values of a `.npy` file `volsplat` wrote (little-endian, C order), in order.
pub(crate) fn npy_f32(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap();
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    bytes[10 + header_len..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}
