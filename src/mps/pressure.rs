//! The step's sparse linear systems (PPE and implicit viscosity): Jacobi- or multigrid-
//! preconditioned conjugate gradient, and BiCGStab for the exact projection.
use super::multigrid::Multigrid;
use super::reduce::{CHUNK, MIN_PARALLEL_LEN, sum_by};
use super::sparse::CsrMatrix;
use rayon::prelude::*;

/// The preconditioner of a CG solve.
#[derive(Clone, Copy)]
pub enum Preconditioner<'a> {
    /// z = D^-1 r.
    Jacobi,
    /// One multigrid cycle (built for the solve's matrix).
    Multigrid(&'a Multigrid),
}

/// Outcome of a CG solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveReport {
    pub iterations: u32,
    /// ||b - A x|| / ||b|| at exit (0 when b = 0).
    pub relative_residual: f64,
    pub converged: bool,
}

/// Solves A x = b for symmetric positive definite A with the given preconditioner, starting
/// from the guess in `x`. Stops when ||r|| <= tolerance ||b||. All reductions are order-fixed
/// (docs/design.md section 6).
pub fn solve_pcg(
    a: &CsrMatrix,
    b: &[f64],
    x: &mut [f64],
    tolerance: f64,
    max_iterations: u32,
    preconditioner: Preconditioner,
) -> SolveReport {
    let b: Vec<[f64; 1]> = b.iter().map(|&v| [v]).collect();
    let mut x1: Vec<[f64; 1]> = x.iter().map(|&v| [v]).collect();
    let [report] = solve_pcg_many(a, &b, &mut x1, tolerance, max_iterations, preconditioner);
    for (x, v) in x.iter_mut().zip(&x1) {
        *x = v[0];
    }
    report
}

