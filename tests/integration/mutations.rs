//! Property test: thousands of random mutations of real run files and manifests (bit flips,
//! byte overwrites, truncations, splices of one file's range into another, duplications, and
//! for run files damage inside a chunk with its CRC made to match) never panic or hang the
//! reader, the manifest loader or the runner, and never give part of a file as the whole.
//! Most go through the library in-process, each call on its own thread under a time bound;
//! a smaller number go through `runner` with a timeout, whose exit codes must be documented
//! ones. The RNG is seeded, so every run tries the same mutations.
//!
//! `cargo test --release --test mutations -- --nocapture` prints the counts.
use crate::common;
use assert_cmd::Command;
use mps_runner::experiment::{self, Plan};
use mps_runner::record::{FileCheck, RunFile, check_run, read_messages, read_run};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// In-process mutations of run files and of manifests.
const FILE_MUTATIONS: usize = 5000;
const MANIFEST_MUTATIONS: usize = 5000;
/// Mutated files that the reader accepts and that then go through verify, the plots and
/// resume in-process (a replay or resume of the small seeds takes about 10 ms).
const CONSUMER_CALLS: usize = 400;
/// A call that takes longer than this is a hang (the slowest take milliseconds).
const CALL_LIMIT: Duration = Duration::from_secs(10);
/// A `runner` call that takes longer is killed and counted as a hang (the slowest runs 20
/// steps of a 13 000-particle 3D scene: well under a second).
const PROCESS_LIMIT: Duration = Duration::from_secs(30);

/// xorshift64* (Vigna): deterministic and enough to scatter mutations.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in 0..n (0 when n is 0).
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }

    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    BitFlip,
    Overwrite,
    Truncate,
    Splice,
    Duplicate,
    /// Run files: bytes inside a chunk changed, the chunk rewritten uncompressed with a
    /// matching CRC (damage the CRC cannot see, to reach the record and message decoding).
    ChunkContent,
    /// Manifests: one value replaced, or a line deleted, repeated or re-indented.
    Token,
}

/// Offsets of the top-level records of an MCAP file (after the start magic).
fn record_starts(bytes: &[u8]) -> Vec<(usize, u8, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        out.push((at, bytes[at], len));
        at = at.saturating_add(9).saturating_add(len);
    }
    out
}

/// A position in `len` bytes: half uniform, half near a structure start in `hot` (record
/// headers, lengths, CRCs and sizes sit there).
fn position(rng: &mut Rng, len: usize, hot: &[usize]) -> usize {
    if len == 0 {
        return 0;
    }
    if hot.is_empty() || rng.below(2) == 0 {
        rng.below(len)
    } else {
        (rng.pick(hot) + rng.below(48)).min(len - 1)
    }
}

const SPECIAL_BYTES: [u8; 6] = [0x00, 0xff, 0x7f, 0x80, 0x01, 0x0a];

/// One byte-level mutation of `target` (`donor` is where splices come from).
fn mutate_bytes(
    rng: &mut Rng,
    kind: Kind,
    target: &[u8],
    donor: &[u8],
    hot: &[usize],
) -> (Vec<u8>, String) {
    let mut out = target.to_vec();
    let len = target.len();
    match kind {
        Kind::BitFlip => {
            let at = position(rng, len, hot);
            let bit = rng.below(8);
            out[at] ^= 1 << bit;
            (out, format!("bit {bit} of byte {at} flipped"))
        }
        Kind::Overwrite => {
            let at = position(rng, len, hot);
            let n = 1 + rng.below(8);
            for byte in &mut out[at..(at + n).min(len)] {
                *byte = if rng.below(2) == 0 {
                    *rng.pick(&SPECIAL_BYTES)
                } else {
                    rng.next() as u8
                };
            }
            (out, format!("{n} bytes at {at} overwritten"))
        }
        Kind::Truncate => {
            let at = position(rng, len, hot);
            out.truncate(at);
            (out, format!("cut to {at} bytes"))
        }
        Kind::Splice => {
            let n = 1 + rng.below(4096.min(donor.len()));
            let from = rng.below(donor.len() - n + 1);
            let at = position(rng, len, hot);
            let piece = &donor[from..from + n];
            if rng.below(2) == 0 {
                out.splice(at..(at + n).min(len), piece.iter().copied());
                (
                    out,
                    format!("donor bytes {from}..{} written over byte {at}", from + n),
                )
            } else {
                out.splice(at..at, piece.iter().copied());
                (
                    out,
                    format!("donor bytes {from}..{} inserted at byte {at}", from + n),
                )
            }
        }
        Kind::Duplicate => {
            let at = position(rng, len, hot);
            let n = 1 + rng.below(4096.min(len - at));
            let piece = target[at..at + n].to_vec();
            out.splice(at + n..at + n, piece);
            (out, format!("bytes {at}..{} repeated", at + n))
        }
        Kind::ChunkContent | Kind::Token => unreachable!("not a byte-level mutation"),
    }
}

