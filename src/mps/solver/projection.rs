//! The energy-stable increment projection of the incremental scheme
//! ([`IncrementProjection::EnergyStable`]).
//!
//! The approximate projection (`incremental.rs`) takes the source from the MPS divergence
//! (weight w/r^2, radius re_n), the matrix from the MPS Laplacian L (weight w, radius re_lap)
//! and the correction from the corrected gradient G. Because G L^-1 D is no projection, some
//! pair modes are over-corrected: a pair at 0.5 l0 gets back about 2.4 times its relative
//! velocity (README, "Holding still"), and violent flows blow up.
//!
//! Here the divergence is the adjoint of the gradient actually applied, D = -G^T (equal
//! particle volumes), and the matrix is A = G^T G + eps L. Then u = u* - G A^-1 G^T u* has
//! eigenvalues in [0, 1] on any arrangement: the correction never adds kinetic energy to any
//! mode, a close pair included (eps = 0 is the exact projection of Cummins & Rudman 1999;
//! eps L damps the odd-even pressure modes that G does not see). G is the corrected gradient
//! in difference form, so the carried pressure's force and the projection use one operator:
//! p^n + dp has exactly the gradient the projection intended.
//! - Walls and dummies carry a pressure of their own (in the state), held fixed in the
//!   projection (dp = 0 there; the adjoint then sees walls at rest, and a wall's own velocity
//!   enters D as a known term) and set after it to the fluid's pressure carried
//!   hydrostatically to them (a zero normal derivative of the dynamic pressure; exact for a
//!   hydrostatic field).
//! - Surface particles take dp = 0 in the projection and p = 0 after it: a pressure dropped at
//!   the surface acts through the carried gradient of the next step.
//!
//! At rest with p^n hydrostatic, u* = 0, the source is zero and dp = 0: nothing moves.
use super::{PARTICLES_PER_TASK, ParticleKind, SolveReport, Solver, StepError};
use crate::mps::kernel::weight;
use crate::mps::particles::Vector;
use crate::mps::pressure::CsrMatrix;
use rayon::prelude::*;
use std::time::Instant;

/// How the incremental scheme projects u* (see the module text).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IncrementProjection {
    /// MPS Laplacian matrix, corrected gradient, walls mirrored (the first incremental scheme).
    Approximate,
    /// A = G^T G + eps L with G = -D^T: never adds kinetic energy.
    EnergyStable { regularisation: f64 },
}

/// One fluid particle m's row of G: G_m dp = own dp_m + sum over `columns` of b dp_j, where
/// b = C_m r_mj w / r_mj^2 for every neighbour j within re_n (fluid, wall or dummy) and
/// own = -sum of those b (difference form).
struct GradientRow<const D: usize> {
    columns: Vec<(u32, Vector<D>)>,
    own: Vector<D>,
}

impl<const D: usize> GradientRow<D> {
    fn empty() -> Self {
        Self {
            columns: Vec::new(),
            own: Vector::<D>::zeros(),
        }
    }

    /// The coefficient of dp_k in this row (m: the row's own particle).
    fn of(&self, m: usize, k: usize) -> Vector<D> {
        if m == k {
            return self.own;
        }
        self.columns
            .iter()
            .find(|&&(j, _)| j as usize == k)
            .map_or(Vector::<D>::zeros(), |&(_, b)| b)
    }
}

