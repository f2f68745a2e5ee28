//! The recording reader against docs/spec/recording-format.md: the
//! reference recordings (counts and measurement order from their key and
//! expected files), the replay order over chunk layouts, and one test per
//! class of bad input.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// this file's helpers are test code too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use std::path::Path;

use proptest::prelude::*;
use serde_json::{json, Value};
use tortwin_recording::error::InputError;
use tortwin_recording::reader::{ReaderContext, RecordingReader};
use tortwin_recording::{BogiePosition, Direction, Event, EventKind, Quantity};

// Shared with the workspace's tests (tests/common), which use all of it.
#[path = "support/recording.rs"]
#[allow(dead_code, unreachable_pub)]
mod recording;
use recording::{axle, msg, section, write_recording, Layout, Msg, LAYOUTS};

/// `tests/reference/recordings/NAME` at the workspace's root: recordings
/// of the independent implementation (tests/reference/README.md).
fn reference_recording(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/reference/recordings")
        .join(name)
}

const T0: u64 = 1_712_534_400_000_000_000;
const SEC: u64 = 1_000_000_000;

/// A valid recording; the comment gives each message's index in the file.
/// F-1 (20 m/s, last axle at 2.5 m) occupies the section from 10 s to
/// 10 + 602.5 / 20 = 40.125 s.
fn base() -> Vec<Msg> {
    vec![
        // 0
        msg("/section", T0, section()),
        // 1
        msg(
            "/environment/weather",
            T0 + SEC,
            json!({"air_temperature_c": 14.5, "relative_humidity": 0.71, "precipitation_mm_h": 0.0}),
        ),
        // 2
        msg(
            "/train/passage",
            T0 + 10 * SEC,
            json!({"train_id": "F-1", "direction": "up", "speed_mps": 20.0,
                   "axles": [axle(0.0, "leading"), axle(2.5, "trailing")]}),
        ),
        // 3
        msg(
            "/applicator/pulse",
            T0 + 5 * SEC,
            json!({"applicator_id": "A1", "rail": "left", "mass_g": 0.1}),
        ),
        // 4
        msg(
            "/measurement/friction",
            T0 + 13 * SEC,
            json!({"site_id": "M1", "rail": "right", "quantity": "mu",
                   "train_id": "F-1", "axle_index": 1, "value": 0.312}),
        ),
        // 5
        msg(
            "/measurement/friction",
            T0 + 50 * SEC,
            json!({"site_id": "M2", "rail": "left", "quantity": "rail_mu", "value": 0.35}),
        ),
        // 6
        msg("/diagnostics/heartbeat", T0 + 2 * SEC, json!({"ok": true})),
        // 7
        msg(
            "/train/passage",
            T0 + 100 * SEC,
            json!({"train_id": "F-2", "direction": "down", "speed_mps": 25.0,
                   "axles": [axle(0.0, "leading")]}),
        ),
        // 8
        msg(
            "/measurement/friction",
            T0 + 101 * SEC,
            json!({"site_id": "M2", "rail": "left", "quantity": "adhesion",
                   "train_id": "F-2", "axle_index": 0, "value": 0.21}),
        ),
    ]
}

/// `msgs` with message `i`'s JSON changed by `f`.
fn with(mut msgs: Vec<Msg>, i: usize, f: impl FnOnce(&mut Value)) -> Vec<Msg> {
    let mut value: Value = serde_json::from_slice(&msgs[i].data).unwrap();
    f(&mut value);
    msgs[i].data = serde_json::to_vec(&value).unwrap();
    msgs
}

fn with_raw(mut msgs: Vec<Msg>, i: usize, text: &str) -> Vec<Msg> {
    msgs[i].data = text.as_bytes().to_vec();
    msgs
}

fn with_time(mut msgs: Vec<Msg>, i: usize, log_time: u64) -> Vec<Msg> {
    msgs[i].log_time = log_time;
    msgs
}

fn remove(value: &mut Value, pointer: &str, key: &str) {
    value
        .pointer_mut(pointer)
        .unwrap()
        .as_object_mut()
        .unwrap()
        .remove(key)
        .unwrap();
}

/// Reads `path` whole with [`RecordingReader::open`], and again with
/// [`RecordingReader::open_beside`] (the layout pass beside the replay),
/// which must end the same way: the same events if the file is sound, the
/// same error if not (before it, a reader beside the pass may have given
/// events that one laid out first never gives).
fn read_all(path: &Path, ctx: ReaderContext) -> Result<(RecordingReader, Vec<Event>), InputError> {
    let (laid, laid_items) = read_items(path, ctx, RecordingReader::open);
    let (beside, beside_items) = read_items(path, ctx, RecordingReader::open_beside);
    match laid {
        Some(_) => assert_eq!(laid_items, beside_items, "{path:?}: beside the layout pass"),
        None => assert_eq!(
            laid_items.last(),
            beside_items.last(),
            "{path:?}: beside the layout pass"
        ),
    }
    let mut events = Vec::new();
    for item in laid_items {
        events.push(item?);
    }
    let (Some(laid), Some(beside)) = (laid, beside) else {
        unreachable!("a reader that did not open gave its error above")
    };
    assert_eq!(laid.layout(), beside.layout(), "{path:?}: the layout");
    assert_eq!(laid.message_count(), beside.message_count());
    Ok((laid, events))
}

/// The reader `open` gives for `path` and everything it reads (an error
/// ends it), or no reader and the error it opened with.
fn read_items(
    path: &Path,
    ctx: ReaderContext,
    open: fn(&Path, ReaderContext) -> Result<RecordingReader, InputError>,
) -> (Option<RecordingReader>, Vec<Result<Event, InputError>>) {
    match open(path, ctx) {
        Ok(mut reader) => {
            let items = reader.by_ref().collect();
            assert!(reader.next().is_none(), "{path:?}: more after the end");
            (Some(reader), items)
        }
        Err(e) => (None, vec![Err(e)]),
    }
}

/// Why `path` is refused, read both ways ([`read_all`]).
fn refused(path: &Path) -> InputError {
    match read_all(path, ReaderContext::default()) {
        Ok((_, events)) => panic!(
            "expected {path:?} to be refused, read {} events",
            events.len()
        ),
        Err(e) => e,
    }
}

fn read_msgs(msgs: &[Msg], layout: Layout) -> Result<(RecordingReader, Vec<Event>), InputError> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("recording.mcap");
    write_recording(&path, msgs, layout);
    read_all(&path, ReaderContext::default())
}

