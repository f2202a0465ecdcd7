//! One run: manifest -> test module (scene) -> solver -> MCAP recording.
//!
//! `mps/` does one step of the method; this module owns the process around it, in three
//! parts: [`config`] (the solver's configuration from the manifest), [`driver`] (the time loop:
//! output schedules, checkpoints, stop conditions, outcome) and [`frames`] (what one step
//! records: diagnostics rows and point clouds).
pub mod config;
pub mod driver;
pub mod frames;

pub use config::{rheology, solver_config};
pub use driver::{
    LoopControl, LoopEnd, LoopStart, POURED, Progress, ProgressFn, Sink, rules_during_pour,
    time_loop,
};
pub use frames::time_ns;

use crate::experiment::{Resolved, build_scene};
use crate::mps::{Solver, StageTimes};
use crate::proto::mps::v1::Summary;
use crate::record::{Existing, Outcome, RecordError, Recorder, RunHeader};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// How to run (never part of the experiment: none of it changes the state bits).
#[derive(Clone, Default)]
pub struct RunOptions {
    pub out_dir: PathBuf,
    /// Worker threads; None = all cores.
    pub threads: Option<usize>,
    /// Told where the run stands after every step.
    pub progress: Option<ProgressFn>,
    /// Set from outside (signal handler) to stop the run cleanly as "interrupted".
    pub interrupt: Option<Arc<AtomicBool>>,
    /// Refuse a run whose scene is estimated to hold more particles than this, before
    /// anything is allocated or written ([`crate::experiment::estimate_particles`]); None =
    /// no limit.
    pub max_particles: Option<u64>,
    /// Replace the run's file (and a killed run's `.partial`) if it exists; the default
    /// refuses ([`Recorder::create`]).
    pub overwrite: bool,
}

/// What a finished run produced.
#[derive(Debug, Clone)]
pub struct RunResult {
    pub path: PathBuf,
    pub outcome: Outcome,
    pub summary: Summary,
    /// See [`LoopEnd::stop_reason`].
    pub stop_reason: String,
    /// Wall-clock seconds of the time loop (reported, never recorded).
    pub wall_time_s: f64,
    /// Wall-clock seconds per solver stage (reported, never recorded).
    pub timing: StageTimes,
}

