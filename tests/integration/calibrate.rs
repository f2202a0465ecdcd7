//! `runner calibrate`: a run at a known yield stress gives an L-flow value; the calibration
//! from that value must recover the yield stress within what the resolution allows, record
//! every run it made, and reuse them when run again. The slump's closed-form first guess is
//! checked against the closed form it inverts.
use crate::common;

use std::path::Path;

/// The L-flow test with the seed's 410 particles, dt_max = 1e-3 s, the front read at 2 s
/// (no stop rule). The value taken when 90 % of the particles are non-flowing scatters by
/// about a spacing between nearby yield stresses (the share hovers near 90 % while the front
/// creeps: 0.531 m at 123.1 Pa, 0.543 m at 125 Pa, 0.519 m at 133.2 Pa), which would test
/// that scatter rather than the search; at 2 s the front still moves and falls smoothly with
/// the yield stress. About 3 s of CPU a run.
const COARSE: [&str; 3] = [
    "time.dt_max_s=1e-3",
    "time.end_s=2",
    "stop.non_flowing_fraction=null",
];
const L0_M: f64 = 0.01;

fn calibration_text(measured_m: f64, tolerance_m: f64) -> String {
    let base = common::experiment("l_flow_2d.yaml");
    let sets: Vec<String> = COARSE.iter().map(|s| format!("  - {s}\n")).collect();
    format!(
        "name: calib_test\nbase: {}\nset:\n{}measured:\n  l_flow_value_m: {measured_m}\ntolerance:\n  l_flow_value_m: {tolerance_m}\nfit:\n  fluid.yield_stress_pa: [40, 400]\npoints_per_round: 2\nmax_evaluations: 12\n",
        base.display(),
        sets.concat()
    )
}

fn calibrate(path: &Path, out: &Path) -> (Option<i32>, String, String) {
    common::runner_all(&[
        "calibrate".as_ref(),
        path.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ])
}

#[test]
fn a_known_yield_stress_is_recovered_from_its_spread() {
    let tau_pa = 125.0;
    let dir = tempfile::tempdir().unwrap();
    let mut sets: Vec<&str> = COARSE.to_vec();
    sets.push("fluid.yield_stress_pa=125");
    let known = common::run_completed(&common::resolve("l_flow_2d.yaml", &sets), dir.path(), 2);
    let measured_m = known.summary.metrics["l_flow_value_m"];

    // The front is placed to about a spacing (see below).
    let tolerance_m = L0_M;
    let path = dir.path().join("calib.yaml");
    std::fs::write(&path, calibration_text(measured_m, tolerance_m)).unwrap();
    let out = dir.path().join("runs");
    let (code, stdout, stderr) = calibrate(&path, &out);
    eprintln!("{stderr}");
    assert_eq!(code, Some(0), "{stderr}");
    let json_path = std::path::PathBuf::from(stdout.trim());
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    let fit = &record["fits"][0];
    assert_eq!(fit["converged"], true);
    let fitted = fit["fitted"]["fluid.yield_stress_pa"].as_f64().unwrap();
    // One fitted value: one stage, whose bracket holds the measured value and the fitted one.
    let stages = fit["stages"].as_array().unwrap();
    assert_eq!(stages.len(), 1);
    let b = stages[0]["bracket"].as_array().expect("a bracket");
    let (p0, m0) = (b[0][0].as_f64().unwrap(), b[0][1].as_f64().unwrap());
    let (p1, m1) = (b[1][0].as_f64().unwrap(), b[1][1].as_f64().unwrap());
    assert!(p0 <= fitted && fitted <= p1, "{b:?} {fitted}");
    assert!(m0 >= measured_m && measured_m >= m1, "{b:?} {measured_m}");
    assert_eq!(
        fit["brackets"]["fluid.yield_stress_pa"][0].as_f64(),
        Some(p0)
    );
    // As close as the resolution allows: the front at 2 s scatters by about a spacing between
    // nearby yield stresses (MEASURED: 0.385 m at 125 Pa, 0.390 m at 128.5 Pa, 0.388 m at
    // 133.2 Pa), and L ~ tau^(-s) with s >= 0.2 (MEASURED 0.23 between 111 and 144 Pa), so
    // tau is known to (l0 / L) / 0.2 of itself (13 % here).
    let allowed = tau_pa * (L0_M / measured_m) / 0.2;
    assert!(
        (fitted - tau_pa).abs() <= allowed,
        "fitted {fitted} Pa, known {tau_pa} Pa, allowed +-{allowed:.2} Pa"
    );
    // Every run is a recorded file in the folder, named by its experiment hash.
    let evaluations = stages[0]["evaluations"].as_array().unwrap();
    assert!(evaluations.len() >= 2);
    for e in evaluations {
        let file = json_path
            .parent()
            .unwrap()
            .join(e["file"].as_str().unwrap());
        let hash = e["experiment_sha256"].as_str().unwrap();
        assert!(file.exists(), "{}", file.display());
        assert!(file.to_string_lossy().contains(&hash[..12]));
        assert_eq!(e["start"], "ran");
    }
    assert!(
        json_path
            .parent()
            .unwrap()
            .join("calibration-l_flow_value_m-vs-fluid.yield_stress_pa.svg")
            .exists()
    );

    // Run again: every run is reused, the result is the same.
    let (code, _, stderr) = calibrate(&path, &out);
    assert_eq!(code, Some(0), "{stderr}");
    let again: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    assert_eq!(again["fits"][0]["fitted"], fit["fitted"]);
    for e in again["fits"][0]["stages"][0]["evaluations"]
        .as_array()
        .unwrap()
    {
        assert_eq!(e["start"], "existing", "{e}");
    }
}

