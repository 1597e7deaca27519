//! Printing for the binary: every line a command writes goes through here, so that a
//! closed stdout or stderr never panics (`println!` does: `mesoflow nodes | head`).
//!
//! A reader that goes away (a broken pipe: `| head` has read what it wanted) ends the
//! printing quietly: later lines are dropped and the command runs on to its own end and
//! exit code (a run still writes its outputs, `validate` still exits 2 for a bad file).
//! Any other failure to write stdout (a full disk behind `> file`) is kept and reported
//! when the command ends, as a failure, since the report is then incomplete.
//! Diagnostics on stderr are best effort: when stderr is gone there is nowhere to say so.

use std::fmt;
use std::io::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set once a write to stdout met a broken pipe: nothing more is written there.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);
/// The first failure to write stdout other than a broken pipe.
static STDOUT_FAILURE: Mutex<Option<String>> = Mutex::new(None);

/// Writes to stdout (see the module doc for what happens when that fails).
pub fn stdout(args: fmt::Arguments) {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.flush()) {
        STDOUT_CLOSED.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe
            && let Ok(mut failure) = STDOUT_FAILURE.lock()
        {
            failure.get_or_insert_with(|| e.to_string());
        }
    }
}

/// Writes to stderr; a failure is ignored (there is no other place to report it).
pub fn stderr(args: fmt::Arguments) {
    let _ = std::io::stderr().lock().write_fmt(args);
}

/// Why stdout could not be written (not for a reader that went away), if it could not.
pub fn stdout_failure() -> Option<String> {
    STDOUT_FAILURE.lock().ok().and_then(|f| f.clone())
}

/// `println!` to stdout through [`stdout`].
macro_rules! outln {
    () => { $crate::out::stdout(format_args!("\n")) };
    ($($arg:tt)*) => { $crate::out::stdout(format_args!("{}\n", format_args!($($arg)*))) };
}

/// `print!` to stdout through [`stdout`].
macro_rules! out {
    ($($arg:tt)*) => { $crate::out::stdout(format_args!($($arg)*)) };
}

/// `eprintln!` to stderr through [`stderr`].
macro_rules! note {
    ($($arg:tt)*) => { $crate::out::stderr(format_args!("{}\n", format_args!($($arg)*))) };
}
