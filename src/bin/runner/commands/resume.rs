//! `runner resume FILE`: continue an interrupted (or killed, `.partial`) run from its last
//! checkpoint into its finished file. Exit codes as for a run; 2 when the file cannot be
//! resumed.

use crate::cli::ResumeArgs;
use crate::error::{CliError, Done, Result};
use crate::run_file::{FileState, file_state};
use crate::{interrupt, progress};
use mps_runner::report::time_text;
use mps_runner::resume::{ResumeOptions, resume};

pub fn command(args: ResumeArgs) -> Result {
    let file = &args.file;
    match file_state(file) {
        FileState::Incomplete(why) => {
            return Err(CliError::BadInput(format!(
                "cannot resume: {why}; a killed run's .partial file resumes, a damaged finished one does not"
            )));
        }
        FileState::Unusable(why) => {
            return Err(CliError::BadInput(format!("cannot resume: {why}")));
        }
        FileState::PartialDamaged(why) => {
            eprintln!("warning: {why}; resuming from the last of those checkpoints");
        }
        FileState::Usable => {}
    }
    let display = progress::Display::new(args.quiet);
    let options = ResumeOptions {
        threads: args.threads,
        progress: display.as_ref().map(|d| d.callback()),
        interrupt: interrupt::flag(),
    };
    let resumed = resume(file, &options);
    if let Some(d) = &display {
        d.finish_all();
    }
    let r = resumed?;
    let end_s = r
        .result
        .summary
        .metrics
        .get("simulated_time_s")
        .copied()
        .unwrap_or(f64::NAN);
    eprintln!(
        "resumed from checkpoint {} (step {}, t = {} s, {} messages copied): {} at t = {} s; wall time {:.2} s",
        r.from_checkpoint,
        r.from_step,
        time_text(r.from_time_s),
        r.copied_messages,
        r.result.outcome.as_str(),
        time_text(end_s),
        r.result.wall_time_s
    );
    if !r.result.summary.reason.is_empty() {
        eprintln!("reason: {}", r.result.summary.reason);
    }
    println!("{}", r.result.path.display());
    Ok(Done::of(&r.result.outcome))
}
