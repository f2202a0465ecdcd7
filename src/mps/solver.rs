//! One time step of the MPS method (docs/design.md section 3), stage by stage. The stages, in
//! the order [`Solver::step`] runs them (docs/design.md section 3.1 numbers them the same way,
//! and so do the labels in the code):
//! (1) inlets pour and (2) rigid bodies take their path velocity; (3) neighbour lists and
//! kernel pairs (`neighbours.rs`); (4) the carried pressure's force (incremental scheme,
//! `incremental.rs`); (5) implicit viscosity and gravity give u* (`mps/viscosity.rs`);
//! (6) r* = r + dt u*; (7) neighbours again and collisions (`contact.rs`); (8) the projection:
//! pressure and the correction of velocity and position (`standard.rs`, or `incremental.rs`
//! and `exact.rs`); (9) pair stabilisation, particle shifting and (10) a second fluid-wall
//! collision pass (`contact.rs`); (11) the clock advances and the state is checked
//! (`state.rs`).
use super::body::RigidBody;
use super::grid::{KernelPairs, MirrorPlanes, Neighbours};
use super::inlet::Inlet;
use super::kernel::RefValues;
use super::particles::{ParticleKind, Particles, Vector};
use super::pressure::SolveReport;
use super::reduce::PARTICLES_PER_TASK;
use super::reduce::max_by;
use super::rheology::Rheology;
use super::viscosity::{
    FACE_RADIUS_SPACINGS, Loads, SlipWall, StrainRateGradient, ViscousSettings, WallFaces,
    predict_velocity,
};
use super::yield_solve::{Tensor, YieldSolve};
use rayon::prelude::*;
use stage_momentum::StepProbe;
pub use stage_momentum::{STAGE_NAMES, StageMomentum};
use std::time::Instant;

