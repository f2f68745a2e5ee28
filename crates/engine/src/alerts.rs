//! Alerts an operator acts on, read from what the engine tells its sinks
//! (docs/spec/interfaces.md, "Alerts"): [`Alerting`] passes every call on
//! to the sink it wraps and, after each, the alerts that call raised or
//! cleared, as [`Sink::alert`]. Everything is decided from the calls in
//! their order, so a replay and a follower of the same recording raise the
//! same alerts at the same log_times.
//!
//! | kind | from | raised when |
//! |---|---|---|
//! | `friction_low` | each train's simulated field, per rail and band | mu below the band over `below_length_m` of the section, `trains` trains in a row |
//! | `friction_high` | the same, within the protected stretch | mu above the band over `above_length_m`, `trains` trains in a row |
//! | `pulses_stopped` | pulses and trains | an applicator rail that has pulsed gets none for `pulses.trains` trains |
//! | `applicator_fade` | residual charts | a chart's CUSUM of "measured above simulated", corroborated by another site or rail the same applicator feeds |
//! | `applicator_surplus` | residual charts | the same for "measured below simulated" |
//! | `sensor_drift` | residual charts | a chart's CUSUM, either way, alone |
//! | `sensor_stuck` | readings | `stuck.readings` readings in a row the same while the simulated value moved `model_range` |
//! | `data_gap` | weather | a gap of `factor` typical intervals in an input that came regularly |
//!
//! A residual chart is one site, rail and quantity. Its sample is a train's
//! mean residual (measured − simulated) over the axles measured there,
//! readings beyond 5 standard deviations of their median left out (a
//! tribometer reading is a sample on its own). The first `warmup` samples
//! set the spread between trains `s_b²` (robustly, from their median
//! absolute deviation) and within a train `s_w²` (pooled, and kept up with
//! every normal sample after): a sample of n readings has variance `v =
//! s_b² + s_w² / n`. The chart is a self-starting CUSUM: each sample less the
//! weighted mean `x̄` of the normal samples before it, `z = (x − x̄) / √(v +
//! var x̄)` (these recursive residuals are independent and standard normal
//! when nothing changes), clipped to ±h/2 (no single train raises an
//! alarm), feeds `S⁺ = max(0, S⁺ + z − k)` and `S⁻ = max(0, S⁻ − z − k)`; a
//! sum above `h` alarms. A sample joins `x̄` while its chart is quiet. The run
//! length between false alarms of one side is then Siegmund's `(e^{2kb} −
//! 2kb − 1) / (2k²)`, `b = h + 1.166`: 19 100 samples at the defaults (k =
//! 0.5, h = 8), checked by the tests against simulated noise.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use tortwin_model::config::alerts::AlertConfig;
use tortwin_recording::Quantity;

use crate::sink::{
    FieldSnapshot, LineWheels, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink,
    SinkResult, SnapshotKind, TrainEvent, WheelContacts,
};

/// What an alert is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum AlertKind {
    FrictionLow,
    FrictionHigh,
    PulsesStopped,
    ApplicatorFade,
    ApplicatorSurplus,
    SensorDrift,
    SensorStuck,
    DataGap,
}

impl AlertKind {
    pub fn as_str(self) -> &'static str {
        match self {
            AlertKind::FrictionLow => "friction_low",
            AlertKind::FrictionHigh => "friction_high",
            AlertKind::PulsesStopped => "pulses_stopped",
            AlertKind::ApplicatorFade => "applicator_fade",
            AlertKind::ApplicatorSurplus => "applicator_surplus",
            AlertKind::SensorDrift => "sensor_drift",
            AlertKind::SensorStuck => "sensor_stuck",
            AlertKind::DataGap => "data_gap",
        }
    }
}

/// An alert begins (`Raised`) or ends (`Cleared`); a data gap is raised
/// once, when the data resumes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlertState {
    Raised,
    Cleared,
}

impl AlertState {
    pub fn as_str(self) -> &'static str {
        match self {
            AlertState::Raised => "raised",
            AlertState::Cleared => "cleared",
        }
    }
}

/// One alert and its evidence.
#[derive(Debug, Clone, PartialEq)]
pub struct Alert {
    /// The event that decided it (a train's end, a reading, a message).
    pub log_time_ns: u64,
    pub kind: AlertKind,
    pub state: AlertState,
    /// Braking risk (`friction_low`) is an error; the rest warnings; a
    /// cleared alert is information.
    pub error: bool,
    pub applicator_id: Option<String>,
    pub site_id: Option<String>,
    pub rail: Option<String>,
    pub band: Option<String>,
    pub quantity: Option<Quantity>,
    pub train_id: Option<String>,
    /// One line for a person.
    pub message: String,
    /// The numbers behind it, named.
    pub evidence: Vec<(&'static str, f64)>,
    /// Sites behind an applicator's alert.
    pub sites: Vec<String>,
}

impl Alert {
    fn new(log_time_ns: u64, kind: AlertKind, state: AlertState, message: String) -> Alert {
        Alert {
            log_time_ns,
            kind,
            state,
            error: kind == AlertKind::FrictionLow && state == AlertState::Raised,
            applicator_id: None,
            site_id: None,
            rail: None,
            band: None,
            quantity: None,
            train_id: None,
            message,
            evidence: Vec::new(),
            sites: Vec::new(),
        }
    }
}

/// Passes every call to `inner`, and the alerts each raises or clears.
pub struct Alerting<S> {
    pub inner: S,
    /// `None` with alerts off: the calls only pass through.
    detector: Option<Detector>,
    raised: Vec<Alert>,
}

impl<S: Sink> Alerting<S> {
    /// Alerts from a fresh start, or continuing `memory` (a state's,
    /// checked with [`AlertMemory::check`]). With `config.enabled` false
    /// it passes the calls on and raises nothing.
    pub fn new(config: AlertConfig, memory: Option<AlertMemory>, inner: S) -> Self {
        let detector = config.enabled.then(|| {
            let mut detector = Detector::new(config);
            detector.resume = memory;
            detector
        });
        Alerting {
            inner,
            detector,
            raised: Vec::new(),
        }
    }

    /// What the alerts remember, for the state (`None` when they are off).
    pub fn memory(&self) -> Option<AlertMemory> {
        self.detector.as_ref().map(|d| AlertMemory {
            low: d.low.clone(),
            high: d.high.clone(),
            pulses: d
                .pulses
                .iter()
                .map(|(k, w)| (k.0, k.1, w.clone()))
                .collect(),
            charts: d
                .charts
                .iter()
                .map(|(k, c)| (k.0, k.1, k.2, c.clone()))
                .collect(),
            stuck: d
                .stuck
                .iter()
                .map(|(k, c)| (k.0, k.1, k.2, c.clone()))
                .collect(),
            applicator_alarm: d.applicator_alarm.clone(),
            gap: d.gap.clone(),
        })
    }

