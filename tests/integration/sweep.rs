//! Sweeps (`sweep:` manifests) and the SVG reports.
use crate::common;
use mps_runner::experiment;
use mps_runner::experiment::{Plan, Sweep, plan_from_str};
use mps_runner::manifest::ManifestError;
use mps_runner::record::read_run;
use mps_runner::report;
use mps_runner::sweep_run::{SweepOptions, run_sweep};
use std::path::{Path, PathBuf};

fn smoke_text() -> String {
    std::fs::read_to_string(common::experiment("smoke_2d.yaml")).unwrap()
}

/// smoke_2d.yaml with `section` appended.
fn with_section(section: &str) -> String {
    format!("{}\n{section}", smoke_text())
}

fn sets(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn sweep_of(text: &str, overrides: &[&str]) -> Sweep {
    match plan_from_str(text, "sweep.yaml", &sets(overrides)).unwrap() {
        Plan::Sweep(s) => s,
        Plan::Single(_) => panic!("expected a sweep"),
    }
}

fn sweep_err(text: &str, overrides: &[&str]) -> ManifestError {
    plan_from_str(text, "sweep.yaml", &sets(overrides)).unwrap_err()
}

const TWO_AXES: &str =
    "sweep:\n  scene.column_width_m: [0.1, 0.15, 0.2]\n  gravity_m_s2: [9.81, 5]\n";

#[test]
fn no_sweep_section_is_a_single_plan_equal_to_load() {
    let plan = plan_from_str(&smoke_text(), "x", &sets(&["time.end_s=0.05"])).unwrap();
    let plain = experiment::from_str(&smoke_text(), "x", &sets(&["time.end_s=0.05"])).unwrap();
    assert_eq!(plan, Plan::Single(Box::new(plain)));
}

#[test]
fn points_are_the_product_in_written_order_last_key_fastest() {
    let s = sweep_of(&with_section(TWO_AXES), &[]);
    let labels: Vec<String> = s.points.iter().map(|p| p.label()).collect();
    assert_eq!(
        labels,
        [
            "scene.column_width_m=0.1 gravity_m_s2=9.81",
            "scene.column_width_m=0.1 gravity_m_s2=5",
            "scene.column_width_m=0.15 gravity_m_s2=9.81",
            "scene.column_width_m=0.15 gravity_m_s2=5",
            "scene.column_width_m=0.2 gravity_m_s2=9.81",
            "scene.column_width_m=0.2 gravity_m_s2=5",
        ]
    );
    assert_eq!(s.name, "smoke_2d");
    assert_eq!(s.hash_hex.len(), 64);
    assert_eq!(
        s.folder_name(),
        format!("smoke_2d-sweep-{}", &s.hash_hex[..12])
    );
    // Key order is part of the sweep (it orders the points).
    let swapped = "sweep:\n  gravity_m_s2: [9.81, 5]\n  scene.column_width_m: [0.1, 0.15, 0.2]\n";
    let t = sweep_of(&with_section(swapped), &[]);
    assert_eq!(
        t.points[1].label(),
        "gravity_m_s2=9.81 scene.column_width_m=0.15"
    );
    assert_ne!(t.hash_hex, s.hash_hex);
}

#[test]
fn each_point_equals_the_plain_manifest_with_sets() {
    let text = with_section(TWO_AXES);
    let s = sweep_of(&text, &["time.end_s=0.05"]);
    assert_eq!(s.points.len(), 6);
    for p in &s.points {
        let mut o = vec!["time.end_s=0.05".to_string()];
        o.extend(p.assignments.iter().map(|(k, v)| format!("{k}={v}")));
        let plain = experiment::load(&common::experiment("smoke_2d.yaml"), &o).unwrap();
        assert_eq!(p.resolved.canonical, plain.canonical);
        assert_eq!(p.resolved.hash_hex, plain.hash_hex);
        assert!(!p.resolved.canonical.contains("sweep"));
        // The recorded source and overrides reproduce the point.
        assert_eq!(p.resolved.source_text, text);
        assert_eq!(p.resolved.overrides, o);
    }
    // Hashes are all distinct; the sweep hash ignores comments and spelling (5 vs 5.0).
    let mut hashes: Vec<&str> = s
        .points
        .iter()
        .map(|p| p.resolved.hash_hex.as_str())
        .collect();
    hashes.sort();
    hashes.dedup();
    assert_eq!(hashes.len(), 6);
    let respelled = "sweep:  # comment\n  scene.column_width_m: [0.10, 0.15, 0.2]\n  gravity_m_s2: [9.81, 5.0]\n";
    assert_eq!(
        sweep_of(&with_section(respelled), &["time.end_s=0.05"]).hash_hex,
        s.hash_hex
    );
}

#[test]
fn set_on_a_swept_key_pins_it() {
    let s = sweep_of(&with_section(TWO_AXES), &["gravity_m_s2=3"]);
    assert_eq!(s.axes.len(), 1);
    assert_eq!(s.points.len(), 3);
    for p in &s.points {
        assert_eq!(p.resolved.manifest.gravity_m_s2, 3.0);
    }
}

#[test]
fn flow_style_and_sweep_first_keep_other_locations() {
    let s = sweep_of(
        &format!(
            "sweep: {{gravity_m_s2: [1, 2], time.end_s: [0.01]}}\n{}",
            smoke_text()
        ),
        &[],
    );
    assert_eq!(s.points.len(), 2);
    // A top-level flow mapping with the sweep entry first.
    let flow = "{sweep: {gravity_m_s2: [1, 2]}, name: f, dimension: 2, spacing_m: 0.025, \
                time: {end_s: 0.1}, fluid: {model: newtonian, density_kg_m3: 1000, \
                viscosity_pa_s: 0.001}, scene: {kind: dam_break}}";
    assert_eq!(sweep_of(flow, &[]).points.len(), 2);
    // A bad value below a multi-line sweep section keeps its own line and column.
    let text = format!(
        "sweep:\n  gravity_m_s2:\n    - 1\n    - 2\n{}",
        smoke_text()
    );
    let bad = text.replace("end_s: 0.1", "end_s: -1");
    let line = bad.lines().position(|l| l.contains("end_s: -1")).unwrap() + 1;
    let e = sweep_err(&bad, &[]);
    assert_eq!(e.field(), Some("time.end_s"));
    assert_eq!(e.location(), Some((line, 10)), "{e}");
}

#[test]
fn sweep_errors_name_the_key_and_its_location() {
    let base = smoke_text();
    let n = base.lines().count() + 3; // line of the first swept key (after a blank line and `sweep:`)
    let case = |section: &str| sweep_err(&with_section(section), &[]);

    let e = case("sweep:\n  fluid.nope: [1, 2]\n");
    assert_eq!(e.field(), Some("sweep.fluid.nope.0"), "{e}");
    assert!(e.to_string().contains("unknown key `nope`"), "{e}");
    assert_eq!(e.location(), Some((n, 16)), "{e}");

    let e = case("sweep:\n  gravity_m_s2: []\n");
    assert_eq!(e.field(), Some("sweep.gravity_m_s2"));
    assert!(e.to_string().contains("empty list"), "{e}");
    assert_eq!(e.location(), Some((n, 17)), "{e}");

    let e = case("sweep:\n  gravity_m_s2: [1, [2]]\n");
    assert_eq!(e.field(), Some("sweep.gravity_m_s2.1"));
    assert!(e.to_string().contains("not a scalar"), "{e}");
    assert_eq!(e.location(), Some((n, 21)), "{e}");

    let e = case("sweep:\n  gravity_m_s2: 3\n");
    assert!(e.to_string().contains("expected a list"), "{e}");

    let e = case("sweep: [1, 2]\n");
    assert_eq!(e.field(), Some("sweep"));
    assert!(e.to_string().contains("expected a mapping"), "{e}");

    let e = case("sweep: {}\n");
    assert!(e.to_string().contains("empty sweep"), "{e}");

    // A value that fails validation is located at the value in the sweep.
    let e = case("sweep:\n  time.end_s: [0.05, -1]\n");
    assert_eq!(e.field(), Some("sweep.time.end_s.1"), "{e}");
    assert_eq!(e.location(), Some((n, 22)), "{e}");
    assert!(e.to_string().ends_with("(from sweep)"), "{e}");

    // A value of the wrong type.
    let e = case("sweep:\n  dimension: [2, abc]\n");
    assert_eq!(e.field(), Some("sweep.dimension.1"), "{e}");
}

fn write_sweep(dir: &Path, name: &str, section: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, with_section(section)).unwrap();
    path
}

