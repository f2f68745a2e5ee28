//! MCAP -> typed events, in replay order, streaming.
//!
//! The replay order of ../shared/spec/recording-format.md is by `log_time`,
//! ties by topic (`/section`, `/train/passage`, `/applicator/pulse`,
//! `/measurement/friction`, `/environment/weather`, then unknown topics),
//! then by the message's index in the file. Files are not written in that
//! order (the reference recordings append tribometer readings at the end), so
//! the reader merges, and it must do so without holding the whole recording:
//! a recording grows with the days it covers, the engine's state only with
//! the section.
//!
//! How, in two passes over the file:
//!
//! 1. **Layout pass** (`scan_layout`). The data section is walked record by
//!    record (the MCAP framing is `opcode u8, length u64, body`). For every
//!    Chunk it keeps the file offset, the `message_start_time`/
//!    `message_end_time` of its header and how many Message records it holds;
//!    the chunk is decompressed to count them (and to check its CRC and that
//!    every log_time lies inside the header's range), and its records are
//!    dropped again. A Message record outside any chunk keeps only its replay
//!    key and file offset. Channel records are kept (a handful). Memory:
//!    one chunk at a time plus a few words per chunk.
//!
//!    This pass plays the part of the summary's chunk indexes, built from the
//!    data section itself rather than trusted from the summary: file order
//!    *is* data-section order, a summary may be absent or omit messages
//!    written outside chunks, and counting by decompression needs no optional
//!    Message Index records. It also means a corrupt chunk anywhere in the
//!    file fails [`RecordingReader::open`], before the engine has done a day
//!    of work.
//! 2. **Replay** (`ReplayQueue::next_message`). Chunks wait in order of
//!    `message_start_time`. A chunk is decompressed only when the time
//!    frontier reaches it (its start time is not later than the earliest
//!    message already in hand), and its messages go into a heap keyed by
//!    (log_time, topic, index in file); the index of a chunk's k-th message
//!    is the number of messages before the chunk plus k. Only chunks whose
//!    time ranges overlap the frontier are in memory at once.
//!
//! Fallback for messages outside chunks (an unchunked file): their keys
//! (log_time, topic, index, offset) are sorted in memory and each body is
//! read back by offset when its turn comes. That list grows with the number of
//! such messages, i.e. with the recording (about 40 bytes a message); the
//! engine-facing behaviour is the same. The `train_id`s seen so far (for the
//! duplicate check and measurements) also grow with the recording, by one
//! entry per train.
//!
//! Every message is then parsed once into an [`Event`]: units converted (g ->
//! kg, kN -> N), rails, applicators, sites and trains resolved to indices,
//! and every rule of the format page checked. An error names the file and,
//! for a message, its topic, log_time and index in the file, and ends the
//! iteration.

use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, HashMap};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use serde_json::{Map, Value};

use super::{
    Applicator, Axle, AxleRef, BogiePosition, Creepage, Direction, Event, EventKind, Measurement,
    Passage, Pulse, Quantity, Section, Site, Weather,
};
use crate::error::{InputError, MessageLocation};

/// What a recording needs from the replay before it: a recording continues
/// the time axis and the occupation of the section where the previous day's
/// state left them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReaderContext {
    /// The time origin of the replay; `None` takes this recording's `/section`
    /// log_time.
    pub origin_ns: Option<i64>,
    /// Time (s from the origin) at which the last train of the previous
    /// recording had left the section; `NEG_INFINITY` if there was none.
    pub occupied_until_s: f64,
}

impl Default for ReaderContext {
    fn default() -> Self {
        Self {
            origin_ns: None,
            occupied_until_s: f64::NEG_INFINITY,
        }
    }
}

/// A chunk larger than this (uncompressed) is refused rather than allocated:
/// writers use chunks of about a megabyte, and a corrupt size field must not
/// exhaust memory.
const MAX_CHUNK_BYTES: u64 = 1 << 30;

/// Bytes of a record's framing: opcode (1) and body length (8).
const RECORD_HEADER_BYTES: u64 = 9;

/// The topics of the format page, in their tie-break order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
enum Topic {
    Section,
    Passage,
    Pulse,
    Measurement,
    Weather,
    Unknown,
}

