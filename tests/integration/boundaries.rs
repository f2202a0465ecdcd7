//! The `boundaries:` section end to end (`experiments/pour_2d.yaml`): an inlet pours its
//! volume and stops, a rod follows its keyframe path, tags survive checkpoints and replay
//! (from a checkpoint taken mid-pour), and 1 and 2 threads give the same bits.
use crate::common;
use mps_runner::experiment::build_scene;
use mps_runner::mps::ParticleKind;
use mps_runner::record::read_run;

/// 120 particles (0.012 m^2 at l0 = 10 mm) in layers of 6 at 1 m/s: the pour lasts 0.2 s,
/// so the checkpoint at 0.1 s is taken mid-pour.
const SETS: &[&str] = &[
    "boundaries.inlets.0.volume_m3=0.012",
    "time.end_s=0.5",
    "output.checkpoint_interval_s=0.05",
];

#[test]
fn the_inlet_pours_its_volume_and_stops_and_no_concrete_is_lost() {
    let resolved = common::resolve("pour_2d.yaml", SETS);
    let m = &resolved.manifest;
    let l0 = m.spacing_m;
    let initial = build_scene::<2>(m).particles;
    let initial_fluid = initial.fluid_count();
    // The column 0.2 m x 0.1 m at 10 mm; neither the rock nor the rod overlaps it.
    assert_eq!(initial_fluid, 200);
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    let run = read_run(&result.path).unwrap();
    // Fluid and ghosts (fluid that left the domain) per checkpoint: the count only grows,
    // by whole inlet particles, and stops at round(V / l0^2).
    let poured_target = (0.012 / (l0 * l0)).round() as usize;
    let mut previous = initial_fluid;
    for state in &run.states {
        let fluid = state.kind.iter().filter(|&&k| k == 0 || k == 3).count();
        assert!(
            fluid >= previous,
            "the fluid count fell at t = {}",
            state.time_s
        );
        assert!(fluid <= initial_fluid + poured_target);
        previous = fluid;
    }
    let last = run.states.last().unwrap();
    let fluid_and_ghosts = last.kind.iter().filter(|&&k| k == 0 || k == 3).count();
    let poured = fluid_and_ghosts - initial_fluid;
    // V / l0^2 = 0.012 / 1e-4 = 120 particles, exactly the volume.
    assert_eq!(poured, 120);
    assert_eq!(poured_target, 120);
    // The inlet had stopped well before the end: the last two checkpoints agree.
    let before = &run.states[run.states.len() - 2];
    assert_eq!(before.kind.len(), last.kind.len());
    // Every poured particle carries the inlet's tag, the initial fluid its region's tag.
    let metrics = &result.summary.metrics;
    let ghosts_of = |tag: u32| {
        (0..last.kind.len())
            .filter(|&i| last.kind[i] == 3 && last.tag[i] == tag)
            .count() as f64
    };
    assert_eq!(
        metrics["fluid_count_tag_2"] + ghosts_of(2),
        poured_target as f64
    );
    // The upper layer of the column, y in (0.05, 0.1): 20 x 5 particles.
    assert_eq!(metrics["fluid_count_tag_1"] + ghosts_of(1), 100.0);
    assert_eq!(metrics["fluid_count_tag_0"] + ghosts_of(0), 100.0);
}

#[test]
fn the_rod_follows_its_keyframe_path() {
    // A checkpoint at (about) every step: dt is 1 ms (dt_max; the inlet's 1 m/s allows 2 ms).
    let resolved = common::resolve(
        "pour_2d.yaml",
        &["time.end_s=1.2", "output.checkpoint_interval_s=0.001"],
    );
    let m = &resolved.manifest;
    let scene = build_scene::<2>(m);
    let rod = scene.bodies.last().expect("the rod").clone();
    assert!(
        rod.end - rod.first >= 2 * 20,
        "two columns of wall particles, 200 mm high"
    );
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    let run = read_run(&result.path).unwrap();
    assert!(run.states.len() > 1000);
    let mut deepest = 0.0f64;
    for state in &run.states {
        let offset = rod.path.offset_m(state.time_s);
        // Read off the recorded particles, not the path.
        let shift = state.position_m[2 * rod.first + 1] - scene.particles.position_m[rod.first][1];
        deepest = deepest.min(shift);
        for i in rod.first..rod.end {
            for a in 0..2 {
                let expected = scene.particles.position_m[i][a] + offset[a];
                let got = state.position_m[2 * i + a];
                // Offsets added step by step over 1200 steps: round-off of order 1e-14 m.
                assert!(
                    (got - expected).abs() < 1e-9,
                    "t = {}: rod particle {i} axis {a} at {got}, path says {expected}",
                    state.time_s
                );
            }
            assert_eq!(state.kind[i], ParticleKind::Wall as u32);
        }
    }
    // It went all the way down (120 mm at t = 0.5 s and again at 1.2 s), to the same
    // round-off as above.
    assert!((deepest + 0.12).abs() < 1e-9, "{deepest}");
    let last = run.states.last().unwrap();
    let end = last.position_m[2 * rod.first + 1] - scene.particles.position_m[rod.first][1];
    assert!(
        (end + 0.12).abs() < 1e-9,
        "at 1.2 s the rod is down again: {end}"
    );
}

