//! (3), (7) The neighbour lists and the kernel-radius pairs every stage reads, and the periodic
//! seam.

use super::{LIST_SKIN, Solver};
use crate::mps::grid::{KernelPairs, MirrorPlanes, Neighbours};
use crate::mps::particles::ParticleKind;
use crate::mps::reduce::max_by;
use std::time::Instant;

impl<const D: usize> Solver<D> {
    /// Neighbour lists of the active particles at the current positions.
    /// Makes sure the lists hold every active pair closer than the Laplacian radius: rebuilt
    /// when some particle has moved more than half the skin since the last build.
    pub(super) fn rebuild_neighbours(&mut self) {
        let started = Instant::now();
        self.wrap_periodic();
        self.reflect_at_symmetry_planes();
        self.refresh_lists();
        self.timing.neighbours_s += started.elapsed().as_secs_f64();
    }

    /// The kernel-radius pairs at the current positions (after every move of the particles
    /// that later stages see). A wall particle with no fluid particle within the Laplacian
    /// radius gets none: its number density is then 0, so it is a free-surface particle with
    /// p = 0 and no PPE row. Only a wall that is near fluid carries pressure (away from the
    /// fluid a wall's pressure has no meaning; in wall corners it would be a spurious
    /// pressure from the walls' own number density).
    pub(super) fn refresh_pairs(&mut self) {
        let started = Instant::now();
        let r = &self.refs;
        let kind = &self.particles.kind;
        self.pairs = KernelPairs::near_fluid(
            &self.neighbours,
            &self.particles.position_m,
            r.radius_n_m,
            r.radius_lap_m,
            |i| kind[i] == ParticleKind::Fluid,
        );
        self.paired_at_m.clone_from(&self.particles.position_m);
        self.timing.kernel_pairs_s += started.elapsed().as_secs_f64();
    }

    /// Brings every particle that crossed the periodic seam back into the period (the lists
    /// then see it as moved by a period and are rebuilt).
    pub(super) fn wrap_periodic(&mut self) {
        let Some(periodic) = self.config.periodic_x else {
            return;
        };
        for x in &mut self.particles.position_m {
            let offset = x[0] - periodic.min_m;
            if !(0.0..periodic.period_m).contains(&offset) {
                x[0] = periodic.min_m + offset.rem_euclid(periodic.period_m);
                // rem_euclid may round up to the period itself.
                if x[0] >= periodic.min_m + periodic.period_m {
                    x[0] = periodic.min_m;
                }
            }
        }
    }

    /// A fluid particle that crossed a symmetry plane is reflected back, its normal velocity
    /// reversed: its mirror image crossed the other way (specular reflection, free slip).
    pub(super) fn reflect_at_symmetry_planes(&mut self) {
        let planes = self.config.symmetry;
        if planes.is_empty() {
            return;
        }
        let p = &mut self.particles;
        for i in 0..p.len() {
            if p.kind[i] != ParticleKind::Fluid {
                continue;
            }
            for a in MirrorPlanes::axes_of::<D>(planes.axes) {
                let plane = planes.position_m[a];
                if p.position_m[i][a] < plane {
                    p.position_m[i][a] = 2.0 * plane - p.position_m[i][a];
                    p.velocity_m_s[i][a] = -p.velocity_m_s[i][a];
                }
            }
        }
    }

    pub(super) fn refresh_lists(&mut self) {
        let skin = LIST_SKIN * self.config.spacing_m;
        let p = &self.particles;
        let valid = self.listed_at_m.len() == p.len()
            && max_by(p.len(), |i| {
                if p.kind[i].is_active() {
                    (p.position_m[i] - self.listed_at_m[i]).norm()
                } else {
                    0.0
                }
            }) < 0.5 * skin;
        if valid && !self.fresh_lists {
            return;
        }
        let kind = &p.kind;
        // Operators are evaluated at fluid particles and at wall particles with fluid within
        // reach (see `refresh_pairs`): only they get lists. Dummy layers and walls away from
        // the fluid only fill the support of others.
        let cutoff_m = self.config.radius_lap_m + skin;
        let active = |i: usize| kind[i].is_active();
        self.neighbours = Neighbours::build_centres_then_listed(
            &p.position_m,
            cutoff_m,
            self.config.periodic_x.map(|x| x.period_m),
            self.config.symmetry,
            active,
            |i| kind[i] == ParticleKind::Fluid,
            |i| kind[i] == ParticleKind::Wall,
        );
        self.listed_at_m = p.position_m.clone();
        self.timing.list_builds += 1;
    }

    /// Lists holding every pair closer than the collision distances: the number-density pairs
    /// of the last cut when no particle has moved far enough since to close a pair from
    /// beyond their radius (a pair closer than d now was closer than d + 2 max|moved| then),
    /// else the Verlet lists. Both are in ascending index order, and collisions skip pairs
    /// beyond d, so either gives the same bits; the pairs are about a fifth as many in 3D.
    pub(super) fn collision_candidates(&self) -> &Neighbours {
        let c = &self.config;
        let p = &self.particles;
        let reach = c.collision_distance_m.max(c.wall_collision_distance_m);
        if self.paired_at_m.len() != p.len() || self.fresh_lists {
            return &self.neighbours;
        }
        let moved = max_by(p.len(), |i| {
            if p.kind[i].is_active() {
                (p.position_m[i] - self.paired_at_m[i]).norm()
            } else {
                0.0
            }
        });
        // A relative margin for the rounding of the distances.
        if reach + 2.0 * moved < self.refs.radius_n_m * (1.0 - 1e-9) {
            &self.pairs.near
        } else {
            &self.neighbours
        }
    }
}
