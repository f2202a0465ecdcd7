//! Bingham's law with a true rigid state in the viscous stage: the implicit step solved as a
//! minimisation by an augmented Lagrangian (ALG2: Fortin & Glowinski 1983, Glowinski & Le
//! Tallec 1989; for Bingham flow Saramito & Roquet 2001).
//!
//! The backward-Euler viscous step of a Bingham fluid minimises
//! sum_i [ rho/(2 dt) |u_i - u~_i|^2 + (plastic part) + sqrt(2) tau_y |e_i(u)| ], with
//! e_i(u) = sym(G_i(u)) the strain rate of [`super::viscosity::velocity_gradient`]'s
//! corrected model (|e| the Frobenius norm, sqrt(2)|e| = sqrt(Pi), the equivalent shear
//! rate). The yield term is not differentiable at e = 0: that is the rigid state, which the
//! regularised law (seed 000 eqs. 6-7) replaces by a viscosity tau_y / sqrt(Pi_c). Here a
//! strain-rate field gamma_i stands in for e_i(u) with a multiplier lambda_i (the yield part
//! of the deviatoric stress, |lambda_i| <= sqrt(2) tau_y) and a penalty r, and three steps
//! repeat until e(u) = gamma:
//! 1. u: (rho/dt + plastic) u + r E^T E u = rho/dt u~ - E^T (lambda + r (e0 - gamma)), with E
//!    the linear part of e (e = E u + e0, e0 from the walls' known velocities) and E^T its
//!    transpose, the discrete divergence that is E's adjoint (equal particle volumes);
//! 2. gamma_i: theta = lambda_i + r e_i(u); gamma_i = 0 if |theta| <= sqrt(2) tau_y (rigid),
//!    else (|theta| - sqrt(2) tau_y) theta / (r |theta|) (with `volumetric_limit`, the
//!    deviatoric and isotropic parts of theta each by their own limit: [`law_step`]);
//! 3. lambda_i += r (e_i(u) - gamma_i).
//!
//! A particle is rigid when the stress that holds it is below the yield stress, not when its
//! one-step strain rate is small; gamma = 0 there exactly. The multiplier is carried from step
//! to step (it changes little): a still tank then needs one iteration per step, a settling
//! heap 20-50 (docs/validation.md, "A rigid state by an augmented Lagrangian").
use super::anderson::Anderson;
use super::grid::{Neighbours, entry_index};
use super::kernel::RefValues;
use super::operators::{
    MIN_DET_RATIO, gradient_correction, moment_matrix, number_density, weighted_neighbours,
    well_conditioned_inverse,
};
use super::particles::{ParticleKind, Particles, Vector};
use super::pressure::SolveReport;
use super::reduce::{MIN_PARALLEL_LEN, map_particles, max_by, sum_by};
use super::sparse::CsrMatrix;
use super::viscosity::{Frames, Walls};
use nalgebra::SMatrix;
use rayon::prelude::*;

/// A D x D tensor (strain rate, stress).
pub type Tensor<const D: usize> = SMatrix<f64, D, D>;

/// Settings of the augmented-Lagrangian yield solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YieldSolve {
    /// The penalty r, in Pa s.
    pub penalty_pa_s: f64,
    /// Most iterations (u, gamma, lambda) per step.
    pub max_iterations: u32,
    /// Converged when the equivalent shear rate of e(u) - gamma and of gamma's change over an
    /// iteration are both below this everywhere, in 1/s.
    pub tolerance_1_s: f64,
    /// Whether the penalty adapts by residual balancing (see [`solve`]); `penalty_pa_s` is
    /// then where the first step starts and the largest it takes.
    pub adaptive: bool,
    /// Inexact u steps: each CG solve stops once its residual bounds the strain-rate error it
    /// leaves to this fraction of `tolerance_1_s` (see [`solve`]); 0: to the viscous
    /// stage's relative tolerance.
    pub velocity_fraction: f64,
    /// With `velocity_fraction` f > 0: each u step's floor is f times the larger of the
    /// tolerance and the iterations' own residual so far, not f times the tolerance (see
    /// [`solve`]); false: f times the tolerance in every iteration.
    pub velocity_relative: bool,
    /// With `Some(ratio)`, the strain operator is corrected so that its adjoint (the force
    /// -E^T lambda) is zero for a uniform lambda at every interior particle: one whose
    /// neighbours within the strain radius are all fluid unknowns and whose number density
    /// (the gradient's radius) is at least `ratio` n0 (see [`StrainOperator::build`]).
    /// `None`: the operator as built.
    pub consistent_divergence: Option<f64>,
    /// Anderson acceleration of the iterations over the last this many of them
    /// ([`super::anderson`]); 0: plain iterations.
    pub anderson_depth: u32,
    /// With `Some(c)`, the law's step limits the deviatoric part of the stress by
    /// sqrt(2) tau_y (von Mises) and its isotropic part by c sqrt(2) tau_y, each on its own
    /// (see [`law_step`]); `None`: one limit on the whole tensor.
    pub volumetric_limit: Option<f64>,
    /// Each row's penalty scaled to the law's secant viscosity at the step's start (see
    /// [`row_weights`]); false: one penalty for every row.
    pub local_penalty: bool,
}

/// Residual balancing (He, Yang & Wang 2000; Boyd et al. 2011, sec. 3.4.1): the penalty is
/// doubled when e(u) - gamma exceeds gamma's change over the iteration by this factor, and
/// halved in the opposite case.
const BALANCE_RATIO: f64 = 10.0;

/// The balanced penalty's floor, as a fraction of `YieldSolve::penalty_pa_s`: a guard that
/// keeps r (a divisor in the law's step) away from 0 however long the halving goes on; the
/// runs measured ended their steps above 0.003 of it (3.9 Pa s from 1000).
const MIN_PENALTY_FRACTION: f64 = 1e-6;

