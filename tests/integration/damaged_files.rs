//! Damaged run files: each kind of damage in a finished file is named with its byte offset and
//! every command that reads the file refuses it (exit 2); a killed run's `.partial` with a
//! corrupt later chunk is read up to the last intact chunk and resumes from the last
//! checkpoint before the damage, to the same bits as a run that was never killed.
use crate::common;
use mps_runner::record::{RunFile, read_run};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn runner(args: &[&std::ffi::OsStr]) -> (Option<i32>, String) {
    common::runner_output(args)
}

/// A completed smoke run (6 checkpoints) in `dir`.
fn smoke(dir: &Path) -> PathBuf {
    let resolved = common::resolve("smoke_2d.yaml", &[]);
    common::run_completed(&resolved, dir, 1).path
}

/// (offset, opcode, body length) of every top-level record after the start magic.
fn records(bytes: &[u8]) -> Vec<(usize, u8, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        out.push((at, bytes[at], len));
        at += 9 + len;
    }
    out
}

fn first(bytes: &[u8], opcode: u8) -> (usize, usize) {
    records(bytes)
        .into_iter()
        .find(|r| r.1 == opcode)
        .map(|r| (r.0, r.2))
        .unwrap()
}

/// Offsets of the chunk records, in file order.
fn chunks(bytes: &[u8]) -> Vec<usize> {
    records(bytes)
        .into_iter()
        .filter(|r| r.1 == 0x06)
        .map(|r| r.0)
        .collect()
}

/// Offset of the `uncompressed_crc` field in the chunk record at `at` (after the record's
/// opcode and length: start time, end time, uncompressed size).
fn chunk_crc_field(at: usize) -> usize {
    at + 9 + 24
}

/// The file rewritten by the mcap writer with the same messages and metadata, leaving out
/// the `/summary` message or the `outcome` metadata: finished and consistent, CRCs and all.
fn rewritten_without(bytes: &[u8], drop_summary: bool, drop_outcome: bool) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    let mut w = mcap::WriteOptions::new()
        .profile("mps")
        .create(&mut out)
        .unwrap();
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    for index in &summary.metadata_indexes {
        if !(drop_outcome && index.name == "outcome") {
            w.write_metadata(&mcap::read::metadata(bytes, index).unwrap())
                .unwrap();
        }
    }
    let mut ids: BTreeMap<String, u16> = BTreeMap::new();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        if drop_summary && m.channel.topic == "/summary" {
            continue;
        }
        let id = match ids.get(&m.channel.topic) {
            Some(id) => *id,
            None => {
                let schema = m.channel.schema.as_ref().unwrap();
                let s = w
                    .add_schema(&schema.name, &schema.encoding, &schema.data)
                    .unwrap();
                let c = w
                    .add_channel(s, &m.channel.topic, "protobuf", &BTreeMap::new())
                    .unwrap();
                ids.insert(m.channel.topic.clone(), c);
                c
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        w.write_to_known_channel(&header, &m.data).unwrap();
    }
    w.finish().unwrap();
    drop(w);
    out.into_inner()
}