fn svg(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    roxmltree::Document::parse(&text).expect("valid SVG (XML)");
    assert!(text.contains("<svg"));
    text
}

/// Data series (width-2 polylines), circles and texts of an SVG plot.
fn counts(text: &str) -> (usize, usize) {
    let series = text
        .matches("<polyline")
        .zip(text.split("<polyline").skip(1))
        .filter(|(_, rest)| {
            rest.split('>')
                .next()
                .unwrap()
                .contains("stroke-width=\"2\"")
        })
        .count();
    (series, text.matches("<circle").count())
}

#[test]
fn sweep_runs_equal_single_runs_and_are_plotted() {
    let dir = tempfile::tempdir().unwrap();
    let section = "sweep:\n  scene.column_width_m: [0.1, 0.15]\n  gravity_m_s2: [9.81, 5]\n";
    let path = write_sweep(dir.path(), "sweep.yaml", section);
    let out = dir.path().join("runs");
    let assert = common::runner()
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .args(["--set", "time.end_s=0.04", "--quiet"])
        .assert()
        .success();
    let stdout = String::from_utf8(assert.get_output().stdout.clone()).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 5, "{stdout}");
    let folder = PathBuf::from(lines[4]);
    let s = sweep_of(&with_section(section), &["time.end_s=0.04"]);
    assert_eq!(folder, out.join(s.folder_name()));
    for line in &lines[..4] {
        assert!(line.contains(" completed "), "{line}");
    }

    // Every file equals a single run with the equivalent --set.
    let single_dir = dir.path().join("single");
    for p in &s.points {
        let mut o = vec!["time.end_s=0.04".to_string()];
        o.extend(p.assignments.iter().map(|(k, v)| format!("{k}={v}")));
        let plain = experiment::load(&common::experiment("smoke_2d.yaml"), &o).unwrap();
        let single = common::run_in(&plain, &single_dir, 2);
        let file = folder.join(format!("smoke_2d-{}.mcap", plain.short_hash()));
        let swept = read_run(&file).unwrap().summary.unwrap();
        assert_eq!(swept.checkpoints, single.summary.checkpoints);
        assert_eq!(swept.experiment_sha256, plain.hash_hex);
        assert!(!swept.checkpoints.is_empty());
    }

    // The automatic sweep plot: x = column width, one line per gravity value.
    let plot = folder.join("sweep-front_position_m-vs-scene.column_width_m.svg");
    let text = svg(&plot);
    assert_eq!(counts(&text), (2, 4));
    assert!(text.contains("scene.column_width_m [m]"));
    assert!(text.contains("front_position_m [m]"));
    assert!(text.contains("gravity_m_s2=9.81") && text.contains("gravity_m_s2=5"));

    // plot-sweep by hand, other grouping.
    let custom = dir.path().join("custom.svg");
    common::runner()
        .args(["plot-sweep"])
        .arg(&folder)
        .args(["--x", "gravity_m_s2", "--y", "front_position_m", "--group"])
        .arg("scene.column_width_m")
        .arg("--out")
        .arg(&custom)
        .assert()
        .success();
    assert_eq!(counts(&svg(&custom)), (2, 4));
    // Unknown key: bad input.
    common::runner()
        .args(["plot-sweep"])
        .arg(&folder)
        .args(["--x", "fluid.nope", "--y", "front_position_m"])
        .assert()
        .code(2);
}

