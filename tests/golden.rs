//! Golden checksums: the final checkpoint hash of a small run per test kind (the first four
//! pinned before the test modules were moved, issue "One module per workability test"). A
//! refactor must keep them; a value is re-minted only when a change is meant to alter the
//! simulation, and the commit that does so says why. Each case runs on 1, 2, 3 and 8 threads
//! (docs/design.md section 6: the split of the work never depends on the pool size).
mod common;

/// (experiment file, overrides, final checkpoint SHA-256).
const CASES: &[(&str, &[&str], &str)] = &[
    (
        "smoke_2d.yaml",
        &[],
        "04276690291f5b707b6f7fc93fc615c458e4c46184f0fa74082d90a4bc9068a6",
    ),
    // The dam break at 20 mm, multigrid PPE, 0.3 s (the surge has hit the far wall).
    (
        "dam_break_2d.yaml",
        &["spacing_m=0.02", "time.end_s=0.3"],
        "0ccd2f4052b5fdb89e286845aec58b7d894ba197837e5a9e69aeb65e81624812",
    ),
    // A coarse L-flow (Bingham, eq. 8 term on, dt = 1e-4 s), 0.3 s into the flow.
    (
        "l_flow_2d.yaml",
        // pi_c pinned at the value this checksum was minted with (the manifest's default
        // became 0.1 by the stop-rule study; the code path is the same).
        &[
            "spacing_m=0.02",
            "time.end_s=0.3",
            "fluid.critical_strain_rate_1_s=0.05",
        ],
        "5bc6656d49b7ae989702a51d703501585e66cd52a926d71495bcfac1094d8cd7",
    ),
    // The slump at 25 mm: the cone rises 50 mm by 0.25 s and then stays (both phases of the
    // moving wall), 0.4 s.
    (
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "time.end_s=0.4",
            "scene.lift_height_m=0.05",
        ],
        "daa36bfa0be0ffdd2a13fb8e360f55013264c3f6bed557d7ae898b13676d6ba6",
    ),
    // Added after the move (one small run per test kind): the column collapse at 20 mm and
    // the boundary pieces (inlet, obstacle, rod, tags) of pour_2d, 0.3 s.
    (
        "column_collapse_2d.yaml",
        &["spacing_m=0.02", "time.end_s=0.3"],
        "02897624e6b7923872f8b896a49f2aa9ff3b49fbd2ff46039820bc63a4b9c112",
    ),
    (
        "pour_2d.yaml",
        &["time.end_s=0.3"],
        "004caff60a089d3384395443fe23429b5e9cd41da4a1f87e5723dd4a2e39fad8",
    ),
    // The rodding test (added with it): 10 mm, the rod going down from t = 0, 0.5 s (its
    // tip 125 mm into the concrete).
    (
        "rodding_2d.yaml",
        &[
            "spacing_m=0.01",
            "scene.rod_width_m=0.02",
            "scene.start_s=0",
            "time.end_s=0.5",
        ],
        "229c50a4c632f01bca87dea98dcf3ae044536f8b3eebf674dc006dcc5b42b09f",
    ),
    // The L-B box (added with it): 25 mm, 0.5 s of the pour (80 particles in, the first of
    // them spread on the floor of the vertical part). Re-minted when the default spheres
    // moved 200 mm apart (their wall particles are part of the state).
    (
        "lb_box_3d.yaml",
        &["spacing_m=0.025", "time.end_s=0.5"],
        "d7cca934b611c330aecb7d3878abcc81011b91a02abd909fd50eb1972e22713f",
    ),
];

fn final_hash(experiment: &str, sets: &[&str], threads: usize) -> String {
    let resolved = common::resolve(experiment, sets);
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), threads);
    result
        .summary
        .checkpoints
        .last()
        .expect("a run logs its final state")
        .state_sha256
        .clone()
}

#[test]
fn golden_final_checkpoint_hashes_on_1_2_3_and_8_threads() {
    let mut wrong = Vec::new();
    for (experiment, sets, golden) in CASES {
        for threads in [1, 2, 3, 8] {
            let got = final_hash(experiment, sets, threads);
            if got != *golden {
                wrong.push(format!(
                    "{experiment} {sets:?} on {threads} thread(s): {got}, golden {golden}"
                ));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "state bits changed:\n{}",
        wrong.join("\n")
    );
}

#[test]
fn the_3d_wall_collision_constants_are_manifest_fields_with_todays_values() {
    let (experiment, sets, golden) = CASES[3];
    // Written out, today's 3D values (0.8 l0, a second pass) give the pinned bits (another
    // experiment hash, the same state).
    let mut explicit = sets.to_vec();
    explicit.extend([
        "mps.wall_collision_distance=0.8",
        "mps.wall_collision_second_pass=true",
    ]);
    assert_eq!(final_hash(experiment, &explicit, 2), golden);
    // Without the second pass the run differs: the field reaches the solver.
    let mut off = sets.to_vec();
    off.push("mps.wall_collision_second_pass=false");
    assert_ne!(final_hash(experiment, &off, 2), golden);
}

/// docs/design.md section 6: no value the runner records or compares may come from a std
/// transcendental function or `powi` (they call the platform's math library, whose last bits
/// differ between platforms and versions): the library uses `libm` or plain products.
#[test]
fn the_library_calls_no_std_transcendental_function() {
    const STD_MATH: &[&str] = &[
        ".powf(",
        ".powi(",
        ".exp(",
        ".exp2(",
        ".exp_m1(",
        ".ln(",
        ".ln_1p(",
        ".log(",
        ".log2(",
        ".log10(",
        ".sin(",
        ".cos(",
        ".tan(",
        ".sin_cos(",
        ".asin(",
        ".acos(",
        ".atan(",
        ".atan2(",
        ".sinh(",
        ".cosh(",
        ".tanh(",
        ".cbrt(",
        ".hypot(",
    ];
    let mut found = Vec::new();
    let mut files = vec![common::root().join("src")];
    while let Some(path) = files.pop() {
        if path.is_dir() {
            files.extend(std::fs::read_dir(&path).unwrap().map(|e| e.unwrap().path()));
            continue;
        }
        if path.extension().is_none_or(|e| e != "rs") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            for f in STD_MATH.iter().filter(|f| code.contains(*f)) {
                found.push(format!("{}:{}: {f}", path.display(), n + 1));
            }
        }
    }
    assert!(found.is_empty(), "use libm instead:\n{}", found.join("\n"));
}
