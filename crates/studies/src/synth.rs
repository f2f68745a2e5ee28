//! Synthetic recordings: days of traffic on a track section, written in
//! ../shared/spec/recording-format.md, whose measurements are what the
//! project's one engine computes with a *truth* model configuration (the
//! defaults, possibly with hidden effects of ../shared/spec/effects.md),
//! plus Gaussian noise.
//!
//! A synthetic day is the test bench of the discrepancy workflow: the
//! generator knows which effects it hid and how strongly they show, so the
//! workflow's answer can be checked. The key JSON written beside the
//! recording says what was hidden, and `rmse_baseline_vs_truth` says how
//! visible it is (the default model replayed against the truth, no noise).
//!
//! How a recording is made, one calendar day (UTC) at a time:
//!
//! 1. Plan the day: trains (consists, loads, creepages, speeds) at random
//!    times in the service hours, each starting no earlier than the previous
//!    one's last axle has left plus a minimum headway, and leaving before the
//!    service hours end; the pulses the applicator's axle counter triggers;
//!    weather every `weather_interval_s`; the measurements (every axle of a
//!    share of the trains at every site and rail, adhesion at one site for
//!    some of those, tribometer readings between trains). Values on the wire
//!    are rounded as a field device would report them, and the typed
//!    [`Event`]s are built from exactly those values with the reader's unit
//!    conversions, so a replay of the file sees the same numbers.
//! 2. Sort the day into replay order (log_time, topic, file order) and push it
//!    through two [`Engine`]s that live for the whole recording: the truth
//!    model and the default model. A small [`Sink`] collects each
//!    measurement's simulated value by its position in the day. There is no
//!    second stepping loop here: the engine is the model.
//! 3. Write the day's messages in log_time order with measured = truth + noise
//!    (rounded to 1e-5). Tribometer readings may be kept for the end of the
//!    file (`rail_mu_at_end`), as the reference recordings do, to exercise the
//!    reader's merge.
//!
//! Days are cut at midnight, when the section is empty (the service hours end
//! by then and every train has left), so rolling the day's last train when the
//! day ends gives what a replay of the whole file gives. Memory is one day of
//! events plus the tribometer readings kept for the end: a month of traffic
//! streams through.
//!
//! Everything random comes from [`ChaCha8Rng`] streams derived from the seed
//! (traffic, weather, tribometer and noise each have their own, so changing
//! the noise does not move a train); nothing reads the clock, no map is
//! iterated in hash order, and the MCAP metadata has no timestamp: the same
//! parameters give byte-identical files.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::str::FromStr;

use anyhow::{anyhow, Context, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Exp, Normal};
use serde::ser::{SerializeMap, Serializer};
use serde::Serialize;

use tortwin_engine::sink::{MeasurementOutput, Sink};
use tortwin_engine::{Engine, EngineOptions, Grid};
use tortwin_model::config::ModelConfig;
use tortwin_model::error::UsageError;
use tortwin_outputs::files::PartialFile;
use tortwin_recording::{
    Applicator, Axle, AxleRef, BogiePosition, Creepage, Direction, Event, EventKind, Measurement,
    Passage, Pulse, Quantity, Section, Site, Topic, Weather,
};

/// The generator's name in the key and the MCAP metadata.
pub const GENERATOR: &str = "tortwin synth";

const NS_PER_S: f64 = 1e9;
const HOUR_NS: u64 = 3_600_000_000_000;
const DAY_NS: u64 = 24 * HOUR_NS;
/// Standard gravity, m/s², for the cant deficiency of a curve.
const G_MPS2: f64 = 9.81;
/// Distance between the rails' running circles, m (standard gauge).
const RAIL_SPACING_M: f64 = 1.5;
/// The curve radius the creepage ranges below are calibrated for, m.
const REFERENCE_RADIUS_M: f64 = 400.0;
/// Tribometer readings are taken in working hours, at least this long after
/// a train has left and before the next one comes.
const TRIBOMETER_HOURS: (f64, f64) = (7.0, 18.0);
const TRIBOMETER_MARGIN_S: f64 = 60.0;

/// The section layouts the generator knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    /// A 400 m curve: rails `high` and `low`, leading axles steer hard.
    Curve,
    /// Tangent track: rails `left` and `right`, small creepages.
    Tangent,
}

impl FromStr for Preset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "curve" => Ok(Preset::Curve),
            "tangent" => Ok(Preset::Tangent),
            other => Err(format!(
                "unknown preset `{other}` (expected `curve` or `tangent`)"
            )),
        }
    }
}

impl Preset {
    pub fn as_str(self) -> &'static str {
        match self {
            Preset::Curve => "curve",
            Preset::Tangent => "tangent",
        }
    }

    /// The share of trains running `down` when none is asked for: the curve
    /// is one track of a double-track line, the tangent a single track.
    pub fn default_down_share(self) -> f64 {
        match self {
            Preset::Curve => 0.0,
            Preset::Tangent => 0.4,
        }
    }
}

/// A measurement site of the generated section.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SiteParam {
    pub id: String,
    pub position_m: f64,
}

/// Everything that decides a synthetic recording (all of it goes into the
/// key). [`SynthParams::new`] gives the defaults of `tortwin synth`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SynthParams {
    pub seed: u64,
    pub days: u32,
    /// The recording's first log_time (its `/section`): ns since the epoch.
    pub start_ns: u64,
    pub preset: Preset,
    pub section_id: String,
    pub length_m: f64,
    pub rails: Vec<String>,
    pub curve_radius_m: Option<f64>,
    /// Superelevation of the curve, m; sets the cant deficiency that shifts
    /// load to the high rail at speed. Not part of the recording.
    pub cant_m: f64,
    pub rail_head_radius_m: f64,
    pub nominal_wheel_diameter_m: f64,
    pub applicator_id: String,
    pub applicator_position_m: f64,
    pub nominal_pulse_g: f64,
    pub sites: Vec<SiteParam>,
    /// Trains in a full day's service hours.
    pub trains_per_day: u32,
    pub passenger_share: f64,
    pub down_share: f64,
    /// Least time from a train's last axle leaving to the next one entering.
    pub min_headway_s: f64,
    /// Trains run from this hour (UTC) ...
    pub service_start_h: f64,
    /// ... and have left the section by this one: the night is quiet.
    pub service_end_h: f64,
    pub pulse_every_axles: u32,
    /// From the counted axle reaching the applicator to the pulse landing.
    pub pulse_delay_s: f64,
    /// Pulse mass = nominal × (1 + u), u uniform in ±jitter.
    pub pulse_mass_jitter: f64,
    pub weather_interval_s: f64,
    pub rain_events_per_day: f64,
    pub measured_train_share: f64,
    pub adhesion_site: String,
    /// Share of the measured trains that also get adhesion at `adhesion_site`.
    pub adhesion_train_share: f64,
    pub tribometer_per_day: u32,
    pub rail_mu_at_end: bool,
    pub noise_sigma: f64,
    /// Share of the measurements given a gross error (a sensor glitch):
    /// measured = truth + noise ± U(0.1, 0.3).
    pub outlier_share: f64,
    /// Friction changed at one site for a while, outside every model term.
    pub local_friction: Vec<LocalFriction>,
}

/// Friction at one measurement site changed by `delta` for `hours` from
/// `start_h` hours after the start: a local contamination (leaves, a spill)
/// that no effect or generic term of the model describes. Every value
/// measured there in that window (mu, adhesion, rail_mu) is the truth plus
/// `delta`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LocalFriction {
    pub site: String,
    pub start_h: f64,
    pub hours: f64,
    pub delta: f64,
}

/// 2024-04-08T00:00:00Z, the default start.
pub const DEFAULT_START_NS: u64 = 1_712_534_400_000_000_000;

impl SynthParams {
    /// The defaults for a section of `length_m`: sites at 60, 210 and 460 m
    /// of 600 m, scaled with the length; applicator A1 at 10 m on both rails.
    pub fn new(preset: Preset, length_m: f64) -> Self {
        let (section_id, rails, curve_radius_m, cant_m) = match preset {
            Preset::Curve => (
                "curve-400".to_string(),
                vec!["high".to_string(), "low".to_string()],
                Some(400.0),
                0.10,
            ),
            Preset::Tangent => (
                format!("tangent-{}", round_dp(length_m, 1.0)),
                vec!["left".to_string(), "right".to_string()],
                None,
                0.0,
            ),
        };
        let sites = [("M1", 60.0), ("M2", 210.0), ("M3", 460.0)]
            .iter()
            .map(|&(id, at_600)| SiteParam {
                id: id.to_string(),
                position_m: round_dp(at_600 * length_m / 600.0, 100.0),
            })
            .collect();
        SynthParams {
            seed: 1,
            days: 1,
            start_ns: DEFAULT_START_NS,
            preset,
            section_id,
            length_m,
            rails,
            curve_radius_m,
            cant_m,
            rail_head_radius_m: 0.30,
            nominal_wheel_diameter_m: 0.92,
            applicator_id: "A1".to_string(),
            applicator_position_m: 10.0,
            nominal_pulse_g: 0.2,
            sites,
            trains_per_day: 40,
            passenger_share: 0.55,
            down_share: preset.default_down_share(),
            min_headway_s: 120.0,
            service_start_h: 5.0,
            service_end_h: 24.0,
            pulse_every_axles: 2,
            pulse_delay_s: 0.01,
            pulse_mass_jitter: 0.05,
            weather_interval_s: 600.0,
            rain_events_per_day: 0.3,
            measured_train_share: 1.0 / 3.0,
            adhesion_site: "M2".to_string(),
            adhesion_train_share: 0.5,
            tribometer_per_day: 3,
            rail_mu_at_end: true,
            noise_sigma: 0.01,
            outlier_share: 0.0,
            local_friction: Vec::new(),
        }
    }