    fn emit(&mut self) -> SinkResult {
        for alert in self.raised.drain(..) {
            self.inner.alert(&alert)?;
        }
        Ok(())
    }
}

impl<S: Sink> Sink for Alerting<S> {
    fn begin(&mut self, info: &SectionInfo<'_>) -> SinkResult {
        self.inner.begin(info)?;
        if let Some(d) = self.detector.as_mut() {
            d.begin(info);
        }
        Ok(())
    }
    fn train(&mut self, train: &TrainEvent<'_>) -> SinkResult {
        self.inner.train(train)?;
        if let Some(d) = self.detector.as_mut() {
            d.train(train, &mut self.raised);
        }
        self.emit()
    }
    fn pulse(&mut self, pulse: &PulseEvent<'_>) -> SinkResult {
        self.inner.pulse(pulse)?;
        if let Some(d) = self.detector.as_mut() {
            d.pulse(pulse, &mut self.raised);
        }
        self.emit()
    }
    fn measurement(&mut self, m: &MeasurementOutput) -> SinkResult {
        self.inner.measurement(m)?;
        if let Some(d) = self.detector.as_mut() {
            d.measurement(m, &mut self.raised);
        }
        self.emit()
    }
    fn wants_readouts(&self) -> bool {
        self.inner.wants_readouts()
    }
    fn field(&mut self, f: &FieldSnapshot<'_>) -> SinkResult {
        self.inner.field(f)?;
        if let Some(d) = self.detector.as_mut() {
            d.field(f, &mut self.raised);
        }
        self.emit()
    }
    fn wheel_contacts(&mut self, w: &WheelContacts<'_>) -> SinkResult {
        self.inner.wheel_contacts(w)
    }
    fn line_wheels(&mut self, w: &LineWheels<'_>) -> SinkResult {
        self.inner.line_wheels(w)
    }
    fn weather(&mut self, log_time_ns: u64) -> SinkResult {
        self.inner.weather(log_time_ns)?;
        if let Some(d) = self.detector.as_mut() {
            d.weather(log_time_ns, &mut self.raised);
        }
        self.emit()
    }
    fn alert(&mut self, alert: &Alert) -> SinkResult {
        self.inner.alert(alert)
    }
    fn finish(&mut self, summary: &RunSummary) -> SinkResult {
        if let Some(d) = self.detector.as_mut() {
            d.close_samples(None, &mut self.raised);
        }
        self.emit()?;
        self.inner.finish(summary)
    }
}

/// What the alerts remember between recordings (in the state file's
/// `alerts`): per track the runs of trains in and out of the band, per
/// applicator rail its pulse watch, per site, rail and quantity the
/// residual chart and the stuck-reading run, the applicators fading, and
/// the weather's intervals.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlertMemory {
    low: Vec<Run>,
    high: Vec<Run>,
    pulses: Vec<(usize, usize, PulseWatch)>,
    charts: Vec<(usize, usize, Quantity, Chart)>,
    stuck: Vec<(usize, usize, Quantity, Stuck)>,
    applicator_alarm: Vec<[bool; 2]>,
    gap: Gap,
}

impl AlertMemory {
    /// Whether the memory fits `section` with `tracks` rail bands and
    /// holds only what the alerts could have written; the error says what
    /// does not.
    pub fn check(&self, section: &tortwin_recording::Section, tracks: usize) -> Result<(), String> {
        let (rails, sites, applicators) = (
            section.rails.len(),
            section.sites.len(),
            section.applicators.len(),
        );
        if self.low.len() != tracks || self.high.len() != tracks {
            return Err(format!(
                "alerts: {} and {} band runs for {tracks} rail bands",
                self.low.len(),
                self.high.len()
            ));
        }
        if self.applicator_alarm.len() != applicators {
            return Err(format!(
                "alerts.applicator_alarm: {} entries for {applicators} applicators",
                self.applicator_alarm.len()
            ));
        }
        let finite = |what: &str, v: f64| match v.is_finite() {
            true => Ok(()),
            false => Err(format!("alerts: {what} is {v}, not a finite number")),
        };
        for (k, (a, rail, _)) in self.pulses.iter().enumerate() {
            if *a >= applicators || *rail >= rails {
                return Err(format!(
                    "alerts.pulses[{k}]: no applicator {a} on rail {rail}"
                ));
            }
        }
        for (k, (site, rail, _, c)) in self.charts.iter().enumerate() {
            if *site >= sites || *rail >= rails {
                return Err(format!("alerts.charts[{k}]: no site {site} on rail {rail}"));
            }
            let what = format!("alerts.charts[{k}]");
            for v in c
                .open
                .iter()
                .chain(&[c.s_plus, c.s_minus, c.last_z, c.last_shift])
            {
                finite(&what, *v)?;
            }
            for w in &c.warm {
                finite(&what, w.0)?;
                finite(&what, w.2)?;
                if w.1 == 0 || w.2 < 0.0 {
                    return Err(format!("{what}: a warm-up sample of {} readings", w.1));
                }
            }
            if let Some(b) = &c.base {
                for v in [
                    b.var_b,
                    b.within_sum,
                    b.within_dof,
                    b.weight,
                    b.weighted_sum,
                ] {
                    finite(&what, v)?;
                }
                let positive = b.weight > 0.0 && b.var_b >= 0.0 && b.within_sum >= 0.0;
                if !positive || b.within_dof < 0.0 {
                    return Err(format!("{what}: a negative variance or weight"));
                }
            }
            if c.s_plus < 0.0 || c.s_minus < 0.0 || !(-1..=1).contains(&c.alarmed) {
                return Err(format!("{what}: sums below 0 or a side not -1, 0 or 1"));
            }
        }
        for (k, (site, rail, _, st)) in self.stuck.iter().enumerate() {
            if *site >= sites || *rail >= rails {
                return Err(format!("alerts.stuck[{k}]: no site {site} on rail {rail}"));
            }
            for v in [st.first, st.sim_min, st.sim_max] {
                finite(&format!("alerts.stuck[{k}]"), v)?;
            }
        }
        for v in &self.gap.intervals {
            finite("alerts.gap.intervals", *v)?;
        }
        Ok(())
    }
}

/// The section as the alerts need it.
#[derive(Default)]
struct Layout {
    rails: Vec<String>,
    /// (id, position, rails).
    applicators: Vec<(String, f64, Vec<usize>)>,
    /// (id, position).
    sites: Vec<(String, f64)>,
    grid_d_m: Vec<f64>,
    /// Each point's share of the track: half the way to its neighbours.
    width_m: Vec<f64>,
    /// The protected stretch of `friction_high`.
    stretch_m: [f64; 2],
}