/// Writes `msgs` in every layout and checks that reading fails at message
/// `index` (topic, log_time and index named) with a message containing
/// every one of `needles`.
fn expect_error(msgs: &[Msg], index: usize, needles: &[&str]) {
    for layout in LAYOUTS {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.mcap");
        write_recording(&path, msgs, layout);
        let err = match read_all(&path, ReaderContext::default()) {
            Ok((_, events)) => panic!("{layout:?}: expected an error, read {events:?}"),
            Err(err) => err,
        };
        assert_eq!(err.file, path, "{layout:?}: {err}");
        let location = err
            .location
            .as_ref()
            .unwrap_or_else(|| panic!("{layout:?}: no location in `{err}`"));
        assert_eq!(location.index_in_file, index as u64, "{layout:?}: {err}");
        assert_eq!(location.topic, msgs[index].topic, "{layout:?}: {err}");
        assert_eq!(
            location.log_time_ns, msgs[index].log_time,
            "{layout:?}: {err}"
        );
        for needle in needles {
            assert!(
                err.message.contains(needle),
                "{layout:?}: `{}` does not contain `{needle}`",
                err.message
            );
        }
        let shown = err.to_string();
        assert!(shown.contains("bad.mcap") && shown.contains(&msgs[index].topic));
    }
}

/// An error without a message location (the file as a whole is bad).
fn expect_file_error(path: &Path, needles: &[&str]) {
    let err = refused(path);
    assert_eq!(err.file, path, "{err}");
    assert_eq!(err.location, None, "{err}");
    for needle in needles {
        assert!(
            err.message.to_lowercase().contains(needle),
            "`{}` does not contain `{needle}`",
            err.message
        );
    }
}

// ---------------------------------------------------------------------------
// Valid recordings.

#[test]
fn base_recording_replays_in_order_with_si_units_in_every_layout() {
    for layout in LAYOUTS {
        let (reader, events) = read_msgs(&base(), layout).unwrap();
        let section = reader.section();
        assert_eq!(section.section_id, "test-600");
        assert_eq!(section.rails, ["left", "right"]);
        assert_eq!(section.curve_radius_m, None);
        assert_eq!(section.applicators[0].rails, [0, 1]);
        assert_eq!(section.applicators[0].nominal_pulse_kg, 0.2 * 1e-3);
        assert_eq!(section.sites[1].id, "M2");
        assert_eq!(reader.section_log_time_ns(), T0);
        assert_eq!(reader.origin_ns(), T0 as i64);
        assert_eq!(reader.unknown_topic_messages(), 1);
        // F-2 enters at 100 s with one axle at 0 m, 25 m/s.
        assert_eq!(reader.occupied_until_s(), 100.0 + 600.0 / 25.0);

        let order: Vec<(u64, u64)> = events
            .iter()
            .map(|e| (e.index_in_file, (e.log_time_ns - T0) / SEC))
            .collect();
        assert_eq!(
            order,
            [
                (1, 1),
                (3, 5),
                (2, 10),
                (4, 13),
                (5, 50),
                (7, 100),
                (8, 101)
            ],
            "{layout:?}"
        );

        let EventKind::Pulse(pulse) = &events[1].kind else {
            panic!("{:?}", events[1])
        };
        assert_eq!((pulse.applicator, pulse.rail), (0, 0));
        assert_eq!(pulse.mass_kg, 0.1 * 1e-3);

        let EventKind::Passage(f1) = &events[2].kind else {
            panic!("{:?}", events[2])
        };
        assert_eq!((f1.train_id.as_str(), f1.train_seq), ("F-1", 0));
        assert_eq!(f1.direction, Direction::Up);
        assert_eq!(f1.axles.len(), 2);
        assert_eq!(f1.axles[1].offset_m, 2.5);
        assert_eq!(f1.axles[1].bogie_position, BogiePosition::Trailing);
        assert_eq!(f1.axles[0].wheel_load_n, [100.0 * 1e3, 98.0 * 1e3]);
        assert_eq!(f1.axles[0].creepage[1].cy, 0.002);
        assert_eq!(f1.axles[0].creepage[1].spin_per_m, -0.1);

        let EventKind::Measurement(mu) = &events[3].kind else {
            panic!("{:?}", events[3])
        };
        assert_eq!((mu.site, mu.rail, mu.quantity()), (0, 1, Quantity::Mu));
        let axle = mu.axle().unwrap();
        assert_eq!(
            (&*axle.train_id, axle.train_seq, axle.axle_index),
            ("F-1", 0, 1)
        );
        assert_eq!(mu.value, 0.312);

        let EventKind::Measurement(rail_mu) = &events[4].kind else {
            panic!("{:?}", events[4])
        };
        assert_eq!(
            (rail_mu.quantity(), rail_mu.axle().is_none()),
            (Quantity::RailMu, true)
        );

        let EventKind::Passage(f2) = &events[5].kind else {
            panic!("{:?}", events[5])
        };
        assert_eq!((f2.train_seq, f2.direction), (1, Direction::Down));
        let EventKind::Measurement(adhesion) = &events[6].kind else {
            panic!("{:?}", events[6])
        };
        assert_eq!(adhesion.quantity(), Quantity::Adhesion);
        assert_eq!(adhesion.axle().unwrap().train_seq, 1);

        let EventKind::Weather(weather) = &events[0].kind else {
            panic!("{:?}", events[0])
        };
        assert_eq!(weather.relative_humidity, 0.71);
    }
}

/// recording-format.md: `curve_radius_m` may be absent on tangent track
/// (readers accept it absent and `null`); a number is a curve.
#[test]
fn curve_radius_may_be_absent_null_or_a_number() {
    let absent = with(base(), 0, |v| remove(v, "", "curve_radius_m"));
    let curve = with(base(), 0, |v| v["curve_radius_m"] = json!(400.0));
    for layout in LAYOUTS {
        let (reader, events) = read_msgs(&absent, layout).unwrap();
        assert_eq!(reader.section().curve_radius_m, None, "{layout:?}");
        assert_eq!(events.len(), read_msgs(&base(), layout).unwrap().1.len());
        let (reader, _) = read_msgs(&curve, layout).unwrap();
        assert_eq!(reader.section().curve_radius_m, Some(400.0), "{layout:?}");
    }
}

#[test]
fn an_lz4_chunk_reads_as_a_zstd_one() {
    let (_, zstd) = read_msgs(&base(), Layout::OneChunk).unwrap();
    let (_, lz4) = read_msgs(&base(), Layout::OneLz4Chunk).unwrap();
    assert_eq!(lz4, zstd);
}

