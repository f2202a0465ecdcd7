//! `runner bench --suite`: a tiny suite (smoke_2d-sized cases, a 2-point sweep, a scaling
//! series) run end to end through the binary, its Markdown read back; bad suite files refused.
use crate::common;
use std::path::{Path, PathBuf};

/// A 2-point sweep of smoke_2d over the viscosity (the same particles at both points), in
/// `dir`, named as the suite refers to it (relative to the suite's folder).
fn write_sweep(dir: &Path) {
    let text = std::fs::read_to_string(common::experiment("smoke_2d.yaml")).unwrap();
    std::fs::write(
        dir.join("sweep.yaml"),
        format!("{text}\nsweep:\n  fluid.viscosity_pa_s: [1.0e-3, 2.0e-3]\n"),
    )
    .unwrap();
}

fn write_suite(dir: &Path, text: &str) -> PathBuf {
    let path = dir.join("suite.yaml");
    std::fs::write(&path, text).unwrap();
    path
}

fn tiny_suite(dir: &Path) -> PathBuf {
    write_sweep(dir);
    let smoke = common::experiment("smoke_2d.yaml");
    let smoke = smoke.display();
    write_suite(
        dir,
        &format!(
            "cases:
  - name: smoke
    manifest: {smoke}
    set: [time.end_s=0.05]
    quick_set: [time.end_s=0.02]
  - name: smoke_fine
    manifest: {smoke}
    set: [spacing_m=0.02, time.end_s=0.02]
  - name: viscosity_sweep
    manifest: sweep.yaml
    set: [time.end_s=0.02]
scaling:
  manifest: {smoke}
  set: [stop.max_steps=5]
  spacings_m: [0.025, 0.0125, 0.01]
"
        ),
    )
}

/// The rows of the Markdown table whose header line starts with `header`, as cells.
fn table(text: &str, header: &str) -> Vec<Vec<String>> {
    let mut lines = text.lines().skip_while(|l| !l.starts_with(header));
    lines
        .next()
        .unwrap_or_else(|| panic!("no table {header:?} in\n{text}"));
    lines
        .skip(1) // |---|---|
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let inner = l.trim().trim_start_matches('|').trim_end_matches('|');
            inner.split(" | ").map(|c| c.trim().to_string()).collect()
        })
        .collect()
}

fn number(cell: &str) -> f64 {
    cell.parse()
        .unwrap_or_else(|_| panic!("{cell:?} is not a number"))
}

