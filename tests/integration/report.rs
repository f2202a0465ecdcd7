//! `runner report`: the PNG figures and the self-contained HTML page of a run and of a sweep
//! folder, read back as a browser would get them (the page's embedded images decoded, the
//! pixels looked at). `tools/check_report.sh` opens a page in headless Chromium.
use crate::common;
use std::path::{Path, PathBuf};

use base64::Engine as _;
use common::runner_all as runner;
use resvg::tiny_skia::Pixmap;

/// Every `src="..."` of the page.
fn sources(html: &str) -> Vec<&str> {
    html.split("src=\"")
        .skip(1)
        .map(|rest| &rest[..rest.find('"').expect("a closing quote")])
        .collect()
}

/// The page's embedded PNGs, decoded.
fn embedded(html: &str) -> Vec<Vec<u8>> {
    sources(html)
        .into_iter()
        .map(|src| {
            let data = src
                .strip_prefix("data:image/png;base64,")
                .unwrap_or_else(|| panic!("an outside source: {}", &src[..src.len().min(60)]));
            base64::engine::general_purpose::STANDARD
                .decode(data)
                .expect("base64")
        })
        .collect()
}

fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    v.sort();
    v
}

/// Share of pixels in rows `rows` that are not near-white.
fn ink(p: &Pixmap, rows: std::ops::Range<u32>) -> f64 {
    let mut dark = 0usize;
    let mut all = 0usize;
    for y in rows {
        for x in 0..p.width() {
            let c = p.pixel(x, y).unwrap();
            all += 1;
            if u32::from(c.red()) + u32::from(c.green()) + u32::from(c.blue()) < 600 {
                dark += 1;
            }
        }
    }
    dark as f64 / all as f64
}