    /// The recording's end: `days` after the start (exclusive).
    pub fn end_ns(&self) -> u64 {
        self.start_ns
            .saturating_add(u64::from(self.days).saturating_mul(DAY_NS))
    }

    /// Checks that the parameters describe a recording the format allows;
    /// the error names the parameter as a command-line option.
    pub fn validate(&self) -> Result<(), UsageError> {
        let bad = |what: &str, v: &dyn std::fmt::Display, must: &str| {
            Err(UsageError(format!("{what} is {v}; it must be {must}")))
        };
        let share = |what: &str, v: f64| {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                bad(what, &v, "in [0, 1]")
            }
        };
        if self.days == 0 {
            return bad("--days", &self.days, "at least 1");
        }
        if self.end_ns() >= i64::MAX as u64 || self.start_ns >= i64::MAX as u64 {
            return bad("--start", &self.start_ns, "a time before 2262");
        }
        if !(self.length_m.is_finite() && self.length_m > 0.0) {
            return bad("--length-m", &self.length_m, "finite and > 0");
        }
        let grid = Grid::new(self.length_m, self.nominal_wheel_diameter_m);
        if grid.d_m.len() > 10_000_000 {
            return bad("--length-m", &self.length_m, "at most a few thousand km");
        }
        if !(0.0..=self.length_m).contains(&self.applicator_position_m) {
            return bad(
                "--applicator-m",
                &self.applicator_position_m,
                "inside the section (0 to --length-m)",
            );
        }
        if !(self.nominal_pulse_g.is_finite() && self.nominal_pulse_g >= 0.0) {
            return bad("--pulse-g", &self.nominal_pulse_g, "finite and >= 0");
        }
        for site in &self.sites {
            if !(0.0..=self.length_m).contains(&site.position_m) {
                return bad(
                    &format!("site {} position", site.id),
                    &site.position_m,
                    "inside the section",
                );
            }
        }
        if !self.sites.iter().any(|s| s.id == self.adhesion_site) {
            let ids: Vec<&str> = self.sites.iter().map(|s| s.id.as_str()).collect();
            return bad(
                "--adhesion-site",
                &self.adhesion_site,
                &format!("one of the sites ({})", ids.join(", ")),
            );
        }
        share("--passenger-share", self.passenger_share)?;
        share("--down-share", self.down_share)?;
        share("--measured-train-share", self.measured_train_share)?;
        share("--adhesion-train-share", self.adhesion_train_share)?;
        if !(self.min_headway_s.is_finite() && self.min_headway_s >= 0.0) {
            return bad("--min-headway-s", &self.min_headway_s, "finite and >= 0");
        }
        if !(0.0 <= self.service_start_h
            && self.service_start_h < self.service_end_h
            && self.service_end_h <= 24.0)
        {
            return bad(
                "the service hours",
                &format!("{}-{}", self.service_start_h, self.service_end_h),
                "0 <= start < end <= 24",
            );
        }
        if self.pulse_every_axles == 0 {
            return bad("--pulse-every-axles", &0, "at least 1");
        }
        if !(self.pulse_delay_s.is_finite() && (0.0..=60.0).contains(&self.pulse_delay_s)) {
            return bad("--pulse-delay-s", &self.pulse_delay_s, "in [0, 60]");
        }
        if !(0.0..1.0).contains(&self.pulse_mass_jitter) {
            return bad("--pulse-jitter", &self.pulse_mass_jitter, "in [0, 1)");
        }
        if !(self.weather_interval_s.is_finite() && self.weather_interval_s >= 1.0) {
            return bad(
                "--weather-interval-s",
                &self.weather_interval_s,
                "finite and >= 1",
            );
        }
        if !(self.rain_events_per_day.is_finite()
            && (0.0..=100.0).contains(&self.rain_events_per_day))
        {
            return bad(
                "--rain-events-per-day",
                &self.rain_events_per_day,
                "in [0, 100]",
            );
        }
        if !(0.0..=1.0).contains(&self.outlier_share) {
            return bad("--outlier-share", &self.outlier_share, "in [0, 1]");
        }
        for l in &self.local_friction {
            if !self.sites.iter().any(|s| s.id == l.site) {
                return bad("--local-friction site", &l.site, "one of the sites");
            }
            if !(l.start_h.is_finite()
                && l.hours.is_finite()
                && l.hours > 0.0
                && l.delta.is_finite())
            {
                return bad(
                    "--local-friction",
                    &format!(
                        "start_h={}, hours={}, delta={}",
                        l.start_h, l.hours, l.delta
                    ),
                    "finite numbers with hours > 0",
                );
            }
        }
        if !(self.noise_sigma.is_finite() && self.noise_sigma >= 0.0) {
            return bad("--noise-sigma", &self.noise_sigma, "finite and >= 0");
        }
        Ok(())
    }

    /// The `/section` the recording describes, as the reader will type it.
    pub fn section(&self) -> Section {
        Section {
            section_id: self.section_id.clone(),
            length_m: self.length_m,
            rails: self.rails.clone(),
            curve_radius_m: self.curve_radius_m,
            rail_head_radius_m: self.rail_head_radius_m,
            nominal_wheel_diameter_m: self.nominal_wheel_diameter_m,
            applicators: vec![Applicator {
                id: self.applicator_id.clone(),
                position_m: self.applicator_position_m,
                rails: (0..self.rails.len()).collect(),
                // The reader's conversion, so that replay and truth agree.
                nominal_pulse_kg: self.nominal_pulse_g * 1e-3,
            }],
            sites: self
                .sites
                .iter()
                .map(|s| Site {
                    id: s.id.clone(),
                    position_m: s.position_m,
                })
                .collect(),
        }
    }
}

/// Builds the truth configuration: the defaults, overlaid by `truth_config`
/// (a TOML file) and then by every `--hidden` effect in turn, with the
/// validation of [`ModelConfig`] (a bad effect names the key).
pub fn truth_config(truth_config: Option<&Path>, hidden: &[String]) -> Result<ModelConfig> {
    let mut cfg = match truth_config {
        Some(path) => ModelConfig::from_file(path)?,
        None => ModelConfig::default(),
    };
    for spec in hidden {
        let toml = hidden_effect_toml(spec)?;
        cfg.overlay_str(&toml, &format!("--hidden {spec}"))?;
    }
    Ok(cfg)
}

/// `NAME:param=value[,param=value]` (or a bare `NAME`) as the TOML table
/// `[effects.NAME]` that switches the effect on; `generic:key=value,...` as
/// one `[[effects.generic]]` table (e.g.
/// `generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,t0_utc=2024-04-09T12:00:00Z,f=0.6`).
pub fn hidden_effect_toml(spec: &str) -> Result<String, UsageError> {
    let bare_key = |s: &str| {
        !s.is_empty()
            && s.chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    };
    let (name, params) = match spec.split_once(':') {
        Some((name, params)) => (name.trim(), params.trim()),
        None => (spec.trim(), ""),
    };
    if !bare_key(name) {
        return Err(UsageError(format!(
            "--hidden {spec}: `{name}` is not an effect name; expected NAME or \
             NAME:param=value[,param=value], e.g. rail_ageing:tau_s=7200"
        )));
    }
    // `generic:acts_on=...,driver=...,form=...,param=value`: one more
    // `[[effects.generic]]` table, whose names are strings.
    let generic = name == "generic";
    let mut toml = if generic {
        "[[effects.generic]]\n".to_string()
    } else {
        format!("[effects.{name}]\n")
    };
    for pair in params.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let Some((key, value)) = pair.split_once('=') else {
            return Err(UsageError(format!(
                "--hidden {spec}: `{pair}` is not param=value"
            )));
        };
        let (key, value) = (key.trim(), value.trim());
        if !bare_key(key) {
            return Err(UsageError(format!(
                "--hidden {spec}: `{key}` is not a parameter name"
            )));
        }
        if generic && value.parse::<f64>().is_err() {
            toml.push_str(&format!(
                "{key} = {}\n",
                toml::Value::String(value.to_string())
            ));
            continue;
        }
        let number: f64 = value.parse().map_err(|_| {
            UsageError(format!(
                "--hidden {spec}: effects.{name}.{key} = `{value}` is not a number"
            ))
        })?;
        // `{:?}` writes a float TOML reads back exactly (inf and nan included).
        toml.push_str(&format!("{key} = {number:?}\n"));
    }
    Ok(toml)
}

/// What a synthetic recording holds and how visible its hidden effects are:
/// the key written beside the recording.
#[derive(Debug, Clone, Serialize)]
pub struct SynthReport {
    pub generator: &'static str,
    pub version: &'static str,
    /// The recording's file name.
    pub recording: String,
    pub size_bytes: u64,
    pub seed: u64,
    pub days: u32,
    pub start_utc: String,
    pub start_ns: u64,
    pub end_ns: u64,
    /// The hidden effects and their parameters (effects.md names).
    pub effects: serde_json::Value,
    /// The whole truth configuration (defaults included), as TOML.
    pub truth_config_toml: String,
    pub noise: NoiseKey,
    pub truth: &'static str,
    pub baseline: &'static str,
    /// RMSE of the default model against the truth over every measurement
    /// (no noise); `null` without measurements.
    pub rmse_baseline_vs_truth: Option<f64>,
    pub rmse_baseline_vs_truth_by_quantity: ByQuantity<RmseKey>,
    pub rmse_baseline_vs_truth_over_sigma: Option<f64>,
    pub rmse_measured_vs_truth: Option<f64>,
    pub rmse_measured_vs_baseline: Option<f64>,
    pub counts: Counts,
    /// 0-based position among all messages of the file of every measurement
    /// given a gross error (`--outlier-share`).
    pub outliers_index_in_file: Vec<u64>,
    /// Local friction changes outside the model (`--local-friction`).
    pub local_friction: Vec<LocalFriction>,
    pub rain_events_h_from_start: Vec<RainKey>,
    pub grid_points: usize,
    pub applicator_grid_index: usize,
    pub site_grid_indices: BTreeMap<String, usize>,
    pub params: SynthParams,
}

