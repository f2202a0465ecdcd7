//! Reports made from recorded runs: SVG plots of diagnostics, sweep results and particle
//! snapshots (`runner plot`, `runner plot-sweep`, `runner snapshot`); PNG from them
//! ([`png`]) and the report page (`runner report`, [`page`]); what a run file holds
//! (`runner info`, [`info`]) and its data as tables (`runner export`, [`export`]).
//!
//! Plots are drawn as SVG with `plotters`' SVG backend (text as SVG `<text>`, no font
//! lookup); PNGs are those SVGs rasterised with the shipped font.

pub mod cloud;
pub mod export;
pub mod info;
pub mod page;
pub mod plot;
pub mod png;
pub mod profile;
pub mod staged;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::manifest::sweep::lookup;
use crate::proto::mps::v1::Diagnostics;
use crate::record::{RecordError, RunFile, read_run};
use plot::Series;

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Bad request: unknown metric or key, nothing to plot, not a run file.
    #[error("{0}")]
    Input(String),
    /// A run file could not be read.
    #[error(transparent)]
    Read(#[from] RecordError),
    /// The plot could not be written.
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
}

pub type Result<T, E = ReportError> = std::result::Result<T, E>;

/// Built-in `Diagnostics` fields that can be plotted by name, besides `metrics[...]`.
pub const DIAGNOSTICS_FIELDS: &[&str] = &[
    "kinetic_energy_j",
    "max_speed_m_s",
    "dt_s",
    "ppe_iterations",
    "ppe_relative_residual",
    "surface_particle_count",
    "fluid_particle_count",
    "viscosity_iterations",
    "viscosity_relative_residual",
    "non_flowing_fraction",
    "yield_iterations",
    "step",
];

/// The value of diagnostics field or metric `name` in one row.
pub fn diagnostics_value(d: &Diagnostics, name: &str) -> Option<f64> {
    Some(match name {
        "kinetic_energy_j" => d.kinetic_energy_j,
        "max_speed_m_s" => d.max_speed_m_s,
        "dt_s" => d.dt_s,
        "ppe_iterations" => d.ppe_iterations.into(),
        "ppe_relative_residual" => d.ppe_relative_residual,
        "surface_particle_count" => d.surface_particle_count.into(),
        "fluid_particle_count" => d.fluid_particle_count.into(),
        "viscosity_iterations" => d.viscosity_iterations.into(),
        "viscosity_relative_residual" => d.viscosity_relative_residual,
        "non_flowing_fraction" => d.non_flowing_fraction,
        "yield_iterations" => d.yield_iterations.into(),
        "step" => d.step.into(),
        "time_s" => d.time_s,
        _ => return d.metrics.get(name).copied(),
    })
}

/// Default diagnostics quantity of a run: its first experiment metric (by name), else
/// `kinetic_energy_j`.
pub fn default_metric(run: &RunFile) -> String {
    run.diagnostics
        .iter()
        .find_map(|d| d.metrics.keys().next().cloned())
        .unwrap_or_else(|| "kinetic_energy_j".to_string())
}

/// `(time_s, value)` of diagnostics quantity `name`, for every row that has it.
pub fn diagnostics_series(run: &RunFile, name: &str) -> Vec<(f64, f64)> {
    run.diagnostics
        .iter()
        .filter_map(|d| diagnostics_value(d, name).map(|v| (d.time_s, v)))
        .collect()
}

/// The run's resolved manifest (its stored canonical form) as JSON.
pub fn canonical_manifest(run: &RunFile) -> Option<Value> {
    serde_json::from_str(run.manifest_field("canonical")?).ok()
}

/// The value at dotted `key` of the run's resolved manifest.
pub fn manifest_value(run: &RunFile, key: &str) -> Option<Value> {
    canonical_manifest(run).and_then(|m| lookup(&m, key).cloned())
}

/// `name (short hash)` of a run, for titles.
pub fn run_title(run: &RunFile) -> String {
    let name = run.manifest_field("name").unwrap_or("run");
    let hash = run
        .manifest_field("experiment_sha256")
        .map_or("", crate::manifest::canonical::short_hash);
    format!("{name} {hash}")
}

/// The unit of a quantity named with a unit suffix (`front_position_m` -> `m`), if known.
pub fn unit_of(name: &str) -> Option<&'static str> {
    unit_entry(name).map(|(_, unit)| unit)
}