/// Decompresses a random chunk of `file`, mutates its records and writes it back
/// uncompressed with a CRC that matches.
fn mutate_chunk_content(rng: &mut Rng, file: &[u8]) -> (Vec<u8>, String) {
    let chunks: Vec<(usize, usize)> = record_starts(file)
        .into_iter()
        .filter(|r| r.1 == 0x06 && r.0 + 9 + r.2 <= file.len())
        .map(|r| (r.0, r.2))
        .collect();
    let &(at, len) = rng.pick(&chunks);
    let body = &file[at + 9..at + 9 + len];
    let u64_at = |i: usize| u64::from_le_bytes(body[i..i + 8].try_into().unwrap());
    let name_len = u32::from_le_bytes(body[28..32].try_into().unwrap()) as usize;
    let compression = &body[32..32 + name_len];
    let size_at = 32 + name_len;
    let compressed = &body[size_at + 8..size_at + 8 + u64_at(size_at) as usize];
    let records = if compression.is_empty() {
        compressed.to_vec()
    } else {
        zstd::decode_all(compressed).unwrap()
    };
    let inner: Vec<usize> = record_starts(&[&[0u8; 8][..], &records].concat())
        .iter()
        .map(|r| r.0 - 8)
        .collect();
    let kind = *rng.pick(&[
        Kind::BitFlip,
        Kind::Overwrite,
        Kind::Truncate,
        Kind::Duplicate,
    ]);
    let (records, what) = mutate_bytes(rng, kind, &records, &[], &inner);
    let mut chunk = Vec::new();
    chunk.extend_from_slice(&body[..16]); // message start and end times
    chunk.extend_from_slice(&(records.len() as u64).to_le_bytes());
    chunk.extend_from_slice(&crc32fast::hash(&records).to_le_bytes());
    chunk.extend_from_slice(&0u32.to_le_bytes()); // no compression
    chunk.extend_from_slice(&(records.len() as u64).to_le_bytes());
    chunk.extend_from_slice(&records);
    let mut out = file[..at].to_vec();
    out.push(0x06);
    out.extend_from_slice(&(chunk.len() as u64).to_le_bytes());
    out.extend_from_slice(&chunk);
    out.extend_from_slice(&file[at + 9 + len..]);
    (
        out,
        format!("chunk at byte {at}: {what} inside it, CRC recomputed"),
    )
}

/// How a bounded call ended.
enum Bounded<T> {
    Done(T),
    Panicked(String),
    Hung,
}

/// Runs `f` on its own thread, catching a panic, and gives up waiting after `limit` (the
/// thread is left behind; the test fails on any hang).
fn bounded<T: Send + 'static>(
    limit: Duration,
    f: impl FnOnce() -> T + Send + 'static,
) -> Bounded<T> {
    let (send, receive) = mpsc::channel();
    std::thread::spawn(move || {
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
        let _ = send.send(result);
    });
    match receive.recv_timeout(limit) {
        Ok(Ok(value)) => Bounded::Done(value),
        Ok(Err(panic)) => Bounded::Panicked(
            panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default(),
        ),
        Err(_) => Bounded::Hung,
    }
}

/// Counts that the test prints and checks.
#[derive(Default)]
struct Tally {
    tried: usize,
    rejected: usize,
    accepted_whole: usize,
    accepted_partial: usize,
    /// Run files read in part: stopped at a damaged record, or at one cut short (the rest
    /// end on a record boundary).
    stopped_damaged: usize,
    stopped_cut: usize,
    panics: Vec<String>,
    hangs: Vec<String>,
    /// Broken properties (besides panics and hangs), with the mutation that broke them.
    violations: Vec<String>,
    by_kind: BTreeMap<Kind, usize>,
}

impl Tally {
    fn print(&self, what: &str) {
        println!(
            "mutations of {what}: tried {}, rejected cleanly {}, accepted {}, panics {}, hangs {}, violations {}; by kind {:?}",
            self.tried,
            self.rejected,
            self.accepted_whole + self.accepted_partial,
            self.panics.len(),
            self.hangs.len(),
            self.violations.len(),
            self.by_kind
        );
    }

