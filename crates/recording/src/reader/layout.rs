//! The layout pass: where a recording's messages are, without keeping them.
//!
//! The data section is walked record by record (the MCAP framing is
//! `opcode u8, length u64, body`). For every Chunk it keeps the file offset,
//! the `message_start_time` of its header and how many Message records it
//! holds; the chunk is decompressed to count them (and to check its CRC and
//! that every log_time lies inside the header's range), and its records are
//! dropped again. A Message record outside any chunk keeps only its replay
//! key and file offset. Channel records are kept (a handful). Memory: one
//! chunk at a time plus a few words per chunk.
//!
//! This pass plays the part of the summary's chunk indexes, built from the
//! data section itself rather than trusted from the summary: file order *is*
//! data-section order, a summary may be absent or omit messages written
//! outside chunks, and counting by decompression needs no optional Message
//! Index records. It also means a corrupt chunk anywhere in the file fails
//! [`super::RecordingReader::open`], before the engine has done a day of
//! work.
//!
//! The top-level framing is read here because the replay needs each chunk's
//! file offset, which the mcap crate's readers do not report; inside a chunk
//! the crate's sans-io [`LinearReader`] decompresses, checks the CRC and
//! frames the records.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::InputError;
use crate::topic::Topic;

/// A chunk larger than this (uncompressed) is refused rather than allocated:
/// writers use chunks of about a megabyte, and a corrupt size field must not
/// exhaust memory.
const MAX_CHUNK_BYTES: u64 = 1 << 30;

/// Bytes of a record's framing: opcode (1) and body length (8).
pub(super) const RECORD_HEADER_BYTES: u64 = 9;

/// A message's topic for the replay order: the format's topics in their
/// order, then every topic the format does not know.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(super) enum TopicRank {
    Known(Topic),
    Unknown,
}

impl TopicRank {
    pub(super) fn of(topic: &str) -> Self {
        Topic::from_name(topic).map_or(TopicRank::Unknown, TopicRank::Known)
    }
}

/// A message's place in the replay. Unique, since the index is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct ReplayKey {
    pub log_time_ns: u64,
    pub topic: TopicRank,
    pub index_in_file: u64,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct ChannelInfo {
    pub topic: String,
    pub message_encoding: String,
}

/// A Chunk record as the layout pass found it.
#[derive(Debug, Clone)]
pub(super) struct ChunkInfo {
    /// File offset of the record's opcode byte.
    pub record_offset: u64,
    /// Body length of the record.
    pub body_len: u64,
    pub message_start_time: u64,
    /// Index in the file of the chunk's first message.
    pub first_index: u64,
    pub message_count: u64,
}

/// A Message record outside any chunk.
#[derive(Debug, Clone, Copy)]
pub(super) struct LooseMessage {
    pub key: ReplayKey,
    pub body_offset: u64,
    pub body_len: u64,
}

#[derive(Debug, Default)]
pub(super) struct Layout {
    pub channels: HashMap<u16, ChannelInfo>,
    pub chunks: Vec<ChunkInfo>,
    pub loose: Vec<LooseMessage>,
    /// The first two `/section` messages in replay order.
    pub sections: Vec<ReplayKey>,
}

