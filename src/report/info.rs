//! `runner info`: what a run file holds, read by the one reader of run files
//! ([`crate::record::read_run`]), as one structure ([`RunInfo`]) that both the text block
//! ([`RunInfo`]'s `Display`) and the JSON object (serde) are made from.
use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use serde::Serialize;

use crate::record::{
    META_BUILD, META_MANIFEST, META_OUTCOME, META_RUN, RunFile, TOPIC_DIAGNOSTICS, TOPIC_PARTICLES,
    TOPIC_STATE, TOPIC_SUMMARY,
};

/// What a run file holds. Key names are stable (they are the `--json` keys); a value the file
/// does not hold is `None` (JSON `null`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunInfo {
    /// The path as given.
    pub file: String,
    pub size_bytes: u64,
    /// Finished and whole (see [`RunFile::complete`]).
    pub complete: bool,
    /// Named `.partial`: a run in progress or killed.
    pub partial: bool,
    /// Experiment name (`manifest` metadata).
    pub experiment: Option<String>,
    pub experiment_sha256: Option<String>,
    /// `completed`, `failed` or `interrupted`: the `/summary` message's, else the `outcome`
    /// metadata's; `None` when the file holds neither.
    pub outcome: Option<String>,
    /// Why it failed or stopped (empty when completed).
    pub reason: Option<String>,
    /// `Summary.stop`: the stop rule that ended a completed run before `time.end_s`; empty
    /// when it ran to `time.end_s` (and in files written before the field existed); `None`
    /// without a `/summary` message.
    pub stop_rule: Option<String>,
    /// `mps.pressure_scheme` of the stored manifest (`standard` when the canonical form leaves
    /// it out, as it does for that default), followed by `, mps.KEY VALUE` for each of the
    /// scheme's stabilisers and switches the run had on (the canonical form holds them only
    /// then), e.g. `, mps.pair_stabilisation 0.8, mps.exact_projection true`, and ` (= mps.preset
    /// quiet)` when those are exactly the quiet preset's; `None` without a readable manifest.
    pub pressure_scheme: Option<String>,
    /// The `build` metadata: crate_version, git_commit, rustc, target, profile.
    pub build: BTreeMap<String, String>,
    /// Worker threads of the run (`run` metadata; informational).
    pub threads: Option<String>,
    pub particles: Particles,
    /// Simulated time and steps: the summary's, or for a file without one those of its last
    /// `/diagnostics` row (see [`Self::time_from`]).
    pub simulated_time_s: Option<f64>,
    pub steps: Option<f64>,
    /// `summary` or `last_diagnostics`; `None` when neither is there.
    pub time_from: Option<String>,
    pub checkpoints: Checkpoints,
    /// Summary metrics, sorted by name (empty without a `/summary` message).
    pub metrics: BTreeMap<String, f64>,
    /// Messages per channel (topic), counted while reading.
    pub channels: BTreeMap<String, usize>,
    /// What a finished run holds that this file does not, one line each (empty when whole).
    pub missing: Vec<String>,
    /// Where reading an unfinished file stopped before its end (see [`crate::record::Stop`]).
    pub damage: Option<Damage>,
}

/// Particle counts from the summary metrics.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Particles {
    pub total: Option<f64>,
    pub fluid: Option<f64>,
    /// Fluid particles that left the domain (ghosts).
    pub ghost: Option<f64>,
}

/// The `/state` checkpoints the file holds.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Checkpoints {
    pub count: usize,
    pub first_time_s: Option<f64>,
    pub last_time_s: Option<f64>,
    pub list: Vec<CheckpointEntry>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CheckpointEntry {
    pub index: u32,
    pub step: u64,
    pub time_s: f64,
    pub state_sha256: String,
}

/// See [`crate::record::Stop`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Damage {
    pub at_byte: u64,
    /// False when the record is only cut short by the end of the file (a killed run).
    pub damaged: bool,
    pub reason: String,
}

