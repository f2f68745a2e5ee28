//! `tortwin strategy`: which pulse mass, interval, applicator position(s)
//! and rails keep mu in the target band over a section's traffic, for how
//! much product (see [`tortwin_strategy`]).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tortwin_outputs::provenance::Provenance;

use serde::Deserialize;

use tortwin_files::usage::UsageError;
use tortwin_strategy::search::{Method, Space, SpaceConfig, Values};
use tortwin_strategy::{self as strategy, Study, Target, Traffic};
use tortwin_study::progress::{Progress, Silent};
use tortwin_study::{Error, Result};
use tortwin_synth::{self as synth, Preset, SynthParams};

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct StrategyArgs {
    /// The traffic: a recording (MCAP) whose own pulses are replaced by each
    /// strategy's. Required unless --synth.
    #[cfg_attr(
        feature = "cli",
        arg(required_unless_present = "synth", conflicts_with = "synth")
    )]
    pub recording: Option<PathBuf>,
    /// The result directory: strategy.json, report.md with its plots,
    /// recommended.rrd (and traffic.mcap with --synth).
    #[cfg_attr(feature = "cli", arg(long))]
    pub out: PathBuf,
    /// The model, overlaid on the built-in defaults (TOML), found effects
    /// included (e.g. a `tortwin discover` model.toml).
    #[cfg_attr(feature = "cli", arg(long))]
    pub config: Option<super::ConfigSource>,
    /// The target band, the recommendation's limits and the space of
    /// strategies (TOML: [target], [target.band], [space], [search]).
    /// Default: band 0.30-0.40, 0.05-0.8 g, every 1-8 axles, one or two
    /// applicators at the recorded positions or a third and two thirds into
    /// the section, all rails (288 strategies on a one-applicator section).
    #[cfg_attr(feature = "cli", arg(long))]
    pub space: Option<PathBuf>,
    /// Overrides [search] method.
    #[cfg_attr(feature = "cli", arg(long))]
    pub method: Option<Method>,
    /// Generate the traffic with `tortwin synth` instead of reading a
    /// recording (written to OUT/traffic.mcap).
    #[cfg_attr(feature = "cli", arg(long))]
    pub synth: bool,
    /// With --synth: the section, `curve` (400 m radius) or `tangent`.
    #[cfg_attr(
        feature = "cli",
        arg(long, default_value = "curve", requires = "synth")
    )]
    pub synth_preset: Preset,
    /// With --synth: days of traffic.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1, requires = "synth"))]
    pub synth_days: u32,
    /// With --synth: the random seed (the same seed gives the same traffic).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1, requires = "synth"))]
    pub synth_seed: u64,
    /// With --synth: trains a day, both directions together.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 40, requires = "synth"))]
    pub synth_trains_per_day: u32,
    /// With --synth: the section's length in metres.
    #[cfg_attr(
        feature = "cli",
        arg(long, default_value_t = 600.0, requires = "synth")
    )]
    pub synth_length_m: f64,
    /// Worker threads (default: one per core).
    #[cfg_attr(feature = "cli", arg(long))]
    pub threads: Option<usize>,
    /// Print nothing but errors.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

impl StrategyArgs {
    /// Arguments with the defaults, for tests and benchmarks.
    pub fn new(recording: Option<PathBuf>, out: PathBuf) -> Self {
        Self {
            recording,
            out,
            config: None,
            space: None,
            method: None,
            synth: false,
            synth_preset: Preset::Curve,
            synth_days: 1,
            synth_seed: 1,
            synth_trains_per_day: 40,
            synth_length_m: 600.0,
            threads: None,
            quiet: true,
        }
    }
}

/// The strategy file (`--space`): every table and key optional.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct StrategyFile {
    #[serde(default)]
    pub(crate) target: Target,
    #[serde(default)]
    pub(crate) space: SpaceOverlay,
    #[serde(default)]
    pub(crate) search: SearchConfig,
}

/// `[space]`: what is not given comes from [`SpaceConfig::around_today`].
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SpaceOverlay {
    pub(crate) pulse_g: Option<Values>,
    pub(crate) every_axles: Option<Values>,
    pub(crate) positions_m: Option<Vec<f64>>,
    pub(crate) applicators: Option<Vec<usize>>,
    pub(crate) rails: Option<Vec<Vec<String>>>,
}

impl SpaceOverlay {
    pub(crate) fn over(&self, base: SpaceConfig) -> SpaceConfig {
        SpaceConfig {
            pulse_g: self.pulse_g.clone().unwrap_or(base.pulse_g),
            every_axles: self.every_axles.clone().unwrap_or(base.every_axles),
            positions_m: self.positions_m.clone().unwrap_or(base.positions_m),
            applicators: self.applicators.clone().unwrap_or(base.applicators),
            rails: self.rails.clone().unwrap_or(base.rails),
        }
    }
}

/// `[search]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(crate) struct SearchConfig {
    pub(crate) method: Method,
    /// `auto` evaluates every strategy of a space up to this size.
    pub(crate) max_grid: usize,
}

impl Default for SearchConfig {
    fn default() -> Self {
        Self {
            method: Method::Auto,
            max_grid: 400,
        }
    }
}

impl StrategyFile {
    pub(crate) fn read(path: &Path) -> Result<Self, UsageError> {
        let text = tortwin_outputs::files::read_text_input(
            path,
            tortwin_outputs::files::MAX_TEXT_INPUT_BYTES,
        )
        .map_err(|e| UsageError(format!("--space {}: {e}", path.display())))?;
        Self::parse(&text).map_err(|e| UsageError(format!("--space {}: {e}", path.display())))
    }

