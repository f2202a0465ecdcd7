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

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::Read as _;
use std::path::Path;

use mcap::records::{Record, op};
use prost::Message as _;

use super::error::{RecordError, Result, io_err};
use super::{META_OUTCOME, TOPIC_DIAGNOSTICS, TOPIC_PARTICLES, TOPIC_STATE, TOPIC_SUMMARY};
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

/// Where the data and summary sections were found to end.
#[derive(Default)]
struct Sections {
    /// Offset just past the data end record (the start of the summary section).
    summary_start: Option<usize>,
    /// Offset of the first summary offset record.
    summary_offsets_start: Option<usize>,
    chunk_indexes: Vec<(u64, u64)>,
    metadata_indexes: Vec<(u64, u64)>,
    attachment_indexes: Vec<(u64, u64)>,
    statistics: Option<mcap::records::Statistics>,
    /// (start, length) of each summary offset group.
    groups: Vec<(u64, u64)>,
}

impl Walker {
    /// Walks the records after the header. `Err` at the first problem; an unfinished file
    /// that ends on a record boundary is `Ok`.
    fn records(
        &mut self,
        buf: &[u8],
        mut at: usize,
        finished: bool,
        on_message: &mut impl FnMut(u64, Logged),
    ) -> std::result::Result<(), Problem> {
        let mut sections = Sections::default();
        let footer_at = loop {
            let f = match frame(buf, at) {
                Ok(Some(f)) => f,
                Ok(None) if finished => {
                    return Err(damaged(
                        at,
                        format!(
                            "the records end at byte {at} without reaching the footer record at byte {}",
                            buf.len() - MAGIC.len() - FOOTER_RECORD_BYTES
                        ),
                    ));
                }
                Ok(None) => return Ok(()),
                Err(why) => {
                    return Err(Problem {
                        at_byte: at,
                        cut: !finished,
                        reason: why,
                    });
                }
            };
            let name = opcode_name(f.opcode);
            let in_summary = sections.summary_start.is_some();
            let bad_record = |e: &dyn std::fmt::Display| {
                damaged(
                    at,
                    format!("the {name} record at byte {at} cannot be read: {e}"),
                )
            };
            match (f.opcode, in_summary) {
                (op::FOOTER, _) => break at,
                (op::CHUNK, false) => {
                    let messages = self
                        .chunk(f.body)
                        .map_err(|why| damaged(at, format!("the chunk at byte {at} {why}")))?;
                    self.chunks.push((at as u64, (f.end - at) as u64));
                    for (log_time, message) in messages {
                        on_message(log_time, message);
                    }
                }
                (op::MESSAGE, false) => {
                    let message = self
                        .message(f.body)
                        .map_err(|why| damaged(at, format!("the message at byte {at} {why}")))?;
                    if let Some((log_time, message)) = message {
                        on_message(log_time, message);
                    }
                }
                (op::SCHEMA | op::CHANNEL, _) => {
                    let record =
                        mcap::parse_record(f.opcode, f.body).map_err(|e| bad_record(&e))?;
                    if let Record::Channel(c) = record {
                        self.add_channel(c).map_err(|why| {
                            damaged(at, format!("the channel at byte {at} {why}"))
                        })?;
                    }
                }
                (op::METADATA, false) => {
                    let Record::Metadata(m) =
                        mcap::parse_record(f.opcode, f.body).map_err(|e| bad_record(&e))?
                    else {
                        unreachable!("parse_record maps the metadata opcode to Metadata")
                    };
                    if self.metadata.contains_key(&m.name) {
                        return Err(damaged(
                            at,
                            format!(
                                "the metadata record at byte {at} repeats the name `{}`",
                                m.name
                            ),
                        ));
                    }
                    self.metadata_records.push((at as u64, (f.end - at) as u64));
                    self.metadata.insert(m.name, m.metadata);
                }
                (op::ATTACHMENT, false) => {
                    attachment_layout(f.body).map_err(|why| bad_record(&why))?;
                    // Parsing checks the attachment's own CRC.
                    mcap::parse_record(f.opcode, f.body).map_err(|e| bad_record(&e))?;
                    self.attachments.push((at as u64, (f.end - at) as u64));
                }
                (op::MESSAGE_INDEX, false) => {
                    mcap::parse_record(f.opcode, f.body).map_err(|e| bad_record(&e))?;
                }
                (op::DATA_END, false) => {
                    let Record::DataEnd(end) =
                        mcap::parse_record(f.opcode, f.body).map_err(|e| bad_record(&e))?
                    else {
                        unreachable!("parse_record maps the data end opcode to DataEnd")
                    };
                    let computed = crc32fast::hash(&buf[..at]);
                    if end.data_section_crc != 0 && end.data_section_crc != computed {
                        return Err(damaged(
                            at,
                            format!(
                                "the data section (bytes 0 to {at}) fails its CRC (stored {:08x}, computed {computed:08x})",
                                end.data_section_crc
                            ),
                        ));
                    }
                    sections.summary_start = Some(f.end);
                }
                (
                    op::CHUNK_INDEX
                    | op::ATTACHMENT_INDEX
                    | op::METADATA_INDEX
                    | op::STATISTICS
                    | op::SUMMARY_OFFSET,
                    true,
                ) => {
                    let record = mcap::parse_record(f.opcode, f.body).map_err(|e| {
                        damaged(
                            at,
                            format!(
                                "the summary section is unreadable: the {name} record at byte {at}: {e}"
                            ),
                        )
                    })?;
                    sections.add(record, at);
                }
                (_, true) => {
                    return Err(damaged(
                        at,
                        format!("the summary section is unreadable: a {name} record at byte {at}"),
                    ));
                }
                (op::HEADER, false) => {
                    return Err(damaged(at, format!("a second header record at byte {at}")));
                }
                (_, false) => {
                    return Err(damaged(
                        at,
                        format!(
                            "a {name} record at byte {at}, which has no place in the data section"
                        ),
                    ));
                }
            }
            at = f.end;
        };
        let expected_footer_at = buf.len() - MAGIC.len() - FOOTER_RECORD_BYTES;
        if !finished {
            // A footer, yet the file does not end as a finished one does: cut inside the end
            // magic, or followed by something else.
            let after = &buf[(footer_at + FOOTER_RECORD_BYTES).min(buf.len())..];
            return Err(Problem {
                at_byte: footer_at,
                cut: MAGIC.starts_with(after),
                reason: format!(
                    "the footer record at byte {footer_at} is not followed by the MCAP end magic and the end of the file ({} bytes follow it)",
                    after.len()
                ),
            });
        }
        if footer_at != expected_footer_at {
            return Err(damaged(
                footer_at,
                format!(
                    "a footer record at byte {footer_at}, but the file's footer is at byte {expected_footer_at}"
                ),
            ));
        }
        self.check_summary(buf, footer_at, &sections)
    }