    fn assert_clean(&self) {
        assert!(
            self.panics.is_empty(),
            "panics:\n{}",
            self.panics.join("\n")
        );
        assert!(self.hangs.is_empty(), "hangs:\n{}", self.hangs.join("\n"));
        assert!(
            self.violations.is_empty(),
            "violations:\n{}",
            self.violations.join("\n")
        );
    }
}

/// A real run file to mutate, with what it holds.
struct Seed {
    name: &'static str,
    bytes: Vec<u8>,
    /// The file name a mutated copy gets (`.mcap.partial` for the killed run).
    file_name: String,
    run: RunFile,
    hot: Vec<usize>,
}

/// The seeds: a completed smoke run, the same cut inside a chunk as a killed run leaves it
/// (`.partial`), an interrupted one (resumable), and a short pour (tags, inlets).
fn seeds(dir: &Path) -> Vec<Seed> {
    let smoke = common::resolve(
        "smoke_2d.yaml",
        &["time.end_s=0.05", "output.checkpoint_interval_s=0.01"],
    );
    let smoke_path = common::run_completed(&smoke, &dir.join("smoke"), 1).path;
    let pour = common::resolve(
        "pour_2d.yaml",
        &["time.end_s=0.02", "output.checkpoint_interval_s=0.01"],
    );
    let pour_path = common::run_completed(&pour, &dir.join("pour"), 1).path;
    let interrupted = mps_runner::run::run(
        &smoke,
        &mps_runner::run::RunOptions {
            out_dir: dir.join("interrupted"),
            threads: Some(1),
            progress: None,
            interrupt: Some(std::sync::Arc::new(std::sync::atomic::AtomicBool::new(
                true,
            ))),
            max_particles: None,
            overwrite: false,
        },
    )
    .unwrap();
    assert_eq!(interrupted.summary.outcome, "interrupted");
    let smoke_bytes = std::fs::read(&smoke_path).unwrap();
    let chunks: Vec<usize> = record_starts(&smoke_bytes)
        .into_iter()
        .filter(|r| r.1 == 0x06)
        .map(|r| r.0)
        .collect();
    let killed = smoke_bytes[..chunks[chunks.len() - 2] + 100].to_vec();
    let file_name = |p: &Path| p.file_name().unwrap().to_string_lossy().into_owned();
    let mut out = Vec::new();
    for (name, bytes, file_name) in [
        (
            "completed smoke",
            smoke_bytes.clone(),
            file_name(&smoke_path),
        ),
        (
            "killed smoke (.partial)",
            killed,
            format!("{}.partial", file_name(&smoke_path)),
        ),
        (
            "interrupted smoke",
            std::fs::read(&interrupted.path).unwrap(),
            file_name(&interrupted.path),
        ),
        (
            "completed pour",
            std::fs::read(&pour_path).unwrap(),
            file_name(&pour_path),
        ),
    ] {
        let path = dir.join("seed").join(&file_name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &bytes).unwrap();
        let run = read_run(&path).unwrap();
        assert_eq!(run.complete, !file_name.ends_with(".partial"), "{name}");
        let hot = record_starts(&bytes).iter().map(|r| r.0).collect();
        out.push(Seed {
            name,
            bytes,
            file_name,
            run,
            hot,
        });
    }
    out
}

/// What the three readers made of one file (errors as text).
struct Reading {
    run: Result<RunFile, String>,
    messages: Result<usize, String>,
    check: Result<FileCheck, String>,
}

fn read_all(path: PathBuf) -> Reading {
    Reading {
        run: read_run(&path).map_err(|e| e.to_string()),
        messages: read_messages(&path)
            .map(|m| m.len())
            .map_err(|e| e.to_string()),
        check: check_run(&path).map_err(|e| e.to_string()),
    }
}

fn is_prefix<T: PartialEq>(read: &[T], written: &[T]) -> bool {
    read.len() <= written.len() && read == &written[..read.len()]
}

/// Checks one reading of a mutated `seed`; returns what broke, if anything.
/// Whether `mutated` holds a CRC field that is 0 where `seed` has one that is not (MCAP: no
/// CRC to check): the chunk, data-section and summary-section CRCs.
fn zeroed_crc(seed: &[u8], mutated: &[u8]) -> bool {
    let crc_fields = |bytes: &[u8]| -> Vec<u32> {
        let at = |i: usize| {
            bytes
                .get(i..i + 4)
                .map_or(1, |b| u32::from_le_bytes(b.try_into().unwrap()))
        };
        let mut fields: Vec<u32> = record_starts(bytes)
            .iter()
            .filter_map(|&(start, opcode, _)| match opcode {
                0x06 => Some(at(start + 9 + 24)),
                0x0f => Some(at(start + 9)),
                _ => None,
            })
            .collect();
        fields.push(at(bytes.len().saturating_sub(12)));
        fields
    };
    let before = crc_fields(seed).iter().filter(|&&c| c == 0).count();
    crc_fields(mutated).iter().filter(|&&c| c == 0).count() > before
}

