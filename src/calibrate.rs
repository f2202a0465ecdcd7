//! `runner calibrate`: back-calculate manifest values (the yield stress, and optionally the
//! plastic viscosity) from measured workability results (a slump-flow diameter and its t500
//! time, an L-flow value), as seed 004 section 2.1 does by "inverse calculation".
//!
//! One fitted value: a first guess from the test's closed form where it has one
//! ([`crate::experiment::Experiment::yield_stress_guess_pa`]), else the geometric mean of the
//! bounds; rounds of `points_per_round` runs (run concurrently)
//! that first bracket the measured value, stepping by a factor of 2 towards it, then narrow the
//! bracket: each round takes the secant estimate in log-log space (a power law is a straight
//! line there, e.g. the pancake law R ~ tau^(-1/5)) and bisects the larger remaining part for
//! the other runs. It stops when the runs on both sides of the measured value are both within
//! the tolerance of it, so that the bracket they form is the fit's uncertainty.
//!
//! Several fitted values (`pairs`: each from one measured metric): alternating one-value
//! searches (block coordinate descent), each holding the others at their latest fitted
//! values, in the order of `pairs`, until the two runs bracketing a stage's value meet every
//! measured metric within its tolerance. A time metric's stage after the first starts from
//! t ~ mu_p (the viscous time scale mu_p / (rho g H)): value * measured / simulated.
//!
//! The rounds depend on the manifest only (not on the machine's cores), so a calibration gives
//! the same runs and the same result everywhere; every run is an ordinary recorded run in the
//! calibration's folder, named by its experiment hash and reused when it is already there.
use crate::experiment::{self, Resolved, SceneSpec};
use crate::manifest::{self, ManifestError};
use crate::record::Outcome;
use crate::run::{RunError, RunOptions};
use crate::sweep_run::{PointStart, run_point};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A calibration manifest (YAML). Examples in `experiments/calibrations/`.
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
    /// The measured summary metrics, e.g. `{spread_diameter_m: 0.62, t500_s: 1.5}`.
    pub measured: BTreeMap<String, f64>,
    /// How close a run's metric must come to each measured value (same unit).
    pub tolerance: BTreeMap<String, f64>,
    /// The manifest values fitted and their bounds, e.g. `{fluid.yield_stress_pa: [10, 200]}`.
    pub fit: BTreeMap<String, [f64; 2]>,
    /// With more than one fitted value: which measured metric each is fitted from, in the
    /// order the alternating search visits them (empty, and left out of the hash, for one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pairs: Vec<PairSpec>,
    /// Runs per round (run concurrently); part of the search, so fixed by the manifest.
    #[serde(default = "default_points_per_round")]
    pub points_per_round: u32,
    /// The search gives up (exit 3) after this many runs (per spacing).
    #[serde(default = "default_max_evaluations")]
    pub max_evaluations: u32,
    /// A second spacing (m): the same fit there; the difference of the two fitted values is
    /// the spatial resolution's share of the uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check_spacing_m: Option<f64>,
}

/// One entry of `pairs`: the fitted value `fit` is fitted from the measured metric `from`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PairSpec {
    pub fit: String,
    pub from: String,
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
        "the measured values were not all met within their tolerances in {0} runs (calibration.max_evaluations); the brackets reached are in calibration.json"
    )]
    NotConverged(u32),
}

/// One fitted value with the measured metric it is fitted from, checked.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Pair {
    pub parameter: String,
    pub bounds: [f64; 2],
    pub metric: String,
    pub measured: f64,
    pub tolerance: f64,
}