impl Layout {
    /// The applicator that feeds `site` on `rail`: the nearest on that rail
    /// at or before the site (up the chainage), else the nearest after it.
    fn feeder(&self, site: usize, rail: usize) -> Option<usize> {
        let at = self.sites.get(site)?.1;
        let on_rail = || {
            self.applicators
                .iter()
                .enumerate()
                .filter(move |(_, a)| a.2.contains(&rail))
        };
        let before = on_rail()
            .filter(|(_, a)| a.1 <= at)
            .max_by(|x, y| x.1 .1.total_cmp(&y.1 .1));
        let after = on_rail()
            .filter(|(_, a)| a.1 > at)
            .min_by(|x, y| x.1 .1.total_cmp(&y.1 .1));
        before.or(after).map(|(i, _)| i)
    }
}

/// A rail band's run of trains in and out of a condition.
#[derive(Default, Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Run {
    /// Trains in a row with the condition (`on`) or without it.
    on: u32,
    off: u32,
    active: bool,
}

impl Run {
    /// One train: `Some(true)` when the alert is raised now,
    /// `Some(false)` when it clears.
    fn step(&mut self, holds: bool, trains: u32) -> Option<bool> {
        if holds {
            self.on += 1;
            self.off = 0;
        } else {
            self.off += 1;
            self.on = 0;
        }
        if !self.active && self.on >= trains {
            self.active = true;
            return Some(true);
        }
        if self.active && self.off >= trains {
            self.active = false;
            return Some(false);
        }
        None
    }
}

#[derive(Default, Clone, Debug, PartialEq, Serialize, Deserialize)]
struct PulseWatch {
    pulsed: bool,
    trains_since: u32,
    active: bool,
    last_pulse_ns: u64,
}

/// A residual chart: one site, rail and quantity.
#[derive(Default, Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Chart {
    /// The residuals of the train being measured.
    open: Vec<f64>,
    open_train: Option<String>,
    /// The log_time of the open sample's last reading.
    open_last_ns: u64,
    /// Warm-up samples: (median, readings, within-train variance).
    warm: Vec<(f64, usize, f64)>,
    /// Baseline: median, variance between trains, within a train.
    base: Option<Baseline>,
    s_plus: f64,
    s_minus: f64,
    /// The side that alarmed (+1 measured above simulated), until cleared.
    alarmed: i8,
    calm: u32,
    /// An applicator's alert took this chart's alarm.
    in_applicator: bool,
    /// A sensor_drift alert was raised for this chart and not cleared.
    drift_raised: bool,
    last_z: f64,
    last_shift: f64,
    samples: u64,
}

#[derive(Default, Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Stuck {
    first: f64,
    readings: u32,
    sim_min: f64,
    sim_max: f64,
    active: bool,
}

#[derive(Default, Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Gap {
    last_ns: Option<u64>,
    intervals: Vec<f64>,
}

struct Detector {
    config: AlertConfig,
    layout: Layout,
    /// Per track (index of `SectionInfo::tracks`): (rail, band) names and runs.
    low: Vec<Run>,
    high: Vec<Run>,
    pulses: BTreeMap<(usize, usize), PulseWatch>,
    charts: BTreeMap<(usize, usize, Quantity), Chart>,
    stuck: BTreeMap<(usize, usize, Quantity), Stuck>,
    /// Per applicator: its fade and its surplus raised.
    applicator_alarm: Vec<[bool; 2]>,
    gap: Gap,
    /// What a state's alerts remembered, taken at [`Sink::begin`].
    resume: Option<AlertMemory>,
}

impl Detector {
    fn new(config: AlertConfig) -> Self {
        Detector {
            config,
            layout: Layout::default(),
            low: Vec::new(),
            high: Vec::new(),
            pulses: BTreeMap::new(),
            charts: BTreeMap::new(),
            stuck: BTreeMap::new(),
            applicator_alarm: Vec::new(),
            gap: Gap::default(),
            resume: None,
        }
    }

    fn begin(&mut self, info: &SectionInfo<'_>) {
        let s = &info.section;
        let d = info.grid_d_m.to_vec();
        let width_m = (0..d.len()).map(|k| point_width_m(&d, k)).collect();
        let applicators: Vec<_> = s
            .applicators
            .iter()
            .map(|a| (a.id.clone(), a.position_m, a.rails.clone()))
            .collect();
        let sites: Vec<_> = s
            .sites
            .iter()
            .map(|x| (x.id.clone(), x.position_m))
            .collect();
        // The protected stretch: from the first applicator to the first
        // site beyond it, unless the configuration says.
        let first = applicators.iter().map(|a| a.1).min_by(f64::total_cmp);
        let default_from = first.unwrap_or(0.0);
        let default_to = first
            .and_then(|a| {
                sites
                    .iter()
                    .map(|x| x.1)
                    .filter(|&p| p > a)
                    .min_by(f64::total_cmp)
            })
            .unwrap_or(s.length_m);
        let band = &self.config.band;
        let stretch_m = [
            band.from_m.unwrap_or(default_from),
            band.to_m.unwrap_or(default_to),
        ];
        self.applicator_alarm = vec![[false; 2]; applicators.len()];
        self.layout = Layout {
            rails: s.rails.clone(),
            applicators,
            sites,
            grid_d_m: d,
            width_m,
            stretch_m,
        };
        self.low = vec![Run::default(); info.tracks.len()];
        self.high = vec![Run::default(); info.tracks.len()];
        if let Some(m) = self.resume.take() {
            // Checked against this section by the caller (AlertMemory::check).
            if m.low.len() == self.low.len()
                && m.applicator_alarm.len() == self.applicator_alarm.len()
            {
                self.low = m.low;
                self.high = m.high;
                self.pulses = m.pulses.into_iter().map(|(a, r, w)| ((a, r), w)).collect();
                self.charts = m
                    .charts
                    .into_iter()
                    .map(|(s, r, q, c)| ((s, r, q), c))
                    .collect();
                self.stuck = m
                    .stuck
                    .into_iter()
                    .map(|(s, r, q, c)| ((s, r, q), c))
                    .collect();
                self.applicator_alarm = m.applicator_alarm;
                self.gap = m.gap;
            }
        }
    }

    fn rail_name(&self, rail: usize) -> String {
        self.layout.rails.get(rail).cloned().unwrap_or_default()
    }

    fn train(&mut self, train: &TrainEvent<'_>, out: &mut Vec<Alert>) {
        let limit = self.config.pulses.trains;
        for (&(a, rail), watch) in self.pulses.iter_mut() {
            if !watch.pulsed {
                continue;
            }
            watch.trains_since += 1;
            if !watch.active && watch.trains_since >= limit {
                watch.active = true;
                let (id, _, _) = &self.layout.applicators[a];
                let rail_name = self.layout.rails.get(rail).cloned().unwrap_or_default();
                let mut alert = Alert::new(
                    train.log_time_ns,
                    AlertKind::PulsesStopped,
                    AlertState::Raised,
                    format!(
                        "applicator {id} on rail {rail_name}: no pulse for {} trains \
                         (the last at {})",
                        watch.trains_since,
                        utc(watch.last_pulse_ns)
                    ),
                );
                alert.applicator_id = Some(id.clone());
                alert.rail = Some(rail_name);
                alert.train_id = Some(train.train_id.to_string());
                alert.evidence = vec![
                    ("trains", f64::from(watch.trains_since)),
                    ("last_pulse_ns", watch.last_pulse_ns as f64),
                ];
                out.push(alert);
            }
        }
    }

