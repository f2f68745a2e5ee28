//! The section's state between recordings (`--state-out`, `--state-in`;
//! docs/spec/interfaces.md): everything the next day needs, in a
//! versioned JSON document. Floats are written shortest-round-trip and read
//! back exactly, so replaying day 1 then day 2 from day 1's state gives
//! the same bits as replaying both days at once.

use serde::{Deserialize, Serialize};

use super::weather::WeatherState;
use super::{Engine, EngineOptions};
use tortwin_model::config::{Effects, ModelConfig};
use tortwin_recording::line::Line;
use tortwin_recording::Section;

/// Names the document kind, so that a wrong file is refused early.
pub(crate) const STATE_FORMAT: &str = "tortwin-state";
/// Bumped whenever the layout changes; other versions are refused.
pub(crate) const STATE_VERSION: u32 = 1;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EngineState {
    pub format: String,
    pub version: u32,
    /// The section it belongs to; the next recording's must be equal.
    pub section: Section,
    /// The time origin: log_time of the first recording's `/section`.
    pub origin_ns: i64,
    pub tracks: Vec<SavedTrack>,
    /// Written by tortwin before m0 became a constant of the product
    /// (2026-11-26): the latest pulse of every applicator on every track.
    /// Such a state is still read; the entries are no longer needed and
    /// are not written.
    #[serde(default, skip_serializing)]
    pub latest_pulse_kg: Option<serde::de::IgnoredAny>,
    /// The weather in effect and the rain accumulated so far.
    pub weather: WeatherState,
    /// End of the last train's occupation, time_s.
    pub occupied_until_s: Option<f64>,
    /// time_s of the last event replayed: no time in the state is later
    /// (absent in states written before 2026-11-28, which are still read).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_event_s: Option<f64>,
    /// The effects the state was written with (for the reader's information;
    /// a state can be continued with other effects, but not with another
    /// band layout).
    pub effects: Effects,
    /// On a line: its `/line` (line.md, "Outputs and state": the next
    /// recording's segments must be the same; `line_id` and `radius_m`
    /// may differ). Absent for a section.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub line: Option<Line>,
    /// What the alerts remember (their runs of trains, the residual
    /// charts' baselines and sums), so that the next recording's alerts
    /// continue them (crate::alerts). Absent when alerts are off, and in
    /// states written before 2026-12-01.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alerts: Option<crate::alerts::AlertMemory>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedTrack {
    pub rail: String,
    pub band: String,
    pub wheel_pass: u64,
    pub rail_mass_kg: Vec<f64>,
    /// `None` where the point was never touched.
    pub last_touch_s: Vec<Option<f64>>,
    pub precip_at_touch_mm: Vec<f64>,
}

/// A state that does not fit the recording or the configuration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StateError {
    #[error("not a tortwin state (format {found:?}, expected {STATE_FORMAT:?})")]
    Format { found: String },
    #[error("state format version {found}; this tortwin reads version {STATE_VERSION}")]
    Version { found: u32 },
    #[error("the state belongs to another section ({saved:?}); the recording describes {found:?} (a /section may differ only in log_time)")]
    Section { saved: String, found: String },
    #[error("the state has tracks {saved:?} but the configuration gives {found:?} (bogie_bands switched on or off?)")]
    Tracks {
        saved: Vec<String>,
        found: Vec<String>,
    },
    #[error("the state was written {saved}, the recording is {found}: a state continues only the layout it was written for")]
    Line { saved: String, found: String },
    #[error("the state is inconsistent: {0}")]
    Inconsistent(String),
}

pub(super) fn capture(engine: &Engine) -> EngineState {
    EngineState {
        format: STATE_FORMAT.into(),
        version: STATE_VERSION,
        section: engine.section.clone(),
        origin_ns: engine.origin_ns,
        tracks: engine
            .tracks
            .iter()
            .zip(&engine.track_info)
            .map(|(t, info)| SavedTrack {
                rail: info.rail_name.clone(),
                band: info.band.clone(),
                wheel_pass: t.wheel_pass,
                rail_mass_kg: t.rail_mass_kg.clone(),
                last_touch_s: t
                    .last_touch_s
                    .iter()
                    .map(|&x| (!x.is_nan()).then_some(x))
                    .collect(),
                precip_at_touch_mm: t.precip_at_touch_mm.clone(),
            })
            .collect(),
        latest_pulse_kg: None,
        weather: engine.weather,
        occupied_until_s: engine
            .occupied_until_s
            .is_finite()
            .then_some(engine.occupied_until_s),
        last_event_s: engine
            .last_event_s
            .is_finite()
            .then_some(engine.last_event_s),
        effects: engine.cfg.effects.clone(),
        line: engine.line.as_ref().map(|l| l.line.clone()),
        alerts: None,
    }
}

