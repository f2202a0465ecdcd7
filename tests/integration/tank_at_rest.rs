//! The tank at rest (`experiments/tank_at_rest.yaml`, issue "A quiet core"): its summary
//! measures how far a scheme is from the exact rest state (no motion, p = rho g (H - y), a
//! surface that stays), and tells the quiet scheme from the standard one. 20 mm, 1.5 s.
use crate::common;
use mps_runner::record::read_run;

const SPACING_M: f64 = 0.02;

/// The shipped file at 20 mm for 1.5 s under the 2D default (`mps.preset: quiet`), or under
/// `mps.preset=standard` when `standard`.
fn run(experiment: &str, standard: bool) -> (mps_runner::run::RunResult, tempfile::TempDir) {
    let mut sets = vec!["spacing_m=0.02", "time.end_s=1.5"];
    if standard {
        sets.push("mps.preset=standard");
    }
    let resolved = common::resolve(experiment, &sets);
    assert_eq!(
        resolved.manifest.mps.pressure_scheme == mps_runner::manifest::PressureSchemeName::Standard,
        standard
    );
    let dir = tempfile::tempdir().unwrap();
    (common::run_completed(&resolved, dir.path(), 2), dir)
}

#[test]
fn the_quiet_scheme_holds_the_tank_and_its_summary_says_so() {
    let (result, _dir) = run("tank_at_rest.yaml", false);
    let metrics = &result.summary.metrics;
    let fill_m = 0.3;
    // Exactly hydrostatic from the fill height: the preset's surface depth (l0/2) puts the
    // zero of pressure there (measured +7.5e-5). With p = 0 at the top row's centres instead
    // (H - l0/2), the lowest row (y = l0/2) would read l0 / (2 (H - l0/2)) low: -3.45 %.
    let offset = -0.5 * SPACING_M / (fill_m - 0.5 * SPACING_M);
    let error = metrics["bottom_pressure_error"];
    assert!(
        error.abs() < 2e-3,
        "bottom pressure error {error} (zero at the top row's centres would give {offset})"
    );
    let speed = metrics["max_speed_after_settling_m_s"];
    assert!(speed < 1e-3, "max speed after 0.5 s: {speed} m/s");
    let rise = metrics["surface_height_change_m"];
    assert!(rise.abs() < 0.5 * SPACING_M, "surface moved {rise} m");
    // The summary's values are those of the final state, computed here independently.
    let run = read_run(&result.path).unwrap();
    let last = run.states.last().unwrap();
    let fluid: Vec<usize> = (0..last.kind.len())
        .filter(|&i| last.kind[i] == 0)
        .collect();
    let mut heights: Vec<f64> = fluid.iter().map(|&i| last.position_m[2 * i + 1]).collect();
    heights.sort_by(f64::total_cmp);
    let p99 = heights[(0.99 * heights.len() as f64).ceil() as usize - 1];
    assert_eq!(metrics["surface_height_m"], p99);
    // 15 rows of 50: the 743rd height at t = 0 is in the top row, at 0.29 m.
    assert!((metrics["surface_height_m"] - rise - 0.29).abs() < 1e-12);
    let lowest = heights[0];
    let bottom: Vec<usize> = fluid
        .iter()
        .copied()
        .filter(|&i| last.position_m[2 * i + 1] < lowest + 0.5 * SPACING_M)
        .collect();
    assert_eq!(bottom.len(), 50, "one full row at the floor");
    let mean_p = bottom.iter().map(|&i| last.pressure_pa[i]).sum::<f64>() / 50.0;
    assert!((metrics["bottom_pressure_pa"] / mean_p - 1.0).abs() < 1e-12);
    // The largest kinetic energy is that of the first steps, not the end's.
    assert!(metrics["kinetic_energy_max_j"] > metrics["fluid_kinetic_energy_j"]);
    assert_eq!(metrics["non_flowing_fraction"], 0.0, "water always flows");
}

#[test]
fn the_standard_scheme_stirs_the_same_tank() {
    // The noise the quiet scheme removes (docs/validation.md, "Holding still"): above 1 cm/s after
    // settling, and the bottom reads high.
    let (result, _dir) = run("tank_at_rest.yaml", true);
    let metrics = &result.summary.metrics;
    let speed = metrics["max_speed_after_settling_m_s"];
    assert!(speed > 1e-2, "max speed after 0.5 s: {speed} m/s");
}

#[test]
fn a_bingham_layer_below_its_yield_stress_stays_rigid() {
    let (result, _dir) = run("tank_at_rest_bingham.yaml", false);
    let metrics = &result.summary.metrics;
    let speed = metrics["max_speed_after_settling_m_s"];
    assert!(speed < 1e-3, "max speed after 0.5 s: {speed} m/s");
    let share = metrics["non_flowing_fraction"];
    assert!(share >= 0.99, "non-flowing share {share}");
}

#[test]
fn a_fill_above_the_tank_or_a_negative_settling_time_is_refused_naming_the_field() {
    for (set, field) in [
        (
            "scene.fill_height_m=0.5",
            "scene.fill_height_m: must be <= scene.tank_height_m",
        ),
        (
            "scene.settling_time_s=-1",
            "scene.settling_time_s: must be >= 0",
        ),
    ] {
        let sets = vec![set.to_string()];
        let error = mps_runner::experiment::load(&common::experiment("tank_at_rest.yaml"), &sets)
            .expect_err(set)
            .to_string();
        assert!(error.contains(field), "{set}: {error}");
    }
}
