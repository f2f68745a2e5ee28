//! Strategies evaluated per second on a one-day recording (the bundled
//! `recordings/demo_day.mcap`: 40 trains, 2808 axles, 600 m curve, two
//! rails, 1.17 M wheel contacts per evaluation): one strategy on one core,
//! and the 288 strategies of the default space on every core rayon finds
//! (the default `tortwin strategy` search, without the report).
//!
//! `cargo bench --bench strategy`; strategies/s is the "elements" throughput.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use tortwin_model::config::ModelConfig;
use tortwin_strategy::search::{Method, Searcher, Space, SpaceConfig};
use tortwin_strategy::{evaluate, Plan, Strategy, Target, Traffic};

fn strategies_per_second(c: &mut Criterion) {
    // As the command line: this thread is one of rayon's.
    tortwin_jobs::join_rayon_pool();
    let traffic = Traffic::read(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/recordings/demo_day.mcap"
    )))
    .expect("the bundled recording");
    let cfg = ModelConfig::default();
    let target = Target::default();
    let mut group = c.benchmark_group("strategy_demo_day");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(10));

    group.throughput(Throughput::Elements(1));
    let one = Plan::Strategy(Strategy {
        pulse_kg: 0.3e-3,
        every_axles: 3,
        positions_m: vec![10.0, 300.0],
        rails: vec![0, 1],
    });
    group.bench_function("one_strategy_one_core", |b| {
        b.iter(|| evaluate(&traffic, &cfg, &target, &one, false, None).expect("evaluates"))
    });

    let space = Space::new(&SpaceConfig::around_today(&traffic), &traffic).expect("a space");
    group.throughput(Throughput::Elements(space.size() as u64));
    group.bench_function("default_space_grid_all_cores", |b| {
        b.iter(|| {
            let searcher = Searcher::new(&traffic, &cfg, &target, &space, &|_| Ok(()));
            searcher.run(Method::Grid, 0).expect("searches");
            searcher.evaluations()
        })
    });
    group.finish();
}

criterion_group!(benches, strategies_per_second);
criterion_main!(benches);