fn judge(
    kind: Kind,
    seed: &Seed,
    mutated: &[u8],
    reading: &Reading,
    tally: &mut Tally,
) -> Option<String> {
    let (run, messages, check) = match (&reading.run, &reading.messages, &reading.check) {
        (Err(a), Err(b), Err(c)) => {
            tally.rejected += 1;
            return (a.is_empty() || a != b || a != c)
                .then(|| format!("the readers reject it differently: {a:?} / {b:?} / {c:?}"));
        }
        (Ok(run), Ok(messages), Ok(check)) => (run, *messages, check),
        _ => {
            return Some(format!(
                "the readers disagree: read_run {:?}, read_messages {:?}, check_run {:?}",
                reading.run.as_ref().err(),
                reading.messages.as_ref().err(),
                reading.check.as_ref().err()
            ));
        }
    };
    let held =
        run.states.len() + run.diagnostics.len() + run.clouds + usize::from(run.summary.is_some());
    if messages != held
        || check.complete != run.complete
        || check.stop != run.stop
        || check.checkpoints != run.states.len()
    {
        return Some(format!(
            "the readers disagree: {messages} messages against {held}; check {check:?} against complete {} stop {:?}",
            run.complete, run.stop
        ));
    }
    if run.complete {
        tally.accepted_whole += 1;
        // Every byte of a finished file is under a CRC, the magic or the record structure:
        // one read as whole is exactly what was written, unless a CRC it relied on became 0.
        let same = seed.run.complete
            && run.states == seed.run.states
            && run.diagnostics == seed.run.diagnostics
            && run.clouds == seed.run.clouds
            && run.last_cloud == seed.run.last_cloud
            && run.summary == seed.run.summary
            && run.metadata == seed.run.metadata;
        if !same {
            return Some("read as whole but its contents differ from what was written".into());
        }
        return (mutated != seed.bytes && !zeroed_crc(&seed.bytes, mutated))
            .then(|| "read as whole though its bytes changed".to_string());
    }
    tally.accepted_partial += 1;
    match &run.stop {
        Some(s) if s.damaged => tally.stopped_damaged += 1,
        Some(_) => tally.stopped_cut += 1,
        None => {}
    }
    if run.stop.as_ref().is_some_and(|s| s.reason.is_empty()) {
        return Some("a stop without a reason".into());
    }
    // Damage the CRCs cannot see, or bytes from another file, may read as other messages;
    // any other mutation leaves a prefix of what was written.
    if matches!(kind, Kind::ChunkContent | Kind::Splice) {
        return None;
    }
    let states_prefix = is_prefix(&run.states, &seed.run.states);
    let diagnostics_prefix = is_prefix(&run.diagnostics, &seed.run.diagnostics);
    (!states_prefix || !diagnostics_prefix).then(|| {
        format!(
            "read {} checkpoints and {} diagnostics rows that are not a prefix of what was written",
            run.states.len(),
            run.diagnostics.len()
        )
    })
}

/// Replays, plots, draws, profiles and resumes a run file; errors are fine, panics are not.
fn use_run_file(file: &Path) {
    let svg = file.with_extension("svg");
    let _ = mps_runner::verify::verify(
        file,
        &mps_runner::verify::VerifyOptions {
            threads: Some(1),
            ..Default::default()
        },
    );
    let _ = mps_runner::report::plot_run(file, &[], None, Some(&svg));
    let _ = mps_runner::report::snapshot(file, Some("tag"), false, None, Some(&svg));
    let _ = mps_runner::report::snapshot(file, Some("tag"), false, Some(0.01), Some(&svg));
    let _ = mps_runner::report::profile(file, Some(&svg));
    let _ = mps_runner::resume::resume(
        file,
        &mps_runner::resume::ResumeOptions {
            threads: Some(1),
            ..Default::default()
        },
    );
}

