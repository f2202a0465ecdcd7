//! Taking a recorded run back up, for `runner verify` (replay) and `runner resume`: the
//! manifest rebuilt from the canonical form stored in the file and checked against its hash,
//! the messages in file order, and a solver restored from a logged checkpoint.
use crate::checkpoint;
use crate::experiment::{Manifest, Resolved, SceneSpec, build_scene};
use crate::manifest::{self, PresetName};
use crate::mps::Solver;
use crate::proto::mps::v1::StateCheckpoint;
use crate::record::{META_MANIFEST, RunFile, time_text};
use crate::run::solver_config;

/// Why a recorded manifest cannot be taken back up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ManifestCheck {
    /// Nothing to rebuild from (no `manifest` metadata or no canonical form): the file is
    /// unusable.
    #[error("the file has no stored manifest ({0})")]
    Missing(String),
    /// The stored canonical form is not a valid manifest: the file is unusable.
    #[error("the stored canonical manifest is not a valid manifest: {0}")]
    Invalid(String),
    /// The stored manifest does not hash to the recorded experiment hash, or its source text
    /// with its overrides resolves to a different experiment: tampered or corrupted.
    #[error("{0}")]
    Mismatch(String),
}

/// Rebuilds the manifest of a run from the canonical form in its `manifest` metadata and
/// checks it: its SHA-256 must equal the recorded `experiment_sha256` (and the summary's,
/// when there is one), and the source text as written, with the recorded overrides, must
/// resolve to the same hash. The result carries the recorded source text and overrides.
pub fn manifest_of(run: &RunFile) -> Result<Resolved, ManifestCheck> {
    let meta = run
        .metadata
        .get(META_MANIFEST)
        .ok_or_else(|| ManifestCheck::Missing("no `manifest` metadata record".into()))?;
    let field = |k: &str| {
        meta.get(k)
            .ok_or_else(|| ManifestCheck::Missing(format!("`manifest` metadata lacks `{k}`")))
    };
    let canonical = field("canonical")?;
    let recorded = field("experiment_sha256")?;
    let name = meta.get("name").map_or("manifest", |s| s.as_str());
    let resolved = manifest::from_canonical::<SceneSpec>(
        canonical,
        &format!("{name} (stored canonical)"),
        &[],
    )
    .map_err(|e| ManifestCheck::Invalid(e.to_string()))?;
    // The default preset its source was resolved under (none before the field existed).
    let default_preset = match meta.get("default_preset") {
        None => None,
        Some(text) => Some(
            serde_json::from_value::<PresetName>(serde_json::Value::String(text.clone())).map_err(
                |_| {
                    ManifestCheck::Mismatch(format!(
                        "manifest: unknown default_preset {text:?} (written by a newer build?)"
                    ))
                },
            )?,
        ),
    };
    // What the presets set when it was written (1 before the field existed).
    let preset_revision =
        manifest::recorded_revision(meta.get("preset_revision").map(String::as_str))
            .map_err(|e| ManifestCheck::Mismatch(format!("manifest: {e}")))?;
    if resolved.hash_hex != *recorded {
        return Err(ManifestCheck::Mismatch(format!(
            "manifest: the stored canonical form hashes to {}, but the file records experiment_sha256 {recorded}",
            resolved.hash_hex
        )));
    }
    if resolved.canonical != *canonical {
        return Err(ManifestCheck::Mismatch(
            "manifest: the stored canonical form is not in canonical form".into(),
        ));
    }
    if let Some(s) = run
        .summary
        .as_ref()
        .filter(|s| s.experiment_sha256 != *recorded)
    {
        return Err(ManifestCheck::Mismatch(format!(
            "manifest: the summary records experiment_sha256 {}, the metadata {recorded}",
            s.experiment_sha256
        )));
    }
    let overrides: Vec<String> = match meta.get("overrides") {
        Some(text) => serde_json::from_str(text).map_err(|e| {
            ManifestCheck::Mismatch(format!(
                "manifest: stored overrides are not a JSON list: {e}"
            ))
        })?,
        None => Vec::new(),
    };
    let source = meta.get("source").cloned().unwrap_or_default();
    let from_source = manifest::from_str_as_of::<SceneSpec>(
        &source,
        &format!("{name} (stored source)"),
        &overrides,
        default_preset,
        preset_revision,
    );
    match from_source {
        Ok(from_source) if from_source.hash_hex == *recorded => {}
        Ok(from_source) => {
            return Err(ManifestCheck::Mismatch(format!(
                "manifest: the stored source text with overrides {overrides:?} resolves to experiment {}, but the file records {recorded}",
                from_source.hash_hex
            )));
        }
        Err(e) => {
            return Err(ManifestCheck::Mismatch(format!(
                "manifest: the stored source text no longer resolves: {e}"
            )));
        }
    }
    Ok(Resolved {
        source_text: source,
        overrides,
        default_preset,
        preset_revision,
        ..resolved
    })
}