    /// A finished file's summary section and footer against what the data section holds;
    /// then the `/summary` message and `outcome` metadata a finished run ends with.
    fn check_summary(
        &self,
        buf: &[u8],
        footer_at: usize,
        sections: &Sections,
    ) -> std::result::Result<(), Problem> {
        let Some(summary_start) = sections.summary_start else {
            return Err(damaged(
                footer_at,
                "no data end record before the footer (the data section is not closed)".into(),
            ));
        };
        let field = |i: usize| {
            let at = footer_at + RECORD_PREFIX_BYTES + 8 * i;
            u64::from_le_bytes(buf[at..at + 8].try_into().expect("8 bytes"))
        };
        let (footer_summary_start, footer_offsets_start) = (field(0), field(1));
        let crc_at = footer_at + RECORD_PREFIX_BYTES + 16;
        let stored_crc = u32::from_le_bytes(buf[crc_at..crc_at + 4].try_into().expect("4 bytes"));
        let unreadable = |reason: String| {
            damaged(
                summary_start,
                format!("the summary section is unreadable: {reason}"),
            )
        };
        if footer_summary_start != summary_start as u64 {
            return Err(unreadable(format!(
                "the footer places it at byte {footer_summary_start}, it starts at byte {summary_start}"
            )));
        }
        let expected_offsets = sections.summary_offsets_start.map_or(0, |s| s as u64);
        if footer_offsets_start != expected_offsets {
            return Err(unreadable(format!(
                "the footer places its offsets at byte {footer_offsets_start}, they are at byte {expected_offsets}"
            )));
        }
        let computed = crc32fast::hash(&buf[summary_start..crc_at]);
        if stored_crc != 0 && stored_crc != computed {
            return Err(unreadable(format!(
                "bytes {summary_start} to {crc_at} fail their CRC (stored {stored_crc:08x}, computed {computed:08x})"
            )));
        }
        let lists = |what: &str, listed: &[(u64, u64)], held: &[(u64, u64)]| {
            let mut listed = listed.to_vec();
            listed.sort_unstable();
            if listed == held {
                return Ok(());
            }
            Err(unreadable(format!(
                "its index lists {} {what} records at {:?}, the data section holds {} at {:?}",
                listed.len(),
                listed.iter().map(|r| r.0).collect::<Vec<_>>(),
                held.len(),
                held.iter().map(|r| r.0).collect::<Vec<_>>()
            )))
        };
        lists("chunk", &sections.chunk_indexes, &self.chunks)?;
        lists(
            "metadata",
            &sections.metadata_indexes,
            &self.metadata_records,
        )?;
        lists(
            "attachment",
            &sections.attachment_indexes,
            &self.attachments,
        )?;
        let Some(stats) = &sections.statistics else {
            return Err(unreadable("it has no statistics record".into()));
        };
        let counted = [
            ("messages", stats.message_count, self.messages),
            ("chunks", stats.chunk_count.into(), self.chunks.len() as u64),
            (
                "metadata records",
                stats.metadata_count.into(),
                self.metadata_records.len() as u64,
            ),
            (
                "attachments",
                stats.attachment_count.into(),
                self.attachments.len() as u64,
            ),
        ];
        for (what, stated, held) in counted {
            if stated != held {
                return Err(unreadable(format!(
                    "its statistics count {stated} {what}, the data section holds {held}"
                )));
            }
        }
        let section_end = footer_at as u64;
        for &(start, length) in &sections.groups {
            if start < summary_start as u64 || start.saturating_add(length) > section_end {
                return Err(unreadable(format!(
                    "a summary offset points at bytes {start} to {} outside it",
                    start.saturating_add(length)
                )));
            }
        }
        if self.summaries == 0 {
            return Err(damaged(
                footer_at,
                "no /summary message: a finished run ends with one (the file is cut or was not written by a finished run)".into(),
            ));
        }
        if !self.metadata.contains_key(META_OUTCOME) {
            return Err(damaged(
                footer_at,
                "no `outcome` metadata record: a finished run ends with one".into(),
            ));
        }
        Ok(())
    }

