//! Every input the fuzzer found (regressions/README.md) is refused with
//! its clear error (or, where the finding was a wrong result, replayed
//! with finite results: `(accepted)`), without a panic and without a huge
//! allocation.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// this file's helpers are test code too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use std::path::Path;
use std::sync::Arc;

use tortwin_fuzz::campaign::{judge, Verdict};
use tortwin_fuzz::meter::{Meter, FINDING_BYTES};
use tortwin_fuzz::seeds::Seeds;
use tortwin_fuzz::targets::{Kind, Target};

#[global_allocator]
static METER: Meter = Meter;

#[test]
fn every_finding_is_refused_clearly() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("regressions");
    let expected = std::fs::read_to_string(dir.join("expected.txt")).unwrap();
    let seeds = Arc::new(Seeds::make().unwrap());
    let mut checked = 0;
    for line in expected.lines().filter(|l| !l.trim().is_empty()) {
        let (file, want) = line.split_once('\t').unwrap();
        let kind = match file.split('/').next().unwrap() {
            "mcap" => Kind::Mcap,
            "config" => Kind::Config,
            "state" => Kind::State,
            "csv" => Kind::Csv,
            "values" => Kind::Values,
            other => panic!("unknown target folder {other}"),
        };
        let target = Target::new(kind, Arc::clone(&seeds)).unwrap();
        let input = std::fs::read(dir.join(file)).unwrap();
        let (verdict, reading, _) = judge(&target, &input);
        match verdict {
            // An input that once broke a run and is now replayed whole.
            Verdict::Accepted if want == "(accepted)" => {}
            Verdict::Rejected(message) if want != "(accepted)" => {
                assert!(message.contains(want), "{file}: {message}")
            }
            other => panic!("{file}: {other:?}"),
        }
        assert!(
            reading.largest < FINDING_BYTES,
            "{file}: an allocation of {} bytes",
            reading.largest
        );
        checked += 1;
    }
    // Every file in the folders is listed.
    let files = ["mcap", "config", "state", "csv", "values"]
        .iter()
        .filter_map(|d| std::fs::read_dir(dir.join(d)).ok())
        .flatten()
        .count();
    assert_eq!(checked, files);
}
