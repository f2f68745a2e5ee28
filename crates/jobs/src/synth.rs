//! `tortwin synth`: writes a synthetic recording and its key (see
//! [`tortwin_synth`] for how the traffic, weather and measurements are made).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[cfg(feature = "cli")]
use clap::ArgAction;

use tortwin_files::usage::UsageError;
use tortwin_model::config::ModelConfig;
use tortwin_study::{Error, Result};
use tortwin_synth::{self as synth, Preset, SynthParams, SynthReport};

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SynthArgs {
    /// The recording to write (MCAP, docs/spec/recording-format.md).
    #[cfg_attr(feature = "cli", arg(long))]
    pub out: PathBuf,
    /// The key JSON (what was hidden, counts, RMSE baseline vs truth).
    /// Default: OUT with `.mcap` replaced by `.key.json`.
    #[cfg_attr(feature = "cli", arg(long))]
    pub key: Option<PathBuf>,
    /// Section layout: `curve` (rails high/low, radius 400 m) or `tangent`
    /// (rails left/right).
    #[cfg_attr(feature = "cli", arg(long, default_value = "curve"))]
    pub preset: Preset,
    /// A line (docs/spec/line.md) described in a TOML file: its segments,
    /// applicators and sites (docs/examples/line-10km.toml); it replaces
    /// --preset, --length-m and --applicator-m, and trains run both ways
    /// (--down-share 0.5) and may share the line.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "FILE", conflicts_with_all = ["preset", "length_m", "applicator_m"])
    )]
    pub layout: Option<PathBuf>,
    /// Section length; the measurement sites (60, 210, 460 m of 600 m) scale with it.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 600.0))]
    pub length_m: f64,
    /// Position of applicator A1 (both rails).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 10.0))]
    pub applicator_m: f64,
    /// Nominal pulse mass.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.2))]
    pub pulse_g: f64,
    /// Days of traffic.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1))]
    pub days: u32,
    /// The recording's start (RFC 3339, UTC).
    #[cfg_attr(feature = "cli", arg(long, default_value = "2024-04-08T00:00:00Z"))]
    pub start: String,
    /// Trains in a day's service hours (05:00-24:00 UTC).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 40))]
    pub trains_per_day: u32,
    /// Share of passenger trains (EMUs); the others are freight.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.55))]
    pub passenger_share: f64,
    /// Share of trains running down (towards d = 0). Default: 0 on the
    /// curve, 0.4 on tangent track.
    #[cfg_attr(feature = "cli", arg(long))]
    pub down_share: Option<f64>,
    /// Least time from a train leaving the section to the next entering.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 120.0))]
    pub min_headway_s: f64,
    /// The applicator's axle counter fires one pulse per rail every N axles.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 2))]
    pub pulse_every_axles: u32,
    /// Delay from the counted axle at the applicator to the pulse.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.01))]
    pub pulse_delay_s: f64,
    /// Pulse mass = nominal × (1 + u), u uniform in ±jitter.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.05))]
    pub pulse_jitter: f64,
    /// Interval of the weather messages.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 600.0))]
    pub weather_interval_s: f64,
    /// Mean number of rain events per day (1-4 h, 0.5-5 mm/h each).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.3))]
    pub rain_events_per_day: f64,
    /// Share of trains measured: mu of every axle at every site and rail.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1.0 / 3.0))]
    pub measured_train_share: f64,
    /// Share of the measured trains that also get adhesion at --adhesion-site.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.5))]
    pub adhesion_train_share: f64,
    /// The site that measures adhesion.
    #[cfg_attr(feature = "cli", arg(long, default_value = "M2"))]
    pub adhesion_site: String,
    /// Hand tribometer readings (rail_mu) per day, between trains.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 3))]
    pub tribometer_per_day: u32,
    /// Write the tribometer readings at the end of the file, out of time
    /// order (`--rail-mu-at-end false` keeps every message in time order).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = true, action = ArgAction::Set, value_name = "BOOL"))]
    pub rail_mu_at_end: bool,
    /// Standard deviation of the Gaussian noise on every measured value.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.01))]
    pub noise_sigma: f64,
    /// Share of the measurements given a gross error (a sensor glitch of
    /// ±0.1 to 0.3); their indices go into the key.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub outlier_share: f64,
    /// Friction at one site changed outside every model term, e.g.
    /// `M2:start_h=30,hours=12,delta=-0.05` (every value measured there in
    /// that window is the truth plus delta); repeatable.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "SITE:start_h=H,hours=H,delta=D")
    )]
    pub local_friction: Vec<String>,
    /// Seed of every random draw: the same arguments give the same bytes.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Truth model configuration overlaid on the defaults (TOML).
    #[cfg_attr(feature = "cli", arg(long))]
    pub truth_config: Option<super::ConfigSource>,
    /// A hidden effect in the truth model, after --truth-config; repeatable.
    /// E.g. `rail_ageing:tau_s=7200`, `wheel_edge_reservoir:alpha=0.2,r=0.05`,
    /// `bogie_bands`.
    #[cfg_attr(feature = "cli", arg(long, value_name = "NAME[:PARAM=VALUE,...]"))]
    pub hidden: Vec<String>,
    /// Do not print the summary.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

