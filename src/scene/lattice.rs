//! Cell-centred lattice helpers shared by the scene builders.
use crate::mps::Vector;

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

/// How many cells `index` lies outside the box 0..n along any axis (0 = first layer outside),
/// or None when inside. `open_top` leaves the last axis unbounded above.
pub fn layer_outside<const D: usize>(index: [i64; D], n: [i64; D], open_top: bool) -> Option<i64> {
    let mut layer: Option<i64> = None;
    for a in 0..D {
        let out = if index[a] < 0 {
            Some(-index[a] - 1)
        } else if index[a] >= n[a] && !(open_top && a == D - 1) {
            Some(index[a] - n[a])
        } else {
            None
        };
        if let Some(o) = out {
            layer = Some(layer.map_or(o, |l: i64| l.max(o)));
        }
    }
    layer
}
