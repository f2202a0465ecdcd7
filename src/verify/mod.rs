//! `runner verify`: rebuild a run from the manifest stored in its file, replay it, and compare
//! every logged state checkpoint bit for bit (and the summary metrics); `--trend` checks a
//! sweep (see [`trend`]).
pub mod compare;
pub mod trend;

use crate::build_info::BuildInfo;
use crate::experiment::{PLATFORM_POW_METRICS, Resolved, build_scene};
use crate::proto::foxglove::PointCloud;
use crate::proto::mps::v1::{CheckpointHash, Diagnostics, StateCheckpoint, Summary};
use crate::record::{META_BUILD, RunFile, read_run};
use crate::restore::{ManifestCheck, manifest_of, restore_solver};
use crate::run::{LoopControl, LoopStart, RunError, Sink, solver_config, time_loop};
use std::fmt;
use std::path::{Path, PathBuf};

/// What to replay.
#[derive(Clone, Default)]
pub struct VerifyOptions {
    /// Start from logged checkpoint K (its state restored) instead of the manifest's initial
    /// scene; checkpoints K+1.. are compared.
    pub from: Option<u32>,
    /// Stop at logged checkpoint M (default: the last one).
    pub to: Option<u32>,
    /// Worker threads; None = all cores (the bits never depend on it).
    pub threads: Option<usize>,
    /// Told where the replay stands after every step.
    pub progress: Option<crate::run::ProgressFn>,
}

/// The file cannot be used for a replay (exit code 2).
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}: {reason}", path.display())]
pub struct Unusable {
    pub path: PathBuf,
    pub reason: String,
}

/// The first checkpoint where the replay differs from the file.
#[derive(Debug, Clone, PartialEq)]
pub struct Mismatch {
    pub checkpoint: u32,
    pub step: u64,
    pub time_s: f64,
    /// Which particle and field, with both values in full precision.
    pub detail: String,
}

impl fmt::Display for Mismatch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "checkpoint {} (logged step {}, t = {} s): {}",
            self.checkpoint,
            self.step,
            crate::record::time_text(self.time_s),
            self.detail
        )
    }
}

/// What a verification found.
#[derive(Debug, Clone)]
pub struct VerifyReport {
    pub path: PathBuf,
    pub name: String,
    pub experiment_sha256: String,
    /// `completed`, `failed`, `interrupted`, or `unfinished` (no footer: a killed run).
    pub outcome: String,
    /// Set when the build that wrote the file is not this one.
    pub build_warning: Option<String>,
    /// Checkpoint the replay started from (`None`: the manifest's initial scene).
    pub from: Option<u32>,
    /// Last checkpoint compared.
    pub to: u32,
    /// Checkpoints compared and found identical.
    pub matched: usize,
    /// Checkpoints due to be compared.
    pub expected: usize,
    pub mismatch: Option<Mismatch>,
    /// Other failures: the stored manifest, stored hashes that do not match their states,
    /// summary metrics or hashes that differ from the replay.
    pub problems: Vec<String>,
    /// Whether the summary (outcome, metrics, checkpoint hashes) was compared.
    pub summary_compared: bool,
    /// Differences that are explained and accepted (printed, not failures).
    pub notes: Vec<String>,
    /// Logged checkpoint hashes (all of them, for `--print-hashes`).
    pub hashes: Vec<CheckpointHash>,
    /// Wall-clock seconds of the replay.
    pub replay_wall_s: f64,
    /// False when the stored manifest did not match its hash: nothing was replayed.
    pub replayed: bool,
}

impl VerifyReport {
    pub fn passed(&self) -> bool {
        self.mismatch.is_none() && self.problems.is_empty()
    }
}

