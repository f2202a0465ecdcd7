//! Bad input at the command line: each gets one message naming the field (or flag) and what
//! is allowed, exit code 2, and leaves no output file.
use crate::common;
use assert_cmd::Command;

/// (extra arguments after `runner experiments/smoke_2d.yaml --out DIR`, message fragment).
const CASES: &[(&[&str], &str)] = &[
    (
        &["--set", "output.diagnostics_interval_s=1e-300"],
        "output.diagnostics_interval_s: must be >= time.end_s / 1e7",
    ),
    (
        &["--set", "output.cloud_interval_s=1e-12"],
        "output.cloud_interval_s: must be >= time.end_s / 1e7",
    ),
    (
        &["--set", "output.checkpoint_interval_s=0"],
        "output.checkpoint_interval_s: must be > 0",
    ),
    (
        &["--set", "output.cloud_interval_s=1e-6"],
        "output.cloud_interval_s: must be >= the smallest time step 5e-5 s",
    ),
    (
        &["--set", "time.dt_min_s=0.01"],
        "time.dt_min_s: must be <= time.dt_max_s = 0.001, got 0.01",
    ),
    (
        &["--set", "time.dt_min_s=-1e-4"],
        "time.dt_min_s: must be > 0",
    ),
    (
        &["--set", "stop.max_ghost_particles=-1"],
        "stop.max_ghost_particles",
    ),
    (&["--set", "spacing_m=-1"], "spacing_m: must be > 0"),
    (&["--set", "spacing_m=.nan"], "spacing_m"),
    (&["--set", "dimension=4"], "dimension: must be 2 or 3"),
    (&["--set", "time.end_s=0"], "time.end_s: must be > 0"),
    (
        &["--set", "time.courant=2"],
        "time.courant: must be in (0, 1]",
    ),
    (&["--set", "time.end_s=abc"], "time.end_s"),
    (
        &["--set", "gravity_m_s2=-9.81"],
        "gravity_m_s2: must be >= 0",
    ),
    (
        &["--set", "fluid.density_kg_m3=-5"],
        "fluid.density_kg_m3: must be > 0",
    ),
    (
        &["--set", "fluid.viscosity_pa_s=-1"],
        "fluid.viscosity_pa_s: must be >= 0",
    ),
    (&["--set", "fluid.model=honey"], "honey"),
    (
        &["--set", "mps.laplacian_radius=0.5"],
        "mps.laplacian_radius",
    ),
    (
        &["--set", "mps.surface_threshold=1.5"],
        "mps.surface_threshold",
    ),
    (
        &["--set", "mps.wall_layers=0"],
        "mps.wall_layers: must be >= 1",
    ),
    (
        &["--set", "mps.collision_distance=1"],
        "mps.collision_distance",
    ),
    (
        &["--set", "mps.wall_collision_distance=2"],
        "mps.wall_collision_distance",
    ),
    (&["--set", "mps.ppe_tolerance=1"], "mps.ppe_tolerance"),
    (&["--set", "mps.ppe_preconditioner=magic"], "magic"),
    (
        &["--set", "mps.multigrid_over_correction=2"],
        "mps.multigrid_over_correction",
    ),
    (
        &["--set", "stop.max_steps=0"],
        "stop.max_steps: must be >= 1",
    ),
    (
        &["--set", "stop.rest_metric=nope"],
        "stop.rest_metric: `nope` is not a metric",
    ),
    (
        &["--set", "stop.non_flowing_fraction=0.9"],
        "needs a yield-stress fluid",
    ),
    (&["--set", "scene.kind=v_funnel"], "v_funnel"),
    (
        &["--set", "scene.column_height_m=0.04"],
        "scene.column_height_m: must be >= 2 * spacing_m",
    ),
    (
        &["--set", "scene.column_width_m=5"],
        "scene.column_width_m: must be <= scene.tank_width_m",
    ),
    (&["--set", "name=a/b"], "name: may contain only"),
    (&["--set", "nope.key=1"], "unknown key `nope`"),
    (
        &["--set", "boundaries.inlets.0.volume_m3=1"],
        "is a list of 0 items: it is empty, so no item can be set",
    ),
    (&["--set", "spacing_m"], "KEY=VALUE"),
    (&["--threads", "0"], "must be at least 1"),
    (&["--set", "spacing_m=1e-5"], "would hold about 4.4"),
    (
        &["--max-particles", "100"],
        "more than --max-particles = 100",
    ),
    (&["--threads", "x"], "expected a whole number of threads"),
    // Both aborted allocating the walls or the lattice before they were refused.
    (
        &["--set", "mps.wall_layers=100000"],
        "mps.wall_layers: must be <= 10",
    ),
    (
        &["--set", "mps.solid_wall_layers=100000"],
        "mps.solid_wall_layers: must be <= 10",
    ),
    (
        &["--set", "spacing_m=1e-12"],
        "scene.tank_width_m: must be <= 2^24 * spacing_m",
    ),
];

