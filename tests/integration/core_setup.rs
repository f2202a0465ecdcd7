//! Small hand-built scenes for the solver-core tests (bodies, inlets, tags): a walled box,
//! a solver configuration with the usual MPS parameters, and a stepping helper.
#![allow(dead_code)]
use mps_runner::checkpoint;
use mps_runner::experiment::geometry::container::add_walls;
use mps_runner::experiment::geometry::lattice::{centre, for_each_index};
use mps_runner::mps::ParticleKind;
use mps_runner::mps::solver::wall_collision_distance_m;
use mps_runner::mps::{Particles, Rheology, Solver, SolverConfig, SourceTerm, Vector};
use prost::Message as _;

/// A box of `cells` lattice cells (open above its top row), walled by one wall and two dummy
/// layers, its fluid the cells below `fill_rows` on the last axis. Returns the particles and
/// the domain box (the inside plus a margin of two spacings).
pub fn walled_box<const D: usize>(
    spacing_m: f64,
    cells: [i64; D],
    fill_rows: i64,
) -> (Particles<D>, Vector<D>, Vector<D>) {
    let mut p = Particles::<D>::default();
    let mut fill = cells;
    fill[D - 1] = fill_rows;
    for_each_index([0; D], fill, |idx| {
        p.push(centre(idx, spacing_m), ParticleKind::Fluid)
    });
    add_walls(&mut p, &[([0; D], cells)], cells[D - 1], spacing_m, 1, 2);
    let lo = Vector::<D>::from_element(-2.0 * spacing_m);
    let hi = Vector::<D>::from_fn(|a, _| (cells[a] as f64 + 2.0) * spacing_m);
    (p, lo, hi)
}

/// The usual MPS parameters for a viscous Newtonian fluid (no bodies, no inlets).
pub fn config<const D: usize>(
    spacing_m: f64,
    domain_min_m: Vector<D>,
    domain_max_m: Vector<D>,
) -> SolverConfig<D> {
    let l0 = spacing_m;
    SolverConfig {
        spacing_m: l0,
        density_kg_m3: 1000.0,
        rheology: Rheology::Newtonian {
            viscosity_pa_s: 0.05,
        },
        stress_gradient_term: false,
        yield_solve: None,
        viscosity_tolerance: 1e-9,
        viscosity_max_iterations: 2000,
        gravity_m_s2: 9.81,
        gravity_tilt_rad: 0.0,
        periodic_x: None,
        symmetry: Default::default(),
        radius_n_m: 2.1 * l0,
        radius_lap_m: 3.1 * l0,
        radius_strain_m: 2.1 * l0,
        radius_visc_m: 3.1 * l0,
        surface_threshold: 0.97,
        relaxation_coefficient: 0.2,
        source_term: SourceTerm::Mixed,
        multigrid_ppe: false,
        multigrid_single_precision: false,
        multigrid_over_correction: 1.0,
        pressure_scheme: mps_runner::mps::PressureScheme::Standard,
        compression_relaxation: 0.01,
        pair_stabilisation_m: 0.0,
        wall_support_m: 0.0,
        pressure_regularisation: 0.0,
        pressure_smoothing_time_s: 0.0,
        regularisation_radius_m: 1.5 * l0,
        increment_regularisation: 0.0,
        deep_surface_threshold: 0.0,
        deep_surface_pressure_pa: 0.0,
        surface_depth_m: 0.0,
        pressure_floor_pa: 0.0,
        particle_shifting: 0.0,
        particle_shifting_limit_m: 0.05 * l0,
        strain_rate_gradient: mps_runner::mps::viscosity::StrainRateGradient::Plain,
        wall_surface_no_slip: false,
        wall_face_normals: false,
        wall_curvature: false,
        exact_projection: false,
        conservative_gradient: false,
        adjoint_projection: false,
        periodic_hydrostatic: false,
        compressibility_1_pa: 0.45e-9,
        collision_distance_m: 0.5 * l0,
        wall_collision_distance_m: wall_collision_distance_m(D, 0.5 * l0, l0),
        wall_collision_second_pass: D == 3,
        collision_restitution: 0.2,
        ppe_tolerance: 1e-9,
        ppe_max_iterations: 5000,
        courant: 0.2,
        dt_max_s: 1e-3,
        max_speed_m_s: 50.0,
        domain_min_m,
        domain_max_m,
        max_ghost_particles: None,
        bodies: Vec::new(),
        inlets: Vec::new(),
    }
}

/// One step of the CFL time step towards `end_s`; false once `end_s` is reached.
pub fn advance<const D: usize>(solver: &mut Solver<D>, end_s: f64) -> bool {
    // The time is a sum of steps: round-off of order 1e-16 s below end_s.
    if end_s - solver.time_s <= 1e-12 {
        return false;
    }
    let dt = solver.next_dt_s(end_s);
    solver.step(dt).expect("step");
    true
}

/// A solver rebuilt from a checkpoint message of `solver`, sent through its protobuf bytes
/// as a recording would.
pub fn through_checkpoint<const D: usize>(
    solver: &Solver<D>,
    config: SolverConfig<D>,
) -> Solver<D> {
    let msg = checkpoint::to_message(0, solver, 0.0);
    let bytes = msg.encode_to_vec();
    let decoded = mps_runner::proto::mps::v1::StateCheckpoint::decode(&bytes[..]).unwrap();
    assert_eq!(checkpoint::state_sha256(&decoded), msg.state_sha256);
    checkpoint::solver_from_message::<D>(config, &decoded).expect("restore")
}

/// Positions as bits, for exact comparisons.
pub fn position_bits<const D: usize>(p: &Particles<D>) -> Vec<u64> {
    p.position_m
        .iter()
        .flat_map(|x| x.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
        .collect()
}