    fn pulse(&mut self, pulse: &PulseEvent<'_>, out: &mut Vec<Alert>) {
        let watch = self
            .pulses
            .entry((pulse.applicator, pulse.rail))
            .or_default();
        watch.pulsed = true;
        watch.trains_since = 0;
        watch.last_pulse_ns = pulse.log_time_ns;
        if watch.active {
            watch.active = false;
            let mut alert = Alert::new(
                pulse.log_time_ns,
                AlertKind::PulsesStopped,
                AlertState::Cleared,
                format!(
                    "applicator {} on rail {}: pulsing again",
                    pulse.applicator_id, pulse.rail_name
                ),
            );
            alert.applicator_id = Some(pulse.applicator_id.to_string());
            alert.rail = Some(pulse.rail_name.to_string());
            out.push(alert);
        }
    }

    fn field(&mut self, f: &FieldSnapshot<'_>, out: &mut Vec<Alert>) {
        if f.kind != SnapshotKind::Train {
            return;
        }
        // A train's measurements come before its fields: its samples are whole.
        self.close_samples(Some(f.log_time_ns), out);
        let band = &self.config.band;
        let [from, to] = self.layout.stretch_m;
        let (mut below, mut above) = (0.0, 0.0);
        let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
        for (k, &mu) in f.mu.iter().enumerate() {
            if !mu.is_finite() {
                continue; // a line's band no wheel of this train used
            }
            let w = self.layout.width_m.get(k).copied().unwrap_or(0.0);
            if mu < band.lower_mu {
                below += w;
                min = min.min(mu);
            }
            let d = self.layout.grid_d_m.get(k).copied().unwrap_or(f64::NAN);
            if mu > band.upper_mu && (from..=to).contains(&d) {
                above += w;
                max = max.max(mu);
            }
        }
        let trains = band.trains;
        let checks = [
            (
                AlertKind::FrictionLow,
                below >= band.below_length_m && below > 0.0,
                below,
                min,
            ),
            (
                AlertKind::FrictionHigh,
                above >= band.above_length_m && above > 0.0,
                above,
                max,
            ),
        ];
        for (kind, holds, length, extreme) in checks {
            let runs = match kind {
                AlertKind::FrictionLow => &mut self.low,
                _ => &mut self.high,
            };
            let Some(run) = runs.get_mut(f.track) else {
                continue;
            };
            let Some(raised) = run.step(holds, trains) else {
                continue;
            };
            let state = if raised {
                AlertState::Raised
            } else {
                AlertState::Cleared
            };
            let what = match (kind, raised) {
                (AlertKind::FrictionLow, true) => format!(
                    "braking risk: mu below {} over {length:.0} m (least {extreme:.3}), \
                     {trains} trains in a row",
                    band.lower_mu
                ),
                (AlertKind::FrictionLow, false) => {
                    format!(
                        "mu below {} no more, {trains} trains in a row",
                        band.lower_mu
                    )
                }
                (_, true) => format!(
                    "dry: mu above {} over {length:.0} m of {from:.0}-{to:.0} m \
                     (most {extreme:.3}), {trains} trains in a row",
                    band.upper_mu
                ),
                (_, false) => format!(
                    "mu above {} no more within {from:.0}-{to:.0} m, {trains} trains in a row",
                    band.upper_mu
                ),
            };
            let mut alert = Alert::new(
                f.log_time_ns,
                kind,
                state,
                format!("rail {} ({}): {what}", f.rail_name, f.band),
            );
            alert.rail = Some(f.rail_name.to_string());
            alert.band = Some(f.band.to_string());
            alert.train_id = Some(f.train_id.to_string());
            alert.evidence = vec![("length_m", length), ("trains", f64::from(trains))];
            if raised {
                alert.evidence.push(match kind {
                    AlertKind::FrictionLow => ("mu_min", extreme),
                    _ => ("mu_max", extreme),
                });
            }
            if kind == AlertKind::FrictionHigh {
                alert.evidence.push(("from_m", from));
                alert.evidence.push(("to_m", to));
            }
            out.push(alert);
        }
    }

    fn measurement(&mut self, m: &MeasurementOutput, out: &mut Vec<Alert>) {
        let key = (m.site, m.rail, m.quantity);
        let residual = m.measured - m.simulated;
        self.check_stuck(key, m, out);
        match &m.train_id {
            Some(train) => {
                let chart = self.charts.entry(key).or_default();
                if chart.open_train.as_deref() != Some(train.as_ref()) && !chart.open.is_empty() {
                    // A later train's reading: the earlier train's sample is whole.
                    self.close_charts(&[(key, m.log_time_ns)], out);
                }
                let chart = self.charts.entry(key).or_default();
                // A train's readings come together: its id is copied once.
                if chart.open_train.as_deref() != Some(train.as_ref()) {
                    chart.open_train = Some(train.to_string());
                }
                chart.open.push(residual);
                chart.open_last_ns = m.log_time_ns;
            }
            None => {
                // A tribometer reading is a sample on its own.
                let chart = self.charts.entry(key).or_default();
                chart.open.clear();
                chart.open.push(residual);
                chart.open_train = None;
                self.close_charts(&[(key, m.log_time_ns)], out);
            }
        }
    }

    fn check_stuck(
        &mut self,
        key: (usize, usize, Quantity),
        m: &MeasurementOutput,
        out: &mut Vec<Alert>,
    ) {
        let cfg = &self.config.stuck;
        let s = self.stuck.entry(key).or_default();
        if s.readings > 0 && (m.measured - s.first).abs() <= cfg.tolerance {
            s.readings += 1;
            s.sim_min = s.sim_min.min(m.simulated);
            s.sim_max = s.sim_max.max(m.simulated);
        } else {
            let was = s.active;
            *s = Stuck {
                first: m.measured,
                readings: 1,
                sim_min: m.simulated,
                sim_max: m.simulated,
                active: false,
            };
            if was {
                let mut alert = Alert::new(
                    m.log_time_ns,
                    AlertKind::SensorStuck,
                    AlertState::Cleared,
                    format!(
                        "site {} rail {} {}: readings move again",
                        m.site_id,
                        m.rail_name,
                        m.quantity.as_str()
                    ),
                );
                alert.site_id = Some(m.site_id.to_string());
                alert.rail = Some(m.rail_name.to_string());
                alert.quantity = Some(m.quantity);
                out.push(alert);
            }
            return;
        }
        let range = s.sim_max - s.sim_min;
        if !s.active && s.readings >= cfg.readings && range >= cfg.model_range {
            s.active = true;
            let mut alert = Alert::new(
                m.log_time_ns,
                AlertKind::SensorStuck,
                AlertState::Raised,
                format!(
                    "site {} rail {} {}: {} readings in a row at {} while the model moved \
                     {:.3} to {:.3}",
                    m.site_id,
                    m.rail_name,
                    m.quantity.as_str(),
                    s.readings,
                    s.first,
                    s.sim_min,
                    s.sim_max
                ),
            );
            alert.site_id = Some(m.site_id.to_string());
            alert.rail = Some(m.rail_name.to_string());
            alert.quantity = Some(m.quantity);
            alert.train_id = m.train_id.as_ref().map(|t| t.to_string());
            alert.evidence = vec![
                ("readings", f64::from(s.readings)),
                ("value", s.first),
                ("simulated_min", s.sim_min),
                ("simulated_max", s.sim_max),
            ];
            out.push(alert);
        }
    }

