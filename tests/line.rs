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

use tortwin_engine::EngineState;
use tortwin_recording::line::{Line, Segment, SegmentKind};

/// What a replay published and left.
struct Run {
    rec: Recorder,
    state: EngineState,
    summary: tortwin_engine::sink::RunSummary,
}

/// Replays the events of `path` on its section, as the line `line` when
/// given, with `cfg`.
fn run_as(path: &Path, line: Option<Line>, cfg: ModelConfig) -> Run {
    let reader = RecordingReader::open(path, ReaderContext::default()).unwrap();
    let mut engine = Engine::on_line(
        reader.section().clone(),
        line,
        cfg,
        EngineOptions::default(),
        reader.origin_ns(),
    );
    let mut rec = Recorder::with_fields();
    for event in reader {
        engine.push(event.unwrap(), &mut rec).unwrap();
    }
    let summary = engine.finish(&mut rec, 0).unwrap();
    Run {
        rec,
        state: engine.state(),
        summary,
    }
}

fn line_of(segments: &[(&str, SegmentKind, f64)]) -> Line {
    Line {
        line_id: "test".into(),
        segments: segments
            .iter()
            .map(|&(id, kind, end_m)| Segment {
                id: id.into(),
                kind,
                end_m,
                radius_m: None,
            })
            .collect(),
    }
}

fn bits(x: &[f64]) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

/// `line`'s replay is `section`'s bit for bit, the section's track
/// `rail/band` being the line's `rail/band'` by `bands`; the line's tracks
/// that no section track matches are untouched (rail mass 0, no wheel).
fn assert_same(section: &Run, line: &Run, bands: &[(&str, &str)]) {
    let sim = |r: &Run| bits(&r.rec.simulated());
    assert_eq!(sim(section), sim(line), "simulated measurements");
    assert!(!section.rec.measurements.is_empty());
    let renamed = |track: &str| {
        let (rail, band) = track.split_once('/').unwrap();
        let to = bands.iter().find(|(from, _)| *from == band).unwrap().1;
        format!("{rail}/{to}")
    };
    let mut compared = 0;
    for f in &section.rec.fields {
        let track = renamed(&f.track);
        let g = line
            .rec
            .fields
            .iter()
            .find(|g| g.log_time_ns == f.log_time_ns && g.track == track)
            .unwrap_or_else(|| panic!("no field of {track} at {}", f.log_time_ns));
        assert_eq!(
            bits(&f.mu),
            bits(&g.mu),
            "mu of {track} at {}",
            f.log_time_ns
        );
        assert_eq!(bits(&f.adhesion), bits(&g.adhesion), "adhesion of {track}");
        assert_eq!(
            bits(&f.rail_mass_kg),
            bits(&g.rail_mass_kg),
            "rail of {track}"
        );
        assert_eq!(
            bits(&f.wheel_mass_kg),
            bits(&g.wheel_mass_kg),
            "wheel of {track}"
        );
        compared += 1;
    }
    assert!(compared > 0);
    for s in &section.state.tracks {
        let track = renamed(&format!("{}/{}", s.rail, s.band));
        let t = line
            .state
            .tracks
            .iter()
            .find(|t| format!("{}/{}", t.rail, t.band) == track)
            .unwrap();
        assert_eq!(
            bits(&s.rail_mass_kg),
            bits(&t.rail_mass_kg),
            "state of {track}"
        );
        assert_eq!(s.last_touch_s, t.last_touch_s, "touches of {track}");
    }
    let matched: Vec<String> = section
        .state
        .tracks
        .iter()
        .map(|s| renamed(&format!("{}/{}", s.rail, s.band)))
        .collect();
    for t in &line.state.tracks {
        if !matched.contains(&format!("{}/{}", t.rail, t.band)) {
            assert!(
                t.rail_mass_kg.iter().all(|&m| m == 0.0),
                "{}/{}",
                t.rail,
                t.band
            );
            assert!(t.last_touch_s.iter().all(Option::is_none));
        }
    }
    let (a, b) = (&section.summary.mass_balance, &line.summary.mass_balance);
    assert_eq!(
        [a.applied_kg, a.consumed_kg, a.capped_kg, a.carried_out_kg].map(f64::to_bits),
        [b.applied_kg, b.consumed_kg, b.capped_kg, b.carried_out_kg].map(f64::to_bits),
        "mass balance"
    );
    // The rail mass at the end is the sum over tracks, in track order, and
    // a line orders its tracks by rail then band (C, G), bogie_bands the
    // high rail's gauge corner first: the same masses (compared bit for bit
    // above) summed in another order.
    assert!(
        relative(b.on_rail_end_kg, a.on_rail_end_kg) < 1e-14,
        "rail mass at the end"
    );
    assert_eq!(section.summary.contacts, line.summary.contacts);
}

