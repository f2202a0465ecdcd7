//! `runner bench --suite FILE`: the time-to-result benchmark in one command. Each case runs
//! in a child process (`runner bench MANIFEST --set ...`, or the sweep itself for a sweep
//! manifest), so that its peak memory is its own and so that any binary of ours, an older
//! one included (`--runner PATH`), can be measured the same way. Progress goes to stderr,
//! the Markdown tables to stdout (and `--markdown FILE`).
//!
//! Exit codes: 0 every run completed; 3 some case did not (its row says why: the suite goes
//! on); 2 bad suite file or command line (`--runner` that does not run); 1 the Markdown file
//! cannot be written; 130 interrupted (the tables so far are still printed).

mod child;
mod suite_file;
mod table;

use child::Measured;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use suite_file::{Case, Scaling, Suite};
use table::{CaseRow, NA, ScalePoint};

use crate::error::{self, CliError, Done};

/// `runner bench --suite` options.
#[derive(Debug)]
pub struct SuiteArgs {
    pub suite: PathBuf,
    pub quick: bool,
    pub runner: Option<PathBuf>,
    pub threads: Option<usize>,
    pub markdown: Option<PathBuf>,
    /// Only these cases (`scaling` for the scaling series); empty = all.
    pub cases: Vec<String>,
}

/// The binary that runs the cases, as shown in the commands.
struct Runner {
    path: PathBuf,
    shown: String,
    build: String,
}

/// Runs every case (then the scaling series) and prints the tables, also after an interrupt.
pub fn command(args: SuiteArgs) -> error::Result {
    let suite = suite_file::load(&args.suite, args.quick)?;
    let suite = only_cases(suite, &args.cases)
        .map_err(|why| CliError::BadInput(format!("--case: {why}")))?;
    let runner = runner(args.runner.as_deref()).map_err(CliError::BadInput)?;
    let interrupted = interrupt_flag();
    let mut all_completed = true;
    let rows = run_cases(&suite, &runner, &args, &interrupted, &mut all_completed);
    let points = match &suite.scaling {
        Some(s) if !interrupted.load(Ordering::SeqCst) => {
            run_scaling(s, &runner, &args, &interrupted, &mut all_completed)
        }
        _ => Vec::new(),
    };
    let text = markdown(&suite, &runner, &args, &rows, &points);
    print!("{text}");
    if let Some(path) = &args.markdown {
        std::fs::write(path, &text)
            .map_err(|e| CliError::Internal(format!("cannot write {}: {e}", path.display())))?;
    }
    Ok(if interrupted.load(Ordering::SeqCst) {
        Done::Interrupted
    } else if all_completed {
        Done::Success
    } else {
        Done::SimFailed
    })
}

/// The suite cut to the cases named by `--case` (all when none is named); `scaling` names the
/// scaling series. An unknown name is refused with the names there are.
fn only_cases(mut suite: Suite, names: &[String]) -> Result<Suite, String> {
    if names.is_empty() {
        return Ok(suite);
    }
    let known: Vec<&str> = suite.cases.iter().map(|c| c.name.as_str()).collect();
    if let Some(bad) = names
        .iter()
        .find(|n| *n != "scaling" && !known.contains(&n.as_str()))
    {
        return Err(format!(
            "no case `{bad}` in the suite (cases: {}, scaling)",
            known.join(", ")
        ));
    }
    suite.cases.retain(|c| names.contains(&c.name));
    if !names.iter().any(|n| n == "scaling") {
        suite.scaling = None;
    }
    Ok(suite)
}

/// `--runner PATH` (checked by running its `--version`, which also gives its build line), or
/// this executable with its own build identity.
fn runner(given: Option<&Path>) -> Result<Runner, String> {
    let Some(path) = given else {
        let path = std::env::current_exe()
            .map_err(|e| format!("cannot find this executable to run the cases: {e}"))?;
        let shown = shown_path(&path);
        let build = mps_runner::build_info::BuildInfo::current().to_string();
        return Ok(Runner { path, shown, build });
    };
    let out = std::process::Command::new(path)
        .arg("--version")
        .output()
        .map_err(|e| format!("--runner {}: cannot run it: {e}", path.display()))?;
    if !out.status.success() {
        return Err(format!(
            "--runner {}: `--version` failed ({})",
            path.display(),
            out.status
        ));
    }
    Ok(Runner {
        path: path.to_path_buf(),
        shown: path.display().to_string(),
        build: String::from_utf8_lossy(&out.stdout).trim().to_string(),
    })
}