mod conservative;
mod contact;
mod exact;
mod incremental;
mod neighbours;
mod stage_momentum;
mod standard;
mod state;

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
    /// Bingham's law with a rigid state (`yield_solve.rs`); `None`: the regularised law.
    pub yield_solve: Option<YieldSolve>,
    /// Magnitude of gravity, acting along the last axis towards -inf.
    pub gravity_m_s2: f64,
    /// Gravity turned by this angle from -vertical towards +x (an inclined plane as a level
    /// floor under tilted gravity); 0 for a level scene.
    pub gravity_tilt_rad: f64,
    /// x is periodic: positions are kept in [min_m, min_m + period_m) and pairs take the
    /// nearest image across the seam.
    pub periodic_x: Option<PeriodicX>,
    /// Mirror symmetry planes bounding the domain (none: `MirrorPlanes::default()`): the
    /// scene holds the part on their positive side, and every particle near a plane interacts
    /// with the mirror images of its neighbours (a free-slip plane of symmetry).
    pub symmetry: MirrorPlanes,
    pub radius_n_m: f64,
    pub radius_lap_m: f64,
    /// Radius of the strain rate's velocity gradient (m); `radius_n_m` by default.
    pub radius_strain_m: f64,
    /// Radius of the viscous stage's Laplacian (m); `radius_lap_m` by default.
    pub radius_visc_m: f64,
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
    /// Incremental scheme: beta of the increment's regularisation, the same repulsion with
    /// the step's positive increment dp_i in place of p_i, in the correction (0 = off). Zero
    /// at rest on any arrangement.
    pub increment_regularisation: f64,
    /// Incremental scheme: below the surface threshold, a fluid particle whose carried
    /// pressure exceeds `deep_surface_pressure_pa` is on the free surface only if n* is
    /// also below this share of n0 (0 = the threshold alone).
    pub deep_surface_threshold: f64,
    /// The carried pressure above which `deep_surface_threshold` applies (rho g times the
    /// manifest's `deep_surface_head` spacings).
    pub deep_surface_pressure_pa: f64,
    /// Incremental scheme: time constant T (s) of the carried pressure's smoothing toward
    /// the mean of its fluid neighbours' p_j - G_i . r_ij (0 = off; see
    /// `operators::smoothing_sums`). Idle on any linear pressure.
    pub pressure_smoothing_time_s: f64,
    /// Incremental scheme: a free-surface particle holds rho |g| surface_depth_m
    /// max(-n . g/|g|, 0) (0 = p = 0 at surface particles).
    pub surface_depth_m: f64,
    /// The lowest pressure a particle may carry (Pa, <= 0): the clip of the PPE's solution
    /// (standard) and of the carried pressure (incremental). 0: negative pressure clipped.
    pub pressure_floor_pa: f64,
    /// Incremental scheme: A of the particle shifting dr = -A l0^2 sqrt(Pi) dt (d/n0)
    /// sum_j r_ij w(r_ij)/r_ij^2, kept to the tangent plane where a particle's stencil is
    /// incomplete (0 = off). Idle at rest and in rigid motion (Pi = 0).
    pub particle_shifting: f64,
    /// Largest shift per step (m).
    pub particle_shifting_limit_m: f64,
    /// How the strain rate's velocity gradient is estimated.
    pub strain_rate_gradient: StrainRateGradient,
    /// No-slip at the walls' surface, not at the wall particles (see
    /// [`crate::mps::viscosity::ViscousSettings::wall_surface_m`]).
    pub wall_surface_no_slip: bool,
    /// With `wall_surface_no_slip`, each wall particle's own face for the extrapolation
    /// ([`crate::mps::viscosity::WallFaces`]) instead of one plane fitted per fluid particle.
    pub wall_face_normals: bool,
    /// The no-slip walls' ghost velocities on the fluid's parabola (`mps.wall_curvature`,
    /// [`crate::mps::viscosity::ViscousSettings::wall_curvature`]).
    pub wall_curvature: bool,
    /// Incremental scheme: the increment's equation is -D G with the correction's own
    /// divergence and gradient (exact projection, `solver/exact.rs`) instead of the MPS
    /// Laplacian model.
    pub exact_projection: bool,
    /// Incremental scheme: the carried pressure's gradient with its fluid coefficients made
    /// momentum-conserving (`solver/conservative.rs`).
    pub conservative_gradient: bool,
    /// Incremental scheme: the increment's equation is G^T G with the correction's gradient
    /// rows G (the carried gradient's under `conservative_gradient`): an orthogonal
    /// projection (`solver/exact.rs`).
    pub adjoint_projection: bool,
    /// Incremental scheme: the walls' hydrostatic pressure (and the pressure smoothing's)
    /// without gravity's component along the periodic axis ([`Solver::hydrostatic_gravity`]).
    pub periodic_hydrostatic: bool,
    /// Aggregation multigrid instead of Jacobi as the PPE preconditioner.
    pub multigrid_ppe: bool,
    /// Factor on the multigrid cycle's coarse-grid corrections (1: plain aggregation).
    pub multigrid_over_correction: f64,
    /// The multigrid's finest smoothing reads the matrix in single precision.
    pub multigrid_single_precision: bool,
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
    /// Cell-grid (Verlet) list builds and their count, and the partial updates
    /// (`Neighbours::updated`).
    pub neighbours_s: f64,
    pub list_builds: u64,
    pub list_updates: u64,
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

impl StageTimes {
    /// The solver's stages as (label, seconds) rows over `steps` steps, in the order `runner
    /// bench` prints them (its suite reads the labels back), "other" being the step's time
    /// left over by the named stages.
    pub fn stage_rows(&self, steps: f64) -> [(String, f64); 6] {
        let per_step = |total: u64| total as f64 / steps.max(1.0);
        let other = self.step_total_s
            - self.neighbours_s
            - self.kernel_pairs_s
            - self.viscosity_s
            - self.pressure_assembly_s
            - self.pressure_solve_s;
        [
            (
                format!(
                    "neighbour lists ({} cell-grid builds, {} updates)",
                    self.list_builds, self.list_updates
                ),
                self.neighbours_s,
            ),
            (
                "kernel pairs (lists cut to radii)".to_string(),
                self.kernel_pairs_s,
            ),
            (
                format!(
                    "viscosity (strain, assembly, CG {:.1} it/step)",
                    per_step(self.viscosity_iterations)
                ),
                self.viscosity_s,
            ),
            (
                "PPE assembly (n*, surface, source, CSR)".to_string(),
                self.pressure_assembly_s,
            ),
            (
                format!(
                    "PPE solve (CG {:.1} it/step)",
                    per_step(self.ppe_iterations)
                ),
                self.pressure_solve_s,
            ),
            (
                "other solver stages (collision, correction)".to_string(),
                other,
            ),
        ]
    }
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
    /// The yield solve's iterations in the step (0 without it); `viscosity` sums their CG
    /// iterations.
    pub yield_iterations: u32,
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
    /// With the yield solve, each particle's yield stress multiplier from the last step (Pa).
    pub yield_stress_pa: Vec<Tensor<D>>,
    /// The yield solve's adaptive penalty carried to the next step, in Pa s (0: none, the
    /// manifest's penalty; always 0 without `mps.yield_penalty_adaptive`).
    pub yield_penalty_pa_s: f64,
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
    /// With `Some`, each step adds what its stages do to the fluid's momentum, band by band
    /// (a diagnostic; nothing of the state depends on it).
    pub stage_momentum: Option<StageMomentum>,
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
            RefValues::on_lattice::<D>(config.spacing_m, config.radius_n_m, config.radius_lap_m)
                .with_strain_radius::<D>(config.spacing_m, config.radius_strain_m)
                .with_viscous_radius::<D>(config.spacing_m, config.radius_visc_m);
        let inlet_sections = config
            .inlets
            .iter()
            .map(|inlet| inlet.cross_section_beside_m(config.spacing_m, &config.symmetry))
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
            yield_stress_pa: Vec::new(),
            yield_penalty_pa_s: 0.0,
            neighbours: Neighbours::default(),
            pairs: KernelPairs::default(),
            paired_at_m: Vec::new(),
            listed_at_m: Vec::new(),
            fresh_lists: false,
            timing: StageTimes::default(),
            stage_momentum: None,
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

