//! How a command ends, and the one place that turns that into an exit code.
//!
//! A command returns [`Result`]: `Ok(Done)` when it did its work (which may still be a
//! failed or interrupted simulation, or a replay that differs), or `Err(CliError)` when it
//! could not. [`finish`] prints the error, once, and maps both to the documented exit codes
//! (README, "Exit codes"): 0 success, 1 internal or I/O error, 2 bad input (CLI, manifest, or
//! a run file that is unreadable, incomplete or damaged), 3 simulation failed, 130
//! interrupted; `runner verify`: 0 identical, 1 not, 2 the file cannot be used.

use mps_runner::calibrate::CalibrateError;
use mps_runner::manifest::ManifestError;
use mps_runner::record::{Outcome, RecordError};
use mps_runner::report::ReportError;
use mps_runner::resume::ResumeError;
use mps_runner::run::RunError;
use std::process::ExitCode;

const EXIT_INTERNAL: u8 = 1;
/// `runner verify`: the replay differs from the file (or the trend does not hold).
const EXIT_MISMATCH: u8 = 1;
const EXIT_BAD_INPUT: u8 = 2;
const EXIT_SIM_FAILED: u8 = 3;
/// Also the code of a second signal, which exits at once (`interrupt::flag`).
pub const EXIT_INTERRUPTED: u8 = 130;

/// What a command returns.
pub type Result<T = Done> = std::result::Result<T, CliError>;

/// How a command that did its work ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Done {
    /// Exit 0.
    Success,
    /// `runner verify`: the replay differs from the file, or the trend does not hold (exit 1).
    Mismatch,
    /// A simulation failed, or a calibration was not fitted (exit 3).
    SimFailed,
    /// Stopped by a signal (exit 130).
    Interrupted,
}

impl Done {
    /// A run's outcome: completed 0, failed 3, interrupted 130.
    pub fn of(outcome: &Outcome) -> Self {
        match outcome {
            Outcome::Completed => Done::Success,
            Outcome::Failed(_) => Done::SimFailed,
            Outcome::Interrupted(_) => Done::Interrupted,
        }
    }

    fn code(self) -> u8 {
        match self {
            Done::Success => 0,
            Done::Mismatch => EXIT_MISMATCH,
            Done::SimFailed => EXIT_SIM_FAILED,
            Done::Interrupted => EXIT_INTERRUPTED,
        }
    }
}

/// Why a command could not do its work. Printed `error: MESSAGE` on stderr (a refused run
/// adds a `hint:` line), with the exit code of [`CliError::code`].
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// Bad input that the command found itself: an argument, a file that cannot be used
    /// (exit 2).
    #[error("{0}")]
    BadInput(String),
    /// An internal or I/O error, e.g. an output that cannot be written (exit 1).
    #[error("{0}")]
    Internal(String),
    /// A manifest (experiment, calibration, benchmark suite) that cannot be read (exit 2).
    #[error(transparent)]
    Manifest(#[from] ManifestError),
    /// A run that could not be made: exit 2 when it was refused before anything was written
    /// (too large, or its file exists, is being written, or holds a killed run), 1 when the
    /// recording failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// A run that cannot be resumed (exit 2), or whose new file could not be made (as `Run`).
    #[error(transparent)]
    Resume(#[from] ResumeError),
    /// A file that cannot be replayed (exit 2).
    #[error(transparent)]
    Replay(#[from] mps_runner::verify::Unusable),
    /// A figure, table or page that cannot be made: exit 1 when writing failed, 2 else.
    #[error(transparent)]
    Report(#[from] ReportError),
    /// A calibration that did not end fitted: exit 2 bad manifest or bounds, 130 interrupted,
    /// 3 else.
    #[error(transparent)]
    Calibrate(#[from] CalibrateError),
    /// Already reported where it happened (a sweep point's line on stdout): nothing more is
    /// printed, the exit code is this one.
    #[error("")]
    Reported(u8),
}

impl CliError {
    /// A run error already reported on its own line: only its exit code is left.
    pub fn reported(e: &RunError) -> Self {
        CliError::Reported(run_code(e))
    }

    /// The exit code: 1 internal, 2 bad input, 3 simulation failed, 130 interrupted.
    fn code(&self) -> u8 {
        match self {
            CliError::BadInput(_) | CliError::Manifest(_) | CliError::Replay(_) => EXIT_BAD_INPUT,
            CliError::Internal(_) => EXIT_INTERNAL,
            CliError::Run(e) | CliError::Resume(ResumeError::Run(e)) => run_code(e),
            CliError::Resume(ResumeError::Unusable { .. }) => EXIT_BAD_INPUT,
            CliError::Report(ReportError::Write { .. }) => EXIT_INTERNAL,
            CliError::Report(_) => EXIT_BAD_INPUT,
            CliError::Calibrate(CalibrateError::Manifest(_) | CalibrateError::OutOfBounds(_)) => {
                EXIT_BAD_INPUT
            }
            CliError::Calibrate(CalibrateError::Interrupted(_)) => EXIT_INTERRUPTED,
            CliError::Calibrate(_) => EXIT_SIM_FAILED,
            CliError::Reported(code) => *code,
        }
    }

    /// Prints the error on stderr, with what to do about a refused run.
    fn print(&self) {
        let run = match self {
            CliError::Reported(_) => return,
            CliError::Run(e) | CliError::Resume(ResumeError::Run(e)) => Some(e),
            _ => None,
        };
        eprintln!("error: {self}");
        if let Some(RunError::Record(r)) = run {
            print_hint(r);
        }
    }
}

/// Exit code of a run that could not be made: 2 for a run refused before anything was
/// written (too large, or its file exists, is being written, or holds a killed run), 1 for a
/// recording that failed.
fn run_code(e: &RunError) -> u8 {
    match e {
        RunError::TooLarge { .. } => EXIT_BAD_INPUT,
        RunError::Record(r) if r.is_refusal() => EXIT_BAD_INPUT,
        _ => EXIT_INTERNAL,
    }
}

/// What to do about a run refused for the file in its way.
fn print_hint(r: &RecordError) {
    match r {
        RecordError::Exists { path } => eprintln!(
            "hint: `runner verify {}` replays it; --overwrite runs the experiment again and replaces the file when the new one is finished; --out writes elsewhere",
            path.display()
        ),
        RecordError::Busy { .. } => {
            eprintln!("hint: wait for that run to finish, or write elsewhere with --out")
        }
        RecordError::Unfinished { path } => eprintln!(
            "hint: `runner resume {}` continues it from its last checkpoint; --overwrite discards it and starts again",
            path.display()
        ),
        _ => {}
    }
}

/// The one place a command's end becomes the process's exit code (the error printed first).
pub fn finish(result: Result) -> ExitCode {
    match result {
        Ok(done) => ExitCode::from(done.code()),
        Err(e) => {
            e.print();
            ExitCode::from(e.code())
        }
    }
}