#[test]
fn a_mid_pour_checkpoint_replays_bit_for_bit_and_threads_agree() {
    let resolved = common::resolve("pour_2d.yaml", SETS);
    let dir = tempfile::tempdir().unwrap();
    let one = common::run_in(&resolved, &dir.path().join("one"), 1);
    let two = common::run_in(&resolved, &dir.path().join("two"), 2);
    assert_eq!(one.summary.checkpoints, two.summary.checkpoints);
    let run = read_run(&two.path).unwrap();
    // Checkpoint 2 (t = 0.1 s) is mid-pour: tags stored, inlet progress between 0 and all.
    let mid = &run.states[2];
    // The first step at or after 0.1 s, dt = 1 ms.
    assert!(
        (0.1..0.1 + 1e-3 + 1e-12).contains(&mid.time_s),
        "{}",
        mid.time_s
    );
    assert_eq!(mid.tag.len(), mid.kind.len(), "tags are recorded");
    assert_eq!(
        mid.extra_scalars.len(),
        1,
        "the inlet's progress is recorded"
    );
    assert!(mid.extra_scalars[0] > 0.0 && mid.extra_scalars[0] < 120.0);
    common::assert_replays(&two.path, Some(2));
    common::assert_replays(&two.path, None);
}

#[test]
fn bad_boundaries_are_refused_naming_the_field() {
    // Each would otherwise allocate without bound, never end, or cross the fluid in a step.
    let cases: &[(&str, &str)] = &[
        (
            "boundaries.inlets.0.diameter_m=200",
            "boundaries.inlets.0: must lie inside the domain box",
        ),
        (
            "boundaries.inlets.0.diameter_m=1e300",
            "boundaries.inlets.0: must lie inside the domain box",
        ),
        (
            "boundaries.inlets.0.diameter_m=0.001",
            "holds no lattice point",
        ),
        (
            "boundaries.inlets.0.direction.0=nope",
            "boundaries.inlets.0.direction.0",
        ),
        (
            "boundaries.inlets.0.volume_m3=0",
            "boundaries.inlets.0.volume_m3: must be > 0",
        ),
        (
            "boundaries.inlets.0.clearance=2",
            "boundaries.inlets.0.clearance: must be in [0.5, 1]",
        ),
        (
            "boundaries.obstacles.0.centre_m.0=1e5",
            "boundaries.obstacles.0: must lie inside the domain box",
        ),
        (
            "boundaries.obstacles.0.radius_m=1e12",
            "boundaries.obstacles.0: must lie inside the domain box",
        ),
        (
            "boundaries.obstacles.0.radius_m=-1",
            "boundaries.obstacles.0.radius_m",
        ),
        (
            "boundaries.bodies.0.keyframes.1.offset_m.1=-1e5",
            "boundaries.bodies.0.keyframes.1.offset_m: puts the body outside the domain",
        ),
        (
            "boundaries.bodies.0.keyframes.1.time_s=0.21",
            "boundaries.bodies.0.keyframes.1: the body moves at",
        ),
        (
            "boundaries.bodies.0.keyframes.1.time_s=0.1",
            "keyframe times must increase strictly",
        ),
        (
            "boundaries.bodies.0.repeat_s=0.5",
            "boundaries.bodies.0.repeat_s",
        ),
        (
            "boundaries.bodies.0.slip_length_m=-0.01",
            "boundaries.bodies.0.slip_length_m: must be a finite number >= 0",
        ),
        ("boundaries.tags.0.tag=70000", "boundaries.tags.0.tag"),
        (
            "boundaries.inlets.1.tag=1",
            "is a list of 1 item: `1` is not an index; the only one is 0",
        ),
    ];
    let text = std::fs::read_to_string(common::experiment("pour_2d.yaml")).unwrap();
    for (set, fragment) in cases {
        let err = mps_runner::experiment::from_str(&text, "pour_2d.yaml", &[set.to_string()])
            .unwrap_err()
            .to_string();
        assert!(err.contains(fragment), "--set {set}: {err}");
    }
}

