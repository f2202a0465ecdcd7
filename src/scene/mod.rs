//! Scene builders: turn a manifest's geometry into particles. One file per experiment.
pub mod container;
pub mod dam_break;
pub mod l_flow;
pub mod lattice;
pub mod shapes;
pub mod slump;

use crate::mps::{ParticleKind, Particles, Vector};

/// Particles of an experiment plus the box fluid particles must stay in.
#[derive(Debug, Clone)]
pub struct Scene<const D: usize> {
    pub particles: Particles<D>,
    pub domain_min_m: Vector<D>,
    pub domain_max_m: Vector<D>,
    /// Particles of a wall that the solver moves (the slump cone), if any.
    pub moving: Option<std::ops::Range<usize>>,
}

/// Front position: distance from the wall at x = 0 to the far edge of the furthest fluid
/// particle (its centre plus half a spacing, so a column of width a starts at exactly a).
pub fn front_position_m<const D: usize>(particles: &Particles<D>, spacing_m: f64) -> f64 {
    let mut front = f64::NEG_INFINITY;
    for i in 0..particles.len() {
        if particles.kind[i] == ParticleKind::Fluid {
            front = front.max(particles.position_m[i][0]);
        }
    }
    front + 0.5 * spacing_m
}