pub(super) fn scan_layout(path: &Path, file: &mut BufReader<File>) -> Result<Layout, InputError> {
    let corrupt = |what: String| InputError::file(path, what);
    let io_error = |e: std::io::Error| InputError::file(path, format!("cannot read: {e}"));
    let file_len = file.get_ref().metadata().map_err(io_error)?.len();
    let magic_len = mcap::MAGIC.len() as u64;
    if file_len < 2 * magic_len {
        return Err(corrupt(format!(
            "not an MCAP file: only {file_len} bytes long"
        )));
    }
    let head = read_at(file, 0, magic_len).map_err(io_error)?;
    if head != mcap::MAGIC {
        return Err(corrupt(
            "not an MCAP file: bad magic bytes at the start".to_string(),
        ));
    }
    let tail = read_at(file, file_len - magic_len, magic_len).map_err(io_error)?;
    if tail != mcap::MAGIC {
        return Err(corrupt(
            "truncated MCAP file: no magic bytes at the end (the file is cut short \
             or was not finished)"
                .to_string(),
        ));
    }

    let mut layout = Layout::default();
    let mut message_count: u64 = 0;
    let mut offset = magic_len;
    file.seek(SeekFrom::Start(offset)).map_err(io_error)?;
    loop {
        if file_len - offset < RECORD_HEADER_BYTES {
            return Err(corrupt(format!(
                "truncated MCAP file: the data section ends at byte {offset} without a \
                 DataEnd record"
            )));
        }
        let mut frame = [0u8; RECORD_HEADER_BYTES as usize];
        file.read_exact(&mut frame).map_err(io_error)?;
        let [opcode, l0, l1, l2, l3, l4, l5, l6, l7] = frame;
        let body_len = u64::from_le_bytes([l0, l1, l2, l3, l4, l5, l6, l7]);
        let body_offset = offset + RECORD_HEADER_BYTES;
        let end = body_offset
            .checked_add(body_len)
            .filter(|&end| end <= file_len)
            .ok_or_else(|| {
                corrupt(format!(
                    "truncated or corrupt MCAP file: the record at byte {offset} \
                     (opcode {opcode:#04x}) claims {body_len} bytes, past the end of the file"
                ))
            })?;
        match opcode {
            op::DATA_END | op::FOOTER => break,
            op::CHUNK => {
                // Reading the framing again keeps the chunk record whole for
                // the chunk reader.
                file.seek(SeekFrom::Start(offset)).map_err(io_error)?;
                let record =
                    read_exact_vec(file, RECORD_HEADER_BYTES + body_len).map_err(io_error)?;
                let first_index = message_count;
                let message_start_time = scan_chunk(&record, &mut layout, &mut message_count)
                    .map_err(|e| corrupt(format!("unreadable chunk at byte {offset}: {e}")))?;
                layout.chunks.push(ChunkInfo {
                    record_offset: offset,
                    body_len,
                    message_start_time,
                    first_index,
                    message_count: message_count - first_index,
                });
            }
            op::CHANNEL | op::MESSAGE => {
                let body = read_exact_vec(file, body_len).map_err(io_error)?;
                let record = mcap::parse_record(opcode, &body)
                    .map_err(|e| corrupt(format!("corrupt record at byte {offset}: {e}")))?;
                match record {
                    Record::Channel(channel) => add_channel(&mut layout, channel)
                        .map_err(|e| corrupt(format!("record at byte {offset}: {e}")))?,
                    Record::Message { header, .. } => {
                        let key = message_key(&mut layout, &header, message_count)
                            .map_err(|e| corrupt(format!("record at byte {offset}: {e}")))?;
                        layout.loose.push(LooseMessage {
                            key,
                            body_offset,
                            body_len,
                        });
                        message_count += 1;
                    }
                    _ => {}
                }
            }
            _ => {
                let skip = i64::try_from(body_len)
                    .map_err(|_| corrupt(format!("record at byte {offset} is too long")))?;
                file.seek_relative(skip).map_err(io_error)?;
            }
        }
        offset = end;
    }
    Ok(layout)
}

/// Counts a chunk's messages (checking each against the header's time range)
/// and collects its channels. Returns the chunk's `message_start_time`.
fn scan_chunk(record: &[u8], layout: &mut Layout, message_count: &mut u64) -> Result<u64, String> {
    let header = chunk_header(record).map_err(|e| e.to_string())?;
    if header.uncompressed_size > MAX_CHUNK_BYTES {
        return Err(format!(
            "it claims {} bytes uncompressed (at most {MAX_CHUNK_BYTES} are accepted)",
            header.uncompressed_size
        ));
    }
    let (start, end) = (header.message_start_time, header.message_end_time);
    let mut failure: Option<String> = None;
    for_each_chunk_record(record, &header, |opcode, body| {
        match mcap::parse_record(opcode, body)? {
            Record::Channel(channel) => {
                if let Err(e) = add_channel(layout, channel) {
                    failure.get_or_insert(e);
                }
            }
            Record::Message { header, .. } => {
                if header.log_time < start || header.log_time > end {
                    failure.get_or_insert(format!(
                        "message {} has log_time {} ns, outside the chunk's \
                         message_start_time..message_end_time ({start}..{end})",
                        *message_count, header.log_time
                    ));
                }
                if let Err(e) = message_key(layout, &header, *message_count) {
                    failure.get_or_insert(e);
                }
                *message_count += 1;
            }
            _ => {}
        }
        Ok(())
    })
    .map_err(|e| e.to_string())?;
    match failure {
        Some(e) => Err(e),
        None => Ok(start),
    }
}