#[test]
fn run_file_mutations_never_panic_hang_or_pass_for_whole() {
    let dir = tempfile::tempdir().unwrap();
    let seeds = seeds(dir.path());
    let mut rng = Rng(0x005e_ed0f_da3a);
    let mut tally = Tally::default();
    let path = dir.path().join("mutated");
    let started = Instant::now();
    let mut consumed = 0;
    for i in 0..FILE_MUTATIONS {
        let seed = &seeds[i % seeds.len()];
        let donor = &rng.pick(&seeds).bytes;
        let kind = *rng.pick(&[
            Kind::BitFlip,
            Kind::BitFlip,
            Kind::Overwrite,
            Kind::Overwrite,
            Kind::Truncate,
            Kind::Splice,
            Kind::Duplicate,
            Kind::ChunkContent,
        ]);
        let (bytes, what) = if kind == Kind::ChunkContent {
            mutate_chunk_content(&mut rng, &seed.bytes)
        } else {
            mutate_bytes(&mut rng, kind, &seed.bytes, donor, &seed.hot)
        };
        std::fs::write(&path, &bytes).unwrap();
        tally.tried += 1;
        *tally.by_kind.entry(kind).or_default() += 1;
        let label = format!("#{i} {} ({kind:?}: {what})", seed.name);
        let file = path.clone();
        let accepted = match bounded(CALL_LIMIT, move || read_all(file)) {
            Bounded::Done(reading) => {
                if let Some(broken) = judge(kind, seed, &bytes, &reading, &mut tally) {
                    tally.violations.push(format!("{label}: {broken}"));
                }
                reading.run.is_ok()
            }
            Bounded::Panicked(message) => {
                tally.panics.push(format!("{label}: {message}"));
                false
            }
            Bounded::Hung => {
                tally.hangs.push(label.clone());
                false
            }
        };
        // What the reader accepts goes on to the code that uses it: replay, plots, resume.
        if accepted && consumed < CONSUMER_CALLS {
            consumed += 1;
            let case = dir.path().join(format!("consumer{i}"));
            std::fs::create_dir(&case).unwrap();
            let file = case.join(&seed.file_name);
            std::fs::write(&file, &bytes).unwrap();
            match bounded(CALL_LIMIT, move || use_run_file(&file)) {
                Bounded::Done(()) => {}
                Bounded::Panicked(message) => tally
                    .panics
                    .push(format!("{label}, replayed, drawn, resumed: {message}")),
                Bounded::Hung => tally
                    .hangs
                    .push(format!("{label}, replayed, drawn, resumed")),
            }
        }
    }
    println!(
        "  {consumed} accepted files also verified, plotted, drawn, profiled and resumed in-process"
    );
    tally.print("run files (read_run, read_messages, check_run)");
    println!(
        "  accepted: {} whole (unchanged), {} read in part ({} stopped at damage, {} at a record cut short); in {:.1} s",
        tally.accepted_whole,
        tally.accepted_partial,
        tally.stopped_damaged,
        tally.stopped_cut,
        started.elapsed().as_secs_f64()
    );
    tally.assert_clean();
    // The mutations reach every outcome, or they prove little.
    assert!(tally.rejected > FILE_MUTATIONS / 4, "{}", tally.rejected);
    assert!(tally.stopped_damaged > 100, "{}", tally.stopped_damaged);
    assert!(tally.stopped_cut > 100, "{}", tally.stopped_cut);
    assert!(tally.accepted_whole > 0);
}

