//! `runner verify`: fresh runs verify, tampered files fail with a precise message, unusable
//! files exit 2, segments replay.
use crate::common;
use mps_runner::checkpoint::state_sha256;
use mps_runner::record::{Outcome, Recorder, RunHeader, read_run};
use mps_runner::restore::{Logged, read_messages};
use mps_runner::verify::{VerifyOptions, verify};
use std::path::{Path, PathBuf};

/// A completed smoke run in `dir`.
fn smoke_run(dir: &Path) -> PathBuf {
    let resolved = common::resolve("smoke_2d.yaml", &[]);
    common::run_in(&resolved, dir, 2).path
}

/// An edit of one checkpoint message.
type StateEdit = Box<dyn Fn(&mut mps_runner::proto::mps::v1::StateCheckpoint)>;

/// What a rewrite may change.
#[derive(Default)]
struct Edit {
    /// (checkpoint index, edit applied to that checkpoint)
    state: Option<(usize, StateEdit)>,
    /// Recompute the edited checkpoint's stored hash and the summary's list (a careful forger).
    rehash: bool,
    canonical: Option<(String, String)>,
    overrides: Option<Vec<String>>,
    experiment_sha256: Option<String>,
    /// Leave out the recorded default preset.
    drop_default_preset: bool,
    /// Record this preset revision instead (`Some(None)`: none, as files from before).
    preset_revision: Option<Option<u32>>,
}

/// Rewrites the run file `src` to `dst` through the Recorder, with `edit` applied.
fn rewrite(src: &Path, dst: &Path, edit: Edit) {
    let run = read_run(src).unwrap();
    let meta = &run.metadata["manifest"];
    let mut canonical = meta["canonical"].clone();
    if let Some((from, to)) = &edit.canonical {
        assert!(canonical.contains(from.as_str()), "{canonical}");
        canonical = canonical.replace(from.as_str(), to);
    }
    let overrides: Vec<String> = edit
        .overrides
        .clone()
        .unwrap_or_else(|| serde_json::from_str(&meta["overrides"]).unwrap());
    let hash = edit
        .experiment_sha256
        .clone()
        .unwrap_or_else(|| meta["experiment_sha256"].clone());
    let header = RunHeader {
        manifest_source: &meta["source"],
        overrides: &overrides,
        canonical: &canonical,
        experiment_sha256: &hash,
        name: &meta["name"],
        default_preset: meta
            .get("default_preset")
            .map(String::as_str)
            .filter(|_| !edit.drop_default_preset),
        preset_revision: edit.preset_revision.unwrap_or_else(|| {
            meta.get("preset_revision")
                .map(|r| r.parse().expect("a recorded revision is a number"))
        }),
        threads: 1,
    };
    let mut rec = Recorder::create(dst, &header).unwrap();
    let mut summary = None;
    let mut index = 0;
    let mut new_hash = None;
    for (t, msg) in read_messages(src).unwrap() {
        match msg {
            Logged::State(mut s) => {
                if let Some((_, f)) = edit.state.as_ref().filter(|(k, _)| *k == index) {
                    f(&mut s);
                    if edit.rehash {
                        s.state_sha256 = state_sha256(&s);
                        new_hash = Some(s.state_sha256.clone());
                    }
                }
                index += 1;
                rec.write_state(t, &s).unwrap();
            }
            Logged::Diagnostics(d) => rec.write_diagnostics(t, &d).unwrap(),
            Logged::Cloud(c) => rec.write_cloud(t, &c).unwrap(),
            Logged::Summary(s) => summary = Some((t, s)),
        }
    }
    let (t, mut summary) = summary.unwrap();
    if let (Some(h), Some((k, _))) = (new_hash, &edit.state) {
        summary.checkpoints[*k].state_sha256 = h;
    }
    summary.experiment_sha256 = hash.clone();
    let outcome = match summary.outcome.as_str() {
        "completed" => Outcome::Completed,
        "failed" => Outcome::Failed(summary.reason.clone()),
        _ => Outcome::Interrupted(summary.reason.clone()),
    };
    rec.finish(t, &summary, &outcome).unwrap();
}

fn verify_cli(path: &Path) -> (i32, String) {
    let out = common::runner()
        .args(["verify", "-q"])
        .arg(path)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code().unwrap(), text)
}

