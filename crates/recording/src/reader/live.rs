//! Following a recording while another process writes it (`tortwin live`).
//!
//! A logger appends to its MCAP file record by record: the magic and the
//! Header, then Channel records, Chunks (or Messages outside chunks) as they
//! fill, and only at the end the DataEnd, the summary and the Footer. The
//! follower reads each record once it is whole (its framing says how long it
//! is), waits for more where the file ends, and is finished at the DataEnd
//! (or a Footer). A half-written record is not an error: it is waited for.
//!
//! The replay order (log_time, topic, index in the file) is kept without the
//! whole file. The file must be written in time order, up to
//! [`Follow::max_delay`] (zero by default): the *horizon* is the latest
//! log_time of a message of the format read so far, less that delay. A
//! message is handed out once its log_time is before the horizon (a message
//! written later may still share its log_time and go before it by topic),
//! and every message at the end of the file; a message of the format whose
//! log_time is before the horizon when it is read is refused (`tortwin
//! replay` reads any order once the file is finished). So what the follower
//! hands out is exactly what the replay of the finished file reads, or an
//! error; and no event before the horizon is to come, which
//! [`LiveQueue::poll`] tells (the engine then rolls the trains that ended
//! before it without waiting for the next event).

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use mcap::records::{op, Record};

use super::layout::{
    add_channel, check_message_size, chunk_header, for_each_chunk_record, key_of, message_header,
    record_frame, Channels, ReplayKey, TopicRank, MAX_SMALL_RECORD_BYTES, MESSAGE_HEADER_BYTES,
    RECORD_HEADER_BYTES,
};
use super::record;
use super::replay::{MessageData, PendingMessage};
use super::MAX_CHUNK_BYTES;
use crate::error::{InputError, MessageLocation};

/// How a follower waits for a file to grow.
#[derive(Debug, Clone)]
pub struct Follow {
    /// How long to sleep when the file has nothing new.
    pub poll: Duration,
    /// How far behind the latest log_time read a message of the format may
    /// still be written (a source that reaches the logger late); messages
    /// are stepped only once the file has been read this far past them.
    /// Zero: the file is written in time order.
    pub max_delay: Duration,
    /// Set by another thread to stop the follow: the reader then ends with
    /// an error that says so ([`Follow::STOPPED`]).
    pub stop: Arc<AtomicBool>,
    /// A file its writer left unfinished (a logger that crashed mid-file
    /// and began another): once the file has not grown for the duration,
    /// the test is asked; `true` ends the file at its last whole record,
    /// as its DataEnd would.
    pub abandon: Option<(Duration, Abandoned)>,
}

/// Whether a file that stopped growing was left by its writer (see
/// [`Follow::abandon`]).
#[derive(Clone)]
pub struct Abandoned(pub Arc<dyn Fn() -> bool + Send + Sync>);

impl std::fmt::Debug for Abandoned {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Abandoned(..)")
    }
}

impl Follow {
    /// The message of the error a stopped follow ends with.
    pub const STOPPED: &'static str = "stopped while following the recording";

    pub fn new(poll: Duration) -> Self {
        Self {
            poll,
            max_delay: Duration::ZERO,
            stop: Arc::new(AtomicBool::new(false)),
            abandon: None,
        }
    }
}

/// A message read and not yet handed out, ordered by its replay key.
#[derive(Debug)]
struct Held(PendingMessage);

impl PartialEq for Held {
    fn eq(&self, other: &Self) -> bool {
        self.0.key == other.0.key
    }
}
impl Eq for Held {}
impl PartialOrd for Held {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Held {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.key.cmp(&other.0.key)
    }
}

/// The messages of a file being written, in replay order (see the module
/// documentation).
pub(super) struct LiveQueue {
    path: PathBuf,
    file: File,
    follow: Follow,
    /// The next record's offset; 0 before the opening magic was read.
    offset: u64,
    /// The DataEnd (or Footer) was read.
    finished: bool,
    channels: Channels,
    /// Messages read so far (chunks expanded): the next one's index.
    next_index: u64,
    held: BinaryHeap<Reverse<Held>>,
    /// The latest log_time of a message of the format read.
    latest_ns: Option<u64>,
    /// The first message of the format read with a log_time before the
    /// horizon, and the horizon then.
    late: Option<(ReplayKey, u64)>,
    /// The latest log_time [`LiveQueue::poll`] has told.
    told_ns: Option<u64>,
    /// When the file last grew.
    grew: std::time::Instant,
}

/// What [`LiveQueue::poll`] found.
pub(super) enum Polled {
    Message(PendingMessage),
    Time(u64),
    End,
}

