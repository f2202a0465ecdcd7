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

mod record;
mod runs;
mod search;
mod spec;

pub use crate::experiment::Response;
pub use record::{Evaluation, Fit, Record, Stage, write_record};
pub use search::round4;
pub use spec::{Calibration, Pair, PairSpec, Plan, load};

use crate::experiment;
use crate::manifest::ManifestError;
use crate::run::RunError;
use runs::Runs;
use search::{bracket_runs_meet_all, search, stage_start};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Why a calibration could not run or did not converge.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    #[error(transparent)]
    Manifest(#[from] ManifestError),
    /// A run could not be made (its manifest, its file).
    #[error(transparent)]
    Run(#[from] RunError),
    /// No run of the first round finished: nothing to step from.
    #[error("every run of the first round failed; see their files")]
    AllRunsFailed,
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
        let runs = Runs {
            plan,
            sets: &sets,
            dir: &dir,
            options,
        };
        let r = fit_at(&runs, start, &mut fit, on_run);
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
    runs: &Runs,
    mut current: BTreeMap<String, f64>,
    fit: &mut Fit,
    on_run: &dyn Fn(&Fit, &Stage, &Evaluation),
) -> Result<(), CalibrateError> {
    let plan = runs.plan;
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
            let r = search(runs, pair, start, budget, &mut stage, &|s, e| {
                on_run(fit, s, e)
            });
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