#[test]
fn each_bad_input_is_refused_naming_the_field_with_exit_2_and_no_file() {
    assert!(CASES.len() >= 30);
    let mut failures = Vec::new();
    for (args, fragment) in CASES {
        let out = tempfile::tempdir().unwrap();
        let result = Command::cargo_bin("runner")
            .unwrap()
            .arg(common::experiment("smoke_2d.yaml"))
            .arg("--out")
            .arg(out.path())
            .args(*args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&result.stderr);
        // The table of inputs and messages (`-- --nocapture` shows it).
        println!(
            "| `{}` | {:?} | {} |",
            args.join(" "),
            result.status.code(),
            stderr
                .lines()
                .find(|l| l.starts_with("error"))
                .unwrap_or("")
                .replace('|', "\\|")
        );
        let files = std::fs::read_dir(out.path()).unwrap().count();
        if result.status.code() != Some(2) || !stderr.contains(fragment) || files != 0 {
            failures.push(format!(
                "{args:?}: exit {:?}, {files} files, stderr: {stderr}",
                result.status.code()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn scenes_too_large_to_build_are_refused_before_anything_is_built() {
    // Each aborted or exhausted the memory (an OOM kill) before it was refused: the pour's
    // validation built its whole scene to find the domain box, the huge cone's size estimate
    // built a first coarse scene of 1e15 particles.
    let cases: [(&str, &[&str], &str); 2] = [
        (
            "pour_2d.yaml",
            &["spacing_m=1e-5", "time.dt_max_s=1e-8"],
            "the run would hold about 2.4",
        ),
        (
            "slump_3d.yaml",
            &["scene.cone_height_m=18446744073709551616"],
            "scene.cone_height_m: must be <= 2^24 * spacing_m",
        ),
    ];
    for (experiment, sets, fragment) in cases {
        let out = tempfile::tempdir().unwrap();
        let mut command = Command::cargo_bin("runner").unwrap();
        command
            .arg(common::experiment(experiment))
            .arg("--out")
            .arg(out.path())
            .timeout(std::time::Duration::from_secs(60));
        for set in sets {
            command.args(["--set", set]);
        }
        let result = command.output().unwrap();
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert_eq!(result.status.code(), Some(2), "{experiment}: {stderr}");
        assert!(stderr.contains(fragment), "{experiment}: {stderr}");
        assert_eq!(std::fs::read_dir(out.path()).unwrap().count(), 0);
    }
}

#[test]
fn too_many_threads_are_capped_with_a_warning_and_the_same_bits() {
    let out = tempfile::tempdir().unwrap();
    let run = |threads: &str| {
        Command::cargo_bin("runner")
            .unwrap()
            .arg(common::experiment("smoke_2d.yaml"))
            .args([
                "--set",
                "time.end_s=0.02",
                "--quiet",
                "--threads",
                threads,
                "--out",
            ])
            .arg(out.path())
            .output()
            .unwrap()
    };
    let capped = run("100000");
    assert_eq!(capped.status.code(), Some(0));
    assert!(
        String::from_utf8_lossy(&capped.stderr).contains("warning: --threads 100000 capped at")
    );
    let path = String::from_utf8(capped.stdout).unwrap().trim().to_string();
    let hashes = |p: &str| {
        mps_runner::record::read_run(std::path::Path::new(p))
            .unwrap()
            .summary
            .unwrap()
            .checkpoints
    };
    let capped_hashes = hashes(&path);
    std::fs::remove_file(&path).unwrap();
    let one = run("1");
    let path = String::from_utf8(one.stdout).unwrap().trim().to_string();
    assert_eq!(hashes(&path), capped_hashes);
}

#[test]
fn the_size_estimate_is_close_to_the_scene_it_replaces() {
    // (experiment, a spacing fine enough that the estimate extrapolates)
    for (experiment, spacing) in [
        ("dam_break_2d.yaml", "0.001"),
        ("l_flow_2d.yaml", "0.0008"),
        ("slump_3d.yaml", "0.005"),
        ("pour_2d.yaml", "0.002"),
    ] {
        let resolved = common::resolve(experiment, &[&format!("spacing_m={spacing}")]);
        let m = &resolved.manifest;
        let estimate = mps_runner::experiment::estimate_particles(m);
        let poured: f64 = m
            .boundaries
            .inlets
            .iter()
            .map(|i| i.volume_m3 / (m.spacing_m * m.spacing_m))
            .sum();
        let actual = if m.dimension == 3 {
            mps_runner::experiment::build_scene::<3>(m).particles.len()
        } else {
            mps_runner::experiment::build_scene::<2>(m).particles.len()
        } as f64
            + poured;
        eprintln!(
            "{experiment} at {spacing}: estimate {estimate:.0}, actual {actual:.0}, ratio {:.3}",
            estimate / actual
        );
        // A volume-and-surface fit of two coarse counts: the lattice rounding of thin parts
        // (the cone's shell) is what it misses. MEASURED: 0.996 (dam break), 1.012 (L-flow),
        // 0.909 (slump), exact below 20 000 particles (pour).
        assert!(
            (0.8..1.25).contains(&(estimate / actual)),
            "{experiment}: estimate {estimate} against {actual}"
        );
    }
}

#[test]
fn a_finished_run_cut_short_is_called_incomplete_not_verified() {
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve("smoke_2d.yaml", &["time.end_s=0.02"]);
    let path = common::run_completed(&resolved, dir.path(), 1).path;
    let cut = dir.path().join("cut.mcap");
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.pop();
    std::fs::write(&cut, &bytes).unwrap();
    let runner = |args: &[&str]| common::runner_output(args);
    let cut_s = cut.to_str().unwrap();
    let svg = dir.path().join("x.svg");
    for args in [
        vec!["verify", cut_s, "--quiet"],
        vec!["plot", cut_s, "--out", svg.to_str().unwrap()],
        vec!["snapshot", cut_s, "--out", svg.to_str().unwrap()],
        vec!["resume", cut_s],
    ] {
        let (code, stderr) = runner(&args);
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains("is incomplete"), "{args:?}: {stderr}");
    }
    assert!(!svg.exists(), "nothing drawn from half a file");
    // The file whole still verifies.
    let (code, stderr) = runner(&["verify", path.to_str().unwrap(), "--quiet"]);
    assert_eq!(code, Some(0), "{stderr}");
}