/// The shipped manifests, by file name.
fn manifests() -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(common::root().join("experiments"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    out.sort();
    assert!(out.len() >= 8, "{}", out.len());
    out
}

const VALUES: [&str; 24] = [
    "0",
    "-1",
    "1e308",
    "-0.0",
    ".nan",
    ".inf",
    "-.inf",
    "1e-300",
    "18446744073709551616",
    "3",
    "true",
    "null",
    "~",
    "[]",
    "{}",
    "\"\"",
    "abc",
    "0x10",
    "2.0e+3",
    "1_000",
    "*a",
    "&a 1",
    "!!str 5",
    "[1, [2, {a: 3}]]",
];

/// One value replaced, or one line deleted, repeated, or re-indented.
fn mutate_token(rng: &mut Rng, text: &[u8]) -> (Vec<u8>, String) {
    let text = String::from_utf8_lossy(text);
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let i = rng.below(lines.len());
    let what = match rng.below(5) {
        0 | 1 => match lines[i].find(": ") {
            Some(colon) => {
                let value = *rng.pick(&VALUES);
                lines[i] = format!("{}: {value}", &lines[i][..colon]);
                format!("line {} value set to {value}", i + 1)
            }
            None => {
                lines.remove(i);
                format!("line {} deleted", i + 1)
            }
        },
        2 => {
            lines.remove(i);
            format!("line {} deleted", i + 1)
        }
        3 => {
            let copy = lines[i].clone();
            lines.insert(i, copy);
            format!("line {} repeated", i + 1)
        }
        _ => {
            lines[i] = format!("  {}", lines[i]);
            format!("line {} indented", i + 1)
        }
    };
    ((lines.join("\n") + "\n").into_bytes(), what)
}

fn mutate_manifest(
    rng: &mut Rng,
    seeds: &[(String, Vec<u8>)],
    i: usize,
) -> (Kind, Vec<u8>, String) {
    let (name, text) = &seeds[i % seeds.len()];
    let donor = &rng.pick(seeds).1;
    let kind = *rng.pick(&[
        Kind::BitFlip,
        Kind::Overwrite,
        Kind::Truncate,
        Kind::Splice,
        Kind::Duplicate,
        Kind::Token,
        Kind::Token,
        Kind::Token,
    ]);
    let (bytes, what) = if kind == Kind::Token {
        mutate_token(rng, text)
    } else {
        // Line starts are where keys and values begin.
        let hot: Vec<usize> = std::iter::once(0)
            .chain(
                text.iter()
                    .enumerate()
                    .filter(|b| *b.1 == b'\n')
                    .map(|b| b.0 + 1),
            )
            .filter(|&at| at < text.len())
            .collect();
        mutate_bytes(rng, kind, text, donor, &hot)
    };
    (kind, bytes, format!("{name} ({kind:?}: {what})"))
}

/// Loads a mutated manifest; for a single experiment also its canonical form (itself a
/// manifest with the same hash, read as a canonical form: under no default preset) and the particle estimate a run starts with (two coarse
/// scene builds).
fn load_manifest(bytes: Vec<u8>) -> Result<Option<String>, String> {
    let text = String::from_utf8_lossy(&bytes);
    match experiment::plan_from_str(&text, "mutated.yaml", &[]) {
        Err(e) => {
            let message = e.to_string();
            if message.is_empty() {
                return Ok(Some("an empty error message".into()));
            }
            Err(message)
        }
        Ok(Plan::Sweep(s)) => {
            let broken = s.points.is_empty() || s.points.len() > 10_000;
            Ok(broken.then(|| format!("a sweep of {} points", s.points.len())))
        }
        Ok(Plan::Single(r)) => {
            let again = mps_runner::manifest::from_canonical::<experiment::SceneSpec>(
                &r.canonical,
                "canonical.json",
                &[],
            );
            match again {
                Ok(a) if a.hash_hex == r.hash_hex => {}
                Ok(a) => {
                    return Ok(Some(format!(
                        "its canonical form hashes to {} instead of {}",
                        a.hash_hex, r.hash_hex
                    )));
                }
                Err(e) => return Ok(Some(format!("its canonical form is refused: {e}"))),
            }
            let n = experiment::estimate_particles(&r.manifest);
            if !(n.is_finite() && n >= 0.0) {
                return Ok(Some(format!("a particle estimate of {n}")));
            }
            Ok(None)
        }
    }
}

#[test]
fn manifest_mutations_never_panic_or_hang() {
    let seeds = manifests();
    let mut rng = Rng(0x00c0_ffee_0ba5);
    let mut tally = Tally::default();
    let started = Instant::now();
    for i in 0..MANIFEST_MUTATIONS {
        let (kind, bytes, label) = mutate_manifest(&mut rng, &seeds, i);
        tally.tried += 1;
        *tally.by_kind.entry(kind).or_default() += 1;
        match bounded(CALL_LIMIT, move || load_manifest(bytes)) {
            Bounded::Done(Err(_)) => tally.rejected += 1,
            Bounded::Done(Ok(None)) => {
                tally.accepted_whole += 1;
            }
            Bounded::Done(Ok(Some(broken))) => {
                tally.violations.push(format!("#{i} {label}: {broken}"))
            }
            Bounded::Panicked(message) => tally.panics.push(format!("#{i} {label}: {message}")),
            Bounded::Hung => tally.hangs.push(format!("#{i} {label}")),
        }
    }
    tally.print("manifests (plan_from_str, canonical round trip, particle estimate)");
    println!(
        "  each accepted one also estimated; in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    tally.assert_clean();
    assert!(
        tally.rejected > MANIFEST_MUTATIONS / 4,
        "{}",
        tally.rejected
    );
    assert!(
        tally.accepted_whole > MANIFEST_MUTATIONS / 10,
        "{}",
        tally.accepted_whole
    );
}

/// One `runner` call with a timeout: exit code (None when killed by a signal), stderr, and
/// whether it ran into the timeout.
fn runner(args: &[&std::ffi::OsStr]) -> (Option<i32>, String, bool) {
    let started = Instant::now();
    let out = Command::cargo_bin("runner")
        .unwrap()
        .args(args)
        .timeout(PROCESS_LIMIT)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
        started.elapsed() >= PROCESS_LIMIT,
    )
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.map(|e| e.unwrap().path()).collect())
        .unwrap_or_default();
    files.sort();
    files
}

