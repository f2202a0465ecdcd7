//! `runner calibrate CALIBRATION`: back-calculate manifest values (the yield stress) from
//! measured results. Prints the plan and one line per run on stderr, the fitted values and
//! the figures; the record's path on stdout. Exit 0 fitted, 2 bad input, 3 not fitted, 130
//! interrupted, 1 the record cannot be written.

use crate::cli::CalibrateArgs;
use crate::error::{CliError, Done, Result};
use crate::interrupt;
use mps_runner::calibrate::{self, CalibrateOptions, Evaluation, Fit, Plan, Record, Stage};

pub fn command(args: CalibrateArgs) -> Result {
    let plan = calibrate::load(&args.calibration)?;
    print_plan(&plan);
    let options = CalibrateOptions {
        out_dir: args.out,
        interrupt: interrupt::flag(),
        max_particles: Some(args.max_particles),
    };
    let on_run = |fit: &Fit, stage: &Stage, e: &Evaluation| print_run(&plan, fit, stage, e);
    let (dir, record, result) = calibrate::calibrate(&plan, &options, &on_run);
    // The record is written whatever the result: a calibration run again goes on from it.
    let (json, figures) = calibrate::write_record(&dir, &record).map_err(|e| {
        CliError::Internal(format!(
            "cannot write the calibration record in {}: {e}",
            dir.display()
        ))
    })?;
    print_fits(&plan, &record);
    for figure in &figures {
        eprintln!("figure: {}", figure.display());
    }
    println!("{}", json.display());
    result?;
    Ok(Done::Success)
}

/// What is fitted to what, and how many runs a round takes.
fn print_plan(plan: &Plan) {
    for pair in &plan.pairs {
        eprintln!(
            "{}: fitting {} in [{}, {}] to {} = {} (tolerance {})",
            plan.calibration.name,
            pair.parameter,
            pair.bounds[0],
            pair.bounds[1],
            pair.metric,
            pair.measured,
            pair.tolerance,
        );
    }
    eprintln!(
        "{} run(s) per round{}",
        plan.calibration.points_per_round,
        if plan.pairs.len() > 1 {
            ", alternating one value at a time in the order above"
        } else {
            ""
        }
    );
}

/// One line per run: where in the search it is, the values it ran, what it measured.
fn print_run(plan: &Plan, fit: &Fit, stage: &Stage, e: &Evaluation) {
    let held: String = stage
        .held
        .iter()
        .map(|(k, v)| format!(", {k} = {v}"))
        .collect();
    let metrics: Vec<String> = plan
        .pairs
        .iter()
        .map(|q| {
            let m = e.metrics[&q.metric];
            format!("{} = {:.5} (off by {:+.5})", q.metric, m, m - q.measured)
        })
        .collect();
    eprintln!(
        "  [spacing {} m, pass {}, round {}] {} = {}{} -> {}; {} {}, {}",
        fit.spacing_m,
        stage.alternation,
        e.round,
        stage.parameter,
        e.values[&stage.parameter],
        held,
        metrics.join(", "),
        e.start,
        e.outcome,
        e.file
    );
}

/// Per spacing: the bracket and the fitted value of each parameter; then how much the
/// fitted values differ between spacings.
fn print_fits(plan: &Plan, record: &Record) {
    for fit in &record.fits {
        for pair in &plan.pairs {
            if let Some(b) = fit.brackets.get(&pair.parameter) {
                eprintln!(
                    "spacing {} m: bracket {} in [{}, {}]",
                    fit.spacing_m, pair.parameter, b[0], b[1]
                );
            }
            if let Some(f) = fit.fitted.get(&pair.parameter) {
                eprintln!(
                    "spacing {} m: fitted {} = {:.4} (log-log interpolation in the bracket){}",
                    fit.spacing_m,
                    pair.parameter,
                    f,
                    if fit.converged {
                        ""
                    } else {
                        " (not every measured value met within its tolerance)"
                    }
                );
            }
        }
    }
    for (parameter, share) in &record.resolution_share {
        eprintln!(
            "resolution: the fitted {parameter} at the two spacings differ by {:.1} %",
            100.0 * share
        );
    }
}