/// Two values from two measurements: the yield stress from the L-flow front at 2 s and the
/// plastic viscosity from T200, the time the front takes to run 200 mm (EN 12350-10's L-box
/// time), by alternating one-value searches. About 12 runs of 2 s CPU.
#[test]
fn a_known_yield_stress_and_viscosity_are_recovered_from_front_and_t200() {
    let (tau_pa, mu_pa_s) = (125.0, 50.0);
    let dir = tempfile::tempdir().unwrap();
    let known = common::run_completed(&common::resolve("l_flow_2d.yaml", &COARSE), dir.path(), 2);
    let front_m = known.summary.metrics["l_flow_value_m"];
    let t200_s = known.summary.metrics["t200_s"];
    // The crossing is interpolated between diagnostics rows 0.02 s apart; the front scatters by
    // about a spacing, which moves T200 by about l0 / (front speed ~ 0.4 m/s) = 0.025 s.
    let tolerance_s = 0.02;
    let base = common::experiment("l_flow_2d.yaml");
    let sets: Vec<String> = COARSE.iter().map(|s| format!("  - {s}\n")).collect();
    let text = format!(
        "name: calib_two\nbase: {}\nset:\n{}measured:\n  l_flow_value_m: {front_m}\n  t200_s: {t200_s}\ntolerance:\n  l_flow_value_m: {L0_M}\n  t200_s: {tolerance_s}\nfit:\n  fluid.yield_stress_pa: [40, 400]\n  fluid.plastic_viscosity_pa_s: [5, 500]\npairs:\n  - {{fit: fluid.yield_stress_pa, from: l_flow_value_m}}\n  - {{fit: fluid.plastic_viscosity_pa_s, from: t200_s}}\nmax_evaluations: 40\n",
        base.display(),
        sets.concat()
    );
    let path = dir.path().join("calib.yaml");
    std::fs::write(&path, text).unwrap();
    let (code, stdout, stderr) = calibrate(&path, &dir.path().join("runs"));
    eprintln!("{stderr}");
    assert_eq!(code, Some(0), "{stderr}");
    let json_path = std::path::PathBuf::from(stdout.trim());
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    let fit = &record["fits"][0];
    assert_eq!(fit["converged"], true);
    let tau = fit["fitted"]["fluid.yield_stress_pa"].as_f64().unwrap();
    let mu = fit["fitted"]["fluid.plastic_viscosity_pa_s"]
        .as_f64()
        .unwrap();
    // The yield stress as in the one-value test: (l0 / L) / 0.2 of itself.
    let tau_allowed = tau_pa * (L0_M / front_m) / 0.2;
    assert!(
        (tau - tau_pa).abs() <= tau_allowed,
        "tau {tau}, allowed +-{tau_allowed:.2}"
    );
    // T200 ~ mu_p (viscous time scale): the tolerance is tolerance_s / T200 of mu, doubled for
    // what the yield stress's own error moves T200 by.
    let mu_allowed = mu_pa_s * 2.0 * tolerance_s / t200_s;
    assert!(
        (mu - mu_pa_s).abs() <= mu_allowed,
        "mu {mu}, allowed +-{mu_allowed:.2}"
    );
    // The stages alternate, the last one's bracket runs meet both measurements, and every run
    // names its two values.
    let stages = fit["stages"].as_array().unwrap();
    assert!(stages.len() >= 2);
    assert_eq!(stages[0]["parameter"], "fluid.yield_stress_pa");
    assert_eq!(stages[1]["parameter"], "fluid.plastic_viscosity_pa_s");
    let last = stages.last().unwrap();
    let bracket = last["bracket"].as_array().unwrap();
    for side in bracket {
        let p = side[0].as_f64().unwrap();
        let e = last["evaluations"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["values"][last["parameter"].as_str().unwrap()].as_f64() == Some(p))
            .expect("the bracket's run");
        assert!((e["metrics"]["l_flow_value_m"].as_f64().unwrap() - front_m).abs() <= L0_M);
        assert!((e["metrics"]["t200_s"].as_f64().unwrap() - t200_s).abs() <= tolerance_s);
        assert_eq!(e["values"].as_object().unwrap().len(), 2);
    }
    for figure in [
        "calibration-l_flow_value_m-vs-fluid.yield_stress_pa.svg",
        "calibration-t200_s-vs-fluid.plastic_viscosity_pa_s.svg",
        "calibration-t200_s-vs-fluid.plastic_viscosity_pa_s.png",
    ] {
        assert!(
            json_path.parent().unwrap().join(figure).exists(),
            "{figure}"
        );
    }
}

