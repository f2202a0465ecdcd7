//! Recording a run into one MCAP file.
//!
//! Layout of a run file (format `mps.v1`):
//! - metadata written first: `manifest` {source, canonical, experiment_sha256, overrides (JSON
//!   array), name}, `build` {crate_version, git_commit, rustc, target, profile}, `run`
//!   {threads, mcap_format}; attachment `manifest.yaml` (the manifest as written);
//! - channels (message encoding `protobuf`, schema = fully qualified message name with the
//!   FileDescriptorSet of `proto/` as data): `/state` (`mps.v1.StateCheckpoint`), `/particles`
//!   (`foxglove.PointCloud`), `/diagnostics` (`mps.v1.Diagnostics`), `/summary`
//!   (`mps.v1.Summary`); log time = publish time = simulation time in ns; sequence numbers per
//!   channel from 0;
//! - metadata written last: `outcome` {status, reason}.
//!
//! The file is written as `<final>.partial` and renamed on [`Recorder::finish`]. Each
//! checkpoint closes the current chunk and is synced to disk, so a killed run keeps every
//! checkpoint written ([`read_run`] recovers them). The bytes depend only on what is written
//! (zstd with pinned settings, no wall-clock time anywhere).

mod cloud;
mod error;
pub mod metrics_channel;
pub mod read;

use std::collections::BTreeMap;
use std::fs::{self, File};
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};

pub use cloud::{FRAME_ID, point_cloud, timestamp};
pub use error::{RecordError, Result};
pub use metrics_channel::{SCHEMA_METRICS, TOPIC_METRICS};
pub use read::{FileCheck, Logged, RunFile, Stop, check_run, read_messages, read_run};

use crate::build_info::BuildInfo;
use crate::proto::foxglove::PointCloud;
use crate::proto::mps::v1::{Diagnostics, StateCheckpoint, Summary};
use error::{io_err, mcap_err};

/// Value of `run.math`: the recorded closed forms take powers and roots from the `libm` crate
/// (the same bits on every platform). Files without the entry were written by builds that
/// used std (see [`crate::experiment::PLATFORM_POW_METRICS`]).
pub const MATH: &str = "libm";

/// Value of `run.mcap_format` and the header profile prefix.
pub const MCAP_FORMAT: &str = "mps.v1";
/// MCAP header profile of our files.
pub const PROFILE: &str = "mps";
/// Suffix of the file being written.
pub const PARTIAL_SUFFIX: &str = ".partial";

pub const TOPIC_STATE: &str = "/state";
pub const TOPIC_PARTICLES: &str = "/particles";
pub const TOPIC_DIAGNOSTICS: &str = "/diagnostics";
pub const TOPIC_SUMMARY: &str = "/summary";

pub const SCHEMA_STATE: &str = "mps.v1.StateCheckpoint";
pub const SCHEMA_POINT_CLOUD: &str = "foxglove.PointCloud";
pub const SCHEMA_DIAGNOSTICS: &str = "mps.v1.Diagnostics";
pub const SCHEMA_SUMMARY: &str = "mps.v1.Summary";

/// Metadata record names.
pub const META_MANIFEST: &str = "manifest";
pub const META_BUILD: &str = "build";
pub const META_RUN: &str = "run";
pub const META_OUTCOME: &str = "outcome";
/// Attachment holding the manifest text as written.
pub const ATTACHMENT_MANIFEST: &str = "manifest.yaml";

/// Uncompressed chunk size target. Fixed: the chunk boundaries are part of the file bytes.
const CHUNK_SIZE: u64 = 1 << 20;
/// zstd level (3 is zstd's default), pinned so file bytes never depend on a library default.
const ZSTD_LEVEL: u32 = 3;
/// zstd worker threads. 0 = single-threaded zstd (its output differs from NbWorkers >= 1);
/// pinned because the mcap crate defaults to the number of physical CPUs.
const ZSTD_THREADS: u32 = 0;