impl Topic {
    /// The format's topic (names defined once, in [`super::Topic`]), or
    /// `Unknown`, which sorts after every known topic.
    fn of(topic: &str) -> Self {
        match super::Topic::from_name(topic) {
            Some(super::Topic::Section) => Topic::Section,
            Some(super::Topic::Passage) => Topic::Passage,
            Some(super::Topic::Pulse) => Topic::Pulse,
            Some(super::Topic::Measurement) => Topic::Measurement,
            Some(super::Topic::Weather) => Topic::Weather,
            None => Topic::Unknown,
        }
    }
}

/// A message's place in the replay. Unique, since the index is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct ReplayKey {
    log_time_ns: u64,
    topic: Topic,
    index_in_file: u64,
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct ChannelInfo {
    topic: String,
    message_encoding: String,
}

/// A Chunk record as the layout pass found it.
#[derive(Debug, Clone)]
struct ChunkInfo {
    /// File offset of the record's opcode byte.
    record_offset: u64,
    /// Body length of the record.
    body_len: u64,
    message_start_time: u64,
    /// Index in the file of the chunk's first message.
    first_index: u64,
    message_count: u64,
}

/// A Message record outside any chunk.
#[derive(Debug, Clone, Copy)]
struct LooseMessage {
    key: ReplayKey,
    body_offset: u64,
    body_len: u64,
}

#[derive(Debug, Default)]
struct Layout {
    channels: HashMap<u16, ChannelInfo>,
    chunks: Vec<ChunkInfo>,
    loose: Vec<LooseMessage>,
    /// The first two `/section` messages in replay order.
    sections: Vec<ReplayKey>,
}

/// A message taken out of its record, waiting for its turn.
#[derive(Debug)]
struct PendingMessage {
    key: ReplayKey,
    channel_id: u16,
    data: Vec<u8>,
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

/// A train the replay has seen, for measurements and the duplicate check.
#[derive(Debug, Clone, Copy)]
struct TrainSeen {
    train_seq: usize,
    axle_count: usize,
    log_time_ns: u64,
}

/// The messages of a file in replay order, read chunk by chunk as the time
/// frontier reaches them (see the module documentation).
struct ReplayQueue {
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

/// Reads a recording as validated [`Event`]s in replay order; see the module
/// documentation for how it bounds memory. The iterator stops after the first
/// error.
pub struct RecordingReader {
    queue: ReplayQueue,
    section: Section,
    section_log_time_ns: u64,
    origin_ns: i64,
    trains: HashMap<String, TrainSeen>,
    /// `train_id` of the last passage, for the two-trains message.
    last_train_id: Option<String>,
    occupied_until_s: f64,
    unknown_topic_messages: u64,
    finished: bool,
}

impl RecordingReader {
    /// Opens a recording, lays out its chunks and reads and checks its
    /// `/section` message, which must be the first message in replay order
    /// and the only one of its topic.
    pub fn open(path: &Path, ctx: ReaderContext) -> Result<Self, InputError> {
        let file = File::open(path)
            .map_err(|e| InputError::file(path, format!("cannot open the recording: {e}")))?;
        let mut file = BufReader::new(file);
        let layout = scan_layout(path, &mut file)?;
        let Some(&first_section) = layout.sections.first() else {
            return Err(InputError::file(
                path,
                "the recording has no /section message",
            ));
        };
        let mut queue = ReplayQueue::new(path, file, layout.channels, layout.chunks, layout.loose);

        let Some(first) = queue.next_message()? else {
            return Err(InputError::file(
                path,
                "the recording has no /section message",
            ));
        };
        if first.key != first_section {
            let (location, _) = queue.describe(&first)?;
            return Err(InputError::at(
                path,
                location,
                format!(
                    "log_time {} ns is earlier than the /section message's ({} ns); \
                     /section must be the first message of a recording",
                    first.key.log_time_ns, first_section.log_time_ns
                ),
            ));
        }
        let (location, value) = queue.json_body(&first)?;
        if let Some(second) = layout.sections.get(1) {
            return Err(InputError::at(
                path,
                MessageLocation {
                    topic: "/section".to_string(),
                    log_time_ns: second.log_time_ns,
                    index_in_file: second.index_in_file,
                },
                format!(
                    "a second /section message (the first is message {} at log_time {} ns); \
                     a recording has exactly one",
                    first_section.index_in_file, first_section.log_time_ns
                ),
            ));
        }
        let section =
            parse_section(&value).map_err(|m| InputError::at(path, location.clone(), m))?;
        let origin_ns = match ctx.origin_ns {
            Some(origin_ns) => origin_ns,
            None => i64::try_from(first.key.log_time_ns).map_err(|_| {
                InputError::at(
                    path,
                    location,
                    "log_time does not fit a signed 64-bit nanosecond count",
                )
            })?,
        };
        Ok(Self {
            queue,
            section,
            section_log_time_ns: first.key.log_time_ns,
            origin_ns,
            trains: HashMap::new(),
            last_train_id: None,
            occupied_until_s: ctx.occupied_until_s,
            unknown_topic_messages: 0,
            finished: false,
        })
    }

