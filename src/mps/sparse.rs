//! The sparse matrix of the step's linear systems (PPE, implicit viscosity, the multigrid
//! levels): compressed rows, assembled and multiplied in a fixed order.
use super::grid::{Neighbours, entry_index};
use super::reduce::{MIN_PARALLEL_LEN, PARTICLES_PER_TASK};
use rayon::prelude::*;

/// Rows that [`CsrMatrix::rows_product`] computes side by side in the solvers' products.
pub(crate) const ROWS_SIDE_BY_SIDE: usize = 4;

/// Symmetric sparse matrix in compressed rows (diagonal stored separately).
///
/// With `component_diagonal` not empty it is one matrix per vector component m (the viscous
/// stage with mirror symmetry planes): the columns carry the mirror images' plane bits
/// ([`Neighbours::plane_bits`]), component m's entry is the value negated where the image
/// negates component m ([`Neighbours::component_sign`]), and its diagonal is
/// `component_diagonal[i][m]` (`diagonal` then equals it in the rows `image_free` marks).
#[derive(Debug, Clone, Default)]
pub struct CsrMatrix {
    pub diagonal: Vec<f64>,
    pub row_offsets: Vec<usize>,
    pub columns: Vec<u32>,
    pub values: Vec<f64>,
    pub component_diagonal: Vec<[f64; 3]>,
    /// With `component_diagonal`: per row, whether it holds no mirror image (no plane bits in
    /// its columns, every component's diagonal the plain one). Such a row's product is the
    /// plain product bit for bit (a sign of +1 multiplies exactly), so it skips the per-entry
    /// mask and sign: most rows of a quarter or half domain are far from its planes.
    pub image_free: Vec<bool>,
}

