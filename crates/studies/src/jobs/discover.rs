//! `tortwin discover`: which effects of docs/spec/effects.md does the
//! model miss in a recording? (See [`crate::discover`] for the workflow.)

use std::fmt::Write as _;
use std::path::PathBuf;
use tortwin_outputs::provenance::Provenance;

use crate::discover::{self, data::Dataset, Discovery, Options, Progress, Silent};
use crate::{Error, Result};
use tortwin_model::error::UsageError;

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct DiscoverArgs {
    /// The recording (MCAP) with friction measurements.
    pub recording: PathBuf,
    /// The starting model, overlaid on the built-in defaults (TOML). Effects
    /// already in it stay on and are refitted.
    #[cfg_attr(feature = "cli", arg(long))]
    pub config: Option<super::ConfigSource>,
    /// The report directory: report.json, report.md with its plots,
    /// model.toml and residuals.rrd.
    #[cfg_attr(feature = "cli", arg(long))]
    pub report: PathBuf,
    /// A candidate effect must lower the BIC by more than this.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = -10.0, allow_negative_numbers = true))]
    pub bic_threshold: f64,
    /// A candidate effect must remove at least this share of what the
    /// model leaves above the noise estimate.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.25))]
    pub min_excess_share: f64,
    /// A final RMSE above this times the noise estimate is reported as an
    /// unexplained residual.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1.1))]
    pub unexplained_ratio: f64,
    /// Worker threads for the fits (default: one per core).
    #[cfg_attr(feature = "cli", arg(long))]
    pub threads: Option<usize>,
    /// Print nothing but errors.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

/// Runs the workflow the arguments ask for and writes the report.
pub fn run(args: &DiscoverArgs) -> Result<Discovery> {
    run_with(args, &Silent)
}

/// [`run`], telling `progress` the stage and the engine runs done.
pub fn run_with(args: &DiscoverArgs, progress: &dyn Progress) -> Result<Discovery> {
    run_with_data(args, progress).map(|(discovery, _)| discovery)
}

/// [`run_with`], also returning the measurements read (the rows behind
/// `Discovery::residual_before` and `residual_after`).
pub fn run_with_data(args: &DiscoverArgs, progress: &dyn Progress) -> Result<(Discovery, Dataset)> {
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
    let start = super::load_config(args.config.as_ref())?;
    let options = Options {
        bic_threshold: args.bic_threshold,
        min_excess_share: args.min_excess_share,
        unexplained_ratio: args.unexplained_ratio,
        ..Options::default()
    };
    progress.stage(&format!("reading {}", args.recording.display()));
    let data = Dataset::read(&args.recording)?;

    let work = || discover::discover(&data, &start, &options, progress);
    let mut discovery = super::with_threads(args.threads, work).map_err(|e| {
        if progress.cancelled() {
            Error::Cancelled
        } else {
            e.context(format!("discover on {}", args.recording.display()))
        }
    })?;
    let mut inputs = vec![args.recording.as_path()];
    inputs.extend(args.config.as_ref().and_then(super::ConfigSource::path));
    discovery.provenance = Some(Provenance::of_run(&inputs, &start)?);
    progress.stage("writing the report");
    discover::report::write(&args.report, &data, &discovery)?;
    Ok((discovery, data))
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
        // The five best; report.md lists them all.
        let mut best = s
            .candidates
            .iter()
            .take(5)
            .map(|c| format!("{} {:.0}", c.label, c.delta_bic))
            .collect::<Vec<_>>()
            .join(", ");
        if s.candidates.len() > 5 {
            best += &format!(", … {} more in report.md", s.candidates.len() - 5);
        }
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
    let _ = writeln!(
        out,
        "replay with the model found: tortwin replay {} --config {}",
        args.recording.display(),
        args.report.join("model.toml").display()
    );
    out
}