#[derive(Debug, Clone, Serialize)]
pub struct NoiseKey {
    pub distribution: &'static str,
    pub sigma: f64,
    pub applied_to: &'static str,
}

#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct RmseKey {
    pub n: u64,
    pub rmse: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct RainKey {
    pub start_h: f64,
    pub end_h: f64,
    pub mm_h: f64,
}

/// Message and object counts of a synthetic recording.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Counts {
    pub messages: u64,
    pub measurements: u64,
    pub by_quantity: ByQuantity<u64>,
    pub trains: u64,
    pub freight: u64,
    pub passenger: u64,
    pub down: u64,
    pub measured_trains: u64,
    /// Trains drawn for a day that did not fit in its service hours.
    pub dropped_trains: u64,
    pub axles: u64,
    pub pulses: u64,
    pub weather: u64,
    pub wheels: u64,
    pub contacts: u64,
}

/// One value per measured quantity, in the format's order.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct ByQuantity<T> {
    pub mu: T,
    pub adhesion: T,
    pub rail_mu: T,
}

impl<T> ByQuantity<T> {
    pub fn get(&self, q: Quantity) -> &T {
        match q {
            Quantity::Mu => &self.mu,
            Quantity::Adhesion => &self.adhesion,
            Quantity::RailMu => &self.rail_mu,
        }
    }

    pub fn get_mut(&mut self, q: Quantity) -> &mut T {
        match q {
            Quantity::Mu => &mut self.mu,
            Quantity::Adhesion => &mut self.adhesion,
            Quantity::RailMu => &mut self.rail_mu,
        }
    }

    /// The quantities in the format's order, with their values.
    pub fn iter(&self) -> impl Iterator<Item = (Quantity, &T)> {
        QUANTITIES.into_iter().map(move |q| (q, self.get(q)))
    }
}

const QUANTITIES: [Quantity; 3] = [Quantity::Mu, Quantity::Adhesion, Quantity::RailMu];

fn quantity_slot(q: Quantity) -> usize {
    match q {
        Quantity::Mu => 0,
        Quantity::Adhesion => 1,
        Quantity::RailMu => 2,
    }
}

/// Writes the synthetic recording `params` describes to `out` (under a
/// temporary name, renamed when complete), with measurements from the
/// engine run with `truth`, and returns its key.
pub fn generate(params: &SynthParams, truth: &ModelConfig, out: &Path) -> Result<SynthReport> {
    params.validate()?;
    let section = params.section();
    let origin_ns = params.start_ns as i64;
    tortwin_engine::generic::check_terms_against(
        &truth.effects.generic,
        &section,
        "truth configuration",
    )?;
    let mut truth_engine = Engine::new(
        section.clone(),
        truth.clone(),
        EngineOptions::default(),
        origin_ns,
    );
    let mut baseline_engine = Engine::new(
        section.clone(),
        ModelConfig::default(),
        EngineOptions::default(),
        origin_ns,
    );
    let grid = truth_engine.grid().clone();

    let mut planner = Planner::new(params, section.clone());
    let mut writer = RecordingWriter::create(out, params)?;
    let mut counts = Counts::default();
    let mut stats = Residuals::default();
    let noise = Normal::new(0.0, params.noise_sigma)
        .map_err(|e| anyhow!("noise sigma {}: {e}", params.noise_sigma))?;
    let mut noise_rng = stream(params.seed, Stream::Noise);
    let mut outlier_rng = stream(params.seed, Stream::Outliers);
    let mut outliers = Vec::new();
    // Tribometer readings kept for the end of the file: (log_time, json,
    // an outlier).
    let mut at_end: Vec<(u64, Vec<u8>, bool)> = Vec::new();

    writer.section(params.start_ns, &section, params)?;
    for day in planner.days() {
        let mut plan = planner.plan_day(day);
        counts.dropped_trains += plan.dropped_trains;
        plan.items
            .sort_by_key(|p| (p.log_time_ns, p.topic, p.at_end, p.seq));
        let events: Vec<Event> = plan
            .items
            .iter()
            .enumerate()
            .map(|(i, p)| Event {
                log_time_ns: p.log_time_ns,
                index_in_file: i as u64,
                kind: p.event.clone(),
            })
            .collect();
        let truth_values = simulate(&mut truth_engine, &events)?;
        let baseline_values = simulate(&mut baseline_engine, &events)?;

        for (i, item) in plan.items.iter().enumerate() {
            match &item.event {
                EventKind::Passage(passage) => {
                    let train = plan
                        .trains
                        .iter()
                        .find(|t| t.passage.train_seq == passage.train_seq)
                        .ok_or_else(|| anyhow!("train {} was not planned", passage.train_id))?;
                    counts.trains += 1;
                    counts.axles += passage.axles.len() as u64;
                    match train.kind {
                        TrainKind::Freight => counts.freight += 1,
                        TrainKind::Passenger => counts.passenger += 1,
                    }
                    counts.down += u64::from(passage.direction == Direction::Down);
                    counts.measured_trains += u64::from(train.measured);
                    writer.passage(item.log_time_ns, train, &section.rails)?;
                }
                EventKind::Pulse(pulse) => {
                    let mass_g = item
                        .pulse_mass_g
                        .ok_or_else(|| anyhow!("a pulse was planned without its mass in g"))?;
                    counts.pulses += 1;
                    writer.pulse(item.log_time_ns, params, &section.rails[pulse.rail], mass_g)?;
                }
                EventKind::Weather(w) => {
                    counts.weather += 1;
                    writer.weather(item.log_time_ns, w)?;
                }
                EventKind::Measurement(m) => {
                    let (mut truth, baseline) = (truth_values[i], baseline_values[i]);
                    if truth.is_nan() || baseline.is_nan() {
                        return Err(anyhow!(
                            "the engine gave no value for the measurement at log_time {} ns",
                            item.log_time_ns
                        ));
                    }
                    let noise = if params.noise_sigma > 0.0 {
                        noise.sample(&mut noise_rng)
                    } else {
                        0.0
                    };
                    let site_id = &section.sites[m.site].id;
                    for l in &params.local_friction {
                        let from_ns = params.start_ns as f64 + l.start_h * 3600e9;
                        let to_ns = from_ns + l.hours * 3600e9;
                        let t = item.log_time_ns as f64;
                        if &l.site == site_id && t >= from_ns && t < to_ns {
                            truth += l.delta;
                        }
                    }
                    // A draw for every measurement, so that the share does
                    // not move which ones are hit.
                    let u: f64 = outlier_rng.random();
                    let gross = if u < params.outlier_share {
                        let size = outlier_rng.random_range(0.1..0.3);
                        if outlier_rng.random::<bool>() {
                            size
                        } else {
                            -size
                        }
                    } else {
                        0.0
                    };
                    let measured = round_dp(truth + noise + gross, 1e5);
                    stats.add(m.quantity, truth, baseline, measured);
                    counts.measurements += 1;
                    *counts.by_quantity.get_mut(m.quantity) += 1;
                    let json = measurement_json(&section, m, measured)?;
                    if item.at_end {
                        at_end.push((item.log_time_ns, json, gross != 0.0));
                    } else {
                        if gross != 0.0 {
                            outliers.push(writer.messages);
                        }
                        writer.raw(Topic::Measurement, item.log_time_ns, &json)?;
                    }
                }
            }
        }
    }
    for (log_time_ns, json, gross) in &at_end {
        if *gross {
            outliers.push(writer.messages);
        }
        writer.raw(Topic::Measurement, *log_time_ns, json)?;
    }
    counts.messages = writer.messages;
    let size_bytes = writer.finish()?;

    let summary = truth_engine.summary(0);
    counts.wheels = summary.wheels;
    counts.contacts = summary.contacts;

    let mut by_quantity = ByQuantity::<RmseKey>::default();
    for q in QUANTITIES {
        let s = quantity_slot(q);
        *by_quantity.get_mut(q) = RmseKey {
            n: stats.n[s],
            rmse: rmse(stats.baseline_truth[s], stats.n[s]),
        };
    }
    let n_all: u64 = stats.n.iter().sum();
    let sum = |v: &[f64; 3]| v.iter().sum::<f64>();
    let rmse_baseline_vs_truth = rmse(sum(&stats.baseline_truth), n_all);
    let site_grid_indices = section
        .sites
        .iter()
        .map(|s| (s.id.clone(), grid.snap(s.position_m)))
        .collect();
    Ok(SynthReport {
        generator: GENERATOR,
        version: env!("CARGO_PKG_VERSION"),
        recording: out
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
        size_bytes,
        seed: params.seed,
        days: params.days,
        start_utc: utc(params.start_ns),
        start_ns: params.start_ns,
        end_ns: params.end_ns(),
        effects: serde_json::to_value(&truth.effects).context("serializing the effects")?,
        truth_config_toml: truth.to_toml(),
        noise: NoiseKey {
            distribution: "gaussian",
            sigma: params.noise_sigma,
            applied_to: "every /measurement/friction value: measured = truth + N(0, sigma^2), \
                         rounded to 1e-5",
        },
        truth: "tortwin engine with the truth configuration (`effects`, `truth_config_toml`)",
        baseline: "tortwin engine with the default configuration (no effects)",
        rmse_baseline_vs_truth,
        rmse_baseline_vs_truth_by_quantity: by_quantity,
        rmse_baseline_vs_truth_over_sigma: match (rmse_baseline_vs_truth, params.noise_sigma) {
            (Some(r), s) if s > 0.0 => Some(r / s),
            _ => None,
        },
        rmse_measured_vs_truth: rmse(sum(&stats.measured_truth), n_all),
        rmse_measured_vs_baseline: rmse(sum(&stats.measured_baseline), n_all),
        counts,
        outliers_index_in_file: outliers,
        local_friction: params.local_friction.clone(),
        rain_events_h_from_start: planner
            .climate
            .rain
            .iter()
            .map(|r| RainKey {
                start_h: round_dp(
                    r.start_ns.saturating_sub(params.start_ns) as f64 / HOUR_NS as f64,
                    1e3,
                ),
                end_h: round_dp(
                    r.end_ns.saturating_sub(params.start_ns) as f64 / HOUR_NS as f64,
                    1e3,
                ),
                mm_h: round_dp(r.mm_h, 100.0),
            })
            .collect(),
        grid_points: grid.d_m.len(),
        applicator_grid_index: grid.snap(params.applicator_position_m),
        site_grid_indices,
        params: params.clone(),
    })
}

