//! `runner calibrate`: back-calculate one manifest parameter (the yield stress) from a measured
//! workability result (a slump-flow diameter, an L-flow value), as seed 004 section 2.1 does by
//! "inverse calculation".
//!
//! The search: a first guess from the test's closed form where it has one
//! ([`crate::experiment::Experiment::yield_stress_guess_pa`]), else the geometric mean of the
//! bounds; rounds of `points_per_round` runs (run concurrently) that first bracket the
//! measured value, stepping by a factor of 2 towards it, then narrow the bracket: each round
//! takes the secant estimate in log-log space (a power law is a straight line there, e.g.
//! the pancake law R ~ tau^(-1/5)) and bisects the larger remaining part for the other runs.
//! It stops when the runs on both sides of the measured value are both within the tolerance
//! of it, so that the bracket they form is the fit's uncertainty. The rounds depend on
//! the manifest only (not on the machine's cores), so a calibration gives the same runs and
//! the same result everywhere; every run is an ordinary recorded run in the calibration's
//! folder, named by its experiment hash and reused when it is already there.
use crate::experiment::{self, Resolved, SceneSpec};
use crate::manifest::{self, ManifestError};
use crate::record::Outcome;
use crate::run::{RunError, RunOptions};
use crate::sweep_run::{PointStart, run_point};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A calibration manifest (YAML). Example in `experiments/calibrate_slump.yaml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Names the folder `<name>-calib-<hash>`.
    pub name: String,
    /// The experiment manifest whose runs are fitted, relative to this file.
    pub base: String,
    /// `KEY=VALUE` overrides applied to the base (as `--set`), e.g. a coarser spacing.
    #[serde(default)]
    pub set: Vec<String>,
    /// The measured value of one summary metric, e.g. `{spread_diameter_m: 0.62}`.
    pub measured: BTreeMap<String, f64>,
    /// How close a run's metric must come to the measured value (same unit).
    pub tolerance: BTreeMap<String, f64>,
    /// The manifest value fitted and its bounds, e.g. `{fluid.yield_stress_pa: [10, 200]}`.
    pub fit: BTreeMap<String, [f64; 2]>,
    /// Runs per round (run concurrently); part of the search, so fixed by the manifest.
    #[serde(default = "default_points_per_round")]
    pub points_per_round: u32,
    /// The search gives up (exit 3) after this many runs.
    #[serde(default = "default_max_evaluations")]
    pub max_evaluations: u32,
    /// A second spacing (m): the same fit there; the difference of the two fitted values is
    /// the spatial resolution's share of the uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check_spacing_m: Option<f64>,
}

fn default_points_per_round() -> u32 {
    2
}
fn default_max_evaluations() -> u32 {
    16
}

/// Why a calibration could not run or did not converge.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    #[error(transparent)]
    Manifest(#[from] ManifestError),
    #[error("{0}")]
    Run(String),
    /// A run was interrupted (signal): the calibration stops; run it again to go on.
    #[error("{0}")]
    Interrupted(String),
    /// The bounds do not contain the measured value (runs at both ends are on one side).
    #[error("{0}")]
    OutOfBounds(String),
    #[error(
        "no run came within the tolerance of the measured value in {0} runs (calibration.max_evaluations); the bracket reached is in calibration.json"
    )]
    NotConverged(u32),
}

/// The fitted quantities, checked and resolved.
#[derive(Debug, Clone)]
pub struct Plan {
    pub calibration: Calibration,
    /// The base manifest's path (resolved against the calibration file's folder).
    pub base_path: PathBuf,
    pub metric: String,
    pub target: f64,
    pub tolerance: f64,
    pub parameter: String,
    pub bounds: [f64; 2],
    /// SHA-256 of the calibration's canonical JSON and the base experiment's hash.
    pub hash_hex: String,
    /// The base experiment with `set` applied (its test gives the first guess).
    pub base: Resolved,
}

impl Plan {
    pub fn folder_name(&self) -> String {
        format!("{}-calib-{}", self.calibration.name, &self.hash_hex[..12])
    }
}

fn invalid(source: &str, text: &str, field: &str, message: String) -> ManifestError {
    let pos = manifest::locate::SourceMap::build(text).written_pos(field);
    ManifestError::Invalid {
        source_name: source.to_string(),
        field: field.to_string(),
        line: pos.map(|p| p.line),
        column: pos.map(|p| p.column),
        message,
    }
}

/// The one entry of a single-entry map, or an error naming the field.
fn single<'a, T>(
    map: &'a BTreeMap<String, T>,
    field: &str,
    bad: &dyn Fn(&str, String) -> ManifestError,
) -> Result<(&'a String, &'a T), ManifestError> {
    let mut it = map.iter();
    match (it.next(), it.next()) {
        (Some(entry), None) => Ok(entry),
        _ => Err(bad(
            field,
            format!(
                "must hold exactly one entry (one measured metric and one fitted value per calibration), got {}",
                map.len()
            ),
        )),
    }
}

/// Reads and checks a calibration manifest and the base experiment it names.
pub fn load(path: &Path) -> Result<Plan, ManifestError> {
    let text = std::fs::read_to_string(path).map_err(|source| ManifestError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let source = path.display().to_string();
    let calibration: Calibration = serde_saphyr::from_str(&text)
        .map_err(|e| manifest::syntax_error::<SceneSpec>(&e, &source, &text))?;
    let bad = |field: &str, message: String| invalid(&source, &text, field, message);
    let (metric, &target) = single(&calibration.measured, "measured", &bad)?;
    let (parameter, &[lo, hi]) = single(&calibration.fit, "fit", &bad)?;
    let tolerance = *calibration.tolerance.get(metric).ok_or_else(|| {
        bad(
            "tolerance",
            format!("must give the tolerance of the measured metric {metric}"),
        )
    })?;
    if calibration.tolerance.len() != 1 {
        return Err(bad(
            "tolerance",
            format!("must hold only the measured metric {metric}"),
        ));
    }
    if !(target.is_finite() && target > 0.0) {
        return Err(bad(
            &format!("measured.{metric}"),
            format!("must be a finite number > 0, got {target}"),
        ));
    }
    if !(tolerance.is_finite() && tolerance > 0.0 && tolerance < target) {
        return Err(bad(
            &format!("tolerance.{metric}"),
            format!("must be > 0 and below the measured value {target}, got {tolerance}"),
        ));
    }
    if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo < hi) {
        return Err(bad(
            &format!("fit.{parameter}"),
            format!("must be [min, max] with 0 < min < max, got [{lo}, {hi}]"),
        ));
    }
    if !(1..=16).contains(&calibration.points_per_round) {
        return Err(bad(
            "points_per_round",
            format!("must be in 1..=16, got {}", calibration.points_per_round),
        ));
    }
    if !(1..=200).contains(&calibration.max_evaluations) {
        return Err(bad(
            "max_evaluations",
            format!("must be in 1..=200, got {}", calibration.max_evaluations),
        ));
    }
    if let Some(s) = calibration.check_spacing_m
        && !(s.is_finite() && s > 0.0)
    {
        return Err(bad(
            "check_spacing_m",
            format!("must be a spacing > 0 (m), got {s}"),
        ));
    }
    let base_path = path
        .parent()
        .unwrap_or(Path::new("."))
        .join(&calibration.base);
    // The base at both bounds must be a valid experiment (the parameter is a real field).
    let base = experiment::load(&base_path, &calibration.set)?;
    for bound in [lo, hi] {
        experiment::load(&base_path, &sets_with(&calibration.set, parameter, bound))?;
    }
    if let Some(s) = calibration.check_spacing_m {
        let mut sets = calibration.set.clone();
        sets.push(format!("spacing_m={s}"));
        experiment::load(&base_path, &sets)?;
    }
    let mut known = experiment::metric_names(&base.manifest);
    known.extend(
        experiment::crossings(&base.manifest)
            .iter()
            .map(|c| c.name.to_string()),
    );
    if !known.contains(metric) {
        return Err(bad(
            &format!("measured.{metric}"),
            format!(
                "is not a metric of the {} test; it records: {}",
                base.manifest.scene_kind(),
                known.join(", ")
            ),
        ));
    }
    let canonical = serde_json::to_string(&calibration).expect("serialisable");
    let hash_hex = manifest::canonical::sha256_hex(&format!("{canonical}\n{}", base.hash_hex));
    Ok(Plan {
        metric: metric.clone(),
        target,
        tolerance,
        parameter: parameter.clone(),
        bounds: [lo, hi],
        base_path,
        hash_hex,
        base,
        calibration,
    })
}

fn sets_with(base: &[String], parameter: &str, value: f64) -> Vec<String> {
    let mut sets = base.to_vec();
    sets.push(format!("{parameter}={value}"));
    sets
}

/// A parameter value rounded to 4 significant digits: runs get tidy manifests, and a value
/// met again is the same run (reused, not rerun).
pub fn round4(x: f64) -> f64 {
    format!("{x:.3e}")
        .parse()
        .expect("a formatted number parses")
}

/// One run of the search.
#[derive(Debug, Clone, Serialize)]
pub struct Evaluation {
    pub round: u32,
    pub parameter: f64,
    /// The run's summary metric (NaN when the run failed).
    pub metric: f64,
    pub outcome: String,
    pub stop: String,
    pub file: String,
    pub experiment_sha256: String,
    /// `ran`, `existing` (reused) or `resumed`.
    pub start: &'static str,
}

/// One fit (at the base spacing, or at `check_spacing_m`).
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    pub spacing_m: f64,
    pub evaluations: Vec<Evaluation>,
    /// The closest runs on either side of the measured value, as (parameter, metric).
    pub bracket: Option<[(f64, f64); 2]>,
    /// The run closest to the measured value.
    pub best: Option<(f64, f64)>,
    /// Log-log interpolation to the measured value inside the bracket (else the best run).
    pub fitted: Option<f64>,
    pub converged: bool,
}

/// What a calibration did; written to `calibration.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Record {
    pub name: String,
    pub calibration_sha256: String,
    pub base: String,
    pub base_experiment_sha256: String,
    pub metric: String,
    pub measured: f64,
    pub tolerance: f64,
    pub parameter: String,
    pub bounds: [f64; 2],
    pub fits: Vec<Fit>,
    /// |fitted at the base spacing - fitted at check_spacing_m| / fitted at the base spacing.
    pub resolution_share: Option<f64>,
}