/// The calibration, checked and resolved.
#[derive(Debug, Clone)]
pub struct Plan {
    pub calibration: Calibration,
    /// The base manifest's path (resolved against the calibration file's folder).
    pub base_path: PathBuf,
    /// In the order the search visits them.
    pub pairs: Vec<Pair>,
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

/// The (fitted value, measured metric) pairs: implicit for one of each, else from `pairs`,
/// which must use every fitted value and every measured metric exactly once.
fn pairs_of(
    c: &Calibration,
    bad: &dyn Fn(&str, String) -> ManifestError,
) -> Result<Vec<(String, String)>, ManifestError> {
    if c.measured.is_empty() {
        return Err(bad(
            "measured",
            "must give at least one measured metric".into(),
        ));
    }
    if c.fit.len() != c.measured.len() {
        return Err(bad(
            "fit",
            format!(
                "must hold as many fitted values as there are measured metrics (one fitted from each), got {} and {}",
                c.fit.len(),
                c.measured.len()
            ),
        ));
    }
    if c.fit.len() == 1 && c.pairs.is_empty() {
        let p = c.fit.keys().next().expect("one");
        let m = c.measured.keys().next().expect("one");
        return Ok(vec![(p.clone(), m.clone())]);
    }
    if c.pairs.len() != c.fit.len() {
        return Err(bad(
            "pairs",
            format!(
                "must name, for each of the {} fitted values, the measured metric it is fitted from, e.g. `- {{fit: fluid.yield_stress_pa, from: spread_diameter_m}}`; got {} entries",
                c.fit.len(),
                c.pairs.len()
            ),
        ));
    }
    let mut out: Vec<(String, String)> = Vec::new();
    for (i, p) in c.pairs.iter().enumerate() {
        let field = format!("pairs[{i}]");
        if !c.fit.contains_key(&p.fit) {
            return Err(bad(&field, format!("fit {} is not a key of `fit`", p.fit)));
        }
        if !c.measured.contains_key(&p.from) {
            return Err(bad(
                &field,
                format!("from {} is not a key of `measured`", p.from),
            ));
        }
        if out.iter().any(|(f, m)| *f == p.fit || *m == p.from) {
            return Err(bad(
                &field,
                format!(
                    "{} or {} is already paired: each fitted value and each measured metric appears once",
                    p.fit, p.from
                ),
            ));
        }
        out.push((p.fit.clone(), p.from.clone()));
    }
    Ok(out)
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
    let named = pairs_of(&calibration, &bad)?;
    if let Some(extra) = calibration
        .tolerance
        .keys()
        .find(|k| !calibration.measured.contains_key(*k))
    {
        return Err(bad(
            &format!("tolerance.{extra}"),
            "is not a measured metric: give a tolerance for each measured metric only".into(),
        ));
    }
    let mut pairs = Vec::new();
    for (parameter, metric) in named {
        let measured = calibration.measured[&metric];
        let tolerance = *calibration.tolerance.get(&metric).ok_or_else(|| {
            bad(
                "tolerance",
                format!("must give the tolerance of the measured metric {metric}"),
            )
        })?;
        let [lo, hi] = calibration.fit[&parameter];
        if !(measured.is_finite() && measured > 0.0) {
            return Err(bad(
                &format!("measured.{metric}"),
                format!("must be a finite number > 0, got {measured}"),
            ));
        }
        if !(tolerance.is_finite() && tolerance > 0.0 && tolerance < measured) {
            return Err(bad(
                &format!("tolerance.{metric}"),
                format!("must be > 0 and below the measured value {measured}, got {tolerance}"),
            ));
        }
        if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo < hi) {
            return Err(bad(
                &format!("fit.{parameter}"),
                format!("must be [min, max] with 0 < min < max, got [{lo}, {hi}]"),
            ));
        }
        pairs.push(Pair {
            parameter,
            bounds: [lo, hi],
            metric,
            measured,
            tolerance,
        });
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
    // The base at every bound must be a valid experiment (each fitted value is a real field).
    let base = experiment::load(&base_path, &calibration.set)?;
    for pair in &pairs {
        for bound in pair.bounds {
            let value = BTreeMap::from([(pair.parameter.clone(), bound)]);
            experiment::load(&base_path, &sets_with(&calibration.set, &value))?;
        }
    }
    if let Some(s) = calibration.check_spacing_m {
        let mut sets = calibration.set.clone();
        sets.push(format!("spacing_m={s}"));
        experiment::load(&base_path, &sets)?;
    }
    let mut known = experiment::metric_names(&base.manifest);
    known.extend(experiment::row_metric_names(&base.manifest));
    for pair in &pairs {
        if !known.contains(&pair.metric) {
            return Err(bad(
                &format!("measured.{}", pair.metric),
                format!(
                    "is not a metric of the {} test; it records: {}",
                    base.manifest.scene_kind(),
                    known.join(", ")
                ),
            ));
        }
    }
    let canonical = serde_json::to_string(&calibration).expect("serialisable");
    let hash_hex = manifest::canonical::sha256_hex(&format!("{canonical}\n{}", base.hash_hex));
    Ok(Plan {
        pairs,
        base_path,
        hash_hex,
        base,
        calibration,
    })
}

fn sets_with(base: &[String], values: &BTreeMap<String, f64>) -> Vec<String> {
    let mut sets = base.to_vec();
    sets.extend(values.iter().map(|(k, v)| format!("{k}={v}")));
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
    /// Every fitted value of this run.
    pub values: BTreeMap<String, f64>,
    /// The run's measured metrics (NaN, written null, when the run failed).
    pub metrics: BTreeMap<String, f64>,
    pub outcome: String,
    pub stop: String,
    pub file: String,
    pub experiment_sha256: String,
    /// `ran`, `existing` (reused) or `resumed`.
    pub start: &'static str,
}

/// One one-value search: `parameter` fitted from `metric`, the other fitted values `held`.
#[derive(Debug, Clone, Serialize)]
pub struct Stage {
    /// 0 for the first pass over the pairs, 1 for the second, ...
    pub alternation: u32,
    pub parameter: String,
    pub metric: String,
    pub held: BTreeMap<String, f64>,
    pub evaluations: Vec<Evaluation>,
    /// The closest runs on either side of the measured value, as (parameter, metric).
    pub bracket: Option<[(f64, f64); 2]>,
    /// The run closest to the measured value.
    pub best: Option<(f64, f64)>,
    /// Log-log interpolation to the measured value inside the bracket (else the best run).
    pub fitted: Option<f64>,
    pub converged: bool,
}

/// One fit (at the base spacing, or at `check_spacing_m`).
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    pub spacing_m: f64,
    pub stages: Vec<Stage>,
    /// Each fitted value, from its last stage.
    pub fitted: BTreeMap<String, f64>,
    /// Each fitted value's bracket (the parameters of the two runs around the measured
    /// value), from its last stage.
    pub brackets: BTreeMap<String, [f64; 2]>,
    /// Every measured metric met within its tolerance by the runs of the last bracket.
    pub converged: bool,
}

