//! Recording: round trip, byte determinism, recovery of killed runs, point cloud packing.

use crate::common;
use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use mps_runner::build_info::BuildInfo;
use mps_runner::proto::foxglove::{PointCloud, packed_element_field::NumericType};
use mps_runner::proto::mps::v1::{CheckpointHash, Diagnostics, StateCheckpoint, Summary};
use mps_runner::record::{Outcome, Recorder, RunHeader, partial_path, point_cloud, read_run};
use prost::Message as _;

const MANIFEST: &str =
    "name: sample\nexperiment: l_flow\n# a comment kept verbatim\nyield_stress_pa: 120\n";
const CANONICAL: &str = r#"{"experiment":"l_flow","name":"sample","yield_stress_pa":120}"#;
/// SHA-256 of `CANONICAL` (checked in `round_trip_of_a_finished_run`).
const SHA: &str = "2d0e8737302751f624c2905e350c569e7c64825bc64c9f2cf19ecc6f74639604";

fn overrides() -> Vec<String> {
    vec!["yield_stress_pa=120".into(), "name=\"sample\"".into()]
}

fn header(overrides: &[String]) -> RunHeader<'_> {
    RunHeader {
        manifest_source: MANIFEST,
        overrides,
        canonical: CANONICAL,
        experiment_sha256: SHA,
        name: "sample",
        default_preset: None,
        preset_revision: None,
        threads: 4,
    }
}

const N: usize = 5;
const DT_NS: u64 = 100_000;

fn state(index: u32, salt: f64) -> StateCheckpoint {
    let n = N;
    let position_m: Vec<f64> = (0..2 * n)
        .map(|i| 0.01 * i as f64 + 1e-3 * index as f64 + salt)
        .collect();
    let velocity_m_s: Vec<f64> = (0..2 * n)
        .map(|i| -0.5 + 0.1 * (i as f64) * (index as f64))
        .collect();
    StateCheckpoint {
        index,
        step: 10 * index as u64,
        time_s: 1e-3 * index as f64,
        dt_s: 1e-4,
        dimension: 2,
        position_m,
        velocity_m_s,
        pressure_pa: (0..n)
            .map(|i| 100.0 * i as f64 + f64::from(index))
            .collect(),
        kind: (0..n).map(|i| (i % 3) as u32).collect(),
        state_sha256: format!("{index:064x}"),
        extra_scalars: vec![],
        tag: vec![],
        yield_stress_pa: vec![],
        yield_penalty_pa_s: 0.0,
    }
}

fn diagnostics(step: u32) -> Diagnostics {
    let mut metrics = BTreeMap::new();
    metrics.insert("front_position_m".to_string(), 0.1 + f64::from(step) * 1e-3);
    metrics.insert("non_flowing_fraction".to_string(), 0.5);
    Diagnostics {
        step,
        time_s: f64::from(step) * 1e-4,
        dt_s: 1e-4,
        kinetic_energy_j: 0.25 * f64::from(step),
        max_speed_m_s: 1.5,
        ppe_iterations: 30 + step,
        ppe_relative_residual: 1e-9,
        surface_particle_count: 3,
        fluid_particle_count: N as u32,
        metrics,
        viscosity_iterations: 4 + step,
        viscosity_relative_residual: 2e-10,
        non_flowing_fraction: 0.25,
        yield_iterations: 7,
    }
}

fn cloud(s: &StateCheckpoint, time_ns: u64) -> PointCloud {
    let speed: Vec<f32> = (0..N).map(|i| i as f32 * 0.5).collect();
    let pressure: Vec<f32> = s.pressure_pa.iter().map(|&p| p as f32).collect();
    let kind: Vec<f32> = s.kind.iter().map(|&k| k as f32).collect();
    point_cloud(
        time_ns,
        2,
        &s.position_m,
        &[
            ("speed_m_s", &speed),
            ("pressure_pa", &pressure),
            ("kind", &kind),
        ],
    )
}

struct Written {
    states: Vec<StateCheckpoint>,
    diagnostics: Vec<Diagnostics>,
    clouds: usize,
    summary: Summary,
}

