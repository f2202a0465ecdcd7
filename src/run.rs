//! The time loop of one run: manifest -> scene -> solver -> MCAP recording.
//!
//! `mps/` does one step of the method; this module owns the process around it (output
//! schedule, diagnostics, checkpoints, stop conditions, outcome).
use crate::checkpoint;
use crate::experiment::{Manifest, Resolved, Scene, build_scene, experiment_metrics};
use crate::manifest::{Fluid, PpePreconditioner, PpeSource};
use crate::mps::{ParticleKind, Rheology, Solver, SolverConfig, SourceTerm, StageTimes};
use crate::proto::foxglove::PointCloud;
use crate::proto::mps::v1::{CheckpointHash, Diagnostics, StateCheckpoint, Summary};
use crate::record::{Outcome, RecordError, Recorder, RunHeader, point_cloud};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// How to run (never part of the experiment: none of it changes the state bits).
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub out_dir: PathBuf,
    /// Worker threads; None = all cores.
    pub threads: Option<usize>,
    /// Progress lines on stderr.
    pub progress: bool,
    /// Set from outside (signal handler) to stop the run cleanly as "interrupted".
    pub interrupt: Option<Arc<AtomicBool>>,
}

/// What a finished run produced.
#[derive(Debug, Clone)]
pub struct RunResult {
    pub path: PathBuf,
    pub outcome: Outcome,
    pub summary: Summary,
    /// See [`LoopEnd::stop_reason`].
    pub stop_reason: String,
    /// Wall-clock seconds of the time loop (reported, never recorded).
    pub wall_time_s: f64,
    /// Wall-clock seconds per solver stage (reported, never recorded).
    pub timing: StageTimes,
}

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("cannot create output directory {path}: {source}")]
    OutDir {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot start {threads} worker threads: {message}")]
    Threads { threads: usize, message: String },
    #[error(transparent)]
    Record(#[from] RecordError),
}

/// File name of a run: `<name>-<first 12 hex of the experiment hash>.mcap`.
pub fn output_path(out_dir: &Path, resolved: &Resolved) -> PathBuf {
    out_dir.join(format!(
        "{}-{}.mcap",
        resolved.manifest.name,
        resolved.short_hash()
    ))
}

/// Runs the experiment and records it. A simulation that fails (blow-up, solver failure) or
/// is interrupted still yields a finished MCAP file whose outcome says so: that is an `Ok`
/// with a non-completed `outcome`. `Err` means the recording itself could not be made.
pub fn run(resolved: &Resolved, options: &RunOptions) -> Result<RunResult, RunError> {
    std::fs::create_dir_all(&options.out_dir).map_err(|source| RunError::OutDir {
        path: options.out_dir.clone(),
        source,
    })?;
    let (pool, threads) = thread_pool(options.threads)?;
    pool.install(|| match resolved.manifest.dimension {
        3 => run_in::<3>(resolved, options, threads),
        _ => run_in::<2>(resolved, options, threads),
    })
}

/// A worker pool of `threads` threads (None = all cores), and its size. The split of the work
/// never depends on it (DESIGN.md section 6).
pub fn thread_pool(threads: Option<usize>) -> Result<(rayon::ThreadPool, usize), RunError> {
    let threads =
        threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| RunError::Threads {
            threads,
            message: e.to_string(),
        })?;
    Ok((pool, threads))
}

/// What a run file records about its experiment (the same for a run and its resumption).
pub fn run_header(resolved: &Resolved, threads: usize) -> RunHeader<'_> {
    RunHeader {
        manifest_source: &resolved.source_text,
        overrides: &resolved.overrides,
        canonical: &resolved.canonical,
        experiment_sha256: &resolved.hash_hex,
        name: &resolved.manifest.name,
        threads,
    }
}

