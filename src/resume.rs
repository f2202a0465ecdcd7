//! `runner resume`: continue an interrupted run (finished with outcome `interrupted`) or a
//! killed one (a `.partial` file) from its last checkpoint, into a new complete file at the
//! run's usual path. The finished file is what an uninterrupted run would have written: the
//! earlier checkpoints, diagnostics and clouds are copied over in order, the extra checkpoint
//! an interruption writes between two scheduled ones is left out (its state is where the run
//! continues from), and the time loop goes on with its output schedules positioned after
//! the restored time. So the checkpoint hashes equal those of an uninterrupted run.
use crate::checkpoint;
use crate::experiment::Resolved;
use crate::proto::mps::v1::{CheckpointHash, StateCheckpoint};
use crate::record::{Existing, PARTIAL_SUFFIX, Recorder, lock_unfinished, partial_path, read_run};
use crate::restore::{Logged, is_scheduled, manifest_of, read_messages, restore_solver};
use crate::run::{LoopControl, LoopStart, RunError, RunResult, output_path, time_loop, time_ns};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Metadata record a resumed file carries (after `manifest`, `build`, `run`).
pub const META_RESUMED: &str = "resumed";

#[derive(Clone, Default)]
pub struct ResumeOptions {
    /// Worker threads; None = all cores.
    pub threads: Option<usize>,
    pub progress: Option<crate::run::ProgressFn>,
    /// Set from outside (signal handler) to stop cleanly as "interrupted".
    pub interrupt: Option<Arc<AtomicBool>>,
}

#[derive(Debug, thiserror::Error)]
pub enum ResumeError {
    /// The file cannot be resumed (unreadable, completed, failed, no checkpoint, tampered):
    /// exit code 2.
    #[error("{}: cannot resume: {reason}", path.display())]
    Unusable { path: PathBuf, reason: String },
    /// The new file could not be written: exit code 1.
    #[error(transparent)]
    Run(#[from] RunError),
}

/// A resumed run.
#[derive(Debug, Clone)]
pub struct Resumed {
    pub result: RunResult,
    /// The checkpoint the run continued from.
    pub from_checkpoint: u32,
    pub from_step: u64,
    pub from_time_s: f64,
    /// Messages copied from the earlier file.
    pub copied_messages: usize,
}

/// Resumes the run recorded at `path`. See the module documentation.
pub fn resume(path: &Path, options: &ResumeOptions) -> Result<Resumed, ResumeError> {
    let unusable = |reason: String| ResumeError::Unusable {
        path: path.to_path_buf(),
        reason,
    };
    // A `.partial` may still be written by a live runner: refuse rather than take it over.
    // The lock is held until the resumed file is finished (it follows the file aside).
    let _source_lock = if path.to_string_lossy().ends_with(PARTIAL_SUFFIX) {
        Some(lock_unfinished(path).map_err(RunError::from)?)
    } else {
        None
    };
    let run = read_run(path).map_err(|e| unusable(e.to_string()))?;
    if run.complete {
        match run.summary.as_ref().map(|s| s.outcome.as_str()) {
            Some("interrupted") => {}
            Some("completed") => return Err(unusable("the run is already completed".into())),
            Some("failed") => {
                return Err(unusable(
                    "the run failed; resuming would repeat the failure".into(),
                ));
            }
            Some(other) => {
                return Err(unusable(format!(
                    "its summary records the outcome {other:?}; only an interrupted run (or a killed one's .partial file) can be resumed"
                )));
            }
            None => {
                return Err(unusable(
                    "the file is finished but has no /summary message, so its outcome is unknown (damaged?); only an interrupted run (or a killed one's .partial file) can be resumed".into(),
                ));
            }
        }
    }
    let resolved = manifest_of(&run).map_err(|e| unusable(e.to_string()))?;
    let m = &resolved.manifest;
    let Some(from) = run.states.last().cloned() else {
        return Err(unusable("the file has no state checkpoint".into()));
    };
    let last = run.states.len() - 1;
    let from_scheduled = is_scheduled(&run.states, last, m.output.checkpoint_interval_s);
    let messages = read_messages(path).map_err(|e| unusable(e.to_string()))?;

    // Everything logged before the checkpoint we continue from, in file order (for a
    // scheduled checkpoint that includes the diagnostics and cloud of its own time, which
    // the loop writes first; for an extra one, only the scheduled messages of its time).
    let mut copy = Vec::new();
    let mut states_seen = 0;
    for (t, msg) in messages {
        if let Logged::State(_) = msg {
            if states_seen == last {
                if from_scheduled {
                    copy.push((t, msg));
                }
                break;
            }
            states_seen += 1;
        }
        if !matches!(msg, Logged::Summary(_)) {
            copy.push((t, msg));
        }
    }
    let checkpoints: Vec<CheckpointHash> = run.states[..last + usize::from(from_scheduled)]
        .iter()
        .map(checkpoint::hash_entry)
        .collect();
    for (i, s) in run.states.iter().enumerate() {
        if checkpoint::state_sha256(s) != s.state_sha256 || s.index as usize != i {
            return Err(unusable(format!(
                "checkpoint {i} does not match its stored hash or index: the file is damaged"
            )));
        }
    }

    let (pool, threads) = crate::run::thread_pool(options.threads)?;
    let job = Job {
        path,
        complete: run.complete,
        resolved: &resolved,
        from: &from,
        from_scheduled,
        checkpoints,
        copy: &copy,
        threads,
        options,
    };
    let result = pool.install(|| match m.dimension {
        3 => resume_in::<3>(job),
        _ => resume_in::<2>(job),
    })?;
    Ok(Resumed {
        result,
        from_checkpoint: from.index,
        from_step: from.step,
        from_time_s: from.time_s,
        copied_messages: copy.len(),
    })
}

struct Job<'a> {
    path: &'a Path,
    complete: bool,
    resolved: &'a Resolved,
    from: &'a StateCheckpoint,
    from_scheduled: bool,
    checkpoints: Vec<CheckpointHash>,
    copy: &'a [(u64, Logged)],
    threads: usize,
    options: &'a ResumeOptions,
}

