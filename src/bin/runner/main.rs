//! `runner`: the command line. Parses arguments, calls the library, and is the only place
//! that turns results into exit codes: 0 success, 1 internal or I/O error, 2 bad input (CLI,
//! manifest, or a run file that is unreadable, incomplete or damaged), 3 simulation failed,
//! 130 interrupted. `runner verify`: 0 identical, 1 not, 2 the file cannot be used.

/// `print!` and `println!` for this binary: standard output whose reader has gone (`runner
/// RUN | head -1`) is no error of ours, so a closed pipe is ignored rather than a panic (std's
/// macros panic) and the command finishes its work and its exit code; any other failure to
/// write still panics as std's would. Defined before the modules so they use it too.
macro_rules! print {
    ($($arg:tt)*) => {
        $crate::write_stdout(::std::format_args!($($arg)*))
    };
}
macro_rules! println {
    () => {
        print!("\n")
    };
    ($($arg:tt)*) => {
        print!("{}\n", ::std::format_args!($($arg)*))
    };
}

fn write_stdout(args: std::fmt::Arguments) {
    use std::io::Write;
    match std::io::stdout().lock().write_fmt(args) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            panic!("failed printing to stdout: {e}")
        }
        _ => {}
    }
}

mod bench_suite;
mod progress;

use clap::{Parser, Subcommand};
use mps_runner::experiment;
use mps_runner::manifest::sweep;
use mps_runner::record::{Outcome, RecordError};
use mps_runner::report;
use mps_runner::report::time_text;
use mps_runner::resume::{ResumeError, ResumeOptions, resume};
use mps_runner::run::{RunError, RunOptions, run};
use mps_runner::sweep_run::{PointStart, SweepOptions, run_sweep};
use mps_runner::verify::trend::{TrendOptions, trend};
use mps_runner::verify::{VerifyOptions, verify};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

const EXIT_INTERNAL: u8 = 1;
/// `--max-particles` default: about 7.5 GB in 2D, 20 GB in 3D (see `run::run`).
const DEFAULT_MAX_PARTICLES: u64 = 5_000_000;
/// `runner verify`: the replay differs from the file (or the trend does not hold).
const EXIT_MISMATCH: u8 = 1;
const EXIT_BAD_INPUT: u8 = 2;
const EXIT_SIM_FAILED: u8 = 3;
const EXIT_INTERRUPTED: u8 = 130;

