//! The layout pass: where a recording's messages are, without keeping them.
//!
//! The data section is walked record by record (the MCAP framing is
//! `opcode u8, length u64, body`). For every Chunk it keeps the file offset,
//! the `message_start_time` of its header and how many Message records it
//! holds; the chunk is decompressed to count them (and to check its CRC and
//! that every log_time lies inside the header's range), and its records are
//! dropped again. A Message record outside any chunk keeps only its replay
//! key and file offset. Channel records are kept (a handful). Chunks are
//! decompressed on rayon's threads as they are read, up to four ahead, and
//! added in file order; beside the replay (module `feed`), one at a time on
//! the pass's own thread, each handed over as it is added.
//! Memory: up to five compressed chunk records (about 32 MiB at most) with
//! their messages' headers, one decompressed chunk per thread, plus a few
//! words per chunk. The first chunks' messages,
//! up to [`KEPT_CHUNK_BYTES`], are kept for the replay, which would
//! otherwise decompress them again straight away (all of a short recording).
//!
//! This pass plays the part of the summary's chunk indexes, built from the
//! data section itself rather than trusted from the summary: file order *is*
//! data-section order, a summary may be absent or omit messages written
//! outside chunks, and counting by decompression needs no optional Message
//! Index records. It also means a corrupt chunk anywhere in the file fails
//! [`super::RecordingReader::open`], before the engine has done a day of
//! work (beside the replay, before the chunk is replayed, and it is the
//! error the replay reports: module `feed`).
//!
//! The top-level framing is read here because the replay needs each chunk's
//! file offset, which the mcap crate's readers do not report; inside a chunk
//! the crate's sans-io [`LinearReader`] decompresses, checks the CRC and
//! frames the records.

use std::collections::{HashMap, VecDeque};
use std::fs::File;
use std::hash::{BuildHasherDefault, Hasher};
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::Path;
use std::sync::mpsc::{Receiver, Sender};
use std::time::{Duration, Instant};

use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::record;
use crate::error::InputError;
use crate::topic::Topic;

/// A chunk larger than this (uncompressed) is refused rather than allocated:
/// writers use chunks of about a megabyte (tortwin's own: 8 MiB), and a
/// corrupt size field must not exhaust memory. Documented in
/// docs/spec/recording-format.md "Limits".
pub const MAX_CHUNK_BYTES: u64 = 256 << 20;

/// The layout pass keeps the messages of the file's first chunks, while
/// their uncompressed sizes add up to at most this, for the replay.
pub(super) const KEPT_CHUNK_BYTES: u64 = 16 << 20;

/// A message of the format (a topic tortwin reads) larger than this is
/// refused before it is parsed: a `/train/passage` of 10 000 axles is about
/// 2.5 MB. Messages of other topics are skipped whatever their size.
pub const MAX_MESSAGE_BYTES: u64 = 16 << 20;

/// A Channel (or other small) record larger than this is refused.
pub(super) const MAX_SMALL_RECORD_BYTES: u64 = 16 << 20;

/// Bytes of a Message record's header: channel_id u16, sequence u32,
/// log_time u64, publish_time u64.
pub(super) const MESSAGE_HEADER_BYTES: u64 = 22;

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
    /// The topic's place in the replay order, found once for the channel
    /// rather than by name for each of its messages.
    pub rank: TopicRank,
}

/// The channels of a file by id. Looked up for every message (its replay
/// key, its encoding), so hashed by a multiplication rather than SipHash:
/// the ids are the file's own, and a file that chose colliding ones would
/// slow only its own reading of a handful of channels.
pub(super) type Channels = HashMap<u16, ChannelInfo, BuildHasherDefault<ChannelIdHasher>>;

/// The replay rank of a message on channel `id`: its channel's, or
/// [`TopicRank::Unknown`] for a channel the file never defined.
pub(super) fn rank_of(channels: &Channels, id: u16) -> TopicRank {
    channels.get(&id).map_or(TopicRank::Unknown, |c| c.rank)
}

/// [`Channels`]' hasher: Fibonacci hashing of the 16-bit id.
#[derive(Debug, Default)]
pub(super) struct ChannelIdHasher(u64);

impl Hasher for ChannelIdHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u16(&mut self, id: u16) {
        self.write_u64(u64::from(id));
    }

    fn write_u64(&mut self, value: u64) {
        self.0 = (self.0.rotate_left(5) ^ value).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
}

/// A Chunk record as the layout pass found it.
#[derive(Debug, Clone)]
pub(super) struct ChunkInfo {
    /// The chunk's place among the file's chunks, from 0.
    pub number: u64,
    /// File offset of the record's opcode byte.
    pub record_offset: u64,
    /// Body length of the record.
    pub body_len: u64,
    pub message_start_time: u64,
    /// Index in the file of the chunk's first message.
    pub first_index: u64,
    pub message_count: u64,
    /// The chunk's messages, if the layout pass kept them.
    pub kept: Option<ChunkMessages>,
}

/// A chunk's messages in file order: each one's header and the range of
/// `bytes` its data is. `bytes` is the chunk's records as decompressed
/// (the messages' data where they lie, not copied) when the chunk was read
/// whole, else the messages' data copied one after another.
#[derive(Debug, Clone, Default)]
pub(super) struct ChunkMessages {
    pub bytes: Vec<u8>,
    pub messages: Vec<(mcap::records::MessageHeader, Range<usize>)>,
    /// Bytes to reserve at the first copy.
    reserve: usize,
}

impl ChunkMessages {
    /// Room for a chunk's messages: their bytes are most of the chunk.
    fn with_capacity(header: &mcap::records::ChunkHeader) -> Self {
        let size = header.uncompressed_size.min(MAX_CHUNK_BYTES);
        Self {
            bytes: Vec::new(),
            messages: Vec::with_capacity(expected_messages(header)),
            reserve: usize::try_from(size).unwrap_or(0),
        }
    }