    /// The messages of a chunk, decoded, or why the chunk is damaged (the text follows "the
    /// chunk at byte N").
    fn chunk(&mut self, body: &[u8]) -> std::result::Result<Vec<(u64, Logged)>, String> {
        let Record::Chunk { header, data } =
            mcap::parse_record(op::CHUNK, body).map_err(|e| format!("cannot be read: {e}"))?
        else {
            unreachable!("parse_record maps the chunk opcode to Chunk")
        };
        let records: Cow<[u8]> = match header.compression.as_str() {
            "" => data,
            "zstd" => {
                // Read no further than one byte past the stated size: the stated size itself
                // is not trusted with an allocation.
                let mut out = Vec::new();
                zstd::stream::read::Decoder::with_buffer(&data[..])
                    .and_then(|d| {
                        d.take(header.uncompressed_size.saturating_add(1))
                            .read_to_end(&mut out)
                    })
                    .map_err(|e| format!("cannot be decompressed: {e}"))?;
                Cow::Owned(out)
            }
            other => {
                return Err(format!(
                    "uses the compression {other:?}, which no run file uses"
                ));
            }
        };
        if records.len() as u64 != header.uncompressed_size {
            return Err(format!(
                "decompresses to {} bytes, its header says {}",
                records.len(),
                header.uncompressed_size
            ));
        }
        let computed = crc32fast::hash(&records);
        if header.uncompressed_crc != 0 && header.uncompressed_crc != computed {
            return Err(format!(
                "fails its CRC (stored {:08x}, computed {computed:08x})",
                header.uncompressed_crc
            ));
        }
        let mut messages = Vec::new();
        let mut inner = 0;
        while let Some(f) = frame(&records, inner)
            .map_err(|why| format!("holds a record cut short: {why} of its contents"))?
        {
            let in_chunk = |why: String| {
                format!(
                    "holds a {} record at byte {inner} of its contents that {why}",
                    opcode_name(f.opcode)
                )
            };
            match f.opcode {
                op::MESSAGE => {
                    if let Some(m) = self.message(f.body).map_err(in_chunk)? {
                        messages.push(m);
                    }
                }
                op::SCHEMA => {
                    mcap::parse_record(f.opcode, f.body)
                        .map_err(|e| in_chunk(format!("cannot be read: {e}")))?;
                }
                op::CHANNEL => {
                    let Record::Channel(c) = mcap::parse_record(f.opcode, f.body)
                        .map_err(|e| in_chunk(format!("cannot be read: {e}")))?
                    else {
                        unreachable!("parse_record maps the channel opcode to Channel")
                    };
                    self.add_channel(c).map_err(in_chunk)?;
                }
                _ => return Err(in_chunk("has no place in a chunk".into())),
            }
            inner = f.end;
        }
        Ok(messages)
    }

