//! The typed experiment manifest.
//!
//! Every struct rejects unknown fields, and every field that has a default gets it through
//! `#[serde(default = ...)]`, so a deserialized [`Manifest`] is always fully resolved.
//! Units are part of the field names (SI throughout).
//!
//! Adding a variant to [`Fluid`] needs: the variant here, its name in [`Fluid::model_name`],
//! and its checks in `validate.rs` (the compiler points at every `match` that must learn
//! about it). Scene sections belong to the test modules (see [`SceneSection`]).

use serde::{Deserialize, Serialize};

use super::boundaries::Boundaries;
use super::checker::Checker;
use super::preset::PresetName;

/// A complete experiment description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest<S> {
    /// Experiment name, `[A-Za-z0-9_.-]{1,64}`; it becomes part of file names.
    pub name: String,
    /// Spatial dimension: 2 or 3.
    pub dimension: u32,
    /// Initial particle spacing l0 in metres.
    pub spacing_m: f64,
    /// Gravitational acceleration in m/s^2, acting along -y in 2D and -z in 3D.
    #[serde(default = "default_gravity_m_s2")]
    pub gravity_m_s2: f64,
    /// Time integration.
    pub time: Time,
    /// Fluid model and material constants.
    pub fluid: Fluid,
    /// MPS method parameters.
    #[serde(default)]
    pub mps: Mps,
    /// The test and its geometry: one section per workability test, tagged by `kind`
    /// (defined by the test's module, see [`SceneSection`]).
    pub scene: S,
    /// Obstacles, moving bodies, inlets and tag regions any test can add (empty by default).
    #[serde(default)]
    pub boundaries: Boundaries,
    /// What is recorded and how often.
    #[serde(default)]
    pub output: Output,
    /// When a run stops (besides `time.end_s`).
    #[serde(default)]
    pub stop: Stop,
}

impl<S: SceneSection> Manifest<S> {
    /// The `kind` tag of the scene, e.g. `"dam_break"`.
    pub fn scene_kind(&self) -> &'static str {
        self.scene.kind_name()
    }

    /// The smallest time step the run may take: `time.dt_min_s`, or when null
    /// min(courant spacing_m / stop.max_speed_m_s, time.dt_max_s): the smallest step the
    /// CFL rule gives below the speed guard, so the default never fires before the guard.
    pub fn dt_min_s(&self) -> f64 {
        self.time.dt_min_s.unwrap_or_else(|| {
            (self.time.courant * self.spacing_m / self.stop.max_speed_m_s)
                .min(self.largest_step_s())
        })
    }

    /// The largest step: `time.dt_max_s`, and with `time.acoustic_courant` A at most
    /// A spacing_m sqrt(rho kappa) (A spacings per artificial sound speed). The increment's
    /// compressibility term rho kappa / dt^2 stands to the Laplacian's 1 / l0^2 as
    /// (l0 / (c dt))^2: under a fixed `dt_max_s` that share falls as l0^2, and with it the
    /// damping it gives (docs/performance.md, "The 2D default's solver").
    pub fn largest_step_s(&self) -> f64 {
        match self.time.acoustic_courant {
            Some(a) => self.time.dt_max_s.min(
                a * self.spacing_m
                    * (self.fluid.density_kg_m3() * self.mps.compressibility_1_pa).sqrt(),
            ),
            None => self.time.dt_max_s,
        }
    }
}

/// What the manifest needs to know of a `scene:` section. The sections themselves belong to
/// the test modules (`src/experiment/`), which implement this trait; the manifest only
/// parses, checks, canonicalises and hashes them (data flows manifest -> test module).
pub trait SceneSection:
    Serialize + serde::de::DeserializeOwned + Clone + PartialEq + std::fmt::Debug + 'static
{
    /// The `kind` tag, e.g. `"dam_break"`.
    fn kind_name(&self) -> &'static str;
    /// Checks of the section (field paths `scene.*`) and of how the rest of the manifest fits
    /// the test (e.g. its dimension), reported through `c` in field order.
    fn check(&self, m: &Manifest<Self>, c: &mut Checker);
    /// Names of the metrics this test reports for `m` (diagnostics and summary).
    fn metric_names(&self, m: &Manifest<Self>) -> Vec<String>;
    /// One section per kind with its defaults (for learning the manifest's field paths).
    fn samples() -> Vec<Self>;
}

fn default_gravity_m_s2() -> f64 {
    9.81
}