    /// A message whose `data` ends the record body `body`; `at` is where
    /// that body lies in the chunk's decompressed records when they are
    /// kept whole (then nothing is copied), `None` when they are not.
    fn push(
        &mut self,
        header: mcap::records::MessageHeader,
        body: &[u8],
        data: &[u8],
        at: Option<usize>,
    ) {
        let range = match at {
            Some(at) => {
                let start = at + (body.len() - data.len());
                start..start + data.len()
            }
            None => {
                if self.bytes.capacity() == 0 {
                    self.bytes.reserve(self.reserve);
                }
                let start = self.bytes.len();
                self.bytes.extend_from_slice(data);
                start..self.bytes.len()
            }
        };
        self.messages.push((header, range));
    }

    /// Takes the chunk's decompressed records, into which the messages'
    /// ranges point, if it was read whole. When the messages kept are less
    /// than half of them (a chunk mostly of topics tortwin does not read),
    /// their data are copied out instead, so that a chunk held for its
    /// messages holds no more than twice their bytes.
    fn adopt(&mut self, records: Option<Vec<u8>>) {
        let Some(records) = records else {
            return;
        };
        let kept: usize = self.messages.iter().map(|(_, r)| r.len()).sum();
        if 2 * kept >= records.len() {
            self.bytes = records;
            return;
        }
        let mut bytes = Vec::with_capacity(kept);
        for (_, range) in &mut self.messages {
            let start = bytes.len();
            bytes.extend_from_slice(&records[range.clone()]);
            *range = start..bytes.len();
        }
        self.bytes = bytes;
    }
}

/// Room for the messages of a chunk, so that the lists of them are not
/// copied as they grow (a 1 MiB chunk of a recording holds about 5 000):
/// one per 128 bytes uncompressed, about the size of a measurement's record;
/// a chunk of smaller messages grows its lists as before.
fn expected_messages(header: &mcap::records::ChunkHeader) -> usize {
    usize::try_from(header.uncompressed_size.min(MAX_CHUNK_BYTES) / 128).unwrap_or(0)
}

/// Messages outside chunks that follow one another in the file (with no
/// chunk between them) and are already in replay order: the replay reads
/// such a run front to back, so an unchunked file written in time order
/// is one run, read as a stream.
#[derive(Debug, Clone, Copy)]
pub(super) struct LooseRun {
    pub first: ReplayKey,
    pub last: ReplayKey,
    /// File offset of the first message's record (opcode byte).
    pub record_offset: u64,
    pub message_count: u64,
}

#[derive(Debug, Default)]
pub(super) struct Layout {
    pub channels: Channels,
    pub chunks: Vec<ChunkInfo>,
    /// Runs of messages outside chunks, in file order.
    pub loose: Vec<LooseRun>,
    /// The first two `/section` messages in replay order.
    pub sections: Vec<ReplayKey>,
    /// The first two `/line` messages in replay order.
    pub lines: Vec<ReplayKey>,
}

pub(super) fn scan_layout(path: &Path, file: &mut BufReader<File>) -> Result<Layout, InputError> {
    scan(path, file, None)
}

/// The layout pass, handing each chunk to `feed` as it is added
/// ([`super::feed`]): the replay takes them from there while the pass goes
/// on. The chunks in the layout returned keep no messages.
pub(super) fn scan_feeding(
    path: &Path,
    file: &mut BufReader<File>,
    feed: Sender<Fed>,
) -> Result<Layout, InputError> {
    scan(path, file, Some(feed))
}

fn scan(
    path: &Path,
    file: &mut BufReader<File>,
    feed: Option<Sender<Fed>>,
) -> Result<Layout, InputError> {
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
    let mut chunks = PendingChunks::new(feed);
    let walked = walk(path, file, file_len, &mut layout, &mut chunks);
    // A chunk earlier in the file than the record that failed fails first.
    chunks.settle(path, &mut layout)?;
    walked?;
    Ok(layout)
}

/// Chunk records read but not yet scanned: each is decompressed and checked
/// on rayon's threads as soon as it is read, while the next records are
/// read, and what they hold is added to the layout in file order
/// ([`PendingChunks::settle`]) before any record after them, so the layout,
/// the message numbers and the first error are those of a scan one record
/// at a time. (Read a few at a time and then decompressed together, the
/// chunks waited for the reading and a batch for its slowest chunk: on a
/// 3-day recording's eight 1 MiB chunks a third of the two cores idled.)
struct PendingChunks {
    /// The chunks read and not yet added, in file order.
    pending: VecDeque<Pending>,
    /// The scans, as they finish.
    done: (Sender<Scan>, Receiver<Scan>),
    /// Chunks read so far (the next one's number).
    read: u64,
    message_count: u64,
    /// Uncompressed bytes still to keep for the replay; 0 from the first
    /// chunk that does not fit on.
    keep_left: u64,
    /// Where each chunk goes as it is added, when the replay runs beside
    /// the pass.
    feed: Option<Sender<Fed>>,
}

/// A chunk the layout pass added, for a replay that runs beside it
/// ([`super::feed`]): the chunk (with its messages, if kept) and the
/// channels known once it was added, for its messages' topics.
pub(super) type Fed = (ChunkInfo, Channels);

/// How long the layout pass polls for a chunk's scan before it sleeps
/// ([`PendingChunks::settle_oldest`]): about what a 1 MiB chunk takes.
const POLL: Duration = Duration::from_millis(2);

/// A chunk's scan: its number and contents, or the panic that ended it
/// (resumed on the layout pass's thread, as a parallel iterator would).
type Scan = (u64, std::thread::Result<Result<ChunkContents, String>>);

/// A chunk read and being scanned.
struct Pending {
    number: u64,
    /// File offset and body length of the record.
    offset: u64,
    body_len: u64,
    /// Bytes of the record, held by its scan.
    bytes: usize,
    contents: Option<std::thread::Result<Result<ChunkContents, String>>>,
}

impl PendingChunks {
    /// Chunks read ahead at most, and their compressed bytes: the records
    /// are held, and one decompressed chunk per thread.
    const MAX: usize = 4;
    const MAX_BYTES: usize = 32 << 20;

