//! The MCAP output sink: a synthetic stream written, read back with the mcap
//! crate and validated against the channels' JSON Schemas by the independent
//! Python checker (tests/python/check_mcap.py, which needs
//! `pip install mcap jsonschema`; a missing package fails the test).

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;
use tortwin_engine::sink::{
    FieldSnapshot, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink, SnapshotKind,
    TrackInfo, TrainEvent,
};
use tortwin_jobs::replay::{replay, ReplayArgs};
use tortwin_outputs::mcap_out::{McapCompression, McapSink, NonFiniteValue};
use tortwin_recording::{Applicator, Direction, Quantity, Section, Site};

const ORIGIN_NS: u64 = 1_700_000_000_000_000_000;
const TRAIN_NS: u64 = ORIGIN_NS + 60_000_000_000;
const TRAIN_END_NS: u64 = TRAIN_NS + 95_500_000_000;
const ALL_TOPICS: [&str; 7] = [
    "/twin/section",
    "/twin/train",
    "/twin/pulse",
    "/twin/measurement",
    "/twin/field",
    "/foxglove/track",
    "/foxglove/log",
];

fn section() -> Section {
    Section {
        section_id: "curve-417".to_owned(),
        length_m: 30.0,
        rails: vec!["high".to_owned(), "low".to_owned()],
        curve_radius_m: Some(400.0),
        rail_head_radius_m: 0.30,
        nominal_wheel_diameter_m: 0.92,
        applicators: vec![Applicator {
            id: "A1".to_owned(),
            position_m: 5.9,
            rails: vec![0, 1],
            nominal_pulse_kg: 1e-4,
        }],
        sites: vec![Site {
            id: "M1".to_owned(),
            position_m: 20.0,
        }],
    }
}

fn grid_d_m() -> Vec<f64> {
    let c_m = std::f64::consts::PI * 0.92;
    (0..=10).map(|i| i as f64 * c_m).collect()
}

fn tracks() -> Vec<TrackInfo> {
    vec![
        TrackInfo {
            rail: 0,
            rail_name: "high".to_owned(),
            band: "top".to_owned(),
        },
        TrackInfo {
            rail: 1,
            rail_name: "low".to_owned(),
            band: "top".to_owned(),
        },
    ]
}

fn measurement(
    log_time_ns: u64,
    quantity: Quantity,
    axle_index: Option<usize>,
    measured: f64,
    simulated: f64,
) -> MeasurementOutput {
    MeasurementOutput {
        log_time_ns,
        index_in_file: log_time_ns % 1000,
        site_id: "M1".into(),
        site: 0,
        rail_name: "high".into(),
        rail: 0,
        quantity,
        train_id: axle_index.map(|_| "F-1234".into()),
        axle_index,
        measured,
        simulated,
        readout: None,
    }
}

/// Field arrays of the synthetic snapshots, per track (0 or 1).
struct Field {
    mu: Vec<f64>,
    adhesion: Vec<f64>,
    rail_mass_kg: Vec<f64>,
    wheel_mass_kg: Vec<f64>,
}

fn field_values(track: usize) -> Field {
    let n = grid_d_m().len();
    let offset = track as f64 * 0.01;
    Field {
        mu: (0..n).map(|i| 0.3 + offset + i as f64 * 1e-3).collect(),
        adhesion: (0..n).map(|i| 0.2 + offset + i as f64 * 1e-3).collect(),
        // 2.5 mg and 1.25 mg: exact in binary after the kg -> mg scaling.
        rail_mass_kg: (0..n).map(|i| if i == 2 { 2.5e-6 } else { 0.0 }).collect(),
        wheel_mass_kg: (0..n).map(|i| if i >= 2 { 1.25e-6 } else { 0.0 }).collect(),
    }
}

fn snapshot<'a>(
    kind: SnapshotKind,
    log_time_ns: u64,
    track: usize,
    d_m: &'a [f64],
    field: &'a Field,
) -> FieldSnapshot<'a> {
    FieldSnapshot {
        kind,
        log_time_ns,
        train_id: "F-1234".into(),
        track,
        rail_name: (["high", "low"][track]).into(),
        band: "top".into(),
        wheel_pass: 24,
        d_m: d_m.into(),
        mu: (&field.mu).into(),
        adhesion: (&field.adhesion).into(),
        rail_mass_kg: (&field.rail_mass_kg).into(),
        wheel_mass_kg: (&field.wheel_mass_kg).into(),
    }
}