/// Time integration settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Time {
    /// Simulated end time in seconds.
    pub end_s: f64,
    /// Upper bound of the time step in seconds.
    #[serde(default = "default_dt_max_s")]
    pub dt_max_s: f64,
    /// Courant number of the CFL time-step condition.
    #[serde(default = "default_courant")]
    pub courant: f64,
    /// Smallest time step a run may take (s); a step forced below it fails the run (the
    /// last step to `end_s` excepted). null = see [`Manifest::dt_min_s`].
    #[serde(default)]
    pub dt_min_s: Option<f64>,
    /// Largest step as an acoustic Courant number A: dt <= A spacing_m / c, with c = 1 /
    /// sqrt(rho kappa) the artificial sound speed of `mps.compressibility_1_pa`. null = no
    /// such bound (the rule before the field).
    #[serde(default)]
    pub acoustic_courant: Option<f64>,
}

fn default_dt_max_s() -> f64 {
    1.0e-3
}
fn default_courant() -> f64 {
    0.2
}

/// Fluid model, tagged by the `model` key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum Fluid {
    /// A Newtonian fluid.
    Newtonian {
        /// Density in kg/m^3.
        density_kg_m3: f64,
        /// Dynamic viscosity in Pa s.
        viscosity_pa_s: f64,
    },
    /// Bingham fluid of seed 000 (eqs. 6-7): eta + tau_y/sqrt(Pi) while flowing,
    /// eta + tau_y/sqrt(Pi_c) when Pi <= Pi_c = (2 pi_c)^2.
    Bingham {
        /// Density in kg/m^3.
        density_kg_m3: f64,
        /// Plastic viscosity eta in Pa s.
        plastic_viscosity_pa_s: f64,
        /// Yield stress tau_y in Pa.
        yield_stress_pa: f64,
        /// pi_c: critical strain rate in 1/s (non-flowing below it).
        critical_strain_rate_1_s: f64,
        /// Seed 000 eq. 8 stress-gradient term 2 e . grad(Lambda) (off = "analysis example 1").
        #[serde(default = "default_true")]
        stress_gradient_term: bool,
    },
    /// Bi-viscosity model of seed 004: mu_r below gamma_c = tau_0/(mu_r - mu_p), else
    /// mu_p + tau_0/gamma_dot.
    BiViscosity {
        /// Density in kg/m^3.
        density_kg_m3: f64,
        /// Plastic viscosity mu_p in Pa s.
        plastic_viscosity_pa_s: f64,
        /// Yield stress tau_0 in Pa.
        yield_stress_pa: f64,
        /// Rigid viscosity mu_r in Pa s (> plastic viscosity; >= 1000 times it for ~1 % model error).
        rigid_viscosity_pa_s: f64,
        /// Seed 000 eq. 8 stress-gradient term.
        #[serde(default = "default_true")]
        stress_gradient_term: bool,
    },
}

fn default_true() -> bool {
    true
}

impl Fluid {
    /// The `model` tag, e.g. `"newtonian"`.
    pub fn model_name(&self) -> &'static str {
        match self {
            Fluid::Newtonian { .. } => "newtonian",
            Fluid::Bingham { .. } => "bingham",
            Fluid::BiViscosity { .. } => "bi_viscosity",
        }
    }

    /// Density in kg/m^3 (every model has one).
    pub fn density_kg_m3(&self) -> f64 {
        match self {
            Fluid::Newtonian { density_kg_m3, .. }
            | Fluid::Bingham { density_kg_m3, .. }
            | Fluid::BiViscosity { density_kg_m3, .. } => *density_kg_m3,
        }
    }
}

