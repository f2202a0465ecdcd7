//! Running an expanded sweep: every point into one folder, points run concurrently.
//!
//! `workers` threads each take the next point in expansion order and run it with
//! `threads: Some(1)`. Each run is deterministic and independent of the thread count, so the
//! files do not depend on the scheme; only the order in which points finish does.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::experiment::Sweep;
use crate::run::{RunError, RunOptions, RunResult, run};

/// How to run a sweep.
#[derive(Debug, Clone, Default)]
pub struct SweepOptions {
    /// Parent directory; the sweep writes into `out_dir/<Sweep::folder_name>`.
    pub out_dir: PathBuf,
    /// Concurrent points; None = all cores (at most the number of points).
    pub workers: Option<usize>,
    /// Passed to every run (set from a signal handler to interrupt them all).
    pub interrupt: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Passed to every run (see [`RunOptions::max_particles`]).
    pub max_particles: Option<u64>,
    /// Passed to every run (see [`RunOptions::overwrite`]).
    pub overwrite: bool,
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
}

/// The sweep's output folder.
pub fn sweep_dir(out_dir: &Path, sweep: &Sweep) -> PathBuf {
    out_dir.join(sweep.folder_name())
}

/// Runs every point of `sweep`; `on_done` is called (from a worker thread, one call at a
/// time) as each point finishes. Returns the folder and the outcomes in expansion order.
pub fn run_sweep(
    sweep: &Sweep,
    options: &SweepOptions,
    on_done: &(dyn Fn(&PointOutcome) + Sync),
) -> (PathBuf, Vec<PointOutcome>) {
    let dir = sweep_dir(&options.out_dir, sweep);
    let n = sweep.points.len();
    let workers = options
        .workers
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, n.max(1));
    let next = AtomicUsize::new(0);
    let done: Mutex<Vec<PointOutcome>> = Mutex::new(Vec::with_capacity(n));
    let run_options = RunOptions {
        out_dir: dir.clone(),
        threads: Some(1),
        progress: false,
        interrupt: options.interrupt.clone(),
        max_particles: options.max_particles,
        overwrite: options.overwrite,
    };
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| {
                loop {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    let Some(point) = sweep.points.get(index) else {
                        break;
                    };
                    let outcome = PointOutcome {
                        index,
                        label: point.label(),
                        result: run(&point.resolved, &run_options),
                    };
                    let mut done = done.lock().unwrap_or_else(|e| e.into_inner());
                    on_done(&outcome);
                    done.push(outcome);
                }
            });
        }
    });
    let mut outcomes = done.into_inner().unwrap_or_else(|e| e.into_inner());
    outcomes.sort_by_key(|o| o.index);
    (dir, outcomes)
}