impl fmt::Display for VerifyReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let start = match self.from {
            None => "the manifest's initial state".to_string(),
            Some(k) => format!("logged checkpoint {k}"),
        };
        let replay = if self.replayed {
            format!(
                "replayed from {start} to checkpoint {} in {:.2} s",
                self.to, self.replay_wall_s
            )
        } else {
            "not replayed".to_string()
        };
        writeln!(
            f,
            "{}: run {} (experiment {}), outcome {}; {replay}",
            self.path.display(),
            self.name,
            self.experiment_sha256,
            self.outcome,
        )?;
        if let Some(m) = &self.mismatch {
            writeln!(f, "MISMATCH at {m}")?;
        }
        for p in &self.problems {
            writeln!(f, "MISMATCH: {p}")?;
        }
        for n in &self.notes {
            writeln!(f, "note: {n}")?;
        }
        if !self.replayed {
            return write!(
                f,
                "FAILED: the stored manifest is not the recorded experiment"
            );
        }
        let summary = if self.summary_compared {
            if self.problems.is_empty() {
                "; summary metrics identical"
            } else {
                ""
            }
        } else if self.mismatch.is_some() {
            "; summary not compared (a checkpoint differs)"
        } else {
            "; summary not compared (segment, or the file has no summary)"
        };
        write!(
            f,
            "{}: {} of {} checkpoints identical bit for bit{summary}",
            if self.passed() { "ok" } else { "FAILED" },
            self.matched,
            self.expected
        )
    }
}

/// The build that wrote the file vs this one; `None` when they are the same.
pub fn build_difference(run: &RunFile) -> Option<String> {
    let current = BuildInfo::current();
    let Some(b) = run.metadata.get(META_BUILD) else {
        return Some(format!(
            "the file records no build; replaying with {current}"
        ));
    };
    let get = |k: &str| b.get(k).map_or("", |s| s.as_str());
    let same = get("crate_version") == current.crate_version
        && get("git_commit") == current.git_commit
        && get("rustc") == current.rustc
        && get("target") == current.target
        && get("profile") == current.profile;
    (!same).then(|| {
        format!(
            "the file was written by mps_runner {} ({}; {}; {}; {}), this is {current}: a different build may give different bits",
            get("crate_version"),
            get("git_commit"),
            get("profile"),
            get("target"),
            get("rustc")
        )
    })
}

