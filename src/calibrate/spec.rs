//! The calibration manifest: its fields, and its check against the base experiment.

use super::Response;
use crate::experiment::{self, Resolved, SceneSpec};
use crate::manifest::validate::{Checker, POSITIVE, between, fmt_num};
use crate::manifest::{self, ManifestError};
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

/// One fitted value with the measured metric it is fitted from, checked.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Pair {
    pub parameter: String,
    pub bounds: [f64; 2],
    pub metric: String,
    pub measured: f64,
    pub tolerance: f64,
    /// How the metric responds as the concrete stiffens, where the test says.
    #[serde(skip)]
    pub response: Option<Response>,
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
        format!(
            "{}-calib-{}",
            self.calibration.name,
            manifest::canonical::short_hash(&self.hash_hex)
        )
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

/// The first issue the checker found, as the manifest error that places it.
fn first_issue(
    c: Checker,
    bad: &dyn Fn(&str, String) -> ManifestError,
) -> Result<(), ManifestError> {
    match c.into_issues().into_iter().next() {
        Some(issue) => Err(bad(&issue.field, issue.message)),
        None => Ok(()),
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
        // The manifest's checker, so that these read like every other manifest message.
        let mut c = Checker::new();
        if c.real(&format!("measured.{metric}"), measured, POSITIVE)
            && c.real(&format!("tolerance.{metric}"), tolerance, POSITIVE)
            && tolerance >= measured
        {
            c.fail(
                &format!("tolerance.{metric}"),
                format!(
                    "must be below the measured value {}, got {}",
                    fmt_num(measured),
                    fmt_num(tolerance)
                ),
            );
        }
        let field = format!("fit.{parameter}");
        if c.real(&field, lo, POSITIVE) && c.real(&field, hi, POSITIVE) && lo >= hi {
            c.fail(
                &field,
                format!(
                    "must be [min, max] with min < max, got [{}, {}]",
                    fmt_num(lo),
                    fmt_num(hi)
                ),
            );
        }
        first_issue(c, &bad)?;
        pairs.push(Pair {
            parameter,
            bounds: [lo, hi],
            metric,
            measured,
            tolerance,
            response: None,
        });
    }
    let mut c = Checker::new();
    let count = |n: u32| f64::from(n);
    c.real(
        "points_per_round",
        count(calibration.points_per_round),
        between(1.0, true, 16.0, true),
    );
    c.real(
        "max_evaluations",
        count(calibration.max_evaluations),
        between(1.0, true, 200.0, true),
    );
    if let Some(s) = calibration.check_spacing_m {
        c.real("check_spacing_m", s, POSITIVE);
    }
    first_issue(c, &bad)?;
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
    for pair in &mut pairs {
        pair.response = base
            .manifest
            .scene
            .stiffening_response(&base.manifest, &pair.metric);
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

pub(super) fn sets_with(base: &[String], values: &BTreeMap<String, f64>) -> Vec<String> {
    let mut sets = base.to_vec();
    sets.extend(values.iter().map(|(k, v)| format!("{k}={v}")));
    sets
}
