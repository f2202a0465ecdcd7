//! Order-fixed parallel reductions (docs/design.md section 6).
//!
//! rayon's `sum`/`reduce` combine partial results in an order that depends on work stealing,
//! so floating-point sums change with the thread count. Here the split into chunks depends on
//! the data length alone and the partial sums are added in chunk order.
use rayon::prelude::*;

/// Elements per partial sum. A constant: never derived from the thread count.
pub const CHUNK: usize = 1024;

/// Below this many elements a parallel loop is not split further: for small systems the cost
/// of handing work to threads exceeds the work. (Only scheduling: results never depend on it.)
pub const MIN_PARALLEL_LEN: usize = 4096;

/// Number of particles handed to one task by the per-particle loops (each particle gathers
/// over tens of neighbours, so tasks can be smaller than for plain vector loops). Also the
/// largest task: the work per particle is very uneven (fluid particles first, then walls
/// with little or nothing to do), and rayon's adaptive split would leave one thread with
/// most of it.
pub const PARTICLES_PER_TASK: usize = 256;

/// f(i) for every particle index in 0..n, in tasks of [`PARTICLES_PER_TASK`] particles,
/// collected in index order (each value computed by one task alone: the same bits on any
/// thread count).
pub fn map_particles<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
    (0..n)
        .into_par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .with_max_len(PARTICLES_PER_TASK)
        .map(f)
        .collect()
}

/// Sum of f(i) for i in 0..n, bitwise identical on any thread count.
pub fn sum_by<F>(n: usize, f: F) -> f64
where
    F: Fn(usize) -> f64 + Sync + Send,
{
    let chunks = n.div_ceil(CHUNK);
    let partial: Vec<f64> = (0..chunks)
        .into_par_iter()
        .with_min_len(MIN_PARALLEL_LEN / CHUNK)
        .map(|c| {
            let mut s = 0.0;
            for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                s += f(i);
            }
            s
        })
        .collect();
    partial.iter().fold(0.0, |acc, s| acc + s)
}

/// Dot product a . b with the fixed chunking of [`sum_by`].
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    sum_by(a.len(), |i| a[i] * b[i])
}

/// Maximum of f(i) (max is exact and order-independent; NaN propagates as NaN).
pub fn max_by<F>(n: usize, f: F) -> f64
where
    F: Fn(usize) -> f64 + Sync + Send,
{
    (0..n).into_par_iter().map(f).reduce(
        || f64::NEG_INFINITY,
        |a, b| {
            if a.is_nan() || b.is_nan() {
                f64::NAN
            } else {
                a.max(b)
            }
        },
    )
}
