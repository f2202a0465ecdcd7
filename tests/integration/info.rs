//! `runner info` and `runner export`: what a run file holds, as text and JSON, and its data as
//! CSV and JSON, for a finished run, a sweep folder and a killed or cut file.
use crate::common;
use mps_runner::record::{check_run, read_run};
use serde_json::Value;
use std::path::{Path, PathBuf};

use common::runner_all as runner;

/// A finished smoke_2d run in `dir`.
fn smoke(dir: &Path) -> PathBuf {
    common::run_completed(&common::resolve("smoke_2d.yaml", &[]), dir, 1).path
}

/// Header and rows of CSV without quoted fields (all that these tables hold).
fn parse_csv(text: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    for r in &rows {
        assert_eq!(r.len(), header.len(), "every row has every column: {r:?}");
    }
    (header, rows)
}

fn column(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

#[test]
fn info_of_a_finished_run_as_text_and_json() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke(dir.path());
    let run = read_run(&path).unwrap();
    let summary = run.summary.clone().unwrap();

    let (code, text, _) = runner(&["info".as_ref(), path.as_os_str()]);
    assert_eq!(code, Some(0), "{text}");
    let line = |key: &str| {
        text.lines()
            .find(|l| l.starts_with(&format!("{key:<12} ")))
            .unwrap_or_else(|| panic!("no `{key}` line in\n{text}"))
            .to_string()
    };
    assert!(line("file").ends_with("finished)"), "{text}");
    assert_eq!(
        line("experiment"),
        format!("experiment   smoke_2d {}", summary.experiment_sha256)
    );
    assert_eq!(line("outcome"), "outcome      completed");
    assert_eq!(line("stop rule"), "stop rule    none (ran to time.end_s)");
    // The 2D default, `mps.preset: quiet`.
    assert_eq!(
        line("scheme"),
        "scheme       mps.pressure_scheme incremental, mps.pair_stabilisation 0.8, \
         mps.wall_support 0.95, mps.pressure_regularisation 1.0, mps.regularisation_radius 1.5, \
         mps.surface_depth 0.5, mps.corrected_strain_rate true, mps.compressibility_1_pa 1e-7, \
         time.acoustic_courant 40.0 (= mps.preset quiet)"
    );
    assert!(line("build").contains("release profile"), "{text}");
    assert_eq!(line("threads"), "threads      1");
    assert!(line("simulated").contains("t = 0.1 s, 100 steps"), "{text}");
    assert!(
        line("checkpoints").starts_with(&format!("checkpoints  {},", summary.checkpoints.len()))
    );
    assert!(!text.contains("missing"), "{text}");
    let front = summary.metrics["front_position_m"];
    assert!(
        text.lines()
            .any(|l| l.trim_start().starts_with("front_position_m")
                && l.trim_end().ends_with(&front.to_string())),
        "{text}"
    );

    let (code, json, _) = runner(&["info".as_ref(), "--json".as_ref(), path.as_os_str()]);
    assert_eq!(code, Some(0));
    let info: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(info["outcome"], "completed");
    assert_eq!(info["complete"], true);
    assert_eq!(info["partial"], false);
    assert_eq!(info["experiment"], "smoke_2d");
    // The file name carries the first 12 hex digits of the experiment hash.
    let name = path.file_name().unwrap().to_str().unwrap();
    let prefix = name
        .strip_prefix("smoke_2d-")
        .and_then(|s| s.strip_suffix(".mcap"))
        .unwrap();
    assert_eq!(prefix.len(), 12);
    let hash = info["experiment_sha256"].as_str().unwrap();
    assert!(hash.starts_with(prefix) && hash.len() == 64, "{hash}");
    assert_eq!(hash, summary.experiment_sha256);
    assert_eq!(info["stop_rule"], "");
    assert_eq!(info["build"]["profile"], "release");
    assert_eq!(info["build"]["crate_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(info["threads"], "1");
    assert_eq!(
        info["particles"]["total"].as_f64(),
        summary.metrics.get("particle_count").copied()
    );
    assert_eq!(
        info["particles"]["fluid"].as_f64(),
        summary.metrics.get("fluid_particle_count").copied()
    );
    assert_eq!(info["steps"].as_f64(), Some(100.0));
    assert_eq!(info["time_from"], "summary");
    let checkpoints = &info["checkpoints"];
    assert_eq!(
        checkpoints["count"].as_u64(),
        Some(summary.checkpoints.len() as u64)
    );
    let listed: Vec<&str> = checkpoints["list"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["state_sha256"].as_str().unwrap())
        .collect();
    let logged: Vec<&str> = summary
        .checkpoints
        .iter()
        .map(|c| c.state_sha256.as_str())
        .collect();
    assert_eq!(listed, logged);
    assert_eq!(
        checkpoints["last_time_s"].as_f64(),
        summary.checkpoints.last().map(|c| c.time_s)
    );
    let metrics = info["metrics"].as_object().unwrap();
    assert_eq!(metrics.len(), summary.metrics.len());
    for (k, v) in &summary.metrics {
        assert_eq!(metrics[k].as_f64(), Some(*v), "{k}");
    }
    let channels = &info["channels"];
    assert_eq!(
        channels["/diagnostics"].as_u64(),
        Some(run.diagnostics.len() as u64)
    );
    assert_eq!(channels["/state"].as_u64(), Some(run.states.len() as u64));
    assert_eq!(channels["/particles"].as_u64(), Some(run.clouds as u64));
    assert_eq!(channels["/summary"].as_u64(), Some(1));
    assert_eq!(info["missing"].as_array().unwrap().len(), 0);
    assert!(info["damage"].is_null());
}

#[test]
fn info_names_the_quiet_schemes_switches_and_a_compressibility_off_its_default() {
    let dir = tempfile::tempdir().unwrap();
    let sets = [
        "time.end_s=0.005",
        "mps.preset=standard",
        "mps.pressure_scheme=incremental",
        "mps.pair_stabilisation=0.8",
        "mps.corrected_strain_rate=true",
        "mps.compressibility_1_pa=1e-7",
    ];
    let path = common::run_completed(&common::resolve("smoke_2d.yaml", &sets), dir.path(), 1).path;
    let (code, text, _) = runner(&["info".as_ref(), path.as_os_str()]);
    assert_eq!(code, Some(0), "{text}");
    let scheme = text.lines().find(|l| l.starts_with("scheme ")).unwrap();
    assert_eq!(
        scheme,
        "scheme       mps.pressure_scheme incremental, mps.pair_stabilisation 0.8, \
         mps.corrected_strain_rate true, mps.compressibility_1_pa 1e-7"
    );
    let (_, json, _) = runner(&["info".as_ref(), "--json".as_ref(), path.as_os_str()]);
    let info: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(
        info["pressure_scheme"].as_str(),
        scheme.strip_prefix("scheme       mps.pressure_scheme ")
    );
}

#[test]
fn info_says_when_a_run_used_the_quiet_preset() {
    let dir = tempfile::tempdir().unwrap();
    let sets = ["time.end_s=0.005", "mps.preset=quiet"];
    let path = common::run_completed(&common::resolve("smoke_2d.yaml", &sets), dir.path(), 1).path;
    let (code, text, _) = runner(&["info".as_ref(), path.as_os_str()]);
    assert_eq!(code, Some(0), "{text}");
    let scheme = text.lines().find(|l| l.starts_with("scheme ")).unwrap();
    assert!(scheme.starts_with("scheme       mps.pressure_scheme incremental, "));
    assert!(scheme.ends_with(" (= mps.preset quiet)"), "{scheme}");
    // One field off the preset: the fields are listed, the preset is not claimed.
    let sets = [
        "time.end_s=0.005",
        "mps.preset=quiet",
        "mps.wall_support=0.9",
    ];
    let dir2 = tempfile::tempdir().unwrap();
    let path = common::run_completed(&common::resolve("smoke_2d.yaml", &sets), dir2.path(), 1).path;
    let (_, text, _) = runner(&["info".as_ref(), path.as_os_str()]);
    let scheme = text.lines().find(|l| l.starts_with("scheme ")).unwrap();
    assert!(
        scheme.contains("mps.wall_support 0.9") && !scheme.contains("preset"),
        "{scheme}"
    );
}

#[test]
fn export_of_a_run_as_csv_and_json() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke(dir.path());
    let run = read_run(&path).unwrap();
    let summary = run.summary.clone().unwrap();

    let (code, csv, err) = runner(&["export".as_ref(), path.as_os_str(), "--csv".as_ref()]);
    assert_eq!(code, Some(0), "{err}");
    let (header, rows) = parse_csv(&csv);
    assert_eq!(header[..3], ["time_s", "step", "dt_s"]);
    for c in ["kinetic_energy_j", "max_speed_m_s", "front_position_m"] {
        column(&header, c);
    }
    assert_eq!(rows.len(), run.diagnostics.len());
    assert!(rows.len() > 2);
    let time = column(&header, "time_s");
    let times: Vec<f64> = rows.iter().map(|r| r[time].parse().unwrap()).collect();
    assert!(times.windows(2).all(|w| w[0] < w[1]), "{times:?}");
    // Values read back are the recorded bits.
    let front = column(&header, "front_position_m");
    for (row, d) in rows.iter().zip(&run.diagnostics) {
        assert_eq!(row[time].parse::<f64>().unwrap(), d.time_s);
        assert_eq!(
            row[front].parse::<f64>().unwrap(),
            d.metrics["front_position_m"]
        );
        assert_eq!(row[column(&header, "step")], d.step.to_string());
    }

    // --summary: the one-row summary table.
    let (code, csv, _) = runner(&[
        "export".as_ref(),
        path.as_os_str(),
        "--csv".as_ref(),
        "--summary".as_ref(),
    ]);
    assert_eq!(code, Some(0));
    let (header, rows) = parse_csv(&csv);
    assert_eq!(
        header[..4],
        ["file", "experiment_sha256", "outcome", "stop_time_s"]
    );
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0][0], path.file_name().unwrap().to_str().unwrap());
    assert_eq!(rows[0][1], summary.experiment_sha256);
    assert_eq!(rows[0][2], "completed");
    assert_eq!(
        rows[0][3].parse::<f64>().unwrap(),
        summary.metrics["stop_time_s"]
    );
    assert_eq!(
        header.iter().filter(|h| *h == "stop_time_s").count(),
        1,
        "{header:?}"
    );
    assert_eq!(
        rows[0][column(&header, "front_position_m")]
            .parse::<f64>()
            .unwrap(),
        summary.metrics["front_position_m"]
    );

    // JSON, written to --out: both tables, every row with every column.
    let out = dir.path().join("export.json");
    let (code, stdout, _) = runner(&[
        "export".as_ref(),
        path.as_os_str(),
        "--json".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert_eq!(code, Some(0));
    assert_eq!(stdout.trim(), out.display().to_string());
    let v: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let diag = &v["diagnostics"];
    let columns = diag["columns"].as_array().unwrap();
    let rows = diag["rows"].as_array().unwrap();
    assert_eq!(rows.len(), run.diagnostics.len());
    for row in rows {
        assert_eq!(row.as_object().unwrap().len(), columns.len());
    }
    assert_eq!(
        rows.last().unwrap()["time_s"].as_f64(),
        run.diagnostics.last().map(|d| d.time_s)
    );
    assert_eq!(v["summary"]["rows"][0]["outcome"], "completed");

    // Neither --csv nor --json: a usage error.
    let (code, _, _) = runner(&["export".as_ref(), path.as_os_str()]);
    assert_eq!(code, Some(2));
}

#[test]
fn export_of_a_sweep_folder_has_a_row_per_run_with_the_swept_values() {
    let dir = tempfile::tempdir().unwrap();
    let folder = common::smoke_sweep_folder(dir.path());

    let (code, csv, err) = runner(&["export".as_ref(), folder.as_os_str(), "--csv".as_ref()]);
    assert_eq!(code, Some(0), "{err}");
    let (header, rows) = parse_csv(&csv);
    assert_eq!(
        header[..4],
        ["file", "experiment_sha256", "outcome", "stop_time_s"]
    );
    // Only the swept key differs between the runs: no other manifest value is a column.
    assert_eq!(header[4], "scene.column_width_m", "{header:?}");
    assert!(!header.iter().any(|h| h == "name" || h == "gravity_m_s2"));
    column(&header, "front_position_m");
    assert_eq!(rows.len(), 2);
    let width = column(&header, "scene.column_width_m");
    let mut widths: Vec<f64> = rows.iter().map(|r| r[width].parse().unwrap()).collect();
    widths.sort_by(f64::total_cmp);
    assert_eq!(widths, [0.1, 0.15]);
    for row in &rows {
        let run = read_run(&folder.join(&row[0])).unwrap();
        let summary = run.summary.unwrap();
        assert_eq!(row[1], summary.experiment_sha256);
        assert!(row[0].contains(&summary.experiment_sha256[..12]));
        assert_eq!(row[2], "completed");
        assert_eq!(
            row[3].parse::<f64>().unwrap(),
            summary.metrics["stop_time_s"]
        );
        assert_eq!(
            row[column(&header, "front_position_m")]
                .parse::<f64>()
                .unwrap(),
            summary.metrics["front_position_m"]
        );
        let manifest =
            mps_runner::report::canonical_manifest(&read_run(&folder.join(&row[0])).unwrap())
                .unwrap();
        assert_eq!(
            row[width].parse::<f64>().ok(),
            manifest["scene"]["column_width_m"].as_f64()
        );
    }

    // JSON: the same table; a file that is not a run is listed as skipped.
    std::fs::write(folder.join("junk.mcap"), b"not a run").unwrap();
    let (code, json, err) = runner(&["export".as_ref(), folder.as_os_str(), "--json".as_ref()]);
    assert_eq!(code, Some(0));
    assert!(
        err.contains("skipped") && err.contains("junk.mcap"),
        "{err}"
    );
    let v: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["rows"].as_array().unwrap().len(), 2);
    assert_eq!(v["columns"][4], "scene.column_width_m");
    assert_eq!(v["skipped"].as_array().unwrap().len(), 1);

    // A folder without a run: bad input.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let (code, _, _) = runner(&["export".as_ref(), empty.as_os_str(), "--csv".as_ref()]);
    assert_eq!(code, Some(2));
}

