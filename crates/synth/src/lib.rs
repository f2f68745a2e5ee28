//! Synthetic recordings: days of traffic on a track section, written in
//! docs/spec/recording-format.md, whose measurements are what the
//! project's one engine computes with a *truth* model configuration (the
//! defaults, possibly with hidden effects of docs/spec/effects.md),
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
//!    typed events are built from exactly those values with the reader's unit
//!    conversions, so a replay of the file sees the same numbers.
//! 2. Sort the day into replay order (log_time, topic, file order) and push it
//!    through two engines that live for the whole recording: the truth
//!    model and the default model. A small sink collects each
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
//! Everything random comes from `ChaCha8Rng` streams derived from the seed
//! (traffic, weather, tribometer and noise each have their own, so changing
//! the noise does not move a train); nothing reads the clock, no map is
//! iterated in hash order, and the MCAP metadata has no timestamp: the same
//! parameters give byte-identical files.
//!
//! One job a file: `params` (what decides a recording), `hidden` (the
//! truth configuration), `climate` (the weather), `traffic` (what a
//! train is), `planner` (a day's trains, pulses, weather and
//! measurements), `truth` (the engine runs, noise and the key's figures),
//! `writing` (the file, through the recording crate's writer),
//! `report` (the key) and `layout` (a line described segment by segment,
//! docs/spec/line.md: loads and creepages per segment, applicators on one
//! rail or both, trains both ways that may share the line).

mod climate;
mod hidden;
mod layout;
mod params;
mod planner;
mod report;
mod traffic;
mod truth;
mod writing;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub use hidden::truth_config;
pub use layout::{LayoutApplicator, LayoutSegment, LineLayout};
pub use params::{LocalFriction, Preset, SiteParam, SynthParams};
pub use report::{ByQuantity, Counts, NoiseKey, RainKey, RmseKey, SynthReport};
pub use truth::generate;

/// The generator's name in the key and the MCAP metadata.
pub(crate) const GENERATOR: &str = "tortwin synth";

const NS_PER_S: f64 = 1e9;
const HOUR_NS: u64 = 3_600_000_000_000;
const DAY_NS: u64 = 24 * HOUR_NS;

/// `x` rounded to `1 / scale` (scale a power of ten): the integer divided
/// by the scale is the double nearest the short decimal, so JSON shows it short.
fn round_dp(x: f64, scale: f64) -> f64 {
    (x * scale).round() / scale
}

/// A log_time as an RFC 3339 UTC string.
pub(crate) fn utc(log_time_ns: u64) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