/// This executable as a command a user can paste: relative to the current folder when it is
/// below it (`./target/release/runner`).
fn shown_path(path: &Path) -> String {
    std::env::current_dir()
        .ok()
        .and_then(|cwd| path.strip_prefix(cwd).ok().map(Path::to_path_buf))
        .map_or_else(
            || path.display().to_string(),
            |rel| format!("./{}", rel.display()),
        )
}

/// SIGINT/SIGTERM stop the suite after the case that is running (a terminal's Ctrl-C also
/// reaches the child, which finishes its run as interrupted); the tables so far are printed.
fn interrupt_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let set = flag.clone();
    if let Err(e) = ctrlc::set_handler(move || {
        set.store(true, Ordering::SeqCst);
        eprintln!("interrupt: stopping the suite after the case that is running");
    }) {
        eprintln!("warning: cannot install the signal handler: {e}");
    }
    flag
}

fn run_cases(
    suite: &Suite,
    runner: &Runner,
    args: &SuiteArgs,
    interrupted: &AtomicBool,
    all_completed: &mut bool,
) -> Vec<CaseRow> {
    let mut rows = Vec::new();
    for (k, case) in suite.cases.iter().enumerate() {
        let label = format!("case {}/{} {}", k + 1, suite.cases.len(), case.name);
        let (row, completed) = match case.sweep_points {
            None => bench_case(case, runner, args, &label),
            Some(points) => sweep_case(case, points, runner, args, &label, k),
        };
        *all_completed &= completed;
        let stop = !completed && row.outcome.contains("exit 130");
        rows.push(row);
        if stop || interrupted.load(Ordering::SeqCst) {
            interrupted.store(true, Ordering::SeqCst);
            break;
        }
    }
    rows
}

/// `runner bench MANIFEST --set ... [--threads N]`, its report read back.
fn bench_case(case: &Case, runner: &Runner, args: &SuiteArgs, label: &str) -> (CaseRow, bool) {
    let argv = bench_args(&case.manifest, &case.sets, args.threads);
    let command = command_text(&runner.shown, &argv);
    eprintln!("bench suite: {label}: {command}");
    let mut row = empty_row(&case.name, &command);
    let Some(measured) = started(child::run(&runner.path, &argv), &mut row) else {
        return (row, false);
    };
    if let Some(r) = child::parse_bench(&measured.stdout) {
        row.particles = r.particles.to_string();
        row.steps = r.steps.to_string();
        row.wall_s = format!("{:.3}", r.wall_s);
        row.rate = format!("{:.0}", r.particle_steps_per_s);
        row.stages = table::largest_stages(&r.stages);
        row.outcome = r.outcome;
    }
    // Every stage's seconds, which the table's three largest shares do not give (comparing
    // thread counts stage by stage needs them).
    for line in child::stage_table(&measured.stdout) {
        eprintln!("    {line}");
    }
    finish_row(row, &measured)
}

/// The measured child with its time to result and peak memory in the row, or None with the
/// reason it could not start in the outcome cell.
fn started(run: std::io::Result<Measured>, row: &mut CaseRow) -> Option<Measured> {
    match run {
        Ok(m) => {
            row.time_to_result_s = format!("{:.2}", m.wall_s);
            row.peak_mib = table::mib(m.peak_kib);
            Some(m)
        }
        Err(e) => {
            row.outcome = format!("cannot start: {e}");
            eprintln!("  {}", row.outcome);
            None
        }
    }
}

/// The outcome cell with the exit status when the run did not succeed, and the progress line.
fn finish_row(mut row: CaseRow, measured: &Measured) -> (CaseRow, bool) {
    let completed = measured.success() && row.outcome == "completed";
    if row.outcome == NA {
        row.outcome = format!("error ({})", measured.status_text());
    } else if !measured.success() {
        row.outcome = format!("{} ({})", row.outcome, measured.status_text());
    }
    if !measured.success()
        && let Some(line) = measured.error_line()
    {
        eprintln!("  {line}");
    }
    eprintln!(
        "  {} in {:.2} s, peak {} MiB",
        row.outcome, measured.wall_s, row.peak_mib
    );
    (row, completed)
}