/// The one function from a read run file to [`RunInfo`].
pub fn run_info(path: &Path, size_bytes: u64, run: &RunFile) -> RunInfo {
    let meta = |record: &str, key: &str| -> Option<String> {
        run.metadata.get(record).and_then(|m| m.get(key)).cloned()
    };
    let summary = run.summary.as_ref();
    let metric = |k: &str| summary.and_then(|s| s.metrics.get(k).copied());
    let outcome = summary
        .map(|s| s.outcome.clone())
        .or_else(|| meta(META_OUTCOME, "status"));
    let reason = summary
        .map(|s| s.reason.clone())
        .or_else(|| meta(META_OUTCOME, "reason"));
    let last_row = run.diagnostics.last();
    let (simulated_time_s, steps, time_from) = match (summary, last_row) {
        (Some(_), _) => (metric("simulated_time_s"), metric("steps"), Some("summary")),
        (None, Some(d)) => (
            Some(d.time_s),
            Some(d.step.into()),
            Some("last_diagnostics"),
        ),
        (None, None) => (None, None, None),
    };
    let list: Vec<CheckpointEntry> = run
        .states
        .iter()
        .map(|s| CheckpointEntry {
            index: s.index,
            step: s.step,
            time_s: s.time_s,
            state_sha256: s.state_sha256.clone(),
        })
        .collect();
    let checkpoints = Checkpoints {
        count: list.len(),
        first_time_s: list.first().map(|c| c.time_s),
        last_time_s: list.last().map(|c| c.time_s),
        list,
    };
    let channels = [
        (TOPIC_STATE, run.states.len()),
        (TOPIC_PARTICLES, run.clouds),
        (TOPIC_DIAGNOSTICS, run.diagnostics.len()),
        (TOPIC_SUMMARY, usize::from(summary.is_some())),
    ]
    .into_iter()
    .map(|(t, n)| (t.to_string(), n))
    .chain(run.other_channels.iter().map(|(t, n)| (t.clone(), *n)))
    .collect();

    let mut missing = Vec::new();
    if !run.complete {
        missing.push(
            "the end of a finished file: no MCAP summary section, footer and end magic (a run in progress, killed, or cut short)".to_string(),
        );
    }
    for (record, what) in [
        (META_MANIFEST, "the experiment"),
        (META_BUILD, "the build"),
        (META_RUN, "the thread count"),
    ] {
        if !run.metadata.contains_key(record) {
            missing.push(format!("no `{record}` metadata record ({what})"));
        }
    }
    if summary.is_none() {
        missing.push(
            "no /summary message (no metrics, stop rule or checkpoint list; time and steps are the last /diagnostics row's)".to_string(),
        );
    }
    if !run.metadata.contains_key(META_OUTCOME) {
        missing.push("no `outcome` metadata record (how the run ended)".to_string());
    }
    if !run.complete {
        missing.push(match checkpoints.list.last() {
            Some(c) => format!(
                "the run after its last checkpoint (index {}, step {}, t = {} s): `runner resume` continues a .partial from there",
                c.index,
                c.step,
                super::time_text(c.time_s)
            ),
            None => "every checkpoint: the file holds none".to_string(),
        });
    }
    RunInfo {
        file: path.display().to_string(),
        size_bytes,
        complete: run.complete,
        partial: path
            .to_string_lossy()
            .ends_with(crate::record::PARTIAL_SUFFIX),
        experiment: meta(META_MANIFEST, "name"),
        experiment_sha256: meta(META_MANIFEST, "experiment_sha256")
            .or_else(|| summary.map(|s| s.experiment_sha256.clone())),
        outcome,
        reason,
        stop_rule: summary.map(|s| s.stop.clone()),
        pressure_scheme: super::canonical_manifest(run).map(|m| {
            let mps = m.get("mps");
            let mut text = mps
                .and_then(|mps| mps.get("pressure_scheme"))
                .and_then(|v| v.as_str())
                .unwrap_or("standard")
                .to_string();
            // The scheme's switches (stabilisers, floor, ...) are in the canonical form only when on.
            for key in [
                "pair_stabilisation",
                "wall_support",
                "pressure_regularisation",
                "increment_regularisation",
                "deep_surface_threshold",
                "deep_surface_head",
                "regularisation_radius",
                "pressure_smoothing_time_s",
                "surface_depth",
                "pressure_floor_pa",
                "particle_shifting",
                "particle_shifting_limit",
                "corrected_strain_rate",
                "wall_surface_no_slip",
                "wall_face_normals",
                "wall_curvature",
                "quadratic_strain_rate",
                "strain_rate_radius",
                "viscous_laplacian_radius",
                "exact_projection",
                "conservative_gradient",
                "adjoint_projection",
                "periodic_hydrostatic",
                "yield_penalty_pa_s",
                "yield_max_iterations",
                "yield_tolerance_1_s",
                "yield_penalty_adaptive",
                "yield_penalty_local",
                "yield_velocity_fraction",
                "yield_velocity_relative",
                "yield_anderson_depth",
                "yield_consistent_divergence",
                "yield_volumetric_limit",
            ] {
                if let Some(v) = mps.and_then(|mps| mps.get(key)) {
                    text.push_str(&format!(", mps.{key} {v}"));
                }
            }
            // Always in the canonical form; named when it is not the default, since under the
            // incremental scheme it damps the increment's two-step mode (docs/validation.md).
            let default = crate::manifest::Mps::default().compressibility_1_pa;
            if let Some(v) = mps
                .and_then(|mps| mps.get("compressibility_1_pa"))
                .and_then(|v| v.as_f64())
                .filter(|v| *v != default)
            {
                text.push_str(&format!(", mps.compressibility_1_pa {v:e}"));
            }
            // In the canonical form only when set; the 2D default's bound since revision 4.
            if let Some(v) = m.get("time").and_then(|t| t.get("acoustic_courant")) {
                text.push_str(&format!(", time.acoustic_courant {v}"));
            }
            if is_quiet_preset(run) {
                text.push_str(" (= mps.preset quiet)");
            }
            text
        }),
        build: run.metadata.get(META_BUILD).cloned().unwrap_or_default(),
        threads: meta(META_RUN, "threads"),
        particles: Particles {
            total: metric("particle_count"),
            fluid: metric("fluid_particle_count"),
            ghost: metric("ghost_particle_count"),
        },
        simulated_time_s,
        steps,
        time_from: time_from.map(str::to_string),
        checkpoints,
        metrics: summary.map(|s| s.metrics.clone()).unwrap_or_default(),
        channels,
        missing,
        damage: run.stop.as_ref().map(|s| Damage {
            at_byte: s.at_byte,
            damaged: s.damaged,
            reason: s.reason.clone(),
        }),
    }
}

