//! Dam break: a fluid column against the left wall of an open tank (Koshizuka & Oka 1996;
//! Martin & Moyce 1952). In 3D the tank has a depth and the column spans it.
use super::geometry::container::add_walls;
use super::geometry::lattice::{cells, centre, for_each_index};
use super::{Experiment, Manifest, Scene};
use crate::manifest::validate::{Checker, NON_NEGATIVE, POSITIVE, fmt_num};
use crate::mps::{ParticleKind, Particles, Vector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// `scene: {kind: dam_break}`: a rectangular fluid column collapsing in a tank (Martin &
/// Moyce; Koshizuka & Oka). The tank's lower-left(-front) inner corner is the origin; the
/// column stands against the wall at x = 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DamBreak {
    /// Inner width of the tank along x, in metres.
    pub tank_width_m: f64,
    /// Inner height of the tank along the vertical axis, in metres.
    pub tank_height_m: f64,
    /// Inner depth of the tank along y (3D only), in metres.
    pub tank_depth_m: f64,
    /// Width of the fluid column along x, in metres.
    pub column_width_m: f64,
    /// Height of the fluid column, in metres.
    pub column_height_m: f64,
    /// Navier slip length of the tank's side walls (y = 0 and y = depth; 3D only), in
    /// metres: large, free slip, so that a 3D tank one slice deep stands for the 2D case.
    /// null: no slip, as every wall.
    pub side_slip_length_m: Option<f64>,
}

impl Default for DamBreak {
    fn default() -> Self {
        Self {
            tank_width_m: 1.0,
            tank_height_m: 0.6,
            tank_depth_m: 0.1,
            column_width_m: 0.25,
            column_height_m: 0.5,
            side_slip_length_m: None,
        }
    }
}

impl Experiment for DamBreak {
    fn flow_measures(&self) -> &'static [&'static str] {
        &["front_position_m"]
    }

    fn check(&self, m: &Manifest, c: &mut Checker) {
        check_tank(self, m, c);
    }
    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        build::<D>(self, m.spacing_m, m.mps.wall_layers, m.mps.dummy_layers)
    }
    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>) {
        domain::<D>(self, m.spacing_m)
    }
    fn metric_names(&self, _m: &Manifest) -> Vec<&'static str> {
        Vec::new()
    }
    fn metrics<const D: usize>(
        &self,
        _m: &Manifest,
        _particles: &Particles<D>,
        _time_s: f64,
        _out: &mut BTreeMap<String, f64>,
    ) {
    }
    fn trend_metric(&self) -> &'static str {
        "front_position_m"
    }
}

/// Checks of a tank and column (shared with the column collapse, which uses this geometry).
pub fn check_tank(p: &DamBreak, m: &Manifest, c: &mut Checker) {
    let dims = [
        ("scene.tank_width_m", p.tank_width_m),
        ("scene.tank_height_m", p.tank_height_m),
        ("scene.tank_depth_m", p.tank_depth_m),
        ("scene.column_width_m", p.column_width_m),
        ("scene.column_height_m", p.column_height_m),
    ];
    let mut all_ok = true;
    for (field, x) in dims {
        all_ok &= c.real(field, x, POSITIVE);
    }
    all_ok &= super::check_3d_only(
        m,
        c,
        "scene.side_slip_length_m",
        p.side_slip_length_m,
        NON_NEGATIVE,
        "a 2D tank has no side walls",
    );
    if !all_ok {
        return;
    }
    for (field, inner, outer_field, outer) in [
        (
            "scene.column_width_m",
            p.column_width_m,
            "scene.tank_width_m",
            p.tank_width_m,
        ),
        (
            "scene.column_height_m",
            p.column_height_m,
            "scene.tank_height_m",
            p.tank_height_m,
        ),
    ] {
        if inner > outer {
            c.fail(
                field,
                format!(
                    "must be <= {outer_field} ({}), got {}",
                    fmt_num(outer),
                    fmt_num(inner)
                ),
            );
        }
    }
    if super::spacing_ok(m) {
        // The depth is used in 3D only.
        let used: Vec<(&str, f64)> = dims
            .into_iter()
            .filter(|(field, _)| *field != "scene.tank_depth_m" || m.dimension == 3)
            .collect();
        c.lattice_lengths(&used, m.spacing_m);
    }
}

/// Horizontal size along axis `a` (x = width; in 3D, y = depth).
fn horizontal(a: usize, width_m: f64, depth_m: f64) -> f64 {
    if a == 0 { width_m } else { depth_m }
}

/// The tank in lattice cells along each axis.
fn tank_cells<const D: usize>(p: &DamBreak, spacing_m: f64) -> [i64; D] {
    std::array::from_fn(|a| {
        if a == D - 1 {
            cells(p.tank_height_m, spacing_m)
        } else {
            cells(horizontal(a, p.tank_width_m, p.tank_depth_m), spacing_m)
        }
    })
}

/// Fluid may splash over the walls; beyond one tank size away it becomes a ghost.
pub fn domain<const D: usize>(p: &DamBreak, spacing_m: f64) -> (Vector<D>, Vector<D>) {
    let tank = tank_cells::<D>(p, spacing_m);
    let extent = Vector::<D>::from_fn(|a, _| tank[a] as f64 * spacing_m);
    (-extent, extent * 2.0)
}

pub fn build<const D: usize>(
    p: &DamBreak,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
) -> Scene<D> {
    let tank = tank_cells::<D>(p, spacing_m);
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
    let mut bodies = Vec::new();
    if let (3, Some(slip_length_m)) = (D, p.side_slip_length_m) {
        // The side walls (every wall or dummy outside the tank's depth) move to the end, in
        // their order, as one body at rest whose surface the viscous terms let slip
        // (`mps::viscosity::SlipWall`).
        let depth_m = tank[1] as f64 * spacing_m;
        let side = |i: usize| {
            let y = particles.position_m[i][1];
            particles.kind[i] != ParticleKind::Fluid && !(0.0..depth_m).contains(&y)
        };
        let mut sorted = Particles::<D>::default();
        let mut first = 0;
        for beside in [false, true] {
            first = sorted.len();
            for i in (0..particles.len()).filter(|&i| side(i) == beside) {
                sorted.push_tagged(particles.position_m[i], particles.kind[i], particles.tag[i]);
            }
        }
        bodies.push(super::slipping_walls(first, sorted.len(), slip_length_m));
        particles = sorted;
    }
    let (domain_min_m, domain_max_m) = domain::<D>(p, spacing_m);
    Scene {
        particles,
        domain_min_m,
        domain_max_m,
        bodies,
        inlets: Vec::new(),
        gravity_tilt_rad: 0.0,
        periodic_x: None,
        symmetry: Default::default(),
    }
}
