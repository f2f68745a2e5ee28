//! Cutting a recording into service days and merging days back
//! (`tortwin_recording::cut`): checked against the `mcap` crate's own
//! reader. Every message of the input lands in exactly one day, bytes
//! unchanged (an unknown topic's too, out of time order in the file); each
//! day opens with the `/section` and reads as a valid recording; the
//! merged days are the input again, message for message; a day of
//! another section is refused, naming the file and the message.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// the helpers here assert too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

// Shared with the workspace's tests (tests/common), which use all of it.
#[path = "support/recording.rs"]
#[allow(dead_code, unreachable_pub)]
mod recording;

use std::path::{Path, PathBuf};

use recording::{copy_recording, read_messages, write_recording, Layout, Msg};
use tortwin_recording::cut::{merge, split_by_day};
use tortwin_recording::error::ConvertError;
use tortwin_recording::{ReaderContext, RecordingReader};

fn two_days() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/reference/recordings/curve_2day.mcap")
}

/// (topic, log_time, bytes) of every message but the `/section`s, sorted.
fn contents(path: &Path) -> Vec<(String, u64, Vec<u8>)> {
    let mut all: Vec<_> = read_messages(path)
        .into_iter()
        .filter(|m| m.topic != "/section")
        .map(|m| (m.topic, m.log_time, m.data))
        .collect();
    all.sort();
    all
}

/// Reads every event of `path` with the replay's reader: how many.
fn events(path: &Path) -> usize {
    let reader = RecordingReader::open(path, ReaderContext::default()).expect("a valid recording");
    let mut n = 0;
    for event in reader {
        event.expect("a valid event");
        n += 1;
    }
    n
}

#[test]
fn the_days_hold_every_message_once_and_merge_back() {
    let dir = tempfile::tempdir().unwrap();
    // The reference recording with an unknown topic's messages appended at
    // the end of the file, out of time order.
    let input = dir.path().join("two_days.mcap");
    let mut extra: Vec<Msg> = Vec::new();
    copy_recording(&two_days(), &input, |m| {
        if m.topic == "/environment/weather" {
            extra.push(Msg {
                topic: "/vendor/diagnostics".into(),
                encoding: "cbor".into(),
                data: vec![0xA0, extra.len() as u8],
                ..m.clone()
            });
        }
        true
    });
    let mut msgs = read_messages(&input);
    msgs.extend(extra);
    write_recording(&input, &msgs, Layout::OneChunk);

    let days = split_by_day(&input, &dir.path().join("days")).expect("the recording is cut");
    let dates: Vec<&str> = days.iter().map(|d| d.date.as_str()).collect();
    assert_eq!(dates.len(), 2, "{dates:?}");
    assert!(dates[0] < dates[1]);
    let mut together: Vec<(String, u64, Vec<u8>)> = Vec::new();
    for (k, day) in days.iter().enumerate() {
        assert_eq!(
            day.path,
            dir.path().join("days").join(format!("{}.mcap", day.date))
        );
        let messages = read_messages(&day.path);
        assert_eq!(messages.len() as u64, day.messages);
        // The /section first in the file, at the day's opening.
        assert_eq!(messages[0].topic, "/section");
        let passages: Vec<u64> = messages
            .iter()
            .filter(|m| m.topic == "/train/passage")
            .map(|m| m.log_time)
            .collect();
        if k > 0 {
            assert_eq!(
                messages[0].log_time, passages[0],
                "opened at its first train"
            );
        }
        // Its first passage on its date, and none of another day's.
        let first_day = passages[0] / 86_400_000_000_000;
        assert!(passages
            .iter()
            .all(|&t| t / 86_400_000_000_000 == first_day));
        assert!(events(&day.path) > 0);
        together.extend(contents(&day.path));
    }
    together.sort();
    assert_eq!(
        together,
        contents(&input),
        "every message once, bytes unchanged"
    );
    assert!(together.iter().any(|m| m.0 == "/vendor/diagnostics"));

    let merged = dir.path().join("merged.mcap");
    let paths: Vec<PathBuf> = days.iter().map(|d| d.path.clone()).collect();
    let written = merge(&paths, &merged).expect("the days merge");
    assert_eq!(contents(&merged), contents(&input));
    assert_eq!(written as usize, contents(&input).len() + 1);
    assert_eq!(
        events(&merged),
        events(&input),
        "the merged days replay as the input"
    );
    // Cutting again writes the same days.
    let again = split_by_day(&merged, &dir.path().join("again")).unwrap();
    for (a, b) in days.iter().zip(&again) {
        assert_eq!(a.date, b.date);
        assert_eq!(contents(&a.path), contents(&b.path));
    }
}

