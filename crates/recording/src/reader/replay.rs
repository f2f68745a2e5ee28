//! The replay: a file's messages in replay order, chunk by chunk as the time
//! frontier reaches them.
//!
//! Chunks wait in order of `message_start_time`. A chunk is decompressed
//! only when the frontier reaches it (its start time is not later than the
//! earliest message already in hand), and its messages go into a heap keyed
//! by (log_time, topic, index in file); the index of a chunk's k-th message
//! is the number of messages before the chunk plus k. Only chunks whose time
//! ranges overlap the frontier are in memory at once.
//!
//! Messages outside chunks (an unchunked file) are the fallback: their keys
//! (log_time, topic, index, offset) are sorted in memory and each body is
//! read back by offset when its turn comes. That list grows with the number
//! of such messages, i.e. with the recording (about 40 bytes a message); the
//! engine-facing behaviour is the same.

use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, HashMap};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use mcap::records::{op, Record};

use super::layout::{
    chunk_header, for_each_chunk_record, read_at, ChannelInfo, ChunkInfo, LooseMessage, ReplayKey,
    TopicRank, RECORD_HEADER_BYTES,
};
use crate::error::{InputError, MessageLocation};

/// A message taken out of its record, waiting for its turn.
#[derive(Debug)]
pub(super) struct PendingMessage {
    pub key: ReplayKey,
    pub channel_id: u16,
    pub data: Vec<u8>,
}

impl PartialEq for PendingMessage {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key
    }
}
impl Eq for PendingMessage {}
impl PartialOrd for PendingMessage {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for PendingMessage {
    fn cmp(&self, other: &Self) -> Ordering {
        self.key.cmp(&other.key)
    }
}

/// The messages of a file in replay order (see the module documentation).
pub(super) struct ReplayQueue {
    path: PathBuf,
    file: BufReader<File>,
    channels: HashMap<u16, ChannelInfo>,
    /// Chunks not yet decompressed, the next one last.
    waiting_chunks: Vec<ChunkInfo>,
    /// Messages outside chunks not yet replayed, the next one last.
    waiting_loose: Vec<LooseMessage>,
    /// Messages of decompressed chunks not yet replayed.
    ready: BinaryHeap<Reverse<PendingMessage>>,
}

impl ReplayQueue {
    pub(super) fn new(
        path: &Path,
        file: BufReader<File>,
        channels: HashMap<u16, ChannelInfo>,
        chunks: Vec<ChunkInfo>,
        loose: Vec<LooseMessage>,
    ) -> Self {
        let mut waiting_chunks: Vec<ChunkInfo> =
            chunks.into_iter().filter(|c| c.message_count > 0).collect();
        // Next chunk last; equal start times in file order.
        waiting_chunks.sort_by_key(|c| Reverse((c.message_start_time, c.first_index)));
        let mut waiting_loose = loose;
        waiting_loose.sort_by_key(|m| Reverse(m.key));
        Self {
            path: path.to_path_buf(),
            file,
            channels,
            waiting_chunks,
            waiting_loose,
            ready: BinaryHeap::new(),
        }
    }

    fn error(&self, location: MessageLocation, message: String) -> InputError {
        InputError::at(&self.path, location, message)
    }

    fn corrupt(&self, what: String) -> InputError {
        InputError::file(&self.path, what)
    }

    /// The next message in replay order, decompressing chunks as the frontier
    /// reaches them.
    pub(super) fn next_message(&mut self) -> Result<Option<PendingMessage>, InputError> {
        loop {
            let in_hand = match (self.ready.peek(), self.waiting_loose.last()) {
                (Some(Reverse(m)), Some(l)) => Some(m.key.min(l.key)),
                (Some(Reverse(m)), None) => Some(m.key),
                (None, Some(l)) => Some(l.key),
                (None, None) => None,
            };
            // A chunk whose first log_time is not later than the earliest
            // message in hand may hold a message that goes before it.
            let load = match (self.waiting_chunks.last(), in_hand) {
                (Some(chunk), Some(key)) => chunk.message_start_time <= key.log_time_ns,
                (Some(_), None) => true,
                (None, _) => false,
            };
            if !load {
                break;
            }
            if let Some(chunk) = self.waiting_chunks.pop() {
                self.load_chunk(&chunk)?;
            }
        }
        let take_loose = match (self.ready.peek(), self.waiting_loose.last()) {
            (Some(Reverse(m)), Some(l)) => l.key < m.key,
            (None, Some(_)) => true,
            (_, None) => false,
        };
        if take_loose {
            let Some(loose) = self.waiting_loose.pop() else {
                return Ok(None);
            };
            return self.read_loose(loose).map(Some);
        }
        Ok(self.ready.pop().map(|Reverse(m)| m))
    }

