//! `runner verify --trend DIR`: across the runs of a sweep, a result metric must fall as a
//! manifest value rises (by default the L-flow value against the yield stress), and the
//! power-law exponent of that fall is reported.
//!
//! x is read from the canonical manifest stored in each file by a dotted key, y from the
//! summary metrics. Runs are grouped by every other manifest key whose value differs between
//! them (except `name` and `output.*`, which do not change the physics); within each group y
//! must strictly decrease as x increases. The exponent b of y = a x^b is the least-squares
//! slope of ln y against ln x over the points with x > 0 and y > 0 (ln from std: these
//! numbers are reported, never part of a simulated state).
use crate::record::read_run;
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

pub const DEFAULT_X: &str = "fluid.yield_stress_pa";

#[derive(Debug, Clone)]
pub struct TrendOptions {
    /// Dotted key of the manifest value on the x axis.
    pub x_key: String,
    /// Summary metric on the y axis; None = the runs' test's own trend metric
    /// ([`crate::experiment::Experiment::trend_metric`], e.g. `l_flow_value_m` for the L-flow).
    pub y_metric: Option<String>,
}

impl Default for TrendOptions {
    fn default() -> Self {
        Self {
            x_key: DEFAULT_X.to_string(),
            y_metric: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub file: PathBuf,
}

/// y = a x^b, fitted on logs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerFit {
    pub a: f64,
    pub b: f64,
    /// Coefficient of determination of the log-log fit.
    pub r2: f64,
    pub points: usize,
}

#[derive(Debug, Clone)]
pub struct Group {
    /// The values of the keys that tell the groups apart (empty: one group).
    pub key: Vec<(String, String)>,
    /// Sorted by x.
    pub points: Vec<Point>,
    /// Pairs that break the strict decrease.
    pub violations: Vec<String>,
    pub fit: Option<PowerFit>,
}

#[derive(Debug, Clone)]
pub struct TrendReport {
    pub dir: PathBuf,
    pub options: TrendOptions,
    pub groups: Vec<Group>,
    /// Files left out, and why.
    pub skipped: Vec<(PathBuf, String)>,
}

impl TrendReport {
    /// Every group has two or more distinct x values and y strictly falls in each.
    pub fn passed(&self) -> bool {
        !self.groups.is_empty()
            && self
                .groups
                .iter()
                .all(|g| g.violations.is_empty() && distinct_x(g) >= 2)
    }
}

fn distinct_x(g: &Group) -> usize {
    let mut xs: Vec<u64> = g.points.iter().map(|p| p.x.to_bits()).collect();
    xs.dedup();
    xs.len()
}

/// Dotted leaf keys of a JSON value (a stored canonical manifest), with their JSON text.
pub fn flatten(v: &serde_json::Value, prefix: &str, out: &mut BTreeMap<String, String>) {
    match v {
        serde_json::Value::Object(map) => {
            for (k, child) in map {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(child, &key, out);
            }
        }
        other => {
            out.insert(prefix.to_string(), other.to_string());
        }
    }
}

/// The keys of flattened manifests ([`flatten`]) whose value is not the same in all of them
/// (a key absent from some counts as differing), sorted; `name` and `output.*` are left
/// out: they do not change the physics. For a sweep folder: the swept keys.
pub fn varying_keys(manifests: &[&BTreeMap<String, String>]) -> Vec<String> {
    let all_keys: std::collections::BTreeSet<&String> =
        manifests.iter().flat_map(|k| k.keys()).collect();
    all_keys
        .into_iter()
        .filter(|k| *k != "name" && !k.starts_with("output."))
        .filter(|k| {
            let first = manifests[0].get(*k);
            manifests.iter().any(|keys| keys.get(*k) != first)
        })
        .cloned()
        .collect()
}

/// Least-squares fit of ln y = ln a + b ln x over the points with x > 0 and y > 0.
pub fn power_fit(points: &[Point]) -> Option<PowerFit> {
    let logs: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.x > 0.0 && p.y > 0.0)
        .map(|p| (libm::log(p.x), libm::log(p.y)))
        .collect();
    let n = logs.len() as f64;
    if logs.len() < 2 {
        return None;
    }
    let mx = logs.iter().map(|p| p.0).sum::<f64>() / n;
    let my = logs.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = logs.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    let sxy: f64 = logs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let syy: f64 = logs.iter().map(|p| (p.1 - my) * (p.1 - my)).sum();
    if sxx == 0.0 {
        return None;
    }
    let b = sxy / sxx;
    let r2 = if syy == 0.0 {
        1.0
    } else {
        sxy * sxy / (sxx * syy)
    };
    Some(PowerFit {
        a: libm::exp(my - b * mx),
        b,
        r2,
        points: logs.len(),
    })
}