impl LiveQueue {
    pub(super) fn open(path: &Path, follow: Follow) -> Result<Self, InputError> {
        let file = tortwin_files::open_input(path)
            .map_err(|e| InputError::file(path, format!("cannot open the recording: {e}")))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
            follow,
            offset: 0,
            finished: false,
            channels: Channels::default(),
            next_index: 0,
            held: BinaryHeap::new(),
            latest_ns: None,
            late: None,
            told_ns: None,
            grew: std::time::Instant::now(),
        })
    }

    fn corrupt(&self, what: String) -> InputError {
        InputError::file(&self.path, what)
    }

    /// The next message in replay order, waiting for the file to grow;
    /// `None` once the file is finished and every message handed out.
    pub(super) fn next_message(&mut self) -> Result<Option<PendingMessage>, InputError> {
        loop {
            match self.poll(false)? {
                Polled::Message(m) => return Ok(Some(m)),
                Polled::End => return Ok(None),
                Polled::Time(_) => {}
            }
        }
    }

    /// The next message, or with `times` the latest log_time read when the
    /// file has grown and no message can be handed out yet (nothing earlier
    /// than it can come: the time has passed for what is held).
    pub(super) fn poll(&mut self, times: bool) -> Result<Polled, InputError> {
        loop {
            if let Some(message) = self.release() {
                return Ok(Polled::Message(message));
            }
            if self.finished {
                return Ok(Polled::End);
            }
            if let Some(t) = self.horizon().filter(|&t| times && self.told_ns < Some(t)) {
                self.told_ns = Some(t);
                return Ok(Polled::Time(t));
            }
            if self.read_more()? {
                self.grew = std::time::Instant::now();
            } else {
                if self.follow.stop.load(Ordering::Relaxed) {
                    return Err(self.corrupt(Follow::STOPPED.to_string()));
                }
                if let Some((after, left)) = &self.follow.abandon {
                    if self.grew.elapsed() >= *after && (left.0)() {
                        // What is whole is read; the rest is lost with its writer.
                        self.finished = true;
                        continue;
                    }
                }
                std::thread::sleep(self.follow.poll);
            }
        }
    }

    /// The latest log_time read less the delay allowed: no message of the
    /// format before it is to come.
    fn horizon(&self) -> Option<u64> {
        let delay = u64::try_from(self.follow.max_delay.as_nanos()).unwrap_or(u64::MAX);
        self.latest_ns.map(|t| t.saturating_sub(delay))
    }

    /// The first message held, if nothing read later can go before it.
    fn release(&mut self) -> Option<PendingMessage> {
        let Reverse(Held(first)) = self.held.peek()?;
        let due = self.finished || self.horizon().is_some_and(|h| first.key.log_time_ns < h);
        if !due {
            return None;
        }
        let Reverse(Held(message)) = self.held.pop()?;
        Some(message)
    }

    /// Reads the whole records the file has gained; `false` if none.
    fn read_more(&mut self) -> Result<bool, InputError> {
        let io_error =
            |e: std::io::Error| InputError::file(&self.path, format!("cannot read: {e}"));
        let len = self.file.metadata().map_err(io_error)?.len();
        let magic_len = mcap::MAGIC.len() as u64;
        let mut progressed = false;
        if self.offset == 0 {
            if len < magic_len {
                return Ok(false);
            }
            let magic = self.read_at(0, magic_len)?;
            if magic != mcap::MAGIC {
                return Err(
                    self.corrupt("not an MCAP file: bad magic bytes at the start".to_string())
                );
            }
            self.offset = magic_len;
            progressed = true;
        }
        while !self.finished && len - self.offset >= RECORD_HEADER_BYTES {
            let frame = self.read_at(self.offset, RECORD_HEADER_BYTES)?;
            let (opcode, body_len) = record_frame(&frame);
            // The longest record tortwin accepts is a chunk of at most
            // MAX_CHUNK_BYTES (compressed no longer than that, or stored):
            // a longer length is corrupt, not a record still being written.
            let longest = MAX_CHUNK_BYTES + (1 << 20);
            if body_len > longest {
                return Err(self.corrupt(format!(
                    "the record at byte {} (opcode {opcode:#04x}) claims {body_len} bytes \
                     (at most {longest} are accepted)",
                    self.offset
                )));
            }
            let end = self.offset + RECORD_HEADER_BYTES + body_len;
            if end > len {
                // Half written: wait for the rest.
                break;
            }
            let at = self.offset;
            match opcode {
                op::DATA_END | op::FOOTER => self.finished = true,
                op::CHANNEL => {
                    if body_len > MAX_SMALL_RECORD_BYTES {
                        return Err(self.corrupt(format!(
                            "the Channel record at byte {at} claims {body_len} bytes (at most \
                             {MAX_SMALL_RECORD_BYTES} are accepted)"
                        )));
                    }
                    let body = self.read_at(at + RECORD_HEADER_BYTES, body_len)?;
                    match record::parse(opcode, &body) {
                        Ok(Record::Channel(channel)) => add_channel(&mut self.channels, channel)
                            .map_err(|e| self.corrupt(format!("record at byte {at}: {e}")))?,
                        Ok(_) => {}
                        Err(e) => {
                            return Err(self.corrupt(format!("corrupt record at byte {at}: {e}")))
                        }
                    }
                }
                op::CHUNK => {
                    let record = self.read_at(at, RECORD_HEADER_BYTES + body_len)?;
                    self.add_chunk(&record)
                        .map_err(|e| self.corrupt(format!("unreadable chunk at byte {at}: {e}")))?;
                }
                op::MESSAGE => {
                    if body_len < MESSAGE_HEADER_BYTES {
                        return Err(self.corrupt(format!(
                            "corrupt record at byte {at}: a Message record of {body_len} bytes \
                             (its header alone is {MESSAGE_HEADER_BYTES})"
                        )));
                    }
                    let body = self.read_at(at + RECORD_HEADER_BYTES, body_len)?;
                    let header = message_header(&body);
                    let data = body[MESSAGE_HEADER_BYTES as usize..].to_vec();
                    self.add_message(header, MessageData::whole(data))
                        .map_err(|e| self.corrupt(format!("record at byte {at}: {e}")))?;
                }
                _ => {}
            }
            self.offset = end;
            progressed = true;
        }
        self.check_order()?;
        Ok(progressed)
    }

    /// A chunk's channels and messages, in file order.
    fn add_chunk(&mut self, record: &[u8]) -> Result<(), String> {
        let header = chunk_header(record)?;
        if header.uncompressed_size > MAX_CHUNK_BYTES {
            return Err(format!(
                "it claims {} bytes uncompressed (at most {MAX_CHUNK_BYTES} are accepted)",
                header.uncompressed_size
            ));
        }
        let (start, end) = (header.message_start_time, header.message_end_time);
        let mut bytes = Vec::new();
        let mut channels = Vec::new();
        let mut messages = Vec::new();
        for_each_chunk_record(record, &header, |opcode, body| {
            match record::parse(opcode, body)? {
                Record::Channel(channel) => channels.push((messages.len(), channel)),
                Record::Message { header, data } => {
                    let from = bytes.len();
                    bytes.extend_from_slice(&data);
                    messages.push((header, from..bytes.len()));
                }
                _ => {}
            }
            Ok(())
        })?;
        let buffer = Arc::new(bytes);
        let mut channels = channels.into_iter().peekable();
        for (k, (header, range)) in messages.into_iter().enumerate() {
            // The chunk's channels before this message.
            while let Some((_, channel)) = channels.next_if(|(before, _)| *before <= k) {
                add_channel(&mut self.channels, channel)?;
            }
            if header.log_time < start || header.log_time > end {
                return Err(format!(
                    "message {} has log_time {} ns, outside the chunk's \
                     message_start_time..message_end_time ({start}..{end})",
                    self.next_index, header.log_time
                ));
            }
            self.add_message(header, MessageData::shared(&buffer, range))?;
        }
        for (_, channel) in channels {
            add_channel(&mut self.channels, channel)?;
        }
        Ok(())
    }

    fn add_message(
        &mut self,
        header: mcap::records::MessageHeader,
        data: MessageData,
    ) -> Result<(), String> {
        let key = key_of(&self.channels, &header, self.next_index)?;
        check_message_size(key, data.as_slice().len() as u64)?;
        self.next_index += 1;
        // A message on a topic the format does not know is skipped wherever
        // it comes: its time neither counts nor is checked.
        if key.topic != TopicRank::Unknown {
            if let Some(horizon) = self.horizon().filter(|&h| key.log_time_ns < h) {
                self.late.get_or_insert((key, horizon));
            }
            self.latest_ns = Some(
                self.latest_ns
                    .map_or(key.log_time_ns, |t| t.max(key.log_time_ns)),
            );
        }
        self.held.push(Reverse(Held(PendingMessage {
            key,
            channel_id: header.channel_id,
            sequence: header.sequence,
            publish_time_ns: header.publish_time,
            data,
        })));
        Ok(())
    }

    /// Refuses a message of the format read with a log_time before the
    /// horizon.
    fn check_order(&self) -> Result<(), InputError> {
        let Some((late, horizon)) = self.late else {
            return Ok(());
        };
        let topic = match late.topic {
            TopicRank::Known(topic) => topic.name().to_string(),
            TopicRank::Unknown => String::new(),
        };
        let delay = self.follow.max_delay.as_secs_f64();
        Err(InputError::at(
            &self.path,
            MessageLocation {
                topic,
                log_time_ns: late.log_time_ns,
                index_in_file: late.index_in_file,
            },
            format!(
                "written {:.3} s behind a message read before it (log_time {} ns), more than \
                 the {delay} s a followed recording may lag (--max-delay-s): its place in replay \
                 order has passed (`tortwin replay` reads any order once the file is finished)",
                (horizon - late.log_time_ns) as f64 * 1e-9 + delay,
                horizon + u64::try_from(self.follow.max_delay.as_nanos()).unwrap_or(0)
            ),
        ))
    }

    fn read_at(&mut self, offset: u64, len: u64) -> Result<Vec<u8>, InputError> {
        let mut buf = vec![0u8; len as usize];
        self.file
            .seek(SeekFrom::Start(offset))
            .and_then(|_| self.file.read_exact(&mut buf))
            .map_err(|e| InputError::file(&self.path, format!("cannot read: {e}")))?;
        Ok(buf)
    }

    pub(super) fn location(&self, message: &PendingMessage) -> MessageLocation {
        super::replay::location(&self.channels, message)
    }

    pub(super) fn channels(&self) -> &Channels {
        &self.channels
    }

    pub(super) fn path(&self) -> &Path {
        &self.path
    }
}
