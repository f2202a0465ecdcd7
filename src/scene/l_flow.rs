//! L-flow test box (seed 000; JSCE/EFNARC-like L-box): a vertical part holding the concrete
//! and a horizontal channel it flows into once the gate is opened at t = 0. In 3D the box has
//! a depth along y.
use super::Scene;
use super::container::add_walls;
use super::lattice::{cells, centre, for_each_index};
use crate::mps::{ParticleKind, Particles, Vector};

#[derive(Debug, Clone, PartialEq)]
pub struct LFlow {
    pub vertical_width_m: f64,
    pub vertical_height_m: f64,
    pub channel_length_m: f64,
    pub channel_height_m: f64,
    pub fill_height_m: f64,
    pub depth_m: f64,
}

pub fn build<const D: usize>(
    p: &LFlow,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
) -> Scene<D> {
    let n = |x: f64| cells(x, spacing_m);
    let (width, length) = (
        n(p.vertical_width_m),
        n(p.vertical_width_m + p.channel_length_m),
    );
    // Axis 0: along the channel; last axis: vertical; axis 1 in 3D: depth.
    let extent = |along: i64, vertical: i64| -> [i64; D] {
        std::array::from_fn(|a| {
            if a == 0 {
                along
            } else if a == D - 1 {
                vertical
            } else {
                n(p.depth_m)
            }
        })
    };
    let vertical_part = ([0; D], extent(width, n(p.vertical_height_m)));
    let channel = ([0; D], extent(length, n(p.channel_height_m)));
    let mut particles = Particles::<D>::default();
    for_each_index([0; D], extent(width, n(p.fill_height_m)), |idx| {
        particles.push(centre(idx, spacing_m), ParticleKind::Fluid)
    });
    add_walls(
        &mut particles,
        &[vertical_part, channel],
        vertical_part.1[D - 1],
        spacing_m,
        wall_layers,
        dummy_layers,
    );
    let size = Vector::<D>::from_fn(|a, _| vertical_part.1[a].max(channel.1[a]) as f64 * spacing_m);
    Scene {
        particles,
        domain_min_m: -size,
        domain_max_m: size * 2.0,
        moving: None,
    }
}

/// L-flow value: distance from the gate (x = vertical_width_m) to the far edge of the
/// furthest fluid particle (centre + l0/2); 0 while nothing has passed the gate.
pub fn l_flow_value_m<const D: usize>(particles: &Particles<D>, p: &LFlow, spacing_m: f64) -> f64 {
    let gate_x_m = cells(p.vertical_width_m, spacing_m) as f64 * spacing_m;
    let front = super::front_position_m(particles, spacing_m);
    (front - gate_x_m).max(0.0)
}
