//! The `tortwin` commands as library functions (docs/spec/interfaces.md).
//!
//! Each job takes its options (a plain struct; with the `cli` feature it is
//! also the command's `clap::Args`), writes its files and returns what it
//! found, plus a `render` of the few lines the command prints. The binary
//! adds only argument parsing, the progress display and exit codes.

mod alert_post;
pub mod discover;
pub mod live;
pub mod paper;
mod printable;
pub mod recordings;
pub mod replay;
pub mod strategy;
pub mod summary;
pub mod synth;
pub mod tables;

pub use printable::printable;

use tortwin_model::config::ModelConfig;
use tortwin_model::error::ConfigError;

pub use tortwin_study::ConfigSource;
use tortwin_study::{Error, Result};

/// The `tortwin` command line, as the binary parses its arguments and the
/// Python package parses the argument lists it builds (one definition: a
/// flag and its Python keyword cannot drift apart).
#[cfg(feature = "cli")]
#[derive(Debug, clap::Parser)]
#[command(
    name = "tortwin",
    version,
    about = "Digital twin of a track section for top-of-rail friction management",
    after_help = "Exit status: 0 on success, 2 on bad input or usage (the message names the \
                  file and where in it), 1 otherwise. Documentation: docs/ in the repository."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[cfg(feature = "cli")]
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Replay a recording of a track section and publish the friction field
    /// (rerun recording, MCAP for Foxglove).
    Replay(crate::replay::ReplayArgs),
    /// Follow a recording while a logger writes it (or a folder in which
    /// its files appear) and write what a replay of the finished files
    /// writes, as it goes, with checkpoints to continue from.
    Live(crate::live::LiveArgs),
    /// Build a recording from CSV tables (section.toml, passages.csv,
    /// pulses.csv, weather.csv, measurements.csv; docs/spec/csv-tables.md).
    Import(crate::tables::ImportArgs),
    /// Replay a recording into tables: measurements with simulated values
    /// and residuals, the field per train (long format) and per-train
    /// summaries, as Parquet and CSV.
    Export(crate::tables::ExportArgs),
    /// Recompute the paper's Figures 7 and 13–17 as CSV and SVG.
    Paper(crate::paper::PaperArgs),
    /// Write a synthetic recording (traffic, pulses, weather, noisy
    /// measurements from a truth model with optional hidden effects).
    Synth(crate::synth::SynthArgs),
    /// Find the effects the model misses in a recording: residuals,
    /// covariates, candidate effects fitted and selected (BIC, share of the
    /// excess over the noise, cross-validation by day and by site); writes
    /// report.json, report.md with plots, model.toml and residuals.rrd.
    Discover(crate::discover::DiscoverArgs),
    /// Calibrate the site's constants (muD, muC, km, kc, kt, cN, m0, ...)
    /// on a recording: which ones it determines, their values with 95 %
    /// intervals, which only in combination; writes report.json
    /// (site_constants), report.md, model.toml and residuals.rrd.
    Calibrate(crate::discover::CalibrateArgs),
    /// Evaluate application strategies (pulse mass, interval, applicator
    /// positions, rails) over a section's traffic: share of the section in
    /// the target band, carry-on distance, over-application, product per
    /// day; search, Pareto front, recommendation; writes strategy.json,
    /// report.md with plots and recommended.rrd.
    Strategy(crate::strategy::StrategyArgs),
    /// Cut a recording of several days into one recording per service day
    /// (from a day's first train to the next day's first), each opening
    /// with the /section message.
    Split(crate::recordings::SplitArgs),
    /// Merge consecutive days of one section into one recording.
    Merge(crate::recordings::MergeArgs),
}

/// Makes the calling thread one of the threads of rayon's global pool (if
/// no pool has been made yet), as the command line does first thing (a
/// replay where it first wants the pool: [`join_rayon_pool_when_wanted`]). The
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

/// [`join_rayon_pool`] where the calling thread first wants the pool
/// ([`tortwin_handover::pool::before_pool_use`]) rather than now: what
/// `tortwin replay` does, whose tracks roll in parallel only for long
/// trains, and whose layout pass uses the pool only for a recording laid
/// out before the replay ([`tortwin_handover::pool`] says what it saves).
pub fn join_rayon_pool_when_wanted() {
    tortwin_handover::pool::defer_pool_start(join_rayon_pool);
}

/// Loads the model configuration: the defaults, overlaid by `source`.
pub(crate) fn load_config(source: Option<&ConfigSource>) -> Result<ModelConfig, ConfigError> {
    Ok(match source {
        Some(s) => s.load()?,
        None => ModelConfig::default(),
    })
}

/// The alerts' thresholds: the defaults, overlaid by `source`'s `[alerts]`.
pub(crate) fn load_alerts(
    source: Option<&ConfigSource>,
) -> Result<tortwin_model::config::alerts::AlertConfig, ConfigError> {
    Ok(match source {
        Some(s) => s.load_alerts()?,
        None => Default::default(),
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
        return Err(tortwin_files::usage::UsageError(format!(
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
