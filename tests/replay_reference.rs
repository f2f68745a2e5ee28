//! Replaying the reference recordings of tests/reference/recordings
//! (written by an independent implementation) gives, for every measurement,
//! the `simulated` value of NAME.expected.csv to 1e-9 relative, in the same
//! replay order. generic_day is replayed with generic_day.config.toml: every
//! acts_on and form of the generic terms, several drivers and scopes at once.

use std::path::PathBuf;

use tortwin::app::replay::{replay, ReplayArgs};
use tortwin::sink::{MeasurementOutput, Sink};

/// index_in_file, log_time, site, rail, quantity, train, axle, measured, simulated.
type Row = (
    u64,
    u64,
    String,
    String,
    String,
    Option<String>,
    Option<usize>,
    f64,
    f64,
);

#[derive(Default)]
struct Collect {
    rows: Vec<Row>,
}

impl Sink for Collect {
    fn measurement(&mut self, m: &MeasurementOutput<'_>) -> anyhow::Result<()> {
        self.rows.push((
            m.index_in_file,
            m.log_time_ns,
            m.site_id.to_string(),
            m.rail_name.to_string(),
            m.quantity.as_str().to_string(),
            m.train_id.map(str::to_string),
            m.axle_index,
            m.measured,
            m.simulated,
        ));
        Ok(())
    }
}

pub fn reference_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/reference/recordings")
}

pub fn args(recording: PathBuf) -> ReplayArgs {
    ReplayArgs::new(recording)
}

fn check(name: &str) {
    check_with(name, None);
}

fn check_with(name: &str, config: Option<&str>) {
    let mut collect = Collect::default();
    let mut a = args(reference_dir().join(format!("{name}.mcap")));
    a.config = config.map(|c| reference_dir().join(c));
    let summary = replay(&a, &mut [&mut collect]).unwrap();
    let expected =
        std::fs::read_to_string(reference_dir().join(format!("{name}.expected.csv"))).unwrap();
    let rows: Vec<&str> = expected.lines().skip(1).filter(|l| !l.is_empty()).collect();
    assert_eq!(
        collect.rows.len(),
        rows.len(),
        "{name}: number of measurements"
    );
    let mut worst = 0.0f64;
    for (got, line) in collect.rows.iter().zip(&rows) {
        let f: Vec<&str> = line.split(',').collect();
        let (index, log_time): (u64, u64) = (f[0].parse().unwrap(), f[1].parse().unwrap());
        let want: f64 = f[8].parse().unwrap();
        let measured: f64 = f[7].parse().unwrap();
        assert_eq!(
            (got.0, got.1),
            (index, log_time),
            "{name}: replay order at {line}"
        );
        assert_eq!(
            (got.2.as_str(), got.3.as_str(), got.4.as_str()),
            (f[2], f[3], f[4]),
            "{line}"
        );
        assert_eq!(got.5.as_deref().unwrap_or(""), f[5], "{line}");
        assert_eq!(
            got.6.map(|a| a.to_string()).unwrap_or_default(),
            f[6],
            "{line}"
        );
        assert_eq!(got.7, measured, "{line}");
        let rel = (got.8 - want).abs() / want.abs();
        worst = worst.max(rel);
        assert!(
            rel <= 1e-9,
            "{name}: simulated {} vs expected {want} (relative {rel:e}) at {line}",
            got.8
        );
    }
    eprintln!(
        "{name}: {} measurements, worst relative difference {worst:e}",
        rows.len()
    );
    let closing = summary.mass_balance.closing_error();
    assert!(
        closing < 1e-12,
        "{name}: mass balance closes to {closing:e}"
    );
}

#[test]
fn tangent_day_matches_the_reference() {
    check("tangent_day");
}

#[test]
fn curve_2day_matches_the_reference() {
    check("curve_2day");
}

#[test]
fn generic_day_matches_the_reference() {
    check_with("generic_day", Some("generic_day.config.toml"));
}
