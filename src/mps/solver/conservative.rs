//! A carried-pressure gradient that conserves momentum among fluid particles
//! (`conservative_gradient`, incremental scheme).
//!
//! The corrected gradient in difference form, G_i = sum_j b_ij (p_j - p_i) with
//! b_ij = M_i^-1 r_ij w_ij / r_ij^2 (Khayyer & Gotoh 2011), is exact for a linear pressure on
//! any arrangement, but off the lattice b_ij != -b_ji: the fluid's pressure forces on one
//! another do not cancel, and a disordered layer on an incline is pushed along the slope by
//! -11 % to +12 % of its driving force (docs/validation.md, "A disordered layer on an
//! incline"). Written as G_i = sum_c a_ic p_c over columns c (a_ii the row's own -sum_j b_ij),
//! the total force of the fluid on itself is -sum_c p_c s_c with s_c = sum_i a_ic, the column
//! sums. Here the coefficients of fluid neighbours are changed by the least amount (weighted
//! by r^2 / w) after which every row stays first-order exact and the column sums vanish
//! where the continuum has no boundary force (the construction of the yield solve's
//! consistent divergence, [`make_divergence_consistent`]): at every particle whose
//! neighbours are all fluid and which is not on the free surface, entirely; at a particle
//! beside a wall or on the surface, across the boundary's normal only, so that the
//! boundary pushes along its normal (the normal of the plane through the neighbouring wall
//! particles, or through the neighbouring surface particles). Particles beside a mirror
//! plane, or both on the surface and beside a wall, keep their sums. What is left is the
//! walls' own pressures (p_i + rho g . r_ij) and the pressure regularisation, neither of
//! them pairwise (docs/validation.md, "A disordered layer on an incline").
use super::{ParticleKind, Solver};
use crate::mps::grid::{Neighbours, entry_index};
use crate::mps::operators::{weighted_neighbours, well_conditioned_inverse};
use crate::mps::particles::Vector;
use crate::mps::reduce::map_particles;
use crate::mps::yield_solve::{ColumnSum, Row, Tensor, make_divergence_consistent};
use nalgebra::SMatrix;

/// Per particle, the fluid part of its carried gradient: entries (a fluid neighbour's list
/// entry, coefficient a_ic), its own last (empty for non-fluid particles).
pub(super) type GradientRows<const D: usize> = Vec<Vec<(u32, Vector<D>)>>;

impl<const D: usize> Solver<D> {
    /// The conservative fluid rows of the carried gradient at the current positions, with
    /// `corrections` each fluid particle's M_i^-1 and `number_density` its number density
    /// (the free surface's rule: below `surface_threshold` n0).
    pub(super) fn conservative_gradient_rows(
        &self,
        corrections: &[SMatrix<f64, D, D>],
        number_density: &[f64],
    ) -> GradientRows<D> {
        let p = &self.particles;
        let nb = &self.pairs.near;
        let radius = self.refs.radius_n_m;
        let threshold = self.config.surface_threshold * self.refs.n0;
        let mut per_row: Vec<Row<D>> = map_particles(p.len(), |i| {
            if p.kind[i] != ParticleKind::Fluid {
                return (
                    Vec::new(),
                    Tensor::<D>::zeros(),
                    Some((Vec::new(), ColumnSum::Free)),
                );
            }
            let mut entries = Vec::new();
            let mut pairs = Vec::new();
            let mut own = Vector::<D>::zeros();
            let mut through_plane = false;
            // Kernel-weighted sums of the displacements to all neighbours and to walls.
            let (mut to_all, mut to_walls) = (Vector::<D>::zeros(), Vector::<D>::zeros());
            let mut wall_layer = Vec::new();
            let mut surface_layer = vec![Vector::<D>::zeros()];
            for (e, r, r2, w) in weighted_neighbours(&p.position_m, nb, i, radius) {
                through_plane |= Neighbours::plane_bits(e) != 0;
                to_all += r * w;
                if p.kind[entry_index(e)] != ParticleKind::Fluid {
                    to_walls += r * w;
                    if p.kind[entry_index(e)] == ParticleKind::Wall {
                        wall_layer.push(r);
                    }
                    continue;
                }
                if number_density[entry_index(e)] < threshold {
                    surface_layer.push(r);
                }
                let b = corrections[i] * r * (w / r2);
                entries.push((e, b));
                pairs.push((r, w / r2));
                own -= b;
            }
            entries.push((i as u32, own));
            let surface = number_density[i] < threshold;
            let wall = to_walls != Vector::<D>::zeros();
            // The boundary's normal: toward the walls, or away from the fluid at the surface.
            let tangential = |n: Vector<D>| match n.try_normalize(0.0) {
                Some(n) => ColumnSum::Tangential(n),
                None => ColumnSum::Free,
            };
            let sum = match (through_plane, surface, wall) {
                (false, false, false) => ColumnSum::Zero,
                (false, true, false) => tangential(plane_normal(&surface_layer, to_all)),
                (false, false, true) => tangential(plane_normal(&wall_layer, to_walls)),
                _ => ColumnSum::Free,
            };
            (entries, Tensor::<D>::zeros(), Some((pairs, sum)))
        });
        // Not reaching the CG's tolerance leaves valid rows (each still first-order exact)
        // with part of the column sums.
        make_divergence_consistent(&mut per_row, self.refs.n0);
        per_row.into_iter().map(|row| row.0).collect()
    }
}

/// sum_c a_ic p_c over a row of [`GradientRows`].
pub(super) fn row_gradient<const D: usize>(
    row: &[(u32, Vector<D>)],
    pressure_pa: &[f64],
) -> Vector<D> {
    row.iter().fold(Vector::<D>::zeros(), |g, (c, a)| {
        g + a * pressure_pa[entry_index(*c)]
    })
}

/// The normal of the plane through `points` (the direction of least spread: inverse
/// iteration on their covariance from `guess`), exact for a flat layer of wall particles
/// wherever i stands; `guess` itself when the points do not span a plane.
fn plane_normal<const D: usize>(points: &[Vector<D>], guess: Vector<D>) -> Vector<D> {
    if points.len() < D {
        return guess;
    }
    let mean = points.iter().fold(Vector::<D>::zeros(), |m, x| m + x) / points.len() as f64;
    let spread = points.iter().fold(SMatrix::<f64, D, D>::zeros(), |c, x| {
        c + (x - mean) * (x - mean).transpose()
    });
    let shift = 1e-9 * spread.trace();
    let shifted = spread + SMatrix::<f64, D, D>::identity() * shift;
    match well_conditioned_inverse(&shifted, D as f64, 0.0) {
        Some(inverse) if shift > 0.0 => {
            (0..4).fold(guess, |v, _| (inverse * v).try_normalize(0.0).unwrap_or(v))
        }
        _ => guess,
    }
}
