//! The time loop shared by runs, resumed runs and replays: output schedules, checkpoints,
//! stop conditions and the outcome.
use super::RunError;
use super::frames::{cloud, diagnostics, time_ns};
use crate::checkpoint;
use crate::experiment::{Manifest, RowTracker, experiment_metrics};
use crate::manifest::PpePreconditioner;
use crate::mps::{ParticleKind, Solver, StepError};
use crate::proto::foxglove::PointCloud;
use crate::proto::mps::v1::{CheckpointHash, Diagnostics, StateCheckpoint, Summary};
use crate::record::{Outcome, Recorder};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Emission schedule of one output stream: fires at t = 0, interval, 2 interval, ... (the
/// first step that reaches each multiple).
struct Schedule {
    interval_s: f64,
    next: u64,
}

impl Schedule {
    fn new(interval_s: f64) -> Self {
        Self {
            interval_s,
            next: 0,
        }
    }
    /// The schedule of a run restored at `time_s`, that time already processed: the next
    /// emission is at the smallest k with k interval > time_s (where [`Schedule::due`] leaves
    /// it whether or not it fired at `time_s`).
    fn after(interval_s: f64, time_s: f64) -> Self {
        let mut next = ((time_s / interval_s) as u64).saturating_sub(2);
        while time_s >= next as f64 * interval_s {
            next += 1;
        }
        Self { interval_s, next }
    }
    /// Whether an emission is due at `time_s`; then the next is the smallest k with
    /// k interval > time_s. The search starts two below time_s / interval (every k below that
    /// is passed anyway), so a step that spans many intervals costs no more than one.
    fn due(&mut self, time_s: f64) -> bool {
        if time_s < self.next as f64 * self.interval_s {
            return false;
        }
        self.next = self
            .next
            .max(((time_s / self.interval_s) as u64).saturating_sub(2));
        while time_s >= self.next as f64 * self.interval_s {
            self.next += 1;
        }
        true
    }
}

/// Where the time loop's output goes: the [`Recorder`] for a run or a resume, a comparison
/// with a logged run for a replay (`runner verify`). One loop serves all of them.
pub trait Sink {
    /// Whether diagnostics rows and point clouds are wanted (a replay skips building them).
    fn wants_frames(&self) -> bool {
        true
    }
    fn diagnostics(&mut self, time_ns: u64, msg: &Diagnostics) -> Result<(), RunError>;
    fn cloud(&mut self, time_ns: u64, msg: &PointCloud) -> Result<(), RunError>;
    /// A state checkpoint (`msg.index` is its 0-based number in the run, hash filled in).
    fn checkpoint(&mut self, time_ns: u64, msg: &StateCheckpoint) -> Result<(), RunError>;
    /// False stops the loop as if interrupted (a replay that found a mismatch).
    fn keep_going(&self) -> bool {
        true
    }
}

impl Sink for Recorder {
    fn diagnostics(&mut self, time_ns: u64, msg: &Diagnostics) -> Result<(), RunError> {
        Ok(self.write_diagnostics(time_ns, msg)?)
    }
    fn cloud(&mut self, time_ns: u64, msg: &PointCloud) -> Result<(), RunError> {
        Ok(self.write_cloud(time_ns, msg)?)
    }
    fn checkpoint(&mut self, time_ns: u64, msg: &StateCheckpoint) -> Result<(), RunError> {
        Ok(self.write_state(time_ns, msg)?)
    }
}

/// Where the time loop starts. The default is a fresh run: the solver holds the initial
/// scene at step 0 and every output stream fires at t = 0.
#[derive(Debug, Clone, Default)]
pub struct LoopStart {
    /// The solver's state was restored from a checkpoint whose time has been processed: the
    /// output schedules start at the first multiple of their interval after it.
    pub restored: bool,
    /// Checkpoints already logged (their hashes go into the summary; the next index follows).
    pub checkpoints: Vec<CheckpointHash>,
    /// Step of the last checkpoint already logged, if it holds the solver's current state.
    pub last_checkpoint_step: Option<u64>,
    /// The diagnostics rows already logged up to the restored time (time, experiment
    /// metrics): they give the crossings and maxima found so far (see [`crate::experiment::RowTracker`]).
    pub logged_rows: Vec<(f64, BTreeMap<String, f64>)>,
}

/// Where a run stands, given to a progress display after every step (never recorded; the
/// library does not print it).
#[derive(Debug, Clone)]
pub struct Progress<'a> {
    /// `<name>-<first 12 hex of the experiment hash>`, as the run's file is named.
    pub run: &'a str,
    pub time_s: f64,
    /// `time.end_s`; a cap when [`Self::stops_early`].
    pub end_s: f64,
    pub step: u64,
    pub particles: usize,
    /// A stop rule (`stop.rest_metric`, `stop.non_flowing_fraction`) may end the run first.
    pub stops_early: bool,
}

