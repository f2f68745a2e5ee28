//! MCAP -> typed events, in replay order, streaming.
//!
//! The replay order of docs/spec/recording-format.md is by `log_time`,
//! ties by topic (`/section`, `/train/passage`, `/applicator/pulse`,
//! `/measurement/friction`, `/environment/weather`, then unknown topics),
//! then by the message's index in the file. Files are not written in that
//! order (the reference recordings append tribometer readings at the end), so
//! the reader merges, and it must do so without holding the whole recording:
//! a recording grows with the days it covers, the engine's state only with
//! the section.
//!
//! Three parts, each in its file:
//!
//! 1. `layout`: one pass over the data section learns where the chunks
//!    and messages are, and checks every chunk, without keeping messages.
//! 2. `replay`: the messages in replay order, a chunk decompressed only
//!    when the time frontier reaches it: memory is a few chunks, not the
//!    recording.
//! 3. `decode`: each message parsed once into its wire struct and
//!    then into an [`Event`], every rule of the format checked. The
//!    `train_id`s seen so far (for the duplicate check and measurements)
//!    grow with the recording, by one entry a train.
//!
//! An error names the file and, for a message, its topic, log_time and
//! index in the file, and ends the iteration.

mod feed;
mod layout;
mod live;
mod record;
mod replay;

use std::io::BufReader;
use std::path::Path;

use crate::decode::{self, Decoder};
use crate::error::{InputError, MessageLocation};
use crate::event::{Event, EventKind, Section};
use crate::line::{self, Line};
use crate::topic::Topic;
use crate::wire::{LineMsg, MeasurementMsg, PassageMsg, PulseMsg, SectionMsg, WeatherMsg};
use layout::{ReplayKey, TopicRank};
pub use layout::{MAX_CHUNK_BYTES, MAX_MESSAGE_BYTES};
pub use live::{Abandoned, Follow};
use live::{LiveQueue, Polled};
use replay::{PendingMessage, ReplayQueue};

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

/// Reads a recording as validated [`Event`]s in replay order; see the module
/// documentation for how it bounds memory. The iterator stops after the first
/// error.
pub struct RecordingReader {
    queue: Queue,
    /// A message taken after the `/section` to look for a `/line`, not yet
    /// decoded (a followed file).
    taken: Option<PendingMessage>,
    decoder: Decoder,
    /// The `/section` message as written (g, rail names).
    section_msg: SectionMsg,
    section_log_time_ns: u64,
    unknown_topic_messages: u64,
    layout: LayoutSummary,
    finished: bool,
    /// With the layout pass beside the replay: what the reader saw, for
    /// its verdict.
    beside: Option<Beside>,
}

/// How a file holds its messages (from the layout pass): what the replay
/// keeps in memory grows with the chunks that overlap in time and with the
/// runs, not with the messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LayoutSummary {
    /// Messages in the file, every topic.
    pub messages: u64,
    pub chunks: u64,
    /// Messages outside chunks.
    pub loose_messages: u64,
    /// Runs of messages outside chunks already in replay order: 1 for an
    /// unchunked file written in time order.
    pub loose_runs: u64,
}

impl LayoutSummary {
    fn of(layout: &layout::Layout) -> Self {
        let loose_messages = layout.loose.iter().map(|r| r.message_count).sum::<u64>();
        LayoutSummary {
            messages: layout.chunks.iter().map(|c| c.message_count).sum::<u64>() + loose_messages,
            chunks: layout.chunks.len() as u64,
            loose_messages,
            loose_runs: layout.loose.len() as u64,
        }
    }
}

impl RecordingReader {
    /// Opens a recording, lays out its chunks and reads and checks its
    /// `/section` message, which must be the first message in replay order
    /// and the only one of its topic.
    pub fn open(path: &Path, ctx: ReaderContext) -> Result<Self, InputError> {
        let file = tortwin_files::open_input(path)
            .map_err(|e| InputError::file(path, format!("cannot open the recording: {e}")))?;
        Self::lay_out(path, BufReader::new(file), ctx)
    }