/// The strain rate as a linear map of the unknown velocities (the viscous stage's rows):
/// e_k = sym(sum over entries (c, a) of S_c u_c a^T) + e0_k, where S_c negates the normal
/// components of the mirror planes whose bits ride in column c (a mirror image's velocity,
/// [`Neighbours::reflected`]; the identity without planes).
pub(crate) struct StrainOperator<const D: usize> {
    offsets: Vec<usize>,
    columns: Vec<u32>,
    coefficients: Vec<Vector<D>>,
    constant: Vec<Tensor<D>>,
    // The transpose: per unknown, its (row, coefficient) entries in row order; a row index
    // carries the entry's plane bits.
    t_offsets: Vec<usize>,
    t_rows: Vec<u32>,
    t_coefficients: Vec<Vector<D>>,
}

impl<const D: usize> StrainOperator<D> {
    /// The corrected strain rate of each row's particle (`rows[k]`, `row_of` its inverse) over
    /// the neighbours within the strain rate's radius: G_i = sum_j (u_j - u_i) b_ij^T,
    /// b_ij = M_i^-1 r_ij w_ij / r_ij^2; a wall or dummy neighbour carries its own velocity times the frame's
    /// factor (as in `velocity_gradient`), which goes to e0.
    pub(crate) fn build(
        p: &Particles<D>,
        nb: &Neighbours,
        refs: &RefValues,
        rows: &[usize],
        row_of: &[u32],
        walls: &Walls<'_, D>,
        consistent_divergence: Option<f64>,
    ) -> Self {
        let mut per_row: Vec<Row<D>> = map_particles(rows.len(), |k| {
            let i = rows[k];
            let radius = refs.radius_strain_m;
            let frames = Frames::of(p, nb, i, radius, walls);
            let m = moment_matrix(&p.position_m, nb, i, radius);
            let c = gradient_correction(&m, refs.n0_strain, MIN_DET_RATIO);
            let mut entries = Vec::new();
            let mut own = Vector::<D>::zeros();
            let mut constant = Tensor::<D>::zeros();
            // (pairs, whether every neighbour is an unknown without plane bits)
            let mut geometry = consistent_divergence.map(|_| (Vec::new(), true));
            for (e, r, r2, w) in weighted_neighbours(&p.position_m, nb, i, radius) {
                let j = entry_index(e);
                // M_i is symmetric: b^T = r^T M^-1 w / r^2.
                let b = c.transpose() * r * (w / r2);
                let unknown = p.kind[j] == ParticleKind::Fluid && row_of[j] != u32::MAX;
                if let Some((pairs, all_unknown)) = &mut geometry {
                    *all_unknown &= unknown && Neighbours::plane_bits(e) == 0;
                    if unknown {
                        pairs.push((r, w / r2));
                    }
                }
                if unknown {
                    // i's own image too: (S u_i - u_i) b^T.
                    entries.push((row_of[j] | Neighbours::plane_bits(e), b));
                    own -= b;
                } else {
                    let f = frames.factor(e, &r);
                    constant += nb.reflect(e, p.velocity_m_s[j]) * (b * f).transpose();
                    own -= b * f;
                }
            }
            entries.push((k as u32, own));
            let geometry = geometry.map(|(pairs, all_unknown)| {
                // The free surface's rule (number density with the gradient's radius).
                let density = number_density(&p.position_m, nb, i, refs.radius_n_m, |_| true);
                let ratio = consistent_divergence.unwrap_or(1.0);
                let interior = all_unknown && density >= ratio * refs.n0;
                let sum = if interior {
                    ColumnSum::Zero
                } else {
                    ColumnSum::Free
                };
                (pairs, sum)
            });
            (entries, (constant + constant.transpose()) * 0.5, geometry)
        });
        if consistent_divergence.is_some() {
            // Not reaching the tolerance leaves a valid operator (every row still first-order
            // exact), with part of the column sums.
            make_divergence_consistent(&mut per_row, refs.n0_strain);
        }
        let mut op = Self {
            offsets: Vec::with_capacity(rows.len() + 1),
            columns: Vec::new(),
            coefficients: Vec::new(),
            constant: Vec::with_capacity(rows.len()),
            t_offsets: Vec::new(),
            t_rows: Vec::new(),
            t_coefficients: Vec::new(),
        };
        op.offsets.push(0);
        for (entries, constant, _) in per_row {
            for (c, a) in entries {
                op.columns.push(c);
                op.coefficients.push(a);
            }
            op.offsets.push(op.columns.len());
            op.constant.push(constant);
        }
        let (t_offsets, slot) =
            column_order(rows.len(), op.columns.iter().map(|&c| entry_index(c)));
        op.t_offsets = t_offsets;
        op.t_rows = vec![0; op.columns.len()];
        op.t_coefficients = vec![Vector::<D>::zeros(); op.columns.len()];
        for k in 0..rows.len() {
            let row = op.offsets[k]..op.offsets[k + 1];
            for (e, &s) in row.clone().zip(&slot[row]) {
                op.t_rows[s] = k as u32 | Neighbours::plane_bits(op.columns[e]);
                op.t_coefficients[s] = op.coefficients[e];
            }
        }
        op
    }

    fn rows(&self) -> usize {
        self.constant.len()
    }

    /// E u (without e0).
    fn apply(&self, u: &[[f64; D]]) -> Vec<Tensor<D>> {
        self.apply_weighted(u, None)
    }

    /// W E u, row k scaled by `weight[k]` (E u without weights).
    fn apply_weighted(&self, u: &[[f64; D]], weight: Option<&[f64]>) -> Vec<Tensor<D>> {
        map_particles(self.rows(), |k| {
            let mut g = Tensor::<D>::zeros();
            for e in self.offsets[k]..self.offsets[k + 1] {
                let c = self.columns[e];
                let x = Neighbours::reflected(c, Vector::<D>::from(u[entry_index(c)]));
                g += x * self.coefficients[e].transpose();
            }
            let sym = (g + g.transpose()) * 0.5;
            weight.map_or(sym, |w| sym * w[k])
        })
    }

    /// E^T s for a field s of symmetric tensors (s : sym(S u a^T) = u . S s a).
    fn apply_transpose(&self, s: &[Tensor<D>]) -> Vec<[f64; D]> {
        map_particles(self.rows(), |c| {
            let mut v = Vector::<D>::zeros();
            for e in self.t_offsets[c]..self.t_offsets[c + 1] {
                let k = self.t_rows[e];
                v += Neighbours::reflected(k, s[entry_index(k)] * self.t_coefficients[e]);
            }
            v.into()
        })
    }