/// A small run: `n_states` checkpoints, with diagnostics and clouds between them.
/// Returns what was written and the recorder, not finished.
fn record_run(final_path: &Path, n_states: u32, salt: f64) -> (Recorder, Written) {
    let ov = overrides();
    let mut rec = Recorder::create(final_path, &header(&ov)).expect("create");
    let mut w = Written {
        states: vec![],
        diagnostics: vec![],
        clouds: 0,
        summary: Summary::default(),
    };
    for k in 0..n_states {
        let t = u64::from(k) * 10 * DT_NS;
        for j in 0..3u32 {
            let d = diagnostics(10 * k + j);
            rec.write_diagnostics(t + u64::from(j) * DT_NS, &d).unwrap();
            w.diagnostics.push(d);
        }
        let s = state(k, salt);
        rec.write_cloud(t, &cloud(&s, t)).unwrap();
        w.clouds += 1;
        rec.write_state(t, &s).unwrap();
        w.summary.checkpoints.push(CheckpointHash {
            index: s.index,
            step: s.step,
            time_s: s.time_s,
            state_sha256: s.state_sha256.clone(),
        });
        w.states.push(s);
    }
    w.summary.metrics.insert("l_flow_m".into(), 0.42);
    (rec, w)
}

fn finished_run(dir: &Path, salt: f64) -> (PathBuf, Written) {
    let final_path = dir.join("sample.mcap");
    let (rec, mut w) = record_run(&final_path, 4, salt);
    let end = 40 * DT_NS;
    let out = rec.finish(end, &w.summary, &Outcome::Completed).unwrap();
    assert_eq!(out, final_path);
    w.summary.outcome = "completed".into();
    w.summary.experiment_sha256 = SHA.into();
    (final_path, w)
}

