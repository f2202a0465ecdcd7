//! Aggregation multigrid preconditioner for the pressure Poisson equation.
//!
//! Jacobi-preconditioned CG needs O(1/l0) iterations (about 170 on the 5 mm dam break). Here
//! the unknowns are grouped geometrically: level k+1 has one unknown per cell of 2^(k+1)
//! spacings, and its matrix is the Galerkin product P^T A P with the piecewise-constant P
//! (plain aggregation: the sums of the fine entries, cheap to form every step). One
//! application of the preconditioner is a symmetric cycle: Jacobi pre-smoothing, restriction,
//! the coarse cycle (twice on each coarse level, a W-cycle, which plain aggregation needs),
//! prolongation and Jacobi post-smoothing; the coarsest level is solved by a dense Cholesky
//! factorisation. The cycle is a fixed symmetric positive definite linear operator, so CG
//! stays plain CG. Optionally the finest level's smoothing reads the matrix's entries rounded
//! to f32 (bound by memory there; the cycle stays symmetric, CG's product stays f64).
//!
//! Determinism (docs/design.md section 6): aggregates follow from the cells alone; every coarse
//! entry and every restricted value is summed over the members of an aggregate in ascending index
//! order; products are gathered row by row. Nothing depends on the thread count.
use super::dense::DenseCholesky;
use super::sparse::CsrMatrix;
use rayon::prelude::*;

/// Jacobi damping of the smoother: the MPS matrices (and their Galerkin products) are
/// diagonally dominant, so the eigenvalues of D^-1 A lie in (0, 2) and 2/3 damps the upper
/// half of the spectrum by at least a factor 3.
const SMOOTHER_DAMPING: f64 = 2.0 / 3.0;
thread_local! {
    /// Per-thread scratch of the Galerkin product: sums per coarse column, whether a column
    /// has a sum in the current row, and the columns touched (all clean between rows).
    static SCRATCH: std::cell::RefCell<(Vec<f64>, Vec<bool>, Vec<u32>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new(), Vec::new())) };
}

/// Levels at or below this many unknowns are solved exactly (dense Cholesky).
const COARSEST_ROWS: usize = 150;

/// One level below the finest: its matrix and the map from the unknowns of the level above.
struct Coarse {
    matrix: CsrMatrix,
    inv_diagonal: Vec<f64>,
    /// Aggregate (row of this level) of each row of the level above.
    aggregate_of: Vec<u32>,
    /// Rows of the level above, grouped by aggregate in ascending order: the members of
    /// aggregate I are `members[member_offsets[I]..member_offsets[I + 1]]`.
    member_offsets: Vec<usize>,
    members: Vec<u32>,
}

/// The cycle's data for one matrix: the coarse levels and the factor of the coarsest.
pub struct Multigrid {
    fine_inv_diagonal: Vec<f64>,
    /// The finest matrix's off-diagonal values in single precision, read by the finest
    /// level's smoothing instead of the f64 ones (empty: the f64 ones).
    fine_values_single: Vec<f32>,
    /// Factor on every coarse-grid correction (1: plain aggregation).
    over_correction: f64,
    levels: Vec<Coarse>,
    /// Lower-triangular Cholesky factor (row-major, n x n) of the coarsest matrix, or None when
    /// the finest level is small enough to be the coarsest.
    coarsest: DenseCholesky,
}

impl Multigrid {
    /// Builds the hierarchy of `fine` whose row i sits in the lattice cell `cells[i]` (integer
    /// coordinates in spacings; unused axes 0). `over_correction` in (0, 2) scales each
    /// coarse-grid correction: the piecewise-constant prolongation of plain aggregation
    /// under-shoots smooth errors, and a factor above 1 makes up for it (over-correction, a
    /// known remedy for plain aggregation). The cycle stays a fixed symmetric operator.
    /// `single_precision`: the finest level's smoothing multiplies by the matrix with its
    /// off-diagonal entries rounded to f32 (still symmetric, each entry within a relative
    /// 6e-8): that level's two products read 8 bytes an entry instead of 12, and the solve
    /// still converges to its tolerance on A, which CG's own product keeps in f64.
    pub fn new(
        fine: &CsrMatrix,
        cells: &[[i64; 3]],
        over_correction: f64,
        single_precision: bool,
    ) -> Self {
        assert_eq!(cells.len(), fine.rows());
        let fine_inv_diagonal = inverse(&fine.diagonal);
        let fine_values_single = if single_precision {
            fine.values.par_iter().map(|&v| v as f32).collect()
        } else {
            Vec::new()
        };
        let mut levels: Vec<Coarse> = Vec::new();
        let mut cells = cells.to_vec();
        loop {
            let above = levels.last().map_or(fine, |l| &l.matrix);
            if above.rows() <= COARSEST_ROWS {
                break;
            }
            let (coarse, coarse_cells) = Coarse::aggregate(above, &cells);
            if coarse.matrix.rows() == above.rows() {
                break; // no coarsening possible (isolated unknowns)
            }
            levels.push(coarse);
            cells = coarse_cells;
        }
        let coarsest = dense_cholesky(levels.last().map_or(fine, |l| &l.matrix));
        Self {
            fine_inv_diagonal,
            fine_values_single,
            over_correction,
            levels,
            coarsest,
        }
    }

