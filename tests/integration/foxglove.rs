//! Runs open in Foxglove and Lichtblick: a run file decoded exactly as those viewers decode it
//! (tools/foxglove/decode.js: protobufjs `Root.fromDescriptor` on each schema's
//! FileDescriptorSet, `toObject` with `{defaults: true, longs: BigInt}`, the viewers'
//! message-path rules) holds what the Rust reader reads, bit for bit, under the plot paths the
//! docs/file-format.md and tools/foxglove/mps-layout.json use.
//!
//! Needs Node.js (18+) and npm; `npm ci` fills tools/foxglove/node_modules from the committed
//! package-lock.json when it is missing. Without node the tests fail and say so.
use crate::common;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use mps_runner::proto::foxglove::PointCloud;
use mps_runner::proto::mps::v1::Diagnostics;
use mps_runner::record::{Logged, read_messages, read_run};
use serde_json::Value;

/// The plot path of one experiment metric in the viewers: protobufjs decodes a protobuf `map`
/// as a list of `{key, value}` entries, so a metric is picked out of the list by its key.
fn metric_path(topic: &str, key: &str) -> String {
    format!("{topic}.metrics[:]{{key==\"{key}\"}}.value")
}

/// Scalar fields of `mps.v1.Diagnostics` and their values, as the viewers' numbers.
fn diagnostics_fields(d: &Diagnostics) -> Vec<(&'static str, f64)> {
    vec![
        ("step", f64::from(d.step)),
        ("time_s", d.time_s),
        ("dt_s", d.dt_s),
        ("kinetic_energy_j", d.kinetic_energy_j),
        ("max_speed_m_s", d.max_speed_m_s),
        ("ppe_iterations", f64::from(d.ppe_iterations)),
        ("ppe_relative_residual", d.ppe_relative_residual),
        (
            "surface_particle_count",
            f64::from(d.surface_particle_count),
        ),
        ("fluid_particle_count", f64::from(d.fluid_particle_count)),
        ("viscosity_iterations", f64::from(d.viscosity_iterations)),
        ("viscosity_relative_residual", d.viscosity_relative_residual),
        ("non_flowing_fraction", d.non_flowing_fraction),
        ("yield_iterations", f64::from(d.yield_iterations)),
    ]
}

fn tool_dir() -> PathBuf {
    common::root().join("tools").join("foxglove")
}

/// Checks that node runs and that tools/foxglove's packages are installed (`npm ci` once per
/// test process when node_modules is missing). Panics with what to install otherwise.
fn node_ready() {
    static READY: OnceLock<Result<(), String>> = OnceLock::new();
    let ready = READY.get_or_init(|| {
        let version = Command::new("node").arg("--version").output().map_err(|e| {
            format!(
                "cannot run `node` ({e}): these tests decode run files with protobufjs exactly as \
                 Foxglove/Lichtblick do; install Node.js 18 or newer with npm"
            )
        })?;
        if !version.status.success() {
            return Err("`node --version` failed: install Node.js 18 or newer".into());
        }
        let dir = tool_dir();
        if !dir.join("node_modules").is_dir() {
            let out = Command::new("npm")
                .args(["ci", "--no-audit", "--no-fund", "--prefix"])
                .arg(&dir)
                .output()
                .map_err(|e| format!("cannot run `npm` ({e}): install npm with Node.js"))?;
            if !out.status.success() {
                return Err(format!(
                    "`npm ci --prefix {}` failed:\n{}",
                    dir.display(),
                    String::from_utf8_lossy(&out.stderr)
                ));
            }
        }
        Ok(())
    });
    if let Err(why) = ready {
        panic!("{why}");
    }
}

/// `node tools/foxglove/decode.js FILE --series --path P...`: its exit code and JSON summary.
fn decode(file: &Path, paths: &[String]) -> (Option<i32>, Value) {
    node_ready();
    let mut cmd = Command::new("node");
    cmd.arg(tool_dir().join("decode.js"))
        .arg(file)
        .arg("--series");
    for p in paths {
        cmd.arg("--path").arg(p);
    }
    let out = cmd.output().expect("run node");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let json = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!(
            "decode.js printed no JSON ({e}), exit {:?}:\n{stdout}\n{}",
            out.status.code(),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (out.status.code(), json)
}

/// The entry of `path` in the summary's `plot_paths`.
fn plot_path<'a>(summary: &'a Value, path: &str) -> &'a Value {
    summary["plot_paths"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["path"] == path)
        .unwrap_or_else(|| panic!("{path} was not evaluated"))
}

