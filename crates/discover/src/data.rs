//! The recording in memory, its measurements as rows, the covariates each
//! row carries, and the one function the fits call: [`Dataset::simulate`].
//!
//! A few days of a section are small (a 3-day synthetic recording is about
//! 25 000 events), so the recording is read once and every evaluation of a
//! candidate model replays the in-memory events through the one
//! [`Engine`] with a sink that only keeps the simulated value of each
//! measurement. There is no second model here: the covariates are facts of
//! the recording (where the site is, when the previous train passed it, how
//! much it rained since), computed from the events.

use std::collections::HashMap;
use std::path::Path;

use tortwin_engine::sink::{MeasurementOutput, Sink};
use tortwin_engine::weather::WeatherState;
use tortwin_engine::{Engine, EngineOptions, Readout, ReadoutModel};
use tortwin_model::config::ModelConfig;
use tortwin_model::product::ProductKey;
use tortwin_model::tangent;
use tortwin_recording::{
    BogiePosition, Direction, Event, EventKind, Passage, Quantity, Recording, Section,
};
use tortwin_study::{Error, Result};

pub(crate) const DAY_NS: u64 = 86_400_000_000_000;
const HOUR_NS: u64 = 3_600_000_000_000;

/// One measurement of the recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub log_time_ns: u64,
    pub index_in_file: u64,
    pub site: usize,
    pub rail: usize,
    pub quantity: Quantity,
    /// The measured train and axle (`None` for `rail_mu`).
    pub train_seq: Option<usize>,
    pub axle_index: Option<usize>,
    pub measured: f64,
    /// 0-based UTC calendar day from the recording's first day: the blocks
    /// of the cross-validation.
    pub day: usize,
}

/// What a covariate is, for binning and for the reader of the report.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    /// NaN where the value is unknown (its own bin).
    Continuous(Vec<f64>),
    /// A code per row into `labels`.
    Categorical {
        labels: Vec<String>,
        codes: Vec<u32>,
    },
}

/// One covariate: a value per row.
#[derive(Debug, Clone, PartialEq)]
pub struct Covariate {
    /// Machine name, e.g. `distance_from_applicator_m`.
    pub name: &'static str,
    /// What it is, for people.
    pub description: &'static str,
    pub values: Values,
}

/// The recording, read once.
pub struct Dataset {
    pub path: std::path::PathBuf,
    pub section: Section,
    pub origin_ns: i64,
    pub events: Vec<Event>,
    pub rows: Vec<Row>,
    /// `index_in_file` of a measurement -> its row.
    row_of_index: HashMap<u64, usize>,
    pub passages: Vec<PassageFacts>,
    pub covariates: Vec<Covariate>,
    /// The weather in effect at any time.
    weather: WeatherAt,
    /// Days with at least one measurement, ascending (values of [`Row::day`]).
    pub days: Vec<usize>,
    /// UTC midnight of day 0, ns.
    pub day0_ns: u64,
    pub unknown_topic_messages: u64,
}

/// What the covariates need of a passage.
#[derive(Debug, Clone, PartialEq)]
pub struct PassageFacts {
    pub log_time_ns: u64,
    pub train_id: String,
    pub direction: Direction,
    pub speed_mps: f64,
    pub bogies: Vec<BogiePosition>,
    pub axle_offsets_m: Vec<f64>,
    /// [axle][rail], N.
    pub wheel_load_n: Vec<Vec<f64>>,
    /// [axle][rail]: `sqrt(cx² + cy²)`.
    pub creepage: Vec<Vec<f64>>,
}

impl Dataset {
    /// Reads the whole recording.
    pub fn read(path: &Path) -> Result<Self> {
        let r = Recording::read_section(path, "discover and calibrate need")?;
        let day0_ns = (r.section_log_time_ns / DAY_NS) * DAY_NS;
        Self::from_events(
            &r.path,
            r.section,
            r.origin_ns,
            day0_ns,
            r.events,
            r.unknown_topic_messages,
        )
    }