/// The unit suffix of a name (`_m_s` of `max_speed_m_s`), see [`unit_of`].
pub fn unit_suffix(name: &str) -> Option<&'static str> {
    unit_entry(name).map(|(suffix, _)| suffix)
}

fn unit_entry(name: &str) -> Option<(&'static str, &'static str)> {
    const SUFFIXES: &[(&str, &str)] = &[
        ("_kg_m3", "kg/m³"),
        ("_m_s2", "m/s²"),
        ("_m_s", "m/s"),
        ("_pa_s", "Pa s"),
        ("_1_pa", "1/Pa"),
        ("_pa", "Pa"),
        ("_ms", "ms"),
        ("_m", "m"),
        ("_s", "s"),
        ("_j", "J"),
        ("_kg", "kg"),
    ];
    let last = name.rsplit('.').next().unwrap_or(name);
    SUFFIXES
        .iter()
        .find(|(suffix, _)| last.ends_with(suffix))
        .copied()
}

/// Axis label: the name with its unit in brackets (`[-]` when unitless).
pub fn axis_label(name: &str) -> String {
    format!("{name} [{}]", unit_of(name).unwrap_or("-"))
}

/// A short file-name-safe form of `s`.
fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// `path` without its `.mcap` extension, plus `suffix`.
fn beside(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or_else(|| "run".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}{suffix}"))
}

fn read(path: &Path) -> Result<RunFile> {
    Ok(read_run(path)?)
}

/// `(x, value)` of diagnostics quantity `name` against quantity `x`: with `time_s`, every
/// row; otherwise one point per value `x` takes, from the first row that has it (for a
/// counter such as `strokes_done`: the state just after each count is reached).
pub fn diagnostics_series_against(run: &RunFile, x: &str, name: &str) -> Vec<(f64, f64)> {
    if x == "time_s" {
        return diagnostics_series(run, name);
    }
    first_rows_at(run, x, name)
        .into_iter()
        .filter_map(|k| {
            let d = &run.diagnostics[k];
            Some((diagnostics_value(d, x)?, diagnostics_value(d, name)?))
        })
        .collect()
}

/// Indices of the diagnostics rows that hold both `x` and `name`, the first such row at each
/// value `x` takes (for a counter: the row just after each count is reached).
pub fn first_rows_at(run: &RunFile, x: &str, name: &str) -> Vec<usize> {
    let mut seen: Vec<f64> = Vec::new();
    let mut rows = Vec::new();
    for (k, d) in run.diagnostics.iter().enumerate() {
        if let (Some(xv), Some(_)) = (diagnostics_value(d, x), diagnostics_value(d, name))
            && !seen.contains(&xv)
        {
            seen.push(xv);
            rows.push(k);
        }
    }
    rows
}

/// `runner plot`: diagnostics quantities `metrics` (default [`default_metric`]), one line
/// each, against simulated time or quantity `x` (see [`diagnostics_series_against`]).
/// Default output: `<run>-<first metric>[-vs-<x>].svg` beside the run file.
pub fn plot_run(
    mcap: &Path,
    metrics: &[String],
    x: Option<&str>,
    out: Option<&Path>,
) -> Result<PathBuf> {
    let run = read(mcap)?;
    let metrics = if metrics.is_empty() {
        vec![default_metric(&run)]
    } else {
        metrics.to_vec()
    };
    let x = x.unwrap_or("time_s");
    let mut series = Vec::new();
    for name in std::iter::once(x).chain(metrics.iter().map(String::as_str)) {
        let points = diagnostics_series_against(&run, "time_s", name);
        if points.is_empty() {
            let mut known: Vec<String> = DIAGNOSTICS_FIELDS.iter().map(|s| s.to_string()).collect();
            if let Some(d) = run.diagnostics.first() {
                known.extend(d.metrics.keys().cloned());
            }
            return Err(ReportError::Input(format!(
                "{}: no diagnostics value `{name}`; known: {}",
                mcap.display(),
                known.join(", ")
            )));
        }
    }
    for name in &metrics {
        series.push(Series {
            label: name.clone(),
            points: diagnostics_series_against(&run, x, name),
        });
    }
    let first = &metrics[0];
    let suffix = if x == "time_s" {
        String::new()
    } else {
        format!("-vs-{}", slug(x))
    };
    let out = out.map_or_else(
        || beside(mcap, &format!("-{}{suffix}.svg", slug(first))),
        Path::to_path_buf,
    );
    let y_label = if metrics.len() == 1 {
        axis_label(first)
    } else {
        metrics.join(", ")
    };
    plot::line_plot(
        &out,
        &format!("{}: {}", run_title(&run), {
            // A title that fits the figure; the legend names every line.
            let all = metrics.join(", ");
            if all.len() <= 60 {
                all
            } else {
                format!("{} and {} more", metrics[0], metrics.len() - 1)
            }
        }),
        &axis_label(x),
        &y_label,
        &series,
        false,
    )?;
    Ok(out)
}

