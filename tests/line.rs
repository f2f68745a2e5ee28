//! A line (docs/spec/line.md): its checks 1 to 5. The reference line,
//! tests/reference/recordings/line_field.mcap, and the mu its last train's
//! first wagon sees along it, tests/reference/line_field.csv, come from an
//! independent implementation (tests/reference/README.md).

use std::path::{Path, PathBuf};

use tortwin_engine::sink::{Sink, SinkResult, WheelContacts};
use tortwin_engine::{Engine, EngineOptions};
use tortwin_jobs::replay::{replay, ReplayArgs};
use tortwin_model::config::ModelConfig;
use tortwin_model::product;
use tortwin_recording::reader::{ReaderContext, RecordingReader};

mod common;
use common::Recorder;

fn recordings() -> PathBuf {
    common::reference("recordings")
}

/// Keeps every wheel's step-2 masses of one train.
#[derive(Default)]
struct Contacts {
    train_seq: usize,
    /// (axle, rail) -> masses in grid order.
    seen: Vec<((usize, usize), Vec<f64>)>,
}

impl Sink for Contacts {
    fn wheel_contacts(&mut self, w: &WheelContacts<'_>) -> SinkResult {
        if w.train_seq == self.train_seq {
            self.seen.push(((w.axle, w.rail), w.seen_mass_kg.to_vec()));
        }
        Ok(())
    }
}

/// Replays `path` on the engine (as a line when it has a `/line`) with
/// every wheel's contacts handed to `sink`.
fn replay_engine(path: &Path, sink: &mut dyn Sink) -> Engine {
    let reader = RecordingReader::open(path, ReaderContext::default()).unwrap();
    let opts = EngineOptions {
        every_wheel_contacts: true,
        ..EngineOptions::default()
    };
    let mut engine = Engine::on_line(
        reader.section().clone(),
        reader.line().cloned(),
        ModelConfig::default(),
        opts,
        reader.origin_ns(),
    );
    for event in reader {
        engine.push(event.unwrap(), sink).unwrap();
    }
    engine.finish(sink, 0).unwrap();
    engine
}

fn relative(got: f64, want: f64) -> f64 {
    if got == want {
        0.0
    } else {
        (got - want).abs() / want.abs()
    }
}

/// Check 5, its measurements: every simulated value of
/// line_field.expected.csv to 1e-9 relative, in replay order, through the
/// command's replay.
#[test]
fn the_field_line_gives_the_reference_measurements() {
    let mut collect = Recorder::default();
    let args = ReplayArgs::new(recordings().join("line_field.mcap"));
    let summary = replay(&args, None, &mut [&mut collect], &tortwin_study::Silent)
        .unwrap()
        .summary;
    let expected = std::fs::read_to_string(recordings().join("line_field.expected.csv")).unwrap();
    let rows: Vec<&str> = expected.lines().skip(1).filter(|l| !l.is_empty()).collect();
    assert_eq!(collect.measurements.len(), rows.len());
    let mut worst = 0.0f64;
    for (got, line) in collect.measurements.iter().zip(&rows) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(got.index_in_file, f[0].parse::<u64>().unwrap(), "{line}");
        assert_eq!(
            (got.site.as_str(), got.rail.as_str(), got.quantity.as_str()),
            (f[2], f[3], f[4]),
            "{line}"
        );
        let want: f64 = f[8].parse().unwrap();
        let rel = relative(got.simulated, want);
        worst = worst.max(rel);
        assert!(rel <= 1e-9, "simulated {} at {line}", got.simulated);
    }
    eprintln!(
        "line_field: {} measurements, worst relative difference {worst:e}",
        rows.len()
    );
    let closing = summary.mass_balance.closing_error();
    assert!(closing < 1e-12, "mass balance closes to {closing:e}");
}

/// Check 5, the field: the mu every point of the line gives the last
/// train's axles 4 (leading) and 5 (trailing) on both rails, against
/// line_field.csv to 1e-9 relative.
#[test]
fn the_field_line_gives_the_reference_mu_along_it() {
    let mut contacts = Contacts {
        train_seq: 11,
        ..Contacts::default()
    };
    let engine = replay_engine(&recordings().join("line_field.mcap"), &mut contacts);
    let table = std::fs::read_to_string(common::reference("line_field.csv")).unwrap();
    let rows: Vec<&str> = table.lines().skip(1).filter(|l| !l.is_empty()).collect();
    assert_eq!(rows.len(), engine.grid().d_m.len());
    let p = ModelConfig::default().product;
    let seen = |axle: usize, rail: usize| {
        &contacts
            .seen
            .iter()
            .find(|(k, _)| *k == (axle, rail))
            .unwrap_or_else(|| panic!("no contacts of axle {axle} on rail {rail}"))
            .1
    };
    // Columns: mu_lead_left, mu_trail_left, mu_lead_right, mu_trail_right.
    let wheels = [(4, 0), (5, 0), (4, 1), (5, 1)];
    let mut worst = 0.0f64;
    for (i, line) in rows.iter().enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        let d: f64 = f[0].parse().unwrap();
        assert_eq!(d, engine.grid().d_m[i], "{line}");
        for (k, &(axle, rail)) in wheels.iter().enumerate() {
            let want: f64 = f[4 + k].parse().unwrap();
            let got = product::friction(&p, seen(axle, rail)[i]);
            let rel = relative(got, want);
            worst = worst.max(rel);
            assert!(rel <= 1e-9, "axle {axle} rail {rail}: {got} at {line}");
        }
    }
    eprintln!(
        "line_field.csv: {} points x 4 wheels, worst relative difference {worst:e}",
        rows.len()
    );
}