/// Pushes one day's events (already in replay order) through `engine` and
/// returns each measurement's simulated value by its position in `events`
/// (NaN for the other events). The day ends in the quiet night, so rolling
/// its last train now is what a replay of the whole file does later.
fn simulate(engine: &mut Engine, events: &[Event]) -> Result<Vec<f64>> {
    struct Collect<'a>(&'a mut [f64]);
    impl Sink for Collect<'_> {
        fn measurement(&mut self, m: &MeasurementOutput<'_>) -> tortwin_engine::sink::SinkResult {
            let slot = self
                .0
                .get_mut(m.index_in_file as usize)
                .ok_or_else(|| anyhow!("measurement index {} out of range", m.index_in_file))?;
            *slot = m.simulated;
            Ok(())
        }
    }
    let mut values = vec![f64::NAN; events.len()];
    let mut sink = Collect(&mut values);
    for event in events {
        engine.push(event.clone(), &mut sink)?;
    }
    engine.finish(&mut sink, 0)?;
    Ok(values)
}

/// Sums of squared differences per quantity.
#[derive(Debug, Default)]
struct Residuals {
    n: [u64; 3],
    baseline_truth: [f64; 3],
    measured_truth: [f64; 3],
    measured_baseline: [f64; 3],
}

impl Residuals {
    fn add(&mut self, q: Quantity, truth: f64, baseline: f64, measured: f64) {
        let s = quantity_slot(q);
        self.n[s] += 1;
        self.baseline_truth[s] += (baseline - truth).powi(2);
        self.measured_truth[s] += (measured - truth).powi(2);
        self.measured_baseline[s] += (measured - baseline).powi(2);
    }
}

fn rmse(sum_sq: f64, n: u64) -> Option<f64> {
    (n > 0).then(|| (sum_sq / n as f64).sqrt())
}

/// `x` rounded to `1 / scale` (scale a power of ten): the integer divided
/// by the scale is the double nearest the short decimal, so JSON shows it short.
fn round_dp(x: f64, scale: f64) -> f64 {
    (x * scale).round() / scale
}

/// A log_time as an RFC 3339 UTC string.
pub fn utc(log_time_ns: u64) -> String {
    let secs = (log_time_ns / 1_000_000_000) as i64;
    let nanos = (log_time_ns % 1_000_000_000) as u32;
    chrono::DateTime::from_timestamp(secs, nanos).map_or_else(
        || format!("{log_time_ns} ns"),
        |t| t.to_rfc3339_opts(chrono::SecondsFormat::AutoSi, true),
    )
}

/// The independent random streams of one seed.
#[derive(Debug, Clone, Copy)]
enum Stream {
    Traffic = 1,
    Weather = 2,
    Tribometer = 3,
    Noise = 4,
    Outliers = 5,
}

fn stream(seed: u64, which: Stream) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(which as u64);
    rng
}

fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

// ---------------------------------------------------------------------------
// Traffic

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TrainKind {
    Freight,
    Passenger,
}

impl TrainKind {
    fn as_str(self) -> &'static str {
        match self {
            TrainKind::Freight => "freight",
            TrainKind::Passenger => "passenger",
        }
    }
}

/// One vehicle of a consist: two two-axle bogies.
#[derive(Debug, Clone, Copy)]
struct Vehicle {
    /// Length over buffers (or couplers).
    length_m: f64,
    bogie_centres_m: f64,
    /// Axle spacing within a bogie.
    wheelbase_m: f64,
    /// Mean static wheel load, kN.
    wheel_load_kn: f64,
}

/// Bo'Bo' locomotive (e.g. a TRAXX-like 4-axle electric, ~21 t axle load).
const LOCOMOTIVE: (f64, f64, f64) = (19.0, 10.3, 2.5);
/// Four-axle freight wagons on Y25 bogies: (length, bogie centres, wheelbase).
const WAGONS: [(f64, f64, f64); 5] = [
    (19.74, 14.86, 1.8), // flat wagon for containers
    (15.74, 10.5, 1.8),  // open high-sided wagon
    (16.24, 11.0, 1.8),  // tank wagon
    (23.24, 17.5, 2.0),  // sliding-wall van
    (12.54, 7.8, 1.8),   // hopper
];
/// EMU car: 26.4 m, bogies at 19 m, 2.5 m wheelbase.
const EMU_CAR: (f64, f64, f64) = (26.4, 19.0, 2.5);

fn freight_consist(rng: &mut ChaCha8Rng) -> Vec<Vehicle> {
    let locomotives = if rng.random_bool(0.3) { 2 } else { 1 };
    let wagons = rng.random_range(20..=40);
    // A block train of one wagon type, or a mixed one.
    let block = rng
        .random_bool(0.6)
        .then(|| rng.random_range(0..WAGONS.len()));
    let mut consist = Vec::with_capacity(locomotives + wagons);
    for _ in 0..locomotives {
        let (length_m, bogie_centres_m, wheelbase_m) = LOCOMOTIVE;
        consist.push(Vehicle {
            length_m,
            bogie_centres_m,
            wheelbase_m,
            wheel_load_kn: uniform(rng, 100.0, 110.0),
        });
    }
    for _ in 0..wagons {
        let kind = block.unwrap_or_else(|| rng.random_range(0..WAGONS.len()));
        let (length_m, bogie_centres_m, wheelbase_m) = WAGONS[kind];
        consist.push(Vehicle {
            length_m,
            bogie_centres_m,
            wheelbase_m,
            wheel_load_kn: uniform(rng, 90.0, 125.0),
        });
    }
    consist
}

fn passenger_consist(rng: &mut ChaCha8Rng) -> Vec<Vehicle> {
    let units = if rng.random_bool(0.35) { 2 } else { 1 };
    let cars_per_unit = rng.random_range(4..=6);
    let (length_m, bogie_centres_m, wheelbase_m) = EMU_CAR;
    (0..units * cars_per_unit)
        .map(|_| Vehicle {
            length_m,
            bogie_centres_m,
            wheelbase_m,
            wheel_load_kn: uniform(rng, 65.0, 85.0),
        })
        .collect()
}

/// A planned train: the typed passage plus what goes on the wire.
#[derive(Debug, Clone)]
struct TrainPlan {
    kind: TrainKind,
    passage: Passage,
    /// Wheel loads as written, kN: `[axle * rails + rail]`.
    load_kn: Vec<f64>,
    log_time_ns: u64,
    measured: bool,
    adhesion: bool,
}

/// Creepages of one wheel on one rail (model input, not a simulation).
/// In a curve a bogie's leading axle runs with a large angle of attack: large
/// lateral creepage and spin, of opposite spin sign on the two rails, and a
/// longitudinal creepage from the rolling radius difference; the trailing
/// axle runs nearly radial. On tangent track every creepage is small.
fn creepages(
    rng: &mut ChaCha8Rng,
    curve_radius_m: Option<f64>,
    position: BogiePosition,
) -> [Creepage; 2] {
    let c = |cx: f64, cy: f64, spin: f64| Creepage {
        cx: round_dp(cx, 1e6),
        cy: round_dp(cy, 1e6),
        spin_per_m: round_dp(spin, 1e4),
    };
    match curve_radius_m {
        Some(radius_m) => {
            let k = (REFERENCE_RADIUS_M / radius_m).min(3.0);
            let (cx, cy, spin_outer, spin_inner) = match position {
                BogiePosition::Leading => (
                    uniform(rng, 0.002, 0.006),
                    k * uniform(rng, 0.003, 0.008),
                    k * uniform(rng, 0.10, 0.30),
                    -k * uniform(rng, 0.08, 0.25),
                ),
                BogiePosition::Trailing => (
                    uniform(rng, 0.0005, 0.002),
                    uniform(rng, -0.001, 0.002),
                    k * uniform(rng, 0.02, 0.10),
                    -k * uniform(rng, 0.02, 0.08),
                ),
            };
            let cx_inner = -cx * uniform(rng, 0.8, 1.2);
            let cy_inner = cy * uniform(rng, 0.85, 1.0);
            [c(cx, cy, spin_outer), c(cx_inner, cy_inner, spin_inner)]
        }
        None => {
            let mut one = |spin_lo: f64, spin_hi: f64| {
                c(
                    uniform(rng, -0.002, 0.002),
                    uniform(rng, -0.001, 0.001),
                    uniform(rng, spin_lo, spin_hi),
                )
            };
            [one(0.01, 0.05), one(-0.06, -0.008)]
        }
    }
}

