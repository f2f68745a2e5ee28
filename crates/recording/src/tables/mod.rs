//! A recording as tables: the files a wayside installation typically
//! exports, in and out (docs/spec/csv-tables.md).
//!
//! | file | one row per | columns |
//! |---|---|---|
//! | `section.toml` | — | the `/section` message, and `time_utc`, when it takes effect |
//! | `passages.csv` | axle of a train | `train_id`, time, `direction`, `speed_mps`, `axle_offset_m`, `bogie_position`, `wheel_diameter_m`, and per rail R `wheel_load_kN_R`, `cx_R`, `cy_R`, `spin_per_m_R` |
//! | `pulses.csv` | pump stroke | time, `applicator_id`, `rail`, `mass_g` |
//! | `weather.csv` | weather message | time, `air_temperature_c`, `relative_humidity`, `precipitation_mm_h` |
//! | `measurements.csv` | measurement | time, `site_id`, `rail`, `quantity`, `train_id`, `axle_index`, `value` |
//!
//! The time column is `time_utc` (RFC 3339, any offset, up to nanoseconds)
//! or `log_time_ns` (integer nanoseconds since the Unix epoch). Units are
//! the recording format's: g, kN, m, m/s. The rows of a train are
//! consecutive and in axle order; `pulses`, `weather` and `measurements`
//! are optional files.
//!
//! [`import`] turns such a folder into a recording, checking every rule
//! of the format with an error that names the file, line and column;
//! [`export`] writes a recording's inputs back as such a folder, with the
//! recording's own numbers (so the two are each other's inverse).

pub mod export;
pub mod import;

use std::borrow::Cow;

use chrono::{DateTime, SecondsFormat, Utc};

/// The first characters that make a spreadsheet run a cell as a formula.
pub const FORMULA_STARTS: [char; 6] = ['=', '+', '-', '@', '\t', '\r'];

/// A text cell (an id) as no spreadsheet runs it: `'` in front of one
/// that begins like a formula (docs/spec/csv-tables.md; OWASP, "CSV
/// Injection"). Numbers are never passed through it.
pub fn inert(id: &str) -> Cow<'_, str> {
    if id.starts_with(FORMULA_STARTS) {
        Cow::Owned(format!("'{id}"))
    } else {
        Cow::Borrowed(id)
    }
}

/// An id as [`inert`] wrote it, the `'` taken off again.
pub fn active(id: &str) -> &str {
    match id.strip_prefix('\'') {
        Some(rest) if rest.starts_with(FORMULA_STARTS) => rest,
        _ => id,
    }
}

pub const SECTION_FILE: &str = "section.toml";
pub const PASSAGES_FILE: &str = "passages.csv";
pub const PULSES_FILE: &str = "pulses.csv";
pub const WEATHER_FILE: &str = "weather.csv";
pub const MEASUREMENTS_FILE: &str = "measurements.csv";

/// The time column, RFC 3339.
pub const TIME_UTC: &str = "time_utc";
/// The time column, integer ns since the epoch.
pub const LOG_TIME_NS: &str = "log_time_ns";

/// The columns of `passages.csv` that do not depend on the rails.
pub const PASSAGE_COLUMNS: [&str; 6] = [
    "train_id",
    "direction",
    "speed_mps",
    "axle_offset_m",
    "bogie_position",
    "wheel_diameter_m",
];
pub const PULSE_COLUMNS: [&str; 3] = ["applicator_id", "rail", "mass_g"];
pub const WEATHER_COLUMNS: [&str; 3] = [
    "air_temperature_c",
    "relative_humidity",
    "precipitation_mm_h",
];
pub const MEASUREMENT_COLUMNS: [&str; 6] = [
    "site_id",
    "rail",
    "quantity",
    "train_id",
    "axle_index",
    "value",
];

/// The per-rail columns of `passages.csv` for `rail`, in their order.
pub fn rail_columns(rail: &str) -> [String; 4] {
    [
        format!("wheel_load_kN_{rail}"),
        format!("cx_{rail}"),
        format!("cy_{rail}"),
        format!("spin_per_m_{rail}"),
    ]
}

/// An RFC 3339 time as ns since the epoch (UTC).
pub fn parse_time(text: &str) -> Result<u64, String> {
    let t = DateTime::parse_from_rfc3339(text).map_err(|e| {
        format!("`{text}` is not an RFC 3339 time such as 2024-04-08T05:12:33.5Z ({e})")
    })?;
    t.timestamp_nanos_opt()
        .and_then(|ns| u64::try_from(ns).ok())
        .ok_or_else(|| format!("`{text}` is outside 1970 to 2262, the recordings' time range"))
}

/// ns since the epoch as RFC 3339 UTC, with as many fractional digits as
/// it needs (exact to the nanosecond).
pub fn format_time(log_time_ns: u64) -> String {
    let ns = i64::try_from(log_time_ns).unwrap_or(i64::MAX);
    DateTime::<Utc>::from_timestamp_nanos(ns).to_rfc3339_opts(SecondsFormat::AutoSi, true)
}

/// A float as the shortest text that reads back to the same number.
pub fn format_number(x: f64) -> String {
    format!("{x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_round_trip_to_the_nanosecond() {
        for ns in [
            0,
            1_712_534_400_000_000_000,
            1_712_534_400_123_456_789,
            1_712_534_401_500_000_000,
        ] {
            assert_eq!(parse_time(&format_time(ns)).unwrap(), ns);
        }
        assert_eq!(
            format_time(1_712_534_400_500_000_000),
            "2024-04-08T00:00:00.500Z"
        );
        assert_eq!(
            parse_time("2024-04-08T02:00:00+02:00").unwrap(),
            1_712_534_400_000_000_000
        );
        assert!(parse_time("2024-04-08 00:00").is_err());
        assert!(parse_time("1969-12-31T23:59:59Z").is_err());
    }

    #[test]
    fn numbers_round_trip() {
        for x in [0.1, 1e-9, 1.0 / 3.0, 112.0, -0.003, 1e21, 5e-324] {
            assert_eq!(format_number(x).parse::<f64>().unwrap(), x);
        }
    }
}