impl<const D: usize> Solver<D> {
    /// Steps (3) and (4) with the energy-stable projection. Returns the PPE report and the
    /// count of surface particles.
    pub(super) fn energy_stable_projection(
        &mut self,
        dt_s: f64,
        regularisation: f64,
    ) -> Result<(SolveReport, usize), StepError> {
        let pressure_started = Instant::now();
        let c = &self.config;
        let refs = self.refs;
        let rho = c.density_kg_m3;
        let number_density = self.number_density();
        let corrections = self.gradient_corrections();
        let p = &self.particles;
        let near = &self.pairs.near;
        let radius = refs.radius_n_m;
        let is_fluid = |i: usize| p.kind[i] == ParticleKind::Fluid;
        let threshold = c.surface_threshold * refs.n0;
        let surface: Vec<bool> = (0..p.len())
            .map(|i| is_fluid(i) && number_density[i] < threshold)
            .collect();
        let surface_count = surface.iter().filter(|&&s| s).count();
        let g_rows: Vec<GradientRow<D>> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|m| {
                let mut row = GradientRow::empty();
                if !is_fluid(m) {
                    return row;
                }
                for &j in near.of(m) {
                    let r = near.displacement(&p.position_m, m, j as usize);
                    let r2 = r.norm_squared();
                    let w = weight(r2.sqrt(), radius);
                    if w > 0.0 {
                        let b = corrections[m] * (r * (w / r2));
                        row.own -= b;
                        row.columns.push((j, b));
                    }
                }
                row
            })
            .collect();
        // The fluid rows of G that hold particle x: x itself if fluid, and its fluid neighbours
        // within re_n (the pairs are symmetric).
        let holders: Vec<Vec<u32>> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|x| {
                let mut h = Vec::new();
                if is_fluid(x) {
                    h.push(x as u32);
                }
                for &m in near.of(x) {
                    if is_fluid(m as usize)
                        && weight(
                            near.displacement(&p.position_m, x, m as usize).norm(),
                            radius,
                        ) > 0.0
                    {
                        h.push(m);
                    }
                }
                h
            })
            .collect();
        // Unknowns: fluid off the surface, and every wall or dummy that some fluid row holds.
        let mut unknown_of = vec![u32::MAX; p.len()];
        let mut rows = Vec::new();
        for x in 0..p.len() {
            let unknown = if is_fluid(x) {
                !surface[x]
            } else {
                !holders[x].is_empty()
            };
            if unknown {
                unknown_of[x] = rows.len() as u32;
                rows.push(x);
            }
        }
        // Source: -(rho/dt) D u* with D = -G^T over the fluid velocities, plus the walls' own
        // velocities as known terms (relative velocity at a wall row; C_k r_kw w/r^2 . u_w at a
        // fluid row, which makes a uniform translation of fluid and walls free of divergence on
        // a lattice); at fluid rows the relaxed compression.
        let compression_scale = c.compression_relaxation * rho / (dt_s * dt_s);
        let source: Vec<f64> = rows
            .par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|&x| {
                let mut div = 0.0;
                let ux = p.velocity_m_s[x];
                for &m in &holders[x] {
                    let m = m as usize;
                    let g = g_rows[m].of(m, x);
                    if is_fluid(x) {
                        div -= g.dot(&p.velocity_m_s[m]);
                    } else {
                        div += g.dot(&(ux - p.velocity_m_s[m]));
                    }
                }
                if !is_fluid(x) {
                    return -rho / dt_s * div;
                }
                for &(j, b) in &g_rows[x].columns {
                    if !is_fluid(j as usize) {
                        div += b.dot(&p.velocity_m_s[j as usize]);
                    }
                }
                let compression = (number_density[x] - refs.n0).max(0.0) / refs.n0;
                -rho / dt_s * div + compression_scale * compression
            })
            .collect();
        // A = G^T G + eps L over the unknowns. Row x gathers G_mx . G_mk over the rows m that
        // hold x, in a fixed order, then sorts the terms by column (stable) and sums each
        // column's terms in that order. L couples the pressure nodes (fluid, and walls that
        // some fluid row holds) within re_lap; the surface's dp = 0 sits on the diagonal only.
        let lap = &self.pairs.lap;
        let lap_coef = regularisation * 2.0 * D as f64 / (refs.lambda_m2 * refs.n0_lap);
        let (matrix, _) = CsrMatrix::assemble(rows.len(), |k, columns, values| {
            let x = rows[k];
            let mut terms: Vec<(u32, f64)> = Vec::new();
            for &m in &holders[x] {
                let m = m as usize;
                let row = &g_rows[m];
                let gmx = row.of(m, x);
                if unknown_of[m] != u32::MAX {
                    terms.push((unknown_of[m], gmx.dot(&row.own)));
                }
                for &(j, b) in &row.columns {
                    if unknown_of[j as usize] != u32::MAX {
                        terms.push((unknown_of[j as usize], gmx.dot(&b)));
                    }
                }
            }
            if lap_coef > 0.0 {
                let mut diag = 0.0;
                for &j in lap.of(x) {
                    let j = j as usize;
                    if !(is_fluid(j) || unknown_of[j] != u32::MAX) {
                        continue;
                    }
                    let r = lap.displacement(&p.position_m, x, j).norm();
                    let a = lap_coef * weight(r, refs.radius_lap_m);
                    if a == 0.0 {
                        continue;
                    }
                    diag += a;
                    if unknown_of[j] != u32::MAX {
                        terms.push((unknown_of[j], -a));
                    }
                }
                terms.push((k as u32, diag));
            }
            terms.sort_by_key(|t| t.0);
            let mut diagonal = 0.0;
            let mut n = 0;
            while n < terms.len() {
                let col = terms[n].0;
                let mut v = 0.0;
                while n < terms.len() && terms[n].0 == col {
                    v += terms[n].1;
                    n += 1;
                }
                if col as usize == k {
                    diagonal = v;
                } else {
                    columns.push(col);
                    values.push(v);
                }
            }
            (diagonal, ())
        });
        let mut solution = vec![0.0; rows.len()];
        let solve_started = Instant::now();
        let ppe = self.solve_ppe_system(&matrix, &source, &mut solution, &rows);
        let solve_s = solve_started.elapsed().as_secs_f64();
        self.timing.pressure_solve_s += solve_s;
        self.timing.ppe_iterations += u64::from(ppe.iterations);
        self.check_pressure_solve(&ppe)?;

        let p = &self.particles;
        let increment: Vec<f64> = (0..p.len())
            .map(|i| match unknown_of[i] {
                u32::MAX => 0.0,
                k => solution[k as usize],
            })
            .collect();
        let correction_scale = -dt_s / rho;
        let dv: Vec<Vector<D>> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|m| {
                let row = &g_rows[m];
                let mut g = row.own * increment[m];
                for &(j, b) in &row.columns {
                    g += b * increment[j as usize];
                }
                g * correction_scale
            })
            .collect();
        // New carried pressure: p^n + dp at every unknown (fluid clipped at 0), 0 on the
        // surface and at walls no fluid row holds.
        let new_pressure: Vec<f64> = (0..p.len())
            .map(|i| match unknown_of[i] {
                u32::MAX => 0.0,
                _ if is_fluid(i) => (p.pressure_pa[i] + increment[i]).max(0.0),
                _ => p.pressure_pa[i] + increment[i],
            })
            .collect();
        self.timing.pressure_assembly_s += pressure_started.elapsed().as_secs_f64() - solve_s;
        let p = &mut self.particles;
        p.pressure_pa = new_pressure;
        super::per_particle(&mut p.velocity_m_s, &mut p.position_m, |i, v, x| {
            *v += dv[i];
            *x += dv[i] * dt_s;
        });
        Ok((ppe, surface_count))
    }
}
