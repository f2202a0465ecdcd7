//! The sparse matrix of the step's linear systems (PPE, implicit viscosity, the multigrid
//! levels): compressed rows, assembled and multiplied in a fixed order.
use super::grid::{Neighbours, entry_index};
use super::reduce::{MIN_PARALLEL_LEN, PARTICLES_PER_TASK};
use rayon::prelude::*;

/// Symmetric sparse matrix in compressed rows (diagonal stored separately).
///
/// With `component_diagonal` not empty it is one matrix per vector component m (the viscous
/// stage with mirror symmetry planes): the columns carry the mirror images' plane bits
/// ([`Neighbours::plane_bits`]), component m's entry is the value negated where the image
/// negates component m ([`Neighbours::component_sign`]), and its diagonal is
/// `component_diagonal[i][m]` (`diagonal` is then unused).
#[derive(Debug, Clone, Default)]
pub struct CsrMatrix {
    pub diagonal: Vec<f64>,
    pub row_offsets: Vec<usize>,
    pub columns: Vec<u32>,
    pub values: Vec<f64>,
    pub component_diagonal: Vec<[f64; 3]>,
}

impl CsrMatrix {
    /// Assembles `n` rows in parallel, in fixed chunks of rows (so no allocation per row):
    /// `row(k, columns, values)` appends the off-diagonal entries of row k and returns its
    /// diagonal and one more value of the caller's per row.
    pub fn assemble<T: Send>(
        n: usize,
        row: impl Fn(usize, &mut Vec<u32>, &mut Vec<f64>) -> (f64, T) + Sync,
    ) -> (Self, Vec<T>) {
        type Chunk<T> = (Vec<f64>, Vec<usize>, Vec<u32>, Vec<f64>, Vec<T>);
        let chunks: Vec<Chunk<T>> = (0..n.div_ceil(PARTICLES_PER_TASK))
            .into_par_iter()
            .with_max_len(1)
            .map(|c| {
                let range = c * PARTICLES_PER_TASK..((c + 1) * PARTICLES_PER_TASK).min(n);
                let mut diagonal = Vec::with_capacity(range.len());
                let mut ends = Vec::with_capacity(range.len());
                let mut extra = Vec::with_capacity(range.len());
                let (mut columns, mut values) = (Vec::new(), Vec::new());
                for k in range {
                    let (d, t) = row(k, &mut columns, &mut values);
                    diagonal.push(d);
                    ends.push(columns.len());
                    extra.push(t);
                }
                (diagonal, ends, columns, values, extra)
            })
            .collect();
        let mut m = CsrMatrix {
            diagonal: Vec::with_capacity(n),
            row_offsets: Vec::with_capacity(n + 1),
            columns: Vec::with_capacity(chunks.iter().map(|c| c.2.len()).sum()),
            values: Vec::with_capacity(chunks.iter().map(|c| c.3.len()).sum()),
            component_diagonal: Vec::new(),
        };
        m.row_offsets.push(0);
        let mut extras = Vec::with_capacity(n);
        for (diagonal, ends, columns, values, extra) in chunks {
            let base = m.columns.len();
            m.diagonal.extend_from_slice(&diagonal);
            m.row_offsets.extend(ends.iter().map(|e| base + e));
            m.columns.extend_from_slice(&columns);
            m.values.extend_from_slice(&values);
            extras.extend(extra);
        }
        (m, extras)
    }

    pub fn rows(&self) -> usize {
        self.diagonal.len()
    }

    /// This matrix, assembled with plane bits in its columns ([`Neighbours::plane_bits`]), as
    /// one matrix per vector component (see `component_diagonal`): row k's diagonal for
    /// component m gains `own_image(k)[m]`.
    pub fn with_component_diagonals(mut self, own_image: impl Fn(usize) -> [f64; 3]) -> Self {
        self.component_diagonal = (0..self.rows())
            .map(|k| {
                let own = own_image(k);
                std::array::from_fn(|m| self.diagonal[k] + own[m])
            })
            .collect();
        self
    }

    /// Component m's diagonal entry of row i.
    #[inline]
    pub fn diagonal_of(&self, i: usize, m: usize) -> f64 {
        if self.component_diagonal.is_empty() {
            self.diagonal[i]
        } else {
            self.component_diagonal[i][m]
        }
    }

    /// y = A x for M vectors at once (one pass over the matrix), each row gathered by its own
    /// task in a fixed order: every component gets the bits of a single product.
    pub fn multiply<const M: usize>(&self, x: &[[f64; M]], y: &mut [[f64; M]]) {
        assert_eq!(x.len(), self.rows());
        y.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .enumerate()
            .for_each(|(i, yi)| *yi = self.row_product(i, x));
    }

    /// Row i of A x.
    #[inline]
    pub fn row_value(&self, i: usize, x: &[f64]) -> f64 {
        debug_assert!(self.component_diagonal.is_empty());
        let range = self.row_offsets[i]..self.row_offsets[i + 1];
        let mut s = self.diagonal[i] * x[i];
        for (&c, &v) in self.columns[range.clone()].iter().zip(&self.values[range]) {
            s += v * x[c as usize];
        }
        s
    }

    /// Row i of A x, for M vectors.
    #[inline]
    pub(crate) fn row_product<const M: usize>(&self, i: usize, x: &[[f64; M]]) -> [f64; M] {
        let range = self.row_offsets[i]..self.row_offsets[i + 1];
        if !self.component_diagonal.is_empty() {
            let mut s: [f64; M] = std::array::from_fn(|m| self.component_diagonal[i][m] * x[i][m]);
            for (&c, &v) in self.columns[range.clone()].iter().zip(&self.values[range]) {
                let xc = &x[entry_index(c)];
                for m in 0..M {
                    s[m] += v * Neighbours::component_sign(c, m) * xc[m];
                }
            }
            return s;
        }
        let mut s = [0.0; M];
        for m in 0..M {
            s[m] = self.diagonal[i] * x[i][m];
        }
        // Zipped slices: no bounds check per entry but the column lookup.
        for (&c, &v) in self.columns[range.clone()].iter().zip(&self.values[range]) {
            let xc = &x[c as usize];
            for m in 0..M {
                s[m] += v * xc[m];
            }
        }
        s
    }
}
