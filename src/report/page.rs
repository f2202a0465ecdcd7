//! `runner report FILE|DIR`: the figures of a run (or of a sweep folder) as PNG, and one
//! self-contained HTML page (figures embedded as data URIs, no script, no outside file) that
//! shows them with the run's facts.
//!
//! A run: its diagnostics against time (each experiment metric; the shares of a mixing test
//! together; kinetic energy and top speed), snapshots at chosen times coloured by a point
//! field with a colour bar (3D: from the side, and the last one from above by height), and
//! the test's own figure where it has one (the surface against the closed form: slump flow,
//! L-B box). A sweep folder: every summary metric against the swept value, and the table of
//! runs.
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use base64::Engine as _;

use super::export::{Cell, Table, finished_rows, summary_table};
use super::info::{RunInfo, run_info};
use super::{ReportError, Result};

/// What to draw.
#[derive(Debug, Clone, Default)]
pub struct ReportOptions {
    /// The report folder (default: `<run>-report/` beside the run, `DIR/report/` for a folder).
    pub out: Option<PathBuf>,
    /// Snapshot times (s); empty: four, from the start to the end of the run.
    pub times_s: Vec<f64>,
    /// The point field that colours snapshots (default `speed_m_s`).
    pub field: Option<String>,
    /// Keep each figure's SVG beside its PNG.
    pub keep_svg: bool,
}

/// One figure of the page.
#[derive(Debug, Clone)]
pub struct Figure {
    pub png: PathBuf,
    pub caption: String,
}

/// What [`report`] wrote.
#[derive(Debug, Clone)]
pub struct Report {
    pub dir: PathBuf,
    pub page: PathBuf,
    pub figures: Vec<Figure>,
    /// Figures that could not be drawn, and why (the page lists them too).
    pub skipped: Vec<String>,
}

/// `runner report`: a run file or a folder of run files.
pub fn report(path: &Path, options: &ReportOptions) -> Result<Report> {
    if path.is_dir() {
        sweep_report(path, options)
    } else {
        run_report(path, options)
    }
}

/// The figures drawn so far: each SVG turned into a PNG (the SVG kept only on request).
struct Figures {
    dir: PathBuf,
    keep_svg: bool,
    done: Vec<Figure>,
    skipped: Vec<String>,
}

impl Figures {
    /// Writes the page (`body`, then the figures) and says what the report holds.
    fn finish(self, title: &str, body: &str) -> Result<Report> {
        let page = write_page(&self.dir, title, body, &self.done, &self.skipped)?;
        Ok(Report {
            dir: self.dir,
            page,
            figures: self.done,
            skipped: self.skipped,
        })
    }

    fn svg(&self, name: &str) -> PathBuf {
        self.dir.join(format!("{name}.svg"))
    }
    /// Takes the outcome of drawing `svg`: a PNG with `caption`, or a line in `skipped`.
    fn add<T>(&mut self, svg: &Path, caption: String, drawn: Result<T>) {
        match drawn.and_then(|_| super::png::png_beside(svg)) {
            Ok(png) => self.done.push(Figure { png, caption }),
            Err(e) => self.skipped.push(format!("{caption}: {e}")),
        }
        if !self.keep_svg {
            let _ = std::fs::remove_file(svg);
        }
    }
}

fn report_dir(default: PathBuf, options: &ReportOptions) -> Result<PathBuf> {
    let dir = options.out.clone().unwrap_or(default);
    std::fs::create_dir_all(&dir).map_err(|e| ReportError::Write {
        path: dir.clone(),
        message: e.to_string(),
    })?;
    Ok(dir)
}

