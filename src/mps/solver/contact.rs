//! (7) and (10) Collisions of particles closer than the collision distance, and (9) the pair
//! stabilisation and particle shifting of the incremental scheme.

use super::{Solver, per_particle};
use crate::mps::grid::{Neighbours, entry_index};
use crate::mps::operators::{difference_sum, inward_sum, number_density};
use crate::mps::particles::{ParticleKind, Vector};
use crate::mps::reduce::PARTICLES_PER_TASK;
use crate::mps::reduce::map_particles;
use rayon::prelude::*;

impl<const D: usize> Solver<D> {
    /// Particle shifting (Fickian, Lind et al. 2012) with a diffusion coefficient that follows
    /// the local shear rate, D = A l0^2 sqrt(Pi_i) (as shear-induced self-diffusion does):
    /// dr_i = -A l0^2 sqrt(Pi_i) dt (d/n0) sum_j r_ij w(r_ij)/r_ij^2 over every neighbour
    /// within the number-density radius. The sum points towards i's closest neighbours and is
    /// zero on a lattice; sqrt(Pi) is zero at rest and in a rigid plug, and does not change
    /// under a uniform motion, so neither a fluid at rest nor a translating or unyielded block
    /// is shifted. Where the stencil is incomplete (n_i < n0: the free surface and the rows
    /// under it) only the part along the surface is kept (normal from the kernel-weighted
    /// directions to the neighbours within the Laplacian radius), so that the fluid keeps its
    /// volume. At most `particle_shifting_limit_m` per step. Velocity and carried pressure
    /// move with the particle unchanged (measured: carrying the pressure to the new position
    /// to first order, p + dr . grad(p), leaves a tank at rest as it was and lets the 12 mm
    /// slump creep on to +2.4 % of its closed form; docs/validation.md, "Particle shifting").
    pub(super) fn shift_particles(&mut self, dt_s: f64) {
        let c = &self.config;
        let l0 = c.spacing_m;
        let scale = -c.particle_shifting * l0 * l0 * dt_s * D as f64 / self.refs.n0;
        let limit_m = c.particle_shifting_limit_m;
        let surface_n = c.surface_threshold * self.refs.n0;
        let rheology = c.rheology;
        let p = &self.particles;
        let (near, lap) = (&self.pairs.near, &self.pairs.lap);
        let refs = self.refs;
        // Pi from this step's viscous stage.
        let strain = &self.strain_invariant;
        let shifts: Vec<Vector<D>> = map_particles(p.len(), |i| {
            let pi = strain.get(i).copied().unwrap_or(0.0);
            // Non-flowing (Pi <= Pi_c) material is not shifted: an unyielded plug keeps its
            // arrangement.
            if p.kind[i] != ParticleKind::Fluid || pi == 0.0 || !rheology.is_flowing(pi) {
                return Vector::<D>::zeros();
            }
            let shear_rate_1_s = pi.sqrt();
            let density = number_density(&p.position_m, near, i, refs.radius_n_m, |_| true);
            // At the free surface only neighbours closer than a spacing count: there the
            // kernel sum also reads the truncated stencil's rows below (measured: a tank at
            // rest then drifts its top row along the surface at 0.017 m/s).
            let at_surface = density < surface_n;
            let crowd = difference_sum(&p.position_m, near, i, refs.radius_n_m, |_, r| {
                (!at_surface || r.norm_squared() < l0 * l0).then_some(1.0)
            });
            let mut dr = crowd * (scale * shear_rate_1_s);
            if density < refs.n0 {
                let inward = inward_sum(&p.position_m, lap, i, refs.radius_lap_m, |_, _| true);
                let length = inward.norm();
                if length > 0.0 {
                    let n = inward / length;
                    dr -= n * n.dot(&dr);
                }
            }
            let length = dr.norm();
            if length > limit_m {
                dr *= limit_m / length;
            }
            dr
        });
        for (x, dr) in self.particles.position_m.iter_mut().zip(&shifts) {
            *x += *dr;
        }
    }