/// `(topic, schema name)` in channel order; the index is the channel slot.
const CHANNELS: [(&str, &str); 4] = [
    (TOPIC_STATE, SCHEMA_STATE),
    (TOPIC_PARTICLES, SCHEMA_POINT_CLOUD),
    (TOPIC_DIAGNOSTICS, SCHEMA_DIAGNOSTICS),
    (TOPIC_SUMMARY, SCHEMA_SUMMARY),
];
const SLOT_STATE: usize = 0;
const SLOT_PARTICLES: usize = 1;
const SLOT_DIAGNOSTICS: usize = 2;
const SLOT_SUMMARY: usize = 3;

/// What a run file records about its experiment, written at the start.
#[derive(Debug, Clone, Copy)]
pub struct RunHeader<'a> {
    /// Manifest text as written.
    pub manifest_source: &'a str,
    /// `--set` strings, in order.
    pub overrides: &'a [String],
    /// Canonical JSON of the resolved manifest.
    pub canonical: &'a str,
    /// Hex SHA-256 of `canonical`.
    pub experiment_sha256: &'a str,
    pub name: &'a str,
    /// The default preset the source was resolved under (`manifest::default_preset` for a
    /// new run); recorded as `default_preset` only when there is one.
    pub default_preset: Option<&'a str>,
    /// What the presets set when the source was resolved (`manifest::PRESET_REVISION` for
    /// a new run); recorded as `preset_revision` (`None`: not recorded, as in files from
    /// before the revisions, which read as revision 1).
    pub preset_revision: Option<u32>,
    /// Informational only (the recorded state does not depend on it).
    pub threads: usize,
}

/// How a run ended; recorded in the `outcome` metadata and the `/summary` message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    Completed,
    Failed(String),
    Interrupted(String),
}

impl Outcome {
    /// `"completed"`, `"failed"` or `"interrupted"`.
    pub fn as_str(&self) -> &'static str {
        match self {
            Outcome::Completed => "completed",
            Outcome::Failed(_) => "failed",
            Outcome::Interrupted(_) => "interrupted",
        }
    }

    /// Why the run failed or stopped; empty when completed.
    pub fn reason(&self) -> &str {
        match self {
            Outcome::Completed => "",
            Outcome::Failed(r) | Outcome::Interrupted(r) => r,
        }
    }
}

/// `<final_path>.partial`: where a run is written until it is finished.
pub fn partial_path(final_path: &Path) -> PathBuf {
    let mut name = final_path.as_os_str().to_owned();
    name.push(PARTIAL_SUFFIX);
    PathBuf::from(name)
}

/// Whether [`Recorder::create_with`] may replace what a run of the same experiment left.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Existing {
    /// Refuse when the final file or a killed run's `.partial` exists.
    #[default]
    Refuse,
    /// Replace both (the new file takes the final name only when it is finished).
    Replace,
}

/// Opens and locks `partial` for writing, empty, after the checks of [`Existing`].
fn claim(final_path: &Path, partial: &Path, existing: Existing) -> Result<File> {
    let refuse = existing == Existing::Refuse;
    let exists = |path: &Path| path.try_exists().unwrap_or(true);
    if refuse && exists(final_path) {
        return Err(RecordError::Exists {
            path: final_path.to_path_buf(),
        });
    }
    let file = fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(partial)
        .map_err(io_err(partial))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(fs::TryLockError::WouldBlock) => {
            return Err(RecordError::Busy {
                path: partial.to_path_buf(),
            });
        }
        Err(fs::TryLockError::Error(e)) => return Err(io_err(partial)(e)),
    }
    let len = file.metadata().map_err(io_err(partial))?.len();
    // The final file may have appeared while the lock was taken (a runner that finished).
    if refuse && exists(final_path) {
        if len == 0 {
            let _ = fs::remove_file(partial);
        }
        return Err(RecordError::Exists {
            path: final_path.to_path_buf(),
        });
    }
    if refuse && len > 0 {
        return Err(RecordError::Unfinished {
            path: partial.to_path_buf(),
        });
    }
    file.set_len(0).map_err(io_err(partial))?;
    Ok(file)
}