    /// The diagonal of E^T E per unknown and component: |sym(e_a c^T)|^2 = (|c|^2 + c_a^2)/2
    /// summed over the unknown's entries (exact without mirror planes; with them a row that
    /// holds a column and its image counts each apart: the Jacobi preconditioner only).
    /// With `weight` per row w_k, the diagonal of E^T W E instead.
    fn normal_diagonal(&self, weight: Option<&[f64]>) -> Vec<[f64; D]> {
        map_particles(self.rows(), |c| {
            let mut d = [0.0; D];
            for e in self.t_offsets[c]..self.t_offsets[c + 1] {
                let a = &self.t_coefficients[e];
                let a2 = a.norm_squared();
                let w = weight.map_or(1.0, |w| w[entry_index(self.t_rows[e])]);
                for (m, d) in d.iter_mut().enumerate() {
                    *d += w * (0.5 * (a2 + a[m] * a[m]));
                }
            }
            d
        })
    }
}

/// The transpose of a list of entries by their columns (counting sort): the columns' starts
/// (n + 1 of them) and each entry's slot in column order, entries of one column in list
/// order (a fixed order, whatever the thread count).
fn column_order(
    n: usize,
    columns: impl Iterator<Item = usize> + Clone,
) -> (Vec<usize>, Vec<usize>) {
    let mut starts = vec![0usize; n + 1];
    for c in columns.clone() {
        starts[c + 1] += 1;
    }
    for c in 0..n {
        starts[c + 1] += starts[c];
    }
    let mut fill = starts.clone();
    let slot = columns
        .map(|c| {
            fill[c] += 1;
            fill[c] - 1
        })
        .collect();
    (starts, slot)
}

/// One row of the strain operator (or of the carried pressure's gradient,
/// `solver/conservative.rs`) as built: its entries (the last is the row's own), e0, and
/// with the consistent divergence each unknown entry's (r_ij, w_ij / r_ij^2) and what
/// [`make_divergence_consistent`] asks of the row's particle's column sum.
pub(crate) type Row<const D: usize> = (
    Vec<(u32, Vector<D>)>,
    Tensor<D>,
    Option<(Vec<(Vector<D>, f64)>, ColumnSum<D>)>,
);

/// What [`make_divergence_consistent`] asks of one particle's column sum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum ColumnSum<const D: usize> {
    /// Left as built (a boundary particle whose sum is the boundary's force).
    Free,
    /// Zero (an interior particle).
    Zero,
    /// Zero across the unit normal n, free along it: a boundary particle whose force on the
    /// rest must be the boundary's normal push.
    Tangential(Vector<D>),
}

impl<const D: usize> ColumnSum<D> {
    /// The part of v that the constraint holds to zero.
    fn held(&self, v: Vector<D>) -> Vector<D> {
        match self {
            Self::Free => Vector::<D>::zeros(),
            Self::Zero => v,
            Self::Tangential(n) => v - n * n.dot(&v),
        }
    }
}

/// Most CG iterations of the correction in [`make_divergence_consistent`].
const CONSISTENCY_MAX_ITERATIONS: u32 = 2000;
/// The correction's CG tolerance, relative to the column sums it removes. What it leaves,
/// tol |s| lambda / l0, must move a rigid particle by much less than the yield solve's
/// tolerance in a step: with 1e-3 the operator changed from step to step by enough that the
/// 10 mm 2D heap crept at 0.2-1 mm/s (docs/validation.md); 1e-6 leaves about 3e-7 1/s there.
const CONSISTENCY_TOLERANCE: f64 = 1e-6;

