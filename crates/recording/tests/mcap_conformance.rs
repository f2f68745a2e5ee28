//! The MCAP project's conformance files (mcap-conformance/README.md beside
//! this file) through tortwin's reader: every channel and message as the
//! suite says. That `tortwin replay` refuses each of them clearly is
//! tests/cli_replay.rs's.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// this file's helpers are test code too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use serde_json::Value;
use tortwin_recording::reader::RawMessages;

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mcap-conformance/data")
}

// Shared with the workspace's tests/cli_replay.rs.
#[path = "support/conformance.rs"]
#[allow(unreachable_pub)]
mod conformance;

fn conformance_files() -> Vec<PathBuf> {
    conformance::conformance_files(&data_dir())
}

/// A record's fields as a map (the JSON lists them as [name, value] pairs).
fn field<'a>(record: &'a Value, name: &str) -> &'a Value {
    record["fields"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f[0] == name)
        .map(|f| &f[1])
        .unwrap_or_else(|| panic!("no field {name} in {record}"))
}

fn int(v: &Value) -> u64 {
    v.as_str().unwrap().parse().unwrap()
}

fn bytes(v: &Value) -> Vec<u8> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|b| b.as_str().unwrap().parse().unwrap())
        .collect()
}

#[test]
fn every_conformance_file_reads_as_the_suite_says() {
    let files = conformance_files();
    assert_eq!(files.len(), 416, "the copied suite");
    let mut messages_checked = 0;
    for path in &files {
        let expected: Value =
            serde_json::from_str(&std::fs::read_to_string(path.with_extension("json")).unwrap())
                .unwrap();
        let records = expected["records"].as_array().unwrap();
        let mut want_channels: Vec<(u16, String, String)> = records
            .iter()
            .filter(|r| r["type"] == "Channel")
            .map(|r| {
                (
                    int(field(r, "id")) as u16,
                    field(r, "topic").as_str().unwrap().to_string(),
                    field(r, "message_encoding").as_str().unwrap().to_string(),
                )
            })
            .collect();
        want_channels.sort();
        want_channels.dedup();
        // (log_time, index in file order) sorts the file into replay order.
        let mut want_messages: Vec<(u64, usize, u16, u32, u64, Vec<u8>)> = records
            .iter()
            .filter(|r| r["type"] == "Message")
            .enumerate()
            .map(|(i, r)| {
                (
                    int(field(r, "log_time")),
                    i,
                    int(field(r, "channel_id")) as u16,
                    int(field(r, "sequence")) as u32,
                    int(field(r, "publish_time")),
                    bytes(field(r, "data")),
                )
            })
            .collect();
        want_messages.sort_by_key(|m| (m.0, m.1));

        let reader = RawMessages::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        // Channels in the summary only (rch) are not needed by a streaming
        // reader; every data-section channel must be there.
        let got_channels = reader.channels();
        for c in &got_channels {
            assert!(want_channels.contains(c), "{}: {c:?}", path.display());
        }
        let got: Vec<_> = reader
            .map(|m| m.unwrap_or_else(|e| panic!("{}: {e}", path.display())))
            .collect();
        assert_eq!(got.len(), want_messages.len(), "{}", path.display());
        for (k, (g, w)) in got.iter().zip(&want_messages).enumerate() {
            assert_eq!(
                (
                    g.log_time_ns,
                    g.channel_id,
                    g.sequence,
                    g.publish_time_ns,
                    &g.data
                ),
                (w.0, w.2, w.3, w.4, &w.5),
                "{} message {k}",
                path.display()
            );
            assert_eq!(g.index_in_file, w.1 as u64, "{}", path.display());
            assert!(
                got_channels.iter().any(|c| c.0 == g.channel_id),
                "{}: channel {}",
                path.display(),
                g.channel_id
            );
        }
        messages_checked += got.len();
    }
    // OneMessage, OneSchemalessMessage (1 each) and TenMessages (10) in
    // all their variants.
    assert!(messages_checked > 500, "{messages_checked}");
}
