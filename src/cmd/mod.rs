//! One module per subcommand beyond run/check/nodes/dot.

pub mod bench;
pub mod calibrate;
pub mod emulate;
pub mod eval;
pub mod inspect;
pub mod live;
pub mod paths;
pub mod pipeline;
pub mod repair;
pub mod reproduce;
pub mod send;
pub mod simulate;

/// An error that means "the graph is invalid": the process exits with status 2, as `check`
/// and `run` do for a graph that does not validate. The text is the errors, one per line.
#[derive(Debug)]
pub struct InvalidGraph(pub String);

impl std::fmt::Display for InvalidGraph {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for InvalidGraph {}

/// Prints `text` on standard output for a command that keeps SIGPIPE ignored (`run`, `bench`,
/// `emulate`, `calibrate`, `eval`, `reproduce`: see `default_sigpipe` in main.rs). A closed
/// output (`| head`) is not a panic there: `what` is named on stderr as not printed, and the
/// command goes on (its files are written either way).
pub fn print_or_warn(text: &str, what: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        warn(&format!("{what} not printed: standard output: {e}"));
    }
}

/// `text` as a line on stderr, never a panic (see [`warn`]): for what a command says between
/// the files it writes.
pub fn note(text: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr().lock(), "{text}");
}

/// `warning: {text}` on stderr, never a panic: stderr may be the same closed pipe
/// (`2>&1 | head`), and a command printing past it still has files to write.
pub fn warn(text: &str) {
    note(&format!("warning: {text}"));
}