/// The synthetic run: begin, two pulses, a train, three measurements (one
/// `rail_mu`), two train snapshots and a wheel snapshot.
fn write_synthetic(sink: &mut McapSink) -> tortwin_engine::sink::SinkResult {
    let section = section();
    let grid = grid_d_m();
    let tracks = tracks();
    sink.begin(&SectionInfo {
        section: std::borrow::Cow::Borrowed(&section),
        grid_d_m: (&grid).into(),
        tracks: (&tracks).into(),
        applicator_points: (&[2][..]).into(),
        site_points: (&[7][..]).into(),
        origin_ns: ORIGIN_NS as i64,
        line: None,
    })?;
    for (k, rail_name) in ["high", "low"].into_iter().enumerate() {
        sink.pulse(&PulseEvent {
            log_time_ns: ORIGIN_NS + 1_000 + k as u64,
            applicator: 0,
            applicator_id: "A1".into(),
            rail: k,
            rail_name: rail_name.into(),
            mass_kg: 1e-4,
        })?;
    }
    sink.train(&TrainEvent {
        log_time_ns: TRAIN_NS,
        end_ns: TRAIN_END_NS,
        train_id: "F-1234".into(),
        direction: Direction::Down,
        speed_mps: 18.0,
        axles: 12,
    })?;
    sink.measurement(&measurement(
        TRAIN_NS + 10_000_000_001,
        Quantity::Mu,
        Some(7),
        0.312,
        0.1 + 0.2,
    ))?;
    sink.measurement(&measurement(
        TRAIN_NS + 10_000_000_002,
        Quantity::Adhesion,
        Some(11),
        0.21,
        1.0 / 3.0,
    ))?;
    let (d0, d1) = (field_values(0), field_values(1));
    sink.field(&snapshot(SnapshotKind::Wheel, TRAIN_NS + 1, 0, &grid, &d0))?;
    sink.field(&snapshot(SnapshotKind::Train, TRAIN_END_NS, 0, &grid, &d0))?;
    sink.field(&snapshot(SnapshotKind::Train, TRAIN_END_NS, 1, &grid, &d1))?;
    sink.measurement(&measurement(
        TRAIN_END_NS + 3_600_000_000_000,
        Quantity::RailMu,
        None,
        0.35,
        std::f64::consts::FRAC_1_PI,
    ))?;
    Ok(())
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Runs tests/python/check_mcap.py; fails (never skips) without python3 or
/// its packages.
fn run_checker(path: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![path.as_os_str()];
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    let output = common::python("check_mcap.py", &args);
    assert_ne!(
        output.status.code(),
        Some(3),
        "check_mcap.py lacks a Python package: run `pip install mcap jsonschema`\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

#[test]
fn writes_every_topic_and_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("twin.mcap");
    let mut sink = McapSink::create(&path, None, McapCompression::Small).unwrap();
    write_synthetic(&mut sink).unwrap();
    assert!(!path.exists(), "nothing under the final name before finish");
    sink.finish(&RunSummary::default()).unwrap();
    drop(sink);
    assert_eq!(
        files_in(dir.path()),
        ["twin.mcap"],
        "no temporary file left"
    );

    let bytes = std::fs::read(&path).unwrap();

    // (a) Read back with the mcap crate.
    let mut by_topic: BTreeMap<String, Vec<(u64, Value)>> = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        assert_eq!(message.publish_time, message.log_time);
        assert_eq!(message.channel.message_encoding, "json");
        let schema = message
            .channel
            .schema
            .as_ref()
            .expect("every channel has a schema");
        assert_eq!(schema.encoding, "jsonschema");
        let name = schema.name.clone();
        let schema: Value = serde_json::from_slice(&schema.data).unwrap();
        if name.starts_with("foxglove.") {
            // Foxglove's own schema, as its npm package has it.
            assert_eq!(schema["title"], name.as_str());
        } else {
            assert_eq!(
                schema["$schema"],
                "https://json-schema.org/draft/2020-12/schema"
            );
        }
        let value: Value = serde_json::from_slice(&message.data).unwrap();
        by_topic
            .entry(message.channel.topic.clone())
            .or_default()
            .push((message.log_time, value));
    }
    let counts: BTreeMap<&str, usize> = by_topic
        .iter()
        .map(|(t, m)| (t.as_str(), m.len()))
        .collect();
    assert_eq!(
        counts,
        BTreeMap::from([
            // A train, a pulse line per applicator and rail.
            ("/foxglove/log", 3),
            // One scene once both tracks' snapshots are in.
            ("/foxglove/track", 1),
            ("/twin/field", 2),
            ("/twin/measurement", 3),
            ("/twin/pulse", 2),
            ("/twin/section", 1),
            ("/twin/train", 1),
        ])
    );

    let (t, section) = &by_topic["/twin/section"][0];
    assert_eq!(*t, ORIGIN_NS);
    assert_eq!(section["section_id"], "curve-417");
    assert_eq!(section["grid_d_m"].as_array().unwrap().len(), 11);
    assert_eq!(section["grid_d_m"][3].as_f64(), Some(grid_d_m()[3]));
    assert_eq!(section["applicators"][0]["grid_index"], 2);
    assert_eq!(
        section["applicators"][0]["rails"],
        serde_json::json!(["high", "low"])
    );
    assert_eq!(section["sites"][0]["grid_index"], 7);
    assert_eq!(section["tracks"][1]["rail"], "low");

    let (t, train) = &by_topic["/twin/train"][0];
    assert_eq!(*t, TRAIN_NS);
    assert_eq!(train["direction"], "down");
    assert_eq!(train["axles"], 12);
    assert_eq!(train["end_time_ns"].as_u64(), Some(TRAIN_END_NS));
    assert_eq!(train["duration_s"].as_f64(), Some(95.5));

    // The pulses before the train, written with its snapshot.
    let pulses = &by_topic["/twin/pulse"];
    assert_eq!(pulses[1].0, TRAIN_END_NS);
    assert_eq!(pulses[1].1["rail"], "low");
    assert_eq!(pulses[1].1["pulses"], 1);
    assert_eq!(
        pulses[1].1["first_time_ns"].as_u64(),
        Some(ORIGIN_NS + 1_001)
    );
    assert_eq!(
        pulses[1].1["last_time_ns"].as_u64(),
        Some(ORIGIN_NS + 1_001)
    );
    // 1e-4 kg is 0.1 g, to the last bit of the g -> kg -> g round trip.
    assert!((pulses[1].1["mass_g"].as_f64().unwrap() - 0.1).abs() <= 1e-16);

    let measurements = &by_topic["/twin/measurement"];
    let times: Vec<u64> = measurements.iter().map(|(t, _)| *t).collect();
    assert_eq!(
        times,
        [
            TRAIN_NS + 10_000_000_001,
            TRAIN_NS + 10_000_000_002,
            TRAIN_END_NS + 3_600_000_000_000
        ]
    );
    let mu = &measurements[0].1;
    assert_eq!(mu["quantity"], "mu");
    assert_eq!(mu["train_id"], "F-1234");
    assert_eq!(mu["axle_index"], 7);
    // Floats round-trip to the bit.
    assert_eq!(
        mu["measured"].as_f64().unwrap().to_bits(),
        0.312f64.to_bits()
    );
    assert_eq!(
        mu["simulated"].as_f64().unwrap().to_bits(),
        (0.1f64 + 0.2).to_bits()
    );
    assert_eq!(
        measurements[1].1["simulated"].as_f64().unwrap().to_bits(),
        (1.0f64 / 3.0).to_bits()
    );
    let rail_mu = measurements[2].1.as_object().unwrap();
    assert_eq!(rail_mu["quantity"], "rail_mu");
    assert!(!rail_mu.contains_key("train_id"));
    assert!(!rail_mu.contains_key("axle_index"));

    let fields = &by_topic["/twin/field"];
    assert!(
        fields.iter().all(|(t, _)| *t == TRAIN_END_NS),
        "wheel snapshot ignored"
    );
    let (high, low) = (&fields[0].1, &fields[1].1);
    assert_eq!(high["rail"], "high");
    assert_eq!(low["rail"], "low");
    assert_eq!(high["band"], "top");
    assert_eq!(high["wheel_pass"], 24);
    // mu to 1e-4: the double nearest the 4-decimal value, printed short.
    let mu = field_values(1).mu[4];
    assert_eq!(low["mu"][4].as_f64(), Some((mu * 1e4).round() / 1e4));
    assert_eq!(low["mu"][4].to_string(), "0.314");
    assert_eq!(high["rail_mass_mg"][2].as_f64(), Some(2.5));
    assert_eq!(high["rail_mass_mg"][3].as_f64(), Some(0.0));
    assert_eq!(high["wheel_mass_mg"][5].as_f64(), Some(1.25));
    // No distances: they are /twin/section's grid_d_m.
    assert!(high.get("d_m").is_none());
    for key in ["mu", "adhesion", "rail_mass_mg", "wheel_mass_mg"] {
        assert_eq!(high[key].as_array().unwrap().len(), 11, "{key}");
    }

    // The Foxglove scene: both tracks' lines, a colour per grid point, and
    // the labels.
    let (t, scene) = &by_topic["/foxglove/track"][0];
    assert_eq!(*t, TRAIN_END_NS);
    let entities = scene["entities"].as_array().unwrap();
    let ids: Vec<&str> = entities.iter().map(|e| e["id"].as_str().unwrap()).collect();
    assert_eq!(ids, ["track/high/top", "track/low/top", "labels"]);
    // The low rail: a colour per point, the points where mu's class
    // changes (its mu rises from 0.31 by 0.001 a point) and the ends.
    let line = &entities[1]["lines"][0];
    let points = line["points"].as_array().unwrap();
    let colors = line["colors"].as_array().unwrap();
    assert_eq!(points.len(), colors.len());
    assert!((2..11).contains(&points.len()), "{}", points.len());
    // d = 0 on the inner rail of a 30 m curve: offset -g/2, g = 2 m.
    assert_eq!(points[0]["x"].as_f64(), Some(0.0));
    assert_eq!(points[0]["y"].as_f64(), Some(-1.0));
    // mu 0.31 is in the band: green.
    let (r, g, b) = (
        colors[0]["r"].as_f64().unwrap(),
        colors[0]["g"].as_f64().unwrap(),
        colors[0]["b"].as_f64().unwrap(),
    );
    assert!(g > r && g > b, "{r} {g} {b}");
    let texts: Vec<&str> = entities[2]["texts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["text"].as_str().unwrap())
        .collect();
    assert!(
        texts.contains(&"A1 (6 m)") && texts.contains(&"site M1 (20 m)"),
        "{texts:?}"
    );
    let logs: Vec<(&str, &str)> = by_topic["/foxglove/log"]
        .iter()
        .map(|(_, l)| (l["name"].as_str().unwrap(), l["message"].as_str().unwrap()))
        .collect();
    assert_eq!(
        logs[0],
        ("trains", "train F-1234 down, 18.0 m/s (65 km/h), 12 axles")
    );
    assert_eq!(logs[1], ("A1", "1 pulse, 0.100 g in all, on the high rail"));

    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    assert_eq!(summary.stats.as_ref().unwrap().message_count, 13);
    // /twin/alert is declared though this run raised none.
    assert_eq!(summary.channels.len(), 8);
    assert!(!summary.chunk_indexes.is_empty());
    assert!(summary
        .chunk_indexes
        .iter()
        .all(|c| c.compression == "zstd"));
    assert_eq!(summary.metadata_indexes.len(), 1);
    let metadata = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).unwrap();
    assert_eq!(metadata.name, "tortwin");
    assert_eq!(metadata.metadata["version"], env!("CARGO_PKG_VERSION"));

    // (b) The independent checker: every message against its schema.
    let mut args = vec!["--expect-topics"];
    args.extend(ALL_TOPICS);
    args.extend(["--expect-count", "/twin/field=2"]);
    args.extend(["--expect-count", "/twin/measurement=3"]);
    let output = run_checker(&path, &args);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "check_mcap.py failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(stdout.contains("/twin/measurement\t3"), "{stdout}");
}

#[test]
fn checker_rejects_messages_that_break_their_schema() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut writer = mcap::Writer::new(file).unwrap();
        let schema = br#"{"$schema": "https://json-schema.org/draft/2020-12/schema",
            "type": "object", "required": ["measured"],
            "properties": {"measured": {"type": "number"}}}"#;
        let schema_id = writer.add_schema("bad", "jsonschema", schema).unwrap();
        let channel = writer
            .add_channel(schema_id, "/twin/measurement", "json", &BTreeMap::new())
            .unwrap();
        for (sequence, data) in [
            &br#"{"measured": 0.3}"#[..],
            br#"{"measured": "0.3"}"#,
            br#"{"simulated": 0.3}"#,
            br#"{"measured": NaN}"#,
        ]
        .into_iter()
        .enumerate()
        {
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: sequence as u32,
                log_time: 1,
                publish_time: 1,
            };
            writer.write_to_known_channel(&header, data).unwrap();
        }
        writer.finish().unwrap();
    }
    let output = run_checker(&path, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert_eq!(
        stderr.matches("FAIL /twin/measurement").count(),
        3,
        "{stderr}"
    );

    let output = run_checker(&path, &["--expect-topics", "/twin/field"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("FAIL /twin/field"), "{stderr}");
}

/// The two compressions write the same messages; `Small` in fewer bytes.
/// The messages are a real replay's (the bundled demo day into two sinks at
/// once): how much a level gains depends on the data (on 20 000 synthetic
/// measurements alone, level 1 wrote fewer bytes than level 8).
#[test]
fn compressions_write_the_same_messages_in_different_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let recording = Path::new(env!("CARGO_MANIFEST_DIR")).join("recordings/demo_day.mcap");
    let fast_path = dir.path().join("fast.mcap");
    let small_path = dir.path().join("small.mcap");
    let mut fast = McapSink::create(&fast_path, None, McapCompression::Fast).unwrap();
    let mut small = McapSink::create(&small_path, None, McapCompression::Small).unwrap();
    replay(
        &ReplayArgs::new(recording),
        None,
        &mut [&mut fast, &mut small],
        &tortwin_study::Silent,
    )
    .unwrap();
    drop((fast, small));
    let (fast, small) = (
        std::fs::read(&fast_path).unwrap(),
        std::fs::read(&small_path).unwrap(),
    );
    let messages = |bytes: &[u8]| -> Vec<(String, u64, Vec<u8>)> {
        mcap::MessageStream::new(bytes)
            .unwrap()
            .map(|m| {
                let m = m.unwrap();
                (m.channel.topic.clone(), m.log_time, m.data.into_owned())
            })
            .collect()
    };
    let (fast_messages, small_messages) = (messages(&fast), messages(&small));
    assert!(fast_messages.len() > 6_000, "{}", fast_messages.len());
    assert!(fast_messages == small_messages, "the same messages");
    assert!(
        small.len() < fast.len() * 9 / 10,
        "level 8 ({} bytes) is at least a tenth smaller than level 1 ({} bytes)",
        small.len(),
        fast.len()
    );
    assert_eq!(
        McapCompression::for_recording(McapCompression::SMALL_FROM_MESSAGES - 1),
        McapCompression::Fast
    );
    assert_eq!(
        McapCompression::for_recording(McapCompression::SMALL_FROM_MESSAGES),
        McapCompression::Small
    );
}

