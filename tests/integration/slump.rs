//! Slump-flow test, 3D (seed 004): scene geometry, the cone lift, determinism in 3D and a
//! coarse check of the final spread against the closed form of Roussel & Coussot (2005).
use crate::common;
use mps_runner::experiment::build_scene;
use mps_runner::experiment::slump;
use mps_runner::mps::ParticleKind;
use mps_runner::record::{Outcome, read_run};

const FRUSTUM_L: f64 = 5.497_787_143_782_138; // pi 0.3 (0.1^2 + 0.1 0.05 + 0.05^2) / 3, in L

fn spec() -> slump::Slump {
    slump::Slump {
        cone_height_m: 0.3,
        cone_bottom_diameter_m: 0.2,
        cone_top_diameter_m: 0.1,
        plate_size_m: 0.9,
        ..slump::Slump::default()
    }
}

#[test]
fn frustum_volume_is_5_5_litres() {
    assert!((spec().cone_volume_m3() * 1e3 - FRUSTUM_L).abs() < 1e-12);
}

#[test]
fn two_dimensions_are_rejected() {
    // Told before what the 2D default preset would clash with (eq. 8's term in this file).
    let err = mps_runner::experiment::load(
        &common::experiment("slump_3d.yaml"),
        &["dimension=2".to_string()],
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("dimension") && err.contains("3D"), "{err}");
}

#[test]
fn scene_geometry() {
    for (l0, layers) in [(0.025, 3usize), (0.016, 3)] {
        let sets = [format!("spacing_m={l0}")];
        let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
        let m = common::resolve("slump_3d.yaml", &sets).manifest;
        let scene = build_scene::<3>(&m);
        let p = &scene.particles;
        // Fluid volume: cell-centre count times l0^3. The count of lattice points in a smooth
        // body errs by a fraction of the surface cells: allow 0.1 l0 times the frustum's
        // surface (0.18 m^2), i.e. 0.46 L at 25 mm and 0.29 L at 16 mm.
        let n = p.fluid_count();
        let volume_l = n as f64 * l0 * l0 * l0 * 1e3;
        let tolerance_l = 0.1 * l0 * 0.183 * 1e3;
        assert!(
            (volume_l - FRUSTUM_L).abs() < tolerance_l,
            "l0 = {l0}: {n} particles, {volume_l} L"
        );
        // Every fluid particle is inside the frustum, and symmetric under x -> -x.
        let cone = scene
            .bodies
            .first()
            .map(|w| w.first..w.end)
            .expect("a cone");
        for i in 0..p.len() {
            let x = p.position_m[i];
            let r = (x[0] * x[0] + x[1] * x[1]).sqrt();
            match p.kind[i] {
                ParticleKind::Fluid => {
                    assert!(r < spec().radius_at_m(x[2]) && x[2] > 0.0 && x[2] < 0.3 + l0);
                    assert!(!cone.contains(&i));
                }
                _ if cone.contains(&i) => {
                    // The cone shell: outside the frustum, within the wall + dummy layers.
                    let rz = spec().radius_at_m(x[2]);
                    assert!(r >= rz && r < rz + layers as f64 * l0, "{x:?}");
                }
                _ => assert!(x[2] < 0.0, "plate particle above the plate: {x:?}"),
            }
        }
        let mirrored = p
            .position_m
            .iter()
            .zip(&p.kind)
            .filter(|(x, k)| **k == ParticleKind::Fluid && x[0] < 0.0)
            .count();
        assert_eq!(2 * mirrored, n);
        // The plate: 3 layers under the whole square plate.
        let side = (0.45 / l0).round() as usize * 2;
        assert_eq!(p.len() - cone.len() - n, side * side * layers);
        eprintln!(
            "l0 = {l0}: {n} fluid ({volume_l:.3} L), {} cone, {} particles",
            cone.len(),
            p.len()
        );
    }
    // Removed at once: no cone.
    let m = common::resolve(
        "slump_3d.yaml",
        &["spacing_m=0.025", "scene.lift_speed_m_s=0"],
    )
    .manifest;
    assert!(build_scene::<3>(&m).bodies.is_empty());
}