/// A progress display: called from the thread running the loop, so it must be cheap (or
/// throttle itself).
pub type ProgressFn = Arc<dyn Fn(&Progress) + Send + Sync>;

/// What may stop the loop besides the experiment's own end and stop conditions.
#[derive(Clone, Default)]
pub struct LoopControl {
    /// Set from outside (signal handler): stop as "interrupted".
    pub interrupt: Option<Arc<AtomicBool>>,
    /// Told where the run stands after every step.
    pub progress: Option<ProgressFn>,
    /// Stop as "interrupted" once this step is reached (a replay of an interrupted or cut
    /// short run, or of a segment), at the same point of the loop as a signal would.
    pub stop_at_step: Option<u64>,
    /// The stop rules as builds before the pour rule applied them: a rule may stop the run
    /// while an inlet still has concrete to pour (the replay of a file written then; see
    /// [`POURED`]).
    pub rules_during_pour: bool,
}

/// Added to a stop rule's reason in a run with inlets: the rules wait until every inlet has
/// poured its volume (a front that stalls mid-pour, the first splash run out along the
/// channel, is not the material at rest). A file whose rule-stopped reason lacks it was
/// written before the rules waited, and is replayed by the rules as they were then.
pub const POURED: &str = " (every inlet had poured)";

/// Whether a file whose summary gives `stop` was stopped by a rule as the rules were before
/// they waited for the inlets (a rule's reason without [`POURED`]; without inlets the two
/// agree): its replay takes the rules it was written under.
pub fn rules_during_pour(stop: &str) -> bool {
    let by_rule = stop.starts_with(SETTLED) || stop.contains(NON_FLOWING_RULE);
    by_rule && !stop.ends_with(POURED)
}

/// How the rest rule's reason starts, and what the non-flowing rule's holds (written below,
/// recognised by [`rules_during_pour`]).
const SETTLED: &str = "settled: ";
const NON_FLOWING_RULE: &str = "(stop.non_flowing_fraction = ";

/// How the loop ended: the outcome and the summary (metrics at the last state, every
/// checkpoint hash).
#[derive(Debug, Clone)]
pub struct LoopEnd {
    pub outcome: Outcome,
    pub summary: Summary,
    /// Why a completed run stopped before `time.end_s` (a stop condition), else empty;
    /// recorded as `Summary.stop`.
    pub stop_reason: String,
}