/// A manifest value as a number: numbers as they are, booleans as 0/1.
fn as_number(v: &Value) -> Option<f64> {
    match v {
        Value::Number(n) => n.as_f64(),
        Value::Bool(b) => Some(f64::from(u8::from(*b))),
        _ => None,
    }
}

/// What [`plot_sweep`] drew.
#[derive(Debug, Clone)]
pub struct SweepPlot {
    pub path: PathBuf,
    /// Group label -> number of points.
    pub groups: BTreeMap<String, usize>,
    /// Run files left out (unreadable, unfinished, or without the metric) and why.
    pub skipped: Vec<(PathBuf, String)>,
}

/// The finished run files (`*.mcap`) of a folder, sorted by name.
pub fn run_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| ReportError::Input(format!("{}: cannot read folder: {e}", dir.display())))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    files.sort();
    Ok(files)
}

/// `runner plot-sweep`: summary metric `y` of every completed run in `dir` against manifest
/// value `x`, one line per value of manifest key `group` (if given). Default output:
/// `DIR/sweep-<y>-vs-<x>.svg`.
pub fn plot_sweep(
    dir: &Path,
    x: &str,
    y: &str,
    group: Option<&str>,
    out: Option<&Path>,
) -> Result<SweepPlot> {
    let mut groups: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    let mut skipped = Vec::new();
    let mut title = None;
    for file in run_files(dir)? {
        let run = match read_run(&file) {
            Ok(r) => r,
            Err(e) => {
                skipped.push((file, e.to_string()));
                continue;
            }
        };
        let Some(summary) = run.summary.as_ref().filter(|s| s.outcome == "completed") else {
            skipped.push((file, "not a completed run".into()));
            continue;
        };
        let Some(manifest) = canonical_manifest(&run) else {
            skipped.push((file, "no canonical manifest in its metadata".into()));
            continue;
        };
        let Some(xv) = lookup(&manifest, x) else {
            return Err(ReportError::Input(format!(
                "{}: the manifest has no key `{x}`",
                file.display()
            )));
        };
        let Some(xv) = as_number(xv) else {
            return Err(ReportError::Input(format!(
                "{}: `{x}` = {xv} is not a number",
                file.display()
            )));
        };
        let Some(&yv) = summary.metrics.get(y) else {
            skipped.push((file, format!("no summary metric `{y}`")));
            continue;
        };
        let label = match group {
            Some(g) => match lookup(&manifest, g) {
                Some(v) => format!("{g}={}", value_text(v)),
                None => {
                    return Err(ReportError::Input(format!(
                        "{}: the manifest has no key `{g}`",
                        file.display()
                    )));
                }
            },
            None => y.to_string(),
        };
        title.get_or_insert_with(|| {
            manifest
                .get("name")
                .and_then(Value::as_str)
                .unwrap_or("sweep")
                .to_string()
        });
        groups.entry(label).or_default().push((xv, yv));
    }
    if groups.is_empty() {
        return Err(ReportError::Input(format!(
            "{}: no completed run with summary metric `{y}`",
            dir.display()
        )));
    }
    let series: Vec<Series> = groups
        .into_iter()
        .map(|(label, mut points)| {
            points.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
            Series { label, points }
        })
        .collect();
    let out = out.map_or_else(
        || dir.join(format!("sweep-{}-vs-{}.svg", slug(y), slug(x))),
        Path::to_path_buf,
    );
    let folder = dir
        .file_name()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let name = title.unwrap_or_default();
    let title = if folder.is_empty() || folder == name {
        format!("{name}: {y} vs {x}")
    } else {
        format!("{folder}: {y} vs {x}")
    };
    plot::line_plot(&out, &title, &axis_label(x), &axis_label(y), &series, true)?;
    Ok(SweepPlot {
        path: out,
        groups: series
            .iter()
            .map(|s| (s.label.clone(), s.points.len()))
            .collect(),
        skipped,
    })
}

/// A scalar as plain text (strings without quotes).
fn value_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        v => v.to_string(),
    }
}