/// The rheology a manifest's fluid section describes, and whether eq. 8's term is on.
pub fn rheology(fluid: &Fluid) -> (Rheology, bool) {
    match *fluid {
        Fluid::Newtonian { viscosity_pa_s, .. } => (Rheology::Newtonian { viscosity_pa_s }, false),
        Fluid::Bingham {
            plastic_viscosity_pa_s,
            yield_stress_pa,
            critical_strain_rate_1_s,
            stress_gradient_term,
            ..
        } => (
            Rheology::seed000(
                plastic_viscosity_pa_s,
                yield_stress_pa,
                critical_strain_rate_1_s,
            ),
            stress_gradient_term,
        ),
        Fluid::BiViscosity {
            plastic_viscosity_pa_s,
            yield_stress_pa,
            rigid_viscosity_pa_s,
            stress_gradient_term,
            ..
        } => (
            Rheology::bi_viscosity(
                plastic_viscosity_pa_s,
                yield_stress_pa,
                rigid_viscosity_pa_s,
            ),
            stress_gradient_term,
        ),
    }
}

/// Solver parameters from the manifest (radii and distances scaled by the spacing).
pub fn solver_config<const D: usize>(m: &Manifest, scene: &Scene<D>) -> SolverConfig<D> {
    let (rheology, stress_gradient_term) = rheology(&m.fluid);
    let l0 = m.spacing_m;
    SolverConfig {
        spacing_m: l0,
        density_kg_m3: m.fluid.density_kg_m3(),
        rheology,
        stress_gradient_term,
        viscosity_tolerance: m.mps.viscosity_tolerance,
        viscosity_max_iterations: m.mps.viscosity_max_iterations,
        gravity_m_s2: m.gravity_m_s2,
        radius_n_m: m.mps.number_density_radius * l0,
        radius_lap_m: m.mps.laplacian_radius * l0,
        surface_threshold: m.mps.surface_threshold,
        relaxation_coefficient: m.mps.relaxation_coefficient,
        multigrid_ppe: m.mps.ppe_preconditioner == PpePreconditioner::Multigrid,
        source_term: match m.mps.source_term {
            PpeSource::NumberDensity => SourceTerm::NumberDensity,
            PpeSource::Mixed => SourceTerm::Mixed,
        },
        compressibility_1_pa: m.mps.compressibility_1_pa,
        collision_distance_m: m.mps.collision_distance * l0,
        wall_collision_distance_m: match m.mps.wall_collision_distance {
            Some(d) => d * l0,
            None => {
                crate::mps::solver::wall_collision_distance_m(D, m.mps.collision_distance * l0, l0)
            }
        },
        wall_collision_second_pass: m.mps.wall_collision_second_pass.unwrap_or(D == 3),
        collision_restitution: m.mps.collision_restitution,
        ppe_tolerance: m.mps.ppe_tolerance,
        ppe_max_iterations: m.mps.ppe_max_iterations,
        courant: m.time.courant,
        dt_max_s: m.time.dt_max_s,
        max_speed_m_s: m.stop.max_speed_m_s,
        domain_min_m: scene.domain_min_m,
        domain_max_m: scene.domain_max_m,
        bodies: scene.bodies.clone(),
        inlets: scene.inlets.clone(),
    }
}

/// Simulation time in integer nanoseconds (MCAP log time).
pub fn time_ns(time_s: f64) -> u64 {
    (time_s * 1e9).round() as u64
}

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
    fn due(&mut self, time_s: f64) -> bool {
        if time_s >= self.next as f64 * self.interval_s {
            while time_s >= self.next as f64 * self.interval_s {
                self.next += 1;
            }
            true
        } else {
            false
        }
    }
}

