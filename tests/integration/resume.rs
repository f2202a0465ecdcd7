//! Interrupts and resume, end to end with the real binary: SIGINT (and SIGTERM) finish the
//! file as interrupted, SIGKILL leaves a `.partial` file; `runner resume` on either gives the
//! same checkpoint hashes (and as many diagnostics rows and clouds) as a run that was never
//! interrupted. A run file being written, finished or left by a killed run is never overwritten
//! by another runner unless asked (`--overwrite`).
use crate::common;
use mps_runner::record::{RunFile, read_run};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Long enough (about 2000 steps) to be interrupted well before its end.
const SETS: [&str; 4] = ["--set", "time.end_s=2", "--threads", "2"];

fn start(out: &Path) -> Child {
    start_with("smoke_2d.yaml", &SETS, out)
}

fn start_with(experiment: &str, sets: &[&str], out: &Path) -> Child {
    common::runner_process()
        .arg(common::experiment(experiment))
        .arg("--out")
        .arg(out)
        .args(sets)
        .arg("-q")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

/// The `.partial` file of a run in `out`, once it holds at least `n` checkpoints.
fn wait_for_checkpoints(out: &Path, n: usize) -> PathBuf {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        assert!(Instant::now() < deadline, "no {n} checkpoints in time");
        let partial = std::fs::read_dir(out).ok().and_then(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .find(|p| p.to_string_lossy().ends_with(".mcap.partial"))
        });
        if let Some(p) = partial.filter(|p| read_run(p).is_ok_and(|r| r.states.len() >= n)) {
            return p;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn signal(child: &Child, sig: &str) {
    let status = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

fn resume(path: &Path) -> PathBuf {
    let out = common::runner_process()
        .args(["resume", "-q", "--threads", "1"])
        .arg(path)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    PathBuf::from(String::from_utf8(out.stdout).unwrap().trim())
}

fn verify_ok(path: &Path) {
    let out = common::runner_process()
        .args(["verify", "-q"])
        .arg(path)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

fn hashes(run: &RunFile) -> Vec<(u32, u64, u64, String)> {
    run.summary
        .as_ref()
        .unwrap()
        .checkpoints
        .iter()
        .map(|c| (c.index, c.step, c.time_s.to_bits(), c.state_sha256.clone()))
        .collect()
}

fn assert_same_run(resumed: &RunFile, reference: &RunFile) {
    assert!(resumed.complete);
    assert_eq!(resumed.summary.as_ref().unwrap().outcome, "completed");
    assert_eq!(hashes(resumed), hashes(reference));
    assert_eq!(resumed.states, reference.states);
    assert_eq!(resumed.diagnostics, reference.diagnostics);
    assert_eq!(resumed.clouds, reference.clouds);
    assert_eq!(
        resumed.summary.as_ref().unwrap().metrics,
        reference.summary.as_ref().unwrap().metrics
    );
    assert!(resumed.metadata.contains_key("resumed"));
}

fn only_file(dir: &Path) -> PathBuf {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    files[0].clone()
}

#[test]
fn resume_after_sigint_sigterm_and_sigkill_matches_an_uninterrupted_run() {
    let dir = tempfile::tempdir().unwrap();
    let reference_dir = dir.path().join("uninterrupted");
    let status = start(&reference_dir).wait().unwrap();
    assert!(status.success());
    let reference = read_run(&only_file(&reference_dir)).unwrap();
    assert!(hashes(&reference).len() > 90);

    for sig in ["-INT", "-TERM"] {
        let out = dir.path().join(sig);
        let mut child = start(&out);
        wait_for_checkpoints(&out, 5);
        signal(&child, sig);
        let status = child.wait().unwrap();
        assert_eq!(status.code(), Some(130), "{sig}");
        // Finished, marked interrupted, final state checkpointed; it verifies as it stands.
        let file = only_file(&out);
        assert!(file.to_string_lossy().ends_with(".mcap"));
        let interrupted = read_run(&file).unwrap();
        assert!(interrupted.complete);
        let summary = interrupted.summary.as_ref().unwrap();
        assert_eq!(summary.outcome, "interrupted");
        assert_eq!(interrupted.metadata["outcome"]["status"], "interrupted");
        assert!(summary.checkpoints.len() < hashes(&reference).len());
        assert_eq!(
            interrupted.states.last().unwrap().step as f64,
            summary.metrics["steps"],
            "the last checkpoint is the state at the interruption"
        );
        verify_ok(&file);
        let resumed = resume(&file);
        assert_eq!(resumed, file, "same final path");
        assert_same_run(&read_run(&resumed).unwrap(), &reference);
        verify_ok(&resumed);
        assert_eq!(only_file(&out), resumed);
    }

    let out = dir.path().join("kill");
    let mut child = start(&out);
    let partial = wait_for_checkpoints(&out, 5);
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let killed = read_run(&partial).unwrap();
    assert!(!killed.complete);
    assert!(killed.states.len() >= 5);
    verify_ok(&partial);
    let resumed = resume(&partial);
    assert_eq!(
        resumed.to_string_lossy(),
        partial.to_string_lossy().trim_end_matches(".partial")
    );
    assert_same_run(&read_run(&resumed).unwrap(), &reference);
    // Nothing else left behind (no .partial, no moved-aside source).
    assert_eq!(only_file(&out), resumed);
}

#[test]
fn resume_refuses_a_completed_run() {
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve("smoke_2d.yaml", &["time.end_s=0.02"]);
    let path = common::run_in(&resolved, dir.path(), 1).path;
    let out = common::runner_process()
        .arg("resume")
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("already completed"));
}

#[test]
fn an_interrupted_library_run_resumes_to_the_same_hashes() {
    // Interrupt flag set before the run: it stops at step 0 after its first checkpoint.
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve("smoke_2d.yaml", &[]);
    let reference = common::run_in(&resolved, &dir.path().join("ref"), 2);
    let out = dir.path().join("int");
    let result = mps_runner::run::run(
        &resolved,
        &mps_runner::run::RunOptions {
            out_dir: out.clone(),
            threads: Some(2),
            progress: None,
            interrupt: Some(Arc::new(AtomicBool::new(true))),
            max_particles: None,
            overwrite: false,
        },
    )
    .unwrap();
    assert_eq!(result.summary.outcome, "interrupted");
    assert_eq!(result.summary.checkpoints.len(), 1);
    let resumed = mps_runner::resume::resume(
        &result.path,
        &mps_runner::resume::ResumeOptions {
            threads: Some(1),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(resumed.from_checkpoint, 0);
    assert_eq!(
        resumed.result.summary.checkpoints,
        reference.summary.checkpoints
    );
}

#[test]
fn a_pour_killed_while_pouring_resumes_to_the_same_bits() {
    // pour_2d with 120 particles to pour (0.2 s) and a checkpoint every 0.02 s: killed once
    // 4 checkpoints (t = 0.06 s) are on disk, so normally mid-pour; the resumed run must
    // match an uninterrupted one wherever the kill landed (particle count, tags, inlet
    // progress all come from the checkpoint).
    let sets = [
        "--set",
        "boundaries.inlets.0.volume_m3=0.012",
        "--set",
        "time.end_s=0.4",
        "--set",
        "output.checkpoint_interval_s=0.02",
        "--threads",
        "2",
    ];
    let dir = tempfile::tempdir().unwrap();
    let reference_dir = dir.path().join("uninterrupted");
    assert!(
        start_with("pour_2d.yaml", &sets, &reference_dir)
            .wait()
            .unwrap()
            .success()
    );
    let reference = read_run(&only_file(&reference_dir)).unwrap();
    let out = dir.path().join("kill");
    let mut child = start_with("pour_2d.yaml", &sets, &out);
    let partial = wait_for_checkpoints(&out, 4);
    child.kill().unwrap();
    child.wait().unwrap();
    let killed = read_run(&partial).unwrap();
    assert!(!killed.complete);
    verify_ok(&partial);
    let resumed = resume(&partial);
    assert_same_run(&read_run(&resumed).unwrap(), &reference);
    verify_ok(&resumed);
}

fn run_smoke(out: &Path, extra: &[&str]) -> std::process::Output {
    common::runner_process()
        .arg(common::experiment("smoke_2d.yaml"))
        .arg("--out")
        .arg(out)
        .arg("-q")
        .args(extra)
        .output()
        .unwrap()
}

fn refused_with(out: &std::process::Output, fragments: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(out.stdout.is_empty(), "no file path printed");
    for f in fragments {
        assert!(stderr.contains(f), "{f:?} not in: {stderr}");
    }
}

#[test]
fn a_finished_run_is_replaced_only_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let first = run_smoke(dir.path(), &[]);
    assert!(first.status.success());
    let path = only_file(dir.path());
    let bytes = std::fs::read(&path).unwrap();
    refused_with(
        &run_smoke(dir.path(), &[]),
        &["already exists", "--overwrite", "runner verify"],
    );
    assert_eq!(std::fs::read(&path).unwrap(), bytes, "left as it was");
    assert_eq!(only_file(dir.path()), path, "no .partial left behind");
    // --overwrite runs again: the same experiment and build give the same checkpoints.
    assert!(run_smoke(dir.path(), &["--overwrite"]).status.success());
    assert_eq!(only_file(dir.path()), path);
    assert_eq!(
        hashes(&read_run(&path).unwrap()),
        hashes(&read_run_bytes(&bytes))
    );
    verify_ok(&path);
}

fn read_run_bytes(bytes: &[u8]) -> RunFile {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("copy.mcap");
    std::fs::write(&path, bytes).unwrap();
    read_run(&path).unwrap()
}

#[test]
fn a_run_being_written_is_left_alone_by_a_second_runner_and_by_resume() {
    // About 20000 steps (several seconds): still running while the others are refused.
    let sets = ["--set", "time.end_s=20", "--threads", "1"];
    let dir = tempfile::tempdir().unwrap();
    let mut child = start_with("smoke_2d.yaml", &sets, dir.path());
    let partial = wait_for_checkpoints(dir.path(), 2);
    let busy = ["another runner is writing", ".partial"];
    refused_with(&run_smoke(dir.path(), &sets), &busy);
    let mut overwrite = sets.to_vec();
    overwrite.push("--overwrite");
    refused_with(&run_smoke(dir.path(), &overwrite), &busy);
    let out = common::runner_process()
        .args(["resume", "-q"])
        .arg(&partial)
        .output()
        .unwrap();
    refused_with(&out, &busy);
    // The first run was not disturbed: stopped now, it finishes its file as usual.
    signal(&child, "-INT");
    assert_eq!(child.wait().unwrap().code(), Some(130));
    let file = only_file(dir.path());
    assert_eq!(
        read_run(&file).unwrap().summary.unwrap().outcome,
        "interrupted"
    );
    verify_ok(&file);
}

#[test]
fn a_killed_runs_partial_is_kept_until_resumed_or_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = start(dir.path());
    let partial = wait_for_checkpoints(dir.path(), 3);
    child.kill().unwrap();
    child.wait().unwrap();
    let bytes = std::fs::read(&partial).unwrap();
    refused_with(
        &run_smoke(dir.path(), &SETS),
        &["holds an unfinished run", "runner resume", "--overwrite"],
    );
    assert_eq!(std::fs::read(&partial).unwrap(), bytes, "kept as it was");
    let resumed = resume(&partial);
    assert_eq!(only_file(dir.path()), resumed);
    assert_eq!(
        read_run(&resumed).unwrap().summary.unwrap().outcome,
        "completed"
    );
}

/// Many recorders of one run file at once, in one process (the lock is per open file, so
/// threads contend as processes do): exactly one gets to write it, the others are refused
/// and nothing they did shows in the file.
#[test]
fn concurrent_recorders_of_one_file_get_it_once() {
    use mps_runner::record::{Outcome, RecordError, Recorder};
    use std::sync::Barrier;
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve("smoke_2d.yaml", &[]);
    let path = mps_runner::run::output_path(dir.path(), &resolved);
    let header = mps_runner::run::run_header(&resolved, 1);
    let barrier = Barrier::new(8);
    let results: Vec<Result<Recorder, RecordError>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..8)
            .map(|_| {
                s.spawn(|| {
                    barrier.wait();
                    Recorder::create(&path, &header)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let (winners, refused): (Vec<_>, Vec<_>) = results.into_iter().partition(Result::is_ok);
    assert_eq!(winners.len(), 1);
    for r in &refused {
        let e = r.as_ref().err().unwrap();
        assert!(matches!(e, RecordError::Busy { .. }), "{e}");
    }
    let recorder = winners.into_iter().next().unwrap().unwrap();
    let summary = mps_runner::proto::mps::v1::Summary::default();
    let finished = recorder.finish(0, &summary, &Outcome::Completed).unwrap();
    assert_eq!(finished, path);
    assert!(read_run(&path).unwrap().complete);
    assert!(matches!(
        Recorder::create(&path, &header),
        Err(RecordError::Exists { .. })
    ));
}
