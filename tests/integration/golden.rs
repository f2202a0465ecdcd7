//! Golden checksums: the final checkpoint hash of a small run per test kind (the first four
//! pinned before the test modules were moved, issue "One module per workability test"). A
//! refactor must keep them; a value is re-minted only when a change is meant to alter the
//! simulation, and the commit that does so says why. Each case runs on 1, 2, 3 and 8 threads
//! (docs/design.md section 6: the split of the work never depends on the pool size).
//! All eight re-minted when the default `mps.ppe_tolerance` became 1e-6 (the error budget in
//! docs/performance.md); with `mps.ppe_tolerance=1e-9` set, the runs give the values before.
//! When `mps.preset: quiet` became the 2D default, the 2D cases of the standard scheme (smoke,
//! dam break, heap, pour) took `mps.preset=standard`, with which they give their values
//! before; the L-flow and the rodding write it in their files.
//! When the preset's revision 2 gave the quiet yield set the walls' own faces
//! (`mps.wall_face_normals`), the two preset cases took `mps.wall_face_normals=false`, with
//! which they give their values before (so the revision changed that field alone), and the
//! same two runs under revision 2 were minted: the 2D heap as shipped and the 3D slump.
//! When revision 3 gave the 2D quiet set the multigrid PPE (`mps.ppe_preconditioner:
//! multigrid`, over-correction 1.5), the 2D cases of revisions 1 and 2 and the 2D default's
//! smoke run took `mps.ppe_preconditioner=jacobi`, with which they give their values before,
//! and the heap and the smoke run under revision 3 were minted (the 3D slump is the same
//! under revisions 2 and 3).
//! When revision 5 gave the quiet 3D yield set the increment's regularisation
//! (`mps.increment_regularisation: 5` at `mps.regularisation_radius: 1.45`), the two 3D
//! slump cases of revisions 1 and 2 took `mps.increment_regularisation=0`, with which they
//! give their values before, and the slump under revision 5 was minted.
//! When revision 6 gave the quiet 3D yield set local penalties and Anderson acceleration
//! (`mps.yield_penalty_local: true`, `mps.yield_anderson_depth: 5`,
//! `mps.yield_max_iterations: 200`), the three 3D slump cases before it took the three fields'
//! defaults, with which they give their values before, and the slump under revision 6 was
//! minted.
use crate::common;

