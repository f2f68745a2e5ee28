//! The commands of the `tortwin` binary (../shared/spec/interfaces.md).
//! Each command is a function of its arguments over the library; `main.rs`
//! only parses and maps errors to exit codes.

pub mod discover;
pub mod paper;
pub mod replay;
pub mod strategy;
pub mod summary;
pub mod synth;

use std::time::Duration;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

/// The recording the main job replays when none is given.
pub const DEFAULT_RECORDING: &str =
    concat!(env!("CARGO_MANIFEST_DIR"), "/recordings/demo_day.mcap");

#[derive(Debug, Parser)]
#[command(
    name = "tortwin",
    version,
    about = "Digital twin of a track section for top-of-rail friction management"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Replay a recording of a track section and publish the friction field.
    Replay(replay::ReplayArgs),
    /// Recompute the paper's Figures 7 and 13–17 as CSV and SVG.
    Paper(paper::PaperArgs),
    /// Write a synthetic recording (traffic, pulses, weather, noisy
    /// measurements from a truth model with optional hidden effects).
    Synth(synth::SynthArgs),
    /// Find the effects the model misses in a recording: residuals,
    /// covariates, candidate effects fitted and selected (BIC, share of the
    /// excess over the noise, cross-validation by day and by site); writes
    /// report.json, report.md with plots, model.toml and residuals.rrd.
    Discover(discover::DiscoverArgs),
    /// Evaluate application strategies (pulse mass, interval, applicator
    /// positions, rails) over a section's traffic: share of the section in
    /// the target band, carry-on distance, over-application, product per
    /// day; search, Pareto front, recommendation; writes strategy.json,
    /// report.md with plots and recommended.rrd.
    Strategy(strategy::StrategyArgs),
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Replay(args) => replay::main(args),
        Command::Paper(args) => paper::main(args),
        Command::Synth(args) => synth::main(args),
        Command::Discover(args) => discover::main(args),
        Command::Strategy(args) => strategy::main(args),
    }
}

pub use crate::output::write_atomically;

/// A spinner on stderr for a long command (indicatif hides it when stderr
/// is not a terminal; `quiet` hides it always). `template` is indicatif's,
/// e.g. `"{spinner} {elapsed} {pos} engine runs  {msg}"`.
pub(crate) fn spinner(quiet: bool, template: &str) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    if quiet {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar.set_style(
        ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
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
            .context("cannot start the worker threads")?
            .install(work),
        None => work(),
    }
}
