//! Takes a recorded 3D or 2D run up from one of its checkpoints with settings changed, and
//! steps it on, printing the fluid's kinetic energy, its largest speed and its non-flowing
//! share as it goes. The cheap way to ask "what does this one setting do to that state"
//! (docs/validation.md, "The 3D thin layer under revision 2, from its checkpoint": the
//! L-box's stirred layer from its 20 s checkpoint) without rerunning the flow that led there.
//! Nothing is written. With no setting changed it says whether the file's checkpoint at the
//! last step was reproduced bit for bit, as `runner verify` would.
//!
//! Usage: cargo run --release --example step_from -- FILE.mcap --at T_S --for S
//!        [--every S] [--threads N] [--metric NAME] [KEY=VALUE ...]
//! `--at` takes the last checkpoint at or before T_S; each KEY=VALUE is a `--set` applied on
//! top of the file's own overrides (so `mps.surface_depth=0`). `--every` prints a row each
//! S seconds of simulated time (default 0.1): the mean and largest kinetic energy of the
//! fluid over the interval, the largest speed and the non-flowing share at its end, and the
//! test's metric NAME there (e.g. `filling_distance_m`; the names of the summary's metrics).
use mps_runner::experiment::{SceneSpec, experiment_metrics};
use mps_runner::manifest;
use mps_runner::mps::{ParticleKind, Solver};
use mps_runner::proto::mps::v1::StateCheckpoint;
use mps_runner::record::read_run;
use mps_runner::restore::manifest_of;
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut file = None;
    let (mut at_s, mut for_s, mut every_s, mut threads) = (0.0, 1.0, 0.1, 1usize);
    let mut sets = Vec::new();
    let mut metric = None;
    let mut i = 0;
    while i < args.len() {
        let value = |i: usize| -> f64 {
            args.get(i + 1)
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{} needs a number", args[i]))
        };
        match args[i].as_str() {
            "--at" => (at_s, i) = (value(i), i + 1),
            "--for" => (for_s, i) = (value(i), i + 1),
            "--every" => (every_s, i) = (value(i), i + 1),
            "--threads" => (threads, i) = (value(i) as usize, i + 1),
            "--metric" => {
                metric = Some(args.get(i + 1).expect("--metric needs a name").clone());
                i += 1;
            }
            a if a.starts_with("--") => panic!("unknown option {a}"),
            a if a.contains('=') => sets.push(a.to_string()),
            a => file = Some(PathBuf::from(a)),
        }
        i += 1;
    }
    let file = file.expect("a run file");
    let run = read_run(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let recorded = manifest_of(&run).unwrap_or_else(|e| panic!("{e}"));
    let mut overrides = recorded.overrides.clone();
    overrides.extend(sets);
    let resolved = manifest::from_str_as_of::<SceneSpec>(
        &recorded.source_text,
        "stored source",
        &overrides,
        recorded.default_preset,
        recorded.preset_revision,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let states = &run.states;
    let state = states
        .iter()
        .rev()
        .find(|s| s.time_s <= at_s + 1e-9)
        .expect("no checkpoint at or before --at");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let m = &resolved.manifest;
    pool.install(|| match m.dimension {
        2 => step_on::<2>(m, state, states, for_s, every_s, metric.as_deref()),
        _ => step_on::<3>(m, state, states, for_s, every_s, metric.as_deref()),
    });
}

fn step_on<const D: usize>(
    m: &mps_runner::experiment::Manifest,
    state: &StateCheckpoint,
    recorded: &[StateCheckpoint],
    for_s: f64,
    every_s: f64,
    metric: Option<&str>,
) {
    let scene = mps_runner::experiment::build_scene::<D>(m);
    let config = mps_runner::run::solver_config(m, &scene);
    let mut solver: Solver<D> = mps_runner::checkpoint::solver_from_message(config, state)
        .unwrap_or_else(|e| panic!("{e}"));
    let start = solver.time_s;
    let end = start + for_s;
    let volume = m.spacing_m.powi(D as i32);
    let kinetic = |s: &Solver<D>| -> f64 {
        let p = &s.particles;
        (0..p.len())
            .filter(|&i| p.kind[i] == ParticleKind::Fluid)
            .map(|i| 0.5 * m.fluid.density_kg_m3() * volume * p.velocity_m_s[i].norm_squared())
            .sum()
    };
    println!(
        "# from t = {start} s (step {}), {} particles",
        solver.step,
        solver.particles.len()
    );
    println!("t_s  mean_ke_j  max_ke_j  max_speed_m_s  non_flowing  steps");
    let (mut sum, mut count, mut max_ke, mut next) = (0.0, 0usize, 0.0f64, start + every_s);
    // The step as the run took it (clamped to the manifest's end time, not to ours), so that
    // nothing changed means the recorded steps; stop at the first step that reaches `end`.
    let horizon_s = m.time.end_s.max(end);
    while solver.time_s < end - 1e-9 {
        let dt = solver.next_dt_s(horizon_s);
        if let Err(e) = solver.step(dt) {
            println!("# step failed at t = {}: {e:?}", solver.time_s);
            return;
        }
        let ke = kinetic(&solver);
        sum += ke;
        count += 1;
        max_ke = max_ke.max(ke);
        if solver.time_s >= next - 1e-9 {
            let fluid: Vec<usize> = (0..solver.particles.len())
                .filter(|&i| solver.particles.kind[i] == ParticleKind::Fluid)
                .collect();
            let rigid = fluid.iter().filter(|&&i| !solver.is_flowing(i)).count();
            let shown = metric.map_or(String::new(), |name| {
                let metrics = experiment_metrics(m, &solver.particles, solver.time_s);
                match metrics.get(name) {
                    Some(v) => format!("  {name} {v:.4}"),
                    None => panic!("no metric {name:?}; the test has {:?}", metrics.keys()),
                }
            });
            println!(
                "{:.3}  {:.3e}  {:.3e}  {:.3e}  {:.3}  {}{}",
                solver.time_s,
                sum / count as f64,
                max_ke,
                solver.max_fluid_speed_m_s(),
                rigid as f64 / fluid.len().max(1) as f64,
                count,
                shown
            );
            (sum, count, max_ke) = (0.0, 0, 0.0);
            next += every_s;
        }
    }
    // With nothing changed, a recorded checkpoint at the same step must be reproduced bit for
    // bit (the replay `runner verify` does); say so, so that a changed setting is the only
    // difference a comparison sees.
    if let Some(r) = recorded.iter().find(|r| r.step == solver.step) {
        let msg = mps_runner::checkpoint::to_message(r.index, &solver, r.dt_s);
        // The checkpoint's own hash, as verify compares it: every field of the state.
        let same = msg.state_sha256 == r.state_sha256;
        println!(
            "# the file's checkpoint at step {}: {}",
            r.step,
            if same { "identical" } else { "differs" }
        );
    }
}
