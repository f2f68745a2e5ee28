//! Library errors.
//!
//! Bad input is the user's to fix, so it must say where it is: the file, and
//! for a message the topic, its log_time and its index in the file
//! (../shared/spec/recording-format.md). The binary maps [`InputError`] and
//! [`ConfigError`] to exit status 2 and anything else to 1
//! (../shared/spec/interfaces.md).

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

/// A model configuration that cannot be used: names the key.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("configuration {source_name}: {key}: {message}")]
pub struct ConfigError {
    /// The file (or "built-in defaults") the bad value came from.
    pub source_name: String,
    /// The dotted key, e.g. `product.km1_kg` or `effects.rail_ageing.tau_s`.
    pub key: String,
    pub message: String,
}

/// True when an error chain holds bad user input (exit status 2).
pub fn is_input_error(err: &anyhow::Error) -> bool {
    err.chain().any(|e| {
        e.downcast_ref::<InputError>().is_some()
            || e.downcast_ref::<ConfigError>().is_some()
            || e.downcast_ref::<UsageError>().is_some()
    })
}

/// A command line that asks for something impossible (exit status 2).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);
