//! (3), (7) The neighbour lists and the kernel-radius pairs every stage reads, and the periodic
//! seam.

use super::{LIST_SKIN, Solver};
use crate::mps::grid::{KernelPairs, MirrorPlanes, Neighbours};
use crate::mps::particles::ParticleKind;
use crate::mps::particles::Vector;
use crate::mps::reduce::PARTICLES_PER_TASK;
use crate::mps::reduce::max_by;
use rayon::prelude::*;
use std::time::Instant;

/// A particle whose reference is renewed moved at least this share of the skin: renewing
/// more than the half skin that forces it puts off the next update (only speed depends on it).
const REFERENCE_REFRESH: f64 = 0.25;

/// The lists are built whole when more than one particle in this many moved (a partial
/// update then costs about as much as a build; only speed depends on it).
const MOVED_SHARE_FOR_WHOLE_BUILD: usize = 4;

/// With mirror planes, when more than one in this many of the particles that hold lists
/// moved: an update there also searches the moved particles' images, and a lifting cone's
/// walls (moved, most of them near the planes and holding no list) then cost more as an
/// update than a build, which searches only the holders (measured; only speed depends on it).
const HOLDERS_SHARE_FOR_WHOLE_BUILD: usize = 2;

impl<const D: usize> Solver<D> {
    /// Neighbour lists of the active particles at the current positions.
    /// Makes sure the lists hold every active pair closer than the Laplacian radius: renewed
    /// when some particle has moved half the skin from its reference position (`refresh_lists`).
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
        let earlier = std::mem::take(&mut self.pairs);
        self.pairs = KernelPairs::near_fluid(
            &self.neighbours,
            &self.particles.position_m,
            r.radius_n_m,
            r.radius_lap_m,
            |i| kind[i] == ParticleKind::Fluid,
            earlier,
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

    /// Keeps every active pair closer than the Laplacian radius in the lists (Verlet lists with
    /// a skin, each particle listed at its own reference position `listed_at_m`). When some
    /// particle has moved half the skin from its reference, or particles were poured, the
    /// particles that moved a share of the skin (and the poured ones) get new references and
    /// only their entries change ([`Neighbours::updated`], mirror images included); the lists
    /// are built whole when many moved, at the start, after a particle left the domain, and
    /// under wall faces.
    /// Lists are ascending, and every stage cuts them to its radius at the current positions,
    /// so either way gives the same pairs in the same order: the same bits.
    pub(super) fn refresh_lists(&mut self) {
        let skin = LIST_SKIN * self.config.spacing_m;
        let p = &self.particles;
        let (n, listed) = (p.len(), self.listed_at_m.len());
        let moved_by = |i: usize| {
            if i < listed && p.kind[i].is_active() {
                (p.position_m[i] - self.listed_at_m[i]).norm()
            } else {
                0.0
            }
        };
        let valid = listed == n && max_by(n, moved_by) < 0.5 * skin;
        if valid && !self.fresh_lists {
            return;
        }
        let kind = &p.kind;
        let active = |i: usize| kind[i].is_active();
        let centre = |i: usize| kind[i] == ParticleKind::Fluid;
        let then = |i: usize| kind[i] == ParticleKind::Wall;
        // The wall faces read which walls have fluid in their lists (`WallFaces::build`), which
        // depends on when the lists were made: with them the lists are built whole, as always.
        let faces_read_lists = self.config.wall_surface_no_slip && self.config.wall_face_normals;
        if listed > 0
            && listed <= n
            && (listed..n).all(active)
            && !self.fresh_lists
            && !faces_read_lists
        {
            let moved: Vec<u32> = (0..n)
                .into_par_iter()
                .with_min_len(PARTICLES_PER_TASK)
                .filter(|&i| i >= listed || moved_by(i) >= REFERENCE_REFRESH * skin)
                .map(|i| i as u32)
                .collect();
            let few = if self.config.symmetry.is_empty() {
                moved.len() <= n / MOVED_SHARE_FOR_WHOLE_BUILD
            } else {
                let holders = (0..listed)
                    .into_par_iter()
                    .with_min_len(PARTICLES_PER_TASK)
                    .filter(|&i| !self.neighbours.of(i).is_empty())
                    .count();
                moved.len() <= holders / HOLDERS_SHARE_FOR_WHOLE_BUILD
            };
            if few {
                self.listed_at_m.resize(n, Vector::<D>::zeros());
                for &i in &moved {
                    self.listed_at_m[i as usize] = p.position_m[i as usize];
                }
                self.neighbours =
                    self.neighbours
                        .updated(&self.listed_at_m, &moved, active, centre, then);
                self.timing.list_updates += 1;
                return;
            }
        }
        // Operators are evaluated at fluid particles and at wall particles with fluid within
        // reach (see `refresh_pairs`): only they get lists. Dummy layers and walls away from
        // the fluid only fill the support of others.
        let cutoff_m = self.config.radius_lap_m + skin;
        self.neighbours = Neighbours::build_centres_then_listed(
            &p.position_m,
            cutoff_m,
            self.config.periodic_x.map(|x| x.period_m),
            self.config.symmetry,
            active,
            centre,
            then,
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