#[test]
fn a_day_of_another_section_is_not_merged() {
    let dir = tempfile::tempdir().unwrap();
    let other = dir.path().join("other.mcap");
    copy_recording(&two_days(), &other, |m| {
        if m.topic == "/section" {
            let mut v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            v["length_m"] = serde_json::json!(v["length_m"].as_f64().unwrap() + 1.0);
            m.data = serde_json::to_vec(&v).unwrap();
        }
        true
    });
    let out = dir.path().join("merged.mcap");
    let err = merge(&[two_days(), other.clone()], &out).expect_err("two sections");
    let text = err.to_string();
    assert!(matches!(err, ConvertError::Input(_)), "{text}");
    assert!(
        text.contains("other.mcap") && text.contains("/section"),
        "{text}"
    );
    assert!(!out.exists(), "nothing written under the final name");
}

#[test]
fn a_recording_without_a_train_cannot_be_cut() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("no_trains.mcap");
    copy_recording(&two_days(), &input, |m| {
        m.topic != "/train/passage" && m.topic != "/measurement/friction"
    });
    let err = split_by_day(&input, &dir.path().join("days")).expect_err("no passage");
    assert!(
        err.to_string().contains("no /train/passage message"),
        "{err}"
    );
    assert!(
        !dir.path().join("days").exists()
            || std::fs::read_dir(dir.path().join("days")).unwrap().count() == 0
    );
}

/// The two-day reference recording as a line: a `/line` (a curve between
/// two tangents, `high` outer) written right after its `/section`, at its
/// log_time, with `line_id` as given.
fn two_days_as_a_line(path: &Path, line_id: &str) {
    let mut msgs = read_messages(&two_days());
    let at = msgs.iter().position(|m| m.topic == "/section").unwrap();
    let line = serde_json::json!({
        "line_id": line_id,
        "segments": [
            {"id": "T0", "type": "tangent", "end_m": 100.0},
            {"id": "C1", "type": "curve", "end_m": 500.0, "high_rail": "high", "radius_m": 400.0},
            {"id": "T1", "type": "tangent", "end_m": 600.0}
        ]
    });
    let section_time = msgs[at].log_time;
    msgs.insert(at + 1, recording::msg("/line", section_time, line));
    write_recording(path, &msgs, Layout::OneChunk);
}

#[test]
fn a_line_s_days_each_open_with_its_section_and_line_and_merge_back() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("line.mcap");
    two_days_as_a_line(&input, "a");
    let days = split_by_day(&input, &dir.path().join("days")).expect("the line is cut");
    assert_eq!(days.len(), 2);
    for day in &days {
        let messages = read_messages(&day.path);
        assert_eq!(messages[0].topic, "/section");
        assert_eq!(messages[1].topic, "/line");
        assert_eq!(messages[1].log_time, messages[0].log_time);
        assert_eq!(messages.iter().filter(|m| m.topic == "/line").count(), 1);
        let reader = RecordingReader::open(&day.path, ReaderContext::default()).unwrap();
        assert_eq!(reader.line().map(|l| l.segments.len()), Some(3));
    }
    let merged = dir.path().join("merged.mcap");
    let paths: Vec<PathBuf> = days.iter().map(|d| d.path.clone()).collect();
    merge(&paths, &merged).expect("the days merge");
    assert_eq!(contents(&merged), contents(&input));
    assert_eq!(events(&merged), events(&input));

    // A day of another line (or of the section without its line) is not merged.
    let other = dir.path().join("other.mcap");
    two_days_as_a_line(&other, "b");
    let err = merge(&[input.clone(), other], &dir.path().join("no.mcap")).expect_err("two lines");
    assert!(err.to_string().contains("/line"), "{err}");
    let err = merge(&[input, two_days()], &dir.path().join("no.mcap")).expect_err("line, section");
    assert!(err.to_string().contains("/line"), "{err}");
}