/// A solver holding the state of a logged checkpoint (step, time and inlet progress
/// included), configured from the manifest. The checkpoint's stored hash must match its
/// contents, and its `dt_s` must be the step the solver computes from that state. Call it inside the thread pool of
/// the replay.
pub fn restore_solver<const D: usize>(
    m: &Manifest,
    msg: &StateCheckpoint,
) -> Result<Solver<D>, String> {
    let recomputed = checkpoint::state_sha256(msg);
    if recomputed != msg.state_sha256 {
        return Err(format!(
            "checkpoint {} (step {}, t = {} s): stored state_sha256 {} does not match its contents ({recomputed})",
            msg.index,
            msg.step,
            time_text(msg.time_s),
            msg.state_sha256
        ));
    }
    let scene = build_scene::<D>(m);
    let config = solver_config(m, &scene);
    let solver = checkpoint::solver_from_message::<D>(config, msg)?;
    // Particles are only ever added (by inlets, at the end): the scene's particles plus those
    // poured, or the bodies' index ranges would point at the wrong particles.
    let expected = scene.particles.len() as u64 + solver.inlet_emitted.iter().sum::<u64>();
    if solver.particles.len() as u64 != expected {
        return Err(format!(
            "checkpoint {} (step {}, t = {} s) holds {} particles, but the scene has {} and its inlets poured {}",
            msg.index,
            msg.step,
            time_text(msg.time_s),
            solver.particles.len(),
            scene.particles.len(),
            expected - scene.particles.len() as u64
        ));
    }
    let dt = solver.next_dt_s(m.time.end_s);
    if dt.to_bits() != msg.dt_s.to_bits() {
        return Err(format!(
            "checkpoint {} (step {}, t = {} s): its dt_s {:e} is not the step its state gives ({dt:e})",
            msg.index,
            msg.step,
            time_text(msg.time_s),
            msg.dt_s
        ));
    }
    Ok(solver)
}

/// Whether checkpoint `states[i]` was written by the checkpoint schedule (the first step
/// that reached a multiple of `interval_s`), rather than as the extra final state of a run
/// that stopped between two scheduled ones. Only the last checkpoint of a file can be such
/// an extra. It is scheduled iff a multiple of the interval lies in (t_{i-1}, t_i]: the
/// first step reaching that multiple would otherwise have written a checkpoint in between.
pub fn is_scheduled(states: &[StateCheckpoint], i: usize, interval_s: f64) -> bool {
    if i == 0 {
        return states[0].step == 0;
    }
    let (before, t) = (states[i - 1].time_s, states[i].time_s);
    let mut k = ((before / interval_s) as u64).saturating_sub(2);
    while before >= k as f64 * interval_s {
        k += 1;
    }
    t >= k as f64 * interval_s
}

pub use crate::record::{Logged, read_messages};
