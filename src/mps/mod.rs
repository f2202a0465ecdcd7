//! The MPS solver core, generic over the dimension `D` (2 or 3).
pub mod grid;
pub mod kernel;
pub mod multigrid;
pub mod operators;
pub mod particles;
pub mod pressure;
pub mod reduce;
pub mod rheology;
pub mod solver;
pub mod viscosity;

pub use particles::{ParticleKind, Particles, Vector};
pub use rheology::Rheology;
pub use solver::{MovingWall, Solver, SolverConfig, SourceTerm, StageTimes, StepError, StepReport};
