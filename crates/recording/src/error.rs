//! A recording (or a state file) that breaks its format.
//!
//! Bad input is the user's to fix, so it must say where it is: the file, and
//! for a message the topic, its log_time and its index in the file
//! (../shared/spec/recording-format.md).

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

/// A recording (or a state file) that breaks its format.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputError {
    pub file: PathBuf,
    pub location: Option<MessageLocation>,
    pub message: String,
}

impl InputError {
    pub fn file(file: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self {
            file: file.into(),
            location: None,
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
            message: message.into(),
        }
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.location {
            Some(loc) => write!(f, "{}: {}: {}", self.file.display(), loc, self.message),
            None => write!(f, "{}: {}", self.file.display(), self.message),
        }
    }
}

impl std::error::Error for InputError {}