#[test]
fn each_kind_of_damage_in_a_finished_file_is_named_and_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke(dir.path());
    let whole = std::fs::read(&path).unwrap();
    let late = chunks(&whole)[chunks(&whole).len() - 3];
    let (data_end, _) = first(&whole, 0x0f);
    let (manifest_meta, _) = first(&whole, 0x0c);
    let (chunk_index, _) = first(&whole, 0x08);
    let footer = whole.len() - 8 - 29;
    let flip = |at: usize| {
        let mut b = whole.clone();
        b[at] ^= 0x10;
        b
    };
    let mut longer = whole.clone();
    longer[late + 1 + 4] = 0x7f; // a length byte of the chunk record
    let cases: Vec<(&str, Vec<u8>, String)> = vec![
        (
            "a flipped bit in a late chunk's CRC",
            flip(chunk_crc_field(late)),
            format!("damaged: the chunk at byte {late} fails its CRC (stored "),
        ),
        (
            "a flipped bit in a late chunk's compressed data",
            flip(late + 200),
            format!("damaged: the chunk at byte {late} "),
        ),
        (
            "a chunk's length running past the end",
            longer,
            format!("damaged: the chunk record at byte {late} needs "),
        ),
        (
            "a flipped bit in the manifest metadata (outside chunks)",
            flip(manifest_meta + 100),
            format!("damaged: the data section (bytes 0 to {data_end}) fails its CRC"),
        ),
        (
            "a flipped bit in a chunk index",
            flip(chunk_index + 20),
            "damaged: the summary section is unreadable: bytes".to_string(),
        ),
        (
            "the footer pointing elsewhere",
            flip(footer + 9 + 1),
            "damaged: the summary section is unreadable: the footer places it at byte".to_string(),
        ),
        (
            "no /summary message",
            rewritten_without(&whole, true, false),
            "damaged: no /summary message: a finished run ends with one".to_string(),
        ),
        (
            "no outcome metadata",
            rewritten_without(&whole, false, true),
            "damaged: no `outcome` metadata record".to_string(),
        ),
    ];
    let svg = dir.path().join("drawn.svg");
    for (what, bytes, fragment) in &cases {
        let file = dir.path().join("damaged.mcap");
        std::fs::write(&file, bytes).unwrap();
        let error = read_run(&file).unwrap_err().to_string();
        assert!(error.contains(fragment.as_str()), "{what}: {error}");
        for command in ["verify", "plot", "snapshot", "profile", "resume"] {
            let mut args: Vec<&std::ffi::OsStr> = vec![command.as_ref(), file.as_os_str()];
            if command != "verify" && command != "resume" {
                args.extend([std::ffi::OsStr::new("--out"), svg.as_os_str()]);
            }
            let (code, stderr) = runner(&args);
            assert_eq!(code, Some(2), "{what}, {command}: {stderr}");
            assert!(
                stderr.contains(fragment.as_str()),
                "{what}, {command}: {stderr}"
            );
        }
        assert!(!svg.exists(), "{what}: something was drawn");
        assert_eq!(
            &std::fs::read(&file).unwrap(),
            bytes,
            "{what}: file changed"
        );
    }
    // The same file whole reads and verifies.
    assert!(read_run(&path).unwrap().complete);
    let (code, stderr) = runner(&["verify".as_ref(), path.as_os_str(), "-q".as_ref()]);
    assert_eq!(code, Some(0), "{stderr}");
}