#[test]
fn run_sweep_library_and_failed_points() {
    let dir = tempfile::tempdir().unwrap();
    // The second point fails (blow-up guard); the others still run: exit 3.
    let path = write_sweep(
        dir.path(),
        "sweep.yaml",
        "sweep:\n  stop.max_speed_m_s: [100, 0.01, 50]\n",
    );
    let out = dir.path().join("runs");
    let assert = common::runner()
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .args(["--set", "time.end_s=0.03", "--quiet", "--threads", "2"])
        .assert()
        .code(3);
    let stdout = String::from_utf8(assert.get_output().stdout.clone()).unwrap();
    assert_eq!(
        stdout.lines().filter(|l| l.contains(" failed ")).count(),
        1,
        "{stdout}"
    );
    assert_eq!(
        stdout.lines().filter(|l| l.contains(" completed ")).count(),
        2
    );
    let folder = PathBuf::from(stdout.lines().last().unwrap());
    assert_eq!(report::run_files(&folder).unwrap().len(), 3);

    // Library: outcomes in expansion order, one worker gives the same files.
    let s = sweep_of(
        &with_section("sweep:\n  gravity_m_s2: [9.81, 4]\n"),
        &["time.end_s=0.02"],
    );
    let options = SweepOptions {
        out_dir: dir.path().join("lib"),
        workers: Some(1),
        interrupt: None,
        max_particles: None,
        overwrite: false,
        ..Default::default()
    };
    let (folder, outcomes) = run_sweep(&s, &options, &|_| {});
    assert_eq!(outcomes.iter().map(|o| o.index).collect::<Vec<_>>(), [0, 1]);
    for (o, p) in outcomes.iter().zip(&s.points) {
        let r = o.result.as_ref().unwrap();
        assert_eq!(
            r.path,
            folder.join(format!("smoke_2d-{}.mcap", p.resolved.short_hash()))
        );
    }

    // Bad sweep: exit 2, message names the key.
    let bad = write_sweep(dir.path(), "bad.yaml", "sweep:\n  fluid.nope: [1]\n");
    let assert = common::runner().arg(&bad).assert().code(2);
    let stderr = String::from_utf8(assert.get_output().stderr.clone()).unwrap();
    assert!(stderr.contains("sweep.fluid.nope"), "{stderr}");

    // `runner hash` of a sweep prints the sweep hash.
    let assert = common::runner().arg("hash").arg(&path).assert().success();
    let hash = String::from_utf8(assert.get_output().stdout.clone()).unwrap();
    let s = sweep_of(
        &with_section("sweep:\n  stop.max_speed_m_s: [100, 0.01, 50]\n"),
        &[],
    );
    assert_eq!(hash.trim(), s.hash_hex);
}

