//! Linear stability of the step at rest: the growth per step of the fastest-growing small
//! disturbance of a still column of water in a walled box, by matrix-free power iteration on
//! the step map (each iteration steps the rest state plus eps times the current disturbance
//! once, at a fixed dt). Above 1 the rest state is unstable. A few seconds in 2D instead of a
//! run that fails seconds of simulated time later (docs/validation.md, "Holding still").
//!
//! Usage: cargo run --release --example linear_growth -- [--dim 2|3] [--width CELLS]
//!        [--depth ROWS] [--spacing M] [--beta B] [--pair D] [--wall W] [--compression G]
//!        [--iterations N] [--dt S] [--exact 0|1]
//! Defaults: 2D, 6 cells wide, 30 rows deep, 10 mm, incremental scheme with pair 0.8,
//! wall 0.95, beta 0, compression 0 (its max(n - n0, 0) has a kink at the lattice, which a
//! difference quotient would see as a growing mode), 2000 iterations, dt 1e-3 s.
//! The state is every fluid particle's velocity, pressure and position; the rest state
//! starts from the hydrostatic pressure rho g (y_top - y), an exact fixed point.
#[path = "../tests/integration/core_setup.rs"]
mod core_setup;

use core_setup::{config, walled_box};
use mps_runner::mps::{ParticleKind, Particles, PressureScheme, Rheology, Solver};

struct Options {
    dim: usize,
    width: i64,
    depth: i64,
    spacing_m: f64,
    beta: f64,
    pair: f64,
    wall: f64,
    compression: f64,
    iterations: usize,
    dt_s: f64,
    exact: bool,
}