    pub fn section(&self) -> &Section {
        &self.section
    }

    pub fn section_log_time_ns(&self) -> u64 {
        self.section_log_time_ns
    }

    /// The replay's time origin: the context's, or this `/section` log_time.
    pub fn origin_ns(&self) -> i64 {
        self.origin_ns
    }

    /// Messages on unknown topics skipped so far.
    pub fn unknown_topic_messages(&self) -> u64 {
        self.unknown_topic_messages
    }

    /// Time (s from the origin) at which the last train read so far leaves
    /// the section: its `t_passage + (length_m + offset of its last axle) /
    /// speed_mps`; the context's value before the first passage.
    pub fn occupied_until_s(&self) -> f64 {
        self.occupied_until_s
    }

    fn error(&self, location: MessageLocation, message: String) -> InputError {
        InputError::at(&self.queue.path, location, message)
    }

    /// Time in s from the origin, as model.md "Units and time" defines it.
    fn time_s(&self, log_time_ns: u64) -> Option<f64> {
        let t = i64::try_from(log_time_ns).ok()?;
        Some(t.checked_sub(self.origin_ns)? as f64 * 1e-9)
    }

    fn decode(&mut self, message: PendingMessage) -> Result<Option<Event>, InputError> {
        let topic = message.key.topic;
        if topic == Topic::Unknown {
            self.unknown_topic_messages += 1;
            return Ok(None);
        }
        let (location, value) = self.queue.json_body(&message)?;
        let kind = match topic {
            Topic::Section => Err(format!(
                "a second /section message (the first is at log_time {} ns); \
                 a recording has exactly one",
                self.section_log_time_ns
            )),
            Topic::Passage => self.passage(&value, message.key.log_time_ns),
            Topic::Pulse => parse_pulse(&value, &self.section).map(EventKind::Pulse),
            Topic::Measurement => self.measurement(&value).map(EventKind::Measurement),
            Topic::Weather => parse_weather(&value).map(EventKind::Weather),
            Topic::Unknown => return Ok(None),
        }
        .map_err(|m| self.error(location, m))?;
        Ok(Some(Event {
            log_time_ns: message.key.log_time_ns,
            index_in_file: message.key.index_in_file,
            kind,
        }))
    }

    fn passage(&mut self, value: &Value, log_time_ns: u64) -> Result<EventKind, String> {
        let train_seq = self.trains.len();
        let passage = parse_passage(value, &self.section, train_seq)?;
        if let Some(seen) = self.trains.get(&passage.train_id) {
            return Err(format!(
                "duplicate train_id `{}`: passage {} at log_time {} ns already has it",
                passage.train_id, seen.train_seq, seen.log_time_ns
            ));
        }
        let t_passage_s = self.time_s(log_time_ns).ok_or_else(|| {
            format!(
                "log_time {log_time_ns} ns is out of range for the time origin {} ns",
                self.origin_ns
            )
        })?;
        if t_passage_s < self.occupied_until_s {
            let previous = match &self.last_train_id {
                Some(id) => format!("train `{id}`"),
                None => "the last train of the previous recording".to_string(),
            };
            return Err(format!(
                "two trains in the section at once: train `{}` enters at {t_passage_s} s, \
                 before {previous} has left it at {} s",
                passage.train_id, self.occupied_until_s
            ));
        }
        let last_offset_m = passage.axles.last().map_or(0.0, |a| a.offset_m);
        self.occupied_until_s =
            t_passage_s + (self.section.length_m + last_offset_m) / passage.speed_mps;
        self.trains.insert(
            passage.train_id.clone(),
            TrainSeen {
                train_seq,
                axle_count: passage.axles.len(),
                log_time_ns,
            },
        );
        self.last_train_id = Some(passage.train_id.clone());
        Ok(EventKind::Passage(passage))
    }

