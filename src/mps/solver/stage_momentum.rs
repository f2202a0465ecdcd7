//! What each stage of the step does to the fluid's momentum along one axis, band by band
//! along the last axis (the height): a diagnostic, off unless a caller sets
//! [`super::Solver::stage_momentum`]. In a steady layer the stages' forces balance in every
//! band, so their sums from the top down are the shear stresses each stage carries across a
//! level, and the sum over all bands of a stage whose forces are internal must vanish
//! (docs/validation.md, "A disordered layer on an incline": the carried pressure's force
//! does not). It reads velocities only; the state and its bits are untouched.
use super::super::particles::{ParticleKind, Particles, Vector};

/// The stages, in the order of the step.
pub const STAGE_NAMES: [&str; 7] = [
    "carried_pressure",
    "viscous_and_yield",
    "collisions",
    "projection",
    "pair_stabilisation_and_shifting",
    "second_collisions",
    "body_force",
];

/// Sums over the steps taken since it was set: per band, the particle-steps spent in it and
/// each stage's change of the component `axis` of the fluid's velocity (m/s, summed over
/// particles and steps). A particle's band is its height at the start of the step, over
/// `band_m`, clamped to the bands.
#[derive(Debug, Clone, PartialEq)]
pub struct StageMomentum {
    pub axis: usize,
    pub band_m: f64,
    pub particle_steps: Vec<f64>,
    pub change_m_s: Vec<[f64; STAGE_NAMES.len()]>,
    /// Simulated time and steps summed over.
    pub time_s: f64,
    pub steps: u64,
}

impl StageMomentum {
    pub fn new(axis: usize, band_m: f64, bands: usize) -> Self {
        Self {
            axis,
            band_m,
            particle_steps: vec![0.0; bands],
            change_m_s: vec![[0.0; STAGE_NAMES.len()]; bands],
            time_s: 0.0,
            steps: 0,
        }
    }
}

/// One step's bookkeeping: the sums it adds to, the bands and the velocity component before
/// the stage running.
pub(super) struct StepProbe<'a> {
    sums: &'a mut StageMomentum,
    bands: Vec<Option<usize>>,
    before: Vec<f64>,
}

impl<'a> StepProbe<'a> {
    pub(super) fn start<const D: usize>(sums: &'a mut StageMomentum, p: &Particles<D>) -> Self {
        let last = sums.particle_steps.len() - 1;
        let bands: Vec<Option<usize>> = (0..p.len())
            .map(|i| {
                (p.kind[i] == ParticleKind::Fluid).then(|| {
                    let b = (p.position_m[i][D - 1] / sums.band_m).floor();
                    b.clamp(0.0, last as f64) as usize
                })
            })
            .collect();
        for b in bands.iter().flatten() {
            sums.particle_steps[*b] += 1.0;
        }
        let before = p.velocity_m_s.iter().map(|v| v[sums.axis]).collect();
        Self {
            sums,
            bands,
            before,
        }
    }

    pub(super) fn axis(&self) -> usize {
        self.sums.axis
    }

    /// Adds `change(i)` to stage `stage` of i's band for every fluid particle.
    pub(super) fn add(&mut self, stage: usize, change: impl Fn(usize) -> f64) {
        for (i, band) in self.bands.iter().enumerate() {
            if let Some(b) = band {
                self.sums.change_m_s[*b][stage] += change(i);
            }
        }
    }

    /// Adds the change of the velocities since the last mark to `stage`, and marks them.
    pub(super) fn mark<const D: usize>(&mut self, stage: usize, velocity_m_s: &[Vector<D>]) {
        let axis = self.sums.axis;
        for (i, band) in self.bands.iter().enumerate() {
            if let Some(b) = band {
                self.sums.change_m_s[*b][stage] += velocity_m_s[i][axis] - self.before[i];
            }
        }
        self.reset(velocity_m_s);
    }

    pub(super) fn reset<const D: usize>(&mut self, velocity_m_s: &[Vector<D>]) {
        let axis = self.sums.axis;
        for (b, v) in self.before.iter_mut().zip(velocity_m_s) {
            *b = v[axis];
        }
    }
}