fn map(entries: &[(&str, &str)]) -> BTreeMap<String, String> {
    entries
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

#[test]
fn round_trip_of_a_finished_run() {
    let dir = tempfile::tempdir().unwrap();
    let (path, w) = finished_run(dir.path(), 0.0);
    assert!(path.exists());
    assert!(!partial_path(&path).exists(), ".partial left behind");

    let run = read_run(&path).unwrap();
    assert!(run.complete);
    assert_eq!(run.stop, None);
    assert_eq!(run.states, w.states);
    assert_eq!(run.diagnostics, w.diagnostics);
    assert_eq!(run.clouds, w.clouds);
    assert_eq!(run.summary.as_ref(), Some(&w.summary));

    let b = BuildInfo::current();
    let mut expected = BTreeMap::new();
    expected.insert(
        "manifest".to_string(),
        map(&[
            ("source", MANIFEST),
            ("canonical", CANONICAL),
            ("experiment_sha256", SHA),
            ("overrides", r#"["yield_stress_pa=120","name=\"sample\""]"#),
            ("name", "sample"),
        ]),
    );
    expected.insert(
        "build".to_string(),
        map(&[
            ("crate_version", b.crate_version),
            ("git_commit", b.git_commit),
            ("rustc", b.rustc),
            ("target", b.target),
            ("profile", b.profile),
        ]),
    );
    expected.insert(
        "run".to_string(),
        map(&[
            ("threads", "4"),
            ("mcap_format", "mps.v1"),
            ("math", "libm"),
        ]),
    );
    expected.insert(
        "outcome".to_string(),
        map(&[("status", "completed"), ("reason", "")]),
    );
    assert_eq!(run.metadata, expected);
    // The overrides value is a JSON array that gives back the strings.
    let ov: Vec<String> = serde_json::from_str(&run.metadata["manifest"]["overrides"]).unwrap();
    assert_eq!(ov, overrides());
    use sha2::Digest as _;
    assert_eq!(hex::encode(sha2::Sha256::digest(CANONICAL.as_bytes())), SHA);
}

#[test]
fn mcap_layout_as_other_readers_see_it() {
    let dir = tempfile::tempdir().unwrap();
    let (path, w) = finished_run(dir.path(), 0.0);
    let buf = fs::read(&path).unwrap();

    // Header.
    let first = mcap::read::LinearReader::new(&buf)
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    match first {
        mcap::records::Record::Header(h) => {
            assert_eq!(h.profile, "mps");
            assert!(
                h.library.contains(env!("CARGO_PKG_VERSION")),
                "{}",
                h.library
            );
        }
        other => panic!("first record is not a header: {other:?}"),
    }

    // Summary section: channels, schemas, statistics, attachment, metadata.
    let summary = mcap::Summary::read(&buf).unwrap().expect("summary section");
    let mut topics: BTreeMap<String, (String, String, String)> = BTreeMap::new();
    for ch in summary.channels.values() {
        let schema = ch.schema.as_ref().expect("schema");
        if ch.topic == "/metrics" {
            // Made per run: the one message, time_s then the metrics of the first row.
            let set = <prost_types::FileDescriptorSet as prost::Message>::decode(&schema.data[..])
                .expect("a FileDescriptorSet");
            let message = &set.file[0].message_type[0];
            let names: Vec<&str> = message.field.iter().map(|f| f.name()).collect();
            let mut expected = vec!["time_s"];
            expected.extend(w.diagnostics[0].metrics.keys().map(String::as_str));
            assert_eq!(names, expected);
        } else {
            assert_eq!(&schema.data[..], mps_runner::proto::DESCRIPTOR_SET);
        }
        topics.insert(
            ch.topic.clone(),
            (
                schema.name.clone(),
                schema.encoding.clone(),
                ch.message_encoding.clone(),
            ),
        );
    }
    let pb = |s: &str| {
        (
            s.to_string(),
            "protobuf".to_string(),
            "protobuf".to_string(),
        )
    };
    let mut expected = BTreeMap::new();
    expected.insert("/state".to_string(), pb("mps.v1.StateCheckpoint"));
    expected.insert("/particles".to_string(), pb("foxglove.PointCloud"));
    expected.insert("/diagnostics".to_string(), pb("mps.v1.Diagnostics"));
    expected.insert("/summary".to_string(), pb("mps.v1.Summary"));
    expected.insert("/metrics".to_string(), pb("mps.v1.run.Metrics"));
    assert_eq!(topics, expected);

    let stats = summary.stats.as_ref().unwrap();
    // /metrics: one message per /diagnostics row.
    let total = w.states.len() + 2 * w.diagnostics.len() + w.clouds + 1;
    assert_eq!(stats.message_count, total as u64);
    assert_eq!(stats.metadata_count, 4);
    assert_eq!(stats.attachment_count, 1);

    assert_eq!(summary.attachment_indexes.len(), 1);
    let att = mcap::read::attachment(&buf, &summary.attachment_indexes[0]).unwrap();
    assert_eq!(att.name, "manifest.yaml");
    assert_eq!(att.media_type, "application/yaml");
    assert_eq!((att.log_time, att.create_time), (0, 0));
    assert_eq!(&att.data[..], MANIFEST.as_bytes());

    // Every message: sequence per channel from 0, publish time = log time, time order per
    // channel, and the /summary message last.
    let mut next_seq: BTreeMap<String, u32> = BTreeMap::new();
    let mut last_time: BTreeMap<String, u64> = BTreeMap::new();
    let mut last_topic = String::new();
    for m in mcap::MessageStream::new(&buf).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.clone();
        let seq = next_seq.entry(topic.clone()).or_insert(0);
        assert_eq!(m.sequence, *seq, "sequence on {topic}");
        *seq += 1;
        assert_eq!(m.publish_time, m.log_time);
        let lt = last_time.entry(topic.clone()).or_insert(0);
        assert!(m.log_time >= *lt, "time goes back on {topic}");
        *lt = m.log_time;
        last_topic = topic;
    }
    assert_eq!(last_topic, "/summary");
    assert_eq!(next_seq["/state"], w.states.len() as u32);
    assert_eq!(next_seq["/diagnostics"], w.diagnostics.len() as u32);
    assert_eq!(next_seq["/particles"], w.clouds as u32);
    assert_eq!(next_seq["/summary"], 1);
}

#[test]
fn failed_outcome_is_recorded_in_summary_and_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("failed.mcap");
    let (rec, w) = record_run(&path, 2, 0.0);
    let outcome = Outcome::Failed("PPE did not converge at step 17".into());
    assert_eq!(outcome.as_str(), "failed");
    rec.finish(17 * DT_NS, &w.summary, &outcome).unwrap();
    let run = read_run(&path).unwrap();
    let s = run.summary.unwrap();
    assert_eq!(s.outcome, "failed");
    assert_eq!(s.reason, "PPE did not converge at step 17");
    assert_eq!(
        run.metadata["outcome"],
        map(&[
            ("status", "failed"),
            ("reason", "PPE did not converge at step 17")
        ])
    );
    let i = Outcome::Interrupted("SIGINT".into());
    assert_eq!((i.as_str(), i.reason()), ("interrupted", "SIGINT"));
    assert_eq!(
        (Outcome::Completed.as_str(), Outcome::Completed.reason()),
        ("completed", "")
    );
}