#[test]
fn plot_and_snapshot_of_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve("smoke_2d.yaml", &["time.end_s=0.04"]);
    let result = common::run_in(&resolved, dir.path(), 1);
    let run = read_run(&result.path).unwrap();
    assert!(run.clouds > 0);
    let frame = report::cloud::Frame::decode(run.last_cloud.as_ref().unwrap()).unwrap();
    assert!(frame.fields.contains_key("kind") && frame.fields.contains_key("speed_m_s"));

    // Default metric: the first experiment metric; one series with one point per row.
    let assert = common::runner()
        .arg("plot")
        .arg(&result.path)
        .assert()
        .success();
    let out = PathBuf::from(
        String::from_utf8(assert.get_output().stdout.clone())
            .unwrap()
            .trim(),
    );
    assert!(out.ends_with(format!(
        "smoke_2d-{}-front_position_m.svg",
        resolved.short_hash()
    )));
    let text = svg(&out);
    assert_eq!(counts(&text).0, 1);
    assert!(text.contains("time_s [s]") && text.contains(resolved.short_hash()));
    let points = text
        .split("<polyline")
        .find(|p| p.split('>').next().unwrap().contains("stroke-width=\"2\""))
        .unwrap()
        .split("points=\"")
        .nth(1)
        .unwrap()
        .split('"')
        .next()
        .unwrap()
        .split_whitespace()
        .count();
    assert_eq!(points, run.diagnostics.len());

    let ke = dir.path().join("ke.svg");
    common::runner()
        .arg("plot")
        .arg(&result.path)
        .args(["--metric", "kinetic_energy_j", "--out"])
        .arg(&ke)
        .assert()
        .success();
    assert!(svg(&ke).contains("kinetic_energy_j [J]"));
    common::runner()
        .arg("plot")
        .arg(&result.path)
        .args(["--metric", "nope"])
        .assert()
        .code(2);

    // Snapshots: one circle per particle, categorical and ramp colouring.
    for field in ["kind", "speed_m_s"] {
        let out = dir.path().join(format!("snap-{field}.svg"));
        common::runner()
            .arg("snapshot")
            .arg(&result.path)
            .args(["--field", field, "--out"])
            .arg(&out)
            .assert()
            .success();
        let text = svg(&out);
        assert_eq!(counts(&text).1, frame.len(), "{field}");
        assert!(text.contains("x [m]") && text.contains("y [m]"));
    }
    common::runner()
        .arg("snapshot")
        .arg(&result.path)
        .args(["--field", "nope"])
        .assert()
        .code(2);
}