/// M independent solves A x_m = b_m with the same matrix (the velocity components of the
/// viscous stage), run side by side so that each matrix product serves all of them. Every
/// component goes through exactly the operations of its own [`solve_pcg`] and stops at its
/// own convergence: the bits do not depend on M.
///
/// Each iteration makes three parallel passes over fixed chunks of [`CHUNK`] rows: the
/// product A p with p . Ap, the updates of x, r and z with r . z and r . r, and the new p.
/// The dot products are summed within each chunk in row order and then over the chunks in
/// order, exactly as [`sum_by`] does (docs/design.md section 6).
pub fn solve_pcg_many<const M: usize>(
    a: &CsrMatrix,
    b: &[[f64; M]],
    x: &mut [[f64; M]],
    tolerance: f64,
    max_iterations: u32,
    preconditioner: Preconditioner,
) -> [SolveReport; M] {
    let n = a.rows();
    let dot_m = |u: &[[f64; M]], v: &[[f64; M]], m: usize| sum_by(n, |i| u[i][m] * v[i][m]);
    let b_norm: [f64; M] = std::array::from_fn(|m| dot_m(b, b, m).sqrt());
    let mut reports = [SolveReport {
        iterations: 0,
        relative_residual: 0.0,
        converged: true,
    }; M];
    // Components with b = 0 have the solution 0.
    let mut running: [bool; M] = std::array::from_fn(|m| n > 0 && b_norm[m] != 0.0);
    for m in 0..M {
        if !running[m] {
            x.iter_mut().for_each(|v| v[m] = 0.0);
        }
    }
    if !running.iter().any(|&r| r) {
        return reports;
    }
    let inv_diag: Vec<[f64; M]> = (0..n)
        .into_par_iter()
        .with_min_len(MIN_PARALLEL_LEN)
        .map(|i| std::array::from_fn(|m| 1.0 / a.diagonal_of(i, m)))
        .collect();
    let mut r = vec![[0.0; M]; n];
    a.multiply(x, &mut r);
    r.par_iter_mut()
        .with_min_len(MIN_PARALLEL_LEN)
        .zip(b)
        .for_each(|(r, b)| {
            for m in 0..M {
                r[m] = b[m] - r[m];
            }
        });
    let multigrid = match preconditioner {
        Preconditioner::Jacobi => None,
        Preconditioner::Multigrid(mg) => {
            debug_assert!(
                a.component_diagonal.is_empty(),
                "multigrid of a scalar matrix only"
            );
            Some(mg)
        }
    };
    let jacobi = multigrid.is_none();
    let mut z: Vec<[f64; M]> = if jacobi {
        r.par_iter()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&inv_diag)
            .map(|(r, d)| std::array::from_fn(|m| r[m] * d[m]))
            .collect()
    } else {
        vec![[0.0; M]; n]
    };
    // z = B r for the running components (multigrid; the Jacobi z is formed with the
    // updates).
    let cycle = |r: &[[f64; M]], z: &mut [[f64; M]], running: &[bool; M]| {
        if let Some(mg) = multigrid {
            for m in (0..M).filter(|&m| running[m]) {
                let r_m: Vec<f64> = r.iter().map(|v| v[m]).collect();
                let mut z_m = vec![0.0; n];
                mg.apply(a, &r_m, &mut z_m);
                z.iter_mut().zip(&z_m).for_each(|(z, v)| z[m] = *v);
            }
        }
    };
    cycle(&r, &mut z, &running);
    let mut p = z.clone();
    let mut ap = vec![[0.0; M]; n];
    let mut rz: [f64; M] = std::array::from_fn(|m| dot_m(&r, &z, m));
    let mut r_norm: [f64; M] = std::array::from_fn(|m| dot_m(&r, &r, m).sqrt());
    let mut alpha = [0.0; M];
    loop {
        for m in 0..M {
            if running[m]
                && (reports[m].iterations >= max_iterations || r_norm[m] <= tolerance * b_norm[m])
            {
                running[m] = false;
            }
        }
        if !running.iter().any(|&r| r) {
            break;
        }
        // A p and p . Ap.
        let p_ap: Vec<[f64; M]> = ap
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, ap)| {
                let mut s = [0.0; M];
                a.products_into(c * CHUNK, &p, ap);
                for (k, ap) in ap.iter().enumerate() {
                    let i = c * CHUNK + k;
                    for m in 0..M {
                        s[m] += p[i][m] * ap[m];
                    }
                }
                s
            })
            .collect();
        let p_ap = in_order(&p_ap);
        for m in 0..M {
            if running[m] {
                if p_ap[m].is_nan() || p_ap[m] <= 0.0 {
                    // Not positive definite (or NaN): reported as not converged.
                    running[m] = false;
                    continue;
                }
                alpha[m] = rz[m] / p_ap[m];
            }
        }
        // x += alpha p, r -= alpha Ap, with r . r; Jacobi: z = D^-1 r and r . z too.
        let sums: Vec<([f64; M], [f64; M])> = x
            .par_chunks_mut(CHUNK)
            .zip(r.par_chunks_mut(CHUNK))
            .zip(z.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, ((x, r), z))| {
                let (mut rz, mut rr) = ([0.0; M], [0.0; M]);
                for k in 0..x.len() {
                    let i = c * CHUNK + k;
                    for m in 0..M {
                        if running[m] {
                            x[k][m] += alpha[m] * p[i][m];
                            r[k][m] -= alpha[m] * ap[i][m];
                            if jacobi {
                                z[k][m] = r[k][m] * inv_diag[i][m];
                                rz[m] += r[k][m] * z[k][m];
                            }
                            rr[m] += r[k][m] * r[k][m];
                        }
                    }
                }
                (rz, rr)
            })
            .collect();
        let rz_sums: Vec<[f64; M]> = sums.iter().map(|s| s.0).collect();
        let rr_sums: Vec<[f64; M]> = sums.iter().map(|s| s.1).collect();
        let (mut rz_new, rr) = (in_order(&rz_sums), in_order(&rr_sums));
        if multigrid.is_some() {
            cycle(&r, &mut z, &running);
            rz_new = std::array::from_fn(|m| dot_m(&r, &z, m));
        }
        let mut beta = [0.0; M];
        for m in 0..M {
            if running[m] {
                beta[m] = rz_new[m] / rz[m];
                rz[m] = rz_new[m];
            }
        }
        p.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&z)
            .for_each(|(p, z)| {
                for m in 0..M {
                    if running[m] {
                        p[m] = z[m] + beta[m] * p[m];
                    }
                }
            });
        for m in 0..M {
            if running[m] {
                r_norm[m] = rr[m].sqrt();
                reports[m].iterations += 1;
            }
        }
    }
    for m in 0..M {
        if b_norm[m] != 0.0 && n > 0 {
            let relative_residual = r_norm[m] / b_norm[m];
            reports[m].relative_residual = relative_residual;
            reports[m].converged = relative_residual <= tolerance;
        }
    }
    reports
}

