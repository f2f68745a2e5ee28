//! A recording read whole into memory, for the studies that replay it many
//! times (discover's fits, strategy's evaluations). The replay command does
//! not use it: it streams with [`RecordingReader`], so its memory is bounded
//! by the section, not the recording.

use std::path::{Path, PathBuf};

use crate::error::InputError;
use crate::event::{Event, Section};
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
        })
    }

    /// The log_time of the last event (the `/section`'s without events).
    pub fn last_log_time_ns(&self) -> u64 {
        // Replay order is log_time order.
        self.events
            .last()
            .map_or(self.section_log_time_ns, |e| e.log_time_ns)
    }
}