/// The time loop: from the solver's current state to the end (or a stop), sending
/// diagnostics, clouds and checkpoints to `sink` on their schedules, and the final state as
/// a checkpoint. Every run, resume and replay goes through here, so a replay takes exactly
/// the steps the run took.
pub fn time_loop<const D: usize>(
    m: &Manifest,
    experiment_sha256: &str,
    solver: &mut Solver<D>,
    start: LoopStart,
    control: &LoopControl,
    sink: &mut dyn Sink,
) -> Result<LoopEnd, RunError> {
    let end_s = m.time.end_s;
    let schedule = |interval_s: f64| {
        if start.restored {
            Schedule::after(interval_s, solver.time_s)
        } else {
            Schedule::new(interval_s)
        }
    };
    let mut diag_schedule = schedule(m.output.diagnostics_interval_s);
    let mut cloud_schedule = schedule(m.output.cloud_interval_s);
    let mut checkpoint_schedule = schedule(m.output.checkpoint_interval_s);
    let run_label = format!(
        "{}-{}",
        m.name,
        crate::manifest::canonical::short_hash(experiment_sha256)
    );
    let stops_early = m.stop.rest_metric.is_some() || m.stop.non_flowing_fraction.is_some();
    let has_inlets = !solver.config.inlets.is_empty();
    // Whether a stop rule may fire now, and what its reason then ends with.
    let rules_apply = |solver: &Solver<D>| control.rules_during_pour || !solver.pouring();
    let poured = if has_inlets && !control.rules_during_pour {
        POURED
    } else {
        ""
    };
    let mut tracked = RowTracker::new(m);
    for (t, metrics) in &start.logged_rows {
        tracked.row(*t, |k| metrics.get(k).copied());
    }
    let mut checkpoints: Vec<CheckpointHash> = start.checkpoints;
    let mut last_checkpoint_step: Option<u64> = start.last_checkpoint_step;
    let mut outcome = Outcome::Completed;
    let mut stop_reason = String::new();
    let mut report = None;
    let mut dt_s = solver.next_dt_s(end_s);
    let dt_min_s = m.dt_min_s();
    let frames = sink.wants_frames();
    // The rest metric at the previous checkpoint. A restored run starts at a checkpoint, so
    // its value is that of the restored state: replays and resumed runs stop where the run
    // did.
    let mut rest_previous: Option<f64> = match &m.stop.rest_metric {
        Some(name) if start.restored => {
            Some(experiment_metrics(m, &solver.particles, solver.time_s)[name])
        }
        _ => None,
    };

    loop {
        let t = solver.time_s;
        if diag_schedule.due(t) {
            if frames {
                let row = diagnostics(m, solver, dt_s, report.as_ref());
                tracked.row(t, |k| row.metrics.get(k).copied());
                sink.diagnostics(time_ns(t), &row)?;
            } else if !tracked.is_empty() {
                let metrics = experiment_metrics(m, &solver.particles, t);
                tracked.row(t, |k| metrics.get(k).copied());
            }
        }
        if cloud_schedule.due(t) && frames {
            sink.cloud(time_ns(t), &cloud(solver))?;
        }
        if checkpoint_schedule.due(t) {
            let msg = checkpoint::to_message(checkpoints.len() as u32, solver, dt_s);
            checkpoints.push(checkpoint::hash_entry(&msg));
            sink.checkpoint(time_ns(t), &msg)?;
            last_checkpoint_step = Some(solver.step);
            if let Some(name) = &m.stop.rest_metric {
                let value = experiment_metrics(m, &solver.particles, solver.time_s)[name];
                let change = rest_previous.map(|previous| (value - previous).abs());
                rest_previous = Some(value);
                if let Some(change) = change
                    && t >= m.stop.rest_after_s
                    && change < m.stop.rest_metric_change
                    && rules_apply(solver)
                {
                    stop_reason = format!(
                        "{SETTLED}{name} changed by {change:.3e} over the last checkpoint interval (stop.rest_metric_change = {}){poured}",
                        m.stop.rest_metric_change
                    );
                    break;
                }
            }
        }
        if let Some(progress) = &control.progress {
            progress(&Progress {
                run: &run_label,
                time_s: t,
                end_s,
                step: solver.step,
                particles: solver.particles.len(),
                stops_early,
            });
        }
        // Stop when the remaining time is a negligible sliver of a step (float round-off).
        if end_s - t <= 1e-9 * end_s {
            break;
        }
        if solver.step >= m.stop.max_steps {
            stop_reason = format!("stop.max_steps = {} reached", m.stop.max_steps);
            break;
        }
        if let Some(flag) = &control.interrupt
            && flag.load(Ordering::SeqCst)
        {
            outcome = Outcome::Interrupted("interrupted by signal".to_string());
            break;
        }
        if let Some(stop) = control.stop_at_step.filter(|&s| solver.step >= s) {
            outcome = Outcome::Interrupted(format!("stopped at step {stop}"));
            break;
        }
        if !sink.keep_going() {
            outcome = Outcome::Interrupted("stopped by the output".to_string());
            break;
        }
        // A step forced below the minimum (the last one, cut to reach end_s, excepted) means
        // the flow has run away: fail before taking it.
        if dt_s < dt_min_s && dt_s < end_s - solver.time_s {
            let e = StepError::TimeStepTooSmall {
                dt_s,
                min_s: dt_min_s,
                speed_m_s: solver.max_fluid_speed_m_s(),
                step: solver.step,
            };
            outcome = Outcome::Failed(e.to_string());
            break;
        }
        match solver.step(dt_s) {
            Ok(r) => report = Some(r),
            Err(e) => {
                outcome = Outcome::Failed(failure_text(&e, m));
                break;
            }
        }
        dt_s = solver.next_dt_s(end_s);
        if let (Some(share), Some(r)) = (m.stop.non_flowing_fraction, &report)
            && solver.time_s >= m.stop.non_flowing_after_s
            && r.non_flowing_fraction >= share
            && rules_apply(solver)
        {
            stop_reason = format!(
                "{:.1} % of the fluid particles are non-flowing {NON_FLOWING_RULE}{share}){poured}",
                100.0 * r.non_flowing_fraction
            );
            break;
        }
    }

    // The final state is always checkpointed (unless the last step failed mid-way: its
    // state is not a consistent MPS state, the previous checkpoint stands).
    let failed = matches!(outcome, Outcome::Failed(_));
    if !failed && last_checkpoint_step != Some(solver.step) {
        let msg = checkpoint::to_message(checkpoints.len() as u32, solver, dt_s);
        checkpoints.push(checkpoint::hash_entry(&msg));
        sink.checkpoint(time_ns(solver.time_s), &msg)?;
        if frames {
            sink.diagnostics(
                time_ns(solver.time_s),
                &diagnostics(m, solver, dt_s, report.as_ref()),
            )?;
            sink.cloud(time_ns(solver.time_s), &cloud(solver))?;
        }
    }

    let p = &solver.particles;
    let mut metrics: BTreeMap<String, f64> = experiment_metrics(m, p, solver.time_s);
    metrics.insert("particle_count".into(), p.len() as f64);
    metrics.insert("fluid_particle_count".into(), p.fluid_count() as f64);
    metrics.insert(
        "ghost_particle_count".into(),
        p.count(ParticleKind::Ghost) as f64,
    );
    metrics.insert("steps".into(), solver.step as f64);
    metrics.insert("simulated_time_s".into(), solver.time_s);
    metrics.insert("stop_time_s".into(), solver.time_s);
    // The share of the fluid that the last step left non-flowing (a yield-stress material at
    // rest: 1); none when no step was taken.
    if let Some(r) = &report {
        metrics.insert("non_flowing_fraction".into(), r.non_flowing_fraction);
    }
    for (name, t) in tracked.found() {
        metrics.insert(name.clone(), *t);
    }
    let summary = Summary {
        outcome: outcome.as_str().to_string(),
        reason: outcome.reason().to_string(),
        metrics: metrics.into_iter().collect(),
        checkpoints,
        experiment_sha256: experiment_sha256.to_string(),
        stop: stop_reason.clone(),
    };
    Ok(LoopEnd {
        outcome,
        summary,
        stop_reason,
    })
}

/// What a failed step says, with the manifest's remedy where there is one: Jacobi's
/// iterations grow with the particles across the domain, multigrid's do not.
fn failure_text(e: &StepError, m: &Manifest) -> String {
    let text = e.to_string();
    match e {
        StepError::PressureNotConverged { .. }
            if m.mps.ppe_preconditioner == PpePreconditioner::Jacobi =>
        {
            format!(
                "{text}; under the Jacobi preconditioner the iterations grow with the \
                 particles across the domain, `mps.ppe_preconditioner: multigrid` keeps them \
                 nearly constant"
            )
        }
        _ => text,
    }
}