#[derive(Parser, Debug)]
#[command(
    name = "runner",
    version,
    about = "Run an MPS experiment manifest and record it into one MCAP file",
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Experiment manifest (YAML).
    manifest: Option<PathBuf>,
    /// Output directory for the MCAP file.
    #[arg(long, default_value = "runs")]
    out: PathBuf,
    /// Override a manifest field before validation and hashing, e.g. --set spacing_m=0.02
    /// (repeatable; dotted paths).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Worker threads (default: all cores). Results are bitwise identical for any count.
    #[arg(long, value_parser = threads_arg)]
    threads: Option<usize>,
    /// Refuse a run whose scene is estimated to hold more particles than this (checked
    /// before anything is allocated or written).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_PARTICLES)]
    max_particles: u64,
    /// No progress lines on stderr.
    #[arg(long, short)]
    quiet: bool,
    /// Run even if this experiment's file (or a killed run's .partial) is already in the
    /// output folder, and replace it once the new file is finished (default: refuse, exit 2).
    #[arg(long)]
    overwrite: bool,
    /// Sweeps only: summary metric(s) to plot into the sweep folder (repeatable; default:
    /// every summary metric that is not a count or bookkeeping).
    #[arg(long = "plot-y", value_name = "METRIC")]
    plot_y: Vec<String>,
    /// Sweeps only: run slice I of N (the points whose index k has k mod N = I - 1) into the
    /// same sweep folder; default in a Slurm job array: SLURM_ARRAY_TASK_ID (from
    /// SLURM_ARRAY_TASK_MIN) of SLURM_ARRAY_TASK_COUNT. A sliced run draws no sweep plots.
    #[arg(long, value_name = "I/N", value_parser = mps_runner::sweep_run::Shard::parse)]
    shard: Option<mps_runner::sweep_run::Shard>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run an experiment manifest: the same as `runner MANIFEST [OPTIONS]`
    Run(RunArgs),
    /// Draw the particle set a manifest starts from (walls, dummies, fluid, inlets) as
    /// sections, SVG: in 3D through y = AT_Y from the side and through z = AT_Z from above,
    /// in 2D the plane; prints the files written.
    Draw {
        manifest: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// 3D: the side section's plane y, metres (default: the middle of the scene).
        #[arg(long, value_name = "M")]
        at_y: Option<f64>,
        /// 3D: the top section's plane z, metres (default: a quarter of the way up the scene).
        #[arg(long, value_name = "M")]
        at_z: Option<f64>,
        /// Folder for the SVG files (<name>-scene-side.svg, <name>-scene-top.svg).
        #[arg(long, default_value = ".")]
        out: PathBuf,
        /// Refuse a scene estimated to hold more particles than this (before it is built).
        #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_PARTICLES)]
        max_particles: u64,
    },
    /// Print the SHA-256 experiment hash of a manifest (after --set overrides).
    Hash {
        manifest: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Print the canonical form as well.
        #[arg(long)]
        canonical: bool,
    },
    /// Run an experiment (recorded as usual) and report particle-steps per second and the
    /// wall time split by solver stage and recording; or, with --suite FILE, run a benchmark
    /// suite (each case in a child process) and print Markdown tables of the results.
    Bench {
        #[arg(required_unless_present = "suite", conflicts_with = "suite")]
        manifest: Option<PathBuf>,
        #[arg(long = "set", value_name = "KEY=VALUE", conflicts_with = "suite")]
        set: Vec<String>,
        /// Worker threads (with --suite: passed to every case).
        #[arg(long, value_parser = threads_arg)]
        threads: Option<usize>,
        /// Keep the MCAP file in this directory (default: a temporary one, removed).
        #[arg(long, conflicts_with = "suite")]
        out: Option<PathBuf>,
        /// Benchmark suite file (e.g. benchmarks/suite.yaml): its cases and scaling series.
        #[arg(long, value_name = "FILE")]
        suite: Option<PathBuf>,
        /// With --suite: add each case's quick_set (shorter runs).
        #[arg(long, conflicts_with = "manifest")]
        quick: bool,
        /// With --suite: the runner binary to measure (default: this one), e.g. an older
        /// build for before/after numbers.
        #[arg(long, value_name = "PATH", conflicts_with = "manifest")]
        runner: Option<PathBuf>,
        /// With --suite: also write the Markdown tables to this file.
        #[arg(long, value_name = "OUT.md", conflicts_with = "manifest")]
        markdown: Option<PathBuf>,
        /// With --suite: run only this case (repeatable; `scaling` for the scaling series).
        #[arg(long = "case", value_name = "NAME", conflicts_with = "manifest")]
        cases: Vec<String>,
    },
    /// Replay a run from the manifest stored in its MCAP file and compare every checkpoint
    /// bit for bit (exit 0 identical, 1 not, 2 file unusable); or, with --trend DIR, check
    /// that a metric falls as a manifest value rises across the runs in DIR.
    Verify(VerifyArgs),
    /// Continue an interrupted (or killed, `.partial`) run from its last checkpoint.
    Resume {
        file: PathBuf,
        #[arg(long, value_parser = threads_arg)]
        threads: Option<usize>,
        #[arg(long, short)]
        quiet: bool,
    },
    /// Plot diagnostics quantities of one run against simulated time, or against another
    /// quantity (SVG).
    Plot {
        run: PathBuf,
        /// `Diagnostics.metrics` key or built-in field such as kinetic_energy_j (default:
        /// the first metric); repeat for several lines.
        #[arg(long)]
        metric: Vec<String>,
        /// Quantity for the x axis (default time_s); another one, e.g. strokes_done, gives a
        /// point per value it takes, from the first diagnostics row that has it.
        #[arg(long)]
        x: Option<String>,
        /// Output file (default: <run>-<metric>[-vs-<x>].svg beside the run).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Back-calculate a manifest value (the yield stress) from a measured result (e.g. a
    /// slump-flow diameter or an L-flow value) given in a calibration manifest: runs the
    /// base experiment until a run matches within the tolerance, and writes
    /// calibration.json and a figure into OUT/<name>-calib-<hash>/ (exit 0 fitted, 2 bad
    /// input, 3 not fitted, 130 interrupted; run it again to go on: finished runs are reused).
    Calibrate {
        calibration: PathBuf,
        /// Parent folder of the calibration's folder.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// Refuse runs estimated to hold more particles than this.
        #[arg(long = "max-particles", value_name = "N", default_value_t = 5_000_000)]
        max_particles: u64,
    },
    /// Plot a summary metric of every run in a folder against a manifest value (SVG).
    PlotSweep {
        dir: PathBuf,
        /// Dotted manifest key for the x axis, e.g. fluid.yield_stress_pa.
        #[arg(long)]
        x: String,
        /// Summary metric for the y axis, e.g. front_position_m.
        #[arg(long)]
        y: String,
        /// Dotted manifest key: one line per value.
        #[arg(long)]
        group: Option<String>,
        /// Output file (default: DIR/sweep-<y>-vs-<x>.svg).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Draw the last particle frame of a run, coloured by a point field (SVG).
    Snapshot {
        run: PathBuf,
        /// Point-cloud field to colour by (default: kind; `height_m`: the vertical coordinate).
        #[arg(long)]
        field: Option<String>,
        /// 3D runs: view from above, fluid only (default: from the side, x-z, with walls).
        #[arg(long)]
        top: bool,
        /// The frame nearest this simulated time (default: the last frame).
        #[arg(long, value_name = "SECONDS")]
        time: Option<f64>,
        /// Output file (default: <run>-snapshot-<field>[-t<time>].svg beside the run).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// PNG figures of a run (diagnostics against time, snapshots with a colour bar, the
    /// test's own figure) or of a sweep folder (each summary metric against the swept value),
    /// and one self-contained HTML page showing them with the run's facts; prints the page's
    /// path
    Report {
        /// Run file, or a folder of run files (a sweep folder).
        path: PathBuf,
        /// Report folder (default: <run>-report/ beside the run; DIR/report/ for a folder).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Snapshot time (s; repeatable; default: four from the start to the end).
        #[arg(long = "time", value_name = "SECONDS")]
        times: Vec<f64>,
        /// Point field that colours the snapshots (default: speed_m_s).
        #[arg(long)]
        field: Option<String>,
        /// Keep each figure's SVG beside its PNG.
        #[arg(long)]
        svg: bool,
    },
    /// Write one resolved manifest per point of a sweep (its canonical form, which hashes to
    /// the point's experiment hash) as OUT/<name>-<first 12 hex of its hash>.yaml; prints
    /// their paths. For running points elsewhere (GNU parallel, a scheduler) one by one
    Expand {
        manifest: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Folder for the manifests (default: manifests/<name>-sweep-<hash>/).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// What a run file holds: experiment, outcome, stop rule, build, particles, time,
    /// checkpoints, metrics, channels; for an unfinished or cut file, what is missing (exit 0;
    /// 2 when the file is unusable, or named finished but incomplete: it is described, then
    /// refused).
    Info {
        file: PathBuf,
        /// One JSON object instead of the text block.
        #[arg(long)]
        json: bool,
    },
    /// A run's diagnostics time series (one row per /diagnostics message), or with DIR one
    /// row per run file of a sweep folder (its swept manifest values and summary metrics), as
    /// CSV or JSON.
    #[command(group(clap::ArgGroup::new("format").required(true).args(["csv", "json"])))]
    Export {
        /// Run file, or a folder of run files (a sweep folder).
        path: PathBuf,
        /// CSV with a header line (empty cells where a row has no value).
        #[arg(long)]
        csv: bool,
        /// JSON: columns and rows, each row an object with every column (null where missing).
        #[arg(long)]
        json: bool,
        /// FILE: the one-row summary table (as for a folder) instead of the diagnostics.
        #[arg(long)]
        summary: bool,
        /// Write here instead of stdout (the path is printed).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Slump-flow and L-B box runs: the free surface of the last checkpoint against its closed
    /// form (slump: h(r), Roussel & Coussot 2005; L-box, no spheres: h(x), Nguyen, Roussel &
    /// Coussot 2006), printed as a table and drawn (SVG). Several runs of one test (e.g. one
    /// experiment at several spacings) go into one figure.
    Profile {
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// Output file (default: <run>-profile.svg beside the run; with several runs
        /// <first run>-profiles.svg).
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

#[derive(clap::Args, Debug)]
struct VerifyArgs {
    /// Run file (.mcap or .mcap.partial).
    #[arg(required_unless_present = "trend", conflicts_with = "trend")]
    file: Option<PathBuf>,
    /// Start from logged checkpoint K (restored) instead of the initial state.
    #[arg(long, value_name = "K")]
    from: Option<u32>,
    /// Stop at logged checkpoint M (default: the last).
    #[arg(long, value_name = "M")]
    to: Option<u32>,
    #[arg(long, value_parser = threads_arg)]
    threads: Option<usize>,
    /// Print the logged checkpoint hashes on stdout (index step time sha256), after the check.
    #[arg(long)]
    print_hashes: bool,
    #[arg(long, short)]
    quiet: bool,
    /// Check the trend across the runs in DIR instead.
    #[arg(long, value_name = "DIR")]
    trend: Option<PathBuf>,
    /// Manifest key on the x axis of --trend.
    #[arg(long = "x", value_name = "KEY", default_value = mps_runner::verify::trend::DEFAULT_X)]
    x_key: String,
    /// Summary metric on the y axis of --trend [default: the test's own, e.g. l_flow_value_m
    /// for the L-flow, spread_diameter_m for the slump, filling_distance_m for the L-B box].
    /// Repeatable: each metric is checked, and all must fall.
    #[arg(long = "y", value_name = "METRIC")]
    y_metric: Vec<String>,
}

/// Most worker threads `--threads` gives: twice the cores, and at least 8 (so that thread
/// counts beyond the cores can still be checked for determinism). Beyond that threads only
/// wait for each other: 1000 threads ran 100 times slower than 2.
fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (2 * cores).max(8)
}

/// `--threads N`: at least 1; more than [`max_threads`] is capped, with a warning.
fn threads_arg(text: &str) -> Result<usize, String> {
    let n: usize = text
        .trim()
        .parse()
        .map_err(|_| format!("expected a whole number of threads, got {text:?}"))?;
    if n == 0 {
        return Err("must be at least 1".to_string());
    }
    let cap = max_threads();
    if n > cap {
        eprintln!(
            "warning: --threads {n} capped at {cap} (twice the cores, at least 8); the results are the same bits for any count"
        );
        return Ok(cap);
    }
    Ok(n)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A reader that stops early (`runner info RUN | head`) ends these print-only commands as
    // it ends other Unix tools, by SIGPIPE, instead of a panic on the closed pipe. Commands
    // that write run files keep Rust's default (EPIPE), so a closed stdout cannot cut a file.
    #[cfg(unix)]
    if matches!(
        cli.command,
        Some(Command::Info { .. } | Command::Export { .. } | Command::Hash { .. })
    ) {
        // SAFETY: restores the default disposition of one signal before any thread exists.
        unsafe {
            libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        }
    }
    match cli.command {
        Some(Command::Draw {
            manifest,
            set,
            at_y,
            at_z,
            out,
            max_particles,
        }) => draw_command(&manifest, &set, at_y, at_z, &out, max_particles),
        Some(Command::Hash {
            manifest: path,
            set,
            canonical,
        }) => match experiment::load_plan(&path, &set) {
            Ok(sweep::Plan::Single(resolved)) => {
                if canonical {
                    println!("{}", resolved.canonical);
                }
                println!("{}", resolved.hash_hex);
                ExitCode::SUCCESS
            }
            Ok(sweep::Plan::Sweep(s)) => {
                if canonical {
                    println!("{}", s.canonical);
                }
                println!("{}", s.hash_hex);
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(EXIT_BAD_INPUT)
            }
        },
        Some(Command::Bench {
            manifest,
            set,
            threads,
            out,
            suite,
            quick,
            runner,
            markdown,
            cases,
        }) => match (suite, manifest) {
            (Some(suite), _) => bench_suite::suite_command(bench_suite::SuiteArgs {
                suite,
                quick,
                runner,
                threads,
                markdown,
                cases,
            }),
            (None, Some(manifest)) => bench_command(&manifest, &set, threads, out),
            (None, None) => unreachable!("clap requires MANIFEST without --suite"),
        },
        Some(Command::Verify(args)) => verify_command(args),
        Some(Command::Resume {
            file,
            threads,
            quiet,
        }) => resume_command(&file, threads, quiet),
        Some(Command::Plot {
            run,
            metric,
            x,
            out,
        }) => {
            if let Err(code) = readable_run(&run) {
                return code;
            }
            report_result(report::plot_run(
                &run,
                &metric,
                x.as_deref(),
                out.as_deref(),
            ))
        }
        Some(Command::PlotSweep {
            dir,
            x,
            y,
            group,
            out,
        }) => report_result(
            report::plot_sweep(&dir, &x, &y, group.as_deref(), out.as_deref()).map(|p| {
                for (file, why) in &p.skipped {
                    eprintln!("skipped {}: {why}", file.display());
                }
                p.path
            }),
        ),
        Some(Command::Snapshot {
            run,
            field,
            top,
            time,
            out,
        }) => {
            if let Err(code) = readable_run(&run) {
                return code;
            }
            report_result(report::snapshot(
                &run,
                field.as_deref(),
                top,
                time,
                out.as_deref(),
            ))
        }
        Some(Command::Profile { runs, out }) => {
            if let Some(code) = runs.iter().find_map(|run| readable_run(run).err()) {
                return code;
            }
            let drawn = match runs.as_slice() {
                [run] => report::profile(run, out.as_deref()),
                _ => report::profiles(&runs, out.as_deref()),
            };
            report_result(drawn.map(|(path, table)| {
                print!("{table}");
                path
            }))
        }
        Some(Command::Report {
            path,
            out,
            times,
            field,
            svg,
        }) => {
            if !path.is_dir()
                && let Err(code) = readable_run(&path)
            {
                return code;
            }
            let options = report::page::ReportOptions {
                out,
                times_s: times,
                field,
                keep_svg: svg,
            };
            report_results(report::page::report(&path, &options).map(|r| {
                for why in &r.skipped {
                    eprintln!("left out: {why}");
                }
                eprintln!("{} figure(s) in {}", r.figures.len(), r.dir.display());
                vec![r.page]
            }))
        }
        Some(Command::Expand { manifest, set, out }) => expand_command(&manifest, &set, out),
        Some(Command::Info { file, json }) => info_command(&file, json),
        Some(Command::Export {
            path,
            csv,
            json: _,
            summary,
            out,
        }) => export_command(&path, csv, summary, out.as_deref()),
        Some(Command::Calibrate {
            calibration,
            out,
            max_particles,
        }) => calibrate_command(&calibration, out, max_particles),
        Some(Command::Run(args)) => run_command(args),
        None => run_command(cli.run),
    }
}

fn calibrate_command(path: &Path, out_dir: PathBuf, max_particles: u64) -> ExitCode {
    use mps_runner::calibrate::{self, CalibrateError, CalibrateOptions};
    let plan = match calibrate::load(path) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    for pair in &plan.pairs {
        eprintln!(
            "{}: fitting {} in [{}, {}] to {} = {} (tolerance {})",
            plan.calibration.name,
            pair.parameter,
            pair.bounds[0],
            pair.bounds[1],
            pair.metric,
            pair.measured,
            pair.tolerance,
        );
    }
    eprintln!(
        "{} run(s) per round{}",
        plan.calibration.points_per_round,
        if plan.pairs.len() > 1 {
            ", alternating one value at a time in the order above"
        } else {
            ""
        }
    );
    let options = CalibrateOptions {
        out_dir,
        interrupt: interrupt_flag(),
        max_particles: Some(max_particles),
    };
    let on_run = |fit: &calibrate::Fit, stage: &calibrate::Stage, e: &calibrate::Evaluation| {
        let held: String = stage
            .held
            .iter()
            .map(|(k, v)| format!(", {k} = {v}"))
            .collect();
        let metrics: Vec<String> = plan
            .pairs
            .iter()
            .map(|q| {
                let m = e.metrics[&q.metric];
                format!("{} = {:.5} (off by {:+.5})", q.metric, m, m - q.measured)
            })
            .collect();
        eprintln!(
            "  [spacing {} m, pass {}, round {}] {} = {}{} -> {}; {} {}, {}",
            fit.spacing_m,
            stage.alternation,
            e.round,
            stage.parameter,
            e.values[&stage.parameter],
            held,
            metrics.join(", "),
            e.start,
            e.outcome,
            e.file
        );
    };
    let (dir, record, result) = calibrate::calibrate(&plan, &options, &on_run);
    match calibrate::write_record(&dir, &record) {
        Ok((json, figures)) => {
            for fit in &record.fits {
                for pair in &plan.pairs {
                    if let Some(b) = fit.brackets.get(&pair.parameter) {
                        eprintln!(
                            "spacing {} m: bracket {} in [{}, {}]",
                            fit.spacing_m, pair.parameter, b[0], b[1]
                        );
                    }
                    if let Some(f) = fit.fitted.get(&pair.parameter) {
                        eprintln!(
                            "spacing {} m: fitted {} = {:.4} (log-log interpolation in the bracket){}",
                            fit.spacing_m,
                            pair.parameter,
                            f,
                            if fit.converged {
                                ""
                            } else {
                                " (not every measured value met within its tolerance)"
                            }
                        );
                    }
                }
            }
            for (parameter, share) in &record.resolution_share {
                eprintln!(
                    "resolution: the fitted {parameter} at the two spacings differ by {:.1} %",
                    100.0 * share
                );
            }
            for figure in &figures {
                eprintln!("figure: {}", figure.display());
            }
            println!("{}", json.display());
        }
        Err(e) => {
            eprintln!(
                "error: cannot write the calibration record in {}: {e}",
                dir.display()
            );
            return ExitCode::from(EXIT_INTERNAL);
        }
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            match e {
                CalibrateError::Manifest(_) | CalibrateError::OutOfBounds(_) => {
                    ExitCode::from(EXIT_BAD_INPUT)
                }
                CalibrateError::Interrupted(_) => ExitCode::from(EXIT_INTERRUPTED),
                _ => ExitCode::from(EXIT_SIM_FAILED),
            }
        }
    }
}

/// For verify and info: an unusable file is refused (exit 2); a damaged `.partial` is read
/// with a warning; a file named finished without its end gives why (Some), to be reported.
fn incomplete_or_refused(file: &Path) -> Result<Option<String>, ExitCode> {
    match file_state(file) {
        FileState::Unusable(why) => {
            eprintln!("error: {why}");
            Err(ExitCode::from(EXIT_BAD_INPUT))
        }
        FileState::Incomplete(why) => Ok(Some(why)),
        FileState::PartialDamaged(why) => {
            eprintln!("warning: {why}");
            Ok(None)
        }
        FileState::Usable => Ok(None),
    }
}

/// `runner info`: a finished file or a `.partial` (damaged or not, with a warning) is
/// described, exit 0; a file named finished without its end is described with what it
/// misses, then refused (exit 2, as verify does); an unusable one is refused (exit 2).
fn info_command(file: &std::path::Path, json: bool) -> ExitCode {
    let incomplete = match incomplete_or_refused(file) {
        Ok(i) => i,
        Err(code) => return code,
    };
    let info = match report::info::info(file) {
        Ok(i) => i,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    if json {
        match serde_json::to_string_pretty(&info) {
            Ok(text) => println!("{text}"),
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(EXIT_INTERNAL);
            }
        }
    } else {
        print!("{info}");
    }
    match incomplete {
        Some(why) => {
            eprintln!("error: {why}");
            ExitCode::from(EXIT_BAD_INPUT)
        }
        None => ExitCode::SUCCESS,
    }
}

/// `runner export`: a run file as its diagnostics (or with `summary` its one-row summary),
/// a folder as one summary row per finished run file; CSV (`csv`) or JSON, to stdout or
/// `out`. A run file is taken as plot takes it (`readable_run`).
fn export_command(
    path: &std::path::Path,
    csv: bool,
    summary: bool,
    out: Option<&std::path::Path>,
) -> ExitCode {
    use mps_runner::report::export::{export_dir, export_file};
    let text = if path.is_dir() {
        let (table, skipped) = match export_dir(path) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(EXIT_BAD_INPUT);
            }
        };
        for (file, why) in &skipped {
            eprintln!("skipped {}: {why}", file.display());
        }
        if csv {
            table.to_csv()
        } else {
            let mut value = table.to_json();
            value["dir"] = path.display().to_string().into();
            value["skipped"] = skipped
                .iter()
                .map(|(f, why)| serde_json::json!({"file": f.display().to_string(), "reason": why}))
                .collect();
            value.to_string() + "\n"
        }
    } else {
        if let Err(code) = readable_run(path) {
            return code;
        }
        let (diagnostics, summary_row) = match export_file(path) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(EXIT_BAD_INPUT);
            }
        };
        match (csv, summary) {
            (true, false) => diagnostics.to_csv(),
            (true, true) => summary_row.to_csv(),
            (false, true) => summary_row.to_json().to_string() + "\n",
            (false, false) => {
                serde_json::json!({
                    "file": path.display().to_string(),
                    "diagnostics": diagnostics.to_json(),
                    "summary": summary_row.to_json(),
                })
                .to_string()
                    + "\n"
            }
        }
    };
    match out {
        None => {
            print!("{text}");
            ExitCode::SUCCESS
        }
        Some(out) => match std::fs::write(out, text) {
            Ok(()) => {
                println!("{}", out.display());
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: cannot write {}: {e}", out.display());
                ExitCode::from(EXIT_INTERNAL)
            }
        },
    }
}

