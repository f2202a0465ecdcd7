//! Particle interaction models of MPS (seed 000 eqs. 3 and 4), for one particle i.
//!
//! Each function gathers over the neighbour list of i in its fixed order, so results do not
//! depend on the thread that computes them.
use super::grid::{Neighbours, entry_index};
use super::kernel::weight;
use super::particles::Vector;

/// n_i = sum_j w(|r_ij|) over neighbours j accepted by `include`.
#[inline]
pub fn number_density<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
    include: impl Fn(usize) -> bool,
) -> f64 {
    let mut n = 0.0;
    for &e in nb.of(i) {
        let j = entry_index(e);
        if include(j) {
            n += weight(nb.displacement(positions, i, e).norm(), radius_m);
        }
    }
    n
}

/// sum_j r_ij w(|r_ij|) / |r_ij| over neighbours j accepted by `include(j, r_ij)`: the
/// kernel-weighted direction towards the neighbours, which points into the fluid at a free
/// surface (minus the outward normal, once normalised).
#[inline]
pub fn inward_sum<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
    include: impl Fn(usize, &Vector<D>) -> bool,
) -> Vector<D> {
    let mut inward = Vector::<D>::zeros();
    for &e in nb.of(i) {
        let j = entry_index(e);
        let r = nb.displacement(positions, i, e);
        if !include(j, &r) {
            continue;
        }
        let d = r.norm();
        let w = weight(d, radius_m);
        if w > 0.0 {
            inward += r * (w / d);
        }
    }
    inward
}

/// Gradient model (eq. 3): d/n0 sum_j (phi_j - phi_i) r_ij w(|r_ij|) / |r_ij|^2, where
/// `difference(j)` returns phi_j - phi_i (or None to skip j).
#[inline]
pub fn gradient<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
    n0: f64,
    difference: impl Fn(usize) -> Option<f64>,
) -> Vector<D> {
    difference_sum(positions, nb, i, radius_m, |j, _| difference(j)) * (D as f64 / n0)
}

/// sum_j (phi_j - phi_i) r_ij w(|r_ij|) / |r_ij|^2 over the neighbours within `radius_m`, with
/// `difference(j, r_ij)` giving phi_j - phi_i (None skips j): the sum both gradient models
/// normalise.
#[inline]
pub(crate) fn difference_sum<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
    difference: impl Fn(usize, &Vector<D>) -> Option<f64>,
) -> Vector<D> {
    let mut g = Vector::<D>::zeros();
    for &e in nb.of(i) {
        let j = entry_index(e);
        let r = nb.displacement(positions, i, e);
        let r2 = r.norm_squared();
        let w = weight(r2.sqrt(), radius_m);
        if w == 0.0 {
            continue;
        }
        if let Some(d) = difference(j, &r) {
            g += r * (d * w / r2);
        }
    }
    g
}

/// sum_j r_ij w(|r_ij|)/|r_ij|^2 over i's neighbours within `radius_m`: the gradient model's
/// sum for the constant 1, zero on a complete lattice shell; it points away from whichever
/// neighbour is closer than the others (the pressure regularisation's repulsion).
pub fn shell_repulsion<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
) -> Vector<D> {
    difference_sum(positions, nb, i, radius_m, |_, _| Some(1.0))
}

/// Divergence model: d/n0 sum_j (u_j - u_i) . r_ij w(|r_ij|) / |r_ij|^2, where
/// `difference(e)` returns u_j - u_i for list entry e (a mirror image's u_j reflected, see
/// [`Neighbours::reflect`]). Only the pair's radial relative velocity counts, so a shear
/// along a no-slip wall adds nothing.
#[inline]
pub fn divergence<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
    n0: f64,
    difference: impl Fn(u32) -> Vector<D>,
) -> f64 {
    let mut s = 0.0;
    for &e in nb.of(i) {
        let r = nb.displacement(positions, i, e);
        let r2 = r.norm_squared();
        let w = weight(r2.sqrt(), radius_m);
        if w > 0.0 {
            s += difference(e).dot(&r) * w / r2;
        }
    }
    s * (D as f64 / n0)
}

