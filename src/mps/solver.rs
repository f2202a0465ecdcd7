//! One time step of the MPS method (DESIGN.md section 3), stage by stage.
use super::body::RigidBody;
use super::grid::{KernelPairs, Neighbours};
use super::inlet::Inlet;
use super::kernel::{RefValues, weight};
use super::multigrid::Multigrid;
use super::operators::{gradient, number_density};
use super::particles::{ParticleKind, Particles, Vector};
use super::pressure::{CsrMatrix, Preconditioner, SolveReport, solve_pcg};
use super::reduce::PARTICLES_PER_TASK;
use super::reduce::max_by;
use super::rheology::Rheology;
use super::viscosity::{StrainRateGradient, ViscousSettings, predict_velocity};
use rayon::prelude::*;
use std::time::Instant;

mod exact;
mod incremental;

/// Physical and numerical parameters of the solver, all in SI units.
#[derive(Debug, Clone, PartialEq)]
pub struct SolverConfig<const D: usize> {
    pub spacing_m: f64,
    pub density_kg_m3: f64,
    pub rheology: Rheology,
    /// Seed 000 eq. 8 stress-gradient term on/off.
    pub stress_gradient_term: bool,
    pub viscosity_tolerance: f64,
    pub viscosity_max_iterations: u32,
    /// Magnitude of gravity, acting along the last axis towards -inf.
    pub gravity_m_s2: f64,
    /// Gravity turned by this angle from -vertical towards +x (an inclined plane as a level
    /// floor under tilted gravity); 0 for a level scene.
    pub gravity_tilt_rad: f64,
    /// x is periodic: positions are kept in [min_m, min_m + period_m) and pairs take the
    /// nearest image across the seam.
    pub periodic_x: Option<PeriodicX>,
    pub radius_n_m: f64,
    pub radius_lap_m: f64,
    /// beta: a particle is on the free surface when n* < beta n0.
    pub surface_threshold: f64,
    /// gamma: relaxation of the number-density source term.
    pub relaxation_coefficient: f64,
    pub source_term: SourceTerm,
    /// How pressure is computed and applied (see [`PressureScheme`]).
    pub pressure_scheme: PressureScheme,
    /// gamma_c of the incremental scheme: relaxation of its compression term
    /// gamma_c rho/dt^2 max(n*_i - n0, 0)/n0 (volume kept where the velocity source drifts).
    pub compression_relaxation: f64,
    /// Incremental scheme: fluid pairs closer than this (m) are pushed back to it within the
    /// step (dynamic stabilisation; 0 = off). Idle while every pair is this far apart.
    pub pair_stabilisation_m: f64,
    /// Incremental scheme: a wall particle with a fluid particle closer than this (m) takes
    /// part in the increment's PPE, and that fluid particle's carried gradient sees its walls
    /// no lower than itself (0 = off). Idle at rest, where fluid sits a spacing from walls.
    pub wall_support_m: f64,
    /// Incremental scheme: beta of the pressure regularisation, -(beta p_i/rho) (d/n0)
    /// sum_j r_ij w(r_ij)/r_ij^2 over neighbours within `regularisation_radius_m` (0 = off).
    /// Zero on a lattice at rest.
    pub pressure_regularisation: f64,
    pub regularisation_radius_m: f64,
    /// Incremental scheme: a free-surface particle holds rho |g| surface_depth_m
    /// max(-n . g/|g|, 0) (0 = p = 0 at surface particles).
    pub surface_depth_m: f64,
    /// How the strain rate's velocity gradient is estimated.
    pub strain_rate_gradient: StrainRateGradient,
    /// No-slip at the walls' surface, not at the wall particles (see
    /// [`crate::mps::viscosity::ViscousSettings::wall_surface_m`]).
    pub wall_surface_no_slip: bool,
    /// Incremental scheme: the increment's equation is -D G with the correction's own
    /// divergence and gradient (exact projection, `solver/exact.rs`) instead of the MPS
    /// Laplacian model.
    pub exact_projection: bool,
    /// Aggregation multigrid instead of Jacobi as the PPE preconditioner.
    pub multigrid_ppe: bool,
    pub compressibility_1_pa: f64,
    pub collision_distance_m: f64,
    /// Collision distance between a fluid and a wall particle (see
    /// [`wall_collision_distance_m`]).
    pub wall_collision_distance_m: f64,
    /// Collide fluid-wall pairs again after the pressure correction (the manifest's default
    /// is on in 3D: see [`wall_collision_distance_m`]).
    pub wall_collision_second_pass: bool,
    pub collision_restitution: f64,
    pub ppe_tolerance: f64,
    pub ppe_max_iterations: u32,
    pub courant: f64,
    pub dt_max_s: f64,
    /// Blow-up guard: a step fails when a particle gets faster than this.
    pub max_speed_m_s: f64,
    /// Fluid that leaves this box becomes a ghost.
    pub domain_min_m: Vector<D>,
    pub domain_max_m: Vector<D>,
    /// A step fails once more fluid particles than this have left the domain box (None = no
    /// limit).
    pub max_ghost_particles: Option<usize>,
    /// Walls that move on time-pure paths (the slump cone), applied in order.
    pub bodies: Vec<RigidBody<D>>,
    /// Openings that pour fluid, served in order at the start of each step.
    pub inlets: Vec<Inlet<D>>,
}