/// Takes the lock a writing [`Recorder`] holds on a `.partial` file, for a process that is
/// about to take the file over (resume); `Busy` when a runner is still writing it. Hold the
/// returned handle until done: the lock follows the file through a rename.
pub fn lock_unfinished(partial: &Path) -> Result<File> {
    let file = File::open(partial).map_err(io_err(partial))?;
    match file.try_lock() {
        Ok(()) => Ok(file),
        Err(fs::TryLockError::WouldBlock) => Err(RecordError::Busy {
            path: partial.to_path_buf(),
        }),
        Err(fs::TryLockError::Error(e)) => Err(io_err(partial)(e)),
    }
}

/// Writes one run file. See the module documentation for the layout.
///
/// Dropping a `Recorder` without [`finish`](Recorder::finish) closes the open chunk and leaves
/// the `.partial` file without summary section or footer, like a killed run.
pub struct Recorder {
    /// `None` only after `finish` took it.
    writer: Option<mcap::Writer<BufWriter<File>>>,
    /// Second handle on the same open file, used for `sync_data`.
    sync_handle: File,
    partial: PathBuf,
    final_path: PathBuf,
    experiment_sha256: String,
    channel_ids: [u16; 4],
    sequences: [u32; 4],
    /// `/metrics`: added at the first `/diagnostics` row that has metrics (its names make
    /// the schema); channel id, layout and next sequence number.
    metrics: Option<(u16, metrics_channel::MetricsLayout, u32)>,
}

impl Recorder {
    /// Creates `<final_path>.partial`, and writes the header, the start metadata, the manifest
    /// attachment, schemas and channels. The result is synced to disk. Refuses (nothing
    /// written) when `final_path` exists, when another process is writing the same run, or
    /// when a killed run's `.partial` is there: see [`Recorder::create_with`].
    pub fn create(final_path: &Path, header: &RunHeader) -> Result<Recorder> {
        Self::create_with(final_path, header, Existing::Refuse)
    }

    /// [`Recorder::create`], with `existing` saying whether an existing final file or a
    /// killed run's `.partial` may be replaced. The `.partial` file is locked (an exclusive
    /// advisory lock, released when the recorder is dropped) in either case, so two processes
    /// never write the same run file; a replaced final file is only replaced by the atomic
    /// rename of [`Recorder::finish`].
    pub fn create_with(
        final_path: &Path,
        header: &RunHeader,
        existing: Existing,
    ) -> Result<Recorder> {
        let partial = partial_path(final_path);
        let file = claim(final_path, &partial, existing)?;
        let sync_handle = file.try_clone().map_err(io_err(&partial))?;
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(ZSTD_LEVEL)
            .compression_threads(ZSTD_THREADS)
            .chunk_size(Some(CHUNK_SIZE))
            .profile(PROFILE)
            .library(format!(
                "mps_runner/{} {}",
                env!("CARGO_PKG_VERSION"),
                mcap::LIBRARY_IDENTIFIER
            ));
        let mut writer = options
            .create(BufWriter::new(file))
            .map_err(mcap_err(&partial))?;

        let build = BuildInfo::current();
        let overrides = serde_json::to_string(header.overrides).expect("strings serialize");
        let threads = header.threads.to_string();
        let preset_revision = header.preset_revision.map(|r| r.to_string());
        let mut manifest_entries = vec![
            ("source", header.manifest_source),
            ("canonical", header.canonical),
            ("experiment_sha256", header.experiment_sha256),
            ("overrides", overrides.as_str()),
            ("name", header.name),
        ];
        if let Some(preset) = header.default_preset {
            manifest_entries.push(("default_preset", preset));
        }
        if let Some(revision) = &preset_revision {
            manifest_entries.push(("preset_revision", revision.as_str()));
        }
        let start_metadata: [(&str, Vec<(&str, &str)>); 3] = [
            (META_MANIFEST, manifest_entries),
            (
                META_BUILD,
                vec![
                    ("crate_version", build.crate_version),
                    ("git_commit", build.git_commit),
                    ("rustc", build.rustc),
                    ("target", build.target),
                    ("profile", build.profile),
                ],
            ),
            (
                META_RUN,
                vec![
                    ("threads", &threads),
                    ("mcap_format", MCAP_FORMAT),
                    ("math", MATH),
                ],
            ),
        ];
        for (name, entries) in start_metadata {
            writer
                .write_metadata(&metadata(name, &entries))
                .map_err(mcap_err(&partial))?;
        }
        writer
            .attach(&mcap::Attachment {
                log_time: 0,
                create_time: 0,
                name: ATTACHMENT_MANIFEST.to_string(),
                media_type: "application/yaml".to_string(),
                data: header.manifest_source.as_bytes().into(),
            })
            .map_err(mcap_err(&partial))?;

        let mut channel_ids = [0u16; 4];
        let no_metadata = BTreeMap::new();
        for (slot, (topic, schema_name)) in CHANNELS.iter().enumerate() {
            let schema_id = writer
                .add_schema(schema_name, "protobuf", crate::proto::DESCRIPTOR_SET)
                .map_err(mcap_err(&partial))?;
            channel_ids[slot] = writer
                .add_channel(schema_id, topic, "protobuf", &no_metadata)
                .map_err(mcap_err(&partial))?;
        }

        let mut recorder = Recorder {
            writer: Some(writer),
            sync_handle,
            partial,
            final_path: final_path.to_path_buf(),
            experiment_sha256: header.experiment_sha256.to_string(),
            channel_ids,
            sequences: [0; 4],
            metrics: None,
        };
        recorder.flush_and_sync()?;
        Ok(recorder)
    }

