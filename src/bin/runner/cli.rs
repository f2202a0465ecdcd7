//! The command line as clap reads it: the top-level `runner MANIFEST [OPTIONS]` (a run), the
//! subcommands and their options. What each command does is in `commands/`.

use clap::{Parser, Subcommand};
use std::path::PathBuf;

/// `--max-particles` default: the largest scene (an estimate of its particle count, checked
/// before anything is allocated) a run, a drawing or a calibration takes without being told
/// more: about 7.5 GB of memory in 2D, 20 GB in 3D (see `run::check_size`).
pub const DEFAULT_MAX_PARTICLES: u64 = 5_000_000;

#[derive(Parser, Debug)]
#[command(
    name = "runner",
    version,
    about = "Run an MPS experiment manifest and record it into one MCAP file",
    args_conflicts_with_subcommands = true
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    #[command(flatten)]
    pub run: RunArgs,
}

// The variants' doc comments are the commands' help texts; each command's options are a
// struct of their own, handed whole to its handler.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run an experiment manifest: the same as `runner MANIFEST [OPTIONS]`
    Run(RunArgs),
    /// Draw the particle set a manifest starts from (walls, dummies, fluid, inlets) as
    /// sections, SVG: in 3D through y = AT_Y from the side and through z = AT_Z from above,
    /// in 2D the plane; prints the files written.
    Draw(DrawArgs),
    /// Print the SHA-256 experiment hash of a manifest (after --set overrides).
    Hash(HashArgs),
    /// Run an experiment (recorded as usual) and report particle-steps per second and the
    /// wall time split by solver stage and recording; or, with --suite FILE, run a benchmark
    /// suite (each case in a child process) and print Markdown tables of the results.
    Bench(BenchArgs),
    /// Replay a run from the manifest stored in its MCAP file and compare every checkpoint
    /// bit for bit (exit 0 identical, 1 not, 2 file unusable); or, with --trend DIR, check
    /// that a metric falls as a manifest value rises across the runs in DIR.
    Verify(VerifyArgs),
    /// Continue an interrupted (or killed, `.partial`) run from its last checkpoint.
    Resume(ResumeArgs),
    /// Plot diagnostics quantities of one run against simulated time, or against another
    /// quantity (SVG).
    Plot(PlotArgs),
    /// Back-calculate a manifest value (the yield stress) from a measured result (e.g. a
    /// slump-flow diameter or an L-flow value) given in a calibration manifest: runs the
    /// base experiment until a run matches within the tolerance, and writes
    /// calibration.json and a figure into OUT/<name>-calib-<hash>/ (exit 0 fitted, 2 bad
    /// input, 3 not fitted, 130 interrupted; run it again to go on: finished runs are reused).
    Calibrate(CalibrateArgs),
    /// Plot a summary metric of every run in a folder against a manifest value (SVG).
    PlotSweep(PlotSweepArgs),
    /// Draw the last particle frame of a run, coloured by a point field (SVG).
    Snapshot(SnapshotArgs),
    /// PNG figures of a run (diagnostics against time, snapshots with a colour bar, the
    /// test's own figure) or of a sweep folder (each summary metric against the swept value),
    /// and one self-contained HTML page showing them with the run's facts; prints the page's
    /// path
    Report(ReportArgs),
    /// Write one resolved manifest per point of a sweep (its canonical form, which hashes to
    /// the point's experiment hash) as OUT/<name>-<first 12 hex of its hash>.yaml; prints
    /// their paths. For running points elsewhere (GNU parallel, a scheduler) one by one
    Expand(ExpandArgs),
    /// What a run file holds: experiment, outcome, stop rule, build, particles, time,
    /// checkpoints, metrics, channels; for an unfinished or cut file, what is missing (exit 0;
    /// 2 when the file is unusable, or named finished but incomplete: it is described, then
    /// refused).
    Info(InfoArgs),
    /// A run's diagnostics time series (one row per /diagnostics message), or with DIR one
    /// row per run file of a sweep folder (its swept manifest values and summary metrics), as
    /// CSV or JSON.
    #[command(group(clap::ArgGroup::new("format").required(true).args(["csv", "json"])))]
    Export(ExportArgs),
    /// Slump-flow and L-B box runs: the free surface of the last checkpoint against its closed
    /// form (slump: h(r), Roussel & Coussot 2005; L-box, no spheres: h(x), Nguyen, Roussel &
    /// Coussot 2006), printed as a table and drawn (SVG). Several runs of one test (e.g. one
    /// experiment at several spacings) go into one figure.
    Profile(ProfileArgs),
}

