//! `runner`: the command line. Parses the arguments (`cli`) and hands them to their command
//! (`commands/`); every command returns how it ended and `error::finish` alone prints an
//! error and turns the end into the exit code: 0 success, 1 internal or I/O error, 2 bad
//! input (CLI, manifest, or a run file that is unreadable, incomplete or damaged), 3
//! simulation failed, 130 interrupted. `runner verify`: 0 identical, 1 not, 2 the file
//! cannot be used.
//!
//! The other modules: `progress` (bars and lines on stderr), `interrupt` (SIGINT and
//! SIGTERM), `run_file` (how far a run file can be trusted before it is read), `allocator`
//! (where memory comes from: large blocks on transparent huge pages, glibc's parameters).

/// `print!` and `println!` for this binary: standard output whose reader has gone (`runner
/// RUN | head -1`) is no error of ours, so a closed pipe is ignored rather than a panic (std's
/// macros panic) and the command finishes its work and its exit code; any other failure to
/// write still panics as std's would. Defined before the modules so they use it too.
macro_rules! print {
    ($($arg:tt)*) => {
        $crate::write_stdout(::std::format_args!($($arg)*))
    };
}
macro_rules! println {
    () => {
        print!("\n")
    };
    ($($arg:tt)*) => {
        print!("{}\n", ::std::format_args!($($arg)*))
    };
}

fn write_stdout(args: std::fmt::Arguments) {
    use std::io::Write;
    match std::io::stdout().lock().write_fmt(args) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            panic!("failed printing to stdout: {e}")
        }
        _ => {}
    }
}

mod allocator;
mod cli;
mod commands;
mod error;
mod interrupt;
mod progress;
mod run_file;

#[global_allocator]
static ALLOCATOR: allocator::HugePageAlloc = allocator::HugePageAlloc;

use clap::Parser;
use cli::{Cli, Command};
use commands::{bench, calibrate, figures, files, manifest, resume, run, verify};
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A reader that stops early (`runner info RUN | head`) ends these print-only commands as
    // it ends other Unix tools, by SIGPIPE, instead of a panic on the closed pipe. Commands
    // that write run files keep Rust's default (EPIPE), so a closed stdout cannot cut a file.
    #[cfg(unix)]
    if matches!(
        cli.command,
        Some(Command::Info(_) | Command::Export(_) | Command::Hash(_))
    ) {
        // SAFETY: restores the default disposition of one signal before any thread exists.
        unsafe {
            libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        }
    }
    // Only where memory comes from changes, not a bit of a run.
    allocator::tune_glibc();
    let ended = match cli.command {
        None => run::command(cli.run),
        Some(Command::Run(args)) => run::command(args),
        Some(Command::Resume(args)) => resume::command(args),
        Some(Command::Verify(args)) => verify::command(args),
        Some(Command::Bench(args)) => bench::command(args),
        Some(Command::Calibrate(args)) => calibrate::command(args),
        Some(Command::Hash(args)) => manifest::hash(args),
        Some(Command::Expand(args)) => manifest::expand(args),
        Some(Command::Info(args)) => files::info(args),
        Some(Command::Export(args)) => files::export(args),
        Some(Command::Draw(args)) => figures::draw(args),
        Some(Command::Plot(args)) => figures::plot(args),
        Some(Command::PlotSweep(args)) => figures::plot_sweep(args),
        Some(Command::Snapshot(args)) => figures::snapshot(args),
        Some(Command::Profile(args)) => figures::profile(args),
        Some(Command::Report(args)) => figures::page(args),
    };
    error::finish(ended)
}