/// Checks a `runner` call: a documented exit code, and the files left as they should be.
/// Returns what broke.
fn judge_cli(
    command: &str,
    code: Option<i32>,
    stderr: &str,
    file: &Path,
    before: &[u8],
    dir: &Path,
    svg: &Path,
) -> Option<String> {
    let allowed: &[i32] = match command {
        "verify" => &[0, 1, 2],
        "resume" => &[0, 2, 3],
        _ => &[0, 2],
    };
    let Some(code) = code.filter(|c| allowed.contains(c)) else {
        return Some(format!("exit {code:?}, not one of {allowed:?}: {stderr}"));
    };
    if code == 2 && !stderr.contains("error: ") {
        return Some(format!("exit 2 without an error message: {stderr}"));
    }
    let named_finished = !file.to_string_lossy().ends_with(".partial");
    let whole = || check_run(file).is_ok_and(|c| c.complete);
    match command {
        "resume" if code != 2 => {
            // The run goes on into a complete file at its usual path that replays bit for bit,
            // and nothing else is left beside it.
            let files = files_in(dir);
            let [result] = files.as_slice() else {
                return Some(format!("exit {code} leaves {files:?}"));
            };
            let Ok(run) = read_run(result) else {
                return Some(format!("exit {code}: {} unreadable", result.display()));
            };
            if !run.complete {
                return Some(format!("exit {code}: {} not complete", result.display()));
            }
            let report = mps_runner::verify::verify(
                result,
                &mps_runner::verify::VerifyOptions {
                    threads: Some(1),
                    ..Default::default()
                },
            );
            if !report.as_ref().is_ok_and(|r| r.passed()) {
                return Some(format!("the resumed file does not verify: {report:?}"));
            }
            None
        }
        _ => {
            // Read-only commands and refused resumes leave the file as it was; a refused
            // resume adds nothing.
            if std::fs::read(file).ok().as_deref() != Some(before) {
                return Some("the file was changed".into());
            }
            if command == "resume" && files_in(dir).len() != 1 {
                return Some(format!("a refused resume left {:?}", files_in(dir)));
            }
            if (command == "plot" || command == "snapshot" || command == "profile")
                && (code == 0) != svg.exists()
            {
                return Some(format!(
                    "exit {code} with drawing present: {}",
                    svg.exists()
                ));
            }
            // Nothing is presented from part of a file named as finished.
            if code == 0 && named_finished && !whole() {
                return Some(format!(
                    "exit 0 on a {} that does not read as whole",
                    file.display()
                ));
            }
            None
        }
    }
}

