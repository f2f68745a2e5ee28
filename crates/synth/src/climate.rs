//! The weather of a synthetic recording: a slow part drawn once (daily mean
//! temperatures, diurnal amplitudes, rain events) and the weather message
//! at any time drawn from it.

use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Exp};

use super::params::SynthParams;
use super::{round_dp, uniform, DAY_NS, HOUR_NS};
use tortwin_recording::Weather;

#[derive(Debug, Clone, Copy)]
pub(super) struct RainEvent {
    pub(super) start_ns: u64,
    pub(super) end_ns: u64,
    pub(super) mm_h: f64,
}

/// The weather's slow part, drawn once: a daily mean temperature (a random
/// walk around 15 °C) and diurnal amplitude anchored at noon of every
/// calendar day, and the rain events (a Poisson process).
#[derive(Debug, Clone)]
pub(super) struct Climate {
    pub(super) first_midnight_ns: u64,
    /// Per calendar day from the day before `first_midnight_ns`: (mean, amplitude) °C.
    days: Vec<(f64, f64)>,
    pub(super) rain: Vec<RainEvent>,
}

impl Climate {
    pub(super) fn new(p: &SynthParams, rng: &mut ChaCha8Rng) -> Climate {
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
    pub(super) fn weather(&self, t_ns: u64, rng: &mut ChaCha8Rng) -> Weather {
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

#[cfg(test)]
mod tests {
    use super::super::{stream, Preset, Stream};
    use super::*;

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