/// How to run the calibration's runs.
#[derive(Debug, Clone, Default)]
pub struct CalibrateOptions {
    pub out_dir: PathBuf,
    pub interrupt: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    pub max_particles: Option<u64>,
}

/// Runs the calibration; `on_run` is called for each finished run (in round order).
pub fn calibrate(
    plan: &Plan,
    options: &CalibrateOptions,
    on_run: &dyn Fn(&Fit, &Evaluation),
) -> (PathBuf, Record, Result<(), CalibrateError>) {
    let dir = options.out_dir.join(plan.folder_name());
    let mut record = Record {
        name: plan.calibration.name.clone(),
        calibration_sha256: plan.hash_hex.clone(),
        base: plan.calibration.base.clone(),
        base_experiment_sha256: plan.base.hash_hex.clone(),
        metric: plan.metric.clone(),
        measured: plan.target,
        tolerance: plan.tolerance,
        parameter: plan.parameter.clone(),
        bounds: plan.bounds,
        fits: Vec::new(),
        resolution_share: None,
    };
    let guess = {
        let m = &plan.base.manifest;
        experiment::yield_stress_guess_pa(m, &plan.metric, plan.target)
            .filter(|_| plan.parameter == "fluid.yield_stress_pa")
            .unwrap_or_else(|| libm::sqrt(plan.bounds[0] * plan.bounds[1]))
    };
    let mut spacings = vec![(plan.calibration.set.clone(), plan.base.manifest.spacing_m)];
    if let Some(s) = plan.calibration.check_spacing_m {
        let mut sets = plan.calibration.set.clone();
        sets.push(format!("spacing_m={s}"));
        spacings.push((sets, s));
    }
    let mut result = Ok(());
    for (sets, spacing_m) in spacings {
        // The check fit starts from the first fit's value.
        let start = record.fits.first().and_then(|f| f.fitted).unwrap_or(guess);
        let mut fit = Fit {
            spacing_m,
            evaluations: Vec::new(),
            bracket: None,
            best: None,
            fitted: None,
            converged: false,
        };
        let r = search(plan, &sets, start, &dir, options, &mut fit, on_run);
        record.fits.push(fit);
        if let Err(e) = r {
            result = Err(e);
            break;
        }
    }
    if let [a, b] = record.fits.as_slice()
        && let (Some(x), Some(y)) = (a.fitted, b.fitted)
    {
        record.resolution_share = Some((x - y).abs() / x);
    }
    (dir, record, result)
}