/// Summary metrics worth plotting by default after a sweep: all but counts and
/// bookkeeping (`*_count`, `steps`, `simulated_time_s`).
pub fn default_sweep_metrics(metrics: &BTreeMap<String, f64>) -> Vec<String> {
    metrics
        .keys()
        .filter(|k| !k.ends_with("_count") && *k != "steps" && *k != "simulated_time_s")
        .cloned()
        .collect()
}

pub use crate::record::time_text;

/// `runner snapshot`: the last `/particles` frame of a run, or the one nearest `time_s`,
/// coloured by `field` (default `kind`). Default output:
/// `<run>-snapshot-<field>[-t<time>].svg` beside the run file.
pub fn snapshot(
    mcap: &Path,
    field: Option<&str>,
    top: bool,
    time_s: Option<f64>,
    out: Option<&Path>,
) -> Result<PathBuf> {
    let run = read(mcap)?;
    let chosen = match time_s {
        None => run.last_cloud.clone(),
        Some(t) => {
            let clouds =
                crate::record::read_messages(mcap)?
                    .into_iter()
                    .filter_map(|(log_ns, m)| match m {
                        crate::record::Logged::Cloud(c) => Some((log_ns, c)),
                        _ => None,
                    });
            // The frame nearest t (the earlier one on a tie).
            let target_ns = crate::run::time_ns(t.max(0.0));
            clouds
                .min_by_key(|(log_ns, _)| log_ns.abs_diff(target_ns))
                .map(|(_, c)| c)
        }
    };
    let Some(pc) = chosen.as_ref() else {
        return Err(ReportError::Input(format!(
            "{}: no /particles frame",
            mcap.display()
        )));
    };
    let mut frame = cloud::Frame::decode(pc)
        .map_err(|e| ReportError::Input(format!("{}: /particles: {e}", mcap.display())))?;
    let field = field.unwrap_or("kind");
    if field == "height_m" {
        // The vertical coordinate as a field (3D from above: the height of the surface).
        let vertical = if frame.z.iter().all(|z| *z == 0.0) {
            &frame.y
        } else {
            &frame.z
        };
        frame.fields.insert("height_m".into(), vertical.clone());
    }
    if !frame.fields.contains_key(field) {
        return Err(ReportError::Input(format!(
            "{}: the point cloud has no field `{field}`; fields: {}",
            mcap.display(),
            frame.fields.keys().cloned().collect::<Vec<_>>().join(", ")
        )));
    }
    let dimension = manifest_value(&run, "dimension")
        .and_then(|v| v.as_u64())
        .unwrap_or(if frame.z.iter().all(|z| *z == 0.0) {
            2
        } else {
            3
        });
    let view = match (dimension == 3, top) {
        (true, true) => plot::View::Top,
        (true, false) => plot::View::Side,
        (false, _) => plot::View::Plane,
    };
    let suffix = if view == plot::View::Top { "-top" } else { "" };
    let time = pc
        .timestamp
        .as_ref()
        .map_or(0.0, |t| t.seconds as f64 + f64::from(t.nanos) * 1e-9);
    let at = if time_s.is_some() {
        format!("-t{}", slug(&format!("{time:.2}")))
    } else {
        String::new()
    };
    let out = out.map_or_else(
        || beside(mcap, &format!("-snapshot{suffix}-{}{at}.svg", slug(field))),
        Path::to_path_buf,
    );
    let title = format!("{} at t = {} s: {field}", run_title(&run), time_text(time));
    plot::snapshot_plot(&out, &title, &frame, field, view)?;
    Ok(out)
}

pub use profile::{profile, profile_if_any, profiles};

/// `runner draw`: the particle set at t = 0 of a manifest (walls, dummies, fluid, and each
/// inlet's cross-section as `inlet`) as sections: in 3D one through the plane y = `at_y_m`
/// seen from the side and one through z = `at_z_m` seen from above (each the one layer of
/// lattice cells nearest the plane; defaults: the middle of the particles' y range and a
/// quarter of the way up their z range), in 2D the plane itself. Files
/// `<name>-scene-{side,top}.svg` (3D) or `<name>-scene.svg` (2D) in `out_dir`.
/// The test's sections of the run's last checkpoint as cells ([`crate::experiment::Experiment::cell_maps`]); empty for most tests.
pub fn cell_maps(run: &RunFile) -> Result<Vec<crate::experiment::CellMap>> {
    let resolved = crate::restore::manifest_of(run)
        .map_err(|e| ReportError::Input(format!("the run's manifest: {e}")))?;
    let m = &resolved.manifest;
    let Some(state) = run.states.last() else {
        return Ok(Vec::new());
    };
    let last = |e: String| ReportError::Input(format!("last checkpoint: {e}"));
    Ok(if m.dimension == 3 {
        let p = crate::checkpoint::particles_from_message::<3>(state).map_err(last)?;
        m.scene.cell_maps(m, &p)
    } else {
        let p = crate::checkpoint::particles_from_message::<2>(state).map_err(last)?;
        m.scene.cell_maps(m, &p)
    })
}