    /// Closes every chart's open sample (`at`: the log_time the alerts
    /// carry; `None` at the end of the run, each chart's last reading's).
    fn close_samples(&mut self, at: Option<u64>, out: &mut Vec<Alert>) {
        let open: Vec<_> = self
            .charts
            .iter()
            .filter(|(_, c)| !c.open.is_empty())
            .map(|(k, c)| (*k, at.unwrap_or(c.open_last_ns)))
            .collect();
        self.close_charts(&open, out);
    }

    /// Takes a chart's open sample into its baseline or its CUSUM.
    /// Closes the charts' open samples, then decides what their alarms
    /// mean: after every chart has taken the train, so that the sites
    /// that agree are seen together.
    fn close_charts(&mut self, charts: &[((usize, usize, Quantity), u64)], out: &mut Vec<Alert>) {
        let mut turns = Vec::new();
        for &(key, at_ns) in charts {
            if let Some(turn) = self.close_chart(key) {
                turns.push((key, at_ns, turn));
            }
        }
        for (key, at_ns, (side, alarmed, train_id)) in turns {
            match alarmed {
                true => self.alarm(key, side, at_ns, train_id, out),
                false => self.cleared_chart(key, side, at_ns, out),
            }
        }
    }

    /// Takes a chart's open sample into its baseline or its CUSUM; returns
    /// the side that alarmed (`true`) or cleared (`false`) with the train.
    fn close_chart(&mut self, key: (usize, usize, Quantity)) -> Option<(i8, bool, Option<String>)> {
        let cfg = self.config.residual.clone();
        let chart = self.charts.get_mut(&key).filter(|c| !c.open.is_empty())?;
        // The train's readings, less gross errors: those beyond 5 standard
        // deviations (the chart's, or this train's own robust one) of
        // their median; the sample is the mean of the rest.
        let mid = median(&mut chart.open);
        let spread = match chart.base.as_ref().map(Baseline::var_w) {
            Some(var_w) if var_w > 0.0 => var_w.sqrt(),
            _ => {
                let mut d: Vec<f64> = chart.open.iter().map(|r| (r - mid).abs()).collect();
                1.4826 * median(&mut d)
            }
        };
        chart.open.retain(|r| (r - mid).abs() <= 5.0 * spread);
        let n = chart.open.len().max(1);
        let x = match chart.open.is_empty() {
            true => mid,
            false => chart.open.iter().sum::<f64>() / n as f64,
        };
        let within = if n > 1 {
            chart.open.iter().map(|r| (r - x).powi(2)).sum::<f64>() / (n - 1) as f64
        } else {
            0.0
        };
        chart.open.clear();
        let train_id = chart.open_train.take();
        chart.samples += 1;
        let Some(base) = chart.base.as_mut() else {
            chart.warm.push((x, n, within));
            if chart.warm.len() >= cfg.warmup as usize {
                chart.base = Some(Baseline::of(&chart.warm));
                chart.warm = Vec::new();
            }
            return None;
        };
        // The self-starting CUSUM's recursive residual: the sample less the
        // mean of the samples before it, over the spread of both.
        let v = base.variance(n);
        let shift = x - base.mean();
        let z = (shift / (v + base.mean_variance()).sqrt()).clamp(-cfg.h / 2.0, cfg.h / 2.0);
        let quiet = chart.alarmed == 0 && z.abs() < cfg.h / 2.0;
        chart.last_z = z;
        chart.last_shift = shift;
        chart.s_plus = (chart.s_plus + z - cfg.k).max(0.0);
        chart.s_minus = (chart.s_minus - z - cfg.k).max(0.0);
        if chart.alarmed != 0 {
            chart.calm = if z.abs() < 1.0 { chart.calm + 1 } else { 0 };
            if chart.calm >= cfg.clear {
                let side = chart.alarmed;
                chart.alarmed = 0;
                chart.calm = 0;
                chart.s_plus = 0.0;
                chart.s_minus = 0.0;
                return Some((side, false, train_id));
            }
            return None;
        }
        let side = if chart.s_plus > cfg.h {
            1
        } else if chart.s_minus > cfg.h {
            -1
        } else {
            if quiet {
                // A sample of the chart's normal: it joins the baseline.
                if let Some(base) = chart.base.as_mut() {
                    base.add(x, n, within);
                }
            }
            return None;
        };
        chart.alarmed = side;
        chart.calm = 0;
        Some((side, true, train_id))
    }