/// Reads `path` and describes it (see [`run_info`]).
pub fn info(path: &Path) -> super::Result<RunInfo> {
    let run = crate::record::read_run(path)?;
    let size = std::fs::metadata(path).map_or(0, |m| m.len());
    Ok(run_info(path, size, &run))
}

/// A value or `-`.
fn or_dash<T: fmt::Display>(v: Option<T>) -> String {
    v.map_or_else(|| "-".to_string(), |v| v.to_string())
}

/// The text block of `runner info`: one aligned line per item, the metrics after.
impl fmt::Display for RunInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let state = match (self.complete, self.partial) {
            (true, _) => "finished",
            (false, true) => "unfinished (.partial)",
            (false, false) => "INCOMPLETE",
        };
        let mut lines: Vec<(&str, String)> = vec![
            (
                "file",
                format!("{} ({} bytes, {state})", self.file, self.size_bytes),
            ),
            (
                "experiment",
                format!(
                    "{} {}",
                    or_dash(self.experiment.as_deref()),
                    or_dash(self.experiment_sha256.as_deref())
                ),
            ),
        ];
        let outcome = match (&self.outcome, &self.reason) {
            (Some(o), Some(r)) if !r.is_empty() => format!("{o}: {r}"),
            (Some(o), _) => o.clone(),
            (None, _) => "- (no outcome recorded)".to_string(),
        };
        lines.push(("outcome", outcome));
        let stop = match self.stop_rule.as_deref() {
            None => "-".to_string(),
            Some("") if self.outcome.as_deref() == Some("completed") => {
                "none (ran to time.end_s)".to_string()
            }
            Some("") => "none".to_string(),
            Some(rule) => rule.to_string(),
        };
        lines.push(("stop rule", stop));
        lines.push((
            "scheme",
            format!(
                "mps.pressure_scheme {}",
                or_dash(self.pressure_scheme.as_deref())
            ),
        ));
        let b = |k: &str| or_dash(self.build.get(k));
        lines.push((
            "build",
            format!(
                "mps_runner {}, commit {}, {}, {} profile, {}",
                b("crate_version"),
                b("git_commit"),
                b("rustc"),
                b("profile"),
                b("target")
            ),
        ));
        lines.push(("threads", or_dash(self.threads.as_deref())));
        let p = &self.particles;
        lines.push((
            "particles",
            format!(
                "{} ({} fluid, {} ghost)",
                or_dash(p.total),
                or_dash(p.fluid),
                or_dash(p.ghost)
            ),
        ));
        let from = match self.time_from.as_deref() {
            Some("last_diagnostics") => " (last /diagnostics row)",
            _ => "",
        };
        lines.push((
            "simulated",
            format!(
                "t = {} s, {} steps{from}",
                or_dash(self.simulated_time_s),
                or_dash(self.steps)
            ),
        ));
        let c = &self.checkpoints;
        lines.push((
            "checkpoints",
            match (c.first_time_s, c.last_time_s) {
                (Some(first), Some(last)) => {
                    format!("{}, t = {first} s to {last} s", c.count)
                }
                _ => "0".to_string(),
            },
        ));
        lines.push((
            "channels",
            self.channels
                .iter()
                .map(|(t, n)| format!("{t} {n}"))
                .collect::<Vec<_>>()
                .join(", "),
        ));
        for m in &self.missing {
            lines.push(("missing", m.clone()));
        }
        if let Some(d) = &self.damage {
            let what = if d.damaged { "damaged" } else { "cut short" };
            lines.push((
                "read up to",
                format!("byte {} ({what}): {}", d.at_byte, d.reason),
            ));
        }
        lines.push(("metrics", self.metrics.len().to_string()));
        for (k, v) in &lines {
            writeln!(f, "{k:<12} {v}")?;
        }
        let width = self.metrics.keys().map(String::len).max().unwrap_or(0);
        for (k, v) in &self.metrics {
            writeln!(f, "  {k:<width$}  {v}")?;
        }
        Ok(())
    }
}

/// Whether the run's manifest holds exactly the quiet preset's fields (as they were at the
/// file's preset revision): setting the preset on its stored canonical form leaves the
/// experiment's hash (that of the form itself) as it was.
fn is_quiet_preset(run: &RunFile) -> bool {
    let Some(canonical) = run.manifest_field("canonical") else {
        return false;
    };
    let Ok(revision) = crate::manifest::recorded_revision(run.manifest_field("preset_revision"))
    else {
        return false;
    };
    let preset = format!("mps.preset={}", crate::manifest::PresetName::Quiet.name());
    crate::manifest::from_str_as_of::<crate::experiment::SceneSpec>(
        canonical,
        "canonical",
        &[preset],
        None,
        revision,
    )
    .is_ok_and(|quiet| quiet.hash_hex == crate::manifest::canonical::sha256_hex(canonical))
}