#[test]
fn fresh_run_verifies_and_an_untouched_rewrite_too() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke_run(dir.path());
    let (code, text) = verify_cli(&path);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("ok: 6 of 6 checkpoints identical bit for bit"),
        "{text}"
    );
    assert!(text.contains("summary metrics identical"), "{text}");
    assert!(
        !text.contains("warning"),
        "same build must not warn: {text}"
    );
    // The rewrite helper itself changes nothing that matters.
    let copy = dir.path().join("copy.mcap");
    rewrite(&path, &copy, Edit::default());
    let (code, text) = verify_cli(&copy);
    assert_eq!(code, 0, "{text}");
}

#[test]
fn every_experiment_verifies_at_coarse_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let mut names: Vec<_> = std::fs::read_dir(common::root().join("experiments"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".yaml"))
        .collect();
    names.sort();
    assert!(!names.is_empty());
    for name in names {
        let mut sets = vec![
            "spacing_m=0.025",
            "time.end_s=0.05",
            "output.checkpoint_interval_s=0.01",
        ];
        if name == "rodding_2d.yaml" {
            // At 25 mm the rod must be two spacings wide and one spacing from the walls and
            // the floor: one 50 mm rod in the middle of the 150 mm form.
            sets.extend([
                "scene.rod_width_m=0.05",
                "scene.stroke_positions_m.0=0.075",
                "scene.stroke_positions_m.1=0.075",
                "scene.stroke_positions_m.2=0.075",
                "scene.stroke_bottom_m=0.025",
            ]);
        }
        if name.starts_with("rockfill_") && name != "rockfill_3d.yaml" {
            // The 2D beds: rocks at least two spacings across, both classes of 60 mm.
            sets.push("scene.bed.sizes.0.diameter_m=0.06");
        }
        if name == "inclined_layer.yaml" {
            // The periodic cell must hold three list cells: 3 (3.1 + 0.5) 25 mm = 0.27 m.
            sets.push("scene.period_m=0.3");
        }
        let resolved = common::resolve(&name, &sets);
        let result = common::run_in(&resolved, dir.path(), 2);
        let report = verify(
            &result.path,
            &VerifyOptions {
                threads: Some(1),
                ..VerifyOptions::default()
            },
        )
        .unwrap();
        assert!(report.passed(), "{name}: {report}");
        assert!(report.summary_compared, "{name}: {report}");
        assert_eq!(report.matched, result.summary.checkpoints.len(), "{report}");
    }
}

#[test]
fn segments_replay_from_a_logged_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke_run(dir.path());
    for (from, to, n) in [
        (Some(0), Some(2), 2),
        (Some(2), Some(4), 2),
        (Some(3), None, 2),
    ] {
        let report = verify(
            &path,
            &VerifyOptions {
                from,
                to,
                threads: Some(2),
                progress: None,
            },
        )
        .unwrap();
        assert!(report.passed(), "{report}");
        assert_eq!(report.matched, n, "{report}");
        assert_eq!(report.summary_compared, to.is_none(), "{report}");
    }
    let out = common::runner()
        .args(["verify", "-q", "--from", "5"])
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(2),
        "nothing after the last checkpoint"
    );
}

#[test]
fn a_changed_checkpoint_value_is_caught_with_particle_field_and_values() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke_run(dir.path());
    let logged = read_run(&path).unwrap().states[2].velocity_m_s[7];
    let bumped = f64::from_bits(logged.to_bits() + 1);
    for rehash in [false, true] {
        let tampered = dir.path().join(format!("tampered-{rehash}.mcap"));
        rewrite(
            &path,
            &tampered,
            Edit {
                state: Some((2, Box::new(move |s| s.velocity_m_s[7] = bumped))),
                rehash,
                ..Edit::default()
            },
        );
        let (code, text) = verify_cli(&tampered);
        eprintln!("verify of a tampered checkpoint (rehash = {rehash}):\n{text}");
        assert_eq!(code, 1, "{text}");
        assert!(
            text.contains("MISMATCH at checkpoint 2 (logged step 40"),
            "{text}"
        );
        assert!(
            text.contains("particle 3 (fluid) velocity_m_s[1]"),
            "{text}"
        );
        assert!(
            text.contains(&format!(
                "logged {bumped:e} (bits 0x{:016x}), replayed {logged:e} (bits 0x{:016x})",
                bumped.to_bits(),
                logged.to_bits()
            )),
            "{text}"
        );
        assert!(
            text.contains("FAILED: 2 of 6 checkpoints identical"),
            "{text}"
        );
        // A naive edit also leaves a stored hash that no longer matches its state.
        assert_eq!(
            text.contains("stored state_sha256")
                && text.contains("does not match the logged state"),
            !rehash,
            "{text}"
        );
    }
}