    /// A chart alarmed: the applicator's if another site or rail the same
    /// applicator feeds agrees (a fade when measured friction is above the
    /// model, a surplus when below), else the sensor's drift (nothing if
    /// the sensor is stuck: that alert says it).
    fn alarm(
        &mut self,
        key: (usize, usize, Quantity),
        side: i8,
        at_ns: u64,
        train_id: Option<String>,
        out: &mut Vec<Alert>,
    ) {
        let (site, rail, quantity) = key;
        let h = self.config.residual.h;
        let bar = self.config.residual.corroborate * h;
        let feeder = self.layout.feeder(site, rail);
        let agreeing: Vec<(usize, usize, Quantity)> = match feeder {
            Some(a) => self
                .charts
                .iter()
                .filter(|(k, c)| {
                    let sum = if side > 0 { c.s_plus } else { c.s_minus };
                    (k.0, k.1) != (site, rail)
                        && self.layout.feeder(k.0, k.1) == Some(a)
                        && (c.alarmed == side || sum >= bar)
                })
                .map(|(k, _)| *k)
                .collect(),
            None => Vec::new(),
        };
        let chart = &self.charts[&key];
        let (stat, shift, z) = (
            if side > 0 {
                chart.s_plus
            } else {
                chart.s_minus
            },
            chart.last_shift,
            chart.last_z,
        );
        let site_id = self.site_name(site);
        let rail_name = self.rail_name(rail);
        if let (Some(a), false) = (feeder, agreeing.is_empty()) {
            for k in std::iter::once(key).chain(agreeing.iter().copied()) {
                if let Some(c) = self.charts.get_mut(&k) {
                    c.in_applicator = true;
                }
            }
            let slot = usize::from(side < 0);
            if self.applicator_alarm[a][slot] {
                return;
            }
            self.applicator_alarm[a][slot] = true;
            let id = self.layout.applicators[a].0.clone();
            let sites: Vec<String> = std::iter::once(key)
                .chain(agreeing.iter().copied())
                .map(|(s, r, q)| {
                    format!("{} {} {}", self.site_name(s), self.rail_name(r), q.as_str())
                })
                .collect();
            let (kind, what) = match side > 0 {
                true => (
                    AlertKind::ApplicatorFade,
                    "measured friction above the model: less product than the log says \
                     (a clogged nozzle, an empty tank, a pump that delivers less)",
                ),
                false => (
                    AlertKind::ApplicatorSurplus,
                    "measured friction below the model: more product than the log says \
                     (pulses not logged, or larger than recorded)",
                ),
            };
            let mut alert = Alert::new(
                at_ns,
                kind,
                AlertState::Raised,
                format!(
                    "applicator {id}: {what}, at {} (at {site_id} {rail_name} {} by \
                     {shift:+.3}, CUSUM {stat:.1} > {h})",
                    sites.join(", "),
                    quantity.as_str()
                ),
            );
            alert.applicator_id = Some(id);
            alert.site_id = Some(site_id);
            alert.rail = Some(rail_name);
            alert.quantity = Some(quantity);
            alert.train_id = train_id;
            alert.sites = sites;
            alert.evidence = vec![("statistic", stat), ("h", h), ("shift", shift), ("z", z)];
            out.push(alert);
            return;
        }
        if self.stuck.get(&key).is_some_and(|s| s.active) {
            return;
        }
        if let Some(c) = self.charts.get_mut(&key) {
            c.drift_raised = true;
        }
        let way = if side > 0 { "above" } else { "below" };
        let mut alert = Alert::new(
            at_ns,
            AlertKind::SensorDrift,
            AlertState::Raised,
            format!(
                "site {site_id} rail {rail_name} {}: measured {way} the model by {shift:+.3} \
                 (CUSUM {stat:.1} > {h}); no other site the same applicator feeds agrees",
                quantity.as_str()
            ),
        );
        alert.site_id = Some(site_id);
        alert.rail = Some(rail_name);
        alert.quantity = Some(quantity);
        alert.train_id = train_id;
        alert.evidence = vec![
            ("statistic", stat),
            ("h", h),
            ("shift", shift),
            ("z", z),
            ("direction", f64::from(side)),
        ];
        out.push(alert);
    }

    /// A chart that alarmed on `side` is calm again: its drift alert
    /// clears, and its applicator's once no chart of it is alarmed.
    fn cleared_chart(
        &mut self,
        key: (usize, usize, Quantity),
        side: i8,
        at_ns: u64,
        out: &mut Vec<Alert>,
    ) {
        let (site, rail, quantity) = key;
        let Some(chart) = self.charts.get_mut(&key) else {
            return;
        };
        let drift = std::mem::take(&mut chart.drift_raised);
        let applicator = std::mem::take(&mut chart.in_applicator);
        if drift {
            let mut alert = Alert::new(
                at_ns,
                AlertKind::SensorDrift,
                AlertState::Cleared,
                format!(
                    "site {} rail {} {}: agrees with the model again",
                    self.site_name(site),
                    self.rail_name(rail),
                    quantity.as_str()
                ),
            );
            alert.site_id = Some(self.site_name(site));
            alert.rail = Some(self.rail_name(rail));
            alert.quantity = Some(quantity);
            out.push(alert);
        }
        let Some(a) = self.layout.feeder(site, rail).filter(|_| applicator) else {
            return;
        };
        let slot = usize::from(side < 0);
        let still = self.charts.iter().any(|(k, c)| {
            c.in_applicator && c.alarmed == side && self.layout.feeder(k.0, k.1) == Some(a)
        });
        if still || !self.applicator_alarm[a][slot] {
            return;
        }
        self.applicator_alarm[a][slot] = false;
        let id = self.layout.applicators[a].0.clone();
        let kind = match side > 0 {
            true => AlertKind::ApplicatorFade,
            false => AlertKind::ApplicatorSurplus,
        };
        let mut alert = Alert::new(
            at_ns,
            kind,
            AlertState::Cleared,
            format!("applicator {id}: the sites it feeds agree with the model again"),
        );
        alert.applicator_id = Some(id);
        out.push(alert);
    }

    fn site_name(&self, site: usize) -> String {
        self.layout
            .sites
            .get(site)
            .map(|s| s.0.clone())
            .unwrap_or_default()
    }

    fn weather(&mut self, log_time_ns: u64, out: &mut Vec<Alert>) {
        let cfg = &self.config.data_gap;
        let gap = &mut self.gap;
        let Some(last) = gap.last_ns.replace(log_time_ns) else {
            return;
        };
        let interval_s = log_time_ns.saturating_sub(last) as f64 * 1e-9;
        let n = cfg.intervals as usize;
        if gap.intervals.len() >= n {
            let typical = median(&mut gap.intervals.clone());
            let regular = typical > 0.0
                && gap
                    .intervals
                    .iter()
                    .all(|i| (i - typical).abs() <= 0.1 * typical);
            if regular && interval_s > cfg.factor * typical {
                let mut alert = Alert::new(
                    log_time_ns,
                    AlertKind::DataGap,
                    AlertState::Raised,
                    format!(
                        "no /environment/weather from {} to {} ({:.0} s; it came every {:.0} s)",
                        utc(last),
                        utc(log_time_ns),
                        interval_s,
                        typical
                    ),
                );
                alert.evidence = vec![
                    ("from_ns", last as f64),
                    ("gap_s", interval_s),
                    ("typical_s", typical),
                ];
                out.push(alert);
                return; // the gap is not a typical interval
            }
            gap.intervals.remove(0);
        }
        gap.intervals.push(interval_s);
    }
}

/// A residual chart's normal: the variance between trains (`var_b`, set
/// by the warm-up), the readings' variance within a train (pooled over
/// every normal sample) and the samples' weighted mean (weights 1 / their
/// variance), to which every normal sample is added.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Baseline {
    var_b: f64,
    within_sum: f64,
    within_dof: f64,
    /// Sum of the weights, and of the weighted samples.
    weight: f64,
    weighted_sum: f64,
}

