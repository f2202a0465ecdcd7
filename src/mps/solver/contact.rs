//! (7) and (10) Collisions of particles closer than the collision distance, and (9) the pair
//! stabilisation of the incremental scheme.

use super::{Solver, per_particle};
use crate::mps::grid::Neighbours;
use crate::mps::particles::{ParticleKind, Vector};
use crate::mps::reduce::PARTICLES_PER_TASK;
use rayon::prelude::*;

impl<const D: usize> Solver<D> {
    /// Dynamic stabilisation (Tsuruta, Khayyer & Gotoh 2013, simplified): each fluid particle
    /// closer than `distance_m` to another gets the velocity that moves it back by its share
    /// of the shortfall within this step, along the pair's axis: half against fluid (equal and
    /// opposite, so momentum is kept), all against a wall or dummy. Idle when every pair is at
    /// least `distance_m` apart (a lattice at rest).
    pub(super) fn stabilise_pairs(&mut self, dt_s: f64, distance_m: f64) {
        let nb = &self.pairs.near;
        let dv = self.pair_velocity_changes(nb, |_, j, r| {
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

    /// For every fluid particle i, minus the sum over its neighbours j in `nb` (in list order)
    /// of `pair(i, j, r_ij)` where it is Some; zero elsewhere.
    pub(super) fn pair_velocity_changes(
        &self,
        nb: &Neighbours,
        pair: impl Fn(usize, usize, Vector<D>) -> Option<Vector<D>> + Sync,
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
                for &j in nb.of(i) {
                    let j = j as usize;
                    if let Some(v) = pair(i, j, nb.displacement(&p.position_m, i, j)) {
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
        let dv = self.pair_velocity_changes(nb, |i, j, r| {
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
            let approach = (p.velocity_m_s[i] - p.velocity_m_s[j]).dot(&n);
            // Only approaching pairs collide; the fluid particle of a fluid-wall pair takes it all.
            (approach > 0.0).then(|| {
                let share = if fluid_pair { 0.5 } else { 1.0 };
                n * ((1.0 + e) * share * approach)
            })
        });
        self.apply_velocity_changes(&dv, dt_s);
    }
}
