//! A finished file's summary section and footer, checked against its data section.

use super::{Problem, RECORD_PREFIX_BYTES, Walker, damaged};
use crate::record::META_OUTCOME;
use mcap::records::Record;

/// Where the data and summary sections were found to end.
#[derive(Default)]
pub(super) struct Sections {
    /// Offset just past the data end record (the start of the summary section).
    pub(super) summary_start: Option<usize>,
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
    /// A finished file's summary section and footer against what the data section holds;
    /// then the `/summary` message and `outcome` metadata a finished run ends with.
    pub(super) fn check_summary(
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
}

impl Sections {
    pub(super) fn add(&mut self, record: Record, at: usize) {
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
