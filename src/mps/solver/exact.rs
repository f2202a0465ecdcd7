//! The exact projection of the incremental scheme (`exact_projection`): the increment's
//! equation is built from the very divergence and gradient that measure and correct the
//! velocity, A = -D G, instead of the MPS Laplacian model. The corrected velocity then has
//! the divergence the equation asked for, to the solver's tolerance; on frozen positions the
//! projection I - G (D G)^-1 D is idempotent, so no disturbance can grow through it, whatever
//! the walls' treatment (Cummins & Rudman 1999 discuss exact against approximate projection
//! in SPH). The price: A spans two rings of neighbours and is not symmetric (BiCGStab).
//!
//! The adjoint projection (`adjoint_projection`, experimental) takes the same rows G with
//! the divergence adjoint to them, A = G^T G: symmetric, and the projection orthogonal. With
//! non-conservative rows G^T does not vanish on a rigid translation off the lattice, so it
//! goes with the conservative gradient (docs/validation.md, "The adjoint projection").
use super::Solver;
use crate::mps::grid::entry_index;
use crate::mps::kernel::weight;
use crate::mps::particles::{ParticleKind, Vector};
use crate::mps::reduce::map_particles;
use crate::mps::sparse::CsrMatrix;
use nalgebra::SMatrix;

/// One fluid particle's gradient as a linear map of the increment: (particle, coefficient)
/// pairs, sorted by particle.
pub(super) type GradientRow<const D: usize> = Vec<(u32, Vector<D>)>;

/// A row given as (column, value) pairs, sorted by column with each column's values summed.
fn merged<T: Copy + std::ops::AddAssign>(mut entries: Vec<(u32, T)>) -> Vec<(u32, T)> {
    // A stable sort keeps each column's contributions in their order of arrival: the sums
    // below are the same on any thread count.
    entries.sort_by_key(|e| e.0);
    let mut out: Vec<(u32, T)> = Vec::with_capacity(entries.len());
    for (c, v) in entries {
        match out.last_mut() {
            Some(last) if last.0 == c => last.1 += v,
            _ => out.push((c, v)),
        }
    }
    out
}

/// One row of an increment's matrix from its (column, value) entries (particle columns, in
/// any order): merged per column, the own column `own` added to `diag_extra` as the diagonal,
/// unknowns (`unknown_of`) pushed as CSR entries in ascending order, and the known columns
/// moved over: returns the diagonal and -sum a_ij known_j.
fn split_row(
    entries: Vec<(u32, f64)>,
    own: usize,
    diag_extra: f64,
    unknown_of: &[u32],
    known: &[f64],
    columns: &mut Vec<u32>,
    values: &mut Vec<f64>,
) -> (f64, f64) {
    let mut diag = diag_extra;
    let mut known_sum = 0.0;
    for (col, v) in merged(entries) {
        let col = col as usize;
        if col == own {
            diag += v;
        } else if unknown_of[col] != u32::MAX {
            columns.push(unknown_of[col]);
            values.push(v);
        } else {
            known_sum -= v * known[col];
        }
    }
    (diag, known_sum)
}

impl<const D: usize> Solver<D> {
    /// The corrected increment gradient of every fluid particle as sparse rows (empty for
    /// other particles): C_i sum_j (dp_j - dp_i) e_ij over fluid neighbours, with
    /// e_ij = r_ij w_ij / r_ij^2, and walls and dummies carrying the weighted mean of i's
    /// fluid neighbours' increments (as the increment's correction does); supporting walls
    /// (`support`) are unknowns and carry their own. With `conservative` (the carried
    /// gradient's conservative rows, for the adjoint projection) those rows replace the
    /// fluid neighbours' C_i e_ij terms, so the correction pushes as the prediction does.
    pub(super) fn gradient_rows(
        &self,
        corrections: &[SMatrix<f64, D, D>],
        support: &[bool],
        conservative: Option<&super::conservative::GradientRows<D>>,
    ) -> Vec<GradientRow<D>> {
        let p = &self.particles;
        let nb = &self.pairs.near;
        let radius = self.refs.radius_n_m;
        map_particles(p.len(), |i| {
            if p.kind[i] != ParticleKind::Fluid {
                return Vec::new();
            }
            let c = &corrections[i];
            let mut entries: Vec<(u32, Vector<D>)> = Vec::new();
            let mut own = Vector::<D>::zeros();
            let mut walls = Vector::<D>::zeros();
            let mut fluid_weights: Vec<(u32, f64)> = Vec::new();
            let mut weight_sum = 0.0;
            for &j in nb.of(i) {
                let r = nb.displacement(&p.position_m, i, j);
                let r2 = r.norm_squared();
                let w = weight(r2.sqrt(), radius);
                if w == 0.0 {
                    continue;
                }
                let e = r * (w / r2);
                if p.kind[entry_index(j)] == ParticleKind::Fluid || support[entry_index(j)] {
                    let ce = c * e;
                    if conservative.is_none() || support[entry_index(j)] {
                        entries.push((j, ce));
                        own -= ce;
                    }
                    if p.kind[entry_index(j)] == ParticleKind::Fluid {
                        fluid_weights.push((j, w));
                        weight_sum += w;
                    }
                } else {
                    walls += e;
                }
            }
            if weight_sum > 0.0 && walls != Vector::<D>::zeros() {
                let ce = c * walls;
                for &(j, w) in &fluid_weights {
                    entries.push((j, ce * (w / weight_sum)));
                }
                own -= ce;
            }
            entries.push((i as u32, own));
            if let Some(rows) = conservative {
                entries.extend(rows[i].iter().map(|&(e, a)| (entry_index(e) as u32, a)));
            }
            merged(entries)
        })
    }