/// The smallest change db_ij to the unknown entries (weighted by r_ij^2 / w_ij) after which
/// (a) every row stays first-order exact, sum_j r_ij db_ij^T = 0, and (b) every interior
/// particle c ([`ColumnSum::Zero`]) has a zero column sum, sum_i b_ic + own_c = 0 (a
/// [`ColumnSum::Tangential`] one, zero across its normal): E^T of a uniform lambda is then 0
/// there, as the continuous divergence of a uniform stress is, where the corrected gradient's
/// adjoint leaves lambda / l0 times the disorder (docs/validation.md, "A divergence consistent
/// for a uniform stress"). Entries through a mirror plane are left as built (their particles
/// are not interior), and so are the rows too one-sided for (a) to be solved (det of
/// sum_e w_e r_e r_e^T below [`MIN_DET_RATIO`] of the lattice's; here w_e is w_ij / r_ij^2,
/// so M_k is the moment matrix of the corrected gradient over the unknown neighbours).
///
/// With a multiplier mu_c per interior particle (0 elsewhere) for (b), (a)'s multipliers
/// eliminate row by row: db_e = w_e (mu_c - mu_k - F_k r_e) for entry e of row k and column c,
/// F_k = sum_e w_e (mu_c - mu_k) r_e^T M_k^-1, M_k = sum_e w_e r_e r_e^T: the weighted
/// departure of mu from its linear fit at k. (b) is then S mu = -s (s the column sums), S
/// symmetric positive definite, solved by Jacobi-preconditioned CG from 0 in every step.
pub(crate) fn make_divergence_consistent<const D: usize>(
    per_row: &mut [Row<D>],
    n0: f64,
) -> SolveReport {
    let n = per_row.len();
    let constraint: Vec<ColumnSum<D>> = per_row
        .iter()
        .map(|row| row.2.as_ref().map_or(ColumnSum::Free, |g| g.1))
        .collect();
    let interior = |c: usize| constraint[c] != ColumnSum::Free;
    // The unknown entries without plane bits: (row, column, position in the row, r, w).
    let mut entries: Vec<(u32, u32, u32, Vector<D>, f64)> = Vec::new();
    let mut row_start = Vec::with_capacity(n + 1);
    let mut inverse_moments: Vec<Tensor<D>> = Vec::with_capacity(n);
    for (k, (list, _, geometry)) in per_row.iter().enumerate() {
        row_start.push(entries.len());
        let pairs = &geometry.as_ref().expect("geometry kept when consistent").0;
        let first = entries.len();
        for (position, (&(c, _), &(r, w))) in list.iter().zip(pairs).enumerate() {
            if Neighbours::plane_bits(c) == 0 {
                entries.push((k as u32, c, position as u32, r, w));
            }
        }
        let m = entries[first..]
            .iter()
            .fold(Tensor::<D>::zeros(), |m, e| m + e.3 * e.3.transpose() * e.4);
        match well_conditioned_inverse(&m, n0, MIN_DET_RATIO) {
            Some(inverse) => inverse_moments.push(inverse),
            None => {
                // Left as built: no entry of this row changes.
                entries.truncate(first);
                inverse_moments.push(Tensor::<D>::zeros());
            }
        }
    }
    row_start.push(entries.len());
    // Per column, its entries in entry order (the transpose; a fixed order).
    let (column_start, slot) = column_order(n, entries.iter().map(|e| e.1 as usize));
    let mut by_column = vec![0u32; entries.len()];
    for (index, &slot) in slot.iter().enumerate() {
        by_column[slot] = index as u32;
    }
    // db per entry for a given mu, in entry order (rows in turn): each row's linear fit of
    // the held multipliers first, then every entry's change from it.
    let change = |mu: &[[f64; D]]| -> Vec<Vector<D>> {
        let held: Vec<Vector<D>> =
            map_particles(n, |c| constraint[c].held(Vector::<D>::from(mu[c])));
        let fit: Vec<Tensor<D>> = map_particles(n, |k| {
            entries[row_start[k]..row_start[k + 1]]
                .iter()
                .fold(Tensor::<D>::zeros(), |g, e| {
                    g + (held[e.1 as usize] - held[k]) * e.3.transpose() * e.4
                })
                * inverse_moments[k]
        });
        map_particles(entries.len(), |e| {
            let (k, c, _, r, w) = entries[e];
            (held[c as usize] - held[k as usize] - fit[k as usize] * r) * w
        })
    };
    let apply = |mu: &[[f64; D]], out: &mut [[f64; D]]| {
        let db = change(mu);
        let result: Vec<[f64; D]> = map_particles(n, |c| {
            if !interior(c) {
                return mu[c];
            }
            let mut column = -db[row_start[c]..row_start[c + 1]]
                .iter()
                .fold(Vector::<D>::zeros(), |a, d| a + d);
            for &e in &by_column[column_start[c]..column_start[c + 1]] {
                column += db[e as usize];
            }
            match constraint[c] {
                // Along a tangential constraint's normal mu is unused: the identity there
                // keeps the system definite (its right-hand side is 0, so mu stays 0 there).
                ColumnSum::Tangential(normal) => {
                    let mu_c = Vector::<D>::from(mu[c]);
                    (constraint[c].held(column) + normal * normal.dot(&mu_c)).into()
                }
                _ => column.into(),
            }
        });
        out.copy_from_slice(&result);
    };
    // Jacobi: the weights mu_c meets, through its own row and its column.
    let inv_diag: Vec<[f64; D]> = map_particles(n, |c| {
        let d: f64 = if interior(c) {
            entries[row_start[c]..row_start[c + 1]]
                .iter()
                .map(|e| e.4)
                .chain(
                    by_column[column_start[c]..column_start[c + 1]]
                        .iter()
                        .map(|&e| entries[e as usize].4),
                )
                .sum()
        } else {
            0.0
        };
        [if d > 0.0 { 1.0 / d } else { 1.0 }; D]
    });
    // The column sums to remove, -s_c per interior c, over every entry (those of rows left as
    // built too), in row order.
    let mut sums = vec![Vector::<D>::zeros(); n];
    for (list, _, _) in per_row.iter() {
        for (c, a) in list {
            if Neighbours::plane_bits(*c) == 0 {
                sums[entry_index(*c)] += a;
            }
        }
    }
    let rhs: Vec<[f64; D]> = (0..n)
        .map(|c| {
            if interior(c) {
                constraint[c].held(-sums[c]).into()
            } else {
                [0.0; D]
            }
        })
        .collect();
    let mut mu = vec![[0.0; D]; n];
    let report = conjugate_gradient(
        apply,
        &inv_diag,
        &rhs,
        &mut mu,
        CONSISTENCY_TOLERANCE,
        0.0,
        CONSISTENCY_MAX_ITERATIONS,
    );
    let db = change(&mu);
    for (entry, &d) in entries.iter().zip(&db) {
        let row = &mut per_row[entry.0 as usize].0;
        row[entry.2 as usize].1 += d;
        let last = row.len() - 1;
        row[last].1 -= d;
    }
    report
}

/// The outcome of [`solve`].
pub(crate) struct YieldOutcome<const D: usize> {
    /// gamma per row: the strain rate of the law (0 where rigid).
    pub strain_rate: Vec<Tensor<D>>,
    /// lambda per row, in Pa.
    pub stress_pa: Vec<Tensor<D>>,
    /// With the adaptive penalty, the penalty at the end of the step, in Pa s, carried to the
    /// next; 0 otherwise.
    pub penalty_pa_s: f64,
    /// The augmented-Lagrangian iterations the step ran (at most `max_iterations`; equal to it
    /// when the step stopped at the cap rather than on its tolerance).
    pub iterations: u32,
    /// CG iterations summed over the u steps, the largest relative residual, and whether the
    /// iterations met their tolerance.
    pub solve: SolveReport,
}

