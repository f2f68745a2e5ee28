//! The `tortwin` commands as library functions (docs/spec/interfaces.md).
//!
//! Each job takes its options (a plain struct; with the `cli` feature it is
//! also the command's `clap::Args`), writes its files and returns what it
//! found, plus a `render` of the few lines the command prints. The binary
//! adds only argument parsing, the progress display and exit codes.

pub mod discover;
pub mod paper;
pub mod replay;
pub mod strategy;
pub mod summary;
pub mod synth;
pub mod tables;

use tortwin_model::config::ModelConfig;
use tortwin_model::error::ConfigError;

use crate::{Error, Result};

/// Loads the model configuration: the defaults, overlaid by `path`.
pub(crate) fn load_config(path: Option<&std::path::Path>) -> Result<ModelConfig, ConfigError> {
    Ok(match path {
        Some(p) => ModelConfig::from_file(p)?,
        None => ModelConfig::default(),
    })
}

/// Runs `work` on a pool of `threads` workers, or on rayon's global pool
/// (one per core) when `None`.
pub(crate) fn with_threads<T: Send>(
    threads: Option<usize>,
    work: impl FnOnce() -> Result<T> + Send,
) -> Result<T> {
    match threads {
        Some(threads) => rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()
            .map_err(Error::Threads)?
            .install(work),
        None => work(),
    }
}