#[test]
fn ties_go_by_topic_then_file_order() {
    let t = T0 + 5 * SEC;
    let msgs = vec![
        msg("/section", T0, section()),
        msg(
            "/environment/weather",
            t,
            json!({"air_temperature_c": 3.0, "relative_humidity": 0.9, "precipitation_mm_h": 1.0}),
        ),
        msg(
            "/applicator/pulse",
            t,
            json!({"applicator_id": "A1", "rail": "right", "mass_g": 0.1}),
        ),
        msg(
            "/measurement/friction",
            t,
            json!({"site_id": "M1", "rail": "left", "quantity": "rail_mu", "value": 0.3}),
        ),
        msg(
            "/applicator/pulse",
            t,
            json!({"applicator_id": "A1", "rail": "left", "mass_g": 0.1}),
        ),
        msg(
            "/train/passage",
            t,
            json!({"train_id": "F-1", "direction": "up", "speed_mps": 20.0,
                   "axles": [axle(0.0, "leading")]}),
        ),
        msg("/x/unknown", t, json!({})),
    ];
    for layout in LAYOUTS {
        let (reader, events) = read_msgs(&msgs, layout).unwrap();
        let indices: Vec<u64> = events.iter().map(|e| e.index_in_file).collect();
        assert_eq!(indices, [5, 2, 4, 3, 1], "{layout:?}");
        assert_eq!(reader.unknown_topic_messages(), 1);
    }
}

#[test]
fn context_carries_origin_and_occupation() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("day2.mcap");
    write_recording(&path, &base(), Layout::OneChunk);
    let origin_ns = (T0 - 86_400 * SEC) as i64;
    let ctx = ReaderContext {
        origin_ns: Some(origin_ns),
        occupied_until_s: 86_400.0 + 10.0,
    };
    let (reader, events) = read_all(&path, ctx).unwrap();
    assert_eq!(reader.origin_ns(), origin_ns);
    assert_eq!(reader.section_log_time_ns(), T0);
    assert_eq!(events.len(), 7);

    // The previous day's last train leaves a moment after F-1 enters.
    let ctx = ReaderContext {
        origin_ns: Some(origin_ns),
        occupied_until_s: 86_400.0 + 10.5,
    };
    let err = read_all(&path, ctx).err().unwrap();
    let location = err.location.unwrap();
    assert_eq!(
        (location.index_in_file, location.topic.as_str()),
        (2, "/train/passage")
    );
    assert!(
        err.message.contains("previous recording"),
        "{}",
        err.message
    );
}

#[test]
fn a_train_may_enter_exactly_when_the_previous_one_has_left() {
    // F-1 leaves at time_s 10 + 602.5 / 20, computed as the reader does.
    let leaves_s = (10 * SEC) as i64 as f64 * 1e-9 + (600.0 + 2.5) / 20.0;
    let mut enter = T0 + 40 * SEC;
    while ((enter - T0) as i64 as f64 * 1e-9) < leaves_s {
        enter += 1;
    }
    let ok = with_time(base(), 7, enter);
    let ok = with_time(ok, 8, enter + SEC);
    assert!(read_msgs(&ok, Layout::OneChunk).is_ok());
    let early = with_time(ok, 7, enter - 1);
    expect_error(&early, 7, &["two trains in the section at once", "`F-1`"]);
}

/// One message of each kind that needs no train, at random times (with many
/// ties), in random chunk layouts: the reader must give them back sorted by
/// (log_time, topic, index in file).
fn shuffled_recording() -> impl Strategy<Value = (Vec<(u64, u8)>, u8)> {
    (proptest::collection::vec((0u64..6, 0u8..4), 1..40), 0u8..3)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn replay_order_is_a_sort_of_the_file(
        (picks, layout) in shuffled_recording()
    ) {
        let mut msgs = vec![msg("/section", T0, section())];
        for (seconds, kind) in &picks {
            let t = T0 + seconds * SEC;
            msgs.push(match kind {
                0 => msg("/applicator/pulse", t,
                         json!({"applicator_id": "A1", "rail": "left", "mass_g": 0.1})),
                1 => msg("/measurement/friction", t,
                         json!({"site_id": "M1", "rail": "left", "quantity": "rail_mu",
                                "value": 0.3})),
                2 => msg("/environment/weather", t,
                         json!({"air_temperature_c": 3.0, "relative_humidity": 0.9,
                                "precipitation_mm_h": 1.0})),
                _ => msg("/x/unknown", t, json!({})),
            });
        }
        let layout = LAYOUTS[layout as usize];
        let (reader, events) = read_msgs(&msgs, layout).unwrap();

        let rank = |topic: &str| match topic {
            "/section" => 0,
            "/train/passage" => 1,
            "/applicator/pulse" => 2,
            "/measurement/friction" => 3,
            "/environment/weather" => 4,
            _ => 5,
        };
        let mut expected: Vec<(u64, u8, u64)> = msgs
            .iter()
            .enumerate()
            .skip(1)
            .filter(|(_, m)| rank(&m.topic) < 5)
            .map(|(i, m)| (m.log_time, rank(&m.topic), i as u64))
            .collect();
        expected.sort();
        let got: Vec<(u64, u64)> = events.iter().map(|e| (e.log_time_ns, e.index_in_file)).collect();
        let want: Vec<(u64, u64)> = expected.iter().map(|&(t, _, i)| (t, i)).collect();
        prop_assert_eq!(got, want);
        let unknown = picks.iter().filter(|(_, kind)| *kind == 3).count() as u64;
        prop_assert_eq!(reader.unknown_topic_messages(), unknown);
        // Unchunked, the reader holds a run per stretch of the file already
        // in replay order: a new run wherever (log_time, topic) goes back.
        if layout == Layout::Unchunked {
            let keys: Vec<(u64, u8)> = msgs.iter().map(|m| (m.log_time, rank(&m.topic))).collect();
            let runs = 1 + keys.windows(2).filter(|w| w[1] < w[0]).count() as u64;
            prop_assert_eq!(reader.layout().loose_runs, runs);
            prop_assert_eq!(reader.layout().loose_messages, msgs.len() as u64);
        }
    }
}

// ---------------------------------------------------------------------------
// Limits (docs/spec/recording-format.md "Limits").

#[test]
fn a_train_of_more_than_ten_thousand_axles_is_refused() {
    let axles: Vec<Value> = (0..10_001)
        .map(|i| axle(i as f64 * 2.5, "leading"))
        .collect();
    let msgs = with(base(), 2, |v| v["axles"] = Value::Array(axles));
    expect_error(&msgs, 2, &["10001 axles; a train may have at most 10000"]);
}

#[test]
fn a_grid_of_more_than_200000_points_is_refused_before_it_is_made() {
    // The smallest wheels (0.1 m, their physical range's edge): 62 km
    // make 197 353 points and pass, 62.9 km make 200 217 and do not.
    // (The messages before the second train, which would enter while the
    // first is still on so long a section.)
    let wheels = |length_m: f64| {
        let mut msgs = with(base(), 0, move |v| {
            v["nominal_wheel_diameter_m"] = json!(0.1);
            v["length_m"] = json!(length_m);
        });
        let second = msgs
            .iter()
            .enumerate()
            .filter(|(_, m)| m.topic == "/train/passage")
            .nth(1)
            .map_or(msgs.len(), |(k, _)| k);
        msgs.truncate(second);
        msgs
    };
    read_msgs(&wheels(62_000.0), Layout::OneChunk).unwrap();
    expect_error(
        &wheels(62_900.0),
        0,
        &["make a grid of 200217 points a rail", "at most 200000"],
    );
}