/// Reads every `.mcap` file in `dir` (not recursing) and checks the trend. `Err` when the
/// directory cannot be read or holds no usable run.
pub fn trend(dir: &Path, options: &TrendOptions) -> Result<TrendReport, String> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    files.sort();
    let mut skipped = Vec::new();
    let mut runs: Vec<(BTreeMap<String, String>, Point)> = Vec::new();
    // The y metric: the option, else the trend metric of the first run's test.
    let mut resolved_y: Option<String> = None;
    for file in files {
        let run = match read_run(&file) {
            Ok(r) => r,
            Err(e) => {
                skipped.push((file, format!("unreadable: {e}")));
                continue;
            }
        };
        let Some(summary) = run.summary.as_ref().filter(|_| run.complete) else {
            skipped.push((file, "unfinished (no summary)".into()));
            continue;
        };
        if summary.outcome != "completed" {
            skipped.push((file, format!("outcome {}", summary.outcome)));
            continue;
        }
        let Some(canonical) = run.manifest_field("canonical") else {
            skipped.push((file, "no stored manifest".into()));
            continue;
        };
        let value: serde_json::Value = match serde_json::from_str(canonical) {
            Ok(v) => v,
            Err(e) => {
                skipped.push((file, format!("stored manifest is not JSON: {e}")));
                continue;
            }
        };
        let mut keys = BTreeMap::new();
        flatten(&value, "", &mut keys);
        let Some(x) = keys.get(&options.x_key).and_then(|v| v.parse::<f64>().ok()) else {
            skipped.push((file, format!("manifest has no number at {}", options.x_key)));
            continue;
        };
        let y_metric = match (&options.y_metric, test_trend_metric(&value)) {
            (Some(name), _) => name.clone(),
            (None, Some(name)) => name.to_string(),
            (None, None) => {
                skipped.push((
                    file,
                    "the stored manifest names no known test (scene.kind): give --y".into(),
                ));
                continue;
            }
        };
        let y_metric = resolved_y.get_or_insert(y_metric).clone();
        let Some(&y) = summary.metrics.get(&y_metric) else {
            skipped.push((file, format!("summary has no metric {y_metric}")));
            continue;
        };
        runs.push((keys, Point { x, y, file }));
    }
    let options = TrendOptions {
        x_key: options.x_key.clone(),
        y_metric: resolved_y.or_else(|| options.y_metric.clone()),
    };
    let y_name = options
        .y_metric
        .clone()
        .unwrap_or_else(|| "its test's metric".into());
    if runs.is_empty() {
        return Err(format!(
            "{}: no completed run with {} in its manifest and {y_name} in its summary",
            dir.display(),
            options.x_key,
        ));
    }
    // Keys that tell runs apart, besides x.
    let manifests: Vec<&BTreeMap<String, String>> = runs.iter().map(|(k, _)| k).collect();
    let varying: Vec<String> = varying_keys(&manifests)
        .into_iter()
        .filter(|k| *k != options.x_key)
        .collect();
    let mut groups: BTreeMap<Vec<(String, String)>, Vec<Point>> = BTreeMap::new();
    for (keys, point) in runs {
        let key = varying
            .iter()
            .map(|k| {
                let v = keys.get(k).cloned().unwrap_or_else(|| "(absent)".into());
                (k.clone(), v)
            })
            .collect();
        groups.entry(key).or_default().push(point);
    }
    let groups = groups
        .into_iter()
        .map(|(key, mut points)| {
            points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
            let mut violations = Vec::new();
            for (i, lo) in points.iter().enumerate() {
                for hi in &points[i + 1..] {
                    if hi.x > lo.x && hi.y >= lo.y {
                        violations.push(format!(
                            "{} = {} gives {} = {}, not below {} at {} = {}",
                            options.x_key, hi.x, y_name, hi.y, lo.y, options.x_key, lo.x
                        ));
                    }
                }
            }
            let fit = power_fit(&points);
            Group {
                key,
                points,
                violations,
                fit,
            }
        })
        .collect();
    Ok(TrendReport {
        dir: dir.to_path_buf(),
        options,
        groups,
        skipped,
    })
}

impl fmt::Display for TrendReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let xk = &self.options.x_key;
        let yk = self.options.y_metric.as_deref().unwrap_or("y");
        for g in &self.groups {
            if g.key.is_empty() {
                writeln!(f, "{}: all runs", self.dir.display())?;
            } else {
                let key: Vec<String> = g.key.iter().map(|(k, v)| format!("{k}={v}")).collect();
                writeln!(f, "{}: group {}", self.dir.display(), key.join(", "))?;
            }
            writeln!(f, "  {xk:>24}  {yk:>24}  file")?;
            for p in &g.points {
                let name = p.file.file_name().unwrap_or_default().to_string_lossy();
                writeln!(f, "  {:>24}  {:>24}  {name}", p.x, p.y)?;
            }
            match &g.fit {
                Some(fit) => writeln!(
                    f,
                    "  power law: {yk} = {:.4e} * {xk}^{:.4} (R^2 = {:.4}, {} points with x > 0); the lubrication estimate for a yield-stress heap is about -1/3",
                    fit.a, fit.b, fit.r2, fit.points
                )?,
                None => writeln!(f, "  power law: not enough points with x > 0 and y > 0")?,
            }
            if distinct_x(g) < 2 {
                writeln!(
                    f,
                    "  FAILED: fewer than two values of {xk}: the trend cannot be checked"
                )?;
            } else if g.violations.is_empty() {
                writeln!(f, "  ok: {yk} falls strictly as {xk} rises")?;
            } else {
                for v in &g.violations {
                    writeln!(f, "  FAILED: {v}")?;
                }
            }
        }
        for (file, why) in &self.skipped {
            writeln!(f, "skipped {}: {why}", file.display())?;
        }
        write!(
            f,
            "{}",
            if self.passed() {
                "trend ok"
            } else {
                "trend FAILED"
            }
        )
    }
}

/// The default trend metric of the test a stored canonical manifest describes.
fn test_trend_metric(canonical: &serde_json::Value) -> Option<&'static str> {
    let scene = canonical.get("scene")?.clone();
    serde_json::from_value::<crate::experiment::SceneSpec>(scene)
        .ok()
        .map(|s| s.trend_metric())
}
