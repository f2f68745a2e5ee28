//! Why the rerun output could not be written.

use std::path::{Path, PathBuf};

use crate::rerun_sdk::external::re_log_types::InvalidApplicationIdError;
use crate::rerun_sdk::sink::SinkFlushError;
use crate::rerun_sdk::RecordingStreamError;

use crate::files::FileError;

/// A failure of the [`super::RerunSink`]; every variant names the output
/// by its final path.
#[derive(Debug, thiserror::Error)]
pub enum RerunError {
    #[error(transparent)]
    File(#[from] FileError),
    #[error("rerun output {}: application id {id:?}", path.display())]
    ApplicationId {
        path: PathBuf,
        id: String,
        #[source]
        source: InvalidApplicationIdError,
    },
    /// The SDK failed at `what` ("starting the recording", "train T1", ...).
    #[error("rerun output {}: {what}", path.display())]
    Sdk {
        path: PathBuf,
        what: String,
        // Boxed: the SDK's error is large, and every `Result` of the sink
        // would carry its size.
        #[source]
        source: Box<RecordingStreamError>,
    },
    #[error("rerun output {}: flushing", path.display())]
    Flush {
        path: PathBuf,
        #[source]
        source: SinkFlushError,
    },
    /// The SDK's file writer stopped and writing to the file fails: the
    /// cause, found by [`crate::files::PartialFile::probe_write`].
    #[error("rerun output {}: the file writer stopped", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("rerun output {}: already finished", path.display())]
    Finished { path: PathBuf },
    #[error("rerun output {}: no section: the sink was never begun", path.display())]
    NotBegun { path: PathBuf },
    #[error("rerun output {}: the blueprint has no messages", path.display())]
    EmptyBlueprint { path: PathBuf },
    /// A log_time or wheel pass count beyond rerun's i64 timelines.
    #[error("rerun output {}: {what} {value} is out of range", path.display())]
    OutOfRange {
        path: PathBuf,
        what: &'static str,
        value: u64,
    },
    #[error(
        "rerun output {}: field snapshot of train {train_id} on {track}: \
         {field} has {len} points, the grid {grid}",
        path.display()
    )]
    SnapshotLength {
        path: PathBuf,
        train_id: String,
        /// "rail/band".
        track: String,
        field: &'static str,
        len: usize,
        grid: usize,
    },
    #[error(
        "rerun output {}: field snapshot for track {track} but the section has {tracks} tracks",
        path.display()
    )]
    NoTrack {
        path: PathBuf,
        track: usize,
        tracks: usize,
    },
}

impl RerunError {
    /// Whether the user asked for the impossible (see
    /// [`FileError::is_input`]).
    pub fn is_input(&self) -> bool {
        match self {
            RerunError::File(e) => e.is_input(),
            other => crate::files::caused_by_environment(other),
        }
    }
}

/// Makes an SDK failure at `what` into a [`RerunError::Sdk`] for `path`;
/// `what` is only formatted on failure (the sink logs at every event).
pub(super) fn sdk_error<'a>(
    path: &'a Path,
    what: impl FnOnce() -> String + 'a,
) -> impl FnOnce(RecordingStreamError) -> RerunError + 'a {
    move |source| RerunError::Sdk {
        path: path.to_path_buf(),
        what: what(),
        source: Box::new(source),
    }
}