    pub(crate) fn parse(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|e| e.to_string())
    }
}

/// Runs the study the arguments ask for and writes the result.
pub fn run(args: &StrategyArgs) -> Result<(Traffic, Study)> {
    run_with(args, &Silent)
}

/// [`run`], telling `progress` the stage and the strategies evaluated.
pub fn run_with(args: &StrategyArgs, progress: &dyn Progress) -> Result<(Traffic, Study)> {
    let _inputs = tortwin_outputs::files::InputScope::enter();
    if args.out.is_file() {
        return Err(UsageError(format!(
            "--out {}: is a file; it must be a directory (created if missing)",
            args.out.display()
        ))
        .into());
    }
    if args.synth && args.recording.is_some() {
        return Err(UsageError("give a recording or --synth, not both".into()).into());
    }
    let cfg = super::load_config(args.config.as_ref())?;
    let file = match &args.space {
        Some(path) => StrategyFile::read(path)?,
        None => StrategyFile::default(),
    };
    let traffic = if args.synth {
        let mut p = SynthParams::new(args.synth_preset, args.synth_length_m);
        p.days = args.synth_days;
        p.seed = args.synth_seed;
        p.trains_per_day = args.synth_trains_per_day;
        p.validate_as("synth-")?;
        std::fs::create_dir_all(&args.out).map_err(|source| Error::Io {
            what: "creating",
            path: args.out.clone(),
            source,
        })?;
        let path = args.out.join("traffic.mcap");
        progress.stage(&format!("writing the traffic {}", path.display()));
        synth::generate(&p, &cfg, &path, progress)
            .map_err(|e| e.context(format!("writing {}", path.display())))?;
        Traffic::read(&path)?
    } else {
        let path = args.recording.clone().ok_or_else(|| {
            UsageError("no traffic: give a recording (REC.mcap) or --synth".into())
        })?;
        progress.stage(&format!("reading {}", path.display()));
        Traffic::read(&path)?
    };
    let target = file.target.clone();
    target.check(&traffic.section)?;
    let space_cfg = file.space.over(SpaceConfig::around_today(&traffic));
    let space = Space::new(&space_cfg, &traffic)?;
    let method = args.method.unwrap_or(file.search.method);

    progress.stage_of(
        &format!("evaluating strategies ({} in the space)", space.size()),
        space.size() as u64,
    );
    let done = |n: usize| {
        progress.done(n as u64);
        tortwin_study::progress::check(progress)
    };
    let work = || {
        strategy::study(
            &traffic,
            &cfg,
            &target,
            &space,
            method,
            file.search.max_grid,
            &done,
        )
    };
    let study = super::with_threads(args.threads, work).map_err(|e| {
        if progress.cancelled() {
            Error::Cancelled
        } else {
            e.context(format!("strategy study on {}", traffic.source))
        }
    })?;
    progress.stage("writing the report");
    let traffic_path = match &args.recording {
        Some(path) if !args.synth => path.clone(),
        _ => args.out.join("traffic.mcap"),
    };
    let mut inputs = vec![traffic_path.as_path()];
    inputs.extend(args.config.as_ref().and_then(super::ConfigSource::path));
    inputs.extend(args.space.as_deref());
    let provenance = Provenance::of_run(&inputs, &cfg)?;
    // Written whole beside the output folder, then moved in: a report that
    // fails half-way leaves none of its files (tortwin_files::StagedFolder).
    let staged = tortwin_outputs::files::StagedFolder::beside(&args.out)?;
    strategy::report::write(
        staged.path(),
        &traffic,
        &cfg,
        &target,
        &space,
        &study,
        &provenance,
    )?;
    staged.commit()?;
    Ok((traffic, study))
}

/// The few lines printed at the end.
pub fn render(args: &StrategyArgs, traffic: &Traffic, s: &Study, elapsed_s: f64) -> String {
    let mut out = String::new();
    let pct = |v: f64| format!("{:.1} %", 100.0 * v);
    let _ = writeln!(out, "strategy {}", traffic.source);
    let _ = writeln!(
        out,
        "  {} trains, {} axles over {} day(s); {} of {} strategies evaluated ({:?}) in {:.1} s ({} in {elapsed_s:.1} s with the report)",
        traffic.trains,
        traffic.axles,
        traffic.days(),
        s.search_evaluations,
        s.space_size,
        s.method,
        s.search_seconds,
        s.evaluated.len(),
    );
    let _ = writeln!(
        out,
        "  today:       {} in band, {} below, {:.1} g/day",
        pct(s.today.coverage),
        pct(s.today.below_share),
        s.today.product_g_per_day
    );
    match &s.recommended {
        Some(r) => {
            let _ = writeln!(
                out,
                "  recommended: {} in band, {} below, {:.1} g/day: {}",
                pct(r.figures.coverage),
                pct(r.figures.below_share),
                r.figures.product_g_per_day,
                r.strategy.describe(&traffic.section)
            );
        }
        None => {
            let _ = writeln!(
                out,
                "  no strategy of the space keeps the share below the band within the limit"
            );
        }
    }
    let _ = writeln!(
        out,
        "report: {} (report.md, strategy.json, recommended.rrd)",
        args.out.display()
    );
    out
}