#[test]
fn a_message_of_the_format_over_16_mib_is_refused_and_one_of_another_topic_is_skipped() {
    let pad = "x".repeat(17 << 20);
    // An unknown extra field is ignored by the format, its size is not.
    let big = with(base(), 1, |v| v["pad"] = json!(pad));
    for layout in LAYOUTS {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.mcap");
        write_recording(&path, &big, layout);
        expect_file_error(
            &path,
            &[
                "message 1 (log_time",
                "a message of the format may be at most 16777216 bytes",
            ],
        );
    }
    let mut msgs = base();
    msgs[6] = msg("/diagnostics/heartbeat", T0 + 2 * SEC, json!({"pad": pad}));
    for layout in LAYOUTS {
        let (reader, events) = read_msgs(&msgs, layout).unwrap();
        assert_eq!(events.len(), 7, "{layout:?}");
        assert_eq!(reader.unknown_topic_messages(), 1);
    }
}

/// The bundled recordings rewritten without chunks: in time order they are
/// one run, read as a stream; with the tribometer readings at the end of
/// the file (as written), two. The events are the originals'.
#[test]
fn an_unchunked_file_in_time_order_is_one_run() {
    let dir = tempfile::tempdir().unwrap();
    for (name, sort, runs) in [
        ("demo_day.mcap", false, 2),
        ("demo_day.mcap", true, 1),
        ("curve_day_bands_rain.mcap", false, 2),
    ] {
        let original = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../recordings")
            .join(name);
        let bytes = std::fs::read(&original).unwrap();
        let mut messages: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        if sort {
            messages.sort_by_key(|m| m.log_time);
        }
        let path = dir.path().join("unchunked.mcap");
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut writer = mcap::WriteOptions::new()
            .use_chunks(false)
            .create(file)
            .unwrap();
        for m in &messages {
            writer.write(m).unwrap();
        }
        writer.finish().unwrap();
        drop(writer);
        let (reader, events) = read_all(&path, ReaderContext::default()).unwrap();
        let layout = reader.layout();
        assert_eq!(
            (layout.chunks, layout.loose_runs),
            (0, runs),
            "{name} sorted {sort}"
        );
        assert_eq!(layout.loose_messages, messages.len() as u64);
        let (_, want) = read_all(&original, ReaderContext::default()).unwrap();
        let strip = |e: &[Event]| -> Vec<(u64, String)> {
            e.iter()
                .map(|e| (e.log_time_ns, format!("{:?}", e.kind)))
                .collect()
        };
        assert_eq!(strip(&events), strip(&want), "{name}");
    }
}

// ---------------------------------------------------------------------------
// The reference recordings.

