//! Mirror symmetry planes (`scene.quarter_domain` of the slump): a quarter of the slump
//! between the planes x = 0 and y = 0, where every particle near a plane meets the mirror
//! images of its neighbours, is the whole slump cut in four: the same particles on the same
//! paths to round-off, under the standard scheme and the quiet 3D set.
use crate::common;
use mps_runner::record::read_run;
use std::collections::HashMap;

/// Fluid particles of a run as (initial position's bits) -> final position.
fn fluid_paths(path: &std::path::Path) -> HashMap<[u64; 3], [f64; 3]> {
    let run = read_run(path).unwrap();
    let (first, last) = (run.states.first().unwrap(), run.states.last().unwrap());
    assert_eq!(first.kind.len(), last.kind.len());
    (0..first.kind.len())
        .filter(|&i| first.kind[i] == 0)
        .map(|i| {
            let start = &first.position_m[3 * i..3 * i + 3];
            let end = &last.position_m[3 * i..3 * i + 3];
            (
                std::array::from_fn(|a| start[a].to_bits()),
                std::array::from_fn(|a| end[a]),
            )
        })
        .collect()
}

/// Runs `experiment` at the 25 mm-class sets `sets` with both solves at 1e-12 (so that two
/// runs of different linear systems agree to round-off, not to the default 1e-6), two
/// threads, asserting that it completed; the folder is returned to keep the file.
fn run_tight(
    experiment: &str,
    sets: &[&str],
) -> (
    std::path::PathBuf,
    std::collections::BTreeMap<String, f64>,
    tempfile::TempDir,
) {
    let mut all = vec!["mps.ppe_tolerance=1e-12", "mps.viscosity_tolerance=1e-12"];
    all.extend_from_slice(sets);
    let resolved = common::resolve(experiment, &all);
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    (result.path, result.summary.metrics, dir)
}

/// The whole 25 mm slump (360 concrete particles) and its quarter (90), cone lifted, to
/// `end_s`, with the extra manifest settings `sets`: every particle of the quarter ends where
/// the particle of the whole that started in the same cell does. A missing or wrongly
/// reflected image (a plane that acted as a free surface, a wall, or a velocity not mirrored)
/// moves the particles next to the plane by millimetres within a few steps. Both solves run
/// to 1e-12: the whole and the quarter are different linear systems, so at the default 1e-6
/// their iterative answers differ by the tolerance (1e-10 m in positions after 0.1 s), not
/// by round-off.
fn quarter_follows_the_whole(end_s: f64, sets: &[&str]) {
    let run = |quarter: bool| {
        let end = format!("time.end_s={end_s}");
        let mut all = vec!["spacing_m=0.025", &end];
        all.extend_from_slice(sets);
        if quarter {
            all.push("scene.quarter_domain=true");
        }
        let (path, metrics, dir) = run_tight("slump_3d.yaml", &all);
        (fluid_paths(&path), metrics, dir)
    };
    let (whole, whole_metrics, _keep_whole) = run(false);
    let (quarter, quarter_metrics, _keep_quarter) = run(true);
    assert_eq!(whole.len(), 360);
    assert_eq!(4 * quarter.len(), whole.len());
    let mut worst = 0.0f64;
    for (start, end) in &quarter {
        let start_m = start.map(f64::from_bits);
        assert!(start_m[0] > 0.0 && start_m[1] > 0.0, "{start_m:?}");
        let twin = whole
            .get(start)
            .unwrap_or_else(|| panic!("no particle of the whole started at {start_m:?}"));
        for a in 0..3 {
            worst = worst.max((end[a] - twin[a]).abs());
        }
    }
    // 1e-10 m: 4e-9 spacings, far below any effect of a plane that is not a mirror, above
    // the round-off of the two sums' orders.
    assert!(
        worst < 1e-10,
        "{sets:?}: quarter and whole apart by {worst} m"
    );
    // The metrics are the whole slump's: the spread from the quarter's two octants, the
    // count on the plate times four.
    for name in [
        "spread_diameter_m",
        "centre_height_m",
        "fluid_on_plate_count",
    ] {
        let (q, w) = (quarter_metrics[name], whole_metrics[name]);
        assert!(
            (q - w).abs() <= 1e-10 * w.abs(),
            "{name}: quarter {q}, whole {w}"
        );
    }
}

