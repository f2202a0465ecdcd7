//! Containers made of a union of boxes, walled by wall and dummy particle layers.
use super::lattice::{centre, for_each_index};
use crate::mps::{ParticleKind, Particles};

/// A box of lattice cells, lo..hi (hi exclusive) on every axis.
pub type CellBox<const D: usize> = ([i64; D], [i64; D]);

/// Chebyshev distance in cells from `index` to the box (0 inside).
fn distance<const D: usize>(index: [i64; D], b: &CellBox<D>) -> i64 {
    (0..D)
        .map(|a| (b.0[a] - index[a]).max(index[a] - (b.1[a] - 1)).max(0))
        .max()
        .unwrap_or(0)
}

/// Adds the wall particles of a container whose inside is the union of `interior` boxes:
/// every cell within `wall_layers + dummy_layers` cells of the inside (Chebyshev distance) and
/// below the cell row `top` (the container is open above it). The first `wall_layers` layers
/// are wall particles, the rest dummies. Cells are visited in a fixed order.
pub fn add_walls<const D: usize>(
    particles: &mut Particles<D>,
    interior: &[CellBox<D>],
    top: i64,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
) {
    let layers = (wall_layers + dummy_layers) as i64;
    let mut lo = [i64::MAX; D];
    let mut hi = [i64::MIN; D];
    for b in interior {
        for a in 0..D {
            lo[a] = lo[a].min(b.0[a] - layers);
            hi[a] = hi[a].max(b.1[a] + layers);
        }
    }
    hi[D - 1] = hi[D - 1].min(top);
    for_each_index(lo, hi, |idx| {
        let d = interior.iter().map(|b| distance(idx, b)).min().unwrap_or(0);
        if d == 0 || d > layers {
            return;
        }
        let kind = if d <= wall_layers as i64 {
            ParticleKind::Wall
        } else {
            ParticleKind::Dummy
        };
        particles.push(centre(idx, spacing_m), kind);
    });
}
