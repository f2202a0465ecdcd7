use mps_runner::mps::*;
use mps_runner::scene::dam_break::*;
fn main() {
    let l0: f64 = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(0.02);
    let p = DamBreak {
        tank_width_m: 1.0,
        tank_height_m: 0.6,
        tank_depth_m: 0.1,
        column_width_m: 0.25,
        column_height_m: 0.5,
    };
    let s = build::<2>(&p, l0, 1, 2);
    let cfg = SolverConfig::<2> {
        spacing_m: l0,
        density_kg_m3: 1000.0,
        viscosity_pa_s: 1e-3,
        gravity_m_s2: 9.81,
        radius_n_m: 2.1 * l0,
        radius_lap_m: 3.1 * l0,
        surface_threshold: 0.97,
        relaxation_coefficient: 0.2,
        compressibility_1_pa: 0.45e-9,
        collision_distance_m: 0.5 * l0,
        collision_restitution: 0.2,
        ppe_tolerance: 1e-9,
        ppe_max_iterations: 2000,
        courant: 0.2,
        dt_max_s: 1e-3,
        max_speed_m_s: 100.0,
        domain_min_m: s.domain_min_m,
        domain_max_m: s.domain_max_m,
    };
    let n = s.particles.len();
    let mut solver = Solver::new(cfg, s.particles);
    println!(
        "n={} fluid={} refs={:?}",
        n,
        solver.particles.fluid_count(),
        solver.refs
    );
    let t0 = std::time::Instant::now();
    let scale = (2.0 * 9.81 / 0.25f64).sqrt();
    let mut next = 0.0;
    let mut iters = 0u64;
    while solver.time_s < 0.5 {
        let dt = solver.next_dt_s(0.5);
        let r = solver.step(dt).unwrap();
        iters += r.ppe.iterations as u64;
        if solver.step <= 3 {
            let pp = &solver.particles;
            let mut best = 0;
            for i in 0..pp.len() {
                if pp.kind[i] == ParticleKind::Fluid && pp.position_m[i][0] > pp.position_m[best][0]
                {
                    best = i;
                }
            }
            println!(
                "step {} best {} pos {:?} vel {:?} p {} maxspeed {}",
                solver.step,
                best,
                pp.position_m[best].as_slice(),
                pp.velocity_m_s[best].as_slice(),
                pp.pressure_pa[best],
                solver.max_fluid_speed_m_s()
            );
        }
        if solver.time_s >= next {
            let f = front_position_m(&solver.particles, l0);
            println!(
                "t={:.3} T={:.3} Z={:.3} dt={:.2e} it={} res={:.1e} surf={}",
                solver.time_s,
                solver.time_s * scale,
                f / 0.25,
                dt,
                r.ppe.iterations,
                r.ppe.relative_residual,
                r.surface_count
            );
            next += 0.025;
        }
    }
    let el = t0.elapsed().as_secs_f64();
    println!(
        "steps={} wall={:.2}s pss={:.0} mean_it={:.1}",
        solver.step,
        el,
        (n as f64 * solver.step as f64) / el,
        iters as f64 / solver.step as f64
    );
}
