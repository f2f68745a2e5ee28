//! The `tortwin` commands as library functions (docs/spec/interfaces.md).
//!
//! Each job takes its options (a plain struct; with the `cli` feature it is
//! also the command's `clap::Args`), writes its files and returns what it
//! found, plus a `render` of the few lines the command prints. The binary
//! adds only argument parsing, the progress display and exit codes.

pub mod discover;
pub mod paper;
mod printable;
pub mod replay;
pub mod strategy;
pub mod summary;
pub mod synth;
pub mod tables;

pub use printable::printable;
use std::path::{Path, PathBuf};

use tortwin_model::config::ModelConfig;
use tortwin_model::error::ConfigError;

use crate::{Error, Result};

/// Makes the calling thread one of the threads of rayon's global pool (if
/// no pool has been made yet), as the command line does first thing. The
/// engine runs on the calling thread and hands a train's tracks to rayon:
/// as one of the pool's threads it rolls a track itself and takes the
/// other too when no worker is free (both cores busy with the outputs),
/// instead of waiting for a worker to wake and be scheduled. Call it from
/// the thread that will run the jobs, before any other use of rayon.
pub fn join_rayon_pool() {
    // An existing pool (made by the application) is kept as it is.
    let _ = rayon::ThreadPoolBuilder::new()
        .use_current_thread()
        .build_global();
}

/// Where a job's model configuration comes from: the keys it changes are
/// overlaid on the built-in defaults.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigSource {
    /// A TOML file (`--config PATH`).
    File(PathBuf),
    /// TOML text held in memory (the Python package's dictionaries); `name`
    /// stands for it in error messages.
    Text { text: String, name: String },
}

impl ConfigSource {
    /// The file, when the configuration is one (for provenance and the
    /// commands a report suggests).
    pub fn path(&self) -> Option<&Path> {
        match self {
            ConfigSource::File(p) => Some(p),
            ConfigSource::Text { .. } => None,
        }
    }

    /// What error messages call it.
    pub fn name(&self) -> String {
        match self {
            ConfigSource::File(p) => p.display().to_string(),
            ConfigSource::Text { name, .. } => name.clone(),
        }
    }

    /// The defaults overlaid with this configuration.
    pub fn load(&self) -> Result<ModelConfig, ConfigError> {
        match self {
            ConfigSource::File(p) => {
                let text = tortwin_outputs::files::read_text_input(
                    p,
                    tortwin_outputs::files::MAX_TEXT_INPUT_BYTES,
                )
                .map_err(|e| ConfigError {
                    source_name: p.display().to_string(),
                    key: "-".into(),
                    message: format!("cannot read: {e}"),
                })?;
                ModelConfig::from_overlay_str(&text, &p.display().to_string())
            }
            ConfigSource::Text { text, name } => ModelConfig::from_overlay_str(text, name),
        }
    }
}

impl From<PathBuf> for ConfigSource {
    fn from(path: PathBuf) -> Self {
        ConfigSource::File(path)
    }
}

/// `--config PATH` on the command line.
impl std::str::FromStr for ConfigSource {
    type Err = std::convert::Infallible;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(ConfigSource::File(s.into()))
    }
}

/// Loads the model configuration: the defaults, overlaid by `source`.
pub(crate) fn load_config(source: Option<&ConfigSource>) -> Result<ModelConfig, ConfigError> {
    Ok(match source {
        Some(s) => s.load()?,
        None => ModelConfig::default(),
    })
}

/// The most worker threads `--threads` asks for: a worker per core of the
/// largest machines; each costs a stack and the replays' buffers, so ten
/// thousand would only spend memory and start-up time.
pub const MAX_THREADS: usize = 1024;

/// Runs `work` on a pool of `threads` workers, or on rayon's global pool
/// (one per core) when `None`.
pub(crate) fn with_threads<T: Send>(
    threads: Option<usize>,
    work: impl FnOnce() -> Result<T> + Send,
) -> Result<T> {
    if let Some(n) = threads.filter(|n| !(1..=MAX_THREADS).contains(n)) {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        return Err(tortwin_model::error::UsageError(format!(
            "--threads {n}: give 1 to {MAX_THREADS} (a worker per core; this machine has {cores})"
        ))
        .into());
    }
    match threads {
        Some(threads) => rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()
            .map_err(Error::Threads)?
            .install(work),
        None => work(),
    }
}