/// Writes the recording and its key (`--key`, or beside it: NAME.key.json
/// for NAME.mcap); returns the key and where it was written.
pub fn synth(args: &SynthArgs) -> Result<(SynthReport, PathBuf)> {
    synth_with(args, &tortwin_study::progress::Silent)
}

/// [`synth`], telling `progress` how many days are simulated.
pub fn synth_with(
    args: &SynthArgs,
    progress: &dyn tortwin_study::progress::Progress,
) -> Result<(SynthReport, PathBuf)> {
    let _inputs = tortwin_outputs::files::InputScope::enter();
    let (params, truth) = prepare(args)?;
    let key_path = key_path(args);
    if key_path == args.out {
        return Err(UsageError(format!(
            "the recording and its key would both be written to {}",
            key_path.display()
        ))
        .into());
    }
    let report = synth::generate(&params, &truth, &args.out, progress)
        .map_err(|e| e.context(format!("writing {}", args.out.display())))?;
    let mut text = serde_json::to_string_pretty(&report).map_err(|source| Error::Json {
        what: "the key",
        source,
    })?;
    text.push('\n');
    tortwin_outputs::files::write_atomically(&key_path, text.as_bytes())?;
    Ok((report, key_path))
}

/// The generator's parameters and the truth configuration the arguments ask
/// for; every check that can fail is done here, before anything is written.
fn prepare(args: &SynthArgs) -> Result<(SynthParams, ModelConfig)> {
    let start = chrono::DateTime::parse_from_rfc3339(&args.start).map_err(|e| {
        UsageError(format!(
            "--start {}: not an RFC 3339 time such as 2024-04-08T00:00:00Z ({e})",
            args.start
        ))
    })?;
    let start_ns = start
        .timestamp_nanos_opt()
        .and_then(|ns| u64::try_from(ns).ok())
        .ok_or_else(|| {
            UsageError(format!(
                "--start {}: must lie between 1970 and 2262",
                args.start
            ))
        })?;
    let mut p = match &args.layout {
        Some(path) => SynthParams::on_line(read_layout(path)?),
        None => SynthParams::new(args.preset, args.length_m),
    };
    p.seed = args.seed;
    p.days = args.days;
    p.start_ns = start_ns;
    if p.line.is_none() {
        p.applicator_position_m = args.applicator_m;
    }
    p.nominal_pulse_g = args.pulse_g;
    p.trains_per_day = args.trains_per_day;
    p.passenger_share = args.passenger_share;
    p.down_share = args
        .down_share
        .unwrap_or_else(|| p.preset.default_down_share());
    p.min_headway_s = args.min_headway_s;
    p.pulse_every_axles = args.pulse_every_axles;
    p.pulse_delay_s = args.pulse_delay_s;
    p.pulse_mass_jitter = args.pulse_jitter;
    p.weather_interval_s = args.weather_interval_s;
    p.rain_events_per_day = args.rain_events_per_day;
    p.measured_train_share = args.measured_train_share;
    p.adhesion_train_share = args.adhesion_train_share;
    if p.line.as_ref().is_none_or(|l| l.adhesion_site.is_none()) {
        p.adhesion_site = args.adhesion_site.clone();
    }
    p.tribometer_per_day = args.tribometer_per_day;
    p.rail_mu_at_end = args.rail_mu_at_end;
    p.noise_sigma = args.noise_sigma;
    p.outlier_share = args.outlier_share;
    p.local_friction = args
        .local_friction
        .iter()
        .map(|spec| parse_local_friction(spec))
        .collect::<Result<_, _>>()?;
    p.validate()?;
    let truth = synth::truth_config(args.truth_config.as_ref(), &args.hidden)?;
    Ok((p, truth))
}

/// The line `--layout` describes.
fn read_layout(path: &Path) -> Result<synth::LineLayout> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        what: "reading the layout",
        path: path.to_path_buf(),
        source,
    })?;
    synth::LineLayout::from_toml(&text, &path.display().to_string())
        .map_err(|e| UsageError(format!("--layout {e}")).into())
}

/// `--key`, or the recording's path with `.mcap` replaced by `.key.json`.
fn key_path(args: &SynthArgs) -> PathBuf {
    if let Some(key) = &args.key {
        return key.clone();
    }
    let name = args
        .out
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let stem = name.strip_suffix(".mcap").unwrap_or(&name);
    args.out.with_file_name(format!("{stem}.key.json"))
}

