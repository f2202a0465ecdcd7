//! Column collapse (validation, docs/design.md section 5): a Bingham column in the dam-break tank
//! collapses against the wall at x = 0 and comes to rest as a heap whose length has a closed
//! form from lubrication theory, L = (3A/2)^(2/3) (rho g / (2 tau_y))^(1/3) for a
//! cross-section A, with the surface h = sqrt(2 tau_y d / (rho g)) at a distance d back from
//! the front.
use super::dam_break::{DamBreak, check_tank};
use super::{Experiment, Manifest, Scene, yield_stress_pa};
use crate::manifest::validate::Checker;
use crate::mps::{ParticleKind, Particles, Vector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// `scene: {kind: column_collapse}`: the dam-break tank and column, the same fields with
/// the same defaults.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ColumnCollapse {
    pub tank: DamBreak,
}

impl Experiment for ColumnCollapse {
    fn flow_measures(&self) -> &'static [&'static str] {
        &["heap_length_m"]
    }

    fn check(&self, m: &Manifest, c: &mut Checker) {
        check_tank(&self.tank, m, c);
        if yield_stress_pa(&m.fluid) <= 0.0 {
            c.fail(
                "fluid.model",
                "scene.kind column_collapse compares with a yield-stress heap: the fluid needs a yield stress > 0 (bingham or bi_viscosity)".to_string(),
            );
        }
    }
    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        self.tank.build::<D>(m)
    }
    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>) {
        self.tank.domain::<D>(m)
    }
    fn metric_names(&self, _m: &Manifest) -> Vec<&'static str> {
        vec!["heap_length_m", "closed_form_heap_length_m"]
    }
    fn metrics<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
        _time_s: f64,
        out: &mut BTreeMap<String, f64>,
    ) {
        let l0 = m.spacing_m;
        out.insert(
            "heap_length_m".into(),
            super::front_position_m(particles, l0),
        );
        // A: the fluid's cross-section (its volume per unit depth in 3D).
        let fluid = particles.count(ParticleKind::Fluid) as f64;
        let cell_m2 = l0 * l0;
        let area_m2 = if D == 3 {
            let depth_m = super::geometry::lattice::cells(self.tank.tank_depth_m, l0) as f64 * l0;
            fluid * cell_m2 * l0 / depth_m
        } else {
            fluid * cell_m2
        };
        out.insert(
            "closed_form_heap_length_m".into(),
            closed_form_heap_length_m(
                area_m2,
                m.fluid.density_kg_m3(),
                m.gravity_m_s2,
                yield_stress_pa(&m.fluid),
            ),
        );
    }
    fn trend_metric(&self) -> &'static str {
        "heap_length_m"
    }
}

/// L = (3A/2)^(2/3) (rho g / (2 tau_y))^(1/3) = cbrt((3A/2)^2 rho g / (2 tau_y)) (cube root
/// from libm: the value is recorded and compared bit for bit).
pub fn closed_form_heap_length_m(
    area_m2: f64,
    density_kg_m3: f64,
    gravity_m_s2: f64,
    yield_stress_pa: f64,
) -> f64 {
    let a = 1.5 * area_m2;
    libm::cbrt(a * a * density_kg_m3 * gravity_m_s2 / (2.0 * yield_stress_pa))
}
