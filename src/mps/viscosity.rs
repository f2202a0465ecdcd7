//! Viscous stage of the step: strain rate, effective viscosity, the optional stress-gradient
//! term of seed 000 eq. 8, and the implicit viscous predictor solved by CG.
use super::grid::Neighbours;
use super::kernel::{RefValues, weight};
use super::operators::gradient;
use super::particles::{ParticleKind, Particles, Vector};
use super::pressure::{CsrMatrix, SolveReport, solve_pcg};
use super::reduce::PARTICLES_PER_TASK;
use super::rheology::Rheology;
use nalgebra::SMatrix;
use rayon::prelude::*;

/// Settings of the viscous stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViscousSettings {
    pub rheology: Rheology,
    pub density_kg_m3: f64,
    /// Seed 000 eq. 8 term 2 e . grad(Lambda) / rho (explicit).
    pub stress_gradient_term: bool,
    pub tolerance: f64,
    pub max_iterations: u32,
}

/// Result of the viscous stage.
#[derive(Debug, Clone)]
pub struct ViscousStage<const D: usize> {
    /// Predicted velocity u* of every particle (walls keep theirs).
    pub velocity_m_s: Vec<Vector<D>>,
    /// Strain-rate invariant Pi = 2 e:e per particle (0 for non-fluid).
    pub strain_invariant: Vec<f64>,
    /// Worst CG report over the velocity components (iterations summed).
    pub solve: SolveReport,
}

/// Velocity gradient G_ab = d u_a / d x_b at fluid particle i by the gradient model (eq. 3,
/// applied to each velocity component as in seed 000 eqs. 12-13); walls and dummies carry
/// their own velocity, which makes the floor no-slip.
pub fn velocity_gradient<const D: usize>(
    p: &Particles<D>,
    nb: &Neighbours,
    refs: &RefValues,
    i: usize,
) -> SMatrix<f64, D, D> {
    let pi = p.position_m[i];
    let ui = p.velocity_m_s[i];
    let mut g = SMatrix::<f64, D, D>::zeros();
    for &j in nb.of(i) {
        let j = j as usize;
        let r = p.position_m[j] - pi;
        let r2 = r.norm_squared();
        let w = weight(r2.sqrt(), refs.radius_n_m);
        if w == 0.0 {
            continue;
        }
        g += (p.velocity_m_s[j] - ui) * (r.transpose() * (w / r2));
    }
    g * (D as f64 / refs.n0)
}

/// Pi = 2 e_ij e_ij with e = (G + G^T)/2 (seed 000 eqs. 9-11, full tensor contraction).
pub fn strain_invariant<const D: usize>(g: &SMatrix<f64, D, D>) -> f64 {
    let e = (g + g.transpose()) * 0.5;
    2.0 * e.component_mul(&e).sum()
}

