//! Bit-for-bit comparison of a replayed checkpoint with the logged one.
use crate::mps::ParticleKind;
use crate::proto::mps::v1::StateCheckpoint;

/// A value in full precision: shortest round-trip decimal and its bits.
pub fn full(x: f64) -> String {
    format!("{x:e} (bits 0x{:016x})", x.to_bits())
}

fn kind_name(k: u32) -> String {
    match ParticleKind::from_u32(k) {
        Some(ParticleKind::Fluid) => "fluid".into(),
        Some(ParticleKind::Wall) => "wall".into(),
        Some(ParticleKind::Dummy) => "dummy".into(),
        Some(ParticleKind::Ghost) => "ghost".into(),
        None => format!("kind {k}"),
    }
}

/// The first difference between a logged and a replayed checkpoint, in this order: header
/// (dimension, step, time, dt, particle count), then particle by particle (kind, position,
/// velocity, pressure), then the extra scalars and the tags, then the stored hash. `None`
/// when identical bit for bit.
pub fn first_difference(logged: &StateCheckpoint, replayed: &StateCheckpoint) -> Option<String> {
    if logged.dimension != replayed.dimension {
        return Some(format!(
            "dimension: logged {}, replayed {}",
            logged.dimension, replayed.dimension
        ));
    }
    if logged.step != replayed.step {
        return Some(format!(
            "step: logged {}, replayed {}",
            logged.step, replayed.step
        ));
    }
    for (name, a, b) in [
        ("time_s", logged.time_s, replayed.time_s),
        ("dt_s", logged.dt_s, replayed.dt_s),
    ] {
        if a.to_bits() != b.to_bits() {
            return Some(format!("{name}: logged {}, replayed {}", full(a), full(b)));
        }
    }
    let d = replayed.dimension as usize;
    let n = replayed.kind.len();
    let lens = [
        logged.kind.len(),
        logged.position_m.len(),
        logged.velocity_m_s.len(),
        logged.pressure_pa.len(),
    ];
    if lens != [n, n * d, n * d, n] {
        return Some(format!(
            "particle count: logged arrays kind/position/velocity/pressure have lengths {lens:?}, replayed {n} particles in {d}D"
        ));
    }
    for i in 0..n {
        let what = |field: &str| format!("particle {i} ({}) {field}", kind_name(replayed.kind[i]));
        if logged.kind[i] != replayed.kind[i] {
            return Some(format!(
                "{}: logged {} ({}), replayed {} ({})",
                what("kind"),
                logged.kind[i],
                kind_name(logged.kind[i]),
                replayed.kind[i],
                kind_name(replayed.kind[i])
            ));
        }
        for (field, la, ra) in [
            ("position_m", &logged.position_m, &replayed.position_m),
            ("velocity_m_s", &logged.velocity_m_s, &replayed.velocity_m_s),
        ] {
            for c in 0..d {
                let (a, b) = (la[i * d + c], ra[i * d + c]);
                if a.to_bits() != b.to_bits() {
                    return Some(format!(
                        "{}: logged {}, replayed {}",
                        what(&format!("{field}[{c}]")),
                        full(a),
                        full(b)
                    ));
                }
            }
        }
        let (a, b) = (logged.pressure_pa[i], replayed.pressure_pa[i]);
        if a.to_bits() != b.to_bits() {
            return Some(format!(
                "{}: logged {}, replayed {}",
                what("pressure_pa"),
                full(a),
                full(b)
            ));
        }
    }
    if logged.extra_scalars.len() != replayed.extra_scalars.len()
        || logged
            .extra_scalars
            .iter()
            .zip(&replayed.extra_scalars)
            .any(|(a, b)| a.to_bits() != b.to_bits())
    {
        return Some(format!(
            "extra_scalars: logged {:?}, replayed {:?}",
            logged.extra_scalars, replayed.extra_scalars
        ));
    }
    if logged.tag != replayed.tag {
        return Some(format!(
            "tag: logged {} values, replayed {} (first difference at particle {})",
            logged.tag.len(),
            replayed.tag.len(),
            logged
                .tag
                .iter()
                .zip(&replayed.tag)
                .position(|(a, b)| a != b)
                .unwrap_or(logged.tag.len().min(replayed.tag.len()))
        ));
    }
    if logged.state_sha256 != replayed.state_sha256 {
        return Some(format!(
            "state_sha256: logged {}, replayed {} (the state itself is identical: the stored hash is wrong)",
            logged.state_sha256, replayed.state_sha256
        ));
    }
    None
}