    fn new(feed: Option<Sender<Fed>>) -> Self {
        Self {
            pending: VecDeque::new(),
            done: std::sync::mpsc::channel(),
            read: 0,
            message_count: 0,
            keep_left: KEPT_CHUNK_BYTES,
            feed,
        }
    }

    /// Starts the scan of a chunk record (file offset, body length, the
    /// record whole); adds the oldest chunks to the layout while more than
    /// [`Self::MAX`] (or [`Self::MAX_BYTES`]) are pending.
    fn push(
        &mut self,
        path: &Path,
        layout: &mut Layout,
        (offset, body_len, record): (u64, u64, Vec<u8>),
    ) -> Result<(), InputError> {
        // Whether to keep the chunk, in file order (a chunk whose header
        // does not parse fails in read_chunk).
        let size = chunk_header(&record).map_or(u64::MAX, |h| h.uncompressed_size);
        let keep = size <= self.keep_left;
        self.keep_left = if keep { self.keep_left - size } else { 0 };
        let number = self.read;
        self.read += 1;
        self.pending.push_back(Pending {
            number,
            offset,
            body_len,
            bytes: record.len(),
            contents: None,
        });
        if self.feed.is_some() {
            // Beside the replay the pass scans its chunks on its own thread,
            // one at a time: the other core is the engine's, and rayon's
            // threads may be the replay's own (a pool of one, the thread
            // that waits for the chunk, would never run the scan).
            self.file((
                number,
                std::panic::catch_unwind(|| read_chunk(&record, keep)),
            ));
            return self.settle_oldest(path, layout);
        }
        let done = self.done.0.clone();
        tortwin_handover::pool::before_pool_use();
        rayon::spawn(move || {
            let scan = std::panic::catch_unwind(|| read_chunk(&record, keep));
            // The layout pass may have failed and gone: nobody to tell.
            let _ = done.send((number, scan));
        });
        while self.pending.len() > Self::MAX
            || self.pending.iter().map(|p| p.bytes).sum::<usize>() > Self::MAX_BYTES
        {
            self.settle_oldest(path, layout)?;
        }
        Ok(())
    }

    /// Adds every pending chunk to the layout, in file order; the first
    /// chunk that fails is the error.
    fn settle(&mut self, path: &Path, layout: &mut Layout) -> Result<(), InputError> {
        while !self.pending.is_empty() {
            self.settle_oldest(path, layout)?;
        }
        Ok(())
    }

    /// Waits for the oldest pending chunk's scan (running scans of the pool
    /// meanwhile when this is one of its threads) and adds the chunk. A
    /// scan that runs on another thread is polled for, up to [`POLL`],
    /// before this thread sleeps until a scan ends: woken, it was queued
    /// for the core of the thread that woke it (the scheduler expects a
    /// thread that wakes another to sleep), which went on with the next
    /// chunk, while the other core idled for as long as a chunk takes.
    fn settle_oldest(&mut self, path: &Path, layout: &mut Layout) -> Result<(), InputError> {
        let mut polling_since = None;
        loop {
            while let Ok(scan) = self.done.1.try_recv() {
                self.file(scan);
            }
            if self.pending.front().is_some_and(|p| p.contents.is_some()) {
                break;
            }
            if rayon::yield_now() == Some(rayon::Yield::Executed) {
                continue;
            }
            if polling_since.get_or_insert_with(Instant::now).elapsed() < POLL {
                std::thread::yield_now();
                continue;
            }
            match self.done.1.recv() {
                Ok(scan) => self.file(scan),
                Err(_) => unreachable!("the layout pass holds a sender"),
            }
        }
        let Some(Pending {
            number,
            offset,
            body_len,
            contents: Some(contents),
            ..
        }) = self.pending.pop_front()
        else {
            return Ok(());
        };
        let contents = contents.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        let first_index = self.message_count;
        let added = contents.and_then(|c| add_chunk(c, layout, &mut self.message_count));
        let (message_start_time, kept) = added.map_err(|e| {
            // This chunk is the error, not one after it.
            self.pending.clear();
            InputError::file(path, format!("unreadable chunk at byte {offset}: {e}"))
        })?;
        let mut chunk = ChunkInfo {
            number,
            record_offset: offset,
            body_len,
            message_start_time,
            first_index,
            message_count: self.message_count - first_index,
            kept,
        };
        if let Some(feed) = &self.feed {
            let fed = ChunkInfo {
                kept: chunk.kept.take(),
                ..chunk.clone()
            };
            if feed.send((fed, layout.channels.clone())).is_err() {
                // The reader is gone: nobody wants the rest.
                self.pending.clear();
                return Err(InputError::file(path, "the replay stopped"));
            }
        }
        layout.chunks.push(chunk);
        Ok(())
    }

    /// Files a finished scan with its chunk.
    fn file(&mut self, (number, contents): Scan) {
        if let Some(p) = self.pending.iter_mut().find(|p| p.number == number) {
            p.contents = Some(contents);
        }
    }
}