/// Chunk partial sums added in chunk order (as [`sum_by`] combines them).
fn in_order<const M: usize>(partials: &[[f64; M]]) -> [f64; M] {
    let mut total = [0.0; M];
    for s in partials {
        for m in 0..M {
            total[m] += s[m];
        }
    }
    total
}

/// Solves A x = b for a general (non-symmetric) A by Jacobi-preconditioned BiCGStab (van der
/// Vorst 1992), from the guess in `x`. Stops when ||r|| <= tolerance ||b||. Reductions are
/// order-fixed as in [`solve_pcg`] (docs/design.md section 6).
pub fn solve_bicgstab(
    a: &CsrMatrix,
    b: &[f64],
    x: &mut [f64],
    tolerance: f64,
    max_iterations: u32,
) -> SolveReport {
    use super::reduce::dot;
    let n = a.rows();
    let product = |v: &[f64], out: &mut Vec<f64>| {
        *out = (0..n)
            .into_par_iter()
            .with_min_len(MIN_PARALLEL_LEN)
            .map(|i| a.row_value(i, v))
            .collect();
    };
    let jacobi = |v: &[f64]| -> Vec<f64> {
        v.par_iter()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&a.diagonal)
            .map(|(v, d)| if *d != 0.0 { v / d } else { *v })
            .collect()
    };
    let b_norm = dot(b, b).sqrt();
    let mut ax = Vec::new();
    product(x, &mut ax);
    let mut r: Vec<f64> = b.iter().zip(&ax).map(|(b, ax)| b - ax).collect();
    let report = |iterations: u32, r: &[f64]| {
        let norm = dot(r, r).sqrt();
        let relative = if b_norm > 0.0 { norm / b_norm } else { norm };
        SolveReport {
            iterations,
            relative_residual: relative,
            converged: relative <= tolerance || norm == 0.0,
        }
    };
    let first = report(0, &r);
    if first.converged || first.relative_residual.is_nan() {
        return first;
    }
    let shadow = r.clone();
    let (mut rho, mut alpha, mut omega) = (1.0f64, 1.0f64, 1.0f64);
    let mut v = vec![0.0; n];
    let mut p = vec![0.0; n];
    let mut t = Vec::new();
    for iteration in 1..=max_iterations {
        let rho_next = dot(&shadow, &r);
        if rho_next == 0.0 || omega == 0.0 {
            return report(iteration, &r);
        }
        let beta = (rho_next / rho) * (alpha / omega);
        rho = rho_next;
        p = (0..n)
            .into_par_iter()
            .with_min_len(MIN_PARALLEL_LEN)
            .map(|i| r[i] + beta * (p[i] - omega * v[i]))
            .collect();
        let y = jacobi(&p);
        product(&y, &mut v);
        alpha = rho / dot(&shadow, &v);
        let s: Vec<f64> = (0..n)
            .into_par_iter()
            .with_min_len(MIN_PARALLEL_LEN)
            .map(|i| r[i] - alpha * v[i])
            .collect();
        x.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&y)
            .for_each(|(x, y)| *x += alpha * y);
        let half = report(iteration, &s);
        if half.converged || half.relative_residual.is_nan() {
            return half;
        }
        let z = jacobi(&s);
        product(&z, &mut t);
        omega = dot(&t, &s) / dot(&t, &t);
        x.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&z)
            .for_each(|(x, z)| *x += omega * z);
        r = (0..n)
            .into_par_iter()
            .with_min_len(MIN_PARALLEL_LEN)
            .map(|i| s[i] - omega * t[i])
            .collect();
        let full = report(iteration, &r);
        if full.converged || full.relative_residual.is_nan() {
            return full;
        }
    }
    report(max_iterations, &r)
}