#[test]
fn info_of_a_cut_file_names_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke(dir.path());
    let full = read_run(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();

    // Cut to half its length, under its finished name: described, then refused (exit 2).
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let check = check_run(&cut).unwrap();
    let stop = check.stop.clone().expect("a cut file stops before its end");
    assert!(!check.complete && check.checkpoints < full.states.len());
    let (code, text, err) = runner(&["info".as_ref(), cut.as_os_str()]);
    assert_eq!(code, Some(2), "{text}");
    assert!(err.contains("incomplete"), "{err}");
    assert!(text.contains("INCOMPLETE"), "{text}");
    assert!(text.contains("missing      no /summary message"), "{text}");
    assert!(
        text.contains("missing      no `outcome` metadata record"),
        "{text}"
    );
    assert!(
        text.contains("outcome      - (no outcome recorded)"),
        "{text}"
    );
    assert!(
        text.contains(&format!("read up to   byte {} (cut short)", stop.at_byte)),
        "{text}"
    );
    let last = &full.states[check.checkpoints - 1];
    assert!(
        text.contains(&format!(
            "checkpoints  {}, t = 0 s to {} s",
            check.checkpoints, last.time_s
        )),
        "{text}"
    );

    // The same bytes as a killed run's .partial: its partial contents, exit 0.
    let partial = dir.path().join("killed.mcap.partial");
    std::fs::write(&partial, &bytes[..bytes.len() / 2]).unwrap();
    let (code, json, err) = runner(&["info".as_ref(), "--json".as_ref(), partial.as_os_str()]);
    assert_eq!(code, Some(0), "{err}");
    let info: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(info["complete"], false);
    assert_eq!(info["partial"], true);
    assert!(info["outcome"].is_null() && info["stop_rule"].is_null());
    assert_eq!(info["experiment"], "smoke_2d");
    assert_eq!(info["channels"]["/summary"], 0);
    assert_eq!(
        info["checkpoints"]["count"].as_u64(),
        Some(check.checkpoints as u64)
    );
    assert_eq!(
        info["checkpoints"]["last_time_s"].as_f64(),
        Some(last.time_s)
    );
    assert_eq!(info["time_from"], "last_diagnostics");
    let recovered = read_run(&partial).unwrap();
    assert_eq!(
        info["simulated_time_s"].as_f64(),
        recovered.diagnostics.last().map(|d| d.time_s)
    );
    assert_eq!(info["damage"]["at_byte"].as_u64(), Some(stop.at_byte));
    assert_eq!(info["damage"]["damaged"], false);
    let missing: Vec<&str> = info["missing"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap())
        .collect();
    assert!(missing.iter().any(|m| m.starts_with("no /summary message")));
    assert!(
        missing
            .iter()
            .any(|m| m.starts_with("no `outcome` metadata"))
    );
    assert!(missing.iter().any(|m| m.contains(&format!(
        "t = {} s",
        mps_runner::report::time_text(last.time_s)
    ))));
    assert!(info["metrics"].as_object().unwrap().is_empty());

    // Its diagnostics export holds the rows read before the cut.
    let (code, csv, _) = runner(&["export".as_ref(), partial.as_os_str(), "--csv".as_ref()]);
    assert_eq!(code, Some(0));
    let (_, rows) = parse_csv(&csv);
    assert_eq!(rows.len(), recovered.diagnostics.len());
    assert!(rows.len() < full.diagnostics.len());
    // The cut file under its finished name is refused by export, as by plot.
    let (code, _, _) = runner(&["export".as_ref(), cut.as_os_str(), "--csv".as_ref()]);
    assert_eq!(code, Some(2));

    // Not a run file at all: unusable, exit 2, nothing on stdout.
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not a run").unwrap();
    let (code, out, err) = runner(&["info".as_ref(), junk.as_os_str()]);
    assert_eq!(code, Some(2));
    assert!(out.is_empty() && err.contains("MCAP"), "{err}");
}

