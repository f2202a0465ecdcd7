//! Reading a run file back, complete or cut short by a killed process, and telling a damaged
//! file from either.
//!
//! One walker ([`walk`]) reads every file, record by record, with its own framing of the MCAP
//! records (opcode, length, body) so that every problem can be placed at a byte offset:
//! - a *finished* file (it ends with the MCAP footer and end magic) must be whole: every chunk
//!   decompresses to its stated size and matches its CRC, the data and summary sections match
//!   theirs, the summary section's indexes and statistics describe the data section, and the
//!   file holds its `/summary` message and `outcome` metadata. Anything else is
//!   [`RecordError::Damaged`] and nothing of the file is handed back;
//! - an *unfinished* file (a `.partial`, or a finished one that lost its end) is read up to the
//!   first record that is cut short or damaged, and everything before it is handed back with
//!   a [`Stop`] that says where and why. Reading stops there rather than skipping the record:
//!   a resumed run copies everything before the checkpoint it continues from, so what comes
//!   after a gap is of no use to it, and after a damaged length the next record boundary is a
//!   guess.
//!
//! A chunk is used all or nothing: its records are decompressed, checked against the CRC and
//! decoded before any of them is handed on.

mod summary;
mod walker;

use std::collections::BTreeMap;
use std::path::Path;

use mcap::records::op;

use super::error::{RecordError, Result, io_err};
use crate::proto::foxglove::PointCloud;
use crate::proto::mps::v1::{Diagnostics, StateCheckpoint, Summary};

/// Everything a run file holds, decoded, in file order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunFile {
    /// Metadata records by name (`manifest`, `build`, `run`, and `outcome` when finished).
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    pub states: Vec<StateCheckpoint>,
    pub diagnostics: Vec<Diagnostics>,
    /// Number of `/particles` frames (each one decoded to check it).
    pub clouds: usize,
    /// The last `/particles` frame, decoded (for snapshots).
    pub last_cloud: Option<PointCloud>,
    pub summary: Option<Summary>,
    /// The file is finished and whole: summary section, footer, every CRC, the `/summary`
    /// message. When false, the fields above hold what the file holds before [`Self::stop`].
    pub complete: bool,
    /// For an unfinished file: where and why reading stopped before the end of the file;
    /// `None` when the file ends on a record boundary (a killed run between two chunks).
    pub stop: Option<Stop>,
    /// Messages per topic on the channels that are not decoded here (`/metrics`: the same
    /// values as the `/diagnostics` metrics, for viewers).
    pub other_channels: BTreeMap<String, usize>,
}

impl RunFile {
    /// Field `key` of the run's `manifest` metadata record (`name`, `experiment_sha256`,
    /// `canonical`, `overrides`), as written.
    pub fn manifest_field(&self, key: &str) -> Option<&str> {
        self.metadata
            .get(super::META_MANIFEST)?
            .get(key)
            .map(String::as_str)
    }
}

/// Where reading an unfinished file stopped before its end.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stop {
    /// Offset of the record reading stopped at, from the start of the file.
    pub at_byte: u64,
    /// True when that record is damaged (fails its CRC, cannot be read or decoded, breaks a
    /// channel's sequence); false when it is only cut short by the end of the file, as a
    /// killed run leaves its last chunk.
    pub damaged: bool,
    /// What is wrong with it, e.g. "the chunk at byte 5120 fails its CRC (...)".
    pub reason: String,
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.reason)
    }
}

/// What [`check_run`] found: the structure of a file as [`read_run`] reads it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileCheck {
    /// See [`RunFile::complete`].
    pub complete: bool,
    /// See [`RunFile::stop`].
    pub stop: Option<Stop>,
    /// `/state` checkpoints read before the stop (all of them when there is none).
    pub checkpoints: usize,
}

#[derive(Debug)]
struct ChannelInfo {
    topic: String,
    message_encoding: String,
}

/// One logged message, decoded.
#[derive(Debug, Clone, PartialEq)]
pub enum Logged {
    State(StateCheckpoint),
    Diagnostics(Diagnostics),
    Cloud(PointCloud),
    Summary(Summary),
}