/// MPS method parameters. Radii and distances are in units of `spacing_m`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mps {
    /// Effective radius re for number density and gradient (units of spacing).
    #[serde(default = "default_number_density_radius")]
    pub number_density_radius: f64,
    /// Effective radius re for the Laplacian (units of spacing).
    #[serde(default = "default_laplacian_radius")]
    pub laplacian_radius: f64,
    /// beta: a particle is on the free surface when n* < beta n0.
    #[serde(default = "default_surface_threshold")]
    pub surface_threshold: f64,
    /// gamma, relaxation coefficient of the PPE source term.
    #[serde(default = "default_relaxation_coefficient")]
    pub relaxation_coefficient: f64,
    /// Source term of the pressure Poisson equation: `number_density` (Koshizuka & Oka) or
    /// `mixed` (Tanaka & Masunaga 2010: velocity divergence plus relaxed density error).
    #[serde(default = "default_source_term")]
    pub source_term: PpeSource,
    /// One switch for a whole set of the fields below: `quiet` (the quiet core: the
    /// incremental scheme with its stabilisers, and for a fluid with a yield stress the rigid
    /// state by the augmented Lagrangian; docs/validation.md, "Holding still") or `standard`
    /// (those fields at their defaults). null = none. A field written beside the preset
    /// wins over it in the same place (the file, or `--set`); a preset set by `--set` wins
    /// over the file's fields. Resolved into the fields before validation and left out of
    /// the canonical form (`src/manifest/preset.rs` lists its values).
    #[serde(default)]
    pub preset: Option<PresetName>,
    /// How pressure is found and applied: `standard` (Koshizuka & Oka: the PPE gives the whole
    /// pressure from `source_term`, gradient with p_j - p_min; files written before the choice
    /// existed used it) or `incremental` (the pressure is carried between steps and the PPE
    /// gives its increment from the velocity divergence; consistent gradient, walls mirror
    /// the pressure hydrostatically: a fluid at rest is an exact fixed point). With
    /// `incremental`, `source_term` and `relaxation_coefficient` are unused.
    #[serde(default)]
    pub pressure_scheme: PressureSchemeName,
    /// gamma_c of the incremental scheme: relaxation of its compression term
    /// gamma_c rho/dt^2 max(n* - n0, 0)/n0. In [0, 1]. Unused by `standard`.
    #[serde(default = "default_compression_relaxation")]
    pub compression_relaxation: f64,
    /// Incremental scheme, units of spacing: after the correction, fluid pairs closer than
    /// this are pushed back to it within the step (dynamic stabilisation, Tsuruta, Khayyer &
    /// Gotoh 2013); a fluid-wall pair moves the fluid particle alone. 0 = off. In [0, 1).
    /// Idle on a lattice. Unused by `standard`.
    #[serde(default)]
    pub pair_stabilisation: f64,
    /// Incremental scheme, units of spacing: a wall particle with a fluid particle closer than
    /// this becomes an unknown of the increment's PPE (its own velocity divergence as the
    /// source), and that fluid particle's carried gradient sees its walls no lower than
    /// itself, so walls push back on fluid driven into them. 0 = off. In [0, 1). Idle at rest
    /// (fluid sits a spacing from the walls). Unused by `standard`.
    #[serde(default)]
    pub wall_support: f64,
    /// Incremental scheme, dimensionless beta: each fluid particle i also feels
    /// -(beta p_i/rho) (d/n0) sum_j r_ij w_s(r_ij)/r_ij^2 over every neighbour closer than
    /// `regularisation_radius` (w_s the MPS weight of that radius): a repulsion that grows as a
    /// neighbour comes closer, in proportion to the particle's pressure. Zero on a lattice at
    /// rest (the first shell is complete in the interior, walls and dummies complete it at
    /// walls, and surface particles hold p = 0). 0 = off. Unused by `standard`.
    #[serde(default)]
    pub pressure_regularisation: f64,
    /// Radius of `pressure_regularisation` in units of spacing, in (1, 2): beyond the first
    /// shell of neighbours (the lattice's diagonal sqrt(2) included at the default), short of
    /// the second, so that the row below a flat surface has its whole shell. In 3D below
    /// 1.478, where the shell still resists a shear of its rows (1.5 does not).
    #[serde(default = "default_regularisation_radius")]
    pub regularisation_radius: f64,
    /// Incremental scheme, dimensionless beta: in the correction each interior fluid particle
    /// with a positive pressure increment dp_i also feels -(beta dp_i/rho) (d/n0)
    /// sum_j r_ij w_s(r_ij)/r_ij^2 over the neighbours within `regularisation_radius`: the
    /// pressure regularisation's repulsion in proportion to the step's increment instead of
    /// the carried pressure, so it is idle at rest whatever the arrangement and carries no
    /// friction in proportion to the depth. 0 = off. In [0, 100]. Unused by `standard`.
    #[serde(default)]
    pub increment_regularisation: f64,
    /// Incremental scheme: a fluid particle below `surface_threshold` whose carried pressure
    /// exceeds that of `deep_surface_head` spacings of fluid (rho g h l0) is on the free
    /// surface only if its number density is also below this share of n0. Deep in the
    /// material a free surface is a cavity's wall, far below the threshold; a particle that
    /// only dips under it (beside a rock's stepped surface, in the loose packing a pour
    /// leaves) keeps its row instead of flickering to the surface's pressure, a drop of
    /// several kPa that jolts its neighbours (docs/validation.md, "The rock bed's residual
    /// stir"). 0 = off (the threshold alone, at any depth). In [0, `surface_threshold`).
    /// Unused by `standard`.
    #[serde(default)]
    pub deep_surface_threshold: f64,
    /// Incremental scheme, spacings: the depth, as carried pressure over rho g l0, below
    /// which `deep_surface_threshold` applies. In (0, 1000]. Read only with it on.
    #[serde(default = "default_deep_surface_head")]
    pub deep_surface_head: f64,
    /// Incremental scheme, seconds: after each step every interior fluid particle's carried
    /// pressure moves a share dt/T of the way toward the kernel-weighted mean of its fluid
    /// neighbours' pressures carried back to it along their fitted plane, p_j - G_i . r_ij
    /// (G_i their corrected gradient). Idle for any linear pressure; it removes the
    /// particle-scale noise that the increment leaves where the predicted velocity has no
    /// divergence (rigid material), which the velocity correction never sees. 0 = off. In
    /// [0, 1000]. Unused by `standard`.
    #[serde(default)]
    pub pressure_smoothing_time_s: f64,
    /// Incremental scheme, units of spacing, in [0, 1]: a free-surface particle holds the
    /// hydrostatic pressure of this depth of fluid beyond its centre along its outward normal,
    /// rho |g| d l0 max(-n . g/|g|, 0) (n from its neighbours, walls standing above it left
    /// out), instead of 0: the surface lies half a spacing beyond the surface particles'
    /// centres, so 0.5 puts the zero of pressure there. 0 = off (p = 0 at the centres).
    /// Unused by `standard`.
    #[serde(default)]
    pub surface_depth: f64,
    /// The lowest (gauge) pressure a particle may carry, in Pa, in [-101325, 0]: the PPE's
    /// solution (standard) or the carried pressure (incremental) is clipped to it. 0 = the
    /// usual MPS clip of negative pressure; below 0 the concrete can pull (suction), down to
    /// vacuum at -101325 Pa. Left out of the canonical form while 0.
    #[serde(default)]
    pub pressure_floor_pa: f64,
    /// Incremental scheme, dimensionless A of the particle shifting (Fickian, Lind et al.
    /// 2012, with a diffusion coefficient A l0^2 sqrt(Pi) that follows the local shear rate):
    /// after the correction each fluid particle is shifted by
    /// -A l0^2 sqrt(Pi) dt (d/n0) sum_j r_ij w(r_ij)/r_ij^2, away from its closest
    /// neighbours; where its stencil is incomplete (n < n0: at and under the free surface)
    /// only along the surface, so that the fluid keeps its volume. Idle at rest, under a
    /// uniform motion and in unyielded material. 0 = off. In [0, 1000]. Unused by `standard`.
    #[serde(default)]
    pub particle_shifting: f64,
    /// Largest shift per step, units of spacing, in (0, 0.5]. Read only with
    /// `particle_shifting` on.
    #[serde(default = "default_particle_shifting_limit")]
    pub particle_shifting_limit: f64,
    /// The velocity gradient of the strain rate with the corrective matrix (first-order
    /// consistent, as the incremental scheme's pressure gradient) instead of the plain MPS
    /// gradient model, which is short by up to half near the free surface and walls.
    #[serde(default)]
    pub corrected_strain_rate: bool,
    /// The no-slip condition at the walls' surface, half a spacing in front of their first
    /// row, instead of at the wall particles: in the viscous term and the strain rate a wall
    /// or dummy neighbour's velocity is extrapolated linearly through that surface (Morris,
    /// Fox & Zhu 1997). Without it a sheared layer slips by half a spacing at the floor.
    #[serde(default)]
    pub wall_surface_no_slip: bool,
    /// With `wall_surface_no_slip`: each wall particle's own face (its outward normal from
    /// the wall particles around it) for the extrapolation, instead of one plane fitted to all
    /// of a fluid particle's wall neighbours, which misplaces the surface near an edge (a
    /// floor under a side wall) by up to a spacing. Experimental, off by default.
    #[serde(default)]
    pub wall_face_normals: bool,
    /// With `wall_surface_no_slip` and `wall_face_normals`: a wall neighbour's ghost velocity
    /// continues the parabola that fits the fluid along the wall's normal instead of the line
    /// through the wall and the particle (exact for a curved profile; lagged a step, zero at
    /// rest). Experimental.
    #[serde(default)]
    pub wall_curvature: bool,
    /// The strain rate's velocity gradient from a weighted least-squares fit of a quadratic
    /// velocity field over the neighbours (exact for a parabolic profile: a sheared zone one
    /// or two spacings thick), instead of the gradient model. Not with
    /// `corrected_strain_rate`.
    #[serde(default)]
    pub quadratic_strain_rate: bool,
    /// Radius of the strain rate's velocity gradient, in units of spacing (null: the
    /// number-density radius). A layer a few particles thick moving as a plug over a sheared
    /// bottom row reads shear in every row whose stencil reaches the wall; a stencil of the
    /// first shell (1.5) keeps the shear where it is. In (1, 5] and at most
    /// `laplacian_radius` (the neighbour lists' reach).
    #[serde(default)]
    pub strain_rate_radius: Option<f64>,
    /// Radius of the viscous stage's Laplacian, in units of spacing (null: `laplacian_radius`,
    /// which the pressure keeps). The viscous solve's matrix has one entry per neighbour in
    /// it: a 3D row holds about 125 at 3.1, 32 at 2.1 and 18 at 1.5. Under the yield solve
    /// set it with `strain_rate_radius`: the two stencils must agree on where the shear
    /// starts (`tests/integration/bingham.rs`). In (1, `laplacian_radius`].
    #[serde(default)]
    pub viscous_laplacian_radius: Option<f64>,
    /// Incremental scheme: the increment's equation built from the very divergence and
    /// gradient that measure and correct the velocity (-D G, an exact projection: the
    /// corrected velocity has the divergence asked for), instead of the MPS Laplacian model.
    /// Supporting walls (`wall_support`) are unknowns of it too. Unused by `standard`.
    #[serde(default)]
    pub exact_projection: bool,
    /// Incremental scheme: the carried pressure's gradient with the coefficients of its fluid
    /// neighbours changed by the least amount after which each row stays exact for a linear
    /// pressure and the fluid's pressure forces on itself sum to zero (momentum conserved
    /// off the lattice). Unused by `standard`.
    #[serde(default)]
    pub conservative_gradient: bool,
    /// Incremental scheme, experimental: the increment's equation is G^T G dp = (rho/dt)
    /// G^T u* with G the correction's own gradient rows (the carried gradient's rows under
    /// `conservative_gradient`) and G^T the divergence adjoint to it, so the projection is
    /// orthogonal: it removes kinetic energy and never adds any. Not with `exact_projection`.
    /// Unused by `standard`.
    #[serde(default)]
    pub adjoint_projection: bool,
    /// Incremental scheme: the hydrostatic pressure that the wall and dummy particles carry
    /// (p_i + rho g . r_ij) leaves out gravity's component along a periodic axis, along
    /// which a steady periodic flow's pressure has no gradient (the inclined layer, whose
    /// shear stress carries that component). Changes nothing without a periodic axis or
    /// with level gravity. Unused by `standard`.
    #[serde(default)]
    pub periodic_hydrostatic: bool,
    /// Penalty r of Bingham's law with a rigid state, in Pa s: the viscous stage minimises
    /// the step's dissipation by an augmented Lagrangian (`src/mps/yield_solve.rs`), so that
    /// material whose stress stays below the yield stress has exactly zero strain rate,
    /// instead of the regularised law's non-flowing viscosity. 0 = off (the regularised law;
    /// `fluid.critical_strain_rate_1_s` or the rigid viscosity then only say which particles
    /// count as flowing). A Bingham or bi-viscosity fluid without `stress_gradient_term`.
    #[serde(default)]
    pub yield_penalty_pa_s: f64,
    /// Most augmented-Lagrangian iterations per step (each one a CG solve).
    #[serde(default = "default_yield_max_iterations")]
    pub yield_max_iterations: u32,
    /// The iterations stop when the law's strain rate and the velocity's agree, and the law's
    /// changed over the last iteration, within this equivalent shear rate everywhere, in 1/s.
    #[serde(default = "default_yield_tolerance_1_s")]
    pub yield_tolerance_1_s: f64,
    /// Whether the penalty adapts by residual balancing (Boyd et al. 2011, sec. 3.4.1):
    /// `yield_penalty_pa_s` is then where it starts, and the penalty reached is carried from
    /// step to step (in the checkpoints). Off: the penalty stays fixed.
    #[serde(default)]
    pub yield_penalty_adaptive: bool,
    /// Each row of the yield solve gets its own penalty, the law's secant viscosity at the
    /// step's start, at most `yield_penalty_pa_s` (`src/mps/yield_solve.rs`, `row_weights`).
    /// Off: one penalty for every row, as before.
    #[serde(default)]
    pub yield_penalty_local: bool,
    /// Each iteration's velocity solve stops once its residual bounds the strain-rate error it
    /// leaves to this fraction of `yield_tolerance_1_s` (`src/mps/yield_solve.rs`, inexact
    /// u steps); 0 = solve to `viscosity_tolerance`, as before.
    #[serde(default)]
    pub yield_velocity_fraction: f64,
    /// With `yield_velocity_fraction`: each velocity solve's floor scales with how far the
    /// iterations still are from `yield_tolerance_1_s` (`src/mps/yield_solve.rs`, `solve`).
    /// Off: the fraction of the tolerance in every iteration, as before.
    #[serde(default)]
    pub yield_velocity_relative: bool,
    /// Anderson acceleration of the yield solve's iterations over the last this many of them
    /// (`src/mps/anderson.rs`); 0 = plain iterations, as before.
    #[serde(default)]
    pub yield_anderson_depth: u32,
    /// The yield solve's strain operator corrected so that a uniform stress exerts no force on
    /// an interior particle (`src/mps/yield_solve.rs`, `make_divergence_consistent`; interior:
    /// all neighbours fluid and a number density of at least `surface_threshold` n0). Off: the
    /// corrected gradient's adjoint, as before.
    #[serde(default)]
    pub yield_consistent_divergence: bool,
    /// The yield solve's law on the deviatoric strain rate alone (von Mises), its volumetric
    /// part held rigid up to this factor times sqrt(2) tau_y on its own
    /// (`src/mps/yield_solve.rs`); null = one limit on the whole tensor, as before.
    #[serde(default)]
    pub yield_volumetric_limit: Option<f64>,
    /// Artificial compressibility on the PPE diagonal, in 1/Pa.
    #[serde(default = "default_compressibility_1_pa")]
    pub compressibility_1_pa: f64,
    /// Collision distance (units of spacing).
    #[serde(default = "default_collision_distance")]
    pub collision_distance: f64,
    /// Restitution coefficient of the collision model.
    #[serde(default = "default_collision_restitution")]
    pub collision_restitution: f64,
    /// Collision distance between a fluid and a wall particle (units of spacing). null = the
    /// rule files were written with before the field existed: `collision_distance` in 2D,
    /// max(`collision_distance`, 0.8) in 3D, where a 3D wall lattice has gaps of 0.71 l0
    /// that a surface particle would fall through.
    #[serde(default)]
    pub wall_collision_distance: Option<f64>,
    /// Collide fluid-wall pairs once more after the pressure correction (which can push a
    /// surface particle into a gap of the wall lattice). null = the rule before the field
    /// existed: on in 3D, off in 2D.
    #[serde(default)]
    pub wall_collision_second_pass: Option<bool>,
    /// Preconditioner of the PPE conjugate-gradient solver: `jacobi` (the default, which
    /// files written before the choice existed used) or `multigrid` (aggregation multigrid:
    /// a few times fewer iterations; same solution to `ppe_tolerance`, other bits).
    #[serde(default)]
    pub ppe_preconditioner: PpePreconditioner,
    /// Multigrid only, in (0, 2): the factor on each coarse-grid correction of the cycle
    /// (1 = plain aggregation, the behaviour before the field existed). Above 1 it makes up
    /// for the piecewise-constant prolongation's under-shoot: fewer iterations, and a count
    /// that grows less with the size (docs/performance.md, "Multigrid over-correction").
    #[serde(default = "default_multigrid_over_correction")]
    pub multigrid_over_correction: f64,
    /// Multigrid only: the cycle's finest smoothing multiplies by the PPE matrix with its
    /// entries rounded to single precision (8 bytes an entry read instead of 12; CG's own
    /// product stays f64, so the solve meets `ppe_tolerance` on the true matrix). Same
    /// solution to the tolerance, other bits (docs/performance.md, "A single-precision
    /// smoother").
    #[serde(default)]
    pub multigrid_single_precision: bool,
    /// Relative residual tolerance of the PPE conjugate-gradient solver.
    #[serde(default = "default_ppe_tolerance")]
    pub ppe_tolerance: f64,
    /// Iteration cap of the PPE solver.
    #[serde(default = "default_ppe_max_iterations")]
    pub ppe_max_iterations: u32,
    /// Relative residual tolerance of the implicit viscosity CG solver.
    #[serde(default = "default_viscosity_tolerance")]
    pub viscosity_tolerance: f64,
    /// Iteration cap of the viscosity solver (per velocity component).
    #[serde(default = "default_viscosity_max_iterations")]
    pub viscosity_max_iterations: u32,
    /// Wall particle layers (take part in the PPE).
    #[serde(default = "default_wall_layers")]
    pub wall_layers: u32,
    /// Dummy particle layers behind the wall (count in the number density only).
    #[serde(default = "default_dummy_layers")]
    pub dummy_layers: u32,
    /// Wall layers of the scene's solids (obstacles, bodies, the L-B box's spheres, the rock
    /// bed's rocks, the rodding rod); null: `wall_layers`. A sphere's one-layer shell on the
    /// lattice has gaps wider than a flat wall's (docs/rockfill.md); two close them without
    /// thickening the container's walls.
    #[serde(default)]
    pub solid_wall_layers: Option<u32>,
}