/// Check 1: the reference recordings without effects, given a line of one
/// tangent segment, are their section bit for bit (and so give their
/// expected values, which tests/replay_reference.rs checks for the
/// section).
#[test]
fn a_line_of_one_tangent_is_the_section() {
    for name in ["tangent_day", "curve_2day"] {
        let path = recordings().join(format!("{name}.mcap"));
        let section = run_as(&path, None, ModelConfig::default());
        let line = line_of(&[("T", SegmentKind::Tangent, 600.0)]);
        let on_line = run_as(&path, Some(line), ModelConfig::default());
        assert_same(&section, &on_line, &[("top", "C")]);
    }
}

/// Check 2: a line of one curve whose high rail is the rail named `high`
/// is the section with `bogie_bands`, bit for bit: `gauge_corner` is the
/// high rail's `G`, `top` its `C`.
#[test]
fn a_line_of_one_curve_is_the_section_with_bogie_bands() {
    let path = recordings().join("curve_2day.mcap");
    let mut bands = ModelConfig::default();
    bands
        .effects
        .set(tortwin_model::effects::Named::BogieBands, &[]);
    let section = run_as(&path, None, bands);
    let line = line_of(&[("C", SegmentKind::Curve { high_rail: 0 }, 600.0)]);
    let on_line = run_as(&path, Some(line), ModelConfig::default());
    assert_same(&section, &on_line, &[("top", "C"), ("gauge_corner", "G")]);
}

/// Check 3: consecutive segments of one type through which every axle has
/// the same load and creepage are one segment over them, bit for bit,
/// wherever the cuts fall (on grid points, between them, at the ends).
#[test]
fn cuts_between_segments_of_one_type_change_nothing() {
    let path = recordings().join("curve_2day.mcap");
    let spacing = std::f64::consts::PI * 0.92;
    let curve = SegmentKind::Curve { high_rail: 0 };
    let whole = run_as(
        &path,
        Some(line_of(&[("C", curve, 600.0)])),
        ModelConfig::default(),
    );
    let cuts: [&[f64]; 4] = [
        &[300.0],
        &[10.0 * spacing, 10.0 * spacing + 1e-9, 455.5],
        &[spacing * 0.5, 599.999],
        &[1e-9, 59.0, 60.0, 61.0, 209.9, 210.0],
    ];
    for (k, cut) in cuts.iter().enumerate() {
        let ends: Vec<f64> = cut.iter().copied().chain([600.0]).collect();
        let ids: Vec<String> = (0..ends.len()).map(|j| format!("C{j}")).collect();
        let segments: Vec<(&str, SegmentKind, f64)> = ids
            .iter()
            .zip(&ends)
            .map(|(id, &e)| (id.as_str(), curve, e))
            .collect();
        let cut_line = run_as(&path, Some(line_of(&segments)), ModelConfig::default());
        assert_same(&whole, &cut_line, &[("C", "C"), ("G", "G")]);
        eprintln!("cuts {k}: {cut:?} give the whole curve bit for bit");
    }
    // Tangents likewise, on the tangent recording.
    let path = recordings().join("tangent_day.mcap");
    let whole = run_as(
        &path,
        Some(line_of(&[("T", SegmentKind::Tangent, 600.0)])),
        ModelConfig::default(),
    );
    let cut_line = run_as(
        &path,
        Some(line_of(&[
            ("T0", SegmentKind::Tangent, 3.0 * spacing),
            ("T1", SegmentKind::Tangent, 333.3),
            ("T2", SegmentKind::Tangent, 600.0),
        ])),
        ModelConfig::default(),
    );
    assert_same(&whole, &cut_line, &[("C", "C"), ("G", "G")]);
}
