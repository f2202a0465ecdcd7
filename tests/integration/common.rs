//! Helpers shared by the integration tests.
use mps_runner::experiment::{self, Resolved};
use mps_runner::run::{RunOptions, RunResult, run};
use std::path::{Path, PathBuf};

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The Python with the `mcap` readers (tools/requirements.txt) for the tests that drive them.
/// Panics when MPS_PYTHON is unset: an ignored test run by `--include-ignored` must not pass
/// without checking anything.
pub fn python() -> PathBuf {
    match std::env::var_os("MPS_PYTHON") {
        Some(path) => PathBuf::from(path),
        None => panic!(
            "MPS_PYTHON is not set: this test drives the Python mcap reader. Run tools/test.sh \
             (it creates .venv and sets MPS_PYTHON to .venv/bin/python), or set MPS_PYTHON to a \
             python with tools/requirements.txt installed."
        ),
    }
}

pub fn experiment(name: &str) -> PathBuf {
    root().join("experiments").join(name)
}

/// The solver at t = 0 of a resolved manifest's scene, for tests that step it in process.
pub fn solver_of<const D: usize>(m: &experiment::Manifest) -> mps_runner::mps::Solver<D> {
    let scene = experiment::build_scene::<D>(m);
    mps_runner::mps::Solver::new(mps_runner::run::solver_config(m, &scene), scene.particles)
}

pub fn resolve(name: &str, sets: &[&str]) -> Resolved {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    experiment::load(&experiment(name), &sets).expect("manifest")
}

/// Asserts that `name` with `sets` is refused with an error that contains `field` (the
/// field's name and the start of the reason).
pub fn assert_refused(name: &str, sets: &[&str], field: &str) {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    let error = experiment::load(&experiment(name), &sets)
        .expect_err(field)
        .to_string();
    assert!(error.contains(field), "{sets:?}: {error}");
}

/// `rodding_2d.yaml` at 10 mm, its rod 20 mm (two spacings, the narrowest it may be), with
/// `sets` after: the coarse rodding of the tests.
pub fn rodding_10_mm(sets: &[&str]) -> Resolved {
    let all = [&["spacing_m=0.01", "scene.rod_width_m=0.02"], sets].concat();
    resolve("rodding_2d.yaml", &all)
}

pub fn run_in(resolved: &Resolved, out_dir: &Path, threads: usize) -> RunResult {
    run(
        resolved,
        &RunOptions {
            out_dir: out_dir.to_path_buf(),
            threads: Some(threads),
            progress: None,
            interrupt: None,
            max_particles: None,
            overwrite: false,
        },
    )
    .expect("run")
}

/// f() on a worker pool of `threads` threads, the one runs use (`run::thread_pool`).
pub fn on_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    let (pool, _) = mps_runner::run::thread_pool(Some(threads)).expect("a thread pool");
    pool.install(f)
}

/// Runs and asserts that the run completed (its reason otherwise).
pub fn run_completed(resolved: &Resolved, out_dir: &Path, threads: usize) -> RunResult {
    let result = run_in(resolved, out_dir, threads);
    assert_eq!(
        result.outcome,
        mps_runner::record::Outcome::Completed,
        "{}: {}",
        resolved.manifest.name,
        result.summary.reason
    );
    result
}

/// Replays `path` from logged checkpoint `from` (None: from the start) on one thread and
/// asserts that every later checkpoint is identical bit for bit.
pub fn assert_replays(path: &Path, from: Option<u32>) {
    let report = mps_runner::verify::verify(
        path,
        &mps_runner::verify::VerifyOptions {
            from,
            threads: Some(1),
            ..mps_runner::verify::VerifyOptions::default()
        },
    )
    .unwrap();
    assert!(report.passed(), "{report}");
}

/// The `runner` binary as a command to run and assert on.
pub fn runner() -> assert_cmd::Command {
    assert_cmd::Command::cargo_bin("runner").unwrap()
}

/// The `runner` binary as a process to spawn (and signal).
pub fn runner_process() -> std::process::Command {
    use assert_cmd::cargo::CommandCargoExt;
    std::process::Command::cargo_bin("runner").unwrap()
}

/// Runs the `runner` binary with `args`: its exit code and its stderr.
pub fn runner_output<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> (Option<i32>, String) {
    let (code, _, stderr) = runner_all(args);
    (code, stderr)
}

/// Runs the `runner` binary with `args`: its exit code, stdout and stderr.
pub fn runner_all<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> (Option<i32>, String, String) {
    let out = runner().args(args).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A finished 2-point sweep of smoke_2d (`scene.column_width_m` 0.1 and 0.15, 0.04 s) run by
/// the binary in `dir`; returns the sweep folder.
pub fn smoke_sweep_folder(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(experiment("smoke_2d.yaml")).unwrap();
    let manifest = dir.join("sweep.yaml");
    std::fs::write(
        &manifest,
        format!("{text}\nsweep:\n  scene.column_width_m: [0.1, 0.15]\n"),
    )
    .unwrap();
    let out = dir.join("runs");
    let (code, stdout, err) = runner_all(&[
        manifest.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--set".as_ref(),
        "time.end_s=0.04".as_ref(),
        "--quiet".as_ref(),
        "--threads".as_ref(),
        "2".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    PathBuf::from(stdout.lines().last().unwrap())
}

/// The quiet 2D set of `--set`s (docs/validation.md, "Holding still"): the incremental scheme
/// with its stabilisers, the pressure regularisation, the surface depth and the corrected
/// strain rate; the compressibility that damps the increment's two-step mode is not in it.
/// Over the standard scheme (`mps.preset=standard` first), so that a 2D test gets this set and
/// nothing of the 2D default preset, as measured before that default.
pub const QUIET_2D: [&str; 7] = [
    "mps.preset=standard",
    "mps.pressure_scheme=incremental",
    "mps.pair_stabilisation=0.8",
    "mps.wall_support=0.95",
    "mps.pressure_regularisation=1",
    "mps.surface_depth=0.5",
    "mps.corrected_strain_rate=true",
];

/// The quiet 3D set: the 2D set without the pressure regularisation (2D only); 3D has no
/// default preset.
pub const QUIET_3D: [&str; 5] = [
    "mps.pressure_scheme=incremental",
    "mps.pair_stabilisation=0.8",
    "mps.wall_support=0.95",
    "mps.surface_depth=0.5",
    "mps.corrected_strain_rate=true",
];