/// Bracket in parameter order: (parameter, metric) of the adjacent runs whose metrics lie on
/// either side of the target.
fn bracket_of(points: &[(f64, f64)], target: f64) -> Option<[(f64, f64); 2]> {
    let mut sorted: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.1.is_finite()).collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    sorted
        .windows(2)
        .find(|w| (w[0].1 - target) * (w[1].1 - target) <= 0.0)
        .map(|w| [w[0], w[1]])
}

/// The secant estimate in log-log space inside the bracket (geometric midpoint if the two
/// metrics are equal or not positive).
fn secant(b: [(f64, f64); 2], target: f64) -> f64 {
    let [(p0, m0), (p1, m1)] = b;
    if m0 > 0.0 && m1 > 0.0 && m0 != m1 {
        let (lp0, lp1) = (libm::log(p0), libm::log(p1));
        let (lm0, lm1, lt) = (libm::log(m0), libm::log(m1), libm::log(target));
        let s = lp0 + (lt - lm0) * (lp1 - lp0) / (lm1 - lm0);
        libm::exp(s.clamp(lp0.min(lp1), lp0.max(lp1)))
    } else {
        libm::sqrt(p0 * p1)
    }
}

fn search(
    plan: &Plan,
    sets: &[String],
    start: f64,
    dir: &Path,
    options: &CalibrateOptions,
    fit: &mut Fit,
    on_run: &dyn Fn(&Fit, &Evaluation),
) -> Result<(), CalibrateError> {
    let [lo, hi] = plan.bounds;
    let n = plan.calibration.points_per_round as usize;
    let max = plan.calibration.max_evaluations as usize;
    let target = plan.target;
    let clamp = |p: f64| round4(p.clamp(lo, hi));
    let mut round = 0u32;
    // Round 0: points around the guess, a factor 1.3 apart.
    let mut next: Vec<f64> = (0..n)
        .map(|i| clamp(start * libm::pow(1.3, i as f64 - (n as f64 - 1.0) / 2.0)))
        .collect();
    loop {
        next.dedup();
        let done: Vec<f64> = fit.evaluations.iter().map(|e| e.parameter).collect();
        next.retain(|p| !done.contains(p));
        next.truncate(max - fit.evaluations.len());
        if next.is_empty() {
            break;
        }
        for e in run_round(plan, sets, &next, round, dir, options)? {
            fit.evaluations.push(e);
            on_run(fit, fit.evaluations.last().expect("just pushed"));
        }
        round += 1;
        let points: Vec<(f64, f64)> = fit
            .evaluations
            .iter()
            .map(|e| (e.parameter, e.metric))
            .collect();
        fit.best = points
            .iter()
            .copied()
            .filter(|p| p.1.is_finite())
            .min_by(|a, b| (a.1 - target).abs().total_cmp(&(b.1 - target).abs()));
        fit.bracket = bracket_of(&points, target);
        fit.fitted = fit
            .bracket
            .map(|b| secant(b, target))
            .or(fit.best.map(|b| b.0));
        let within = fit
            .best
            .is_some_and(|b| (b.1 - target).abs() <= plan.tolerance);
        // Done when the runs on both sides of the measured value are within the tolerance of
        // it: every value in the bracket then gives it within the tolerance (for a monotone
        // response), so the bracket is the fit's uncertainty.
        let tight = fit.bracket.is_some_and(|b| {
            (b[0].1 - target).abs() <= plan.tolerance && (b[1].1 - target).abs() <= plan.tolerance
        });
        if tight {
            fit.converged = true;
            return Ok(());
        }
        if fit.evaluations.len() >= max {
            break;
        }
        next = match fit.bracket {
            Some(b) => narrowing_points(b, target, n),
            None => widening_points(plan, &points, n, if within { 1.1 } else { 2.0 })?,
        };
    }
    Err(CalibrateError::NotConverged(fit.evaluations.len() as u32))
}

