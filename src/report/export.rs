//! `runner export`: a run's diagnostics time series, or the summaries of the runs of a sweep
//! folder, as one table (CSV or JSON) for a spreadsheet or a data frame.
//!
//! Every row has every column (sorted, see [`diagnostics_table`] and [`summary_table`]); a
//! value a row does not have is empty in CSV and `null` in JSON.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde_json::{Map, Value, json};

use super::{DIAGNOSTICS_FIELDS, Result, diagnostics_value, run_files};
use crate::proto::mps::v1::Summary;
use crate::record::{RunFile, read_run};
use crate::verify::trend::{flatten, varying_keys};

/// One cell of a [`Table`].
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    Number(f64),
    Text(String),
    /// Not in this row.
    Empty,
}

/// Columns and rows of equal length.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    pub columns: Vec<String>,
    pub rows: Vec<Vec<Cell>>,
}

/// A number as CSV text: whole numbers below 2^53 without a fraction (`12`), others in
/// Rust's shortest round-trip form (`0.1`, `1e-7`): the value read back is the same bits.
fn number_text(v: f64) -> String {
    if v.is_finite() && v.fract() == 0.0 && v.abs() < 9.007_199_254_740_992e15 {
        format!("{v}")
    } else {
        format!("{v:?}")
    }
}

/// A CSV field, quoted when it holds a comma, quote or line break (RFC 4180).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

impl Table {
    /// RFC 4180 CSV with a header line; `\n` line ends.
    pub fn to_csv(&self) -> String {
        let mut out = String::new();
        let line = |cells: Vec<String>| cells.join(",") + "\n";
        out += &line(self.columns.iter().map(|c| csv_field(c)).collect());
        for row in &self.rows {
            out += &line(
                row.iter()
                    .map(|c| match c {
                        Cell::Number(v) => number_text(*v),
                        Cell::Text(s) => csv_field(s),
                        Cell::Empty => String::new(),
                    })
                    .collect(),
            );
        }
        out
    }

    /// `{"columns": [...], "rows": [{column: value or null, ...}, ...]}` (non-finite numbers
    /// are `null` too: JSON has none).
    pub fn to_json(&self) -> Value {
        let rows: Vec<Value> = self
            .rows
            .iter()
            .map(|row| {
                let object: Map<String, Value> = self
                    .columns
                    .iter()
                    .zip(row)
                    .map(|(c, cell)| {
                        let v = match cell {
                            Cell::Number(v) => json!(v),
                            Cell::Text(s) => json!(s),
                            Cell::Empty => Value::Null,
                        };
                        (c.clone(), v)
                    })
                    .collect();
                Value::Object(object)
            })
            .collect();
        json!({ "columns": self.columns, "rows": rows })
    }
}

/// Leading columns of [`diagnostics_table`], in this order.
pub const DIAGNOSTICS_LEADING: [&str; 3] = ["time_s", "step", "dt_s"];

/// The `/diagnostics` time series: one row per message in file order. Columns: `time_s`,
/// `step`, `dt_s`, then the other built-in fields ([`DIAGNOSTICS_FIELDS`]) sorted, then every
/// metric key any row has, sorted.
pub fn diagnostics_table(run: &RunFile) -> Table {
    let mut builtin: Vec<&str> = DIAGNOSTICS_FIELDS
        .iter()
        .copied()
        .filter(|f| !DIAGNOSTICS_LEADING.contains(f))
        .collect();
    builtin.sort_unstable();
    let metrics: BTreeSet<&String> = run
        .diagnostics
        .iter()
        .flat_map(|d| d.metrics.keys())
        .filter(|k| !DIAGNOSTICS_LEADING.contains(&k.as_str()) && !builtin.contains(&k.as_str()))
        .collect();
    let columns: Vec<String> = DIAGNOSTICS_LEADING
        .iter()
        .chain(&builtin)
        .map(|s| s.to_string())
        .chain(metrics.into_iter().cloned())
        .collect();
    rows_table(columns, run.diagnostics.iter())
}

/// The table of the diagnostics `rows` with `columns` (built-in fields or metrics; a value a
/// row does not have is empty).
pub fn rows_table<'a>(
    columns: Vec<String>,
    rows: impl Iterator<Item = &'a crate::proto::mps::v1::Diagnostics>,
) -> Table {
    let rows = rows
        .map(|d| {
            columns
                .iter()
                .map(|c| diagnostics_value(d, c).map_or(Cell::Empty, Cell::Number))
                .collect()
        })
        .collect();
    Table { columns, rows }
}

/// What [`summary_table`] needs of one run (a sweep's files are read one at a time and
/// only this is kept, not their checkpoints).
#[derive(Debug, Clone, PartialEq)]
pub struct RunRow {
    /// File name.
    pub file: String,
    pub experiment_sha256: Option<String>,
    pub summary: Option<Summary>,
    /// The stored canonical manifest, flattened ([`flatten`]).
    pub manifest: BTreeMap<String, String>,
}