#[test]
fn a_run_report_is_one_page_with_its_figures_embedded() {
    let dir = tempfile::tempdir().unwrap();
    let run = common::run_completed(&common::resolve("smoke_2d.yaml", &[]), dir.path(), 1);
    let out = dir.path().join("report");
    let (code, stdout, stderr) = runner(&[
        "report".as_ref(),
        run.path.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--time".as_ref(),
        "0".as_ref(),
        "--time".as_ref(),
        "0.05".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    let page = PathBuf::from(stdout.trim());
    assert_eq!(page, out.join("index.html"));
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(!stderr.contains("left out"), "{stderr}");

    // Self-contained: every source is an embedded PNG, the same bytes as the figure files.
    let files = pngs(&out);
    let images = embedded(&html);
    assert_eq!(images.len(), files.len());
    for (bytes, file) in images.iter().zip(&files) {
        assert_eq!(bytes, &std::fs::read(file).unwrap(), "{}", file.display());
    }
    assert!(!html.contains("http://") && !html.contains("https://"));
    // kinetic energy, top speed, the front; two snapshots at the times asked for.
    let names: Vec<String> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for want in ["kinetic_energy_j", "max_speed_m_s", "front_position_m"] {
        assert!(names.iter().any(|n| n.contains(want)), "{want}: {names:?}");
    }
    assert_eq!(
        names.iter().filter(|n| n.starts_with("snapshot-")).count(),
        2
    );
    assert!(html.contains("at the frame nearest t = 0.05 s"));

    // The page opens with the summary (experiment, hash, outcome), then the run's facts and
    // every summary metric.
    let summary = html.find("<h2>Summary</h2>").expect("a summary table");
    assert!(summary < html.find("<h2>Run</h2>").unwrap());
    assert!(html.contains(&run.summary.experiment_sha256));
    assert!(html.contains("<td>completed</td>"));
    for name in run.summary.metrics.keys() {
        assert!(html.contains(&format!("<th>{name}</th>")), "{name}");
    }

    // Real pictures: a title in ink (the shipped font drew it), data in the plot area, and the
    // snapshot's colour bar running from blue to red.
    for bytes in &images {
        let p = Pixmap::decode_png(bytes).expect("a PNG");
        assert!(
            p.width() >= 900 && p.height() >= 150,
            "{}x{}",
            p.width(),
            p.height()
        );
        let title = ink(&p, 0..35);
        assert!(title > 0.002, "no title text: {title}");
        let plot = ink(&p, 40..p.height() - 60);
        assert!(plot > 0.005, "an empty plot: {plot}");
    }
    let snap =
        Pixmap::decode_png(&std::fs::read(out.join("snapshot-01-speed_m_s.png")).unwrap()).unwrap();
    let bar_x = snap.width() - 150 + 27;
    let top = snap.pixel(bar_x, 75).unwrap();
    let bottom = snap.pixel(bar_x, snap.height() - 65).unwrap();
    assert!(top.red() > 200 && top.blue() < 80, "top of the bar {top:?}");
    assert!(
        bottom.blue() > 200 && bottom.red() < 80,
        "bottom of the bar {bottom:?}"
    );
}

#[test]
fn a_sweep_report_plots_each_metric_against_the_swept_value() {
    let dir = tempfile::tempdir().unwrap();
    let folder = common::smoke_sweep_folder(dir.path());
    let (code, stdout, stderr) = runner(&["report".as_ref(), folder.as_os_str()]);
    assert_eq!(code, Some(0), "{stderr}");
    let page = PathBuf::from(stdout.trim());
    assert_eq!(page, folder.join("report").join("index.html"));
    let html = std::fs::read_to_string(&page).unwrap();
    let files = pngs(&folder.join("report"));
    assert!(
        files.iter().any(|f| f
            .to_string_lossy()
            .ends_with("sweep-front_position_m-vs-scene.column_width_m.png")),
        "{files:?}"
    );
    assert_eq!(embedded(&html).len(), files.len());
    // The runs' table: one row per run, the swept value as a column.
    assert!(html.contains("<th>scene.column_width_m</th>"));
    assert_eq!(html.matches(".mcap</td>").count(), 2);
}

#[test]
fn a_report_of_nothing_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (code, _, stderr) = runner(&["report".as_ref(), dir.path().join("no.mcap").as_os_str()]);
    assert_eq!(code, Some(2), "{stderr}");
    let (code, _, stderr) = runner(&["report".as_ref(), dir.path().as_os_str()]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("no finished run file"), "{stderr}");
}

#[test]
fn closed_forms_stand_beside_what_they_predict() {
    // The page's summary table pairs each `closed_form_*` metric with its measured twin.
    let pairs = |name: &str| {
        let m = common::resolve(name, &[]).manifest;
        mps_runner::experiment::closed_form_pairs(&m)
    };
    let has = |all: &[(String, Option<String>)], closed: &str, measured: Option<&str>| {
        assert!(
            all.iter()
                .any(|(c, m)| c == closed && m.as_deref() == measured),
            "{closed} beside {measured:?}: {all:?}"
        );
    };
    let slump = pairs("slump_3d.yaml");
    has(&slump, "closed_form_radius_m", Some("spread_radius_mean_m"));
    has(
        &slump,
        "closed_form_height_r50_m",
        Some("surface_height_r50_m"),
    );
    let layer = pairs("inclined_layer.yaml");
    has(&layer, "closed_form_plug_speed_m_s", Some("plug_speed_m_s"));
    has(&layer, "closed_form_critical_depth_m", None);
    has(
        &pairs("column_collapse_2d.yaml"),
        "closed_form_heap_length_m",
        Some("heap_length_m"),
    );
    has(
        &pairs("l_box_3d.yaml"),
        "closed_form_height_x25_m",
        Some("surface_height_x25_m"),
    );
    has(
        &pairs("rockfill_2d.yaml"),
        "closed_form_surface_slope",
        Some("surface_slope"),
    );
    assert!(pairs("dam_break_2d.yaml").is_empty());
}