/// The cone holds the fluid until the lift starts, then rises at the lift speed; a replay
/// from a checkpoint in the middle of the lift gives the same bits.
#[test]
fn cone_lifts_at_its_speed_and_holds_the_fluid_before() {
    let resolved = common::resolve(
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "scene.lift_start_s=0.1",
            "scene.lift_speed_m_s=0.25",
            "time.end_s=0.2",
            "output.checkpoint_interval_s=0.05",
        ],
    );
    let m = &resolved.manifest;
    let start = build_scene::<3>(m);
    let cone = start.bodies.first().map(|w| w.first..w.end).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_in(&resolved, dir.path(), 2);
    assert_eq!(
        result.outcome,
        Outcome::Completed,
        "{}",
        result.summary.reason
    );
    let run = read_run(&result.path).unwrap();
    assert_eq!(run.states.len(), 5);
    for s in &run.states {
        let rise = (0.25 * (s.time_s - 0.1)).max(0.0);
        for i in cone.clone() {
            let z = s.position_m[3 * i + 2];
            let z0 = start.particles.position_m[i][2];
            assert!(
                (z - z0 - rise).abs() < 1e-9,
                "t = {}: {z} vs {z0} + {rise}",
                s.time_s
            );
        }
        if s.time_s <= 0.1 {
            // Still in the cone (within the collision reach of its wall).
            for i in 0..s.kind.len() {
                if s.kind[i] == 0 {
                    let x = &s.position_m[3 * i..3 * i + 3];
                    let r = (x[0] * x[0] + x[1] * x[1]).sqrt();
                    assert!(r < spec().radius_at_m(x[2]) + 0.5 * m.spacing_m, "{x:?}");
                    assert!(x[2] > -0.5 * m.spacing_m);
                }
            }
        }
    }
    common::assert_replays(&result.path, Some(2));
}

#[test]
fn one_and_two_threads_give_identical_bits_in_3d() {
    let hashes = |threads: usize| {
        let resolved = common::resolve(
            "slump_3d.yaml",
            &[
                "spacing_m=0.025",
                "time.end_s=0.05",
                "output.checkpoint_interval_s=0.01",
            ],
        );
        let dir = tempfile::tempdir().unwrap();
        let result = common::run_in(&resolved, dir.path(), threads);
        assert_eq!(result.outcome, Outcome::Completed);
        let hashes: Vec<String> = result
            .summary
            .checkpoints
            .iter()
            .map(|c| c.state_sha256.clone())
            .collect();
        (hashes, result.summary.metrics)
    };
    let (a, metrics_a) = hashes(1);
    let (b, metrics_b) = hashes(2);
    assert_eq!(a.len(), 6);
    assert_eq!(a, b);
    assert_eq!(metrics_a, metrics_b);
}