// ---------------------------------------------------------------------------
// Weather

#[derive(Debug, Clone, Copy)]
struct RainEvent {
    start_ns: u64,
    end_ns: u64,
    mm_h: f64,
}

/// The weather's slow part, drawn once: a daily mean temperature (a random
/// walk around 15 °C) and diurnal amplitude anchored at noon of every
/// calendar day, and the rain events (a Poisson process).
#[derive(Debug, Clone)]
struct Climate {
    first_midnight_ns: u64,
    /// Per calendar day from the day before `first_midnight_ns`: (mean, amplitude) °C.
    days: Vec<(f64, f64)>,
    rain: Vec<RainEvent>,
}

impl Climate {
    fn new(p: &SynthParams, rng: &mut ChaCha8Rng) -> Climate {
        let first_midnight_ns = p.start_ns - p.start_ns % DAY_NS;
        let calendar_days = (p.end_ns() - first_midnight_ns).div_ceil(DAY_NS) as usize;
        let mut mean = 15.0 + uniform(rng, -3.0, 3.0);
        let days = (0..calendar_days + 3)
            .map(|_| {
                mean = 15.0 + 0.6 * (mean - 15.0) + uniform(rng, -3.0, 3.0);
                (mean, uniform(rng, 4.0, 7.0))
            })
            .collect();
        let mut rain = Vec::new();
        if p.rain_events_per_day > 0.0 {
            if let Ok(gap_days) = Exp::new(p.rain_events_per_day) {
                let mut t_ns = p.start_ns as f64;
                loop {
                    t_ns += gap_days.sample(rng) * DAY_NS as f64;
                    if t_ns >= p.end_ns() as f64 {
                        break;
                    }
                    let start_ns = t_ns as u64;
                    let hours = uniform(rng, 1.0, 4.0);
                    rain.push(RainEvent {
                        start_ns,
                        end_ns: start_ns + (hours * HOUR_NS as f64) as u64,
                        mm_h: uniform(rng, 0.5, 5.0),
                    });
                }
            }
        }
        Climate {
            first_midnight_ns,
            days,
            rain,
        }
    }

    /// Daily mean and amplitude at `t_ns`, interpolated between noon anchors.
    fn day_values(&self, t_ns: u64) -> (f64, f64) {
        // Anchor k (index k + 1 in `days`) sits at noon of calendar day k.
        let hours = (t_ns as f64 - self.first_midnight_ns as f64) / HOUR_NS as f64;
        let x = (hours - 12.0) / 24.0 + 1.0;
        let k = (x.floor().max(0.0) as usize).min(self.days.len() - 2);
        let f = (x - k as f64).clamp(0.0, 1.0);
        let (a, b) = (self.days[k], self.days[k + 1]);
        (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
    }

    fn rain_mm_h(&self, t_ns: u64) -> f64 {
        self.rain
            .iter()
            .filter(|r| r.start_ns <= t_ns && t_ns < r.end_ns)
            .map(|r| r.mm_h)
            .sum()
    }

    /// The weather message at `t_ns`: diurnal temperature (lowest before
    /// dawn, highest mid-afternoon), cooler in rain; humidity falling as the
    /// day warms and near saturation in rain.
    fn weather(&self, t_ns: u64, rng: &mut ChaCha8Rng) -> Weather {
        let (mean_c, amplitude_c) = self.day_values(t_ns);
        let hour = (t_ns % DAY_NS) as f64 / HOUR_NS as f64;
        let diurnal = (2.0 * std::f64::consts::PI * (hour - 10.0) / 24.0).sin();
        let rain = self.rain_mm_h(t_ns);
        let raining = rain > 0.0;
        let mut temperature_c = mean_c + amplitude_c * diurnal + uniform(rng, -0.3, 0.3);
        let mut humidity = 0.72 - 0.025 * amplitude_c * diurnal + uniform(rng, -0.04, 0.04);
        let mut precipitation_mm_h = 0.0;
        if raining {
            temperature_c -= 1.5;
            humidity = humidity.max(uniform(rng, 0.90, 1.0));
            precipitation_mm_h = (rain * uniform(rng, 0.7, 1.3)).max(0.1);
        }
        Weather {
            air_temperature_c: round_dp(temperature_c, 10.0),
            relative_humidity: round_dp(humidity.clamp(0.2, 1.0), 100.0),
            precipitation_mm_h: round_dp(precipitation_mm_h, 10.0),
        }
    }
}

// ---------------------------------------------------------------------------
// Planning a day

/// One message of a day, with its place in the replay.
#[derive(Debug, Clone)]
struct Planned {
    log_time_ns: u64,
    /// The format's topic order: passage 1, pulse 2, measurement 3, weather 4.
    topic: u8,
    /// Written at the end of the file (after every in-order message).
    at_end: bool,
    /// Planning order, the tie-break of equal times and topics.
    seq: u64,
    event: EventKind,
    /// A pulse's mass as written, g.
    pulse_mass_g: Option<f64>,
}

struct DayPlan {
    items: Vec<Planned>,
    trains: Vec<TrainPlan>,
    dropped_trains: u64,
}

/// A calendar day of the recording: `[from_ns, to_ns)`.
#[derive(Debug, Clone, Copy)]
struct Day {
    midnight_ns: u64,
    from_ns: u64,
    to_ns: u64,
}

struct Planner<'p> {
    p: &'p SynthParams,
    section: Section,
    traffic: ChaCha8Rng,
    weather_rng: ChaCha8Rng,
    tribometer: ChaCha8Rng,
    climate: Climate,
    next_train_seq: usize,
    axles_counted: u64,
    /// The last train's passage time and the end of its occupation, as the
    /// reader computes them (s from the origin).
    last_train_s: Option<(f64, f64)>,
    next_weather: u64,
    seq: u64,
}

impl<'p> Planner<'p> {
    fn new(p: &'p SynthParams, section: Section) -> Self {
        let mut weather_rng = stream(p.seed, Stream::Weather);
        let climate = Climate::new(p, &mut weather_rng);
        Planner {
            p,
            section,
            traffic: stream(p.seed, Stream::Traffic),
            weather_rng,
            tribometer: stream(p.seed, Stream::Tribometer),
            climate,
            next_train_seq: 0,
            axles_counted: 0,
            last_train_s: None,
            next_weather: 0,
            seq: 0,
        }
    }

    fn days(&self) -> Vec<Day> {
        let first = self.climate.first_midnight_ns;
        let end = self.p.end_ns();
        (0..)
            .map(|d| first + d * DAY_NS)
            .take_while(|&midnight| midnight < end)
            .map(|midnight_ns| Day {
                midnight_ns,
                from_ns: midnight_ns.max(self.p.start_ns),
                to_ns: (midnight_ns + DAY_NS).min(end),
            })
            .collect()
    }

    fn time_s(&self, log_time_ns: u64) -> f64 {
        (log_time_ns as i64 - self.p.start_ns as i64) as f64 * 1e-9
    }

    fn push(&mut self, items: &mut Vec<Planned>, log_time_ns: u64, topic: u8, event: EventKind) {
        self.seq += 1;
        items.push(Planned {
            log_time_ns,
            topic,
            at_end: false,
            seq: self.seq,
            event,
            pulse_mass_g: None,
        });
    }

    /// When axle `offset_m` of a train reaches `d_m` (recording-format.md).
    fn axle_time_ns(&self, train: &TrainPlan, offset_m: f64, d_m: f64) -> u64 {
        let from_entry_m = match train.passage.direction {
            Direction::Up => d_m,
            Direction::Down => self.p.length_m - d_m,
        };
        let dt_s = (from_entry_m.abs() + offset_m) / train.passage.speed_mps;
        train.log_time_ns + (dt_s * NS_PER_S).round() as u64
    }

    fn plan_day(&mut self, day: Day) -> DayPlan {
        let mut items = Vec::new();
        let p = self.p;

        let interval_ns = (p.weather_interval_s * NS_PER_S).round() as u64;
        loop {
            let t_ns = p.start_ns + self.next_weather * interval_ns;
            if t_ns >= day.to_ns {
                break;
            }
            self.next_weather += 1;
            let w = self.climate.weather(t_ns, &mut self.weather_rng);
            self.push(&mut items, t_ns, 4, EventKind::Weather(w));
        }

        let service_from =
            (day.midnight_ns + (p.service_start_h * HOUR_NS as f64) as u64).max(day.from_ns);
        let service_to =
            (day.midnight_ns + (p.service_end_h * HOUR_NS as f64) as u64).min(day.to_ns);
        let mut trains = Vec::new();
        let mut dropped_trains = 0;
        if service_to > service_from {
            let full_ns = (p.service_end_h - p.service_start_h) * HOUR_NS as f64;
            let share = (service_to - service_from) as f64 / full_ns;
            let n = (f64::from(p.trains_per_day) * share).round() as usize;
            let mut times: Vec<u64> = (0..n)
                .map(|_| {
                    service_from
                        + (self.traffic.random::<f64>() * (service_to - service_from) as f64) as u64
                })
                .collect();
            times.sort_unstable();
            for drawn_ns in times {
                match self.plan_train(drawn_ns, service_to) {
                    Some(train) => trains.push(train),
                    None => dropped_trains += 1,
                }
            }
        }
        for train in &trains {
            self.plan_train_messages(train, &mut items);
        }
        if service_to > service_from {
            self.plan_tribometer(&trains, service_from, service_to, &mut items);
        }
        DayPlan {
            items,
            trains,
            dropped_trains,
        }
    }

