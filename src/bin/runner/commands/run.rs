//! `runner MANIFEST` (or `runner run MANIFEST`): one experiment into one run file, or, for a
//! manifest with a `sweep:` section, every point of the sweep (`commands::sweep`).

use super::sweep;
use crate::cli::RunArgs;
use crate::error::{CliError, Done, Result};
use crate::{interrupt, progress};
use mps_runner::experiment;
use mps_runner::manifest::sweep::Plan;
use mps_runner::report::time_text;
use mps_runner::run::{RunOptions, run};

/// Runs the manifest's experiment, prints its outcome line (stderr) and its file (stdout).
/// Exit 0 completed, 3 failed, 130 interrupted; 2 bad manifest or a refused run, 1 a
/// recording that failed.
pub fn command(args: RunArgs) -> Result {
    let Some(path) = args.manifest.clone() else {
        return Err(CliError::BadInput(
            "no manifest given (usage: runner <MANIFEST> [--out DIR] [--set KEY=VALUE]... [--threads N])".to_string(),
        ));
    };
    let resolved = match experiment::load_plan(&path, &args.set)? {
        Plan::Single(_) if args.shard.is_some() => {
            return Err(CliError::BadInput(format!(
                "--shard: {} has no sweep: section (only a sweep's points can be sliced)",
                path.display()
            )));
        }
        Plan::Single(r) => *r,
        Plan::Sweep(s) => return sweep::command(&s, &args),
    };
    let display = progress::Display::new(args.quiet);
    let options = RunOptions {
        out_dir: args.out,
        threads: args.threads,
        progress: display.as_ref().map(|d| d.callback()),
        interrupt: interrupt::flag(),
        max_particles: Some(args.max_particles),
        overwrite: args.overwrite,
    };
    if !args.quiet {
        eprintln!(
            "{}: experiment {} ({}D, spacing {} m, to t = {} s)",
            resolved.manifest.name,
            resolved.hash_hex,
            resolved.manifest.dimension,
            resolved.manifest.spacing_m,
            resolved.manifest.time.end_s
        );
    }
    let result = run(&resolved, &options);
    if let Some(d) = &display {
        d.finish_all();
    }
    let result = result?;
    let metric = |k: &str| result.summary.metrics.get(k).copied().unwrap_or(f64::NAN);
    let steps = metric("steps");
    let particles = metric("particle_count");
    eprintln!(
        "{}: {} after {} steps, t = {} s; {} particles; wall time {:.2} s ({:.0} particle-steps/s)",
        resolved.manifest.name,
        result.outcome.as_str(),
        steps,
        time_text(metric("simulated_time_s")),
        particles,
        result.wall_time_s,
        steps * particles / result.wall_time_s.max(1e-9)
    );
    if !result.summary.reason.is_empty() {
        eprintln!("reason: {}", result.summary.reason);
    }
    if !result.stop_reason.is_empty() {
        eprintln!("stopped: {}", result.stop_reason);
    }
    println!("{}", result.path.display());
    Ok(Done::of(&result.outcome))
}