/// The augmented-Lagrangian iterations of the module's header. `matrix` and `b` are the
/// viscous stage's plastic system as assembled by `predict_velocity`, rows divided by
/// dt mu_p / rho (so mu_p matrix is rho/dt + mu_p L); `x` holds the start guess and returns
/// the velocity; `carried` is lambda per row from the last step; `carried_penalty_pa_s` the
/// adaptive penalty from the last step (0: none yet, start from `settings.penalty_pa_s`).
/// With `settings.adaptive`, an iteration that did not converge rebalances r
/// ([`BALANCE_RATIO`]): a large r drives e(u) to gamma fast but moves gamma slowly, a small r
/// the opposite, and the step stops only when both are small. r never exceeds
/// `settings.penalty_pa_s`: in a rigid region gamma stays 0, so its change is no measure of
/// r, and a growing r there left a 10 mm heap hovering at the tolerance until it yielded
/// again (docs/validation.md). lambda is kept (it is the stress, not scaled by r), so only the
/// preconditioner changes with r.
///
/// With `settings.velocity_fraction` f > 0 a u step stops at a residual res with
/// |res| <= f (tol / sqrt 2) 2 sqrt(a r), a = `mass_rate_pa_s_m2` (rho/dt): the u system is at
/// least a I + r E^T E, and |E A^-1 v| <= |v| / (2 sqrt(a r)) for such an A (E's singular
/// values s give s / (a + r s^2) <= 1 / (2 sqrt(a r))), so the strain rate the inexact u
/// carries is off by at most f times what the stopping test below can see, in every row.
/// With local penalties r_k = r w_k (`settings.local_penalty`, [`row_weights`]) the system is
/// at least a I + r E^T W E, and the same floor bounds the strain-rate error weighted as the
/// penalty term weighs it: sqrt(w_k) |de_k| <= f tol / sqrt 2, so f times the test in the
/// rigid rows (w_k = 1) and up to 1 / sqrt(w_k) times that in rows whose secant viscosity is
/// below r, where the flow sets the stress (bounding every row instead, with the smallest
/// w_k, took 1.3 times the CG iterations in the 16 mm quarter slump; docs/validation.md).
///
/// With `settings.velocity_relative` the floor is that bound times max(1, rho / tol), rho the
/// larger of the mismatch |e(u) + e0 - gamma| and gamma's change in the iteration before (at
/// the first, the mismatch at the step's start): an inexact augmented Lagrangian whose u
/// steps are only as exact as the iterations have come (a relative error criterion, Eckstein
/// & Bertsekas 1992, Eckstein & Silva 2013). Early iterations are far from the tolerance and
/// need no u step finer than their own error: each CG solve stops after a few iterations
/// instead of carrying the step's whole residual down to the floor in the first (the 8 mm
/// quarter slump: 39.5 instead of 132 CG iterations a step; docs/validation.md). The
/// iterations end only on a u step at the fixed floor (one more iteration when they meet the
/// tolerance on a relaxed one, and the cap's last iteration at it), so the answer carries the
/// same bound as without.
#[allow(clippy::too_many_arguments)]
pub(crate) fn solve<const D: usize>(
    op: &StrainOperator<D>,
    matrix: &CsrMatrix,
    b: &[[f64; D]],
    x: &mut [[f64; D]],
    carried: Vec<Tensor<D>>,
    carried_penalty_pa_s: f64,
    plastic_viscosity_pa_s: f64,
    yield_stress_pa: f64,
    settings: &YieldSolve,
    mass_rate_pa_s_m2: f64,
    cg_tolerance: f64,
    cg_max_iterations: u32,
) -> YieldOutcome<D> {
    let n = op.rows();
    let mu = plastic_viscosity_pa_s;
    let mut r = if settings.adaptive && carried_penalty_pa_s > 0.0 {
        carried_penalty_pa_s
    } else {
        settings.penalty_pa_s
    };
    let limit = std::f64::consts::SQRT_2 * yield_stress_pa;
    let shrink = |theta: &Tensor<D>, r: f64| law_step(theta, r, limit, settings.volumetric_limit);
    let mut e = op.apply(x);
    let weight = settings
        .local_penalty
        .then(|| row_weights(&e, &op.constant, mu, limit, settings.penalty_pa_s));
    // Each row's penalty r w_k (w_k = 1 without local penalties).
    let row_penalty = |k: usize, r: f64| weight.as_ref().map_or(r, |w| r * w[k]);
    let normal = op.normal_diagonal(weight.as_deref());
    let inverse_diagonal = |r: f64| -> Vec<[f64; D]> {
        map_particles(n, |k| {
            std::array::from_fn(|m| 1.0 / (mu * matrix.diagonal_of(k, m) + r * normal[k][m]))
        })
    };
    let tolerance = settings.tolerance_1_s / std::f64::consts::SQRT_2;
    let residual_floor =
        |r: f64| settings.velocity_fraction * tolerance * 2.0 * (mass_rate_pa_s_m2 * r).sqrt();
    let mut inv_diag = inverse_diagonal(r);
    let mut lambda = carried;
    let mut gamma: Vec<Tensor<D>> = map_particles(n, |k| {
        let rk = row_penalty(k, r);
        shrink(&(lambda[k] + (e[k] + op.constant[k]) * rk), rk)
    });
    // Not reaching the yield tolerance in max_iterations is not an error: the multiplier
    // carries on into the next step. A u step that failed its tolerance is.
    let mut report = SolveReport {
        iterations: 0,
        relative_residual: 0.0,
        converged: true,
    };
    let mut anderson =
        (settings.anderson_depth > 0).then(|| Anderson::new(settings.anderson_depth as usize));
    let mut iterations = 0;
    // max_k |e_k(u) + e0_k - gamma_k|: how far the strain rates still disagree.
    let mismatch_of = |e: &[Tensor<D>], gamma: &[Tensor<D>]| {
        max_by(n, |k| (e[k] + op.constant[k] - gamma[k]).norm())
    };
    // How far the iterations are from the tolerance (read by the relative floor alone).
    let mut progress = if settings.velocity_relative {
        mismatch_of(&e, &gamma)
    } else {
        tolerance
    };
    for iteration in 0..settings.max_iterations {
        iterations = iteration + 1;
        // The relative floor's factor (1 without it); the last iteration the cap allows
        // solves its u step to the fixed floor.
        let relax = if settings.velocity_relative && iterations < settings.max_iterations {
            (progress / tolerance).max(1.0)
        } else {
            1.0
        };
        let load: Vec<Tensor<D>> = map_particles(n, |k| {
            lambda[k] + (op.constant[k] - gamma[k]) * row_penalty(k, r)
        });
        let div = op.apply_transpose(&load);
        let rhs: Vec<[f64; D]> =
            map_particles(n, |k| std::array::from_fn(|m| mu * b[k][m] - div[k][m]));
        let apply = |u: &[[f64; D]], y: &mut [[f64; D]]| {
            matrix.multiply(u, y);
            let back = op.apply_transpose(&op.apply_weighted(u, weight.as_deref()));
            y.par_iter_mut()
                .with_min_len(MIN_PARALLEL_LEN)
                .zip(&back)
                .for_each(|(y, t)| {
                    for m in 0..D {
                        y[m] = mu * y[m] + r * t[m];
                    }
                });
        };
        let cg = conjugate_gradient(
            apply,
            &inv_diag,
            &rhs,
            x,
            cg_tolerance,
            residual_floor(r) * relax,
            cg_max_iterations,
        );
        report.iterations += cg.iterations;
        if cg.relative_residual.is_nan() || cg.relative_residual > report.relative_residual {
            report.relative_residual = cg.relative_residual;
        }
        report.converged &= cg.converged;
        e = op.apply(x);
        let next: Vec<(Tensor<D>, Tensor<D>)> = map_particles(n, |k| {
            let rk = row_penalty(k, r);
            let theta = lambda[k] + (e[k] + op.constant[k]) * rk;
            let g = shrink(&theta, rk);
            (g, theta - g * rk)
        });
        let change = max_by(n, |k| (next[k].0 - gamma[k]).norm());
        // The iteration's input, in Pa: (lambda, r gamma).
        let input = anderson
            .as_ref()
            .map(|_| pack(&lambda, &gamma, |k| row_penalty(k, r)));
        gamma = next.iter().map(|v| v.0).collect();
        lambda = next.into_iter().map(|v| v.1).collect();
        let mismatch = mismatch_of(&e, &gamma);
        if mismatch <= tolerance && change <= tolerance {
            if relax == 1.0 {
                break;
            }
            // Converged on a relaxed u step: once more at the fixed floor, so that the u a
            // step ends with is solved as without the relative floor.
            progress = tolerance;
            continue;
        }
        progress = mismatch.max(change);
        if settings.adaptive {
            let balanced = if mismatch > BALANCE_RATIO * change {
                (r * 2.0).min(settings.penalty_pa_s)
            } else if change > BALANCE_RATIO * mismatch {
                (r * 0.5).max(settings.penalty_pa_s * MIN_PENALTY_FRACTION)
            } else {
                r
            };
            if balanced != r {
                r = balanced;
                inv_diag = inverse_diagonal(r);
                // Another penalty is another map: the earlier iterates say nothing of it.
                if let Some(anderson) = &mut anderson {
                    anderson.restart();
                }
                continue;
            }
        }
        // The last iteration's output is the plain one (a consistent u, gamma, lambda).
        if let (Some(anderson), Some(input)) = (&mut anderson, input)
            && iteration + 1 < settings.max_iterations
        {
            let image = pack(&lambda, &gamma, |k| row_penalty(k, r));
            let (mixed, guess) = anderson.next(&input, &image, x.as_flattened());
            (lambda, gamma) = unpack(&mixed, |k| row_penalty(k, r));
            x.as_flattened_mut().copy_from_slice(&guess);
        }
    }
    YieldOutcome {
        strain_rate: gamma,
        stress_pa: lambda,
        penalty_pa_s: if settings.adaptive { r } else { 0.0 },
        iterations,
        solve: report,
    }
}

