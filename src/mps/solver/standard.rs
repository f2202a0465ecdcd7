//! (8) of the standard scheme (`PressureScheme::Standard`): number density n*, free
//! surface, the PPE for the whole pressure (Koshizuka & Oka; docs/design.md section 3), and the
//! correction with the p_j - p_min gradient.

use super::{Solver, SourceTerm, StepError, per_particle};
use crate::mps::grid::{Neighbours, entry_index};
use crate::mps::kernel::weight;
use crate::mps::multigrid::Multigrid;
use crate::mps::operators::{gradient, number_density};
use crate::mps::particles::{ParticleKind, Vector};
use crate::mps::pressure::{Preconditioner, SolveReport, solve_pcg};
use crate::mps::reduce::PARTICLES_PER_TASK;
use crate::mps::sparse::CsrMatrix;
use rayon::prelude::*;
use std::time::Instant;

impl<const D: usize> Solver<D> {
    /// (8) of the standard scheme: n*, free surface, PPE for the whole pressure, and the
    /// correction with the p_j - p_min gradient. Returns the PPE report and the surface count.
    pub(super) fn standard_projection(
        &mut self,
        dt_s: f64,
        start_density: Option<&[f64]>,
    ) -> Result<(SolveReport, usize), StepError> {
        // Number density n*, free surface, pressure Poisson equation.
        let pressure_started = Instant::now();
        let number_density = self.number_density();
        let threshold = self.config.surface_threshold * self.refs.n0;
        let surface: Vec<bool> = number_density
            .par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .map(|&n| n < threshold)
            .collect();
        let source = self.pressure_source(dt_s, start_density.unwrap_or(&number_density));
        let kind = &self.particles.kind;
        let surface_count = (0..kind.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .filter(|&i| kind[i] == ParticleKind::Fluid && surface[i])
            .count();
        let (ppe, solve_s) = self.solve_pressure(dt_s, &source, &surface);
        self.timing.pressure_solve_s += solve_s;
        self.timing.ppe_iterations += u64::from(ppe.iterations);
        self.timing.pressure_assembly_s += pressure_started.elapsed().as_secs_f64() - solve_s;
        self.check_pressure_solve(&ppe)?;

        // Correct velocity and position with the pressure gradient.
        self.correct_with_pressure_gradient(dt_s);
        Ok((ppe, surface_count))
    }

    /// A PPE solve that met a non-finite value or did not converge fails the step.
    pub(super) fn check_pressure_solve(&self, ppe: &SolveReport) -> Result<(), StepError> {
        if ppe.relative_residual.is_nan() {
            return Err(StepError::NonFiniteSolve {
                solve: "pressure",
                step: self.step,
            });
        }
        if !ppe.converged {
            return Err(StepError::PressureNotConverged {
                residual: ppe.relative_residual,
                iterations: ppe.iterations,
                step: self.step,
            });
        }
        Ok(())
    }

    /// n_i with radius re_n at the current positions, over all active particles (dummies
    /// included: they fill the wall's support).
    pub(super) fn number_density(&self) -> Vec<f64> {
        let p = &self.particles;
        let nb = &self.pairs.near;
        let re = self.refs.radius_n_m;
        (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| number_density(&p.position_m, nb, i, re, |_| true))
            .collect()
    }

    /// Right-hand side of the PPE per particle (see [`SourceTerm`]); `density` is n* for the
    /// number-density source and n^k for the mixed one.
    pub(super) fn pressure_source(&self, dt_s: f64, density: &[f64]) -> Vec<f64> {
        let c = &self.config;
        let p = &self.particles;
        let nb = &self.pairs.near;
        let refs = self.refs;
        let rho = c.density_kg_m3;
        let density_scale = c.relaxation_coefficient * rho / (dt_s * dt_s);
        let mixed = c.source_term == SourceTerm::Mixed;
        (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                let mut b = density_scale * (density[i] - refs.n0) / refs.n0;
                if mixed && p.kind[i].has_pressure() {
                    // Divergence model: d/n0 sum_j (u_j - u_i) . r_ij w / |r_ij|^2.
                    let mut div = 0.0;
                    for &e in nb.of(i) {
                        let j = entry_index(e);
                        let r = nb.displacement(&p.position_m, i, e);
                        let r2 = r.norm_squared();
                        let w = weight(r2.sqrt(), refs.radius_n_m);
                        if w > 0.0 {
                            div += (nb.reflect(e, p.velocity_m_s[j]) - p.velocity_m_s[i]).dot(&r)
                                * w
                                / r2;
                        }
                    }
                    b -= rho / dt_s * div * (D as f64 / refs.n0);
                }
                b
            })
            .collect()
    }