    /// Path of the file being written (`<final_path>.partial`).
    pub fn partial_path(&self) -> &Path {
        &self.partial
    }

    /// Writes a checkpoint on `/state`, then closes the chunk and syncs the file data, so a
    /// killed process keeps every completed checkpoint (and everything written before it).
    /// `msg.state_sha256` is the caller's to fill in.
    pub fn write_state(&mut self, log_time_ns: u64, msg: &StateCheckpoint) -> Result<()> {
        self.write(SLOT_STATE, log_time_ns, msg)?;
        self.flush_and_sync()
    }

    /// Writes one more metadata record (e.g. `resumed`). Writing metadata closes the current
    /// chunk: call it right after [`create`](Recorder::create), before any message.
    pub fn write_metadata(&mut self, name: &str, entries: &[(&str, &str)]) -> Result<()> {
        self.writer
            .as_mut()
            .expect("writer present until finish")
            .write_metadata(&metadata(name, entries))
            .map_err(mcap_err(&self.partial))
    }

    /// Writes a particle frame on `/particles` (see [`point_cloud`]).
    pub fn write_cloud(&mut self, log_time_ns: u64, msg: &PointCloud) -> Result<()> {
        self.write(SLOT_PARTICLES, log_time_ns, msg)
    }

    /// Writes a row of the time series on `/diagnostics`, and its experiment metrics on
    /// `/metrics` (see [`metrics_channel`]).
    pub fn write_diagnostics(&mut self, log_time_ns: u64, msg: &Diagnostics) -> Result<()> {
        self.write(SLOT_DIAGNOSTICS, log_time_ns, msg)?;
        if self.metrics.is_none() && !msg.metrics.is_empty() {
            let layout = metrics_channel::MetricsLayout::new(msg.metrics.keys());
            if !layout.is_empty() {
                let writer = self.writer.as_mut().expect("writer present until finish");
                let schema_id = writer
                    .add_schema(SCHEMA_METRICS, "protobuf", &layout.descriptor_set())
                    .map_err(mcap_err(&self.partial))?;
                let channel_id = writer
                    .add_channel(schema_id, TOPIC_METRICS, "protobuf", &BTreeMap::new())
                    .map_err(mcap_err(&self.partial))?;
                self.metrics = Some((channel_id, layout, 0));
            }
        }
        if let Some((channel_id, layout, sequence)) = &mut self.metrics {
            let header = MessageHeader {
                channel_id: *channel_id,
                sequence: *sequence,
                log_time: log_time_ns,
                publish_time: log_time_ns,
            };
            let data = layout.encode(msg.time_s, &msg.metrics);
            self.writer
                .as_mut()
                .expect("writer present until finish")
                .write_to_known_channel(&header, &data)
                .map_err(mcap_err(&self.partial))?;
            *sequence += 1;
        }
        Ok(())
    }

