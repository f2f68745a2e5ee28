//! Golden files: replaying each bundled recording (`recordings/*.mcap`) with
//! the default model gives the `/twin/measurement` values and the digest of
//! the `/twin/field` messages in `tests/golden/`. The golden files were
//! reviewed once; they guard behaviour from then on. Last blessed on
//! 2026-11-26, when m0 of eq. (1) became a constant of the product and the
//! bundled recordings were made again (recordings/README.md).
//!
//! Regenerating them is a deliberate act: `TORTWIN_BLESS=1 cargo test
//! --release --test golden`, with the reason in the commit message.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};
use tortwin_jobs::replay::{replay, ReplayArgs};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The measurement table and the field digest of one replay.
fn outputs(recording: &Path) -> (String, String) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.mcap");
    let args = ReplayArgs {
        out_mcap: Some(out.clone()),
        ..ReplayArgs::new(recording)
    };
    replay(&args, None, &mut [], &tortwin_study::Silent).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    let mut table =
        String::from("log_time_ns,site_id,rail,quantity,train_id,axle_index,measured,simulated\n");
    let mut digest = Sha256::new();
    let mut fields = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        match m.channel.topic.as_str() {
            "/twin/measurement" => {
                let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                let text = |k: &str| {
                    v.get(k).map_or(String::new(), |x| {
                        x.to_string().trim_matches('"').to_string()
                    })
                };
                writeln!(
                    table,
                    "{},{},{},{},{},{},{},{}",
                    m.log_time,
                    text("site_id"),
                    text("rail"),
                    text("quantity"),
                    text("train_id"),
                    text("axle_index"),
                    text("measured"),
                    text("simulated")
                )
                .unwrap();
            }
            "/twin/field" => {
                digest.update(m.log_time.to_le_bytes());
                digest.update(&m.data);
                fields += 1;
            }
            _ => {}
        }
    }
    let hex: String = digest
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    (
        table,
        format!("{fields} /twin/field messages, sha256 {hex}\n"),
    )
}

fn check(golden: &Path, got: &str) {
    if std::env::var_os("TORTWIN_BLESS").is_some() {
        std::fs::write(golden, got).unwrap();
        eprintln!("blessed {}", golden.display());
        return;
    }
    let want = std::fs::read_to_string(golden).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; make it deliberately with TORTWIN_BLESS=1",
            golden.display()
        )
    });
    if want != got {
        let (line, (w, g)) = want
            .lines()
            .zip(got.lines())
            .enumerate()
            .find(|(_, (w, g))| w != g)
            .unwrap_or((
                want.lines().count().min(got.lines().count()),
                ("<end>", "<end>"),
            ));
        panic!(
            "{} differs at line {}:\n  golden: {w}\n  now:    {g}",
            golden.display(),
            line + 1
        );
    }
}

#[test]
fn bundled_recordings_replay_to_their_golden_files() {
    let mut recordings: Vec<PathBuf> = std::fs::read_dir(root().join("recordings"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    recordings.sort();
    assert!(recordings.len() >= 3, "{recordings:?}");
    for recording in &recordings {
        let name = recording.file_stem().unwrap().to_string_lossy();
        let (table, digest) = outputs(recording);
        assert!(table.lines().count() > 1000, "{name}: too few measurements");
        check(
            &root().join(format!("tests/golden/{name}.measurements.csv")),
            &table,
        );
        check(
            &root().join(format!("tests/golden/{name}.field.txt")),
            &digest,
        );
    }
}
