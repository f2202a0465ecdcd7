//! The commands that read a run file (or a folder of them) as text: `runner info` (what it
//! holds) and `runner export` (its tables as CSV or JSON).

use crate::cli::{ExportArgs, InfoArgs};
use crate::error::{CliError, Done, Result};
use crate::run_file::{incomplete_or_refused, readable_run};
use mps_runner::report;
use mps_runner::report::export::{export_dir, export_file};
use std::path::Path;

/// `runner info`: a finished file or a `.partial` (damaged or not, with a warning) is
/// described, exit 0; a file named finished without its end is described with what it
/// misses, then refused (exit 2, as verify does); an unusable one is refused (exit 2).
pub fn info(args: InfoArgs) -> Result {
    let incomplete = incomplete_or_refused(&args.file)?;
    let info = report::info::info(&args.file)?;
    if args.json {
        let text =
            serde_json::to_string_pretty(&info).map_err(|e| CliError::Internal(e.to_string()))?;
        println!("{text}");
    } else {
        print!("{info}");
    }
    match incomplete {
        Some(why) => Err(CliError::BadInput(why)),
        None => Ok(Done::Success),
    }
}

/// `runner export`: a run file as its diagnostics (or with `--summary` its one-row
/// summary), a folder as one summary row per finished run file; CSV (`--csv`) or JSON, to
/// stdout or `--out`. A run file is taken as plot takes it (`readable_run`).
pub fn export(args: ExportArgs) -> Result {
    let (path, csv) = (args.path.as_path(), args.csv);
    let text = if path.is_dir() {
        export_folder(path, csv)?
    } else {
        export_run(path, csv, args.summary)?
    };
    match args.out {
        None => print!("{text}"),
        Some(out) => {
            std::fs::write(&out, text)
                .map_err(|e| CliError::Internal(format!("cannot write {}: {e}", out.display())))?;
            println!("{}", out.display());
        }
    }
    Ok(Done::Success)
}

/// A folder: one summary row per finished run file; the files left out are named on stderr
/// (and in the JSON).
fn export_folder(path: &Path, csv: bool) -> Result<String> {
    let (table, skipped) = export_dir(path)?;
    for (file, why) in &skipped {
        eprintln!("skipped {}: {why}", file.display());
    }
    Ok(if csv {
        table.to_csv()
    } else {
        let mut value = table.to_json();
        value["dir"] = path.display().to_string().into();
        value["skipped"] = skipped
            .iter()
            .map(|(f, why)| serde_json::json!({"file": f.display().to_string(), "reason": why}))
            .collect();
        value.to_string() + "\n"
    })
}

/// A run file: its diagnostics, or its summary row; the JSON of both names the file.
fn export_run(path: &Path, csv: bool, summary: bool) -> Result<String> {
    readable_run(path)?;
    let (diagnostics, summary_row) = export_file(path)?;
    Ok(match (csv, summary) {
        (true, false) => diagnostics.to_csv(),
        (true, true) => summary_row.to_csv(),
        (false, true) => summary_row.to_json().to_string() + "\n",
        (false, false) => {
            serde_json::json!({
                "file": path.display().to_string(),
                "diagnostics": diagnostics.to_json(),
                "summary": summary_row.to_json(),
            })
            .to_string()
                + "\n"
        }
    })
}