    /// The gravity whose rho g . r_ij the walls' pressure adds (and the pressure smoothing
    /// carries along): with `periodic_hydrostatic` and a periodic x, without its x component.
    /// Along a period a steady flow's mean pressure gradient is zero (the inclined layer's
    /// shear stress carries the slope's component); with the whole g a wall under a layer
    /// on a 5 degree slope pushed its lowest band up the slope by 18 % of its driving force
    /// (docs/validation.md, "The walls' pressure along a periodic slope").
    pub(crate) fn hydrostatic_gravity(&self) -> Vector<D> {
        let mut g = self.gravity();
        if self.config.periodic_hydrostatic && self.config.periodic_x.is_some() {
            g[0] = 0.0;
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

    /// The inlets that still have particles to pour (started or not).
    fn pouring_inlets(&self) -> impl Iterator<Item = &Inlet<D>> {
        let c = &self.config;
        c.inlets
            .iter()
            .zip(&self.inlet_emitted)
            .filter(|(inlet, emitted)| **emitted < inlet.total_count(c.spacing_m))
            .map(|(inlet, _)| inlet)
    }

    /// Whether an inlet still has particles to pour (started or not).
    pub fn pouring(&self) -> bool {
        self.pouring_inlets().next().is_some()
    }

    /// Time step from the CFL condition (Courant number on the largest speed) and dt_max, never
    /// past `end_time_s`. Viscosity is implicit, so it sets no limit. An inlet that pours
    /// during the next step (started or starting within dt_max, not finished) counts with its
    /// inflow speed.
    pub fn next_dt_s(&self, end_time_s: f64) -> f64 {
        let c = &self.config;
        let mut dt = c.dt_max_s;
        let mut speed = self.max_fluid_speed_m_s();
        for inlet in self.pouring_inlets() {
            if self.time_s + c.dt_max_s >= inlet.start_s {
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
            yield_solve: c.yield_solve,
            wall_curvature: c.wall_curvature.then_some(c.spacing_m),
            slip_walls: c
                .bodies
                .iter()
                .filter_map(|b| {
                    b.slip_length_m.map(|slip_length_m| SlipWall {
                        particles: b.first..b.end,
                        slip_length_m,
                        surface_m: 0.5 * c.spacing_m,
                    })
                })
                .collect(),
        }
    }

    /// Advances the state by dt_s.
    pub fn step(&mut self, dt_s: f64) -> Result<StepReport, StepError> {
        let started = Instant::now();
        let mut sums = self.stage_momentum.take();
        let result = self.step_stages(dt_s, sums.as_mut());
        if let Some(s) = &mut sums
            && result.is_ok()
        {
            s.time_s += dt_s;
            s.steps += 1;
        }
        self.stage_momentum = sums;
        self.timing.step_total_s += started.elapsed().as_secs_f64();
        result
    }

    fn step_stages(
        &mut self,
        dt_s: f64,
        sums: Option<&mut StageMomentum>,
    ) -> Result<StepReport, StepError> {
        // (1) Inlets pour; (2) rigid bodies carry their path velocity during the step (a
        // moving no-slip wall for the viscous stage).
        self.pour();
        for body in &self.config.bodies {
            let velocity = body.path.velocity_m_s(self.time_s);
            for v in &mut self.particles.velocity_m_s[body.first..body.end] {
                *v = velocity;
            }
        }
        // (3) Neighbours at the current positions.
        self.rebuild_neighbours();
        self.refresh_pairs();
        let mut probe = sums.map(|s| StepProbe::start(s, &self.particles));
        // (4) The carried pressure's force and (5) viscosity (implicit, with the effective
        // viscosity of the rheology) and gravity give the predicted velocity u*.
        let start_density = match self.config.source_term {
            SourceTerm::Mixed => Some(self.number_density()),
            SourceTerm::NumberDensity => None,
        };
        let incremental = self.config.pressure_scheme == PressureScheme::Incremental;
        let pressure_accel = incremental.then(|| self.carried_pressure_acceleration());
        let viscosity_started = Instant::now();
        let settings = self.viscous_settings();
        // Faces in front of the walls at the no-slip surface's own distance.
        let faces = settings
            .wall_surface_m
            .filter(|_| self.config.wall_face_normals)
            .map(|surface_m| {
                WallFaces::build(
                    &self.particles,
                    &self.neighbours,
                    FACE_RADIUS_SPACINGS * self.config.spacing_m,
                    surface_m,
                )
            });
        let stage = predict_velocity(
            &self.particles,
            &self.pairs,
            &self.refs,
            &settings,
            Loads {
                body_force_m_s2: self.gravity(),
                pressure_accel_m_s2: pressure_accel.as_deref(),
                yield_stress_pa: &self.yield_stress_pa,
                yield_penalty_pa_s: self.yield_penalty_pa_s,
                wall_faces: faces.as_ref(),
            },
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
        if let Some(probe) = &mut probe {
            // The prediction's three parts: u* = u + dt (g + a_p) + the implicit viscous and
            // yield step's change.
            let axis = probe.axis();
            let body = self.gravity()[axis] * dt_s;
            let carried = |i: usize| pressure_accel.as_deref().map_or(0.0, |a| a[i][axis] * dt_s);
            probe.add(0, carried);
            probe.add(6, |_| body);
            probe.add(1, |i| {
                stage.velocity_m_s[i][axis]
                    - body
                    - carried(i)
                    - self.particles.velocity_m_s[i][axis]
            });
            probe.reset(&stage.velocity_m_s);
        }
        let non_flowing_fraction = self.non_flowing_fraction(&stage.strain_invariant);
        self.strain_invariant = stage.strain_invariant;
        self.yield_stress_pa = stage.yield_stress_pa;
        self.yield_penalty_pa_s = stage.yield_penalty_pa_s;
        // (6) r* = r + dt u*.
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

        self.check_prediction()?;
        // (7) Neighbours at the predicted positions, used by every later stage of the step.
        self.rebuild_neighbours();
        self.collide(dt_s, false);
        if let Some(probe) = &mut probe {
            probe.mark(2, &self.particles.velocity_m_s);
        }
        self.refresh_pairs();

        // (8) Pressure, and the correction of velocity and position.
        let (ppe, surface_count) = if incremental {
            self.incremental_projection(dt_s)?
        } else {
            self.standard_projection(dt_s, start_density.as_deref())?
        };
        if let Some(probe) = &mut probe {
            probe.mark(3, &self.particles.velocity_m_s);
        }
        // (9) Pair stabilisation and particle shifting, (10) fluid-wall collisions once more.
        if incremental && self.config.pair_stabilisation_m > 0.0 {
            self.stabilise_pairs(dt_s, self.config.pair_stabilisation_m);
        }
        if incremental && self.config.particle_shifting > 0.0 {
            self.shift_particles(dt_s);
        }
        if let Some(probe) = &mut probe {
            probe.mark(4, &self.particles.velocity_m_s);
        }
        if self.config.wall_collision_second_pass {
            // The correction can push a free-surface particle into a gap of the wall lattice
            // (see `wall_collision_distance_m`): fluid-wall pairs collide once more.
            self.collide(dt_s, true);
        }

        if let Some(probe) = &mut probe {
            probe.mark(5, &self.particles.velocity_m_s);
        }
        // (11) The clock, and the state's check.
        self.time_s += dt_s;
        self.step += 1;
        self.check_state()?;
        Ok(StepReport {
            dt_s,
            ppe,
            viscosity: stage.solve,
            yield_iterations: stage.yield_iterations,
            non_flowing_fraction,
            surface_count,
        })
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