/// (experiment file, overrides, final checkpoint SHA-256).
const CASES: &[(&str, &[&str], &str)] = &[
    (
        "smoke_2d.yaml",
        &["mps.preset=standard"],
        "af61f1ea4f72e0367e87ddcf62fbfdcda5cfcec6a1810d93b4fe00da5c069a11",
    ),
    // The dam break at 20 mm, multigrid PPE, 0.3 s (the surge has hit the far wall).
    // Re-minted when the manifest took the multigrid over-correction 1.5 (with
    // mps.multigrid_over_correction=1 the run gives d7f9cb69...).
    (
        "dam_break_2d.yaml",
        &["spacing_m=0.02", "time.end_s=0.3", "mps.preset=standard"],
        "3d0ef6f92ba7d846bb8880f3fee0332b033b118198d77ec1868a1d7a084793bc",
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
        "633c01d3cb353ab97b0ec5e8e1f8379d880bab9030bf772bc116779797c9aab6",
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
        "514c0b8390d0a2be5e386023a062b01e75d9a4d2e8ed62a5cb39ab55822d37fa",
    ),
    // Added after the move (one small run per test kind): the column collapse at 20 mm and
    // the boundary pieces (inlet, obstacle, rod, tags) of pour_2d, 0.3 s.
    (
        "column_collapse_2d.yaml",
        &["spacing_m=0.02", "time.end_s=0.3", "mps.preset=standard"],
        "5c800b1e68d28b17d3443d3100b3b04f30257037fe75c9b163a945e6a4f9c0fc",
    ),
    (
        "pour_2d.yaml",
        &["time.end_s=0.3", "mps.preset=standard"],
        "fb5b12f2920a9049953c84a7379f52e0b7904c4802ec9dd5f39b32607f82b075",
    ),
    // The rodding test (added with it): 10 mm, the rod going down from t = 0, 0.5 s (its
    // tip 125 mm into the concrete). Re-minted when the shipped rod got its steel's slip
    // length (0.1 m); with `scene.rod_slip_length_m=null` the run gives the value before,
    // 01e7fd37.... Re-minted again when the shipped rodding took the quiet 2D scheme (the
    // standard scheme's rest circulation overturned its layers); with
    // `mps.pressure_scheme=standard` and `mps.corrected_strain_rate=false` the run gives
    // the value before, 57485a57.... Re-minted again when the shipped rodding took the PPE's
    // compressibility 1e-7 (it damps the increment's two-step mode that blew the 2.5 mm
    // rodding up); with `mps.compressibility_1_pa=4.5e-10` the run gives the value before,
    // 6fd1f240....
    (
        "rodding_2d.yaml",
        &[
            "spacing_m=0.01",
            "scene.rod_width_m=0.02",
            "scene.start_s=0",
            "time.end_s=0.5",
        ],
        "10937d333c4c759c1696c635ccb208fcf15c7f959a02f22badc1015586069890",
    ),
    // The L-B box (added with it): 25 mm, 0.5 s of the pour (80 particles in, the first of
    // them spread on the floor of the vertical part). Re-minted when the default spheres
    // moved 200 mm apart (their wall particles are part of the state), and again when the
    // manifest gave its spheres two wall layers (`mps.solid_wall_layers: 2`: concrete got
    // through a one-layer shell); with one, the value before.
    (
        "lb_box_3d.yaml",
        &["spacing_m=0.025", "time.end_s=0.5"],
        "2e603ad745262b51fc3cf23bb987738c60bb69f109c7b2890baa135d9dd9b19d",
    ),
    (
        "lb_box_3d.yaml",
        &[
            "spacing_m=0.025",
            "time.end_s=0.5",
            "mps.solid_wall_layers=1",
        ],
        "a01b4eacbd220e1dfd01032798b7f8f48823d3b7188bd8ec7da7f63cfd775ec9",
    ),
    // The quiet preset (issue "A quiet core"), pinned before it became the 2D default: the 2D
    // heap (the 2D yield set: incremental scheme, regularisation, the augmented-Lagrangian
    // rigid state; the shipped heap's default now, the set is kept to say so) and the 3D
    // slump (the 3D yield set) of the cases above.
    (
        "column_collapse_2d.yaml",
        &[
            "spacing_m=0.02",
            "time.end_s=0.3",
            "mps.preset=quiet",
            "mps.wall_face_normals=false",
            "mps.ppe_preconditioner=jacobi",
        ],
        "c94cb8b6def76836fe50de86644605632395b1c20e0ecd16016fd39cc374c261",
    ),
    (
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "time.end_s=0.4",
            "scene.lift_height_m=0.05",
            "mps.preset=quiet",
            "mps.wall_face_normals=false",
            "mps.increment_regularisation=0",
            "mps.yield_penalty_local=false",
            "mps.yield_anderson_depth=0",
            "mps.yield_max_iterations=50",
        ],
        "f3e6279cbf766c7cf7d6e3da9b62076f1dbb3e196af3c73b28ba708d8b114483",
    ),
    // The same two under the preset's revision 2 (the walls' own faces), minted with it: the
    // heap as shipped (the 2D default) and the slump under `mps.preset=quiet`.
    (
        "column_collapse_2d.yaml",
        &[
            "spacing_m=0.02",
            "time.end_s=0.3",
            "mps.ppe_preconditioner=jacobi",
        ],
        "31e5c53edf502ec079401c160a6f7142ec7b3e3d617a81fe6f26c1aef6e7c817",
    ),
    (
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "time.end_s=0.4",
            "scene.lift_height_m=0.05",
            "mps.preset=quiet",
            "mps.increment_regularisation=0",
            "mps.yield_penalty_local=false",
            "mps.yield_anderson_depth=0",
            "mps.yield_max_iterations=50",
        ],
        "acc690ddbaa93d6c58a550b114b6874020035a360f48ceddc5b913afa0e59b45",
    ),
    // The 2D default (`mps.preset: quiet` for water: incremental scheme, stabilisers,
    // regularisation, surface depth, compressibility 1e-7), minted when it became the default:
    // the smoke run as shipped then, with the Jacobi PPE of revisions 1 and 2.
    (
        "smoke_2d.yaml",
        &["mps.ppe_preconditioner=jacobi"],
        "cffad25215e00982ef5de150096e3e568c8cc3e5a19ecbf976bc5fa0fb4f5191",
    ),
    // Revision 3 (the multigrid PPE in 2D), minted with it: the heap and the smoke run as
    // shipped.
    (
        "column_collapse_2d.yaml",
        &["spacing_m=0.02", "time.end_s=0.3"],
        "64337bcc2352b73286b131f8b4c68de79278aa3d6c6b418c547ae300e80c6268",
    ),
    (
        "smoke_2d.yaml",
        &[],
        "ddd53deabfeb3113c6a3ba56b1d6f578c67598f0fd25f1bff3cddcbc77e90049",
    ),
    // Revision 5 (the increment's regularisation in the quiet 3D yield set), minted with it:
    // the 3D slump under `mps.preset=quiet`.
    (
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "time.end_s=0.4",
            "scene.lift_height_m=0.05",
            "mps.preset=quiet",
            "mps.yield_penalty_local=false",
            "mps.yield_anderson_depth=0",
            "mps.yield_max_iterations=50",
        ],
        "11717747548a13500ed22f6944114f8d166f7da2db113e814b16db40c06ef3a1",
    ),
    // Revision 6 (local penalties and Anderson acceleration in the quiet 3D yield set),
    // minted with it: the 3D slump under `mps.preset=quiet`.
    (
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "time.end_s=0.4",
            "scene.lift_height_m=0.05",
            "mps.preset=quiet",
        ],
        "919137ba63a8147cb2fc8ad2f11ab01f2a328cb59fd172fae40a8e61408d3959",
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