fn add_channel(layout: &mut Layout, channel: mcap::records::Channel) -> Result<(), String> {
    let info = ChannelInfo {
        topic: channel.topic,
        message_encoding: channel.message_encoding,
    };
    match layout.channels.get(&channel.id) {
        Some(known) if *known != info => Err(format!(
            "channel {} is defined twice, as `{}` and as `{}`",
            channel.id, known.topic, info.topic
        )),
        Some(_) => Ok(()),
        None => {
            layout.channels.insert(channel.id, info);
            Ok(())
        }
    }
}

/// The replay key of the message with this header and index, remembering the
/// first two `/section` messages.
fn message_key(
    layout: &mut Layout,
    header: &mcap::records::MessageHeader,
    index_in_file: u64,
) -> Result<ReplayKey, String> {
    let channel = layout.channels.get(&header.channel_id).ok_or_else(|| {
        format!(
            "message {index_in_file} (log_time {} ns) refers to channel {}, \
             which no Channel record before it defines",
            header.log_time, header.channel_id
        )
    })?;
    let key = ReplayKey {
        log_time_ns: header.log_time,
        topic: TopicRank::of(&channel.topic),
        index_in_file,
    };
    if key.topic == TopicRank::Known(Topic::Section) {
        layout.sections.push(key);
        layout.sections.sort();
        layout.sections.truncate(2);
    }
    Ok(key)
}

/// The header of a chunk record given whole (framing included).
pub(super) fn chunk_header(record: &[u8]) -> mcap::McapResult<mcap::records::ChunkHeader> {
    let body = record
        .get(RECORD_HEADER_BYTES as usize..)
        .ok_or(mcap::McapError::UnexpectedEof)?;
    match mcap::parse_record(op::CHUNK, body)? {
        Record::Chunk { header, .. } => Ok(header),
        _ => Err(mcap::McapError::BadIndex),
    }
}

/// Calls `f` with the opcode and body of every Channel and Message record
/// inside a chunk record (given whole, framing included), decompressing and
/// checking the CRC with the mcap crate's streaming reader. Other records are
/// not parsed at all.
pub(super) fn for_each_chunk_record(
    record: &[u8],
    header: &mcap::records::ChunkHeader,
    mut f: impl FnMut(u8, &[u8]) -> mcap::McapResult<()>,
) -> mcap::McapResult<()> {
    // No record inside the chunk is longer than the chunk, and no more
    // compressed bytes need buffering than the record holds.
    let limit = header
        .uncompressed_size
        .min(MAX_CHUNK_BYTES)
        .max(record.len() as u64);
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_skip_end_magic(true)
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(usize::try_from(limit).unwrap_or(usize::MAX)),
    );
    let mut rest = record;
    while let Some(event) = reader.next_event() {
        match event? {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(rest.len());
                let (now, later) = rest.split_at(n);
                reader.insert(n).copy_from_slice(now);
                reader.notify_read(n);
                rest = later;
            }
            LinearReadEvent::Record { opcode, data } => {
                if opcode == op::CHANNEL || opcode == op::MESSAGE {
                    f(opcode, data)?;
                }
            }
        }
    }
    Ok(())
}

pub(super) fn read_at(
    file: &mut BufReader<File>,
    offset: u64,
    len: u64,
) -> std::io::Result<Vec<u8>> {
    file.seek(SeekFrom::Start(offset))?;
    read_exact_vec(file, len)
}

fn read_exact_vec(file: &mut BufReader<File>, len: u64) -> std::io::Result<Vec<u8>> {
    let len = usize::try_from(len)
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidData, "record too long"))?;
    let mut buf = vec![0u8; len];
    file.read_exact(&mut buf)?;
    Ok(buf)
}
