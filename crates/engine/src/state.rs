//! The section's state between recordings (`--state-out`, `--state-in`;
//! docs/spec/interfaces.md): everything the next day needs, in a
//! versioned JSON document. Floats are written shortest-round-trip and read
//! back exactly, so replaying day 1 then day 2 from day 1's state gives
//! the same bits as replaying both days at once.

use serde::{Deserialize, Serialize};

use super::weather::WeatherState;
use super::{Engine, EngineOptions};
use tortwin_model::config::{Effects, ModelConfig};
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
    /// The effects the state was written with (for the reader's information;
    /// a state can be continued with other effects, but not with another
    /// band layout).
    pub effects: Effects,
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
        effects: engine.cfg.effects.clone(),
    }
}

fn track_names(tracks: impl Iterator<Item = (String, String)>) -> Vec<String> {
    tracks
        .map(|(rail, band)| format!("{rail}/{band}"))
        .collect()
}

pub(super) fn restore(
    section: Section,
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
    let mut engine = Engine::new(section, cfg, opts, saved.origin_ns);
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
    let points = engine.grid.d_m.len();
    for (track, s) in engine.tracks.iter_mut().zip(&saved.tracks) {
        let lengths = [
            s.rail_mass_kg.len(),
            s.last_touch_s.len(),
            s.precip_at_touch_mm.len(),
        ];
        if lengths.iter().any(|&n| n != points) {
            return Err(StateError::Inconsistent(format!(
                "track {}/{} has {lengths:?} values for a grid of {points} points",
                s.rail, s.band
            )));
        }
        if let Some(bad) = s
            .rail_mass_kg
            .iter()
            .find(|m| !(m.is_finite() && **m >= 0.0))
        {
            return Err(StateError::Inconsistent(format!(
                "track {}/{} holds a rail mass of {bad} kg",
                s.rail, s.band
            )));
        }
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
    Ok(engine)
}