/// Inside the bracket: the secant estimate, then bisections of the larger remaining part.
fn narrowing_points(b: [(f64, f64); 2], target: f64, n: usize) -> Vec<f64> {
    let mut cuts = vec![b[0].0, round4(secant(b, target)), b[1].0];
    while cuts.len() < n + 2 {
        let (i, _) =
            cuts.windows(2)
                .map(|w| w[1] / w[0])
                .enumerate()
                .fold(
                    (0, 0.0),
                    |best, (i, r)| if r > best.1 { (i, r) } else { best },
                );
        let mid = round4(libm::sqrt(cuts[i] * cuts[i + 1]));
        if mid <= cuts[i] || mid >= cuts[i + 1] {
            break;
        }
        cuts.insert(i + 1, mid);
    }
    cuts[1..cuts.len() - 1].to_vec()
}

/// No bracket yet: every run is on one side of the measured value. Step beyond the run
/// nearest the value, by powers of `factor` (2; 1.1 once a run is within the tolerance), in
/// the direction the response points to.
fn widening_points(
    plan: &Plan,
    points: &[(f64, f64)],
    n: usize,
    factor: f64,
) -> Result<Vec<f64>, CalibrateError> {
    let [lo, hi] = plan.bounds;
    let mut ok: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.1.is_finite()).collect();
    if ok.is_empty() {
        return Err(CalibrateError::Run(
            "every run of the first round failed; see their files".into(),
        ));
    }
    ok.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (first, last) = (ok[0], ok[ok.len() - 1]);
    // The direction from the data when the runs differ by more than the tolerance (a
    // simulated metric scatters by about a spacing); else the physical prior: a flow length
    // falls as the yield stress (or viscosity) rises, a time (a metric in seconds) rises.
    let falling = if (last.1 - first.1).abs() > plan.tolerance {
        last.1 < first.1
    } else {
        !plan.metric.ends_with("_s")
    };
    let below = first.1 < plan.target; // every metric is below the target
    let go_down = below == falling;
    let (from, bound) = if go_down { (first, lo) } else { (last, hi) };
    if from.0 == bound {
        return Err(CalibrateError::OutOfBounds(format!(
            "the measured {} = {} is outside what fit.{} in [{lo}, {hi}] gives: at {} the run gives {}",
            plan.metric, plan.target, plan.parameter, from.0, from.1
        )));
    }
    Ok((1..=n)
        .map(|k| {
            let f = libm::pow(factor, k as f64);
            round4(if go_down { from.0 / f } else { from.0 * f }.clamp(lo, hi))
        })
        .collect())
}