/// The sweep run as a user runs it (`runner MANIFEST --out TMP --quiet`), timed as a whole;
/// particle-steps summed over its points from their run files.
fn sweep_case(
    case: &Case,
    points: usize,
    runner: &Runner,
    args: &SuiteArgs,
    label: &str,
    k: usize,
) -> (CaseRow, bool) {
    let tmp = TempDir::new(k);
    let mut argv: Vec<OsString> = vec![case.manifest.clone().into()];
    argv.extend(set_args(&case.sets));
    argv.extend(["--out".into(), tmp.0.clone().into(), "--quiet".into()]);
    argv.extend(threads_args(args.threads));
    let command = command_text(&runner.shown, &argv);
    eprintln!("bench suite: {label} (a sweep of {points} points): {command}");
    let mut row = empty_row(&format!("{} ({points} points)", case.name), &command);
    let run = tmp.create().and_then(|()| child::run(&runner.path, &argv));
    let Some(measured) = started(run, &mut row) else {
        return (row, false);
    };
    row.wall_s = row.time_to_result_s.clone();
    match sweep_totals(&tmp.0) {
        Ok(t) => fill_sweep_row(&mut row, &t, points, measured.wall_s),
        Err(why) => eprintln!("  no run files to read: {why}"),
    }
    finish_row(row, &measured)
}

/// What the points' run files say, summed.
struct SweepTotals {
    files: usize,
    completed: usize,
    particles: (f64, f64),
    steps: f64,
    particle_steps: f64,
}

/// Reads every run file of the sweep folder(s) in `dir` with the library's reader (the
/// summary's `steps` and `particle_count`, as `runner export DIR` does).
fn sweep_totals(dir: &Path) -> Result<SweepTotals, String> {
    let mut t = SweepTotals {
        files: 0,
        completed: 0,
        particles: (f64::INFINITY, 0.0),
        steps: 0.0,
        particle_steps: 0.0,
    };
    let folders = std::fs::read_dir(dir).map_err(|e| e.to_string())?;
    for folder in folders
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
    {
        let (rows, _) =
            mps_runner::report::export::finished_rows(&folder).map_err(|e| e.to_string())?;
        for summary in rows.iter().filter_map(|r| r.summary.as_ref()) {
            let metric = |k: &str| summary.metrics.get(k).copied().unwrap_or(0.0);
            let (steps, particles) = (metric("steps"), metric("particle_count"));
            t.files += 1;
            t.completed += usize::from(summary.outcome == "completed");
            t.particles = (t.particles.0.min(particles), t.particles.1.max(particles));
            t.steps += steps;
            t.particle_steps += steps * particles;
        }
    }
    if t.files == 0 {
        return Err(format!("no finished run file under {}", dir.display()));
    }
    Ok(t)
}

/// Particles: the points' count when they all have the same, else `min-max`; steps: summed;
/// particle-steps/s over the sweep's whole wall time.
fn fill_sweep_row(row: &mut CaseRow, t: &SweepTotals, points: usize, wall_s: f64) {
    let (lo, hi) = t.particles;
    row.particles = if lo == hi {
        hi.to_string()
    } else {
        format!("{lo}-{hi}")
    };
    row.steps = t.steps.to_string();
    row.rate = format!("{:.0}", t.particle_steps / wall_s.max(1e-9));
    row.outcome = if t.completed == points {
        "completed".into()
    } else {
        format!("{} of {points} completed", t.completed)
    };
}

/// The scaling series: `runner bench` at each spacing (`--set spacing_m=S` after the rest).
fn run_scaling(
    s: &Scaling,
    runner: &Runner,
    args: &SuiteArgs,
    interrupted: &AtomicBool,
    all_completed: &mut bool,
) -> Vec<ScalePoint> {
    let mut points = Vec::new();
    for (k, spacing) in s.spacings_m.iter().enumerate() {
        let argv = bench_args(&s.manifest, &scaling_sets(s, *spacing), args.threads);
        let command = command_text(&runner.shown, &argv);
        eprintln!(
            "bench suite: scaling {}/{}: {command}",
            k + 1,
            s.spacings_m.len()
        );
        let point = scale_point(*spacing, child::run(&runner.path, &argv));
        eprintln!(
            "  {} (peak {} MiB)",
            point.outcome,
            table::mib(point.peak_kib)
        );
        *all_completed &= point.outcome == "completed";
        let stop = point.outcome.contains("exit 130");
        points.push(point);
        if stop || interrupted.load(Ordering::SeqCst) {
            interrupted.store(true, Ordering::SeqCst);
            break;
        }
    }
    points
}

fn scaling_sets(s: &Scaling, spacing: f64) -> Vec<String> {
    let mut sets = s.sets.clone();
    sets.push(format!("spacing_m={spacing}"));
    sets
}