/// Replays the run recorded at `path` and compares it with the file.
///
/// `Err` when the file cannot be used (unreadable, no manifest, no checkpoint in range);
/// otherwise the report says whether everything matched.
pub fn verify(path: &Path, options: &VerifyOptions) -> Result<VerifyReport, Unusable> {
    let unusable = |reason: String| Unusable {
        path: path.to_path_buf(),
        reason,
    };
    let run = read_run(path).map_err(|e| unusable(e.to_string()))?;
    let meta_name = run.manifest_field("name").unwrap_or_default().to_string();
    let mut report = VerifyReport {
        path: path.to_path_buf(),
        name: meta_name,
        experiment_sha256: run
            .manifest_field("experiment_sha256")
            .unwrap_or_default()
            .to_string(),
        outcome: if run.complete {
            run.summary
                .as_ref()
                .map_or("unknown".to_string(), |s| s.outcome.clone())
        } else {
            "unfinished".to_string()
        },
        build_warning: build_difference(&run),
        from: options.from,
        to: 0,
        matched: 0,
        expected: 0,
        mismatch: None,
        problems: Vec::new(),
        summary_compared: false,
        notes: Vec::new(),
        hashes: run
            .states
            .iter()
            .map(crate::checkpoint::hash_entry)
            .collect(),
        replay_wall_s: 0.0,
        replayed: false,
    };
    let resolved = match manifest_of(&run) {
        Ok(r) => r,
        Err(e @ (ManifestCheck::Missing(_) | ManifestCheck::Invalid(_))) => {
            return Err(unusable(e.to_string()));
        }
        Err(ManifestCheck::Mismatch(m)) => {
            // The replay would be of another experiment than the one recorded: stop here.
            report.problems.push(m);
            return Ok(report);
        }
    };
    if run.states.is_empty() {
        return Err(unusable(
            "the file has no state checkpoint to compare".into(),
        ));
    }
    for (i, s) in run.states.iter().enumerate() {
        if s.index as usize != i {
            report.problems.push(format!(
                "checkpoint {i} of the file carries index {}",
                s.index
            ));
        }
    }
    let last = (run.states.len() - 1) as u32;
    let to = options.to.unwrap_or(last);
    if to > last {
        return Err(unusable(format!(
            "--to {to}: the file has checkpoints 0 to {last}"
        )));
    }
    if let Some(k) = options.from.filter(|&k| k >= to) {
        return Err(unusable(format!(
            "--from {k} must be before the last checkpoint to compare ({to})"
        )));
    }
    report.to = to;
    let first_compared = options.from.map_or(0, |k| k + 1);
    report.expected = (to + 1 - first_compared) as usize;
    // Stored hashes against stored states, over the range compared (a file can be wrong on
    // its own, whatever the replay gives).
    for s in &run.states[first_compared as usize..=to as usize] {
        let h = crate::checkpoint::state_sha256(s);
        if h != s.state_sha256 {
            report.problems.push(format!(
                "checkpoint {} (step {}, t = {} s): stored state_sha256 {} does not match the logged state ({h})",
                s.index,
                s.step,
                crate::record::time_text(s.time_s),
                s.state_sha256
            ));
        }
    }
    if let Some(summary) = &run.summary {
        let listed: Vec<&str> = summary
            .checkpoints
            .iter()
            .map(|c| c.state_sha256.as_str())
            .collect();
        let logged: Vec<&str> = run.states.iter().map(|s| s.state_sha256.as_str()).collect();
        if listed != logged {
            report.problems.push(format!(
                "the summary lists {} checkpoint hashes that differ from the {} logged checkpoints' stored hashes",
                listed.len(),
                logged.len()
            ));
        }
    }

    let (pool, _) =
        crate::run::thread_pool(options.threads).map_err(|e| unusable(e.to_string()))?;
    let started = std::time::Instant::now();
    let replay = pool.install(|| match resolved.manifest.dimension {
        3 => replay::<3>(&resolved, &run, options, to),
        _ => replay::<2>(&resolved, &run, options, to),
    });
    report.replay_wall_s = started.elapsed().as_secs_f64();
    report.replayed = true;
    let (compare, summary) = replay.map_err(unusable)?;
    report.matched = compare.matched;
    report.mismatch = compare.mismatch;
    if report.mismatch.is_none() && compare.next < to as usize + 1 {
        let s = &run.states[compare.next];
        report.mismatch = Some(Mismatch {
            checkpoint: s.index,
            step: s.step,
            time_s: s.time_s,
            detail: format!(
                "the replay ended ({}{}) at step {} without reaching this checkpoint",
                summary.outcome,
                if summary.reason.is_empty() {
                    String::new()
                } else {
                    format!(": {}", summary.reason)
                },
                summary.metrics.get("steps").copied().unwrap_or(f64::NAN)
            ),
        });
    }
    let whole = report.mismatch.is_none() && to == last && run.complete;
    if let Some(logged) = run.summary.as_ref().filter(|_| whole) {
        report.summary_compared = true;
        let platform_pow = run
            .metadata
            .get(crate::record::META_RUN)
            .is_none_or(|r| !r.contains_key("math"));
        let (problems, notes) = compare_summaries(logged, &summary, platform_pow);
        report.problems.extend(problems);
        report.notes.extend(notes);
    }
    Ok(report)
}