#[test]
fn a_changed_stored_manifest_is_caught() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke_run(dir.path());
    let run = read_run(&path).unwrap();
    let recorded = run.metadata["manifest"]["experiment_sha256"].clone();

    // One value of the canonical manifest changed, hash left alone.
    let tampered = dir.path().join("manifest.mcap");
    rewrite(
        &path,
        &tampered,
        Edit {
            canonical: Some((
                "\"gravity_m_s2\":9.81".into(),
                "\"gravity_m_s2\":9.8".into(),
            )),
            ..Edit::default()
        },
    );
    let (code, text) = verify_cli(&tampered);
    eprintln!("verify of a tampered manifest:\n{text}");
    assert_eq!(code, 1, "{text}");
    let changed = common::resolve("smoke_2d.yaml", &["gravity_m_s2=9.8"]).hash_hex;
    assert!(
        text.contains(&format!(
            "MISMATCH: manifest: the stored canonical form hashes to {changed}, but the file records experiment_sha256 {recorded}"
        )),
        "{text}"
    );

    // A consistent forgery (canonical, overrides and hash all changed): the replay is of a
    // different experiment, and the first checkpoint after the initial state differs.
    let forged = dir.path().join("forged.mcap");
    let changed_canonical = common::resolve("smoke_2d.yaml", &["gravity_m_s2=9.8"]).canonical;
    rewrite(
        &path,
        &forged,
        Edit {
            canonical: Some((
                run.metadata["manifest"]["canonical"].clone(),
                changed_canonical,
            )),
            overrides: Some(vec!["gravity_m_s2=9.8".into()]),
            experiment_sha256: Some(changed),
            ..Edit::default()
        },
    );
    let (code, text) = verify_cli(&forged);
    eprintln!("verify of a consistently forged manifest:\n{text}");
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("MISMATCH at checkpoint 1 (logged step 20"),
        "{text}"
    );
    assert!(
        text.contains("FAILED: 1 of 6 checkpoints identical"),
        "{text}"
    );
}

#[test]
fn unusable_files_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("not.mcap");
    std::fs::write(&text, "name: not an mcap file\n").unwrap();
    let empty = dir.path().join("empty.mcap");
    std::fs::write(&empty, "").unwrap();
    // A run file cut before its first checkpoint: header and metadata only.
    let resolved = common::resolve("smoke_2d.yaml", &[]);
    let started = dir.path().join("started.mcap");
    drop(
        Recorder::create(
            &started,
            &RunHeader {
                manifest_source: &resolved.source_text,
                overrides: &[],
                canonical: &resolved.canonical,
                experiment_sha256: &resolved.hash_hex,
                name: "smoke_2d",
                default_preset: resolved.default_preset.map(|p| p.name()),
                preset_revision: Some(resolved.preset_revision),
                threads: 1,
            },
        )
        .unwrap(),
    );
    let started = PathBuf::from(format!("{}.partial", started.display()));
    let missing = dir.path().join("missing.mcap");
    for (path, needle) in [
        (&text, "not.mcap"),
        (&empty, "empty.mcap"),
        (&started, "no state checkpoint"),
        (&missing, "missing.mcap"),
    ] {
        let (code, out) = verify_cli(path);
        assert_eq!(code, 2, "{}: {out}", path.display());
        assert!(out.contains(needle), "{out}");
    }
    // Neither a file nor --trend: a usage error.
    common::runner().arg("verify").assert().code(2);
}

#[test]
fn print_hashes_lists_every_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let path = smoke_run(dir.path());
    let out = common::runner()
        .args(["verify", "-q", "--print-hashes", "--threads", "1"])
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let stdout = String::from_utf8(out.stdout).unwrap();
    let summary = read_run(&path).unwrap().summary.unwrap();
    let lines: Vec<&str> = stdout.lines().skip(2).collect();
    assert_eq!(lines.len(), summary.checkpoints.len());
    for (line, c) in lines.iter().zip(&summary.checkpoints) {
        assert!(
            line.starts_with(&format!("{} {} ", c.index, c.step)),
            "{line}"
        );
        assert!(line.ends_with(&c.state_sha256), "{line}");
    }
}