impl Fit {
    pub fn evaluation_count(&self) -> usize {
        self.stages.iter().map(|s| s.evaluations.len()).sum()
    }
}

/// What a calibration did; written to `calibration.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Record {
    pub name: String,
    pub calibration_sha256: String,
    pub base: String,
    pub base_experiment_sha256: String,
    pub pairs: Vec<Pair>,
    pub fits: Vec<Fit>,
    /// Per fitted value: |fitted at the base spacing - fitted at check_spacing_m| / fitted at
    /// the base spacing.
    pub resolution_share: BTreeMap<String, f64>,
}

/// How to run the calibration's runs.
#[derive(Debug, Clone, Default)]
pub struct CalibrateOptions {
    pub out_dir: PathBuf,
    pub interrupt: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    pub max_particles: Option<u64>,
}

/// The first values: the closed-form guess for the yield stress where the test has one, else
/// the geometric mean of the bounds.
fn first_values(plan: &Plan) -> BTreeMap<String, f64> {
    plan.pairs
        .iter()
        .map(|pair| {
            let [lo, hi] = pair.bounds;
            let guess = (pair.parameter == "fluid.yield_stress_pa")
                .then(|| {
                    experiment::yield_stress_guess_pa(
                        &plan.base.manifest,
                        &pair.metric,
                        pair.measured,
                    )
                })
                .flatten()
                .filter(|v| v.is_finite() && *v > 0.0)
                .unwrap_or_else(|| libm::sqrt(lo * hi));
            (pair.parameter.clone(), round4(guess.clamp(lo, hi)))
        })
        .collect()
}

/// Runs the calibration; `on_run` is called for each finished run (in round order).
pub fn calibrate(
    plan: &Plan,
    options: &CalibrateOptions,
    on_run: &dyn Fn(&Fit, &Stage, &Evaluation),
) -> (PathBuf, Record, Result<(), CalibrateError>) {
    let dir = options.out_dir.join(plan.folder_name());
    let mut record = Record {
        name: plan.calibration.name.clone(),
        calibration_sha256: plan.hash_hex.clone(),
        base: plan.calibration.base.clone(),
        base_experiment_sha256: plan.base.hash_hex.clone(),
        pairs: plan.pairs.clone(),
        fits: Vec::new(),
        resolution_share: BTreeMap::new(),
    };
    let mut spacings = vec![(plan.calibration.set.clone(), plan.base.manifest.spacing_m)];
    if let Some(s) = plan.calibration.check_spacing_m {
        let mut sets = plan.calibration.set.clone();
        sets.push(format!("spacing_m={s}"));
        spacings.push((sets, s));
    }
    let mut result = Ok(());
    for (sets, spacing_m) in spacings {
        // The check fit starts from the first fit's values.
        let start = match record.fits.first() {
            Some(f) if f.fitted.len() == plan.pairs.len() => f.fitted.clone(),
            _ => first_values(plan),
        };
        let mut fit = Fit {
            spacing_m,
            stages: Vec::new(),
            fitted: BTreeMap::new(),
            brackets: BTreeMap::new(),
            converged: false,
        };
        let r = fit_at(plan, &sets, start, &dir, options, &mut fit, on_run);
        record.fits.push(fit);
        if let Err(e) = r {
            result = Err(e);
            break;
        }
    }
    if let [a, b] = record.fits.as_slice() {
        for (k, x) in &a.fitted {
            if let Some(y) = b.fitted.get(k) {
                record.resolution_share.insert(k.clone(), (x - y).abs() / x);
            }
        }
    }
    (dir, record, result)
}

