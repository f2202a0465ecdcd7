//! Reading a run file back, complete or cut short by a killed process.

use std::collections::BTreeMap;
use std::path::Path;

use mcap::read::{ChunkReader, LinearReader, Options};
use mcap::records::Record;
use prost::Message as _;

use super::error::{RecordError, Result, io_err, mcap_err};
use super::{TOPIC_DIAGNOSTICS, TOPIC_PARTICLES, TOPIC_STATE, TOPIC_SUMMARY};
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
    /// The file has its summary section and footer (the recorder finished it). When false,
    /// the fields above hold what the completed chunks contain.
    pub complete: bool,
    /// For an incomplete file: why reading stopped before the end of the file (typically an
    /// unfinished chunk at the tail); `None` when the file ends on a record boundary.
    pub tail_error: Option<String>,
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

/// Reads a run file. A complete file must be valid throughout. A file without footer (a killed
/// run, or a `.partial` file) is read up to the last record that can be parsed: every
/// completed chunk is recovered, along with the metadata written at the start, and
/// `complete` is false.
pub fn read_run(path: &Path) -> Result<RunFile> {
    let mut run = RunFile::default();
    let (mut states, mut diagnostics, mut clouds) = (Vec::new(), Vec::new(), 0);
    let (mut last_cloud, mut summary) = (None, None);
    let walked = walk(path, |_, message| {
        match message {
            Logged::State(m) => states.push(m),
            Logged::Diagnostics(m) => diagnostics.push(m),
            Logged::Cloud(m) => {
                last_cloud = Some(m);
                clouds += 1;
            }
            Logged::Summary(m) => {
                if summary.replace(m).is_some() {
                    return Err(RecordError::Invalid {
                        path: path.to_path_buf(),
                        reason: "more than one /summary message".into(),
                    });
                }
            }
        }
        Ok(())
    })?;
    run.metadata = walked.metadata;
    run.complete = walked.complete;
    run.tail_error = walked.tail_error;
    run.states = states;
    run.diagnostics = diagnostics;
    run.clouds = clouds;
    run.last_cloud = last_cloud;
    run.summary = summary;
    Ok(run)
}

/// Every message of a run file in file order with its log time, up to the last complete
/// chunk of an unfinished file (the same reading as [`read_run`]).
pub fn read_messages(path: &Path) -> Result<Vec<(u64, Logged)>> {
    let mut out = Vec::new();
    walk(path, |log_time, message| {
        out.push((log_time, message));
        Ok(())
    })?;
    Ok(out)
}

/// What a walk over a file found besides its messages.
struct Walked {
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    complete: bool,
    tail_error: Option<String>,
}

/// The one reader of run files: visits every message on our topics in file order, decoded,
/// with its log time; collects the metadata. See [`read_run`] for unfinished files.
fn walk(path: &Path, mut on_message: impl FnMut(u64, Logged) -> Result<()>) -> Result<Walked> {
    let buf = std::fs::read(path).map_err(io_err(path))?;
    let complete = mcap::read::footer(&buf).is_ok();
    let reader = if complete {
        LinearReader::new(&buf)
    } else {
        LinearReader::new_with_options(&buf, Options::IgnoreEndMagic.into())
    }
    .map_err(mcap_err(path))?;

    let mut walked = Walked {
        metadata: BTreeMap::new(),
        complete,
        tail_error: None,
    };
    let mut channels: BTreeMap<u16, ChannelInfo> = BTreeMap::new();
    let mut counts: BTreeMap<&'static str, usize> = BTreeMap::new();
    let mut saw_header = false;
    let mut on_record = |record: Record| -> Result<()> {
        match record {
            Record::Channel(c) => add_channel(&mut channels, c),
            Record::Message { header, data } => {
                if let Some(m) = decode(path, &channels, &mut counts, header.channel_id, &data)? {
                    on_message(header.log_time, m)?;
                }
            }
            _ => {}
        }
        Ok(())
    };
    for record in reader {
        let record = match record {
            Ok(r) => r,
            // Only a file that starts as an MCAP file may end in an unreadable tail.
            Err(e) if !complete && saw_header => {
                walked.tail_error = Some(e.to_string());
                break;
            }
            Err(e) => return Err(mcap_err(path)(e)),
        };
        if !saw_header {
            if !matches!(record, Record::Header(_)) {
                return Err(RecordError::Invalid {
                    path: path.to_path_buf(),
                    reason: "the first record is not an MCAP header".into(),
                });
            }
            saw_header = true;
        }
        match record {
            Record::Chunk { header, data } => {
                // A chunk the linear reader yields is whole; damage inside it is an error.
                for inner in ChunkReader::new(header, &data).map_err(mcap_err(path))? {
                    on_record(inner.map_err(mcap_err(path))?)?;
                }
            }
            Record::Metadata(m) => {
                walked.metadata.insert(m.name, m.metadata);
            }
            other => on_record(other)?,
        }
    }
    if !saw_header {
        return Err(RecordError::Invalid {
            path: path.to_path_buf(),
            reason: "empty MCAP file (no header record)".into(),
        });
    }
    Ok(walked)
}

fn add_channel(channels: &mut BTreeMap<u16, ChannelInfo>, c: mcap::records::Channel) {
    channels.insert(
        c.id,
        ChannelInfo {
            topic: c.topic,
            message_encoding: c.message_encoding,
        },
    );
}

/// The message decoded, or None on a topic that is not ours.
fn decode(
    path: &Path,
    channels: &BTreeMap<u16, ChannelInfo>,
    counts: &mut BTreeMap<&'static str, usize>,
    channel_id: u16,
    data: &[u8],
) -> Result<Option<Logged>> {
    let invalid = |reason: String| RecordError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    let channel = channels
        .get(&channel_id)
        .ok_or_else(|| invalid(format!("message on undeclared channel {channel_id}")))?;
    let Some(topic) = [
        TOPIC_STATE,
        TOPIC_PARTICLES,
        TOPIC_DIAGNOSTICS,
        TOPIC_SUMMARY,
    ]
    .into_iter()
    .find(|t| *t == channel.topic) else {
        return Ok(None);
    };
    if channel.message_encoding != "protobuf" {
        return Err(invalid(format!(
            "channel {} has message encoding {:?}, expected \"protobuf\"",
            channel.topic, channel.message_encoding
        )));
    }
    let index = counts.entry(topic).or_default();
    let decode_err = |source| RecordError::Decode {
        path: path.to_path_buf(),
        what: format!("message {index} on {topic}"),
        source,
    };
    let message = match topic {
        TOPIC_STATE => Logged::State(StateCheckpoint::decode(data).map_err(decode_err)?),
        TOPIC_PARTICLES => Logged::Cloud(PointCloud::decode(data).map_err(decode_err)?),
        TOPIC_DIAGNOSTICS => Logged::Diagnostics(Diagnostics::decode(data).map_err(decode_err)?),
        _ => Logged::Summary(Summary::decode(data).map_err(decode_err)?),
    };
    *index += 1;
    Ok(Some(message))
}