/// What a run file's structure lets verify, resume, info, plot, snapshot, profile and export do with it
/// (see `record::read`: the reader that checks it is the one they read with).
enum FileState {
    /// Finished and whole, or a `.partial` that ends as a killed run leaves it (on a record
    /// boundary or in a chunk cut short).
    Usable,
    /// A `.partial` damaged before its end: it is read up to its last intact chunk. The text
    /// says where and what is lost.
    PartialDamaged(String),
    /// Named as finished (not `.partial`) but without the footer and end magic a finished run
    /// writes: cut short or damaged after it was written.
    Incomplete(String),
    /// Cannot be read as a run: not a run file, missing, or finished but damaged.
    Unusable(String),
}

fn file_state(path: &std::path::Path) -> FileState {
    let check = match mps_runner::record::check_run(path) {
        Ok(c) => c,
        Err(e) => return FileState::Unusable(e.to_string()),
    };
    if check.complete {
        return FileState::Usable;
    }
    let n = check.checkpoints;
    if !path.to_string_lossy().ends_with(".partial") {
        let held = match &check.stop {
            Some(stop) => format!("{stop} ({n} checkpoints before it)"),
            None => format!("it ends on a record boundary after {n} checkpoints"),
        };
        return FileState::Incomplete(format!(
            "{} is incomplete: it does not end with the MCAP footer and magic that a finished run writes (cut short or damaged after it was written; a run in progress or killed is named .partial); {held}",
            path.display()
        ));
    }
    match check.stop.filter(|s| s.damaged) {
        Some(stop) => FileState::PartialDamaged(format!(
            "{} is damaged: {stop}; it is read up to the last intact chunk before that ({n} checkpoints), and no further",
            path.display()
        )),
        None => FileState::Usable,
    }
}

