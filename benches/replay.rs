//! End-to-end replay throughput with the outputs on: the reference
//! recordings of tests/reference/recordings read from MCAP, stepped,
//! and written to MCAP and rerun files; and issue 16's case, three days of
//! the synthetic 600 m curve (`tortwin synth --days 3 --trains-per-day 56`,
//! seed 1: about 5 M contacts) with the MCAP output only; and issue 45's
//! comparison of a line with a section under the same freight traffic
//! (the 10 km example line for 2 days, the 1.5 km curve for 8), MCAP out.
//! Reported as contacts per second.
//! Peak memory is measured by scripts/bench-memory.sh (criterion cannot).
//!
//! `cargo bench --bench replay`

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use tortwin_jobs::replay::{replay, ReplayArgs};

fn args(recording: PathBuf, out: &std::path::Path) -> ReplayArgs {
    ReplayArgs {
        out_mcap: Some(out.join("bench.mcap")),
        out_rrd: Some(out.join("bench.rrd")),
        ..ReplayArgs::new(recording)
    }
}

fn replay_with_outputs(c: &mut Criterion) {
    // As the command line: this thread is one of rayon's.
    tortwin_jobs::join_rayon_pool();
    let mut group = c.benchmark_group("replay");
    group.sample_size(10);
    let out = tempfile::tempdir().expect("a temporary directory");
    for name in ["tangent_day", "curve_2day"] {
        let recording = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("tests/reference/recordings")
            .join(format!("{name}.mcap"));
        let a = args(recording, out.path());
        let contacts = replay(&a, None, &mut [], &tortwin_study::Silent)
            .expect("the reference recording replays")
            .summary
            .contacts;
        group.throughput(Throughput::Elements(contacts));
        group.bench_function(format!("{name}_mcap_and_rrd_out"), |b| {
            b.iter(|| replay(&a, None, &mut [], &tortwin_study::Silent).expect("replays"))
        });
    }
    // Issue 16's yardstick: 3 days on the 600 m curve, MCAP out.
    let recording = out.path().join("curve_3day.mcap");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_tortwin"))
        .args([
            "synth",
            "--days",
            "3",
            "--trains-per-day",
            "56",
            "--seed",
            "1",
            "-q",
            "--out",
        ])
        .arg(&recording)
        .status()
        .expect("tortwin synth runs");
    assert!(status.success(), "tortwin synth failed");
    let a = ReplayArgs {
        out_mcap: Some(out.path().join("bench.mcap")),
        ..ReplayArgs::new(recording)
    };
    let contacts = replay(&a, None, &mut [], &tortwin_study::Silent)
        .expect("replays")
        .summary
        .contacts;
    group.throughput(Throughput::Elements(contacts));
    group.bench_function("curve_3day_mcap_out", |b| {
        b.iter(|| replay(&a, None, &mut [], &tortwin_study::Silent).expect("replays"))
    });
    // Issue 45's comparison: a line's contacts per second against a
    // section's, the same freight traffic (40 trains a day, seed 1), MCAP
    // out, in one run of one binary: the 10 km example line for 2 days
    // and the 1.5 km section for 8 (both about 70 M contacts).
    let here = env!("CARGO_MANIFEST_DIR");
    let layout = format!("{here}/docs/examples/line-10km.toml");
    for (name, days, shape) in [
        ("line_10km_2day_mcap_out", "2", ["--layout", layout.as_str()]),
        ("section_1500m_8day_mcap_out", "8", ["--length-m", "1500"]),
    ] {
        let recording = out.path().join(format!("{name}.mcap"));
        let status = std::process::Command::new(env!("CARGO_BIN_EXE_tortwin"))
            .args(["synth", "--days", days, "--passenger-share", "0"])
            .args(["--seed", "1", "-q"])
            .args(shape)
            .arg("--out")
            .arg(&recording)
            .status()
            .expect("tortwin synth runs");
        assert!(status.success(), "tortwin synth failed");
        let a = ReplayArgs {
            out_mcap: Some(out.path().join("bench.mcap")),
            ..ReplayArgs::new(recording)
        };
        let contacts = replay(&a, None, &mut [], &tortwin_study::Silent)
            .expect("replays")
            .summary
            .contacts;
        group.throughput(Throughput::Elements(contacts));
        group.bench_function(name, |b| {
            b.iter(|| replay(&a, None, &mut [], &tortwin_study::Silent).expect("replays"))
        });
    }
    group.finish();
}

criterion_group!(benches, replay_with_outputs);
criterion_main!(benches);
