//! One measured child process (wall clock, exit status, peak memory) and the reading of
//! `runner bench`'s human-readable report. The report is parsed rather than changed to a
//! machine format so that an older binary of ours, given by `--runner`, can be measured the
//! same way (the "before" of a before/after comparison).

use std::ffi::OsString;
use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

/// What a child process did.
#[derive(Debug)]
pub struct Measured {
    /// Exit code; `None` when a signal ended it (see `signal`).
    pub code: Option<i32>,
    pub signal: Option<i32>,
    /// Spawn to exit, as the parent saw it.
    pub wall_s: f64,
    /// Peak resident memory of this child alone (KiB); `None` where it cannot be had.
    pub peak_kib: Option<u64>,
    pub stdout: String,
    pub stderr: String,
}

impl Measured {
    pub fn success(&self) -> bool {
        self.code == Some(0)
    }

    /// `exit 3`, `signal 9`.
    pub fn status_text(&self) -> String {
        match (self.code, self.signal) {
            (Some(c), _) => format!("exit {c}"),
            (None, Some(s)) => format!("signal {s}"),
            (None, None) => "unknown exit".to_string(),
        }
    }

    /// The child's first `error:` line on stderr (or its last line), for the progress log.
    pub fn error_line(&self) -> Option<&str> {
        let mut lines = self.stderr.lines().map(str::trim).filter(|l| !l.is_empty());
        let last = lines.clone().next_back();
        lines.find(|l| l.starts_with("error")).or(last)
    }
}

/// Runs `runner args...` to its end, stdout and stderr captured (read on threads so that a
/// full pipe never blocks the child), stdin closed.
pub fn run(runner: &Path, args: &[OsString]) -> std::io::Result<Measured> {
    let start = Instant::now();
    let mut child = Command::new(runner)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()?;
    let stdout = drain(child.stdout.take());
    let stderr = drain(child.stderr.take());
    let (code, signal, peak_kib) = wait(&mut child)?;
    let wall_s = start.elapsed().as_secs_f64();
    Ok(Measured {
        code,
        signal,
        wall_s,
        peak_kib,
        stdout: stdout.join().unwrap_or_default(),
        stderr: stderr.join().unwrap_or_default(),
    })
}

fn drain<R: Read + Send + 'static>(pipe: Option<R>) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        if let Some(mut p) = pipe {
            let _ = p.read_to_end(&mut bytes);
        }
        String::from_utf8_lossy(&bytes).into_owned()
    })
}

/// Waits with `wait4`, which returns the resource usage of this one child: its `ru_maxrss`
/// is the child's own peak (getrusage(RUSAGE_CHILDREN) gives only the largest over every
/// child waited for so far, which after a large case hides the smaller ones).
#[cfg(unix)]
fn wait(
    child: &mut std::process::Child,
) -> std::io::Result<(Option<i32>, Option<i32>, Option<u64>)> {
    use std::os::unix::process::ExitStatusExt;
    let pid = child.id() as libc::pid_t;
    let mut status: libc::c_int = 0;
    // SAFETY: rusage is plain data (all-zero is a valid value); wait4 writes into the two
    // locals, and reaps only our own child `pid`, which std has not waited for.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        if r == pid {
            break;
        }
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
    let exit = std::process::ExitStatus::from_raw(status);
    Ok((
        exit.code(),
        exit.signal(),
        Some(maxrss_kib(usage.ru_maxrss)),
    ))
}

/// `ru_maxrss` is in bytes on macOS and iOS, in KiB elsewhere (Linux, the BSDs).
#[cfg(unix)]
fn maxrss_kib(maxrss: libc::c_long) -> u64 {
    let v = u64::try_from(maxrss).unwrap_or(0);
    if cfg!(any(target_os = "macos", target_os = "ios")) {
        v / 1024
    } else {
        v
    }
}

/// No per-child peak memory outside Unix: the table says n/a.
#[cfg(not(unix))]
fn wait(
    child: &mut std::process::Child,
) -> std::io::Result<(Option<i32>, Option<i32>, Option<u64>)> {
    let status = child.wait()?;
    Ok((status.code(), None, None))
}

/// What `runner bench` printed about its run.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchReport {
    pub particles: f64,
    pub steps: f64,
    pub outcome: String,
    /// The run's wall time as the child measured it (the scene build and the temporary
    /// folder's clean-up excepted).
    pub wall_s: f64,
    pub particle_steps_per_s: f64,
    /// Stage name and share of the wall time (%), as printed.
    pub stages: Vec<(String, f64)>,
}

