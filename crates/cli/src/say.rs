//! Lines for the user on stderr (notes, warnings, what was written, errors), written so that a
//! full or closed stderr (`2>/dev/full`) never stops a command or loses its output: `eprintln!`
//! panics when stderr cannot be written.

use std::io::Write;

/// Writes `text` and a newline to stderr, ignoring errors.
pub(crate) fn line(text: &str) {
    let _ = writeln!(std::io::stderr().lock(), "{text}");
}

/// `say!("…", args)`: [`line`] with `format!` arguments, in place of `eprintln!`.
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::say::line(&format!($($arg)*))
    };
}
pub(crate) use say;