/// Source term of the pressure Poisson equation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceTerm {
    /// gamma rho/dt^2 (n*_i - n0)/n0 (Koshizuka & Oka 1996).
    NumberDensity,
    /// -(rho/dt) div(u*)_i + gamma rho/dt^2 (n^k_i - n0)/n0 with n^k at the start of the step
    /// (Tanaka & Masunaga 2010): much less pressure noise.
    Mixed,
}

/// How the pressure is found and applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PressureScheme {
    /// Koshizuka & Oka: the PPE gives the whole pressure each step (source per
    /// [`SourceTerm`]), wall particles carry PPE pressure, dummies none, and the gradient uses
    /// p_j - min p over the neighbourhood.
    Standard,
    /// Incremental projection (see `incremental.rs`): the pressure is carried from step to
    /// step and enters the prediction; the PPE solves for its increment from the velocity
    /// divergence of u*; the gradient is first-order consistent (corrective matrix,
    /// difference form); walls and dummies mirror the pressure hydrostatically. A fluid at
    /// rest under hydrostatic pressure is then a fixed point of the step.
    Incremental,
}

/// The fluid-wall collision distance for a fluid-fluid one of `collision_distance_m`.
/// In 2D a wall's gaps between neighbouring wall particles are l0 wide, so a fluid particle
/// cannot pass closer than l0/2 to them and the collision distance (0.5 l0 by default) closes
/// them. In 3D the gap at the centre of a square of wall particles leaves half a face
/// diagonal, 0.707 l0: a fluid particle without pressure (free surface, as in a thin spreading
/// layer) falls through the wall and its dummy layers under gravity. So in 3D fluid-wall
/// pairs collide below max(collision distance, 0.8 l0), which stops a particle over such a gap
/// 0.37 l0 above the wall layer's centres and leaves a particle resting on the wall (l0 above
/// it) untouched. 2D is unchanged.
pub fn wall_collision_distance_m(
    dimension: usize,
    collision_distance_m: f64,
    spacing_m: f64,
) -> f64 {
    if dimension == 3 {
        collision_distance_m.max(0.8 * spacing_m)
    } else {
        collision_distance_m
    }
}

/// Wall-clock seconds spent in each stage of the step, summed over steps (for benchmarks;
/// never part of the state or of any recording).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    /// Cell-grid (Verlet) list builds and their count.
    pub neighbours_s: f64,
    pub list_builds: u64,
    /// Filtering the lists to the kernel radii (twice per step).
    pub kernel_pairs_s: f64,
    /// CG iterations summed over steps (viscosity: over the velocity components).
    pub ppe_iterations: u64,
    pub viscosity_iterations: u64,
    pub viscosity_s: f64,
    pub pressure_assembly_s: f64,
    pub pressure_solve_s: f64,
    pub step_total_s: f64,
}

/// Why a step could not be completed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    #[error("non-finite position or velocity at particle {particle} (step {step})")]
    NonFinite { particle: usize, step: u64 },
    #[error(
        "particle {particle} speed {speed_m_s:.3e} m/s exceeds stop.max_speed_m_s = {limit_m_s} (step {step})"
    )]
    TooFast {
        particle: usize,
        speed_m_s: f64,
        limit_m_s: f64,
        step: u64,
    },
    #[error(
        "time step {dt_s:.3e} s is below the smallest allowed, {min_s:.3e} s (time.dt_min_s), at step {step}: the fastest particle moves at {speed_m_s:.3e} m/s"
    )]
    TimeStepTooSmall {
        dt_s: f64,
        min_s: f64,
        speed_m_s: f64,
        step: u64,
    },
    #[error(
        "particle {particle} left the domain box at {position_m} (step {step}): {ghosts} particles have left it, more than stop.max_ghost_particles = {limit}"
    )]
    LeftDomain {
        particle: usize,
        /// Where it left, formatted `(x, y[, z]) m`.
        position_m: String,
        ghosts: usize,
        limit: usize,
        step: u64,
    },
    #[error(
        "the {solve} solve met a non-finite value (NaN or infinity) at step {step}: the state entering it is not finite"
    )]
    NonFiniteSolve { solve: &'static str, step: u64 },
    #[error(
        "viscosity solve did not converge: relative residual {residual:.3e} after {iterations} iterations (step {step})"
    )]
    ViscosityNotConverged {
        residual: f64,
        iterations: u32,
        step: u64,
    },
    #[error(
        "pressure solve did not converge: relative residual {residual:.3e} after {iterations} iterations (step {step})"
    )]
    PressureNotConverged {
        residual: f64,
        iterations: u32,
        step: u64,
    },
}

/// What one step did, for diagnostics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    pub dt_s: f64,
    pub ppe: SolveReport,
    pub viscosity: SolveReport,
    /// Share of fluid particles that were non-flowing (Pi <= Pi_c) at the start of the step.
    pub non_flowing_fraction: f64,
    pub surface_count: usize,
}