    /// Builds the rows and covariates of events already in replay order.
    pub fn from_events(
        path: &Path,
        section: Section,
        origin_ns: i64,
        day0_ns: u64,
        events: Vec<Event>,
        unknown_topic_messages: u64,
    ) -> Result<Self> {
        let mut rows = Vec::new();
        let mut passages = Vec::new();
        let mut weather_steps: Vec<WeatherState> = Vec::new();
        let time_s = |ns: u64| (ns as i64).wrapping_sub(origin_ns) as f64 * 1e-9;
        for event in &events {
            match &event.kind {
                EventKind::Passage(p) => passages.push(passage_facts(event.log_time_ns, p)),
                EventKind::Measurement(m) => rows.push(Row {
                    log_time_ns: event.log_time_ns,
                    index_in_file: event.index_in_file,
                    site: m.site,
                    rail: m.rail,
                    quantity: m.quantity(),
                    train_seq: m.axle().map(|a| a.train_seq),
                    axle_index: m.axle().map(|a| a.axle_index),
                    measured: m.value,
                    day: (event.log_time_ns.saturating_sub(day0_ns) / DAY_NS) as usize,
                }),
                EventKind::Weather(w) => {
                    let last = weather_steps.last().copied().unwrap_or_default();
                    weather_steps.push(last.after_message(time_s(event.log_time_ns), *w));
                }
                EventKind::Pulse(_) => {}
            }
        }
        if rows.is_empty() {
            return Err(tortwin_recording::error::InputError::file(
                path,
                "the recording has no /measurement/friction message: nothing to compare the model with",
            )
            .into());
        }
        let row_of_index = rows
            .iter()
            .enumerate()
            .map(|(k, r)| (r.index_in_file, k))
            .collect();
        let mut days: Vec<usize> = rows.iter().map(|r| r.day).collect();
        days.sort_unstable();
        days.dedup();
        let weather = WeatherAt {
            steps: weather_steps,
            origin_ns,
        };
        let covariates = covariates(&section, &rows, &passages, &weather, day0_ns);
        Ok(Self {
            path: path.to_path_buf(),
            section,
            origin_ns,
            events,
            rows,
            row_of_index,
            passages,
            covariates,
            weather,
            days,
            day0_ns,
            unknown_topic_messages,
        })
    }

    /// The simulated value of every row with `cfg`: one replay of the
    /// in-memory recording through the engine.
    pub fn simulate(&self, cfg: &ModelConfig) -> Result<Vec<f64>> {
        Ok(self.replay(cfg, false, None, 0)?.0)
    }

    /// [`Dataset::simulate`], and what every row's value was read from
    /// (for [`Dataset::read_out`] at other read-out parameters).
    pub fn simulate_with_readouts(&self, cfg: &ModelConfig) -> Result<(Vec<f64>, Vec<Readout>)> {
        let (simulated, readouts, _) = self.replay(cfg, true, None, 0)?;
        Ok((simulated, complete(readouts)))
    }

    /// [`Dataset::simulate_with_readouts`] in one replay with tangents
    /// ([`EngineOptions::tangents`]), and every row's derivative with
    /// respect to `ln p` of each constant of `keys` (state constants,
    /// [`tortwin_model::role::Role::State`]): `∂ value / ∂ mass` at the
    /// mass read ([`ReadoutModel::slope`]) times the mass's tangent. One
    /// column per key, then one per effect parameter of `effects` (at most
    /// [`tangent::EFFECT_SLOTS`]; the derivative in the parameter itself,
    /// [`tangent::EffectParam`]).
    pub fn simulate_with_tangents(
        &self,
        cfg: &ModelConfig,
        keys: &[ProductKey],
        effects: &[tangent::EffectParam],
    ) -> Result<Sensitivities> {
        assert!(
            effects.len() <= tangent::EFFECT_SLOTS,
            "too many effect slots"
        );
        let followed = std::array::from_fn(|k| effects.get(k).copied());
        let (simulated, readouts, _) = self.replay(cfg, true, Some(followed), 0)?;
        let readouts = complete(readouts);
        let model = ReadoutModel::new(&self.section, cfg, self.origin_ns);
        let slopes: Vec<f64> = self
            .rows
            .iter()
            .zip(&readouts)
            .map(|(row, r)| model.slope(r, row.site, row.rail, row.quantity))
            .collect();
        let slots = keys
            .iter()
            .map(|&key| tangent::slot(key))
            .chain((0..effects.len()).map(|k| Some(tangent::effect_slot(k))));
        let columns = slots
            .map(|slot| {
                readouts
                    .iter()
                    .zip(&slopes)
                    .map(|(r, slope)| match (slot, r.mass_tangent) {
                        (Some(k), Some(t)) => slope * t[k],
                        _ => 0.0,
                    })
                    .collect()
            })
            .collect();
        Ok(Sensitivities {
            simulated,
            readouts,
            columns,
        })
    }

