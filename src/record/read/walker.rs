//! The walker's record loop: each record framed, checked and decoded in turn.

use super::summary::Sections;
use super::{
    ChannelInfo, FOOTER_RECORD_BYTES, Logged, MAGIC, Problem, Walker, damaged, frame, opcode_name,
};
use crate::proto::foxglove::PointCloud;
use crate::proto::mps::v1::{Diagnostics, StateCheckpoint, Summary};
use crate::record::{TOPIC_DIAGNOSTICS, TOPIC_PARTICLES, TOPIC_STATE, TOPIC_SUMMARY};
use mcap::records::{Record, op};
use prost::Message as _;
use std::borrow::Cow;
use std::io::Read as _;

impl Walker {
    /// Walks the records after the header. `Err` at the first problem; an unfinished file
    /// that ends on a record boundary is `Ok`.
    pub(super) fn records(
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

    /// The messages of a chunk, decoded, or why the chunk is damaged (the text follows "the
    /// chunk at byte N").
    pub(super) fn chunk(&mut self, body: &[u8]) -> std::result::Result<Vec<(u64, Logged)>, String> {
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

    pub(super) fn add_channel(
        &mut self,
        c: mcap::records::Channel,
    ) -> std::result::Result<(), String> {
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
    pub(super) fn message(
        &mut self,
        body: &[u8],
    ) -> std::result::Result<Option<(u64, Logged)>, String> {
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