    /// PPE (Koshizuka & Oka): -<lap p>_i + rho kappa p_i / dt^2 = source_i for fluid and wall
    /// particles not on the surface; p = 0 on the surface (Dirichlet).
    /// Assembled once in CSR and solved by Jacobi-PCG; the pressure is clipped at
    /// `pressure_floor_pa` (0: no negative pressure).
    /// Returns the solver's report and the seconds spent in the CG solve.
    pub(super) fn solve_pressure(
        &mut self,
        dt_s: f64,
        source: &[f64],
        surface: &[bool],
    ) -> (SolveReport, f64) {
        let p = &self.particles;
        let unknown_of: Vec<u32> = {
            let mut next = 0u32;
            (0..p.len())
                .map(|i| {
                    if p.kind[i].has_pressure() && !surface[i] {
                        next += 1;
                        next - 1
                    } else {
                        u32::MAX
                    }
                })
                .collect()
        };
        let rows: Vec<usize> = (0..p.len())
            .filter(|&i| unknown_of[i] != u32::MAX)
            .collect();
        let (matrix, _) = self.assemble_ppe(
            dt_s,
            &rows,
            &unknown_of,
            |j| p.kind[j].has_pressure(),
            |_| 0.0,
        );
        let rhs: Vec<f64> = rows.iter().map(|&i| source[i]).collect();
        // Warm start from the previous pressure (part of the recorded state, so replays and
        // resumed runs start the solver from the same guess).
        let mut solution: Vec<f64> = rows.iter().map(|&i| p.pressure_pa[i]).collect();
        let solve_started = Instant::now();
        let report = self.solve_ppe_system(&matrix, &rhs, &mut solution, &rows);
        let solve_s = solve_started.elapsed().as_secs_f64();
        let floor_pa = self.config.pressure_floor_pa;
        let pressure = &mut self.particles.pressure_pa;
        pressure.iter_mut().for_each(|v| *v = 0.0);
        for (k, &i) in rows.iter().enumerate() {
            pressure[i] = solution[k].max(floor_pa);
        }
        (report, solve_s)
    }

    /// The PPE matrix -<lap>_i + rho kappa / dt^2 (eq. 4, Laplacian radius) on the particles
    /// `rows` (unknown k at particle rows[k], `unknown_of` its inverse, u32::MAX for none),
    /// over the neighbours j with `include(j)`. A neighbour that is no unknown has the known
    /// value `known(j)`; returns per row the sum of a_ij known(j), which belongs on the right
    /// side.
    pub(super) fn assemble_ppe(
        &self,
        dt_s: f64,
        rows: &[usize],
        unknown_of: &[u32],
        include: impl Fn(usize) -> bool + Sync,
        known: impl Fn(usize) -> f64 + Sync,
    ) -> (CsrMatrix, Vec<f64>) {
        let p = &self.particles;
        let nb = &self.pairs.lap;
        let refs = self.refs;
        let coef = 2.0 * D as f64 / (refs.lambda_m2 * refs.n0_lap);
        let diag_extra =
            self.config.density_kg_m3 * self.config.compressibility_1_pa / (dt_s * dt_s);
        CsrMatrix::assemble(rows.len(), |k, columns, values| {
            let i = rows[k];
            let mut diag = diag_extra;
            let mut known_sum = 0.0;
            for &e in nb.of(i) {
                let j = entry_index(e);
                // i's own mirror image carries p_i: its term p_i' - p_i vanishes.
                if !include(j) || Neighbours::is_own_image(e, i) {
                    continue;
                }
                let a = coef
                    * weight(
                        nb.displacement(&p.position_m, i, e).norm(),
                        refs.radius_lap_m,
                    );
                if a == 0.0 {
                    continue;
                }
                diag += a;
                if unknown_of[j] != u32::MAX {
                    columns.push(unknown_of[j]);
                    values.push(-a);
                } else {
                    known_sum += a * known(j);
                }
            }
            (diag, known_sum)
        })
    }

    /// Solves the PPE `matrix` (rows at particles `rows`) by PCG from the guess in `solution`,
    /// preconditioned by Jacobi or by aggregation multigrid, whose aggregates follow each
    /// unknown's lattice cell (spacings from the origin).
    pub(super) fn solve_ppe_system(
        &self,
        matrix: &CsrMatrix,
        rhs: &[f64],
        solution: &mut [f64],
        rows: &[usize],
    ) -> SolveReport {
        let c = &self.config;
        let p = &self.particles;
        let multigrid = c.multigrid_ppe.then(|| {
            let l0 = c.spacing_m;
            let cells: Vec<[i64; 3]> = rows
                .iter()
                .map(|&i| {
                    let x = p.position_m[i];
                    std::array::from_fn(|a| if a < D { (x[a] / l0).floor() as i64 } else { 0 })
                })
                .collect();
            Multigrid::new(
                matrix,
                &cells,
                c.multigrid_over_correction,
                c.multigrid_single_precision,
            )
        });
        solve_pcg(
            matrix,
            rhs,
            solution,
            c.ppe_tolerance,
            c.ppe_max_iterations,
            multigrid
                .as_ref()
                .map_or(Preconditioner::Jacobi, Preconditioner::Multigrid),
        )
    }

    /// u += -dt/rho <grad p>, r += dt * (change of u), with the gradient model (eq. 3) using
    /// p_j - min_k p_k over i and its neighbours (keeps the pair force repulsive).
    pub(super) fn correct_with_pressure_gradient(&mut self, dt_s: f64) {
        let p = &self.particles;
        let nb = &self.pairs.near;
        let refs = self.refs;
        let scale = -dt_s / self.config.density_kg_m3;
        let dv: Vec<Vector<D>> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                if p.kind[i] != ParticleKind::Fluid {
                    return Vector::<D>::zeros();
                }
                let mut p_min = p.pressure_pa[i];
                for &e in nb.of(i) {
                    let j = entry_index(e);
                    if p.kind[j].has_pressure()
                        && weight(nb.displacement(&p.position_m, i, e).norm(), refs.radius_n_m)
                            > 0.0
                    {
                        p_min = p_min.min(p.pressure_pa[j]);
                    }
                }
                gradient(&p.position_m, nb, i, refs.radius_n_m, refs.n0, |j| {
                    p.kind[j].has_pressure().then(|| p.pressure_pa[j] - p_min)
                }) * scale
            })
            .collect();
        let p = &mut self.particles;
        per_particle(&mut p.velocity_m_s, &mut p.position_m, |i, v, x| {
            *v += dv[i];
            *x += dv[i] * dt_s;
        });
    }
}