    /// The simulated value of every row with `cfg`, read from `readouts`
    /// (of a replay of a configuration with `cfg`'s state part,
    /// [`ModelConfig::state_part`]) without a replay: the replay's values
    /// bit for bit.
    pub fn read_out(&self, cfg: &ModelConfig, readouts: &[Readout]) -> Vec<f64> {
        let model = ReadoutModel::new(&self.section, cfg, self.origin_ns);
        self.rows
            .iter()
            .zip(readouts)
            .map(|(row, r)| model.value(r, row.site, row.rail, row.quantity))
            .collect()
    }

    /// [`Dataset::simulate_with_readouts`], with the engine kept at
    /// `checkpoints` points evenly spread over the events, from which a
    /// configuration that differs only in later time steps continues
    /// ([`Dataset::resume`]).
    pub fn simulate_with_checkpoints(
        &self,
        cfg: &ModelConfig,
        checkpoints: usize,
    ) -> Result<(Vec<f64>, Vec<Readout>, Checkpoints)> {
        let (simulated, readouts, cps) = self.replay(cfg, true, None, checkpoints)?;
        Ok((simulated, complete(readouts), cps))
    }

    /// The read-outs of every row with `cfg`, continued from the latest of
    /// `from`'s checkpoints that `cfg` can take over
    /// ([`Engine::resume_with`]: `cfg` is the checkpointed configuration
    /// with time steps appended that act only after it), the rows given
    /// before it taken from `base` (that replay's read-outs). `None` when no
    /// checkpoint fits. The same values as a replay of `cfg` from the start.
    pub fn resume(
        &self,
        cfg: &ModelConfig,
        from: &Checkpoints,
        base: &[Readout],
    ) -> Option<Result<Vec<Readout>>> {
        let (next, mut engine) = from
            .at
            .iter()
            .rev()
            .find_map(|(next, e)| e.resume_with(cfg).map(|e| (*next, e)))?;
        let readouts = from
            .given_during
            .iter()
            .zip(base)
            .map(|(&k, r)| (k < next).then_some(*r))
            .collect();
        let mut sink = Collect {
            row_of_index: &self.row_of_index,
            simulated: vec![0.0; self.rows.len()],
            readouts,
            given_during: Vec::new(),
            pushed: next,
        };
        let mut run = || -> Result<Vec<Readout>> {
            for event in &self.events[next..] {
                engine
                    .push(event.clone(), &mut sink)
                    .map_err(|source| self.replay_error(source))?;
            }
            engine.finish(&mut sink, self.unknown_topic_messages)?;
            if let Some(k) = sink.readouts.iter().position(Option::is_none) {
                return Err(Error::NotSimulated {
                    file: self.path.clone(),
                    log_time_ns: self.rows[k].log_time_ns,
                    index_in_file: Some(self.rows[k].index_in_file),
                });
            }
            Ok(complete(std::mem::take(&mut sink.readouts)))
        };
        Some(run())
    }

    /// An engine error of a replay of this recording.
    fn replay_error(&self, source: tortwin_engine::EngineError) -> Error {
        Error::Replay {
            what: self.path.display().to_string(),
            source,
        }
    }

    fn replay(
        &self,
        cfg: &ModelConfig,
        readouts: bool,
        tangents: Option<[Option<tangent::EffectParam>; tangent::EFFECT_SLOTS]>,
        checkpoints: usize,
    ) -> Result<(Vec<f64>, Vec<Option<Readout>>, Checkpoints)> {
        let mut engine = Engine::new(
            self.section.clone(),
            cfg.clone(),
            EngineOptions {
                tangents: tangents.is_some(),
                effect_tangents: tangents.unwrap_or_default(),
                // A candidate whose arithmetic overflows ranks last (its
                // SSE is NaN), as before the engine checked its outputs.
                non_finite_allowed: true,
                ..EngineOptions::default()
            },
            self.origin_ns,
        );
        let mut sink = Collect {
            row_of_index: &self.row_of_index,
            simulated: vec![f64::NAN; self.rows.len()],
            readouts: if readouts {
                vec![None; self.rows.len()]
            } else {
                Vec::new()
            },
            given_during: if checkpoints > 0 {
                vec![usize::MAX; self.rows.len()]
            } else {
                Vec::new()
            },
            pushed: 0,
        };
        let every = (self.events.len() / (checkpoints + 1)).max(1);
        let mut at = Vec::with_capacity(checkpoints);
        for (k, event) in self.events.iter().enumerate() {
            if at.len() < checkpoints && k > 0 && k % every == 0 {
                at.push((k, engine.clone()));
            }
            sink.pushed = k;
            engine
                .push(event.clone(), &mut sink)
                .map_err(|source| self.replay_error(source))?;
        }
        sink.pushed = self.events.len();
        engine.finish(&mut sink, self.unknown_topic_messages)?;
        if let Some(k) = sink.simulated.iter().position(|v| !v.is_finite()) {
            return Err(Error::NotSimulated {
                file: self.path.clone(),
                log_time_ns: self.rows[k].log_time_ns,
                index_in_file: Some(self.rows[k].index_in_file),
            });
        }
        let cps = Checkpoints {
            at,
            given_during: sink.given_during,
        };
        Ok((sink.simulated, sink.readouts, cps))
    }

