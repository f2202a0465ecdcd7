//! Particle interaction models of MPS (seed 000 eqs. 3 and 4), for one particle i.
//!
//! Each function gathers over the neighbour list of i in its fixed order, so results do not
//! depend on the thread that computes them.
use super::grid::Neighbours;
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
    for &j in nb.of(i) {
        let j = j as usize;
        if include(j) {
            n += weight(nb.displacement(positions, i, j).norm(), radius_m);
        }
    }
    n
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
    let mut g = Vector::<D>::zeros();
    for &j in nb.of(i) {
        let j = j as usize;
        let r = nb.displacement(positions, i, j);
        let r2 = r.norm_squared();
        let w = weight(r2.sqrt(), radius_m);
        if w == 0.0 {
            continue;
        }
        if let Some(d) = difference(j) {
            g += r * (d * w / r2);
        }
    }
    g * (D as f64 / n0)
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
    for &j in nb.of(i) {
        let j = j as usize;
        let w = weight(nb.displacement(positions, i, j).norm(), radius_m);
        if w == 0.0 {
            continue;
        }
        if let Some(d) = difference(j) {
            s += d * w;
        }
    }
    s * (2.0 * D as f64 / (lambda_m2 * n0))
}