impl Mps {
    /// The wall layers a solid gets: `solid_wall_layers`, else `wall_layers`.
    pub fn wall_layers_of_solids(&self) -> u32 {
        self.solid_wall_layers.unwrap_or(self.wall_layers)
    }
}

impl Default for Mps {
    fn default() -> Self {
        Mps {
            number_density_radius: default_number_density_radius(),
            laplacian_radius: default_laplacian_radius(),
            surface_threshold: default_surface_threshold(),
            relaxation_coefficient: default_relaxation_coefficient(),
            source_term: default_source_term(),
            preset: None,
            pressure_scheme: PressureSchemeName::default(),
            compression_relaxation: default_compression_relaxation(),
            pair_stabilisation: 0.0,
            wall_support: 0.0,
            pressure_regularisation: 0.0,
            regularisation_radius: default_regularisation_radius(),
            increment_regularisation: 0.0,
            deep_surface_threshold: 0.0,
            deep_surface_head: default_deep_surface_head(),
            pressure_smoothing_time_s: 0.0,
            surface_depth: 0.0,
            pressure_floor_pa: 0.0,
            particle_shifting: 0.0,
            particle_shifting_limit: default_particle_shifting_limit(),
            corrected_strain_rate: false,
            wall_surface_no_slip: false,
            wall_face_normals: false,
            wall_curvature: false,
            quadratic_strain_rate: false,
            strain_rate_radius: None,
            viscous_laplacian_radius: None,
            exact_projection: false,
            conservative_gradient: false,
            adjoint_projection: false,
            periodic_hydrostatic: false,
            ppe_preconditioner: PpePreconditioner::default(),
            multigrid_over_correction: default_multigrid_over_correction(),
            multigrid_single_precision: false,
            yield_penalty_pa_s: 0.0,
            yield_max_iterations: default_yield_max_iterations(),
            yield_tolerance_1_s: default_yield_tolerance_1_s(),
            yield_penalty_adaptive: false,
            yield_penalty_local: false,
            yield_velocity_fraction: 0.0,
            yield_velocity_relative: false,
            yield_anderson_depth: 0,
            yield_consistent_divergence: false,
            yield_volumetric_limit: None,
            compressibility_1_pa: default_compressibility_1_pa(),
            collision_distance: default_collision_distance(),
            collision_restitution: default_collision_restitution(),
            wall_collision_distance: None,
            wall_collision_second_pass: None,
            ppe_tolerance: default_ppe_tolerance(),
            ppe_max_iterations: default_ppe_max_iterations(),
            viscosity_tolerance: default_viscosity_tolerance(),
            viscosity_max_iterations: default_viscosity_max_iterations(),
            wall_layers: default_wall_layers(),
            dummy_layers: default_dummy_layers(),
            solid_wall_layers: None,
        }
    }
}