fn parse() -> Options {
    let mut o = Options {
        dim: 2,
        width: 6,
        depth: 30,
        spacing_m: 0.01,
        beta: 0.0,
        pair: 0.8,
        wall: 0.95,
        compression: 0.0,
        iterations: 2000,
        dt_s: 1e-3,
        exact: false,
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    for pair in args.chunks(2) {
        let value = pair
            .get(1)
            .unwrap_or_else(|| panic!("{} needs a value", pair[0]));
        let number = || -> f64 {
            value
                .parse()
                .unwrap_or_else(|_| panic!("{}: not a number: {value}", pair[0]))
        };
        match pair[0].as_str() {
            "--dim" => o.dim = number() as usize,
            "--width" => o.width = number() as i64,
            "--depth" => o.depth = number() as i64,
            "--spacing" => o.spacing_m = number(),
            "--beta" => o.beta = number(),
            "--pair" => o.pair = number(),
            "--wall" => o.wall = number(),
            "--compression" => o.compression = number(),
            "--iterations" => o.iterations = number() as usize,
            "--dt" => o.dt_s = number(),
            "--exact" => o.exact = number() != 0.0,
            other => panic!("unknown option {other}"),
        }
    }
    o
}

fn main() {
    let o = parse();
    match o.dim {
        2 => growth::<2>(&o),
        3 => growth::<3>(&o),
        d => panic!("--dim must be 2 or 3, got {d}"),
    }
}

fn growth<const D: usize>(o: &Options) {
    let l0 = o.spacing_m;
    let cells: [i64; D] = std::array::from_fn(|a| if a + 1 == D { o.depth + 4 } else { o.width });
    let (mut particles, lo, hi) = walled_box::<D>(l0, cells, o.depth);
    let mut cfg = config::<D>(l0, lo, hi);
    cfg.rheology = Rheology::Newtonian {
        viscosity_pa_s: 1e-3,
    };
    cfg.pressure_scheme = PressureScheme::Incremental;
    cfg.pair_stabilisation_m = o.pair * l0;
    cfg.wall_support_m = o.wall * l0;
    cfg.pressure_regularisation = o.beta;
    cfg.compression_relaxation = o.compression;
    cfg.exact_projection = o.exact;
    let fluid: Vec<usize> = (0..particles.len())
        .filter(|&i| particles.kind[i] == ParticleKind::Fluid)
        .collect();
    let top = fluid
        .iter()
        .map(|&i| particles.position_m[i][D - 1])
        .fold(f64::MIN, f64::max);
    let rho_g = cfg.density_kg_m3 * cfg.gravity_m_s2;
    for &i in &fluid {
        particles.pressure_pa[i] = rho_g * (top - particles.position_m[i][D - 1]);
    }
    // Per fluid particle: velocity (m/s), pressure (kPa), position (mm): comparable scales.
    let per = 2 * D + 1;
    let pack = |p: &Particles<D>| -> Vec<f64> {
        let mut x = vec![0.0; per * fluid.len()];
        for (k, &i) in fluid.iter().enumerate() {
            for a in 0..D {
                x[per * k + a] = p.velocity_m_s[i][a];
                x[per * k + D + 1 + a] = p.position_m[i][a] * 1e3;
            }
            x[per * k + D] = p.pressure_pa[i] * 1e-3;
        }
        x
    };
    let step = |x: &[f64]| -> Vec<f64> {
        let mut p = particles.clone();
        for (k, &i) in fluid.iter().enumerate() {
            for a in 0..D {
                p.velocity_m_s[i][a] = x[per * k + a];
                p.position_m[i][a] = x[per * k + D + 1 + a] * 1e-3;
            }
            p.pressure_pa[i] = x[per * k + D] * 1e3;
        }
        let mut solver = Solver::new(cfg.clone(), p);
        solver.step(o.dt_s).expect("a step from near rest");
        pack(&solver.particles)
    };
    let x0 = pack(&particles);
    let f0 = step(&x0);
    let residual = x0
        .iter()
        .zip(&f0)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    println!(
        "{}D column {} x {} rows at {} m, beta {}: {} fluid particles; rest-state residual {residual:.1e}",
        D,
        o.width,
        o.depth,
        l0,
        o.beta,
        fluid.len()
    );
    // A fixed pseudo-random start: the result does not depend on it once converged.
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let mut v: Vec<f64> = (0..x0.len())
        .map(|k| ((k * 7919) % 13) as f64 - 6.0)
        .collect();
    let n = norm(&v);
    v.iter_mut().for_each(|a| *a /= n);
    let eps = 1e-6;
    let mut log_growth = 0.0;
    let last = o.iterations / 4;
    for it in 0..o.iterations {
        let probe: Vec<f64> = x0.iter().zip(&v).map(|(a, b)| a + eps * b).collect();
        let mut w: Vec<f64> = step(&probe)
            .iter()
            .zip(&f0)
            .map(|(a, b)| (a - b) / eps)
            .collect();
        let n = norm(&w);
        if it >= o.iterations - last {
            log_growth += n.ln();
        }
        w.iter_mut().for_each(|a| *a /= n);
        v = w;
    }
    let growth = (log_growth / last as f64).exp();
    // A neutral mode with a Jordan block (a free translation) reads slightly above 1 after
    // N iterations: about (N / (0.75 N))^(1 / (0.25 N)).
    let neutral = (1.0f64 / 0.75).powf(1.0 / last as f64);
    println!("growth per step {growth:.6} (a neutral drift reads up to {neutral:.6})");
    let mut parts: Vec<(f64, usize)> = v.iter().enumerate().map(|(c, a)| (a.abs(), c)).collect();
    parts.sort_by(|a, b| b.0.total_cmp(&a.0));
    let names = ["velocity", "pressure", "position"];
    for &(a, c) in parts.iter().take(6) {
        let i = fluid[c / per];
        let part = c % per;
        let name = if part < D {
            names[0]
        } else if part == D {
            names[1]
        } else {
            names[2]
        };
        let axis = if part < D {
            part
        } else if part > D {
            part - D - 1
        } else {
            0
        };
        println!(
            "  particle {i} at {:?} mm: {name}{} {a:.3}",
            particles.position_m[i]
                .iter()
                .map(|x| (x * 1e3).round())
                .collect::<Vec<_>>(),
            if part == D {
                String::new()
            } else {
                format!("[{axis}]")
            },
        );
    }
}