fn diagnostics<const D: usize>(
    m: &Manifest,
    solver: &Solver<D>,
    dt_s: f64,
    report: Option<&crate::mps::StepReport>,
) -> Diagnostics {
    let p = &solver.particles;
    let mass_kg = solver.config.density_kg_m3 * m.spacing_m.powi(D as i32);
    let mut kinetic = 0.0;
    for i in 0..p.len() {
        if p.kind[i] == ParticleKind::Fluid {
            kinetic += 0.5 * mass_kg * p.velocity_m_s[i].norm_squared();
        }
    }
    Diagnostics {
        step: solver.step as u32,
        time_s: solver.time_s,
        dt_s,
        kinetic_energy_j: kinetic,
        max_speed_m_s: solver.max_fluid_speed_m_s(),
        ppe_iterations: report.map_or(0, |r| r.ppe.iterations),
        ppe_relative_residual: report.map_or(0.0, |r| r.ppe.relative_residual),
        surface_particle_count: report.map_or(0, |r| r.surface_count as u32),
        fluid_particle_count: p.fluid_count() as u32,
        viscosity_iterations: report.map_or(0, |r| r.viscosity.iterations),
        viscosity_relative_residual: report.map_or(0.0, |r| r.viscosity.relative_residual),
        non_flowing_fraction: report.map_or(0.0, |r| r.non_flowing_fraction),
        metrics: experiment_metrics(m, p).into_iter().collect(),
    }
}

fn cloud<const D: usize>(solver: &Solver<D>) -> PointCloud {
    let p = &solver.particles;
    // Dummies only pad the walls and ghosts have left the domain: neither is shown.
    let shown: Vec<usize> = (0..p.len())
        .filter(|&i| matches!(p.kind[i], ParticleKind::Fluid | ParticleKind::Wall))
        .collect();
    let positions: Vec<f64> = shown
        .iter()
        .flat_map(|&i| p.position_m[i].iter().copied().collect::<Vec<_>>())
        .collect();
    let speed: Vec<f32> = shown
        .iter()
        .map(|&i| p.velocity_m_s[i].norm() as f32)
        .collect();
    let pressure: Vec<f32> = shown.iter().map(|&i| p.pressure_pa[i] as f32).collect();
    let kind: Vec<f32> = shown.iter().map(|&i| p.kind[i] as u32 as f32).collect();
    let tag: Vec<f32> = shown.iter().map(|&i| f32::from(p.tag[i])).collect();
    // 1 = flowing (Pi > Pi_c at the start of the last step), 0 = non-flowing or not fluid.
    let flowing: Vec<f32> = shown
        .iter()
        .map(|&i| {
            f32::from(u8::from(
                p.kind[i] == ParticleKind::Fluid && solver.is_flowing(i),
            ))
        })
        .collect();
    point_cloud(
        time_ns(solver.time_s),
        D,
        &positions,
        &[
            ("speed_m_s", &speed),
            ("pressure_pa", &pressure),
            ("kind", &kind),
            ("tag", &tag),
            ("flowing", &flowing),
        ],
    )
}

fn run_in<const D: usize>(
    resolved: &Resolved,
    options: &RunOptions,
    threads: usize,
) -> Result<RunResult, RunError> {
    let m = &resolved.manifest;
    let scene = build_scene::<D>(m);
    let config = solver_config(m, &scene);
    let mut solver = Solver::new(config, scene.particles);
    let path = output_path(&options.out_dir, resolved);
    let mut recorder = Recorder::create(&path, &run_header(resolved, threads))?;
    let started = std::time::Instant::now();
    let control = LoopControl {
        interrupt: options.interrupt.clone(),
        progress: options.progress,
        stop_at_step: None,
    };
    let end = time_loop(
        m,
        &resolved.hash_hex,
        &mut solver,
        LoopStart::default(),
        &control,
        &mut recorder,
    )?;
    let path = recorder.finish(time_ns(solver.time_s), &end.summary, &end.outcome)?;
    Ok(RunResult {
        path,
        outcome: end.outcome,
        summary: end.summary,
        stop_reason: end.stop_reason,
        wall_time_s: started.elapsed().as_secs_f64(),
        timing: solver.timing,
    })
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
}

