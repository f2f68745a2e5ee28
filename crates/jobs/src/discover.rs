//! `tortwin discover`: which effects of docs/spec/effects.md does the
//! model miss in a recording? (See [`tortwin_discover`] for the workflow.)

use std::fmt::Write as _;
use std::path::PathBuf;
use tortwin_outputs::provenance::Provenance;

use tortwin_discover::{self as discover, data::Dataset, Discovery, Options, Progress, Silent};
use tortwin_files::usage::UsageError;
use tortwin_study::{Error, Result};

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
    /// Search effects against the starting model's constants as they are,
    /// without calibrating the site's constants first (a model already
    /// calibrated for this site).
    #[cfg_attr(feature = "cli", arg(long))]
    pub no_calibrate: bool,
    /// Worker threads for the fits (default: one per core).
    #[cfg_attr(feature = "cli", arg(long))]
    pub threads: Option<usize>,
    /// Print nothing but errors.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

/// `tortwin calibrate`: the site's constants alone (step 0 of discover,
/// no effect searched), docs/spec/interfaces.md "Site constants".
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct CalibrateArgs {
    /// The recording (MCAP) with friction measurements.
    pub recording: PathBuf,
    /// The starting model, overlaid on the built-in defaults (TOML): its
    /// constants are where the calibration starts and what an interval is
    /// compared with; its effects stay on as they are.
    #[cfg_attr(feature = "cli", arg(long))]
    pub config: Option<super::ConfigSource>,
    /// The report directory: report.json (`site_constants`), report.md,
    /// model.toml (the calibrated constants) and residuals.rrd.
    #[cfg_attr(feature = "cli", arg(long))]
    pub report: PathBuf,
    /// Worker threads (default: one per core).
    #[cfg_attr(feature = "cli", arg(long))]
    pub threads: Option<usize>,
    /// Print nothing but errors.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

impl CalibrateArgs {
    /// The same study as discover with no effect searched.
    fn as_discover(&self) -> DiscoverArgs {
        DiscoverArgs {
            recording: self.recording.clone(),
            config: self.config.clone(),
            report: self.report.clone(),
            bic_threshold: -10.0,
            min_excess_share: 0.25,
            unexplained_ratio: 1.1,
            no_calibrate: false,
            threads: self.threads,
            quiet: self.quiet,
        }
    }
}

/// Calibrates the site's constants and writes the report.
pub fn calibrate(args: &CalibrateArgs) -> Result<Discovery> {
    calibrate_with(args, &Silent)
}

/// [`calibrate`], telling `progress` the stage.
pub fn calibrate_with(args: &CalibrateArgs, progress: &dyn Progress) -> Result<Discovery> {
    calibrate_with_data(args, progress).map(|(d, _)| d)
}

/// [`calibrate_with`], also returning the measurements read.
pub fn calibrate_with_data(
    args: &CalibrateArgs,
    progress: &dyn Progress,
) -> Result<(Discovery, Dataset)> {
    let options = Options {
        max_steps: 0,
        ..Options::default()
    };
    study(&args.as_discover(), options, progress)
}

/// What a run read and what its evaluations cost, one line (discover and
/// calibrate print it alike).
fn work_line(d: &Discovery, elapsed_s: f64) -> String {
    let unit = d
        .replay_ms
        .map_or_else(String::new, |ms| format!(" of {ms:.0} ms"));
    format!(
        "  {} measurements over {} days; {} engine runs and {} with tangents, {:.1} \
         run-equivalents{unit} in {elapsed_s:.1} s",
        d.measurements,
        d.days,
        d.engine_runs,
        d.tangent_runs(),
        d.run_equivalents
    )
}

/// The few lines `tortwin calibrate` prints.
pub fn render_calibration(args: &CalibrateArgs, d: &Discovery, elapsed_s: f64) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "calibrate {}", args.recording.display());
    let _ = writeln!(out, "{}", work_line(d, elapsed_s));
    for c in &d.site_constants {
        let ci = c.ci95.map_or_else(
            || "-".to_string(),
            |[lo, hi]| format!("{}–{}", discover::fmt_param(lo), discover::fmt_param(hi)),
        );
        let _ = writeln!(
            out,
            "  {:<17} {:>10}  {:>21}  {}",
            c.key,
            discover::fmt_param(c.value),
            ci,
            if c.determined {
                "determined"
            } else {
                &c.status
            }
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
    let options = Options {
        bic_threshold: args.bic_threshold,
        min_excess_share: args.min_excess_share,
        unexplained_ratio: args.unexplained_ratio,
        calibrate: !args.no_calibrate,
        ..Options::default()
    };
    study(args, options, progress)
}

/// Reads the recording, runs the workflow with `options` and writes the
/// report.
fn study(
    args: &DiscoverArgs,
    options: Options,
    progress: &dyn Progress,
) -> Result<(Discovery, Dataset)> {
    let _inputs = tortwin_outputs::files::InputScope::enter();
    if args.report.is_file() {
        return Err(UsageError(format!(
            "--report {}: is a file; it must be a directory (created if missing)",
            args.report.display()
        ))
        .into());
    }
    let start = super::load_config(args.config.as_ref())?;
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
    // Written whole beside the report folder, then moved in: a report that
    // fails half-way leaves none of its files (tortwin_files::StagedFolder).
    let staged = tortwin_outputs::files::StagedFolder::beside(&args.report)?;
    discover::report::write(staged.path(), &data, &discovery)?;
    staged.commit()?;
    Ok((discovery, data))
}

/// The few lines printed at the end.
pub fn render(args: &DiscoverArgs, d: &Discovery, elapsed_s: f64) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "discover {}", args.recording.display());
    let _ = writeln!(out, "{}", work_line(d, elapsed_s));
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