    /// A train drawn for `drawn_ns`: it enters then, or once the previous
    /// train has left plus the headway; `None` if it would still be in the
    /// section at `service_to`.
    fn plan_train(&mut self, drawn_ns: u64, service_to: u64) -> Option<TrainPlan> {
        let p = self.p;
        let rng = &mut self.traffic;
        let kind = if rng.random_bool(p.passenger_share) {
            TrainKind::Passenger
        } else {
            TrainKind::Freight
        };
        let consist = match kind {
            TrainKind::Freight => freight_consist(rng),
            TrainKind::Passenger => passenger_consist(rng),
        };
        let speed_mps = round_dp(
            match kind {
                TrainKind::Freight => uniform(rng, 12.0, 22.0),
                TrainKind::Passenger => uniform(rng, 18.0, 30.0),
            },
            10.0,
        );
        let direction = if rng.random_bool(p.down_share) {
            Direction::Down
        } else {
            Direction::Up
        };
        let measured = rng.random_bool(p.measured_train_share);
        let adhesion = measured && rng.random_bool(p.adhesion_train_share);

        // Above the balance speed of the curve the high rail carries more:
        // load transfer ~ unbalanced lateral acceleration × centre of
        // gravity height / half the rail spacing, here 12 % per m/s².
        let load_shift = match p.curve_radius_m {
            Some(radius_m) => {
                let unbalanced_mps2 =
                    speed_mps * speed_mps / radius_m - G_MPS2 * p.cant_m / RAIL_SPACING_M;
                (0.12 * unbalanced_mps2).clamp(-0.12, 0.25)
            }
            None => 0.0,
        };
        let rails = p.rails.len();
        let mut axles = Vec::new();
        let mut load_kn = Vec::new();
        let mut front_m = 0.0;
        for vehicle in &consist {
            let overhang_m =
                (vehicle.length_m - vehicle.bogie_centres_m - vehicle.wheelbase_m) / 2.0;
            let positions = [
                (0.0, BogiePosition::Leading),
                (vehicle.wheelbase_m, BogiePosition::Trailing),
                (vehicle.bogie_centres_m, BogiePosition::Leading),
                (
                    vehicle.bogie_centres_m + vehicle.wheelbase_m,
                    BogiePosition::Trailing,
                ),
            ];
            for (at_m, bogie_position) in positions {
                let axle_load_kn = vehicle.wheel_load_kn * (1.0 + uniform(rng, -0.03, 0.03));
                let creepage = creepages(rng, p.curve_radius_m, bogie_position);
                let wheel_diameter_m = round_dp(uniform(rng, 0.84, 0.96), 1e3);
                let mut wheel_load_n = Vec::with_capacity(rails);
                for rail in 0..rails {
                    let side = if rail == 0 { 1.0 } else { -1.0 };
                    let kn = round_dp(
                        axle_load_kn
                            * (1.0 + side * load_shift)
                            * (1.0 + uniform(rng, -0.01, 0.01)),
                        10.0,
                    );
                    load_kn.push(kn);
                    // The reader's kN -> N conversion, exactly.
                    wheel_load_n.push(kn * 1e3);
                }
                axles.push(Axle {
                    offset_m: round_dp(front_m + overhang_m + at_m, 100.0),
                    bogie_position,
                    wheel_diameter_m,
                    wheel_load_n,
                    creepage: creepage[..rails.min(2)].to_vec(),
                });
            }
            front_m += vehicle.length_m;
        }
        let last_offset_m = axles.last().map_or(0.0, |a| a.offset_m);
        let occupation_s = (p.length_m + last_offset_m) / speed_mps;

        // Earliest entry: as drawn, or the previous train's exit plus the
        // headway, checked with the reader's own arithmetic.
        let mut log_time_ns = drawn_ns;
        if let Some((_, occupied_until_s)) = self.last_train_s {
            let earliest_s = occupied_until_s + p.min_headway_s;
            let earliest_ns = p.start_ns + (earliest_s * NS_PER_S).ceil().max(0.0) as u64;
            log_time_ns = log_time_ns.max(earliest_ns);
            while self.time_s(log_time_ns) < occupied_until_s {
                log_time_ns += 1;
            }
        }
        let end_ns = log_time_ns + (occupation_s * NS_PER_S).ceil() as u64 + 1;
        if end_ns > service_to {
            return None;
        }
        let t_s = self.time_s(log_time_ns);
        self.last_train_s = Some((t_s, t_s + occupation_s));

        let train_seq = self.next_train_seq;
        self.next_train_seq += 1;
        let prefix = match kind {
            TrainKind::Freight => "F",
            TrainKind::Passenger => "P",
        };
        Some(TrainPlan {
            kind,
            passage: Passage {
                train_id: format!("{prefix}-{:05}", train_seq + 1),
                train_seq,
                direction,
                speed_mps,
                axles,
            },
            load_kn,
            log_time_ns,
            measured,
            adhesion,
        })
    }

    /// The passage, the pulses its axles trigger and its measurements.
    fn plan_train_messages(&mut self, train: &TrainPlan, items: &mut Vec<Planned>) {
        let p = self.p;
        self.push(
            items,
            train.log_time_ns,
            1,
            EventKind::Passage(train.passage.clone()),
        );

        let delay_ns = (p.pulse_delay_s * NS_PER_S).round() as u64;
        for axle in &train.passage.axles {
            self.axles_counted += 1;
            if !self
                .axles_counted
                .is_multiple_of(u64::from(p.pulse_every_axles))
            {
                continue;
            }
            let at_ns = self.axle_time_ns(train, axle.offset_m, p.applicator_position_m) + delay_ns;
            for rail in 0..p.rails.len() {
                let jitter = uniform(&mut self.traffic, -p.pulse_mass_jitter, p.pulse_mass_jitter);
                let mass_g = round_dp(p.nominal_pulse_g * (1.0 + jitter), 1e4);
                self.push(
                    items,
                    at_ns,
                    2,
                    EventKind::Pulse(Pulse {
                        applicator: 0,
                        rail,
                        mass_kg: mass_g * 1e-3,
                    }),
                );
                if let Some(last) = items.last_mut() {
                    last.pulse_mass_g = Some(mass_g);
                }
            }
        }

        if !train.measured {
            return;
        }
        let adhesion_site = self
            .section
            .sites
            .iter()
            .position(|s| s.id == p.adhesion_site);
        for (site, s) in self.section.sites.clone().iter().enumerate() {
            let quantities: &[Quantity] = if train.adhesion && Some(site) == adhesion_site {
                &[Quantity::Mu, Quantity::Adhesion]
            } else {
                &[Quantity::Mu]
            };
            for (axle_index, axle) in train.passage.axles.iter().enumerate() {
                let at_ns = self.axle_time_ns(train, axle.offset_m, s.position_m);
                for &quantity in quantities {
                    for rail in 0..p.rails.len() {
                        self.push(
                            items,
                            at_ns,
                            3,
                            EventKind::Measurement(Measurement {
                                site,
                                rail,
                                quantity,
                                axle: Some(AxleRef {
                                    train_id: train.passage.train_id.clone(),
                                    train_seq: train.passage.train_seq,
                                    axle_index,
                                }),
                                value: 0.0,
                            }),
                        );
                    }
                }
            }
        }
    }