/// Reads a run file. A finished file must be whole ([`RecordError::Damaged`] otherwise); an
/// unfinished one (a killed run, or a `.partial` file) is read up to its first record that is
/// cut short or damaged: every chunk before it is recovered, along with the metadata written
/// at the start, `complete` is false and `stop` says where reading stopped.
pub fn read_run(path: &Path) -> Result<RunFile> {
    let mut run = RunFile::default();
    let walked = walk(path, |_, message| match message {
        Logged::State(m) => run.states.push(m),
        Logged::Diagnostics(m) => run.diagnostics.push(m),
        Logged::Cloud(m) => {
            run.last_cloud = Some(m);
            run.clouds += 1;
        }
        Logged::Summary(m) => run.summary = Some(m),
    })?;
    run.metadata = walked.metadata;
    run.complete = walked.complete;
    run.stop = walked.stop;
    run.other_channels = walked.others;
    Ok(run)
}

/// Every message of a run file in file order with its log time, up to the stop of an
/// unfinished file (the same reading as [`read_run`]).
pub fn read_messages(path: &Path) -> Result<Vec<(u64, Logged)>> {
    let mut out = Vec::new();
    walk(path, |log_time, message| out.push((log_time, message)))?;
    Ok(out)
}

/// Checks a run file's structure as [`read_run`] reads it, without keeping its messages.
pub fn check_run(path: &Path) -> Result<FileCheck> {
    let mut checkpoints = 0;
    let walked = walk(path, |_, message| {
        if let Logged::State(_) = message {
            checkpoints += 1;
        }
    })?;
    Ok(FileCheck {
        complete: walked.complete,
        stop: walked.stop,
        checkpoints,
    })
}

/// What a walk over a file found besides its messages.
struct Walked {
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    complete: bool,
    stop: Option<Stop>,
    others: BTreeMap<String, usize>,
}

/// Opcode, length and end magic framing (MCAP spec: opcode u8, body length u64 LE).
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
const RECORD_PREFIX_BYTES: usize = 9;
/// A footer record: prefix plus summary_start u64, summary_offset_start u64, summary_crc u32.
const FOOTER_RECORD_BYTES: usize = RECORD_PREFIX_BYTES + 20;

/// One record in a byte buffer: opcode and body.
struct Framed<'a> {
    opcode: u8,
    body: &'a [u8],
    /// Offset just past the record.
    end: usize,
}

/// The record starting at `at`, `Ok(None)` at the end of the buffer, or why it cannot be
/// framed (it runs past the end).
fn frame(buf: &[u8], at: usize) -> std::result::Result<Option<Framed<'_>>, String> {
    let rest = &buf[at..];
    if rest.is_empty() {
        return Ok(None);
    }
    if rest.len() < RECORD_PREFIX_BYTES {
        return Err(format!(
            "only {} of the 9 bytes of a record's opcode and length remain at byte {at}",
            rest.len()
        ));
    }
    let opcode = rest[0];
    let len = u64::from_le_bytes(rest[1..9].try_into().expect("8 bytes"));
    let available = (rest.len() - RECORD_PREFIX_BYTES) as u64;
    if opcode == op::CHUNK && len == u64::MAX {
        // The mcap writer streams a chunk with this placeholder length and fills in the real
        // one when it closes the chunk: a run in progress, or killed while writing it.
        return Err(format!(
            "the chunk at byte {at} is still open (its length is written when it closes)"
        ));
    }
    if len > available {
        return Err(format!(
            "the {} record at byte {at} needs {len} bytes, {available} remain",
            opcode_name(opcode)
        ));
    }
    let end = at + RECORD_PREFIX_BYTES + len as usize;
    Ok(Some(Framed {
        opcode,
        body: &buf[at + RECORD_PREFIX_BYTES..end],
        end,
    }))
}

fn opcode_name(opcode: u8) -> String {
    match opcode {
        op::HEADER => "header".into(),
        op::FOOTER => "footer".into(),
        op::SCHEMA => "schema".into(),
        op::CHANNEL => "channel".into(),
        op::MESSAGE => "message".into(),
        op::CHUNK => "chunk".into(),
        op::MESSAGE_INDEX => "message index".into(),
        op::CHUNK_INDEX => "chunk index".into(),
        op::ATTACHMENT => "attachment".into(),
        op::ATTACHMENT_INDEX => "attachment index".into(),
        op::STATISTICS => "statistics".into(),
        op::METADATA => "metadata".into(),
        op::METADATA_INDEX => "metadata index".into(),
        op::SUMMARY_OFFSET => "summary offset".into(),
        op::DATA_END => "data end".into(),
        other => format!("unknown (opcode 0x{other:02x})"),
    }
}

/// A problem found at a byte offset: cut short by the end of the file, or damaged.
struct Problem {
    at_byte: usize,
    cut: bool,
    reason: String,
}