#[test]
fn bad_calibrations_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let good = calibration_text(0.5, 0.0025);
    for (from, to, field) in [
        ("[40, 400]", "[400, 40]", "fit.fluid.yield_stress_pa"),
        ("l_flow_value_m: 0.5\n", "heap_length_m: 0.5\n", "tolerance"),
        (
            "tolerance:\n  l_flow_value_m: 0.0025",
            "tolerance:\n  l_flow_value_m: -1",
            "tolerance.l_flow_value_m",
        ),
        (
            "points_per_round: 2",
            "points_per_round: 0",
            "points_per_round",
        ),
        (
            "points_per_round: 2",
            "point_per_round: 2",
            "point_per_round",
        ),
    ] {
        let text = good.replacen(from, to, 1);
        assert_ne!(text, good, "{from}");
        let path = dir.path().join("bad.yaml");
        std::fs::write(&path, &text).unwrap();
        let (code, _, stderr) = calibrate(&path, &dir.path().join("runs"));
        assert_eq!(code, Some(2), "{stderr}");
        assert!(stderr.contains(field), "{field}: {stderr}");
        assert!(
            !dir.path().join("runs").exists(),
            "nothing is written for bad input"
        );
    }
    // Two fitted values need `pairs`, each naming a fitted value and a measured metric once.
    let two = good
        .replacen(
            "l_flow_value_m: 0.5\n",
            "l_flow_value_m: 0.5\n  t200_s: 0.5\n",
            1,
        )
        .replacen(
            "l_flow_value_m: 0.0025\n",
            "l_flow_value_m: 0.0025\n  t200_s: 0.02\n",
            1,
        )
        .replacen(
            "[40, 400]\n",
            "[40, 400]\n  fluid.plastic_viscosity_pa_s: [5, 500]\n",
            1,
        );
    let pairs = "pairs:\n  - {fit: fluid.yield_stress_pa, from: l_flow_value_m}\n  - {fit: fluid.plastic_viscosity_pa_s, from: t200_s}\n";
    for (text, field) in [
        (two.clone(), "pairs"),
        (
            format!("{two}{}", pairs.replacen("from: t200_s", "from: t400_s", 1)),
            "pairs[1]",
        ),
        (
            format!(
                "{two}{}",
                pairs.replacen("from: t200_s", "from: l_flow_value_m", 1)
            ),
            "pairs[1]",
        ),
        (
            format!("{two}{pairs}").replacen("  t200_s: 0.02\n", "", 1),
            "tolerance",
        ),
        (
            format!("{}{pairs}", two.replacen("  t200_s: 0.5\n", "", 1)),
            "fit",
        ),
    ] {
        let path = dir.path().join("bad2.yaml");
        std::fs::write(&path, &text).unwrap();
        let (code, _, stderr) = calibrate(&path, &dir.path().join("runs"));
        assert_eq!(code, Some(2), "{text}\n{stderr}");
        assert!(stderr.contains(field), "{field}: {stderr}");
    }
    // A measured value outside what the bounds give: exit 2, named.
    let far = calibration_text(0.05, 0.0025);
    let path = dir.path().join("far.yaml");
    std::fs::write(&path, far).unwrap();
    let (code, _, stderr) = calibrate(&path, &dir.path().join("runs2"));
    eprintln!("{stderr}");
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("outside what fit.fluid.yield_stress_pa"),
        "{stderr}"
    );
}

#[test]
fn the_slump_guess_inverts_the_pancake_law() {
    let resolved = common::resolve("slump_3d.yaml", &[]);
    let m = &resolved.manifest;
    let mps_runner::experiment::SceneSpec::Slump(slump) = &m.scene else {
        panic!("slump_3d.yaml is a slump")
    };
    let volume = slump.cone_volume_m3();
    for tau in [20.0, 50.0, 120.0] {
        let r = mps_runner::experiment::slump::closed_form_radius_m(
            m.fluid.density_kg_m3(),
            m.gravity_m_s2,
            volume,
            tau,
        );
        let guess =
            mps_runner::experiment::yield_stress_guess_pa(m, "spread_diameter_m", 2.0 * r).unwrap();
        assert!((guess - tau).abs() < 1e-9 * tau, "{guess} {tau}");
    }
    // No closed form for the L-flow value: no guess (the search starts mid-bounds).
    let l_flow = common::resolve("l_flow_2d.yaml", &[]);
    assert!(
        mps_runner::experiment::yield_stress_guess_pa(&l_flow.manifest, "l_flow_value_m", 0.5)
            .is_none()
    );
}