    /// The weather in effect at `log_time_ns` (the defaults before the first
    /// message).
    pub(crate) fn weather_at(&self, log_time_ns: u64) -> tortwin_recording::Weather {
        self.weather.state(log_time_ns).current
    }

    /// The section's name of a rail.
    pub fn rail_name(&self, rail: usize) -> &str {
        self.section.rails.get(rail).map_or("?", String::as_str)
    }

    /// The section's id of a measurement site.
    pub fn site_name(&self, site: usize) -> &str {
        self.section.sites.get(site).map_or("?", |s| s.id.as_str())
    }

    /// A covariate by name.
    pub(crate) fn covariate(&self, name: &str) -> Option<&Covariate> {
        self.covariates.iter().find(|c| c.name == name)
    }
}

/// Engines kept along a replay ([`Dataset::simulate_with_checkpoints`]).
pub struct Checkpoints {
    /// (the index of the next event, the engine before it), ascending.
    at: Vec<(usize, Engine)>,
    /// Per row: the index of the event during whose push its value was
    /// given (the number of events for those given at the end).
    given_during: Vec<usize>,
}

impl Checkpoints {
    /// How many engines are kept.
    pub fn len(&self) -> usize {
        self.at.len()
    }

    pub fn is_empty(&self) -> bool {
        self.at.is_empty()
    }
}

/// Every row's read-out, given that every row was simulated.
fn complete(readouts: Vec<Option<Readout>>) -> Vec<Readout> {
    readouts.into_iter().flatten().collect()
}

/// What [`Dataset::simulate_with_tangents`] gives.
pub struct Sensitivities {
    /// Every row's simulated value.
    pub simulated: Vec<f64>,
    /// What every row's value was read from.
    pub readouts: Vec<Readout>,
    /// Per key asked for: every row's derivative in `ln p`.
    pub columns: Vec<Vec<f64>>,
}

/// Keeps each measurement's simulated value, by its row, what it was read
/// from when `readouts` is not empty, and during which event's push it came
/// when `given_during` is not empty.
struct Collect<'a> {
    row_of_index: &'a HashMap<u64, usize>,
    simulated: Vec<f64>,
    readouts: Vec<Option<Readout>>,
    given_during: Vec<usize>,
    /// The index of the event being pushed.
    pushed: usize,
}

impl Sink for Collect<'_> {
    fn measurement(&mut self, m: &MeasurementOutput) -> tortwin_engine::sink::SinkResult {
        if let Some(&k) = self.row_of_index.get(&m.index_in_file) {
            self.simulated[k] = m.simulated;
            if let Some(slot) = self.readouts.get_mut(k) {
                *slot = m.readout.as_deref().copied();
            }
            if let Some(slot) = self.given_during.get_mut(k) {
                *slot = self.pushed;
            }
        }
        Ok(())
    }

    fn wants_readouts(&self) -> bool {
        !self.readouts.is_empty()
    }
}

fn passage_facts(log_time_ns: u64, p: &Passage) -> PassageFacts {
    PassageFacts {
        log_time_ns,
        train_id: p.train_id.clone(),
        direction: p.direction,
        speed_mps: p.speed_mps,
        bogies: p.axles.iter().map(|a| a.bogie_position).collect(),
        axle_offsets_m: p.axles.iter().map(|a| a.offset_m).collect(),
        wheel_load_n: p.axles.iter().map(|a| a.wheel_load_n.clone()).collect(),
        creepage: p
            .axles
            .iter()
            .map(|a| {
                a.creepage
                    .iter()
                    .map(|c| (c.cx * c.cx + c.cy * c.cy).sqrt())
                    .collect()
            })
            .collect(),
    }
}

/// The weather in effect at any time, from the recording's messages.
struct WeatherAt {
    /// The state after each message, in replay order.
    steps: Vec<WeatherState>,
    origin_ns: i64,
}

