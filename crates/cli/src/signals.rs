//! Stopping on SIGINT, SIGTERM and SIGHUP (`signal-hook`): the first signal asks the command to
//! stop at its next check (between frames, or from a render's progress callback), so that it
//! removes its temporary files and partial outputs and exits with 128 + the signal's number
//! (130 for SIGINT, 143 for SIGTERM); a second signal ends the process at once with that
//! status.

use anyhow::Result;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// The signals handled.
#[cfg(unix)]
const SIGNALS: &[i32] = &[
    signal_hook::consts::SIGINT,
    signal_hook::consts::SIGTERM,
    signal_hook::consts::SIGHUP,
];
#[cfg(not(unix))]
const SIGNALS: &[i32] = &[signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM];

/// Whether a stop was asked for, and by which signal.
#[derive(Clone)]
pub(crate) struct Stop {
    signal: Arc<AtomicUsize>,
}

impl Stop {
    /// Installs the handlers for the rest of the process.
    pub(crate) fn install() -> Result<Stop> {
        let signal = Arc::new(AtomicUsize::new(0));
        let seen = Arc::new(AtomicBool::new(false));
        for &sig in SIGNALS {
            // Registered first, so it runs first: exits only if a signal came before.
            signal_hook::flag::register_conditional_shutdown(sig, 128 + sig, Arc::clone(&seen))?;
            signal_hook::flag::register(sig, Arc::clone(&seen))?;
            signal_hook::flag::register_usize(sig, Arc::clone(&signal), sig as usize)?;
        }
        Ok(Stop { signal })
    }

    /// The signal that asked to stop, if one did.
    pub(crate) fn signal(&self) -> Option<i32> {
        match self.signal.load(Ordering::SeqCst) {
            0 => None,
            s => Some(s as i32),
        }
    }

    /// `Err(Interrupted)` if a signal asked to stop; `done` says what was left behind.
    pub(crate) fn check(&self, done: &str) -> std::result::Result<(), Interrupted> {
        match self.signal() {
            Some(signal) => Err(Interrupted {
                signal,
                done: done.to_string(),
            }),
            None => Ok(()),
        }
    }
}

/// A command stopped by a signal; the process exits with 128 + `signal`.
#[derive(Debug)]
pub(crate) struct Interrupted {
    /// The signal's number.
    pub signal: i32,
    /// What was stopped and what was left (or removed).
    pub done: String,
}

impl Interrupted {
    /// The exit status: 128 + the signal's number.
    pub(crate) fn status(&self) -> u8 {
        (128 + self.signal).clamp(0, 255) as u8
    }
}

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let name = match self.signal {
            s if s == SIGINT => "SIGINT".to_string(),
            s if s == SIGTERM => "SIGTERM".to_string(),
            n => format!("signal {n}"),
        };
        write!(f, "interrupted by {name}: {}", self.done)
    }
}

impl std::error::Error for Interrupted {}
