//! Inclined layer (issue "A quiet core"): a layer of depth h on a plane inclined at theta,
//! periodic along the slope, no-slip floor, free surface, started at rest. Modelled as a
//! level floor under gravity tilted by theta towards +x. Closed form for a Bingham fluid
//! (yield stress tau_0, plastic viscosity mu_p): the wall stress is rho g sin(theta) h, so the
//! layer stays rigid when h <= h_c = tau_0 / (rho g sin theta); above, it shears in a bottom
//! zone of thickness h - h_c under a plug moving at U = rho g sin(theta) (h - h_c)^2 / (2 mu_p)
//! (a Newtonian film, tau_0 = 0: the Nusselt surface speed rho g sin(theta) h^2 / (2 mu)).
//! 2D only: the neighbour grid has one periodic axis.
use super::geometry::lattice::{cells, centre, for_each_index};
use super::{Experiment, Manifest, Scene, require_2d, yield_stress_pa};
use crate::manifest::validate::{Checker, POSITIVE, between, fmt_num};
use crate::manifest::Fluid;
use crate::mps::{ParticleKind, Particles, PeriodicX, Vector};
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
}

impl Default for InclinedLayer {
    fn default() -> Self {
        Self {
            layer_depth_m: 0.04,
            period_m: 0.2,
            incline_deg: 5.0,
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
    fn period(&self, spacing_m: f64) -> PeriodicX {
        PeriodicX {
            min_m: 0.0,
            period_m: cells(self.period_m, spacing_m) as f64 * spacing_m,
        }
    }
}

/// (rho g sin theta, h_c, U) of the closed form for `m`'s fluid.
fn closed_form(layer: &InclinedLayer, m: &Manifest) -> (f64, f64, f64) {
    let driving = m.fluid.density_kg_m3() * m.gravity_m_s2 * libm::sin(layer.incline_rad());
    let viscosity = match m.fluid {
        Fluid::Newtonian { viscosity_pa_s, .. } => viscosity_pa_s,
        Fluid::Bingham {
            plastic_viscosity_pa_s,
            ..
        }
        | Fluid::BiViscosity {
            plastic_viscosity_pa_s,
            ..
        } => plastic_viscosity_pa_s,
    };
    let critical_m = yield_stress_pa(&m.fluid) / driving;
    let sheared_m = (layer.depth_m(m.spacing_m) - critical_m).max(0.0);
    (
        driving,
        critical_m,
        driving * sheared_m * sheared_m / (2.0 * viscosity),
    )
}

impl Experiment for InclinedLayer {
    fn check(&self, m: &Manifest, c: &mut Checker) {
        require_2d(m, c, "inclined_layer", "its periodic axis is the only one the grid has");
        let depth_ok = c.real("scene.layer_depth_m", self.layer_depth_m, POSITIVE);
        let period_ok = c.real("scene.period_m", self.period_m, POSITIVE);
        c.real(
            "scene.incline_deg",
            self.incline_deg,
            between(0.0, false, 90.0, false),
        );
        if !(depth_ok && period_ok && super::spacing_ok(m)) {
            return;
        }
        c.lattice_lengths(
            &[
                ("scene.layer_depth_m", self.layer_depth_m),
                ("scene.period_m", self.period_m),
            ],
            m.spacing_m,
        );
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
        let mut particles = Particles::<D>::default();
        let mut lo = [0i64; D];
        let mut hi = [1i64; D];
        hi[0] = columns;
        hi[D - 1] = rows;
        for_each_index(lo, hi, |idx| {
            particles.push(centre(idx, l0), ParticleKind::Fluid)
        });
        // The floor: wall rows on top, dummies below, across the whole period.
        lo[D - 1] = -layers;
        hi[D - 1] = 0;
        for_each_index(lo, hi, |idx| {
            let kind = if idx[D - 1] >= -i64::from(m.mps.wall_layers) {
                ParticleKind::Wall
            } else {
                ParticleKind::Dummy
            };
            particles.push(centre(idx, l0), kind)
        });
        let (domain_min_m, domain_max_m) = self.domain::<D>(m);
        Scene {
            particles,
            domain_min_m,
            domain_max_m,
            bodies: Vec::new(),
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
        let (mut sum, mut count, mut fastest) = (0.0, 0usize, 0.0f64);
        for i in 0..particles.len() {
            if particles.kind[i] != ParticleKind::Fluid {
                continue;
            }
            let v = particles.velocity_m_s[i];
            fastest = fastest.max(v.norm_squared());
            if particles.position_m[i][D - 1] >= (1.0 - PLUG_SHARE) * depth_m {
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