#[test]
fn identical_recordings_give_identical_bytes() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let c = tempfile::tempdir().unwrap();
    let (pa, _) = finished_run(a.path(), 0.0);
    let (pb, _) = finished_run(b.path(), 0.0);
    let (pc, _) = finished_run(c.path(), 1e-12);
    let (ba, bb, bc) = (
        fs::read(pa).unwrap(),
        fs::read(pb).unwrap(),
        fs::read(pc).unwrap(),
    );
    assert!(ba == bb, "two identical recordings differ in their bytes");
    // And the comparison can see a one-ulp-scale change in one coordinate.
    assert!(ba != bc);
}

#[test]
fn killed_run_keeps_every_flushed_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.mcap");
    let (mut rec, w) = record_run(&path, 3, 0.0);
    // Written after the last checkpoint: still in an open chunk when the process dies.
    let s = state(3, 0.0);
    rec.write_cloud(99, &cloud(&s, 99)).unwrap();
    rec.write_diagnostics(99, &diagnostics(99)).unwrap();
    // A killed process runs no destructor.
    std::mem::forget(rec);

    let partial = partial_path(&path);
    assert!(!path.exists());
    let run = read_run(&partial).unwrap();
    assert!(!run.complete);
    assert_eq!(run.states, w.states);
    assert_eq!(run.diagnostics, w.diagnostics);
    assert_eq!(run.clouds, w.clouds);
    assert_eq!(run.summary, None);
    assert_eq!(run.metadata["manifest"]["canonical"], CANONICAL);
    assert_eq!(run.metadata["run"]["threads"], "4");
    assert!(run.metadata.contains_key("build"));
    assert!(!run.metadata.contains_key("outcome"));
}

#[test]
fn dropped_recorder_leaves_an_unfinished_partial_with_all_messages() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dropped.mcap");
    let (mut rec, w) = record_run(&path, 2, 0.0);
    rec.write_diagnostics(99, &diagnostics(99)).unwrap();
    drop(rec);
    assert!(!path.exists());
    let run = read_run(&partial_path(&path)).unwrap();
    assert!(!run.complete);
    assert_eq!(run.stop, None);
    assert_eq!(run.states, w.states);
    assert_eq!(run.diagnostics.len(), w.diagnostics.len() + 1);
    assert_eq!(run.summary, None);
}

#[test]
fn truncated_tail_is_skipped_and_complete_chunks_recovered() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("trunc.mcap");
    let partial = partial_path(&path);
    let ov = overrides();
    let mut rec = Recorder::create(&path, &header(&ov)).unwrap();
    let mut sizes = vec![];
    let mut states = vec![];
    for k in 0..4 {
        let s = state(k, 0.0);
        rec.write_cloud(u64::from(k), &cloud(&s, u64::from(k)))
            .unwrap();
        rec.write_state(u64::from(k), &s).unwrap();
        states.push(s);
        sizes.push(fs::metadata(&partial).unwrap().len());
    }
    rec.finish(10, &Summary::default(), &Outcome::Completed)
        .unwrap();
    let full = fs::read(&path).unwrap();

    let cut = dir.path().join("cut.mcap");
    // Cut inside the chunk after checkpoint k: checkpoints 0..=k survive.
    for k in 0..3 {
        let mid = (sizes[k] + sizes[k + 1]) / 2;
        fs::write(&cut, &full[..mid as usize]).unwrap();
        let run = read_run(&cut).unwrap();
        assert!(!run.complete);
        // Cut short, as a killed run leaves it: not damaged, and placed at the chunk's start.
        let stop = run.stop.as_ref().unwrap_or_else(|| panic!("cut at {mid}"));
        assert!(!stop.damaged, "cut at {mid}: {stop}");
        assert_eq!(stop.at_byte, sizes[k], "cut at {mid}: {stop}");
        assert_eq!(run.states, states[..=k], "cut at {mid}");
        assert_eq!(run.clouds, k + 1);
    }
    // Cut exactly at a flush point: a clean record boundary.
    fs::write(&cut, &full[..sizes[1] as usize]).unwrap();
    let run = read_run(&cut).unwrap();
    assert_eq!((run.complete, run.stop.as_ref()), (false, None));
    assert_eq!(run.states, states[..2]);
    // A file that lost only its last byte has lost its footer.
    fs::write(&cut, &full[..full.len() - 1]).unwrap();
    let run = read_run(&cut).unwrap();
    assert!(!run.complete);
    assert_eq!(run.states, states);
    assert!(run.summary.is_some());
    let stop = run.stop.unwrap();
    assert!(!stop.damaged && stop.reason.contains("end magic"), "{stop}");
}

