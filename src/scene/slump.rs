//! Slump-flow test, 3D (seed 004; EN 12350-8): a frustum-shaped cone standing on a square
//! no-slip plate is filled with concrete and lifted; the concrete spreads into a pancake.
//!
//! Geometry: the plate's top surface is z = 0 and the cone's axis is x = y = 0 (a lattice
//! cell corner, so the particle arrangement is symmetric under the quarter turns). Particles
//! sit at cell centres (k + 1/2) l0.
//! - Fluid: every cell centre strictly inside the frustum, z in (0, cone height), radius
//!   R(z) from the bottom radius at z = 0 to the top radius at the cone height.
//! - Plate: `wall_layers` wall and `dummy_layers` dummy layers under the whole square plate
//!   (side `plate_size_m`), no rim: fluid that runs off the edge falls and becomes a ghost when
//!   it leaves the domain box.
//! - Cone: the cells whose horizontal distance r from the axis lies in
//!   [R(z), R(z) + wall_layers l0) are wall particles, those in the next `dummy_layers` l0
//!   dummies (z from 0 to the cone height; the cone is open at the top and bottom). Built
//!   last, so the cone is the index range [`Scene::moving`], which the solver lifts.
use super::Scene;
use super::lattice::{cells, centre, for_each_index};
use crate::mps::{ParticleKind, Particles, Vector};

#[derive(Debug, Clone, PartialEq)]
pub struct Slump {
    pub cone_height_m: f64,
    pub cone_bottom_diameter_m: f64,
    pub cone_top_diameter_m: f64,
    pub plate_size_m: f64,
}

impl Slump {
    /// Inner radius of the cone at height z (linear from bottom to top).
    pub fn radius_at_m(&self, z_m: f64) -> f64 {
        let (rb, rt) = (
            0.5 * self.cone_bottom_diameter_m,
            0.5 * self.cone_top_diameter_m,
        );
        rb + (rt - rb) * (z_m / self.cone_height_m)
    }
    /// Volume of the frustum: pi h (R^2 + R r + r^2) / 3.
    pub fn cone_volume_m3(&self) -> f64 {
        let (rb, rt) = (
            0.5 * self.cone_bottom_diameter_m,
            0.5 * self.cone_top_diameter_m,
        );
        std::f64::consts::PI * self.cone_height_m * (rb * rb + rb * rt + rt * rt) / 3.0
    }
}

/// Builds the slump scene (3D only: the manifest rejects `dimension: 2`).
pub fn build<const D: usize>(
    p: &Slump,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
    with_cone: bool,
) -> Scene<D> {
    assert!(D == 3, "the slump scene is 3D");
    let l0 = spacing_m;
    let layers = i64::from(wall_layers + dummy_layers);
    let height = cells(p.cone_height_m, l0);
    let half_plate = cells(0.5 * p.plate_size_m, l0);
    let rb = 0.5 * p.cone_bottom_diameter_m.max(p.cone_top_diameter_m);
    let reach = (rb / l0).ceil() as i64 + layers + 1;
    let horizontal_r2 = |x: &Vector<D>| x[0] * x[0] + x[1] * x[1];
    let mut particles = Particles::<D>::default();

    // Fluid inside the frustum.
    let lo: [i64; D] = std::array::from_fn(|a| if a == D - 1 { 0 } else { -reach });
    let hi: [i64; D] = std::array::from_fn(|a| if a == D - 1 { height } else { reach });
    for_each_index(lo, hi, |idx| {
        let x = centre(idx, l0);
        let r = p.radius_at_m(x[D - 1]);
        if horizontal_r2(&x) < r * r {
            particles.push(x, ParticleKind::Fluid);
        }
    });

    // Plate: wall layers right under z = 0, then dummies.
    let plate_lo: [i64; D] =
        std::array::from_fn(|a| if a == D - 1 { -layers } else { -half_plate });
    let plate_hi: [i64; D] = std::array::from_fn(|a| if a == D - 1 { 0 } else { half_plate });
    for_each_index(plate_lo, plate_hi, |idx| {
        let kind = if idx[D - 1] >= -i64::from(wall_layers) {
            ParticleKind::Wall
        } else {
            ParticleKind::Dummy
        };
        particles.push(centre(idx, l0), kind);
    });

    // Cone shell, last: the solver moves this index range.
    let first = particles.len();
    if with_cone {
        for_each_index(lo, hi, |idx| {
            let x = centre(idx, l0);
            let r = p.radius_at_m(x[D - 1]);
            let r2 = horizontal_r2(&x);
            let wall_r = r + f64::from(wall_layers) * l0;
            let outer_r = r + layers as f64 * l0;
            if r2 < r * r || r2 >= outer_r * outer_r {
                return;
            }
            let kind = if r2 < wall_r * wall_r {
                ParticleKind::Wall
            } else {
                ParticleKind::Dummy
            };
            particles.push(x, kind);
        });
    }
    let end = particles.len();

    // Fluid beyond half a plate past the edge, or that fell well below it, is a ghost.
    let side = half_plate as f64 * l0;
    let top = 2.0 * p.cone_height_m + 1.0;
    let domain_min_m = Vector::<D>::from_fn(|a, _| if a == D - 1 { -0.5 } else { -2.0 * side });
    let domain_max_m = Vector::<D>::from_fn(|a, _| if a == D - 1 { top } else { 2.0 * side });
    Scene {
        particles,
        domain_min_m,
        domain_max_m,
        moving: (end > first).then_some(first..end),
    }
}