    /// [`Self::open`] with the layout pass beside the replay (module `feed`):
    /// the first events come before every chunk has been checked, and the
    /// same errors as from [`Self::open`] come first. What the pass finds
    /// wrong with the file, and what [`Self::open`] would have refused
    /// once it was laid out (a second `/section`, a `/line` out of place),
    /// is the error the reader reports, instead of one found later in the
    /// replay (the events before it are those [`Self::open`] would have
    /// given had the file been sound). A caller that stops on an error of
    /// its own asks [`Self::layout_verdict`] first. [`Self::message_count`]
    /// is the Message Index records' count until the pass has ended.
    /// A file that does not say where its chunks are without decompressing
    /// them ([`layout::chunk_heads`]), or whose chunks hold more than
    /// [`layout::KEPT_CHUNK_BYTES`] uncompressed (more than the pass keeps
    /// for the replay), is laid out first, as by [`Self::open`].
    pub fn open_beside(path: &Path, ctx: ReaderContext) -> Result<Self, InputError> {
        let opened = tortwin_files::open_input(path)
            .map_err(|e| InputError::file(path, format!("cannot open the recording: {e}")))?;
        let mut file = BufReader::new(opened);
        // The pass reads through a handle of its own, on the same file.
        let second = std::fs::File::open(path)
            .ok()
            .filter(|second| same_file(file.get_ref(), second));
        // Beside the replay only while the pass keeps every chunk it reads
        // for it: then the pass does the replay's decompressing. Past that
        // it decompresses each chunk once more than the replay, on the
        // cores the replay wants, and it would not be done sooner: a
        // recording's last chunk, of measurements appended, is due early,
        // and the replay waits for it to be added (the year: 13.0-13.2 s
        // beside the replay against 12.6-12.8 s laid out first).
        let heads = layout::chunk_heads(&mut file)
            .filter(|heads| heads.uncompressed_bytes <= layout::KEPT_CHUNK_BYTES);
        let (Some(heads), Some(second)) = (heads, second) else {
            return Self::lay_out(path, file, ctx);
        };
        let Ok(feed) = feed::Feed::start(path, second) else {
            return Self::lay_out(path, file, ctx);
        };
        let summary = LayoutSummary {
            messages: heads.indexed_messages,
            chunks: heads.chunks.len() as u64,
            loose_messages: 0,
            loose_runs: 0,
        };
        let queue = Queue::Replay(ReplayQueue::beside(path, file, heads.chunks, feed));
        Self::start(path, queue, Start::Beside, summary, ctx)
    }

    /// Lays the file out whole, then reads its `/section` (and `/line`).
    fn lay_out(
        path: &Path,
        mut file: BufReader<std::fs::File>,
        ctx: ReaderContext,
    ) -> Result<Self, InputError> {
        let layout = layout::scan_layout(path, &mut file)?;
        if layout.sections.is_empty() {
            return Err(InputError::file(
                path,
                "the recording has no /section message",
            ));
        }
        let summary = LayoutSummary::of(&layout);
        let keys = Keys {
            sections: layout.sections,
            lines: layout.lines,
        };
        let queue = Queue::Replay(ReplayQueue::new(
            path,
            file,
            layout.channels,
            layout.chunks,
            layout.loose,
            false,
        ));
        Self::start(path, queue, Start::Laid(&keys), summary, ctx)
    }

    /// Follows a recording another process is still writing
    /// ([`Follow`]; the module `live`): the same events as [`Self::open`]
    /// of the finished file, each once it can be known to be next. Waits
    /// here for the `/section` message (and a `/line`).
    pub fn follow(path: &Path, ctx: ReaderContext, follow: Follow) -> Result<Self, InputError> {
        let queue = Queue::Live(LiveQueue::open(path, follow)?);
        Self::start(path, queue, Start::Followed, LayoutSummary::default(), ctx)
    }