#[test]
fn a_killed_run_with_a_corrupt_late_chunk_resumes_from_the_last_intact_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let reference_path = smoke(&dir.path().join("reference"));
    let reference = read_run(&reference_path).unwrap();
    let whole = std::fs::read(&reference_path).unwrap();
    // The last chunk holds the /summary message, the one before it the final checkpoint.
    let starts = chunks(&whole);
    let n = starts.len();
    // As a killed run leaves it: cut inside the chunk of its final checkpoint ...
    let mut killed = whole[..starts[n - 2] + 40].to_vec();
    // ... and a byte inside an earlier chunk's compressed data damaged on disk since.
    let damaged_at = starts[n - 4];
    killed[damaged_at + 300] ^= 0x01;
    // The checkpoints in the chunks before the damaged one.
    let cut_there = dir.path().join("cut_there.mcap.partial");
    std::fs::write(&cut_there, &whole[..damaged_at]).unwrap();
    let intact = read_run(&cut_there).unwrap().states.len();
    assert!(
        intact >= 2 && intact + 2 <= reference.states.len(),
        "{intact}"
    );

    let out = dir.path().join("killed");
    std::fs::create_dir(&out).unwrap();
    let partial = out.join(format!(
        "{}.partial",
        reference_path.file_name().unwrap().to_string_lossy()
    ));
    std::fs::write(&partial, &killed).unwrap();
    let run: RunFile = read_run(&partial).unwrap();
    let stop = run.stop.clone().unwrap();
    assert!(!run.complete);
    assert!(stop.damaged, "{stop}");
    assert_eq!(stop.at_byte, damaged_at as u64, "{stop}");
    // Everything before the damaged chunk, nothing from it or after it.
    assert_eq!(run.states, reference.states[..intact]);
    assert!(run.diagnostics.len() < reference.diagnostics.len());
    assert_eq!(
        run.diagnostics,
        reference.diagnostics[..run.diagnostics.len()]
    );

    // verify and plot use what is intact and warn.
    let warning = format!("is damaged: the chunk at byte {damaged_at} ");
    let (code, stderr) = runner(&["verify".as_ref(), partial.as_os_str(), "-q".as_ref()]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains(&warning), "{stderr}");
    let svg = dir.path().join("partial.svg");
    let (code, stderr) = runner(&[
        "plot".as_ref(),
        partial.as_os_str(),
        "--out".as_ref(),
        svg.as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains(&warning), "{stderr}");

    let (code, stderr) = runner(&[
        "resume".as_ref(),
        partial.as_os_str(),
        "-q".as_ref(),
        "--threads".as_ref(),
        "1".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains(&warning), "{stderr}");
    assert!(
        stderr.contains(&format!("resumed from checkpoint {}", intact - 1)),
        "{stderr}"
    );
    let resumed_path = out.join(reference_path.file_name().unwrap());
    let files: Vec<_> = std::fs::read_dir(&out).unwrap().collect();
    assert_eq!(files.len(), 1, "only the resumed file is left: {files:?}");
    let resumed = read_run(&resumed_path).unwrap();
    assert!(resumed.complete);
    assert_eq!(resumed.summary.as_ref().unwrap().outcome, "completed");
    assert_eq!(resumed.states, reference.states);
    assert_eq!(resumed.diagnostics, reference.diagnostics);
    assert_eq!(resumed.clouds, reference.clouds);
    assert_eq!(
        resumed.summary.as_ref().unwrap().checkpoints,
        reference.summary.as_ref().unwrap().checkpoints
    );
    assert_eq!(
        resumed.summary.as_ref().unwrap().metrics,
        reference.summary.as_ref().unwrap().metrics
    );
    let (code, stderr) = runner(&["verify".as_ref(), resumed_path.as_os_str(), "-q".as_ref()]);
    assert_eq!(code, Some(0), "{stderr}");
    common::assert_replays(&resumed_path, None);
}

#[test]
fn an_attachment_too_short_for_its_crc_is_damage_not_a_panic() {
    // The mcap crate slices an attachment body by its data length and takes the last 4 bytes
    // as its CRC without checking that they follow the data (it panics on this record).
    let dir = tempfile::tempdir().unwrap();
    let whole = std::fs::read(smoke(dir.path())).unwrap();
    let (at, _) = first(&whole, 0x09);
    let mut body = Vec::new();
    body.extend_from_slice(&[0u8; 16]); // log and create times
    body.extend_from_slice(&0u32.to_le_bytes()); // name ""
    body.extend_from_slice(&0u32.to_le_bytes()); // media type ""
    body.extend_from_slice(&0u64.to_le_bytes()); // data length 0, then no CRC
    let mut bytes = whole[..at].to_vec();
    bytes.push(0x09);
    bytes.extend_from_slice(&(body.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&body);
    let partial = dir.path().join("short.mcap.partial");
    std::fs::write(&partial, &bytes).unwrap();
    let run = read_run(&partial).unwrap();
    let stop = run.stop.unwrap();
    assert!(stop.damaged, "{stop}");
    assert_eq!(stop.at_byte, at as u64);
    assert!(
        stop.reason.contains("attachment record") && stop.reason.contains("shorter"),
        "{stop}"
    );
}