/// Differences between the logged summary and the replay's, and the accepted ones: with
/// `platform_pow` (a file written before `run.math`), a [`PLATFORM_POW_METRICS`] value one
/// unit in the last place from the replay's.
fn compare_summaries(
    logged: &Summary,
    replayed: &Summary,
    platform_pow: bool,
) -> (Vec<String>, Vec<String>) {
    let mut out = Vec::new();
    let mut notes = Vec::new();
    // An interrupted run's replay is stopped at the same step, so its outcome is
    // "interrupted" too; only the reason (signal vs step) differs.
    if logged.outcome != replayed.outcome {
        out.push(format!(
            "summary outcome: logged {}, replayed {}",
            logged.outcome, replayed.outcome
        ));
    } else if logged.outcome != "interrupted" && logged.reason != replayed.reason {
        out.push(format!(
            "summary reason: logged {:?}, replayed {:?}",
            logged.reason, replayed.reason
        ));
    }
    if logged.stop != replayed.stop {
        if logged.stop.is_empty() && logged.outcome == "completed" {
            notes.push(format!(
                "summary stop: the file does not record why the run stopped (written before the summary's stop field); the replay stopped by: {}",
                replayed.stop
            ));
        } else if logged.outcome != "interrupted" {
            out.push(format!(
                "summary stop: logged {:?}, replayed {:?}",
                logged.stop, replayed.stop
            ));
        }
    }
    let keys: std::collections::BTreeSet<&String> = logged
        .metrics
        .keys()
        .chain(replayed.metrics.keys())
        .collect();
    for k in keys {
        match (logged.metrics.get(k), replayed.metrics.get(k)) {
            (Some(a), Some(b)) if a.to_bits() == b.to_bits() => {}
            (Some(a), Some(b))
                if platform_pow
                    && PLATFORM_POW_METRICS.contains(&k.as_str())
                    && a.is_sign_positive() == b.is_sign_positive()
                    && a.to_bits().abs_diff(b.to_bits()) == 1 =>
            {
                notes.push(format!(
                    "summary metric {k}: logged {}, replayed {}, one unit in the last place apart: the file's build computed this closed form with the platform's pow, this one with libm (the file has no run.math entry); the simulation is not affected",
                    compare::full(*a),
                    compare::full(*b)
                ));
            }
            (Some(a), Some(b)) => out.push(format!(
                "summary metric {k}: logged {}, replayed {}",
                compare::full(*a),
                compare::full(*b)
            )),
            (None, Some(b)) if crate::experiment::LATER_METRICS.contains(&k.as_str()) => {
                notes.push(format!(
                    "summary metric {k}: not in the file (written before this build recorded it); the replay gives {}",
                    compare::full(*b)
                ))
            }
            (a, b) => out.push(format!("summary metric {k}: logged {a:?}, replayed {b:?}")),
        }
    }
    let hashes = |s: &Summary| {
        s.checkpoints
            .iter()
            .map(|c| (c.index, c.step, c.time_s.to_bits(), c.state_sha256.clone()))
            .collect::<Vec<_>>()
    };
    if hashes(logged) != hashes(replayed) {
        out.push("summary checkpoint hashes differ from the replay's".to_string());
    }
    (out, notes)
}

/// The comparing sink: each replayed checkpoint against the logged one of the same index.
struct Compare<'a> {
    logged: &'a [StateCheckpoint],
    /// Index of the next checkpoint expected from the replay.
    next: usize,
    last: usize,
    matched: usize,
    mismatch: Option<Mismatch>,
}

impl Sink for Compare<'_> {
    fn wants_frames(&self) -> bool {
        false
    }
    fn diagnostics(&mut self, _: u64, _: &Diagnostics) -> Result<(), RunError> {
        Ok(())
    }
    fn cloud(&mut self, _: u64, _: &PointCloud) -> Result<(), RunError> {
        Ok(())
    }
    fn checkpoint(&mut self, _: u64, msg: &StateCheckpoint) -> Result<(), RunError> {
        if self.mismatch.is_some() {
            return Ok(());
        }
        let i = msg.index as usize;
        let detail = if i != self.next {
            Some(format!(
                "the replay numbered its checkpoint {i}, expected {}",
                self.next
            ))
        } else if i > self.last {
            Some(format!(
                "the replay wrote checkpoint {i} (step {}, t = {} s) past the last one compared",
                msg.step,
                crate::record::time_text(msg.time_s)
            ))
        } else {
            compare::first_difference(&self.logged[i], msg)
        };
        match detail {
            None => self.matched += 1,
            Some(detail) => {
                let at = self.logged.get(i.min(self.logged.len() - 1)).unwrap();
                self.mismatch = Some(Mismatch {
                    checkpoint: i as u32,
                    step: at.step,
                    time_s: at.time_s,
                    detail,
                });
            }
        }
        self.next = i + 1;
        Ok(())
    }
    fn keep_going(&self) -> bool {
        self.mismatch.is_none()
    }
}