fn default_number_density_radius() -> f64 {
    2.1
}
fn default_laplacian_radius() -> f64 {
    3.1
}
fn default_surface_threshold() -> f64 {
    0.97
}
fn default_relaxation_coefficient() -> f64 {
    0.2
}
/// PPE source term choice (see [`Mps::source_term`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PpeSource {
    NumberDensity,
    Mixed,
}

/// Pressure scheme choice (see [`Mps::pressure_scheme`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PressureSchemeName {
    #[default]
    Standard,
    Incremental,
}

impl PressureSchemeName {
    /// The manifest's spelling.
    pub fn name(self) -> &'static str {
        match self {
            Self::Standard => "standard",
            Self::Incremental => "incremental",
        }
    }
}

fn default_deep_surface_head() -> f64 {
    3.0
}

fn default_regularisation_radius() -> f64 {
    1.5
}

fn default_yield_max_iterations() -> u32 {
    50
}

fn default_yield_tolerance_1_s() -> f64 {
    1e-3
}

fn default_particle_shifting_limit() -> f64 {
    0.05
}

fn default_compression_relaxation() -> f64 {
    0.01
}

/// PPE preconditioner choice (see [`Mps::ppe_preconditioner`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PpePreconditioner {
    #[default]
    Jacobi,
    Multigrid,
}

