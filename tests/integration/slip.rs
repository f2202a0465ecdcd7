//! Navier slip at a rigid body's surface (`SlipWall`, the rod's and the cone's
//! `*_slip_length_m`): plane Couette flow between a resting floor (no slip at its surface) and
//! a plate moving at U with slip length b has the closed form u(y) = U y / (H + b), y from the
//! floor's surface and H the gap between the two surfaces. A linear field is an exact steady
//! solution of the MPS viscous operator on a lattice, so the discrete profile must match the
//! closed form to the solver's tolerance for every b: no slip (b = 0), b = H, free slip.
use mps_runner::mps::grid::{KernelPairs, Neighbours};
use mps_runner::mps::kernel::RefValues;
use mps_runner::mps::viscosity::{
    Loads, SlipWall, StrainRateGradient, ViscousSettings, Walls, predict_velocity,
    strain_invariant, velocity_gradient,
};
use mps_runner::mps::{ParticleKind, Particles, Rheology, Vector};

use crate::common;

const ROWS: i64 = 12;
const COLUMNS: i64 = 10; // period 10 l0 >= 3 Laplacian cutoffs
const LAYERS: i64 = 3;
const SPACING_M: f64 = 0.01;
const PLATE_SPEED_M_S: f64 = 0.1;

/// Particles of the channel: fluid rows 0..ROWS, the floor below and the plate above (the
/// plate's particles last, moving at U along x). Returns them, the plate's index range and
/// the fluid particles.
fn channel() -> (Particles<2>, std::ops::Range<usize>, Vec<usize>) {
    let mut p = Particles::<2>::default();
    let mut fluid = Vec::new();
    for row in -LAYERS..ROWS {
        for col in 0..COLUMNS {
            let x = Vector::<2>::new(
                (col as f64 + 0.5) * SPACING_M,
                (row as f64 + 0.5) * SPACING_M,
            );
            if row >= 0 {
                fluid.push(p.len());
                p.push(x, ParticleKind::Fluid);
            } else {
                p.push(x, ParticleKind::Wall);
            }
        }
    }
    let first = p.len();
    for row in ROWS..ROWS + LAYERS {
        for col in 0..COLUMNS {
            let x = Vector::<2>::new(
                (col as f64 + 0.5) * SPACING_M,
                (row as f64 + 0.5) * SPACING_M,
            );
            p.push(x, ParticleKind::Wall);
            let k = p.len() - 1;
            p.velocity_m_s[k] = Vector::<2>::new(PLATE_SPEED_M_S, 0.0);
        }
    }
    let plate = first..p.len();
    (p, plate, fluid)
}

/// The steady profile of the channel with the plate's slip length (None: the plate's
/// particles carry U, no slip at their centres): (y, u, sqrt(Pi)) of every fluid particle.
fn steady(slip_length_m: Option<f64>) -> Vec<(f64, f64, f64)> {
    let (mut p, plate, fluid) = channel();
    let l0 = SPACING_M;
    let refs = RefValues::on_lattice::<2>(l0, 2.1 * l0, 3.1 * l0);
    let nb = Neighbours::build_periodic_x(&p.position_m, refs.radius_lap_m, COLUMNS as f64 * l0);
    let pairs = KernelPairs::new(&nb, &p.position_m, refs.radius_n_m, refs.radius_lap_m);
    let settings = ViscousSettings {
        rheology: Rheology::Newtonian {
            viscosity_pa_s: 50.0,
        },
        density_kg_m3: 2300.0,
        stress_gradient_term: false,
        tolerance: 1e-13,
        max_iterations: 10_000,
        gradient: StrainRateGradient::Corrected,
        // The floor: no slip at its surface, half a spacing in front of its particles.
        wall_surface_m: Some(0.5 * l0),
        slip_walls: slip_length_m
            .map(|b| SlipWall {
                particles: plate.clone(),
                slip_length_m: b,
                surface_m: 0.5 * l0,
            })
            .into_iter()
            .collect(),
        yield_solve: None,
        wall_curvature: None,
    };
    for step in 0..2_000 {
        let stage = predict_velocity(
            &p,
            &pairs,
            &refs,
            &settings,
            Loads::body_force(Vector::zeros()),
            10.0,
        );
        assert!(stage.solve.converged, "{:?}", stage.solve);
        let change = fluid
            .iter()
            .map(|&i| (stage.velocity_m_s[i] - p.velocity_m_s[i]).norm())
            .fold(0.0, f64::max);
        p.velocity_m_s = stage.velocity_m_s;
        if change < 1e-14 {
            break;
        }
        assert!(step < 1_999, "no steady state, last change {change}");
    }
    fluid
        .iter()
        .map(|&i| {
            let g = velocity_gradient(
                &p,
                &pairs.near,
                &refs,
                i,
                settings.gradient,
                &Walls::of(&settings, None),
            );
            (
                p.position_m[i][1],
                p.velocity_m_s[i][0],
                strain_invariant(&g).sqrt(),
            )
        })
        .collect()
}

