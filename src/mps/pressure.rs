//! Pressure Poisson equation: assembly in CSR and a Jacobi-preconditioned conjugate gradient.
use super::reduce::{MIN_PARALLEL_LEN, dot, sum_by};
use rayon::prelude::*;

/// Symmetric sparse matrix in compressed rows (diagonal stored separately).
#[derive(Debug, Clone, Default)]
pub struct CsrMatrix {
    pub diagonal: Vec<f64>,
    pub row_offsets: Vec<usize>,
    pub columns: Vec<u32>,
    pub values: Vec<f64>,
}

/// One assembled row of a symmetric system: diagonal and off-diagonal (column, value) entries.
#[derive(Debug, Clone, Default)]
pub struct Row {
    pub diagonal: f64,
    pub entries: Vec<(u32, f64)>,
}

impl CsrMatrix {
    /// Packs assembled rows, in order, into compressed rows.
    pub fn from_rows<'a>(rows: impl IntoIterator<Item = &'a Row>) -> Self {
        let mut m = CsrMatrix {
            row_offsets: vec![0],
            ..Default::default()
        };
        for row in rows {
            m.diagonal.push(row.diagonal);
            for &(c, v) in &row.entries {
                m.columns.push(c);
                m.values.push(v);
            }
            m.row_offsets.push(m.columns.len());
        }
        m
    }

    pub fn rows(&self) -> usize {
        self.diagonal.len()
    }

    /// y = A x, each row gathered by its own task in a fixed order.
    pub fn multiply(&self, x: &[f64], y: &mut [f64]) {
        assert_eq!(x.len(), self.rows());
        y.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .enumerate()
            .for_each(|(i, yi)| {
                let range = self.row_offsets[i]..self.row_offsets[i + 1];
                let mut s = self.diagonal[i] * x[i];
                // Zipped slices: no bounds check per entry but the column lookup.
                for (&c, &v) in self.columns[range.clone()].iter().zip(&self.values[range]) {
                    s += v * x[c as usize];
                }
                *yi = s;
            });
    }
}

/// Outcome of a CG solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveReport {
    pub iterations: u32,
    /// ||b - A x|| / ||b|| at exit (0 when b = 0).
    pub relative_residual: f64,
    pub converged: bool,
}

/// Solves A x = b for symmetric positive definite A with a Jacobi preconditioner, starting from
/// the guess in `x`. Stops when ||r|| <= tolerance ||b||. All reductions are order-fixed
/// (DESIGN.md 6).
pub fn solve_pcg(
    a: &CsrMatrix,
    b: &[f64],
    x: &mut [f64],
    tolerance: f64,
    max_iterations: u32,
) -> SolveReport {
    let n = a.rows();
    let b_norm = dot(b, b).sqrt();
    if n == 0 || b_norm == 0.0 {
        x.iter_mut().for_each(|v| *v = 0.0);
        return SolveReport {
            iterations: 0,
            relative_residual: 0.0,
            converged: true,
        };
    }
    let inv_diag: Vec<f64> = a
        .diagonal
        .par_iter()
        .with_min_len(MIN_PARALLEL_LEN)
        .map(|d| 1.0 / d)
        .collect();
    let mut r = vec![0.0; n];
    a.multiply(x, &mut r);
    r.par_iter_mut()
        .with_min_len(MIN_PARALLEL_LEN)
        .zip(b)
        .for_each(|(r, b)| *r = b - *r);
    let mut z: Vec<f64> = r
        .par_iter()
        .with_min_len(MIN_PARALLEL_LEN)
        .zip(&inv_diag)
        .map(|(r, m)| r * m)
        .collect();
    let mut p = z.clone();
    let mut ap = vec![0.0; n];
    let mut rz = dot(&r, &z);
    let mut r_norm = dot(&r, &r).sqrt();
    let mut iterations = 0;
    while iterations < max_iterations {
        if r_norm <= tolerance * b_norm {
            break;
        }
        a.multiply(&p, &mut ap);
        let p_ap = dot(&p, &ap);
        if p_ap.is_nan() || p_ap <= 0.0 {
            break; // not positive definite (or NaN): report as not converged
        }
        let alpha = rz / p_ap;
        x.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&p)
            .for_each(|(x, p)| *x += alpha * p);
        r.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&ap)
            .for_each(|(r, ap)| *r -= alpha * ap);
        z.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(r.par_iter().with_min_len(MIN_PARALLEL_LEN).zip(&inv_diag))
            .for_each(|(z, (r, m))| *z = r * m);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&z)
            .for_each(|(p, z)| *p = z + beta * *p);
        r_norm = sum_by(n, |i| r[i] * r[i]).sqrt();
        iterations += 1;
    }
    let relative_residual = r_norm / b_norm;
    SolveReport {
        iterations,
        relative_residual,
        converged: relative_residual <= tolerance,
    }
}