/// Reads `runner bench`'s report:
/// ```text
/// NAME (2D, spacing 0.005 m): 6338 particles (5000 fluid), 401 steps to t = 0.2 s, 2 threads
/// outcome completed; wall time 6.200 s; 408000 particle-steps/s
/// stage                                            seconds   share
/// neighbour lists (4 cell-grid builds, 0 updates)   0.001   10.3%
/// ...
/// ```
/// `None` when the first two lines are not there (the child refused the run or crashed).
pub fn parse_bench(stdout: &str) -> Option<BenchReport> {
    let mut lines = stdout.lines();
    let head = lines.find(|l| l.contains(" particles (") && l.contains(" steps to t = "))?;
    let particles = number_before(head, " particles (")?;
    let steps = number_before(head, " steps to t = ")?;
    let result = lines.find(|l| l.starts_with("outcome "))?;
    let outcome = result.strip_prefix("outcome ")?.split(';').next()?.trim();
    let wall_s = number_after(result, "wall time ")?;
    let particle_steps_per_s = number_before(result, " particle-steps/s")?;
    let stages = stage_table(stdout)
        .into_iter()
        .skip(1)
        .map_while(stage_line)
        .collect();
    Some(BenchReport {
        particles,
        steps,
        outcome: outcome.to_string(),
        wall_s,
        particle_steps_per_s,
        stages,
    })
}

/// The stage table of `runner bench`'s report as printed: its header and its stage rows
/// (empty when there is none). It follows the `outcome` line, so a run named "stage" does
/// not start it.
pub fn stage_table(stdout: &str) -> Vec<&str> {
    let mut lines = stdout
        .lines()
        .skip_while(|l| !l.starts_with("outcome "))
        .skip(1)
        .skip_while(|l| !l.starts_with("stage "));
    let Some(header) = lines.next() else {
        return Vec::new();
    };
    std::iter::once(header)
        .chain(lines.take_while(|l| stage_line(l).is_some()))
        .collect()
}

/// `NAME   SECONDS   SHARE%`: the name may hold spaces, so the two numbers are taken from the
/// right.
fn stage_line(line: &str) -> Option<(String, f64)> {
    let (rest, share) = last_word(line)?;
    let share = share.strip_suffix('%')?.parse().ok()?;
    let (name, seconds) = last_word(rest)?;
    seconds.parse::<f64>().ok()?;
    let name = name.trim();
    (!name.is_empty()).then(|| (name.to_string(), share))
}

/// `("a b", "c")` from `"a b   c"`.
fn last_word(text: &str) -> Option<(&str, &str)> {
    let text = text.trim_end();
    let i = text.rfind(char::is_whitespace)?;
    Some((&text[..i], &text[i + 1..]))
}

/// The number that ends just before `marker` (the word before it).
fn number_before(text: &str, marker: &str) -> Option<f64> {
    let end = text.find(marker)?;
    text[..end].split_whitespace().last()?.parse().ok()
}

/// The number that starts just after `marker`.
fn number_after(text: &str, marker: &str) -> Option<f64> {
    let start = text.find(marker)? + marker.len();
    text[start..].split_whitespace().next()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    const REPORT: &str = "\
smoke_2d (2D, spacing 0.025 m): 246 particles (72 fluid), 50 steps to t = 0.05 s, 2 threads
outcome completed; wall time 0.009 s; 1359997 particle-steps/s
stage                                            seconds   share
neighbour lists (4 cell-grid builds, 0 updates)   0.001   10.3%
viscosity (strain, assembly, CG 2.9 it/step)       0.001   11.3%
PPE solve (CG 22.8 it/step)                        0.001   12.0%
recording and output                               0.002   27.6%
";

    #[test]
    fn reads_the_bench_report() {
        let r = parse_bench(REPORT).unwrap();
        assert_eq!((r.particles, r.steps), (246.0, 50.0));
        assert_eq!(r.outcome, "completed");
        assert_eq!((r.wall_s, r.particle_steps_per_s), (0.009, 1359997.0));
        assert_eq!(r.stages.len(), 4);
        assert_eq!(
            r.stages[1],
            ("viscosity (strain, assembly, CG 2.9 it/step)".into(), 11.3)
        );
    }

    #[test]
    fn no_report_without_its_lines() {
        assert_eq!(parse_bench("error: no such file\n"), None);
        assert!(stage_table("error: no such file\n").is_empty());
    }

    #[test]
    fn the_stage_table_is_its_header_and_rows() {
        let stdout = format!("{REPORT}/tmp/x.mcap\n");
        let table = stage_table(&stdout);
        assert_eq!(table.len(), 5, "{table:?}");
        assert!(table[0].starts_with("stage "));
        assert!(table[4].starts_with("recording and output "));
        // A run named "stage" is not the table's header.
        let named = REPORT.replacen("smoke_2d (", "stage (", 1);
        assert_eq!(stage_table(&named), stage_table(REPORT));
    }
}