impl RunRow {
    pub fn of(file: String, run: &RunFile) -> Self {
        let mut manifest = BTreeMap::new();
        if let Some(v) = super::canonical_manifest(run) {
            flatten(&v, "", &mut manifest);
        }
        let experiment_sha256 = run
            .summary
            .as_ref()
            .map(|s| s.experiment_sha256.clone())
            .filter(|h| !h.is_empty())
            .or_else(|| run.manifest_field("experiment_sha256").map(str::to_string));
        Self {
            file,
            experiment_sha256,
            summary: run.summary.clone(),
            manifest,
        }
    }
}

/// Leading columns of [`summary_table`], in this order.
pub const SUMMARY_LEADING: [&str; 4] = ["file", "experiment_sha256", "outcome", "stop_time_s"];

/// One row per run: `file` (name), `experiment_sha256`, `outcome` (`incomplete` for a file
/// without a `/summary` message), `stop_time_s` (the summary metric; `simulated_time_s` in
/// files written before it existed), then the manifest values that differ between the runs
/// (dotted keys, sorted; see [`varying_keys`]: for a sweep folder, the swept keys), then
/// every other summary metric, sorted.
pub fn summary_table(runs: &[RunRow]) -> Table {
    let refs: Vec<&BTreeMap<String, String>> = runs.iter().map(|r| &r.manifest).collect();
    let varying = if runs.len() > 1 {
        varying_keys(&refs)
    } else {
        Vec::new()
    };
    let metrics: BTreeSet<&String> = runs
        .iter()
        .filter_map(|r| r.summary.as_ref())
        .flat_map(|s| s.metrics.keys())
        .filter(|k| !SUMMARY_LEADING.contains(&k.as_str()))
        .collect();
    let columns: Vec<String> = SUMMARY_LEADING
        .iter()
        .map(|s| s.to_string())
        .chain(varying.iter().cloned())
        .chain(metrics.iter().map(|m| m.to_string()))
        .collect();
    let rows = runs
        .iter()
        .map(|r| {
            let summary = r.summary.as_ref();
            let metric = |k: &str| {
                summary
                    .and_then(|s| s.metrics.get(k).copied())
                    .map_or(Cell::Empty, Cell::Number)
            };
            let mut row = vec![
                Cell::Text(r.file.clone()),
                r.experiment_sha256.clone().map_or(Cell::Empty, Cell::Text),
                Cell::Text(summary.map_or_else(|| "incomplete".into(), |s| s.outcome.clone())),
                match metric("stop_time_s") {
                    Cell::Empty => metric("simulated_time_s"),
                    stop => stop,
                },
            ];
            row.extend(varying.iter().map(|k| match r.manifest.get(k) {
                None => Cell::Empty,
                Some(text) => match serde_json::from_str::<Value>(text) {
                    Ok(Value::Number(n)) => n.as_f64().map_or(Cell::Empty, Cell::Number),
                    Ok(Value::String(s)) => Cell::Text(s),
                    _ => Cell::Text(text.clone()),
                },
            }));
            row.extend(metrics.iter().map(|m| metric(m)));
            row
        })
        .collect();
    Table { columns, rows }
}

/// The file name of `path` as text.
fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

/// `runner export FILE`: its diagnostics table and its one-row summary table.
pub fn export_file(path: &Path) -> Result<(Table, Table)> {
    let run = read_run(path)?;
    let diagnostics = diagnostics_table(&run);
    let summary = summary_table(&[RunRow::of(file_name(path), &run)]);
    Ok((diagnostics, summary))
}

/// Files of a folder left out of its table, each with why.
pub type LeftOut = Vec<(PathBuf, String)>;

/// `runner export DIR`: the summary table of the run files (`*.mcap`) in `dir`, and the files
/// left out (unreadable, or unfinished: no `/summary` message) with why.
pub fn export_dir(dir: &Path) -> Result<(Table, LeftOut)> {
    let (runs, skipped) = finished_rows(dir)?;
    Ok((summary_table(&runs), skipped))
}

/// The finished run files (`*.mcap`) of `dir` as rows, and the files left out with why; an
/// error when none is finished.
pub fn finished_rows(dir: &Path) -> Result<(Vec<RunRow>, LeftOut)> {
    let mut runs = Vec::new();
    let mut skipped = Vec::new();
    for file in run_files(dir)? {
        match read_run(&file) {
            Ok(run) if run.summary.is_some() && run.complete => {
                runs.push(RunRow::of(file_name(&file), &run));
            }
            Ok(_) => skipped.push((file, "unfinished: no /summary message or no footer".into())),
            Err(e) => skipped.push((file, e.to_string())),
        }
    }
    if runs.is_empty() {
        return Err(super::ReportError::Input(format!(
            "{}: no finished run file (*.mcap) to export",
            dir.display()
        )));
    }
    Ok((runs, skipped))
}