    /// Number of levels including the finest.
    pub fn depth(&self) -> usize {
        self.levels.len() + 1
    }

    /// z = B r, one cycle from a zero guess.
    pub fn apply(&self, fine: &CsrMatrix, r: &[f64], z: &mut [f64]) {
        self.cycle(0, fine, &self.fine_inv_diagonal, r, z);
    }

    /// residual = r - A z on `level`, with the single-precision values on the finest level
    /// where the cycle was built with them.
    fn residual_at(&self, level: usize, a: &CsrMatrix, z: &[f64], r: &[f64], residual: &mut [f64]) {
        let single = (level == 0 && !self.fine_values_single.is_empty())
            .then_some(&self.fine_values_single[..]);
        residual_of(a, single, z, r, residual);
    }

    fn cycle(&self, level: usize, a: &CsrMatrix, inv_diagonal: &[f64], r: &[f64], z: &mut [f64]) {
        if level == self.levels.len() {
            self.coarsest.solve(r, z);
            return;
        }
        let coarse = &self.levels[level];
        // Pre-smoothing from zero: z = w D^-1 r.
        for_rows(z, |i, z| *z = SMOOTHER_DAMPING * inv_diagonal[i] * r[i]);
        let mut residual = vec![0.0; r.len()];
        self.residual_at(level, a, z, r, &mut residual);
        // Coarse correction, twice (W-cycle): e = B_c r_c, then e += B_c (r_c - A_c e).
        let r_coarse = coarse.restrict(&residual);
        let mut e = vec![0.0; r_coarse.len()];
        self.cycle(
            level + 1,
            &coarse.matrix,
            &coarse.inv_diagonal,
            &r_coarse,
            &mut e,
        );
        if level + 1 < self.levels.len() {
            let mut r2 = vec![0.0; e.len()];
            residual_of(&coarse.matrix, None, &e, &r_coarse, &mut r2);
            let mut e2 = vec![0.0; e.len()];
            self.cycle(
                level + 1,
                &coarse.matrix,
                &coarse.inv_diagonal,
                &r2,
                &mut e2,
            );
            e.iter_mut().zip(&e2).for_each(|(e, d)| *e += d);
        }
        let scale = self.over_correction;
        for_rows(z, |i, z| *z += scale * e[coarse.aggregate_of[i] as usize]);
        // Post-smoothing: z += w D^-1 (r - A z).
        self.residual_at(level, a, z, r, &mut residual);
        for_rows(z, |i, z| {
            *z += SMOOTHER_DAMPING * inv_diagonal[i] * residual[i]
        });
    }
}