impl WeatherAt {
    fn state(&self, log_time_ns: u64) -> WeatherState {
        let t = self.time_s(log_time_ns);
        let k = self
            .steps
            .partition_point(|s| s.since_s.is_some_and(|since| since <= t));
        k.checked_sub(1)
            .and_then(|k| self.steps.get(k))
            .copied()
            .unwrap_or_default()
    }

    fn time_s(&self, log_time_ns: u64) -> f64 {
        (log_time_ns as i64).wrapping_sub(self.origin_ns) as f64 * 1e-9
    }

    /// P(t), mm since the time origin (effects.md, `rain_washoff`).
    fn precip_mm(&self, log_time_ns: u64) -> f64 {
        self.state(log_time_ns)
            .precip_mm_at(self.time_s(log_time_ns))
    }
}

/// When a passage's axle `k` is over position `x_m`: ns.
fn axle_at_ns(section: &Section, p: &PassageFacts, axle: usize, x_m: f64) -> u64 {
    let from_entry_m = match p.direction {
        Direction::Up => x_m,
        Direction::Down => section.length_m - x_m,
    };
    let offset_m = p.axle_offsets_m.get(axle).copied().unwrap_or(0.0);
    p.log_time_ns + ((from_entry_m + offset_m) / p.speed_mps * 1e9).round() as u64
}

/// Distance downstream of the nearest applicator serving `rail` that a
/// wheel travelling in `direction` has passed before reaching `x_m`; NaN
/// when it has passed none.
fn downstream_of_applicator_m(
    section: &Section,
    rail: usize,
    direction: Direction,
    x_m: f64,
) -> f64 {
    section
        .applicators
        .iter()
        .filter(|a| a.rails.contains(&rail))
        .map(|a| match direction {
            Direction::Up => x_m - a.position_m,
            Direction::Down => a.position_m - x_m,
        })
        .filter(|d| *d >= 0.0)
        .fold(f64::NAN, f64::min)
}

