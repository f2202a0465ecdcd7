//! Running one round of a stage: each run an ordinary recorded run in the calibration's
//! folder, through the sweep's runner (a finished file is reused, an interrupted one
//! resumed).

use super::record::Evaluation;
use super::spec::sets_with;
use super::{CalibrateError, CalibrateOptions, Pair, Plan};
use crate::experiment::{self, Resolved};
use crate::record::Outcome;
use crate::run::RunOptions;
use crate::sweep_run::run_points;
use std::collections::BTreeMap;
use std::path::Path;

/// Where a fit's runs are made: the plan, the base's overrides at this spacing, the
/// calibration's folder and the options.
pub(super) struct Runs<'a> {
    pub plan: &'a Plan,
    pub sets: &'a [String],
    pub dir: &'a Path,
    pub options: &'a CalibrateOptions,
}

impl Runs<'_> {
    /// Runs `pair.parameter` at each of `values` with the other fitted values `held`.
    pub(super) fn round(
        &self,
        held: &BTreeMap<String, f64>,
        pair: &Pair,
        values: &[f64],
        round: u32,
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
            .map(|all| experiment::load(&self.plan.base_path, &sets_with(self.sets, all)))
            .collect::<Result<_, _>>()?;
        let run_options = RunOptions {
            out_dir: self.dir.to_path_buf(),
            threads: Some(1),
            progress: None,
            interrupt: self.options.interrupt.clone(),
            max_particles: self.options.max_particles,
            overwrite: false,
        };
        // Every run of the round at once (the round's size is the manifest's, not the cores').
        let points: Vec<&Resolved> = resolved.iter().collect();
        let results = run_points(&points, &run_options, points.len(), &|_, result, start| {
            (result, start)
        });
        let mut out = Vec::new();
        for ((all, r), (result, start)) in runs.into_iter().zip(&resolved).zip(results) {
            let result = result?;
            if let Outcome::Interrupted(why) = &result.outcome {
                return Err(CalibrateError::Interrupted(format!(
                    "{}: {why}; run the calibration again to go on",
                    result.path.display()
                )));
            }
            let completed = matches!(result.outcome, Outcome::Completed);
            let metrics = self
                .plan
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
}
