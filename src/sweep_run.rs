//! Running an expanded sweep: every point into one folder, points run concurrently.
//!
//! `workers` threads each take the next point in expansion order and run it with
//! `threads: Some(1)`. Each run is deterministic and independent of the thread count, so the
//! files do not depend on the scheme; only the order in which points finish does.
//!
//! A sweep run again into its folder picks up where it was: a point whose finished file is
//! there (completed or failed: a replay would fail the same way) is taken as it is, an
//! interrupted one or a killed one's `.partial` is resumed ([`crate::resume`]), the rest run.
//! `overwrite` runs every point again.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::experiment::{Resolved, Sweep};
use crate::record::{Outcome, RecordError, partial_path, read_run};
use crate::resume::{ResumeError, ResumeOptions, resume};
use crate::run::{RunError, RunOptions, RunResult, output_path, run};

/// How to run a sweep.
#[derive(Clone, Default)]
pub struct SweepOptions {
    /// Passed to every run: told where each stands after every step (the run's label tells
    /// the concurrent points apart).
    pub progress: Option<crate::run::ProgressFn>,
    /// Parent directory; the sweep writes into `out_dir/<Sweep::folder_name>`.
    pub out_dir: PathBuf,
    /// Concurrent points; None = all cores (at most the number of points).
    pub workers: Option<usize>,
    /// Passed to every run (set from a signal handler to interrupt them all).
    pub interrupt: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Passed to every run (see [`RunOptions::max_particles`]).
    pub max_particles: Option<u64>,
    /// Run every point again, replacing its file (see [`RunOptions::overwrite`]); the default
    /// takes finished points as they are and resumes interrupted ones.
    pub overwrite: bool,
    /// Run one slice of the points only (see [`Shard`]); None = all.
    pub shard: Option<Shard>,
}

/// Slice `index` (1-based) of `count`: the points whose expansion index k has
/// k mod count = index - 1. The slices of 1..=count together are every point once, and each
/// point's file is the same whichever slice ran it (the sweep folder does not depend on it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Parses `I/N` with 1 <= I <= N.
    pub fn parse(text: &str) -> Result<Self, String> {
        let (i, n) = text
            .split_once('/')
            .ok_or_else(|| format!("expected I/N (e.g. 2/8), got `{text}`"))?;
        let number = |s: &str| {
            s.trim()
                .parse::<usize>()
                .map_err(|_| format!("expected I/N with whole numbers, got `{text}`"))
        };
        let (index, count) = (number(i)?, number(n)?);
        if count == 0 || index == 0 || index > count {
            return Err(format!("expected 1 <= I <= N, got {index}/{count}"));
        }
        Ok(Self { index, count })
    }

    /// From a Slurm job array: task `SLURM_ARRAY_TASK_ID` (counted from
    /// `SLURM_ARRAY_TASK_MIN`, default 0) of `SLURM_ARRAY_TASK_COUNT`; None when not in one.
    pub fn from_slurm(env: impl Fn(&str) -> Option<String>) -> Result<Option<Self>, String> {
        let (Some(id), Some(count)) = (env("SLURM_ARRAY_TASK_ID"), env("SLURM_ARRAY_TASK_COUNT"))
        else {
            return Ok(None);
        };
        let min = env("SLURM_ARRAY_TASK_MIN").unwrap_or_else(|| "0".into());
        let number = |name: &str, s: &str| {
            s.trim()
                .parse::<usize>()
                .map_err(|_| format!("{name} = `{s}` is not a whole number"))
        };
        let (id, count, min) = (
            number("SLURM_ARRAY_TASK_ID", &id)?,
            number("SLURM_ARRAY_TASK_COUNT", &count)?,
            number("SLURM_ARRAY_TASK_MIN", &min)?,
        );
        if id < min || id - min >= count {
            return Err(format!(
                "SLURM_ARRAY_TASK_ID = {id} is not one of the {count} tasks from SLURM_ARRAY_TASK_MIN = {min} (the array must be contiguous, e.g. --array=0-{})",
                count.saturating_sub(1)
            ));
        }
        Ok(Some(Self {
            index: id - min + 1,
            count,
        }))
    }

    /// Whether the point at expansion index `k` is in this slice.
    pub fn has(&self, k: usize) -> bool {
        k % self.count == self.index - 1
    }
}

/// How a point's result came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointStart {
    /// Run from its initial state.
    Ran,
    /// Its finished file was already in the folder (from an earlier run of the sweep).
    Existing,
    /// Resumed from the last checkpoint of an interrupted or killed run of it.
    Resumed,
}

impl PointStart {
    /// `ran`, `existing` or `resumed` (as recorded in a calibration's record).
    pub fn as_str(self) -> &'static str {
        match self {
            PointStart::Ran => "ran",
            PointStart::Existing => "existing",
            PointStart::Resumed => "resumed",
        }
    }
}