#[test]
fn a_run_ended_by_its_stop_condition_verifies() {
    // A Bingham run that stops as soon as most particles are non-flowing (the L-flow rule):
    // the replay must stop at the same step and report the same summary.
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve(
        "l_flow_2d.yaml",
        &[
            "spacing_m=0.025",
            "time.end_s=0.5",
            "stop.non_flowing_after_s=0.002",
            "stop.non_flowing_fraction=0.5",
            "output.checkpoint_interval_s=0.001",
        ],
    );
    let result = common::run_in(&resolved, dir.path(), 2);
    assert_eq!(result.outcome, Outcome::Completed);
    assert!(
        result.stop_reason.contains("non-flowing"),
        "{}",
        result.stop_reason
    );
    // Everything is at rest before the flow starts, so the rule stops at its first check,
    // t >= stop.non_flowing_after_s = 0.002 s (dt = 1e-4 s: one step of margin). MEASURED:
    // 0.002 s.
    let stop = result.summary.metrics["stop_time_s"];
    assert!((0.002 - 1e-12..0.0021).contains(&stop), "{stop}");
    let (code, text) = verify_cli(&result.path);
    assert_eq!(code, 0, "{text}");
}

#[test]
fn a_run_stopped_as_settled_verifies_from_the_start_and_from_a_checkpoint() {
    // The rest rule compares a metric with its value at the previous checkpoint; a replay
    // from checkpoint K takes that value from the restored state, so it must stop at the same
    // checkpoint. The tolerance (5 cm per 10 ms) is loose enough to stop at the first check.
    let dir = tempfile::tempdir().unwrap();
    let settings = [
        "spacing_m=0.025",
        "time.end_s=0.5",
        "output.checkpoint_interval_s=0.01",
        "stop.rest_metric=front_position_m",
        "stop.rest_after_s=0.03",
    ];
    let loose: Vec<&str> = settings
        .iter()
        .copied()
        .chain(["stop.rest_metric_change=0.05"])
        .collect();
    let resolved = common::resolve("l_flow_2d.yaml", &loose);
    let result = common::run_in(&resolved, dir.path(), 2);
    assert_eq!(result.outcome, Outcome::Completed);
    assert!(
        result.stop_reason.contains("settled"),
        "{}",
        result.stop_reason
    );
    let stop = result.summary.metrics["stop_time_s"];
    // Checkpoints fall on the first step at or after each multiple of the interval (dt 1e-4 s);
    // the upper end leaves two steps.
    assert!((0.03..0.0302).contains(&stop), "stopped at {stop} s");
    assert_eq!(result.summary.checkpoints.len(), 4);
    let (code, text) = verify_cli(&result.path);
    assert_eq!(code, 0, "{text}");
    let out = common::runner()
        .args(["verify", "-q", "--from", "2"])
        .arg(&result.path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // A tolerance the moving front never meets: the run goes on to its end time.
    let strict: Vec<&str> = settings
        .iter()
        .copied()
        .chain(["stop.rest_metric_change=1e-9", "time.end_s=0.06"])
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let result = common::run_in(&common::resolve("l_flow_2d.yaml", &strict), dir.path(), 2);
    assert!(result.stop_reason.is_empty(), "{}", result.stop_reason);
    // The last step is cut to end at end_s; the time is a sum of 600 steps, round-off of
    // order 1e-16 s.
    assert!((result.summary.metrics["stop_time_s"] - 0.06).abs() < 1e-9);
}

/// A file records the default preset its source was resolved under, and is taken back up
/// under it: the 2D default (`mps.preset: quiet`, `manifest::default_preset`) is recorded and
/// load-bearing, since without it the source resolves to another experiment; a 3D file,
/// resolved under none, records nothing (the metadata layout before the default).
#[test]
fn a_file_resolved_under_a_default_preset_records_it_and_verifies() {
    use mps_runner::experiment::SceneSpec;
    use mps_runner::manifest::{self, PresetName};
    let dir = tempfile::tempdir().unwrap();
    let in_3d = common::run_completed(
        &common::resolve("slump_3d.yaml", &["spacing_m=0.025", "time.end_s=0.005"]),
        dir.path(),
        1,
    );
    let in_3d = read_run(&in_3d.path).unwrap();
    assert_eq!(in_3d.manifest_field("default_preset"), None);

    let path = common::experiment("smoke_2d.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    let sets = vec!["time.end_s=0.005".to_string()];
    let resolved = manifest::from_str::<SceneSpec>(&text, "smoke_2d.yaml", &sets).unwrap();
    assert_eq!(resolved.default_preset, Some(PresetName::Quiet));
    let before =
        manifest::from_str_under::<SceneSpec>(&text, "smoke_2d.yaml", &sets, None).unwrap();
    assert_ne!(resolved.hash_hex, before.hash_hex);
    let out = tempfile::tempdir().unwrap();
    let file = common::run_completed(&resolved, out.path(), 1).path;
    let run = read_run(&file).unwrap();
    assert_eq!(run.manifest_field("default_preset"), Some("quiet"));
    let back = mps_runner::restore::manifest_of(&run).unwrap();
    assert_eq!(back.hash_hex, resolved.hash_hex);
    assert_eq!(back.default_preset, Some(PresetName::Quiet));
    common::runner()
        .args(["verify", "--quiet"])
        .arg(&file)
        .assert()
        .success();
    // Without the record the source resolves under none, as a file from before the default
    // does, to another experiment, and verify says so: the record is what keeps such a file
    // verifiable.
    let cut = out.path().join("without_default.mcap");
    rewrite(
        &file,
        &cut,
        Edit {
            drop_default_preset: true,
            ..Edit::default()
        },
    );
    assert_source_resolves_to(verify_cli(&cut), &sets, &before.hash_hex);
}

/// Verify's answer `(code, text)` refuses a file whose stored source, with its overrides
/// `sets`, resolves to the experiment `hash` rather than the recorded one.
fn assert_source_resolves_to((code, text): (i32, String), sets: &[String], hash: &str) {
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains(&format!(
            "the stored source text with overrides {sets:?} resolves to experiment {hash}"
        )),
        "{text}"
    );
}

/// A file records the preset revision its source was resolved under (`manifest.preset_revision`)
/// and is taken back up under it, so that a preset that gains a field (revision 2: the walls'
/// own faces for a yield-stress fluid) leaves files written before verifying. A 2D Bingham run
/// under the default `quiet`, resolved as revision 1 resolved it: its file records 1 and
/// verifies; without the record (a file from before revisions) it reads as 1 and verifies; told
/// 2 its source resolves to revision 2's experiment, another one, and verify says so; a
/// revision this build does not know is refused. `info` names the preset by the file's revision.
#[test]
fn a_file_records_its_preset_revision_and_verifies_under_it() {
    use mps_runner::experiment::SceneSpec;
    use mps_runner::manifest::{self, PRESET_REVISION, PresetName};
    let path = common::experiment("inclined_layer.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    let sets: Vec<String> = ["spacing_m=0.01", "scene.period_m=0.12", "time.end_s=0.003"]
        .map(String::from)
        .to_vec();
    let as_of = |revision: u32| {
        manifest::from_str_as_of::<SceneSpec>(
            &text,
            "inclined_layer.yaml",
            &sets,
            Some(PresetName::Quiet),
            revision,
        )
        .unwrap()
    };
    let first = as_of(1);
    assert!(!first.manifest.mps.wall_face_normals);
    let today = manifest::from_str::<SceneSpec>(&text, "inclined_layer.yaml", &sets).unwrap();
    assert_eq!(today.preset_revision, PRESET_REVISION);
    assert!(today.manifest.mps.wall_face_normals);
    assert_ne!(first.hash_hex, today.hash_hex);
    let second = as_of(2);
    assert!(second.manifest.mps.wall_face_normals);
    let out = tempfile::tempdir().unwrap();
    let file = common::run_completed(&first, out.path(), 1).path;
    let run = read_run(&file).unwrap();
    assert_eq!(run.manifest_field("preset_revision"), Some("1"));
    assert_eq!(
        mps_runner::restore::manifest_of(&run)
            .unwrap()
            .preset_revision,
        1
    );
    let (code, text) = verify_cli(&file);
    assert_eq!(code, 0, "{text}");
    // `info` reads the scheme against the preset as it was at the file's revision.
    let info = common::runner().arg("info").arg(&file).output().unwrap();
    let info = String::from_utf8_lossy(&info.stdout);
    assert!(info.contains("(= mps.preset quiet)"), "{info}");
    let rewritten = |name: &str, revision: Option<u32>| {
        let to = out.path().join(name);
        rewrite(
            &file,
            &to,
            Edit {
                preset_revision: Some(revision),
                ..Edit::default()
            },
        );
        verify_cli(&to)
    };
    let (code, text) = rewritten("unrecorded.mcap", None);
    assert_eq!(code, 0, "{text}");
    assert_source_resolves_to(rewritten("told_2.mcap", Some(2)), &sets, &second.hash_hex);
    let (code, text) = rewritten("told_99.mcap", Some(99));
    assert_eq!(code, 1, "{text}");
    assert!(text.contains("unknown preset_revision \"99\""), "{text}");
}