fn run_report(path: &Path, options: &ReportOptions) -> Result<Report> {
    let run = super::read(path)?;
    let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let info = run_info(path, size, &run);
    let dir = report_dir(super::beside(path, "-report"), options)?;
    let mut f = Figures {
        dir,
        keep_svg: options.keep_svg,
        done: Vec::new(),
        skipped: Vec::new(),
    };

    // Diagnostics against time: each experiment metric (shares together), then the built-ins.
    // A metric with the same bits in every row (a closed form, a bed's porosity) is no curve:
    // it stands in the summary table.
    let varies = |name: &String| {
        let mut values = run
            .diagnostics
            .iter()
            .map(|d| d.metrics.get(name).map(|v| v.to_bits()));
        let first = values.next().flatten();
        run.diagnostics.len() < 2 || values.any(|v| v != first)
    };
    let names: Vec<String> = run
        .diagnostics
        .first()
        .map(|d| d.metrics.keys().filter(|n| varies(n)).cloned().collect())
        .unwrap_or_default();
    let mut groups = metric_groups(&names);
    groups.push(vec!["kinetic_energy_j".into()]);
    groups.push(vec!["max_speed_m_s".into()]);
    for (k, metrics) in groups.iter().enumerate() {
        let svg = f.svg(&format!("diagnostics-{k:02}-{}", super::slug(&metrics[0])));
        let drawn = super::plot_run(path, metrics, None, Some(&svg));
        let what = metrics.join(", ");
        f.add(&svg, format!("{what} against simulated time"), drawn);
    }

    // Snapshots.
    let end_s = info.simulated_time_s.unwrap_or(0.0);
    let times: Vec<f64> = if options.times_s.is_empty() {
        (0..4).map(|k| end_s * f64::from(k) / 3.0).collect()
    } else {
        options.times_s.clone()
    };
    let field = options.field.as_deref().unwrap_or("speed_m_s");
    for (k, t) in times.iter().enumerate() {
        let svg = f.svg(&format!("snapshot-{k:02}-{}", super::slug(field)));
        let drawn = super::snapshot(path, Some(field), false, Some(*t), Some(&svg));
        f.add(
            &svg,
            format!(
                "{field} at the frame nearest t = {} s",
                super::time_text(*t)
            ),
            drawn,
        );
    }
    let three_d = super::manifest_value(&run, "dimension").and_then(|v| v.as_u64()) == Some(3);
    if three_d {
        let svg = f.svg("snapshot-top-height_m");
        let drawn = super::snapshot(path, Some("height_m"), true, None, Some(&svg));
        f.add(&svg, "the last frame from above, by height".into(), drawn);
    }

    // The test's own figure, where it has one.
    let svg = f.svg("profile");
    match super::profile_if_any(path, Some(&svg)) {
        Ok(None) => {}
        drawn => f.add(
            &svg,
            "the surface of the last checkpoint against the closed form".into(),
            drawn,
        ),
    }

    // The test's sections of the last checkpoint as cells (the rock fill's concrete, rock
    // and empty void).
    match super::cell_maps(&run) {
        Ok(maps) => {
            for (k, map) in maps.iter().enumerate() {
                let svg = f.svg(&format!("cells-{k:02}-{}", super::slug(&map.title)));
                let title = format!("{}: {}", super::run_title(&run), map.title);
                let drawn = super::plot::cell_map(&svg, &title, map);
                f.add(&svg, format!("{} of the last checkpoint", map.title), drawn);
            }
        }
        Err(e) => f.skipped.push(format!("the test's sections: {e}")),
    }

    // A test that goes in stages: its figures against the stage, and the per-stage table.
    let mut stage_table = None;
    match super::staged::staged_figures(&run) {
        Ok(None) => {}
        Ok(Some(staged)) => {
            for (k, figure) in staged.figures.iter().enumerate() {
                let svg = f.svg(&format!("stages-{k:02}-{}", super::slug(&figure.title)));
                let drawn = super::staged::draw(&run, &staged, figure, &svg);
                let caption = format!("{} against {}", figure.title, staged.stage_label);
                f.add(&svg, caption, drawn);
            }
            stage_table = Some((staged.stage_label, super::staged::table(&run, &staged)));
        }
        Err(e) => f.skipped.push(format!("the test's figures by stage: {e}")),
    }

    let title = format!("Run report: {}", super::run_title(&run));
    let mut body = String::new();
    summary_html(&mut body, &info, &run);
    facts_html(&mut body, &info);
    metrics_html(&mut body, &info);
    if let Some((label, table)) = stage_table {
        let _ = write!(body, "<h2>By {}</h2>", esc(label));
        table_html(&mut body, &table);
    }
    f.finish(&title, &body)
}