#[test]
fn couette_flow_with_navier_slip_at_the_plate_is_the_closed_form() {
    let gap_m = ROWS as f64 * SPACING_M;
    for b in [0.0, gap_m, 1e6] {
        let rate = PLATE_SPEED_M_S / (gap_m + b);
        let profile = steady(Some(b));
        for &(y, u, shear) in &profile {
            assert!(
                (u - rate * y).abs() < 1e-9 * PLATE_SPEED_M_S,
                "b = {b} m: u({y}) = {u}, closed form {}",
                rate * y
            );
            assert!(
                (shear - rate).abs() < 1e-6 * PLATE_SPEED_M_S / gap_m,
                "b = {b} m: shear rate at y = {y} is {shear}, closed form {rate}"
            );
        }
        // The slip itself: the plate's surface moves at U, the fluid there at U - b du/dy.
        let top = profile.iter().map(|t| t.0).fold(f64::MIN, f64::max);
        let u_top = profile.iter().find(|t| t.0 == top).map(|t| t.1).unwrap();
        let slip = PLATE_SPEED_M_S - (u_top + rate * (gap_m - top));
        assert!(
            (slip - b * rate).abs() < 1e-9 * PLATE_SPEED_M_S,
            "slip {slip} m/s at b = {b}"
        );
    }
}

#[test]
fn zero_slip_length_is_the_no_slip_condition_at_the_surface() {
    // b = 0 through the slip wall's own frame and the walls' no-slip surface condition
    // (`mps.wall_surface_no_slip`, here on for every wall) are one condition.
    let slip = steady(Some(0.0));
    let surface = steady(None);
    for (a, b) in slip.iter().zip(&surface) {
        assert!(
            (a.1 - b.1).abs() < 1e-12,
            "u({}) = {} against {}",
            a.0,
            a.1,
            b.1
        );
    }
}

/// A whole run: the rodding form at 10 mm, one stroke. Pulled out, the rod that holds no slip
/// at its particles lifts a column of concrete above the fill; a free-slipping rod (the
/// manifest's `scene.rod_slip_length_m`, through the solver's bodies) lifts almost none.
#[test]
fn a_free_slipping_rod_comes_out_of_the_concrete_clean() {
    let dir = tempfile::tempdir().unwrap();
    let lifted = |sets: &[&str]| -> f64 {
        let stroke = [
            "scene.strokes=1",
            "time.end_s=3.0",
            "output.checkpoint_interval_s=1.0",
        ];
        let resolved = common::rodding_10_mm(&[&stroke, sets].concat());
        let result = common::run_completed(&resolved, dir.path(), 2);
        // Run on 2 threads, replayed on 1: the same bits (the slip walls' frames and
        // factors are per particle, in a fixed order).
        common::assert_replays(&result.path, None);
        let run = mps_runner::record::read_run(&result.path).unwrap();
        let row = run
            .diagnostics
            .iter()
            .find(|d| d.metrics["strokes_done"] >= 1.0)
            .expect("the stroke ends before the run");
        row.metrics["fluid_on_rod_count"] / f64::from(row.fluid_particle_count)
    };
    // The shipped rod slips (its steel's slip length): null takes the field out.
    let no_slip = lifted(&["scene.rod_slip_length_m=null"]);
    let free = lifted(&["scene.rod_slip_length_m=1.0"]);
    println!(
        "share of the concrete above the fill after the stroke: no slip {no_slip}, free slip {free}"
    );
    assert!(no_slip > 0.05, "no slip: {no_slip}");
    assert!(free < 0.02, "free slip: {free}");
}
