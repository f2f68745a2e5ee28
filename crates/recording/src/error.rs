//! A recording (or a state file) that breaks its format, and a recording
//! that cannot be written.
//!
//! Bad input is the user's to fix, so it must say where it is: the file, and
//! for a message the topic, its log_time and its index in the file
//! (docs/spec/recording-format.md).

use std::fmt;
use std::path::PathBuf;

/// Where in a recording a problem is: the message's topic, log_time and
/// 0-based index in the file (every message of the file counted).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MessageLocation {
    pub topic: String,
    pub log_time_ns: u64,
    pub index_in_file: u64,
}

impl fmt::Display for MessageLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "topic {}, log_time {} ns, message index {}",
            self.topic, self.log_time_ns, self.index_in_file
        )
    }
}

/// Where in a table (CSV) a problem is: the 1-based line and column, as
/// editors and `file:line:column` links count them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellLocation {
    pub line: u64,
    pub column: usize,
}

/// A recording, a state file or a table that breaks its format.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{}{}: {}{message}",
    .file.display(),
    .cell.map_or(String::new(), |c| format!(":{}:{}", c.line, c.column)),
    .location.as_ref().map_or(String::new(), |l| format!("{l}: "))
)]
pub struct InputError {
    pub file: PathBuf,
    pub location: Option<MessageLocation>,
    /// For a table: the line and column.
    pub cell: Option<CellLocation>,
    pub message: String,
}

impl InputError {
    pub fn file(file: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self {
            file: file.into(),
            location: None,
            cell: None,
            message: message.into(),
        }
    }

    /// A problem at `line` and `column` (1-based) of a table.
    pub fn cell(
        file: impl Into<PathBuf>,
        line: u64,
        column: usize,
        message: impl Into<String>,
    ) -> Self {
        Self {
            file: file.into(),
            location: None,
            cell: Some(CellLocation { line, column }),
            message: message.into(),
        }
    }

    pub fn at(
        file: impl Into<PathBuf>,
        location: MessageLocation,
        message: impl Into<String>,
    ) -> Self {
        Self {
            file: file.into(),
            location: Some(location),
            cell: None,
            message: message.into(),
        }
    }
}

/// A recording that could not be written: what was being written, and why.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The MCAP layer failed (an I/O error, an unknown channel).
    #[error("{what}: {source}")]
    Mcap {
        what: String,
        #[source]
        source: mcap::McapError,
    },
    /// A message could not be serialized as JSON.
    #[error("serializing a {topic} message: {source}")]
    Json {
        topic: &'static str,
        #[source]
        source: serde_json::Error,
    },
}

/// Why a recording or its tables could not be converted: `tortwin import`
/// (tables to a recording), `export` (a recording's inputs to tables),
/// `split` and `merge` (a recording to its days and back).
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    /// An input that breaks its format (the user's to fix: exit status 2).
    #[error(transparent)]
    Input(#[from] InputError),
    /// A recording that could not be written.
    #[error("writing {}: {source}", .path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: WriteError,
    },
    /// The file system refused `what` ("creating", "writing", ...) on `path`.
    #[error("{what} {}: {source}", .path.display())]
    Io {
        what: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// An output that cannot be (an input of its name, a pipe, a folder
    /// that cannot be made).
    #[error(transparent)]
    File(#[from] tortwin_files::FileError),
}
