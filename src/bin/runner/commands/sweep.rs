//! A manifest with a `sweep:` section, run: every point (or one slice of them) into the
//! sweep folder, one line per finished point, then the sweep plots.

use crate::cli::{RunArgs, threads_or_cores};
use crate::error::{CliError, Done, Result};
use crate::{interrupt, progress};
use mps_runner::experiment::Sweep;
use mps_runner::manifest::sweep::Axis;
use mps_runner::record::Outcome;
use mps_runner::report;
use mps_runner::sweep_run::{PointOutcome, PointStart, Shard, SweepOptions, run_sweep};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Runs every point of a sweep (points concurrently, one thread each; `--threads` caps the
/// concurrent points), prints one line per finished point, plots the results into the sweep
/// folder, and prints the folder last. Exit 0 when every point completed, 3 when any failed,
/// 1 when a file could not be written, 130 when interrupted.
pub fn command(s: &Sweep, args: &RunArgs) -> Result {
    let shard = match args.shard {
        Some(shard) => Some(shard),
        None => Shard::from_slurm(|k| std::env::var(k).ok())
            .map_err(|e| CliError::BadInput(format!("--shard from the Slurm job array: {e}")))?,
    };
    let total = (0..s.points.len())
        .filter(|&k| shard.is_none_or(|sh| sh.has(k)))
        .count();
    if !args.quiet {
        eprintln!(
            "{}: sweep {} of {} points over {}{}",
            s.name,
            s.hash_hex,
            s.points.len(),
            s.axes
                .iter()
                .map(|a| a.key.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            match shard {
                Some(sh) => format!(
                    "; slice {}/{} ({}): {total} of them",
                    sh.index,
                    sh.count,
                    if args.shard.is_some() {
                        "--shard"
                    } else {
                        "Slurm job array"
                    }
                ),
                None => String::new(),
            }
        );
    }
    let display = progress::Display::for_sweep(args.quiet, total);
    let workers = threads_or_cores(args.threads).clamp(1, total.max(1));
    let finished = AtomicUsize::new(0);
    let options = SweepOptions {
        progress: display.as_ref().map(|d| d.callback()),
        out_dir: args.out.clone(),
        workers: args.threads,
        interrupt: interrupt::flag(),
        max_particles: Some(args.max_particles),
        overwrite: args.overwrite,
        shard,
    };
    let on_done = |o: &PointOutcome| {
        let print = || print_point(o, total, args.quiet);
        match &display {
            Some(d) => {
                if let Ok(r) = &o.result
                    && let Some(stem) = r.path.file_stem()
                {
                    d.finished(&stem.to_string_lossy());
                }
                d.suspend(print);
                let done = finished.fetch_add(1, Ordering::Relaxed) + 1;
                d.point_done(done, total, workers);
            }
            None => print(),
        }
    };
    let (dir, outcomes) = run_sweep(s, &options, &on_done);
    if let Some(d) = &display {
        d.finish_all();
    }

    if shard.is_some() && !args.quiet {
        eprintln!(
            "no sweep plots for a slice: once every slice is done, `runner report DIR` (or `runner plot-sweep`) plots the whole sweep"
        );
    }
    if shard.is_none() {
        plot(s, &dir, &outcomes, args);
    }

    println!("{}", dir.display());
    // Each point's error was printed on its line: only its exit code is left.
    let mut done = Done::Success;
    for o in &outcomes {
        match &o.result {
            Ok(r) => match r.outcome {
                Outcome::Completed => {}
                Outcome::Failed(_) => done = Done::SimFailed,
                Outcome::Interrupted(_) => return Ok(Done::Interrupted),
            },
            Err(e) => return Err(CliError::reported(e)),
        }
    }
    Ok(done)
}

/// The sweep plots: x = the first numeric axis, groups = the other axes' values; y = each
/// `--plot-y` metric, or by default every summary metric that is not bookkeeping. Not for a
/// slice: slices finishing together would write the same plot files.
fn plot(s: &Sweep, dir: &std::path::Path, outcomes: &[PointOutcome], args: &RunArgs) {
    let numeric = |a: &Axis| a.values.iter().all(serde_json::Value::is_number);
    let Some(x) = s.axes.iter().find(|a| numeric(a)) else {
        return;
    };
    let others: Vec<&str> = s
        .axes
        .iter()
        .filter(|a| a.key != x.key)
        .map(|a| a.key.as_str())
        .collect();
    let metrics = if args.plot_y.is_empty() {
        outcomes
            .iter()
            .find_map(|o| o.result.as_ref().ok())
            .map(|r| report::default_sweep_metrics(&r.summary.metrics))
            .unwrap_or_default()
    } else {
        args.plot_y.clone()
    };
    // Only one grouping key fits a legend: group by the first other axis.
    let group = others.first().copied();
    for y in metrics {
        match report::plot_sweep(dir, &x.key, &y, group, None) {
            Ok(p) => {
                if !args.quiet {
                    eprintln!("plot: {}", p.path.display());
                }
            }
            Err(e) => eprintln!("warning: no sweep plot of {y}: {e}"),
        }
    }
}

/// The line of a finished sweep point: `[i/n] KEY=VALUE... OUTCOME PATH` on stdout; the
/// reason of a failure or a stop on stderr.
fn print_point(o: &PointOutcome, total: usize, quiet: bool) {
    match &o.result {
        Ok(r) => {
            let start = match o.start {
                PointStart::Ran => "",
                PointStart::Existing => " (its file was there)",
                PointStart::Resumed => " (resumed)",
            };
            println!(
                "[{}/{total}] {} {} {}{start}",
                o.index + 1,
                o.label,
                r.outcome.as_str(),
                r.path.display()
            );
            if !r.summary.reason.is_empty() && !quiet {
                eprintln!("[{}/{total}] reason: {}", o.index + 1, r.summary.reason);
            }
            if !r.stop_reason.is_empty() && !quiet {
                eprintln!("[{}/{total}] stopped: {}", o.index + 1, r.stop_reason);
            }
            // The file holds no wall time (nothing in it depends on the machine's speed).
            if o.start != PointStart::Existing && !quiet {
                eprintln!(
                    "[{}/{total}] wall time {:.1} s{}",
                    o.index + 1,
                    r.wall_time_s,
                    if o.start == PointStart::Resumed {
                        " (this session)"
                    } else {
                        ""
                    }
                );
            }
        }
        Err(e) => println!("[{}/{total}] {} error {e}", o.index + 1, o.label),
    }
}