pub struct Solver<const D: usize> {
    pub config: SolverConfig<D>,
    pub refs: RefValues,
    pub particles: Particles<D>,
    pub time_s: f64,
    pub step: u64,
    /// Particles poured so far by each inlet of `config.inlets` (same order). Part of the
    /// state: recorded in the checkpoint's `extra_scalars`, restored on resume and replay.
    pub inlet_emitted: Vec<u64>,
    /// Cross-section lattice of each inlet (derived from the configuration once).
    inlet_sections: Vec<Vec<Vector<D>>>,
    /// Strain-rate invariant Pi of every particle at the start of the last step (empty before
    /// the first step). Derived data for output, not part of the state.
    pub strain_invariant: Vec<f64>,
    neighbours: Neighbours,
    /// Pairs of `neighbours` within the kernel radii at the current positions.
    pairs: KernelPairs,
    /// Positions when `pairs` were cut.
    paired_at_m: Vec<Vector<D>>,
    /// Positions when the neighbour lists were built (Verlet lists with a skin).
    listed_at_m: Vec<Vector<D>>,
    /// Rebuild the lists at every stage (slower; for checking that reuse changes no bit).
    pub fresh_lists: bool,
    /// Time spent per stage so far.
    pub timing: StageTimes,
}

/// Extra reach of the neighbour lists beyond the Laplacian radius, in spacings: lists stay
/// valid until a particle has moved half of it. Lists are in index order and operators skip
/// pairs beyond their radius, so results do not depend on when lists were rebuilt (the same
/// bits as fresh lists every stage).
const LIST_SKIN: f64 = 0.5;

/// A periodic x axis (see [`SolverConfig::periodic_x`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeriodicX {
    pub min_m: f64,
    pub period_m: f64,
}

impl PeriodicX {
    /// The shortest period the neighbour grid accepts for a Laplacian radius (three list
    /// cutoffs, the radius plus the skin).
    pub fn min_period_m(radius_lap_m: f64, spacing_m: f64) -> f64 {
        3.0 * (radius_lap_m + LIST_SKIN * spacing_m)
    }
}

impl<const D: usize> Solver<D> {
    pub fn new(config: SolverConfig<D>, particles: Particles<D>) -> Self {
        let refs =
            RefValues::on_lattice::<D>(config.spacing_m, config.radius_n_m, config.radius_lap_m);
        let inlet_sections = config
            .inlets
            .iter()
            .map(|inlet| inlet.cross_section_m(config.spacing_m))
            .collect();
        Self {
            inlet_emitted: vec![0; config.inlets.len()],
            inlet_sections,
            config,
            refs,
            particles,
            time_s: 0.0,
            step: 0,
            strain_invariant: Vec::new(),
            neighbours: Neighbours::default(),
            pairs: KernelPairs::default(),
            paired_at_m: Vec::new(),
            listed_at_m: Vec::new(),
            fresh_lists: false,
            timing: StageTimes::default(),
        }
    }

    fn gravity(&self) -> Vector<D> {
        let c = &self.config;
        let mut g = Vector::<D>::zeros();
        if c.gravity_tilt_rad == 0.0 {
            g[D - 1] = -c.gravity_m_s2;
        } else {
            // libm: the value enters the state, which must not depend on the platform.
            g[0] = c.gravity_m_s2 * libm::sin(c.gravity_tilt_rad);
            g[D - 1] = -c.gravity_m_s2 * libm::cos(c.gravity_tilt_rad);
        }
        g
    }

    /// Largest fluid speed (m/s).
    pub fn max_fluid_speed_m_s(&self) -> f64 {
        let p = &self.particles;
        max_by(p.len(), |i| {
            if p.kind[i] == ParticleKind::Fluid {
                p.velocity_m_s[i].norm()
            } else {
                0.0
            }
        })
    }

    /// Time step from the CFL condition (Courant number on the largest speed) and dt_max, never
    /// past `end_time_s`. Viscosity is implicit, so it sets no limit. An inlet that pours
    /// during the next step (started or starting within dt_max, not finished) counts with its
    /// inflow speed.
    pub fn next_dt_s(&self, end_time_s: f64) -> f64 {
        let c = &self.config;
        let mut dt = c.dt_max_s;
        let mut speed = self.max_fluid_speed_m_s();
        for (inlet, &emitted) in c.inlets.iter().zip(&self.inlet_emitted) {
            if emitted < inlet.total_count(c.spacing_m) && self.time_s + c.dt_max_s >= inlet.start_s
            {
                speed = speed.max(inlet.speed_m_s);
            }
        }
        if speed > 0.0 {
            dt = dt.min(c.courant * c.spacing_m / speed);
        }
        let remaining = end_time_s - self.time_s;
        if remaining < dt {
            dt = remaining;
        }
        dt
    }

    /// Settings of the viscous stage.
    pub fn viscous_settings(&self) -> ViscousSettings {
        let c = &self.config;
        ViscousSettings {
            rheology: c.rheology,
            density_kg_m3: c.density_kg_m3,
            stress_gradient_term: c.stress_gradient_term,
            tolerance: c.viscosity_tolerance,
            max_iterations: c.viscosity_max_iterations,
            gradient: c.strain_rate_gradient,
            wall_surface_m: c.wall_surface_no_slip.then_some(0.5 * c.spacing_m),
        }
    }

    /// Advances the state by dt_s.
    pub fn step(&mut self, dt_s: f64) -> Result<StepReport, StepError> {
        let started = Instant::now();
        let result = self.step_stages(dt_s);
        self.timing.step_total_s += started.elapsed().as_secs_f64();
        result
    }