    /// Dynamic stabilisation (Tsuruta, Khayyer & Gotoh 2013, simplified): each fluid particle
    /// closer than `distance_m` to another gets the velocity that moves it back by its share
    /// of the shortfall within this step, along the pair's axis: half against fluid (equal and
    /// opposite, so momentum is kept), all against a wall or dummy. Idle when every pair is at
    /// least `distance_m` apart (a lattice at rest).
    pub(super) fn stabilise_pairs(&mut self, dt_s: f64, distance_m: f64) {
        let nb = &self.pairs.near;
        let dv = self.pair_velocity_changes(nb, |_, e, r| {
            let j = entry_index(e);
            let d = r.norm();
            if d >= distance_m || d == 0.0 {
                return None;
            }
            let share = if self.particles.kind[j] == ParticleKind::Fluid {
                0.5
            } else {
                1.0
            };
            Some(r * (share * (distance_m - d) / (d * dt_s)))
        });
        self.apply_velocity_changes(&dv, dt_s);
    }

    /// For every fluid particle i, minus the sum over its list entries e in `nb` (in list
    /// order) of `pair(i, e, r_ij)` where it is Some; zero elsewhere.
    pub(super) fn pair_velocity_changes(
        &self,
        nb: &Neighbours,
        pair: impl Fn(usize, u32, Vector<D>) -> Option<Vector<D>> + Sync,
    ) -> Vec<Vector<D>> {
        let p = &self.particles;
        (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                let mut dv = Vector::<D>::zeros();
                if p.kind[i] != ParticleKind::Fluid {
                    return dv;
                }
                for &e in nb.of(i) {
                    if let Some(v) = pair(i, e, nb.displacement(&p.position_m, i, e)) {
                        dv -= v;
                    }
                }
                dv
            })
            .collect()
    }

    /// u += dv, r += dt dv at every particle.
    pub(super) fn apply_velocity_changes(&mut self, dv: &[Vector<D>], dt_s: f64) {
        let p = &mut self.particles;
        per_particle(&mut p.velocity_m_s, &mut p.position_m, |i, v, x| {
            *v += dv[i];
            *x += dv[i] * dt_s;
        });
    }

    /// Collision model: fluid pairs closer than the collision distance that approach each
    /// other exchange momentum along their line of centres with restitution e (equal masses;
    /// walls are immovable). Jacobi-style: all impulses from the pre-collision velocities.
    /// `walls_only`: fluid-wall pairs only.
    pub(super) fn collide(&mut self, dt_s: f64, walls_only: bool) {
        let c = &self.config;
        if c.collision_distance_m <= 0.0 {
            return;
        }
        let p = &self.particles;
        let nb = self.collision_candidates();
        let d2 = c.collision_distance_m * c.collision_distance_m;
        let d2_wall = c.wall_collision_distance_m * c.wall_collision_distance_m;
        let e = c.collision_restitution;
        let dv = self.pair_velocity_changes(nb, |i, entry, r| {
            let j = entry_index(entry);
            if p.kind[j] == ParticleKind::Dummy {
                return None;
            }
            let r2 = r.norm_squared();
            let fluid_pair = p.kind[j] == ParticleKind::Fluid;
            if fluid_pair && walls_only {
                return None;
            }
            if r2 >= (if fluid_pair { d2 } else { d2_wall }) || r2 == 0.0 {
                return None;
            }
            let n = r / r2.sqrt();
            let approach = (p.velocity_m_s[i] - nb.reflect(entry, p.velocity_m_s[j])).dot(&n);
            // Only approaching pairs collide; the fluid particle of a fluid-wall pair takes it all.
            (approach > 0.0).then(|| {
                let share = if fluid_pair { 0.5 } else { 1.0 };
                n * ((1.0 + e) * share * approach)
            })
        });
        self.apply_velocity_changes(&dv, dt_s);
    }
}