#[test]
fn suite_runs_every_case_and_the_scaling_series() {
    let dir = tempfile::tempdir().unwrap();
    let suite = tiny_suite(dir.path());
    let md = dir.path().join("out.md");
    let (code, stdout, stderr) = common::runner_all(&[
        "bench".as_ref(),
        "--suite".as_ref(),
        suite.as_os_str(),
        "--quick".as_ref(),
        "--threads".as_ref(),
        "2".as_ref(),
        "--markdown".as_ref(),
        md.as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{stderr}\n{stdout}");
    assert_eq!(std::fs::read_to_string(&md).unwrap(), stdout);
    assert!(stdout.starts_with("Benchmark suite"), "{stdout}");
    assert!(
        stdout.contains("threads 2") && stdout.contains(" UTC"),
        "{stdout}"
    );
    for name in ["smoke", "smoke_fine", "viscosity_sweep"] {
        assert!(
            stderr.contains(&format!(" {name}")),
            "no progress line for {name}: {stderr}"
        );
    }

    let rows = table(&stdout, "| case |");
    let names: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(names, ["smoke", "smoke_fine", "viscosity_sweep (2 points)"]);
    for r in &rows {
        assert_eq!(r.len(), 10, "{r:?}");
        assert!(
            number(&r[2]) > 0.0 && number(&r[3]) > 0.0,
            "particles, steps: {r:?}"
        );
        for cell in [&r[4], &r[5], &r[6]] {
            assert!(number(cell) > 0.0, "wall, rate, time to result: {r:?}");
        }
        assert_eq!(r[7], "completed", "{r:?}");
        if cfg!(unix) {
            assert!(number(&r[9]) > 0.0, "peak MiB: {r:?}");
        }
    }
    // --quick added the quick_set after the set: the 0.02 s end applies.
    assert!(
        rows[0][1].contains("--set time.end_s=0.05 --set time.end_s=0.02"),
        "{:?}",
        rows[0]
    );
    assert!(rows[0][8].contains('%'), "largest stages: {:?}", rows[0]);
    // The sweep: 2 points of 246 particles, its steps summed, no stage split.
    let sweep = &rows[2];
    assert_eq!(number(&sweep[2]), 246.0);
    assert!(number(&sweep[3]) > number(&rows[0][3]), "{sweep:?}");
    assert_eq!(sweep[8], "n/a");
    let out = sweep[1]
        .split("--out ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap();
    assert!(
        !Path::new(out).exists(),
        "the sweep's temporary folder {out} is left"
    );

    let scaling = table(&stdout, "| spacing m |");
    assert_eq!(scaling.len(), 3, "{stdout}");
    let particles: Vec<f64> = scaling.iter().map(|r| number(&r[1])).collect();
    assert!(particles.windows(2).all(|w| w[0] < w[1]), "{particles:?}");
    for r in &scaling {
        assert_eq!(number(&r[2]), 5.0, "stop.max_steps=5: {r:?}");
        assert!(number(&r[4]) > 0.0, "{r:?}");
        if cfg!(unix) {
            assert!(number(&r[5]) > 0.0 && number(&r[6]) > 0.0, "{r:?}");
        }
        assert_eq!(r[7], "completed");
    }
}

#[test]
fn runner_option_measures_the_given_binary() {
    let dir = tempfile::tempdir().unwrap();
    let smoke = common::experiment("smoke_2d.yaml");
    let suite = write_suite(
        dir.path(),
        &format!(
            "cases:\n  - name: smoke\n    manifest: {}\n    set: [time.end_s=0.01]\n",
            smoke.display()
        ),
    );
    let bin = env!("CARGO_BIN_EXE_runner");
    let (code, stdout, stderr) =
        common::runner_all(&["bench", "--suite", suite.to_str().unwrap(), "--runner", bin]);
    assert_eq!(code, Some(0), "{stderr}");
    // The header gives the binary and its `--version`; the command starts with it.
    assert!(
        stdout.contains(&format!("runner `{bin}` (runner ")),
        "{stdout}"
    );
    let rows = table(&stdout, "| case |");
    assert!(
        rows[0][1].starts_with(&format!("`{bin} bench ")),
        "{rows:?}"
    );
    assert!(
        !stdout.contains("| spacing m |"),
        "no scaling series in this suite: {stdout}"
    );
    // The progress lines give every stage's seconds, not only the table's three shares.
    let stage_rows: Vec<&str> = stderr
        .lines()
        .skip_while(|l| !l.starts_with("    stage "))
        .skip(1)
        .take_while(|l| l.starts_with("    ") && l.ends_with('%'))
        .collect();
    assert_eq!(stage_rows.len(), 7, "{stderr}");
    assert!(stage_rows[4].starts_with("    PPE solve (CG "), "{stderr}");
}

#[test]
fn a_failing_case_is_a_row_not_an_abort() {
    let dir = tempfile::tempdir().unwrap();
    let smoke = common::experiment("smoke_2d.yaml");
    // A speed guard of 0.01 m/s fails the dam break at once (exit 3); the next case runs.
    let suite = write_suite(
        dir.path(),
        &format!(
            "cases:
  - name: blows_up
    manifest: {0}
    set: [time.end_s=0.05, stop.max_speed_m_s=0.01]
  - name: fine
    manifest: {0}
    set: [time.end_s=0.01]
",
            smoke.display()
        ),
    );
    let (code, stdout, stderr) = common::runner_all(&["bench", "--suite", suite.to_str().unwrap()]);
    assert_eq!(code, Some(3), "{stderr}\n{stdout}");
    let rows = table(&stdout, "| case |");
    assert_eq!(rows.len(), 2, "{stdout}");
    assert_eq!(rows[0][7], "failed (exit 3)", "{rows:?}");
    assert_eq!(rows[1][7], "completed", "{rows:?}");
}

/// The suite's error: exit 2 and stderr.
fn refused(text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let suite = write_suite(dir.path(), text);
    let (code, stderr) = common::runner_output(&["bench", "--suite", suite.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{stderr}");
    stderr
}

#[test]
fn bad_suite_files_are_refused_naming_the_field() {
    let smoke = common::experiment("smoke_2d.yaml");
    let smoke = smoke.display();
    let err = refused(&format!(
        "cases:\n  - name: a\n    manifest: {smoke}\n    sett: [time.end_s=0.02]\n"
    ));
    assert!(
        err.contains("suite.yaml:4:5: cases.0.sett: unknown field `sett`"),
        "{err}"
    );

    let err = refused("cases:\n  - name: a\n    manifest: missing.yaml\n");
    assert!(err.contains("suite.yaml:3:15: cases.0.manifest: "), "{err}");
    assert!(err.contains("missing.yaml is not a file"), "{err}");

    let err = refused(&format!(
        "cases:\n  - name: a\n    manifest: {smoke}\n    set: [time.end_s=0.02, time.nope=1]\n"
    ));
    assert!(
        err.contains("cases.0.set.1: --set time.nope: unknown key `nope`"),
        "{err}"
    );

    let err = refused(&format!(
        "scaling:\n  manifest: {smoke}\n  spacings_m: [0.025, -1]\n"
    ));
    assert!(
        err.contains("scaling.spacings_m.1: must be a spacing > 0"),
        "{err}"
    );
}

#[test]
fn a_missing_suite_file_is_bad_input() {
    let (code, stderr) = common::runner_output(&["bench", "--suite", "no/such/suite.yaml"]);
    assert_eq!(code, Some(2));
    assert!(
        stderr.contains("no/such/suite.yaml: cannot read the suite file"),
        "{stderr}"
    );
}

#[test]
fn case_option_runs_only_the_named_cases() {
    let dir = tempfile::tempdir().unwrap();
    let suite = tiny_suite(dir.path());
    let suite = suite.to_str().unwrap();
    let (code, stdout, stderr) =
        common::runner_all(&["bench", "--suite", suite, "--case", "scaling"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!stdout.contains("| case |"), "no case was named: {stdout}");
    assert!(stdout.contains("| spacing m |"), "{stdout}");
    let (code, _, stderr) = common::runner_all(&["bench", "--suite", suite, "--case", "nope"]);
    assert_eq!(code, Some(2));
    assert!(
        stderr.contains("--case: no case `nope`") && stderr.contains("scaling"),
        "{stderr}"
    );
}