    fn step_stages(&mut self, dt_s: f64) -> Result<StepReport, StepError> {
        // (1) Viscosity (implicit, with the effective viscosity of the rheology) and gravity
        // give the predicted velocity u*, then (2) r* = r + dt u*.
        self.pour();
        // Rigid bodies carry their path velocity during the step (a moving no-slip wall for
        // the viscous stage).
        for body in &self.config.bodies {
            let velocity = body.path.velocity_m_s(self.time_s);
            for v in &mut self.particles.velocity_m_s[body.first..body.end] {
                *v = velocity;
            }
        }
        self.rebuild_neighbours();
        self.refresh_pairs();
        let start_density = match self.config.source_term {
            SourceTerm::Mixed => Some(self.number_density()),
            SourceTerm::NumberDensity => None,
        };
        let incremental = self.config.pressure_scheme == PressureScheme::Incremental;
        let pressure_accel = incremental.then(|| self.carried_pressure_acceleration());
        let viscosity_started = Instant::now();
        let stage = predict_velocity(
            &self.particles,
            &self.pairs,
            &self.refs,
            &self.viscous_settings(),
            self.gravity(),
            pressure_accel.as_deref(),
            dt_s,
        );
        self.timing.viscosity_s += viscosity_started.elapsed().as_secs_f64();
        self.timing.viscosity_iterations += u64::from(stage.solve.iterations);
        if stage.solve.relative_residual.is_nan() {
            return Err(StepError::NonFiniteSolve {
                solve: "viscosity",
                step: self.step,
            });
        }
        if !stage.solve.converged {
            return Err(StepError::ViscosityNotConverged {
                residual: stage.solve.relative_residual,
                iterations: stage.solve.iterations,
                step: self.step,
            });
        }
        let non_flowing_fraction = self.non_flowing_fraction(&stage.strain_invariant);
        self.strain_invariant = stage.strain_invariant;
        {
            let p = &mut self.particles;
            let kind = &p.kind;
            per_particle(&mut p.velocity_m_s, &mut p.position_m, |i, v, x| {
                if kind[i] == ParticleKind::Fluid {
                    *v = stage.velocity_m_s[i];
                    *x += *v * dt_s;
                }
            });
            // Bodies move by the change of their path offset over the step, so they stay at
            // their initial position plus the offset (up to round-off) without any state.
            for body in &self.config.bodies {
                let path = &body.path;
                let shift = path.offset_m(self.time_s + dt_s) - path.offset_m(self.time_s);
                for x in &mut p.position_m[body.first..body.end] {
                    *x += shift;
                }
            }
        }

        // Neighbours at the predicted positions, used by every later stage of the step.
        self.rebuild_neighbours();
        self.collide(dt_s, false);
        self.refresh_pairs();

        // (3) Pressure, (4) correction of velocity and position.
        let (ppe, surface_count) = if incremental {
            self.incremental_projection(dt_s)?
        } else {
            self.standard_projection(dt_s, start_density.as_deref())?
        };
        if incremental && self.config.pair_stabilisation_m > 0.0 {
            self.stabilise_pairs(dt_s, self.config.pair_stabilisation_m);
        }
        if self.config.wall_collision_second_pass {
            // The correction can push a free-surface particle into a gap of the wall lattice
            // (see `wall_collision_distance_m`): fluid-wall pairs collide once more.
            self.collide(dt_s, true);
        }

        self.time_s += dt_s;
        self.step += 1;
        self.check_state()?;
        Ok(StepReport {
            dt_s,
            ppe,
            viscosity: stage.solve,
            non_flowing_fraction,
            surface_count,
        })
    }

