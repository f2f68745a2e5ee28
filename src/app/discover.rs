//! `tortwin discover`: which effects of ../shared/spec/effects.md does the
//! model miss in a recording? (See [`crate::discover`] for the workflow.)

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use indicatif::ProgressBar;

use crate::discover::{self, data::Dataset, Discovery, Options, Progress};
use crate::error::UsageError;

#[derive(Debug, Clone, clap::Args)]
pub struct DiscoverArgs {
    /// The recording (MCAP) with friction measurements.
    pub recording: PathBuf,
    /// The starting model, overlaid on the built-in defaults (TOML). Effects
    /// already in it stay on and are refitted.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The report directory: report.json, report.md with its plots,
    /// model.toml and residuals.rrd.
    #[arg(long)]
    pub report: PathBuf,
    /// A candidate effect must lower the BIC by more than this.
    #[arg(long, default_value_t = -10.0, allow_negative_numbers = true)]
    pub bic_threshold: f64,
    /// A candidate effect must remove at least this share of what the
    /// model leaves above the noise estimate.
    #[arg(long, default_value_t = 0.25)]
    pub min_excess_share: f64,
    /// A final RMSE above this times the noise estimate is reported as an
    /// unexplained residual.
    #[arg(long, default_value_t = 1.1)]
    pub unexplained_ratio: f64,
    /// Worker threads for the fits (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print nothing but errors.
    #[arg(long, short)]
    pub quiet: bool,
}

/// The progress display on stderr (indicatif hides it when stderr is not a
/// terminal).
struct Bar(ProgressBar);

impl Progress for Bar {
    fn stage(&self, message: &str) {
        self.0.set_message(message.to_string());
    }
    fn runs(&self, runs: usize) {
        self.0.set_position(runs as u64);
    }
}

pub fn main(args: DiscoverArgs) -> Result<()> {
    let t0 = Instant::now();
    let discovery = run(&args)?;
    if !args.quiet {
        print!("{}", render(&args, &discovery, t0.elapsed().as_secs_f64()));
    }
    Ok(())
}

/// Runs the workflow the arguments ask for and writes the report.
pub fn run(args: &DiscoverArgs) -> Result<Discovery> {
    if !(args.bic_threshold.is_finite() && args.bic_threshold <= 0.0) {
        return Err(UsageError(format!(
            "--bic-threshold {}: must be a finite number <= 0",
            args.bic_threshold
        ))
        .into());
    }
    if !(args.min_excess_share.is_finite() && (0.0..=1.0).contains(&args.min_excess_share)) {
        return Err(UsageError(format!(
            "--min-excess-share {}: must be in [0, 1]",
            args.min_excess_share
        ))
        .into());
    }
    if !(args.unexplained_ratio.is_finite() && args.unexplained_ratio >= 1.0) {
        return Err(UsageError(format!(
            "--unexplained-ratio {}: must be a finite number >= 1",
            args.unexplained_ratio
        ))
        .into());
    }
    if args.report.is_file() {
        return Err(UsageError(format!(
            "--report {}: is a file; it must be a directory (created if missing)",
            args.report.display()
        ))
        .into());
    }
    let start = super::replay::load_config(args.config.as_deref())?;
    let options = Options {
        bic_threshold: args.bic_threshold,
        min_excess_share: args.min_excess_share,
        unexplained_ratio: args.unexplained_ratio,
        ..Options::default()
    };
    let bar = super::spinner(args.quiet, "{spinner} {elapsed} {pos} engine runs  {msg}");
    bar.set_message(format!("reading {}", args.recording.display()));
    let data = Dataset::read(&args.recording)?;

    let work = || discover::discover(&data, &start, &options, &Bar(bar.clone()));
    let discovery = super::with_threads(args.threads, work)
        .with_context(|| format!("discover on {}", args.recording.display()))?;
    bar.set_message("writing the report");
    discover::report::write(&args.report, &data, &discovery)?;
    bar.finish_and_clear();
    Ok(discovery)
}

/// The few lines printed at the end.
pub fn render(args: &DiscoverArgs, d: &Discovery, elapsed_s: f64) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "discover {}", args.recording.display());
    let _ = writeln!(
        out,
        "  {} measurements over {} days; {} engine runs in {elapsed_s:.1} s",
        d.measurements, d.days, d.engine_runs
    );
    for s in &d.steps {
        let best = s
            .candidates
            .iter()
            .map(|c| format!("{} {:.0}", c.name, c.delta_bic))
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            out,
            "  step {}: ΔBIC {best}; {}",
            s.step,
            s.accepted
                .as_deref()
                .map_or_else(|| "none passes".to_string(), |a| format!("added {a}"))
        );
    }
    let _ = writeln!(out, "  {}", d.verdict);
    let _ = writeln!(
        out,
        "report: {} (report.md, report.json, model.toml, residuals.rrd)",
        args.report.display()
    );
    out
}