/// Number of angular sectors of the spread radius (octants: decided by signs and |x| vs |y|,
/// exact, no trigonometry).
pub const SECTORS: usize = 8;

/// Octant of a horizontal direction (x, y), 0..8.
fn sector(x: f64, y: f64) -> usize {
    usize::from(x < 0.0) * 4 + usize::from(y < 0.0) * 2 + usize::from(x.abs() < y.abs())
}

/// Whether fluid particle i counts as the concrete on the plate: at most `z_max_m` high
/// (the cone height: a few particles stick to the cone's wall and are lifted with it).
pub fn on_plate<const D: usize>(particles: &Particles<D>, i: usize, z_max_m: f64) -> bool {
    particles.kind[i] == ParticleKind::Fluid && particles.position_m[i][D - 1] <= z_max_m
}

/// Spread radius per sector: the horizontal distance from the axis of the furthest fluid
/// particle on the plate in that sector plus l0/2 (its far edge), 0 for an empty sector.
pub fn spread_radii_m<const D: usize>(
    particles: &Particles<D>,
    spacing_m: f64,
    z_max_m: f64,
) -> [f64; SECTORS] {
    let mut r2_max = [f64::NEG_INFINITY; SECTORS];
    for i in 0..particles.len() {
        if !on_plate(particles, i, z_max_m) {
            continue;
        }
        let x = particles.position_m[i];
        let s = sector(x[0], x[1]);
        r2_max[s] = r2_max[s].max(x[0] * x[0] + x[1] * x[1]);
    }
    r2_max.map(|r2| {
        if r2.is_finite() {
            r2.sqrt() + 0.5 * spacing_m
        } else {
            0.0
        }
    })
}

/// Height of the fluid surface at horizontal distance `r_m` from the axis: the highest fluid
/// particle on the plate whose distance lies within `band_m` of `r_m`, plus l0/2 (0 when there
/// is none).
pub fn surface_height_m<const D: usize>(
    particles: &Particles<D>,
    spacing_m: f64,
    r_m: f64,
    band_m: f64,
    z_max_m: f64,
) -> f64 {
    let mut top = f64::NEG_INFINITY;
    for i in 0..particles.len() {
        if !on_plate(particles, i, z_max_m) {
            continue;
        }
        let x = particles.position_m[i];
        let r = (x[0] * x[0] + x[1] * x[1]).sqrt();
        if (r - r_m).abs() < band_m {
            top = top.max(x[D - 1]);
        }
    }
    if top.is_finite() {
        top + 0.5 * spacing_m
    } else {
        0.0
    }
}

/// Roussel & Coussot (2005), thin "pancake" regime: final radius of a yield-stress fluid of
/// volume V spread on a plane, R = (225 rho g V^2 / (128 pi^2 tau_0))^(1/5).
pub fn closed_form_radius_m(
    density_kg_m3: f64,
    gravity_m_s2: f64,
    volume_m3: f64,
    yield_stress_pa: f64,
) -> f64 {
    let pi2 = std::f64::consts::PI * std::f64::consts::PI;
    (225.0 * density_kg_m3 * gravity_m_s2 * volume_m3 * volume_m3 / (128.0 * pi2 * yield_stress_pa))
        .powf(0.2)
}

/// The surface at rest of that pancake, h(r) = sqrt(2 tau_0 (R - r) / (rho g)) (0 beyond R).
pub fn closed_form_height_m(
    density_kg_m3: f64,
    gravity_m_s2: f64,
    yield_stress_pa: f64,
    radius_m: f64,
    r_m: f64,
) -> f64 {
    (2.0 * yield_stress_pa * (radius_m - r_m).max(0.0) / (density_kg_m3 * gravity_m_s2)).sqrt()
}