    fn measurement(&self, value: &Value) -> Result<Measurement, String> {
        let obj = Obj::root(value)?;
        let site = resolve_site(&self.section, obj.str("site_id")?)?;
        let rail = resolve_rail(&self.section, obj.str("rail")?, "rail")?;
        let quantity = match obj.str("quantity")? {
            "mu" => Quantity::Mu,
            "adhesion" => Quantity::Adhesion,
            "rail_mu" => Quantity::RailMu,
            other => {
                return Err(format!(
                    "unknown quantity `{other}` (expected `mu`, `adhesion` or `rail_mu`)"
                ))
            }
        };
        let axle = match quantity {
            Quantity::RailMu => {
                for key in ["train_id", "axle_index"] {
                    if let Some(v) = obj.optional(key) {
                        return Err(format!(
                            "a `rail_mu` measurement is of the rail alone, \
                             but it has `{key}` = {}",
                            show(v)
                        ));
                    }
                }
                None
            }
            Quantity::Mu | Quantity::Adhesion => {
                let train_id = obj.str("train_id")?;
                let axle_index = obj.index("axle_index")?;
                let Some(train) = self.trains.get(train_id) else {
                    return Err(format!(
                        "train_id `{train_id}` is unknown: no /train/passage with it \
                         comes before this measurement"
                    ));
                };
                if axle_index >= train.axle_count {
                    return Err(format!(
                        "axle_index {axle_index} is out of range: train `{train_id}` has {} axles",
                        train.axle_count
                    ));
                }
                Some(AxleRef {
                    train_id: train_id.to_string(),
                    train_seq: train.train_seq,
                    axle_index,
                })
            }
        };
        Ok(Measurement {
            site,
            rail,
            quantity,
            axle,
            value: obj.number("value")?,
        })
    }
}

impl ReplayQueue {
    fn new(
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
    fn next_message(&mut self) -> Result<Option<PendingMessage>, InputError> {
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
                    .map_or(Topic::Unknown, |c| Topic::of(&c.topic));
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

    /// The message's location and its channel's message encoding.
    fn describe(&self, message: &PendingMessage) -> Result<(MessageLocation, String), InputError> {
        // The layout pass checked that every message's channel is defined.
        let channel = self.channels.get(&message.channel_id).ok_or_else(|| {
            self.corrupt(format!(
                "message {} refers to undefined channel {}",
                message.key.index_in_file, message.channel_id
            ))
        })?;
        Ok((
            MessageLocation {
                topic: channel.topic.clone(),
                log_time_ns: message.key.log_time_ns,
                index_in_file: message.key.index_in_file,
            },
            channel.message_encoding.clone(),
        ))
    }

    /// A known topic's message body as JSON, with its location.
    fn json_body(&self, message: &PendingMessage) -> Result<(MessageLocation, Value), InputError> {
        let (location, encoding) = self.describe(message)?;
        if encoding != "json" {
            return Err(self.error(
                location,
                format!("message encoding is `{encoding}`; this topic must be `json`"),
            ));
        }
        match serde_json::from_slice::<Value>(&message.data) {
            Ok(value) => Ok((location, value)),
            Err(e) => Err(self.error(
                location,
                format!(
                    "the message is not valid JSON ({e}); NaN and infinity are not JSON numbers"
                ),
            )),
        }
    }
}

impl Iterator for RecordingReader {
    type Item = Result<Event, InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.finished {
            let step = match self.queue.next_message() {
                Ok(Some(message)) => self.decode(message),
                Ok(None) => {
                    self.finished = true;
                    return None;
                }
                Err(e) => Err(e),
            };
            match step {
                Ok(Some(event)) => return Some(Ok(event)),
                Ok(None) => continue,
                Err(e) => {
                    self.finished = true;
                    return Some(Err(e));
                }
            }
        }
        None
    }
}

// ---------------------------------------------------------------------------
// The layout pass.

/// Walks the data section once; see the module documentation.
fn scan_layout(path: &Path, file: &mut BufReader<File>) -> Result<Layout, InputError> {
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
        topic: Topic::of(&channel.topic),
        index_in_file,
    };
    if key.topic == Topic::Section {
        layout.sections.push(key);
        layout.sections.sort();
        layout.sections.truncate(2);
    }
    Ok(key)
}

/// The header of a chunk record given whole (framing included).
fn chunk_header(record: &[u8]) -> mcap::McapResult<mcap::records::ChunkHeader> {
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
fn for_each_chunk_record(
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

fn read_at(file: &mut BufReader<File>, offset: u64, len: u64) -> std::io::Result<Vec<u8>> {
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

// ---------------------------------------------------------------------------
// JSON -> typed values. Errors are messages; the caller adds the location.

/// A JSON object being taken apart; `path` names it in messages
/// (e.g. `axles[2].creepage.high.`).
struct Obj<'a> {
    map: &'a Map<String, Value>,
    path: String,
}

/// A JSON value for a message, shortened so a huge value cannot flood it.
fn show(value: &Value) -> String {
    const MAX_CHARS: usize = 60;
    let text = value.to_string();
    if text.chars().count() > MAX_CHARS {
        let short: String = text.chars().take(MAX_CHARS).collect();
        format!("{short}...")
    } else {
        text
    }
}

impl<'a> Obj<'a> {
    fn root(value: &'a Value) -> Result<Self, String> {
        match value {
            Value::Object(map) => Ok(Self {
                map,
                path: String::new(),
            }),
            other => Err(format!(
                "the message must be a JSON object, got {}",
                show(other)
            )),
        }
    }

    fn name(&self, key: &str) -> String {
        format!("{}{key}", self.path)
    }

    fn get(&self, key: &str) -> Result<&'a Value, String> {
        self.map
            .get(key)
            .ok_or_else(|| format!("missing field `{}`", self.name(key)))
    }

    /// A field that may be absent; `null` counts as absent.
    fn optional(&self, key: &str) -> Option<&'a Value> {
        self.map.get(key).filter(|v| !v.is_null())
    }

    fn object(&self, key: &str) -> Result<Obj<'a>, String> {
        match self.get(key)? {
            Value::Object(map) => Ok(Obj {
                map,
                path: format!("{}.", self.name(key)),
            }),
            other => Err(format!(
                "field `{}` must be an object, got {}",
                self.name(key),
                show(other)
            )),
        }
    }