    /// Writes `/summary` and the `outcome` metadata, finishes the MCAP file (summary section
    /// and footer), syncs it and renames it to its final path, which it returns.
    ///
    /// The summary's `outcome` and `reason` are set from `outcome`, and its
    /// `experiment_sha256` from the run header when left empty, so that the message and the
    /// metadata always agree.
    pub fn finish(
        mut self,
        log_time_ns: u64,
        summary: &Summary,
        outcome: &Outcome,
    ) -> Result<PathBuf> {
        let mut summary = summary.clone();
        summary.outcome = outcome.as_str().to_string();
        summary.reason = outcome.reason().to_string();
        if summary.experiment_sha256.is_empty() {
            summary.experiment_sha256 = self.experiment_sha256.clone();
        }
        self.write(SLOT_SUMMARY, log_time_ns, &summary)?;

        let partial = self.partial.clone();
        let mut writer = self.writer.take().expect("writer present until finish");
        writer
            .write_metadata(&metadata(
                META_OUTCOME,
                &[("status", outcome.as_str()), ("reason", outcome.reason())],
            ))
            .map_err(mcap_err(&partial))?;
        writer.finish().map_err(mcap_err(&partial))?;
        // finish() succeeded, so dropping the writer later would not write again; into_inner
        // hands back the buffered file so that its flush error is not lost.
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| io_err(&partial)(e.into_error()))?;
        file.sync_all().map_err(io_err(&partial))?;
        drop(file);
        fs::rename(&partial, &self.final_path).map_err(io_err(&self.final_path))?;
        sync_parent_dir(&self.final_path)?;
        Ok(self.final_path.clone())
    }

    fn write<M: prost::Message>(&mut self, slot: usize, log_time_ns: u64, msg: &M) -> Result<()> {
        let data = msg.encode_to_vec();
        let header = MessageHeader {
            channel_id: self.channel_ids[slot],
            sequence: self.sequences[slot],
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.writer
            .as_mut()
            .expect("writer present until finish")
            .write_to_known_channel(&header, &data)
            .map_err(mcap_err(&self.partial))?;
        self.sequences[slot] += 1;
        Ok(())
    }

    /// Closes the current chunk, flushes buffers and syncs the file data to disk.
    fn flush_and_sync(&mut self) -> Result<()> {
        self.writer
            .as_mut()
            .expect("writer present until finish")
            .flush()
            .map_err(mcap_err(&self.partial))?;
        self.sync_handle.sync_data().map_err(io_err(&self.partial))
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if let Some(mut writer) = self.writer.take() {
            // Not finished (an error path or a panic): keep what was written, in complete
            // chunks, but write no summary section or footer. mcap's own Drop would call
            // finish(); into_inner() sidesteps it.
            let _ = writer.flush();
            let _ = writer.into_inner().into_inner();
            let _ = self.sync_handle.sync_data();
        }
    }
}

fn metadata(name: &str, entries: &[(&str, &str)]) -> Metadata {
    Metadata {
        name: name.to_string(),
        metadata: entries
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect(),
    }
}

#[cfg(unix)]
fn sync_parent_dir(path: &Path) -> Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(io_err(dir))
}

#[cfg(not(unix))]
fn sync_parent_dir(_path: &Path) -> Result<()> {
    Ok(())
}

/// A simulated time for titles and messages: to the microsecond, trailing zeros dropped (`0.3`, not
/// `0.30000000000000004`).
pub fn time_text(t_s: f64) -> String {
    let s = format!("{t_s:.6}");
    let s = s.trim_end_matches('0');
    s.strip_suffix('.').unwrap_or(s).to_string()
}
