//! The Bingham viscosity model against closed forms (DESIGN.md sections 4 and 5).
mod common;
use mps_runner::mps::grid::{KernelPairs, Neighbours};
use mps_runner::mps::kernel::RefValues;
use mps_runner::mps::viscosity::{ViscousSettings, predict_velocity};
use mps_runner::mps::{ParticleKind, Particles, Rheology, Vector};
use mps_runner::record::Outcome;

/// Plane Poiseuille flow of a Bingham fluid between walls at y = +-h, driven by a body force
/// G/rho along x, on a strip periodic in x: marching the implicit viscous step (the viscosity
/// model alone: no pressure, positions fixed) to steady state gives its MPS solution.
fn bingham_poiseuille(
    rheology: Rheology,
    stress_gradient_term: bool,
    cells_per_half_width: i64,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let h = 0.1;
    let l0 = h / cells_per_half_width as f64;
    let rho = 2300.0;
    let g_pa_m = 2500.0;
    let layers = 3;
    let columns = 10; // period 10 l0 >= 3 Laplacian cutoffs
    let mut p = Particles::<2>::default();
    let mut column0 = Vec::new();
    for row in -cells_per_half_width - layers..cells_per_half_width + layers {
        for col in 0..columns {
            let pos = Vector::<2>::new((col as f64 + 0.5) * l0, (row as f64 + 0.5) * l0);
            let inside = row >= -cells_per_half_width && row < cells_per_half_width;
            if inside && col == 0 {
                column0.push(p.len());
            }
            p.push(
                pos,
                if inside {
                    ParticleKind::Fluid
                } else {
                    ParticleKind::Wall
                },
            );
        }
    }
    let refs = RefValues::on_lattice::<2>(l0, 2.1 * l0, 3.1 * l0);
    let nb = Neighbours::build_periodic_x(&p.position_m, refs.radius_lap_m, columns as f64 * l0);
    // Particles do not move in this test: one set of kernel pairs serves every step.
    let pairs = KernelPairs::new(&nb, &p.position_m, refs.radius_n_m, refs.radius_lap_m);
    let settings = ViscousSettings {
        rheology,
        density_kg_m3: rho,
        stress_gradient_term,
        tolerance: 1e-12,
        max_iterations: 10_000,
    };
    let force = Vector::<2>::new(g_pa_m / rho, 0.0);
    let dt_s = 0.05;
    let mut strain = Vec::new();
    for step in 0..20_000 {
        let stage = predict_velocity(&p, &pairs, &refs, &settings, force, dt_s);
        assert!(stage.solve.converged, "{:?}", stage.solve);
        let change = (0..p.len())
            .map(|i| (stage.velocity_m_s[i] - p.velocity_m_s[i]).norm())
            .fold(0.0, f64::max);
        p.velocity_m_s = stage.velocity_m_s;
        strain = stage.strain_invariant;
        if change < 1e-12 {
            break;
        }
        assert!(step < 19_999, "no steady state, last change {change}");
    }
    let y: Vec<f64> = column0.iter().map(|&i| p.position_m[i][1]).collect();
    let u: Vec<f64> = column0.iter().map(|&i| p.velocity_m_s[i][0]).collect();
    let pi: Vec<f64> = column0.iter().map(|&i| strain[i]).collect();
    (y, u, pi)
}

/// Closed form of Bingham plane Poiseuille flow.
fn exact(y: f64, h: f64, g: f64, tau: f64, eta: f64) -> f64 {
    let plug = tau / g;
    let y = y.abs().max(plug);
    g / (2.0 * eta) * (h * h - y * y) - tau / eta * (h - y)
}

