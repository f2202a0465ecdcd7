//! Inclined layer (issue "A quiet core"): a layer of depth h on a plane inclined at theta,
//! periodic along the slope, no-slip floor, free surface, started at rest. Modelled as a
//! level floor under gravity tilted by theta towards +x. Closed form for a Bingham fluid
//! (yield stress tau_0, plastic viscosity mu_p): the wall stress is rho g sin(theta) h, so the
//! layer stays rigid when h <= h_c = tau_0 / (rho g sin theta); above, it shears in a bottom
//! zone of thickness h - h_c under a plug moving at U = rho g sin(theta) (h - h_c)^2 / (2 mu_p)
//! (a Newtonian film, tau_0 = 0: the Nusselt surface speed rho g sin(theta) h^2 / (2 mu)).
//! In 3D the layer is a channel of width `width_m` between side walls (the neighbour grid has
//! one periodic axis), no-slip or slipping (`side_slip_length_m`; free slip stands for a layer
//! of unbounded width), and the plug speed is taken over the middle third of the width.
//! With a slipping floor (`floor_slip_length_m`, 3D) the side walls alone hold the layer: the
//! shear runs across the channel, and the same closed form holds with h replaced by the
//! half-width W/2 (plane Poiseuille flow of a Bingham fluid between the side walls): rigid
//! for W/2 <= h_c, else a middle plug at U = rho g sin(theta) (W/2 - h_c)^2 / (2 mu_p). It
//! checks the side walls' grip, which holds a heap in an L-box.
use super::geometry::lattice::{cells, centre, for_each_index};
use super::{Experiment, Manifest, Scene, check_3d_only, slipping_walls, yield_stress_pa};
use crate::manifest::validate::{Checker, NON_NEGATIVE, POSITIVE, between, fmt_num};
use crate::manifest::Fluid;
use crate::mps::{ParticleKind, Particles, PeriodicX, Vector};
use crate::rng::SplitMix64;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The plug speed is the mean along-slope velocity of the particles in this top share of the
/// layer (inside the plug for h <= 5 h_c).
const PLUG_SHARE: f64 = 0.2;

/// `scene: {kind: inclined_layer}`: the floor's top is y = 0, the layer spans x in
/// [0, period_m) and y in [0, layer_depth_m).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InclinedLayer {
    /// Depth h of the layer, normal to the plane, in metres.
    pub layer_depth_m: f64,
    /// Length of the periodic cell along the slope, in metres.
    pub period_m: f64,
    /// Inclination theta of the plane, in degrees.
    pub incline_deg: f64,
    /// Width of the channel between the side walls, in metres: 3D only (and required there).
    pub width_m: Option<f64>,
    /// Navier slip length of the side walls, in metres (3D; large: free slip, so that the
    /// channel stands for a layer of unbounded width). Absent: no slip.
    pub side_slip_length_m: Option<f64>,
    /// Navier slip length of the floor, in metres (3D; large: free slip, so that only the side
    /// walls hold the layer, which needs `side_slip_length_m` absent; the closed form then
    /// takes the floor as free-slip, for a slip length far above the layer's size). Absent: no
    /// slip.
    pub floor_slip_length_m: Option<f64>,
    /// The layer's particles start displaced from the lattice by up to this fraction of the
    /// spacing in each coordinate (uniform, from `disorder_seed`): a disordered layer such as
    /// a flow leaves behind. Absent: the lattice.
    pub disorder: Option<f64>,
    /// Seed of the SplitMix64 sequence that draws the displacements (absent: 1).
    pub disorder_seed: Option<u64>,
}

impl Default for InclinedLayer {
    fn default() -> Self {
        Self {
            layer_depth_m: 0.04,
            period_m: 0.2,
            incline_deg: 5.0,
            width_m: None,
            side_slip_length_m: None,
            floor_slip_length_m: None,
            disorder: None,
            disorder_seed: None,
        }
    }
}