/// A line's state continues the same segments (id, type, end, high rail,
/// curve end); its `line_id` and `radius_m` may differ.
fn check_line(saved: Option<&Line>, found: Option<&Line>) -> Result<(), StateError> {
    let describe = |line: Option<&Line>| match line {
        None => "for a section (no /line)".to_string(),
        Some(l) => format!(
            "for a line of segments [{}]",
            l.segments
                .iter()
                .map(|s| format!("{} {:?} to {} m", s.id, s.kind, s.end_m))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let same = match (saved, found) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            a.segments.len() == b.segments.len()
                && a.segments.iter().zip(&b.segments).all(|(x, y)| {
                    x.id == y.id && x.kind == y.kind && x.end_m.to_bits() == y.end_m.to_bits()
                })
        }
        _ => false,
    };
    match same {
        true => Ok(()),
        false => Err(StateError::Line {
            saved: describe(saved),
            found: describe(found),
        }),
    }
}

fn track_names(tracks: impl Iterator<Item = (String, String)>) -> Vec<String> {
    tracks
        .map(|(rail, band)| format!("{rail}/{band}"))
        .collect()
}

pub(super) fn restore(
    section: Section,
    line: Option<Line>,
    cfg: ModelConfig,
    opts: EngineOptions,
    saved: &EngineState,
) -> Result<Engine, StateError> {
    if saved.format != STATE_FORMAT {
        return Err(StateError::Format {
            found: saved.format.clone(),
        });
    }
    if saved.version != STATE_VERSION {
        return Err(StateError::Version {
            found: saved.version,
        });
    }
    if saved.section != section {
        return Err(StateError::Section {
            saved: saved.section.section_id.clone(),
            found: section.section_id.clone(),
        });
    }
    check_line(saved.line.as_ref(), line.as_ref())?;
    let mut engine = Engine::on_line(section, line, cfg, opts, saved.origin_ns);
    let found = track_names(
        engine
            .track_info
            .iter()
            .map(|t| (t.rail_name.clone(), t.band.clone())),
    );
    let saved_names = track_names(
        saved
            .tracks
            .iter()
            .map(|t| (t.rail.clone(), t.band.clone())),
    );
    if found != saved_names {
        return Err(StateError::Tracks {
            saved: saved_names,
            found,
        });
    }
    let times = Times::of(saved)?;
    check_weather(&saved.weather, &times)?;
    let points = engine.grid.d_m.len();
    for (k, (track, s)) in engine.tracks.iter_mut().zip(&saved.tracks).enumerate() {
        let lengths = [
            s.rail_mass_kg.len(),
            s.last_touch_s.len(),
            s.precip_at_touch_mm.len(),
        ];
        if lengths.iter().any(|&n| n != points) {
            return Err(StateError::Inconsistent(format!(
                "tracks[{k}] (track {}/{}) has {lengths:?} values for a grid of {points} points",
                s.rail, s.band
            )));
        }
        check_track(k, s, &engine.cfg, &times, &saved.weather)?;
        track.rail_mass_kg.clone_from(&s.rail_mass_kg);
        track.last_touch_s = s
            .last_touch_s
            .iter()
            .map(|x| x.unwrap_or(f64::NAN))
            .collect();
        track.precip_at_touch_mm.clone_from(&s.precip_at_touch_mm);
        track.wheel_pass = s.wheel_pass;
    }
    engine.weather = saved.weather;
    engine.occupied_until_s = saved.occupied_until_s.unwrap_or(f64::NEG_INFINITY);
    engine.last_event_s = saved.last_event_s.unwrap_or(f64::NEG_INFINITY);
    Ok(engine)
}

/// Wheel passes a track may have counted: every count tortwin writes is
/// read back exactly by JSON readers that hold numbers as doubles (2^53:
/// a million wheels a day for 25 million years).
pub(crate) const MAX_WHEEL_PASS: u64 = 1 << 53;

/// The times a state may hold, in time_s: from the epoch to the last
/// instant a signed 64-bit nanosecond count holds (2262-04-11), and no
/// later than the state's own time where the state says it: its last
/// event, or the end of its last train's occupation (whose wheels touch
/// the rail until then), whichever is later.
struct Times {
    lo_s: f64,
    hi_s: f64,
    latest_s: Option<f64>,
    origin_ns: i64,
}