/// MEASURED: 3.2e-13 m apart at 0.3 s.
#[test]
fn quarter_slump_is_the_whole_under_the_standard_scheme() {
    quarter_follows_the_whole(0.3, &[]);
}

/// To 0.1 s: the quiet set's thresholds (the pair stabilisation's distance, wall contact)
/// turn round-off into 1e-7 m by 0.15 s, for the whole run against itself with g changed in
/// its 13th digit as much as against the quarter. MEASURED: 2.7e-14 m apart at 0.1 s.
#[test]
fn quarter_slump_is_the_whole_under_the_quiet_set() {
    quarter_follows_the_whole(0.1, &common::QUIET_3D);
}

/// The yield solve's strain-rate rows hold mirror images too (an image's velocity reflected
/// in E u and its adjoint): to 0.1 s under the quiet 3D set, the yield flags and the first
/// shell's strain rate. MEASURED: 3.6e-15 m apart at 0.1 s (1.0e-4 m when E u takes an image's
/// velocity unreflected).
#[test]
fn quarter_slump_is_the_whole_under_the_yield_solve() {
    let yield_flags = [
        "fluid.stress_gradient_term=false",
        "mps.wall_surface_no_slip=true",
        "mps.yield_penalty_pa_s=1000",
        "mps.strain_rate_radius=1.5",
    ];
    quarter_follows_the_whole(0.1, &[&common::QUIET_3D[..], &yield_flags].concat());
}

/// A quarter run replays bit for bit on one thread from a two-thread run's checkpoint: the
/// images' order in the lists is fixed (plane bits, then index) whatever the threads.
#[test]
fn quarter_slump_replays_on_one_thread() {
    let resolved = common::resolve(
        "slump_3d.yaml",
        &[
            "spacing_m=0.025",
            "time.end_s=0.2",
            "output.checkpoint_interval_s=0.05",
            "scene.quarter_domain=true",
        ],
    );
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    common::assert_replays(&result.path, None);
    common::assert_replays(&result.path, Some(2));
}

/// The exact and the adjoint projections have no mirror images: the manifest says so,
/// naming the field and the projection.
#[test]
fn quarter_with_the_exact_projection_is_refused() {
    for projection in ["exact_projection", "adjoint_projection"] {
        let err = mps_runner::experiment::load(
            &common::experiment("slump_3d.yaml"),
            &[
                "scene.quarter_domain=true".to_string(),
                "mps.pressure_scheme=incremental".to_string(),
                format!("mps.{projection}=true"),
            ],
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("scene.quarter_domain") && err.contains(projection),
            "{err}"
        );
    }
}

/// Fluid positions of a run's last checkpoint.
fn last_fluid(path: &std::path::Path) -> Vec<[f64; 3]> {
    let run = read_run(path).unwrap();
    let last = run.states.last().unwrap();
    (0..last.kind.len())
        .filter(|&i| last.kind[i] == 0)
        .map(|i| std::array::from_fn(|a| last.position_m[3 * i + a]))
        .collect()
}

