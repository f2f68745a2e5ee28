//! The reader following a file while it grows (`RecordingReader::follow`):
//! a finished recording is written again into a file a piece at a time (a
//! chunk per message, each chunk in two halves with pauses between) while
//! the reader follows it; what it reads must be what `open` reads of the
//! finished file, or, where the file was not written in time order, an
//! error that names the message.

#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use std::io::Write;
use std::path::Path;
use std::time::Duration;

use serde_json::json;
use tortwin_recording::error::InputError;
use tortwin_recording::reader::{Follow, ReaderContext, RecordingReader};
use tortwin_recording::Event;

#[path = "support/recording.rs"]
#[allow(dead_code, unreachable_pub)]
mod recording;
use recording::{axle, msg, section, write_recording, Layout, Msg};

const T0: u64 = 1_712_534_400_000_000_000;
const SEC: u64 = 1_000_000_000;

/// Messages in file order (the comment: index in the file). Written out of
/// time order by at most 5 s, which a follower allowing a minute's delay
/// puts in place: the pulse at 5 s comes after the passage at 10 s, the
/// pulse at 50 s after the measurement at 50 s (a tie: the pulse goes first
/// by topic); and the heartbeat (a topic tortwin does not read) at 2 s long
/// after later messages, which is no error at all.
fn messages() -> Vec<Msg> {
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
        msg(
            "/applicator/pulse",
            T0 + 50 * SEC,
            json!({"applicator_id": "A1", "rail": "right", "mass_g": 0.1}),
        ),
        // 7
        msg("/diagnostics/heartbeat", T0 + 2 * SEC, json!({"ok": true})),
        // 8
        msg(
            "/train/passage",
            T0 + 100 * SEC,
            json!({"train_id": "F-2", "direction": "down", "speed_mps": 25.0,
                   "axles": [axle(0.0, "leading")]}),
        ),
        // 9
        msg(
            "/measurement/friction",
            T0 + 101 * SEC,
            json!({"site_id": "M2", "rail": "left", "quantity": "adhesion",
                   "train_id": "F-2", "axle_index": 0, "value": 0.21}),
        ),
    ]
}

/// The offsets at which the file's top-level records end.
fn record_ends(bytes: &[u8]) -> Vec<usize> {
    let mut ends = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        at += 9 + len;
        ends.push(at);
    }
    ends
}

/// Writes the finished file `whole` into `path` a record at a time, each
/// record in two halves, pausing between; runs on a thread of its own.
fn grow(whole: Vec<u8>, path: &Path) -> std::thread::JoinHandle<()> {
    let mut file = std::fs::File::create(path).unwrap();
    std::thread::spawn(move || {
        let mut from = 0;
        for end in record_ends(&whole).into_iter().chain([whole.len()]) {
            let end = end.min(whole.len());
            let half = from + (end - from) / 2;
            for part in [&whole[from..half], &whole[half..end]] {
                file.write_all(part).unwrap();
                file.flush().unwrap();
                std::thread::sleep(Duration::from_millis(15));
            }
            from = end;
        }
    })
}

/// What the follower reads while `msgs` are written, and what `open`
/// reads of the finished file.
fn follow_and_open(
    msgs: &[Msg],
    max_delay: Duration,
) -> (
    Result<Vec<Event>, InputError>,
    Result<Vec<Event>, InputError>,
) {
    let dir = tempfile::tempdir().unwrap();
    let finished = dir.path().join("finished.mcap");
    write_recording(&finished, msgs, Layout::ChunkPerMessage);
    let growing = dir.path().join("growing.mcap");
    let writer = grow(std::fs::read(&finished).unwrap(), &growing);
    let follow = Follow {
        max_delay,
        ..Follow::new(Duration::from_millis(2))
    };
    let followed = RecordingReader::follow(&growing, ReaderContext::default(), follow)
        .and_then(|reader| reader.collect::<Result<Vec<_>, _>>());
    writer.join().unwrap();
    let opened = RecordingReader::open(&finished, ReaderContext::default())
        .and_then(|reader| reader.collect::<Result<Vec<_>, _>>());
    (followed, opened)
}

const MINUTE: Duration = Duration::from_secs(60);

#[test]
fn a_file_read_as_it_is_written_gives_the_finished_file_s_events() {
    let (followed, opened) = follow_and_open(&messages(), MINUTE);
    let opened = opened.unwrap();
    assert_eq!(opened.len(), 8);
    assert_eq!(followed.unwrap(), opened);
}

#[test]
fn a_message_later_than_the_delay_allowed_is_refused_where_it_is() {
    let mut msgs = messages();
    // Read after the measurement at 101 s: a reading at 20 s is 81 s late.
    msgs.push(msg(
        "/measurement/friction",
        T0 + 20 * SEC,
        json!({"site_id": "M2", "rail": "left", "quantity": "rail_mu", "value": 0.33}),
    ));
    let (followed, opened) = follow_and_open(&msgs, MINUTE);
    assert_eq!(opened.unwrap().len(), 9, "the finished file reads");
    let err = followed.unwrap_err().to_string();
    for needle in [
        "growing.mcap",
        "/measurement/friction",
        &format!("log_time {}", T0 + 20 * SEC),
        "index 10",
        "81.000 s behind",
        &format!("log_time {} ns", T0 + 101 * SEC),
        "--max-delay-s",
    ] {
        assert!(err.contains(needle), "{needle:?} not in: {err}");
    }
    // Without a delay allowed, the pulse written 5 s behind the passage is
    // refused already.
    let (followed, _) = follow_and_open(&messages(), Duration::ZERO);
    let err = followed.unwrap_err().to_string();
    for needle in ["/applicator/pulse", "index 3", "5.000 s behind"] {
        assert!(err.contains(needle), "{needle:?} not in: {err}");
    }
}

#[test]
fn a_half_written_file_is_waited_for_and_a_stop_ends_the_wait() {
    let dir = tempfile::tempdir().unwrap();
    let finished = dir.path().join("finished.mcap");
    write_recording(&finished, &messages(), Layout::ChunkPerMessage);
    let whole = std::fs::read(&finished).unwrap();
    // The file cut in the middle of its fifth record: what came before is
    // read, then the reader waits; a stop ends it with an error saying so.
    let ends = record_ends(&whole);
    let cut = (ends[3] + ends[4]) / 2;
    let growing = dir.path().join("growing.mcap");
    std::fs::write(&growing, &whole[..cut]).unwrap();
    let follow = Follow::new(Duration::from_millis(2));
    let stop = follow.stop.clone();
    let stopper = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(300));
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
    });
    let result = RecordingReader::follow(&growing, ReaderContext::default(), follow)
        .and_then(|reader| reader.collect::<Result<Vec<_>, _>>());
    stopper.join().unwrap();
    let err = result.unwrap_err().to_string();
    assert!(err.contains(Follow::STOPPED), "{err}");
}
