//! Progress bars on stderr (`indicatif`): drawn only when stderr is a terminal and `--quiet`
//! was not given, so pipes, logs and tests see nothing.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};
use std::io::IsTerminal;

/// Steps of a bar that shows a fraction.
const FRACTION_STEPS: u64 = 1000;

/// A progress bar, or nothing when stderr is not a terminal or the command is quiet.
pub(crate) struct Bar(Option<ProgressBar>);

impl Bar {
    fn make(len: u64, template: &str, quiet: bool) -> Self {
        if quiet || !std::io::stderr().is_terminal() {
            return Bar(None);
        }
        let style = ProgressStyle::with_template(template)
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .with_key("rate", |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = w.write_str(&rate(s.per_sec()));
            })
            .progress_chars("=> ");
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
        bar.set_style(style);
        Bar(Some(bar))
    }

    /// A bar for one render, fed with fractions in [0, 1] ([`Bar::set_fraction`]).
    pub(crate) fn fraction(label: &str, quiet: bool) -> Self {
        let b = Bar::make(
            FRACTION_STEPS,
            "{prefix} {msg:9} [{bar:32}] {percent:>3}% {elapsed} (ETA {eta})",
            quiet,
        );
        b.set_prefix(label);
        b
    }

    /// A bar of `n` items (frames), with rate ([`rate`]) and ETA.
    pub(crate) fn items(n: u64, label: &str, quiet: bool) -> Self {
        let b = Bar::make(
            n,
            "{prefix} [{bar:32}] {pos}/{len} {rate} {elapsed} (ETA {eta})",
            quiet,
        );
        b.set_prefix(label);
        b
    }

    /// A spinner with the elapsed time, for work that reports no fraction (the study reports).
    pub(crate) fn spinner(label: &str, quiet: bool) -> Self {
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
    pub(crate) fn set_fraction(&self, f: f64, stage: &str) {
        if let Some(b) = &self.0 {
            b.set_position((f.clamp(0.0, 1.0) * FRACTION_STEPS as f64) as u64);
            b.set_message(stage.to_string());
        }
    }

    /// Advances an item bar by one.
    pub(crate) fn inc(&self) {
        if let Some(b) = &self.0 {
            b.inc(1);
        }
    }

    /// Prints `line` on stderr above the bar.
    pub(crate) fn println(&self, line: &str) {
        match &self.0 {
            Some(b) => b.suspend(|| crate::say::line(line)),
            None => crate::say::line(line),
        }
    }

    /// Removes the bar from the terminal.
    pub(crate) fn clear(&self) {
        if let Some(b) = &self.0 {
            b.finish_and_clear();
        }
    }
}

/// A rate of items per second for the bar, with three significant digits (`7.10/s`, `24.0/s`,
/// `312/s`), or the seconds per item when below one (`4.2 s each`); indicatif's own `per_sec`
/// prints four decimals (`7.1024/s`).
pub(crate) fn rate(per_sec: f64) -> String {
    if !(per_sec.is_finite() && per_sec > 0.0) {
        return "-/s".into();
    }
    if per_sec < 1.0 {
        let each = 1.0 / per_sec;
        return if each < 10.0 {
            format!("{each:.1} s each")
        } else {
            format!("{each:.0} s each")
        };
    }
    match per_sec {
        r if r < 10.0 => format!("{r:.2}/s"),
        r if r < 100.0 => format!("{r:.1}/s"),
        r => format!("{r:.0}/s"),
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        self.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::rate;

    /// Issue 28: the movie bar printed `7.1024/s`.
    #[test]
    fn rates_have_three_significant_digits() {
        assert_eq!(rate(7.1024), "7.10/s");
        assert_eq!(rate(24.04), "24.0/s");
        assert_eq!(rate(312.4), "312/s");
        assert_eq!(rate(0.24), "4.2 s each");
        assert_eq!(rate(0.02), "50 s each");
        assert_eq!(rate(0.0), "-/s");
        assert_eq!(rate(f64::NAN), "-/s");
    }
}
