//! Replaying the reference recordings of tests/reference/recordings
//! (written by an independent implementation) gives, for every measurement,
//! the `simulated` value of NAME.expected.csv to 1e-9 relative, in the same
//! replay order. generic_day is replayed with generic_day.config.toml: every
//! acts_on and form of the generic terms, several drivers and scopes at once.

use std::path::PathBuf;

use tortwin_jobs::replay::{replay, ReplayArgs};

mod common;
use common::Recorder;

fn reference_dir() -> PathBuf {
    common::reference("recordings")
}

fn check(name: &str) {
    check_with(name, None);
}

fn check_with(name: &str, config: Option<&str>) {
    let mut collect = Recorder::default();
    let mut a = ReplayArgs::new(reference_dir().join(format!("{name}.mcap")));
    a.config = config.map(|c| reference_dir().join(c).into());
    let summary = replay(&a, None, &mut [&mut collect], &tortwin_study::Silent)
        .unwrap()
        .summary;
    let expected =
        std::fs::read_to_string(reference_dir().join(format!("{name}.expected.csv"))).unwrap();
    let rows: Vec<&str> = expected.lines().skip(1).filter(|l| !l.is_empty()).collect();
    assert_eq!(
        collect.measurements.len(),
        rows.len(),
        "{name}: number of measurements"
    );
    let mut worst = 0.0f64;
    for (got, line) in collect.measurements.iter().zip(&rows) {
        let f: Vec<&str> = line.split(',').collect();
        let (index, log_time): (u64, u64) = (f[0].parse().unwrap(), f[1].parse().unwrap());
        let want: f64 = f[8].parse().unwrap();
        let measured: f64 = f[7].parse().unwrap();
        assert_eq!(
            (got.index_in_file, got.log_time_ns),
            (index, log_time),
            "{name}: replay order at {line}"
        );
        assert_eq!(
            (got.site.as_str(), got.rail.as_str(), got.quantity.as_str()),
            (f[2], f[3], f[4]),
            "{line}"
        );
        assert_eq!(got.train_id.as_deref().unwrap_or(""), f[5], "{line}");
        assert_eq!(
            got.axle_index.map(|a| a.to_string()).unwrap_or_default(),
            f[6],
            "{line}"
        );
        assert_eq!(got.measured, measured, "{line}");
        let rel = (got.simulated - want).abs() / want.abs();
        worst = worst.max(rel);
        assert!(
            rel <= 1e-9,
            "{name}: simulated {} vs expected {want} (relative {rel:e}) at {line}",
            got.simulated
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