fn check_reference(name: &str) {
    let key: Value = serde_json::from_slice(
        &std::fs::read(reference_recording(&format!("{name}.key.json"))).unwrap(),
    )
    .unwrap();
    let counts = &key["counts"];
    let count = |field: &str| counts[field].as_u64().unwrap();

    let (reader, events) = read_all(
        &reference_recording(&format!("{name}.mcap")),
        ReaderContext::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let section = reader.section().clone();
    assert_eq!(
        section.section_id,
        key["params"]["section_id"].as_str().unwrap()
    );
    assert_eq!(
        reader.section_log_time_ns(),
        key["start_ns"].as_u64().unwrap()
    );

    let mut trains = 0;
    let mut pulses = 0;
    let mut weather = 0;
    let mut measurements = Vec::new();
    let mut previous: Option<(u64, u8, u64)> = None;
    for event in &events {
        let rank = match &event.kind {
            EventKind::Passage(_) => {
                trains += 1;
                1
            }
            EventKind::Pulse(_) => {
                pulses += 1;
                2
            }
            EventKind::Measurement(m) => {
                measurements.push((event, m));
                3
            }
            EventKind::Weather(_) => {
                weather += 1;
                4
            }
        };
        let replay_key = (event.log_time_ns, rank, event.index_in_file);
        if let Some(previous) = previous {
            assert!(previous < replay_key, "{previous:?} then {replay_key:?}");
        }
        previous = Some(replay_key);
    }
    assert_eq!(trains, count("trains"));
    assert_eq!(pulses, count("pulses"));
    assert_eq!(weather, count("weather"));
    assert_eq!(measurements.len() as u64, count("measurements"));
    let unknown: u64 = key["unknown_topics"]
        .as_object()
        .unwrap()
        .values()
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert_eq!(reader.unknown_topic_messages(), unknown);
    assert_eq!(1 + events.len() as u64 + unknown, count("messages"));
    for quantity in [Quantity::Mu, Quantity::Adhesion, Quantity::RailMu] {
        let n = measurements
            .iter()
            .filter(|(_, m)| m.quantity() == quantity)
            .count() as u64;
        assert_eq!(
            n,
            counts["by_quantity"][quantity.as_str()].as_u64().unwrap()
        );
    }

    let csv =
        std::fs::read_to_string(reference_recording(&format!("{name}.expected.csv"))).unwrap();
    let mut rows = csv.lines();
    assert_eq!(
        rows.next().unwrap(),
        "index_in_file,log_time_ns,site_id,rail,quantity,train_id,axle_index,measured,simulated"
    );
    let rows: Vec<&str> = rows.collect();
    assert_eq!(rows.len(), measurements.len());
    for (row, (event, m)) in rows.iter().zip(&measurements) {
        let f: Vec<&str> = row.split(',').collect();
        let axle = m.axle();
        let got = [
            event.index_in_file.to_string(),
            event.log_time_ns.to_string(),
            section.sites[m.site].id.clone(),
            section.rails[m.rail].clone(),
            m.quantity().as_str().to_string(),
            axle.map_or(String::new(), |a| a.train_id.to_string()),
            axle.map_or(String::new(), |a| a.axle_index.to_string()),
        ];
        assert_eq!(got.as_slice(), &f[..7], "row {row}");
        assert_eq!(m.value, f[7].parse::<f64>().unwrap(), "row {row}");
    }
}

#[test]
fn reference_tangent_day() {
    check_reference("tangent_day");
}

#[test]
fn reference_curve_2day() {
    check_reference("curve_2day");
}

// ---------------------------------------------------------------------------
// Bad input: one test per class. Indices refer to `base()`.

macro_rules! bad_input {
    ($($name:ident: $build:expr => $index:expr, [$($needle:expr),* $(,)?];)*) => {
        $(
            #[test]
            fn $name() {
                let msgs: Vec<Msg> = $build;
                expect_error(&msgs, $index, &[$($needle),*]);
            }
        )*
    };
}

bad_input! {
    missing_field:
        with(base(), 2, |v| remove(v, "", "speed_mps"))
        => 2, ["missing field `speed_mps`"];
    missing_nested_field:
        with(base(), 2, |v| remove(v, "/axles/1/creepage/right", "cy"))
        => 2, ["`axles[1].creepage.right`", "missing field `cy`"];
    true_is_not_a_number:
        with(base(), 2, |v| v["speed_mps"] = json!(true))
        => 2, ["`speed_mps`", "true"];
    string_is_not_a_number:
        with(base(), 0, |v| v["length_m"] = json!("600"))
        => 0, ["`length_m`", "\"600\""];
    number_is_not_a_string:
        with(base(), 3, |v| v["applicator_id"] = json!(1))
        => 3, ["`applicator_id`", "string"];
    axles_not_an_array:
        with(base(), 2, |v| v["axles"] = json!({"offset_m": 0.0}))
        => 2, ["`axles`", "array"];
    message_not_an_object:
        with_raw(base(), 2, "[1, 2]")
        => 2, ["object", "[1,2]"];
    nan_token_is_bad_json:
        with_raw(base(), 4, r#"{"site_id": "M1", "rail": "right", "quantity": "mu",
                              "train_id": "F-1", "axle_index": 1, "value": NaN}"#)
        => 4, ["not valid JSON"];
    infinite_number:
        with_raw(base(), 1, r#"{"air_temperature_c": 1e999, "relative_humidity": 0.7,
                              "precipitation_mm_h": 0.0}"#)
        => 1, ["JSON"];
    truncated_json:
        with_raw(base(), 5, r#"{"site_id": "M2", "rail": "#)
        => 5, ["not valid JSON"];
    fractional_axle_index:
        with(base(), 4, |v| v["axle_index"] = json!(1.5))
        => 4, ["`axle_index`", "integer", "1.5"];
    negative_axle_index:
        with(base(), 4, |v| v["axle_index"] = json!(-1))
        => 4, ["`axle_index`", "-1"];
    zero_wheel_load:
        with(base(), 2, |v| v["axles"][0]["wheel_load_kN"]["left"] = json!(0.0))
        => 2, ["`axles[0].wheel_load_kN.left`", "positive"];
    zero_speed:
        with(base(), 2, |v| v["speed_mps"] = json!(0))
        => 2, ["`speed_mps`", "positive"];
    negative_wheel_diameter:
        with(base(), 2, |v| v["axles"][1]["wheel_diameter_m"] = json!(-0.92))
        => 2, ["`axles[1].wheel_diameter_m`", "-0.92"];
    zero_section_length:
        with(base(), 0, |v| v["length_m"] = json!(0.0))
        => 0, ["`length_m`", "physical range 1 to"];
    zero_rail_head_radius:
        with(base(), 0, |v| v["rail_head_radius_m"] = json!(0.0))
        => 0, ["`rail_head_radius_m`", "positive"];
    zero_nominal_wheel_diameter:
        with(base(), 0, |v| v["nominal_wheel_diameter_m"] = json!(0.0))
        => 0, ["`nominal_wheel_diameter_m`", "positive"];
    zero_curve_radius:
        with(base(), 0, |v| v["curve_radius_m"] = json!(0.0))
        => 0, ["`curve_radius_m`", "physical range 10 to"];
    negative_pulse_mass:
        with(base(), 3, |v| v["mass_g"] = json!(-0.1))
        => 3, ["`mass_g`", "negative", "-0.1"];
    negative_nominal_pulse:
        with(base(), 0, |v| v["applicators"][0]["nominal_pulse_g"] = json!(-0.2))
        => 0, ["`applicators[0].nominal_pulse_g`", "negative"];
    negative_precipitation:
        with(base(), 1, |v| v["precipitation_mm_h"] = json!(-1.0))
        => 1, ["`precipitation_mm_h`", "negative"];
    negative_axle_offset:
        with(base(), 2, |v| v["axles"][0]["offset_m"] = json!(-0.5))
        => 2, ["`axles[0].offset_m`", "-0.5"];
    decreasing_axle_offset:
        with(base(), 2, |v| v["axles"][0]["offset_m"] = json!(3.0))
        => 2, ["`axles[1].offset_m`", "2.5", "3"];
    empty_axles:
        with(base(), 2, |v| v["axles"] = json!([]))
        => 2, ["`axles`", "empty"];
    empty_rails:
        with(base(), 0, |v| v["rails"] = json!([]))
        => 0, ["`rails`", "empty"];
    empty_applicators:
        with(base(), 0, |v| v["applicators"] = json!([]))
        => 0, ["`applicators`", "empty"];
    empty_applicator_rails:
        with(base(), 0, |v| v["applicators"][0]["rails"] = json!([]))
        => 0, ["`applicators[0].rails`", "empty"];
    duplicate_rail:
        with(base(), 0, |v| v["rails"] = json!(["left", "right", "left"]))
        => 0, ["duplicate rail `left`"];
    duplicate_applicator:
        with(base(), 0, |v| {
            let a = v["applicators"][0].clone();
            v["applicators"].as_array_mut().unwrap().push(a);
        })
        => 0, ["duplicate applicator id `A1`"];
    duplicate_site:
        with(base(), 0, |v| v["measurement_sites"][1]["id"] = json!("M1"))
        => 0, ["duplicate measurement site id `M1`"];
    unknown_direction:
        with(base(), 2, |v| v["direction"] = json!("sideways"))
        => 2, ["direction", "`sideways`"];
    unknown_bogie_position:
        with(base(), 2, |v| v["axles"][1]["bogie_position"] = json!("middle"))
        => 2, ["`axles[1].bogie_position`", "`middle`"];
    unknown_quantity:
        with(base(), 4, |v| v["quantity"] = json!("mu_max"))
        => 4, ["quantity", "`mu_max`"];
    pulse_on_a_rail_the_applicator_does_not_list:
        with(
            with(base(), 0, |v| v["applicators"][0]["rails"] = json!(["left"])),
            3,
            |v| v["rail"] = json!("right"),
        )
        => 3, ["applicator `A1`", "rail `right`"];
    unknown_rail:
        with(base(), 3, |v| v["rail"] = json!("middle"))
        => 3, ["`rail`", "`middle`"];
    unknown_rail_of_an_applicator:
        with(base(), 0, |v| v["applicators"][0]["rails"] = json!(["left", "middle"]))
        => 0, ["`applicators[0].rails[1]`", "`middle`"];
    per_rail_map_lacks_a_rail:
        with(base(), 2, |v| remove(v, "/axles/1/wheel_load_kN", "right"))
        => 2, ["`axles[1].wheel_load_kN`", "lacks rail `right`"];
    per_rail_map_names_an_unknown_rail:
        with(base(), 2, |v| v["axles"][0]["creepage"]["middle"] = json!({"cx": 0, "cy": 0, "spin_per_m": 0}))
        => 2, ["`axles[0].creepage`", "`middle`"];
    unknown_applicator:
        with(base(), 3, |v| v["applicator_id"] = json!("A9"))
        => 3, ["applicator `A9`"];
    unknown_site:
        with(base(), 5, |v| v["site_id"] = json!("M9"))
        => 5, ["site `M9`"];
    duplicate_train_id:
        with(base(), 7, |v| v["train_id"] = json!("F-1"))
        => 7, ["duplicate train_id `F-1`"];
    measurement_of_an_unknown_train:
        with(base(), 4, |v| v["train_id"] = json!("F-9"))
        => 4, ["train_id `F-9`", "unknown"];
    measurement_before_its_train_in_replay_order:
        with_time(base(), 4, T0 + 9 * SEC)
        => 4, ["train_id `F-1`", "unknown"];
    axle_index_out_of_range:
        with(base(), 4, |v| v["axle_index"] = json!(2))
        => 4, ["axle_index 2", "2 axles"];
    mu_without_train:
        with(base(), 4, |v| remove(v, "", "train_id"))
        => 4, ["missing field `train_id`"];
    rail_mu_with_a_train:
        with(base(), 5, |v| v["train_id"] = json!("F-1"))
        => 5, ["rail_mu", "`train_id`"];
    second_section:
        { let mut m = base(); m.push(msg("/section", T0 + 20 * SEC, section())); m }
        => 9, ["second /section"];
    message_earlier_than_section:
        with_time(base(), 1, T0 - 1)
        => 1, ["earlier than the /section"];
    unknown_topic_earlier_than_section:
        with_time(base(), 6, T0 - SEC)
        => 6, ["earlier than the /section"];
    known_topic_not_json:
        { let mut m = base(); m[1].encoding = "cdr".to_string(); m }
        => 1, ["`cdr`", "json"];
    site_outside_the_section:
        with(base(), 0, |v| v["measurement_sites"][1]["position_m"] = json!(600.5))
        => 0, ["`measurement_sites[1].position_m`", "600.5", "outside"];
    applicator_outside_the_section:
        with(base(), 0, |v| v["applicators"][0]["position_m"] = json!(-1.0))
        => 0, ["`applicators[0].position_m`", "outside"];
    duplicate_field_name:
        with_raw(base(), 3, r#"{"applicator_id": "A1", "rail": "left", "mass_g": 0.1, "mass_g": 0.2}"#)
        => 3, ["duplicate field `mass_g`"];
    per_rail_map_names_a_rail_twice:
        with_raw(base(), 2, r#"{"train_id": "F-1", "direction": "up", "speed_mps": 20.0, "axles": [
            {"offset_m": 0.0, "bogie_position": "leading", "wheel_diameter_m": 0.92,
             "wheel_load_kN": {"left": 100.0, "right": 98.0, "left": 90.0},
             "creepage": {"left": {"cx": 0.01, "cy": 0.0, "spin_per_m": 0.1},
                          "right": {"cx": -0.01, "cy": 0.002, "spin_per_m": -0.1}}}]}"#)
        => 2, ["`axles[0].wheel_load_kN`", "rail `left` twice"];
    two_trains_at_once:
        with_time(base(), 7, T0 + 30 * SEC)
        => 7, ["two trains in the section at once", "`F-2`", "`F-1`"];
}

#[test]
fn unknown_topic_may_use_any_encoding() {
    let mut msgs = base();
    msgs[6].encoding = "protobuf".to_string();
    msgs[6].data = vec![0xff, 0x00, 0x13];
    let (reader, events) = read_msgs(&msgs, Layout::OneChunk).unwrap();
    assert_eq!((events.len(), reader.unknown_topic_messages()), (7, 1));
}

#[test]
fn iteration_stops_after_the_first_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.mcap");
    write_recording(
        &path,
        &with_time(base(), 7, T0 + 30 * SEC),
        Layout::OneChunk,
    );
    let mut reader = RecordingReader::open(&path, ReaderContext::default()).unwrap();
    let results: Vec<_> = reader.by_ref().collect();
    assert!(results.last().unwrap().is_err());
    assert_eq!(results.iter().filter(|r| r.is_err()).count(), 1);
    assert!(reader.next().is_none());
}

#[test]
fn recording_without_section() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nosection.mcap");
    write_recording(&path, &base()[1..], Layout::OneChunk);
    expect_file_error(&path, &["no /section"]);
}

