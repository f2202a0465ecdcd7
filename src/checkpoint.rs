//! Full-precision state checkpoints: canonical bytes, their SHA-256, and the conversion to and
//! from the recorded `mps.v1.StateCheckpoint` message.
use crate::mps::{ParticleKind, Particles, Solver, Vector};
use crate::proto::mps::v1::{CheckpointHash, StateCheckpoint};
use sha2::{Digest, Sha256};

/// Bits of a value with -0.0 folded onto +0.0 (equal values must hash equally).
#[inline]
pub fn canonical_bits(x: f64) -> u64 {
    if x == 0.0 { 0 } else { x.to_bits() }
}

/// SHA-256 of the canonical state bytes, in this order, all little-endian: the tag
/// `mps.v1.state`, step (u64), time_s and dt_s (f64 bits), dimension (u32), particle count
/// (u64), then every position component, every velocity component, every pressure (f64 bits,
/// -0.0 as +0.0, particle-major), and every kind (u32).
pub fn state_sha256(msg: &StateCheckpoint) -> String {
    let mut h = Sha256::new();
    h.update(b"mps.v1.state");
    h.update(msg.step.to_le_bytes());
    h.update(canonical_bits(msg.time_s).to_le_bytes());
    h.update(canonical_bits(msg.dt_s).to_le_bytes());
    h.update(msg.dimension.to_le_bytes());
    h.update((msg.kind.len() as u64).to_le_bytes());
    for v in msg
        .position_m
        .iter()
        .chain(&msg.velocity_m_s)
        .chain(&msg.pressure_pa)
    {
        h.update(canonical_bits(*v).to_le_bytes());
    }
    for k in &msg.kind {
        h.update(k.to_le_bytes());
    }
    hex::encode(h.finalize())
}

/// Checkpoint message of the solver's current state, hash filled in. `dt_s` is the step the
/// run would take next.
pub fn to_message<const D: usize>(index: u32, solver: &Solver<D>, dt_s: f64) -> StateCheckpoint {
    let p = &solver.particles;
    let flat = |v: &[Vector<D>]| {
        v.iter()
            .flat_map(|x| x.iter().copied())
            .collect::<Vec<f64>>()
    };
    let mut msg = StateCheckpoint {
        index,
        step: solver.step,
        time_s: solver.time_s,
        dt_s,
        dimension: D as u32,
        position_m: flat(&p.position_m),
        velocity_m_s: flat(&p.velocity_m_s),
        pressure_pa: p.pressure_pa.clone(),
        kind: p.kind.iter().map(|k| *k as u32).collect(),
        state_sha256: String::new(),
        extra_scalars: Vec::new(),
    };
    msg.state_sha256 = state_sha256(&msg);
    msg
}

/// Particles of a checkpoint message (for resume and replay).
pub fn particles_from_message<const D: usize>(
    msg: &StateCheckpoint,
) -> Result<Particles<D>, String> {
    let n = msg.kind.len();
    if msg.dimension as usize != D
        || msg.position_m.len() != n * D
        || msg.velocity_m_s.len() != n * D
        || msg.pressure_pa.len() != n
    {
        return Err(format!(
            "checkpoint {} has inconsistent array lengths for dimension {}",
            msg.index, msg.dimension
        ));
    }
    let vecs = |v: &[f64]| {
        v.chunks_exact(D)
            .map(Vector::<D>::from_column_slice)
            .collect::<Vec<_>>()
    };
    let kind = msg
        .kind
        .iter()
        .map(|&k| {
            ParticleKind::from_u32(k)
                .ok_or_else(|| format!("checkpoint {}: unknown particle kind {k}", msg.index))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Particles {
        position_m: vecs(&msg.position_m),
        velocity_m_s: vecs(&msg.velocity_m_s),
        pressure_pa: msg.pressure_pa.clone(),
        kind,
    })
}

/// The summary's entry for a checkpoint.
pub fn hash_entry(msg: &StateCheckpoint) -> CheckpointHash {
    CheckpointHash {
        index: msg.index,
        step: msg.step,
        time_s: msg.time_s,
        state_sha256: msg.state_sha256.clone(),
    }
}