fn run_round(
    plan: &Plan,
    sets: &[String],
    values: &[f64],
    round: u32,
    dir: &Path,
    options: &CalibrateOptions,
) -> Result<Vec<Evaluation>, CalibrateError> {
    let resolved: Vec<Resolved> = values
        .iter()
        .map(|&v| experiment::load(&plan.base_path, &sets_with(sets, &plan.parameter, v)))
        .collect::<Result<_, _>>()?;
    let run_options = RunOptions {
        out_dir: dir.to_path_buf(),
        threads: Some(1),
        progress: false,
        interrupt: options.interrupt.clone(),
        max_particles: options.max_particles,
        overwrite: false,
    };
    let results: Vec<(Result<crate::run::RunResult, RunError>, PointStart)> =
        std::thread::scope(|s| {
            let handles: Vec<_> = resolved
                .iter()
                .map(|r| s.spawn(|| run_point(r, &run_options)))
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("a calibration run panicked"))
                .collect()
        });
    let mut out = Vec::new();
    for ((value, r), (result, start)) in values.iter().zip(&resolved).zip(results) {
        let result = result.map_err(|e| CalibrateError::Run(e.to_string()))?;
        if let Outcome::Interrupted(why) = &result.outcome {
            return Err(CalibrateError::Interrupted(format!(
                "{}: {why}; run the calibration again to go on",
                result.path.display()
            )));
        }
        out.push(Evaluation {
            round,
            parameter: *value,
            metric: match result.outcome {
                Outcome::Completed => result
                    .summary
                    .metrics
                    .get(&plan.metric)
                    .copied()
                    .unwrap_or(f64::NAN),
                _ => f64::NAN,
            },
            outcome: result.outcome.as_str().to_string(),
            stop: result.summary.stop.clone(),
            file: result
                .path
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            experiment_sha256: r.hash_hex.clone(),
            start: start.as_str(),
        });
    }
    Ok(out)
}

