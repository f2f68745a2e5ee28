//! `tortwin discover` end to end on a 3-day synthetic recording (written by
//! `tortwin synth`, seed 11, sigma 0.01) with `rail_ageing` (tau_s = 7200)
//! hidden in its truth: read the recording, replay it, fit every candidate
//! effect, cross-validate, select, and write the report. Two rounds of
//! candidates (the effect is found in the first, nothing passes in the
//! second), about 200 engine runs on the cores rayon finds.
//!
//! `cargo bench --bench discover`

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};

use tortwin::app::discover::{run, DiscoverArgs};

fn discover_3_days(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let recording = dir.path().join("rec.mcap");
    let status = Command::new(env!("CARGO_BIN_EXE_tortwin"))
        .args([
            "synth",
            "--days",
            "3",
            "--seed",
            "11",
            "--noise-sigma",
            "0.01",
        ])
        .args([
            "--rain-events-per-day",
            "1",
            "--hidden",
            "rail_ageing:tau_s=7200",
        ])
        .arg("--out")
        .arg(&recording)
        .arg("-q")
        .status()
        .expect("tortwin synth runs");
    assert!(status.success(), "tortwin synth failed");
    let args = DiscoverArgs {
        recording: recording.clone(),
        config: None,
        report: PathBuf::from(dir.path()).join("report"),
        bic_threshold: -10.0,
        min_excess_share: 0.25,
        unexplained_ratio: 1.1,
        threads: None,
        quiet: true,
    };
    let found = run(&args).expect("discover runs");
    assert_eq!(found.effects_found.len(), 1);
    eprintln!(
        "discover: {} engine runs, found {:?}",
        found.engine_runs, found.effects_found
    );

    let mut group = c.benchmark_group("discover");
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(180));
    group.bench_function("3_days_rail_ageing_hidden", |b| {
        b.iter(|| run(&args).expect("discover runs"))
    });
    group.finish();
}

criterion_group!(benches, discover_3_days);
criterion_main!(benches);