impl RunResult {
    /// The result of a time loop that ended as `end`, its file finished at `path`.
    pub fn new(
        path: PathBuf,
        end: LoopEnd,
        started: std::time::Instant,
        timing: StageTimes,
    ) -> Self {
        RunResult {
            path,
            outcome: end.outcome,
            summary: end.summary,
            stop_reason: end.stop_reason,
            wall_time_s: started.elapsed().as_secs_f64(),
            timing,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("cannot create output directory {path}: {source}")]
    OutDir {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot start {threads} worker threads: {message}")]
    Threads { threads: usize, message: String },
    #[error(
        "the run would hold about {particles:.3e} particles (about {memory_gb:.1} GB of memory), more than --max-particles = {limit}: use a coarser spacing_m, or raise --max-particles if the machine has the memory"
    )]
    TooLarge {
        particles: f64,
        memory_gb: f64,
        limit: u64,
    },
    #[error(transparent)]
    Record(#[from] RecordError),
}

/// A logged diagnostics row as (time, experiment metrics), for [`LoopStart::logged_rows`].
pub fn logged_row(
    d: &crate::proto::mps::v1::Diagnostics,
) -> (f64, std::collections::BTreeMap<String, f64>) {
    (d.time_s, d.metrics.clone().into_iter().collect())
}

/// File name of a run: `<name>-<first 12 hex of the experiment hash>.mcap`.
pub fn output_path(out_dir: &Path, resolved: &Resolved) -> PathBuf {
    out_dir.join(format!(
        "{}-{}.mcap",
        resolved.manifest.name,
        resolved.short_hash()
    ))
}

/// Refuses a scene estimated ([`crate::experiment::estimate_particles`]) to hold more than
/// `limit` particles, before anything is built.
pub fn check_size(m: &crate::experiment::Manifest, limit: u64) -> Result<(), RunError> {
    let particles = crate::experiment::estimate_particles(m);
    if particles > limit as f64 {
        // Measured peak memory per particle: 1.5 kB in 2D (dam break, 35 k and 49 k
        // particles), 1.6 kB in 3D (slump, 35 k); 4 kB covers 3D scenes of more fluid.
        let per_particle = if m.dimension == 3 { 4e3 } else { 1.5e3 };
        return Err(RunError::TooLarge {
            particles,
            memory_gb: particles * per_particle / 1e9,
            limit,
        });
    }
    Ok(())
}

/// Runs the experiment and records it. A simulation that fails (blow-up, solver failure) or
/// is interrupted still yields a finished MCAP file whose outcome says so: that is an `Ok`
/// with a non-completed `outcome`. `Err` means the recording itself could not be made.
pub fn run(resolved: &Resolved, options: &RunOptions) -> Result<RunResult, RunError> {
    if let Some(limit) = options.max_particles {
        check_size(&resolved.manifest, limit)?;
    }
    std::fs::create_dir_all(&options.out_dir).map_err(|source| RunError::OutDir {
        path: options.out_dir.clone(),
        source,
    })?;
    let (pool, threads) = thread_pool(options.threads)?;
    pool.install(|| match resolved.manifest.dimension {
        3 => run_in::<3>(resolved, options, threads),
        _ => run_in::<2>(resolved, options, threads),
    })
}

/// A worker pool of `threads` threads (None = all cores), and its size. The split of the work
/// never depends on it (docs/design.md section 6).
pub fn thread_pool(threads: Option<usize>) -> Result<(rayon::ThreadPool, usize), RunError> {
    let threads =
        threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| RunError::Threads {
            threads,
            message: e.to_string(),
        })?;
    Ok((pool, threads))
}

/// What a run file records about its experiment (the same for a run and its resumption).
pub fn run_header(resolved: &Resolved, threads: usize) -> RunHeader<'_> {
    RunHeader {
        manifest_source: &resolved.source_text,
        overrides: &resolved.overrides,
        canonical: &resolved.canonical,
        experiment_sha256: &resolved.hash_hex,
        name: &resolved.manifest.name,
        default_preset: resolved.default_preset.map(|p| p.name()),
        preset_revision: Some(resolved.preset_revision),
        threads,
    }
}

/// The test's own metadata records ([`crate::experiment::file_records`]).
pub fn write_file_records(
    m: &crate::experiment::Manifest,
    recorder: &mut Recorder,
) -> Result<(), RunError> {
    for (name, entries) in crate::experiment::file_records(m) {
        let entries: Vec<(&str, &str)> = entries.iter().map(|(k, v)| (*k, v.as_str())).collect();
        recorder.write_metadata(name, &entries)?;
    }
    Ok(())
}

fn run_in<const D: usize>(
    resolved: &Resolved,
    options: &RunOptions,
    threads: usize,
) -> Result<RunResult, RunError> {
    let m = &resolved.manifest;
    let scene = build_scene::<D>(m);
    let config = solver_config(m, &scene);
    let mut solver = Solver::new(config, scene.particles);
    let path = output_path(&options.out_dir, resolved);
    let existing = if options.overwrite {
        Existing::Replace
    } else {
        Existing::Refuse
    };
    let mut recorder = Recorder::create_with(&path, &run_header(resolved, threads), existing)?;
    write_file_records(m, &mut recorder)?;
    let started = std::time::Instant::now();
    let control = LoopControl {
        interrupt: options.interrupt.clone(),
        progress: options.progress.clone(),
        stop_at_step: None,
        rules_during_pour: false,
    };
    let end = time_loop(
        m,
        &resolved.hash_hex,
        &mut solver,
        LoopStart::default(),
        &control,
        &mut recorder,
    )?;
    let path = recorder.finish(time_ns(solver.time_s), &end.summary, &end.outcome)?;
    Ok(RunResult::new(path, end, started, solver.timing))
}
