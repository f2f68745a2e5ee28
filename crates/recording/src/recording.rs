//! A recording read whole into memory, for the studies that replay it many
//! times (discover's fits, strategy's evaluations). The replay command does
//! not use it: it streams with [`RecordingReader`], so its memory is bounded
//! by the section, not the recording.

use std::path::{Path, PathBuf};

use crate::error::InputError;
use crate::event::{Event, Section};
use crate::line::Line;
use crate::reader::{ReaderContext, RecordingReader};

/// Every event of a recording after its `/section`, in replay order, checked
/// as the reader checks them.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub path: PathBuf,
    pub section: Section,
    pub section_log_time_ns: u64,
    /// The replay's time origin: the `/section` log_time.
    pub origin_ns: i64,
    pub events: Vec<Event>,
    pub unknown_topic_messages: u64,
    /// The `/line`, when the recording is a line (docs/spec/line.md).
    pub line: Option<Line>,
}

impl Recording {
    /// Reads the whole recording; the first bad message is the error.
    pub fn read(path: &Path) -> Result<Self, InputError> {
        let mut reader = RecordingReader::open(path, ReaderContext::default())?;
        let events = reader
            .by_ref()
            .collect::<Result<Vec<Event>, InputError>>()?;
        Ok(Self {
            path: path.to_path_buf(),
            section: reader.section().clone(),
            section_log_time_ns: reader.section_log_time_ns(),
            origin_ns: reader.origin_ns(),
            events,
            unknown_topic_messages: reader.unknown_topic_messages(),
            line: reader.line().cloned(),
        })
    }

    /// [`Recording::read`] for a study that takes sections only: a line is
    /// refused, naming the file and `study`, rather than read as the
    /// section it is not.
    pub fn read_section(path: &Path, study: &str) -> Result<Self, InputError> {
        let r = Self::read(path)?;
        match &r.line {
            None => Ok(r),
            Some(line) => Err(InputError::file(
                path,
                format!(
                    "the recording is a line (`/line` `{}`, {} segments); in this version of \
                     tortwin {study} a section (a recording without /line): replay the line \
                     with `tortwin replay` (docs/spec/line.md)",
                    line.line_id,
                    line.segments.len()
                ),
            )),
        }
    }

    /// The log_time of the last event (the `/section`'s without events).
    pub fn last_log_time_ns(&self) -> u64 {
        // Replay order is log_time order.
        self.events
            .last()
            .map_or(self.section_log_time_ns, |e| e.log_time_ns)
    }
}
