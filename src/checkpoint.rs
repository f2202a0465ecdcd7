//! Full-precision state checkpoints: canonical bytes, their SHA-256, and the conversion to and
//! from the recorded `mps.v1.StateCheckpoint` message.
use crate::mps::{ParticleKind, Particles, Solver, SolverConfig, Vector};
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
/// -0.0 as +0.0, particle-major), and every kind (u32). Then, only when the message's `tag`
/// array is non-empty: the marker `tag` and every tag (u32); and only when `extra_scalars`
/// is non-empty: the marker `extra_scalars`, their count (u64) and every value (f64 bits,
/// -0.0 as +0.0); and only when `yield_stress_pa` is non-empty: the marker `yield_stress_pa`,
/// its count (u64) and every value (f64 bits, -0.0 as +0.0); and only when
/// `yield_penalty_pa_s` is non-zero: the marker `yield_penalty_pa_s` and its f64 bits. These
/// were added after the first files were written: a state without them hashes as it always
/// did.
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
    if !msg.tag.is_empty() {
        h.update(b"tag");
        for t in &msg.tag {
            h.update(t.to_le_bytes());
        }
    }
    if !msg.extra_scalars.is_empty() {
        h.update(b"extra_scalars");
        h.update((msg.extra_scalars.len() as u64).to_le_bytes());
        for v in &msg.extra_scalars {
            h.update(canonical_bits(*v).to_le_bytes());
        }
    }
    if !msg.yield_stress_pa.is_empty() {
        h.update(b"yield_stress_pa");
        h.update((msg.yield_stress_pa.len() as u64).to_le_bytes());
        for v in &msg.yield_stress_pa {
            h.update(canonical_bits(*v).to_le_bytes());
        }
    }
    if msg.yield_penalty_pa_s != 0.0 {
        h.update(b"yield_penalty_pa_s");
        h.update(canonical_bits(msg.yield_penalty_pa_s).to_le_bytes());
    }
    hex::encode(h.finalize())
}

/// Checkpoint message of the solver's current state, hash filled in. `dt_s` is the step the
/// run would take next. Tags are written only when some tag is non-zero (else the array is
/// left empty); `extra_scalars` holds the particles poured by each inlet (exact as f64),
/// empty without inlets.
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
        extra_scalars: solver.inlet_emitted.iter().map(|&n| n as f64).collect(),
        tag: if p.tag.iter().any(|&t| t != 0) {
            p.tag.iter().map(|&t| u32::from(t)).collect()
        } else {
            Vec::new()
        },
        // Row-major per particle (nalgebra stores columns first).
        yield_stress_pa: solver
            .yield_stress_pa
            .iter()
            .flat_map(|s| s.transpose().iter().copied().collect::<Vec<f64>>())
            .collect(),
        yield_penalty_pa_s: solver.yield_penalty_pa_s,
    };
    msg.state_sha256 = state_sha256(&msg);
    msg
}

/// Particles of a checkpoint message (for resume and replay). An empty `tag` array means
/// every tag is 0.
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
    let tag = if msg.tag.is_empty() {
        vec![0; n]
    } else if msg.tag.len() != n {
        return Err(format!(
            "checkpoint {}: {} tags for {n} particles",
            msg.index,
            msg.tag.len()
        ));
    } else {
        msg.tag
            .iter()
            .map(|&t| {
                u16::try_from(t)
                    .map_err(|_| format!("checkpoint {}: tag {t} does not fit 16 bits", msg.index))
            })
            .collect::<Result<Vec<_>, _>>()?
    };
    Ok(Particles {
        position_m: vecs(&msg.position_m),
        velocity_m_s: vecs(&msg.velocity_m_s),
        pressure_pa: msg.pressure_pa.clone(),
        kind,
        tag,
    })
}

/// A solver configured by `config` holding the state of a checkpoint message: particles,
/// step, time and the particles each inlet has poured (from `extra_scalars`, one per inlet
/// of `config`, whole numbers). The one place where a solver is rebuilt from a recording.
pub fn solver_from_message<const D: usize>(
    config: SolverConfig<D>,
    msg: &StateCheckpoint,
) -> Result<Solver<D>, String> {
    let particles = particles_from_message::<D>(msg)?;
    if msg.extra_scalars.len() != config.inlets.len() {
        return Err(format!(
            "checkpoint {}: {} extra scalars, but the experiment has {} inlets",
            msg.index,
            msg.extra_scalars.len(),
            config.inlets.len()
        ));
    }
    let mut emitted = Vec::with_capacity(config.inlets.len());
    for (inlet, &v) in config.inlets.iter().zip(&msg.extra_scalars) {
        let total = inlet.total_count(config.spacing_m);
        if !(v >= 0.0 && v.fract() == 0.0 && v <= total as f64) {
            return Err(format!(
                "checkpoint {}: an inlet has poured {v} particles, not a whole number in 0..={total}",
                msg.index
            ));
        }
        emitted.push(v as u64);
    }
    let n = particles.len();
    let stress = &msg.yield_stress_pa;
    if !stress.is_empty() && stress.len() != n * D * D {
        return Err(format!(
            "checkpoint {}: {} yield stress values for {n} particles in {D}D",
            msg.index,
            stress.len()
        ));
    }
    let penalty = msg.yield_penalty_pa_s;
    if !(penalty.is_finite() && penalty >= 0.0) {
        return Err(format!(
            "checkpoint {}: yield penalty {penalty} Pa s is not a finite value >= 0",
            msg.index
        ));
    }
    let mut solver = Solver::new(config, particles);
    solver.yield_penalty_pa_s = penalty;
    solver.yield_stress_pa = stress
        .chunks_exact(D * D)
        .map(crate::mps::yield_solve::Tensor::<D>::from_row_slice)
        .collect();
    solver.time_s = msg.time_s;
    solver.step = msg.step;
    solver.inlet_emitted = emitted;
    Ok(solver)
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
