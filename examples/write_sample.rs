//! Writes a small sample run file, for checking outside readers on it:
//!
//! ```text
//! cargo run --release --example write_sample -- /tmp/sample.mcap [--killed]
//! .venv/bin/python tools/check_mcap.py /tmp/sample.mcap
//! ```
//!
//! With `--killed`, stops without finishing (as a killed process would) and leaves
//! `<path>.partial`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use mps_runner::proto::mps::v1::{CheckpointHash, Diagnostics, StateCheckpoint, Summary};
use mps_runner::record::{Outcome, Recorder, RunHeader, point_cloud};
use sha2::{Digest, Sha256};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().ok_or("usage: write_sample PATH [--killed]")?);
    let killed = args.next().as_deref() == Some("--killed");

    let manifest = "name: sample\nexperiment: dam_break\nparticles_per_side: 8\n";
    let canonical = r#"{"experiment":"dam_break","name":"sample","particles_per_side":8}"#;
    let sha = hex::encode(Sha256::digest(canonical.as_bytes()));
    let overrides = vec!["particles_per_side=8".to_string()];
    let header = RunHeader {
        manifest_source: manifest,
        overrides: &overrides,
        canonical,
        experiment_sha256: &sha,
        name: "sample",
        default_preset: None,
        preset_revision: None,
        threads: 1,
    };
    let mut rec = Recorder::create(&path, &header)?;

    // An 8 x 8 block of particles falling freely, 2D.
    let side = 8usize;
    let l0 = 0.01;
    let dt = 1e-3;
    let mut pos: Vec<f64> = Vec::new();
    for j in 0..side {
        for i in 0..side {
            pos.extend([i as f64 * l0, 0.1 + j as f64 * l0]);
        }
    }
    let n = side * side;
    let mut vel = vec![0.0f64; 2 * n];
    let mut summary = Summary::default();
    for step in 0..=50u32 {
        let t = f64::from(step) * dt;
        let t_ns = u64::from(step) * 1_000_000;
        if step > 0 {
            for p in 0..n {
                vel[2 * p + 1] -= 9.81 * dt;
                pos[2 * p + 1] += vel[2 * p + 1] * dt;
            }
        }
        let speed: Vec<f32> = (0..n).map(|p| vel[2 * p + 1].abs() as f32).collect();
        let pressure = vec![0.0f32; n];
        let kind = vec![0.0f32; n];
        let mut metrics = BTreeMap::new();
        metrics.insert("front_position_m".to_string(), (side - 1) as f64 * l0);
        rec.write_diagnostics(
            t_ns,
            &Diagnostics {
                step,
                time_s: t,
                dt_s: dt,
                kinetic_energy_j: 0.5 * speed.iter().map(|&s| f64::from(s * s)).sum::<f64>(),
                max_speed_m_s: f64::from(speed.iter().cloned().fold(0.0, f32::max)),
                fluid_particle_count: n as u32,
                metrics,
                ..Default::default()
            },
        )?;
        if step % 10 == 0 {
            rec.write_cloud(
                t_ns,
                &point_cloud(
                    t_ns,
                    2,
                    &pos,
                    &[
                        ("speed_m_s", &speed),
                        ("pressure_pa", &pressure),
                        ("kind", &kind),
                    ],
                ),
            )?;
        }
        if step % 25 == 0 {
            let index = step / 25;
            let mut s = StateCheckpoint {
                index,
                step: u64::from(step),
                time_s: t,
                dt_s: dt,
                dimension: 2,
                position_m: pos.clone(),
                velocity_m_s: vel.clone(),
                pressure_pa: vec![0.0; n],
                kind: vec![0; n],
                ..Default::default()
            };
            // Stand-in for the real state hash (defined by the solver, not by recording).
            let mut h = Sha256::new();
            for x in s.position_m.iter().chain(&s.velocity_m_s) {
                h.update(x.to_le_bytes());
            }
            s.state_sha256 = hex::encode(h.finalize());
            summary.checkpoints.push(CheckpointHash {
                index,
                step: s.step,
                time_s: t,
                state_sha256: s.state_sha256.clone(),
            });
            rec.write_state(t_ns, &s)?;
        }
    }
    if killed {
        std::mem::forget(rec);
        eprintln!("left {}.partial unfinished", path.display());
        return Ok(());
    }
    summary
        .metrics
        .insert("final_time_s".to_string(), 50.0 * dt);
    let out = rec.finish(50_000_000, &summary, &Outcome::Completed)?;
    println!("{}", out.display());
    Ok(())
}