/// Writes `calibration.json` and the figure (metric against parameter, every run, the
/// measured value as a line) into the calibration's folder.
pub fn write_record(dir: &Path, record: &Record) -> std::io::Result<(PathBuf, PathBuf)> {
    std::fs::create_dir_all(dir)?;
    let json = dir.join("calibration.json");
    let text = serde_json::to_string_pretty(record).expect("serialisable");
    let partial = dir.join("calibration.json.partial");
    std::fs::write(&partial, text + "\n")?;
    std::fs::rename(&partial, &json)?;
    let figure = dir.join(format!(
        "calibration-{}-vs-{}.svg",
        record.metric, record.parameter
    ));
    let mut series = Vec::new();
    for fit in &record.fits {
        let mut points: Vec<(f64, f64)> = fit
            .evaluations
            .iter()
            .filter(|e| e.metric.is_finite())
            .map(|e| (e.parameter, e.metric))
            .collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        series.push(crate::report::plot::Series {
            label: format!("runs at spacing {} m", fit.spacing_m),
            points,
        });
    }
    let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
    let (x0, x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if x0.is_finite() {
        series.push(crate::report::plot::Series {
            label: format!("measured {} = {}", record.metric, record.measured),
            points: vec![(x0, record.measured), (x1, record.measured)],
        });
    }
    crate::report::plot::line_plot(
        &figure,
        &format!(
            "calibration {}: {} against {}",
            record.name, record.metric, record.parameter
        ),
        &crate::report::axis_label(&record.parameter),
        &crate::report::axis_label(&record.metric),
        &series,
        true,
    )
    .map_err(|e| std::io::Error::other(e.to_string()))?;
    Ok((json, figure))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn narrowing_takes_the_secant_then_bisects_the_larger_part() {
        // R ~ tau^(-1/5): the log-log secant through two exact points hits the target.
        let law = |t: f64| libm::pow(t, -0.2);
        let b = [(20.0, law(20.0)), (80.0, law(80.0))];
        let s = secant(b, law(50.0));
        assert!((s - 50.0).abs() < 1e-9, "{s}");
        let pts = narrowing_points(b, law(50.0), 2);
        assert_eq!(pts.len(), 2);
        assert_eq!(pts[1], 50.0);
        // The larger part in log terms is [20, 50]: its geometric midpoint 31.62.
        assert_eq!(pts[0], round4(libm::sqrt(20.0 * 50.0)));
    }

    #[test]
    fn the_bracket_is_the_adjacent_pair_around_the_target() {
        let pts = [(10.0, 0.8), (40.0, 0.6), (20.0, 0.7), (80.0, 0.5)];
        assert_eq!(bracket_of(&pts, 0.65), Some([(20.0, 0.7), (40.0, 0.6)]));
        assert_eq!(bracket_of(&pts, 0.9), None);
    }

    #[test]
    fn rounding_keeps_four_significant_digits() {
        assert_eq!(round4(47.26789), 47.27);
        assert_eq!(round4(0.0123456), 0.01235);
    }
}