// `runner MANIFEST` and `runner run MANIFEST`.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Experiment manifest (YAML).
    pub manifest: Option<PathBuf>,
    /// Output directory for the MCAP file.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Override a manifest field before validation and hashing, e.g. --set spacing_m=0.02
    /// (repeatable; dotted paths).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Worker threads (default: all cores). Results are bitwise identical for any count.
    #[arg(long, value_parser = threads_arg)]
    pub threads: Option<usize>,
    /// Refuse a run whose scene is estimated to hold more particles than this (checked
    /// before anything is allocated or written).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_PARTICLES)]
    pub max_particles: u64,
    /// No progress lines on stderr.
    #[arg(long, short)]
    pub quiet: bool,
    /// Run even if this experiment's file (or a killed run's .partial) is already in the
    /// output folder, and replace it once the new file is finished (default: refuse, exit 2).
    #[arg(long)]
    pub overwrite: bool,
    /// Sweeps only: summary metric(s) to plot into the sweep folder (repeatable; default:
    /// every summary metric that is not a count or bookkeeping).
    #[arg(long = "plot-y", value_name = "METRIC")]
    pub plot_y: Vec<String>,
    /// Sweeps only: run slice I of N (the points whose index k has k mod N = I - 1) into the
    /// same sweep folder; default in a Slurm job array: SLURM_ARRAY_TASK_ID (from
    /// SLURM_ARRAY_TASK_MIN) of SLURM_ARRAY_TASK_COUNT. A sliced run draws no sweep plots.
    #[arg(long, value_name = "I/N", value_parser = mps_runner::sweep_run::Shard::parse)]
    pub shard: Option<mps_runner::sweep_run::Shard>,
}

// `runner draw`.
#[derive(clap::Args, Debug)]
pub struct DrawArgs {
    pub manifest: PathBuf,
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// 3D: the side section's plane y, metres (default: the middle of the scene).
    #[arg(long, value_name = "M")]
    pub at_y: Option<f64>,
    /// 3D: the top section's plane z, metres (default: a quarter of the way up the scene).
    #[arg(long, value_name = "M")]
    pub at_z: Option<f64>,
    /// Folder for the SVG files (<name>-scene-side.svg, <name>-scene-top.svg).
    #[arg(long, default_value = ".")]
    pub out: PathBuf,
    /// Refuse a scene estimated to hold more particles than this (before it is built).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_PARTICLES)]
    pub max_particles: u64,
}

// `runner hash`.
#[derive(clap::Args, Debug)]
pub struct HashArgs {
    pub manifest: PathBuf,
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Print the canonical form as well.
    #[arg(long)]
    pub canonical: bool,
}

// `runner bench MANIFEST` or `runner bench --suite FILE`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[arg(required_unless_present = "suite", conflicts_with = "suite")]
    pub manifest: Option<PathBuf>,
    #[arg(long = "set", value_name = "KEY=VALUE", conflicts_with = "suite")]
    pub set: Vec<String>,
    /// Worker threads (with --suite: passed to every case).
    #[arg(long, value_parser = threads_arg)]
    pub threads: Option<usize>,
    /// Keep the MCAP file in this directory (default: a temporary one, removed).
    #[arg(long, conflicts_with = "suite")]
    pub out: Option<PathBuf>,
    /// Benchmark suite file (e.g. benchmarks/suite.yaml): its cases and scaling series.
    #[arg(long, value_name = "FILE")]
    pub suite: Option<PathBuf>,
    /// With --suite: add each case's quick_set (shorter runs).
    #[arg(long, conflicts_with = "manifest")]
    pub quick: bool,
    /// With --suite: the runner binary to measure (default: this one), e.g. an older
    /// build for before/after numbers.
    #[arg(long, value_name = "PATH", conflicts_with = "manifest")]
    pub runner: Option<PathBuf>,
    /// With --suite: also write the Markdown tables to this file.
    #[arg(long, value_name = "OUT.md", conflicts_with = "manifest")]
    pub markdown: Option<PathBuf>,
    /// With --suite: run only this case (repeatable; `scaling` for the scaling series).
    #[arg(long = "case", value_name = "NAME", conflicts_with = "manifest")]
    pub cases: Vec<String>,
}

// `runner verify FILE` or `runner verify --trend DIR`.
#[derive(clap::Args, Debug)]
pub struct VerifyArgs {
    /// Run file (.mcap or .mcap.partial).
    #[arg(required_unless_present = "trend", conflicts_with = "trend")]
    pub file: Option<PathBuf>,
    /// Start from logged checkpoint K (restored) instead of the initial state.
    #[arg(long, value_name = "K")]
    pub from: Option<u32>,
    /// Stop at logged checkpoint M (default: the last).
    #[arg(long, value_name = "M")]
    pub to: Option<u32>,
    #[arg(long, value_parser = threads_arg)]
    pub threads: Option<usize>,
    /// Print the logged checkpoint hashes on stdout (index step time sha256), after the check.
    #[arg(long)]
    pub print_hashes: bool,
    #[arg(long, short)]
    pub quiet: bool,
    /// Check the trend across the runs in DIR instead.
    #[arg(long, value_name = "DIR")]
    pub trend: Option<PathBuf>,
    /// Manifest key on the x axis of --trend.
    #[arg(long = "x", value_name = "KEY", default_value = mps_runner::verify::trend::DEFAULT_X)]
    pub x_key: String,
    /// Summary metric on the y axis of --trend [default: the test's own, e.g. l_flow_value_m
    /// for the L-flow, spread_diameter_m for the slump, filling_distance_m for the L-B box].
    /// Repeatable: each metric is checked, and all must fall.
    #[arg(long = "y", value_name = "METRIC")]
    pub y_metric: Vec<String>,
}