#[test]
fn units_from_key_suffixes() {
    assert_eq!(
        report::axis_label("fluid.yield_stress_pa"),
        "fluid.yield_stress_pa [Pa]"
    );
    assert_eq!(report::axis_label("gravity_m_s2"), "gravity_m_s2 [m/s²]");
    assert_eq!(report::axis_label("max_speed_m_s"), "max_speed_m_s [m/s]");
    assert_eq!(report::axis_label("l_flow_value_m"), "l_flow_value_m [m]");
    assert_eq!(report::axis_label("steps"), "steps [-]");
    assert_eq!(
        report::plot::coloring(&[0.0, 1.0, 1.0]),
        report::plot::Coloring::Categorical(vec![0, 1])
    );
}

#[test]
fn only_the_points_need_to_be_valid() {
    // The file's own end time is invalid; every point overrides it.
    let text =
        with_section("sweep:\n  time.end_s: [0.01, 0.02]\n").replace("end_s: 0.1", "end_s: -1");
    assert!(experiment::from_str(&text, "x", &[]).is_err());
    assert_eq!(sweep_of(&text, &[]).points.len(), 2);
    // A YAML syntax error still has its usual location.
    let e = sweep_err(&with_section("sweep:\n  gravity_m_s2: [1, 2\n"), &[]);
    assert!(matches!(e, ManifestError::Syntax { .. }), "{e}");
}

/// A sweep run again picks up where it was: interrupted points resume (to the bits of an
/// uninterrupted sweep), finished points are taken as they are, `overwrite` runs them again.
#[test]
fn a_sweep_run_again_resumes_interrupted_points_and_keeps_finished_ones() {
    use mps_runner::sweep_run::PointStart;
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;
    let dir = tempfile::tempdir().unwrap();
    let s = sweep_of(
        &with_section("sweep:\n  gravity_m_s2: [9.81, 4]\n"),
        &["time.end_s=0.02"],
    );
    let options = |out: &str, interrupted: bool, overwrite: bool| SweepOptions {
        out_dir: dir.path().join(out),
        workers: Some(2),
        interrupt: Some(Arc::new(AtomicBool::new(interrupted))),
        max_particles: None,
        overwrite,
        ..Default::default()
    };
    let hashes = |outcomes: &[mps_runner::sweep_run::PointOutcome]| -> Vec<Vec<String>> {
        outcomes
            .iter()
            .map(|o| {
                let r = o.result.as_ref().unwrap();
                r.summary
                    .checkpoints
                    .iter()
                    .map(|c| c.state_sha256.clone())
                    .collect()
            })
            .collect()
    };
    let (_, reference) = run_sweep(&s, &options("ref", false, false), &|_| {});
    // Interrupted before the first step: every point's file is finished as interrupted.
    let (folder, first) = run_sweep(&s, &options("sweep", true, false), &|_| {});
    for o in &first {
        assert_eq!(o.result.as_ref().unwrap().summary.outcome, "interrupted");
    }
    let (_, second) = run_sweep(&s, &options("sweep", false, false), &|_| {});
    for o in &second {
        assert_eq!(o.start, PointStart::Resumed);
        assert_eq!(o.result.as_ref().unwrap().summary.outcome, "completed");
    }
    assert_eq!(hashes(&second), hashes(&reference));
    let files = report::run_files(&folder).unwrap();
    assert_eq!(files.len(), 2);
    let bytes: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(f).unwrap()).collect();
    let (_, third) = run_sweep(&s, &options("sweep", false, false), &|_| {});
    for o in &third {
        assert_eq!(o.start, PointStart::Existing);
    }
    assert_eq!(hashes(&third), hashes(&reference));
    let again: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(f).unwrap()).collect();
    assert_eq!(again, bytes, "finished points are not written again");
    let (_, fourth) = run_sweep(&s, &options("sweep", false, true), &|_| {});
    for o in &fourth {
        assert_eq!(o.start, PointStart::Ran);
    }
    assert_eq!(hashes(&fourth), hashes(&reference));
}