/// The law's step (step 2 of the iterations): gamma = argmin F(g) + r/2 |g - theta / r|^2,
/// F the yield term. With `volumetric: None`, F(g) = limit |g| on the whole tensor, so the
/// multiplier's isotropic part (a pressure-like stress that holds the velocity's discrete
/// divergence) shares the limit with the deviatoric part. With `Some(c)`, F(g) = limit
/// |dev g| + c limit |iso g|: Bingham's criterion (von Mises) on the deviatoric part alone,
/// the isotropic part held rigid up to its own limit c limit (c = 0: not at all).
pub(crate) fn law_step<const D: usize>(
    theta: &Tensor<D>,
    r: f64,
    limit: f64,
    volumetric: Option<f64>,
) -> Tensor<D> {
    let soft = |part: Tensor<D>, bound: f64| {
        let size = part.norm();
        if size <= bound {
            Tensor::<D>::zeros()
        } else {
            part * ((size - bound) / (r * size))
        }
    };
    match volumetric {
        None => soft(*theta, limit),
        Some(c) => {
            let iso = isotropic_part(theta);
            soft(theta - iso, limit) + soft(iso, c * limit)
        }
    }
}

/// Pi = 2 g : g of the law's strain rate, the deviatoric part's with `volumetric` set (the
/// criterion's, see [`law_step`]): what counts a particle as flowing.
pub(crate) fn strain_invariant<const D: usize>(g: &Tensor<D>, volumetric: Option<f64>) -> f64 {
    match volumetric {
        None => 2.0 * g.norm_squared(),
        Some(_) => 2.0 * (g - isotropic_part(g)).norm_squared(),
    }
}

/// (tr t / D) I: the isotropic part of a tensor (the rest is its deviatoric part).
fn isotropic_part<const D: usize>(t: &Tensor<D>) -> Tensor<D> {
    Tensor::<D>::identity() * (t.trace() / D as f64)
}

/// (lambda_k, r_k gamma_k) per row, one flat vector (the accelerated iteration's variable);
/// `r` gives row k's penalty.
fn pack<const D: usize>(
    lambda: &[Tensor<D>],
    gamma: &[Tensor<D>],
    r: impl Fn(usize) -> f64,
) -> Vec<f64> {
    let mut v = Vec::with_capacity(2 * D * D * lambda.len());
    for (k, (l, g)) in lambda.iter().zip(gamma).enumerate() {
        v.extend_from_slice(l.as_slice());
        v.extend((g * r(k)).iter());
    }
    v
}

/// The inverse of [`pack`].
fn unpack<const D: usize>(v: &[f64], r: impl Fn(usize) -> f64) -> (Vec<Tensor<D>>, Vec<Tensor<D>>) {
    v.chunks_exact(2 * D * D)
        .enumerate()
        .map(|(k, c)| {
            (
                Tensor::<D>::from_column_slice(&c[..D * D]),
                Tensor::<D>::from_column_slice(&c[D * D..]) / r(k),
            )
        })
        .unzip()
}