impl Times {
    fn of(saved: &EngineState) -> Result<Self, StateError> {
        if saved.origin_ns < 0 {
            return Err(StateError::Inconsistent(format!(
                "origin_ns = {} is before the epoch; log_times are never negative",
                saved.origin_ns
            )));
        }
        let origin = saved.origin_ns as f64;
        let mut times = Self {
            lo_s: -origin * 1e-9,
            hi_s: (i64::MAX as f64 - origin) * 1e-9,
            latest_s: None,
            origin_ns: saved.origin_ns,
        };
        if let Some(t) = saved.last_event_s {
            times.check("last_event_s", t)?;
        }
        if let Some(t) = saved.occupied_until_s {
            times.check("occupied_until_s", t)?;
        }
        times.latest_s = match (saved.last_event_s, saved.occupied_until_s) {
            (Some(e), Some(o)) => Some(e.max(o)),
            (Some(e), None) => Some(e),
            // States written before 2026-11-28 do not say their last event.
            (None, _) => None,
        };
        Ok(times)
    }

    /// `t` (time_s, named `what`) is finite, within the range and not after
    /// the state's own time.
    fn check(&self, what: &str, t: f64) -> Result<(), StateError> {
        let latest = self.latest_s.unwrap_or(self.hi_s).min(self.hi_s);
        if t.is_finite() && (self.lo_s..=latest).contains(&t) {
            return Ok(());
        }
        Err(StateError::Inconsistent(format!(
            "{what} = {t:?} s is outside {} to {latest} s from the time origin origin_ns = {} \
             (the epoch to 2262-04-11, and no later than the state's last event or train: \
             last_event_s, occupied_until_s)",
            self.lo_s, self.origin_ns
        )))
    }
}

/// The weather a state carries: values within the recording's ranges,
/// its time within the state's, rain accumulated never negative.
fn check_weather(w: &WeatherState, times: &Times) -> Result<(), StateError> {
    use tortwin_recording::limits;
    let values = [
        (
            "air_temperature_c",
            w.current.air_temperature_c,
            limits::AIR_TEMPERATURE_C,
        ),
        (
            "relative_humidity",
            w.current.relative_humidity,
            limits::RELATIVE_HUMIDITY,
        ),
        (
            "precipitation_mm_h",
            w.current.precipitation_mm_h,
            limits::PRECIPITATION_MM_H,
        ),
    ];
    for (name, x, range) in values {
        if !range.contains(x) {
            return Err(StateError::Inconsistent(format!(
                "weather.current.{name} = {x} is outside {} to {} {}",
                range.lo, range.hi, range.unit
            )));
        }
    }
    if let Some(t) = w.since_s {
        times.check("weather.since_s", t)?;
    }
    if !(w.precip_at_since_mm.is_finite() && w.precip_at_since_mm >= 0.0) {
        return Err(StateError::Inconsistent(format!(
            "weather.precip_at_since_mm = {:?} mm; rain accumulated is a finite amount, never \
             negative",
            w.precip_at_since_mm
        )));
    }
    Ok(())
}

/// One saved track: masses within [0, the configuration's cap], times
/// within the state's, rain at each touch within what has fallen, a wheel
/// count that cannot wrap.
fn check_track(
    k: usize,
    s: &SavedTrack,
    cfg: &ModelConfig,
    times: &Times,
    weather: &WeatherState,
) -> Result<(), StateError> {
    let name = format!("tracks[{k}] (track {}/{})", s.rail, s.band);
    let cap = cfg.product.m_max_kg;
    if let Some((i, m)) = s
        .rail_mass_kg
        .iter()
        .enumerate()
        .find(|(_, m)| !(m.is_finite() && **m >= 0.0 && **m <= cap))
    {
        return Err(StateError::Inconsistent(format!(
            "{name} rail_mass_kg[{i}] = {m:?} kg; a rail mass lies within 0 and the cap \
             product.m_max_kg = {cap} kg (a state written with a larger cap cannot be \
             continued with this one)"
        )));
    }
    for (i, t) in s.last_touch_s.iter().enumerate() {
        if let Some(t) = t {
            times.check(&format!("{name} last_touch_s[{i}]"), *t)?;
        }
    }
    // Rain accumulated at a touch: no more than had fallen by the last
    // event (or by the weather message in effect, for older states).
    let fallen = times
        .latest_s
        .or(weather.since_s)
        .map_or(weather.precip_at_since_mm, |t| weather.precip_mm_at(t));
    if let Some((i, p)) = s
        .precip_at_touch_mm
        .iter()
        .enumerate()
        .find(|(_, p)| !(p.is_finite() && **p >= 0.0 && **p <= fallen * (1.0 + 1e-12)))
    {
        return Err(StateError::Inconsistent(format!(
            "{name} precip_at_touch_mm[{i}] = {p:?} mm; the rain accumulated at a touch lies \
             within 0 and the {fallen} mm fallen by the state's last event"
        )));
    }
    if s.wheel_pass > MAX_WHEEL_PASS {
        return Err(StateError::Inconsistent(format!(
            "{name} wheel_pass = {}; at most 2^53 = {MAX_WHEEL_PASS} (counts are read back as \
             doubles)",
            s.wheel_pass
        )));
    }
    Ok(())
}