/// The data section record by record, up to its DataEnd (or Footer).
fn walk(
    path: &Path,
    file: &mut BufReader<File>,
    file_len: u64,
    layout: &mut Layout,
    chunks: &mut PendingChunks,
) -> Result<(), InputError> {
    let corrupt = |what: String| InputError::file(path, what);
    let io_error = |e: std::io::Error| InputError::file(path, format!("cannot read: {e}"));
    let mut offset = mcap::MAGIC.len() as u64;
    // Whether a message outside chunks may extend the last run (no chunk
    // since it).
    let mut run_open = false;
    file.seek(SeekFrom::Start(offset)).map_err(io_error)?;
    loop {
        let (opcode, body_len, end) =
            next_frame(path, file, offset, file_len, "data section", "DataEnd")?;
        match opcode {
            op::FOOTER => return footer_ends_file(path, offset, end, file_len),
            op::DATA_END => return walk_summary(path, file, end, file_len),
            op::CHUNK => {
                run_open = false;
                // Reading the framing again keeps the chunk record whole for
                // the chunk reader.
                file.seek(SeekFrom::Start(offset)).map_err(io_error)?;
                let record =
                    read_exact_vec(file, RECORD_HEADER_BYTES + body_len).map_err(io_error)?;
                chunks.push(path, layout, (offset, body_len, record))?;
            }
            op::CHANNEL => {
                // Channels and messages outside chunks come after the
                // chunks before them.
                chunks.settle(path, layout)?;
                if body_len > MAX_SMALL_RECORD_BYTES {
                    return Err(corrupt(format!(
                        "the Channel record at byte {offset} claims {body_len} bytes (at most \
                         {MAX_SMALL_RECORD_BYTES} are accepted)"
                    )));
                }
                let body = read_exact_vec(file, body_len).map_err(io_error)?;
                match record::parse(opcode, &body) {
                    Ok(Record::Channel(channel)) => add_channel(&mut layout.channels, channel)
                        .map_err(|e| corrupt(format!("record at byte {offset}: {e}")))?,
                    Ok(_) => {}
                    Err(e) => return Err(corrupt(format!("corrupt record at byte {offset}: {e}"))),
                }
            }
            op::MESSAGE => {
                chunks.settle(path, layout)?;
                let message_count = chunks.message_count;
                if body_len < MESSAGE_HEADER_BYTES {
                    return Err(corrupt(format!(
                        "corrupt record at byte {offset}: a Message record of {body_len} bytes \
                         (its header alone is {MESSAGE_HEADER_BYTES})"
                    )));
                }
                let head = read_exact_vec(file, MESSAGE_HEADER_BYTES).map_err(io_error)?;
                let header = message_header(&head);
                let key = message_key(layout, &header, message_count)
                    .and_then(|key| {
                        check_message_size(key, body_len - MESSAGE_HEADER_BYTES).map(|()| key)
                    })
                    .map_err(|e| corrupt(format!("record at byte {offset}: {e}")))?;
                match layout.loose.last_mut() {
                    Some(run) if run_open && key > run.last => {
                        run.last = key;
                        run.message_count += 1;
                    }
                    _ => layout.loose.push(LooseRun {
                        first: key,
                        last: key,
                        record_offset: offset,
                        message_count: 1,
                    }),
                }
                run_open = true;
                chunks.message_count += 1;
                file.seek_relative((body_len - MESSAGE_HEADER_BYTES) as i64)
                    .map_err(io_error)?;
            }
            _ => {
                let skip = i64::try_from(body_len)
                    .map_err(|_| corrupt(format!("record at byte {offset} is too long")))?;
                file.seek_relative(skip).map_err(io_error)?;
            }
        }
        offset = end;
    }
}

/// A file's chunks as their records' framing and headers tell them, before
/// the layout pass has read them: what a replay needs to start while the
/// pass goes on beside it ([`super::feed`]).
#[derive(Debug)]
pub(super) struct ChunkHeads {
    /// Each chunk's number, offset, body length and `message_start_time`;
    /// its first index, message count and messages are the pass's to tell.
    pub chunks: Vec<ChunkInfo>,
    /// The messages the Message Index records list: the file's messages,
    /// unless the indexes are wrong (the layout pass counts them itself).
    pub indexed_messages: u64,
    /// The chunks' records uncompressed, as their headers say.
    pub uncompressed_bytes: u64,
}

/// The chunks of a file whose messages are all in chunks, each followed by
/// its Message Index records, read from the framing of the top-level
/// records and the first three fields of each chunk's header (its times
/// and uncompressed size): a few dozen bytes
/// a chunk, nothing decompressed. `None` for any other file: one with
/// Channel or Message records outside chunks, a chunk without indexes, a
/// framing the layout pass would refuse. Such files are laid out before
/// the replay starts, as always.
pub(super) fn chunk_heads(file: &mut BufReader<File>) -> Option<ChunkHeads> {
    let file_len = file.get_ref().metadata().ok()?.len();
    let magic_len = mcap::MAGIC.len() as u64;
    if file_len < 2 * magic_len || read_at(file, 0, magic_len).ok()? != mcap::MAGIC {
        return None;
    }
    let mut heads = ChunkHeads {
        chunks: Vec::new(),
        indexed_messages: 0,
        uncompressed_bytes: 0,
    };
    // Whether the last chunk has a Message Index record after it.
    let mut indexed = true;
    let mut offset = magic_len;
    file.seek(SeekFrom::Start(offset)).ok()?;
    loop {
        let mut frame = [0u8; RECORD_HEADER_BYTES as usize];
        file.read_exact(&mut frame).ok()?;
        let (opcode, body_len) = record_frame(&frame);
        let end = (offset + RECORD_HEADER_BYTES)
            .checked_add(body_len)
            .filter(|&end| end + magic_len <= file_len)?;
        let mut skip = body_len;
        match opcode {
            op::DATA_END | op::FOOTER => return indexed.then_some(heads),
            op::CHANNEL | op::MESSAGE => return None,
            op::CHUNK => {
                if !indexed || body_len < 24 {
                    return None;
                }
                // message_start_time, message_end_time, uncompressed_size.
                let mut times = [0u8; 24];
                file.read_exact(&mut times).ok()?;
                skip -= 24;
                let le = |at: usize| {
                    let mut bytes = [0u8; 8];
                    bytes.copy_from_slice(&times[at..at + 8]);
                    u64::from_le_bytes(bytes)
                };
                heads.uncompressed_bytes = heads.uncompressed_bytes.saturating_add(le(16));
                heads.chunks.push(ChunkInfo {
                    number: heads.chunks.len() as u64,
                    record_offset: offset,
                    body_len,
                    message_start_time: le(0),
                    first_index: 0,
                    message_count: 0,
                    kept: None,
                });
                indexed = false;
            }
            op::MESSAGE_INDEX => {
                // channel_id u16, then the entries' byte length u32 and
                // entries of (log_time u64, offset u64).
                let entries = body_len.checked_sub(6).filter(|n| n % 16 == 0)?;
                heads.indexed_messages += entries / 16;
                indexed = true;
            }
            _ => {}
        }
        file.seek_relative(i64::try_from(skip).ok()?).ok()?;
        offset = end;
    }
}

