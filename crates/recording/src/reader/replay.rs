//! The replay: a file's messages in replay order, chunk by chunk as the time
//! frontier reaches them.
//!
//! Chunks wait in order of `message_start_time`. A chunk is decompressed
//! only when the frontier reaches it (its start time is not later than the
//! earliest message already in hand); its messages, keyed by (log_time,
//! topic, index in file), are put in that order (most writers write them so
//! already) and the chunk is merged with the others in hand as a run: a
//! heap of runs, not of messages. The index of a chunk's k-th message is
//! the number of messages before the chunk plus k. A chunk's messages keep
//! their bytes in one buffer, shared by the messages handed out. Only chunks
//! whose time ranges overlap the frontier are in memory at once.
//!
//! Messages outside chunks (an unchunked file) come in runs (see
//! [`LooseRun`]): the runs wait in order of their first message and are
//! merged, each read front to back from the file when the frontier
//! reaches it, holding one message per run in hand. A file written in time
//! order is one run, read as a stream; memory grows with the number of
//! runs (a file in reverse time order is the worst case: a run a message).

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;
use std::fs::File;
use std::io::BufReader;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::op;

use super::feed::Feed;
use super::layout::{
    chunk_messages, message_header, rank_of, read_at, read_exact_vec, record_frame, Channels,
    ChunkInfo, Layout, LooseRun, ReplayKey, TopicRank, MAX_MESSAGE_BYTES, MESSAGE_HEADER_BYTES,
    RECORD_HEADER_BYTES,
};
use crate::error::{InputError, MessageLocation};

/// A message taken out of its record, waiting for its turn.
#[derive(Debug)]
pub(super) struct PendingMessage {
    pub key: ReplayKey,
    pub channel_id: u16,
    pub sequence: u32,
    pub publish_time_ns: u64,
    pub data: MessageData,
}

/// A message's bytes: a range of its chunk's buffer (or of a buffer of its
/// own), shared rather than copied.
#[derive(Debug, Clone)]
pub(super) struct MessageData {
    buffer: Arc<Vec<u8>>,
    range: Range<usize>,
}

impl MessageData {
    pub(super) fn whole(bytes: Vec<u8>) -> Self {
        let range = 0..bytes.len();
        Self {
            buffer: Arc::new(bytes),
            range,
        }
    }

    /// `range` of a buffer shared with other messages (a chunk's).
    pub(super) fn shared(buffer: &Arc<Vec<u8>>, range: Range<usize>) -> Self {
        Self {
            buffer: Arc::clone(buffer),
            range,
        }
    }

    pub(super) fn as_slice(&self) -> &[u8] {
        &self.buffer[self.range.clone()]
    }
}

/// A run in a heap of runs, by the key of its next message: the heap's
/// top is the run whose next message goes first.
#[derive(Debug)]
struct Next<T> {
    key: ReplayKey,
    run: T,
}

impl<T> PartialEq for Next<T> {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key
    }
}
impl<T> Eq for Next<T> {}
impl<T> PartialOrd for Next<T> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl<T> Ord for Next<T> {
    /// Reversed: `BinaryHeap` keeps its greatest on top.
    fn cmp(&self, other: &Self) -> Ordering {
        other.key.cmp(&self.key)
    }
}

/// The messages of a file in replay order (see the module documentation).
pub(super) struct ReplayQueue {
    path: PathBuf,
    file: BufReader<File>,
    channels: Channels,
    /// Chunks not yet decompressed, the next one last.
    waiting_chunks: Vec<ChunkInfo>,
    /// Runs of messages outside chunks not yet started, the next one last.
    waiting_runs: Vec<LooseRun>,
    /// Runs started: each with its next message in hand.
    active_runs: BinaryHeap<Next<RunHead>>,
    /// Decompressed chunks with messages not yet replayed.
    ready: BinaryHeap<Next<ChunkRun>>,
    /// Whether messages on topics tortwin does not read keep their data
    /// (outside chunks they are otherwise not read at all).
    keep_unknown: bool,
    /// The layout pass, when it runs beside the replay: the chunks come
    /// from it (module `feed`).
    feed: Option<Feed>,
}