    fn load_chunk(&mut self, chunk: &ChunkInfo) -> Result<(), InputError> {
        let record = read_at(
            &mut self.file,
            chunk.record_offset,
            RECORD_HEADER_BYTES + chunk.body_len,
        )
        .map_err(|e| {
            self.corrupt(format!(
                "cannot read the chunk at byte {}: {e}",
                chunk.record_offset
            ))
        })?;
        let mut next_index = chunk.first_index;
        let mut messages = Vec::new();
        let channels = &self.channels;
        let counted = chunk_header(&record).and_then(|header| {
            for_each_chunk_record(&record, &header, |opcode, body| {
                let Record::Message { header, data } = mcap::parse_record(opcode, body)? else {
                    return Ok(());
                };
                let topic = channels
                    .get(&header.channel_id)
                    .map_or(TopicRank::Unknown, |c| TopicRank::of(&c.topic));
                messages.push(PendingMessage {
                    key: ReplayKey {
                        log_time_ns: header.log_time,
                        topic,
                        index_in_file: next_index,
                    },
                    channel_id: header.channel_id,
                    data: data.into_owned(),
                });
                next_index += 1;
                Ok(())
            })
        });
        counted.map_err(|e| {
            self.corrupt(format!(
                "unreadable chunk at byte {}: {e}",
                chunk.record_offset
            ))
        })?;
        if next_index - chunk.first_index != chunk.message_count {
            return Err(self.corrupt(format!(
                "the chunk at byte {} changed while it was read ({} messages, then {})",
                chunk.record_offset,
                chunk.message_count,
                next_index - chunk.first_index
            )));
        }
        self.ready.extend(messages.into_iter().map(Reverse));
        Ok(())
    }

    fn read_loose(&mut self, loose: LooseMessage) -> Result<PendingMessage, InputError> {
        let body = read_at(&mut self.file, loose.body_offset, loose.body_len).map_err(|e| {
            self.corrupt(format!(
                "cannot read the message at byte {}: {e}",
                loose.body_offset
            ))
        })?;
        match mcap::parse_record(op::MESSAGE, &body) {
            Ok(Record::Message { header, data }) => Ok(PendingMessage {
                key: loose.key,
                channel_id: header.channel_id,
                data: data.into_owned(),
            }),
            Ok(_) => Err(self.corrupt(format!(
                "the message at byte {} changed while it was read",
                loose.body_offset
            ))),
            Err(e) => Err(self.corrupt(format!(
                "corrupt message record at byte {}: {e}",
                loose.body_offset
            ))),
        }
    }

    /// Where the message is, for an error about it.
    pub(super) fn location(&self, message: &PendingMessage) -> MessageLocation {
        MessageLocation {
            // The layout pass checked that every message's channel is defined.
            topic: self
                .channels
                .get(&message.channel_id)
                .map_or_else(String::new, |c| c.topic.clone()),
            log_time_ns: message.key.log_time_ns,
            index_in_file: message.key.index_in_file,
        }
    }

    /// Checks that a known topic's message is JSON encoded.
    pub(super) fn check_json(&self, message: &PendingMessage) -> Result<(), InputError> {
        match self.channels.get(&message.channel_id) {
            Some(channel) if channel.message_encoding == "json" => Ok(()),
            Some(channel) => Err(self.error(
                self.location(message),
                format!(
                    "message encoding is `{}`; this topic must be `json`",
                    channel.message_encoding
                ),
            )),
            None => Err(self.corrupt(format!(
                "message {} refers to undefined channel {}",
                message.key.index_in_file, message.channel_id
            ))),
        }
    }

    pub(super) fn path(&self) -> &Path {
        &self.path
    }
}