/// Asserts that `path` resolves to one number per message, at the given log times, with exactly
/// the bits of `expected`.
fn assert_series(summary: &Value, path: &str, expected: &[(u64, f64)]) {
    let entry = plot_path(summary, path);
    assert_eq!(entry["resolves"], true, "{path} does not resolve: {entry}");
    let series = entry["series"].as_array().unwrap();
    assert_eq!(series.len(), expected.len(), "{path}: message count");
    for (i, (item, (log_time, value))) in series.iter().zip(expected).enumerate() {
        assert_eq!(
            item[0],
            log_time.to_string(),
            "{path}: log time of message {i}"
        );
        assert_eq!(
            item[2].as_str(),
            Some(format!("{:016x}", value.to_bits()).as_str()),
            "{path}: message {i}: the viewer gets {} where the file holds {value:e}",
            item[1]
        );
    }
}

/// Plot paths of every Plot panel in tools/foxglove/mps-layout.json, and the layout itself.
fn layout() -> (Value, Vec<String>) {
    let text = std::fs::read_to_string(tool_dir().join("mps-layout.json")).unwrap();
    let layout: Value = serde_json::from_str(&text).expect("mps-layout.json is JSON");
    let mut paths = Vec::new();
    for (id, config) in layout["configById"].as_object().unwrap() {
        if id.starts_with("Plot!") {
            for p in config["paths"].as_array().unwrap() {
                paths.push(p["value"].as_str().unwrap().to_string());
            }
        }
    }
    (layout, paths)
}

