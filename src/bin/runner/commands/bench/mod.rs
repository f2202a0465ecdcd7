//! `runner bench MANIFEST`: one run (recorded as usual), then particle-steps per second and
//! where the wall time went; `runner bench --suite FILE`: the benchmark suite (`suite`).

mod suite;

use crate::cli::{BenchArgs, DEFAULT_MAX_PARTICLES, threads_or_cores};
use crate::error::{CliError, Done, Result};
use crate::interrupt;
use mps_runner::experiment;
use mps_runner::manifest::sweep::Plan;
use mps_runner::report::time_text;
use mps_runner::run::{RunOptions, RunResult, run};
use std::path::{Path, PathBuf};

pub fn command(args: BenchArgs) -> Result {
    match (args.suite, args.manifest) {
        (Some(suite), _) => suite::command(suite::SuiteArgs {
            suite,
            quick: args.quick,
            runner: args.runner,
            threads: args.threads,
            markdown: args.markdown,
            cases: args.cases,
        }),
        (None, Some(manifest)) => one(&manifest, &args.set, args.threads, args.out),
        (None, None) => unreachable!("clap requires MANIFEST without --suite"),
    }
}

/// One run, then particle-steps per second and the wall time by solver stage.
fn one(path: &Path, set: &[String], threads: Option<usize>, out: Option<PathBuf>) -> Result {
    let resolved = match experiment::load_plan(path, set)? {
        Plan::Single(r) => *r,
        Plan::Sweep(_) => {
            return Err(CliError::BadInput(
                "runner bench takes a single experiment, not a sweep".to_string(),
            ));
        }
    };
    let temporary = out.is_none();
    let out_dir = out
        .unwrap_or_else(|| std::env::temp_dir().join(format!("mps_bench-{}", std::process::id())));
    let options = RunOptions {
        out_dir: out_dir.clone(),
        threads,
        progress: None,
        interrupt: interrupt::flag(),
        max_particles: Some(DEFAULT_MAX_PARTICLES),
        // A benchmark measures; its file is a by-product, replaced by the next one.
        overwrite: true,
    };
    let result = run(&resolved, &options)?;
    let metric = |k: &str| result.summary.metrics.get(k).copied().unwrap_or(f64::NAN);
    let (steps, particles) = (metric("steps"), metric("particle_count"));
    let wall = result.wall_time_s.max(1e-12);
    // The suite reads these two lines back (`suite::child`): keep their form.
    println!(
        "{} ({}D, spacing {} m): {} particles ({} fluid), {} steps to t = {} s, {} threads",
        resolved.manifest.name,
        resolved.manifest.dimension,
        resolved.manifest.spacing_m,
        particles,
        metric("fluid_particle_count"),
        steps,
        time_text(metric("simulated_time_s")),
        threads_or_cores(threads)
    );
    println!(
        "outcome {}; wall time {:.3} s; {:.0} particle-steps/s",
        result.outcome.as_str(),
        wall,
        steps * particles / wall
    );
    print_stages(&result, steps, wall);
    if temporary {
        let _ = std::fs::remove_dir_all(&out_dir);
    } else {
        println!("{}", result.path.display());
    }
    Ok(Done::of(&result.outcome))
}

/// The table of where the wall time went: solver stages, then recording and output.
fn print_stages(result: &RunResult, steps: f64, wall: f64) {
    let t = &result.timing;
    let recording = ("recording and output".to_string(), wall - t.step_total_s);
    let rows = t.stage_rows(steps).into_iter().chain([recording]);
    println!("{:<46} {:>9} {:>7}", "stage", "seconds", "share");
    for (name, seconds) in rows {
        println!("{name:<46} {seconds:>9.3} {:>6.1}%", 100.0 * seconds / wall);
    }
}
