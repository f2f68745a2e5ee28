//! What decides a synthetic recording: the section layout (a preset), the
//! traffic, application, weather and measurement parameters, and their
//! checks. Every field goes into the key.

use std::f64::consts::PI;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::layout::LineLayout;
use super::{round_dp, DAY_NS};
use tortwin_files::usage::UsageError;
use tortwin_recording::{Applicator, Section, Site};

/// The section layouts the generator knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    /// A 400 m curve: rails `high` and `low`, leading axles steer hard.
    Curve,
    /// Tangent track: rails `left` and `right`, small creepages.
    Tangent,
    /// A line described by a layout file (`--layout`, line.md).
    Line,
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
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            Preset::Curve => "curve",
            Preset::Tangent => "tangent",
            Preset::Line => "line",
        }
    }

    /// The share of trains running `down` when none is asked for: the curve
    /// is one track of a double-track line, the tangent a single track.
    pub fn default_down_share(self) -> f64 {
        match self {
            Preset::Curve => 0.0,
            Preset::Tangent => 0.4,
            Preset::Line => 0.5,
        }
    }
}

/// A measurement site of the generated section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteParam {
    pub id: String,
    pub position_m: f64,
}

/// Everything that decides a synthetic recording (all of it goes into the
/// key); its defaults are those of `tortwin synth`.
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
    /// A line (`--layout`): its segments, applicators and sites, which
    /// replace the preset's geometry, applicator A1 and sites.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<LineLayout>,
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
pub(crate) const DEFAULT_START_NS: u64 = 1_712_534_400_000_000_000;

/// The most days one synthetic recording spans: ten years (its size and
/// generation time grow with the days; longer spans are replayed day by
/// day with a state).
pub(crate) const MAX_DAYS: u32 = 3660;

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
            // A line's own rails and id replace these (`on_line`).
            Preset::Tangent | Preset::Line => (
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
            line: None,
        }
    }

    /// The defaults on the line `layout` describes: its rails, segments,
    /// applicators and sites; trains both ways in equal shares.
    pub fn on_line(layout: LineLayout) -> Self {
        let mut p = SynthParams::new(Preset::Line, layout.length_m());
        p.section_id = layout.line_id.clone();
        p.rails = layout.rails.clone();
        p.curve_radius_m = None;
        p.cant_m = 0.0;
        p.sites = layout.sites.clone();
        if let Some(site) = &layout.adhesion_site {
            p.adhesion_site = site.clone();
        }
        p.line = Some(layout);
        p
    }

    /// Applicator `a`'s nominal pulse mass, g.
    pub(crate) fn nominal_pulse_g(&self, a: usize) -> f64 {
        self.line
            .as_ref()
            .and_then(|l| l.applicators.get(a))
            .and_then(|app| app.nominal_pulse_g)
            .unwrap_or(self.nominal_pulse_g)
    }

    /// The recording's end: `days` after the start (exclusive).
    pub(crate) fn end_ns(&self) -> u64 {
        self.start_ns
            .saturating_add(u64::from(self.days).saturating_mul(DAY_NS))
    }

    /// Checks that the parameters describe a recording the format allows;
    /// the error names the parameter as a command-line option.
    pub fn validate(&self) -> Result<(), UsageError> {
        self.validate_as("")
    }

    /// [`SynthParams::validate`] with the options named as a command that
    /// prefixes them gives them (`strategy --synth-days`: `"synth-"`).
    pub fn validate_as(&self, prefix: &str) -> Result<(), UsageError> {
        let bad = |what: &str, v: &dyn std::fmt::Display, must: &str| {
            let what = what.replacen("--", &format!("--{prefix}"), 1);
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
        if self.days > MAX_DAYS {
            return bad(
                "--days",
                &self.days,
                &format!("at most {MAX_DAYS} (ten years; replay longer spans day by day)"),
            );
        }
        if self.start_ns >= i64::MAX as u64 {
            return bad("--start", &self.start_ns, "a time before 2262");
        }
        if self.end_ns() >= i64::MAX as u64 {
            return bad(
                "--days",
                &self.days,
                "few enough to end before 2262 from the start",
            );
        }
        if let Some(layout) = &self.line {
            layout.validate().map_err(|e| UsageError(layout.error(e)))?;
        }
        if !(self.length_m.is_finite() && self.length_m > 0.0) {
            return bad("--length-m", &self.length_m, "finite and > 0");
        }
        // The replay's limit (docs/spec/recording-format.md "Limits"),
        // checked before the grid is made.
        let points = (self.length_m / (PI * self.nominal_wheel_diameter_m)).floor() + 1.0;
        if points > tortwin_recording::MAX_GRID_POINTS as f64 {
            return bad(
                "--length-m",
                &self.length_m,
                &format!(
                    "at most {} grid points (one per wheel circumference)",
                    tortwin_recording::MAX_GRID_POINTS
                ),
            );
        }
        if let Some(layout) = &self.line {
            layout
                .line(&self.section())
                .map_err(|e| UsageError(layout.error(e)))?;
        } else if !(0.0..=self.length_m).contains(&self.applicator_position_m) {
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
                let layout = self
                    .line
                    .as_ref()
                    .map_or_else(String::new, |l| format!("--layout {}: ", l.source));
                return bad(
                    &format!("{layout}site {} position", site.id),
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
    pub(crate) fn section(&self) -> Section {
        if let Some(layout) = &self.line {
            let rail = |name: &String| self.rails.iter().position(|r| r == name);
            return Section {
                section_id: self.section_id.clone(),
                length_m: self.length_m,
                rails: self.rails.clone(),
                curve_radius_m: None,
                rail_head_radius_m: self.rail_head_radius_m,
                nominal_wheel_diameter_m: self.nominal_wheel_diameter_m,
                applicators: layout
                    .applicators
                    .iter()
                    .enumerate()
                    .map(|(a, app)| Applicator {
                        id: app.id.clone(),
                        position_m: app.position_m,
                        rails: match &app.rails {
                            Some(names) => names.iter().filter_map(rail).collect(),
                            None => (0..self.rails.len()).collect(),
                        },
                        nominal_pulse_kg: self.nominal_pulse_g(a) * 1e-3,
                    })
                    .collect(),
                sites: self.sites(),
            };
        }
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
            sites: self.sites(),
        }
    }

    fn sites(&self) -> Vec<Site> {
        self.sites
            .iter()
            .map(|s| Site {
                id: s.id.clone(),
                position_m: s.position_m,
            })
            .collect()
    }
}
