//! Newtonian dam break against Martin & Moyce (1952) and the open MPS codes (docs/design.md
//! section 5).
use crate::common;
use mps_runner::experiment::SceneSpec;
use mps_runner::experiment::dam_break::DamBreak;
use mps_runner::record::read_run;

/// Width a of the water column (its height is 2a), as in experiments/dam_break_2d.yaml.
const A_M: f64 = 0.25;

/// Measured fronts of one source in tests/data/dam_break_front.csv: (T, Z) with
/// T = t sqrt(2g/a), Z = z/a.
fn measured(source: &str) -> Vec<(f64, f64)> {
    let text =
        std::fs::read_to_string(common::root().join("tests/data/dam_break_front.csv")).unwrap();
    text.lines()
        .filter(|l| l.split(',').next() == Some(source))
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[1].parse().unwrap(), f[2].parse().unwrap())
        })
        .collect()
}

/// Martin & Moyce (1952), a = 2.25 in, n^2 = 2.
fn martin_moyce() -> Vec<(f64, f64)> {
    measured("martin_moyce_a2.25in")
}

/// Linear interpolation of a monotone-in-x table.
fn interpolate(table: &[(f64, f64)], x: f64) -> Option<f64> {
    table
        .windows(2)
        .find(|w| w[0].0 <= x && x <= w[1].0)
        .map(|w| {
            let s = (x - w[0].0) / (w[1].0 - w[0].0);
            w[0].1 + s * (w[1].1 - w[0].1)
        })
}

/// Largest relative deviation of `curve`, delayed by `shift`, from the points `reference`
/// (infinite where the curve does not reach).
fn max_error(reference: &[(f64, f64)], curve: &[(f64, f64)], shift: f64) -> f64 {
    reference
        .iter()
        .map(|&(t, z)| match interpolate(curve, t - shift) {
            Some(zc) => ((zc - z) / z).abs(),
            None => f64::INFINITY,
        })
        .fold(0.0, f64::max)
}