/// The files of a folder (name -> bytes), `.mcap` only.
fn run_files(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect()
}

/// Slices of a sweep (`--shard I/N`, or a Slurm job array's variables) run into one folder
/// give the unsliced sweep's files, byte for byte; bad slices are refused.
#[test]
fn shards_together_are_the_whole_sweep_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let section = "sweep:\n  scene.column_width_m: [0.1, 0.15]\n  gravity_m_s2: [9.81, 5]\n";
    let path = write_sweep(dir.path(), "sweep.yaml", section);
    let s = sweep_of(&with_section(section), &["time.end_s=0.04"]);
    let run = |out: &Path, extra: &[&str], env: &[(&str, &str)]| {
        let mut cmd = common::runner();
        cmd.arg(&path)
            .arg("--out")
            .arg(out)
            .args(["--set", "time.end_s=0.04", "--quiet"])
            .args(extra)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("SLURM_ARRAY_TASK_COUNT")
            .env_remove("SLURM_ARRAY_TASK_MIN");
        for (k, v) in env {
            cmd.env(k, v);
        }
        cmd.output().unwrap()
    };
    let whole = dir.path().join("whole");
    assert!(run(&whole, &[], &[]).status.success());
    let whole_files = run_files(&whole.join(s.folder_name()));
    assert_eq!(whole_files.len(), 4);

    // Three slices of four points: 2 + 1 + 1, into one folder.
    let sliced = dir.path().join("sliced");
    let mut counts = Vec::new();
    for i in 1..=3 {
        let out = run(&sliced, &["--shard", &format!("{i}/3")], &[]);
        assert!(out.status.success(), "{out:?}");
        let stdout = String::from_utf8(out.stdout).unwrap();
        counts.push(stdout.lines().filter(|l| l.contains(" completed ")).count());
    }
    assert_eq!(counts, [2, 1, 1]);
    assert!(
        run_files(&sliced.join(s.folder_name())) == whole_files,
        "the slices' files differ from the whole sweep's"
    );
    // No sweep plot from a slice.
    assert!(
        !std::fs::read_dir(sliced.join(s.folder_name()))
            .unwrap()
            .any(|e| e.unwrap().path().extension().is_some_and(|x| x == "svg"))
    );

    // A Slurm array --array=5-7: task 5 is slice 1/3, the points 1 and 4.
    let slurm = dir.path().join("slurm");
    let env = [
        ("SLURM_ARRAY_TASK_ID", "5"),
        ("SLURM_ARRAY_TASK_MIN", "5"),
        ("SLURM_ARRAY_TASK_COUNT", "3"),
    ];
    let out = run(&slurm, &[], &env);
    assert!(out.status.success(), "{out:?}");
    let got = run_files(&slurm.join(s.folder_name()));
    let expected: Vec<String> = [0, 3]
        .iter()
        .map(|&k| format!("smoke_2d-{}.mcap", &s.points[k].resolved.hash_hex[..12]))
        .collect();
    assert_eq!(got.keys().cloned().collect::<Vec<_>>(), {
        let mut e = expected.clone();
        e.sort();
        e
    });
    for (name, bytes) in &got {
        assert!(bytes == &whole_files[name], "{name} differs");
    }

    // Bad slices: exit 2, named, nothing run.
    for (extra, env, needle) in [
        (vec!["--shard", "0/3"], vec![], "1 <= I <= N"),
        (vec!["--shard", "4/3"], vec![], "1 <= I <= N"),
        (vec!["--shard", "two"], vec![], "I/N"),
        (
            vec![],
            vec![
                ("SLURM_ARRAY_TASK_ID", "9"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ],
            "SLURM_ARRAY_TASK_ID",
        ),
    ] {
        let bad = dir.path().join("bad");
        let out = run(&bad, &extra, &env);
        assert_eq!(out.status.code(), Some(2), "{out:?}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains(needle),
            "{out:?}"
        );
        assert!(!bad.exists());
    }
    let single = common::runner()
        .arg(common::experiment("smoke_2d.yaml"))
        .args(["--shard", "1/2", "--out"])
        .arg(dir.path().join("single"))
        .output()
        .unwrap();
    assert_eq!(single.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&single.stderr).contains("--shard"));
}