pub fn draw_scene(
    m: &crate::experiment::Manifest,
    at_y_m: Option<f64>,
    at_z_m: Option<f64>,
    out_dir: &Path,
) -> Result<Vec<PathBuf>> {
    match m.dimension {
        3 => draw_scene_d::<3>(m, at_y_m, at_z_m, out_dir),
        _ => draw_scene_d::<2>(m, at_y_m, at_z_m, out_dir),
    }
}

/// The `kind` value `runner draw` gives inlet points (after the particle kinds 0-3).
const INLET_KIND: f32 = 4.0;

fn draw_scene_d<const D: usize>(
    m: &crate::experiment::Manifest,
    at_y_m: Option<f64>,
    at_z_m: Option<f64>,
    out_dir: &Path,
) -> Result<Vec<PathBuf>> {
    let l0 = m.spacing_m;
    let scene = crate::experiment::build_scene::<D>(m);
    let p = &scene.particles;
    let mut points: Vec<([f64; 3], f32)> = (0..p.len())
        .map(|i| {
            let x = p.position_m[i];
            (
                [x[0], x[1], if D == 3 { x[2] } else { 0.0 }],
                p.kind[i] as u32 as f32,
            )
        })
        .collect();
    for inlet in &scene.inlets {
        for x in inlet.cross_section_beside_m(l0, &scene.symmetry) {
            points.push(([x[0], x[1], if D == 3 { x[2] } else { 0.0 }], INLET_KIND));
        }
    }
    std::fs::create_dir_all(out_dir).map_err(|e| ReportError::Write {
        path: out_dir.to_path_buf(),
        message: e.to_string(),
    })?;
    let frame_of = |keep: &dyn Fn(&[f64; 3], f32) -> bool| {
        let mut f = cloud::Frame::default();
        let mut kind = Vec::new();
        for (x, k) in points.iter().filter(|(x, k)| keep(x, *k)) {
            f.x.push(x[0] as f32);
            f.y.push(x[1] as f32);
            f.z.push(x[2] as f32);
            kind.push(*k);
        }
        f.fields.insert("kind".into(), kind);
        f
    };
    let title = |what: &str| {
        format!(
            "{} (scene.kind {}, spacing {} m): {what}",
            m.name,
            m.scene.kind_name(),
            l0
        )
    };
    if D == 2 {
        let out = out_dir.join(format!("{}-scene.svg", m.name));
        plot::snapshot_plot(
            &out,
            &title("t = 0"),
            &frame_of(&|_, _| true),
            "kind",
            plot::View::Plane,
        )?;
        return Ok(vec![out]);
    }
    // The cell-centre plane nearest a coordinate: ((floor(c / l0)) + 1/2) l0.
    let snap = |c: f64| ((c / l0).floor() + 0.5) * l0;
    let range = |a: usize| {
        points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (x, _)| {
                (lo.min(x[a]), hi.max(x[a]))
            })
    };
    let (y0, y1) = range(1);
    let (z0, z1) = range(2);
    let at_y = snap(at_y_m.unwrap_or(0.5 * (y0 + y1)));
    let at_z = snap(at_z_m.unwrap_or(z0 + 0.25 * (z1 - z0)));
    let side = out_dir.join(format!("{}-scene-side.svg", m.name));
    plot::snapshot_plot(
        &side,
        &title(&format!(
            "section y = {at_y:.4} m, from the side (inlets projected)"
        )),
        &frame_of(&|x, k| k == INLET_KIND || (x[1] - at_y).abs() < 0.5 * l0),
        "kind",
        plot::View::Side,
    )?;
    let top = out_dir.join(format!("{}-scene-top.svg", m.name));
    plot::snapshot_plot(
        &top,
        &title(&format!(
            "section z = {at_z:.4} m, from above (inlets projected)"
        )),
        &frame_of(&|x, k| k == INLET_KIND || (x[2] - at_z).abs() < 0.5 * l0),
        "kind",
        plot::View::Plane,
    )?;
    Ok(vec![side, top])
}
