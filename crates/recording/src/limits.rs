//! The physical range of every number a recording holds
//! (docs/spec/recording-format.md, "Limits"): wide enough for any railway
//! (the extremes of the world's rolling stock, track and weather), narrow
//! enough that the model's arithmetic stays finite. A value outside is an
//! input error naming the field, as a negative load is.
//!
//! Times: a log_time is a signed 64-bit count of nanoseconds
//! ([`LAST_LOG_TIME_NS`]); a train must leave the section before it.

/// A closed range `lo ..= hi` in `unit`, and why it is that wide.
#[derive(Debug, Clone, Copy)]
pub struct Range {
    pub lo: f64,
    pub hi: f64,
    pub unit: &'static str,
    pub why: &'static str,
}

impl Range {
    pub fn contains(&self, x: f64) -> bool {
        (self.lo..=self.hi).contains(&x)
    }
}

/// `speed_mps`: from a shunting crawl to above the rail speed record
/// (574.8 km/h = 160 m/s); the slowest train must leave a section within
/// the time a log_time can hold.
pub const SPEED_MPS: Range = Range {
    lo: 0.01,
    hi: 200.0,
    unit: "m/s",
    why: "a crawl of 36 m/h to above the rail speed record (160 m/s)",
};

/// `wheel_diameter_m` and `nominal_wheel_diameter_m`.
pub const WHEEL_DIAMETER_M: Range = Range {
    lo: 0.1,
    hi: 3.0,
    unit: "m",
    why: "below the smallest low-floor wheels (0.3 m), above the largest driving wheels \
          ever built (2.3 m)",
};

/// `axles[].wheel_load_kN`.
pub const WHEEL_LOAD_KN: Range = Range {
    lo: 0.1,
    hi: 1000.0,
    unit: "kN",
    why: "from an empty inspection trolley to five times the heaviest axle load in service \
          (40 t: 200 kN a wheel)",
};

/// `length_m` of a `/section`: a point to a line; the grid's limit (200 000
/// points a rail, a point per 0.1 m of wheel circumference or more) is
/// reached first on long sections.
pub const SECTION_LENGTH_M: Range = Range {
    lo: 1.0,
    hi: 1_000_000.0,
    unit: "m",
    why: "a metre (a wheel's contact with one grid point) to 1000 km",
};

/// `curve_radius_m` of a `/section` (absent on tangent track).
pub const CURVE_RADIUS_M: Range = Range {
    lo: 10.0,
    hi: 1e7,
    unit: "m",
    why: "tram curves of 12 m to a tangent's 10 000 km",
};

/// `axles[].offset_m`.
pub const OFFSET_M: Range = Range {
    lo: 0.0,
    hi: 20_000.0,
    unit: "m",
    why: "the longest trains run 7.4 km",
};

/// `creepage.*.cx` and `cy`: a creepage is a speed ratio.
pub const CREEPAGE: Range = Range {
    lo: -1.0,
    hi: 1.0,
    unit: "",
    why: "a creepage of 1 is a wheel sliding at the train's speed (rolling contacts stay \
          below 0.05)",
};

/// `creepage.*.spin_per_m`.
pub const SPIN_PER_M: Range = Range {
    lo: -100.0,
    hi: 100.0,
    unit: "1/m",
    why: "sin(contact angle) over the rolling radius: at most about 4 1/m on a flange",
};

/// `rail_head_radius_m`.
pub const RAIL_HEAD_RADIUS_M: Range = Range {
    lo: 0.01,
    hi: 100.0,
    unit: "m",
    why: "rail heads are crowned with radii of 0.08 to 0.6 m; 100 m is a flat head",
};

/// `mass_g` of a pulse and `nominal_pulse_g`.
pub const PULSE_G: Range = Range {
    lo: 0.0,
    hi: 1000.0,
    unit: "g",
    why: "a pump stroke delivers about 0.1 g; a kilogram is a spill, not a pulse",
};

/// `value` of a measurement.
pub const MEASURED_VALUE: Range = Range {
    lo: -10.0,
    hi: 10.0,
    unit: "",
    why: "friction and adhesion coefficients lie within -1 and 1; an instrument's offset \
          does not reach ten",
};

/// `air_temperature_c`.
pub const AIR_TEMPERATURE_C: Range = Range {
    lo: -90.0,
    hi: 70.0,
    unit: "°C",
    why: "the air temperatures recorded on earth run from -89.2 to 56.7 °C",
};

/// `relative_humidity`, a fraction.
pub const RELATIVE_HUMIDITY: Range = Range {
    lo: 0.0,
    hi: 1.0,
    unit: "",
    why: "a fraction of saturation",
};

/// `precipitation_mm_h`.
pub const PRECIPITATION_MM_H: Range = Range {
    lo: 0.0,
    hi: 500.0,
    unit: "mm/h",
    why: "the heaviest rain measured fell at about 400 mm/h over an hour",
};

/// Rails of a section: two, four on dual gauge; each is a grid of its own.
pub const MAX_RAILS: usize = 16;

/// Applicators of a section: a few a curve, a few dozen on a long line
/// (every pulse looks its applicator up, and the engine keeps one entry
/// per applicator and rail).
pub const MAX_APPLICATORS: usize = 1000;

/// Measurement sites of a section (every contact at a site is kept until
/// its train's measurements are read).
pub const MAX_SITES: usize = 1000;

/// The last instant a log_time can stand for: `i64::MAX` ns after the
/// epoch, 2262-04-11T23:47:16.854775807Z (the time origin and every time
/// tortwin writes are signed 64-bit nanosecond counts, as the MCAP tools'
/// and rerun's are).
pub const LAST_LOG_TIME_NS: u64 = i64::MAX as u64;
