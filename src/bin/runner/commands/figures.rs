//! The commands that draw: `plot`, `plot-sweep`, `snapshot`, `profile` and `report` (from run
//! files) and `draw` (the scene a manifest starts from). Each prints the files it wrote;
//! exit 1 when writing failed, 2 for anything else in the way.

use crate::cli::{DrawArgs, PlotArgs, PlotSweepArgs, ProfileArgs, ReportArgs, SnapshotArgs};
use crate::error::{CliError, Done, Result};
use crate::run_file::readable_run;
use mps_runner::{experiment, report};
use std::path::PathBuf;

/// `runner plot`: diagnostics quantities of one run against time (or another quantity).
pub fn plot(args: PlotArgs) -> Result {
    readable_run(&args.run)?;
    let path = report::plot_run(
        &args.run,
        &args.metric,
        args.x.as_deref(),
        args.out.as_deref(),
    )?;
    Ok(print_paths([path]))
}

/// `runner plot-sweep`: a summary metric of every run in a folder against a manifest value.
pub fn plot_sweep(args: PlotSweepArgs) -> Result {
    let plot = report::plot_sweep(
        &args.dir,
        &args.x,
        &args.y,
        args.group.as_deref(),
        args.out.as_deref(),
    )?;
    for (file, why) in &plot.skipped {
        eprintln!("skipped {}: {why}", file.display());
    }
    Ok(print_paths([plot.path]))
}

/// `runner snapshot`: one particle frame of a run, coloured by a point field.
pub fn snapshot(args: SnapshotArgs) -> Result {
    readable_run(&args.run)?;
    let path = report::snapshot(
        &args.run,
        args.field.as_deref(),
        args.top,
        args.time,
        args.out.as_deref(),
    )?;
    Ok(print_paths([path]))
}

/// `runner profile`: the free surface against its closed form, as a table (stdout) and a
/// figure; several runs of one test in one figure.
pub fn profile(args: ProfileArgs) -> Result {
    for run in &args.runs {
        readable_run(run)?;
    }
    let (path, table) = match args.runs.as_slice() {
        [run] => report::profile(run, args.out.as_deref()),
        runs => report::profiles(runs, args.out.as_deref()),
    }?;
    print!("{table}");
    Ok(print_paths([path]))
}

/// `runner report`: the PNG figures and the HTML page of a run or a sweep folder; prints the
/// page's path.
pub fn page(args: ReportArgs) -> Result {
    if !args.path.is_dir() {
        readable_run(&args.path)?;
    }
    let options = report::page::ReportOptions {
        out: args.out,
        times_s: args.times,
        field: args.field,
        keep_svg: args.svg,
    };
    let made = report::page::report(&args.path, &options)?;
    for why in &made.skipped {
        eprintln!("left out: {why}");
    }
    eprintln!("{} figure(s) in {}", made.figures.len(), made.dir.display());
    Ok(print_paths([made.page]))
}

/// `runner draw`: the particle set a manifest starts from, as sections.
pub fn draw(args: DrawArgs) -> Result {
    let resolved = experiment::load(&args.manifest, &args.set)?;
    let m = &resolved.manifest;
    mps_runner::run::check_size(m, args.max_particles)?;
    for (name, v) in [("--at-y", args.at_y), ("--at-z", args.at_z)] {
        if v.is_some_and(|v| !v.is_finite()) {
            return Err(CliError::BadInput(format!(
                "{name} must be a finite number"
            )));
        }
    }
    let paths = report::draw_scene(m, args.at_y, args.at_z, &args.out)?;
    Ok(print_paths(paths))
}

/// Prints the files written, one a line.
fn print_paths(paths: impl IntoIterator<Item = PathBuf>) -> Done {
    for path in paths {
        println!("{}", path.display());
    }
    Done::Success
}