#[test]
fn corrupt_complete_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = finished_run(dir.path(), 0.0);
    let mut bytes = fs::read(&path).unwrap();
    // Flip a byte in the middle of the last chunk's compressed data.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let chunk = summary.chunk_indexes.last().unwrap();
    let i = (chunk.chunk_start_offset + chunk.chunk_length - chunk.compressed_size / 2) as usize;
    bytes[i] ^= 0x55;
    fs::write(&path, &bytes).unwrap();
    // Named with the chunk's offset (it fails its CRC or cannot be decompressed).
    let message = read_run(&path).unwrap_err().to_string();
    let named = format!("damaged: the chunk at byte {} ", chunk.chunk_start_offset);
    assert!(message.contains(&named), "{message}");
}

#[test]
fn files_that_are_not_run_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("notes.mcap");
    fs::write(&text, "name: not an mcap file\n").unwrap();
    assert!(read_run(&text).is_err());
    let empty = dir.path().join("empty.mcap");
    fs::write(&empty, b"").unwrap();
    assert!(read_run(&empty).is_err());
    // Magic only, cut inside the header record.
    let (path, _) = finished_run(dir.path(), 0.0);
    let bytes = fs::read(&path).unwrap();
    fs::write(&empty, &bytes[..12]).unwrap();
    assert!(read_run(&empty).is_err());
    assert!(read_run(&dir.path().join("missing.mcap")).is_err());
}

fn f32_at(data: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(data[at..at + 4].try_into().unwrap())
}

