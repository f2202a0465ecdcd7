//! Takes a recorded 3D or 2D run up from one of its checkpoints with settings changed, and
//! steps it on, printing the fluid's kinetic energy, its largest speed and its non-flowing
//! share as it goes. The cheap way to ask "what does this one setting do to that state"
//! (docs/validation.md, "The 3D thin layer under revision 2, from its checkpoint": the
//! L-box's stirred layer from its 20 s checkpoint) without rerunning the flow that led there.
//! Nothing is written. With no setting changed it says whether the file's checkpoint at the
//! last step was reproduced bit for bit, as `runner verify` would.
//!
//! Usage: cargo run --release --example step_from -- FILE.mcap --at T_S --for S
//!        [--every S] [--threads N] [--metric NAME] [--watch I] [KEY=VALUE ...]
//! `--at` takes the last checkpoint at or before T_S; each KEY=VALUE is a `--set` applied on
//! top of the file's own overrides (so `mps.surface_depth=0`). `--every` prints a row each
//! S seconds of simulated time (default 0.1): the mean and largest kinetic energy of the
//! fluid over the interval, the largest speed and the non-flowing share at its end, the
//! test's metric NAME there (e.g. `filling_distance_m`; the names of the summary's metrics),
//! and with a yield solve its iterations a step (`yield_it` mean/largest: a solve at its cap,
//! `mps.yield_max_iterations`, every step has not converged).
//! `--stage-momentum BAND_M --area A_M2` also sums what each stage of the step does to the
//! fluid's momentum along x in bands of height BAND_M ([`mps_runner::mps::StageMomentum`]) and
//! prints, per band, each stage's force on the band and, summed from the top down, the shear
//! stress it carries across the band's floor, both in Pa over the area A_M2 of a band (the
//! period in 2D, per metre of depth; period times width in 3D), and each stage's force on
//! the whole fluid (docs/validation.md, "A disordered layer on an incline").
//! `--watch I` prints particle I after every step: its position, velocity and pressure, and
//! its nearest neighbour (distance in spacings, kind): how a single particle blows up.
//! `--where` prints, at the end, where the fluid moves and where its number density sits
//! below the surface threshold (bands of distance to the walls, of height; [`locate`]): how
//! the rock bed's residual stir was traced to the free surface flagged inside the concrete
//! (docs/validation.md, "The rock bed's residual stir"). Each row also gives the fluid's
//! centre-of-mass height (`com_z`) and its carried pressure's excess over the hydrostatic
//! one under the highest fluid particle (`p_excess`: mean, 1st and 99th percentiles; under a
//! flat top only).
use mps_runner::experiment::{SceneSpec, experiment_metrics};
use mps_runner::manifest;
use mps_runner::mps::grid::{Neighbours, entry_index};
use mps_runner::mps::kernel::weight;
use mps_runner::mps::operators::number_density;
use mps_runner::mps::{ParticleKind, STAGE_NAMES, Solver, StageMomentum};
use mps_runner::proto::mps::v1::StateCheckpoint;
use mps_runner::record::read_run;
use mps_runner::restore::manifest_of;
use std::path::PathBuf;

