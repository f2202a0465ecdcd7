//! The solver's configuration from a manifest and its test's scene.
use crate::experiment::{Manifest, Scene};
use crate::manifest::{Fluid, PpePreconditioner, PpeSource, PressureSchemeName};
use crate::mps::viscosity::StrainRateGradient;
use crate::mps::yield_solve::YieldSolve;
use crate::mps::{PressureScheme, Rheology, SolverConfig, SourceTerm};

/// The rheology a manifest's fluid section describes, and whether eq. 8's term is on.
pub fn rheology(fluid: &Fluid) -> (Rheology, bool) {
    match *fluid {
        Fluid::Newtonian { viscosity_pa_s, .. } => (Rheology::Newtonian { viscosity_pa_s }, false),
        Fluid::Bingham {
            plastic_viscosity_pa_s,
            yield_stress_pa,
            critical_strain_rate_1_s,
            stress_gradient_term,
            ..
        } => (
            Rheology::seed000(
                plastic_viscosity_pa_s,
                yield_stress_pa,
                critical_strain_rate_1_s,
            ),
            stress_gradient_term,
        ),
        Fluid::BiViscosity {
            plastic_viscosity_pa_s,
            yield_stress_pa,
            rigid_viscosity_pa_s,
            stress_gradient_term,
            ..
        } => (
            Rheology::bi_viscosity(
                plastic_viscosity_pa_s,
                yield_stress_pa,
                rigid_viscosity_pa_s,
            ),
            stress_gradient_term,
        ),
    }
}

/// Solver parameters from the manifest (radii and distances scaled by the spacing).
pub fn solver_config<const D: usize>(m: &Manifest, scene: &Scene<D>) -> SolverConfig<D> {
    let (rheology, stress_gradient_term) = rheology(&m.fluid);
    let l0 = m.spacing_m;
    SolverConfig {
        spacing_m: l0,
        density_kg_m3: m.fluid.density_kg_m3(),
        rheology,
        stress_gradient_term,
        viscosity_tolerance: m.mps.viscosity_tolerance,
        viscosity_max_iterations: m.mps.viscosity_max_iterations,
        yield_solve: (m.mps.yield_penalty_pa_s > 0.0).then_some(YieldSolve {
            penalty_pa_s: m.mps.yield_penalty_pa_s,
            max_iterations: m.mps.yield_max_iterations,
            tolerance_1_s: m.mps.yield_tolerance_1_s,
            adaptive: m.mps.yield_penalty_adaptive,
            velocity_fraction: m.mps.yield_velocity_fraction,
            velocity_relative: m.mps.yield_velocity_relative,
            anderson_depth: m.mps.yield_anderson_depth,
            consistent_divergence: m
                .mps
                .yield_consistent_divergence
                .then_some(m.mps.surface_threshold),
            volumetric_limit: m.mps.yield_volumetric_limit,
            local_penalty: m.mps.yield_penalty_local,
        }),
        gravity_m_s2: m.gravity_m_s2,
        gravity_tilt_rad: scene.gravity_tilt_rad,
        periodic_x: scene.periodic_x,
        symmetry: scene.symmetry,
        radius_n_m: m.mps.number_density_radius * l0,
        radius_lap_m: m.mps.laplacian_radius * l0,
        radius_strain_m: m
            .mps
            .strain_rate_radius
            .unwrap_or(m.mps.number_density_radius)
            * l0,
        radius_visc_m: m
            .mps
            .viscous_laplacian_radius
            .unwrap_or(m.mps.laplacian_radius)
            * l0,
        surface_threshold: m.mps.surface_threshold,
        relaxation_coefficient: m.mps.relaxation_coefficient,
        multigrid_ppe: m.mps.ppe_preconditioner == PpePreconditioner::Multigrid,
        multigrid_over_correction: m.mps.multigrid_over_correction,
        multigrid_single_precision: m.mps.multigrid_single_precision,
        source_term: match m.mps.source_term {
            PpeSource::NumberDensity => SourceTerm::NumberDensity,
            PpeSource::Mixed => SourceTerm::Mixed,
        },
        pressure_scheme: match m.mps.pressure_scheme {
            PressureSchemeName::Standard => PressureScheme::Standard,
            PressureSchemeName::Incremental => PressureScheme::Incremental,
        },
        compression_relaxation: m.mps.compression_relaxation,
        pair_stabilisation_m: m.mps.pair_stabilisation * l0,
        wall_support_m: m.mps.wall_support * l0,
        pressure_regularisation: m.mps.pressure_regularisation,
        pressure_smoothing_time_s: m.mps.pressure_smoothing_time_s,
        regularisation_radius_m: m.mps.regularisation_radius * l0,
        increment_regularisation: m.mps.increment_regularisation,
        deep_surface_threshold: m.mps.deep_surface_threshold,
        deep_surface_pressure_pa: m.fluid.density_kg_m3()
            * m.gravity_m_s2
            * m.mps.deep_surface_head
            * l0,
        surface_depth_m: m.mps.surface_depth * l0,
        pressure_floor_pa: m.mps.pressure_floor_pa,
        particle_shifting: m.mps.particle_shifting,
        particle_shifting_limit_m: m.mps.particle_shifting_limit * l0,
        // Validation refuses both on.
        strain_rate_gradient: if m.mps.quadratic_strain_rate {
            StrainRateGradient::Quadratic
        } else if m.mps.corrected_strain_rate {
            StrainRateGradient::Corrected
        } else {
            StrainRateGradient::Plain
        },
        wall_surface_no_slip: m.mps.wall_surface_no_slip,
        wall_face_normals: m.mps.wall_face_normals,
        wall_curvature: m.mps.wall_curvature,
        exact_projection: m.mps.exact_projection,
        conservative_gradient: m.mps.conservative_gradient,
        adjoint_projection: m.mps.adjoint_projection,
        periodic_hydrostatic: m.mps.periodic_hydrostatic,
        compressibility_1_pa: m.mps.compressibility_1_pa,
        collision_distance_m: m.mps.collision_distance * l0,
        wall_collision_distance_m: match m.mps.wall_collision_distance {
            Some(d) => d * l0,
            None => {
                crate::mps::solver::wall_collision_distance_m(D, m.mps.collision_distance * l0, l0)
            }
        },
        wall_collision_second_pass: m.mps.wall_collision_second_pass.unwrap_or(D == 3),
        collision_restitution: m.mps.collision_restitution,
        ppe_tolerance: m.mps.ppe_tolerance,
        ppe_max_iterations: m.mps.ppe_max_iterations,
        courant: m.time.courant,
        dt_max_s: m.largest_step_s(),
        max_speed_m_s: m.stop.max_speed_m_s,
        domain_min_m: scene.domain_min_m,
        domain_max_m: scene.domain_max_m,
        max_ghost_particles: m
            .stop
            .max_ghost_particles
            .map(|n| usize::try_from(n).unwrap_or(usize::MAX)),
        bodies: scene.bodies.clone(),
        inlets: scene.inlets.clone(),
    }
}
