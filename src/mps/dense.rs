//! Dense Cholesky factorisation of small symmetric positive definite systems (the multigrid's
//! coarsest level, the least-squares problem of Anderson acceleration).

/// The factor L (A = L L^T) of a small SPD matrix, row-major.
pub(crate) struct DenseCholesky {
    n: usize,
    lower: Vec<f64>,
}

impl DenseCholesky {
    /// Factors the row-major n x n matrix `a` (only its lower triangle is read), row by row.
    /// A pivot that is not positive is lifted to the smallest positive number with `guard`
    /// (an SPD matrix whose tiny pivot round-off made zero), else the factorisation fails.
    pub(crate) fn factor(mut a: Vec<f64>, n: usize, guard: bool) -> Option<Self> {
        assert_eq!(a.len(), n * n);
        for i in 0..n {
            for j in 0..=i {
                let mut s = a[i * n + j];
                for k in 0..j {
                    s -= a[i * n + k] * a[j * n + k];
                }
                a[i * n + j] = if i == j {
                    if !guard && (s.is_nan() || s <= 0.0) {
                        return None;
                    }
                    s.max(f64::MIN_POSITIVE).sqrt()
                } else {
                    s / a[j * n + j]
                };
            }
        }
        Some(Self { n, lower: a })
    }

    /// Solves L L^T x = b.
    pub(crate) fn solve(&self, b: &[f64], x: &mut [f64]) {
        let (n, l) = (self.n, &self.lower);
        for i in 0..n {
            let mut s = b[i];
            for k in 0..i {
                s -= l[i * n + k] * x[k];
            }
            x[i] = s / l[i * n + i];
        }
        for i in (0..n).rev() {
            let mut s = x[i];
            for k in i + 1..n {
                s -= l[k * n + i] * x[k];
            }
            x[i] = s / l[i * n + i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_system_and_refuses_a_singular_one_unless_guarded() {
        let a = DenseCholesky::factor(vec![4.0, 2.0, 2.0, 3.0], 2, false).unwrap();
        let mut x = [0.0; 2];
        a.solve(&[2.0, 1.0], &mut x);
        assert!((x[0] - 0.5).abs() < 1e-15 && x[1].abs() < 1e-15);
        let singular = vec![1.0, 1.0, 1.0, 1.0];
        assert!(DenseCholesky::factor(singular.clone(), 2, false).is_none());
        assert!(DenseCholesky::factor(singular, 2, true).is_some());
    }
}