    /// -D G over the unknowns `rows` (fluid particles and supporting walls; `unknown_of` their
    /// row), D the MPS divergence (walls keep their velocity: a wall neighbour adds nothing but
    /// its weight to i's own term, and a wall row has no own term),
    /// plus the artificial compressibility on the diagonal. Known columns (surface particles)
    /// are summed against `known` into the second value of each row.
    pub(super) fn exact_ppe(
        &self,
        dt_s: f64,
        rows: &[usize],
        unknown_of: &[u32],
        gradient: &[GradientRow<D>],
        known: &[f64],
    ) -> (CsrMatrix, Vec<f64>) {
        let p = &self.particles;
        let nb = &self.pairs.near;
        let refs = self.refs;
        let scale = D as f64 / refs.n0;
        let diag_extra =
            self.config.density_kg_m3 * self.config.compressibility_1_pa / (dt_s * dt_s);
        CsrMatrix::assemble(rows.len(), |k, columns, values| {
            let i = rows[k];
            let mut entries: Vec<(u32, f64)> = Vec::new();
            let mut all = Vector::<D>::zeros();
            for &j in nb.of(i) {
                let r = nb.displacement(&p.position_m, i, j);
                let r2 = r.norm_squared();
                let w = weight(r2.sqrt(), refs.radius_n_m);
                if w == 0.0 {
                    continue;
                }
                let e = r * (w / r2);
                all += e;
                if p.kind[entry_index(j)] == ParticleKind::Fluid {
                    // -(d/n0) e_ij . G_j
                    for &(col, g) in &gradient[entry_index(j)] {
                        entries.push((col, -scale * e.dot(&g)));
                    }
                }
            }
            // +(d/n0) (sum_j e_ij) . G_i (empty for a wall)
            for &(col, g) in &gradient[i] {
                entries.push((col, scale * all.dot(&g)));
            }
            split_row(entries, i, diag_extra, unknown_of, known, columns, values)
        })
    }

    /// G^T G over the unknowns `rows` (`unknown_of` their row), summed over every fluid
    /// particle's gradient row, plus the artificial compressibility on the diagonal; with
    /// G^T u* per row (G^T the divergence adjoint to G, up to its sign: -div). The
    /// correction u* - (dt/rho) G dp then has G^T u = 0 and is the orthogonal projection
    /// of u*: it removes kinetic energy and never adds any. Known columns (surface
    /// particles) are summed against `known` into the second vector. Symmetric positive
    /// definite with the surface's known columns or the compressibility: plain CG.
    pub(super) fn adjoint_ppe(
        &self,
        dt_s: f64,
        rows: &[usize],
        unknown_of: &[u32],
        gradient: &[GradientRow<D>],
        known: &[f64],
    ) -> (CsrMatrix, Vec<f64>, Vec<f64>) {
        let p = &self.particles;
        let diag_extra =
            self.config.density_kg_m3 * self.config.compressibility_1_pa / (dt_s * dt_s);
        // G^T: per column c, its (fluid row i, g_ic) in ascending i.
        let mut transpose: Vec<Vec<(u32, Vector<D>)>> = vec![Vec::new(); p.len()];
        for (i, row) in gradient.iter().enumerate() {
            for &(c, g) in row {
                transpose[c as usize].push((i as u32, g));
            }
        }
        let (matrix, sums) = CsrMatrix::assemble(rows.len(), |k, columns, values| {
            let c = rows[k];
            let mut entries: Vec<(u32, f64)> = Vec::new();
            let mut adjoint_divergence = 0.0;
            for &(i, g_ic) in &transpose[c] {
                adjoint_divergence += g_ic.dot(&p.velocity_m_s[i as usize]);
                for &(l, g_il) in &gradient[i as usize] {
                    entries.push((l, g_ic.dot(&g_il)));
                }
            }
            let (diag, known_sum) =
                split_row(entries, c, diag_extra, unknown_of, known, columns, values);
            (diag, (known_sum, adjoint_divergence))
        });
        let (known_sums, divergence) = sums.into_iter().unzip();
        (matrix, known_sums, divergence)
    }
}