/// The delay in `shifts` that brings `curve` closest to `reference`, and the error then.
fn best_shift(
    reference: &[(f64, f64)],
    curve: &[(f64, f64)],
    shifts: impl Iterator<Item = f64>,
) -> (f64, f64) {
    shifts
        .map(|s| (s, max_error(reference, curve, s)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap()
}

/// Runs the 0.25 m x 0.5 m water column at `spacing_m` up to `end_s` (2 threads) and returns
/// gravity and its front (t [s], front_position_m [m]) at every diagnostics row (every 5 ms).
fn front_history(spacing_m: f64, end_s: f64) -> (f64, Vec<(f64, f64)>) {
    front_history_with(spacing_m, end_s, &[])
}

/// [`front_history`] with more `--set`s.
fn front_history_with(spacing_m: f64, end_s: f64, more: &[&str]) -> (f64, Vec<(f64, f64)>) {
    let sets = [
        format!("spacing_m={spacing_m}"),
        format!("time.end_s={end_s}"),
        "output.diagnostics_interval_s=0.005".to_string(),
    ];
    let mut sets: Vec<&str> = sets.iter().map(|s| s.as_str()).collect();
    sets.extend_from_slice(more);
    let resolved = common::resolve("dam_break_2d.yaml", &sets);
    let m = &resolved.manifest;
    assert!(
        matches!(&m.scene, SceneSpec::DamBreak(DamBreak { column_width_m, column_height_m, .. })
        if *column_width_m == A_M && *column_height_m == 2.0 * A_M)
    );
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    let run = read_run(&result.path).unwrap();
    let front: Vec<(f64, f64)> = run
        .diagnostics
        .iter()
        .map(|d| (d.time_s, d.metrics["front_position_m"]))
        .collect();
    // The spacing divides a: the fluid is exactly the a x 2a column (at 20 mm it would be
    // 13 x 25 particles, 0.26 m wide).
    assert!(
        (front[0].1 - A_M).abs() < 1e-12,
        "front starts at {} m, not the column width",
        front[0].1
    );
    (m.gravity_m_s2, front)
}

/// No time origin to fit: at t = 0.2 s the open MPS codes MPS-Basic and PolyMPS put the
/// front of this column at 0.587-0.602 m (at 5 mm; docs/design.md section 5).
#[test]
fn front_at_fixed_time_matches_open_mps_codes() {
    // 6.25 mm (40 x 80 fluid particles, 5 s on 2 threads): the closest whole-cell spacing
    // to the codes' 5 mm that stays within the test budget (5 mm: 12 s).
    // The standard scheme, as the codes run it (the 2D default's front against the issue's
    // band: `stabilised_incremental_scheme_keeps_the_front`).
    let spacing_m = 0.00625;
    let (_, front) = front_history_with(spacing_m, 0.2, &["mps.preset=standard"]);
    let at = interpolate(&front, 0.2).expect("a diagnostics row at or after t = 0.2 s");
    // Both codes' range, widened by half a spacing each side: the front (furthest centre +
    // l0/2) is resolved to l0/2. Measured at t = 0.2 s: 5 mm 0.5949, 6.25 mm 0.5961, 10 mm
    // 0.5844, 12.5 mm 0.5879, 25 mm 0.5823 m (each inside the range widened by its l0/2).
    let (low, high) = (0.587 - 0.5 * spacing_m, 0.602 + 0.5 * spacing_m);
    eprintln!(
        "front at t = 0.2 s: {at:.4} m (open MPS codes 0.587-0.602 m; allowed {low:.4}-{high:.4})"
    );
    assert!(
        (low..=high).contains(&at),
        "front {at} m at t = 0.2 s outside {low}-{high} m"
    );
}

/// The 2D default, `mps.preset: quiet` (the incremental scheme with its stabilisers), carries
/// the column through the violent phase, where the bare incremental scheme blows up at the toe
/// at 0.06 s (docs/validation.md, "Holding still"), and keeps the front within the band the
/// issue "A quiet core" sets at 5 mm.
#[test]
fn stabilised_incremental_scheme_keeps_the_front() {
    let spacing_m = 0.005;
    // To 0.3 s: the surge is about to reach the far wall.
    let (_, front) = front_history_with(spacing_m, 0.3, &[]);
    let at = interpolate(&front, 0.2).expect("a diagnostics row at or after t = 0.2 s");
    // The open codes give 0.587-0.602 m; the issue allows 0.575-0.615 m at 5 mm. Measured
    // 0.609 m (the 2D set without the surface depth, the corrected strain rate and the
    // compressibility 1e-7: 0.603 m; the standard scheme 0.595 m).
    let (low, high) = (0.575, 0.615);
    eprintln!("incremental front at t = 0.2 s: {at:.4} m (allowed {low:.4}-{high:.4})");
    assert!(
        (low..=high).contains(&at),
        "front {at} m at t = 0.2 s outside {low}-{high} m"
    );
}

#[test]
fn surge_front_follows_martin_and_moyce() {
    // 12.5 mm: the column is 20 x 40 particles (whole cells), about 1.4 k particles in all,
    // 2 s on 2 threads to t = 0.4 s, when the front has reached the far wall (Z = 4).
    let spacing_m = 0.0125;
    let (g, front) = front_history(spacing_m, 0.4);
    let time_scale = (2.0 * g / A_M).sqrt();
    // Simulated front, dimensionless (T, Z).
    let sim: Vec<(f64, f64)> = front
        .into_iter()
        .map(|(t, z)| (t * time_scale, z / A_M))
        .collect();

    // The gate of the experiment takes time to clear, so its time origin lags the ideal
    // instantaneous release by an unknown constant: compare after the best constant shift
    // (searched in 0..0.6), and check the shift is small.
    let mm: Vec<(f64, f64)> = martin_moyce().into_iter().filter(|p| p.1 < 3.8).collect();
    let (best_shift_t, best_error) = best_shift(&mm, &sim, (0..=120).map(|k| k as f64 * 0.005));
    let raw_error = max_error(&mm, &sim, 0.0);
    eprintln!(
        "raw max error {raw_error:.3}, best shift dT = {best_shift_t:.3}, error then {best_error:.3}"
    );
    for &(t, z) in &mm {
        eprintln!(
            "T = {t:.3}: Martin & Moyce Z = {z:.3}, MPS Z = {:.3} (shifted {:.3})",
            interpolate(&sim, t).unwrap_or(f64::NAN),
            interpolate(&sim, t - best_shift_t).unwrap_or(f64::NAN)
        );
    }
    // The two experiments in the data file differ by this much after their own best shift
    // (Koshizuka & Oka against Martin & Moyce: measured 5.9 %, 6.6 % unshifted).
    let (_, scatter) = best_shift(
        &mm,
        &measured("koshizuka_oka"),
        (-60..=60).map(|k| k as f64 * 0.005),
    );
    // Tolerance: that scatter plus the front's resolution, half a spacing over the smallest
    // compared Z (2.1 % at 12.5 mm): 7.9 %. Measured at 12.5 mm: 2.0 % after dT = 0.275.
    let tolerance = scatter + 0.5 * spacing_m / (A_M * mm[0].1);
    eprintln!("experiments' scatter {scatter:.3}, tolerance {tolerance:.3}");
    assert!(
        best_error < tolerance,
        "front off by {best_error:.3} (> {tolerance:.3}) after shift {best_shift_t}"
    );
    // Plausibility bound, not a measured figure: 0.4 is 45 ms at this column's scale (22 ms
    // at Martin & Moyce's a = 2.25 in); measured 0.275 at 12.5 mm (18.5 % ahead unshifted).
    assert!(
        best_shift_t <= 0.4,
        "time shift {best_shift_t} too large to be the gate's delay"
    );

    // Surge speed, independent of the time origin: slope dZ/dT between Z = 1.5 and 3.5.
    let slope = |table: &[(f64, f64)]| {
        let inv: Vec<(f64, f64)> = table.iter().map(|&(t, z)| (z, t)).collect();
        let t_at = |z: f64| interpolate(&inv, z).unwrap();
        2.0 / (t_at(3.5) - t_at(1.5))
    };
    let sim_rising: Vec<(f64, f64)> = sim.iter().copied().take_while(|p| p.1 < 3.9).collect();
    let measured_points = martin_moyce();
    let (s_sim, s_mm) = (slope(&sim_rising), slope(&measured_points));
    // Scatter of the measured slope: the standard error of the least-squares line through
    // the Martin & Moyce points the interpolation uses (the last at Z <= 1.5 to the first
    // at Z >= 3.5), relative to its slope.
    let first = measured_points.iter().rposition(|p| p.1 <= 1.5).unwrap();
    let last = measured_points.iter().position(|p| p.1 >= 3.5).unwrap();
    let slope_scatter = relative_slope_error(&measured_points[first..=last]);
    // Tolerance: that scatter (measured 5.4 %, 4 points) plus the front's resolution, l0/2 at
    // each end over Delta Z = 2, l0/(2a) (2.5 % at 12.5 mm). Measured dZ/dT: 1.208 (5 mm),
    // 1.219 (6.25 mm), 1.183 (10 mm), 1.198 (12.5 mm), 1.141 (25 mm); Martin & Moyce 1.207.
    let tolerance = slope_scatter + spacing_m / (2.0 * A_M);
    let deviation = (s_sim - s_mm) / s_mm;
    eprintln!(
        "surge speed dZ/dT: MPS {s_sim:.3}, Martin & Moyce {s_mm:.3} ({deviation:+.3}; \
         measured scatter {slope_scatter:.3}, tolerance {tolerance:.3})"
    );
    assert!(
        deviation.abs() < tolerance,
        "surge speed {s_sim} vs {s_mm} (off by {deviation:+.3} > {tolerance:.3})"
    );
}

/// Standard error of the least-squares slope through `points` (x, y), over the slope.
fn relative_slope_error(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    let (mx, my) = (
        points.iter().map(|p| p.0).sum::<f64>() / n,
        points.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let b = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / sxx;
    let residuals: f64 = points
        .iter()
        .map(|p| (p.1 - my - b * (p.0 - mx)).powi(2))
        .sum();
    (residuals / (n - 2.0) / sxx).sqrt() / b
}

/// `scene.side_slip_length_m` (3D): the tank's side walls (every wall and dummy particle
/// outside the depth) become one body at rest whose surface slips, the same particles as the
/// no-slip tank, moved to the end in their order; without it the tank is built as before.
/// In 2D, or negative, it is refused naming the field.
#[test]
fn a_3d_tank_with_slipping_side_walls_holds_the_same_particles_with_the_sides_as_one_body() {
    use mps_runner::experiment::build_scene;
    use mps_runner::mps::ParticleKind;
    let base = [
        "dimension=3",
        "spacing_m=0.02",
        "scene.tank_width_m=0.4",
        "scene.tank_height_m=0.2",
        "scene.tank_depth_m=0.06",
        "scene.column_width_m=0.1",
        "scene.column_height_m=0.1",
    ];
    let plain = build_scene::<3>(&common::resolve("dam_break_2d.yaml", &base).manifest);
    let mut sets = base.to_vec();
    sets.push("scene.side_slip_length_m=1000");
    let slip = build_scene::<3>(&common::resolve("dam_break_2d.yaml", &sets).manifest);
    assert!(plain.bodies.is_empty());
    assert_eq!(slip.bodies.len(), 1);
    let body = &slip.bodies[0];
    assert_eq!(body.slip_length_m, Some(1000.0));
    assert_eq!(body.end, slip.particles.len());
    let p = &slip.particles;
    let beside = |i: usize| !(0.0..0.06).contains(&p.position_m[i][1]);
    for i in 0..p.len() {
        let in_body = (body.first..body.end).contains(&i);
        assert_eq!(
            in_body,
            p.kind[i] != ParticleKind::Fluid && beside(i),
            "particle {i}"
        );
    }
    // Walls on both sides, every one of them a wall or dummy, down to the floor's dummies.
    assert!((body.first..body.end).any(|i| p.position_m[i][1] < 0.0));
    assert!((body.first..body.end).any(|i| p.position_m[i][1] > 0.06));
    let key = |s: &mps_runner::experiment::Scene<3>| {
        let mut k: Vec<(Vec<u64>, ParticleKind)> = (0..s.particles.len())
            .map(|i| {
                let x = s.particles.position_m[i];
                (x.iter().map(|v| v.to_bits()).collect(), s.particles.kind[i])
            })
            .collect();
        k.sort_by(|a, b| a.0.cmp(&b.0));
        k
    };
    assert_eq!(key(&plain), key(&slip));
    for (sets, field) in [
        (
            vec!["scene.side_slip_length_m=1000"],
            "scene.side_slip_length_m: is for dimension 3 only",
        ),
        (
            vec![
                "dimension=3",
                "scene.tank_depth_m=0.1",
                "scene.side_slip_length_m=-1",
            ],
            "scene.side_slip_length_m: must be >= 0",
        ),
    ] {
        common::assert_refused("dam_break_2d.yaml", &sets, field);
    }
}
