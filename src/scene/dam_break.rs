//! Dam break: a fluid column against the left wall of an open tank (Koshizuka & Oka 1996;
//! Martin & Moyce 1952). In 3D the tank has a depth and the column spans it.
use super::Scene;
use super::container::add_walls;
use super::lattice::{cells, centre, for_each_index};
use crate::mps::{ParticleKind, Particles, Vector};

#[derive(Debug, Clone, PartialEq)]
pub struct DamBreak {
    pub tank_width_m: f64,
    pub tank_height_m: f64,
    pub tank_depth_m: f64,
    pub column_width_m: f64,
    pub column_height_m: f64,
}

/// Horizontal size along axis `a` (x = width; in 3D, y = depth).
fn horizontal(a: usize, width_m: f64, depth_m: f64) -> f64 {
    if a == 0 { width_m } else { depth_m }
}

pub fn build<const D: usize>(
    p: &DamBreak,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
) -> Scene<D> {
    let tank: [i64; D] = std::array::from_fn(|a| {
        if a == D - 1 {
            cells(p.tank_height_m, spacing_m)
        } else {
            cells(horizontal(a, p.tank_width_m, p.tank_depth_m), spacing_m)
        }
    });
    let column: [i64; D] = std::array::from_fn(|a| {
        if a == D - 1 {
            cells(p.column_height_m, spacing_m)
        } else {
            cells(horizontal(a, p.column_width_m, p.tank_depth_m), spacing_m)
        }
    });
    let mut particles = Particles::<D>::default();
    for_each_index([0; D], column, |idx| {
        particles.push(centre(idx, spacing_m), ParticleKind::Fluid)
    });
    add_walls(
        &mut particles,
        &[([0; D], tank)],
        tank[D - 1],
        spacing_m,
        wall_layers,
        dummy_layers,
    );
    // Fluid may splash over the walls; beyond one tank size away it becomes a ghost.
    let extent = Vector::<D>::from_fn(|a, _| tank[a] as f64 * spacing_m);
    Scene {
        particles,
        domain_min_m: -extent,
        domain_max_m: extent * 2.0,
        moving: None,
    }
}