#[test]
fn truncated_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("whole.mcap");
    write_recording(&path, &base(), Layout::OneChunk);
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    expect_file_error(&cut, &["truncated"]);
    // Cut at many lengths (the last few bytes each): never a panic.
    let lengths = (0..bytes.len())
        .step_by(7)
        .chain(bytes.len() - 16..bytes.len());
    for len in lengths {
        std::fs::write(&cut, &bytes[..len]).unwrap();
        refused(&cut);
    }
}

#[test]
fn garbage_and_empty_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("garbage.mcap");
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(&path, &garbage).unwrap();
    expect_file_error(&path, &["not an mcap file"]);
    std::fs::write(&path, b"").unwrap();
    expect_file_error(&path, &["not an mcap file"]);
    let missing = dir.path().join("missing.mcap");
    expect_file_error(&missing, &["cannot open"]);
}

/// (opcode, offset, body length) of the data section's top-level records.
fn top_level_records(bytes: &[u8]) -> Vec<(u8, usize, usize)> {
    let mut records = Vec::new();
    let mut offset = 8;
    while offset + 9 <= bytes.len() {
        let opcode = bytes[offset];
        let len = u64::from_le_bytes(bytes[offset + 1..offset + 9].try_into().unwrap()) as usize;
        records.push((opcode, offset, len));
        if opcode == 0x0F {
            break;
        }
        offset += 9 + len;
    }
    records
}

#[test]
fn corrupt_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("recording.mcap");
    write_recording(&path, &base(), Layout::OneChunk);
    let bytes = std::fs::read(&path).unwrap();
    let &(_, offset, len) = top_level_records(&bytes)
        .iter()
        .find(|(opcode, _, _)| *opcode == 0x06)
        .unwrap();
    let bad = dir.path().join("bad.mcap");
    // Flip one byte of the compressed records, then every byte of the chunk
    // in turn: an error naming the file each time, never a panic.
    let mut flipped = bytes.clone();
    flipped[offset + 9 + len - 20] ^= 0x5a;
    std::fs::write(&bad, &flipped).unwrap();
    expect_file_error(&bad, &["chunk"]);
    for i in offset..offset + 9 + len {
        let mut flipped = bytes.clone();
        flipped[i] ^= 0xff;
        std::fs::write(&bad, &flipped).unwrap();
        if let Err(err) = read_all(&bad, ReaderContext::default()) {
            assert_eq!(err.file, bad);
        }
    }
}