    fn add_channel(&mut self, c: mcap::records::Channel) -> std::result::Result<(), String> {
        if let Some(known) = self.channels.get(&c.id) {
            if known.topic != c.topic || known.message_encoding != c.message_encoding {
                return Err(format!(
                    "redefines channel {} ({}) as {}",
                    c.id, known.topic, c.topic
                ));
            }
            return Ok(());
        }
        self.channels.insert(
            c.id,
            ChannelInfo {
                topic: c.topic,
                message_encoding: c.message_encoding,
            },
        );
        Ok(())
    }

    /// A message record decoded, `None` on a topic that is not ours, or why it is damaged.
    fn message(&mut self, body: &[u8]) -> std::result::Result<Option<(u64, Logged)>, String> {
        let Record::Message { header, data } =
            mcap::parse_record(op::MESSAGE, body).map_err(|e| format!("cannot be read: {e}"))?
        else {
            unreachable!("parse_record maps the message opcode to Message")
        };
        self.messages += 1;
        let channel = self
            .channels
            .get(&header.channel_id)
            .ok_or_else(|| format!("is on undeclared channel {}", header.channel_id))?;
        let Some(topic) = [
            TOPIC_STATE,
            TOPIC_PARTICLES,
            TOPIC_DIAGNOSTICS,
            TOPIC_SUMMARY,
        ]
        .into_iter()
        .find(|t| *t == channel.topic) else {
            *self.others.entry(channel.topic.clone()).or_default() += 1;
            return Ok(None);
        };
        if channel.message_encoding != "protobuf" {
            return Err(format!(
                "is on channel {} with message encoding {:?}, expected \"protobuf\"",
                channel.topic, channel.message_encoding
            ));
        }
        let expected = self.next_sequence.entry(header.channel_id).or_default();
        if header.sequence != *expected {
            return Err(format!(
                "carries sequence number {} on {topic}, where {} comes next (a message is missing or repeated)",
                header.sequence, *expected
            ));
        }
        *expected = expected.saturating_add(1);
        let index = self.decoded.entry(topic).or_default();
        let decode_err = |e: prost::DecodeError| {
            format!("holds message {index} on {topic}, which cannot be decoded: {e}")
        };
        let message = match topic {
            TOPIC_STATE => Logged::State(StateCheckpoint::decode(&data[..]).map_err(decode_err)?),
            TOPIC_PARTICLES => Logged::Cloud(PointCloud::decode(&data[..]).map_err(decode_err)?),
            TOPIC_DIAGNOSTICS => {
                Logged::Diagnostics(Diagnostics::decode(&data[..]).map_err(decode_err)?)
            }
            _ => {
                if self.summaries > 0 {
                    return Err("is a second /summary message".into());
                }
                self.summaries += 1;
                Logged::Summary(Summary::decode(&data[..]).map_err(decode_err)?)
            }
        };
        *index += 1;
        Ok(Some((header.log_time, message)))
    }
}

impl Sections {
    fn add(&mut self, record: Record, at: usize) {
        match record {
            Record::ChunkIndex(c) => self
                .chunk_indexes
                .push((c.chunk_start_offset, c.chunk_length)),
            Record::MetadataIndex(m) => self.metadata_indexes.push((m.offset, m.length)),
            Record::AttachmentIndex(a) => self.attachment_indexes.push((a.offset, a.length)),
            Record::Statistics(s) => self.statistics = Some(s),
            Record::SummaryOffset(o) => {
                self.summary_offsets_start.get_or_insert(at);
                self.groups.push((o.group_start, o.group_length));
            }
            _ => {}
        }
    }
}

/// Checks the lengths inside an attachment record before the mcap crate slices by them
/// (it indexes past the end of a body too short for its CRC): log_time, create_time, name,
/// media type, data length and data, CRC.
fn attachment_layout(body: &[u8]) -> std::result::Result<(), String> {
    let u32_at = |at: usize| {
        body.get(at..at + 4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")) as usize)
    };
    let short = || "it is shorter than its fields say".to_string();
    let name_len = u32_at(16).ok_or_else(short)?;
    let media_at = 20usize.checked_add(name_len).ok_or_else(short)?;
    let media_len = u32_at(media_at).ok_or_else(short)?;
    let data_len_at = (media_at + 4).checked_add(media_len).ok_or_else(short)?;
    let data_len = body
        .get(data_len_at..data_len_at + 8)
        .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
        .ok_or_else(short)?;
    let needed = (data_len_at as u64 + 8)
        .checked_add(data_len)
        .and_then(|n| n.checked_add(4))
        .ok_or_else(short)?;
    if needed != body.len() as u64 {
        return Err(format!(
            "it is {} than its fields say (they take {needed} bytes, it has {})",
            if needed > body.len() as u64 {
                "shorter"
            } else {
                "longer"
            },
            body.len()
        ));
    }
    Ok(())
}