/// The summary section after the DataEnd at `offset`, frame by frame (the
/// records are not read), up to the Footer, which must end where the
/// file's closing magic begins.
fn walk_summary(
    path: &Path,
    file: &mut BufReader<File>,
    mut offset: u64,
    file_len: u64,
) -> Result<(), InputError> {
    let corrupt = |what: String| InputError::file(path, what);
    let io_error = |e: std::io::Error| InputError::file(path, format!("cannot read: {e}"));
    file.seek(SeekFrom::Start(offset)).map_err(io_error)?;
    loop {
        let (opcode, body_len, end) =
            next_frame(path, file, offset, file_len, "summary section", "Footer")?;
        if opcode == op::FOOTER {
            return footer_ends_file(path, offset, end, file_len);
        }
        let skip = i64::try_from(body_len)
            .map_err(|_| corrupt(format!("record at byte {offset} is too long")))?;
        file.seek_relative(skip).map_err(io_error)?;
        offset = end;
    }
}

/// The framing of the record at `offset` (the file positioned there):
/// its opcode, body length and end, checked to lie within the file. A
/// `section` that ends first lacks its closing `record`.
fn next_frame(
    path: &Path,
    file: &mut BufReader<File>,
    offset: u64,
    file_len: u64,
    section: &str,
    record: &str,
) -> Result<(u8, u64, u64), InputError> {
    let corrupt = |what: String| InputError::file(path, what);
    if file_len - offset < RECORD_HEADER_BYTES {
        return Err(corrupt(format!(
            "truncated MCAP file: the {section} ends at byte {offset} without a {record} record"
        )));
    }
    let mut frame = [0u8; RECORD_HEADER_BYTES as usize];
    file.read_exact(&mut frame)
        .map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    let (opcode, body_len) = record_frame(&frame);
    let end = (offset + RECORD_HEADER_BYTES)
        .checked_add(body_len)
        .filter(|&end| end <= file_len)
        .ok_or_else(|| {
            corrupt(format!(
                "truncated or corrupt MCAP file: the record at byte {offset} \
                 (opcode {opcode:#04x}) claims {body_len} bytes, past the end of the file"
            ))
        })?;
    Ok((opcode, body_len, end))
}

/// A Footer record at `offset` ending at `end` is the file's last record:
/// only the closing magic follows it. Anything more is refused rather than
/// ignored: two MCAP files joined into one would otherwise replay as the
/// first alone.
fn footer_ends_file(path: &Path, offset: u64, end: u64, file_len: u64) -> Result<(), InputError> {
    let magic_len = mcap::MAGIC.len() as u64;
    if end + magic_len == file_len {
        return Ok(());
    }
    Err(InputError::file(
        path,
        format!(
            "{} bytes follow the MCAP file's Footer record (at byte {offset}) and its closing \
             magic: two MCAP files joined into one, or data appended after the end? A \
             recording is one MCAP file (replay the files one after the other with \
             --state-out and --state-in)",
            file_len.saturating_sub(end + magic_len)
        ),
    ))
}

/// A chunk's Channel and Message records in file order, decompressed and
/// CRC-checked; the record's header's time range. A kept chunk's messages
/// are listed once, in `kept` (their data lengths are their ranges'); the
/// others' headers and data lengths in `messages`.
struct ChunkContents {
    message_start_time: u64,
    message_end_time: u64,
    /// Each Channel record with the number of messages before it in the
    /// chunk. Boxed: a chunk holds a handful of channels.
    channels: Vec<(usize, Box<mcap::records::Channel>)>,
    messages: Vec<(mcap::records::MessageHeader, u64)>,
    kept: Option<ChunkMessages>,
}

/// Reads a chunk record (given whole), keeping its messages if `keep`:
/// what fails here fails whatever came before the chunk.
fn read_chunk(record: &[u8], keep: bool) -> Result<ChunkContents, String> {
    let header = chunk_header(record)?;
    if header.uncompressed_size > MAX_CHUNK_BYTES {
        return Err(format!(
            "it claims {} bytes uncompressed (at most {MAX_CHUNK_BYTES} are accepted)",
            header.uncompressed_size
        ));
    }
    let mut kept = keep.then(|| ChunkMessages::with_capacity(&header));
    let mut channels = Vec::new();
    // A kept chunk's messages are listed in `kept` alone: a second list of
    // them was as large as the first, memory the layout pass touched fresh.
    let mut messages = match keep {
        true => Vec::new(),
        false => Vec::with_capacity(expected_messages(&header)),
    };
    let mut count = 0;
    let whole = chunk_records_whole(record, &header, |opcode, body, at| {
        match record::parse(opcode, body)? {
            Record::Channel(channel) => channels.push((count, Box::new(channel))),
            Record::Message { header, data } => {
                match &mut kept {
                    Some(kept) => kept.push(header, body, &data, at),
                    None => messages.push((header, data.len() as u64)),
                }
                count += 1;
            }
            _ => {}
        }
        Ok(())
    })?;
    if let Some(kept) = &mut kept {
        kept.adopt(whole);
    }
    Ok(ChunkContents {
        message_start_time: header.message_start_time,
        message_end_time: header.message_end_time,
        channels,
        messages,
        kept,
    })
}

/// The messages of a chunk record (given whole), decompressed; the bytes
/// of a message whose channel `keep` refuses (an unknown topic) are not
/// kept (its header is: it counts in the file's order). Memory: the
/// chunk's records as decompressed, or the format's messages of the chunk
/// when they are less than half of them ([`ChunkMessages::adopt`]).
pub(super) fn chunk_messages(
    record: &[u8],
    keep: impl Fn(u16) -> bool,
) -> Result<ChunkMessages, String> {
    let header = chunk_header(record)?;
    let mut kept = ChunkMessages::with_capacity(&header);
    let whole = chunk_records_whole(record, &header, |opcode, body, at| {
        if let Record::Message { header, data } = record::parse(opcode, body)? {
            let data: &[u8] = if keep(header.channel_id) { &data } else { &[] };
            // An empty range at the end of the record body.
            kept.push(header, body, data, at);
        }
        Ok(())
    })?;
    kept.adopt(whole);
    Ok(kept)
}