/// The alternating search at one spacing (a single pass for one fitted value).
fn fit_at(
    plan: &Plan,
    sets: &[String],
    mut current: BTreeMap<String, f64>,
    dir: &Path,
    options: &CalibrateOptions,
    fit: &mut Fit,
    on_run: &dyn Fn(&Fit, &Stage, &Evaluation),
) -> Result<(), CalibrateError> {
    let max = plan.calibration.max_evaluations as usize;
    let mut alternation = 0u32;
    let result = 'passes: loop {
        for pair in &plan.pairs {
            let mut held = current.clone();
            held.remove(&pair.parameter);
            let start = stage_start(pair, &current, fit);
            let mut stage = Stage {
                alternation,
                parameter: pair.parameter.clone(),
                metric: pair.metric.clone(),
                held,
                evaluations: Vec::new(),
                bracket: None,
                best: None,
                fitted: None,
                converged: false,
            };
            let budget = max.saturating_sub(fit.evaluation_count());
            let r = search(
                plan,
                pair,
                sets,
                start,
                budget,
                dir,
                options,
                &mut stage,
                &|s, e| on_run(fit, s, e),
            );
            if let Some(f) = stage.fitted {
                current.insert(pair.parameter.clone(), round4(f));
            }
            let all_met = stage.converged && bracket_runs_meet_all(plan, &stage);
            fit.stages.push(stage);
            if let Err(e) = r {
                break 'passes Err(match e {
                    CalibrateError::NotConverged(_) => {
                        CalibrateError::NotConverged(fit.evaluation_count() as u32)
                    }
                    e => e,
                });
            }
            if all_met {
                fit.converged = true;
                break 'passes Ok(());
            }
            if fit.evaluation_count() >= max {
                break 'passes Err(CalibrateError::NotConverged(fit.evaluation_count() as u32));
            }
        }
        alternation += 1;
    };
    for pair in &plan.pairs {
        if let Some(stage) = fit
            .stages
            .iter()
            .rev()
            .find(|s| s.parameter == pair.parameter)
        {
            if let Some(f) = stage.fitted {
                fit.fitted.insert(pair.parameter.clone(), f);
            }
            if let Some(b) = stage.bracket {
                fit.brackets
                    .insert(pair.parameter.clone(), [b[0].0, b[1].0]);
            }
        }
    }
    result
}

/// Where a stage's search starts: the current value; for a time metric after an earlier
/// stage, scaled by measured / simulated at that stage's best run (t ~ mu_p, the viscous time
/// scale mu_p / (rho g H)).
fn stage_start(pair: &Pair, current: &BTreeMap<String, f64>, fit: &Fit) -> f64 {
    let value = current[&pair.parameter];
    let last_best = fit.stages.last().and_then(|s| {
        let (p, _) = s.best?;
        s.evaluations
            .iter()
            .find(|e| e.values[&s.parameter] == p)
            .and_then(|e| e.metrics.get(&pair.metric).copied())
    });
    match last_best {
        Some(t) if pair.metric.ends_with("_s") && t.is_finite() && t > 0.0 => {
            round4((value * pair.measured / t).clamp(pair.bounds[0], pair.bounds[1]))
        }
        _ => value,
    }
}

