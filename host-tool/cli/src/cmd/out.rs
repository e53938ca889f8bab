//! Standard output for every command: text and the one JSON document of
//! `--json` go through here, never through `println!`.
//!
//! Why: Rust ignores SIGPIPE, so when the reader of a pipe goes away
//! (`trueaxis compare … --json | head -c 400`) a write fails with EPIPE,
//! and `println!` turns that into a panic with a backtrace hint. Here a
//! closed stdout becomes [`StdoutClosed`], which the command returns like
//! any error (so it stops writing) and `main` maps to a quiet exit 0 — the
//! reader asked for no more, which is not a failure of the command. Any
//! other write error is a real error (exit 1).

use std::io::{ErrorKind, Write};
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Result;

/// Stdout was closed by its reader (EPIPE): stop quietly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("stdout was closed by its reader")]
pub struct StdoutClosed;

/// True when `e` (or anything in its context chain) is [`StdoutClosed`].
pub fn is_stdout_closed(e: &anyhow::Error) -> bool {
    e.chain().any(|c| c.is::<StdoutClosed>())
}

/// Something was written to stdout (a `--json` command that fails after
/// its document must not write a second one).
static WROTE: AtomicBool = AtomicBool::new(false);

/// Writes `text` to stdout as is and flushes (so a closed pipe is seen
/// here, not later in a destructor that cannot report it).
pub fn print(text: &str) -> Result<()> {
    WROTE.store(true, Ordering::Relaxed);
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == ErrorKind::BrokenPipe => Err(StdoutClosed.into()),
        Err(e) => Err(anyhow::Error::new(e).context("cannot write to stdout")),
    }
}

/// Writes `doc` as one line of JSON (the `--json` document).
pub fn json<T: serde::Serialize + ?Sized>(doc: &T) -> Result<()> {
    print(&(serde_json::to_string(doc)? + "\n"))
}

/// Writes `doc` as pretty-printed JSON (still one document).
pub fn json_pretty<T: serde::Serialize + ?Sized>(doc: &T) -> Result<()> {
    print(&(serde_json::to_string_pretty(doc)? + "\n"))
}

/// The JSON document a `--json` command that fails writes to stdout, so a
/// script reading stdout gets one document either way (docs/cli.md):
/// `{"error": "…", "exit_code": 1}` — the message as on stderr.
pub fn error_json(e: &anyhow::Error, exit_code: u8) -> serde_json::Value {
    serde_json::json!({"error": super::flags::render(e), "exit_code": exit_code})
}

/// Exits on a clap error: a usage error (exit 2) under `--json` is a JSON
/// document on stdout too (`{error, exit_code, usage}`); help and version
/// print as they always do.
pub fn usage_exit(e: clap::Error, json: bool) -> ! {
    if json && e.use_stderr() {
        let _ = self::json(&serde_json::json!({
            "error": e.kind().to_string(),
            "exit_code": 2,
            "usage": e.render().to_string(),
        }));
    }
    e.exit()
}

/// Writes [`error_json`] to stdout unless something was written already
/// (a document then a failed check: the document stands).
pub fn json_error(e: &anyhow::Error, exit_code: u8) {
    if !WROTE.load(Ordering::Relaxed) {
        let _ = json(&error_json(e, exit_code));
    }
}

/// `println!` through [`print`]: evaluates to `anyhow::Result<()>`.
macro_rules! outln {
    () => {
        $crate::cmd::out::print("\n")
    };
    ($($arg:tt)*) => {
        $crate::cmd::out::print(&format!("{}\n", format_args!($($arg)*)))
    };
}
pub(crate) use outln;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stdout_closed_is_found_behind_context() {
        let e: anyhow::Error = StdoutClosed.into();
        let e = e.context("writing the report");
        assert!(is_stdout_closed(&e));
        assert!(!is_stdout_closed(&anyhow::anyhow!("other")));
    }
}