fn scale_point(spacing_m: f64, measured: std::io::Result<Measured>) -> ScalePoint {
    let measured = match measured {
        Ok(m) => m,
        Err(e) => {
            return ScalePoint {
                spacing_m,
                report: None,
                peak_kib: None,
                outcome: format!("cannot start: {e}"),
            };
        }
    };
    let report = child::parse_bench(&measured.stdout);
    let mut outcome = report
        .as_ref()
        .map_or("error".into(), |r| r.outcome.clone());
    if !measured.success() {
        outcome = format!("{outcome} ({})", measured.status_text());
    }
    ScalePoint {
        spacing_m,
        report,
        peak_kib: measured.peak_kib,
        outcome,
    }
}

fn bench_args(manifest: &Path, sets: &[String], threads: Option<usize>) -> Vec<OsString> {
    let mut argv: Vec<OsString> = vec!["bench".into(), manifest.into()];
    argv.extend(set_args(sets));
    argv.extend(threads_args(threads));
    argv
}

fn set_args(sets: &[String]) -> Vec<OsString> {
    sets.iter()
        .flat_map(|s| ["--set".into(), s.into()])
        .collect()
}

fn threads_args(threads: Option<usize>) -> Vec<OsString> {
    threads
        .map(|n| vec!["--threads".into(), n.to_string().into()])
        .unwrap_or_default()
}

/// The command as a shell would take it: words with other than plain characters quoted.
fn command_text(runner: &str, argv: &[OsString]) -> String {
    std::iter::once(runner.to_string())
        .chain(argv.iter().map(|a| a.to_string_lossy().into_owned()))
        .map(|w| shell_word(&w))
        .collect::<Vec<_>>()
        .join(" ")
}

fn shell_word(word: &str) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "_./=:,+-@%".contains(c);
    if !word.is_empty() && word.chars().all(plain) {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', r"'\''"))
    }
}

fn empty_row(name: &str, command: &str) -> CaseRow {
    CaseRow {
        name: name.to_string(),
        command: command.to_string(),
        particles: NA.into(),
        steps: NA.into(),
        wall_s: NA.into(),
        rate: NA.into(),
        time_to_result_s: NA.into(),
        outcome: NA.into(),
        stages: NA.into(),
        peak_mib: NA.into(),
    }
}

/// A sweep's output folder, removed when dropped (the runs are by-products of the timing).
struct TempDir(PathBuf);

impl TempDir {
    fn new(k: usize) -> TempDir {
        let name = format!("mps_bench_suite-{}-{k}", std::process::id());
        TempDir(std::env::temp_dir().join(name))
    }

    fn create(&self) -> std::io::Result<()> {
        let _ = std::fs::remove_dir_all(&self.0);
        std::fs::create_dir_all(&self.0)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn markdown(
    suite: &Suite,
    runner: &Runner,
    args: &SuiteArgs,
    rows: &[CaseRow],
    points: &[ScalePoint],
) -> String {
    let mut text = header(runner, args) + "\n";
    if !suite.cases.is_empty() {
        text += "\n";
        text += &table::case_table(rows);
    }
    if let Some(s) = &suite.scaling {
        let sets = [s.sets.clone(), vec!["spacing_m=S".to_string()]].concat();
        let command = command_text(&runner.shown, &bench_args(&s.manifest, &sets, args.threads));
        text += "\n";
        text += &table::scaling_table(&command, points);
    }
    text
}

/// One line: suite, runner and its build, threads, date (UTC), CPUs.
fn header(runner: &Runner, args: &SuiteArgs) -> String {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = args
        .threads
        .map_or_else(|| format!("default (all {cpus})"), |n| n.to_string());
    format!(
        "Benchmark suite `{}`{}: runner `{}` ({}), threads {threads}, {} UTC, {cpus} CPUs",
        args.suite.display(),
        if args.quick { " (--quick)" } else { "" },
        runner.shown,
        runner.build,
        utc_now()
    )
}

/// `YYYY-MM-DD HH:MM` from the system clock (days to a civil date: H. Hinnant's algorithm,
/// to need no date crate for one line).
fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as i64);
    let (days, rest) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}",
        rest / 3600,
        rest % 3600 / 60
    )
}

fn civil_from_days(days: i64) -> (i64, i64, i64) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_782), (2024, 2, 29));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
    }

    #[test]
    fn shell_words_quoted_when_needed() {
        assert_eq!(shell_word("spacing_m=0.005"), "spacing_m=0.005");
        assert_eq!(shell_word("a=[1, 2]"), "'a=[1, 2]'");
        assert_eq!(shell_word("it's"), r"'it'\''s'");
    }
}