    /// Reads and checks the `/section` (and `/line`) from `queue`: with the
    /// file's layout where it was laid out, else as they come; beside the
    /// layout pass, an error is the one the layout would have given first
    /// ([`verdict`]).
    fn start(
        path: &Path,
        mut queue: Queue,
        mode: Start<'_>,
        summary: LayoutSummary,
        ctx: ReaderContext,
    ) -> Result<Self, InputError> {
        let mut seen = Seen::default();
        let beside = matches!(mode, Start::Beside);
        // Beside the layout pass, an error at `phase` waits for its verdict.
        let fail = |queue: &mut Queue, seen: &Seen, phase: Phase, e: InputError| match beside {
            true => verdict(queue, seen, phase).err().unwrap_or(e),
            false => e,
        };
        let no_section = || InputError::file(path, "the recording has no /section message");
        let first = match queue.next_message() {
            Ok(Some(first)) => first,
            Ok(None) => return Err(fail(&mut queue, &seen, Phase::First, no_section())),
            Err(e) => return Err(fail(&mut queue, &seen, Phase::First, e)),
        };
        let first_location = queue.location(&first);
        seen.first = Some((first.key, first_location.clone()));
        let at_first = |message: String| InputError::at(path, first_location.clone(), message);
        let section = match mode {
            Start::Laid(keys) => check_sections(path, keys, first.key, &first_location),
            Start::Followed | Start::Beside => {
                if first.key.topic == TopicRank::Known(Topic::Section) {
                    Ok(())
                } else {
                    Err(at_first(
                        "the first message in replay order is not the /section message; \
                         /section must be the first message of a recording"
                            .to_string(),
                    ))
                }
            }
        }
        .and_then(|()| queue.check_json(&first))
        .and_then(|()| {
            decode::parse::<SectionMsg>(first.data.as_slice()).map_err(|e| at_first(e.message))
        })
        .and_then(|msg| {
            let section = decode::section(&msg).map_err(|e| at_first(e.message))?;
            Ok((msg, section))
        });
        let (msg, section) = match section {
            Ok(read) => read,
            Err(e) => return Err(fail(&mut queue, &seen, Phase::Section, e)),
        };
        seen.section_log_time_ns = first.key.log_time_ns;
        let line = match mode {
            Start::Laid(keys) => read_line(
                path,
                &mut queue,
                &keys.lines,
                &section,
                first.key.log_time_ns,
            )
            .map(|line| (line, None)),
            Start::Followed => follow_line(path, &mut queue, &section, first.key.log_time_ns),
            Start::Beside => queue.next_message().and_then(|next| {
                seen.after_section = Some(next.as_ref().map(|m| m.key));
                line_or_next(path, &queue, next, &section, first.key.log_time_ns)
            }),
        };
        let (line, taken) = match line {
            Ok(read) => read,
            Err(e) => return Err(fail(&mut queue, &seen, Phase::Line, e)),
        };
        let origin_ns = match ctx.origin_ns {
            Some(origin_ns) => origin_ns,
            None => match i64::try_from(first.key.log_time_ns) {
                Ok(origin_ns) => origin_ns,
                Err(_) => {
                    let e = at_first(
                        "log_time does not fit a signed 64-bit nanosecond count".to_string(),
                    );
                    return Err(fail(&mut queue, &seen, Phase::Later, e));
                }
            },
        };
        Ok(Self {
            queue,
            taken,
            decoder: Decoder::new(section, line, origin_ns, ctx.occupied_until_s),
            section_msg: msg,
            section_log_time_ns: first.key.log_time_ns,
            unknown_topic_messages: 0,
            layout: summary,
            finished: false,
            beside: beside.then_some(Beside {
                seen,
                verdict: None,
            }),
        })
    }

    /// Beside the layout pass ([`Self::open_beside`]): waits for it to end
    /// and returns what [`Self::open`] would have refused the file for
    /// (the first thing wrong with it), or `Ok` if nothing; the
    /// layout's counts are then the file's. A caller that stops on an
    /// error of its own reports this one instead. Always `Ok` for a file
    /// laid out before the replay.
    pub fn layout_verdict(&mut self) -> Result<(), InputError> {
        let Some(beside) = &mut self.beside else {
            return Ok(());
        };
        if let Some(verdict) = &beside.verdict {
            return verdict.clone();
        }
        let verdict = verdict(&mut self.queue, &beside.seen, Phase::Later);
        if let Some(layout) = self.queue.laid_out() {
            self.layout = layout;
        }
        beside.verdict = Some(verdict.clone());
        verdict
    }

    /// How many messages the file holds (every topic, `/section` included):
    /// the length of a replay, for a progress display.
    pub fn message_count(&self) -> u64 {
        self.layout.messages
    }

    /// How the file holds its messages.
    pub fn layout(&self) -> LayoutSummary {
        self.layout
    }

    /// The recording's `/line` (line.md); `None` for a section.
    pub fn line(&self) -> Option<&Line> {
        self.decoder.line()
    }

    /// The `/section` message as it is on the wire (grams, rail names).
    pub fn section_msg(&self) -> &SectionMsg {
        &self.section_msg
    }

    pub fn section(&self) -> &Section {
        self.decoder.section()
    }

    pub fn section_log_time_ns(&self) -> u64 {
        self.section_log_time_ns
    }

    /// The replay's time origin: the context's, or this `/section` log_time.
    pub fn origin_ns(&self) -> i64 {
        self.decoder.origin_ns()
    }

    /// Messages on unknown topics skipped so far.
    pub fn unknown_topic_messages(&self) -> u64 {
        self.unknown_topic_messages
    }

    /// Time (s from the origin) at which the last train read so far leaves
    /// the section: its `t_passage + (length_m + offset of its last axle) /
    /// speed_mps`; the context's value before the first passage.
    pub fn occupied_until_s(&self) -> f64 {
        self.decoder.occupied_until_s()
    }

    /// The next message of the format as written, with its event: every
    /// rule checked as for the events alone. What `tortwin export` writes
    /// back as tables, in the recording's own units and digits (converting
    /// an event's kg back to g need not give the same number).
    pub fn next_with_wire(&mut self) -> Option<Result<(Event, Wire), InputError>> {
        loop {
            match self.step(false, true)? {
                Ok(Step::Event(event, Some(wire))) => return Some(Ok((event, wire))),
                Ok(_) => continue,
                Err(e) => return Some(Err(e)),
            }
        }
    }

