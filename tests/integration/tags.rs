//! Particle tags (layer, material, origin): through the checkpoint message and back, the
//! state hash of files without tags unchanged, ghosts keeping theirs.
use crate::core_setup;
use core_setup::{advance, config, walled_box};
use mps_runner::checkpoint::{canonical_bits, particles_from_message, state_sha256, to_message};
use mps_runner::mps::{ParticleKind, Solver, Vector};
use mps_runner::proto::mps::v1::StateCheckpoint;
use sha2::{Digest, Sha256};

/// The state hash exactly as files were hashed before tags and inlets existed.
fn legacy_sha256(msg: &StateCheckpoint) -> String {
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

fn small_solver(tags: &[u16]) -> Solver<2> {
    let l0 = 0.02;
    let (mut p, lo, hi) = walled_box::<2>(l0, [6, 6], 2);
    for (i, &t) in tags.iter().enumerate() {
        p.tag[i] = t;
    }
    Solver::new(config::<2>(l0, lo, hi), p)
}

#[test]
fn all_zero_tags_leave_the_message_and_its_hash_as_before() {
    let mut solver = small_solver(&[]);
    advance(&mut solver, 0.01);
    let msg = to_message(3, &solver, 1e-4);
    assert!(msg.tag.is_empty(), "all-zero tags are not written");
    assert!(msg.extra_scalars.is_empty(), "no inlets, no extra scalars");
    assert_eq!(msg.state_sha256, legacy_sha256(&msg));
    let p = particles_from_message::<2>(&msg).unwrap();
    assert_eq!(p.tag, vec![0; p.len()]);
    assert_eq!(p, solver.particles);
}

#[test]
fn tags_survive_the_message_and_change_the_hash() {
    let tags = [0, 1, 2, 65535, 7];
    let solver = small_solver(&tags);
    let msg = to_message(0, &solver, 1e-4);
    assert_eq!(msg.tag.len(), solver.particles.len());
    let back = particles_from_message::<2>(&msg).unwrap();
    assert_eq!(&back.tag[..tags.len()], &tags);
    assert_eq!(back, solver.particles);

    let untagged = to_message(0, &small_solver(&[]), 1e-4);
    assert_ne!(msg.state_sha256, untagged.state_sha256);
    let mut changed = msg.clone();
    changed.tag[1] = 2;
    assert_ne!(state_sha256(&changed), msg.state_sha256);
    // An explicit all-zero array is a different message from an empty one, and hashes so.
    let mut zeros = untagged.clone();
    zeros.tag = vec![0; zeros.kind.len()];
    assert_ne!(state_sha256(&zeros), untagged.state_sha256);
    assert_eq!(
        particles_from_message::<2>(&zeros).unwrap(),
        particles_from_message::<2>(&untagged).unwrap()
    );

    let mut short = msg.clone();
    short.tag.pop();
    assert!(particles_from_message::<2>(&short).is_err());
    let mut wide = msg.clone();
    wide.tag[0] = 70_000;
    assert!(particles_from_message::<2>(&wide).is_err());
}

#[test]
fn a_ghost_keeps_its_tag() {
    let l0 = 0.02;
    let (mut p, lo, hi) = walled_box::<2>(l0, [6, 6], 2);
    // A tagged particle flying out of the box.
    p.push_tagged(Vector::<2>::new(0.06, 0.2), ParticleKind::Fluid, 9);
    let i = p.len() - 1;
    p.velocity_m_s[i] = Vector::<2>::new(0.0, 3.0);
    let mut solver = Solver::new(config::<2>(l0, lo, hi), p);
    while solver.particles.kind[i] != ParticleKind::Ghost {
        assert!(advance(&mut solver, 1.0), "never left the domain");
    }
    assert_eq!(solver.particles.tag[i], 9);
    let msg = to_message(0, &solver, 0.0);
    assert_eq!(msg.tag[i], 9);
}
