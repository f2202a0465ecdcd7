//! `runner verify FILE`: replay a run from the manifest it stores and compare every
//! checkpoint bit for bit; `runner verify --trend DIR`: check that a metric falls as a
//! manifest value rises across the runs in DIR. Exit 0 identical (holds), 1 not, 2 the file
//! (or folder) cannot be used.

use crate::cli::VerifyArgs;
use crate::error::{CliError, Done, Result};
use crate::progress;
use crate::run_file::incomplete_or_refused;
use mps_runner::verify::trend::{TrendOptions, trend};
use mps_runner::verify::{VerifyOptions, verify};
use std::path::Path;

pub fn command(args: VerifyArgs) -> Result {
    if let Some(dir) = &args.trend {
        return trend_command(dir, &args.x_key, args.y_metric);
    }
    let file = args.file.expect("clap requires FILE without --trend");
    // An incomplete file still has its checkpoints replayed, but is not called verified.
    let incomplete = incomplete_or_refused(&file)?;
    let display = progress::Display::new(args.quiet);
    let options = VerifyOptions {
        from: args.from,
        to: args.to,
        threads: args.threads,
        progress: display.as_ref().map(|d| d.callback()),
    };
    let verified = verify(&file, &options);
    if let Some(d) = &display {
        d.finish_all();
    }
    let report = verified?;
    if let Some(w) = &report.build_warning {
        eprintln!("warning: {w}");
    }
    println!("{report}");
    if args.print_hashes {
        for h in &report.hashes {
            println!("{} {} {:e} {}", h.index, h.step, h.time_s, h.state_sha256);
        }
    }
    if let Some(why) = incomplete {
        // The checkpoints it still holds were replayed, but it is not the whole run.
        Err(CliError::BadInput(why))
    } else if report.passed() {
        Ok(Done::Success)
    } else {
        Ok(Done::Mismatch)
    }
}

/// `--trend DIR`: one report per `--y` metric (the test's own by default), a blank line
/// between them; every one must hold.
fn trend_command(dir: &Path, x_key: &str, y_metrics: Vec<String>) -> Result {
    let metrics: Vec<Option<String>> = if y_metrics.is_empty() {
        vec![None]
    } else {
        y_metrics.into_iter().map(Some).collect()
    };
    let mut all_passed = true;
    for (k, y_metric) in metrics.into_iter().enumerate() {
        let options = TrendOptions {
            x_key: x_key.to_string(),
            y_metric,
        };
        let report = trend(dir, &options).map_err(CliError::BadInput)?;
        if k > 0 {
            println!();
        }
        println!("{report}");
        all_passed &= report.passed();
    }
    Ok(if all_passed {
        Done::Success
    } else {
        Done::Mismatch
    })
}
