//! Recordings cut into service days and days merged into one recording,
//! streaming: the messages go from file to file as written (their bytes,
//! every topic, unknown ones too), in replay order, never all in memory.
//!
//! A service day holds the messages from its first train's passage (its
//! UTC date) to the next day's first passage, so that no train is in the
//! section at a cut; the first day also holds what comes before its first
//! train. Each day's file opens with the `/section` message, logged at the
//! day's first passage (the first day's at its own log_time), and on a
//! line its `/line` at the same time. Merging is the inverse: the first
//! recording's `/section` (and `/line`), then every other message of every
//! recording; each later `/section` and `/line` must be the first one's.
//!
//! The outputs are written under temporary names and moved into place
//! whole: all the days of a cut appear together, or none.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use chrono::DateTime;

use crate::decode;
use crate::error::{ConvertError, InputError, MessageLocation, WriteError};
use crate::reader::{RawMessage, RawMessages};
use crate::topic::Topic;
use crate::wire::{LineMsg, SectionMsg};
use crate::writer::RecordingWriter;

/// One service day of a cut.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Day {
    /// `YYYY-MM-DD`, the UTC date of its first passage.
    pub date: String,
    pub path: PathBuf,
    pub messages: u64,
}

/// Cuts `input` into one recording per service day,
/// `folder/YYYY-MM-DD.mcap` (the folder is made if missing; files of
/// those names in it are replaced). Two passes over the input: the first
/// finds each day's first passage, the second copies.
pub fn split_by_day(input: &Path, folder: &Path) -> Result<Vec<Day>, ConvertError> {
    let starts = first_passages(input)?;
    let staged = tortwin_files::StagedFolder::beside(folder)?;
    let mut raw = RawMessages::open(input)?;
    let Opening {
        section,
        line,
        next,
    } = opening(input, &mut raw)?;
    let mut days: Vec<Day> = Vec::with_capacity(starts.len());
    let mut out: Option<Output> = None;
    for m in next.map(Ok).into_iter().chain(raw) {
        let m = m?;
        // The day of a message: the last whose first passage is not later.
        let k = starts
            .partition_point(|(_, start)| *start <= m.log_time_ns)
            .saturating_sub(1);
        if out.as_ref().is_none_or(|o| o.day != k) {
            if let Some(o) = out.take() {
                days.push(o.finish()?);
            }
            let (date, start) = &starts[k];
            let path = staged.path().join(format!("{date}.mcap"));
            let mut o = Output::create(path, k, date.clone())?;
            let at = (k > 0).then_some(*start);
            o.copy(&section, at)?;
            if let Some(line) = &line {
                o.copy(line, at)?;
            }
            out = Some(o);
        }
        if let Some(o) = out.as_mut() {
            o.copy(&m, None)?;
        }
    }
    if let Some(o) = out.take() {
        days.push(o.finish()?);
    }
    staged.commit()?;
    for day in &mut days {
        day.path = folder.join(format!("{}.mcap", day.date));
    }
    Ok(days)
}

/// Merges `inputs` (consecutive days of one section, in order) into one
/// recording at `out`; returns the messages written.
pub fn merge(inputs: &[PathBuf], out: &Path) -> Result<u64, ConvertError> {
    let mut temp = tortwin_files::PartialFile::beside(out)?;
    let mut o = temp.open_with(|path| Output::create(path.to_path_buf(), 0, String::new()))?;
    let mut first: Option<(PathBuf, SectionMsg, Option<LineMsg>)> = None;
    for input in inputs {
        let mut raw = RawMessages::open(input)?;
        let Opening {
            section,
            line,
            next,
        } = opening(input, &mut raw)?;
        let msg: SectionMsg = decode::parse(&section.data)
            .map_err(|e| InputError::at(input, location(&section), e.message))?;
        let line_msg: Option<LineMsg> = line
            .as_ref()
            .map(|l| {
                decode::parse(&l.data).map_err(|e| InputError::at(input, location(l), e.message))
            })
            .transpose()?;
        match &first {
            None => {
                o.copy(&section, None)?;
                if let Some(line) = &line {
                    o.copy(line, None)?;
                }
                first = Some((input.clone(), msg, line_msg));
            }
            Some((path, known, _)) if *known != msg => {
                return Err(InputError::at(
                    input,
                    location(&section),
                    format!(
                        "its /section is not the one of {}: only days of one section \
                         can be merged",
                        path.display()
                    ),
                )
                .into());
            }
            Some((path, _, known)) if *known != line_msg => {
                let at = line.as_ref().unwrap_or(&section);
                return Err(InputError::at(
                    input,
                    location(at),
                    format!(
                        "its /line is not the one of {}: only days of one line can be merged",
                        path.display()
                    ),
                )
                .into());
            }
            Some(_) => {}
        }
        for m in next.map(Ok).into_iter().chain(raw) {
            o.copy(&m?, None)?;
        }
    }
    let messages = o.finish()?.messages;
    temp.commit()?;
    Ok(messages)
}