/// The layout pass reads chunks a few at a time in parallel: the error is
/// still the first bad chunk's in file order, and a bad chunk comes before a
/// cut-short record after it.
#[test]
fn the_first_bad_chunk_in_file_order_is_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("recording.mcap");
    write_recording(&path, &base(), Layout::ChunkPerMessage);
    let bytes = std::fs::read(&path).unwrap();
    let chunks: Vec<(usize, usize)> = top_level_records(&bytes)
        .iter()
        .filter(|(opcode, _, _)| *opcode == 0x06)
        .map(|&(_, offset, len)| (offset, len))
        .collect();
    assert!(chunks.len() >= 9, "{} chunks", chunks.len());
    // A chunk's CRC is bytes 24..28 of its body.
    let break_crc = |bytes: &mut Vec<u8>, k: usize| bytes[chunks[k].0 + 9 + 24] ^= 0xff;
    let bad = dir.path().join("bad.mcap");
    // Four chunks are read ahead at most: (4, 5) and (5, 6) are both still
    // waiting when the overlong record is met.
    for (first, later) in [(1, 6), (2, 3), (4, 5), (5, 6), (0, 7)] {
        let mut broken = bytes.clone();
        break_crc(&mut broken, first);
        break_crc(&mut broken, later);
        std::fs::write(&bad, &broken).unwrap();
        let err = refused(&bad);
        let text = err.to_string();
        assert!(
            text.contains(&format!("unreadable chunk at byte {}:", chunks[first].0)),
            "chunks {first} and {later} broken: {text}"
        );
        // A record after the later chunk claiming more bytes than the file
        // has: the broken chunk is still the error.
        std::fs::write(&bad, overlong_record_after(&broken, chunks[later])).unwrap();
        let err = refused(&bad);
        assert!(
            err.to_string()
                .contains(&format!("unreadable chunk at byte {}:", chunks[first].0)),
            "{err}"
        );
    }
    // Only the overlong record: it is the error.
    std::fs::write(&bad, overlong_record_after(&bytes, chunks[6])).unwrap();
    let err = refused(&bad);
    assert!(
        err.to_string().contains("past the end of the file"),
        "{err}"
    );
}

/// The file up to the end of the chunk at (offset, body length), then a
/// Message Index record claiming a megabyte, then the closing magic.
fn overlong_record_after(bytes: &[u8], (offset, len): (usize, usize)) -> Vec<u8> {
    let mut out = bytes[..offset + 9 + len].to_vec();
    out.push(0x07);
    out.extend_from_slice(&(1u64 << 20).to_le_bytes());
    out.extend_from_slice(&bytes[bytes.len() - 8..]);
    out
}

// ---------------------------------------------------------------------------
// A line (line.md): the `/line` message beside the section.

/// The base recording's 600 m cut into a tangent, a transition and a
/// curve, the `/line` written as the file's message `at`.
fn with_line(at: usize, log_time: u64) -> Vec<Msg> {
    let mut msgs = base();
    let line = json!({
        "line_id": "test-line",
        "segments": [
            {"id": "T0", "type": "tangent", "end_m": 150.0, "high_rail": 3},
            {"id": "X1", "type": "transition", "end_m": 210.0, "high_rail": "right", "curve_at": "end"},
            {"id": "C1", "type": "curve", "end_m": 600.0, "high_rail": "right", "radius_m": 400.0}
        ]
    });
    msgs.insert(at, msg("/line", log_time, line));
    msgs
}

#[test]
fn a_line_is_read_beside_its_section_wherever_the_file_puts_it() {
    let (plain_reader, plain) = read_msgs(&base(), Layout::OneChunk).unwrap();
    let last = base().len();
    for at in [1, last] {
        for layout in LAYOUTS {
            let (reader, events) = read_msgs(&with_line(at, T0), layout).unwrap();
            let line = reader.line().expect("the recording is a line");
            assert_eq!(line.line_id, "test-line");
            let ends: Vec<f64> = line.segments.iter().map(|s| s.end_m).collect();
            assert_eq!(ends, [150.0, 210.0, 600.0]);
            // Every other message means what it meant.
            assert_eq!(events.len(), plain.len(), "{at} {layout:?}");
            assert_eq!(
                reader.unknown_topic_messages(),
                plain_reader.unknown_topic_messages()
            );
        }
    }
    assert!(plain_reader.line().is_none());
}

#[test]
fn a_line_at_another_time_than_its_section_is_refused() {
    expect_error(&with_line(1, T0 + 1), 1, &["/section's log_time"]);
}

#[test]
fn a_second_line_is_refused() {
    let mut msgs = with_line(1, T0);
    let again = msgs[1].clone();
    msgs.push(again);
    expect_error(&msgs, msgs.len() - 1, &["a second /line"]);
}

#[test]
fn a_line_whose_segments_break_line_md_is_refused_naming_the_field() {
    let cases: [(&str, Value, &[&str]); 3] = [
        (
            "an end before the section's",
            json!(599.0),
            &["segments[2].end_m", "length_m"],
        ),
        (
            "a high rail of no rail",
            json!("outer"),
            &["segments[2].high_rail", "names no rail"],
        ),
        (
            "no curve_at",
            Value::Null,
            &["segments[1].curve_at", "missing"],
        ),
    ];
    for (what, value, needles) in cases {
        let msgs = with(with_line(1, T0), 1, |line| match what {
            "an end before the section's" => line["segments"][2]["end_m"] = value,
            "a high rail of no rail" => line["segments"][2]["high_rail"] = value,
            _ => remove(line, "/segments/1", "curve_at"),
        });
        expect_error(&msgs, 1, needles);
    }
}

#[test]
fn a_line_needs_a_section_of_two_rails() {
    let msgs = with(with_line(1, T0), 0, |section| {
        section["rails"] = json!(["left", "right", "third"]);
    });
    expect_error(&msgs, 1, &["exactly two rails"]);
}

/// The passage F-1 (message 3 once the `/line` is message 1) with
/// `segments` on its leading axle.
fn with_axle_segments(line: bool, segments: Value) -> Vec<Msg> {
    let msgs = if line { with_line(1, T0) } else { base() };
    let at = if line { 3 } else { 2 };
    with(msgs, at, |p| p["axles"][0]["segments"] = segments)
}

fn passage_axles(events: &[Event]) -> Vec<tortwin_recording::Axle> {
    match events.iter().find_map(|e| match &e.kind {
        EventKind::Passage(p) => Some(p.axles.clone()),
        _ => None,
    }) {
        Some(axles) => axles,
        None => panic!("no passage"),
    }
}

