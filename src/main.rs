//! The `mesoflow` binary: the command line (`cli`) over the engine library, and the GPU
//! benchmarks (`bench`, `mesoflow bench ...`).

// First, so that its printing macros are in scope in every module after it.
#[macro_use]
mod out;

mod bench;
mod cli;
mod frames;

use std::process::ExitCode;

use clap::Parser;

/// The exit code of an interrupted command (128 + SIGINT, as shells report it).
const INTERRUPTED: i32 = 130;

fn main() -> ExitCode {
    let args = match cli::Cli::try_parse() {
        Ok(args) => args,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    // An interrupt (SIGINT, SIGTERM, SIGHUP) removes the outputs being written, whose
    // temporaries would otherwise be left behind, and exits as interrupted.
    if let Err(e) = ctrlc::set_handler(|| {
        mesoflow::npy::abandon_writes();
        note!("mesoflow: interrupted");
        std::process::exit(INTERRUPTED);
    }) {
        note!("mesoflow: no interrupt handler ({e}): an interrupt may leave temporary files");
    }
    let result = cli::execute(args.command);
    // A report that could not be written is a failure of its own (a closed pipe is not:
    // its reader has all it wanted).
    let unwritten = out::stdout_failure();
    match result {
        Ok(()) => match unwritten {
            None => ExitCode::SUCCESS,
            Some(e) => {
                note!("error: cannot write to stdout: {e}");
                ExitCode::from(1)
            }
        },
        Err(e) => {
            note!("error: {}", e.to_string().trim_end());
            ExitCode::from(e.exit_code())
        }
    }
}