/// u* from (I - dt nu_i <lap>) u* = u^n + dt (body force + eq. 8 term), with nu_i from u^n.
/// Each row is divided by dt nu_i, which makes the matrix symmetric positive definite:
/// (1/(dt nu_i) + sum_j a_ij) u_i - sum_j a_ij u_j = rhs_i / (dt nu_i), a_ij = 2d/(lambda n0) w_ij;
/// wall and dummy velocities are known and move to the right-hand side.
pub fn predict_velocity<const D: usize>(
    p: &Particles<D>,
    nb: &Neighbours,
    refs: &RefValues,
    settings: &ViscousSettings,
    body_force_m_s2: Vector<D>,
    dt_s: f64,
) -> ViscousStage<D> {
    let rho = settings.density_kg_m3;
    let n = p.len();
    let is_fluid = |i: usize| p.kind[i] == ParticleKind::Fluid;
    let gradients: Vec<SMatrix<f64, D, D>> = (0..n)
        .into_par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .map(|i| {
            if is_fluid(i) {
                velocity_gradient(p, nb, refs, i)
            } else {
                SMatrix::zeros()
            }
        })
        .collect();
    let strain: Vec<f64> = gradients
        .par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .map(strain_invariant)
        .collect();
    let rheology = settings.rheology;

    // Explicit part: u^n + dt (f + 2 e . grad(Lambda) / rho).
    let lambda: Vec<f64> = strain
        .par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .map(|&s| rheology.yield_viscosity_pa_s(s))
        .collect();
    let rhs: Vec<Vector<D>> = (0..n)
        .into_par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .map(|i| {
            if !is_fluid(i) {
                return p.velocity_m_s[i];
            }
            let mut accel = body_force_m_s2;
            if settings.stress_gradient_term {
                let grad_lambda =
                    gradient(&p.position_m, nb.of(i), i, refs.radius_n_m, refs.n0, |j| {
                        is_fluid(j).then(|| lambda[j] - lambda[i])
                    });
                let g = &gradients[i];
                let e = (g + g.transpose()) * 0.5;
                accel += e * grad_lambda * (2.0 / rho);
            }
            p.velocity_m_s[i] + accel * dt_s
        })
        .collect();

    let nu: Vec<f64> = strain
        .iter()
        .map(|&s| rheology.viscosity_pa_s(s) / rho)
        .collect();
    let rows: Vec<usize> = (0..n).filter(|&i| is_fluid(i) && nu[i] > 0.0).collect();
    let mut velocity = rhs.clone();
    let mut solve = SolveReport {
        iterations: 0,
        relative_residual: 0.0,
        converged: true,
    };
    if rows.is_empty() {
        return ViscousStage {
            velocity_m_s: velocity,
            strain_invariant: strain,
            solve,
        };
    }
    let mut row_of = vec![u32::MAX; n];
    for (k, &i) in rows.iter().enumerate() {
        row_of[i] = k as u32;
    }
    let coef = 2.0 * D as f64 / (refs.lambda_m2 * refs.n0_lap);
    // Per row: diagonal, scale 1/(dt nu_i), known boundary contribution, fluid couplings.
    let assembled: Vec<(f64, f64, Vector<D>, Vec<(u32, f64)>)> = rows
        .par_iter()
        .map(|&i| {
            let scale = 1.0 / (dt_s * nu[i]);
            let mut diag = scale;
            let mut boundary = Vector::<D>::zeros();
            let mut entries = Vec::new();
            for &j in nb.of(i) {
                let j = j as usize;
                let a = coef
                    * weight(
                        (p.position_m[j] - p.position_m[i]).norm(),
                        refs.radius_lap_m,
                    );
                if a == 0.0 {
                    continue;
                }
                diag += a;
                if row_of[j] != u32::MAX {
                    entries.push((row_of[j], -a));
                } else {
                    boundary += p.velocity_m_s[j] * a;
                }
            }
            (diag, scale, boundary, entries)
        })
        .collect();
    let mut matrix = CsrMatrix {
        row_offsets: vec![0],
        ..Default::default()
    };
    for (diag, _, _, entries) in &assembled {
        matrix.diagonal.push(*diag);
        for &(c, v) in entries {
            matrix.columns.push(c);
            matrix.values.push(v);
        }
        matrix.row_offsets.push(matrix.columns.len());
    }
    for axis in 0..D {
        let b: Vec<f64> = rows
            .iter()
            .zip(&assembled)
            .map(|(&i, (_, scale, boundary, _))| rhs[i][axis] * scale + boundary[axis])
            .collect();
        // Start from the current velocity: close to the answer, and part of the state.
        let mut x: Vec<f64> = rows.iter().map(|&i| p.velocity_m_s[i][axis]).collect();
        let report = solve_pcg(
            &matrix,
            &b,
            &mut x,
            settings.tolerance,
            settings.max_iterations,
        );
        solve.iterations += report.iterations;
        solve.relative_residual = solve.relative_residual.max(report.relative_residual);
        solve.converged &= report.converged;
        for (k, &i) in rows.iter().enumerate() {
            velocity[i][axis] = x[k];
        }
    }
    ViscousStage {
        velocity_m_s: velocity,
        strain_invariant: strain,
        solve,
    }
}
