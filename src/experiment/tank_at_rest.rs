//! Tank at rest (issue "A quiet core"): a closed tank filled to a flat level, started at
//! rest. The exact answer is that nothing moves: the speed stays zero, the pressure is
//! hydrostatic, p = rho g (H - y), and the surface stays where it is. What a scheme makes of
//! it measures its noise (docs/validation.md, "Holding still"). Any fluid model: with a yield
//! stress the layer must also stay rigid.
use super::dam_break::{self, DamBreak};
use super::geometry::lattice::cells;
use super::{Experiment, Extreme, Manifest, Scene};
use crate::manifest::validate::{Checker, NON_NEGATIVE, POSITIVE, fmt_num};
use crate::mps::particles::cell_volume;
use crate::mps::{ParticleKind, Particles, Vector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The height percentile that stands for the free surface (robust to a few splashed
/// particles, which the maximum is not).
const SURFACE_PERCENTILE: f64 = 0.99;

/// `scene: {kind: tank_at_rest}`: the tank's lower-left(-front) inner corner is the origin,
/// the fill spans the whole floor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TankAtRest {
    /// Inner width of the tank along x, in metres.
    pub tank_width_m: f64,
    /// Inner depth of the tank along y (3D only), in metres.
    pub tank_depth_m: f64,
    /// Inner height of the tank, in metres (>= fill_height_m).
    pub tank_height_m: f64,
    /// Height H of the fill, in metres.
    pub fill_height_m: f64,
    /// Start of the window over which `max_speed_after_settling_m_s` is taken, in seconds
    /// (the first steps build the pressure up from zero); a run that ends before it has no
    /// such summary metric.
    pub settling_time_s: f64,
}

impl Default for TankAtRest {
    fn default() -> Self {
        Self {
            tank_width_m: 1.0,
            tank_depth_m: 0.15,
            tank_height_m: 0.4,
            fill_height_m: 0.3,
            settling_time_s: 0.5,
        }
    }
}

impl TankAtRest {
    /// The dam-break geometry with a column as wide as the tank.
    fn tank(&self) -> DamBreak {
        DamBreak {
            tank_width_m: self.tank_width_m,
            tank_height_m: self.tank_height_m,
            tank_depth_m: self.tank_depth_m,
            column_width_m: self.tank_width_m,
            column_height_m: self.fill_height_m,
            side_slip_length_m: None,
        }
    }

    /// The fill height H on the lattice (whole rows of particles).
    fn fill_m(&self, spacing_m: f64) -> f64 {
        cells(self.fill_height_m, spacing_m) as f64 * spacing_m
    }
}

impl Experiment for TankAtRest {
    fn check(&self, m: &Manifest, c: &mut Checker) {
        let dims = [
            ("scene.tank_width_m", self.tank_width_m),
            ("scene.tank_depth_m", self.tank_depth_m),
            ("scene.tank_height_m", self.tank_height_m),
            ("scene.fill_height_m", self.fill_height_m),
        ];
        let mut all_ok = true;
        for (field, x) in dims {
            all_ok &= c.real(field, x, POSITIVE);
        }
        all_ok &= c.real("scene.settling_time_s", self.settling_time_s, NON_NEGATIVE);
        if !all_ok {
            return;
        }
        if self.fill_height_m > self.tank_height_m {
            c.fail(
                "scene.fill_height_m",
                format!(
                    "must be <= scene.tank_height_m ({}), got {}",
                    fmt_num(self.tank_height_m),
                    fmt_num(self.fill_height_m)
                ),
            );
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
    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        dam_break::build::<D>(&self.tank(), m.spacing_m, m.mps.wall_layers, m.mps.dummy_layers)
    }
    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>) {
        dam_break::domain::<D>(&self.tank(), m.spacing_m)
    }
    fn metric_names(&self, _m: &Manifest) -> Vec<&'static str> {
        vec![
            "fluid_max_speed_m_s",
            "fluid_kinetic_energy_j",
            "bottom_pressure_pa",
            "closed_form_bottom_pressure_pa",
            "bottom_pressure_error",
            "surface_height_m",
            "surface_height_change_m",
        ]
    }
    fn metrics<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
        _time_s: f64,
        out: &mut BTreeMap<String, f64>,
    ) {
        let l0 = m.spacing_m;
        let fluid: Vec<usize> = (0..particles.len())
            .filter(|&i| particles.kind[i] == ParticleKind::Fluid)
            .collect();
        if fluid.is_empty() {
            return;
        }
        let mass_kg = m.fluid.density_kg_m3() * cell_volume(l0, D);
        let (mut speed, mut kinetic) = (0.0f64, 0.0);
        for &i in &fluid {
            let v2 = particles.velocity_m_s[i].norm_squared();
            speed = speed.max(v2);
            kinetic += 0.5 * mass_kg * v2;
        }
        out.insert("fluid_max_speed_m_s".into(), speed.sqrt());
        out.insert("fluid_kinetic_energy_j".into(), kinetic);

        // The lowest row: fluid within half a spacing of the lowest particle.
        let height = |i: usize| particles.position_m[i][D - 1];
        let lowest = fluid.iter().map(|&i| height(i)).fold(f64::INFINITY, f64::min);
        let fill_m = self.fill_m(l0);
        let rho_g = m.fluid.density_kg_m3() * m.gravity_m_s2;
        let (mut pressure, mut closed, mut count) = (0.0, 0.0, 0usize);
        for &i in &fluid {
            if height(i) < lowest + 0.5 * l0 {
                pressure += particles.pressure_pa[i];
                closed += rho_g * (fill_m - height(i));
                count += 1;
            }
        }
        let (pressure, closed) = (pressure / count as f64, closed / count as f64);
        out.insert("bottom_pressure_pa".into(), pressure);
        out.insert("closed_form_bottom_pressure_pa".into(), closed);
        out.insert("bottom_pressure_error".into(), pressure / closed - 1.0);

        let mut heights: Vec<f64> = fluid.iter().map(|&i| height(i)).collect();
        heights.sort_by(f64::total_cmp);
        let surface = heights[rank(heights.len(), SURFACE_PERCENTILE)];
        out.insert("surface_height_m".into(), surface);
        // At t = 0 each of the fill's rows holds one particle per floor cell: the rank's row.
        let rows = cells(self.fill_height_m, l0) as usize;
        let per_row = if D == 3 {
            cells(self.tank_width_m, l0) * cells(self.tank_depth_m, l0)
        } else {
            cells(self.tank_width_m, l0)
        } as usize;
        let start_row = (rank(rows * per_row, SURFACE_PERCENTILE) / per_row) as f64;
        out.insert(
            "surface_height_change_m".into(),
            surface - (start_row + 0.5) * l0,
        );
    }
    fn trend_metric(&self) -> &'static str {
        "bottom_pressure_error"
    }
    fn extremes(&self, _m: &Manifest) -> Vec<Extreme> {
        vec![
            Extreme {
                name: "max_speed_after_settling_m_s",
                metric: "fluid_max_speed_m_s",
                since_s: self.settling_time_s,
            },
            Extreme {
                name: "kinetic_energy_max_j",
                metric: "fluid_kinetic_energy_j",
                since_s: 0.0,
            },
        ]
    }
}

/// 0-based index of the nearest-rank `q` quantile of `n` sorted values: ceil(q n) - 1.
fn rank(n: usize, q: f64) -> usize {
    ((q * n as f64).ceil() as usize).clamp(1, n.max(1)) - 1
}