    fn array(&self, key: &str) -> Result<&'a [Value], String> {
        match self.get(key)? {
            Value::Array(items) => Ok(items),
            other => Err(format!(
                "field `{}` must be an array, got {}",
                self.name(key),
                show(other)
            )),
        }
    }

    fn non_empty_array(&self, key: &str) -> Result<&'a [Value], String> {
        let items = self.array(key)?;
        if items.is_empty() {
            return Err(format!("field `{}` must not be empty", self.name(key)));
        }
        Ok(items)
    }

    /// The element `i` of array `key` as an object.
    fn element(&self, key: &str, i: usize, value: &'a Value) -> Result<Obj<'a>, String> {
        match value {
            Value::Object(map) => Ok(Obj {
                map,
                path: format!("{}[{i}].", self.name(key)),
            }),
            other => Err(format!(
                "`{}[{i}]` must be an object, got {}",
                self.name(key),
                show(other)
            )),
        }
    }

    fn str(&self, key: &str) -> Result<&'a str, String> {
        match self.get(key)? {
            Value::String(s) => Ok(s),
            other => Err(format!(
                "field `{}` must be a string, got {}",
                self.name(key),
                show(other)
            )),
        }
    }

    /// A finite JSON number (an integer is a valid float; `true` is not).
    fn number(&self, key: &str) -> Result<f64, String> {
        let value = self.get(key)?;
        match value.as_f64() {
            Some(x) if value.is_number() && x.is_finite() => Ok(x),
            _ => Err(format!(
                "field `{}` must be a finite number, got {}",
                self.name(key),
                show(value)
            )),
        }
    }

    fn positive(&self, key: &str) -> Result<f64, String> {
        let x = self.number(key)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(format!(
                "field `{}` must be positive, got {x}",
                self.name(key)
            ))
        }
    }

    fn non_negative(&self, key: &str) -> Result<f64, String> {
        let x = self.number(key)?;
        if x >= 0.0 {
            Ok(x)
        } else {
            Err(format!(
                "field `{}` must not be negative, got {x}",
                self.name(key)
            ))
        }
    }

    /// A non-negative JSON integer (`7`, not `7.0`).
    fn index(&self, key: &str) -> Result<usize, String> {
        let value = self.get(key)?;
        value
            .as_u64()
            .and_then(|i| usize::try_from(i).ok())
            .ok_or_else(|| {
                format!(
                    "field `{}` must be a non-negative integer, got {}",
                    self.name(key),
                    show(value)
                )
            })
    }

    /// A map with exactly one entry per rail of the section, in rail order.
    fn per_rail<T>(
        &self,
        key: &str,
        rails: &[String],
        mut item: impl FnMut(&Obj<'a>, &str) -> Result<T, String>,
    ) -> Result<Vec<T>, String> {
        let map = self.object(key)?;
        if let Some(unknown) = map.map.keys().find(|k| !rails.contains(k)) {
            return Err(format!(
                "`{}` names rail `{unknown}`, which the section does not have (rails: {})",
                self.name(key),
                rails.join(", ")
            ));
        }
        rails
            .iter()
            .map(|rail| {
                if map.map.contains_key(rail) {
                    item(&map, rail)
                } else {
                    Err(format!("`{}` lacks rail `{rail}`", self.name(key)))
                }
            })
            .collect()
    }
}

