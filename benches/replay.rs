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

use std::path::{Path, PathBuf};

use criterion::measurement::WallTime;
use criterion::{criterion_group, criterion_main, BenchmarkGroup, Criterion, Throughput};

use tortwin_jobs::replay::{replay, ReplayArgs};

fn args(recording: PathBuf, out: &Path) -> ReplayArgs {
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
        bench_replay(&mut group, &format!("{name}_mcap_and_rrd_out"), &a);
    }
    // Issue 16's yardstick: 3 days on the 600 m curve, MCAP out.
    let curve = ["--days", "3", "--trains-per-day", "56", "--seed", "1"];
    synthetic(&mut group, out.path(), "curve_3day_mcap_out", &curve);
    // Issue 45's comparison: a line's contacts per second against a
    // section's, the same freight traffic (40 trains a day, seed 1), MCAP
    // out, in one run of one binary: the 10 km example line for 2 days
    // and the 1.5 km section for 8 (70 and 42 M contacts).
    let layout = format!(
        "{}/docs/examples/line-10km.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let freight = ["--passenger-share", "0", "--seed", "1"];
    let line = [&freight[..], &["--days", "2", "--layout", &layout]].concat();
    synthetic(&mut group, out.path(), "line_10km_2day_mcap_out", &line);
    let section = [&freight[..], &["--days", "8", "--length-m", "1500"]].concat();
    synthetic(
        &mut group,
        out.path(),
        "section_1500m_8day_mcap_out",
        &section,
    );
    group.finish();
}

/// `tortwin synth` with `synth_args` into `out`, and that recording's
/// replay with MCAP out benchmarked as `name`.
fn synthetic(
    group: &mut BenchmarkGroup<'_, WallTime>,
    out: &Path,
    name: &str,
    synth_args: &[&str],
) {
    let recording = out.join(format!("{name}.mcap"));
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_tortwin"))
        .arg("synth")
        .args(synth_args)
        .args(["-q", "--out"])
        .arg(&recording)
        .status()
        .expect("tortwin synth runs");
    assert!(status.success(), "tortwin synth failed");
    let a = ReplayArgs {
        out_mcap: Some(out.join("bench.mcap")),
        ..ReplayArgs::new(recording)
    };
    bench_replay(group, name, &a);
}

/// The replay of `a` benchmarked as `name`, its throughput in contacts.
fn bench_replay(group: &mut BenchmarkGroup<'_, WallTime>, name: &str, a: &ReplayArgs) {
    let contacts = replay(a, None, &mut [], &tortwin_study::Silent)
        .expect("the recording replays")
        .summary
        .contacts;
    group.throughput(Throughput::Elements(contacts));
    group.bench_function(name, |b| {
        b.iter(|| replay(a, None, &mut [], &tortwin_study::Silent).expect("replays"))
    });
}

criterion_group!(benches, replay_with_outputs);
criterion_main!(benches);