/// Counts a chunk's messages (checking each against the header's time range)
/// and collects its channels. Returns the chunk's `message_start_time` and
/// the messages kept.
fn add_chunk(
    contents: ChunkContents,
    layout: &mut Layout,
    message_count: &mut u64,
) -> Result<(u64, Option<ChunkMessages>), String> {
    let ChunkContents {
        message_start_time: start,
        message_end_time: end,
        channels,
        messages,
        kept,
    } = contents;
    let mut channels = channels.into_iter().peekable();
    let mut failure: Option<String> = None;
    // The chunk's records in file order: the channels defined before the
    // message at `position`, then the message.
    let mut add = |position: usize, header: &mcap::records::MessageHeader, data_len: u64| {
        while let Some((_, channel)) = channels.next_if(|(before, _)| *before <= position) {
            if let Err(e) = add_channel(&mut layout.channels, *channel) {
                failure.get_or_insert(e);
            }
        }
        if header.log_time < start || header.log_time > end {
            failure.get_or_insert(format!(
                "message {} has log_time {} ns, outside the chunk's \
                 message_start_time..message_end_time ({start}..{end})",
                *message_count, header.log_time
            ));
        }
        let checked = message_key(layout, header, *message_count)
            .and_then(|key| check_message_size(key, data_len));
        if let Err(e) = checked {
            failure.get_or_insert(e);
        }
        *message_count += 1;
    };
    match &kept {
        Some(kept) => {
            for (position, (header, range)) in kept.messages.iter().enumerate() {
                add(position, header, range.len() as u64);
            }
        }
        None => {
            for (position, (header, data_len)) in messages.iter().enumerate() {
                add(position, header, *data_len);
            }
        }
    }
    // The channels after the last message.
    for (_, channel) in channels {
        if let Err(e) = add_channel(&mut layout.channels, *channel) {
            failure.get_or_insert(e);
        }
    }
    match failure {
        Some(e) => Err(e),
        None => Ok((start, kept)),
    }
}

