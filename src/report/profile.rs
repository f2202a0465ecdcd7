//! `runner profile`: the surface at rest of a run against its test's closed form. The test
//! measures it and writes its table ([`crate::experiment::Experiment::surface_profile`]);
//! this module only reads the run and draws.

use std::path::{Path, PathBuf};

use super::plot::{self, Series};
use super::{ReportError, Result, beside, read, run_title};
use crate::experiment::SurfaceProfile;
use crate::record::RunFile;

/// `runner profile`: the surface at rest of a run against its closed form, as a table
/// (returned) and an SVG plot (default `<run>-profile.svg`). An error for a test without a
/// profile.
pub fn profile(mcap: &Path, out: Option<&Path>) -> Result<(PathBuf, String)> {
    let run = read(mcap)?;
    draw(&run, mcap, out)?.ok_or_else(|| not_profiled(&run))
}

/// As [`profile`], `None` when the run's test has no surface profile (the report's case).
pub fn profile_if_any(mcap: &Path, out: Option<&Path>) -> Result<Option<(PathBuf, String)>> {
    draw(&read(mcap)?, mcap, out)
}

fn draw(run: &RunFile, mcap: &Path, out: Option<&Path>) -> Result<Option<(PathBuf, String)>> {
    let Some(fig) = surface_profile(run)? else {
        return Ok(None);
    };
    let out = out.map_or_else(|| beside(mcap, "-profile.svg"), Path::to_path_buf);
    let title = format!("{}: surface at t = {:.2} s", run_title(run), fig.time_s);
    let series: Vec<Series> = std::iter::once(fig.surface)
        .chain(fig.closed_at_measured)
        .chain(fig.closed_for_volume)
        .collect();
    plot::line_plot(&out, &title, fig.x_label, "h [m]", &series, false)?;
    Ok(Some((out, fig.table)))
}

/// `runner profile RUN RUN...`: several runs of one test (e.g. one experiment at several
/// spacings) in one figure: each run's surface, and the closed form for the first run's
/// volume; the table is each run's table in turn. Default figure: `<first run>-profiles.svg`.
pub fn profiles(mcaps: &[PathBuf], out: Option<&Path>) -> Result<(PathBuf, String)> {
    let [first, ..] = mcaps else {
        return Err(ReportError::Input("no run file given".into()));
    };
    let out = out.map_or_else(|| beside(first, "-profiles.svg"), Path::to_path_buf);
    let figs = mcaps
        .iter()
        .map(|f| {
            let run = read(f)?;
            let fig = surface_profile(&run)?.ok_or_else(|| not_profiled(&run))?;
            Ok((fig, run))
        })
        .collect::<Result<Vec<_>>>()?;
    let kind = scene_kind(&figs[0].1);
    if let Some((_, run)) = figs.iter().find(|(_, r)| scene_kind(r) != kind) {
        return Err(ReportError::Input(format!(
            "{} ({}) is not the same test as {} ({kind}): one figure takes runs of one kind",
            run_title(run),
            scene_kind(run),
            run_title(&figs[0].1)
        )));
    }
    let mut series: Vec<Series> = figs
        .iter()
        .map(|(f, run)| Series {
            label: format!(
                "{}: MPS, l0 = {} mm, t = {:.1} s",
                run_title(run),
                1000.0 * f.spacing_m,
                f.time_s
            ),
            points: f.surface.points.clone(),
        })
        .collect();
    if let Some(closed) = &figs[0].0.closed_for_volume {
        series.push(Series {
            label: format!("{} (volume of the first run)", closed.label),
            points: closed.points.clone(),
        });
    }
    let title = format!("{} runs: surface against the closed form", figs.len());
    plot::line_plot(&out, &title, figs[0].0.x_label, "h [m]", &series, false)?;
    let table = figs
        .iter()
        .map(|(f, _)| f.table.as_str())
        .collect::<Vec<_>>()
        .join("\n");
    Ok((out, table))
}

fn scene_kind(run: &RunFile) -> String {
    super::manifest_value(run, "scene.kind")
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_else(|| "unknown".into())
}

fn not_profiled(run: &RunFile) -> ReportError {
    ReportError::Input(format!(
        "run `{}` is a {} run, and that test has no surface profile against a closed form",
        run_title(run),
        scene_kind(run)
    ))
}

/// The profile of the run's last checkpoint, `None` for a test without one (2D runs
/// included: every profile is of a 3D free surface).
fn surface_profile(run: &RunFile) -> Result<Option<SurfaceProfile>> {
    let resolved = crate::restore::manifest_of(run)
        .map_err(|e| ReportError::Input(format!("the run's manifest: {e}")))?;
    let m = &resolved.manifest;
    if m.dimension != 3 {
        return Ok(None);
    }
    let state = run
        .states
        .last()
        .ok_or_else(|| ReportError::Input("the run has no checkpoint".into()))?;
    let particles = crate::checkpoint::particles_from_message::<3>(state)
        .map_err(|e| ReportError::Input(format!("last checkpoint: {e}")))?;
    m.scene
        .surface_profile(m, &particles, state.time_s, &run_title(run))
        .transpose()
        .map_err(ReportError::Input)
}
