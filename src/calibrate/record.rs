//! What a calibration did: its runs, stages and fits, written to `calibration.json` with
//! one figure per fitted value.

use super::Pair;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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