fn resolve_rail(section: &Section, name: &str, field: &str) -> Result<usize, String> {
    section.rails.iter().position(|r| r == name).ok_or_else(|| {
        format!(
            "field `{field}`: rail `{name}` is not a rail of the section (rails: {})",
            section.rails.join(", ")
        )
    })
}

fn resolve_site(section: &Section, id: &str) -> Result<usize, String> {
    section
        .sites
        .iter()
        .position(|s| s.id == id)
        .ok_or_else(|| format!("field `site_id`: unknown measurement site `{id}`"))
}

fn parse_section(value: &Value) -> Result<Section, String> {
    let obj = Obj::root(value)?;
    let length_m = obj.positive("length_m")?;

    let mut rails: Vec<String> = Vec::new();
    for (i, rail) in obj.non_empty_array("rails")?.iter().enumerate() {
        let Value::String(name) = rail else {
            return Err(format!("`rails[{i}]` must be a string, got {}", show(rail)));
        };
        if rails.contains(name) {
            return Err(format!("duplicate rail `{name}` in `rails`"));
        }
        rails.push(name.clone());
    }

    let curve_radius_m = match obj.get("curve_radius_m")? {
        Value::Null => None,
        _ => Some(obj.positive("curve_radius_m")?),
    };

    let position_in_section = |element: &Obj, key: &str| -> Result<f64, String> {
        let x = element.number(key)?;
        if (0.0..=length_m).contains(&x) {
            Ok(x)
        } else {
            Err(format!(
                "field `{}` = {x} is outside the section (0 to {length_m} m)",
                element.name(key)
            ))
        }
    };

    let mut applicators: Vec<Applicator> = Vec::new();
    for (i, item) in obj.non_empty_array("applicators")?.iter().enumerate() {
        let a = obj.element("applicators", i, item)?;
        let id = a.str("id")?;
        if applicators.iter().any(|known| known.id == id) {
            return Err(format!("duplicate applicator id `{id}`"));
        }
        let mut applicator_rails = Vec::new();
        for (j, rail) in a.non_empty_array("rails")?.iter().enumerate() {
            let field = format!("{}[{j}]", a.name("rails"));
            let Value::String(name) = rail else {
                return Err(format!("`{field}` must be a string, got {}", show(rail)));
            };
            let Some(index) = rails.iter().position(|r| r == name) else {
                return Err(format!(
                    "field `{field}`: rail `{name}` is not a rail of the section (rails: {})",
                    rails.join(", ")
                ));
            };
            if applicator_rails.contains(&index) {
                return Err(format!("duplicate rail `{name}` in `{}`", a.name("rails")));
            }
            applicator_rails.push(index);
        }
        applicators.push(Applicator {
            id: id.to_string(),
            position_m: position_in_section(&a, "position_m")?,
            rails: applicator_rails,
            nominal_pulse_kg: a.non_negative("nominal_pulse_g")? * 1e-3,
        });
    }

    let mut sites: Vec<Site> = Vec::new();
    for (i, item) in obj.array("measurement_sites")?.iter().enumerate() {
        let s = obj.element("measurement_sites", i, item)?;
        let id = s.str("id")?;
        if sites.iter().any(|known| known.id == id) {
            return Err(format!("duplicate measurement site id `{id}`"));
        }
        sites.push(Site {
            id: id.to_string(),
            position_m: position_in_section(&s, "position_m")?,
        });
    }

    Ok(Section {
        section_id: obj.str("section_id")?.to_string(),
        length_m,
        rails,
        curve_radius_m,
        rail_head_radius_m: obj.positive("rail_head_radius_m")?,
        nominal_wheel_diameter_m: obj.positive("nominal_wheel_diameter_m")?,
        applicators,
        sites,
    })
}