#[test]
fn an_axle_s_segments_replace_its_load_or_creepage_there() {
    let segments = json!({
        "C1": {"wheel_load_kN": {"right": 120.0, "left": 80.0}},
        "T0": {"creepage": {"left": {"cx": 0.0, "cy": 0.0, "spin_per_m": 0.0},
                            "right": {"cx": 0.0, "cy": 0.001, "spin_per_m": 0.0}}}
    });
    let (_, events) = read_msgs(&with_axle_segments(true, segments), Layout::OneChunk).unwrap();
    let axles = passage_axles(&events);
    let s = &axles[0].segments;
    // Sorted by segment: T0 (0) before C1 (2); kN -> N per rail index.
    assert_eq!(s.iter().map(|s| s.segment).collect::<Vec<_>>(), [0, 2]);
    assert_eq!(s[1].wheel_load_n, Some(vec![80e3, 120e3]));
    assert!(s[1].creepage.is_none() && s[0].wheel_load_n.is_none());
    assert_eq!(s[0].creepage.as_ref().map(|c| c[1].cy), Some(0.001));
    assert!(axles[1].segments.is_empty());
}

#[test]
fn without_a_line_an_axle_s_segments_are_an_unknown_field() {
    for segments in [json!({"nowhere": {}}), json!(7)] {
        let (_, events) =
            read_msgs(&with_axle_segments(false, segments), Layout::OneChunk).unwrap();
        assert!(passage_axles(&events)[0].segments.is_empty());
    }
}

#[test]
fn an_axle_s_segments_that_break_line_md_are_refused_naming_the_field() {
    let cases: [(Value, &[&str]); 5] = [
        (
            json!({"C9": {"wheel_load_kN": {"left": 80.0, "right": 80.0}}}),
            &["axles[0].segments.C9", "does not have"],
        ),
        (json!({"C1": {}}), &["axles[0].segments.C1", "neither"]),
        (
            json!({"C1": {"wheel_load_kN": {"left": 80.0}}}),
            &["axles[0].segments.C1.wheel_load_kN", "lacks rail `right`"],
        ),
        (
            json!({"C1": {"wheel_load_kN": {"left": 80.0, "right": -1.0}}}),
            &["axles[0].segments.C1.wheel_load_kN.right"],
        ),
        (json!({"C1": {"creepage": 3}}), &["axles[0].segments"]),
    ];
    for (segments, needles) in cases {
        expect_error(&with_axle_segments(true, segments), 3, needles);
    }
}

// ---------------------------------------------------------------------------
// The layout pass beside the replay (`RecordingReader::open_beside`).

/// A file with a chunk per message, its last chunk's CRC broken, and the
/// byte offset of that chunk.
fn last_chunk_broken(dir: &Path, msgs: &[Msg]) -> (std::path::PathBuf, usize) {
    let path = dir.join("recording.mcap");
    write_recording(&path, msgs, Layout::ChunkPerMessage);
    let mut bytes = std::fs::read(&path).unwrap();
    let &(_, offset, _) = top_level_records(&bytes)
        .iter()
        .rfind(|(opcode, _, _)| *opcode == 0x06)
        .unwrap();
    // A chunk's CRC is bytes 24..28 of its body.
    bytes[offset + 9 + 24] ^= 0xff;
    let bad = dir.join("bad.mcap");
    std::fs::write(&bad, &bytes).unwrap();
    (bad, offset)
}

/// Beside the pass the replay starts before the last chunk is checked:
/// the reader opens a file `open` refuses, gives the events before that
/// chunk is due and then the same error, and none after it.
#[test]
fn beside_the_layout_pass_a_broken_chunk_is_the_error_when_it_is_due() {
    let dir = tempfile::tempdir().unwrap();
    let (bad, offset) = last_chunk_broken(dir.path(), &base());
    let laid = RecordingReader::open(&bad, ReaderContext::default())
        .err()
        .expect("a broken chunk is refused");
    assert!(
        laid.message
            .contains(&format!("unreadable chunk at byte {offset}:")),
        "{laid}"
    );
    let mut reader = RecordingReader::open_beside(&bad, ReaderContext::default())
        .expect("the replay starts before the last chunk is checked");
    let items: Vec<_> = reader.by_ref().collect();
    let (last, events) = items.split_last().unwrap();
    assert_eq!(last.as_ref().err(), Some(&laid));
    // The sound file's events, but the last (the broken chunk's).
    let (_, sound) =
        read_all(&dir.path().join("recording.mcap"), ReaderContext::default()).unwrap();
    let events: Vec<Event> = events.iter().map(|e| e.clone().unwrap()).collect();
    assert_eq!(events, sound[..sound.len() - 1]);
    assert!(reader.next().is_none());
    assert_eq!(reader.layout_verdict(), Err(laid));
}

/// What `open` refuses once the file is laid out (a second `/section`, a
/// `/line` that is not next after it, a second `/line`) is the error
/// beside the pass too, wherever the replay meets the message: also when
/// a caller stops first and asks for the verdict.
#[test]
fn beside_the_layout_pass_the_section_and_line_checks_come_first() {
    let mut second_section = base();
    second_section.push(msg("/section", T0 + 20 * SEC, section()));
    let mut second_line = with_line(1, T0);
    let again = second_line[1].clone();
    second_line.push(Msg {
        log_time: T0 + 20 * SEC,
        ..again
    });
    let cases = [
        (second_section, "a second /section"),
        (
            with_line(5, T0 + 20 * SEC),
            "not at the /section's log_time",
        ),
        (second_line, "a second /line"),
    ];
    for (msgs, needle) in cases {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.mcap");
        write_recording(&path, &msgs, Layout::ChunkPerMessage);
        let laid = refused(&path);
        assert!(laid.message.contains(needle), "{laid}");
        // A caller that stops after the first event and asks.
        let mut reader = RecordingReader::open_beside(&path, ReaderContext::default())
            .expect("the replay starts before the file is laid out");
        assert!(reader.next().is_some_and(|e| e.is_ok()));
        assert_eq!(reader.layout_verdict(), Err(laid.clone()), "{needle}");
        assert_eq!(reader.layout_verdict(), Err(laid), "asked again");
    }
}

/// A sound file: the verdict is `Ok` at any time, the counts the file's.
#[test]
fn beside_the_layout_pass_a_sound_file_reads_as_laid_out() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("recording.mcap");
    write_recording(&path, &base(), Layout::ChunkPerMessage);
    let (laid, events) = read_all(&path, ReaderContext::default()).unwrap();
    let mut reader = RecordingReader::open_beside(&path, ReaderContext::default()).unwrap();
    assert_eq!(reader.layout_verdict(), Ok(()));
    assert_eq!(reader.layout(), laid.layout());
    let again: Vec<Event> = reader.by_ref().map(Result::unwrap).collect();
    assert_eq!(again, events);
}
