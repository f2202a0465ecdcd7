//! (1) Inlets that pour fluid in before a step, and (11) the check of the state after it.

use super::{Solver, StepError};
use crate::mps::particles::{ParticleKind, Vector};
use crate::mps::reduce::PARTICLES_PER_TASK;
use rayon::prelude::*;

impl<const D: usize> Solver<D> {
    /// Inlets, in order: the next layer of each unfinished inlet whose due time has come is
    /// appended at the end of the particle arrays, unless a fluid particle lies within the
    /// inlet's clearance of one of its positions (then the inlet waits). At most one layer per inlet per
    /// step: a second due layer would sit on the first one, which blocks it.
    pub(super) fn pour(&mut self) {
        let l0 = self.config.spacing_m;
        for k in 0..self.config.inlets.len() {
            let inlet = &self.config.inlets[k];
            let section = &self.inlet_sections[k];
            let total = inlet.total_count(l0);
            let emitted = self.inlet_emitted[k];
            if emitted >= total || section.is_empty() {
                continue;
            }
            let layer = emitted / section.len() as u64;
            if self.time_s < inlet.layer_due_s(layer, l0) {
                continue;
            }
            let count = section.len().min((total - emitted) as usize);
            let points = &section[..count];
            // Only fluid near the opening can block it: skip the rest with one distance.
            let clearance2 = inlet.clearance_m * inlet.clearance_m;
            let reach = inlet.radius_m + inlet.clearance_m;
            let p = &self.particles;
            let planes = self.config.symmetry;
            // Fluid blocks the opening, and so do its mirror images.
            let near = |y: Vector<D>| {
                (y - inlet.centre_m).norm_squared() <= reach * reach
                    && points.iter().any(|x| (y - x).norm_squared() < clearance2)
            };
            let blocked = (0..p.len()).any(|i| {
                p.kind[i] == ParticleKind::Fluid
                    && (near(p.position_m[i])
                        || planes
                            .combinations()
                            .any(|bits| near(planes.reflect_point::<D>(bits, p.position_m[i]))))
            });
            if blocked {
                continue;
            }
            let velocity = inlet.unit_direction() * inlet.speed_m_s;
            let p = &mut self.particles;
            for x in points {
                p.push_tagged(*x, ParticleKind::Fluid, inlet.tag);
                *p.velocity_m_s.last_mut().expect("just pushed") = velocity;
            }
            self.inlet_emitted[k] += count as u64;
        }
    }

    /// Why fluid particle i stops the run, if it does: a position or velocity that is not
    /// finite, or a speed above `stop.max_speed_m_s`.
    fn blown_up(&self, i: usize) -> Option<StepError> {
        let p = &self.particles;
        let (x, v) = (p.position_m[i], p.velocity_m_s[i]);
        if p.kind[i] != ParticleKind::Fluid {
            return None;
        }
        if !x.iter().chain(v.iter()).all(|a| a.is_finite()) {
            return Some(StepError::NonFinite {
                particle: i,
                step: self.step,
            });
        }
        let speed = v.norm();
        (speed > self.config.max_speed_m_s).then_some(StepError::TooFast {
            particle: i,
            speed_m_s: speed,
            limit_m_s: self.config.max_speed_m_s,
            step: self.step,
        })
    }

    /// The blow-up guards at the predicted state, before the neighbour search sorts its
    /// positions into cells: the cell count of a prediction blown up to 1e93 m overflows
    /// (a 3D run under `mps.conservative_gradient` panicked so).
    pub(super) fn check_prediction(&self) -> Result<(), StepError> {
        let first = (0..self.particles.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .find_map_first(|i| self.blown_up(i));
        match first {
            Some(error) => Err(error),
            None => Ok(()),
        }
    }

    /// Blow-up guards after a step (finite state, speed limit); fluid that left the domain
    /// box becomes a ghost, at rest where it left.
    pub(super) fn check_state(&mut self) -> Result<(), StepError> {
        let c = &self.config;
        // Only fluid particles that fail a guard or left the box need a look, in index order
        // (found in parallel: most steps there are none).
        let p = &self.particles;
        let flagged: Vec<usize> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .filter(|&i| {
                let x = p.position_m[i];
                self.blown_up(i).is_some()
                    || (p.kind[i] == ParticleKind::Fluid
                        && (0..D).any(|a| x[a] < c.domain_min_m[a] || x[a] > c.domain_max_m[a]))
            })
            .collect();
        for i in flagged {
            if let Some(error) = self.blown_up(i) {
                return Err(error);
            }
            let p = &mut self.particles;
            let x = p.position_m[i];
            if (0..D).any(|a| x[a] < c.domain_min_m[a] || x[a] > c.domain_max_m[a]) {
                p.kind[i] = ParticleKind::Ghost;
                self.listed_at_m.clear();
                p.velocity_m_s[i] = Vector::<D>::zeros();
                p.pressure_pa[i] = 0.0;
                if let Some(limit) = c.max_ghost_particles {
                    let ghosts = p.count(ParticleKind::Ghost);
                    if ghosts > limit {
                        let coords: Vec<String> = x.iter().map(|a| format!("{a:.4}")).collect();
                        return Err(StepError::LeftDomain {
                            particle: i,
                            position_m: format!("({}) m", coords.join(", ")),
                            ghosts,
                            limit,
                            step: self.step,
                        });
                    }
                }
            }
        }
        Ok(())
    }
}