impl CsrMatrix {
    /// Assembles `n` rows in parallel, in fixed chunks of rows (so no allocation per row):
    /// `row(k, columns, values)` appends the off-diagonal entries of row k and returns its
    /// diagonal and one more value of the caller's per row. The chunks are then copied side by
    /// side into the matrix: only where they land depends on the sizes, never a value.
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
                for k in range.clone() {
                    let (d, t) = row(k, &mut columns, &mut values);
                    if k == range.start {
                        // Room for the chunk's rows at a quarter more than the first one's
                        // length (neighbouring rows are alike), so that the vectors rarely grow.
                        let guess = (columns.len() + 1) * range.len() * 5 / 4;
                        columns.reserve(guess);
                        values.reserve(guess);
                    }
                    diagonal.push(d);
                    ends.push(columns.len());
                    extra.push(t);
                }
                (diagonal, ends, columns, values, extra)
            })
            .collect();
        let entries = chunks.iter().map(|c| c.2.len()).sum();
        let mut m = CsrMatrix {
            diagonal: Vec::with_capacity(n),
            row_offsets: Vec::with_capacity(n + 1),
            columns: vec![0; entries],
            values: vec![0.0; entries],
            component_diagonal: Vec::new(),
            image_free: Vec::new(),
        };
        // Each chunk's entries into its own slice of the matrix, in parallel.
        let mut targets = Vec::with_capacity(chunks.len());
        let (mut columns, mut values) = (&mut m.columns[..], &mut m.values[..]);
        for chunk in &chunks {
            let (c, rest_c) = columns.split_at_mut(chunk.2.len());
            let (v, rest_v) = values.split_at_mut(chunk.3.len());
            targets.push((c, v));
            (columns, values) = (rest_c, rest_v);
        }
        let sources: Vec<(&[u32], &[f64])> = chunks.iter().map(|c| (&c.2[..], &c.3[..])).collect();
        sources
            .into_par_iter()
            .zip(targets)
            .for_each(|((columns, values), (c, v))| {
                c.copy_from_slice(columns);
                v.copy_from_slice(values);
            });
        m.row_offsets.push(0);
        let mut extras = Vec::with_capacity(n);
        let mut base = 0;
        for (diagonal, ends, columns, _, extra) in chunks {
            m.diagonal.extend_from_slice(&diagonal);
            m.row_offsets.extend(ends.iter().map(|e| base + e));
            base += columns.len();
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
        self.image_free = (0..self.rows())
            .map(|k| {
                let range = self.row_offsets[k]..self.row_offsets[k + 1];
                self.columns[range]
                    .iter()
                    .all(|&c| Neighbours::plane_bits(c) == 0)
                    && self.component_diagonal[k]
                        .iter()
                        .all(|d| d.to_bits() == self.diagonal[k].to_bits())
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

    /// y = A x for M vectors at once (one pass over the matrix), each row gathered in a fixed
    /// order: every component gets the bits of a single product.
    pub fn multiply<const M: usize>(&self, x: &[[f64; M]], y: &mut [[f64; M]]) {
        assert_eq!(x.len(), self.rows());
        y.par_chunks_mut(MIN_PARALLEL_LEN)
            .enumerate()
            .for_each(|(c, y)| self.products_into(c * MIN_PARALLEL_LEN, x, y));
    }

    /// Rows first..first + out.len() of A x into `out`, [`ROWS_SIDE_BY_SIDE`] at a time (the
    /// bits of [`CsrMatrix::row_product`]).
    #[inline]
    pub(crate) fn products_into<const M: usize>(
        &self,
        first: usize,
        x: &[[f64; M]],
        out: &mut [[f64; M]],
    ) {
        let mut groups = out.chunks_exact_mut(ROWS_SIDE_BY_SIDE);
        let mut i = first;
        for group in &mut groups {
            group.copy_from_slice(&self.rows_product::<M, ROWS_SIDE_BY_SIDE>(i, x));
            i += ROWS_SIDE_BY_SIDE;
        }
        for (k, o) in groups.into_remainder().iter_mut().enumerate() {
            *o = self.row_product(i + k, x);
        }
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

    /// Rows first..first + R of A x, for M vectors, side by side: each row sums its diagonal
    /// term, then its entries in their stored order, so the bits do not depend on R
    /// ([`CsrMatrix::row_product`] is R = 1). One
    /// row is a chain of dependent additions that waits on each; R chains overlap.
    #[inline]
    pub(crate) fn rows_product<const M: usize, const R: usize>(
        &self,
        first: usize,
        x: &[[f64; M]],
    ) -> [[f64; M]; R] {
        // A matrix given component diagonals by hand, without `image_free`, takes the signed
        // product throughout.
        if self.component_diagonal.is_empty()
            || self
                .image_free
                .get(first..first + R)
                .is_some_and(|rows| rows.iter().all(|&f| f))
        {
            self.rows_product_by::<M, R, false>(first, x)
        } else {
            self.rows_product_by::<M, R, true>(first, x)
        }
    }

    /// [`CsrMatrix::rows_product`], with or without the components' own signs and diagonals.
    #[inline(always)]
    fn rows_product_by<const M: usize, const R: usize, const COMPONENTS: bool>(
        &self,
        first: usize,
        x: &[[f64; M]],
    ) -> [[f64; M]; R] {
        self.rows_product_of::<f64, M, R, COMPONENTS>(&self.values, first, x)
    }

    /// Rows first..first + out.len() of A' x into `out`, where A' is this matrix with the
    /// off-diagonal `values` in single precision (each widened exactly to f64 before its
    /// product; the diagonal, the sums and the order of the terms are as in
    /// [`CsrMatrix::products_into`]). A stand-in for A where an approximation serves (the
    /// multigrid's smoother) and reading 4 bytes an entry less pays.
    pub(crate) fn products_into_single(
        &self,
        values: &[f32],
        first: usize,
        x: &[f64],
        out: &mut [f64],
    ) {
        debug_assert!(self.component_diagonal.is_empty());
        let (x, _) = x.as_chunks::<1>();
        let (out, _) = out.as_chunks_mut::<1>();
        let mut groups = out.chunks_exact_mut(ROWS_SIDE_BY_SIDE);
        let mut i = first;
        for group in &mut groups {
            group.copy_from_slice(
                &self.rows_product_of::<f32, 1, ROWS_SIDE_BY_SIDE, false>(values, i, x),
            );
            i += ROWS_SIDE_BY_SIDE;
        }
        for (k, o) in groups.into_remainder().iter_mut().enumerate() {
            *o = self.rows_product_of::<f32, 1, 1, false>(values, i + k, x)[0];
        }
    }

    /// Rows first..first + R of A x with the off-diagonal entries `values` (`self.values`, or
    /// a copy of them in another precision), each row's terms in its own order.
    #[inline(always)]
    fn rows_product_of<
        V: Copy + Into<f64>,
        const M: usize,
        const R: usize,
        const COMPONENTS: bool,
    >(
        &self,
        values: &[V],
        first: usize,
        x: &[[f64; M]],
    ) -> [[f64; M]; R] {
        let start: [usize; R] = std::array::from_fn(|k| self.row_offsets[first + k]);
        let end: [usize; R] = std::array::from_fn(|k| self.row_offsets[first + k + 1]);
        let mut s: [[f64; M]; R] = std::array::from_fn(|k| {
            let i = first + k;
            std::array::from_fn(|m| {
                let d = if COMPONENTS {
                    self.component_diagonal[i][m]
                } else {
                    self.diagonal[i]
                };
                d * x[i][m]
            })
        });
        // One entry of row k.
        let add = |s: &mut [f64; M], c: u32, v: f64| {
            if COMPONENTS {
                let xc = &x[entry_index(c)];
                for m in 0..M {
                    s[m] += v * Neighbours::component_sign(c, m) * xc[m];
                }
            } else {
                let xc = &x[c as usize];
                for m in 0..M {
                    s[m] += v * xc[m];
                }
            }
        };
        let common = (0..R).map(|k| end[k] - start[k]).min().unwrap_or(0);
        let columns: [&[u32]; R] =
            std::array::from_fn(|k| &self.columns[start[k]..start[k] + common]);
        let row_values: [&[V]; R] = std::array::from_fn(|k| &values[start[k]..start[k] + common]);
        for t in 0..common {
            for k in 0..R {
                add(&mut s[k], columns[k][t], row_values[k][t].into());
            }
        }
        for k in 0..R {
            let range = start[k] + common..end[k];
            for (&c, &v) in self.columns[range.clone()].iter().zip(&values[range]) {
                add(&mut s[k], c, v.into());
            }
        }
        s
    }

    /// Row i of A x, for M vectors: the side-by-side product of one row (the same dispatch
    /// between the signed and the plain product, the same order of terms).
    #[inline]
    pub(crate) fn row_product<const M: usize>(&self, i: usize, x: &[[f64; M]]) -> [f64; M] {
        self.rows_product::<M, 1>(i, x)[0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// A random matrix of `n` rows of 0 to 40 entries (values of mixed signs and magnitudes,
    /// so that the order of the additions shows in the last bits); with `planes`, the columns
    /// of rows k with k % 12 < 6 carry random plane bits, and those with k % 12 < 3 their own
    /// diagonal per component: groups of four rows with images, mixed and free of them.
    fn random_matrix(rng: &mut SplitMix64, n: usize, planes: bool) -> CsrMatrix {
        type Row = (Vec<u32>, Vec<f64>, f64);
        let imaged = |k: usize| planes && k % 12 < 6;
        let rows: Vec<Row> = (0..n)
            .map(|k| {
                let len = (rng.unit() * 41.0) as usize;
                let (mut columns, mut values) = (Vec::new(), Vec::new());
                for _ in 0..len {
                    let bits = if imaged(k) {
                        ((rng.unit() * 8.0) as u32) << 29
                    } else {
                        0
                    };
                    columns.push((rng.unit() * n as f64) as u32 | bits);
                    // Magnitudes 1e-6..1e6, so that the order of additions shows in the bits.
                    let scale = [1e-6, 1e-3, 1.0, 1e3, 1e6][(rng.unit() * 5.0) as usize];
                    values.push((rng.unit() - 0.5) * scale);
                }
                (columns, values, 1.0 + rng.unit())
            })
            .collect();
        let (m, _) = CsrMatrix::assemble(n, |k, columns, values| {
            columns.extend_from_slice(&rows[k].0);
            values.extend_from_slice(&rows[k].1);
            (rows[k].2, ())
        });
        if planes {
            m.with_component_diagonals(|k| {
                // Half of the rows with images keep the plain diagonal: their columns' bits
                // alone must keep them off the plain product.
                if imaged(k) && k % 12 < 3 {
                    [k as f64 * 0.1, -0.3, 0.7]
                } else {
                    [0.0; 3]
                }
            })
        } else {
            m
        }
    }

    #[test]
    fn rows_side_by_side_give_the_bits_of_one_row_at_a_time() {
        for planes in [false, true] {
            let mut rng = SplitMix64::new(7 + u64::from(planes));
            let n = 203; // not a multiple of the group: the remainder's rows too
            let a = random_matrix(&mut rng, n, planes);
            if planes {
                // Both kinds of rows, so that both products are checked.
                assert!(a.image_free.iter().any(|&f| f) && a.image_free.iter().any(|&f| !f));
            }
            let x: Vec<[f64; 3]> = (0..n)
                .map(|_| std::array::from_fn(|_| rng.unit() * 2.0 - 1.0))
                .collect();
            let one_by_one: Vec<[f64; 3]> = (0..n).map(|i| a.row_product(i, &x)).collect();
            // Every row, image-free or not, as the signed formula gives it term by term.
            for (i, row) in one_by_one.iter().enumerate() {
                let range = a.row_offsets[i]..a.row_offsets[i + 1];
                for (m, &got) in row.iter().enumerate() {
                    let mut s = a.diagonal_of(i, m) * x[i][m];
                    for k in range.clone() {
                        let c = a.columns[k];
                        s += a.values[k] * Neighbours::component_sign(c, m) * x[entry_index(c)][m];
                    }
                    assert_eq!(got.to_bits(), s.to_bits(), "row {i}, component {m}");
                }
            }
            let mut side_by_side = vec![[0.0; 3]; n];
            a.multiply(&x, &mut side_by_side);
            for i in 0..n {
                for m in 0..3 {
                    assert_eq!(
                        side_by_side[i][m].to_bits(),
                        one_by_one[i][m].to_bits(),
                        "row {i}, component {m}, planes {planes}"
                    );
                }
            }
            // Summed in another order, some row differs in its last bits: the check can see
            // an order changed.
            let reversed = (0..n).any(|i| {
                let range = a.row_offsets[i]..a.row_offsets[i + 1];
                let mut s = a.diagonal_of(i, 0) * x[i][0];
                for k in range.rev() {
                    let c = a.columns[k];
                    s += a.values[k] * Neighbours::component_sign(c, 0) * x[entry_index(c)][0];
                }
                s.to_bits() != one_by_one[i][0].to_bits()
            });
            assert!(reversed, "no row sensitive to its order");
            if !planes {
                let x1: Vec<f64> = x.iter().map(|v| v[0]).collect();
                let (x1c, _) = x1.as_chunks::<1>();
                let mut y = vec![[0.0; 1]; n];
                a.products_into(0, x1c, &mut y);
                for (i, y) in y.iter().enumerate() {
                    assert_eq!(y[0].to_bits(), a.row_value(i, &x1).to_bits(), "row {i}");
                }
            }
        }
    }
}
