//! `runner verify --trend DIR` on synthetic sweeps written through the Recorder.
use assert_cmd::Command;
use mps_runner::proto::mps::v1::Summary;
use mps_runner::record::{Outcome, Recorder, RunHeader};
use mps_runner::verify::trend::{TrendOptions, trend};
use std::path::Path;

/// A finished run file whose manifest has the given yield stress and stress-gradient flag
/// and whose summary has the given L-flow value.
fn fake_run(dir: &Path, n: usize, yield_pa: f64, gradient: bool, l_flow_m: Option<f64>) {
    let canonical = format!(
        r#"{{"dimension":2,"fluid":{{"model":"bingham","stress_gradient_term":{gradient},"yield_stress_pa":{yield_pa}}},"name":"l_flow_{n}","scene":{{"kind":"l_flow"}},"output":{{"checkpoint_interval_s":{}}}}}"#,
        0.1 + n as f64
    );
    let hash = format!("{n:064x}");
    let header = RunHeader {
        manifest_source: &canonical,
        overrides: &[],
        canonical: &canonical,
        experiment_sha256: &hash,
        name: "l_flow",
        default_preset: None,
        preset_revision: None,
        threads: 1,
    };
    let rec = Recorder::create(&dir.join(format!("l_flow-{n}.mcap")), &header).unwrap();
    let summary = Summary {
        metrics: l_flow_m
            .map(|v| ("l_flow_value_m".to_string(), v))
            .into_iter()
            .collect(),
        ..Summary::default()
    };
    rec.finish(0, &summary, &Outcome::Completed).unwrap();
}

fn cli(dir: &Path) -> (i32, String) {
    let out = Command::cargo_bin("runner")
        .unwrap()
        .args(["verify", "--trend"])
        .arg(dir)
        .output()
        .unwrap();
    (
        out.status.code().unwrap(),
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr),
    )
}

#[test]
fn a_falling_trend_passes_and_the_exponent_is_fitted() {
    let dir = tempfile::tempdir().unwrap();
    let mut n = 0;
    for gradient in [false, true] {
        // L = 0.5 tau^(-1/3) (with / without the gradient term: another prefactor).
        let a = if gradient { 0.45 } else { 0.5 };
        for tau in [20.0, 40.0, 80.0, 160.0] {
            n += 1;
            fake_run(
                dir.path(),
                n,
                tau,
                gradient,
                Some(a * f64::powf(tau, -1.0 / 3.0)),
            );
        }
        // The Newtonian end of the sweep: in the order check, not in the fit.
        n += 1;
        fake_run(dir.path(), n, 0.0, gradient, Some(0.7));
    }
    // Not a usable point: no metric.
    fake_run(dir.path(), 99, 10.0, false, None);
    let report = trend(dir.path(), &TrendOptions::default()).unwrap();
    assert!(report.passed(), "{report}");
    assert_eq!(
        report.groups.len(),
        2,
        "grouped by stress_gradient_term only"
    );
    for g in &report.groups {
        assert_eq!(g.points.len(), 5);
        let fit = g.fit.unwrap();
        assert_eq!(fit.points, 4);
        // Exact power-law data: exponent and prefactor come back to log/least-squares
        // round-off (of order 1e-15); the group's prefactor tells the groups apart.
        assert!((fit.b + 1.0 / 3.0).abs() < 1e-9, "{fit:?}");
        let gradient = g.key.iter().any(|(_, v)| v == "true");
        let a = if gradient { 0.45 } else { 0.5 };
        assert!((fit.a / a - 1.0).abs() < 1e-9, "{fit:?}");
        assert!(fit.r2 > 0.999_999);
    }
    assert_eq!(report.skipped.len(), 1);
    let (code, text) = cli(dir.path());
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("group fluid.stress_gradient_term=true"),
        "{text}"
    );
    assert!(text.contains("^-0.3333"), "{text}");
    assert!(text.contains("trend ok"), "{text}");
}

#[test]
fn a_rise_fails_naming_the_pair() {
    let dir = tempfile::tempdir().unwrap();
    for (n, (tau, l)) in [(20.0, 0.30), (40.0, 0.25), (80.0, 0.26), (160.0, 0.2)]
        .into_iter()
        .enumerate()
    {
        fake_run(dir.path(), n, tau, true, Some(l));
    }
    let report = trend(dir.path(), &TrendOptions::default()).unwrap();
    assert!(!report.passed());
    let (code, text) = cli(dir.path());
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("FAILED: fluid.yield_stress_pa = 80 gives l_flow_value_m = 0.26, not below 0.25 at fluid.yield_stress_pa = 40"),
        "{text}"
    );
    assert!(text.contains("trend FAILED"), "{text}");
}

#[test]
fn one_point_or_no_runs_cannot_be_checked() {
    let dir = tempfile::tempdir().unwrap();
    let (code, text) = cli(dir.path());
    assert_eq!(code, 2, "{text}");
    fake_run(dir.path(), 1, 20.0, true, Some(0.3));
    let (code, text) = cli(dir.path());
    assert_eq!(code, 1, "{text}");
    assert!(text.contains("fewer than two values"), "{text}");
}

/// A finished run file with the given yield stress and summary metrics (an L-B box sweep
/// point).
fn fake_lb_run(dir: &Path, n: usize, yield_pa: f64, metrics: &[(&str, f64)]) {
    let canonical = format!(
        r#"{{"dimension":3,"fluid":{{"model":"bi_viscosity","yield_stress_pa":{yield_pa}}},"name":"lb_{n}","scene":{{"kind":"lb_box"}}}}"#
    );
    let hash = format!("{n:064x}");
    let header = RunHeader {
        manifest_source: &canonical,
        overrides: &[],
        canonical: &canonical,
        experiment_sha256: &hash,
        name: "lb",
        default_preset: None,
        preset_revision: None,
        threads: 1,
    };
    let rec = Recorder::create(&dir.join(format!("lb-{n}.mcap")), &header).unwrap();
    let summary = Summary {
        metrics: metrics.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        ..Summary::default()
    };
    rec.finish(0, &summary, &Outcome::Completed).unwrap();
}

/// `--y` repeats: every metric named must fall (the L-B box's filling distance and filling
/// rate); one that rises fails the check even when the other falls.
#[test]
fn several_metrics_must_all_fall() {
    let run = |rate_falls: bool| {
        let dir = tempfile::tempdir().unwrap();
        for (n, tau) in [20.0, 40.0, 80.0].into_iter().enumerate() {
            let rate = if rate_falls {
                1.0 - tau / 100.0
            } else {
                tau / 100.0
            };
            fake_lb_run(
                dir.path(),
                n,
                tau,
                &[("filling_distance_m", 1.0 / tau), ("filling_rate", rate)],
            );
        }
        let out = Command::cargo_bin("runner")
            .unwrap()
            .args(["verify", "--trend"])
            .arg(dir.path())
            .args(["--y", "filling_distance_m", "--y", "filling_rate"])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).to_string();
        (out.status.code().unwrap(), text)
    };
    let (code, text) = run(true);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("filling_distance_m") && text.contains("filling_rate"),
        "{text}"
    );
    let (code, text) = run(false);
    assert_eq!(code, 1, "{text}");
    // Without --y the test's own metric is checked: the filling distance.
    let dir = tempfile::tempdir().unwrap();
    for (n, tau) in [20.0, 40.0].into_iter().enumerate() {
        fake_lb_run(dir.path(), n, tau, &[("filling_distance_m", 1.0 / tau)]);
    }
    let (code, text) = cli(dir.path());
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("filling_distance_m"), "{text}");
}