/// MPS walls of particles at rest give no-slip a little beyond the nominal wall. The
/// Newtonian profile of the same discretisation locates it: the centre velocity G h_eff^2 /
/// (2 eta) gives h_eff. Returns (h_eff, spacing).
fn effective_half_width(cells: i64, g: f64, eta: f64) -> (f64, f64) {
    let (_, u, _) = bingham_poiseuille(
        Rheology::Newtonian {
            viscosity_pa_s: eta,
        },
        false,
        cells,
    );
    let centre = u.iter().cloned().fold(0.0, f64::max);
    ((2.0 * eta * centre / g).sqrt(), 0.1 / cells as f64)
}

#[test]
fn newtonian_poiseuille_is_a_parabola_with_the_wall_within_a_spacing() {
    let (h, g, eta) = (0.1, 2500.0, 50.0);
    let mut offsets = Vec::new();
    for cells in [10, 20] {
        let (y, u, _) = bingham_poiseuille(
            Rheology::Newtonian {
                viscosity_pa_s: eta,
            },
            false,
            cells,
        );
        let (h_eff, l0) = effective_half_width(cells, g, eta);
        eprintln!(
            "{cells} cells: no-slip at {h_eff:.5} m = h + {:.3} l0",
            (h_eff - h) / l0
        );
        assert!(
            h_eff > h && h_eff - h < l0,
            "wall offset {} l0",
            (h_eff - h) / l0
        );
        offsets.push(h_eff - h);
        // With that wall the whole profile is the parabola (the near-wall rows bend it by a
        // few tenths of a percent).
        let centre = g * h_eff * h_eff / (2.0 * eta);
        for (y, u) in y.iter().zip(&u) {
            let exact = g / (2.0 * eta) * (h_eff * h_eff - y * y);
            assert!((u - exact).abs() < 0.01 * centre, "y = {y}: {u} vs {exact}");
        }
    }
    // The offset is a fixed share of the spacing: first-order convergence to the nominal wall.
    let ratio = offsets[0] / offsets[1];
    assert!((ratio - 2.0).abs() < 0.05, "offset ratio {ratio}");
}

