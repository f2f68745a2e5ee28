//! Throughput of the stepping core: the paper's Figure 13 scenario scaled up
//! to 1000 wheel passes over a 3 km section (10 trains of 100 axles, 0.1 g
//! applied before every wheel, 100 kN, 1 % creepage), through the one
//! engine, with no output sink; and the same on a curve's two rails with a
//! pulse before every tenth axle, the rails rolled in parallel and side by
//! side on one thread (a replay's way beside its output threads). Reported
//! as contacts (wheel x grid point) per second.
//!
//! `cargo bench --bench stepping`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use tortwin_engine::sink::Sink;
use tortwin_engine::{Engine, EngineOptions};
use tortwin_model::config::ModelConfig;
use tortwin_recording::{
    Applicator, Axle, BogiePosition, Creepage, Direction, Event, EventKind, Passage, Pulse, Section,
};

const LENGTH_M: f64 = 3000.0;
const TRAINS: usize = 10;
const AXLES: usize = 100;
const AXLE_SPACING_M: f64 = 2.5;
const SPEED_MPS: f64 = 20.0;

struct Discard;
impl Sink for Discard {}

fn section(rails: usize) -> Section {
    Section {
        section_id: "bench".into(),
        length_m: LENGTH_M,
        rails: (0..rails).map(|r| format!("rail{r}")).collect(),
        curve_radius_m: None,
        rail_head_radius_m: 0.3,
        nominal_wheel_diameter_m: 0.92,
        applicators: vec![Applicator {
            id: "A".into(),
            position_m: 0.0,
            rails: (0..rails).collect(),
            nominal_pulse_kg: 1e-4,
        }],
        sites: Vec::new(),
    }
}

/// Trains of AXLES axles; a pulse lands just before every `pulse_every`-th
/// axle reaches d = 0.
fn events(rails: usize, pulse_every: usize) -> Vec<Event> {
    let mut events = Vec::new();
    let train_s = (LENGTH_M + AXLES as f64 * AXLE_SPACING_M) / SPEED_MPS;
    for k in 0..TRAINS {
        let t0_ns = 1_000_000_000_000 + (k as u64) * ((train_s + 60.0) * 1e9) as u64;
        let axles = (0..AXLES)
            .map(|a| Axle {
                offset_m: a as f64 * AXLE_SPACING_M,
                bogie_position: if a % 2 == 0 {
                    BogiePosition::Leading
                } else {
                    BogiePosition::Trailing
                },
                wheel_diameter_m: 0.92,
                wheel_load_n: vec![100e3; rails],
                creepage: vec![
                    Creepage {
                        cx: 0.01,
                        cy: 0.0,
                        spin_per_m: 0.0
                    };
                    rails
                ],
                segments: Vec::new(),
            })
            .collect();
        let passage = Event {
            log_time_ns: t0_ns,
            index_in_file: 0,
            kind: EventKind::Passage(Passage {
                train_id: format!("T{k}"),
                train_seq: k,
                direction: Direction::Up,
                speed_mps: SPEED_MPS,
                axles,
            }),
        };
        // The first pulse comes before the train, the others between axles.
        for a in 0..AXLES {
            let at_s = (a as f64 - 0.5) * AXLE_SPACING_M / SPEED_MPS;
            let log_time_ns = (t0_ns as f64 + at_s * 1e9) as u64;
            if a == 1 {
                events.push(passage.clone());
            }
            if a % pulse_every != 0 {
                continue;
            }
            for rail in 0..rails {
                events.push(Event {
                    log_time_ns,
                    index_in_file: 0,
                    kind: EventKind::Pulse(Pulse {
                        applicator: 0,
                        rail,
                        mass_kg: 1e-4,
                    }),
                });
            }
        }
    }
    events
}

fn run(section: &Section, cfg: &ModelConfig, opts: EngineOptions, events: &[Event]) -> u64 {
    let mut engine = Engine::new(section.clone(), cfg.clone(), opts, 0);
    let mut sink = Discard;
    for e in events {
        engine
            .push(e.clone(), &mut sink)
            .expect("valid synthetic events");
    }
    engine.finish(&mut sink, 0).expect("finishes").contacts
}

fn stepping(c: &mut Criterion) {
    let mut group = c.benchmark_group("stepping");
    group.sample_size(20);
    // A curve's two rails with a pulse before every tenth axle, the
    // replays' common case (the wheels pass the applicator in the
    // registers between pulses): the rails in parallel (no output files),
    // and side by side on one thread, as a replay beside its output
    // files' threads rolls them (`EngineOptions::beside_output_threads`).
    let beside = EngineOptions {
        beside_output_threads: true,
        ..EngineOptions::default()
    };
    for (name, config, rails, pulse_every, opts) in [
        ("paper_model", "", 1, 1, EngineOptions::default()),
        ("paper_model_two_rails", "", 2, 10, EngineOptions::default()),
        ("paper_model_two_rails_side_by_side", "", 2, 10, beside),
        (
            "all_effects",
            "[effects.rail_ageing]\ntau_s = 7200\n[effects.rain_washoff]\nk_per_mm = 0.5\n\
             [effects.temperature_consumption]\nbeta_per_k = 0.02\n[effects.speed_transfer]\nn = 1\n\
             [effects.wheel_edge_reservoir]\nalpha = 0.1\nr = 0.05\n",
            1,
            1,
            EngineOptions::default(),
        ),
    ] {
        let cfg = ModelConfig::from_overlay_str(config, "bench").expect("valid bench config");
        let section = section(rails);
        let events = events(rails, pulse_every);
        let contacts = run(&section, &cfg, opts, &events);
        group.throughput(Throughput::Elements(contacts));
        group.bench_function(format!("{name}_1000_passes_3km"), |b| b.iter(|| run(&section, &cfg, opts, &events)));
    }
    group.finish();
}

criterion_group!(benches, stepping);
criterion_main!(benches);