/// Coarse physics check at l0 = 25 mm (360 concrete particles; the cone removed at once,
/// dt_max = 2 ms). The run stops by the rest rule `slump_3d.yaml` uses (the spread radius
/// moved less than 0.5 mm over a 0.5 s checkpoint interval, from 2 s on), so the verdict does
/// not depend on a chosen end time. At this spacing the closed-form pancake is 1.5 particles
/// thick at its centre: the resolution is the particle, and every tolerance below is a
/// fraction of a spacing. MEASURED: this build's values (stopped at 3.0 s, 6 s of CPU).
#[test]
fn coarse_spread_matches_the_closed_form() {
    let l0 = 0.025;
    let resolved = common::resolve(
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "scene.lift_speed_m_s=0",
            "time.dt_max_s=0.002",
            "output.diagnostics_interval_s=0.1",
        ],
    );
    let m = &resolved.manifest;
    assert_eq!(m.stop.rest_metric.as_deref(), Some("spread_radius_mean_m"));
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    let s = &result.summary.metrics;
    // It settled by the rule, well before the 12 s cap. MEASURED: at 3.0 s.
    let stop = s["stop_time_s"];
    assert!(stop < m.time.end_s - 1.0, "never settled: ran to {stop} s");
    assert_eq!(s["ghost_particle_count"], 0.0);
    // The closed form for the simulated volume (360 l0^3 = 5.625 L): R = 0.3027 m.
    let closed = s["closed_form_radius_m"];
    assert!((closed - 0.3027).abs() < 5e-4, "{closed}");
    // The radius is the furthest centre + l0/2, so the edge is placed to within half a
    // spacing. MEASURED: 0.2983 m at 3.0 s, -4.4 mm = -0.18 l0 (-1.5 %).
    let radius = s["spread_radius_mean_m"];
    assert!(
        (radius - closed).abs() < 0.5 * l0,
        "spread radius {radius} vs {closed} (stopped at {stop} s)"
    );

    // The spread metrics recomputed from the recorded final state, independently of the
    // metric code: octants by angle (atan2), the furthest concrete particle on the plate
    // (z up to the cone height) per octant plus l0/2; the diameter is twice their mean.
    let run = read_run(&result.path).unwrap();
    let last = run.states.last().unwrap();
    let mut furthest = [0.0f64; 8];
    for i in (0..last.kind.len()).filter(|&i| last.kind[i] == 0) {
        let x = &last.position_m[3 * i..3 * i + 3];
        if x[2] > 0.3 {
            continue;
        }
        let angle = x[1].atan2(x[0]).rem_euclid(std::f64::consts::TAU);
        let octant = ((angle / std::f64::consts::FRAC_PI_4) as usize).min(7);
        furthest[octant] = furthest[octant].max(x[0].hypot(x[1]) + 0.5 * l0);
    }
    let mean = furthest.iter().sum::<f64>() / 8.0;
    let max = furthest.iter().copied().fold(0.0, f64::max);
    let min = furthest.iter().copied().fold(f64::INFINITY, f64::min);
    for (name, mine, metric) in [
        ("diameter", 2.0 * mean, s["spread_diameter_m"]),
        ("max", max, s["spread_radius_max_m"]),
        ("min", min, s["spread_radius_min_m"]),
    ] {
        // Only the rounding of hypot against sqrt(x^2 + y^2) differs.
        assert!((mine - metric).abs() < 1e-12, "{name}: {mine} vs {metric}");
    }
    // Round: the octants' radii differ by at most a spacing (a lattice bias or a lost octant
    // would show). MEASURED: 0.2905 to 0.3060 m, 0.62 l0.
    assert!(
        s["spread_radius_max_m"] - s["spread_radius_min_m"] <= l0 + 1e-12,
        "octant radii {} to {}",
        s["spread_radius_min_m"],
        s["spread_radius_max_m"]
    );

    // Settled: the kinetic energy is under a thousandth of its peak. MEASURED: 2.2e-5.
    let peak = run
        .diagnostics
        .iter()
        .map(|d| d.kinetic_energy_j)
        .fold(0.0, f64::max);
    let end = run.diagnostics.last().unwrap().kinetic_energy_j;
    assert!(end < 1e-3 * peak, "{end} J of {peak} J");

    // `runner profile`'s h(r) every spacing from the axis to R against the closed form with
    // the measured R: the top is the highest centre + l0/2, so it moves in steps of a whole
    // layer (l0) and is placed to within half a spacing; a quarter spacing more for the
    // surface particles' offsets from their layer. MEASURED: worst 13.3 mm = 0.53 l0 (the
    // two-particle centre, 41-43 mm against 33-36 mm).
    let state = run.states.last().unwrap();
    let particles = mps_runner::checkpoint::particles_from_message::<3>(state).unwrap();
    let mps_runner::experiment::SceneSpec::Slump(scene) = &m.scene else {
        panic!("not a slump run")
    };
    let profile = scene.profile(m, &particles, state.time_s).unwrap();
    let mut worst = 0.0f64;
    for q in &profile.points {
        worst = worst.max((q.measured_m - q.closed_form_m).abs());
    }
    assert!(worst < 0.75 * l0, "h(r) off by {worst} m");
    eprintln!(
        "stopped at {stop} s: spread radius {radius:.4} m (closed form {closed:.4} m), octants {:.4}..{:.4} m, worst h(r) {worst:.4} m, energy {end:.3e} of {peak:.3e} J",
        s["spread_radius_min_m"], s["spread_radius_max_m"]
    );
}