/// A decompressed chunk: its messages in replay order, the next one at
/// `next` (there is always one: a chunk leaves the heap with its last).
#[derive(Debug)]
struct ChunkRun {
    buffer: Arc<Vec<u8>>,
    messages: Vec<ChunkMessage>,
    next: usize,
}

/// A message of a [`ChunkRun`]: its bytes are `range` of the chunk's buffer.
#[derive(Debug)]
struct ChunkMessage {
    key: ReplayKey,
    channel_id: u16,
    sequence: u32,
    publish_time_ns: u64,
    range: Range<usize>,
}

impl ChunkRun {
    fn head(&self) -> ReplayKey {
        self.messages[self.next].key
    }

    /// Hands out the next message; `false` once it was the last.
    fn take(&mut self) -> (PendingMessage, bool) {
        let m = &self.messages[self.next];
        let message = PendingMessage {
            key: m.key,
            channel_id: m.channel_id,
            sequence: m.sequence,
            publish_time_ns: m.publish_time_ns,
            data: MessageData {
                buffer: Arc::clone(&self.buffer),
                range: m.range.clone(),
            },
        };
        self.next += 1;
        (message, self.next < self.messages.len())
    }
}

/// A started run: its next message, and where the one after it is.
#[derive(Debug)]
struct RunHead {
    message: PendingMessage,
    /// File offset of the record after `message`'s.
    next_offset: u64,
    /// Messages of the run after `message`.
    remaining: u64,
}

impl ReplayQueue {
    pub(super) fn new(
        path: &Path,
        file: BufReader<File>,
        channels: Channels,
        chunks: Vec<ChunkInfo>,
        loose: Vec<LooseRun>,
        keep_unknown: bool,
    ) -> Self {
        let waiting_chunks =
            in_waiting_order(chunks.into_iter().filter(|c| c.message_count > 0).collect());
        let mut waiting_runs = loose;
        waiting_runs.sort_by_key(|r| Reverse(r.first));
        Self {
            path: path.to_path_buf(),
            file,
            channels,
            waiting_chunks,
            waiting_runs,
            active_runs: BinaryHeap::new(),
            ready: BinaryHeap::new(),
            keep_unknown,
            feed: None,
        }
    }

    /// The replay of a file whose layout pass runs beside it (`feed`);
    /// `chunks` as the file's framing gave them
    /// ([`super::layout::chunk_heads`]).
    pub(super) fn beside(
        path: &Path,
        file: BufReader<File>,
        chunks: Vec<ChunkInfo>,
        feed: Feed,
    ) -> Self {
        let mut queue = Self::new(
            path,
            file,
            Channels::default(),
            Vec::new(),
            Vec::new(),
            false,
        );
        // Their message counts are the pass's to tell: none is left out.
        queue.waiting_chunks = in_waiting_order(chunks);
        queue.feed = Some(feed);
        queue
    }

    /// With the layout pass beside the replay: waits for it to end and
    /// returns its layout (its chunks without messages), or the first
    /// thing it found wrong with the file. `None` for a file laid out
    /// before the replay.
    pub(super) fn finish_layout(&mut self) -> Option<Result<&Layout, InputError>> {
        let feed = self.feed.as_mut()?;
        Some(feed.finish(&mut self.channels))
    }

    fn error(&self, location: MessageLocation, message: String) -> InputError {
        InputError::at(&self.path, location, message)
    }

    fn corrupt(&self, what: String) -> InputError {
        InputError::file(&self.path, what)
    }