    /// The next event of a followed recording ([`Self::follow`]), or the
    /// time up to which the file has been read when it has grown and no
    /// event can be handed out yet ([`Followed::Time`]); `None` at the
    /// end. A reader of a finished file gives its events.
    pub fn next_followed(&mut self) -> Option<Result<Followed, InputError>> {
        self.step(true, false).map(|step| {
            step.map(|step| match step {
                Step::Event(event, _) => Followed::Event(event),
                Step::Time(t) => Followed::Time(t),
            })
        })
    }

    /// The next message decoded (with its wire message if `keep_wire`), or
    /// with `times` the time a followed file has been read to; `None` at the
    /// end. An error ends the reading.
    fn step(&mut self, times: bool, keep_wire: bool) -> Option<Result<Step, InputError>> {
        while !self.finished {
            let message = match (self.taken.take(), &mut self.queue) {
                (Some(m), _) => Ok(Some(m)),
                (None, Queue::Live(q)) => match q.poll(times) {
                    Ok(Polled::Message(m)) => Ok(Some(m)),
                    Ok(Polled::Time(t)) => return Some(Ok(Step::Time(t))),
                    Ok(Polled::End) => Ok(None),
                    Err(e) => Err(e),
                },
                (None, Queue::Replay(q)) => q.next_message(),
            };
            let decoded = match message {
                Ok(Some(message)) => self.decode(message, keep_wire),
                Ok(None) => {
                    self.finished = true;
                    // Beside the layout pass, the file is sound only once
                    // it has ended.
                    return self.layout_verdict().err().map(Err);
                }
                Err(e) => Err(e),
            };
            match decoded {
                Ok(Some((event, wire))) => return Some(Ok(Step::Event(event, wire))),
                Ok(None) => continue,
                Err(e) => {
                    self.finished = true;
                    return Some(Err(self.layout_verdict().err().unwrap_or(e)));
                }
            }
        }
        None
    }

    fn decode(
        &mut self,
        message: PendingMessage,
        keep_wire: bool,
    ) -> Result<Option<(Event, Option<Wire>)>, InputError> {
        let TopicRank::Known(topic) = message.key.topic else {
            self.unknown_topic_messages += 1;
            return Ok(None);
        };
        self.queue.check_json(&message)?;
        let log_time_ns = message.key.log_time_ns;
        let data = message.data.as_slice();
        let decoder = &mut self.decoder;
        if let Err(e) = decode::log_time(log_time_ns) {
            let location = self.queue.location(&message);
            return Err(InputError::at(self.queue.path(), location, e.message));
        }
        // Built only when kept: a passage's or a measurement's wire message
        // is cloned for it.
        let keep = |wire: &dyn Fn() -> Wire| keep_wire.then(wire);
        let decoded = match topic {
            Topic::Section => Err(format!(
                "a second /section message (the first is at log_time {} ns); \
                 a recording has exactly one",
                self.section_log_time_ns
            )
            .into()),
            // The one `/line` was read with the section (`read_line`).
            Topic::Line if decoder.line().is_none() => Err(
                "the /line message is not next after the /section in replay order; \
                 a line is given with its section"
                    .to_string()
                    .into(),
            ),
            Topic::Line => Err("a second /line message; a recording has at most one"
                .to_string()
                .into()),
            // Passages are most of a recording's bytes: those in the
            // compact shape are read without serde too.
            Topic::Passage => match (!keep_wire)
                .then(|| decode::compact_passage(data))
                .flatten()
            {
                Some(fields) => decoder
                    .passage(fields, log_time_ns)
                    .map(|p| (EventKind::Passage(p), None)),
                None => decode::parse::<PassageMsg>(data).and_then(|msg| {
                    let p = decoder.passage((&msg).into(), log_time_ns)?;
                    Ok((EventKind::Passage(p), keep(&|| Wire::Passage(msg.clone()))))
                }),
            },
            // A pulse in the compact shape is read without serde too.
            Topic::Pulse => match (!keep_wire).then(|| decode::compact_pulse(data)).flatten() {
                Some(fields) => decoder.pulse(fields).map(|p| (EventKind::Pulse(p), None)),
                None => decode::parse::<PulseMsg>(data).and_then(|msg| {
                    let p = decoder.pulse((&msg).into())?;
                    Ok((EventKind::Pulse(p), keep_wire.then_some(Wire::Pulse(msg))))
                }),
            },
            // Most messages are measurements: those in the compact shape are
            // read without serde (decode/compact.rs), unless the wire
            // message is kept.
            Topic::Measurement => match (!keep_wire)
                .then(|| decode::compact_measurement(data))
                .flatten()
            {
                Some(fields) => decoder
                    .measurement(fields)
                    .map(|m| (EventKind::Measurement(m), None)),
                None => decode::parse::<MeasurementMsg>(data).and_then(|msg| {
                    let m = decoder.measurement((&msg).into())?;
                    Ok((
                        EventKind::Measurement(m),
                        keep_wire.then_some(Wire::Measurement(msg)),
                    ))
                }),
            },
            Topic::Weather => decode::parse::<WeatherMsg>(data).and_then(|msg| {
                let w = decoder.weather(&msg)?;
                Ok((
                    EventKind::Weather(w),
                    keep_wire.then_some(Wire::Weather(msg)),
                ))
            }),
        }
        .map_err(|e: decode::DecodeError| {
            InputError::at(self.queue.path(), self.queue.location(&message), e.message)
        })?;
        let (kind, wire) = decoded;
        Ok(Some((
            Event {
                log_time_ns,
                index_in_file: message.key.index_in_file,
                kind,
            },
            wire,
        )))
    }
}