fn default_source_term() -> PpeSource {
    PpeSource::NumberDensity
}
fn default_compressibility_1_pa() -> f64 {
    0.45e-9
}
fn default_collision_distance() -> f64 {
    0.5
}
fn default_collision_restitution() -> f64 {
    0.2
}
/// From the error budget in docs/performance.md ("Solver tolerances"): at 1e-6 the seeds'
/// metrics and closed-form comparisons move by about their round-off floor or less, and by
/// at most a twentieth of the spacing's error; the viscous solve keeps 1e-9 (a creeping
/// Bingham heap feels its error).
fn default_ppe_tolerance() -> f64 {
    1.0e-6
}
fn default_multigrid_over_correction() -> f64 {
    1.0
}
fn default_ppe_max_iterations() -> u32 {
    2000
}
fn default_viscosity_tolerance() -> f64 {
    1.0e-9
}
fn default_viscosity_max_iterations() -> u32 {
    5000
}
fn default_wall_layers() -> u32 {
    1
}
fn default_dummy_layers() -> u32 {
    2
}

/// Recording intervals, in seconds of simulated time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    /// Interval between full-precision state checkpoints.
    #[serde(default = "default_checkpoint_interval_s")]
    pub checkpoint_interval_s: f64,
    /// Interval between point-cloud frames.
    #[serde(default = "default_cloud_interval_s")]
    pub cloud_interval_s: f64,
    /// Interval between diagnostics messages.
    #[serde(default = "default_diagnostics_interval_s")]
    pub diagnostics_interval_s: f64,
}

