//! The velocity profile of a recorded inclined layer against the Bingham closed form: for a
//! checkpoint, the fluid binned by height in rows of one spacing (count, mean along-slope
//! speed, closed form u(y) = (rho g sin theta / mu_p) ((h - h_c) y - y^2 / 2) below the plug,
//! U in it), the viscous Laplacian's answer to u = y^2/2 on the particles as they are (exact:
//! 1), the yield solve's multiplier (its shear component and its size |lambda|/sqrt(2), both
//! tau_y where the fluid yields in simple shear), each row's disorder (the spread of its
//! heights in spacings, the rms of its velocity about the row's mean, the rms of its carried
//! pressure about the row's mean: a particle-to-particle pattern), and the layer's top
//! (largest height, 99th percentile; over h - l0/2 the layer's depth). Where a disordered
//! layer (`scene.disorder`) moves faster or slower than U, this says which of the floor, the
//! viscous term, the yield term or a swollen layer it is (docs/validation.md, "A disordered
//! layer on an incline").
//! With a slipping floor (`scene.floor_slip_length_m`, 3D) the side walls hold the layer and
//! the rows are bins of the distance from the nearer side wall instead of heights.
//!
//! Usage: cargo run --release --example layer_profile -- FILE.mcap [--at T_S]
use mps_runner::experiment::SceneSpec;
use mps_runner::manifest;
use mps_runner::record::read_run;
use mps_runner::restore::manifest_of;
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let file = PathBuf::from(args.first().expect("a run file"));
    let at_s = args
        .iter()
        .position(|a| a == "--at")
        .map(|i| args[i + 1].parse::<f64>().expect("--at needs a number"))
        .unwrap_or(f64::INFINITY);
    let run = read_run(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let recorded = manifest_of(&run).unwrap_or_else(|e| panic!("{e}"));
    let resolved = manifest::from_str_as_of::<SceneSpec>(
        &recorded.source_text,
        "stored source",
        &recorded.overrides,
        recorded.default_preset,
        recorded.preset_revision,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let m = &resolved.manifest;
    let state = run
        .states
        .iter()
        .rev()
        .find(|s| s.time_s <= at_s + 1e-9)
        .expect("no checkpoint at or before --at");
    let d = state.dimension as usize;
    let l0 = m.spacing_m;
    let SceneSpec::InclinedLayer(layer) = &m.scene else {
        panic!("not an inclined layer")
    };
    // The axis across which the layer shears, and the distance from its wall: the height
    // above the floor, or with a slipping floor the distance from the nearer side wall.
    let width_m = (layer.width_m.unwrap_or(0.0) / l0).round() * l0;
    let side_held = layer.floor_slip_length_m.is_some();
    let across = if side_held { 1 } else { d - 1 };
    let from_wall = |x: &[f64]| {
        if side_held {
            x[across].min(width_m - x[across])
        } else {
            x[across]
        }
    };
    let depth_m = (layer.layer_depth_m / l0).round() * l0;
    let h = if side_held { 0.5 * width_m } else { depth_m };
    let (_, hc, plug) = layer.closed_form_speed_m_s(m, 0.0);
    let closed = |y: f64| layer.closed_form_speed_m_s(m, y).0;
    // The viscous Laplacian's response to u = y^2 / 2 (exact: 1) on this arrangement:
    // (d / (lambda n0)) sum_j w(r_ij) dy^2 over every particle within its radius, x periodic.
    let radius_m = m.mps.laplacian_radius * l0;
    let refs = match d {
        2 => mps_runner::mps::kernel::RefValues::on_lattice::<2>(
            l0,
            m.mps.number_density_radius * l0,
            radius_m,
        ),
        _ => mps_runner::mps::kernel::RefValues::on_lattice::<3>(
            l0,
            m.mps.number_density_radius * l0,
            radius_m,
        ),
    };
    let period_m = (layer.period_m / l0).round() * l0;
    let count_all = state.kind.len();
    let response = |i: usize| -> f64 {
        let xi = &state.position_m[i * d..i * d + d];
        let mut sum = 0.0;
        for j in 0..count_all {
            if j == i {
                continue;
            }
            let xj = &state.position_m[j * d..j * d + d];
            let mut dx = xj[0] - xi[0];
            dx -= (dx / period_m).round() * period_m;
            let mut r2 = dx * dx;
            for a in 1..d {
                r2 += (xj[a] - xi[a]) * (xj[a] - xi[a]);
            }
            let dy = from_wall(xj) - from_wall(xi);
            sum += mps_runner::mps::kernel::weight(r2.sqrt(), radius_m) * dy * dy;
        }
        d as f64 * sum / (refs.lambda_m2 * refs.n0_lap)
    };
    let mut heights = Vec::new();
    let rows = (2.0 * h / l0).ceil() as usize + 2;
    let (mut sum, mut count, mut ysum, mut lap) = (
        vec![0.0; rows],
        vec![0usize; rows],
        vec![0.0; rows],
        vec![0.0; rows],
    );
    // Second moments for the row's disorder: the spread of its heights and its velocity's
    // fluctuation about the row's mean (every component).
    let (mut y2sum, mut v2sum, mut vsum) =
        (vec![0.0; rows], vec![0.0; rows], vec![vec![0.0; d]; rows]);
    // The carried pressure's fluctuation about the row's mean: a pattern from particle to
    // particle that the gradient does not see.
    let (mut psum, mut p2sum) = (vec![0.0; rows], vec![0.0; rows]);
    // The yield solve's multiplier (the yield part of the deviatoric stress): its shear
    // component and its size |lambda| / sqrt(2), both tau_y where the fluid yields in simple
    // shear.
    let (mut shear, mut size) = (vec![0.0; rows], vec![0.0; rows]);
    let stress = &state.yield_stress_pa;
    for (i, &kind) in state.kind.iter().enumerate() {
        if kind != 0 {
            continue;
        }
        let y = from_wall(&state.position_m[i * d..i * d + d]);
        heights.push(state.position_m[i * d + d - 1]);
        let row = ((y / l0).floor().max(0.0) as usize).min(rows - 1);
        sum[row] += state.velocity_m_s[i * d];
        ysum[row] += y;
        y2sum[row] += y * y;
        psum[row] += state.pressure_pa[i];
        p2sum[row] += state.pressure_pa[i] * state.pressure_pa[i];
        for (sum, &v) in vsum[row]
            .iter_mut()
            .zip(&state.velocity_m_s[i * d..i * d + d])
        {
            *sum += v;
            v2sum[row] += v * v;
        }
        lap[row] += response(i);
        if stress.len() == count_all * d * d {
            let t = &stress[i * d * d..(i + 1) * d * d];
            // Across the channel the two side walls shear the layer in opposite senses.
            let sense = if side_held && state.position_m[i * d + across] > 0.5 * width_m {
                -1.0
            } else {
                1.0
            };
            shear[row] += sense * t[across];
            size[row] += t.iter().map(|v| v * v).sum::<f64>().sqrt() / std::f64::consts::SQRT_2;
        }
        count[row] += 1;
    }
    heights.sort_by(f64::total_cmp);
    let top = heights.last().copied().unwrap_or(0.0);
    let p99 = heights[(0.99 * (heights.len() - 1) as f64) as usize];
    println!(
        "# t = {:.3} s; h (or W/2) = {h} m, h_c = {hc:.4} m, U = {:.2} mm/s; top {:.4} m (+{:.2} l0 over h - l0/2), 99th percentile {:.4} m",
        state.time_s,
        1e3 * plug,
        top,
        (top - (depth_m - 0.5 * l0)) / l0,
        p99
    );
    println!(
        "row  y_mean_m  count  u_mm_s  closed_mm_s  laplacian_of_y2/2  yield_shear_pa  yield_size_pa  y_spread_l0  u_fluct_mm_s  p_fluct_pa"
    );
    for r in 0..rows {
        if count[r] == 0 {
            continue;
        }
        let n = count[r] as f64;
        let y = ysum[r] / n;
        // Standard deviations: heights in spacings, velocity (all components) in mm/s.
        let y_spread = spread(y2sum[r] / n, y * y) / l0;
        let v_fluct = spread(
            v2sum[r] / n,
            vsum[r].iter().map(|s| (s / n) * (s / n)).sum(),
        );
        let p_fluct = spread(p2sum[r] / n, (psum[r] / n) * (psum[r] / n));
        println!(
            "{r:3}  {y:.4}  {:5}  {:8.2}  {:8.2}  {:.4}  {:7.2}  {:7.2}  {:6.3}  {:7.2}  {:8.2}",
            count[r],
            1e3 * sum[r] / n,
            1e3 * closed(y),
            lap[r] / n,
            shear[r] / n,
            size[r] / n,
            y_spread,
            1e3 * v_fluct,
            p_fluct
        );
    }
}

/// The standard deviation from the mean square and the square of the mean (0 where rounding
/// makes the difference negative).
fn spread(mean_square: f64, mean_squared: f64) -> f64 {
    (mean_square - mean_squared).max(0.0).sqrt()
}
