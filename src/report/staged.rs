//! The report's figures of a test that goes in stages (the rodding's strokes, see
//! [`crate::experiment::StagedFigures`]): the run's diagnostics at the first row of every
//! stage, drawn against the stage and tabled. The test names the figures; this module only
//! reads the run and draws.

use std::path::Path;

use super::export::{Table, rows_table};
use super::plot::{self, Series};
use super::{ReportError, Result, diagnostics_series_against, first_rows_at, run_title};
use crate::experiment::{StagedFigure, StagedFigures};
use crate::record::RunFile;

/// The run's staged figures, `None` for a test that does not go in stages.
pub fn staged_figures(run: &RunFile) -> Result<Option<StagedFigures>> {
    let resolved = crate::restore::manifest_of(run)
        .map_err(|e| ReportError::Input(format!("the run's manifest: {e}")))?;
    Ok(resolved.manifest.scene.staged_figures())
}

/// Draws `figure` of `staged` as an SVG at `svg`.
pub fn draw(
    run: &RunFile,
    staged: &StagedFigures,
    figure: &StagedFigure,
    svg: &Path,
) -> Result<()> {
    let mut series: Vec<Series> = figure
        .curves
        .iter()
        .map(|(metric, label)| Series {
            label: label.clone(),
            points: diagnostics_series_against(run, staged.stage_metric, metric),
        })
        .collect();
    if series.iter().all(|s| s.points.is_empty()) {
        return Err(ReportError::Input(format!(
            "no diagnostics row holds {} and `{}`",
            figure.title, staged.stage_metric
        )));
    }
    if let Some((value, label)) = &figure.reference {
        let stages = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
        let (lo, hi) = stages.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
        series.push(Series {
            label: label.clone(),
            points: vec![(lo, *value), (hi, *value)],
        });
    }
    let title = format!("{}: {}", run_title(run), figure.title);
    plot::line_plot(
        svg,
        &title,
        staged.stage_label,
        figure.y_label,
        &series,
        true,
    )
}

/// The per-stage table: the stage, its first row's time and the test's table metrics.
pub fn table(run: &RunFile, staged: &StagedFigures) -> Table {
    // The rows that start a stage: those the figures take.
    let rows = first_rows_at(run, staged.stage_metric, staged.stage_metric);
    let mut columns = vec![staged.stage_metric.to_string(), "time_s".to_string()];
    columns.extend(staged.table.iter().map(|m| m.to_string()));
    rows_table(columns, rows.iter().map(|&k| &run.diagnostics[k]))
}