#[test]
fn a_run_decodes_as_foxglove_decodes_it_with_plot_paths_equal_to_the_recorded_values() {
    let dir = tempfile::tempdir().unwrap();
    let path = common::run_completed(&common::resolve("smoke_2d.yaml", &[]), dir.path(), 1).path;
    let run = read_run(&path).unwrap();
    let logged = read_messages(&path).unwrap();
    let summary = run.summary.clone().unwrap();
    let (layout, layout_paths) = layout();
    let keys: BTreeSet<&String> = run
        .diagnostics
        .iter()
        .flat_map(|d| d.metrics.keys())
        .collect();
    let mut paths = layout_paths.clone();
    paths.extend(keys.iter().map(|k| format!("/metrics.{k}")));

    let (code, fox) = decode(&path, &paths);
    assert_eq!(code, Some(0), "decode.js reports a problem: {fox:#}");
    assert_eq!(fox["ok"], true);
    assert_eq!(fox["decoder"]["reader"], "indexed");

    // Every channel decodes, every message, as many as the Rust reader and `runner info` count.
    let (code, info, err) =
        common::runner_all(&["info".as_ref(), "--json".as_ref(), path.as_os_str()]);
    assert_eq!(code, Some(0), "{err}");
    let info: Value = serde_json::from_str(&info).unwrap();
    let expected = [
        ("/state", "mps.v1.StateCheckpoint", run.states.len()),
        ("/particles", "foxglove.PointCloud", run.clouds),
        ("/diagnostics", "mps.v1.Diagnostics", run.diagnostics.len()),
        ("/summary", "mps.v1.Summary", 1),
        ("/metrics", "mps.v1.run.Metrics", run.diagnostics.len()),
    ];
    let channels = fox["channels"].as_object().unwrap();
    assert_eq!(channels.len(), expected.len(), "{:?}", channels.keys());
    for (topic, schema, count) in expected {
        let c = &channels[topic];
        assert_eq!(c["schema"], schema, "{topic}");
        assert_eq!(c["schema_encoding"], "protobuf", "{topic}");
        assert_eq!(c["message_encoding"], "protobuf", "{topic}");
        assert!(
            c["schema_error"].is_null(),
            "{topic}: {}",
            c["schema_error"]
        );
        assert_eq!(
            c["decode_errors"].as_array().unwrap().len(),
            0,
            "{topic}: {c}"
        );
        assert!(count > 0, "{topic}: the smoke run logs it");
        assert_eq!(c["messages"].as_u64(), Some(count as u64), "{topic}");
        assert_eq!(c["decoded"].as_u64(), Some(count as u64), "{topic}");
        assert_eq!(
            c["statistics_count"].as_u64(),
            Some(count as u64),
            "{topic}"
        );
        assert_eq!(
            info["channels"][topic].as_u64(),
            Some(count as u64),
            "{topic}"
        );
    }

    // /diagnostics: every field at the top level, each scalar a JavaScript number (no bigint:
    // 64-bit integers would arrive as bigint and plot poorly), the metrics map a list of
    // {key, value} entries.
    let diag = &channels["/diagnostics"];
    let fields: BTreeSet<&str> = diag["fields"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    for (name, _) in diagnostics_fields(&run.diagnostics[0]) {
        assert!(
            fields.contains(name),
            "/diagnostics has no field {name}: {fields:?}"
        );
    }
    assert!(fields.contains("metrics"));
    for (name, ty) in diag["field_types"].as_object().unwrap() {
        let ty = ty.as_str().unwrap();
        if !ty.contains('[') && name != "metrics" {
            assert!(
                ty.ends_with("-> number"),
                "/diagnostics.{name} arrives as {ty}"
            );
        }
    }
    let metrics = &fox["maps"]["/diagnostics.metrics"];
    assert_eq!(
        metrics["decoded_shape"], "array of {key, value} entries",
        "{metrics}"
    );
    assert_eq!(metrics["datatype"], "mps.v1.Diagnostics.MetricsEntry[]");

    // Every scalar field plots under `/diagnostics.<field>` with the recorded bits and log times.
    let diagnostics: Vec<(u64, &Diagnostics)> = logged
        .iter()
        .filter_map(|(t, m)| match m {
            Logged::Diagnostics(d) => Some((*t, d)),
            _ => None,
        })
        .collect();
    assert_eq!(diagnostics.len(), run.diagnostics.len());
    for (k, (name, _)) in diagnostics_fields(&run.diagnostics[0]).iter().enumerate() {
        let series: Vec<(u64, f64)> = diagnostics
            .iter()
            .map(|(t, d)| (*t, diagnostics_fields(d)[k].1))
            .collect();
        assert_series(&fox, &format!("/diagnostics.{name}"), &series);
    }

    // Every experiment metric plots by the simple path `/metrics.<name>` (the /metrics channel,
    // one field per metric) and by its key in the map, with the recorded bits at the same log
    // times; the object-style path into the map (`.metrics.front_position_m`) finds nothing in
    // these viewers, which is why /metrics exists.
    assert!(keys.contains(&"front_position_m".to_string()), "{keys:?}");
    for key in &keys {
        let series: Vec<(u64, f64)> = diagnostics
            .iter()
            .map(|(t, d)| (*t, d.metrics[key.as_str()]))
            .collect();
        assert_series(&fox, &format!("/metrics.{key}"), &series);
        assert_series(&fox, &metric_path("/diagnostics", key), &series);
        let naive = plot_path(&fox, &format!("/diagnostics.metrics.{key}"));
        assert_eq!(naive["resolves"], false, "{naive}");
        assert_eq!(naive["numbers"], 0, "{naive}");
    }
    let summary_time = logged
        .iter()
        .find_map(|(t, m)| matches!(m, Logged::Summary(_)).then_some(*t))
        .unwrap();
    for (key, value) in &summary.metrics {
        assert_series(
            &fox,
            &metric_path("/summary", key),
            &[(summary_time, *value)],
        );
    }

    // The layout's plot paths all resolve (they were passed with --path, and most are above).
    assert!(!layout_paths.is_empty());
    for p in &layout_paths {
        assert_eq!(plot_path(&fox, p)["resolves"], true, "layout path {p}");
    }
    assert!(
        layout_paths
            .iter()
            .any(|p| p == "/diagnostics.kinetic_energy_j")
    );
    assert!(layout_paths.iter().any(|p| p.starts_with("/metrics.")));

    // /particles: a foxglove.PointCloud the 3D panel draws: x, y, z and the five per-particle
    // fields, FLOAT32 little-endian, at the offsets the Rust side wrote, the same in every frame.
    let pc = &fox["point_cloud"]["/particles"];
    assert_eq!(pc["problems"].as_array().unwrap().len(), 0, "{pc:#}");
    assert_eq!(pc["same_layout_in_every_cloud"], true);
    assert_eq!(pc["messages"].as_u64(), Some(run.clouds as u64));
    let last: &PointCloud = run.last_cloud.as_ref().unwrap();
    assert_eq!(pc["frame_id"], last.frame_id);
    assert_eq!(
        pc["point_stride"].as_u64(),
        Some(u64::from(last.point_stride))
    );
    let stamp = last.timestamp.unwrap();
    // The viewers turn google.protobuf.Timestamp into {sec, nsec}.
    assert_eq!(pc["timestamp"]["sec"].as_i64(), Some(stamp.seconds));
    assert_eq!(
        pc["timestamp"]["nsec"].as_i64(),
        Some(i64::from(stamp.nanos))
    );
    let decoded: Vec<(String, u64, u64)> = pc["fields"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["name"].as_str().unwrap().to_string(),
                f["offset"].as_u64().unwrap(),
                f["type"].as_u64().unwrap(),
            )
        })
        .collect();
    let written: Vec<(String, u64, u64)> = last
        .fields
        .iter()
        .map(|f| (f.name.clone(), u64::from(f.offset), f.r#type as u64))
        .collect();
    assert_eq!(decoded, written);
    let names: Vec<&str> = decoded.iter().map(|(n, _, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "x",
            "y",
            "z",
            "speed_m_s",
            "pressure_pa",
            "kind",
            "tag",
            "flowing"
        ]
    );
    for f in pc["fields"].as_array().unwrap() {
        assert_eq!(f["type_name"], "FLOAT32", "{f}");
    }
    assert_eq!(
        pc["colour_fields"],
        serde_json::json!(["speed_m_s", "pressure_pa", "kind", "tag", "flowing"])
    );
    // The colour range the 3D panel finds for speed_m_s is the range of the recorded values.
    let stride = last.point_stride as usize;
    let speeds: Vec<f64> = last
        .data
        .chunks_exact(stride)
        .map(|p| f64::from(f32::from_le_bytes(p[12..16].try_into().unwrap())))
        .collect();
    assert_eq!(
        pc["points_in_last_cloud"].as_u64(),
        Some(speeds.len() as u64)
    );
    let range = &pc["ranges_in_last_cloud"]["speed_m_s"];
    assert_eq!(
        range["min"].as_f64(),
        speeds.iter().copied().reduce(f64::min)
    );
    assert_eq!(
        range["max"].as_f64(),
        speeds.iter().copied().reduce(f64::max)
    );
    assert!(
        range["max"].as_f64().unwrap() > 0.0,
        "the fluid moves: {range}"
    );

    // The layout's other panels point at what the file holds.
    let panels = layout["configById"].as_object().unwrap();
    let three_d = panels
        .iter()
        .find(|(id, _)| id.starts_with("3D!"))
        .expect("a 3D panel")
        .1;
    let particles = &three_d["topics"]["/particles"];
    assert_eq!(particles["visible"], true);
    assert_eq!(particles["colorMode"], "colormap");
    assert_eq!(particles["colorField"], "speed_m_s");
    assert_eq!(three_d["followTf"], last.frame_id);
    let raw = panels
        .iter()
        .find(|(id, _)| id.starts_with("RawMessages!"))
        .expect("a Raw Messages panel")
        .1;
    assert_eq!(raw["topicPath"], "/summary");
    // Every panel in configById is placed in the layout tree, and nothing else is.
    let mut placed = Vec::new();
    let mut stack = vec![&layout["layout"]];
    while let Some(node) = stack.pop() {
        match node {
            Value::String(id) => placed.push(id.clone()),
            Value::Object(split) => {
                stack.push(&split["first"]);
                stack.push(&split["second"]);
            }
            other => panic!("unexpected layout node {other}"),
        }
    }
    placed.sort();
    let mut ids: Vec<String> = panels.keys().cloned().collect();
    ids.sort();
    assert_eq!(placed, ids);
}

#[test]
fn a_killed_runs_partial_file_decodes_with_the_streaming_reader() {
    // A file without summary or footer (a killed run's .partial, here a finished file cut in
    // half): the viewers fall back to reading it front to back; every complete chunk decodes.
    let dir = tempfile::tempdir().unwrap();
    let path = common::run_completed(&common::resolve("smoke_2d.yaml", &[]), dir.path(), 1).path;
    let bytes = std::fs::read(&path).unwrap();
    let partial = dir.path().join("killed.mcap.partial");
    std::fs::write(&partial, &bytes[..bytes.len() / 2]).unwrap();
    let recovered = read_run(&partial).unwrap();
    assert!(!recovered.complete);

    let (code, fox) = decode(&partial, &[]);
    assert_eq!(code, Some(0), "{fox:#}");
    assert_eq!(fox["decoder"]["reader"], "stream");
    let channels = &fox["channels"];
    for (topic, count) in [
        ("/state", recovered.states.len()),
        ("/particles", recovered.clouds),
        ("/diagnostics", recovered.diagnostics.len()),
        ("/metrics", recovered.diagnostics.len()),
        ("/summary", 0),
    ] {
        assert_eq!(
            channels[topic]["messages"].as_u64(),
            Some(count as u64),
            "{topic}"
        );
        assert_eq!(
            channels[topic]["decoded"].as_u64(),
            Some(count as u64),
            "{topic}"
        );
    }
    assert!(!recovered.diagnostics.is_empty());
    let series: Vec<(u64, f64)> = read_messages(&partial)
        .unwrap()
        .iter()
        .filter_map(|(t, m)| match m {
            Logged::Diagnostics(d) => Some((*t, d.kinetic_energy_j)),
            _ => None,
        })
        .collect();
    assert_series(&fox, "/diagnostics.kinetic_energy_j", &series);
}