/// Local penalties: row k's weight w_k = (mu_p + limit / |e_k|) / r_max, clamped to
/// [`MIN_PENALTY_FRACTION`, 1], so that at r = r_max its penalty r w_k is the law's secant
/// viscosity at the strain rate e_k of the step's start (limit = sqrt 2 tau_y, the law's bound
/// on |lambda|), and r_max itself where that is larger (a rigid row, e_k = 0); the balancing
/// scales every row's penalty with r. The iterations are the same
/// augmented Lagrangian with the penalty term sum_k r_k |e_k(u) - gamma_k|^2 / 2 (any fixed
/// positive r_k give the same minimiser); one r for every row makes flowing rows stiff and
/// the iterations slow where the law's viscosity is far below the rigid rows' penalty.
fn row_weights<const D: usize>(
    e: &[Tensor<D>],
    constant: &[Tensor<D>],
    mu: f64,
    limit: f64,
    largest_pa_s: f64,
) -> Vec<f64> {
    map_particles(e.len(), |k| {
        // Without a yield stress the law is Newtonian (limit / |e| is 0/0 at rest).
        let secant = if limit > 0.0 {
            mu + limit / (e[k] + constant[k]).norm()
        } else {
            mu
        };
        (secant / largest_pa_s).clamp(MIN_PENALTY_FRACTION, 1.0)
    })
}

