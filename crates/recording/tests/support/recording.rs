//! Input recordings for the tests, written with the recording crate's own
//! writer: a list of messages ([`Msg`]) in file order, in any of the chunk
//! layouts the reader must handle, with bytes that need not be valid JSON
//! and encodings that need not be `json`; a copy of an existing recording
//! with messages left out, retimed or changed ([`copy_recording`]); and the
//! small valid section the reader's tests start from.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use serde_json::{json, Value};
use tortwin_recording::{RecordingWriter, Topic};

/// One message of a test recording, as it goes into the file.
#[derive(Debug, Clone)]
pub struct Msg {
    pub topic: String,
    pub log_time: u64,
    pub encoding: String,
    pub data: Vec<u8>,
}

/// A `json` message with `value` as its body.
pub fn msg(topic: &str, log_time: u64, value: Value) -> Msg {
    Msg {
        topic: topic.to_string(),
        log_time,
        encoding: "json".to_string(),
        data: serde_json::to_vec(&value).expect("a JSON value serializes"),
    }
}

/// How the messages are laid out in the file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Layout {
    /// Everything in one zstd chunk.
    OneChunk,
    /// A chunk per message, so chunk start times jump back and forth.
    ChunkPerMessage,
    /// No chunks: runs of messages merged from the file.
    Unchunked,
    /// Everything in one lz4 chunk (the other layouts use zstd).
    OneLz4Chunk,
}

pub const LAYOUTS: [Layout; 3] = [Layout::OneChunk, Layout::ChunkPerMessage, Layout::Unchunked];

/// Writes `msgs` in file order: a format topic in `json` on the writer's
/// own channel, anything else (an unknown topic, another encoding) on a
/// channel of its own.
pub fn write_recording(path: &Path, msgs: &[Msg], layout: Layout) {
    let compression = match layout {
        Layout::OneLz4Chunk => mcap::Compression::Lz4,
        _ => mcap::Compression::Zstd,
    };
    let options = mcap::WriteOptions::new()
        .use_chunks(layout != Layout::Unchunked)
        .compression(Some(compression));
    let file = BufWriter::new(File::create(path).expect("the test can create its file"));
    let mut writer = RecordingWriter::new(file, options, None).expect("the writer starts");
    let mut channels: BTreeMap<(String, String), u16> = BTreeMap::new();
    for m in msgs {
        match Topic::from_name(&m.topic).filter(|_| m.encoding == "json") {
            Some(topic) => writer.write_json(topic, m.log_time, &m.data),
            None => {
                let key = (m.topic.clone(), m.encoding.clone());
                let channel = match channels.get(&key) {
                    Some(&id) => id,
                    None => {
                        let id = writer
                            .add_channel(&m.topic, &m.encoding)
                            .expect("a channel");
                        channels.insert(key, id);
                        id
                    }
                };
                writer.write_to_channel(channel, m.log_time, &m.data)
            }
        }
        .expect("the message is written");
        if layout == Layout::ChunkPerMessage {
            writer.end_chunk().expect("the chunk ends");
        }
    }
    writer.finish().expect("the recording is finished");
}

/// Every message of the recording at `path`, in file order.
pub fn read_messages(path: &Path) -> Vec<Msg> {
    let bytes = std::fs::read(path).expect("the recording is readable");
    mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| {
            let m = m.expect("a readable message");
            Msg {
                topic: m.channel.topic.clone(),
                log_time: m.log_time,
                encoding: m.channel.message_encoding.clone(),
                data: m.data.into_owned(),
            }
        })
        .collect()
}

/// Copies the recording at `src` to `dst` (one zstd chunk at a time, as
/// `tortwin synth` writes), each message through `edit`, which may change it
/// or leave it out (`false`).
pub fn copy_recording(src: &Path, dst: &Path, mut edit: impl FnMut(&mut Msg) -> bool) {
    let msgs: Vec<Msg> = read_messages(src)
        .into_iter()
        .filter_map(|mut m| edit(&mut m).then_some(m))
        .collect();
    write_recording(dst, &msgs, Layout::OneChunk);
}

/// The section of the reader's tests: 600 m of tangent track, rails `left`
/// and `right`, applicator A1 at 10 m, sites M1 at 60 m and M2 at 210 m,
/// and an extra field the reader must ignore.
pub fn section() -> Value {
    json!({
        "section_id": "test-600",
        "length_m": 600.0,
        "rails": ["left", "right"],
        "curve_radius_m": null,
        "rail_head_radius_m": 0.3,
        "nominal_wheel_diameter_m": 0.92,
        "applicators": [
            {"id": "A1", "position_m": 10.0, "rails": ["left", "right"], "nominal_pulse_g": 0.2}
        ],
        "measurement_sites": [
            {"id": "M1", "position_m": 60.0},
            {"id": "M2", "position_m": 210.0}
        ],
        "operator_note": "unknown extra fields are ignored"
    })
}

/// An axle of [`section`]'s trains.
pub fn axle(offset_m: f64, bogie_position: &str) -> Value {
    json!({
        "offset_m": offset_m,
        "bogie_position": bogie_position,
        "wheel_diameter_m": 0.92,
        "wheel_load_kN": {"left": 100.0, "right": 98.0},
        "creepage": {
            "left": {"cx": 0.01, "cy": 0.0, "spin_per_m": 0.1},
            "right": {"cx": -0.01, "cy": 0.002, "spin_per_m": -0.1}
        }
    })
}