fn sweep_report(folder: &Path, options: &ReportOptions) -> Result<Report> {
    let (rows, left_out) = finished_rows(folder)?;
    let mut table = summary_table(&rows);
    let dir = report_dir(folder.join("report"), options)?;
    let mut f = Figures {
        dir,
        keep_svg: options.keep_svg,
        done: Vec::new(),
        skipped: left_out
            .iter()
            .map(|(p, why)| format!("{}: {why}", p.display()))
            .collect(),
    };
    // The swept values: the manifest values that differ between the runs.
    let refs: Vec<_> = rows.iter().map(|r| &r.manifest).collect();
    let varying = crate::verify::trend::varying_keys(&refs);
    let swept: Vec<&String> = varying.iter().collect();
    // The table in the order of the swept values (numbers as numbers).
    let sort_columns: Vec<usize> = swept
        .iter()
        .filter_map(|k| table.columns.iter().position(|c| c == *k))
        .collect();
    table.rows.sort_by(|a, b| {
        sort_columns
            .iter()
            .map(|&c| match (&a[c], &b[c]) {
                (Cell::Number(x), Cell::Number(y)) => x.total_cmp(y),
                (Cell::Text(x), Cell::Text(y)) => x.cmp(y),
                _ => std::cmp::Ordering::Equal,
            })
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let numeric = |c: usize| table.rows.iter().all(|r| matches!(r[c], Cell::Number(_)));
    let x = swept
        .iter()
        .map(|k| {
            table
                .columns
                .iter()
                .position(|c| c == *k)
                .expect("a column")
        })
        .find(|&c| numeric(c))
        .map(|c| table.columns[c].clone());
    match &x {
        None => f.skipped.push(format!(
            "sweep plots: no numeric manifest value differs between the runs of {}",
            folder.display()
        )),
        Some(x) => {
            let group = swept.iter().find(|k| **k != x).map(|k| k.as_str());
            let metrics = rows
                .iter()
                .find_map(|r| r.summary.as_ref())
                .map(|s| super::default_sweep_metrics(&s.metrics))
                .unwrap_or_default();
            for y in metrics {
                let svg = f.svg(&format!("sweep-{}-vs-{}", super::slug(&y), super::slug(x)));
                let drawn = super::plot_sweep(folder, x, &y, group, Some(&svg));
                f.add(&svg, format!("{y} against {x}"), drawn);
            }
        }
    }
    let title = format!("Sweep report: {}", folder.display());
    let mut body = String::new();
    let _ = write!(
        body,
        "<h2>Runs</h2><p>{} finished run file(s) in <code>{}</code>.</p>",
        rows.len(),
        esc(&folder.display().to_string())
    );
    table_html(&mut body, &table);
    f.finish(&title, &body)
}

/// Diagnostics metrics drawn together: names that differ only in their last word before the
/// unit (`spread_radius_{mean,min,max}_m`, `surface_height_r{25,50,75}_m`), and the shares of
/// a mixing table; counts are left out.
fn metric_groups(names: &[String]) -> Vec<Vec<String>> {
    let key = |n: &str| -> String {
        if n.ends_with("_share") {
            return "_share".into();
        }
        let unit = super::unit_suffix(n).unwrap_or("");
        let stem = n.strip_suffix(unit).unwrap_or(n);
        let head = stem.rsplit_once('_').map_or(stem, |(h, _)| h);
        format!("{head}|{unit}")
    };
    let mut groups: Vec<(String, Vec<String>)> = Vec::new();
    for n in names.iter().filter(|n| !n.ends_with("_count")) {
        let k = key(n);
        match groups.iter_mut().find(|(g, _)| *g == k) {
            Some((_, members)) => members.push(n.clone()),
            None => groups.push((k, vec![n.clone()])),
        }
    }
    groups.into_iter().map(|(_, members)| members).collect()
}

/// Text for HTML (the five special characters escaped).
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

fn number(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{v:.0}")
    } else {
        format!("{v:.6}")
    }
}

/// The page's opening table: the experiment, its hash, how it ended, and each result metric
/// of the test beside its closed form and the relative error where it has one.
fn summary_html(out: &mut String, info: &RunInfo, run: &crate::record::RunFile) {
    let or_dash = |v: &Option<String>| v.clone().unwrap_or_else(|| "-".into());
    let ended = match (&info.outcome, &info.reason) {
        (Some(o), Some(r)) if !r.is_empty() => format!("{o}: {r}"),
        (Some(o), _) => o.clone(),
        (None, _) => "-".into(),
    };
    let stop = info
        .stop_rule
        .clone()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "the end time".into());
    out.push_str("<h2>Summary</h2><table class=\"facts\">");
    for (k, v) in [
        ("experiment", or_dash(&info.experiment)),
        ("experiment SHA-256", or_dash(&info.experiment_sha256)),
        ("outcome", ended),
        ("stopped by", stop),
    ] {
        let _ = write!(out, "<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(&v));
    }
    out.push_str("</table>");
    let Ok(resolved) = crate::restore::manifest_of(run) else {
        return;
    };
    let m = &resolved.manifest;
    let pairs = crate::experiment::closed_form_pairs(m);
    let closed: std::collections::BTreeSet<&str> = pairs.iter().map(|p| p.0.as_str()).collect();
    let beside = |name: &str| {
        pairs
            .iter()
            .find(|p| p.1.as_deref() == Some(name))
            .map(|p| p.0.as_str())
    };
    let mut rows = Vec::new();
    let own = crate::experiment::metric_names(m)
        .into_iter()
        .chain(crate::experiment::row_metric_names(m));
    for name in own.filter(|n| !closed.contains(n.as_str())) {
        let Some(&value) = info.metrics.get(&name) else {
            continue;
        };
        let reference = beside(&name).and_then(|c| info.metrics.get(c).copied());
        let error = reference
            .map(|r| 100.0 * (value / r - 1.0))
            .filter(|e| e.is_finite())
            .map(|e| format!("{e:+.1} %"));
        rows.push((name, value, reference, error));
    }
    // Closed forms with no measured twin stand alone.
    for (c, measured) in &pairs {
        if measured.is_none()
            && let Some(&v) = info.metrics.get(c)
        {
            rows.push((c.clone(), v, None, None));
        }
    }
    if rows.is_empty() {
        return;
    }
    out.push_str(
        "<table class=\"runs\"><tr><th>result</th><th>value</th><th>closed form</th><th>error</th></tr>",
    );
    for (name, value, reference, error) in rows {
        let _ = write!(
            out,
            "<tr><th>{}</th><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(&name),
            esc(&number(value)),
            esc(&reference.map_or(String::new(), number)),
            esc(&error.unwrap_or_default())
        );
    }
    out.push_str("</table>");
}

fn facts_html(out: &mut String, info: &RunInfo) {
    let or_dash = |v: &Option<String>| v.clone().unwrap_or_else(|| "-".into());
    // The experiment, its hash and how it ended open the page (the summary table).
    let mut rows: Vec<(&str, String)> = vec![
        ("file", info.file.clone()),
        (
            "simulated time",
            info.simulated_time_s
                .map_or("-".into(), |t| format!("{} s", super::time_text(t))),
        ),
        ("steps", info.steps.map_or("-".into(), number)),
        (
            "particles",
            format!(
                "{} ({} fluid)",
                info.particles.total.map_or("-".into(), number),
                info.particles.fluid.map_or("-".into(), number)
            ),
        ),
        ("checkpoints", info.checkpoints.count.to_string()),
        ("threads", or_dash(&info.threads)),
    ];
    let build: Vec<String> = info.build.iter().map(|(k, v)| format!("{k} {v}")).collect();
    rows.push(("build", build.join(", ")));
    if !info.missing.is_empty() {
        rows.push(("missing", info.missing.join("; ")));
    }
    out.push_str("<h2>Run</h2><table class=\"facts\">");
    for (k, v) in rows {
        let _ = write!(out, "<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(&v));
    }
    out.push_str("</table>");
}

fn metrics_html(out: &mut String, info: &RunInfo) {
    if info.metrics.is_empty() {
        return;
    }
    out.push_str("<h2>Summary metrics</h2><table class=\"facts\">");
    for (k, v) in &info.metrics {
        let _ = write!(
            out,
            "<tr><th>{}</th><td>{}</td></tr>",
            esc(k),
            esc(&number(*v))
        );
    }
    out.push_str("</table>");
}

fn table_html(out: &mut String, table: &Table) {
    out.push_str("<div class=\"wide\"><table class=\"runs\"><tr>");
    for c in &table.columns {
        let _ = write!(out, "<th>{}</th>", esc(c));
    }
    out.push_str("</tr>");
    for row in &table.rows {
        out.push_str("<tr>");
        for cell in row {
            let text = match cell {
                Cell::Number(v) => number(*v),
                Cell::Text(s) => s.clone(),
                Cell::Empty => String::new(),
            };
            let _ = write!(out, "<td>{}</td>", esc(&text));
        }
        out.push_str("</tr>");
    }
    out.push_str("</table></div>");
}

const STYLE: &str = "body{font-family:sans-serif;margin:2em auto;max-width:1200px;color:#222}\
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:1.5em}\
table{border-collapse:collapse;font-size:.9em}th,td{border:1px solid #ddd;padding:.25em .6em;\
text-align:left;vertical-align:top}table.facts th{background:#f4f4f4;white-space:nowrap}\
table.runs th{background:#f4f4f4}table+table{margin-top:1em}div.wide{overflow-x:auto}div.figures{display:grid;grid-template-columns:repeat(auto-fill,minmax(540px,1fr));gap:1em}\
figure{margin:0}figure img{width:100%;border:1px solid #eee}figcaption{font-size:.9em;color:#555}\
ul.skipped{color:#a00}";

/// Writes `index.html`: the body, then every figure as an embedded PNG with its caption.
fn write_page(
    dir: &Path,
    title: &str,
    body: &str,
    figures: &[Figure],
    skipped: &[String],
) -> Result<PathBuf> {
    let page = dir.join("index.html");
    let fail = |message: String| ReportError::Write {
        path: page.clone(),
        message,
    };
    let mut html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><style>{STYLE}</style></head><body><h1>{}</h1>",
        esc(title),
        esc(title)
    );
    html.push_str(body);
    html.push_str("<h2>Figures</h2><div class=\"figures\">");
    for fig in figures {
        let bytes = std::fs::read(&fig.png).map_err(|e| fail(e.to_string()))?;
        let data = base64::engine::general_purpose::STANDARD.encode(bytes);
        let name = fig
            .png
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let _ = write!(
            html,
            "<figure><img alt=\"{}\" src=\"data:image/png;base64,{data}\"><figcaption>{} ({})</figcaption></figure>",
            esc(&fig.caption),
            esc(&fig.caption),
            esc(&name)
        );
    }
    html.push_str("</div>");
    if !skipped.is_empty() {
        html.push_str("<h2>Left out</h2><ul class=\"skipped\">");
        for s in skipped {
            let _ = write!(html, "<li>{}</li>", esc(s));
        }
        html.push_str("</ul>");
    }
    html.push_str("</body></html>\n");
    let partial = dir.join("index.html.partial");
    std::fs::write(&partial, html).map_err(|e| fail(e.to_string()))?;
    std::fs::rename(&partial, &page).map_err(|e| fail(e.to_string()))?;
    Ok(page)
}