/// t500 (EN 12350-8): the time from the start of the lift until the spread diameter reaches
/// 500 mm, interpolated between the diagnostics rows around the crossing. Checked against the
/// recorded diagnostics, and replayed bit for bit from a checkpoint after the crossing (the
/// replay must rebuild it from the logged rows) and from the start.
#[test]
fn t500_is_the_first_crossing_of_500_mm_and_replays() {
    let resolved = common::resolve(
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "scene.lift_speed_m_s=0",
            "time.dt_max_s=0.002",
            "output.diagnostics_interval_s=0.05",
            "output.checkpoint_interval_s=0.5",
        ],
    );
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    let t500 = result.summary.metrics["t500_s"];
    let run = mps_runner::record::read_run(&result.path).unwrap();
    let rows: Vec<(f64, f64)> = run
        .diagnostics
        .iter()
        .map(|d| (d.time_s, d.metrics["spread_diameter_m"]))
        .collect();
    let k = rows
        .iter()
        .position(|r| r.1 >= 0.5)
        .expect("the spread reaches 500 mm");
    assert!(k > 0, "already 500 mm at the start: {rows:?}");
    let ((t0, d0), (t1, d1)) = (rows[k - 1], rows[k]);
    let expected = t0 + (0.5 - d0) / (d1 - d0) * (t1 - t0);
    eprintln!("t500 = {t500} s (rows {t0} s: {d0} m, {t1} s: {d1} m)");
    assert_eq!(t500.to_bits(), expected.to_bits(), "{t500} vs {expected}");
    assert!(t0 < t500 && t500 <= t1);
    // A collapse from a 300 mm cone reaches 500 mm within a second or two, not at once.
    assert!(t500 > 0.05 && t500 < 3.0, "{t500}");
    // Replays from a checkpoint after the crossing and from the start give the same summary.
    let after = run
        .states
        .iter()
        .position(|s| s.time_s > t1)
        .expect("a checkpoint after the crossing");
    assert!(after + 1 < run.states.len());
    common::assert_replays(&result.path, Some(after as u32));
    common::assert_replays(&result.path, None);
}

/// Particle shifting (`mps.particle_shifting`, issue "A quiet core") keeps the incremental
/// scheme's spreading layer from packing. Without pair stabilisation the scheme presses a
/// thin 3D layer together until the collision model stops the pairs at half a spacing; the
/// shifting moves a flowing particle away from its closest neighbours. 16 mm, to 3 s (the
/// spreading), the quarter beside the cone's mirror planes, two threads, then replayed on one
/// thread from the checkpoint at 2 s. MEASURED (the whole cone, `runner` with the same
/// settings): 79 % of the concrete has a neighbour closer than 0.8 l0 without shifting (1st
/// percentile 0.50 l0), 0.1 % with it (0.86 l0); the quarter (commit after f10b2dc): 254 of
/// 336 (76 %) without, none with it.
#[test]
fn particle_shifting_keeps_the_quiet_slump_from_packing() {
    let l0: f64 = 0.016;
    let resolved = common::resolve(
        "slump_3d.yaml",
        &[
            "time.end_s=3",
            "output.checkpoint_interval_s=1",
            "scene.quarter_domain=true",
            "mps.pressure_scheme=incremental",
            "mps.wall_support=0.95",
            "mps.surface_depth=0.5",
            "mps.corrected_strain_rate=true",
            "mps.particle_shifting=40",
        ],
    );
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    let run = read_run(&result.path).unwrap();
    let last = run.states.last().unwrap();
    let fluid: Vec<[f64; 3]> = (0..last.kind.len())
        .filter(|&i| last.kind[i] == ParticleKind::Fluid as u32)
        .map(|i| std::array::from_fn(|k| last.position_m[3 * i + k]))
        .collect();
    let packed = fluid
        .iter()
        .enumerate()
        .filter(|(i, a)| {
            fluid.iter().enumerate().any(|(j, b)| {
                j != *i && (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>() < (0.8 * l0).powi(2)
            })
        })
        .count();
    let share = packed as f64 / fluid.len() as f64;
    eprintln!(
        "{packed} of {} concrete particles closer than 0.8 l0 to another",
        fluid.len()
    );
    assert!(share < 0.05, "{:.1} % packed", 100.0 * share);
    common::assert_replays(&result.path, Some(2));
}