    /// (3)-(4) of the standard scheme: n*, free surface, PPE for the whole pressure, and the
    /// correction with the p_j - p_min gradient. Returns the PPE report and the surface count.
    fn standard_projection(
        &mut self,
        dt_s: f64,
        start_density: Option<&[f64]>,
    ) -> Result<(SolveReport, usize), StepError> {
        // Number density n*, free surface, pressure Poisson equation.
        let pressure_started = Instant::now();
        let number_density = self.number_density();
        let threshold = self.config.surface_threshold * self.refs.n0;
        let surface: Vec<bool> = number_density
            .par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .map(|&n| n < threshold)
            .collect();
        let source = self.pressure_source(dt_s, start_density.unwrap_or(&number_density));
        let kind = &self.particles.kind;
        let surface_count = (0..kind.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .filter(|&i| kind[i] == ParticleKind::Fluid && surface[i])
            .count();
        let (ppe, solve_s) = self.solve_pressure(dt_s, &source, &surface);
        self.timing.pressure_solve_s += solve_s;
        self.timing.ppe_iterations += u64::from(ppe.iterations);
        self.timing.pressure_assembly_s += pressure_started.elapsed().as_secs_f64() - solve_s;
        self.check_pressure_solve(&ppe)?;

        // (4) Correct velocity and position with the pressure gradient.
        self.correct_with_pressure_gradient(dt_s);
        Ok((ppe, surface_count))
    }

    /// A PPE solve that met a non-finite value or did not converge fails the step.
    fn check_pressure_solve(&self, ppe: &SolveReport) -> Result<(), StepError> {
        if ppe.relative_residual.is_nan() {
            return Err(StepError::NonFiniteSolve {
                solve: "pressure",
                step: self.step,
            });
        }
        if !ppe.converged {
            return Err(StepError::PressureNotConverged {
                residual: ppe.relative_residual,
                iterations: ppe.iterations,
                step: self.step,
            });
        }
        Ok(())
    }

    /// Whether particle i flowed at the start of the last step (false before any step).
    pub fn is_flowing(&self, i: usize) -> bool {
        self.strain_invariant
            .get(i)
            .is_some_and(|&pi| self.config.rheology.is_flowing(pi))
    }

    /// Share of fluid particles whose strain-rate invariant is at or below the critical one.
    fn non_flowing_fraction(&self, strain_invariant: &[f64]) -> f64 {
        let p = &self.particles;
        let rheology = self.config.rheology;
        // Whole-number counts: exact in any order.
        let (fluid, resting) = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .filter(|&i| p.kind[i] == ParticleKind::Fluid)
            .map(|i| {
                (
                    1usize,
                    usize::from(!rheology.is_flowing(strain_invariant[i])),
                )
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        if fluid == 0 {
            0.0
        } else {
            resting as f64 / fluid as f64
        }
    }

    /// Neighbour lists of the active particles at the current positions.
    /// Makes sure the lists hold every active pair closer than the Laplacian radius: rebuilt
    /// when some particle has moved more than half the skin since the last build.
    fn rebuild_neighbours(&mut self) {
        let started = Instant::now();
        self.wrap_periodic();
        self.refresh_lists();
        self.timing.neighbours_s += started.elapsed().as_secs_f64();
    }

    /// The kernel-radius pairs at the current positions (after every move of the particles
    /// that later stages see). A wall particle with no fluid particle within the Laplacian
    /// radius gets none: its number density is then 0, so it is a free-surface particle with
    /// p = 0 and no PPE row. Only a wall that is near fluid carries pressure (away from the
    /// fluid a wall's pressure has no meaning; in wall corners it would be a spurious
    /// pressure from the walls' own number density).
    fn refresh_pairs(&mut self) {
        let started = Instant::now();
        let r = &self.refs;
        let kind = &self.particles.kind;
        self.pairs = KernelPairs::near_fluid(
            &self.neighbours,
            &self.particles.position_m,
            r.radius_n_m,
            r.radius_lap_m,
            |i| kind[i] == ParticleKind::Fluid,
        );
        self.paired_at_m.clone_from(&self.particles.position_m);
        self.timing.kernel_pairs_s += started.elapsed().as_secs_f64();
    }

    /// Brings every particle that crossed the periodic seam back into the period (the lists
    /// then see it as moved by a period and are rebuilt).
    fn wrap_periodic(&mut self) {
        let Some(periodic) = self.config.periodic_x else {
            return;
        };
        for x in &mut self.particles.position_m {
            let offset = x[0] - periodic.min_m;
            if !(0.0..periodic.period_m).contains(&offset) {
                x[0] = periodic.min_m + offset.rem_euclid(periodic.period_m);
                // rem_euclid may round up to the period itself.
                if x[0] >= periodic.min_m + periodic.period_m {
                    x[0] = periodic.min_m;
                }
            }
        }
    }

    fn refresh_lists(&mut self) {
        let skin = LIST_SKIN * self.config.spacing_m;
        let p = &self.particles;
        let valid = self.listed_at_m.len() == p.len()
            && max_by(p.len(), |i| {
                if p.kind[i].is_active() {
                    (p.position_m[i] - self.listed_at_m[i]).norm()
                } else {
                    0.0
                }
            }) < 0.5 * skin;
        if valid && !self.fresh_lists {
            return;
        }
        let kind = &p.kind;
        // Operators are evaluated at fluid particles and at wall particles with fluid within
        // reach (see `refresh_pairs`): only they get lists. Dummy layers and walls away from
        // the fluid only fill the support of others.
        let cutoff_m = self.config.radius_lap_m + skin;
        let active = |i: usize| kind[i].is_active();
        self.neighbours = Neighbours::build_centres_then_listed(
            &p.position_m,
            cutoff_m,
            self.config.periodic_x.map(|x| x.period_m),
            active,
            |i| kind[i] == ParticleKind::Fluid,
            |i| kind[i] == ParticleKind::Wall,
        );
        self.listed_at_m = p.position_m.clone();
        self.timing.list_builds += 1;
    }

    /// Lists holding every pair closer than the collision distances: the number-density pairs
    /// of the last cut when no particle has moved far enough since to close a pair from
    /// beyond their radius (a pair closer than d now was closer than d + 2 max|moved| then),
    /// else the Verlet lists. Both are in ascending index order, and collisions skip pairs
    /// beyond d, so either gives the same bits; the pairs are about a fifth as many in 3D.
    fn collision_candidates(&self) -> &Neighbours {
        let c = &self.config;
        let p = &self.particles;
        let reach = c.collision_distance_m.max(c.wall_collision_distance_m);
        if self.paired_at_m.len() != p.len() || self.fresh_lists {
            return &self.neighbours;
        }
        let moved = max_by(p.len(), |i| {
            if p.kind[i].is_active() {
                (p.position_m[i] - self.paired_at_m[i]).norm()
            } else {
                0.0
            }
        });
        // A relative margin for the rounding of the distances.
        if reach + 2.0 * moved < self.refs.radius_n_m * (1.0 - 1e-9) {
            &self.pairs.near
        } else {
            &self.neighbours
        }
    }

    /// Dynamic stabilisation (Tsuruta, Khayyer & Gotoh 2013, simplified): each fluid particle
    /// closer than `distance_m` to another gets the velocity that moves it back by its share
    /// of the shortfall within this step, along the pair's axis: half against fluid (equal and
    /// opposite, so momentum is kept), all against a wall or dummy. Idle when every pair is at
    /// least `distance_m` apart (a lattice at rest).
    fn stabilise_pairs(&mut self, dt_s: f64, distance_m: f64) {
        let nb = &self.pairs.near;
        let dv = self.pair_velocity_changes(nb, |_, j, r| {
            let d = r.norm();
            if d >= distance_m || d == 0.0 {
                return None;
            }
            let share = if self.particles.kind[j] == ParticleKind::Fluid {
                0.5
            } else {
                1.0
            };
            Some(r * (share * (distance_m - d) / (d * dt_s)))
        });
        self.apply_velocity_changes(&dv, dt_s);
    }

    /// For every fluid particle i, minus the sum over its neighbours j in `nb` (in list order)
    /// of `pair(i, j, r_ij)` where it is Some; zero elsewhere.
    fn pair_velocity_changes(
        &self,
        nb: &Neighbours,
        pair: impl Fn(usize, usize, Vector<D>) -> Option<Vector<D>> + Sync,
    ) -> Vec<Vector<D>> {
        let p = &self.particles;
        (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                let mut dv = Vector::<D>::zeros();
                if p.kind[i] != ParticleKind::Fluid {
                    return dv;
                }
                for &j in nb.of(i) {
                    let j = j as usize;
                    if let Some(v) = pair(i, j, nb.displacement(&p.position_m, i, j)) {
                        dv -= v;
                    }
                }
                dv
            })
            .collect()
    }

    /// u += dv, r += dt dv at every particle.
    fn apply_velocity_changes(&mut self, dv: &[Vector<D>], dt_s: f64) {
        let p = &mut self.particles;
        per_particle(&mut p.velocity_m_s, &mut p.position_m, |i, v, x| {
            *v += dv[i];
            *x += dv[i] * dt_s;
        });
    }

    /// (5) Collision model: fluid pairs closer than the collision distance that approach each
    /// other exchange momentum along their line of centres with restitution e (equal masses;
    /// walls are immovable). Jacobi-style: all impulses from the pre-collision velocities.
    /// `walls_only`: fluid-wall pairs only.
    fn collide(&mut self, dt_s: f64, walls_only: bool) {
        let c = &self.config;
        if c.collision_distance_m <= 0.0 {
            return;
        }
        let p = &self.particles;
        let nb = self.collision_candidates();
        let d2 = c.collision_distance_m * c.collision_distance_m;
        let d2_wall = c.wall_collision_distance_m * c.wall_collision_distance_m;
        let e = c.collision_restitution;
        let dv = self.pair_velocity_changes(nb, |i, j, r| {
            if p.kind[j] == ParticleKind::Dummy {
                return None;
            }
            let r2 = r.norm_squared();
            let fluid_pair = p.kind[j] == ParticleKind::Fluid;
            if fluid_pair && walls_only {
                return None;
            }
            if r2 >= (if fluid_pair { d2 } else { d2_wall }) || r2 == 0.0 {
                return None;
            }
            let n = r / r2.sqrt();
            let approach = (p.velocity_m_s[i] - p.velocity_m_s[j]).dot(&n);
            // Only approaching pairs collide; the fluid particle of a fluid-wall pair takes it all.
            (approach > 0.0).then(|| {
                let share = if fluid_pair { 0.5 } else { 1.0 };
                n * ((1.0 + e) * share * approach)
            })
        });
        self.apply_velocity_changes(&dv, dt_s);
    }

    /// n_i with radius re_n at the current positions, over all active particles (dummies
    /// included: they fill the wall's support).
    fn number_density(&self) -> Vec<f64> {
        let p = &self.particles;
        let nb = &self.pairs.near;
        let re = self.refs.radius_n_m;
        (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| number_density(&p.position_m, nb, i, re, |_| true))
            .collect()
    }

    /// Right-hand side of the PPE per particle (see [`SourceTerm`]); `density` is n* for the
    /// number-density source and n^k for the mixed one.
    fn pressure_source(&self, dt_s: f64, density: &[f64]) -> Vec<f64> {
        let c = &self.config;
        let p = &self.particles;
        let nb = &self.pairs.near;
        let refs = self.refs;
        let rho = c.density_kg_m3;
        let density_scale = c.relaxation_coefficient * rho / (dt_s * dt_s);
        let mixed = c.source_term == SourceTerm::Mixed;
        (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                let mut b = density_scale * (density[i] - refs.n0) / refs.n0;
                if mixed && p.kind[i].has_pressure() {
                    // Divergence model: d/n0 sum_j (u_j - u_i) . r_ij w / |r_ij|^2.
                    let mut div = 0.0;
                    for &j in nb.of(i) {
                        let j = j as usize;
                        let r = nb.displacement(&p.position_m, i, j);
                        let r2 = r.norm_squared();
                        let w = weight(r2.sqrt(), refs.radius_n_m);
                        if w > 0.0 {
                            div += (p.velocity_m_s[j] - p.velocity_m_s[i]).dot(&r) * w / r2;
                        }
                    }
                    b -= rho / dt_s * div * (D as f64 / refs.n0);
                }
                b
            })
            .collect()
    }

    /// PPE (Koshizuka & Oka): -<lap p>_i + rho kappa p_i / dt^2 = source_i for fluid and wall
    /// particles not on the surface; p = 0 on the surface (Dirichlet).
    /// Assembled once in CSR and solved by Jacobi-PCG; negative pressure is clipped to 0.
    /// Returns the solver's report and the seconds spent in the CG solve.
    fn solve_pressure(
        &mut self,
        dt_s: f64,
        source: &[f64],
        surface: &[bool],
    ) -> (SolveReport, f64) {
        let p = &self.particles;
        let unknown_of: Vec<u32> = {
            let mut next = 0u32;
            (0..p.len())
                .map(|i| {
                    if p.kind[i].has_pressure() && !surface[i] {
                        next += 1;
                        next - 1
                    } else {
                        u32::MAX
                    }
                })
                .collect()
        };
        let rows: Vec<usize> = (0..p.len())
            .filter(|&i| unknown_of[i] != u32::MAX)
            .collect();
        let (matrix, _) = self.assemble_ppe(
            dt_s,
            &rows,
            &unknown_of,
            |j| p.kind[j].has_pressure(),
            |_| 0.0,
        );
        let rhs: Vec<f64> = rows.iter().map(|&i| source[i]).collect();
        // Warm start from the previous pressure (part of the recorded state, so replays and
        // resumed runs start the solver from the same guess).
        let mut solution: Vec<f64> = rows.iter().map(|&i| p.pressure_pa[i]).collect();
        let solve_started = Instant::now();
        let report = self.solve_ppe_system(&matrix, &rhs, &mut solution, &rows);
        let solve_s = solve_started.elapsed().as_secs_f64();
        let pressure = &mut self.particles.pressure_pa;
        pressure.iter_mut().for_each(|v| *v = 0.0);
        for (k, &i) in rows.iter().enumerate() {
            pressure[i] = solution[k].max(0.0);
        }
        (report, solve_s)
    }

    /// The PPE matrix -<lap>_i + rho kappa / dt^2 (eq. 4, Laplacian radius) on the particles
    /// `rows` (unknown k at particle rows[k], `unknown_of` its inverse, u32::MAX for none),
    /// over the neighbours j with `include(j)`. A neighbour that is no unknown has the known
    /// value `known(j)`; returns per row the sum of a_ij known(j), which belongs on the right
    /// side.
    fn assemble_ppe(
        &self,
        dt_s: f64,
        rows: &[usize],
        unknown_of: &[u32],
        include: impl Fn(usize) -> bool + Sync,
        known: impl Fn(usize) -> f64 + Sync,
    ) -> (CsrMatrix, Vec<f64>) {
        let p = &self.particles;
        let nb = &self.pairs.lap;
        let refs = self.refs;
        let coef = 2.0 * D as f64 / (refs.lambda_m2 * refs.n0_lap);
        let diag_extra =
            self.config.density_kg_m3 * self.config.compressibility_1_pa / (dt_s * dt_s);
        CsrMatrix::assemble(rows.len(), |k, columns, values| {
            let i = rows[k];
            let mut diag = diag_extra;
            let mut known_sum = 0.0;
            for &j in nb.of(i) {
                let j = j as usize;
                if !include(j) {
                    continue;
                }
                let a = coef
                    * weight(
                        nb.displacement(&p.position_m, i, j).norm(),
                        refs.radius_lap_m,
                    );
                if a == 0.0 {
                    continue;
                }
                diag += a;
                if unknown_of[j] != u32::MAX {
                    columns.push(unknown_of[j]);
                    values.push(-a);
                } else {
                    known_sum += a * known(j);
                }
            }
            (diag, known_sum)
        })
    }

    /// Solves the PPE `matrix` (rows at particles `rows`) by PCG from the guess in `solution`,
    /// preconditioned by Jacobi or by aggregation multigrid, whose aggregates follow each
    /// unknown's lattice cell (spacings from the origin).
    fn solve_ppe_system(
        &self,
        matrix: &CsrMatrix,
        rhs: &[f64],
        solution: &mut [f64],
        rows: &[usize],
    ) -> SolveReport {
        let c = &self.config;
        let p = &self.particles;
        let multigrid = c.multigrid_ppe.then(|| {
            let l0 = c.spacing_m;
            let cells: Vec<[i64; 3]> = rows
                .iter()
                .map(|&i| {
                    let x = p.position_m[i];
                    std::array::from_fn(|a| if a < D { (x[a] / l0).floor() as i64 } else { 0 })
                })
                .collect();
            Multigrid::new(matrix, &cells)
        });
        solve_pcg(
            matrix,
            rhs,
            solution,
            c.ppe_tolerance,
            c.ppe_max_iterations,
            multigrid
                .as_ref()
                .map_or(Preconditioner::Jacobi, Preconditioner::Multigrid),
        )
    }

    /// u += -dt/rho <grad p>, r += dt * (change of u), with the gradient model (eq. 3) using
    /// p_j - min_k p_k over i and its neighbours (keeps the pair force repulsive).
    fn correct_with_pressure_gradient(&mut self, dt_s: f64) {
        let p = &self.particles;
        let nb = &self.pairs.near;
        let refs = self.refs;
        let scale = -dt_s / self.config.density_kg_m3;
        let dv: Vec<Vector<D>> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                if p.kind[i] != ParticleKind::Fluid {
                    return Vector::<D>::zeros();
                }
                let mut p_min = p.pressure_pa[i];
                for &j in nb.of(i) {
                    let j = j as usize;
                    if p.kind[j].has_pressure()
                        && weight(nb.displacement(&p.position_m, i, j).norm(), refs.radius_n_m)
                            > 0.0
                    {
                        p_min = p_min.min(p.pressure_pa[j]);
                    }
                }
                gradient(&p.position_m, nb, i, refs.radius_n_m, refs.n0, |j| {
                    p.kind[j].has_pressure().then(|| p.pressure_pa[j] - p_min)
                }) * scale
            })
            .collect();
        let p = &mut self.particles;
        per_particle(&mut p.velocity_m_s, &mut p.position_m, |i, v, x| {
            *v += dv[i];
            *x += dv[i] * dt_s;
        });
    }

    /// Inlets, in order: the next layer of each unfinished inlet whose due time has come is
    /// appended at the end of the particle arrays, unless a fluid particle lies within the
    /// inlet's clearance of one of its positions (then the inlet waits). At most one layer per inlet per
    /// step: a second due layer would sit on the first one, which blocks it.
    fn pour(&mut self) {
        let l0 = self.config.spacing_m;
        for k in 0..self.config.inlets.len() {
            let inlet = &self.config.inlets[k];
            let section = &self.inlet_sections[k];
            let total = inlet.total_count(l0);
            let emitted = self.inlet_emitted[k];
            if emitted >= total || section.is_empty() {
                continue;
            }
            let layer = emitted / section.len() as u64;
            if self.time_s < inlet.layer_due_s(layer, l0) {
                continue;
            }
            let count = section.len().min((total - emitted) as usize);
            let points = &section[..count];
            // Only fluid near the opening can block it: skip the rest with one distance.
            let clearance2 = inlet.clearance_m * inlet.clearance_m;
            let reach = inlet.radius_m + inlet.clearance_m;
            let p = &self.particles;
            let blocked = (0..p.len()).any(|i| {
                p.kind[i] == ParticleKind::Fluid
                    && (p.position_m[i] - inlet.centre_m).norm_squared() <= reach * reach
                    && points
                        .iter()
                        .any(|x| (p.position_m[i] - x).norm_squared() < clearance2)
            });
            if blocked {
                continue;
            }
            let velocity = inlet.unit_direction() * inlet.speed_m_s;
            let p = &mut self.particles;
            for x in points {
                p.push_tagged(*x, ParticleKind::Fluid, inlet.tag);
                *p.velocity_m_s.last_mut().expect("just pushed") = velocity;
            }
            self.inlet_emitted[k] += count as u64;
        }
    }

    /// Blow-up guards after a step (finite state, speed limit); fluid that left the domain
    /// box becomes a ghost, at rest where it left.
    fn check_state(&mut self) -> Result<(), StepError> {
        let c = &self.config;
        // Only fluid particles that fail a guard or left the box need a look, in index order
        // (found in parallel: most steps there are none).
        let p = &self.particles;
        let flagged: Vec<usize> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .filter(|&i| {
                let (x, v) = (p.position_m[i], p.velocity_m_s[i]);
                p.kind[i] == ParticleKind::Fluid
                    && (!x.iter().chain(v.iter()).all(|a| a.is_finite())
                        || v.norm() > c.max_speed_m_s
                        || (0..D).any(|a| x[a] < c.domain_min_m[a] || x[a] > c.domain_max_m[a]))
            })
            .collect();
        let p = &mut self.particles;
        for i in flagged {
            let (x, v) = (p.position_m[i], p.velocity_m_s[i]);
            if !x.iter().chain(v.iter()).all(|a| a.is_finite()) {
                return Err(StepError::NonFinite {
                    particle: i,
                    step: self.step,
                });
            }
            let speed = v.norm();
            if speed > c.max_speed_m_s {
                return Err(StepError::TooFast {
                    particle: i,
                    speed_m_s: speed,
                    limit_m_s: c.max_speed_m_s,
                    step: self.step,
                });
            }
            if (0..D).any(|a| x[a] < c.domain_min_m[a] || x[a] > c.domain_max_m[a]) {
                p.kind[i] = ParticleKind::Ghost;
                self.listed_at_m.clear();
                p.velocity_m_s[i] = Vector::<D>::zeros();
                p.pressure_pa[i] = 0.0;
                if let Some(limit) = c.max_ghost_particles {
                    let ghosts = p.count(ParticleKind::Ghost);
                    if ghosts > limit {
                        let coords: Vec<String> = x.iter().map(|a| format!("{a:.4}")).collect();
                        return Err(StepError::LeftDomain {
                            particle: i,
                            position_m: format!("({}) m", coords.join(", ")),
                            ghosts,
                            limit,
                            step: self.step,
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

/// f(i, velocity_i, position_i) for every particle, in parallel: each particle on its own, so
/// the result does not depend on the split.
fn per_particle<const D: usize>(
    velocity: &mut [Vector<D>],
    position: &mut [Vector<D>],
    f: impl Fn(usize, &mut Vector<D>, &mut Vector<D>) + Sync,
) {
    velocity
        .par_iter_mut()
        .zip(position.par_iter_mut())
        .enumerate()
        .with_min_len(PARTICLES_PER_TASK)
        .for_each(|(i, (v, x))| f(i, v, x));
}
