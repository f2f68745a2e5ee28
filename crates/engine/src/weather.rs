//! The weather in effect at any time, and the precipitation accumulated
//! since the time origin (effects.md, `rain_washoff`).
//!
//! Weather is piecewise constant from one message to the next. Inside a
//! train's occupation the engine knows every message up to the train's end
//! (it buffers them), so a contact at time `t` sees "the last weather message
//! with time <= t" whatever the replay position (model.md).

use serde::{Deserialize, Serialize};

use tortwin_recording::Weather;

/// Precipitation rates are per hour, times in seconds.
pub(crate) const SECONDS_PER_HOUR: f64 = 3600.0;

/// The weather state carried from message to message (and day to day).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WeatherState {
    /// The values in effect (the defaults before the first message).
    pub current: Weather,
    /// time_s of the message in effect; `None` before the first message.
    pub since_s: Option<f64>,
    /// P at `since_s`: precipitation accumulated since the time origin, mm.
    pub precip_at_since_mm: f64,
}

impl Default for WeatherState {
    fn default() -> Self {
        Self {
            current: Weather::default(),
            since_s: None,
            precip_at_since_mm: 0.0,
        }
    }
}

impl WeatherState {
    /// `P(t)` for `t` at or after `since_s`:
    /// `P(t_k) + rate_k * (t - t_k) / 3600` (effects.md). Before the first
    /// message P is 0 and the rate is the default 0.
    #[inline]
    pub fn precip_mm_at(&self, t_s: f64) -> f64 {
        self.precip_parts(t_s)
            .map_or(0.0, |(at_since, rise)| at_since + rise / SECONDS_PER_HOUR)
    }

    /// `P(t_k)` and `rate_k * (t - t_k)` (mm s/h), from which
    /// [`WeatherState::precip_mm_at`] makes `P(t)`; `None` before the first
    /// message. (The wavefront divides four lanes' rises at once.)
    #[inline]
    pub(crate) fn precip_parts(&self, t_s: f64) -> Option<(f64, f64)> {
        self.since_s.map(|t_k| {
            (
                self.precip_at_since_mm,
                self.current.precipitation_mm_h * (t_s - t_k),
            )
        })
    }

    /// The state after a message at `t_s` (message by message accumulation).
    pub fn after_message(&self, t_s: f64, weather: Weather) -> WeatherState {
        WeatherState {
            current: weather,
            since_s: Some(t_s),
            precip_at_since_mm: self.precip_mm_at(t_s),
        }
    }
}

/// The weather over one train's occupation: the state before it plus the
/// messages inside it, in replay order. Lookups are linear: a train lasts
/// minutes and weather comes every few minutes, so the list is short.
#[derive(Debug, Clone, Default)]
pub(crate) struct WeatherTimeline {
    base: WeatherState,
    /// States after each message inside the window, in replay order.
    changes: Vec<WeatherState>,
}

impl WeatherTimeline {
    pub(crate) fn reset(&mut self, base: WeatherState) {
        self.base = base;
        self.changes.clear();
    }

    pub(crate) fn push(&mut self, t_s: f64, weather: Weather) {
        let last = *self.changes.last().unwrap_or(&self.base);
        self.changes.push(last.after_message(t_s, weather));
    }

    /// The state in effect at `t_s`: the last message with time <= t.
    #[inline]
    pub(crate) fn at(&self, t_s: f64) -> &WeatherState {
        let mut state = &self.base;
        for change in &self.changes {
            match change.since_s {
                Some(since) if since <= t_s => state = change,
                _ => break,
            }
        }
        state
    }

    /// Whether no message falls inside the window (one weather throughout).
    pub(crate) fn is_constant(&self) -> bool {
        self.changes.is_empty()
    }

    /// The state after every message of the window.
    /// The weather in effect before the window's first message.
    pub(crate) fn first(&self) -> WeatherState {
        self.base
    }

    pub(crate) fn last(&self) -> WeatherState {
        *self.changes.last().unwrap_or(&self.base)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rain(mm_h: f64) -> Weather {
        Weather {
            precipitation_mm_h: mm_h,
            ..Weather::default()
        }
    }

    #[test]
    fn precipitation_accumulates_message_by_message() {
        let s = WeatherState::default();
        assert_eq!(s.precip_mm_at(1e5), 0.0);
        let s = s.after_message(3600.0, rain(2.0));
        assert_eq!(s.precip_mm_at(3600.0), 0.0);
        assert_eq!(s.precip_mm_at(5400.0), 1.0);
        let s = s.after_message(7200.0, rain(0.0));
        assert_eq!(s.precip_at_since_mm, 2.0);
        assert_eq!(s.precip_mm_at(1e6), 2.0);
    }

    #[test]
    fn timeline_looks_up_the_last_message_at_or_before() {
        let mut tl = WeatherTimeline::default();
        tl.reset(WeatherState::default().after_message(0.0, rain(1.0)));
        tl.push(100.0, rain(3.0));
        tl.push(200.0, rain(0.0));
        assert_eq!(tl.at(50.0).current.precipitation_mm_h, 1.0);
        assert_eq!(tl.at(100.0).current.precipitation_mm_h, 3.0);
        assert_eq!(tl.at(199.0).current.precipitation_mm_h, 3.0);
        assert_eq!(tl.at(250.0).current.precipitation_mm_h, 0.0);
        let p = tl.last().precip_at_since_mm;
        assert!((p - (100.0 / 3600.0 + 300.0 / 3600.0)).abs() < 1e-15);
    }
}