fn resume_in<const D: usize>(job: Job) -> Result<RunResult, ResumeError> {
    let Job {
        path,
        complete,
        resolved,
        from,
        from_scheduled,
        checkpoints,
        copy,
        threads,
        options,
    } = job;
    let m = &resolved.manifest;
    let unusable = |reason: String| ResumeError::Unusable {
        path: path.to_path_buf(),
        reason,
    };
    let mut solver = restore_solver::<D>(m, from).map_err(unusable)?;

    let dir = path.parent().map_or_else(PathBuf::new, Path::to_path_buf);
    let final_path = output_path(&dir, resolved);
    // A killed run's `.partial` is where the new file is written: move it aside first and
    // delete it only once the new file is finished.
    let source_aside = if path == partial_path(&final_path) {
        let aside = PathBuf::from(format!("{}.resume-source", path.display()));
        std::fs::rename(path, &aside).map_err(|e| unusable(format!("cannot move aside: {e}")))?;
        Some(aside)
    } else {
        None
    };
    let started = std::time::Instant::now();
    // Resuming an interrupted finished file replaces it (atomically, once the new file is
    // finished); any other file of the same name is refused.
    let existing = if path == final_path {
        Existing::Replace
    } else {
        Existing::Refuse
    };
    let mut recorder = Recorder::create_with(
        &final_path,
        &crate::run::run_header(resolved, threads),
        existing,
    )
    .map_err(RunError::from)?;
    crate::run::write_file_records(m, &mut recorder)?;
    let (index, step, time) = (
        from.index.to_string(),
        from.step.to_string(),
        format!("{:e}", from.time_s),
    );
    recorder
        .write_metadata(
            META_RESUMED,
            &[
                ("from_checkpoint", &index),
                ("from_step", &step),
                ("from_time_s", &time),
                (
                    "source_outcome",
                    if complete {
                        "interrupted"
                    } else {
                        "unfinished"
                    },
                ),
            ],
        )
        .map_err(RunError::from)?;
    for (t, msg) in copy {
        match msg {
            Logged::State(s) => recorder.write_state(*t, s),
            Logged::Diagnostics(d) => recorder.write_diagnostics(*t, d),
            Logged::Cloud(c) => recorder.write_cloud(*t, c),
            Logged::Summary(_) => Ok(()),
        }
        .map_err(RunError::from)?;
    }
    let control = LoopControl {
        interrupt: options.interrupt.clone(),
        progress: options.progress.clone(),
        stop_at_step: None,
        rules_during_pour: false,
    };
    let start = LoopStart {
        restored: true,
        checkpoints,
        last_checkpoint_step: from_scheduled.then_some(from.step),
        logged_rows: copy
            .iter()
            .filter_map(|(_, msg)| match msg {
                Logged::Diagnostics(d) => Some(crate::run::logged_row(d)),
                _ => None,
            })
            .collect(),
    };
    let end = time_loop(
        m,
        &resolved.hash_hex,
        &mut solver,
        start,
        &control,
        &mut recorder,
    )?;
    let path = recorder
        .finish(time_ns(solver.time_s), &end.summary, &end.outcome)
        .map_err(RunError::from)?;
    if let Some(aside) = source_aside {
        let _ = std::fs::remove_file(aside);
    }
    Ok(RunResult::new(path, end, started, solver.timing))
}