/// What may stop the loop besides the experiment's own end and stop conditions.
#[derive(Debug, Clone, Default)]
pub struct LoopControl {
    /// Set from outside (signal handler): stop as "interrupted".
    pub interrupt: Option<Arc<AtomicBool>>,
    /// Progress lines on stderr.
    pub progress: bool,
    /// Stop as "interrupted" once this step is reached (a replay of an interrupted or cut
    /// short run, or of a segment), at the same point of the loop as a signal would.
    pub stop_at_step: Option<u64>,
}

/// How the loop ended: the outcome and the summary (metrics at the last state, every
/// checkpoint hash).
#[derive(Debug, Clone)]
pub struct LoopEnd {
    pub outcome: Outcome,
    pub summary: Summary,
    /// Why a completed run stopped before `time.end_s` (a stop condition), else empty. Not
    /// recorded: the summary's reason is for failures and interrupts; a stop shows in
    /// `stop_time_s` and the last diagnostics row.
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
    let mut progress_schedule = schedule(end_s / 10.0);
    let mut checkpoints: Vec<CheckpointHash> = start.checkpoints;
    let mut last_checkpoint_step: Option<u64> = start.last_checkpoint_step;
    let mut outcome = Outcome::Completed;
    let mut stop_reason = String::new();
    let mut report = None;
    let mut dt_s = solver.next_dt_s(end_s);
    let frames = sink.wants_frames();
    // The rest metric at the previous checkpoint. A restored run starts at a checkpoint, so
    // its value is that of the restored state: replays and resumed runs stop where the run
    // did.
    let mut rest_previous: Option<f64> = match &m.stop.rest_metric {
        Some(name) if start.restored => Some(experiment_metrics(m, &solver.particles)[name]),
        _ => None,
    };

    loop {
        let t = solver.time_s;
        if diag_schedule.due(t) && frames {
            sink.diagnostics(time_ns(t), &diagnostics(m, solver, dt_s, report.as_ref()))?;
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
                let value = experiment_metrics(m, &solver.particles)[name];
                let change = rest_previous.map(|previous| (value - previous).abs());
                rest_previous = Some(value);
                if let Some(change) = change
                    && t >= m.stop.rest_after_s
                    && change < m.stop.rest_metric_change
                {
                    stop_reason = format!(
                        "settled: {name} changed by {change:.3e} over the last checkpoint interval (stop.rest_metric_change = {})",
                        m.stop.rest_metric_change
                    );
                    break;
                }
            }
        }
        if control.progress && progress_schedule.due(t) {
            eprintln!(
                "{}: t = {:.4} / {} s, step {}",
                m.name, t, end_s, solver.step
            );
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
        match solver.step(dt_s) {
            Ok(r) => report = Some(r),
            Err(e) => {
                outcome = Outcome::Failed(e.to_string());
                break;
            }
        }
        dt_s = solver.next_dt_s(end_s);
        if let (Some(share), Some(r)) = (m.stop.non_flowing_fraction, &report)
            && solver.time_s >= m.stop.non_flowing_after_s
            && r.non_flowing_fraction >= share
        {
            stop_reason = format!(
                "{:.1} % of the fluid particles are non-flowing (stop.non_flowing_fraction = {share})",
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
    let mut metrics: BTreeMap<String, f64> = experiment_metrics(m, p);
    metrics.insert("particle_count".into(), p.len() as f64);
    metrics.insert("fluid_particle_count".into(), p.fluid_count() as f64);
    metrics.insert(
        "ghost_particle_count".into(),
        p.count(ParticleKind::Ghost) as f64,
    );
    metrics.insert("steps".into(), solver.step as f64);
    metrics.insert("simulated_time_s".into(), solver.time_s);
    metrics.insert("stop_time_s".into(), solver.time_s);
    let summary = Summary {
        outcome: outcome.as_str().to_string(),
        reason: outcome.reason().to_string(),
        metrics: metrics.into_iter().collect(),
        checkpoints,
        experiment_sha256: experiment_sha256.to_string(),
    };
    Ok(LoopEnd {
        outcome,
        summary,
        stop_reason,
    })
}
