//! A short campaign (the one CI runs): 2 000 mutants of every target, no
//! finding. The long runs are in the README.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// this file's helpers are test code too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use std::process::Command;

#[test]
fn a_short_campaign_finds_nothing() {
    let out = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_tortwin-fuzz"))
        .args(["--runs", "2000", "--jobs", "2", "--seed", "7", "--out"])
        .arg(out.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stdout}\n{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("summary.json")).unwrap())
            .unwrap();
    for target in ["mcap", "messages", "config", "state", "csv", "values"] {
        let s = &summary[target];
        assert_eq!(s["executions"], 2000, "{target}: {s}");
        assert_eq!(s["findings"], 0, "{target}: {s}");
        let (accepted, rejected) = (
            s["accepted"].as_u64().unwrap(),
            s["rejected"].as_u64().unwrap(),
        );
        assert_eq!(accepted + rejected, 2000, "{target}: {s}");
        // Mutants that still replay and mutants that are refused: both
        // paths are exercised.
        assert!(accepted >= 100 && rejected >= 100, "{target}: {s}");
    }
    assert!(!out.path().join("findings").exists());
}