/// Both runs of the stage's bracket meet every measured metric within its tolerance.
fn bracket_runs_meet_all(plan: &Plan, stage: &Stage) -> bool {
    let Some(b) = stage.bracket else {
        return false;
    };
    b.iter().all(|(p, _)| {
        stage
            .evaluations
            .iter()
            .find(|e| e.values[&stage.parameter] == *p)
            .is_some_and(|e| {
                plan.pairs.iter().all(|q| {
                    e.metrics
                        .get(&q.metric)
                        .is_some_and(|m| (m - q.measured).abs() <= q.tolerance)
                })
            })
    })
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

/// One stage: fits `pair.parameter` from `pair.metric` with `stage.held` fixed, in at most
/// `budget` runs.
#[allow(clippy::too_many_arguments)]
fn search(
    plan: &Plan,
    pair: &Pair,
    sets: &[String],
    start: f64,
    budget: usize,
    dir: &Path,
    options: &CalibrateOptions,
    stage: &mut Stage,
    on_run: &dyn Fn(&Stage, &Evaluation),
) -> Result<(), CalibrateError> {
    let [lo, hi] = pair.bounds;
    let n = plan.calibration.points_per_round as usize;
    let target = pair.measured;
    let clamp = |p: f64| round4(p.clamp(lo, hi));
    let mut round = 0u32;
    // Round 0: points around the start, a factor 1.3 apart.
    let mut next: Vec<f64> = (0..n)
        .map(|i| clamp(start * libm::pow(1.3, i as f64 - (n as f64 - 1.0) / 2.0)))
        .collect();
    loop {
        next.dedup();
        let done: Vec<f64> = stage
            .evaluations
            .iter()
            .map(|e| e.values[&pair.parameter])
            .collect();
        next.retain(|p| !done.contains(p));
        next.truncate(budget.saturating_sub(stage.evaluations.len()));
        if next.is_empty() {
            break;
        }
        for e in run_round(plan, sets, &stage.held, pair, &next, round, dir, options)? {
            stage.evaluations.push(e);
            on_run(stage, stage.evaluations.last().expect("just pushed"));
        }
        round += 1;
        let points: Vec<(f64, f64)> = stage
            .evaluations
            .iter()
            .map(|e| (e.values[&pair.parameter], e.metrics[&pair.metric]))
            .collect();
        stage.best = points
            .iter()
            .copied()
            .filter(|p| p.1.is_finite())
            .min_by(|a, b| (a.1 - target).abs().total_cmp(&(b.1 - target).abs()));
        stage.bracket = bracket_of(&points, target);
        stage.fitted = stage
            .bracket
            .map(|b| secant(b, target))
            .or(stage.best.map(|b| b.0));
        let within = stage
            .best
            .is_some_and(|b| (b.1 - target).abs() <= pair.tolerance);
        // Done when the runs on both sides of the measured value are within the tolerance of
        // it: every value in the bracket then gives it within the tolerance (for a monotone
        // response), so the bracket is the fit's uncertainty.
        let tight = stage.bracket.is_some_and(|b| {
            (b[0].1 - target).abs() <= pair.tolerance && (b[1].1 - target).abs() <= pair.tolerance
        });
        if tight {
            stage.converged = true;
            return Ok(());
        }
        if stage.evaluations.len() >= budget {
            break;
        }
        next = match stage.bracket {
            Some(b) => narrowing_points(b, target, n),
            None => widening_points(pair, &points, n, if within { 1.1 } else { 2.0 })?,
        };
    }
    Err(CalibrateError::NotConverged(stage.evaluations.len() as u32))
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
    pair: &Pair,
    points: &[(f64, f64)],
    n: usize,
    factor: f64,
) -> Result<Vec<f64>, CalibrateError> {
    let [lo, hi] = pair.bounds;
    let mut ok: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.1.is_finite()).collect();
    if ok.is_empty() {
        return Err(CalibrateError::Run(
            "every run of the first round failed; see their files".into(),
        ));
    }
    ok.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (first, last) = (ok[0], ok[ok.len() - 1]);
    // For the yield stress and the plastic viscosity the physics gives the direction: a flow
    // length falls as either rises, a time (a metric in seconds) rises. Runs a little apart
    // can disagree (at 16 mm the slump spread scatters by about a spacing: 0.648 m at 37 Pa,
    // 0.657 m at 48 Pa), so they decide only for other values, and only when they differ by
    // more than the tolerance.
    let known = matches!(
        pair.parameter.as_str(),
        "fluid.yield_stress_pa" | "fluid.plastic_viscosity_pa_s"
    );
    let falling = if !known && (last.1 - first.1).abs() > pair.tolerance {
        last.1 < first.1
    } else {
        !pair.metric.ends_with("_s")
    };
    let below = first.1 < pair.measured; // every metric is below the target
    let go_down = below == falling;
    let (from, bound) = if go_down { (first, lo) } else { (last, hi) };
    if from.0 == bound {
        return Err(CalibrateError::OutOfBounds(format!(
            "the measured {} = {} is outside what fit.{} in [{lo}, {hi}] gives: at {} the run gives {}",
            pair.metric, pair.measured, pair.parameter, from.0, from.1
        )));
    }
    Ok((1..=n)
        .map(|k| {
            let f = libm::pow(factor, k as f64);
            round4(if go_down { from.0 / f } else { from.0 * f }.clamp(lo, hi))
        })
        .collect())
}