// `runner resume`.
#[derive(clap::Args, Debug)]
pub struct ResumeArgs {
    pub file: PathBuf,
    #[arg(long, value_parser = threads_arg)]
    pub threads: Option<usize>,
    #[arg(long, short)]
    pub quiet: bool,
}

// `runner plot`.
#[derive(clap::Args, Debug)]
pub struct PlotArgs {
    pub run: PathBuf,
    /// `Diagnostics.metrics` key or built-in field such as kinetic_energy_j (default:
    /// the first metric); repeat for several lines.
    #[arg(long)]
    pub metric: Vec<String>,
    /// Quantity for the x axis (default time_s); another one, e.g. strokes_done, gives a
    /// point per value it takes, from the first diagnostics row that has it.
    #[arg(long)]
    pub x: Option<String>,
    /// Output file (default: <run>-<metric>[-vs-<x>].svg beside the run).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

// `runner calibrate`.
#[derive(clap::Args, Debug)]
pub struct CalibrateArgs {
    pub calibration: PathBuf,
    /// Parent folder of the calibration's folder.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Refuse runs estimated to hold more particles than this.
    #[arg(long = "max-particles", value_name = "N", default_value_t = DEFAULT_MAX_PARTICLES)]
    pub max_particles: u64,
}

// `runner plot-sweep`.
#[derive(clap::Args, Debug)]
pub struct PlotSweepArgs {
    pub dir: PathBuf,
    /// Dotted manifest key for the x axis, e.g. fluid.yield_stress_pa.
    #[arg(long)]
    pub x: String,
    /// Summary metric for the y axis, e.g. front_position_m.
    #[arg(long)]
    pub y: String,
    /// Dotted manifest key: one line per value.
    #[arg(long)]
    pub group: Option<String>,
    /// Output file (default: DIR/sweep-<y>-vs-<x>.svg).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

// `runner snapshot`.
#[derive(clap::Args, Debug)]
pub struct SnapshotArgs {
    pub run: PathBuf,
    /// Point-cloud field to colour by (default: kind; `height_m`: the vertical coordinate).
    #[arg(long)]
    pub field: Option<String>,
    /// 3D runs: view from above, fluid only (default: from the side, x-z, with walls).
    #[arg(long)]
    pub top: bool,
    /// The frame nearest this simulated time (default: the last frame).
    #[arg(long, value_name = "SECONDS")]
    pub time: Option<f64>,
    /// Output file (default: <run>-snapshot-<field>[-t<time>].svg beside the run).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

// `runner report`.
#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// Run file, or a folder of run files (a sweep folder).
    pub path: PathBuf,
    /// Report folder (default: <run>-report/ beside the run; DIR/report/ for a folder).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Snapshot time (s; repeatable; default: four from the start to the end).
    #[arg(long = "time", value_name = "SECONDS")]
    pub times: Vec<f64>,
    /// Point field that colours the snapshots (default: speed_m_s).
    #[arg(long)]
    pub field: Option<String>,
    /// Keep each figure's SVG beside its PNG.
    #[arg(long)]
    pub svg: bool,
}

// `runner expand`.
#[derive(clap::Args, Debug)]
pub struct ExpandArgs {
    pub manifest: PathBuf,
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Folder for the manifests (default: manifests/<name>-sweep-<hash>/).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

// `runner info`.
#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    pub file: PathBuf,
    /// One JSON object instead of the text block.
    #[arg(long)]
    pub json: bool,
}

// `runner export` (`--csv` or `--json`, one of them required: the group on `Command::Export`).
#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// Run file, or a folder of run files (a sweep folder).
    pub path: PathBuf,
    /// CSV with a header line (empty cells where a row has no value).
    #[arg(long)]
    pub csv: bool,
    /// JSON: columns and rows, each row an object with every column (null where missing).
    #[arg(long)]
    pub json: bool,
    /// FILE: the one-row summary table (as for a folder) instead of the diagnostics.
    #[arg(long)]
    pub summary: bool,
    /// Write here instead of stdout (the path is printed).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

// `runner profile`.
#[derive(clap::Args, Debug)]
pub struct ProfileArgs {
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Output file (default: <run>-profile.svg beside the run; with several runs
    /// <first run>-profiles.svg).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Most worker threads `--threads` gives: twice the cores, and at least 8 (so that thread
/// counts beyond the cores can still be checked for determinism). Beyond that threads only
/// wait for each other: 1000 threads ran 100 times slower than 2.
fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (2 * cores).max(8)
}

/// `--threads N`: at least 1 (clap refuses 0 here, exit 2, so no command checks it again);
/// more than [`max_threads`] is capped, with a warning.
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

/// The worker threads a run uses: `--threads`, or one per core.
pub fn threads_or_cores(threads: Option<usize>) -> usize {
    threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}