impl Default for Output {
    fn default() -> Self {
        Output {
            checkpoint_interval_s: default_checkpoint_interval_s(),
            cloud_interval_s: default_cloud_interval_s(),
            diagnostics_interval_s: default_diagnostics_interval_s(),
        }
    }
}

fn default_checkpoint_interval_s() -> f64 {
    0.1
}
fn default_cloud_interval_s() -> f64 {
    0.02
}
fn default_diagnostics_interval_s() -> f64 {
    0.005
}

/// Stop conditions besides the end time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stop {
    /// Hard cap on the number of time steps.
    #[serde(default = "default_max_steps")]
    pub max_steps: u64,
    /// Blow-up guard: a run whose particle speed exceeds this (m/s) fails.
    #[serde(default = "default_max_speed_m_s")]
    pub max_speed_m_s: f64,
    /// Stop when at least this share of the fluid particles is non-flowing (seed 000 uses
    /// 0.9), checked from `stop.non_flowing_after_s` on. Yield-stress fluids only; null = off.
    #[serde(default)]
    pub non_flowing_fraction: Option<f64>,
    /// Simulated time from which `non_flowing_fraction` is checked (everything is at rest,
    /// hence non-flowing, before the flow starts).
    #[serde(default = "default_non_flowing_after_s")]
    pub non_flowing_after_s: f64,
    /// Stop when the flow has settled: at a checkpoint, this summary metric (e.g.
    /// `spread_radius_mean_m`) has changed by less than `rest_metric_change` since the previous
    /// checkpoint. Checked from `rest_after_s` on. null = off.
    #[serde(default)]
    pub rest_metric: Option<String>,
    /// The change below which the flow counts as settled, in the metric's unit (m for
    /// lengths), over one `output.checkpoint_interval_s`.
    #[serde(default = "default_rest_metric_change")]
    pub rest_metric_change: f64,
    /// Simulated time from which `rest_metric` is checked (for the slump test: after the cone
    /// has been lifted).
    #[serde(default = "default_non_flowing_after_s")]
    pub rest_after_s: f64,
    /// Fluid that leaves the domain box becomes a ghost (docs/manifest.md, "Ghosts"); a run with
    /// more ghosts than this fails (0: the first particle to leave fails it). null = no limit.
    #[serde(default)]
    pub max_ghost_particles: Option<u64>,
}

