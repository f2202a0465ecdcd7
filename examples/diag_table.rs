//! Prints a run's diagnostics (time, kinetic energy, non-flowing share and every experiment
//! metric) as a table, then its summary: `cargo run --release --example diag_table RUN.mcap`.
use mps_runner::record::read_run;

fn main() {
    let path = std::env::args().nth(1).expect("usage: diag_table RUN.mcap");
    let run = read_run(std::path::Path::new(&path)).expect("readable run");
    if let Some(first) = run.diagnostics.first() {
        let names: Vec<&String> = first.metrics.keys().collect();
        print!(
            "{:>8} {:>6} {:>11} {:>6} {:>5} {:>5}",
            "t_s", "step", "kinetic_j", "nonfl", "ppe", "visc"
        );
        for n in &names {
            print!(" {:>12}", n.trim_end_matches("_m"));
        }
        println!();
        for d in &run.diagnostics {
            print!(
                "{:>8.3} {:>6} {:>11.4e} {:>6.3} {:>5} {:>5}",
                d.time_s,
                d.step,
                d.kinetic_energy_j,
                d.non_flowing_fraction,
                d.ppe_iterations,
                d.viscosity_iterations
            );
            for n in &names {
                print!(" {:>12.4}", d.metrics.get(*n).copied().unwrap_or(f64::NAN));
            }
            println!();
        }
    }
    if std::env::var("WHERE").is_ok() {
        where_are(&run);
    }
    if let Some(s) = &run.summary {
        println!("outcome {} {}", s.outcome, s.reason);
        for (k, v) in &s.metrics {
            println!("  {k} = {v}");
        }
    }
}

/// Where the fluid and ghost particles are at each checkpoint (debugging aid).
#[allow(dead_code)]
pub fn where_are(run: &mps_runner::record::RunFile) {
    for s in &run.states {
        let d = s.dimension as usize;
        let mut line = format!("t={:.2}", s.time_s);
        for kind in [0u32, 3] {
            let (mut n, mut zmin, mut zmax, mut rmax) = (0, f64::MAX, f64::MIN, 0.0f64);
            for (i, &k) in s.kind.iter().enumerate() {
                if k == kind {
                    let x = &s.position_m[i * d..i * d + d];
                    n += 1;
                    zmin = zmin.min(x[d - 1]);
                    zmax = zmax.max(x[d - 1]);
                    rmax = rmax.max((x[0] * x[0] + x[1] * x[1]).sqrt());
                }
            }
            line += &format!("  kind{kind}: n={n} z=[{zmin:.3},{zmax:.3}] rmax={rmax:.3}");
            if kind == 0 {
                let high = (0..s.kind.len())
                    .filter(|&i| s.kind[i] == 0 && s.position_m[i * d + d - 1] > 0.1)
                    .count();
                line += &format!(" above0.1m={high}");
            }
        }
        println!("{line}");
    }
}
