//! Containers whose inside is a union of boxes, walled by wall and dummy particle layers: a
//! solid (a box around them minus their union) filled by [`super::shapes::fill_walls`].
use super::shapes::{Shape, fill_walls};
use crate::mps::{Particles, Vector};

pub use super::lattice::CellBox;
use super::lattice::cells;

/// The two boxes of an L-shaped container as lattice boxes: the vertical part (x up to
/// `vertical_width_m`, height `vertical_height_m`) and the horizontal part (x up to
/// `vertical_width_m + channel_length_m`, height `channel_height_m`), both from the origin;
/// axis 0 along the box, the last axis up and, in 3D, axis 1 across it (`depth_m`).
pub fn l_box_parts<const D: usize>(
    vertical_width_m: f64,
    vertical_height_m: f64,
    channel_length_m: f64,
    channel_height_m: f64,
    depth_m: f64,
    spacing_m: f64,
) -> (CellBox<D>, CellBox<D>) {
    let n = |x: f64| cells(x, spacing_m);
    let extent = |along: i64, vertical: i64| -> [i64; D] {
        std::array::from_fn(|a| {
            if a == 0 {
                along
            } else if a == D - 1 {
                vertical
            } else {
                n(depth_m)
            }
        })
    };
    (
        ([0; D], extent(n(vertical_width_m), n(vertical_height_m))),
        (
            [0; D],
            extent(n(vertical_width_m + channel_length_m), n(channel_height_m)),
        ),
    )
}

/// Adds the wall particles of a container whose inside is the union of `interior` boxes:
/// every cell within `wall_layers + dummy_layers` cells of the inside (Chebyshev distance, the
/// box metric of [`Shape::depth_m`]) and below the cell row `top` (the container is open above
/// it). The first `wall_layers` layers are wall particles, the rest dummies. Cells are visited
/// in a fixed order.
pub fn add_walls<const D: usize>(
    particles: &mut Particles<D>,
    interior: &[CellBox<D>],
    top: i64,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
) {
    let layers = i64::from(wall_layers + dummy_layers);
    let mut lo = [i64::MAX; D];
    let mut hi = [i64::MIN; D];
    for b in interior {
        for a in 0..D {
            lo[a] = lo[a].min(b.0[a]);
            hi[a] = hi[a].max(b.1[a]);
        }
    }
    let corner =
        |cells: [i64; D], by: i64| Vector::<D>::from_fn(|a, _| (cells[a] + by) as f64 * spacing_m);
    // The outer box lies 2 layers out, so its own faces are deeper than the layers reach.
    let solid = Shape::Difference {
        from: Box::new(Shape::Box {
            min_m: corner(lo, -2 * layers),
            max_m: corner(hi, 2 * layers),
        }),
        remove: vec![Shape::Union(
            interior
                .iter()
                .map(|b| Shape::Box {
                    min_m: corner(b.0, 0),
                    max_m: corner(b.1, 0),
                })
                .collect(),
        )],
    };
    let scan_lo: [i64; D] = std::array::from_fn(|a| lo[a] - layers);
    let mut scan_hi: [i64; D] = std::array::from_fn(|a| hi[a] + layers);
    scan_hi[D - 1] = scan_hi[D - 1].min(top);
    fill_walls(
        particles,
        &solid,
        (scan_lo, scan_hi),
        spacing_m,
        wall_layers,
        dummy_layers,
    );
}
