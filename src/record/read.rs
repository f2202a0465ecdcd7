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

/// Reads a run file. A complete file must be valid throughout. A file without footer (a killed
/// run, or a `.partial` file) is read up to the last record that can be parsed: every
/// completed chunk is recovered, along with the metadata written at the start, and
/// `complete` is false.
pub fn read_run(path: &Path) -> Result<RunFile> {
    let buf = std::fs::read(path).map_err(io_err(path))?;
    let complete = mcap::read::footer(&buf).is_ok();
    let reader = if complete {
        LinearReader::new(&buf)
    } else {
        LinearReader::new_with_options(&buf, Options::IgnoreEndMagic.into())
    }
    .map_err(mcap_err(path))?;

    let mut run = RunFile {
        complete,
        ..RunFile::default()
    };
    let mut channels: BTreeMap<u16, ChannelInfo> = BTreeMap::new();
    let mut saw_header = false;
    for record in reader {
        let record = match record {
            Ok(r) => r,
            // Only a file that starts as an MCAP file may end in an unreadable tail.
            Err(e) if !complete && saw_header => {
                run.tail_error = Some(e.to_string());
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
                    match inner.map_err(mcap_err(path))? {
                        Record::Channel(c) => {
                            add_channel(&mut channels, c);
                        }
                        Record::Message { header, data } => {
                            on_message(path, &channels, &mut run, header.channel_id, &data)?
                        }
                        _ => {}
                    }
                }
            }
            Record::Channel(c) => add_channel(&mut channels, c),
            Record::Message { header, data } => {
                on_message(path, &channels, &mut run, header.channel_id, &data)?
            }
            Record::Metadata(m) => {
                run.metadata.insert(m.name, m.metadata);
            }
            _ => {}
        }
    }
    if !saw_header {
        return Err(RecordError::Invalid {
            path: path.to_path_buf(),
            reason: "empty MCAP file (no header record)".into(),
        });
    }
    Ok(run)
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

fn on_message(
    path: &Path,
    channels: &BTreeMap<u16, ChannelInfo>,
    run: &mut RunFile,
    channel_id: u16,
    data: &[u8],
) -> Result<()> {
    let invalid = |reason: String| RecordError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    let channel = channels
        .get(&channel_id)
        .ok_or_else(|| invalid(format!("message on undeclared channel {channel_id}")))?;
    let known = [
        TOPIC_STATE,
        TOPIC_PARTICLES,
        TOPIC_DIAGNOSTICS,
        TOPIC_SUMMARY,
    ];
    if !known.contains(&channel.topic.as_str()) {
        return Ok(());
    }
    if channel.message_encoding != "protobuf" {
        return Err(invalid(format!(
            "channel {} has message encoding {:?}, expected \"protobuf\"",
            channel.topic, channel.message_encoding
        )));
    }
    let decode_err = |source| RecordError::Decode {
        path: path.to_path_buf(),
        what: format!(
            "message {} on {}",
            run_count(run, &channel.topic),
            channel.topic
        ),
        source,
    };
    match channel.topic.as_str() {
        TOPIC_STATE => run
            .states
            .push(StateCheckpoint::decode(data).map_err(decode_err)?),
        TOPIC_PARTICLES => {
            run.last_cloud = Some(PointCloud::decode(data).map_err(decode_err)?);
            run.clouds += 1;
        }
        TOPIC_DIAGNOSTICS => run
            .diagnostics
            .push(Diagnostics::decode(data).map_err(decode_err)?),
        TOPIC_SUMMARY => {
            if run.summary.is_some() {
                return Err(invalid("more than one /summary message".into()));
            }
            run.summary = Some(Summary::decode(data).map_err(decode_err)?);
        }
        _ => unreachable!("filtered above"),
    }
    Ok(())
}

/// Index (0-based) of the next message on `topic`, for error messages.
fn run_count(run: &RunFile, topic: &str) -> usize {
    match topic {
        TOPIC_STATE => run.states.len(),
        TOPIC_PARTICLES => run.clouds,
        TOPIC_DIAGNOSTICS => run.diagnostics.len(),
        _ => usize::from(run.summary.is_some()),
    }
}
