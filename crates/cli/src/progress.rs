//! Progress bars on stderr (`indicatif`): drawn only when stderr is a terminal and `--quiet`
//! was not given, so pipes, logs and tests see nothing.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;

/// Steps of a bar that shows a fraction.
const FRACTION_STEPS: u64 = 1000;

/// A progress bar, or nothing when stderr is not a terminal or the command is quiet.
pub struct Bar(Option<ProgressBar>);

impl Bar {
    fn make(len: u64, template: &str, quiet: bool) -> Self {
        if quiet || !std::io::stderr().is_terminal() {
            return Bar(None);
        }
        let style = ProgressStyle::with_template(template)
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
        bar.set_style(style);
        Bar(Some(bar))
    }

    /// A bar for one render, fed with fractions in [0, 1] ([`Bar::set_fraction`]).
    pub fn fraction(label: &str, quiet: bool) -> Self {
        let b = Bar::make(
            FRACTION_STEPS,
            "{prefix} {msg:9} [{bar:32}] {percent:>3}% {elapsed} (ETA {eta})",
            quiet,
        );
        b.set_prefix(label);
        b
    }

    /// A bar of `n` items (frames), with rate and ETA.
    pub fn items(n: u64, label: &str, quiet: bool) -> Self {
        let b = Bar::make(
            n,
            "{prefix} [{bar:32}] {pos}/{len} {per_sec} {elapsed} (ETA {eta})",
            quiet,
        );
        b.set_prefix(label);
        b
    }

    /// A spinner with the elapsed time, for work that reports no fraction (the study reports).
    pub fn spinner(label: &str, quiet: bool) -> Self {
        if quiet || !std::io::stderr().is_terminal() {
            return Bar(None);
        }
        let style = ProgressStyle::with_template("{spinner} {prefix} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner());
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
        bar.set_style(style);
        bar.set_prefix(label.to_string());
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        Bar(Some(bar))
    }

    fn set_prefix(&self, label: &str) {
        if let Some(b) = &self.0 {
            b.set_prefix(label.to_string());
        }
    }

    /// Sets a fraction bar to `f` (clamped to [0, 1]) with the stage name as its message.
    pub fn set_fraction(&self, f: f64, stage: &str) {
        if let Some(b) = &self.0 {
            b.set_position((f.clamp(0.0, 1.0) * FRACTION_STEPS as f64) as u64);
            b.set_message(stage.to_string());
        }
    }

    /// Advances an item bar by one.
    pub fn inc(&self) {
        if let Some(b) = &self.0 {
            b.inc(1);
        }
    }

    /// Prints `line` on stderr above the bar.
    pub fn println(&self, line: &str) {
        match &self.0 {
            Some(b) => b.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }

    /// Removes the bar from the terminal.
    pub fn clear(&self) {
        if let Some(b) = &self.0 {
            b.finish_and_clear();
        }
    }

    /// A render progress callback that moves the bar; never cancels.
    pub fn callback(&self) -> impl FnMut(&volsplat::Progress) -> bool + Send + '_ {
        move |p| {
            self.set_fraction(p.fraction, p.stage);
            true
        }
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        self.clear();
    }
}