/// How one point ended.
#[derive(Debug)]
pub struct PointOutcome {
    /// Index in expansion order.
    pub index: usize,
    /// `key=value ...` of the point.
    pub label: String,
    /// The run (its outcome may be failed or interrupted), or why no file could be made.
    pub result: Result<RunResult, RunError>,
    pub start: PointStart,
}

/// The sweep's output folder.
pub fn sweep_dir(out_dir: &Path, sweep: &Sweep) -> PathBuf {
    out_dir.join(sweep.folder_name())
}

/// Runs every point of `sweep` (of its [`SweepOptions::shard`]); `on_done` is called (from a worker thread, one call at a
/// time) as each point finishes. Returns the folder and the outcomes in expansion order.
pub fn run_sweep(
    sweep: &Sweep,
    options: &SweepOptions,
    on_done: &(dyn Fn(&PointOutcome) + Sync),
) -> (PathBuf, Vec<PointOutcome>) {
    let dir = sweep_dir(&options.out_dir, sweep);
    let mine: Vec<usize> = (0..sweep.points.len())
        .filter(|&k| options.shard.is_none_or(|s| s.has(k)))
        .collect();
    let n = mine.len();
    let workers = options
        .workers
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, n.max(1));
    let run_options = RunOptions {
        out_dir: dir.clone(),
        threads: Some(1),
        progress: options.progress.clone(),
        interrupt: options.interrupt.clone(),
        max_particles: options.max_particles,
        overwrite: options.overwrite,
    };
    let points: Vec<&Resolved> = mine.iter().map(|&k| &sweep.points[k].resolved).collect();
    let outcomes = run_points(&points, &run_options, workers, &|k, result, start| {
        let index = mine[k];
        let outcome = PointOutcome {
            index,
            label: sweep.points[index].label(),
            result,
            start,
        };
        on_done(&outcome);
        outcome
    });
    (dir, outcomes)
}

/// Runs `points` with [`run_point`] on `workers` threads, each taking the next point in
/// order. `finish(k, result, start)` is called as point `k` finishes, one call at a time;
/// its values come back in the order of `points`.
pub(crate) fn run_points<T: Send>(
    points: &[&Resolved],
    options: &RunOptions,
    workers: usize,
    finish: &(dyn Fn(usize, Result<RunResult, RunError>, PointStart) -> T + Sync),
) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let done: Mutex<Vec<(usize, T)>> = Mutex::new(Vec::with_capacity(points.len()));
    std::thread::scope(|s| {
        for _ in 0..workers.clamp(1, points.len().max(1)) {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(resolved) = points.get(k) else {
                        break;
                    };
                    let (result, start) = run_point(resolved, options);
                    let mut done = done.lock().unwrap_or_else(|e| e.into_inner());
                    let value = finish(k, result, start);
                    done.push((k, value));
                }
            });
        }
    });
    let mut done = done.into_inner().unwrap_or_else(|e| e.into_inner());
    done.sort_by_key(|(k, _)| *k);
    done.into_iter().map(|(_, v)| v).collect()
}

/// One point: its finished file taken as it is, an interrupted or killed run of it resumed,
/// or a run (see the module documentation).
pub(crate) fn run_point(
    resolved: &Resolved,
    options: &RunOptions,
) -> (Result<RunResult, RunError>, PointStart) {
    let path = output_path(&options.out_dir, resolved);
    let partial = partial_path(&path);
    if options.overwrite {
        return (run(resolved, options), PointStart::Ran);
    }
    let resume_from = |source: &std::path::Path| {
        let resume_options = ResumeOptions {
            threads: options.threads,
            progress: options.progress.clone(),
            interrupt: options.interrupt.clone(),
        };
        let result = match resume(source, &resume_options) {
            Ok(r) => Ok(r.result),
            Err(ResumeError::Run(e)) => Err(e),
            Err(ResumeError::Unusable { path, reason }) => {
                Err(RunError::Record(RecordError::Invalid { path, reason }))
            }
        };
        (result, PointStart::Resumed)
    };
    if let Ok(file) = read_run(&path)
        && file.complete
        && let Some(summary) = file.summary
        && summary.experiment_sha256 == resolved.hash_hex
    {
        let outcome = match summary.outcome.as_str() {
            "completed" => Outcome::Completed,
            "failed" => Outcome::Failed(summary.reason.clone()),
            _ => return resume_from(&path),
        };
        let result = RunResult {
            path,
            outcome,
            stop_reason: summary.stop.clone(),
            summary,
            wall_time_s: 0.0,
            timing: Default::default(),
        };
        return (Ok(result), PointStart::Existing);
    }
    if partial.exists() && !path.exists() {
        return resume_from(&partial);
    }
    // Nothing usable there: run (a damaged file of the same name is refused, not replaced).
    (run(resolved, options), PointStart::Ran)
}