/// Laplacian model (eq. 4) of a vector field: 2d/(lambda n0) sum_j (u_j - u_i) w(|r_ij|),
/// where `difference(j)` returns u_j - u_i (or None to skip j).
#[inline]
pub fn laplacian<const D: usize, const M: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
    n0: f64,
    lambda_m2: f64,
    difference: impl Fn(usize) -> Option<nalgebra::SVector<f64, M>>,
) -> nalgebra::SVector<f64, M> {
    let mut s = nalgebra::SVector::<f64, M>::zeros();
    for &e in nb.of(i) {
        let j = entry_index(e);
        let w = weight(nb.displacement(positions, i, e).norm(), radius_m);
        if w == 0.0 {
            continue;
        }
        if let Some(d) = difference(j) {
            s += d * w;
        }
    }
    s * (2.0 * D as f64 / (lambda_m2 * n0))
}

/// Moment matrix M_i = sum_j w_ij r_ij (x) r_ij / |r_ij|^2 over the neighbours within
/// `radius_m` (Khayyer & Gotoh 2011, corrective matrix; the 1/n0 cancels against the sum it
/// corrects). On a full regular lattice M = (n0/d) I.
#[inline]
pub fn moment_matrix<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
) -> nalgebra::SMatrix<f64, D, D> {
    let mut m = nalgebra::SMatrix::<f64, D, D>::zeros();
    for (_, r, r2, w) in weighted_neighbours(positions, nb, i, radius_m) {
        m += r * r.transpose() * (w / r2);
    }
    m
}

/// i's neighbours within `radius_m` that have a weight: (entry, r_ij, |r_ij|^2, w(|r_ij|)), in
/// list order.
#[inline]
pub fn weighted_neighbours<'a, const D: usize>(
    positions: &'a [Vector<D>],
    nb: &'a Neighbours,
    i: usize,
    radius_m: f64,
) -> impl Iterator<Item = (u32, Vector<D>, f64, f64)> + 'a {
    nb.of(i).iter().filter_map(move |&e| {
        let r = nb.displacement(positions, i, e);
        let r2 = r.norm_squared();
        let w = weight(r2.sqrt(), radius_m);
        (w > 0.0).then_some((e, r, r2, w))
    })
}

/// The share of the full lattice's det M below which the corrective matrix is not used (a
/// particle with neighbours on one side only: a splash, a thin jet), where the uncorrected
/// normalisation's error is bounded: the incremental scheme's gradients and the corrected
/// strain rate.
pub const MIN_DET_RATIO: f64 = 0.05;

/// The correction that makes `sum_j (phi_j - phi_i) r_ij w / |r_ij|^2` a first-order
/// consistent gradient: M_i^-1 where M_i is well conditioned, else the uncorrected
/// normalisation d/n0 (a particle with too few neighbours, e.g. a splash). "Well conditioned":
/// det M_i at least `min_det_ratio` times that of the full lattice, (n0/d)^d.
#[inline]
pub fn gradient_correction<const D: usize>(
    m: &nalgebra::SMatrix<f64, D, D>,
    n0: f64,
    min_det_ratio: f64,
) -> nalgebra::SMatrix<f64, D, D> {
    // 1 / (n0/d), written as before the split (d/n0 may differ in its last bit).
    let full = n0 / D as f64;
    well_conditioned_inverse(m, n0, min_det_ratio)
        .unwrap_or_else(|| nalgebra::SMatrix::<f64, D, D>::identity() * (1.0 / full))
}