/// How far to step on and what to print.
struct Plan {
    for_s: f64,
    every_s: f64,
    metric: Option<String>,
    /// `--stage-momentum`'s band height, and `--area`.
    band_m: Option<f64>,
    area_m2: f64,
    /// `--watch`: the particle traced after every step.
    watch: Option<usize>,
    /// `--where`: the breakdown of the fluid's motion at the end.
    locate: bool,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut file = None;
    let (mut at_s, mut threads) = (0.0, 1usize);
    let mut plan = Plan {
        for_s: 1.0,
        every_s: 0.1,
        metric: None,
        band_m: None,
        area_m2: 1.0,
        watch: None,
        locate: false,
    };
    let mut sets = Vec::new();
    let mut i = 0;
    while i < args.len() {
        let value = |i: usize| -> f64 {
            args.get(i + 1)
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{} needs a number", args[i]))
        };
        match args[i].as_str() {
            "--at" => (at_s, i) = (value(i), i + 1),
            "--for" => (plan.for_s, i) = (value(i), i + 1),
            "--every" => (plan.every_s, i) = (value(i), i + 1),
            "--threads" => (threads, i) = (value(i) as usize, i + 1),
            "--stage-momentum" => (plan.band_m, i) = (Some(value(i)), i + 1),
            "--area" => (plan.area_m2, i) = (value(i), i + 1),
            "--watch" => (plan.watch, i) = (Some(value(i) as usize), i + 1),
            "--where" => plan.locate = true,
            "--metric" => {
                plan.metric = Some(args.get(i + 1).expect("--metric needs a name").clone());
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
        2 => step_on::<2>(m, state, states, &plan),
        _ => step_on::<3>(m, state, states, &plan),
    });
}

fn step_on<const D: usize>(
    m: &mps_runner::experiment::Manifest,
    state: &StateCheckpoint,
    recorded: &[StateCheckpoint],
    plan: &Plan,
) {
    let (for_s, every_s, metric) = (plan.for_s, plan.every_s, plan.metric.as_deref());
    let scene = mps_runner::experiment::build_scene::<D>(m);
    let config = mps_runner::run::solver_config(m, &scene);
    let mut solver: Solver<D> = mps_runner::checkpoint::solver_from_message(config, state)
        .unwrap_or_else(|e| panic!("{e}"));
    let start = solver.time_s;
    let first_step = solver.step;
    let end = start + for_s;
    if let Some(band_m) = plan.band_m {
        let top = solver
            .particles
            .position_m
            .iter()
            .fold(0.0f64, |top, x| top.max(x[D - 1]));
        let bands = ((2.0 * top / band_m).ceil() as usize).clamp(1, 4096);
        solver.stage_momentum = Some(StageMomentum::new(0, band_m, bands));
    }
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
    // The yield solve's iterations a step over the interval (mean, largest): a solve held at
    // its cap every step has not converged.
    let (mut yield_sum, mut yield_max) = (0u64, 0u32);
    // The step as the run took it (clamped to the manifest's end time, not to ours), so that
    // nothing changed means the recorded steps; stop at the first step that reaches `end`. An
    // `end` that is the manifest's own but for the round-off of the checkpoint's time (a run
    // taken up to its last checkpoint) is the manifest's: its last step lands there.
    let horizon_s = if end <= m.time.end_s * (1.0 + 1e-9) {
        m.time.end_s
    } else {
        end
    };
    while solver.time_s < end - 1e-9 {
        let dt = solver.next_dt_s(horizon_s);
        let stepped = solver.step(dt);
        if let Some(w) = plan.watch {
            watch(&solver, w, m.spacing_m);
        }
        let report = match stepped {
            Ok(report) => report,
            Err(e) => {
                println!("# step failed at t = {}: {e:?}", solver.time_s);
                return;
            }
        };
        yield_sum += u64::from(report.yield_iterations);
        yield_max = yield_max.max(report.yield_iterations);
        let ke = kinetic(&solver);
        sum += ke;
        count += 1;
        max_ke = max_ke.max(ke);
        if solver.time_s >= next - 1e-9 {
            let fluid: Vec<usize> = (0..solver.particles.len())
                .filter(|&i| solver.particles.kind[i] == ParticleKind::Fluid)
                .collect();
            let rigid = fluid.iter().filter(|&&i| !solver.is_flowing(i)).count();
            // The fluid's centre of mass height: a settling or swelling mass.
            let com_m = fluid
                .iter()
                .map(|&i| solver.particles.position_m[i][D - 1])
                .sum::<f64>()
                / fluid.len().max(1) as f64;
            let shown = metric.map_or(String::new(), |name| {
                let metrics = experiment_metrics(m, &solver.particles, solver.time_s);
                match metrics.get(name) {
                    Some(v) => format!("  {name} {v:.4}"),
                    None => panic!("no metric {name:?}; the test has {:?}", metrics.keys()),
                }
            });
            let excess = pressure_excess(&solver, &fluid, m);
            let yield_iterations = if yield_max > 0 {
                format!(
                    "  yield_it {:.1}/{yield_max}",
                    yield_sum as f64 / count as f64
                )
            } else {
                String::new()
            };
            println!(
                "{:.3}  {:.3e}  {:.3e}  {:.3e}  {:.3}  {}  com_z {com_m:.6}{}{excess}{yield_iterations}",
                solver.time_s,
                sum / count as f64,
                max_ke,
                solver.max_fluid_speed_m_s(),
                rigid as f64 / fluid.len().max(1) as f64,
                count,
                shown
            );
            (sum, count, max_ke) = (0.0, 0, 0.0);
            (yield_sum, yield_max) = (0, 0);
            next += every_s;
        }
    }
    if let Some(sums) = &solver.stage_momentum {
        print_stage_momentum(sums, m, plan.area_m2);
    }
    if plan.locate {
        locate(&solver, m.spacing_m);
    }
    print_cost(&solver.timing, solver.step - first_step);
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

/// The carried pressure against the hydrostatic one under the fluid's highest particle,
/// p - rho g (z_top - z): its mean, and its 1st and 99th percentiles, in Pa. A pressure
/// that the material holds against its yield stress, and how it builds up. It means
/// something only under a flat top (a layer, a tank, a filled bed); under a heap or a
/// slump it measures from the heap's summit.
fn pressure_excess<const D: usize>(
    solver: &Solver<D>,
    fluid: &[usize],
    m: &mps_runner::experiment::Manifest,
) -> String {
    let p = &solver.particles;
    if fluid.is_empty() {
        return String::new();
    }
    let top = highest(&p.position_m, fluid.iter().copied());
    let rho_g = m.fluid.density_kg_m3() * m.gravity_m_s2;
    let mut excess: Vec<f64> = fluid
        .iter()
        .map(|&i| p.pressure_pa[i] - rho_g * (top - p.position_m[i][D - 1]))
        .collect();
    let mean = excess.iter().sum::<f64>() / excess.len() as f64;
    excess.sort_by(f64::total_cmp);
    let at = |q: f64| excess[((excess.len() - 1) as f64 * q).round() as usize];
    format!(
        "  p_excess mean {mean:.1} p1 {:.1} p99 {:.1} Pa",
        at(0.01),
        at(0.99)
    )
}

/// The height (last coordinate) of the highest of the particles `indices`.
fn highest<const D: usize>(
    position_m: &[mps_runner::mps::Vector<D>],
    indices: impl Iterator<Item = usize>,
) -> f64 {
    indices.fold(f64::MIN, |top, i| top.max(position_m[i][D - 1]))
}

/// What the steps cost, stage by stage (wall seconds, CG iterations a step; the rows of
/// `runner bench`): the way to compare solver settings on one recorded state.
fn print_cost(t: &mps_runner::mps::StageTimes, steps: u64) {
    println!("# cost of {steps} steps: {:.3} s", t.step_total_s);
    for (name, seconds) in t.stage_rows(steps as f64) {
        println!("#   {name:<46} {seconds:>9.3}");
    }
}

/// One line on particle `w` after a step: time, step, position, velocity, pressure, and its
/// nearest other particle (distance in spacings, kind). A linear search: a trace, not a loop.
fn watch<const D: usize>(solver: &Solver<D>, w: usize, spacing_m: f64) {
    let p = &solver.particles;
    assert!(
        w < p.len(),
        "--watch {w}: the run has {} particles",
        p.len()
    );
    let x = p.position_m[w];
    let nearest = (0..p.len())
        .filter(|&j| j != w)
        .map(|j| ((p.position_m[j] - x).norm(), j))
        .min_by(|a, b| a.0.total_cmp(&b.0));
    let near = nearest.map_or(String::from("none"), |(r, j)| {
        format!("{:.3} l0 ({:?} {j})", r / spacing_m, p.kind[j])
    });
    println!(
        "watch t {:.5} step {} {:?} x {:?} v {:?} |v| {:.3e} p {:.1} nearest {near}",
        solver.time_s,
        solver.step,
        p.kind[w],
        x.as_slice(),
        p.velocity_m_s[w].as_slice(),
        p.velocity_m_s[w].norm(),
        p.pressure_pa[w],
    );
}

/// Each stage's force on each band (Pa over `area_m2`: rho V sum du / (T A)) and, summed from
/// the top down, the shear stress it carries across the band's floor; then its force on the
/// whole fluid.
fn print_stage_momentum(sums: &StageMomentum, m: &mps_runner::experiment::Manifest, area_m2: f64) {
    let volume = m.spacing_m.powi(m.dimension as i32);
    let scale = m.fluid.density_kg_m3() * volume / (sums.time_s * area_m2);
    let used: Vec<usize> = (0..sums.particle_steps.len())
        .filter(|&b| sums.particle_steps[b] > 0.0)
        .collect();
    println!(
        "# stage momentum over {:.4} s, bands of {} m; force on the band, Pa",
        sums.time_s, sums.band_m
    );
    println!("band  y_m  particles  {}", STAGE_NAMES.join("  "));
    for &b in &used {
        let forces: Vec<String> = sums.change_m_s[b]
            .iter()
            .map(|c| format!("{:.3}", c * scale))
            .collect();
        println!(
            "{b}  {:.4}  {:.1}  {}",
            b as f64 * sums.band_m,
            sums.particle_steps[b] / sums.steps.max(1) as f64,
            forces.join("  ")
        );
    }
    println!(
        "# shear stress across the band's floor (the stage's force on every band above it), Pa"
    );
    println!("band  y_m  {}", STAGE_NAMES.join("  "));
    let mut above = [0.0; STAGE_NAMES.len()];
    let mut rows = Vec::new();
    for &b in used.iter().rev() {
        for (a, c) in above.iter_mut().zip(&sums.change_m_s[b]) {
            *a += c * scale;
        }
        let text: Vec<String> = above.iter().map(|a| format!("{a:.3}")).collect();
        rows.push(format!(
            "{b}  {:.4}  {}",
            b as f64 * sums.band_m,
            text.join("  ")
        ));
    }
    for row in rows.iter().rev() {
        println!("{row}");
    }
    let whole: Vec<String> = STAGE_NAMES
        .iter()
        .zip(&above)
        .map(|(n, a)| format!("{n} {a:.3}"))
        .collect();
    println!("# on the whole fluid, Pa: {}", whole.join(", "));
}

/// One fluid particle as `--where` sees it.
struct Spot {
    index: usize,
    /// Distance to the nearest wall or dummy particle, in spacings (4 when none is nearer).
    wall_l0: f64,
    /// n/n0 with the number density's radius, at the current positions.
    density: f64,
    /// |sum_j w_ij r_ij| / sum_j w_ij in spacings: how lopsided the neighbours are (about
    /// 0.4 on a flat free surface, under 0.1 inside).
    deviation_l0: f64,
    speed_m_s: f64,
    flowing: bool,
}

/// Where the fluid moves (`--where`), at the current positions: per band of distance to the
/// nearest wall or dummy particle, the particles, their mean and largest speed, flowing
/// share, mean n/n0 and how many are below the surface threshold (and of those, how many lie
/// deeper than three spacings under the highest fluid particle: the free surface flagged
/// inside the fluid); the centroid deviation of those below the threshold; the mean velocity
/// over all the fluid and in height bands (a settling or swelling mass against a noise that
/// averages out); the ten fastest particles. Neighbours through a periodic boundary or a
/// mirror plane are not counted: there the densities read low.
fn locate<const D: usize>(solver: &Solver<D>, spacing_m: f64) {
    let p = &solver.particles;
    let (re, n0) = (solver.refs.radius_n_m, solver.refs.n0);
    let fluid = |i: usize| p.kind[i] == ParticleKind::Fluid;
    // Four spacings: the wall distance is reported up to there, and the number density's
    // radius lies inside.
    let nb = Neighbours::build_centres(
        &p.position_m,
        4.0 * spacing_m,
        |i| p.kind[i] != ParticleKind::Ghost,
        fluid,
    );
    let mut spots: Vec<Spot> = (0..p.len())
        .filter(|&i| fluid(i))
        .map(|i| {
            let (mut wall_l0, mut centroid) = (4.0f64, mps_runner::mps::Vector::<D>::zeros());
            for &e in nb.of(i) {
                let r = nb.displacement(&p.position_m, i, e);
                if !fluid(entry_index(e)) {
                    wall_l0 = wall_l0.min(r.norm() / spacing_m);
                }
                centroid += r * weight(r.norm(), re);
            }
            let n = number_density(&p.position_m, &nb, i, re, |_| true);
            Spot {
                index: i,
                wall_l0,
                density: n / n0,
                deviation_l0: if n > 0.0 {
                    centroid.norm() / n / spacing_m
                } else {
                    f64::INFINITY
                },
                speed_m_s: p.velocity_m_s[i].norm(),
                flowing: solver.is_flowing(i),
            }
        })
        .collect();
    let threshold = solver.config.surface_threshold;
    let top_m = highest(&p.position_m, spots.iter().map(|s| s.index));
    let deep = |s: &Spot| p.position_m[s.index][D - 1] < top_m - 3.0 * spacing_m;
    println!(
        "# wall distance (l0): particles  mean_speed_m_s  max_speed_m_s  flowing  mean_n/n0  \
         below_{threshold}  of_them_deep"
    );
    for band in 0..5 {
        let sel: Vec<&Spot> = spots
            .iter()
            .filter(|s| (s.wall_l0.floor() as usize).min(4) == band)
            .collect();
        if sel.is_empty() {
            continue;
        }
        let count = sel.len() as f64;
        let mean = sel.iter().map(|s| s.speed_m_s).sum::<f64>() / count;
        let max = sel.iter().map(|s| s.speed_m_s).fold(0.0, f64::max);
        let flowing = sel.iter().filter(|s| s.flowing).count() as f64 / count;
        let density = sel.iter().map(|s| s.density).sum::<f64>() / count;
        let below: Vec<&&Spot> = sel.iter().filter(|s| s.density < threshold).collect();
        let below_deep = below.iter().filter(|s| deep(s)).count();
        println!(
            "#   {:<8} {:>7} {mean:.3e} {max:.3e} {flowing:.3} {density:.4} {} {below_deep}",
            if band < 4 {
                format!("[{band},{})", band + 1)
            } else {
                ">=4".into()
            },
            sel.len(),
            below.len()
        );
    }
    let mut histogram = [0usize; 8];
    for s in spots.iter().filter(|s| s.density < threshold) {
        histogram[((s.deviation_l0 / 0.05) as usize).min(7)] += 1;
    }
    println!(
        "# centroid deviation below the threshold, bins of 0.05 l0 (last: 0.35 up): {histogram:?}"
    );
    let mean_velocity = |sel: &[&Spot]| {
        sel.iter()
            .map(|s| p.velocity_m_s[s.index])
            .fold(mps_runner::mps::Vector::<D>::zeros(), |a, v| a + v)
            / sel.len().max(1) as f64
    };
    let all: Vec<&Spot> = spots.iter().collect();
    println!(
        "# mean velocity of the fluid {:?} m/s",
        mean_velocity(&all).as_slice()
    );
    let band_m = 2.0 * spacing_m;
    let height_band = |s: &Spot| (p.position_m[s.index][D - 1] / band_m).floor() as i64;
    let (low, high) = spots.iter().fold((i64::MAX, i64::MIN), |(l, h), s| {
        (l.min(height_band(s)), h.max(height_band(s)))
    });
    for b in low..=high {
        let sel: Vec<&Spot> = spots.iter().filter(|s| height_band(s) == b).collect();
        if !sel.is_empty() {
            let rms =
                (sel.iter().map(|s| s.speed_m_s.powi(2)).sum::<f64>() / sel.len() as f64).sqrt();
            println!(
                "#   height {:.3} m: {} particles, mean velocity {:?}, rms speed {rms:.3e}",
                b as f64 * band_m,
                sel.len(),
                mean_velocity(&sel).as_slice()
            );
        }
    }
    spots.sort_by(|a, b| b.speed_m_s.total_cmp(&a.speed_m_s));
    println!("# fastest: index  x_m  speed_m_s  wall_l0  n/n0  deviation_l0  flowing");
    for s in spots.iter().take(10) {
        println!(
            "#   {} {:?} {:.3e} {:.2} {:.3} {:.3} {}",
            s.index,
            p.position_m[s.index].as_slice(),
            s.speed_m_s,
            s.wall_l0,
            s.density,
            s.deviation_l0,
            s.flowing
        );
    }
}
