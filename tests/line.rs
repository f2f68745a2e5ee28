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
    let opts = EngineOptions {
        every_wheel_contacts: true,
        ..EngineOptions::default()
    };
    replay_engine_with(path, opts, sink, |_| ())
}

/// Replays `path` on the engine with `opts`, showing `seen` each event.
fn replay_engine_with(
    path: &Path,
    opts: EngineOptions,
    sink: &mut dyn Sink,
    mut seen: impl FnMut(&tortwin_recording::Event),
) -> Engine {
    let reader = RecordingReader::open(path, ReaderContext::default()).unwrap();
    let mut engine = Engine::on_line(
        reader.section().clone(),
        reader.line().cloned(),
        ModelConfig::default(),
        opts,
        reader.origin_ns(),
    );
    for event in reader {
        let event = event.unwrap();
        seen(&event);
        engine.push(event, sink).unwrap();
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

mod sharing {
    //! Trains that share a line (line.md, "Order"): B enters while A is
    //! still on the line, and none catches up with the other.

    use super::*;
    use tortwin_recording::line::CurveAt;
    use tortwin_recording::{
        Applicator, Axle, AxleRef, BogiePosition, Creepage, Direction, Event, EventKind, Measured,
        Measurement, Passage, Pulse, Section, Site,
    };

    const S: f64 = 1e9;

    fn section() -> Section {
        Section {
            section_id: "sharing".into(),
            length_m: 300.0,
            rails: vec!["left".into(), "right".into()],
            curve_radius_m: None,
            rail_head_radius_m: 0.3,
            nominal_wheel_diameter_m: 0.92,
            applicators: vec![Applicator {
                id: "A".into(),
                position_m: 80.0,
                rails: vec![0, 1],
                nominal_pulse_kg: 2e-4,
            }],
            sites: vec![Site {
                id: "M".into(),
                position_m: 150.0,
            }],
        }
    }

    fn line() -> Line {
        let transition = |curve_at| SegmentKind::Transition {
            high_rail: 1,
            curve_at,
        };
        line_of(&[
            ("T0", SegmentKind::Tangent, 40.0),
            ("X1", transition(CurveAt::End), 70.0),
            ("C1", SegmentKind::Curve { high_rail: 1 }, 180.0),
            ("X2", transition(CurveAt::Start), 210.0),
            ("T1", SegmentKind::Tangent, 300.0),
        ])
    }

    fn passage(t_s: f64, seq: usize) -> (f64, EventKind) {
        let creepage = Creepage {
            cx: 0.004,
            cy: 0.002,
            spin_per_m: 0.0,
        };
        let axles = (0..8)
            .map(|k| Axle {
                offset_m: 2.5 * k as f64,
                bogie_position: [BogiePosition::Leading, BogiePosition::Trailing][k % 2],
                wheel_diameter_m: 0.92,
                wheel_load_n: vec![90e3, 110e3],
                creepage: vec![creepage; 2],
                segments: Vec::new(),
            })
            .collect();
        let passage = Passage {
            train_id: format!("T{seq}"),
            train_seq: seq,
            direction: Direction::Up,
            speed_mps: 10.0,
            axles,
        };
        (t_s, EventKind::Passage(passage))
    }

    fn pulse(t_s: f64, rail: usize) -> (f64, EventKind) {
        let p = Pulse {
            applicator: 0,
            rail,
            mass_kg: 2e-4,
        };
        (t_s, EventKind::Pulse(p))
    }

    fn reading(t_s: f64, rail: usize) -> (f64, EventKind) {
        let of = Measured::RailMu;
        let m = Measurement {
            site: 0,
            rail,
            of,
            value: 0.5,
        };
        (t_s, EventKind::Measurement(m))
    }

    fn mu(t_s: f64, seq: usize, axle_index: usize, rail: usize) -> (f64, EventKind) {
        let axle = AxleRef {
            train_id: format!("T{seq}").into(),
            train_seq: seq,
            axle_index,
        };
        let m = Measurement {
            site: 0,
            rail,
            of: Measured::Mu(axle),
            value: 0.5,
        };
        (t_s, EventKind::Measurement(m))
    }

    fn replay(events: &[(f64, EventKind)]) -> Run {
        let mut engine = Engine::on_line(
            section(),
            Some(line()),
            ModelConfig::default(),
            EngineOptions::default(),
            0,
        );
        let mut rec = Recorder::with_fields();
        for (k, (t_s, kind)) in events.iter().enumerate() {
            let event = Event {
                log_time_ns: (t_s * S).round() as u64,
                index_in_file: k as u64,
                kind: kind.clone(),
            };
            engine.push(event, &mut rec).unwrap();
        }
        let summary = engine.finish(&mut rec, 0).unwrap();
        Run {
            rec,
            state: engine.state(),
            summary,
        }
    }

    /// With no effects, time only orders the events at each point. Train A
    /// (T0) enters at 10 s, 10 m/s, its last axle 17.5 m behind the front:
    /// at the applicator (80 m) 18-19.75 s, at the site (150 m) 25-26.75 s,
    /// gone at 41.75 s. Train B (T1) enters at 20 s, while A is on the line:
    /// at the applicator 28-29.75 s, at the site 35-36.75 s. The same line
    /// with B 100 s later (and every pulse or reading that comes after A's
    /// last wheel at its point 100 s later) keeps every point's order, so
    /// it must give the same bits: pulses before, among and after both
    /// trains' wheels, readings between the trains and among B's wheels.
    #[test]
    fn a_train_entering_while_another_is_on_the_line_is_the_same_as_after_it() {
        let shared = |dt: f64| {
            let mut events = vec![
                pulse(1.0, 0),
                pulse(1.0, 1),
                passage(10.0, 0),
                pulse(12.0, 1),
                pulse(19.0, 0),
                reading(20.0, 0),
                passage(20.0 + dt, 1),
                pulse(25.0 + dt, 1),
                reading(26.0, 1),
                mu(27.0, 0, 3, 0),
                mu(27.0, 0, 4, 1),
                pulse(29.0 + dt, 0),
                reading(30.0 + dt, 0),
                pulse(35.0 + dt, 1),
                reading(36.0 + dt, 1),
                mu(38.0 + dt, 1, 0, 1),
                mu(38.0 + dt, 1, 7, 0),
                reading(40.0 + dt, 0),
                pulse(41.0 + dt, 0),
                reading(300.0, 1),
            ];
            events.sort_by(|a, b| a.0.total_cmp(&b.0));
            replay(&events)
        };
        let together = shared(0.0);
        let apart = shared(100.0);
        let sim = |r: &Run| bits(&r.rec.simulated());
        assert_eq!(together.rec.measurements.len(), 10);
        assert_eq!(sim(&together), sim(&apart));
        for (a, b) in together.state.tracks.iter().zip(&apart.state.tracks) {
            assert_eq!(
                bits(&a.rail_mass_kg),
                bits(&b.rail_mass_kg),
                "{}/{}",
                a.rail,
                a.band
            );
        }
        let last = |r: &Run| {
            r.rec
                .fields
                .iter()
                .filter(|f| f.train_id == "T1")
                .map(|f| (f.track.clone(), bits(&f.mu), bits(&f.wheel_mass_kg)))
                .collect::<Vec<_>>()
        };
        assert_eq!(last(&together), last(&apart));
        assert_eq!(
            together.summary.mass_balance.applied_kg.to_bits(),
            apart.summary.mass_balance.applied_kg.to_bits()
        );
        assert!(together.summary.mass_balance.closing_error() < 1e-12);
        // And the order matters: a pulse between the trains lands before
        // B's wheels (B's first axle sees it), one after B's last wheel at
        // the applicator (29.75 s) does not.
        let b_sees = |t_pulse: f64| {
            let mut events = vec![
                pulse(1.0, 0),
                passage(10.0, 0),
                passage(20.0, 1),
                pulse(t_pulse, 0),
                mu(38.0, 1, 0, 0),
            ];
            events.sort_by(|a, b| a.0.total_cmp(&b.0));
            replay(&events).rec.simulated()[0]
        };
        assert!(
            b_sees(25.0) < b_sees(31.0),
            "{} {}",
            b_sees(25.0),
            b_sees(31.0)
        );
    }

    /// Writes a line (or a section, `line` false) of 300 m with two trains
    /// up, the second `start_s` after the first at `speed_mps`; reads it.
    fn read_two_trains(line: bool, start_s: f64, speed_mps: f64) -> Result<usize, String> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("two.mcap");
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w =
            tortwin_recording::RecordingWriter::new(file, mcap::WriteOptions::new(), None).unwrap();
        let t0: u64 = 1_700_000_000_000_000_000;
        use tortwin_recording::Topic;
        let section = r#"{"section_id": "s", "length_m": 300.0, "rails": ["left", "right"],
            "rail_head_radius_m": 0.3, "nominal_wheel_diameter_m": 0.92,
            "applicators": [{"id": "A", "position_m": 50.0, "rails": ["left"], "nominal_pulse_g": 0.1}],
            "measurement_sites": []}"#;
        w.write_json(Topic::Section, t0, section.as_bytes())
            .unwrap();
        if line {
            let l =
                r#"{"line_id": "l", "segments": [{"id": "T", "type": "tangent", "end_m": 300.0}]}"#;
            w.write_json(Topic::Line, t0, l.as_bytes()).unwrap();
        }
        let train = |id: &str, v: f64| {
            let axle = |offset: f64| {
                format!(
                    r#"{{"offset_m": {offset}, "bogie_position": "leading", "wheel_diameter_m": 0.92,
                    "wheel_load_kN": {{"left": 100, "right": 100}},
                    "creepage": {{"left": {{"cx": 0.01, "cy": 0, "spin_per_m": 0}},
                                 "right": {{"cx": 0.01, "cy": 0, "spin_per_m": 0}}}}}}"#
                )
            };
            format!(
                r#"{{"train_id": "{id}", "direction": "up", "speed_mps": {v}, "axles": [{}, {}]}}"#,
                axle(0.0),
                axle(20.0)
            )
        };
        w.write_json(
            Topic::Passage,
            t0 + 10_000_000_000,
            train("A", 10.0).as_bytes(),
        )
        .unwrap();
        let t_b = t0 + 10_000_000_000 + (start_s * 1e9) as u64;
        w.write_json(Topic::Passage, t_b, train("B", speed_mps).as_bytes())
            .unwrap();
        w.finish().unwrap();
        let reader =
            RecordingReader::open(&path, ReaderContext::default()).map_err(|e| e.to_string())?;
        let mut n = 0;
        for event in reader {
            event.map_err(|e| e.to_string())?;
            n += 1;
        }
        Ok(n)
    }

    /// The reader lets a train enter a line while another is on it as long
    /// as it does not catch up with it at either end (equal is allowed);
    /// on a section it stays an error.
    #[test]
    fn trains_share_a_line_while_none_catches_up() {
        // A: front at 0 m at 10 s, last axle (20 m behind) at 12 s, at
        // 300 m at 42 s.
        assert_eq!(read_two_trains(true, 5.0, 10.0), Ok(2));
        assert_eq!(read_two_trains(true, 2.0, 10.0), Ok(2), "equal at d = 0");
        let early = read_two_trains(true, 1.0, 10.0).unwrap_err();
        assert!(
            early.contains("catches up with train `A`") && early.contains("d = 0 m"),
            "{early}"
        );
        // Faster: at 300 m B's front (5 + 300/20 = 20 s after A) is before
        // A's last axle (32 s after A).
        let fast = read_two_trains(true, 5.0, 20.0).unwrap_err();
        assert!(fast.contains("d = 300 m"), "{fast}");
        let section = read_two_trains(false, 5.0, 10.0).unwrap_err();
        assert!(
            section.contains("two trains in the section at once"),
            "{section}"
        );
    }
}