    /// Hand tribometer readings in working hours, in the gaps between trains.
    fn plan_tribometer(
        &mut self,
        trains: &[TrainPlan],
        service_from: u64,
        service_to: u64,
        items: &mut Vec<Planned>,
    ) {
        let p = self.p;
        let day_start = service_from - service_from % DAY_NS;
        let hours_from =
            (day_start + (TRIBOMETER_HOURS.0 * HOUR_NS as f64) as u64).max(service_from);
        let hours_to = (day_start + (TRIBOMETER_HOURS.1 * HOUR_NS as f64) as u64).min(service_to);
        if hours_to <= hours_from {
            return;
        }
        let margin_ns = (TRIBOMETER_MARGIN_S * NS_PER_S) as u64;
        // Free intervals: between the trains' occupations, with a margin.
        let mut free: Vec<(u64, u64)> = Vec::new();
        let mut cursor = hours_from;
        for train in trains {
            let last_offset_m = train.passage.axles.last().map_or(0.0, |a| a.offset_m);
            let end_ns = train.log_time_ns
                + ((p.length_m + last_offset_m) / train.passage.speed_mps * NS_PER_S).ceil() as u64;
            let busy_from = train.log_time_ns.saturating_sub(margin_ns);
            if busy_from > cursor {
                free.push((cursor, busy_from.min(hours_to)));
            }
            cursor = cursor.max(end_ns + margin_ns);
        }
        if cursor < hours_to {
            free.push((cursor, hours_to));
        }
        free.retain(|&(a, b)| b > a);
        let total_ns: u64 = free.iter().map(|&(a, b)| b - a).sum();
        if total_ns == 0 {
            return;
        }
        for _ in 0..p.tribometer_per_day {
            let rng = &mut self.tribometer;
            let mut u = (rng.random::<f64>() * total_ns as f64) as u64;
            let site = rng.random_range(0..self.section.sites.len().max(1));
            let rail = rng.random_range(0..p.rails.len());
            let Some(at_ns) = free.iter().find_map(|&(a, b)| {
                if u < b - a {
                    Some(a + u)
                } else {
                    u -= b - a;
                    None
                }
            }) else {
                continue;
            };
            if self.section.sites.is_empty() {
                continue;
            }
            self.push(
                items,
                at_ns,
                3,
                EventKind::Measurement(Measurement {
                    site,
                    rail,
                    quantity: Quantity::RailMu,
                    axle: None,
                    value: 0.0,
                }),
            );
            if let Some(last) = items.last_mut() {
                last.at_end = p.rail_mu_at_end;
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Writing

/// What the writer declares for each topic of the format.
trait TopicSchema {
    fn schema_name(self) -> &'static str;
    fn schema(self) -> &'static str;
}

impl TopicSchema for Topic {
    fn schema_name(self) -> &'static str {
        match self {
            Topic::Section => "tortwin.input.Section",
            Topic::Passage => "tortwin.input.TrainPassage",
            Topic::Pulse => "tortwin.input.ApplicatorPulse",
            Topic::Measurement => "tortwin.input.MeasurementFriction",
            Topic::Weather => "tortwin.input.EnvironmentWeather",
        }
    }

    fn schema(self) -> &'static str {
        match self {
            Topic::Section => SECTION_SCHEMA,
            Topic::Passage => PASSAGE_SCHEMA,
            Topic::Pulse => PULSE_SCHEMA,
            Topic::Measurement => MEASUREMENT_SCHEMA,
            Topic::Weather => WEATHER_SCHEMA,
        }
    }
}

/// Writes the recording under `.NAME.partial-<pid>` and renames it into
/// place in [`RecordingWriter::finish`]; dropped unfinished, it deletes the
/// temporary file.
struct RecordingWriter {
    // Before `temp`: on drop the writer closes the file before it is deleted.
    writer: Option<mcap::Writer<BufWriter<File>>>,
    temp: PartialFile,
    channels: [u16; 5],
    sequences: [u32; 5],
    json: Vec<u8>,
    messages: u64,
}

impl RecordingWriter {
    fn create(path: &Path, p: &SynthParams) -> Result<Self> {
        let temp = PartialFile::beside(path)?;
        let file = File::create(temp.temp_path())
            .with_context(|| format!("creating {}", temp.temp_path().display()))?;
        let version = env!("CARGO_PKG_VERSION");
        let mut writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(mcap::WriteOptions::DEFAULT_CHUNK_SIZE))
            .compression_threads(0)
            .library(format!("{GENERATOR} {version} (mcap-rs)"))
            .create(BufWriter::new(file))
            .with_context(|| format!("starting {}", temp.temp_path().display()))?;
        writer
            .write_metadata(&mcap::records::Metadata {
                name: "tortwin.synth".to_owned(),
                metadata: BTreeMap::from([
                    ("generator".to_owned(), GENERATOR.to_owned()),
                    ("version".to_owned(), version.to_owned()),
                    ("seed".to_owned(), p.seed.to_string()),
                    ("preset".to_owned(), p.preset.as_str().to_owned()),
                ]),
            })
            .with_context(|| format!("writing {}", temp.temp_path().display()))?;
        let mut channels = [0; 5];
        for topic in Topic::ALL {
            let schema_id = writer
                .add_schema(topic.schema_name(), "jsonschema", topic.schema().as_bytes())
                .with_context(|| format!("adding the schema of {}", topic.name()))?;
            channels[topic as usize] = writer
                .add_channel(schema_id, topic.name(), "json", &BTreeMap::new())
                .with_context(|| format!("adding channel {}", topic.name()))?;
        }
        Ok(RecordingWriter {
            writer: Some(writer),
            temp,
            channels,
            sequences: [0; 5],
            json: Vec::with_capacity(64 * 1024),
            messages: 0,
        })
    }

    fn raw(&mut self, topic: Topic, log_time_ns: u64, json: &[u8]) -> Result<()> {
        let writer = self
            .writer
            .as_mut()
            .ok_or_else(|| anyhow!("{}: already finished", self.temp.final_path().display()))?;
        let sequence = &mut self.sequences[topic as usize];
        *sequence = sequence.wrapping_add(1);
        writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: self.channels[topic as usize],
                    sequence: *sequence,
                    log_time: log_time_ns,
                    publish_time: log_time_ns,
                },
                json,
            )
            .with_context(|| {
                format!(
                    "writing {} to {}",
                    topic.name(),
                    self.temp.temp_path().display()
                )
            })?;
        self.messages += 1;
        Ok(())
    }

    fn write<T: Serialize>(&mut self, topic: Topic, log_time_ns: u64, message: &T) -> Result<()> {
        let mut json = std::mem::take(&mut self.json);
        json.clear();
        serde_json::to_writer(&mut json, message)
            .with_context(|| format!("serializing {}", topic.name()))?;
        let result = self.raw(topic, log_time_ns, &json);
        self.json = json;
        result
    }

    fn section(&mut self, log_time_ns: u64, s: &Section, p: &SynthParams) -> Result<()> {
        #[derive(Serialize)]
        struct ApplicatorMsg<'a> {
            id: &'a str,
            position_m: f64,
            rails: Vec<&'a str>,
            nominal_pulse_g: f64,
        }
        #[derive(Serialize)]
        struct SiteMsg<'a> {
            id: &'a str,
            position_m: f64,
        }
        #[derive(Serialize)]
        struct SectionMsg<'a> {
            section_id: &'a str,
            length_m: f64,
            rails: &'a [String],
            curve_radius_m: Option<f64>,
            rail_head_radius_m: f64,
            nominal_wheel_diameter_m: f64,
            applicators: Vec<ApplicatorMsg<'a>>,
            measurement_sites: Vec<SiteMsg<'a>>,
        }
        let message = SectionMsg {
            section_id: &s.section_id,
            length_m: s.length_m,
            rails: &s.rails,
            curve_radius_m: s.curve_radius_m,
            rail_head_radius_m: s.rail_head_radius_m,
            nominal_wheel_diameter_m: s.nominal_wheel_diameter_m,
            applicators: s
                .applicators
                .iter()
                .map(|a| ApplicatorMsg {
                    id: &a.id,
                    position_m: a.position_m,
                    rails: a.rails.iter().map(|&r| s.rails[r].as_str()).collect(),
                    // The grams the section's kg were converted from.
                    nominal_pulse_g: p.nominal_pulse_g,
                })
                .collect(),
            measurement_sites: s
                .sites
                .iter()
                .map(|site| SiteMsg {
                    id: &site.id,
                    position_m: site.position_m,
                })
                .collect(),
        };
        self.write(Topic::Section, log_time_ns, &message)
    }

    fn passage(&mut self, log_time_ns: u64, train: &TrainPlan, rails: &[String]) -> Result<()> {
        #[derive(Serialize)]
        struct AxleMsg<'a> {
            offset_m: f64,
            bogie_position: &'static str,
            wheel_diameter_m: f64,
            #[serde(rename = "wheel_load_kN")]
            wheel_load_kn: PerRail<'a, f64>,
            creepage: PerRail<'a, CreepageMsg>,
        }
        #[derive(Serialize)]
        struct PassageMsg<'a> {
            train_id: &'a str,
            direction: &'static str,
            speed_mps: f64,
            consist: &'static str,
            axles: Vec<AxleMsg<'a>>,
        }
        let n = rails.len();
        let creepages: Vec<CreepageMsg> = train
            .passage
            .axles
            .iter()
            .flat_map(|a| a.creepage.iter().map(CreepageMsg::from))
            .collect();
        let passage = &train.passage;
        let message = PassageMsg {
            train_id: &passage.train_id,
            direction: match passage.direction {
                Direction::Up => "up",
                Direction::Down => "down",
            },
            speed_mps: passage.speed_mps,
            consist: train.kind.as_str(),
            axles: passage
                .axles
                .iter()
                .enumerate()
                .map(|(i, a)| AxleMsg {
                    offset_m: a.offset_m,
                    bogie_position: match a.bogie_position {
                        BogiePosition::Leading => "leading",
                        BogiePosition::Trailing => "trailing",
                    },
                    wheel_diameter_m: a.wheel_diameter_m,
                    wheel_load_kn: PerRail(rails, &train.load_kn[i * n..(i + 1) * n]),
                    creepage: PerRail(rails, &creepages[i * n..(i + 1) * n]),
                })
                .collect(),
        };
        self.write(Topic::Passage, log_time_ns, &message)
    }

    fn pulse(
        &mut self,
        log_time_ns: u64,
        p: &SynthParams,
        rail: &str,
        mass_g: f64,
    ) -> anyhow::Result<()> {
        #[derive(Serialize)]
        struct PulseMsg<'a> {
            applicator_id: &'a str,
            rail: &'a str,
            mass_g: f64,
        }
        self.write(
            Topic::Pulse,
            log_time_ns,
            &PulseMsg {
                applicator_id: &p.applicator_id,
                rail,
                mass_g,
            },
        )
    }

    fn weather(&mut self, log_time_ns: u64, w: &Weather) -> Result<()> {
        #[derive(Serialize)]
        struct WeatherMsg {
            air_temperature_c: f64,
            relative_humidity: f64,
            precipitation_mm_h: f64,
        }
        self.write(
            Topic::Weather,
            log_time_ns,
            &WeatherMsg {
                air_temperature_c: w.air_temperature_c,
                relative_humidity: w.relative_humidity,
                precipitation_mm_h: w.precipitation_mm_h,
            },
        )
    }

    /// Finishes the file, renames it into place and returns its size.
    fn finish(mut self) -> Result<u64> {
        let mut writer = self
            .writer
            .take()
            .ok_or_else(|| anyhow!("{}: already finished", self.temp.final_path().display()))?;
        let temp_path = self.temp.temp_path().to_path_buf();
        writer
            .finish()
            .with_context(|| format!("finishing {}", temp_path.display()))?;
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| e.into_error())
            .with_context(|| format!("flushing {}", temp_path.display()))?;
        file.sync_all()
            .with_context(|| format!("syncing {}", temp_path.display()))?;
        let size = file
            .metadata()
            .with_context(|| format!("reading the size of {}", temp_path.display()))?
            .len();
        drop(file);
        self.temp.commit()?;
        Ok(size)
    }
}