/// The `/line` message (line.md) of a recording whose `/section` was just
/// read at `section_log_time_ns`, checked against it: at the section's
/// log_time (so the next message in replay order), at most one.
fn read_line(
    path: &Path,
    queue: &mut Queue,
    lines: &[ReplayKey],
    section: &Section,
    section_log_time_ns: u64,
) -> Result<Option<Line>, InputError> {
    let Some(first) = check_lines(path, lines, section_log_time_ns)? else {
        return Ok(None);
    };
    let message = match queue.next_message()? {
        Some(message) => message,
        // The end of the file: refused.
        None => return line_is_next(path, first, None).map(|()| None),
    };
    line_is_next(path, first, Some(message.key))?;
    queue.check_json(&message)?;
    let at = |text: String| InputError::at(path, line_location(&first), text);
    let msg: LineMsg = decode::parse(message.data.as_slice()).map_err(|e| at(e.message))?;
    line::decode(&msg, section)
        .map(Some)
        .map_err(|e| at(e.message))
}

/// Where the `/line` message with `key` is.
fn line_location(key: &ReplayKey) -> MessageLocation {
    MessageLocation {
        topic: Topic::Line.name().to_string(),
        log_time_ns: key.log_time_ns,
        index_in_file: key.index_in_file,
    }
}

/// The first of a laid-out file's `/line` messages (`lines`, the first two
/// in replay order), checked to be at the `/section`'s log_time and the
/// only one; `None` for a section.
fn check_lines(
    path: &Path,
    lines: &[ReplayKey],
    section_log_time_ns: u64,
) -> Result<Option<ReplayKey>, InputError> {
    let Some(&first) = lines.first() else {
        return Ok(None);
    };
    if first.log_time_ns != section_log_time_ns {
        return Err(InputError::at(
            path,
            line_location(&first),
            format!(
                "the /line message is not at the /section's log_time ({section_log_time_ns} ns); \
                 a line is given with its section"
            ),
        ));
    }
    if let Some(second) = lines.get(1) {
        return Err(InputError::at(
            path,
            line_location(second),
            format!(
                "a second /line message (the first is message {}); a recording has at most one",
                first.index_in_file
            ),
        ));
    }
    Ok(Some(first))
}

/// Checks that the message after the `/section` in replay order (`next`,
/// `None` at the end of the file) is the `/line` with key `line`.
fn line_is_next(path: &Path, line: ReplayKey, next: Option<ReplayKey>) -> Result<(), InputError> {
    let at = |text: &str| InputError::at(path, line_location(&line), text.to_string());
    match next {
        None => Err(at("the /line message could not be read")),
        Some(key) if key != line => Err(at(
            "the /line message is not next after the /section in replay order",
        )),
        Some(_) => Ok(()),
    }
}

