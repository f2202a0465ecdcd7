//! The MPS solver core, generic over the dimension `D` (2 or 3).
pub mod anderson;
pub mod body;
pub(crate) mod dense;
pub mod grid;
pub mod inlet;
pub mod kernel;
pub mod multigrid;
pub mod operators;
pub mod particles;
pub mod pressure;
pub mod reduce;
pub mod rheology;
pub mod solver;
pub mod sparse;
pub mod viscosity;
pub mod yield_solve;

pub use body::{Path, RigidBody, Segment};
pub use inlet::Inlet;
pub use particles::{ParticleKind, Particles, Vector};
pub use rheology::Rheology;
pub use solver::{
    PeriodicX, PressureScheme, STAGE_NAMES, Solver, SolverConfig, SourceTerm, StageMomentum,
    StageTimes, StepError, StepReport,
};