/// A measurement as `/measurement/friction` JSON.
fn measurement_json(section: &Section, m: &Measurement, value: f64) -> Result<Vec<u8>> {
    #[derive(Serialize)]
    struct MeasurementMsg<'a> {
        site_id: &'a str,
        rail: &'a str,
        quantity: &'static str,
        #[serde(skip_serializing_if = "Option::is_none")]
        train_id: Option<&'a str>,
        #[serde(skip_serializing_if = "Option::is_none")]
        axle_index: Option<usize>,
        value: f64,
    }
    if !value.is_finite() {
        return Err(anyhow!(
            "a {} measurement is {value}, which JSON cannot hold",
            m.quantity.as_str()
        ));
    }
    let message = MeasurementMsg {
        site_id: &section.sites[m.site].id,
        rail: &section.rails[m.rail],
        quantity: m.quantity.as_str(),
        train_id: m.axle.as_ref().map(|a| a.train_id.as_str()),
        axle_index: m.axle.as_ref().map(|a| a.axle_index),
        value,
    };
    serde_json::to_vec(&message).context("serializing /measurement/friction")
}

#[derive(Serialize)]
struct CreepageMsg {
    cx: f64,
    cy: f64,
    spin_per_m: f64,
}

impl From<&Creepage> for CreepageMsg {
    fn from(c: &Creepage) -> Self {
        CreepageMsg {
            cx: c.cx,
            cy: c.cy,
            spin_per_m: c.spin_per_m,
        }
    }
}

/// A per-rail JSON object with the rails in the section's order.
struct PerRail<'a, T>(&'a [String], &'a [T]);

impl<T: Serialize> Serialize for PerRail<'_, T> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (rail, value) in self.0.iter().zip(self.1) {
            map.serialize_entry(rail, value)?;
        }
        map.end()
    }
}

const SECTION_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "section",
  "description": "The track section: geometry, rails, applicators and measurement sites. Exactly one, first in time.",
  "type": "object",
  "required": ["section_id", "length_m", "rails", "curve_radius_m", "rail_head_radius_m",
               "nominal_wheel_diameter_m", "applicators", "measurement_sites"],
  "properties": {
    "section_id": {"type": "string"},
    "length_m": {"type": "number", "exclusiveMinimum": 0},
    "rails": {"type": "array", "minItems": 1, "uniqueItems": true, "items": {"type": "string"}},
    "curve_radius_m": {"type": ["number", "null"], "description": "null on tangent track"},
    "rail_head_radius_m": {"type": "number", "exclusiveMinimum": 0},
    "nominal_wheel_diameter_m": {"type": "number", "exclusiveMinimum": 0},
    "applicators": {
      "type": "array",
      "minItems": 1,
      "items": {
        "type": "object",
        "required": ["id", "position_m", "rails", "nominal_pulse_g"],
        "properties": {
          "id": {"type": "string"},
          "position_m": {"type": "number", "minimum": 0},
          "rails": {"type": "array", "minItems": 1, "uniqueItems": true, "items": {"type": "string"}},
          "nominal_pulse_g": {"type": "number", "minimum": 0}
        }
      }
    },
    "measurement_sites": {
      "type": "array",
      "items": {
        "type": "object",
        "required": ["id", "position_m"],
        "properties": {
          "id": {"type": "string"},
          "position_m": {"type": "number", "minimum": 0}
        }
      }
    }
  }
}"##;

const PASSAGE_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "train_passage",
  "description": "One train passing the section; log_time is when its front crosses the entry end (d = 0 up, d = length_m down).",
  "type": "object",
  "required": ["train_id", "direction", "speed_mps", "axles"],
  "properties": {
    "train_id": {"type": "string"},
    "direction": {"enum": ["up", "down"]},
    "speed_mps": {"type": "number", "exclusiveMinimum": 0},
    "consist": {"enum": ["freight", "passenger"], "description": "informative; not part of the format"},
    "axles": {
      "type": "array",
      "minItems": 1,
      "items": {
        "type": "object",
        "required": ["offset_m", "bogie_position", "wheel_diameter_m", "wheel_load_kN", "creepage"],
        "properties": {
          "offset_m": {"type": "number", "minimum": 0, "description": "distance behind the train front, m"},
          "bogie_position": {"enum": ["leading", "trailing"]},
          "wheel_diameter_m": {"type": "number", "exclusiveMinimum": 0},
          "wheel_load_kN": {
            "type": "object",
            "description": "vertical wheel force Q per rail name, kN",
            "additionalProperties": {"type": "number", "exclusiveMinimum": 0}
          },
          "creepage": {
            "type": "object",
            "description": "creepage estimate per rail name",
            "additionalProperties": {
              "type": "object",
              "required": ["cx", "cy", "spin_per_m"],
              "properties": {
                "cx": {"type": "number"},
                "cy": {"type": "number"},
                "spin_per_m": {"type": "number"}
              }
            }
          }
        }
      }
    }
  }
}"##;

const PULSE_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "applicator_pulse",
  "description": "One pump stroke; the mass lands on the rail at the applicator's grid point at log_time.",
  "type": "object",
  "required": ["applicator_id", "rail", "mass_g"],
  "properties": {
    "applicator_id": {"type": "string"},
    "rail": {"type": "string"},
    "mass_g": {"type": "number", "minimum": 0}
  }
}"##;

const MEASUREMENT_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "measurement_friction",
  "description": "Measured friction: mu or adhesion of one axle's contact at a site, or rail_mu from a hand tribometer.",
  "type": "object",
  "required": ["site_id", "rail", "quantity", "value"],
  "properties": {
    "site_id": {"type": "string"},
    "rail": {"type": "string"},
    "quantity": {"enum": ["mu", "adhesion", "rail_mu"]},
    "train_id": {"type": "string"},
    "axle_index": {"type": "integer", "minimum": 0},
    "value": {"type": "number"}
  },
  "if": {"properties": {"quantity": {"const": "rail_mu"}}},
  "then": {"not": {"anyOf": [{"required": ["train_id"]}, {"required": ["axle_index"]}]}},
  "else": {"required": ["train_id", "axle_index"]}
}"##;

const WEATHER_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "environment_weather",
  "description": "Weather, piecewise constant until the next message.",
  "type": "object",
  "required": ["air_temperature_c", "relative_humidity", "precipitation_mm_h"],
  "properties": {
    "air_temperature_c": {"type": "number"},
    "relative_humidity": {"type": "number", "minimum": 0, "maximum": 1},
    "precipitation_mm_h": {"type": "number", "minimum": 0}
  }
}"##;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hidden_effects_become_effect_tables() {
        assert_eq!(
            hidden_effect_toml("rail_ageing:tau_s=7200").unwrap(),
            "[effects.rail_ageing]\ntau_s = 7200.0\n"
        );
        assert_eq!(
            hidden_effect_toml("wheel_edge_reservoir:alpha=0.2, r=0.05").unwrap(),
            "[effects.wheel_edge_reservoir]\nalpha = 0.2\nr = 0.05\n"
        );
        assert_eq!(
            hidden_effect_toml("bogie_bands").unwrap(),
            "[effects.bogie_bands]\n"
        );
        assert!(hidden_effect_toml("rail_ageing:tau_s=abc").is_err());
        assert!(hidden_effect_toml("rail ageing").is_err());
        assert!(hidden_effect_toml("x]\n[product:cn=1").is_err());
        let cfg = truth_config(None, &["rail_ageing:tau_s=7200".into()]).unwrap();
        assert_eq!(cfg.effects.rail_ageing.map(|e| e.tau_s), Some(7200.0));
        assert!(truth_config(None, &["rail_ageing:tau_s=-1".into()]).is_err());
        assert!(truth_config(None, &["no_such_effect".into()]).is_err());
    }

    #[test]
    fn rounding_writes_short_decimals() {
        assert_eq!(
            serde_json::to_string(&round_dp(0.123456789, 1e5)).unwrap(),
            "0.12346"
        );
        assert_eq!(
            serde_json::to_string(&round_dp(107.94, 10.0)).unwrap(),
            "107.9"
        );
    }

    #[test]
    fn climate_interpolates_without_jumps() {
        let p = SynthParams::new(Preset::Curve, 600.0);
        let mut rng = stream(1, Stream::Weather);
        let c = Climate::new(&p, &mut rng);
        let mut last = c.day_values(p.start_ns).0;
        for k in 1..(24 * 60) {
            let v = c.day_values(p.start_ns + k * 60_000_000_000).0;
            assert!((v - last).abs() < 0.05, "{last} -> {v}");
            last = v;
        }
    }
}