pub(super) fn add_channel(
    channels: &mut Channels,
    channel: mcap::records::Channel,
) -> Result<(), String> {
    let info = ChannelInfo {
        rank: TopicRank::of(&channel.topic),
        topic: channel.topic,
        message_encoding: channel.message_encoding,
    };
    match channels.get(&channel.id) {
        Some(known) if *known != info => Err(format!(
            "channel {} is defined twice, as `{}` and as `{}`",
            channel.id, known.topic, info.topic
        )),
        Some(_) => Ok(()),
        None => {
            channels.insert(channel.id, info);
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
    let key = key_of(&layout.channels, header, index_in_file)?;
    let first_two = match key.topic {
        TopicRank::Known(Topic::Section) => Some(&mut layout.sections),
        TopicRank::Known(Topic::Line) => Some(&mut layout.lines),
        _ => None,
    };
    if let Some(keys) = first_two {
        keys.push(key);
        keys.sort();
        keys.truncate(2);
    }
    Ok(key)
}

/// The replay key of the message with this header and index, whose
/// channel must have been defined.
pub(super) fn key_of(
    channels: &Channels,
    header: &mcap::records::MessageHeader,
    index_in_file: u64,
) -> Result<ReplayKey, String> {
    let channel = channels.get(&header.channel_id).ok_or_else(|| {
        format!(
            "message {index_in_file} (log_time {} ns) refers to channel {}, \
             which no Channel record before it defines",
            header.log_time, header.channel_id
        )
    })?;
    Ok(ReplayKey {
        log_time_ns: header.log_time,
        topic: channel.rank,
        index_in_file,
    })
}

/// A record's framing (its first [`RECORD_HEADER_BYTES`]): opcode and
/// body length.
pub(super) fn record_frame(frame: &[u8]) -> (u8, u64) {
    let mut len = [0u8; 8];
    len.copy_from_slice(&frame[1..RECORD_HEADER_BYTES as usize]);
    (frame[0], u64::from_le_bytes(len))
}

/// A Message record's header from its first [`MESSAGE_HEADER_BYTES`].
pub(super) fn message_header(head: &[u8]) -> mcap::records::MessageHeader {
    let le = |range: std::ops::Range<usize>| {
        let mut bytes = [0u8; 8];
        bytes[..range.len()].copy_from_slice(&head[range]);
        u64::from_le_bytes(bytes)
    };
    mcap::records::MessageHeader {
        channel_id: le(0..2) as u16,
        sequence: le(2..6) as u32,
        log_time: le(6..14),
        publish_time: le(14..22),
    }
}

/// Refuses a message of the format larger than [`MAX_MESSAGE_BYTES`].
pub(super) fn check_message_size(key: ReplayKey, data_len: u64) -> Result<(), String> {
    if key.topic != TopicRank::Unknown && data_len > MAX_MESSAGE_BYTES {
        return Err(format!(
            "message {} (log_time {} ns) is {data_len} bytes long; a message of the \
             format may be at most {MAX_MESSAGE_BYTES} bytes",
            key.index_in_file, key.log_time_ns
        ));
    }
    Ok(())
}

/// The header of a chunk record given whole (framing included).
pub(super) fn chunk_header(record: &[u8]) -> Result<mcap::records::ChunkHeader, String> {
    let body = record
        .get(RECORD_HEADER_BYTES as usize..)
        .ok_or("the chunk record is cut short")?;
    match record::parse(op::CHUNK, body)? {
        Record::Chunk { header, .. } => Ok(header),
        _ => Err("not a chunk record".to_string()),
    }
}

/// Calls `f` with the opcode and body of every Channel and Message record
/// inside a chunk record (given whole, framing included), decompressed and
/// its CRC checked. Other records are not parsed at all. A well-formed
/// chunk compressed with zstd (or not compressed) is decompressed in one
/// call ([`whole_chunk`]); any other, and any chunk that is not
/// well-formed, goes through the mcap crate's streaming reader, which says
/// what is wrong with it.
pub(super) fn for_each_chunk_record(
    record: &[u8],
    header: &mcap::records::ChunkHeader,
    mut f: impl FnMut(u8, &[u8]) -> Result<(), String>,
) -> Result<(), String> {
    chunk_records_whole(record, header, |opcode, body, _| f(opcode, body)).map(drop)
}

/// [`for_each_chunk_record`], keeping the decompressed records of a chunk
/// read whole: `f` also gets where each record body lies in them, and they
/// are returned (`None` for a chunk that went through the streaming reader).
fn chunk_records_whole(
    record: &[u8],
    header: &mcap::records::ChunkHeader,
    mut f: impl FnMut(u8, &[u8], Option<usize>) -> Result<(), String>,
) -> Result<Option<Vec<u8>>, String> {
    if let Some(records) = whole_chunk(record, header) {
        for (opcode, at, body) in framed(&records) {
            if opcode == op::CHANNEL || opcode == op::MESSAGE {
                f(opcode, body, Some(at))?;
            }
        }
        return Ok(Some(records));
    }
    streamed_chunk_records(record, header, |opcode, body| f(opcode, body, None))?;
    Ok(None)
}

/// [`for_each_chunk_record`] with the mcap crate's streaming reader.
fn streamed_chunk_records(
    record: &[u8],
    header: &mcap::records::ChunkHeader,
    mut f: impl FnMut(u8, &[u8]) -> Result<(), String>,
) -> Result<(), String> {
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
        match event.map_err(|e| e.to_string())? {
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

/// A chunk's records, decompressed in one call: the streaming reader
/// decompresses a record's framing and its body in two calls each, which
/// cost as much again as the decompression itself (measured 2026-12-02).
/// `None` unless the chunk is compressed with zstd or not at all, its
/// records decompress to exactly the header's `uncompressed_size` (at most
/// [`MAX_CHUNK_BYTES`]) with the header's CRC (when it is not zero), and
/// they frame exactly: what the streaming reader reads from such a chunk,
/// record by record, without an error.
fn whole_chunk(record: &[u8], header: &mcap::records::ChunkHeader) -> Option<Vec<u8>> {
    if header.uncompressed_size > MAX_CHUNK_BYTES {
        return None;
    }
    let size = usize::try_from(header.uncompressed_size).ok()?;
    let body = record.get(RECORD_HEADER_BYTES as usize..)?;
    let Ok(Record::Chunk { data, .. }) = record::parse(op::CHUNK, body) else {
        return None;
    };
    let bytes = match header.compression.as_str() {
        "zstd" => zstd::bulk::decompress(&data, size).ok()?,
        "" => data.into_owned(),
        _ => return None,
    };
    if bytes.len() != size
        || (header.uncompressed_crc != 0 && crc32fast::hash(&bytes) != header.uncompressed_crc)
    {
        return None;
    }
    let framed_bytes: usize = framed(&bytes)
        .map(|(_, _, body)| RECORD_HEADER_BYTES as usize + body.len())
        .sum();
    (framed_bytes == size).then_some(bytes)
}

/// The records (opcode, offset of the body in `bytes`, body) of
/// decompressed chunk bytes, in order, as long as they frame: each an
/// opcode, a u64 length and that many bytes.
fn framed(bytes: &[u8]) -> impl Iterator<Item = (u8, usize, &[u8])> {
    let mut rest = bytes;
    std::iter::from_fn(move || {
        let (&opcode, after) = rest.split_first()?;
        let (len, after) = after.split_first_chunk::<8>()?;
        let len = usize::try_from(u64::from_le_bytes(*len)).ok()?;
        if len > after.len() {
            return None;
        }
        let (body, after) = after.split_at(len);
        let at = bytes.len() - rest.len() + RECORD_HEADER_BYTES as usize;
        rest = after;
        Some((opcode, at, body))
    })
}

pub(super) fn read_at(
    file: &mut BufReader<File>,
    offset: u64,
    len: u64,
) -> std::io::Result<Vec<u8>> {
    // Within the buffer, a relative seek keeps it (a run of messages is
    // read front to back this way).
    let pos = file.stream_position()?;
    match i64::try_from(offset.wrapping_sub(pos)) {
        Ok(delta) if offset >= pos || pos - offset < (1 << 20) => file.seek_relative(delta)?,
        _ => {
            file.seek(SeekFrom::Start(offset))?;
        }
    }
    read_exact_vec(file, len)
}

pub(super) fn read_exact_vec(file: &mut BufReader<File>, len: u64) -> std::io::Result<Vec<u8>> {
    let len = usize::try_from(len)
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidData, "record too long"))?;
    let mut buf = vec![0u8; len];
    file.read_exact(&mut buf)?;
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chunk records of an MCAP file written by the mcap crate with
    /// `compression`, chunks of about `chunk_size` bytes.
    fn chunk_records(compression: Option<mcap::Compression>, chunk_size: u64) -> Vec<Vec<u8>> {
        let mut file = std::io::Cursor::new(Vec::new());
        let mut writer = mcap::WriteOptions::new()
            .compression(compression)
            .chunk_size(Some(chunk_size))
            .create(&mut file)
            .expect("a writer");
        let channel = writer
            .add_channel(0, "/applicator/pulse", "json", &Default::default())
            .expect("a channel");
        for k in 0..200u64 {
            let data = format!(r#"{{"applicator_id":"A1","rail":"high","mass_g":{k}.5}}"#);
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: k as u32,
                log_time: 1_000 + k,
                publish_time: 1_000 + k,
            };
            writer
                .write_to_known_channel(&header, data.as_bytes())
                .expect("written");
        }
        writer.finish().expect("finished");
        drop(writer);
        let bytes = file.into_inner();
        let mut records = Vec::new();
        let mut at = mcap::MAGIC.len();
        while at + RECORD_HEADER_BYTES as usize <= bytes.len() {
            let opcode = bytes[at];
            let mut len = [0u8; 8];
            len.copy_from_slice(&bytes[at + 1..at + 9]);
            let end = at + 9 + u64::from_le_bytes(len) as usize;
            if opcode == op::CHUNK {
                records.push(bytes[at..end].to_vec());
            }
            if opcode == op::FOOTER {
                break;
            }
            at = end;
        }
        assert!(records.len() > 2, "{} chunks", records.len());
        records
    }

    type Records = Result<Vec<(u8, Vec<u8>)>, String>;

    fn read_with(
        record: &[u8],
        read: impl Fn(
            &[u8],
            &mcap::records::ChunkHeader,
            &mut dyn FnMut(u8, &[u8]) -> Result<(), String>,
        ) -> Result<(), String>,
    ) -> Records {
        let header = chunk_header(record)?;
        let mut out = Vec::new();
        read(record, &header, &mut |opcode, body| {
            out.push((opcode, body.to_vec()));
            Ok(())
        })?;
        Ok(out)
    }

    #[test]
    fn a_chunk_read_whole_gives_what_the_streaming_reader_gives_also_when_corrupt() {
        let mut whole = 0;
        for compression in [
            Some(mcap::Compression::Zstd),
            None,
            Some(mcap::Compression::Lz4),
        ] {
            for record in chunk_records(compression, 1500) {
                let header = chunk_header(&record).expect("a chunk header");
                if whole_chunk(&record, &header).is_some() {
                    whole += 1;
                }
                // Every byte of the record flipped in turn (its framing
                // excluded: the layout pass reads that itself).
                let cases = std::iter::once(record.clone()).chain(
                    (RECORD_HEADER_BYTES as usize..record.len()).flat_map(|k| {
                        [0x01u8, 0x80].map(|bit| {
                            let mut bad = record.clone();
                            bad[k] ^= bit;
                            bad
                        })
                    }),
                );
                for case in cases {
                    let fast = read_with(&case, |r, h, f| for_each_chunk_record(r, h, f));
                    let streamed = read_with(&case, |r, h, f| streamed_chunk_records(r, h, f));
                    assert_eq!(fast, streamed, "{compression:?}");
                }
            }
        }
        // The zstd and uncompressed chunks (lz4 streams).
        assert!(whole > 4, "{whole} chunks read whole");
    }

    /// An uncompressed chunk record holding `records` (its size and CRC
    /// theirs).
    fn uncompressed_chunk(records: &[u8]) -> Vec<u8> {
        let mut body = Vec::new();
        body.extend_from_slice(&1_000u64.to_le_bytes());
        body.extend_from_slice(&2_000u64.to_le_bytes());
        body.extend_from_slice(&(records.len() as u64).to_le_bytes());
        body.extend_from_slice(&crc32fast::hash(records).to_le_bytes());
        body.extend_from_slice(&0u32.to_le_bytes());
        body.extend_from_slice(&(records.len() as u64).to_le_bytes());
        body.extend_from_slice(records);
        let mut record = vec![op::CHUNK];
        record.extend_from_slice(&(body.len() as u64).to_le_bytes());
        record.extend_from_slice(&body);
        record
    }

    /// A chunk's messages as (header, data).
    fn messages_of(kept: &ChunkMessages) -> Vec<(mcap::records::MessageHeader, Vec<u8>)> {
        kept.messages
            .iter()
            .map(|(h, range)| (*h, kept.bytes[range.clone()].to_vec()))
            .collect()
    }

    /// The messages kept of a chunk read whole point into its decompressed
    /// records (no copy), and are the streaming reader's messages; a chunk
    /// whose kept messages are less than half of it keeps only their bytes.
    #[test]
    fn messages_kept_of_a_chunk_read_whole_are_the_streamed_ones() {
        for compression in [Some(mcap::Compression::Zstd), None] {
            for record in chunk_records(compression, 1500) {
                let header = chunk_header(&record).expect("a chunk header");
                assert!(whole_chunk(&record, &header).is_some());
                for keep_all in [true, false] {
                    let mut streamed = Vec::new();
                    streamed_chunk_records(&record, &header, |opcode, body| {
                        if let Record::Message { header, data } = record::parse(opcode, body)? {
                            let data = if keep_all { data.to_vec() } else { Vec::new() };
                            streamed.push((header, data));
                        }
                        Ok(())
                    })
                    .expect("read");
                    let kept = chunk_messages(&record, |_| keep_all).expect("read");
                    assert_eq!(messages_of(&kept), streamed);
                    let size = header.uncompressed_size as usize;
                    if keep_all {
                        // The decompressed records themselves.
                        assert_eq!(kept.bytes.len(), size);
                        let scanned = read_chunk(&record, true).expect("read");
                        let scanned = scanned.kept.expect("kept");
                        assert_eq!(scanned.bytes.len(), size);
                        assert_eq!(messages_of(&scanned), streamed);
                    } else {
                        assert!(kept.bytes.is_empty(), "{} bytes held", kept.bytes.len());
                    }
                }
            }
        }
    }

    #[test]
    fn records_that_do_not_frame_are_left_to_the_streaming_reader() {
        let record = &chunk_records(None, 1500)[0];
        let header = chunk_header(record).expect("a chunk header");
        let Ok(Record::Chunk { data, .. }) = record::parse(op::CHUNK, &record[9..]) else {
            panic!("not a chunk");
        };
        // The records cut inside the last one, its CRC and size right.
        for cut in [1, 3, 9, 20] {
            let bad = uncompressed_chunk(&data[..data.len() - cut]);
            let bad_header = chunk_header(&bad).expect("a chunk header");
            assert!(whole_chunk(&bad, &bad_header).is_none());
            let fast = read_with(&bad, |r, h, f| for_each_chunk_record(r, h, f));
            let streamed = read_with(&bad, |r, h, f| streamed_chunk_records(r, h, f));
            assert_eq!(fast, streamed);
        }
        // Whole, the same records read whole.
        let good = uncompressed_chunk(&data);
        assert!(whole_chunk(&good, &header).is_some());
        assert_eq!(
            read_with(&good, |r, h, f| for_each_chunk_record(r, h, f)),
            read_with(record, |r, h, f| streamed_chunk_records(r, h, f))
        );
    }
}