fn replay<const D: usize>(
    resolved: &Resolved,
    run: &RunFile,
    options: &VerifyOptions,
    to: u32,
) -> Result<(ReplayCompare, Summary), String> {
    let m = &resolved.manifest;
    let (mut solver, start) = match options.from {
        None => {
            let scene = build_scene::<D>(m);
            let config = solver_config(m, &scene);
            (
                crate::mps::Solver::new(config, scene.particles),
                LoopStart::default(),
            )
        }
        Some(k) => {
            let from = &run.states[k as usize];
            let solver = restore_solver::<D>(m, from)?;
            let start = LoopStart {
                restored: true,
                checkpoints: run.states[..=k as usize]
                    .iter()
                    .map(crate::checkpoint::hash_entry)
                    .collect(),
                last_checkpoint_step: Some(from.step),
                logged_rows: run
                    .diagnostics
                    .iter()
                    .filter(|d| d.time_s <= from.time_s)
                    .map(crate::run::logged_row)
                    .collect(),
            };
            (solver, start)
        }
    };
    let last = run.states.len() - 1;
    let outcome = run.summary.as_ref().map(|s| s.outcome.as_str());
    // A completed or failed run is replayed to its own end (a failure included); an
    // interrupted or unfinished one, or a segment, stops at the step of its last checkpoint,
    // where the run stopped.
    let runs_to_end = to as usize == last && run.complete && outcome != Some("interrupted");
    let control = LoopControl {
        interrupt: None,
        progress: options.progress.clone(),
        stop_at_step: (!runs_to_end).then(|| run.states[to as usize].step),
        rules_during_pour: run
            .summary
            .as_ref()
            .is_some_and(|s| crate::run::rules_during_pour(&s.stop)),
    };
    let mut sink = Compare {
        logged: &run.states,
        next: options.from.map_or(0, |k| k as usize + 1),
        last: to as usize,
        matched: 0,
        mismatch: None,
    };
    let end = time_loop(
        m,
        &resolved.hash_hex,
        &mut solver,
        start,
        &control,
        &mut sink,
    )
    .map_err(|e| e.to_string())?;
    Ok((
        ReplayCompare {
            matched: sink.matched,
            mismatch: sink.mismatch,
            next: sink.next,
        },
        end.summary,
    ))
}

struct ReplayCompare {
    matched: usize,
    mismatch: Option<Mismatch>,
    next: usize,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(metrics: &[(&str, f64)]) -> Summary {
        Summary {
            outcome: "completed".into(),
            metrics: metrics.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            ..Summary::default()
        }
    }

    #[test]
    fn a_platform_pow_metric_one_ulp_off_is_a_note_only_in_files_before_run_math() {
        let x = 0.3012_f64;
        let next = f64::from_bits(x.to_bits() + 1);
        let logged = summary(&[("closed_form_radius_m", x), ("spread_radius_mean_m", x)]);
        let one_ulp = summary(&[("closed_form_radius_m", next), ("spread_radius_mean_m", x)]);
        let (problems, notes) = compare_summaries(&logged, &one_ulp, true);
        assert!(problems.is_empty(), "{problems:?}");
        assert_eq!(notes.len(), 1);
        assert!(notes[0].contains("closed_form_radius_m"), "{}", notes[0]);
        // A file that records run.math was written with libm: every bit counts.
        let (problems, notes) = compare_summaries(&logged, &one_ulp, false);
        assert_eq!((problems.len(), notes.len()), (1, 0));
        // Two units apart, or any other metric one unit apart: a mismatch in any file.
        let two_ulp = summary(&[
            ("closed_form_radius_m", f64::from_bits(x.to_bits() + 2)),
            ("spread_radius_mean_m", x),
        ]);
        assert_eq!(compare_summaries(&logged, &two_ulp, true).0.len(), 1);
        let other = summary(&[("closed_form_radius_m", x), ("spread_radius_mean_m", next)]);
        assert_eq!(compare_summaries(&logged, &other, true).0.len(), 1);
    }

    #[test]
    fn the_stop_rule_must_match_unless_the_file_predates_it() {
        let with_stop = |stop: &str| Summary {
            stop: stop.into(),
            ..summary(&[])
        };
        let rule = with_stop("90.0 % of the fluid particles are non-flowing");
        // A completed file without the field (written before it): a note, not a mismatch.
        let (problems, notes) = compare_summaries(&with_stop(""), &rule, false);
        assert!(problems.is_empty(), "{problems:?}");
        assert_eq!(notes.len(), 1);
        // Recorded and different (the replay ran to the end, or stopped by another rule).
        for replayed in [with_stop(""), with_stop("settled")] {
            let (problems, _) = compare_summaries(&rule, &replayed, false);
            assert_eq!(problems.len(), 1, "{problems:?}");
        }
        assert_eq!(compare_summaries(&rule, &rule, false), (vec![], vec![]));
    }
}