impl InclinedLayer {
    fn incline_rad(&self) -> f64 {
        self.incline_deg * (std::f64::consts::PI / 180.0)
    }
    /// h on the lattice (whole rows).
    fn depth_m(&self, spacing_m: f64) -> f64 {
        cells(self.layer_depth_m, spacing_m) as f64 * spacing_m
    }
    /// The channel's width on the lattice (3D).
    fn width(&self, spacing_m: f64) -> f64 {
        cells(self.width_m.unwrap_or(0.0), spacing_m) as f64 * spacing_m
    }
    /// The distance over which the wall stress builds up from the plug's edge: the depth on
    /// the lattice, or with a slipping floor the half-width (the shear runs across).
    fn sheared_extent_m(&self, spacing_m: f64) -> f64 {
        if self.floor_slip_length_m.is_some() {
            0.5 * self.width(spacing_m)
        } else {
            self.depth_m(spacing_m)
        }
    }
    fn period(&self, spacing_m: f64) -> PeriodicX {
        PeriodicX {
            min_m: 0.0,
            period_m: cells(self.period_m, spacing_m) as f64 * spacing_m,
        }
    }
}

/// The plastic viscosity of `fluid` (a Newtonian fluid's viscosity; its h_c is 0).
fn plastic_viscosity_pa_s(fluid: &Fluid) -> f64 {
    match *fluid {
        Fluid::Newtonian { viscosity_pa_s, .. } => viscosity_pa_s,
        Fluid::Bingham {
            plastic_viscosity_pa_s,
            ..
        }
        | Fluid::BiViscosity {
            plastic_viscosity_pa_s,
            ..
        } => plastic_viscosity_pa_s,
    }
}

/// (rho g sin theta, h_c, U) of the closed form for `m`'s fluid.
fn closed_form(layer: &InclinedLayer, m: &Manifest) -> (f64, f64, f64) {
    let driving = m.fluid.density_kg_m3() * m.gravity_m_s2 * libm::sin(layer.incline_rad());
    let viscosity = plastic_viscosity_pa_s(&m.fluid);
    let critical_m = yield_stress_pa(&m.fluid) / driving;
    let sheared_m = (layer.sheared_extent_m(m.spacing_m) - critical_m).max(0.0);
    (
        driving,
        critical_m,
        driving * sheared_m * sheared_m / (2.0 * viscosity),
    )
}

impl InclinedLayer {
    /// The closed form's along-slope speed at `y_m` above the floor: the sheared zone's
    /// (rho g sin theta / mu_p) ((h - h_c) y - y^2 / 2) below h - h_c, the plug's U above.
    /// With the layer's depth on the lattice (whole rows) and its h_c and U. With a slipping
    /// floor, `y_m` is the distance from the nearer side wall.
    pub fn closed_form_speed_m_s(&self, m: &Manifest, y_m: f64) -> (f64, f64, f64) {
        let (driving, critical_m, plug_m_s) = closed_form(self, m);
        let sheared_m = (self.sheared_extent_m(m.spacing_m) - critical_m).max(0.0);
        let y = y_m.clamp(0.0, sheared_m);
        let speed = driving / plastic_viscosity_pa_s(&m.fluid) * (sheared_m * y - 0.5 * y * y);
        (speed, critical_m, plug_m_s)
    }
}