impl Baseline {
    /// From the warm-up samples: the variance between trains robustly (the
    /// median absolute deviation, less what the spread within a train
    /// explains).
    fn of(warm: &[(f64, usize, f64)]) -> Baseline {
        let mut b = Baseline {
            var_b: 0.0,
            within_sum: 0.0,
            within_dof: 0.0,
            weight: 0.0,
            weighted_sum: 0.0,
        };
        for w in warm.iter().filter(|w| w.1 > 1) {
            b.within_sum += w.2 * (w.1 - 1) as f64;
            b.within_dof += (w.1 - 1) as f64;
        }
        let mut xs: Vec<f64> = warm.iter().map(|w| w.0).collect();
        let x0 = median(&mut xs);
        let mut deviations: Vec<f64> = warm.iter().map(|w| (w.0 - x0).abs()).collect();
        let mad = median(&mut deviations);
        let explained =
            warm.iter().map(|w| b.var_w() / w.1 as f64).sum::<f64>() / warm.len() as f64;
        b.var_b = ((1.4826 * mad).powi(2) - explained).max(0.0);
        for w in warm {
            let v = b.variance(w.1);
            b.weight += 1.0 / v;
            b.weighted_sum += w.0 / v;
        }
        b
    }

    fn var_w(&self) -> f64 {
        match self.within_dof > 0.0 {
            true => self.within_sum / self.within_dof,
            false => 0.0,
        }
    }

    /// The variance of a sample of `n` readings' mean (at least that of
    /// a reading's last digit, 1e-4, squared).
    fn variance(&self, n: usize) -> f64 {
        (self.var_b + self.var_w() / n as f64).max(1e-8)
    }

    fn mean(&self) -> f64 {
        self.weighted_sum / self.weight
    }

    /// The variance of [`Baseline::mean`].
    fn mean_variance(&self) -> f64 {
        1.0 / self.weight
    }

    fn add(&mut self, x: f64, n: usize, within: f64) {
        if n > 1 {
            self.within_sum += within * (n - 1) as f64;
            self.within_dof += (n - 1) as f64;
        }
        let v = self.variance(n);
        self.weight += 1.0 / v;
        self.weighted_sum += x / v;
    }
}

/// The median of `values` (reordered); NaN if empty.
fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    }
}

/// A log_time as UTC (RFC 3339), for a message.
fn utc(ns: u64) -> String {
    tortwin_model::config::terms::format_utc(ns as f64 * 1e-9)
}

