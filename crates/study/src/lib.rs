//! What every study and job of tortwin shares, below them all (synth,
//! discover, strategy, jobs):
//!
//! - [`Error`]: why a study or job stopped, and whether the input is at
//!   fault ([`Error::is_input`]).
//! - [`Progress`]: how a long job reports progress to whoever shows it, and
//!   how it is asked to stop ([`progress::check`]).
//! - [`ConfigSource`]: where a study's model configuration comes from.

pub mod config;
pub mod error;
pub mod progress;

pub use config::ConfigSource;
pub use error::{Error, Result};
pub use progress::{Progress, Silent};
