//! L-flow test box (seed 000; JSCE/EFNARC-like L-box): a vertical part holding the concrete
//! and a horizontal channel it flows into once the gate is opened at t = 0. In 3D the box has
//! a depth along y.
use super::geometry::container::{add_walls, l_box_parts};
use super::geometry::lattice::{cells, centre, for_each_index};
use super::{Experiment, Manifest, Scene};
use crate::manifest::validate::{Checker, POSITIVE, fmt_num};
use crate::mps::{ParticleKind, Particles, Vector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// `scene: {kind: l_flow}`: an L-shaped box; the concrete stands in the vertical part
/// (x in [0, vertical_width_m]) and flows, once the gate at x = vertical_width_m is opened at
/// t = 0, into the horizontal channel (x up to vertical_width_m + channel_length_m, height
/// channel_height_m). The vertical part is open at the top.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LFlow {
    /// Inner width of the vertical part, in metres.
    pub vertical_width_m: f64,
    /// Inner height of the vertical part (wall height), in metres.
    pub vertical_height_m: f64,
    /// Length of the horizontal channel from the gate to its end wall, in metres.
    pub channel_length_m: f64,
    /// Inner height of the horizontal channel, in metres.
    pub channel_height_m: f64,
    /// Height of the concrete in the vertical part at t = 0, in metres.
    pub fill_height_m: f64,
    /// Depth of the box (3D only), in metres.
    pub depth_m: f64,
}

impl Default for LFlow {
    fn default() -> Self {
        Self {
            vertical_width_m: 0.1,
            vertical_height_m: 0.6,
            channel_length_m: 0.8,
            channel_height_m: 0.15,
            fill_height_m: 0.41,
            depth_m: 0.1,
        }
    }
}

impl Experiment for LFlow {
    fn flow_measures(&self) -> &'static [&'static str] {
        &["l_flow_value_m"]
    }

    fn check(&self, m: &Manifest, c: &mut Checker) {
        let mut dims = vec![
            ("scene.vertical_width_m", self.vertical_width_m),
            ("scene.vertical_height_m", self.vertical_height_m),
            ("scene.channel_length_m", self.channel_length_m),
            ("scene.channel_height_m", self.channel_height_m),
            ("scene.fill_height_m", self.fill_height_m),
        ];
        if m.dimension == 3 {
            dims.push(("scene.depth_m", self.depth_m));
        }
        let mut all_ok = true;
        for (field, x) in &dims {
            all_ok &= c.real(field, *x, POSITIVE);
        }
        if !all_ok {
            return;
        }
        for (field, x) in [
            ("scene.fill_height_m", self.fill_height_m),
            ("scene.channel_height_m", self.channel_height_m),
        ] {
            if x > self.vertical_height_m {
                c.fail(
                    field,
                    format!(
                        "must be <= scene.vertical_height_m ({}), got {}",
                        fmt_num(self.vertical_height_m),
                        fmt_num(x)
                    ),
                );
            }
        }
        if super::spacing_ok(m) {
            c.lattice_lengths(&dims, m.spacing_m);
        }
    }
    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        build::<D>(self, m.spacing_m, m.mps.wall_layers, m.mps.dummy_layers)
    }
    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>) {
        let (vertical_part, channel) = parts::<D>(self, m.spacing_m);
        domain::<D>(vertical_part, channel, m.spacing_m)
    }
    fn metric_names(&self, _m: &Manifest) -> Vec<&'static str> {
        vec!["l_flow_value_m"]
    }
    fn metrics<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
        _time_s: f64,
        out: &mut BTreeMap<String, f64>,
    ) {
        out.insert(
            "l_flow_value_m".to_string(),
            l_flow_value_m(particles, self, m.spacing_m),
        );
    }
    fn trend_metric(&self) -> &'static str {
        "l_flow_value_m"
    }
    /// The times the front takes to run 200 mm and 400 mm past the gate (released at t = 0),
    /// as the L-box test's T200 and T400 (EN 12350-10): the flow's speed, which the plastic
    /// viscosity sets.
    fn crossings(&self, _m: &Manifest) -> Vec<super::Crossing> {
        [("t200_s", 0.2), ("t400_s", 0.4)]
            .into_iter()
            .map(|(name, threshold)| super::Crossing {
                name,
                metric: "l_flow_value_m",
                threshold,
                since_s: 0.0,
            })
            .collect()
    }
}

type CellBox<const D: usize> = ([i64; D], [i64; D]);

fn parts<const D: usize>(p: &LFlow, spacing_m: f64) -> (CellBox<D>, CellBox<D>) {
    l_box_parts::<D>(
        p.vertical_width_m,
        p.vertical_height_m,
        p.channel_length_m,
        p.channel_height_m,
        p.depth_m,
        spacing_m,
    )
}

/// Beyond one box size away from the L, fluid becomes a ghost.
pub(super) fn domain<const D: usize>(
    vertical_part: CellBox<D>,
    channel: CellBox<D>,
    spacing_m: f64,
) -> (Vector<D>, Vector<D>) {
    let size = Vector::<D>::from_fn(|a, _| vertical_part.1[a].max(channel.1[a]) as f64 * spacing_m);
    (-size, size * 2.0)
}

pub fn build<const D: usize>(
    p: &LFlow,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
) -> Scene<D> {
    let (vertical_part, channel) = parts::<D>(p, spacing_m);
    let mut particles = Particles::<D>::default();
    let mut fill = vertical_part.1;
    fill[D - 1] = cells(p.fill_height_m, spacing_m);
    for_each_index([0; D], fill, |idx| {
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
    let (domain_min_m, domain_max_m) = domain::<D>(vertical_part, channel, spacing_m);
    Scene {
        particles,
        domain_min_m,
        domain_max_m,
        bodies: Vec::new(),
        inlets: Vec::new(),
        gravity_tilt_rad: 0.0,
        periodic_x: None,
        symmetry: Default::default(),
    }
}

/// L-flow value: distance from the gate (x = vertical_width_m) to the far edge of the
/// furthest fluid particle (centre + l0/2); 0 while nothing has passed the gate.
pub fn l_flow_value_m<const D: usize>(particles: &Particles<D>, p: &LFlow, spacing_m: f64) -> f64 {
    let gate_x_m = cells(p.vertical_width_m, spacing_m) as f64 * spacing_m;
    super::front_past_m(particles, gate_x_m, spacing_m)
}