/// Jacobi-preconditioned CG for a matrix given as a product, over vectors of D components
/// per row (the components are coupled). Order-fixed reductions (docs/design.md section 6).
/// Stops at a residual of `tolerance` relative to b, or of `floor` in absolute terms, the
/// larger of the two.
fn conjugate_gradient<const D: usize>(
    apply: impl Fn(&[[f64; D]], &mut [[f64; D]]),
    inv_diag: &[[f64; D]],
    b: &[[f64; D]],
    x: &mut [[f64; D]],
    tolerance: f64,
    floor: f64,
    max_iterations: u32,
) -> SolveReport {
    let n = b.len();
    let dot = |u: &[[f64; D]], v: &[[f64; D]]| {
        sum_by(n, |k| (0..D).map(|m| u[k][m] * v[k][m]).sum::<f64>())
    };
    let b_norm = dot(b, b).sqrt();
    if n == 0 || b_norm == 0.0 {
        x.iter_mut().for_each(|v| *v = [0.0; D]);
        return SolveReport {
            iterations: 0,
            relative_residual: 0.0,
            converged: true,
        };
    }
    let mut r = vec![[0.0; D]; n];
    apply(x, &mut r);
    for (r, b) in r.iter_mut().zip(b) {
        for m in 0..D {
            r[m] = b[m] - r[m];
        }
    }
    let precondition = |r: &[[f64; D]]| -> Vec<[f64; D]> {
        map_particles(n, |k| std::array::from_fn(|m| r[k][m] * inv_diag[k][m]))
    };
    let mut z = precondition(&r);
    let mut p = z.clone();
    let mut ap = vec![[0.0; D]; n];
    let mut rz = dot(&r, &z);
    let mut r_norm = dot(&r, &r).sqrt();
    let mut iterations = 0;
    let target = (tolerance * b_norm).max(floor);
    while r_norm > target && iterations < max_iterations {
        apply(&p, &mut ap);
        let p_ap = dot(&p, &ap);
        if p_ap.is_nan() || p_ap <= 0.0 {
            break;
        }
        let alpha = rz / p_ap;
        x.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(r.par_iter_mut())
            .zip(p.par_iter().zip(&ap))
            .for_each(|((x, r), (p, ap))| {
                for m in 0..D {
                    x[m] += alpha * p[m];
                    r[m] -= alpha * ap[m];
                }
            });
        z = precondition(&r);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut()
            .with_min_len(MIN_PARALLEL_LEN)
            .zip(&z)
            .for_each(|(p, z)| {
                for m in 0..D {
                    p[m] = z[m] + beta * p[m];
                }
            });
        r_norm = dot(&r, &r).sqrt();
        iterations += 1;
    }
    let relative_residual = r_norm / b_norm;
    SolveReport {
        iterations,
        relative_residual,
        converged: r_norm <= target,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Local penalties: a rigid row (zero strain rate) keeps the cap, a sheared row gets the
    /// law's secant viscosity mu + limit / |e| as a share of the cap, never below the floor.
    #[test]
    fn row_weights_are_the_secant_viscosity_under_the_cap() {
        let (mu, limit, cap) = (50.0, 2f64.sqrt() * 50.0, 1000.0);
        let shear = Tensor::<2>::new(0.0, 1.0, 1.0, 0.0); // |e| = sqrt 2
        let rigid = Tensor::<2>::zeros();
        let constant = [Tensor::<2>::zeros(), Tensor::<2>::zeros(), shear * 0.5];
        let w = row_weights::<2>(&[rigid, shear, shear * 0.5], &constant, mu, limit, cap);
        assert_eq!(w[0], 1.0);
        assert!((w[1] - (mu + limit / 2f64.sqrt()) / cap).abs() < 1e-15);
        // The constant part (walls' velocities) counts: e + e0 = shear.
        assert_eq!(w[2], w[1]);
        // A tiny plastic viscosity and a fast shear: the floor.
        let fast = [shear * 1e12];
        let w = row_weights::<2>(&fast, &[rigid], 1e-9, limit, cap);
        assert_eq!(w[0], MIN_PENALTY_FRACTION);
        // No yield stress (a Bingham fluid of 0 Pa, Newtonian): the plastic viscosity, at
        // rest too (limit / |e| would be 0/0).
        let w = row_weights::<2>(&[rigid, shear], &[rigid, rigid], mu, 0.0, cap);
        assert_eq!(w, vec![mu / cap, mu / cap]);
    }

    /// The law's step with the volumetric part on its own limit: a stress whose deviatoric
    /// part is inside the yield limit stays rigid however large its isotropic part (up to
    /// c limit), where the whole tensor's limit lets it yield; past the limits each part
    /// shrinks by its own; the invariant then counts only the deviatoric strain rate.
    #[test]
    fn the_volumetric_limit_keeps_the_deviatoric_criterion_whole() {
        let (r, limit) = (1000.0, 2f64.sqrt() * 50.0);
        let dev = Tensor::<3>::new(0.0, 40.0, 0.0, 40.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let iso = Tensor::<3>::identity() * 30.0;
        let theta = dev + iso;
        assert!(dev.norm() < limit && theta.norm() > limit);
        // One limit on the whole tensor: it yields.
        let shared = law_step::<3>(&theta, r, limit, None);
        assert!(shared.norm() > 0.0);
        assert_eq!(
            shared,
            theta * ((theta.norm() - limit) / (r * theta.norm()))
        );
        // Its own limit (c = 1, iso.norm() = 52 < 70.7): rigid, gamma = 0 exactly.
        assert_eq!(
            law_step::<3>(&theta, r, limit, Some(1.0)),
            Tensor::<3>::zeros()
        );
        // c = 0: the isotropic part is never held; it passes to gamma whole (theta / r).
        assert_eq!(law_step::<3>(&theta, r, limit, Some(0.0)), iso / r);
        // Past the deviatoric limit the deviatoric part shrinks by the limit alone: the
        // multiplier left (theta - r gamma) keeps the isotropic part whole and its
        // deviatoric part sits on the limit; gamma is traceless.
        let big = dev * 2.0 + iso;
        let g = law_step::<3>(&big, r, limit, Some(1.0));
        let left = big - g * r;
        assert!(((left - iso).norm() - limit).abs() < 1e-12);
        assert!((g.trace()).abs() < 1e-15);
        // The invariant: 2 g : g as before without the limit; the deviatoric part's with it.
        let mixed = g + Tensor::<3>::identity() * 0.5;
        assert_eq!(
            strain_invariant::<3>(&mixed, None),
            2.0 * mixed.norm_squared()
        );
        assert!((strain_invariant::<3>(&mixed, Some(1.0)) - 2.0 * g.norm_squared()).abs() < 1e-12);
    }

    /// A block of `cells`^D fluid particles on a lattice of spacing 1, each moved by up to
    /// `disorder` (a fixed 64-bit LCG), with the neighbours, the strain radius 1.5 and every
    /// particle a row.
    fn jittered_block<const D: usize>(
        cells: usize,
        disorder: f64,
    ) -> (Particles<D>, Neighbours, RefValues, Vec<usize>, Vec<u32>) {
        let mut state = 12345u64;
        let mut jitter = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        let n = cells.pow(D as u32);
        let mut p = Particles::<D>::default();
        for index in 0..n {
            let x = Vector::<D>::from_fn(|a, _| {
                ((index / cells.pow(a as u32)) % cells) as f64 + disorder * jitter()
            });
            p.position_m.push(x);
            p.velocity_m_s.push(Vector::<D>::zeros());
            p.pressure_pa.push(0.0);
            p.kind.push(ParticleKind::Fluid);
            p.tag.push(0);
        }
        let refs = RefValues::on_lattice::<D>(1.0, 2.1, 2.1).with_strain_radius::<D>(1.0, 1.5);
        let nb = Neighbours::build(&p.position_m, 2.1);
        let rows: Vec<usize> = (0..n).collect();
        let row_of: Vec<u32> = (0..n as u32).collect();
        (p, nb, refs, rows, row_of)
    }

    /// E^T of a uniform lambda = I (each particle's column sum) as (its norm over the particles
    /// at least 3 spacings inside, its norm over all), and the largest error of E on the linear
    /// velocity u = (x_1, 0, ..) (strain rate xy 1/2) over all rows.
    fn uniform_force_and_linear_error<const D: usize>(
        disorder: f64,
        consistent: Option<f64>,
    ) -> ((f64, f64), f64) {
        let cells = if D == 2 { 16 } else { 8 };
        let (p, nb, refs, rows, row_of) = jittered_block::<D>(cells, disorder);
        let op = StrainOperator::build(
            &p,
            &nb,
            &refs,
            &rows,
            &row_of,
            &Walls::own_velocity(),
            consistent,
        );
        let force = op.apply_transpose(&vec![Tensor::<D>::identity(); rows.len()]);
        // Inside: at least 3 spacings from every face (the strain stencil reaches 1.5).
        let inside = |x: &Vector<D>| x.iter().all(|&c| c > 2.9 && c < cells as f64 - 3.9);
        let (mut sum_inside, mut sum_all) = (0.0, 0.0);
        for (k, f) in force.iter().enumerate() {
            let f2 = f.iter().map(|v| v * v).sum::<f64>();
            sum_all += f2;
            if inside(&p.position_m[k]) {
                sum_inside += f2;
            }
        }
        let u: Vec<[f64; D]> = p
            .position_m
            .iter()
            .map(|x| std::array::from_fn(|a| if a == 0 { x[1] } else { 0.0 }))
            .collect();
        let e = op.apply(&u);
        let mut exact = Tensor::<D>::zeros();
        exact[(0, 1)] = 0.5;
        exact[(1, 0)] = 0.5;
        let linear_error = e.iter().map(|e| (e - exact).norm()).fold(0.0, f64::max);
        ((sum_inside.sqrt(), sum_all.sqrt()), linear_error)
    }

    #[test]
    fn consistent_divergence_removes_the_uniform_stress_force() {
        fn check<const D: usize>() {
            for disorder in [0.05, 0.2] {
                let ((before, before_all), linear_before) =
                    uniform_force_and_linear_error::<D>(disorder, None);
                let ((after, _), linear_after) =
                    uniform_force_and_linear_error::<D>(disorder, Some(0.8));
                eprintln!(
                    "{D}D disorder {disorder}: |E^T I| inside {before:.3e} -> {after:.3e}; \
                     linear error {linear_before:.1e} -> {linear_after:.1e}"
                );
                // The adjoint of the corrected gradient leaves a force of the order of the
                // disorder (here per unit lambda, summed over the inside particles); the
                // correction's CG leaves at most its relative tolerance of the column sums of
                // all interior particles, which the inside ones are part of.
                assert!(before > 0.1 * disorder, "{before}");
                assert!(
                    after <= CONSISTENCY_TOLERANCE * before_all,
                    "{after} against {before_all}"
                );
                // The correction keeps every row's first-order exactness (at 0.2 l0 some first
                // shells are too one-sided for the corrective matrix, before and after alike).
                assert!(
                    (linear_after - linear_before).abs() < 1e-8,
                    "{linear_after}"
                );
                if disorder < 0.1 {
                    assert!(linear_before < 1e-10, "{linear_before}");
                }
            }
        }
        check::<2>();
        check::<3>();
    }
}