fn damaged(at_byte: usize, reason: String) -> Problem {
    Problem {
        at_byte,
        cut: false,
        reason,
    }
}

/// Walker state: the channels and sequences seen so far, and what the summary section must
/// agree with.
#[derive(Default)]
struct Walker {
    channels: BTreeMap<u16, ChannelInfo>,
    /// Next expected sequence number per channel (the recorder numbers each from 0).
    next_sequence: BTreeMap<u16, u32>,
    /// Messages decoded per topic (to name a message in an error).
    decoded: BTreeMap<&'static str, usize>,
    messages: u64,
    summaries: usize,
    /// (offset, length) of every chunk, metadata and attachment record.
    chunks: Vec<(u64, u64)>,
    metadata_records: Vec<(u64, u64)>,
    attachments: Vec<(u64, u64)>,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// Messages per topic on the other channels (counted, not decoded).
    others: BTreeMap<String, usize>,
}

/// The one reader of run files: visits every message on our topics in file order, decoded,
/// with its log time; collects the metadata. See the module documentation.
fn walk(path: &Path, mut on_message: impl FnMut(u64, Logged)) -> Result<Walked> {
    let buf = std::fs::read(path).map_err(io_err(path))?;
    let invalid = |reason: &str| RecordError::Invalid {
        path: path.to_path_buf(),
        reason: reason.into(),
    };
    if buf.is_empty() {
        return Err(invalid("empty file"));
    }
    if !buf.starts_with(MAGIC) {
        return Err(invalid(
            "it does not start with the MCAP magic bytes (not an MCAP file)",
        ));
    }
    // Footer record and end magic where a finished file has them.
    let finished = buf.len() >= MAGIC.len() + FOOTER_RECORD_BYTES + MAGIC.len()
        && buf.ends_with(MAGIC)
        && buf[buf.len() - MAGIC.len() - FOOTER_RECORD_BYTES] == op::FOOTER;
    let mut walker = Walker::default();
    // The header comes first in every file, finished or not; without it nothing is usable.
    let header_end = match frame(&buf, MAGIC.len()) {
        Ok(Some(f)) if f.opcode == op::HEADER => {
            mcap::parse_record(f.opcode, f.body)
                .map_err(|e| invalid(&format!("its header record cannot be read: {e}")))?;
            f.end
        }
        Ok(Some(f)) => {
            return Err(invalid(&format!(
                "the first record is a {} record, not an MCAP header",
                opcode_name(f.opcode)
            )));
        }
        Ok(None) | Err(_) => return Err(invalid("empty MCAP file (no whole header record)")),
    };
    let result = walker.records(&buf, header_end, finished, &mut on_message);
    let metadata = std::mem::take(&mut walker.metadata);
    let others = std::mem::take(&mut walker.others);
    match result {
        Ok(()) => Ok(Walked {
            metadata,
            complete: finished,
            stop: None,
            others,
        }),
        Err(p) if finished => Err(RecordError::Damaged {
            path: path.to_path_buf(),
            reason: p.reason,
        }),
        Err(p) => Ok(Walked {
            metadata,
            others,
            complete: false,
            stop: Some(Stop {
                at_byte: p.at_byte as u64,
                damaged: !p.cut,
                reason: p.reason,
            }),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(opcode: u8, len: u64, body: &[u8]) -> Vec<u8> {
        let mut b = vec![opcode];
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(body);
        b
    }

    #[test]
    fn an_open_chunk_is_named_as_open_not_as_a_length_of_two_to_the_64() {
        let buf = record(op::CHUNK, u64::MAX, &[0; 44]);
        let why = frame(&buf, 0).err().unwrap();
        assert_eq!(
            why,
            "the chunk at byte 0 is still open (its length is written when it closes)"
        );
        // Any other length past the end is still reported with its numbers.
        let buf = record(op::CHUNK, 100, &[0; 44]);
        assert_eq!(
            frame(&buf, 0).err().unwrap(),
            "the chunk record at byte 0 needs 100 bytes, 44 remain"
        );
        let buf = record(op::METADATA, u64::MAX, &[0; 4]);
        assert!(
            frame(&buf, 0)
                .err()
                .unwrap()
                .contains("needs 18446744073709551615 bytes")
        );
        // A whole record frames.
        let buf = record(op::CHUNK, 3, &[1, 2, 3]);
        let framed = frame(&buf, 0).unwrap().unwrap();
        assert_eq!(
            (framed.opcode, framed.body, framed.end),
            (op::CHUNK, &[1u8, 2, 3][..], 12)
        );
    }
}