#[test]
fn runner_on_mutated_files_and_manifests_exits_with_documented_codes() {
    let dir = tempfile::tempdir().unwrap();
    let seeds = seeds(dir.path());
    let manifest_seeds = manifests();
    let mut rng = Rng(0x0ddb_a115_eed0);
    let mut tally = Tally::default();
    let mut codes: BTreeMap<String, BTreeMap<Option<i32>, usize>> = BTreeMap::new();
    let started = Instant::now();
    // Run files: (command, calls); resume goes to the resumable seeds.
    let plan = [
        ("verify", 30),
        ("plot", 20),
        ("snapshot", 20),
        ("profile", 10),
        ("resume", 40),
    ];
    let mut case = 0;
    for (command, calls) in plan {
        for _ in 0..calls {
            case += 1;
            let candidates: Vec<&Seed> = seeds
                .iter()
                .filter(|s| {
                    command != "resume"
                        || s.name.contains("killed")
                        || s.name.contains("interrupted")
                })
                .collect();
            let seed = *rng.pick(&candidates);
            let kind = *rng.pick(&[
                Kind::BitFlip,
                Kind::Overwrite,
                Kind::Truncate,
                Kind::Splice,
                Kind::Duplicate,
                Kind::ChunkContent,
                Kind::ChunkContent,
            ]);
            let donor = &rng.pick(&seeds).bytes;
            let (bytes, what) = if kind == Kind::ChunkContent {
                mutate_chunk_content(&mut rng, &seed.bytes)
            } else {
                mutate_bytes(&mut rng, kind, &seed.bytes, donor, &seed.hot)
            };
            let case_dir = dir.path().join(format!("case{case}"));
            std::fs::create_dir(&case_dir).unwrap();
            let file = case_dir.join(&seed.file_name);
            std::fs::write(&file, &bytes).unwrap();
            let svg = dir.path().join(format!("case{case}.svg"));
            let mut args: Vec<&std::ffi::OsStr> = vec![command.as_ref(), file.as_os_str()];
            match command {
                "verify" | "resume" => {
                    args.extend(["-q", "--threads", "1"].map(std::ffi::OsStr::new))
                }
                _ => args.extend([std::ffi::OsStr::new("--out"), svg.as_os_str()]),
            }
            let (code, stderr, hung) = runner(&args);
            tally.tried += 1;
            *tally.by_kind.entry(kind).or_default() += 1;
            *codes
                .entry(command.to_string())
                .or_default()
                .entry(code)
                .or_default() += 1;
            let label = format!("{command} on {} ({kind:?}: {what})", seed.name);
            if hung {
                tally.hangs.push(label);
            } else if code.is_none() || code == Some(101) {
                tally
                    .panics
                    .push(format!("{label}: exit {code:?}: {stderr}"));
            } else if let Some(broken) =
                judge_cli(command, code, &stderr, &file, &bytes, &case_dir, &svg)
            {
                tally.violations.push(format!("{label}: {broken}"));
            } else if code == Some(2) {
                tally.rejected += 1;
            } else {
                tally.accepted_whole += 1;
            }
        }
    }
    // Manifests: run for 20 steps at most, at most 20 000 particles. Sweeps are left out
    // (their points run one by one; a single manifest exercises the same loading).
    let mut runs = 0;
    let mut i = 0;
    while runs < 80 {
        i += 1;
        let (kind, bytes, label) = mutate_manifest(&mut rng, &manifest_seeds, i);
        let text = String::from_utf8_lossy(&bytes).into_owned();
        if matches!(
            experiment::plan_from_str(&text, "m.yaml", &[]),
            Ok(Plan::Sweep(_))
        ) {
            continue;
        }
        runs += 1;
        case += 1;
        let manifest = dir.path().join(format!("case{case}.yaml"));
        std::fs::write(&manifest, &bytes).unwrap();
        let out = dir.path().join(format!("case{case}"));
        let (code, stderr, hung) = runner(&[
            manifest.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
            "--set".as_ref(),
            "time.end_s=0.01".as_ref(),
            "--set".as_ref(),
            "stop.max_steps=20".as_ref(),
            "--max-particles".as_ref(),
            "20000".as_ref(),
            "--threads".as_ref(),
            "1".as_ref(),
            "-q".as_ref(),
        ]);
        tally.tried += 1;
        *tally.by_kind.entry(kind).or_default() += 1;
        *codes
            .entry("run".to_string())
            .or_default()
            .entry(code)
            .or_default() += 1;
        let files = files_in(&out);
        let broken = match code {
            _ if hung => {
                tally.hangs.push(label.clone());
                None
            }
            Some(0 | 3) => match files.as_slice() {
                [file] => {
                    let outcome = read_run(file)
                        .ok()
                        .filter(|r| r.complete)
                        .and_then(|r| r.summary)
                        .map(|s| s.outcome);
                    let expected = if code == Some(0) {
                        "completed"
                    } else {
                        "failed"
                    };
                    (outcome.as_deref() != Some(expected))
                        .then(|| format!("exit {code:?} but the file records {outcome:?}"))
                }
                other => Some(format!("exit {code:?} leaves {other:?}")),
            },
            Some(2) => {
                tally.rejected += 1;
                (!files.is_empty() || !stderr.contains("error: "))
                    .then(|| format!("exit 2 leaves {files:?}: {stderr}"))
            }
            None | Some(101) => {
                tally
                    .panics
                    .push(format!("{label}: exit {code:?}: {stderr}"));
                None
            }
            Some(other) => Some(format!("exit {other}, not 0, 2 or 3: {stderr}")),
        };
        if let Some(broken) = broken {
            tally.violations.push(format!("{label}: {broken}"));
        } else if matches!(code, Some(0 | 3)) {
            tally.accepted_whole += 1;
        }
    }
    tally.print(
        "runner calls (verify, plot, snapshot, profile, resume on run files; runs of manifests; accepted = exit 0, 1 or 3, rejected = exit 2)",
    );
    println!(
        "  exit codes by command: {codes:?}; in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    tally.assert_clean();
    // Both refusals and successes, for resumes and for runs.
    let resume = &codes["resume"];
    assert!(
        resume.get(&Some(0)).is_some_and(|&n| n > 0)
            && resume.get(&Some(2)).is_some_and(|&n| n > 0),
        "{resume:?}"
    );
    let run = &codes["run"];
    assert!(
        run.get(&Some(0)).is_some_and(|&n| n > 0) && run.get(&Some(2)).is_some_and(|&n| n > 0),
        "{run:?}"
    );
}