/// The few lines printed after writing.
pub fn render(recording: &Path, key: &Path, r: &SynthReport) -> String {
    let mut out = String::new();
    let p = &r.params;
    let c = &r.counts;
    let opt = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| format!("{v:.5}"));
    // Writing to a String cannot fail.
    let _ = writeln!(
        out,
        "wrote {} ({:.2} MB) and its key {}",
        recording.display(),
        r.size_bytes as f64 / 1e6,
        key.display()
    );
    let geometry = match (&p.line, p.curve_radius_m) {
        (Some(line), _) => {
            let ids: Vec<&str> = line.segments.iter().map(|s| s.id.as_str()).collect();
            format!("line {}: {}", line.line_id, ids.join(" "))
        }
        (None, Some(radius)) => format!("curve radius {radius} m"),
        (None, None) => "tangent".to_string(),
    };
    let sites: Vec<String> = p
        .sites
        .iter()
        .map(|s| format!("{} {} m", s.id, s.position_m))
        .collect();
    let applicators = match &p.line {
        Some(line) => line
            .applicators
            .iter()
            .map(|a| {
                let rails = a
                    .rails
                    .as_ref()
                    .map_or_else(|| p.rails.join("/"), |r| r.join("/"));
                let g = a.nominal_pulse_g.unwrap_or(p.nominal_pulse_g);
                format!("{} at {} m on {rails} ({g} g)", a.id, a.position_m)
            })
            .collect::<Vec<_>>()
            .join(", "),
        None => format!(
            "{} at {} m ({} g)",
            p.applicator_id, p.applicator_position_m, p.nominal_pulse_g
        ),
    };
    let _ = writeln!(
        out,
        "  section {}: {} m, {}, rails {}; {applicators}; sites {}",
        p.section_id,
        p.length_m,
        geometry,
        p.rails.join("/"),
        sites.join(", ")
    );
    let _ = writeln!(
        out,
        "  from {}, {} day{}, seed {}",
        r.start_utc,
        r.days,
        if r.days == 1 { "" } else { "s" },
        r.seed
    );
    let dropped = if c.dropped_trains > 0 {
        format!(", {} dropped for lack of room", c.dropped_trains)
    } else {
        String::new()
    };
    let _ = writeln!(
        out,
        "  trains {} ({} freight, {} passenger, {} down, {} measured{dropped}), axles {}, pulses {}, weather {}, rain events {}",
        c.trains,
        c.freight,
        c.passenger,
        c.down,
        c.measured_trains,
        c.axles,
        c.pulses,
        c.weather,
        r.rain_events_h_from_start.len()
    );
    let _ = writeln!(
        out,
        "  measurements {}: mu {}, adhesion {}, rail_mu {}{}; contacts {}",
        c.measurements,
        c.by_quantity.mu,
        c.by_quantity.adhesion,
        c.by_quantity.rail_mu,
        if p.rail_mu_at_end && c.by_quantity.rail_mu > 0 {
            " (rail_mu at the end of the file)"
        } else {
            ""
        },
        c.contacts
    );
    let _ = writeln!(out, "  truth model: {}", describe_effects(&r.effects));
    let by_quantity: Vec<String> = r
        .rmse_baseline_vs_truth_by_quantity
        .iter()
        .filter(|(_, k)| k.n > 0)
        .map(|(q, k)| format!("{} {}", q.as_str(), opt(k.rmse)))
        .collect();
    let _ = writeln!(
        out,
        "  RMSE baseline vs truth: {} ({})",
        opt(r.rmse_baseline_vs_truth),
        by_quantity.join(", ")
    );
    let _ = writeln!(
        out,
        "  noise sigma {} (RMSE measured vs truth {})",
        p.noise_sigma,
        opt(r.rmse_measured_vs_truth)
    );
    out
}

/// `rail_ageing (tau_s = 7200), bogie_bands`, or that there are none.
fn describe_effects(effects: &serde_json::Value) -> String {
    let Some(map) = effects.as_object().filter(|m| !m.is_empty()) else {
        return "the default model (no hidden effects)".to_string();
    };
    let list: Vec<String> = map
        .iter()
        .map(|(name, params)| {
            let params: Vec<String> = params
                .as_object()
                .map(|p| p.iter().map(|(k, v)| format!("{k} = {v}")).collect())
                .unwrap_or_default();
            if params.is_empty() {
                name.clone()
            } else {
                format!("{name} ({})", params.join(", "))
            }
        })
        .collect();
    format!("hidden effects {}", list.join(", "))
}

/// `SITE:start_h=H,hours=H,delta=D` (every key required).
fn parse_local_friction(spec: &str) -> Result<synth::LocalFriction, UsageError> {
    let usage = || {
        UsageError(format!(
            "--local-friction {spec}: expected SITE:start_h=H,hours=H,delta=D, e.g. M2:start_h=30,hours=12,delta=-0.05"
        ))
    };
    let (site, rest) = spec.split_once(':').ok_or_else(usage)?;
    let (mut start_h, mut hours, mut delta) = (None, None, None);
    for pair in rest.split(',') {
        let (key, value) = pair.split_once('=').ok_or_else(usage)?;
        let v: f64 = value.trim().parse().map_err(|_| usage())?;
        match key.trim() {
            "start_h" => start_h = Some(v),
            "hours" => hours = Some(v),
            "delta" => delta = Some(v),
            _ => return Err(usage()),
        }
    }
    Ok(synth::LocalFriction {
        site: site.trim().to_string(),
        start_h: start_h.ok_or_else(usage)?,
        hours: hours.ok_or_else(usage)?,
        delta: delta.ok_or_else(usage)?,
    })
}