    /// The earliest message in hand.
    fn in_hand(&self) -> Option<ReplayKey> {
        let chunked = self.ready.peek().map(|c| c.key);
        let loose = self.active_runs.peek().map(|r| r.key);
        match (chunked, loose) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The next message in replay order, decompressing chunks and starting
    /// runs as the frontier reaches them.
    pub(super) fn next_message(&mut self) -> Result<Option<PendingMessage>, InputError> {
        loop {
            let in_hand = self.in_hand();
            // A chunk whose first log_time is not later than the earliest
            // message in hand may hold a message that goes before it.
            let chunk_due = self
                .waiting_chunks
                .last()
                .is_some_and(|c| in_hand.is_none_or(|key| c.message_start_time <= key.log_time_ns));
            if chunk_due {
                if let Some(chunk) = self.waiting_chunks.pop() {
                    self.load_chunk(chunk)?;
                }
                continue;
            }
            // A run whose first message goes before the earliest in hand.
            let run_due = self
                .waiting_runs
                .last()
                .is_some_and(|r| in_hand.is_none_or(|key| r.first < key));
            if run_due {
                if let Some(run) = self.waiting_runs.pop() {
                    let head = self.read_run(
                        run.record_offset,
                        run.first.index_in_file,
                        run.message_count,
                    )?;
                    self.active_runs.push(Next {
                        key: head.message.key,
                        run: head,
                    });
                }
                continue;
            }
            break;
        }
        let take_loose = match (self.ready.peek(), self.active_runs.peek()) {
            (Some(c), Some(r)) => r.key < c.key,
            (None, Some(_)) => true,
            (_, None) => false,
        };
        if !take_loose {
            let Some(mut chunk) = self.ready.peek_mut() else {
                return Ok(None);
            };
            let (message, more) = chunk.run.take();
            if more {
                // The heap puts the chunk back in place when `chunk` drops.
                chunk.key = chunk.run.head();
            } else {
                std::collections::binary_heap::PeekMut::pop(chunk);
            }
            return Ok(Some(message));
        }
        let Some(Next { run: head, .. }) = self.active_runs.pop() else {
            return Ok(None);
        };
        if head.remaining > 0 {
            let next = self.read_run(
                head.next_offset,
                head.message.key.index_in_file + 1,
                head.remaining,
            )?;
            self.active_runs.push(Next {
                key: next.message.key,
                run: next,
            });
        }
        Ok(Some(head.message))
    }

    fn load_chunk(&mut self, chunk: ChunkInfo) -> Result<(), InputError> {
        let chunk = match &mut self.feed {
            None => chunk,
            Some(feed) => {
                let added = feed.take(chunk.number, &mut self.channels)?;
                // The same bytes read twice give the same chunk.
                let same = |a: &ChunkInfo| {
                    (a.record_offset, a.body_len, a.message_start_time)
                        == (
                            chunk.record_offset,
                            chunk.body_len,
                            chunk.message_start_time,
                        )
                };
                match added {
                    Some(added) if same(&added) => added,
                    _ => {
                        return Err(self.corrupt(format!(
                            "the chunk at byte {} changed while it was read",
                            chunk.record_offset
                        )))
                    }
                }
            }
        };
        let kept = match chunk.kept {
            Some(kept) => kept,
            None => {
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
                let (channels, keep_unknown) = (&self.channels, self.keep_unknown);
                let keep =
                    |channel: u16| keep_unknown || rank_of(channels, channel) != TopicRank::Unknown;
                chunk_messages(&record, keep).map_err(|e| {
                    self.corrupt(format!(
                        "unreadable chunk at byte {}: {e}",
                        chunk.record_offset
                    ))
                })?
            }
        };
        if kept.messages.len() as u64 != chunk.message_count {
            return Err(self.corrupt(format!(
                "the chunk at byte {} changed while it was read ({} messages, then {})",
                chunk.record_offset,
                chunk.message_count,
                kept.messages.len()
            )));
        }
        let channels = &self.channels;
        let mut messages: Vec<ChunkMessage> = (chunk.first_index..)
            .zip(kept.messages)
            .map(|(index_in_file, (header, range))| ChunkMessage {
                key: ReplayKey {
                    log_time_ns: header.log_time,
                    topic: rank_of(channels, header.channel_id),
                    index_in_file,
                },
                channel_id: header.channel_id,
                sequence: header.sequence,
                publish_time_ns: header.publish_time,
                range,
            })
            .collect();
        if messages.is_empty() {
            return Ok(());
        }
        // Keys are unique (the index is): any sort gives the one order.
        if !messages.is_sorted_by_key(|m| m.key) {
            messages.sort_unstable_by_key(|m| m.key);
        }
        let run = ChunkRun {
            buffer: Arc::new(kept.bytes),
            messages,
            next: 0,
        };
        self.ready.push(Next {
            key: run.head(),
            run,
        });
        Ok(())
    }

    /// The message of a run at or after `offset` (records that are not
    /// messages skipped), with index `index`; `count` messages of the run
    /// are left, this one included.
    fn read_run(&mut self, offset: u64, index: u64, count: u64) -> Result<RunHead, InputError> {
        let mut offset = offset;
        loop {
            let frame = read_at(&mut self.file, offset, RECORD_HEADER_BYTES).map_err(|e| {
                self.corrupt(format!("cannot read the record at byte {offset}: {e}"))
            })?;
            let (opcode, body_len) = record_frame(&frame);
            let next_offset = offset
                .saturating_add(RECORD_HEADER_BYTES)
                .saturating_add(body_len);
            if opcode != op::MESSAGE {
                offset = next_offset;
                continue;
            }
            let path = &self.path;
            let changed = || {
                InputError::file(
                    path,
                    format!("the message record at byte {offset} changed while it was read"),
                )
            };
            let head =
                read_exact_vec(&mut self.file, MESSAGE_HEADER_BYTES).map_err(|_| changed())?;
            let header = message_header(&head);
            let topic = rank_of(&self.channels, header.channel_id);
            let data_len = body_len
                .checked_sub(MESSAGE_HEADER_BYTES)
                .ok_or_else(changed)?;
            let data = if topic == TopicRank::Unknown && !self.keep_unknown {
                Vec::new()
            } else if topic != TopicRank::Unknown && data_len > MAX_MESSAGE_BYTES {
                // The layout pass refused such a message: the file changed.
                return Err(changed());
            } else {
                read_exact_vec(&mut self.file, data_len).map_err(|_| changed())?
            };
            return Ok(RunHead {
                message: PendingMessage {
                    key: ReplayKey {
                        log_time_ns: header.log_time,
                        topic,
                        index_in_file: index,
                    },
                    channel_id: header.channel_id,
                    sequence: header.sequence,
                    publish_time_ns: header.publish_time,
                    data: MessageData::whole(data),
                },
                next_offset,
                remaining: count - 1,
            });
        }
    }

    /// Where the message is, for an error about it.
    pub(super) fn location(&self, message: &PendingMessage) -> MessageLocation {
        location(&self.channels, message)
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

    pub(super) fn channels(&self) -> &Channels {
        &self.channels
    }

    pub(super) fn path(&self) -> &Path {
        &self.path
    }
}

/// Chunks in the order they wait in: by `message_start_time`, equal ones
/// in file order, the next one last.
fn in_waiting_order(mut chunks: Vec<ChunkInfo>) -> Vec<ChunkInfo> {
    chunks.sort_by_key(|c| Reverse((c.message_start_time, c.number)));
    chunks
}

/// Where a message is, for an error about it: its channel's topic (none if
/// the channel is unknown), log_time and index in the file.
pub(super) fn location(channels: &Channels, message: &PendingMessage) -> MessageLocation {
    MessageLocation {
        topic: channels
            .get(&message.channel_id)
            .map_or_else(String::new, |c| c.topic.clone()),
        log_time_ns: message.key.log_time_ns,
        index_in_file: message.key.index_in_file,
    }
}
