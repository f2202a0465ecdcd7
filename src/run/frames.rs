//! What one step records: a diagnostics row and a point cloud of the solver's state.
use crate::experiment::{Manifest, experiment_metrics};
use crate::mps::particles::cell_volume;
use crate::mps::{ParticleKind, Solver};
use crate::proto::foxglove::PointCloud;
use crate::proto::mps::v1::Diagnostics;
use crate::record::point_cloud;

/// Simulation time in integer nanoseconds (MCAP log time).
pub fn time_ns(time_s: f64) -> u64 {
    (time_s * 1e9).round() as u64
}

pub fn diagnostics<const D: usize>(
    m: &Manifest,
    solver: &Solver<D>,
    dt_s: f64,
    report: Option<&crate::mps::StepReport>,
) -> Diagnostics {
    let p = &solver.particles;
    let mass_kg = solver.config.density_kg_m3 * cell_volume(m.spacing_m, D);
    let mut kinetic = 0.0;
    for i in 0..p.len() {
        if p.kind[i] == ParticleKind::Fluid {
            kinetic += 0.5 * mass_kg * p.velocity_m_s[i].norm_squared();
        }
    }
    Diagnostics {
        // A plot-friendly 32-bit field (docs/file-format.md): past 2^32 steps it saturates, never
        // wraps.
        step: u32::try_from(solver.step).unwrap_or(u32::MAX),
        time_s: solver.time_s,
        dt_s,
        kinetic_energy_j: kinetic,
        max_speed_m_s: solver.max_fluid_speed_m_s(),
        ppe_iterations: report.map_or(0, |r| r.ppe.iterations),
        ppe_relative_residual: report.map_or(0.0, |r| r.ppe.relative_residual),
        surface_particle_count: report.map_or(0, |r| r.surface_count as u32),
        fluid_particle_count: p.fluid_count() as u32,
        viscosity_iterations: report.map_or(0, |r| r.viscosity.iterations),
        viscosity_relative_residual: report.map_or(0.0, |r| r.viscosity.relative_residual),
        non_flowing_fraction: report.map_or(0.0, |r| r.non_flowing_fraction),
        yield_iterations: report.map_or(0, |r| r.yield_iterations),
        metrics: experiment_metrics(m, p, solver.time_s)
            .into_iter()
            .collect(),
    }
}

pub fn cloud<const D: usize>(solver: &Solver<D>) -> PointCloud {
    let p = &solver.particles;
    // Dummies only pad the walls and ghosts have left the domain: neither is shown.
    let shown: Vec<usize> = (0..p.len())
        .filter(|&i| matches!(p.kind[i], ParticleKind::Fluid | ParticleKind::Wall))
        .collect();
    let positions: Vec<f64> = shown
        .iter()
        .flat_map(|&i| p.position_m[i].iter().copied().collect::<Vec<_>>())
        .collect();
    let speed: Vec<f32> = shown
        .iter()
        .map(|&i| p.velocity_m_s[i].norm() as f32)
        .collect();
    let pressure: Vec<f32> = shown.iter().map(|&i| p.pressure_pa[i] as f32).collect();
    let kind: Vec<f32> = shown.iter().map(|&i| p.kind[i] as u32 as f32).collect();
    let tag: Vec<f32> = shown.iter().map(|&i| f32::from(p.tag[i])).collect();
    // 1 = flowing (Pi > Pi_c at the start of the last step), 0 = non-flowing or not fluid.
    let flowing: Vec<f32> = shown
        .iter()
        .map(|&i| {
            f32::from(u8::from(
                p.kind[i] == ParticleKind::Fluid && solver.is_flowing(i),
            ))
        })
        .collect();
    point_cloud(
        time_ns(solver.time_s),
        D,
        &positions,
        &[
            ("speed_m_s", &speed),
            ("pressure_pa", &pressure),
            ("kind", &kind),
            ("tag", &tag),
            ("flowing", &flowing),
        ],
    )
}