fn default_rest_metric_change() -> f64 {
    1e-3
}

fn default_non_flowing_after_s() -> f64 {
    0.5
}

impl Default for Stop {
    fn default() -> Self {
        Stop {
            max_steps: default_max_steps(),
            max_speed_m_s: default_max_speed_m_s(),
            non_flowing_fraction: None,
            non_flowing_after_s: default_non_flowing_after_s(),
            rest_metric: None,
            rest_metric_change: default_rest_metric_change(),
            rest_after_s: default_non_flowing_after_s(),
            max_ghost_particles: None,
        }
    }
}

fn default_max_steps() -> u64 {
    10_000_000
}
fn default_max_speed_m_s() -> f64 {
    100.0
}

/// One manifest per variant of each tagged section, for learning the set of field paths
/// (used to name the section of a missing field in error messages). Add new fluid variants
/// here; scene variants come from [`SceneSection::samples`].
pub(crate) fn samples<S: SceneSection>() -> Vec<Manifest<S>> {
    let fluids = [
        Fluid::Newtonian {
            density_kg_m3: 1000.0,
            viscosity_pa_s: 1.0e-3,
        },
        Fluid::Bingham {
            density_kg_m3: 2300.0,
            plastic_viscosity_pa_s: 50.0,
            yield_stress_pa: 100.0,
            critical_strain_rate_1_s: 1.0e-3,
            stress_gradient_term: true,
        },
        Fluid::BiViscosity {
            density_kg_m3: 2300.0,
            plastic_viscosity_pa_s: 50.0,
            yield_stress_pa: 100.0,
            rigid_viscosity_pa_s: 50000.0,
            stress_gradient_term: false,
        },
    ];
    let scenes = S::samples();
    let n = fluids.len().max(scenes.len());
    (0..n)
        .map(|i| Manifest {
            name: "sample".to_string(),
            dimension: 2,
            spacing_m: 0.01,
            gravity_m_s2: default_gravity_m_s2(),
            time: Time {
                end_s: 1.0,
                dt_max_s: default_dt_max_s(),
                courant: default_courant(),
                dt_min_s: None,
                acoustic_courant: None,
            },
            fluid: fluids[i.min(fluids.len() - 1)].clone(),
            mps: Mps::default(),
            scene: scenes[i.min(scenes.len() - 1)].clone(),
            boundaries: Boundaries::default(),
            output: Output::default(),
            stop: Stop::default(),
        })
        .collect()
}