#[test]
fn bingham_poiseuille_plug_matches_closed_form() {
    let (g, tau, eta): (f64, f64, f64) = (2500.0, 100.0, 50.0);
    let cells = 20;
    let (h, l0) = effective_half_width(cells, g, eta);
    let plug_half_width = tau / g; // 0.04 m
    let plug_velocity = (h * g - tau).powi(2) / (2.0 * eta * g);
    for (name, rheology) in [
        (
            "bi-viscosity, mu_r = 1000 mu_p",
            Rheology::bi_viscosity(eta, tau, 1000.0 * eta),
        ),
        (
            "seed 000, 2 pi_c = tau / (999 eta)",
            Rheology::seed000(eta, tau, tau / (2.0 * 999.0 * eta)),
        ),
    ] {
        // With the stress-gradient term (the divergence form): without it the momentum balance
        // is mu u'' = -G, not (mu u')' = -G, and the Bingham closed form does not apply.
        let (y, u, pi) = bingham_poiseuille(rheology, true, cells);
        let non_flowing = y
            .iter()
            .zip(&pi)
            .filter(|(_, pi)| !rheology.is_flowing(**pi))
            .map(|(y, _)| y.abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{name}: non-flowing particles up to |y| = {non_flowing:.4} (the gradient model's support blurs the plug edge)"
        );
        let u_max = u.iter().cloned().fold(0.0, f64::max);
        // The regularisation (mu_r = 1000 mu_p) is worth 1-2 % (DESIGN.md section 4).
        let tolerance = 0.02;
        let error = (u_max - plug_velocity).abs() / plug_velocity;
        eprintln!("{name}: plug velocity {u_max:.5} vs {plug_velocity:.5} (error {error:.4})");
        assert!(
            error < tolerance,
            "{name}: plug velocity {u_max} vs {plug_velocity}"
        );
        // Plug edge from the velocity: one spacing outside the plug the closed form has
        // fallen by G l0^2 / (2 eta); the particles closer to the plug velocity than that
        // locate the edge to a spacing.
        let drop = g * l0 * l0 / (2.0 * eta);
        let measured = y
            .iter()
            .zip(&u)
            .filter(|(_, u)| u_max - **u < drop)
            .map(|(y, _)| y.abs())
            .fold(0.0, f64::max)
            + 0.5 * l0;
        eprintln!("{name}: plug half-width {measured:.4} vs {plug_half_width:.4}");
        assert!(
            (measured - plug_half_width).abs() <= l0 + 1e-12,
            "{name}: plug half-width {measured}"
        );
        let worst = y
            .iter()
            .zip(&u)
            .map(|(y, u)| (u - exact(*y, h, g, tau, eta)).abs())
            .fold(0.0, f64::max)
            / plug_velocity;
        eprintln!("{name}: worst profile error {worst:.4} of the plug velocity");
        assert!(worst < tolerance, "{name}: profile error {worst}");
    }
}

#[test]
fn zero_yield_bingham_is_the_newtonian_limit() {
    let eta = 50.0;
    let (_, u, _) = bingham_poiseuille(
        Rheology::Newtonian {
            viscosity_pa_s: eta,
        },
        false,
        10,
    );
    let (_, u0, _) = bingham_poiseuille(Rheology::seed000(eta, 0.0, 1.0), false, 10);
    assert_eq!(
        u, u0,
        "tau_y = 0 must reproduce the Newtonian result bit for bit"
    );
}

#[test]
fn zero_yield_bingham_run_equals_newtonian_run() {
    let dir = tempfile::tempdir().unwrap();
    let newtonian = common::resolve(
        "smoke_2d.yaml",
        &["time.end_s=0.05", "fluid.viscosity_pa_s=0.5"],
    );
    let bingham = common::resolve(
        "smoke_2d.yaml",
        &[
            "time.end_s=0.05",
            "fluid.model=bingham",
            "fluid.density_kg_m3=1000",
            "fluid.plastic_viscosity_pa_s=0.5",
            "fluid.yield_stress_pa=0",
            "fluid.critical_strain_rate_1_s=1",
            "fluid.stress_gradient_term=false",
        ],
    );
    let a = common::run_in(&newtonian, dir.path(), 2);
    let b = common::run_in(&bingham, dir.path(), 2);
    assert_eq!(a.outcome, Outcome::Completed);
    assert_eq!(b.outcome, Outcome::Completed);
    assert_eq!(a.summary.checkpoints, b.summary.checkpoints);
}

#[test]
fn viscosity_ratio_1000_is_stable_at_the_seed_time_step() {
    // Rigid viscosity 1000 x the plastic one: an explicit viscous step would need
    // dt < 0.2 l0^2 / nu_r = 9.2e-7 s; the implicit one runs at the seed's 1e-4 s.
    let resolved = common::resolve(
        "l_flow_2d.yaml",
        &[
            "time.end_s=0.2",
            "fluid.model=bi_viscosity",
            "fluid.density_kg_m3=2300",
            "fluid.plastic_viscosity_pa_s=50",
            "fluid.yield_stress_pa=125",
            "fluid.rigid_viscosity_pa_s=50000",
        ],
    );
    assert_eq!(resolved.manifest.time.dt_max_s, 1e-4);
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_completed(&resolved, dir.path(), 2);
    assert_eq!(
        result.summary.metrics["steps"], 2000.0,
        "dt stayed at 1e-4 s"
    );
    let run = mps_runner::record::read_run(&result.path).unwrap();
    let fastest = run
        .diagnostics
        .iter()
        .map(|d| d.max_speed_m_s)
        .fold(0.0, f64::max);
    // Free fall from the column height bounds any physical speed: sqrt(2 g 0.41 m) = 2.8 m/s.
    assert!(fastest < 2.8, "max speed {fastest} m/s");
    let front = result.summary.metrics["l_flow_value_m"];
    assert!(
        front > 0.02,
        "the concrete flowed into the channel: {front} m"
    );
}
