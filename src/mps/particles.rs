//! Particle data as parallel arrays (struct of arrays).
use nalgebra::SVector;

pub type Vector<const D: usize> = SVector<f64, D>;

/// Volume of one lattice cell, l0^D (m^3 in 3D, m^2 per metre of depth in 2D), as a
/// product: the same bits as `powi`, without a function whose result may vary by platform.
pub fn cell_volume(spacing_m: f64, dimension: usize) -> f64 {
    (0..dimension).fold(1.0, |v, _| v * spacing_m)
}

/// What a particle is. The discriminants are part of the recorded state (`kind` field).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ParticleKind {
    /// Moves with the flow.
    Fluid = 0,
    /// Wall layer next to the fluid: takes part in the pressure Poisson equation.
    Wall = 1,
    /// Dummy layers behind the wall: count in the number density only.
    Dummy = 2,
    /// Fluid that left the domain (splashed out of the tank): frozen where it left and
    /// excluded from every interaction, as in common MPS codes.
    Ghost = 3,
}

impl ParticleKind {
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Fluid),
            1 => Some(Self::Wall),
            2 => Some(Self::Dummy),
            3 => Some(Self::Ghost),
            _ => None,
        }
    }
    /// Has a pressure of its own (fluid and wall particles).
    #[inline]
    pub fn has_pressure(self) -> bool {
        matches!(self, Self::Fluid | Self::Wall)
    }
    /// Takes part in the simulation at all (everything but ghosts).
    #[inline]
    pub fn is_active(self) -> bool {
        !matches!(self, Self::Ghost)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Particles<const D: usize> {
    pub position_m: Vec<Vector<D>>,
    pub velocity_m_s: Vec<Vector<D>>,
    pub pressure_pa: Vec<f64>,
    pub kind: Vec<ParticleKind>,
    /// A small integer per particle for the user's bookkeeping (layer, material, origin):
    /// recorded and shown, never read by the method itself. Ghosts keep theirs.
    pub tag: Vec<u16>,
}

impl<const D: usize> Default for Particles<D> {
    fn default() -> Self {
        Self {
            position_m: Vec::new(),
            velocity_m_s: Vec::new(),
            pressure_pa: Vec::new(),
            kind: Vec::new(),
            tag: Vec::new(),
        }
    }
}

impl<const D: usize> Particles<D> {
    pub fn len(&self) -> usize {
        self.position_m.len()
    }
    pub fn is_empty(&self) -> bool {
        self.position_m.is_empty()
    }
    /// Appends a particle at rest with pressure 0 and tag 0.
    pub fn push(&mut self, position_m: Vector<D>, kind: ParticleKind) {
        self.push_tagged(position_m, kind, 0);
    }
    /// Appends a particle at rest with pressure 0 and the given tag.
    pub fn push_tagged(&mut self, position_m: Vector<D>, kind: ParticleKind, tag: u16) {
        self.position_m.push(position_m);
        self.velocity_m_s.push(Vector::<D>::zeros());
        self.pressure_pa.push(0.0);
        self.kind.push(kind);
        self.tag.push(tag);
    }
    /// Keeps the particles whose position satisfies `keep`, in their order.
    pub fn retain(&mut self, keep: impl Fn(&Vector<D>) -> bool) {
        let kept: Vec<bool> = self.position_m.iter().map(keep).collect();
        fn cut<T>(values: &mut Vec<T>, kept: &[bool]) {
            let mut k = kept.iter();
            values.retain(|_| *k.next().expect("one flag a particle"));
        }
        cut(&mut self.position_m, &kept);
        cut(&mut self.velocity_m_s, &kept);
        cut(&mut self.pressure_pa, &kept);
        cut(&mut self.kind, &kept);
        cut(&mut self.tag, &kept);
    }
    pub fn count(&self, kind: ParticleKind) -> usize {
        self.kind.iter().filter(|k| **k == kind).count()
    }
    pub fn fluid_count(&self) -> usize {
        self.count(ParticleKind::Fluid)
    }
}