/// The covariates of every row (see the module docs of [`super`]).
fn covariates(
    section: &Section,
    rows: &[Row],
    passages: &[PassageFacts],
    weather: &WeatherAt,
    day0_ns: u64,
) -> Vec<Covariate> {
    let n = rows.len();
    let mut distance = Vec::with_capacity(n);
    let mut gap = Vec::with_capacity(n);
    let mut rain = Vec::with_capacity(n);
    let mut temperature = Vec::with_capacity(n);
    let mut humidity = Vec::with_capacity(n);
    let mut speed = Vec::with_capacity(n);
    let mut load = Vec::with_capacity(n);
    let mut time_of_day = Vec::with_capacity(n);
    let mut axle_position = Vec::with_capacity(n);
    let mut bogie = Vec::with_capacity(n);
    let mut day = Vec::with_capacity(n);
    // Passage log_times, ascending (the reader's replay order).
    let starts: Vec<u64> = passages.iter().map(|p| p.log_time_ns).collect();
    for row in rows {
        let x_m = section
            .sites
            .get(row.site)
            .map_or(f64::NAN, |s| s.position_m);
        // The train that touched the site (the measured one, or for a
        // tribometer the last one before the reading) and the one before it.
        let (train, now_ns) = match row.train_seq {
            Some(seq) => (passages.get(seq).map(|p| (seq, p)), None),
            None => {
                let k = starts.partition_point(|&t| t <= row.log_time_ns);
                (
                    k.checked_sub(1)
                        .and_then(|k| passages.get(k).map(|p| (k, p))),
                    Some(row.log_time_ns),
                )
            }
        };
        // "Now" at the site: the measured train's front, or the reading.
        let now_ns = match (now_ns, train) {
            (Some(t), _) => t,
            (None, Some((_, p))) => axle_at_ns(section, p, 0, x_m),
            (None, None) => row.log_time_ns,
        };
        // The previous touch of the site by a wheel: for a train, the last
        // axle of the train before it; for a reading, the last axle of the
        // last train.
        let previous = match (row.train_seq, train) {
            (Some(_), Some((seq, _))) => seq.checked_sub(1).and_then(|k| passages.get(k)),
            (None, Some((_, p))) => Some(p),
            _ => None,
        };
        let last_touch_ns =
            previous.map(|p| axle_at_ns(section, p, p.axle_offsets_m.len().saturating_sub(1), x_m));
        match last_touch_ns {
            Some(t) if t <= now_ns => {
                gap.push((now_ns - t) as f64 * 1e-9);
                rain.push((weather.precip_mm(now_ns) - weather.precip_mm(t)).max(0.0));
            }
            _ => {
                gap.push(f64::NAN);
                rain.push(f64::NAN);
            }
        }
        let air = weather.state(now_ns).current;
        temperature.push(air.air_temperature_c);
        humidity.push(air.relative_humidity);
        let direction = train.map(|(_, p)| p.direction);
        distance.push(direction.map_or(f64::NAN, |d| {
            downstream_of_applicator_m(section, row.rail, d, x_m)
        }));
        let axle = row.train_seq.zip(row.axle_index);
        let measured_train = row.train_seq.and_then(|s| passages.get(s));
        speed.push(measured_train.map_or(f64::NAN, |p| p.speed_mps));
        load.push(
            match (measured_train, axle) {
                (Some(p), Some((_, a))) => p
                    .wheel_load_n
                    .get(a)
                    .and_then(|l| l.get(row.rail))
                    .map(|q| q * 1e-3),
                _ => None,
            }
            .unwrap_or(f64::NAN),
        );
        axle_position.push(axle.map_or(f64::NAN, |(_, a)| a as f64));
        bogie.push(match (measured_train, axle) {
            (Some(p), Some((_, a))) => match p.bogies.get(a) {
                Some(BogiePosition::Leading) => 0,
                Some(BogiePosition::Trailing) => 1,
                None => 2,
            },
            _ => 2,
        });
        time_of_day.push((row.log_time_ns % DAY_NS) as f64 / HOUR_NS as f64);
        day.push(row.log_time_ns.saturating_sub(day0_ns) / DAY_NS);
    }
    let categorical = |labels: Vec<String>, codes: Vec<u32>| Values::Categorical { labels, codes };
    let days_seen = day.iter().copied().max().unwrap_or(0);
    let day_labels = (0..=days_seen).map(|d| format!("day {d}")).collect();
    let quantity_labels = ["mu", "adhesion", "rail_mu"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let quantity_code = |q: Quantity| match q {
        Quantity::Mu => 0,
        Quantity::Adhesion => 1,
        Quantity::RailMu => 2,
    };
    vec![
        Covariate {
            name: "distance_from_applicator_m",
            description: "distance downstream of the applicator the wheel passed (m)",
            values: Values::Continuous(distance),
        },
        Covariate {
            name: "time_since_last_touch_s",
            description: "time since the site was last touched by a wheel: the previous train's last axle (s)",
            values: Values::Continuous(gap),
        },
        Covariate {
            name: "rain_since_last_touch_mm",
            description: "rain since the site was last touched (mm)",
            values: Values::Continuous(rain),
        },
        Covariate {
            name: "air_temperature_c",
            description: "air temperature (°C)",
            values: Values::Continuous(temperature),
        },
        Covariate {
            name: "relative_humidity",
            description: "relative humidity (0-1)",
            values: Values::Continuous(humidity),
        },
        Covariate {
            name: "train_speed_mps",
            description: "train speed (m/s)",
            values: Values::Continuous(speed),
        },
        Covariate {
            name: "bogie_position",
            description: "leading or trailing axle of its bogie",
            values: categorical(
                vec!["leading".into(), "trailing".into(), "none (tribometer)".into()],
                bogie,
            ),
        },
        Covariate {
            name: "rail",
            description: "rail",
            values: categorical(
                section.rails.clone(),
                rows.iter().map(|r| r.rail as u32).collect(),
            ),
        },
        Covariate {
            name: "wheel_load_kn",
            description: "wheel load on the measured rail (kN)",
            values: Values::Continuous(load),
        },
        Covariate {
            name: "time_of_day_h",
            description: "time of day (h, UTC)",
            values: Values::Continuous(time_of_day),
        },
        Covariate {
            name: "day",
            description: "day of the recording (UTC)",
            values: categorical(day_labels, day.iter().map(|&d| d as u32).collect()),
        },
        Covariate {
            name: "axle_index",
            description: "position of the axle in its train (0 = first)",
            values: Values::Continuous(axle_position),
        },
        Covariate {
            name: "site",
            description: "measurement site",
            values: categorical(
                section.sites.iter().map(|s| s.id.clone()).collect(),
                rows.iter().map(|r| r.site as u32).collect(),
            ),
        },
        Covariate {
            name: "quantity",
            description: "measured quantity",
            values: categorical(
                quantity_labels,
                rows.iter().map(|r| quantity_code(r.quantity)).collect(),
            ),
        },
    ]
}