impl Experiment for InclinedLayer {
    fn check(&self, m: &Manifest, c: &mut Checker) {
        let width_ok = if m.dimension == 3 && self.width_m.is_none() {
            c.fail(
                "scene.width_m",
                "required in 3D: the width of the channel between the side walls (the neighbour grid has one periodic axis)".into(),
            );
            false
        } else {
            check_3d_only(m, c, "scene.width_m", self.width_m, POSITIVE, "a 2D layer has no width")
        };
        let slip_ok = check_3d_only(
            m,
            c,
            "scene.side_slip_length_m",
            self.side_slip_length_m,
            NON_NEGATIVE,
            "a 2D layer has no side walls",
        );
        let floor_ok = check_3d_only(
            m,
            c,
            "scene.floor_slip_length_m",
            self.floor_slip_length_m,
            NON_NEGATIVE,
            "a 2D layer on a slipping floor has nothing to hold it",
        );
        let held_ok = if self.floor_slip_length_m.is_some() && self.side_slip_length_m.is_some() {
            c.fail(
                "scene.floor_slip_length_m",
                "needs side walls that grip (scene.side_slip_length_m absent): with the floor and the side walls slipping nothing holds the layer".into(),
            );
            false
        } else {
            true
        };
        if let Some(disorder) = self.disorder {
            // A quarter spacing keeps every particle 0.75 l0 from the floor's wall row and its
            // neighbours apart by more than the collision distance's half spacing.
            c.real("scene.disorder", disorder, between(0.0, true, 0.25, true));
        }
        let depth_ok = c.real("scene.layer_depth_m", self.layer_depth_m, POSITIVE);
        let period_ok = c.real("scene.period_m", self.period_m, POSITIVE);
        c.real(
            "scene.incline_deg",
            self.incline_deg,
            between(0.0, false, 90.0, false),
        );
        if !(depth_ok && period_ok && width_ok && slip_ok && floor_ok && held_ok && super::spacing_ok(m)) {
            return;
        }
        let mut lengths = vec![
            ("scene.layer_depth_m", self.layer_depth_m),
            ("scene.period_m", self.period_m),
        ];
        lengths.extend(self.width_m.map(|w| ("scene.width_m", w)));
        c.lattice_lengths(&lengths, m.spacing_m);
        let shortest = PeriodicX::min_period_m(m.mps.laplacian_radius * m.spacing_m, m.spacing_m);
        if self.period(m.spacing_m).period_m < shortest {
            c.fail(
                "scene.period_m",
                format!(
                    "must be >= 3 (mps.laplacian_radius + 0.5) spacing_m = {} (the periodic neighbour grid needs three list cells), got {}",
                    fmt_num(shortest),
                    fmt_num(self.period_m)
                ),
            );
        }
    }
    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        let l0 = m.spacing_m;
        let columns = cells(self.period_m, l0);
        let rows = cells(self.layer_depth_m, l0);
        let layers = i64::from(m.mps.wall_layers + m.mps.dummy_layers);
        // 3D: the channel's width in cells (1 in 2D, where axis 1 is the vertical).
        let width = if D == 3 {
            cells(self.width_m.unwrap_or(0.0), l0)
        } else {
            1
        };
        let walls = i64::from(m.mps.wall_layers);
        let mut particles = Particles::<D>::default();
        let mut lo = [0i64; D];
        let mut hi = [1i64; D];
        hi[0] = columns;
        if D == 3 {
            hi[1] = width;
        }
        hi[D - 1] = rows;
        let disorder_m = self.disorder.unwrap_or(0.0) * l0;
        let mut draws = SplitMix64::new(self.disorder_seed.unwrap_or(1));
        let period_m = self.period(l0).period_m;
        for_each_index(lo, hi, |idx| {
            let mut x = centre(idx, l0);
            if disorder_m > 0.0 {
                for a in 0..D {
                    x[a] += disorder_m * (2.0 * draws.unit() - 1.0);
                }
                x[0] = x[0].rem_euclid(period_m);
            }
            particles.push(x, ParticleKind::Fluid)
        });
        // The floor: wall rows on top, dummies below, across the whole period (and in 3D
        // under the side walls too).
        if D == 3 {
            lo[1] = -layers;
            hi[1] = width + layers;
        }
        lo[D - 1] = -layers;
        hi[D - 1] = 0;
        let floor_first = particles.len();
        for_each_index(lo, hi, |idx| {
            let kind = if idx[D - 1] >= -walls {
                ParticleKind::Wall
            } else {
                ParticleKind::Dummy
            };
            particles.push(centre(idx, l0), kind)
        });
        let mut bodies = Vec::new();
        if let (3, Some(slip_length_m)) = (D, self.floor_slip_length_m) {
            bodies.push(slipping_walls(floor_first, particles.len(), slip_length_m));
        }
        if D == 3 {
            let first = particles.len();
            // The side walls: wall rows next to the fluid, dummies behind, from the floor to
            // three rows above the layer, over the whole period.
            for (from, to) in [(-layers, 0), (width, width + layers)] {
                lo[1] = from;
                hi[1] = to;
                lo[D - 1] = 0;
                hi[D - 1] = rows + 3;
                for_each_index(lo, hi, |idx| {
                    let behind = if idx[1] < 0 { -idx[1] } else { idx[1] - width + 1 };
                    let kind = if behind <= walls {
                        ParticleKind::Wall
                    } else {
                        ParticleKind::Dummy
                    };
                    particles.push(centre(idx, l0), kind)
                });
            }
            // With a slip length the side walls are a body at rest, whose surface the viscous
            // terms treat as slipping (`mps::viscosity::SlipWall`).
            if let Some(slip_length_m) = self.side_slip_length_m {
                bodies.push(slipping_walls(first, particles.len(), slip_length_m));
            }
        }
        let (domain_min_m, domain_max_m) = self.domain::<D>(m);
        Scene {
            particles,
            domain_min_m,
            domain_max_m,
            bodies,
            inlets: Vec::new(),
            gravity_tilt_rad: self.incline_rad(),
            periodic_x: Some(self.period(l0)),
            symmetry: Default::default(),
        }
    }
    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>) {
        let l0 = m.spacing_m;
        let period = self.period(l0).period_m;
        let depth = self.depth_m(l0);
        let floor = f64::from(m.mps.wall_layers + m.mps.dummy_layers + 1) * l0;
        let mut lo = Vector::<D>::zeros();
        let mut hi = Vector::<D>::zeros();
        // x never leaves the period; a layer that lifts off by more than its depth has failed.
        lo[0] = -period;
        hi[0] = 2.0 * period;
        if D == 3 {
            lo[1] = -floor;
            hi[1] = self.width(l0) + floor;
        }
        lo[D - 1] = -floor;
        hi[D - 1] = 2.0 * depth + floor;
        (lo, hi)
    }
    fn metric_names(&self, _m: &Manifest) -> Vec<&'static str> {
        vec![
            "plug_speed_m_s",
            "closed_form_plug_speed_m_s",
            "closed_form_critical_depth_m",
            "layer_depth_m",
            "fluid_max_speed_m_s",
        ]
    }
    fn metrics<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
        _time_s: f64,
        out: &mut BTreeMap<String, f64>,
    ) {
        let depth_m = self.depth_m(m.spacing_m);
        let (_, critical_m, plug_m_s) = closed_form(self, m);
        let width_m = self.width(m.spacing_m);
        // 3D: only the middle third of the channel, away from the side walls.
        let in_middle = |x: &Vector<D>| D != 3 || (x[1] >= width_m / 3.0 && x[1] <= 2.0 * width_m / 3.0);
        let (mut sum, mut count, mut fastest) = (0.0, 0usize, 0.0f64);
        for i in 0..particles.len() {
            if particles.kind[i] != ParticleKind::Fluid {
                continue;
            }
            let v = particles.velocity_m_s[i];
            fastest = fastest.max(v.norm_squared());
            let x = &particles.position_m[i];
            if x[D - 1] >= (1.0 - PLUG_SHARE) * depth_m && in_middle(x) {
                sum += v[0];
                count += 1;
            }
        }
        out.insert(
            "plug_speed_m_s".into(),
            if count > 0 { sum / count as f64 } else { 0.0 },
        );
        out.insert("closed_form_plug_speed_m_s".into(), plug_m_s);
        out.insert("closed_form_critical_depth_m".into(), critical_m);
        out.insert("layer_depth_m".into(), depth_m);
        out.insert("fluid_max_speed_m_s".into(), fastest.sqrt());
    }
    fn trend_metric(&self) -> &'static str {
        "plug_speed_m_s"
    }
}