#[test]
fn an_obstacle_on_the_tank_floor_adds_no_particle_twice() {
    // A box sunk into the floor: its wall cells there are the tank's own.
    let resolved = common::resolve("pour_2d.yaml", &[]);
    let mut m = resolved.manifest.clone();
    m.boundaries.obstacles = vec![mps_runner::manifest::shape::ShapeSpec::Box {
        min_m: vec![0.25, -0.05],
        max_m: vec![0.35, 0.04],
    }];
    let p = build_scene::<2>(&m).particles;
    let mut seen = std::collections::BTreeSet::new();
    for x in &p.position_m {
        assert!(
            seen.insert((x[0].to_bits(), x[1].to_bits())),
            "two particles at {x:?}"
        );
    }
}

/// A stop rule waits until every inlet has poured: a front that stalls mid-pour (at 80 Pa the
/// 20 mm half L-box's first splash ran out along the channel and stood still while the pour
/// went on, and its rest rule stopped the run at 6 s with 9.6 of 13 L poured) is not the
/// material at rest. Here a rule that holds at every checkpoint (any change below 1e9 m) would
/// stop the 0.2 s pour at its first checkpoint after 0.02 s; it waits for the last particle,
/// and says so. A file written under the rules as they were (stopped mid-pour) still replays.
#[test]
fn a_stop_rule_waits_for_the_pour_and_files_stopped_mid_pour_still_verify() {
    use mps_runner::record::{Outcome, Recorder};
    use mps_runner::run::{
        LoopControl, LoopStart, POURED, run_header, solver_config, time_loop, time_ns,
        write_file_records,
    };
    let mut sets = SETS.to_vec();
    sets.extend([
        "output.checkpoint_interval_s=0.02",
        "stop.rest_metric=front_position_m",
        "stop.rest_metric_change=1e9",
        "stop.rest_after_s=0.02",
    ]);
    let resolved = common::resolve("pour_2d.yaml", &sets);
    let m = &resolved.manifest;
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 1);
    let stop = &result.summary.stop;
    assert!(
        stop.starts_with("settled") && stop.ends_with(POURED),
        "{stop}"
    );
    let run = read_run(&result.path).unwrap();
    let last = run.states.last().unwrap();
    let poured = last.kind.iter().filter(|&&k| k == 0 || k == 3).count() - 200;
    assert_eq!(poured, 120, "the whole pour");
    // The pour lasts 0.2 s (the test above): stopped at the first checkpoint after it.
    let t = result.summary.metrics["stop_time_s"];
    assert!((0.2..0.25).contains(&t), "stopped at {t} s");
    common::assert_replays(&result.path, None);

    // The same run under the rules as they were: stopped at 0.04 s, mid-pour, without the
    // mark; its replay takes the rules it was written under.
    let scene = build_scene::<2>(m);
    let mut solver = mps_runner::mps::Solver::new(solver_config(m, &scene), scene.particles);
    let path = dir.path().join("before.mcap");
    let mut recorder = Recorder::create(&path, &run_header(&resolved, 1)).unwrap();
    write_file_records(m, &mut recorder).unwrap();
    let control = LoopControl {
        rules_during_pour: true,
        ..LoopControl::default()
    };
    let end = time_loop(
        m,
        &resolved.hash_hex,
        &mut solver,
        LoopStart::default(),
        &control,
        &mut recorder,
    )
    .unwrap();
    assert_eq!(end.outcome, Outcome::Completed);
    assert!(
        end.stop_reason.starts_with("settled") && !end.stop_reason.ends_with(POURED),
        "{}",
        end.stop_reason
    );
    assert!(
        solver.pouring() && solver.time_s < 0.05,
        "t = {}",
        solver.time_s
    );
    recorder
        .finish(time_ns(solver.time_s), &end.summary, &end.outcome)
        .unwrap();
    common::assert_replays(&path, None);
}