/// `runner expand`: one manifest per point, each hashing to its point, and a run of one gives
/// the sweep point's state bits.
#[test]
fn expanded_manifests_are_the_sweep_points() {
    let dir = tempfile::tempdir().unwrap();
    let section = "sweep:\n  scene.column_width_m: [0.1, 0.15]\n  gravity_m_s2: [9.81, 5]\n";
    let path = write_sweep(dir.path(), "sweep.yaml", section);
    let s = sweep_of(&with_section(section), &["time.end_s=0.04"]);
    let out = dir.path().join("manifests");
    let assert = common::runner()
        .arg("expand")
        .arg(&path)
        .args(["--set", "time.end_s=0.04", "--out"])
        .arg(&out)
        .assert()
        .success();
    let stdout = String::from_utf8(assert.get_output().stdout.clone()).unwrap();
    let files: Vec<PathBuf> = stdout.lines().map(PathBuf::from).collect();
    assert_eq!(files.len(), s.points.len());
    for (file, point) in files.iter().zip(&s.points) {
        let resolved = experiment::load(file, &[]).unwrap();
        assert_eq!(resolved.hash_hex, point.resolved.hash_hex);
        assert!(
            file.to_string_lossy()
                .ends_with(&format!("-{}.yaml", &point.resolved.hash_hex[..12]))
        );
    }
    // The second point run from its manifest equals the sweep's run of it.
    let single = dir.path().join("single");
    let assert = common::runner()
        .arg(&files[1])
        .arg("--out")
        .arg(&single)
        .arg("--quiet")
        .assert()
        .success();
    let single_file = PathBuf::from(
        String::from_utf8(assert.get_output().stdout.clone())
            .unwrap()
            .lines()
            .last()
            .unwrap(),
    );
    let sweep_out = dir.path().join("runs");
    common::runner()
        .arg(&path)
        .arg("--out")
        .arg(&sweep_out)
        .args(["--set", "time.end_s=0.04", "--quiet"])
        .assert()
        .success();
    let point_file = sweep_out
        .join(s.folder_name())
        .join(single_file.file_name().unwrap());
    // Same experiment, same state bits (the files' metadata differ: each keeps the manifest
    // text it was run from).
    let (a, b) = (
        read_run(&single_file).unwrap(),
        read_run(&point_file).unwrap(),
    );
    let (a, b) = (a.summary.unwrap(), b.summary.unwrap());
    assert_eq!(a.experiment_sha256, b.experiment_sha256);
    assert!(!a.checkpoints.is_empty());
    assert!(a.checkpoints == b.checkpoints, "checkpoint hashes differ");
    // A manifest without a sweep is refused.
    common::runner()
        .arg("expand")
        .arg(common::experiment("smoke_2d.yaml"))
        .assert()
        .code(2);
}
