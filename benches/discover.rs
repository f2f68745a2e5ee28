//! `tortwin discover` end to end on 3-day synthetic recordings (written by
//! `tortwin synth`, seed 11, sigma 0.01), with the full search space (every
//! named effect and the generic terms' screening): read the recording,
//! replay it, screen, fit the candidates, cross-validate, select, and write
//! the report. Two rounds of candidates each (the effect is found in the
//! first, nothing passes in the second), on the cores rayon finds.
//!
//! - `3_days_rail_ageing_hidden`: `rail_ageing` (tau_s = 7200) in the truth.
//! - `3_days_clogged_nozzle_hidden`: applicator A1 delivers 60 % of its
//!   logged mass from 2024-04-09T12:00Z on (a generic `pulse_mass` step).
//!
//! `cargo bench --bench discover`

use std::process::Command;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};

use tortwin_jobs::discover::{run, DiscoverArgs};

fn case(dir: &std::path::Path, name: &str, hidden: &str) -> DiscoverArgs {
    let recording = dir.join(format!("{name}.mcap"));
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
        .args(["--rain-events-per-day", "1", "--hidden", hidden])
        .arg("--out")
        .arg(&recording)
        .arg("-q")
        .status()
        .expect("tortwin synth runs");
    assert!(status.success(), "tortwin synth failed");
    let args = DiscoverArgs {
        recording,
        config: None,
        report: dir.join(format!("{name}-report")),
        bic_threshold: -10.0,
        min_excess_share: 0.25,
        unexplained_ratio: 1.1,
        no_calibrate: false,
        threads: None,
        quiet: true,
    };
    let found = run(&args).expect("discover runs");
    assert_eq!(found.effects_found.len(), 1, "{:?}", found.effects_found);
    eprintln!(
        "discover {name}: {} engine runs in {:.1} s, found {}",
        found.engine_runs,
        found.elapsed_s,
        found.effects_found[0].text()
    );
    args
}

fn discover_3_days(c: &mut Criterion) {
    // As the command line: this thread is one of rayon's.
    tortwin_jobs::join_rayon_pool();
    let dir = tempfile::tempdir().expect("a temporary directory");
    let ageing = case(dir.path(), "ageing", "rail_ageing:tau_s=7200");
    let nozzle = case(
        dir.path(),
        "nozzle",
        "generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,\
         t0_utc=2024-04-09T12:00:00Z,f=0.6",
    );

    let mut group = c.benchmark_group("discover");
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(300));
    group.bench_function("3_days_rail_ageing_hidden", |b| {
        b.iter(|| run(&ageing).expect("discover runs"))
    });
    group.bench_function("3_days_clogged_nozzle_hidden", |b| {
        b.iter(|| run(&nozzle).expect("discover runs"))
    });
    group.finish();
}

/// `tortwin calibrate` end to end on the first case of tests/calibrate.rs
/// (`mu_d` 0.52 and `kc` 0.80 on the curve, 3 days, seed 31), and what its
/// Jacobians cost: one replay of the recording, plain and with the
/// tangents of the ten state constants.
fn calibrate_3_days(c: &mut Criterion) {
    use tortwin_discover::data::Dataset;
    use tortwin_jobs::discover::{calibrate, CalibrateArgs};
    use tortwin_model::config::ModelConfig;
    use tortwin_model::effects::Named;
    use tortwin_model::tangent::{EffectParam, STATE_KEYS};
    tortwin_jobs::join_rayon_pool();
    let dir = tempfile::tempdir().expect("a temporary directory");
    let truth = dir.path().join("truth.toml");
    std::fs::write(&truth, "[product]\nmu_d = 0.52\nkc = 0.80\n").expect("written");
    let recording = dir.path().join("site.mcap");
    let status = Command::new(env!("CARGO_BIN_EXE_tortwin"))
        .args(["synth", "--days", "3", "--preset", "curve", "--seed", "31"])
        .args(["--noise-sigma", "0.01", "--rain-events-per-day", "1"])
        .arg("--truth-config")
        .arg(&truth)
        .arg("--out")
        .arg(&recording)
        .arg("-q")
        .status()
        .expect("tortwin synth runs");
    assert!(status.success(), "tortwin synth failed");
    let data = Dataset::read(&recording).expect("the recording reads");
    let cfg = ModelConfig::default();
    let args = CalibrateArgs {
        recording: recording.clone(),
        config: None,
        report: dir.path().join("report"),
        threads: None,
        quiet: true,
    };
    let found = calibrate(&args).expect("calibrate runs");
    eprintln!(
        "calibrate: {} replays and {} with tangents, {:.1} run-equivalents in {:.1} s",
        found.engine_runs,
        found.tangent_runs(),
        found.run_equivalents,
        found.elapsed_s
    );
    let mut group = c.benchmark_group("calibrate");
    group.sample_size(10);
    group.bench_function("replay_3_days", |b| {
        b.iter(|| data.simulate(&cfg).expect("replays"))
    });
    group.bench_function("replay_3_days_with_tangents", |b| {
        b.iter(|| {
            data.simulate_with_tangents(&cfg, &STATE_KEYS, &[])
                .expect("replays")
        })
    });
    // Two effects on, their parameters in the tangents' effect slots.
    let mut with_effects = cfg.clone();
    with_effects.effects.set(Named::RailAgeing, &[7200.0]);
    with_effects
        .effects
        .set(Named::TemperatureConsumption, &[0.05]);
    let followed = [
        EffectParam::Named {
            effect: Named::RailAgeing,
            param: 0,
        },
        EffectParam::Named {
            effect: Named::TemperatureConsumption,
            param: 0,
        },
    ];
    group.bench_function("replay_3_days_with_effects", |b| {
        b.iter(|| data.simulate(&with_effects).expect("replays"))
    });
    group.bench_function("replay_3_days_with_effect_tangents", |b| {
        b.iter(|| {
            data.simulate_with_tangents(&with_effects, &STATE_KEYS, &followed)
                .expect("replays")
        })
    });
    group.bench_function("calibrate_3_days_mu_d_kc", |b| {
        b.iter(|| calibrate(&args).expect("calibrate runs"))
    });
    group.finish();
}

criterion_group!(benches, calibrate_3_days, discover_3_days);
criterion_main!(benches);