/// For the commands that present a file's contents (plot, snapshot, profile, export): an incomplete
/// or damaged finished file is refused (exit 2) rather than drawn from part of it; a
/// `.partial` file is drawn with a warning (and another where it is damaged).
fn readable_run(path: &std::path::Path) -> Result<(), ExitCode> {
    match file_state(path) {
        FileState::Incomplete(why) | FileState::Unusable(why) => {
            eprintln!("error: {why}");
            return Err(ExitCode::from(EXIT_BAD_INPUT));
        }
        FileState::PartialDamaged(why) => eprintln!("warning: {why}"),
        FileState::Usable => {}
    }
    if path.to_string_lossy().ends_with(".partial") {
        eprintln!(
            "warning: {} is an unfinished run (in progress or killed): this shows what it holds so far",
            path.display()
        );
    }
    Ok(())
}

/// SIGINT and SIGTERM set the returned flag: the run stops at the next step and finishes its
/// file as interrupted (resumable). A second signal exits at once (the `.partial` file keeps
/// every checkpoint written and can be resumed too).
fn interrupt_flag() -> Option<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    let handler_flag = flag.clone();
    let installed = ctrlc::set_handler(move || {
        if handler_flag.swap(true, Ordering::SeqCst) {
            eprintln!("second interrupt: exiting now; the .partial file can be resumed");
            std::process::exit(i32::from(EXIT_INTERRUPTED));
        }
        eprintln!("interrupt: stopping after this step and finishing the file");
    });
    match installed {
        Ok(()) => Some(flag),
        Err(e) => {
            eprintln!("warning: cannot install the signal handler: {e}");
            None
        }
    }
}