/// The README's picture of the field line (docs/figures/line_field.svg):
/// mu that the last train's axles 4 (leading) and 5 (trailing) see at every
/// point of both rails, over the rows each rail has there. It is drawn from
/// this replay (which the tests above hold to the reference to 1.3e-15) and
/// must equal the committed file; `TORTWIN_WRITE_FIGURES=1` writes it.
#[test]
fn the_readme_picture_of_the_field_line_is_this_replay() {
    use tortwin_plot::{Colour, LinePlot, Panel, ReferenceLine, Series};
    let mut contacts = Contacts {
        train_seq: 11,
        ..Contacts::default()
    };
    let engine = replay_engine(&recordings().join("line_field.mcap"), &mut contacts);
    let p = ModelConfig::default().product;
    let d: Vec<f64> = engine.grid().d_m.clone();
    let mu = |axle: usize, rail: usize| -> Vec<f64> {
        let seen = &contacts
            .seen
            .iter()
            .find(|(k, _)| *k == (axle, rail))
            .unwrap()
            .1;
        seen.iter().map(|&m| product::friction(&p, m)).collect()
    };
    let wheels = [
        ("left (low), leading", 4, 0, Colour::BLUE, false),
        ("left (low), trailing", 5, 0, Colour::BLUE, true),
        ("right (high), leading", 4, 1, Colour::RED, false),
        ("right (high), trailing", 5, 1, Colour::RED, true),
    ];
    let mut top = Panel::new("mu")
        .reference_line(ReferenceLine::new(p.mu_d, "dry (mu_D)"))
        .y_range(0.25, 0.6);
    for (name, axle, rail, colour, trailing) in wheels {
        let s = Series::new(name, d.clone(), mu(axle, rail)).colour(colour);
        top = top.series(if trailing { s.dashed() } else { s });
    }
    // The rows: 1 where a rail is in curve rows (its transition halves at
    // the curve included), 0 on tangent rows.
    let reader = RecordingReader::open(
        &recordings().join("line_field.mcap"),
        ReaderContext::default(),
    )
    .unwrap();
    let line = reader.line().unwrap().clone();
    let curve_rows: Vec<f64> = d
        .iter()
        .map(|&x| {
            let row =
                tortwin_engine::rows::row(&line, 1, tortwin_recording::BogiePosition::Leading, x);
            f64::from(u8::from(row.rail == tortwin_engine::rows::RailBand::G))
        })
        .collect();
    let bottom = Panel::new("1: curve rows (C1, C2), 0: tangent")
        .series(Series::new("", d.clone(), curve_rows).colour(Colour::GREY))
        .y_range(-0.1, 1.1);
    let plot = LinePlot::stacked(
        "Field line: mu seen by the last train's axles 4 and 5 (applicator at 260 m)",
        "d (m)",
        vec![top, bottom],
    );
    let svg = plot.render_svg().unwrap();
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("docs/figures/line_field.svg");
    if std::env::var_os("TORTWIN_WRITE_FIGURES").is_some() {
        std::fs::write(&path, &svg).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == svg,
        "{} differs from this replay's picture: run TORTWIN_WRITE_FIGURES=1 cargo test --release --test line",
        path.display()
    );
}