/// Checks a laid-out file's first message in replay order (`first`, at
/// `location`) against its `/section` messages (the first two in replay
/// order, at least one): the first must be it, and the only one.
fn check_sections(
    path: &Path,
    keys: &Keys,
    first: ReplayKey,
    location: &MessageLocation,
) -> Result<(), InputError> {
    let first_section = keys.sections[0];
    if first != first_section {
        return Err(InputError::at(
            path,
            location.clone(),
            format!(
                "log_time {} ns is earlier than the /section message's ({} ns); \
                 /section must be the first message of a recording",
                first.log_time_ns, first_section.log_time_ns
            ),
        ));
    }
    if let Some(second) = keys.sections.get(1) {
        return Err(InputError::at(
            path,
            MessageLocation {
                topic: Topic::Section.name().to_string(),
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
    Ok(())
}

/// Whether two handles are on the same file (device and inode).
fn same_file(a: &std::fs::File, b: &std::fs::File) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (a.metadata(), b.metadata()) {
        (Ok(a), Ok(b)) => (a.dev(), a.ino()) == (b.dev(), b.ino()),
        _ => false,
    }
}

/// Whether the file at `path` ends as a finished MCAP file does: a Footer
/// record and the closing magic (a file a logger is writing ends in another
/// record, or is its opening magic alone). Such a file is read with
/// [`RecordingReader::open`], in any order, rather than followed.
pub fn looks_finished(path: &Path) -> bool {
    use std::io::{Read, Seek, SeekFrom};
    // Footer: opcode, length 20, summary_start u64, summary_offset_start
    // u64, summary_crc u32; then the magic.
    const FOOTER_BODY: u64 = 20;
    let magic = mcap::MAGIC;
    let tail_len = layout::RECORD_HEADER_BYTES + FOOTER_BODY + magic.len() as u64;
    let Ok(mut file) = std::fs::File::open(path) else {
        return false;
    };
    let mut tail = vec![0u8; tail_len as usize];
    let read = file
        .seek(SeekFrom::End(-(tail_len as i64)))
        .and_then(|_| file.read_exact(&mut tail));
    if read.is_err() {
        return false;
    }
    let (opcode, len) = layout::record_frame(&tail);
    opcode == mcap::records::op::FOOTER
        && len == FOOTER_BODY
        && tail[tail.len() - magic.len()..] == *magic
}

/// A step of [`RecordingReader::next_followed`].
#[derive(Debug, Clone, PartialEq)]
pub enum Followed {
    /// The next event in replay order.
    Event(Event),
    /// No event earlier than this log_time is to come.
    Time(u64),
}

/// A step of [`RecordingReader::step`].
enum Step {
    Event(Event, Option<Wire>),
    Time(u64),
}

/// Where a laid-out file's first two `/section` and `/line` messages are.
struct Keys {
    sections: Vec<ReplayKey>,
    lines: Vec<ReplayKey>,
}

/// The messages a reader takes: a finished file's, laid out, or a file's
/// being written, as they come.
enum Queue {
    Replay(ReplayQueue),
    Live(LiveQueue),
}

impl Queue {
    /// Beside the layout pass, once it has ended well: how the file holds
    /// its messages.
    fn laid_out(&mut self) -> Option<LayoutSummary> {
        match self {
            Queue::Replay(q) => q.finish_layout()?.ok().map(LayoutSummary::of),
            Queue::Live(_) => None,
        }
    }

    fn next_message(&mut self) -> Result<Option<PendingMessage>, InputError> {
        match self {
            Queue::Replay(q) => q.next_message(),
            Queue::Live(q) => q.next_message(),
        }
    }

    fn location(&self, message: &PendingMessage) -> MessageLocation {
        match self {
            Queue::Replay(q) => q.location(message),
            Queue::Live(q) => q.location(message),
        }
    }

    fn check_json(&self, message: &PendingMessage) -> Result<(), InputError> {
        match self {
            Queue::Replay(q) => q.check_json(message),
            Queue::Live(q) => {
                let channel = q.channels().get(&message.channel_id);
                match channel {
                    Some(c) if c.message_encoding == "json" => Ok(()),
                    _ => Err(InputError::at(
                        q.path(),
                        q.location(message),
                        format!(
                            "message encoding is `{}`; this topic must be `json`",
                            channel.map_or("", |c| c.message_encoding.as_str())
                        ),
                    )),
                }
            }
        }
    }

    fn path(&self) -> &Path {
        match self {
            Queue::Replay(q) => q.path(),
            Queue::Live(q) => q.path(),
        }
    }
}

/// A followed file's `/line`: the message after the `/section` in replay
/// order, if it is one (then at the section's log_time); else that message
/// is handed back, to be decoded first.
fn follow_line(
    path: &Path,
    queue: &mut Queue,
    section: &Section,
    section_log_time_ns: u64,
) -> Result<(Option<Line>, Option<PendingMessage>), InputError> {
    let next = queue.next_message()?;
    line_or_next(path, queue, next, section, section_log_time_ns)
}

/// The `/line` if `next` (the message after the `/section` in replay
/// order) is one, else `next` handed back.
fn line_or_next(
    path: &Path,
    queue: &Queue,
    next: Option<PendingMessage>,
    section: &Section,
    section_log_time_ns: u64,
) -> Result<(Option<Line>, Option<PendingMessage>), InputError> {
    let Some(message) = next else {
        return Ok((None, None));
    };
    if message.key.topic != TopicRank::Known(Topic::Line) {
        return Ok((None, Some(message)));
    }
    let at = |text: String| InputError::at(path, queue.location(&message), text);
    if message.key.log_time_ns != section_log_time_ns {
        return Err(at(format!(
            "the /line message is not at the /section's log_time ({section_log_time_ns} ns); \
             a line is given with its section"
        )));
    }
    queue.check_json(&message)?;
    let msg: LineMsg = decode::parse(message.data.as_slice()).map_err(|e| at(e.message))?;
    let line = line::decode(&msg, section).map_err(|e| at(e.message))?;
    Ok((Some(line), None))
}

/// How [`RecordingReader::start`] knows where the `/section` and `/line`
/// are.
enum Start<'a> {
    /// From the file's layout.
    Laid(&'a Keys),
    /// As they come, from a file being written.
    Followed,
    /// As they come, the layout pass beside the replay checking them after.
    Beside,
}

/// What a reader beside the layout pass saw of the messages whose places
/// the layout checks ([`verdict`]).
#[derive(Debug, Default)]
struct Seen {
    /// The first message in replay order: its key and where it is.
    first: Option<(ReplayKey, MessageLocation)>,
    section_log_time_ns: u64,
    /// The key of the message after the `/section` (`None`: the end of
    /// the file), once read.
    after_section: Option<Option<ReplayKey>>,
}

/// A reader beside the layout pass: what it saw, and its verdict once
/// asked.
struct Beside {
    seen: Seen,
    verdict: Option<Result<(), InputError>>,
}

/// Where a reader beside the layout pass was when an error arose, in the
/// order [`RecordingReader::start`] checks a laid-out file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Phase {
    /// Reading the first message.
    First,
    /// Reading the `/section`.
    Section,
    /// Reading the `/line`.
    Line,
    /// After both.
    Later,
}

/// Beside the layout pass: waits for it to end, then makes the checks
/// [`RecordingReader::start`] makes of a laid-out file before its events,
/// those before `phase`. The error they find is the one the reader reports
/// instead of one that arose at `phase`; `Ok` if they find none (the error
/// at `phase` stands). `Ok` for a reader not beside the pass.
fn verdict(queue: &mut Queue, seen: &Seen, phase: Phase) -> Result<(), InputError> {
    let path = queue.path().to_path_buf();
    let Queue::Replay(replay) = queue else {
        return Ok(());
    };
    let Some(layout) = replay.finish_layout() else {
        return Ok(());
    };
    let layout = layout?;
    let keys = Keys {
        sections: layout.sections.clone(),
        lines: layout.lines.clone(),
    };
    if keys.sections.is_empty() {
        return Err(InputError::file(
            &path,
            "the recording has no /section message",
        ));
    }
    let Some((first, location)) = seen.first.as_ref().filter(|_| phase > Phase::First) else {
        return Ok(());
    };
    check_sections(&path, &keys, *first, location)?;
    if phase == Phase::Section {
        return Ok(());
    }
    if let Some(line) = check_lines(&path, &keys.lines, seen.section_log_time_ns)? {
        // A read that failed is the error at `phase`.
        if let Some(next) = seen.after_section {
            line_is_next(&path, line, next)?;
        }
    }
    Ok(())
}

/// A batch of [`read_ahead`] is handed over once its events weigh this
/// much: an event 1, a passage 1 more per axle (its axles are most of its
/// memory), so a batch holds 256 measurements or pulses, or a few trains.
const READ_AHEAD_BATCH: usize = 256;

/// Batches queued between the reading thread and the consumer. Reading
/// ahead by about sixteen trains lets the reader work while the engine
/// rolls one track alone (the year's replay: 17.4 s where two batches gave
/// 18.2 s, both cores 178 % busy instead of 171 %); at most 18 batches are
/// in flight: a few MB even with trains of a thousand axles.
const READ_AHEAD_QUEUE: usize = 16;

/// How much an event counts towards [`READ_AHEAD_BATCH`].
fn read_ahead_weight(event: &Result<Event, InputError>) -> usize {
    match event {
        Ok(Event {
            kind: EventKind::Passage(p),
            ..
        }) => 1 + p.axles.len(),
        _ => 1,
    }
}

/// Runs `consume` over `reader`'s events while a thread of its own reads
/// them ahead (decompressing chunks, merging, parsing JSON and checking
/// every rule), a few batches in front; returns what `consume` returned
/// (the reader is the caller's again, for its counts and its
/// [`RecordingReader::layout_verdict`]). The events come in the same order as
/// from the reader itself; when `consume` stops early, the thread stops at
/// its next batch. The reading thread runs behind the engine
/// ([`tortwin_handover::behind_the_engine`]): a batch replay's reader.
pub fn read_ahead<T>(reader: &mut RecordingReader, consume: impl FnOnce(&mut ReadAhead) -> T) -> T {
    type Batch = Vec<Result<Event, InputError>>;
    let (mut batches, incoming) = tortwin_handover::channel::<Batch>(READ_AHEAD_QUEUE);
    std::thread::scope(|scope| {
        let producer = scope.spawn(move || {
            tortwin_handover::behind_the_engine();
            loop {
                let batch = batches.batch();
                let mut ended = false;
                let mut weight = 0;
                while weight < READ_AHEAD_BATCH {
                    match reader.next() {
                        Some(event) => {
                            weight += read_ahead_weight(&event);
                            batch.push(event);
                        }
                        None => {
                            ended = true;
                            break;
                        }
                    }
                }
                // The consumer pops from the end.
                batch.reverse();
                // An error: the consumer stopped early.
                if batches.hand_over().is_err() || ended {
                    return;
                }
            }
        });
        let mut events = ReadAhead {
            incoming,
            current: Vec::new(),
        };
        let out = consume(&mut events);
        drop(events);
        match producer.join() {
            Ok(()) => out,
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}

/// The events of [`read_ahead`], in replay order.
pub struct ReadAhead {
    incoming: tortwin_handover::Taker<Vec<Result<Event, InputError>>>,
    /// The batch being taken, the next event last.
    current: Vec<Result<Event, InputError>>,
}

impl Iterator for ReadAhead {
    type Item = Result<Event, InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(event) = self.current.pop() {
                return Some(event);
            }
            let next = self.incoming.take()?;
            let used = std::mem::replace(&mut self.current, next);
            self.incoming.give_back(used);
        }
    }
}

/// Every message of an MCAP file as written (any topic, any encoding), in
/// replay order: the reader's layout pass and merge without the format's
/// rules. What the MCAP conformance tests read
/// (crates/recording/tests/mcap_conformance.rs), and what cutting a
/// recording into days and merging days copy ([`crate::cut`]).
pub struct RawMessages {
    queue: ReplayQueue,
    finished: bool,
}

/// A message of [`RawMessages`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawMessage {
    pub channel_id: u16,
    pub topic: String,
    pub message_encoding: String,
    pub sequence: u32,
    pub log_time_ns: u64,
    pub publish_time_ns: u64,
    /// Its place among the file's messages (chunks expanded), from 0.
    pub index_in_file: u64,
    pub data: Vec<u8>,
}

impl RawMessages {
    /// Lays out the file (every chunk checked) as [`RecordingReader::open`]
    /// does.
    pub fn open(path: &Path) -> Result<Self, InputError> {
        let file = tortwin_files::open_input(path)
            .map_err(|e| InputError::file(path, format!("cannot open the recording: {e}")))?;
        let mut file = BufReader::new(file);
        let layout = layout::scan_layout(path, &mut file)?;
        Ok(Self {
            queue: ReplayQueue::new(
                path,
                file,
                layout.channels,
                layout.chunks,
                layout.loose,
                true,
            ),
            finished: false,
        })
    }

    /// The channels: id, topic and message encoding.
    pub fn channels(&self) -> Vec<(u16, String, String)> {
        let mut channels: Vec<_> = self
            .queue
            .channels()
            .iter()
            .map(|(&id, c)| (id, c.topic.clone(), c.message_encoding.clone()))
            .collect();
        channels.sort();
        channels
    }
}

impl Iterator for RawMessages {
    type Item = Result<RawMessage, InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.finished {
            return None;
        }
        let message = match self.queue.next_message() {
            Ok(Some(m)) => m,
            Ok(None) => {
                self.finished = true;
                return None;
            }
            Err(e) => {
                self.finished = true;
                return Some(Err(e));
            }
        };
        let (topic, message_encoding) = self
            .queue
            .channels()
            .get(&message.channel_id)
            .map(|c| (c.topic.clone(), c.message_encoding.clone()))
            .unwrap_or_default();
        Some(Ok(RawMessage {
            channel_id: message.channel_id,
            topic,
            message_encoding,
            sequence: message.sequence,
            log_time_ns: message.key.log_time_ns,
            publish_time_ns: message.publish_time_ns,
            index_in_file: message.key.index_in_file,
            data: message.data.as_slice().to_vec(),
        }))
    }
}

/// A message of the format other than `/section`, as it is on the wire.
#[derive(Debug, Clone, PartialEq)]
pub enum Wire {
    Passage(PassageMsg),
    Pulse(PulseMsg),
    Measurement(MeasurementMsg),
    Weather(WeatherMsg),
}

impl Iterator for RecordingReader {
    type Item = Result<Event, InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            match self.step(false, false)? {
                Ok(Step::Event(event, _)) => return Some(Ok(event)),
                Ok(Step::Time(_)) => continue,
                Err(e) => return Some(Err(e)),
            }
        }
    }
}
