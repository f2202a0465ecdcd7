//! The `runner` binary end to end: outputs, exit codes, error messages.
mod common;
use assert_cmd::Command;
use mps_runner::record::read_run;
use std::path::PathBuf;

fn runner() -> Command {
    Command::cargo_bin("runner").unwrap()
}

#[test]
fn hash_prints_64_hex_digits_and_follows_overrides() {
    let exp = common::experiment("dam_break_2d.yaml");
    let out = runner()
        .arg("hash")
        .arg(&exp)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let hash = String::from_utf8(out).unwrap().trim().to_string();
    assert_eq!(hash.len(), 64);
    assert!(
        hash.chars()
            .all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase())
    );
    let out = runner()
        .args(["hash", "--set", "spacing_m=0.02"])
        .arg(&exp)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    assert_ne!(String::from_utf8(out).unwrap().trim(), hash);
}

#[test]
fn run_writes_named_mcap_and_prints_its_path_last() {
    let dir = tempfile::tempdir().unwrap();
    let exp = common::experiment("smoke_2d.yaml");
    let assert = runner()
        .arg(&exp)
        .arg("--out")
        .arg(dir.path())
        .args(["--threads", "2", "--set", "time.end_s=0.03"])
        .assert()
        .success();
    let stdout = String::from_utf8(assert.get_output().stdout.clone()).unwrap();
    let path = PathBuf::from(stdout.lines().last().unwrap());
    let resolved = common::resolve("smoke_2d.yaml", &["time.end_s=0.03"]);
    assert_eq!(
        path,
        dir.path()
            .join(format!("smoke_2d-{}.mcap", &resolved.hash_hex[..12]))
    );
    let run = read_run(&path).unwrap();
    assert!(run.complete);
    let summary = run.summary.unwrap();
    assert_eq!(summary.outcome, "completed");
    for key in [
        "particle_count",
        "fluid_particle_count",
        "steps",
        "simulated_time_s",
        "front_position_m",
    ] {
        assert!(summary.metrics.contains_key(key), "summary lacks {key}");
    }
    assert!((summary.metrics["simulated_time_s"] - 0.03).abs() < 1e-12);
    assert_eq!(
        run.metadata["manifest"]["experiment_sha256"],
        resolved.hash_hex
    );
    // Nothing half-written is left behind.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
}

#[test]
fn bad_manifest_exits_2_naming_field_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.yaml");
    let text = std::fs::read_to_string(common::experiment("smoke_2d.yaml")).unwrap();
    let text = text.replacen("spacing_m: 0.025", "spacing_m: -0.025", 1);
    assert!(text.contains("spacing_m: -0.025"));
    std::fs::write(&bad, &text).unwrap();
    let line = text
        .lines()
        .position(|l| l.starts_with("spacing_m:"))
        .unwrap()
        + 1;
    let assert = runner()
        .arg(&bad)
        .arg("--out")
        .arg(dir.path())
        .assert()
        .code(2);
    let stderr = String::from_utf8(assert.get_output().stderr.clone()).unwrap();
    assert!(stderr.contains("spacing_m"), "{stderr}");
    assert!(
        stderr.contains(&format!(":{line}:")),
        "line {line} not in: {stderr}"
    );
    // No output file for rejected input.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn unknown_override_and_bad_cli_exit_2() {
    let exp = common::experiment("smoke_2d.yaml");
    let assert = runner()
        .arg(&exp)
        .args(["--set", "time.endd_s=1"])
        .assert()
        .code(2);
    let stderr = String::from_utf8(assert.get_output().stderr.clone()).unwrap();
    assert!(stderr.contains("time.endd_s"), "{stderr}");
    runner()
        .arg(&exp)
        .args(["--threads", "zero"])
        .assert()
        .code(2);
    runner().arg("missing.yaml").assert().code(2);
}

#[test]
fn blow_up_exits_3_and_says_so_in_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let exp = common::experiment("smoke_2d.yaml");
    // A speed limit the falling column exceeds within a few steps stands in for a blow-up.
    let assert = runner()
        .arg(&exp)
        .arg("--out")
        .arg(dir.path())
        .args(["--set", "stop.max_speed_m_s=0.05"])
        .assert()
        .code(3);
    let stdout = String::from_utf8(assert.get_output().stdout.clone()).unwrap();
    let run = read_run(&PathBuf::from(stdout.lines().last().unwrap())).unwrap();
    let summary = run.summary.unwrap();
    assert_eq!(summary.outcome, "failed");
    assert!(
        summary.reason.contains("max_speed_m_s"),
        "{}",
        summary.reason
    );
    assert_eq!(run.metadata["outcome"]["status"], "failed");
    assert!(
        !run.states.is_empty(),
        "checkpoints written before the failure are kept"
    );
}

/// The outside reader (Python `mcap` + `mcap-protobuf-support`) decodes every message of a real
/// run. Needs MPS_PYTHON, which tools/test.sh sets to the python of the venv it creates.
#[test]
#[ignore = "needs the Python venv; tools/test.sh runs it"]
fn python_reader_decodes_a_real_run() {
    let python = common::python();
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve("smoke_2d.yaml", &[]);
    let result = common::run_in(&resolved, dir.path(), 2);
    let out = std::process::Command::new(python)
        .arg(common::root().join("tools/check_mcap.py"))
        .arg(&result.path)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{text}");
    eprintln!("{text}");
}

#[test]
fn bench_reports_throughput_and_a_breakdown_that_adds_up() {
    let exp = common::experiment("smoke_2d.yaml");
    let assert = runner()
        .arg("bench")
        .arg(&exp)
        .args(["--threads", "2", "--set", "time.end_s=0.05"])
        .assert()
        .success();
    let stdout = String::from_utf8(assert.get_output().stdout.clone()).unwrap();
    assert!(stdout.contains("246 particles"), "{stdout}");
    assert!(stdout.contains("particle-steps/s"), "{stdout}");
    // The seven stages account for the whole wall time.
    let shares: Vec<f64> = stdout
        .lines()
        .filter_map(|l| l.trim_end().strip_suffix('%'))
        .map(|l| l.rsplit(' ').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(shares.len(), 7, "{stdout}");
    let total: f64 = shares.iter().sum();
    assert!(
        (total - 100.0).abs() < 0.5,
        "shares add to {total}: {stdout}"
    );
    assert!(shares.iter().all(|s| *s >= 0.0), "{stdout}");
    runner()
        .arg("bench")
        .arg(common::experiment("l_flow_sweep.yaml"))
        .assert()
        .code(2);
}