impl Coarse {
    /// Aggregates the rows of `a` by cells twice as large and forms P^T A P.
    fn aggregate(a: &CsrMatrix, cells: &[[i64; 3]]) -> (Self, Vec<[i64; 3]>) {
        let n = a.rows();
        let parent = |c: &[i64; 3]| -> [i64; 3] { [c[0] >> 1, c[1] >> 1, c[2] >> 1] };
        // Rows sorted by (parent cell, index): aggregates are runs, members ascending.
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.sort_unstable_by_key(|&i| (parent(&cells[i as usize]), i));
        let mut aggregate_of = vec![0u32; n];
        let mut member_offsets = vec![0usize];
        let mut coarse_cells = Vec::new();
        for (k, &i) in order.iter().enumerate() {
            let cell = parent(&cells[i as usize]);
            if k > 0 && cell != parent(&cells[order[k - 1] as usize]) {
                member_offsets.push(k);
            }
            if coarse_cells.len() < member_offsets.len() {
                coarse_cells.push(cell);
            }
            aggregate_of[i as usize] = (member_offsets.len() - 1) as u32;
        }
        member_offsets.push(n);
        let members = order;
        let rows = coarse_cells.len();
        // Row I of P^T A P: the entries of the member rows, summed per aggregate of their
        // column in member order then entry order, whichever thread does it.
        let (matrix, _) = CsrMatrix::assemble(rows, |big_i, columns, values| {
            SCRATCH.with_borrow_mut(|scratch| {
                let (sum, seen, touched) = scratch;
                if sum.len() < rows {
                    sum.resize(rows, 0.0);
                    seen.resize(rows, false);
                }
                let mut diagonal = 0.0;
                for &i in &members[member_offsets[big_i]..member_offsets[big_i + 1]] {
                    let i = i as usize;
                    diagonal += a.diagonal[i];
                    let range = a.row_offsets[i]..a.row_offsets[i + 1];
                    for (&j, &v) in a.columns[range.clone()].iter().zip(&a.values[range]) {
                        let big_j = aggregate_of[j as usize] as usize;
                        if big_j == big_i {
                            diagonal += v;
                        } else if seen[big_j] {
                            sum[big_j] += v;
                        } else {
                            seen[big_j] = true;
                            sum[big_j] = v;
                            touched.push(big_j as u32);
                        }
                    }
                }
                touched.sort_unstable();
                for &big_j in touched.iter() {
                    columns.push(big_j);
                    values.push(sum[big_j as usize]);
                    seen[big_j as usize] = false;
                }
                touched.clear();
                (diagonal, ())
            })
        });
        let inv_diagonal = inverse(&matrix.diagonal);
        (
            Coarse {
                matrix,
                inv_diagonal,
                aggregate_of,
                member_offsets,
                members,
            },
            coarse_cells,
        )
    }

    /// r_c = P^T r: the sum over each aggregate's members, in ascending order.
    fn restrict(&self, r: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.matrix.rows()];
        for_rows(&mut out, |big_i, out| {
            let mut s = 0.0;
            for &i in &self.members[self.member_offsets[big_i]..self.member_offsets[big_i + 1]] {
                s += r[i as usize];
            }
            *out = s;
        });
        out
    }
}

/// residual = r - A z, row by row; A's off-diagonal entries from `single` where given (f32
/// copies of `a.values`).
fn residual_of(a: &CsrMatrix, single: Option<&[f32]>, z: &[f64], r: &[f64], residual: &mut [f64]) {
    // A z by rows side by side (the bits of `row_value`), then r - A z.
    let (z_rows, _) = z.as_chunks::<1>();
    for_row_blocks(residual, |first, out| {
        match single {
            Some(values) => a.products_into_single(values, first, z, out),
            None => a.products_into(first, z_rows, out.as_chunks_mut::<1>().0),
        }
        for (k, o) in out.iter_mut().enumerate() {
            *o = r[first + k] - *o;
        }
    });
}

/// Rows below which a level's loops run on the calling thread: handing work to threads costs
/// more than the work (coarse levels). Only scheduling: every row is computed alike.
const PARALLEL_ROWS: usize = 2048;
const ROWS_PER_TASK: usize = 1024;

/// out[i] = f(i, out[i]) for every row, in parallel on large levels.
fn for_rows(out: &mut [f64], f: impl Fn(usize, &mut f64) + Sync) {
    for_row_blocks(out, |first, block| {
        for (k, o) in block.iter_mut().enumerate() {
            f(first + k, o);
        }
    });
}

/// f(first, rows first..first + len) over consecutive blocks of `out`: one block on small
/// levels, blocks of ROWS_PER_TASK in parallel on large ones.
fn for_row_blocks(out: &mut [f64], f: impl Fn(usize, &mut [f64]) + Sync) {
    if out.len() < PARALLEL_ROWS {
        f(0, out);
    } else {
        out.par_chunks_mut(ROWS_PER_TASK)
            .enumerate()
            .for_each(|(c, block)| f(c * ROWS_PER_TASK, block));
    }
}

fn inverse(diagonal: &[f64]) -> Vec<f64> {
    diagonal.iter().map(|d| 1.0 / d).collect()
}

/// The dense factor of a small SPD matrix in CSR form (the coarsest level).
fn dense_cholesky(a: &CsrMatrix) -> DenseCholesky {
    let n = a.rows();
    let mut dense = vec![0.0; n * n];
    for i in 0..n {
        dense[i * n + i] = a.diagonal[i];
        for k in a.row_offsets[i]..a.row_offsets[i + 1] {
            dense[i * n + a.columns[k] as usize] = a.values[k];
        }
    }
    DenseCholesky::factor(dense, n, true).expect("a guarded factorisation always succeeds")
}