/// The pressure smoothing's sums (`mps.pressure_smoothing_time_s`):
/// (sum_j w_ij (v_j - v_i - G_i . r_ij), sum_j w_ij), whose ratio is the step toward the
/// local mean, over i's neighbours within `radius_m` whose `value(j)` is Some(v_j) (i's own
/// must be), G_i their corrected gradient of v (`fallback_gradient` where they do not span
/// every direction, see [`MIN_DET_RATIO`]). The first is zero for any linear v wherever G_i
/// is corrected: only the part of v that no plane fits is smoothed.
#[inline]
pub fn smoothing_sums<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
    n0: f64,
    value: impl Fn(usize) -> Option<f64>,
    fallback_gradient: Vector<D>,
) -> (f64, f64) {
    let neighbours = || {
        weighted_neighbours(positions, nb, i, radius_m)
            .filter_map(|(e, r, r2, w)| value(entry_index(e)).map(|v| (v, r, r2, w)))
    };
    let vi = value(i).expect("the particle smoothed has a value");
    let mut moments = nalgebra::SMatrix::<f64, D, D>::zeros();
    for (_, r, r2, w) in neighbours() {
        moments += r * r.transpose() * (w / r2);
    }
    let gradient = well_conditioned_inverse(&moments, n0, MIN_DET_RATIO).map_or(
        fallback_gradient,
        |inverse| {
            inverse * difference_sum(positions, nb, i, radius_m, |j, _| value(j).map(|v| v - vi))
        },
    );
    let (mut excess, mut weights) = (0.0, 0.0);
    for (vj, r, _, w) in neighbours() {
        excess += w * (vj - vi - gradient.dot(&r));
        weights += w;
    }
    (excess, weights)
}

/// M_i^-1 where det M_i is at least `min_det_ratio` times the full lattice's (n0/d)^d (see
/// [`gradient_correction`]), else None.
#[inline]
pub fn well_conditioned_inverse<const D: usize>(
    m: &nalgebra::SMatrix<f64, D, D>,
    n0: f64,
    min_det_ratio: f64,
) -> Option<nalgebra::SMatrix<f64, D, D>> {
    let full = n0 / D as f64;
    let lattice_det = (0..D).fold(1.0, |v, _| v * full);
    match determinant_and_inverse(m) {
        Some((det, inverse)) if det >= min_det_ratio * lattice_det => Some(inverse),
        _ => None,
    }
}

/// Determinant and inverse of a small matrix by Gauss-Jordan elimination with partial
/// pivoting (nalgebra's need a dimension bound that a const-generic D lacks); None when a
/// pivot is zero.
fn determinant_and_inverse<const D: usize>(
    m: &nalgebra::SMatrix<f64, D, D>,
) -> Option<(f64, nalgebra::SMatrix<f64, D, D>)> {
    let mut a = *m;
    let mut inverse = nalgebra::SMatrix::<f64, D, D>::identity();
    let mut det = 1.0;
    for col in 0..D {
        let pivot = (col..D)
            .max_by(|&x, &y| a[(x, col)].abs().total_cmp(&a[(y, col)].abs()))
            .expect("col < D");
        if a[(pivot, col)] == 0.0 {
            return None;
        }
        if pivot != col {
            a.swap_rows(pivot, col);
            inverse.swap_rows(pivot, col);
            det = -det;
        }
        let d = a[(col, col)];
        det *= d;
        for k in 0..D {
            a[(col, k)] /= d;
            inverse[(col, k)] /= d;
        }
        for row in 0..D {
            if row != col {
                let f = a[(row, col)];
                if f != 0.0 {
                    for k in 0..D {
                        a[(row, k)] -= f * a[(col, k)];
                        inverse[(row, k)] -= f * inverse[(col, k)];
                    }
                }
            }
        }
    }
    Some((det, inverse))
}

/// Corrected gradient in difference form: C_i sum_j (phi_j - phi_i) r_ij w / |r_ij|^2, with C_i
/// from [`gradient_correction`]; exact for a linear field on any arrangement where M_i is
/// well conditioned. `difference(j, r_ij)` gives phi_j - phi_i for every neighbour j (walls
/// and dummies included: they carry a mirrored value).
#[inline]
pub fn corrected_gradient<const D: usize>(
    positions: &[Vector<D>],
    nb: &Neighbours,
    i: usize,
    radius_m: f64,
    correction: &nalgebra::SMatrix<f64, D, D>,
    difference: impl Fn(usize, &Vector<D>) -> f64,
) -> Vector<D> {
    correction * difference_sum(positions, nb, i, radius_m, |j, r| Some(difference(j, r)))
}