/// `tortwin synth --layout`: a line described segment by segment, written
/// as line.md's recording and replayed to its truth.
mod synth {
    use super::*;
    use std::process::Output;
    use tortwin_recording::{Direction, EventKind};

    fn example() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("docs/examples/line-10km.toml")
    }

    fn run(out: &Path, args: &[&str]) -> Output {
        common::tortwin()
            .arg("synth")
            .arg("--out")
            .arg(out)
            .arg("--quiet")
            .args(args)
            .output()
            .unwrap()
    }

    /// The measurements of `path` as the replay publishes them.
    fn replayed(path: &Path) -> Vec<common::MeasurementRow> {
        let mut rows = Recorder::default();
        replay(
            &ReplayArgs::new(path),
            None,
            &mut [&mut rows],
            &tortwin_study::Silent,
        )
        .unwrap();
        rows.measurements
    }

    /// Every noise-free measured value is the replay's (to the 1e-5 the
    /// generator rounds to): the truth the generator computed is the line
    /// the reader reads back.
    fn assert_replayed_truth(path: &Path) -> usize {
        let rows = replayed(path);
        assert!(!rows.is_empty());
        for m in &rows {
            assert!(
                (m.measured - m.simulated).abs() <= 5.000_001e-6,
                "{m:?} at {}",
                path.display()
            );
        }
        rows.len()
    }

    /// The example layout: 17 segments, curves of both hands, a one-rail
    /// applicator. Its axles carry the tangent's loads and creepages as
    /// their own and each curve's and transition's in `segments`, the
    /// outer rail spinning one way and the inner the other; trains run
    /// both ways; A2 sprays the right rail only; the replay gives back
    /// every measured value.
    #[test]
    fn a_described_line_is_written_as_line_md_says_and_replays_to_its_truth() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("line.mcap");
        let layout = example();
        let o = run(
            &out,
            &[
                "--layout",
                layout.to_str().unwrap(),
                "--noise-sigma",
                "0",
                "--trains-per-day",
                "24",
            ],
        );
        common::check(&o, "synth --layout");
        let reader = RecordingReader::open(&out, ReaderContext::default()).unwrap();
        let line = reader.line().cloned().expect("a /line");
        let section = reader.section().clone();
        assert_eq!(line.line_id, "demo-10km");
        assert_eq!(line.segments.len(), 17);
        assert_eq!(section.length_m, 10_000.0);
        let bends: Vec<usize> = (0..line.segments.len())
            .filter(|&k| !matches!(line.segments[k].kind, SegmentKind::Tangent))
            .collect();
        assert_eq!(bends.len(), 12);
        let right = section.rails.iter().position(|r| r == "right").unwrap();
        let a2 = section
            .applicators
            .iter()
            .position(|a| a.id == "A2")
            .unwrap();
        assert_eq!(section.applicators[a2].rails, vec![right]);
        let (mut up, mut down, mut a2_pulses, mut axles) = (0, 0, 0, 0);
        for event in reader {
            match event.unwrap().kind {
                EventKind::Passage(p) => {
                    match p.direction {
                        Direction::Up => up += 1,
                        Direction::Down => down += 1,
                    }
                    for a in &p.axles {
                        axles += 1;
                        let ks: Vec<usize> = a.segments.iter().map(|s| s.segment).collect();
                        assert_eq!(ks, bends, "{} axle: every curve and transition", p.train_id);
                        assert!(a.creepage[0].spin_per_m > 0.0 && a.creepage[1].spin_per_m < 0.0);
                        for s in &a.segments {
                            let high = match line.segments[s.segment].kind {
                                SegmentKind::Curve { high_rail }
                                | SegmentKind::Transition { high_rail, .. } => high_rail,
                                SegmentKind::Tangent => unreachable!(),
                            };
                            let c = s.creepage.as_ref().unwrap();
                            assert!(
                                c[high].spin_per_m > 0.0,
                                "{}: {c:?}",
                                line.segments[s.segment].id
                            );
                            assert!(c[1 - high].spin_per_m < 0.0);
                            assert_eq!(s.wheel_load_n.as_ref().unwrap().len(), 2);
                        }
                    }
                }
                EventKind::Pulse(p) if p.applicator == a2 => {
                    assert_eq!(p.rail, right);
                    a2_pulses += 1;
                }
                _ => {}
            }
        }
        assert!(up > 0 && down > 0, "both directions: {up} up, {down} down");
        assert!(a2_pulses > 0 && axles > 0);
        let n = assert_replayed_truth(&out);
        assert!(n > 1000, "{n} measurements");
        let key: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join("line.key.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(key["params"]["preset"], "line");
        assert_eq!(key["params"]["line"]["segments"][10]["cant_m"], 0.12);
    }

    /// At 150 trains a day with a minute's headway on 10 km, trains enter
    /// while the one before is still on the line (line.md: none catches
    /// up with another); the reader accepts the file and the replay gives
    /// back every measured value.
    #[test]
    fn trains_share_a_described_line() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("busy.mcap");
        let layout = example();
        let o = run(
            &out,
            &[
                "--layout",
                layout.to_str().unwrap(),
                "--noise-sigma",
                "0",
                "--trains-per-day",
                "150",
                "--min-headway-s",
                "60",
                "--measured-train-share",
                "0.1",
                "--seed",
                "4",
            ],
        );
        common::check(&o, "synth --layout");
        let reader = RecordingReader::open(&out, ReaderContext::default()).unwrap();
        let length_m = reader.section().length_m;
        let mut shared = 0;
        let mut before: Option<(f64, f64)> = None;
        for event in reader {
            let event = event.unwrap();
            if let EventKind::Passage(p) = event.kind {
                let t_s = event.log_time_ns as f64 * 1e-9;
                let last = p.axles.last().unwrap().offset_m;
                if before.is_some_and(|(_, leaves_s)| t_s < leaves_s) {
                    shared += 1;
                }
                before = Some((t_s, t_s + (length_m + last) / p.speed_mps));
            }
        }
        assert!(shared > 5, "{shared} trains entered an occupied line");
        assert_replayed_truth(&out);
    }

    /// Replays `path` as its line with `opts`.
    fn run_with(path: &Path, opts: EngineOptions) -> (Recorder, String, f64) {
        let reader = RecordingReader::open(path, ReaderContext::default()).unwrap();
        let mut engine = Engine::on_line(
            reader.section().clone(),
            reader.line().cloned(),
            ModelConfig::default(),
            opts,
            reader.origin_ns(),
        );
        let mut rec = Recorder::default();
        for event in reader {
            engine.push(event.unwrap(), &mut rec).unwrap();
        }
        let summary = engine.finish(&mut rec, 0).unwrap();
        let state = serde_json::to_string(&engine.state()).unwrap();
        (rec, state, summary.mass_balance.consumed_kg)
    }

    /// Four wheels of a rail at once (the wavefront, each wheel on its
    /// row's bands) are the wheels one at a time, bit for bit, on the
    /// example line: curves of both hands, transitions, a one-rail
    /// applicator, trains both ways and sharing the line. A field snapshot
    /// after every wheel makes the engine roll one wheel at a time.
    #[test]
    fn four_wheels_at_once_are_one_wheel_at_a_time_on_a_line() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("wave.mcap");
        let layout = example();
        let o = run(
            &out,
            &[
                "--layout",
                layout.to_str().unwrap(),
                "--trains-per-day",
                "40",
                "--min-headway-s",
                "30",
                "--measured-train-share",
                "0.5",
                "--seed",
                "9",
            ],
        );
        common::check(&o, "synth --layout");
        let (wave, wave_state, wave_consumed) = run_with(&out, EngineOptions::default());
        let one_at_a_time = EngineOptions {
            snapshot_every_wheel: true,
            ..EngineOptions::default()
        };
        let (serial, serial_state, serial_consumed) = run_with(&out, one_at_a_time);
        assert!(wave.measurements.len() > 10_000);
        let (a, b) = (wave.simulated(), serial.simulated());
        assert_eq!(a.len(), b.len());
        let differ: Vec<usize> = (0..a.len())
            .filter(|&k| a[k].to_bits() != b[k].to_bits())
            .collect();
        assert!(
            differ.is_empty(),
            "{} of {} measurements differ, the first {:?}",
            differ.len(),
            a.len(),
            differ.first().map(|&k| (&wave.measurements[k], b[k]))
        );
        assert_eq!(wave_state, serial_state, "the state after the day");
        assert_eq!(wave_consumed.to_bits(), serial_consumed.to_bits());
    }

    /// A layout the reader would refuse, or one with a key the generator
    /// does not know, is a usage error naming the key; nothing is written.
    #[test]
    fn a_bad_layout_is_refused_naming_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let text = std::fs::read_to_string(example()).unwrap();
        let cases = [
            (
                text.replacen("end_m = 880.0", "end_m = 700.0", 1),
                "segments[1].end_m",
            ),
            (
                text.replacen("radius_m = 400.0", "radius = 400.0", 1),
                "layout1.toml:29:1: unknown field `radius`",
            ),
            (
                text.replacen("rails = [\"right\"]", "rails = [\"high\"]", 1),
                "applicators[1].rails",
            ),
            (
                text.replacen("high_rail = \"left\"", "high_rail = \"north\"", 1),
                "segments[5].high_rail",
            ),
            (
                text.replacen("end_m = 10000.0", "end_m = 1e400", 1),
                "layout4.toml:122:9: floating-point number overflowed",
            ),
            (
                text.replacen("end_m = 10000.0", "end_m = inf", 1),
                "segments[16].end_m = inf",
            ),
            (
                text.replacen("position_m = 9500.0", "position_m = 12000.0", 1),
                "layout6.toml: site M6 position is 12000",
            ),
        ];
        for (i, (layout, names)) in cases.iter().enumerate() {
            let path = dir.path().join(format!("layout{i}.toml"));
            std::fs::write(&path, layout).unwrap();
            let out = dir.path().join(format!("out{i}.mcap"));
            let o = run(&out, &["--layout", path.to_str().unwrap()]);
            let stderr = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "case {i}: {stderr}");
            assert!(
                stderr.contains(names),
                "case {i} should name {names}: {stderr}"
            );
            assert!(!out.exists(), "case {i} wrote {}", out.display());
        }
        let out = dir.path().join("both.mcap");
        let layout = example();
        let o = run(
            &out,
            &["--layout", layout.to_str().unwrap(), "--preset", "tangent"],
        );
        assert_eq!(o.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&o.stderr).contains("--preset"));
        let o = run(
            &out,
            &[
                "--layout",
                layout.to_str().unwrap(),
                "--hidden",
                "rail_ageing:tau_s=7200",
            ],
        );
        assert_eq!(o.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&o.stderr).contains("effects.rail_ageing"));
    }
}