fn outcome_code(outcome: &Outcome) -> ExitCode {
    match outcome {
        Outcome::Completed => ExitCode::SUCCESS,
        Outcome::Failed(_) => ExitCode::from(EXIT_SIM_FAILED),
        Outcome::Interrupted(_) => ExitCode::from(EXIT_INTERRUPTED),
    }
}

fn verify_command(args: VerifyArgs) -> ExitCode {
    if args.threads == Some(0) {
        eprintln!("error: --threads must be at least 1");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    if let Some(dir) = args.trend {
        let metrics: Vec<Option<String>> = if args.y_metric.is_empty() {
            vec![None]
        } else {
            args.y_metric.into_iter().map(Some).collect()
        };
        let mut all_passed = true;
        for (k, y_metric) in metrics.into_iter().enumerate() {
            let options = TrendOptions {
                x_key: args.x_key.clone(),
                y_metric,
            };
            match trend(&dir, &options) {
                Ok(report) => {
                    if k > 0 {
                        println!();
                    }
                    println!("{report}");
                    all_passed &= report.passed();
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    return ExitCode::from(EXIT_BAD_INPUT);
                }
            }
        }
        return if all_passed {
            ExitCode::SUCCESS
        } else {
            ExitCode::from(EXIT_MISMATCH)
        };
    }
    let file = args.file.expect("clap requires FILE without --trend");
    // An incomplete file still has its checkpoints replayed, but is not called verified.
    let incomplete = match incomplete_or_refused(&file) {
        Ok(i) => i,
        Err(code) => return code,
    };
    let display = progress::Display::new(args.quiet);
    let options = VerifyOptions {
        from: args.from,
        to: args.to,
        threads: args.threads,
        progress: display.as_ref().map(|d| d.callback()),
    };
    let verified = verify(&file, &options);
    if let Some(d) = &display {
        d.finish_all();
    }
    match verified {
        Ok(report) => {
            if let Some(w) = &report.build_warning {
                eprintln!("warning: {w}");
            }
            println!("{report}");
            if args.print_hashes {
                for h in &report.hashes {
                    println!("{} {} {:e} {}", h.index, h.step, h.time_s, h.state_sha256);
                }
            }
            if let Some(why) = incomplete {
                // The checkpoints it still holds were replayed, but it is not the whole run.
                eprintln!("error: {why}");
                ExitCode::from(EXIT_BAD_INPUT)
            } else if report.passed() {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(EXIT_MISMATCH)
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(EXIT_BAD_INPUT)
        }
    }
}

fn resume_command(file: &std::path::Path, threads: Option<usize>, quiet: bool) -> ExitCode {
    if threads == Some(0) {
        eprintln!("error: --threads must be at least 1");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    match file_state(file) {
        FileState::Incomplete(why) => {
            eprintln!(
                "error: cannot resume: {why}; a killed run's .partial file resumes, a damaged finished one does not"
            );
            return ExitCode::from(EXIT_BAD_INPUT);
        }
        FileState::Unusable(why) => {
            eprintln!("error: cannot resume: {why}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
        FileState::PartialDamaged(why) => {
            eprintln!("warning: {why}; resuming from the last of those checkpoints");
        }
        FileState::Usable => {}
    }
    let display = progress::Display::new(quiet);
    let options = ResumeOptions {
        threads,
        progress: display.as_ref().map(|d| d.callback()),
        interrupt: interrupt_flag(),
    };
    let resumed = resume(file, &options);
    if let Some(d) = &display {
        d.finish_all();
    }
    match resumed {
        Ok(r) => {
            eprintln!(
                "resumed from checkpoint {} (step {}, t = {} s, {} messages copied): {} at t = {} s; wall time {:.2} s",
                r.from_checkpoint,
                r.from_step,
                time_text(r.from_time_s),
                r.copied_messages,
                r.result.outcome.as_str(),
                time_text(
                    r.result
                        .summary
                        .metrics
                        .get("simulated_time_s")
                        .copied()
                        .unwrap_or(f64::NAN)
                ),
                r.result.wall_time_s
            );
            if !r.result.summary.reason.is_empty() {
                eprintln!("reason: {}", r.result.summary.reason);
            }
            println!("{}", r.result.path.display());
            outcome_code(&r.result.outcome)
        }
        Err(e @ ResumeError::Unusable { .. }) => {
            eprintln!("error: {e}");
            ExitCode::from(EXIT_BAD_INPUT)
        }
        Err(ResumeError::Run(e)) => {
            print_run_error(&e);
            ExitCode::from(run_error_code(&e))
        }
    }
}

/// Prints the plot's path, or the error with its exit code.
fn draw_command(
    path: &Path,
    set: &[String],
    at_y: Option<f64>,
    at_z: Option<f64>,
    out: &Path,
    max_particles: u64,
) -> ExitCode {
    let resolved = match experiment::load(path, set) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let m = &resolved.manifest;
    if let Err(e) = mps_runner::run::check_size(m, max_particles) {
        eprintln!("error: {e}");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    for (name, v) in [("--at-y", at_y), ("--at-z", at_z)] {
        if v.is_some_and(|v| !v.is_finite()) {
            eprintln!("error: {name} must be a finite number");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    }
    report_results(report::draw_scene(m, at_y, at_z, out))
}

fn report_result(result: Result<PathBuf, report::ReportError>) -> ExitCode {
    report_results(result.map(|p| vec![p]))
}

/// Prints the files written (exit 0), or the error: exit 1 when writing failed, 2 else.
fn report_results(result: Result<Vec<PathBuf>, report::ReportError>) -> ExitCode {
    match result {
        Ok(paths) => {
            for path in paths {
                println!("{}", path.display());
            }
            ExitCode::SUCCESS
        }
        Err(e @ report::ReportError::Write { .. }) => {
            eprintln!("error: {e}");
            ExitCode::from(EXIT_INTERNAL)
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(EXIT_BAD_INPUT)
        }
    }
}

/// `runner bench`: one run, then particle-steps per second and where the time went.
fn bench_command(
    path: &std::path::Path,
    set: &[String],
    threads: Option<usize>,
    out: Option<PathBuf>,
) -> ExitCode {
    if threads == Some(0) {
        eprintln!("error: --threads must be at least 1");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    let resolved = match experiment::load_plan(path, set) {
        Ok(sweep::Plan::Single(r)) => *r,
        Ok(sweep::Plan::Sweep(_)) => {
            eprintln!("error: runner bench takes a single experiment, not a sweep");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let temporary = out.is_none();
    let out_dir = out
        .unwrap_or_else(|| std::env::temp_dir().join(format!("mps_bench-{}", std::process::id())));
    let options = RunOptions {
        out_dir: out_dir.clone(),
        threads,
        progress: None,
        interrupt: interrupt_flag(),
        max_particles: Some(DEFAULT_MAX_PARTICLES),
        // A benchmark measures; its file is a by-product, replaced by the next one.
        overwrite: true,
    };
    let result = match run(&resolved, &options) {
        Ok(r) => r,
        Err(e) => {
            print_run_error(&e);
            return ExitCode::from(run_error_code(&e));
        }
    };
    let metric = |k: &str| result.summary.metrics.get(k).copied().unwrap_or(f64::NAN);
    let (steps, particles) = (metric("steps"), metric("particle_count"));
    let wall = result.wall_time_s.max(1e-12);
    let t = result.timing;
    let threads_used =
        threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    println!(
        "{} ({}D, spacing {} m): {} particles ({} fluid), {} steps to t = {} s, {} threads",
        resolved.manifest.name,
        resolved.manifest.dimension,
        resolved.manifest.spacing_m,
        particles,
        metric("fluid_particle_count"),
        steps,
        time_text(metric("simulated_time_s")),
        threads_used
    );
    println!(
        "outcome {}; wall time {:.3} s; {:.0} particle-steps/s",
        result.outcome.as_str(),
        wall,
        steps * particles / wall
    );
    let other = t.step_total_s
        - t.neighbours_s
        - t.kernel_pairs_s
        - t.viscosity_s
        - t.pressure_assembly_s
        - t.pressure_solve_s;
    let per_step = |total: u64| total as f64 / steps.max(1.0);
    let rows = [
        (
            format!("neighbour lists ({} cell-grid builds)", t.list_builds),
            t.neighbours_s,
        ),
        (
            "kernel pairs (lists cut to radii)".to_string(),
            t.kernel_pairs_s,
        ),
        (
            format!(
                "viscosity (strain, assembly, CG {:.1} it/step)",
                per_step(t.viscosity_iterations)
            ),
            t.viscosity_s,
        ),
        (
            "PPE assembly (n*, surface, source, CSR)".to_string(),
            t.pressure_assembly_s,
        ),
        (
            format!("PPE solve (CG {:.1} it/step)", per_step(t.ppe_iterations)),
            t.pressure_solve_s,
        ),
        (
            "other solver stages (collision, correction)".to_string(),
            other,
        ),
        ("recording and output".to_string(), wall - t.step_total_s),
    ];
    println!("{:<46} {:>9} {:>7}", "stage", "seconds", "share");
    for (name, seconds) in rows {
        println!("{name:<46} {seconds:>9.3} {:>6.1}%", 100.0 * seconds / wall);
    }
    if temporary {
        let _ = std::fs::remove_dir_all(&out_dir);
    } else {
        println!("{}", result.path.display());
    }
    outcome_code(&result.outcome)
}

fn run_command(args: RunArgs) -> ExitCode {
    let Some(path) = args.manifest.clone() else {
        eprintln!(
            "error: no manifest given (usage: runner <MANIFEST> [--out DIR] [--set KEY=VALUE]... [--threads N])"
        );
        return ExitCode::from(EXIT_BAD_INPUT);
    };
    if args.threads == Some(0) {
        eprintln!("error: --threads must be at least 1");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    let resolved = match experiment::load_plan(&path, &args.set) {
        Ok(sweep::Plan::Single(_)) if args.shard.is_some() => {
            eprintln!(
                "error: --shard: {} has no sweep: section (only a sweep's points can be sliced)",
                path.display()
            );
            return ExitCode::from(EXIT_BAD_INPUT);
        }
        Ok(sweep::Plan::Single(r)) => *r,
        Ok(sweep::Plan::Sweep(s)) => return sweep_command(&s, &args),
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let display = progress::Display::new(args.quiet);
    let options = RunOptions {
        out_dir: args.out,
        threads: args.threads,
        progress: display.as_ref().map(|d| d.callback()),
        interrupt: interrupt_flag(),
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
    match result {
        Ok(result) => {
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
            outcome_code(&result.outcome)
        }
        Err(e) => {
            print_run_error(&e);
            ExitCode::from(run_error_code(&e))
        }
    }
}

/// Exit code of a run that could not be made: 2 for a run refused before anything was
/// written (too large, or its file exists, is being written, or holds a killed run), 1 for a
/// recording that failed.
fn run_error_code(e: &RunError) -> u8 {
    match e {
        RunError::TooLarge { .. } => EXIT_BAD_INPUT,
        RunError::Record(r) if r.is_refusal() => EXIT_BAD_INPUT,
        _ => EXIT_INTERNAL,
    }
}

/// Prints why a run could not be made, with what to do about a refusal.
fn print_run_error(e: &RunError) {
    eprintln!("error: {e}");
    let RunError::Record(r) = e else { return };
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

/// Runs every point of a sweep (points concurrently, one thread each; `--threads` caps the
/// concurrent points), prints one line per finished point, plots the results into the sweep
/// folder, and prints the folder last. Exit 0 when every point completed, 3 when any failed,
/// 1 when a file could not be written, 130 when interrupted.
fn sweep_command(s: &experiment::Sweep, args: &RunArgs) -> ExitCode {
    let shard = match args.shard {
        Some(shard) => Some(shard),
        None => match mps_runner::sweep_run::Shard::from_slurm(|k| std::env::var(k).ok()) {
            Ok(shard) => shard,
            Err(e) => {
                eprintln!("error: --shard from the Slurm job array: {e}");
                return ExitCode::from(EXIT_BAD_INPUT);
            }
        },
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
    let workers = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, total.max(1));
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let options = SweepOptions {
        progress: display.as_ref().map(|d| d.callback()),
        out_dir: args.out.clone(),
        workers: args.threads,
        interrupt: interrupt_flag(),
        max_particles: Some(args.max_particles),
        overwrite: args.overwrite,
        shard,
    };
    let on_done = |o: &mps_runner::sweep_run::PointOutcome| {
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

    // The sweep plot: x = the first numeric axis, groups = the other axes' values. Not for a
    // slice: slices finishing together would write the same plot files.
    let numeric = |a: &sweep::Axis| a.values.iter().all(serde_json::Value::is_number);
    if shard.is_some() && !args.quiet {
        eprintln!(
            "no sweep plots for a slice: once every slice is done, `runner report DIR` (or `runner plot-sweep`) plots the whole sweep"
        );
    }
    if let Some(x) = s
        .axes
        .iter()
        .find(|a| numeric(a))
        .filter(|_| shard.is_none())
    {
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
            match report::plot_sweep(&dir, &x.key, &y, group, None) {
                Ok(p) => {
                    if !args.quiet {
                        eprintln!("plot: {}", p.path.display());
                    }
                }
                Err(e) => eprintln!("warning: no sweep plot of {y}: {e}"),
            }
        }
    }

    println!("{}", dir.display());
    let mut code = ExitCode::SUCCESS;
    for o in &outcomes {
        match &o.result {
            Ok(r) => match r.outcome {
                Outcome::Completed => {}
                Outcome::Failed(_) => code = ExitCode::from(EXIT_SIM_FAILED),
                Outcome::Interrupted(_) => return ExitCode::from(EXIT_INTERRUPTED),
            },
            Err(e) => return ExitCode::from(run_error_code(e)),
        }
    }
    code
}

/// `runner expand`: one canonical manifest per sweep point.
fn expand_command(path: &Path, set: &[String], out: Option<PathBuf>) -> ExitCode {
    let s = match experiment::load_plan(path, set) {
        Ok(sweep::Plan::Sweep(s)) => s,
        Ok(sweep::Plan::Single(_)) => {
            eprintln!(
                "error: {} has no sweep: section: it is one experiment already",
                path.display()
            );
            return ExitCode::from(EXIT_BAD_INPUT);
        }
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let dir = out.unwrap_or_else(|| PathBuf::from("manifests").join(s.folder_name()));
    if let Err(e) = std::fs::create_dir_all(&dir) {
        eprintln!("error: cannot create {}: {e}", dir.display());
        return ExitCode::from(EXIT_INTERNAL);
    }
    let n = s.points.len();
    for (k, point) in s.points.iter().enumerate() {
        let r = &point.resolved;
        let file = dir.join(format!("{}-{}.yaml", r.manifest.name, &r.hash_hex[..12]));
        // JSON is YAML: the canonical form itself, under a comment naming the point.
        let pretty = serde_json::from_str::<serde_json::Value>(&r.canonical)
            .and_then(|v| serde_json::to_string_pretty(&v))
            .expect("the canonical form is JSON");
        let text = format!(
            "# Point {}/{n} of sweep {} ({}): {}\n# experiment hash {}\n{pretty}\n",
            k + 1,
            s.hash_hex,
            path.display(),
            point.label(),
            r.hash_hex
        );
        if let Err(e) = std::fs::write(&file, text) {
            eprintln!("error: cannot write {}: {e}", file.display());
            return ExitCode::from(EXIT_INTERNAL);
        }
        println!("{}", file.display());
    }
    ExitCode::SUCCESS
}

/// The line of a finished sweep point: `[i/n] KEY=VALUE... OUTCOME PATH` on stdout; the
/// reason of a failure or a stop on stderr.
fn print_point(o: &mps_runner::sweep_run::PointOutcome, total: usize, quiet: bool) {
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