/// The track grid point `k` of `d_m` stands for: half the way to each
/// neighbour (what the band alerts and `live --json`'s lengths add up).
pub fn point_width_m(d_m: &[f64], k: usize) -> f64 {
    let before = if k > 0 { d_m[k] - d_m[k - 1] } else { 0.0 };
    let after = d_m.get(k + 1).map_or(0.0, |x| x - d_m[k]);
    (before + after) / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::borrow::Cow;
    use tortwin_recording::{Applicator, Section, Site};

    use crate::sink::TrackInfo;

    /// Collects the alerts.
    #[derive(Default)]
    struct Heard(Vec<Alert>);

    impl Sink for Heard {
        fn alert(&mut self, a: &Alert) -> SinkResult {
            self.0.push(a.clone());
            Ok(())
        }
    }

    const S: u64 = 1_000_000_000;

    /// 100 m, rails `high` and `low`, A1 at 10 m on both, `sites` sites
    /// M1, M2, ... 40 m apart from 40 m.
    fn section(sites: usize) -> Section {
        Section {
            section_id: "s".into(),
            length_m: 100.0,
            rails: vec!["high".into(), "low".into()],
            curve_radius_m: Some(400.0),
            rail_head_radius_m: 0.3,
            nominal_wheel_diameter_m: 0.92,
            applicators: vec![Applicator {
                id: "A1".into(),
                position_m: 10.0,
                rails: vec![0, 1],
                nominal_pulse_kg: 2e-4,
            }],
            sites: (0..sites)
                .map(|k| Site {
                    id: format!("M{}", k + 1),
                    position_m: 40.0 * (k + 1) as f64,
                })
                .collect(),
        }
    }

    /// [`section`] with two sites, a point every 2 m.
    fn started(config: AlertConfig, memory: Option<AlertMemory>) -> Alerting<Heard> {
        let section = section(2);
        let tracks: Vec<TrackInfo> = (0..2)
            .map(|rail| TrackInfo {
                rail,
                rail_name: section.rails[rail].clone(),
                band: "top".into(),
            })
            .collect();
        let grid: Vec<f64> = (0..=50).map(|i| 2.0 * f64::from(i)).collect();
        let mut a = Alerting::new(config, memory, Heard::default());
        a.begin(&SectionInfo {
            section: Cow::Owned(section),
            grid_d_m: Cow::Owned(grid),
            tracks: Cow::Owned(tracks),
            applicator_points: Cow::Owned(vec![5]),
            site_points: Cow::Owned(vec![20, 40]),
            origin_ns: 0,
            line: None,
        })
        .unwrap();
        a
    }

    fn reading(
        site: usize,
        rail: usize,
        train: &str,
        t: u64,
        measured: f64,
        simulated: f64,
    ) -> MeasurementOutput {
        MeasurementOutput {
            log_time_ns: t,
            index_in_file: 0,
            site_id: ["M1", "M2"][site].into(),
            site,
            rail_name: ["high", "low"][rail].into(),
            rail,
            quantity: Quantity::Mu,
            train_id: Some(train.into()),
            axle_index: Some(0),
            measured,
            simulated,
            readout: None,
        }
    }

    fn field(train: &str, t: u64, mu: f64) -> FieldSnapshot<'static> {
        FieldSnapshot {
            kind: SnapshotKind::Train,
            log_time_ns: t,
            train_id: Cow::Owned(train.into()),
            track: 0,
            rail_name: Cow::Borrowed("high"),
            band: Cow::Borrowed("top"),
            wheel_pass: 0,
            d_m: Cow::Owned(Vec::new()),
            mu: Cow::Owned(vec![mu; 51]),
            adhesion: Cow::Owned(vec![0.2; 51]),
            rail_mass_kg: Cow::Owned(vec![0.0; 51]),
            wheel_mass_kg: Cow::Owned(vec![0.0; 51]),
        }
    }

    fn train(id: &str, t: u64) -> TrainEvent<'static> {
        TrainEvent {
            log_time_ns: t,
            end_ns: t + 30 * S,
            train_id: Cow::Owned(id.into()),
            direction: tortwin_recording::Direction::Up,
            speed_mps: 20.0,
            axles: 16,
        }
    }

    fn kinds(a: &Alerting<Heard>) -> Vec<(&'static str, &'static str)> {
        a.inner
            .0
            .iter()
            .map(|x| (x.kind.as_str(), x.state.as_str()))
            .collect()
    }

    /// Standard normal draws (xorshift64* and Box–Muller): fixed, no crate.
    struct Normal(u64);

    impl Normal {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn draw(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    /// Siegmund's run length between false alarms of one side.
    fn siegmund(k: f64, h: f64) -> f64 {
        let b = 2.0 * k * (h + 1.166);
        (b.exp() - b - 1.0) / (2.0 * k * k)
    }

    #[test]
    fn the_residual_charts_false_alarm_rate_is_the_documented_one() {
        // One chart (one site, one rail) of pure noise: every alarm is a
        // false one. h = 6 to see a few hundred in 400 000 samples.
        let mut config = AlertConfig::default();
        config.residual.h = 6.0;
        let mut a = started(config.clone(), None);
        let mut noise = Normal(0x9E37_79B9_7F4A_7C15);
        let samples = 400_000u64;
        for s in 0..samples {
            let id = format!("T{s}");
            for axle in 0..4 {
                let t = s * 600 * S + axle;
                a.measurement(&reading(0, 0, &id, t, 0.3 + 0.01 * noise.draw(), 0.3))
                    .unwrap();
            }
        }
        a.finish(&RunSummary::default()).unwrap();
        let alarms = a
            .inner
            .0
            .iter()
            .filter(|x| x.state == AlertState::Raised)
            .count() as f64;
        // Each alarm is followed by `clear` calm samples before the chart
        // watches again; both sides alarm.
        let per_side = siegmund(config.residual.k, config.residual.h);
        let expected = samples as f64 / (per_side / 2.0 + f64::from(config.residual.clear));
        assert!(
            (0.7..1.3).contains(&(alarms / expected)),
            "{alarms} false alarms, Siegmund's run length says {expected:.0}"
        );
        assert!(kinds(&a).iter().all(|k| k.0 == "sensor_drift"));
        eprintln!("{alarms} false alarms in {samples} samples; expected {expected:.0}");
        // The defaults (h = 8): the documented run length.
        let documented = siegmund(0.5, 8.0);
        assert!((19_000.0..19_200.0).contains(&documented), "{documented}");
    }

    #[test]
    fn a_shift_at_one_site_is_the_sensor_and_at_two_the_applicator() {
        let mut noise = Normal(7);
        let mut a = started(AlertConfig::default(), None);
        let mut b = started(AlertConfig::default(), None);
        for s in 0..40u64 {
            let id = format!("T{s}");
            let shift = if s >= 20 { 0.05 } else { 0.0 };
            for axle in 0..8 {
                let t = s * 600 * S + axle;
                for (site, rail) in [(0, 0), (1, 0), (0, 1)] {
                    let r = 0.3 + 0.01 * noise.draw();
                    // a: only M1 high moves; b: every site (the applicator).
                    let own = if (site, rail) == (0, 0) { shift } else { 0.0 };
                    a.measurement(&reading(site, rail, &id, t, r + own, 0.3))
                        .unwrap();
                    b.measurement(&reading(site, rail, &id, t, r + shift, 0.3))
                        .unwrap();
                }
            }
            a.field(&field(&id, s * 600 * S + 60 * S, 0.35)).unwrap();
            b.field(&field(&id, s * 600 * S + 60 * S, 0.35)).unwrap();
        }
        assert_eq!(kinds(&a), [("sensor_drift", "raised")]);
        assert_eq!(kinds(&b), [("applicator_fade", "raised")]);
        // Within a few measured trains of the shift (train 20).
        let first = &b.inner.0[0];
        assert!(first.train_id.as_deref() <= Some("T23"), "{first:?}");
        assert_eq!(first.sites.len(), 3, "{first:?}");
    }

    #[test]
    fn stuck_readings_band_runs_pulses_and_gaps() {
        let mut a = started(AlertConfig::default(), None);
        // Stuck: 20 equal readings while the model moves 0.05.
        for i in 0..25u64 {
            let sim = 0.30 + 0.002 * i as f64;
            a.measurement(&reading(1, 1, "T0", i, 0.4, sim)).unwrap();
        }
        a.measurement(&reading(1, 1, "T0", 30, 0.41, 0.35)).unwrap();
        assert_eq!(
            kinds(&a),
            [("sensor_stuck", "raised"), ("sensor_stuck", "cleared")]
        );
        assert_eq!(a.inner.0[0].evidence[0], ("readings", 20.0));
        a.inner.0.clear();

        // Band: three trains below 0.30 over the section, then three in it.
        for (k, mu) in [0.2, 0.2, 0.2, 0.35, 0.35, 0.35].into_iter().enumerate() {
            a.field(&field(&format!("B{k}"), k as u64 * S, mu)).unwrap();
        }
        assert_eq!(
            kinds(&a),
            [("friction_low", "raised"), ("friction_low", "cleared")]
        );
        assert!(a.inner.0[0].error);
        a.inner.0.clear();

        // Pulses: a rail that pulsed gets none for five trains.
        a.pulse(&PulseEvent {
            log_time_ns: 0,
            applicator: 0,
            applicator_id: Cow::Borrowed("A1"),
            rail: 1,
            rail_name: Cow::Borrowed("low"),
            mass_kg: 2e-4,
        })
        .unwrap();
        for k in 0..5u64 {
            a.train(&train(&format!("P{k}"), (k + 1) * 600 * S))
                .unwrap();
        }
        assert_eq!(kinds(&a), [("pulses_stopped", "raised")]);
        a.inner.0.clear();

        // Weather every 600 s, then an hour missing.
        for k in 0..10u64 {
            a.weather(k * 600 * S).unwrap();
        }
        a.weather(9 * 600 * S + 3600 * S).unwrap();
        assert_eq!(kinds(&a), [("data_gap", "raised")]);
        assert_eq!(a.inner.0[0].evidence[1], ("gap_s", 3600.0));
    }

    #[test]
    fn alerts_off_pass_the_calls_through_and_remember_nothing() {
        let config = AlertConfig {
            enabled: false,
            ..AlertConfig::default()
        };
        let mut a = started(config, None);
        for i in 0..25u64 {
            let sim = 0.30 + 0.002 * i as f64;
            a.measurement(&reading(1, 1, "T0", i, 0.4, sim)).unwrap();
        }
        a.finish(&RunSummary::default()).unwrap();
        assert!(a.inner.0.is_empty());
        assert_eq!(a.memory(), None);
    }

    #[test]
    fn what_the_alerts_remember_carries_over_and_is_checked() {
        let mut a = started(AlertConfig::default(), None);
        for s in 0..12u64 {
            a.measurement(&reading(0, 0, &format!("T{s}"), s * S, 0.31, 0.3))
                .unwrap();
        }
        a.finish(&RunSummary::default()).unwrap();
        let memory = a.memory().unwrap();
        let text = serde_json::to_string(&memory).unwrap();
        let back: AlertMemory = serde_json::from_str(&text).unwrap();
        assert_eq!(back, memory);
        let b = started(AlertConfig::default(), Some(back.clone()));
        assert_eq!(b.memory().unwrap(), memory);

        assert_eq!(back.check(&section(2), 2), Ok(()));
        assert!(back
            .check(&section(0), 2)
            .unwrap_err()
            .contains("charts[0]"));
        assert!(back.check(&section(2), 3).is_err());
    }
}