/// The watched axles' view in rerun (issue 45: "mu per rail band along the
/// line ..., the wheel's band masses along the line for a chosen axle"):
/// the engine's [`tortwin_engine::sink::LineWheels`] for axles 4 and 5 of
/// the field line's last train equal the reference's mu (line_field.csv)
/// to 1e-9, `rail_mu` is eq. (4) of the crown's mass after the train, the
/// tread bands carry product; and the command's .rrd
/// (`--line-axle 4`) holds each as a line within 5e-4 of mu (5e-3 decades
/// of mg) with a view per rail in its layout (tests/python/check_rrd.py).
#[test]
fn rerun_shows_a_chosen_axle_along_the_line() {
    use tortwin_engine::sink::{FieldSnapshot, LineWheels};
    #[derive(Default)]
    struct Watch {
        last: Vec<LineWheels<'static>>,
        wheel_pass: u64,
    }
    impl Sink for Watch {
        fn field(&mut self, f: &FieldSnapshot<'_>) -> SinkResult {
            self.wheel_pass = self.wheel_pass.max(f.wheel_pass);
            Ok(())
        }
        fn line_wheels(&mut self, w: &LineWheels<'_>) -> SinkResult {
            if w.rail == 0 {
                self.last.clear();
            }
            let owned = tortwin_engine::sink::Event::LineWheels(w.clone()).into_owned();
            if let tortwin_engine::sink::Event::LineWheels(w) = owned {
                self.last.push(w);
            }
            Ok(())
        }
    }
    let path = recordings().join("line_field.mcap");
    let reader = RecordingReader::open(&path, ReaderContext::default()).unwrap();
    let rails = reader.section().rails.clone();
    let length_m = reader.section().length_m;
    let line = reader.line().unwrap().clone();
    let opts = EngineOptions {
        line_axle: Some(4),
        ..EngineOptions::default()
    };
    let mut watch = Watch::default();
    let mut last = None;
    let engine = replay_engine_with(&path, opts, &mut watch, |event| {
        if let tortwin_recording::EventKind::Passage(p) = &event.kind {
            last = Some((p.direction, p.axles[4].bogie_position));
        }
    });
    assert_eq!(watch.last.len(), 2, "one per rail after the last train");
    let (direction, bogie) = last.unwrap();
    let up = direction == tortwin_recording::Direction::Up;

    let p = ModelConfig::default().product;
    let table = std::fs::read_to_string(common::reference("line_field.csv")).unwrap();
    // Columns: d_m, segment, rows_left, rows_right, then mu_lead_left,
    // mu_trail_left, mu_lead_right, mu_trail_right.
    let rows: Vec<Vec<f64>> = table
        .lines()
        .skip(1)
        .filter(|l| !l.is_empty())
        .map(|l| l.split(',').skip(4).map(|f| f.parse().unwrap()).collect())
        .collect();
    let state = engine.state();
    let mut expected_rails = serde_json::Map::new();
    for w in &watch.last {
        assert_eq!(w.axles, [4, 5]);
        for (k, mu) in w.mu.iter().enumerate() {
            assert_eq!(mu.len(), rows.len());
            for (i, row) in rows.iter().enumerate() {
                let want = row[2 * w.rail + k];
                let rel = relative(mu[i], want);
                assert!(
                    rel <= 1e-9,
                    "axle {} rail {}: {} at {i}, want {want}",
                    w.axles[k],
                    w.rail,
                    mu[i]
                );
            }
        }
        let crown = &state.tracks[2 * w.rail].rail_mass_kg;
        for (i, &m) in crown.iter().enumerate() {
            assert_eq!(w.rail_mu[i], product::friction(&p, m), "rail_mu at {i}");
        }
        // The tread's bands: never negative, and product on them somewhere
        // (the wheels pick it up where the rows let them: line.md's table).
        let [f, c, g] = &w.bands_kg;
        let all = || f.iter().chain(c.iter()).chain(g.iter());
        assert!(all().all(|m| m.is_finite() && *m >= 0.0));
        assert!(
            all().any(|&m| m > 0.0),
            "axle 4 carries product on rail {}",
            w.rail
        );
        // A band changes only at a point whose row puts it in contact
        // (after the contact at each point, in the direction of travel).
        let d = &engine.grid().d_m;
        for (b, band) in w.bands_kg.iter().enumerate() {
            for i in 1..d.len() {
                let (before, at) = if up { (i - 1, i) } else { (i, i - 1) };
                let row = tortwin_engine::rows::row(&line, w.rail, bogie, d[at]);
                if band[at] != band[before] {
                    assert_eq!(
                        row.wheel as usize, b,
                        "rail {} band {b} changed at {at}",
                        w.rail
                    );
                }
            }
        }
        let mg = |v: &[f64]| v.iter().map(|m| m * 1e6).collect::<Vec<_>>();
        expected_rails.insert(
            rails[w.rail].clone(),
            serde_json::json!({
                "axle": w.mu[0], "next_axle": w.mu[1], "rail_mu": w.rail_mu,
                "F": mg(f), "C": mg(c), "G": mg(g),
            }),
        );
    }

    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("line.rrd");
    let args = ReplayArgs {
        out_rrd: Some(rrd.clone()),
        line_axle: 4,
        ..ReplayArgs::new(&path)
    };
    replay(&args, None, &mut [], &tortwin_study::Silent).unwrap();
    let expected = serde_json::json!({
        "blueprint": true,
        "line_wheels": {
            "wheel_pass": watch.wheel_pass,
            "length_m": length_m,
            "d_m": engine.grid().d_m,
            "rails": expected_rails,
        },
    });
    let expected_path = dir.path().join("expected.json");
    std::fs::write(&expected_path, expected.to_string()).unwrap();
    let output = common::python("check_rrd.py", &[&rrd, &expected_path]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "check_rrd.py failed:\n{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    println!("{stdout}");
}