/// The L-B box's half (`scene.half_domain`: y >= W/2 beside the plane through the inlet's
/// axis and the spheres' centres) is the whole box cut in two, while it pours: the inlet's
/// half-disc pours half the particles, each of them on the path of its twin in the whole.
/// Poured particles have no starting cell to pair them by, so each particle of the half is
/// paired with the nearest of the whole's. 25 mm (W is 8 spacings), a 0.1 m inlet (12
/// points, 6 in the half) at 1 m/s, to 0.25 s: the jet falls 0.45 m beside the plane (every
/// particle of the half next to it meets images) and hits the floor at 0.22 s. Both solves
/// to 1e-12: in free fall the two runs stay 1.3e-12 m apart (the solves' tolerance, as in
/// the quarter slump); the impact then amplifies any difference about 30-fold in 0.03 s and
/// then 100-fold every 0.1 s (a round-off twin of the whole, g changed in its 13th digit,
/// too), so a longer run compares chaos, not the plane.
#[test]
fn half_lb_box_is_the_whole_under_the_standard_scheme() {
    let run = |half: bool| {
        let mut all = vec![
            "spacing_m=0.025",
            "scene.inlet_diameter_m=0.1",
            "time.end_s=0.25",
        ];
        if half {
            all.push("scene.half_domain=true");
        }
        let (path, metrics, dir) = run_tight("lb_box_3d.yaml", &all);
        (last_fluid(&path), metrics, dir)
    };
    let (whole, whole_metrics, _keep_whole) = run(false);
    let (half, half_metrics, _keep_half) = run(true);
    let plane_m = 0.1;
    assert_eq!(half.len(), 60);
    assert_eq!(2 * half.len(), whole.len());
    let whole_side: Vec<&[f64; 3]> = whole.iter().filter(|x| x[1] > plane_m).collect();
    assert_eq!(whole_side.len(), half.len());
    let mut worst = 0.0f64;
    for x in &half {
        assert!(x[1] > plane_m, "{x:?} crossed the plane");
        let nearest = whole_side
            .iter()
            .map(|y| (0..3).map(|a| (x[a] - y[a]).abs()).fold(0.0, f64::max))
            .fold(f64::INFINITY, f64::min);
        worst = worst.max(nearest);
    }
    // MEASURED: 2.8e-11 m; with the neighbour lists' images taken out (a mutation: the plane
    // then acts as a free surface) 12.8 mm.
    assert!(worst < 1e-9, "half and whole apart by {worst} m");
    for name in ["poured_volume_m3", "surface_height_x50_m"] {
        let (h, w) = (half_metrics[name], whole_metrics[name]);
        assert!(
            (h - w).abs() <= 1e-9 * w.abs(),
            "{name}: half {h}, whole {w}"
        );
    }
}

/// Spheres off the plane need a mirrored twin, W an even number of spacings, and the
/// exact projection has no mirror images: the manifest says so, naming the field.
#[test]
fn half_lb_box_needs_a_symmetric_box() {
    let load = |path: &std::path::Path, sets: &[&str]| {
        let mut all: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        all.push("scene.half_domain=true".into());
        mps_runner::experiment::load(path, &all)
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    load(&common::experiment("lb_box_3d.yaml"), &[]).unwrap();
    let odd = load(&common::experiment("lb_box_3d.yaml"), &["spacing_m=0.008"]).unwrap_err();
    assert!(
        odd.contains("scene.half_domain") && odd.contains("25"),
        "{odd}"
    );
    let exact = load(
        &common::experiment("lb_box_3d.yaml"),
        &[
            "mps.pressure_scheme=incremental",
            "mps.exact_projection=true",
        ],
    )
    .unwrap_err();
    assert!(
        exact.contains("scene.half_domain") && exact.contains("exact_projection"),
        "{exact}"
    );
    // The first sphere moved off the plane (80 mm spheres, so that one fits beside it),
    // alone and then with its twin.
    let text = std::fs::read_to_string(common::experiment("lb_box_3d.yaml")).unwrap();
    let first = "- [0.325, 0.1, 0.075]";
    assert!(text.contains(first));
    let dir = tempfile::tempdir().unwrap();
    let with = |spheres: &str| {
        let path = dir.path().join("lb.yaml");
        std::fs::write(&path, text.replace(first, spheres)).unwrap();
        load(&path, &["scene.sphere_diameter_m=0.08"])
    };
    let lone = with("- [0.325, 0.06, 0.075]").unwrap_err();
    assert!(
        lone.contains("scene.sphere_centres_m.0") && lone.contains("0.14"),
        "{lone}"
    );
    with("- [0.325, 0.06, 0.075]\n    - [0.325, 0.14, 0.075]").unwrap();
}
