//! Cell-centred lattice helpers shared by the scene builders.
use crate::mps::Vector;

/// A box of lattice cells, lo..hi (hi exclusive) on every axis.
pub type CellBox<const D: usize> = ([i64; D], [i64; D]);

/// Number of whole cells of size `spacing_m` in `length_m` (rounded, at least 1).
pub fn cells(length_m: f64, spacing_m: f64) -> i64 {
    ((length_m / spacing_m).round() as i64).max(1)
}

/// Centre of lattice cell `index` (particles sit at (k + 1/2) l0 so that a box [0, L] holds
/// whole particles and walls start half a spacing outside it).
pub fn centre<const D: usize>(index: [i64; D], spacing_m: f64) -> Vector<D> {
    Vector::<D>::from_fn(|a, _| (index[a] as f64 + 0.5) * spacing_m)
}

/// Visits every index of the box lo..hi (exclusive) in a fixed order, last axis slowest.
pub fn for_each_index<const D: usize>(lo: [i64; D], hi: [i64; D], mut f: impl FnMut([i64; D])) {
    let mut idx = lo;
    if (0..D).any(|a| lo[a] >= hi[a]) {
        return;
    }
    loop {
        f(idx);
        let mut a = 0;
        loop {
            idx[a] += 1;
            if idx[a] < hi[a] {
                break;
            }
            idx[a] = lo[a];
            a += 1;
            if a == D {
                return;
            }
        }
    }
}