#[allow(clippy::too_many_arguments)]
fn run_round(
    plan: &Plan,
    sets: &[String],
    held: &BTreeMap<String, f64>,
    pair: &Pair,
    values: &[f64],
    round: u32,
    dir: &Path,
    options: &CalibrateOptions,
) -> Result<Vec<Evaluation>, CalibrateError> {
    let runs: Vec<BTreeMap<String, f64>> = values
        .iter()
        .map(|&v| {
            let mut all = held.clone();
            all.insert(pair.parameter.clone(), v);
            all
        })
        .collect();
    let resolved: Vec<Resolved> = runs
        .iter()
        .map(|all| experiment::load(&plan.base_path, &sets_with(sets, all)))
        .collect::<Result<_, _>>()?;
    let run_options = RunOptions {
        out_dir: dir.to_path_buf(),
        threads: Some(1),
        progress: None,
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
    for ((all, r), (result, start)) in runs.into_iter().zip(&resolved).zip(results) {
        let result = result.map_err(|e| CalibrateError::Run(e.to_string()))?;
        if let Outcome::Interrupted(why) = &result.outcome {
            return Err(CalibrateError::Interrupted(format!(
                "{}: {why}; run the calibration again to go on",
                result.path.display()
            )));
        }
        let completed = matches!(result.outcome, Outcome::Completed);
        let metrics = plan
            .pairs
            .iter()
            .map(|q| {
                let m = if completed {
                    result.summary.metrics.get(&q.metric).copied()
                } else {
                    None
                };
                (q.metric.clone(), m.unwrap_or(f64::NAN))
            })
            .collect();
        out.push(Evaluation {
            round,
            values: all,
            metrics,
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

/// Writes `calibration.json` and one figure per fitted value (its metric against it, every
/// run of its stages, the measured value as a line; SVG and PNG) into the calibration's
/// folder.
pub fn write_record(dir: &Path, record: &Record) -> std::io::Result<(PathBuf, Vec<PathBuf>)> {
    std::fs::create_dir_all(dir)?;
    let json = dir.join("calibration.json");
    let text = serde_json::to_string_pretty(record).expect("serialisable");
    let partial = dir.join("calibration.json.partial");
    std::fs::write(&partial, text + "\n")?;
    std::fs::rename(&partial, &json)?;
    let mut figures = Vec::new();
    for pair in &record.pairs {
        let figure = dir.join(format!(
            "calibration-{}-vs-{}.svg",
            pair.metric, pair.parameter
        ));
        let mut series = Vec::new();
        for fit in &record.fits {
            for stage in fit.stages.iter().filter(|s| s.parameter == pair.parameter) {
                let mut points: Vec<(f64, f64)> = stage
                    .evaluations
                    .iter()
                    .map(|e| (e.values[&pair.parameter], e.metrics[&pair.metric]))
                    .filter(|p| p.1.is_finite())
                    .collect();
                points.sort_by(|a, b| a.0.total_cmp(&b.0));
                let held: Vec<String> = stage
                    .held
                    .iter()
                    .map(|(k, v)| format!("{k} = {v}"))
                    .collect();
                series.push(crate::report::plot::Series {
                    label: if held.is_empty() {
                        format!("runs at spacing {} m", fit.spacing_m)
                    } else {
                        format!("runs at spacing {} m, {}", fit.spacing_m, held.join(", "))
                    },
                    points,
                });
            }
        }
        let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
        let (x0, x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
        if x0.is_finite() {
            series.push(crate::report::plot::Series {
                label: format!("measured {} = {}", pair.metric, pair.measured),
                points: vec![(x0, pair.measured), (x1, pair.measured)],
            });
        }
        crate::report::plot::line_plot(
            &figure,
            &format!(
                "calibration {}: {} against {}",
                record.name, pair.metric, pair.parameter
            ),
            &crate::report::axis_label(&pair.parameter),
            &crate::report::axis_label(&pair.metric),
            &series,
            true,
        )
        .map_err(|e| std::io::Error::other(e.to_string()))?;
        let png = crate::report::png::png_beside(&figure)
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        figures.push(figure);
        figures.push(png);
    }
    Ok((json, figures))
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