fn parse_passage(value: &Value, section: &Section, train_seq: usize) -> Result<Passage, String> {
    let obj = Obj::root(value)?;
    let train_id = obj.str("train_id")?.to_string();
    let direction = match obj.str("direction")? {
        "up" => Direction::Up,
        "down" => Direction::Down,
        other => {
            return Err(format!(
                "unknown direction `{other}` (expected `up` or `down`)"
            ))
        }
    };
    let speed_mps = obj.positive("speed_mps")?;
    let mut axles: Vec<Axle> = Vec::new();
    for (i, item) in obj.non_empty_array("axles")?.iter().enumerate() {
        let a = obj.element("axles", i, item)?;
        let offset_m = a.non_negative("offset_m")?;
        if let Some(previous) = axles.last() {
            if offset_m < previous.offset_m {
                return Err(format!(
                    "field `{}` = {offset_m} is less than the previous axle's {}; \
                     offsets never decrease along the train",
                    a.name("offset_m"),
                    previous.offset_m
                ));
            }
        }
        let bogie_position = match a.str("bogie_position")? {
            "leading" => BogiePosition::Leading,
            "trailing" => BogiePosition::Trailing,
            other => {
                return Err(format!(
                    "field `{}`: unknown bogie_position `{other}` \
                     (expected `leading` or `trailing`)",
                    a.name("bogie_position")
                ))
            }
        };
        let wheel_load_n = a.per_rail("wheel_load_kN", &section.rails, |m, rail| {
            Ok(m.positive(rail)? * 1e3)
        })?;
        let creepage = a.per_rail("creepage", &section.rails, |m, rail| {
            let c = m.object(rail)?;
            Ok(Creepage {
                cx: c.number("cx")?,
                cy: c.number("cy")?,
                spin_per_m: c.number("spin_per_m")?,
            })
        })?;
        axles.push(Axle {
            offset_m,
            bogie_position,
            wheel_diameter_m: a.positive("wheel_diameter_m")?,
            wheel_load_n,
            creepage,
        });
    }
    Ok(Passage {
        train_id,
        train_seq,
        direction,
        speed_mps,
        axles,
    })
}

fn parse_pulse(value: &Value, section: &Section) -> Result<Pulse, String> {
    let obj = Obj::root(value)?;
    let id = obj.str("applicator_id")?;
    let Some((applicator, a)) = section
        .applicators
        .iter()
        .enumerate()
        .find(|(_, a)| a.id == id)
    else {
        return Err(format!("field `applicator_id`: unknown applicator `{id}`"));
    };
    let rail_name = obj.str("rail")?;
    let rail = resolve_rail(section, rail_name, "rail")?;
    if !a.rails.contains(&rail) {
        let listed: Vec<&str> = a
            .rails
            .iter()
            .filter_map(|&r| section.rails.get(r).map(String::as_str))
            .collect();
        return Err(format!(
            "field `rail`: applicator `{id}` does not apply to rail `{rail_name}` \
             (its rails: {})",
            listed.join(", ")
        ));
    }
    Ok(Pulse {
        applicator,
        rail,
        mass_kg: obj.non_negative("mass_g")? * 1e-3,
    })
}

fn parse_weather(value: &Value) -> Result<Weather, String> {
    let obj = Obj::root(value)?;
    Ok(Weather {
        air_temperature_c: obj.number("air_temperature_c")?,
        relative_humidity: obj.number("relative_humidity")?,
        precipitation_mm_h: obj.non_negative("precipitation_mm_h")?,
    })
}