/// The UTC date and log_time of each day's first passage, in time order.
fn first_passages(input: &Path) -> Result<Vec<(String, u64)>, ConvertError> {
    let mut raw = RawMessages::open(input)?;
    let next = opening(input, &mut raw)?.next;
    let mut starts: Vec<(String, u64)> = Vec::new();
    for m in next.map(Ok).into_iter().chain(raw) {
        let m = m?;
        if m.topic == Topic::Passage.name() {
            let date = utc_date(m.log_time_ns);
            if starts.last().is_none_or(|(d, _)| *d != date) {
                starts.push((date, m.log_time_ns));
            }
        }
    }
    if starts.is_empty() {
        return Err(InputError::file(input, "the recording has no /train/passage message").into());
    }
    Ok(starts)
}

/// A recording's opening: its `/section` and, on a line (line.md), its
/// `/line`; with the message after them when it was read to find out.
struct Opening {
    section: RawMessage,
    line: Option<RawMessage>,
    next: Option<RawMessage>,
}

/// The first message, which must be the `/section`, and the `/line` if
/// the next message is one at the section's log_time (one anywhere else
/// is an ordinary message here, which the reader refuses).
fn opening(input: &Path, raw: &mut RawMessages) -> Result<Opening, ConvertError> {
    let section = match raw.next().transpose()? {
        Some(m) if m.topic == Topic::Section.name() => m,
        Some(m) => {
            return Err(InputError::at(
                input,
                location(&m),
                "the first message in replay order is not the /section message".to_string(),
            )
            .into())
        }
        None => {
            return Err(InputError::file(input, "the recording has no /section message").into())
        }
    };
    let next = raw.next().transpose()?;
    let is_line =
        |m: &RawMessage| m.topic == Topic::Line.name() && m.log_time_ns == section.log_time_ns;
    Ok(match next {
        Some(m) if is_line(&m) => Opening {
            section,
            line: Some(m),
            next: None,
        },
        next => Opening {
            section,
            line: None,
            next,
        },
    })
}

fn location(m: &RawMessage) -> MessageLocation {
    MessageLocation {
        topic: m.topic.clone(),
        log_time_ns: m.log_time_ns,
        index_in_file: m.index_in_file,
    }
}

/// `YYYY-MM-DD` of a log_time.
fn utc_date(log_time_ns: u64) -> String {
    let secs = (log_time_ns / 1_000_000_000) as i64;
    DateTime::from_timestamp(secs, 0)
        .map_or_else(|| format!("t{secs}"), |t| t.format("%Y-%m-%d").to_string())
}

/// One output recording being written.
struct Output {
    path: PathBuf,
    day: usize,
    date: String,
    writer: RecordingWriter<BufWriter<File>>,
    /// Channels outside the format's five (or in another encoding), by
    /// (topic, encoding).
    others: HashMap<(String, String), u16>,
}

impl Output {
    fn create(path: PathBuf, day: usize, date: String) -> Result<Self, ConvertError> {
        let file = File::create(&path).map_err(|source| ConvertError::Io {
            what: "creating",
            path: path.clone(),
            source,
        })?;
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(1 << 20));
        let writer =
            RecordingWriter::new(BufWriter::new(file), options, None).map_err(|source| {
                ConvertError::Write {
                    path: path.clone(),
                    source,
                }
            })?;
        Ok(Self {
            path,
            day,
            date,
            writer,
            others: HashMap::new(),
        })
    }

    /// Writes `m` as it is, at `at` (log and publish time) if given.
    fn copy(&mut self, m: &RawMessage, at: Option<u64>) -> Result<(), ConvertError> {
        let known = Topic::from_name(&m.topic).filter(|_| m.message_encoding == "json");
        let channel = match known {
            Some(topic) => self
                .writer
                .channel_of(topic)
                .map_err(|source| self.write_error(source))?,
            None => {
                let (topic, encoding) = (&m.topic, &m.message_encoding);
                let key = (topic.clone(), encoding.clone());
                match self.others.get(&key) {
                    Some(&id) => id,
                    None => {
                        let id = self
                            .writer
                            .add_channel(topic, encoding)
                            .map_err(|source| self.write_error(source))?;
                        self.others.insert(key, id);
                        id
                    }
                }
            }
        };
        let (log, publish) = at.map_or((m.log_time_ns, m.publish_time_ns), |t| (t, t));
        self.writer
            .write_message(channel, log, publish, &m.data)
            .map_err(|source| self.write_error(source))
    }

    fn write_error(&self, source: WriteError) -> ConvertError {
        ConvertError::Write {
            path: self.path.clone(),
            source,
        }
    }

    fn finish(self) -> Result<Day, ConvertError> {
        let Output {
            path, date, writer, ..
        } = self;
        let messages = writer.messages();
        let mut file = match writer.finish() {
            Ok(file) => file,
            Err(source) => return Err(ConvertError::Write { path, source }),
        };
        if let Err(source) = file.flush() {
            return Err(ConvertError::Io {
                what: "writing",
                path,
                source,
            });
        }
        Ok(Day {
            date,
            path,
            messages,
        })
    }
}
