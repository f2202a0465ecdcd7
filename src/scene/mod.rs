//! Scene builders: turn a manifest's geometry into particles. One file per experiment.
pub mod dam_break;
pub mod lattice;

use crate::mps::{Particles, Vector};

/// Particles of an experiment plus the box fluid particles must stay in.
#[derive(Debug, Clone)]
pub struct Scene<const D: usize> {
    pub particles: Particles<D>,
    pub domain_min_m: Vector<D>,
    pub domain_max_m: Vector<D>,
}