/// `runner info RUN | head` and the like: a reader that has gone before the first line ends
/// the print-only commands quietly (SIGPIPE, as other Unix tools), and a run carries on to
/// its whole file and exit code; never a panic. The pipe's read end is closed before the
/// child starts, so the first write always fails.
#[cfg(unix)]
#[test]
fn output_into_a_closed_pipe_never_panics() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().unwrap();
    let run = smoke(dir.path());
    let run_text = run.to_str().unwrap();
    for args in [
        vec!["info", run_text],
        vec!["export", "--csv", run_text],
        vec![
            "hash",
            common::experiment("smoke_2d.yaml").to_str().unwrap(),
        ],
    ] {
        let out = runner_into_closed_pipe(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !stderr.contains("panicked"),
            "runner {args:?} panicked: {stderr}"
        );
        assert_eq!(
            out.status.signal(),
            Some(libc::SIGPIPE),
            "runner {args:?} ends by SIGPIPE: {:?}, stderr {stderr}",
            out.status
        );
    }
    // A run prints its file's path last: the closed pipe is ignored, the run's exit code
    // stands and the file is whole.
    let out_dir = dir.path().join("piped");
    let manifest = common::experiment("smoke_2d.yaml");
    let out = runner_into_closed_pipe(&[
        manifest.to_str().unwrap(),
        "--quiet",
        "--threads",
        "1",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(0),
        "a run into a closed pipe: {stderr}"
    );
    let file = std::fs::read_dir(&out_dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    assert_eq!(file.extension().unwrap(), "mcap");
    assert_eq!(std::fs::read(&file).unwrap(), std::fs::read(&run).unwrap());
}

/// Runs the binary with `args`, its standard output a pipe whose read end is already closed.
#[cfg(unix)]
fn runner_into_closed_pipe(args: &[&str]) -> std::process::Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    std::process::Command::new(env!("CARGO_BIN_EXE_runner"))
        .args(args)
        .stdout(writer)
        .stderr(std::process::Stdio::piped())
        .output()
        .unwrap()
}