#[test]
fn dropped_sink_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("twin.mcap");
    let mut sink = McapSink::create(&path, None, McapCompression::Small).unwrap();
    write_synthetic(&mut sink).unwrap();
    assert_eq!(files_in(dir.path()).len(), 1, "the temporary file exists");
    drop(sink);
    assert!(!path.exists());
    assert!(
        files_in(dir.path()).is_empty(),
        "{:?}",
        files_in(dir.path())
    );
}

#[test]
fn non_finite_values_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("twin.mcap");
    let mut sink = McapSink::create(&path, None, McapCompression::Small).unwrap();
    write_synthetic(&mut sink).unwrap();

    let err = sink
        .measurement(&measurement(
            ORIGIN_NS + 5,
            Quantity::Mu,
            Some(1),
            0.3,
            f64::NAN,
        ))
        .unwrap_err();
    let non_finite = err
        .downcast_ref::<NonFiniteValue>()
        .expect("a NonFiniteValue");
    assert_eq!(non_finite.topic, "/twin/measurement");
    assert_eq!(non_finite.field, "simulated");
    assert_eq!(non_finite.log_time_ns, ORIGIN_NS + 5);

    let grid = grid_d_m();
    let mut field = field_values(0);
    field.wheel_mass_kg[4] = f64::INFINITY;
    let err = sink
        .field(&snapshot(
            SnapshotKind::Train,
            TRAIN_END_NS,
            0,
            &grid,
            &field,
        ))
        .unwrap_err();
    let non_finite = err
        .downcast_ref::<NonFiniteValue>()
        .expect("a NonFiniteValue");
    assert_eq!(non_finite.field, "wheel_mass_mg");

    // The engine stops at the first error: the sink is dropped unfinished.
    drop(sink);
    assert!(files_in(dir.path()).is_empty());
}