#[test]
fn point_cloud_packing_2d_and_3d() {
    // 2D: x, y, z = 0, then two fields.
    let pos = [0.5, -1.25, 2.0, 3.0, 1e-3, 7.5];
    let speed = [1.0f32, 2.0, 3.0];
    let kind = [0.0f32, 1.0, 2.0];
    let pc = point_cloud(
        1_500_000_123,
        2,
        &pos,
        &[("speed_m_s", &speed), ("kind", &kind)],
    );
    assert_eq!(pc.point_stride, 20);
    assert_eq!(pc.data.len(), 3 * 20);
    let names: Vec<(&str, u32, i32)> = pc
        .fields
        .iter()
        .map(|f| (f.name.as_str(), f.offset, f.r#type))
        .collect();
    let f32t = NumericType::Float32 as i32;
    assert_eq!(f32t, 7);
    assert_eq!(
        names,
        vec![
            ("x", 0, f32t),
            ("y", 4, f32t),
            ("z", 8, f32t),
            ("speed_m_s", 12, f32t),
            ("kind", 16, f32t)
        ]
    );
    for p in 0..3 {
        let b = p * 20;
        assert_eq!(f32_at(&pc.data, b), pos[2 * p] as f32);
        assert_eq!(f32_at(&pc.data, b + 4), pos[2 * p + 1] as f32);
        assert_eq!(f32_at(&pc.data, b + 8), 0.0);
        assert_eq!(f32_at(&pc.data, b + 12), speed[p]);
        assert_eq!(f32_at(&pc.data, b + 16), kind[p]);
    }
    assert_eq!(pc.frame_id, "world");
    let ts = pc.timestamp.unwrap();
    assert_eq!((ts.seconds, ts.nanos), (1, 500_000_123));
    let pose = pc.pose.unwrap();
    let q = pose.orientation.unwrap();
    assert_eq!((q.x, q.y, q.z, q.w), (0.0, 0.0, 0.0, 1.0));
    let p0 = pose.position.unwrap();
    assert_eq!((p0.x, p0.y, p0.z), (0.0, 0.0, 0.0));

    // 3D, no extra field; survives an encode/decode round trip.
    let pos3 = [1.0, 2.0, 3.0, -4.0, -5.0, -6.0];
    let pc3 = point_cloud(0, 3, &pos3, &[]);
    let pc3 = PointCloud::decode(&pc3.encode_to_vec()[..]).unwrap();
    assert_eq!(pc3.point_stride, 12);
    assert_eq!(pc3.data.len(), 24);
    let vals: Vec<f32> = (0..6).map(|i| f32_at(&pc3.data, 4 * i)).collect();
    assert_eq!(vals, vec![1.0, 2.0, 3.0, -4.0, -5.0, -6.0]);
}

#[test]
#[should_panic(expected = "has 2 values for 3 particles")]
fn point_cloud_rejects_a_short_field() {
    point_cloud(0, 2, &[0.0; 6], &[("speed_m_s", &[1.0, 2.0])]);
}

/// Runs `tools/check_mcap.py` (Python `mcap` + `mcap-protobuf-support`) on a finished and a
/// killed recording. Needs MPS_PYTHON, a python with tools/requirements.txt: tools/test.sh sets
/// it to its venv's.
#[test]
#[ignore = "needs the Python readers (tools/requirements.txt); tools/test.sh runs it"]
fn python_reader_accepts_our_files() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = common::python();
    let script = root.join("tools/check_mcap.py");
    let dir = tempfile::tempdir().unwrap();
    let (done, _) = finished_run(dir.path(), 0.0);
    let killed = dir.path().join("killed.mcap");
    let (rec, _) = record_run(&killed, 2, 0.0);
    std::mem::forget(rec);

    let run = |args: &[&std::ffi::OsStr]| {
        let out = std::process::Command::new(&python)
            .arg(&script)
            .args(args)
            .output()
            .expect("run python");
        let text = String::from_utf8_lossy(&out.stdout).to_string()
            + &String::from_utf8_lossy(&out.stderr);
        (out.status.success(), text)
    };
    let (ok, text) = run(&[done.as_os_str()]);
    assert!(ok, "{text}");
    let partial = partial_path(&killed);
    let (ok, text) = run(&["--partial".as_ref(), partial.as_os_str()]);
    assert!(ok, "{text}");
    // Without --partial, an unfinished file must be refused.
    let (ok, text) = run(&[partial.as_os_str()]);
    assert!(!ok, "{text}");
}

/// Set in the child process of `aborted_process_keeps_its_checkpoints`: where it records.
const CHILD_PATH: &str = "MPS_RECORD_CHILD_PATH";

/// A process that dies mid-run keeps its checkpoints. The test runs itself again as a child
/// process (with CHILD_PATH set) that writes three checkpoints and more messages, then aborts
/// (no destructor, no buffer flush: like SIGKILL); the parent reads what is left.
#[test]
fn aborted_process_keeps_its_checkpoints() {
    if let Some(path) = std::env::var_os(CHILD_PATH) {
        let (mut rec, _) = record_run(Path::new(&path), 3, 0.0);
        rec.write_diagnostics(99, &diagnostics(99)).unwrap();
        std::process::abort();
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("aborted.mcap");
    // The harness names a test by its path below the crate root (`record::...`).
    let (_, module) = module_path!().split_once("::").unwrap();
    let status = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            &format!("{module}::aborted_process_keeps_its_checkpoints"),
        ])
        .env(CHILD_PATH, &path)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(!status.success(), "the child should have aborted");
    assert!(!path.exists());
    let run = read_run(&partial_path(&path)).unwrap();
    let expected = (0..3).map(|k| state(k, 0.0)).collect::<Vec<_>>();
    assert!(!run.complete);
    assert_eq!(run.states, expected);
    assert_eq!(run.diagnostics.len(), 9);
    assert_eq!(run.summary, None);
    assert_eq!(run.metadata["manifest"]["experiment_sha256"], SHA);
}
