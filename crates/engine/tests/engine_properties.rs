//! Properties of the engine on random traffic: whatever trains, pulses,
//! weather and effects come, masses stay in [0, m_max], mu in [muC, muD],
//! adhesion in [0, mu], and the mass balance (applied = on the rails + carried
//! out + consumed + squeezed out + lost to effects) closes to 1e-12. And
//! the tracks rolled as a wavefront, on one thread or several, end in the
//! same bits as the wheels rolled one at a time in the serial order.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// this file's helpers are test code too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use proptest::prelude::*;

use tortwin_engine::sink::{FieldSnapshot, Sink, WheelContacts};
use tortwin_engine::{Engine, EngineOptions};
use tortwin_model::config::ModelConfig;
use tortwin_recording::{
    Applicator, Axle, BogiePosition, Creepage, Direction, Event, EventKind, Passage, Pulse,
    Section, Weather,
};

#[derive(Debug, Clone)]
struct TrainSpec {
    gap_s: f64,
    down: bool,
    speed_mps: f64,
    axles: Vec<(f64, f64, f64, f64)>, // load kN, cx, cy, spin
    pulse_every: usize,
    pulse_g: f64,
    temperature_c: f64,
    rain_mm_h: f64,
}

fn train_spec() -> impl Strategy<Value = TrainSpec> {
    (
        10.0..20000.0f64,
        any::<bool>(),
        5.0..40.0f64,
        prop::collection::vec(
            (40.0..150.0f64, -0.02..0.02f64, -0.02..0.02f64, -1.0..1.0f64),
            1..12,
        ),
        1..4usize,
        0.0..0.5f64,
        -10.0..35.0f64,
        prop_oneof![Just(0.0), 0.0..8.0f64],
    )
        .prop_map(
            |(gap_s, down, speed_mps, axles, pulse_every, pulse_g, temperature_c, rain_mm_h)| {
                TrainSpec {
                    gap_s,
                    down,
                    speed_mps,
                    axles,
                    pulse_every,
                    pulse_g,
                    temperature_c,
                    rain_mm_h,
                }
            },
        )
}

fn section() -> Section {
    Section {
        section_id: "prop".into(),
        length_m: 120.0,
        rails: vec!["high".into(), "low".into()],
        curve_radius_m: Some(300.0),
        rail_head_radius_m: 0.3,
        nominal_wheel_diameter_m: 0.92,
        applicators: vec![
            Applicator {
                id: "A1".into(),
                position_m: 15.0,
                rails: vec![0, 1],
                nominal_pulse_kg: 1e-4,
            },
            Applicator {
                id: "A2".into(),
                position_m: 90.0,
                rails: vec![1],
                nominal_pulse_kg: 5e-5,
            },
        ],
        sites: Vec::new(),
    }
}

fn events(trains: &[TrainSpec]) -> Vec<Event> {
    events_on(trains, section().length_m)
}

/// The events of `trains` on a section `length_m` long (one train after
/// the other has left).
fn events_on(trains: &[TrainSpec], length_m: f64) -> Vec<Event> {
    let mut out = Vec::new();
    let mut t = 1_000.0;
    for (k, tr) in trains.iter().enumerate() {
        t += tr.gap_s;
        let ns = |s: f64| (s * 1e9) as u64;
        out.push(Event {
            log_time_ns: ns(t - 1.0),
            index_in_file: 0,
            kind: EventKind::Weather(Weather {
                air_temperature_c: tr.temperature_c,
                relative_humidity: 0.5,
                precipitation_mm_h: tr.rain_mm_h,
            }),
        });
        let axles: Vec<Axle> = tr
            .axles
            .iter()
            .enumerate()
            .map(|(a, &(load, cx, cy, spin))| Axle {
                offset_m: 2.5 * a as f64,
                bogie_position: if a % 2 == 0 {
                    BogiePosition::Leading
                } else {
                    BogiePosition::Trailing
                },
                wheel_diameter_m: 0.92,
                wheel_load_n: vec![load * 1e3, load * 0.9e3],
                creepage: vec![
                    Creepage {
                        cx,
                        cy,
                        spin_per_m: spin
                    };
                    2
                ],
                segments: Vec::new(),
            })
            .collect();
        let last = axles.last().map_or(0.0, |a| a.offset_m);
        out.push(Event {
            log_time_ns: ns(t),
            index_in_file: 0,
            kind: EventKind::Passage(Passage {
                train_id: format!("T{k}"),
                train_seq: k,
                direction: if tr.down {
                    Direction::Down
                } else {
                    Direction::Up
                },
                speed_mps: tr.speed_mps,
                axles,
            }),
        });
        // Pulses between axles at A1 on both rails and at A2 on low.
        for a in (0..tr.axles.len()).step_by(tr.pulse_every) {
            let at = t + (2.5 * a as f64 + 40.0) / tr.speed_mps;
            for (app, rail) in [(0, 0), (0, 1), (1, 1)] {
                out.push(Event {
                    log_time_ns: ns(at),
                    index_in_file: 0,
                    kind: EventKind::Pulse(Pulse {
                        applicator: app,
                        rail,
                        mass_kg: tr.pulse_g * 1e-3,
                    }),
                });
            }
        }
        t += (length_m + last) / tr.speed_mps;
    }
    out.sort_by_key(|e| e.log_time_ns);
    out
}

struct Check {
    mu_c: f64,
    mu_d: f64,
    m_max: f64,
}

impl Sink for Check {
    fn field(&mut self, f: &FieldSnapshot<'_>) -> tortwin_engine::sink::SinkResult {
        Ok(self.check(f)?)
    }
}

impl Check {
    fn check(&self, f: &FieldSnapshot<'_>) -> anyhow::Result<()> {
        for i in 0..f.d_m.len() {
            anyhow::ensure!(
                (self.mu_c..=self.mu_d).contains(&f.mu[i]),
                "mu {} at {}",
                f.mu[i],
                f.d_m[i]
            );
            anyhow::ensure!(
                f.adhesion[i] >= 0.0 && f.adhesion[i] <= f.mu[i] * (1.0 + 1e-12),
                "adhesion {}",
                f.adhesion[i]
            );
            anyhow::ensure!(
                (0.0..=self.m_max).contains(&f.rail_mass_kg[i]),
                "rail mass {}",
                f.rail_mass_kg[i]
            );
            anyhow::ensure!(
                f.wheel_mass_kg[i] >= 0.0,
                "wheel mass {}",
                f.wheel_mass_kg[i]
            );
        }
        Ok(())
    }
}

fn effects() -> impl Strategy<Value = String> {
    prop::collection::vec(any::<bool>(), 6).prop_map(|on| {
        let tables = [
            "[effects.rail_ageing]\ntau_s = 3000\n",
            "[effects.rain_washoff]\nk_per_mm = 0.7\n",
            "[effects.temperature_consumption]\nbeta_per_k = 0.04\n",
            "[effects.speed_transfer]\nn = 2\n",
            "[effects.wheel_edge_reservoir]\nalpha = 0.3\nr = 0.2\n",
            "[effects.bogie_bands]\n",
        ];
        on.iter()
            .zip(tables)
            .filter(|(on, _)| **on)
            .map(|(_, t)| t)
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn random_traffic_keeps_the_state_physical(trains in prop::collection::vec(train_spec(), 1..8), config in effects()) {
        let cfg = ModelConfig::from_overlay_str(&config, "prop").unwrap();
        let mut engine = Engine::new(section(), cfg.clone(), EngineOptions::default(), 0);
        let mut check = Check { mu_c: cfg.product.mu_c, mu_d: cfg.product.mu_d, m_max: cfg.product.m_max_kg };
        for e in events(&trains) {
            engine.push(e, &mut check).map_err(|e| TestCaseError::fail(format!("{e:#}")))?;
        }
        let summary = engine.finish(&mut check, 0).map_err(|e| TestCaseError::fail(format!("{e:#}")))?;
        let b = summary.mass_balance;
        prop_assert!(b.consumed_kg >= 0.0 && b.capped_kg >= 0.0 && b.carried_out_kg >= 0.0 && b.effects_lost_kg >= 0.0);
        prop_assert!(b.closing_error() < 1e-12, "{b:?}: {}", b.closing_error());
        for track in engine.tracks() {
            prop_assert!(track.rail_mass_kg.iter().all(|m| (0.0..=cfg.product.m_max_kg).contains(m)));
        }
    }
}

/// Rolls the events with `opts` on a rayon pool of `threads`; returns every
/// track's state and the mass balance, as bits.
fn rolled_bits(
    cfg: &ModelConfig,
    section: &Section,
    events: &[Event],
    opts: EngineOptions,
    threads: usize,
) -> Result<Vec<u64>, String> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| e.to_string())?;
    pool.install(|| {
        /// Every wheel's contacts, as bits, in the order they come.
        struct Wheels(Vec<u64>);
        impl Sink for Wheels {
            fn wheel_contacts(
                &mut self,
                w: &WheelContacts<'_>,
            ) -> tortwin_engine::sink::SinkResult {
                self.0
                    .extend([w.track as u64, w.rail as u64, w.axle as u64]);
                self.0.extend(w.seen_mass_kg.iter().map(|x| x.to_bits()));
                self.0
                    .extend(w.mu.iter().flat_map(|m| m.iter()).map(|x| x.to_bits()));
                Ok(())
            }
        }
        let mut wheels = Wheels(Vec::new());
        let mut engine = Engine::new(section.clone(), cfg.clone(), opts, 0);
        for e in events {
            engine
                .push(e.clone(), &mut wheels)
                .map_err(|e| format!("{e:#}"))?;
        }
        let b = engine
            .finish(&mut wheels, 0)
            .map_err(|e| format!("{e:#}"))?
            .mass_balance;
        let mut bits: Vec<u64> = [
            b.applied_kg,
            b.on_rail_end_kg,
            b.carried_out_kg,
            b.consumed_kg,
            b.capped_kg,
            b.effects_lost_kg,
        ]
        .iter()
        .map(|x| x.to_bits())
        .collect();
        for t in engine.tracks() {
            bits.push(t.wheel_pass);
            for v in [&t.rail_mass_kg, &t.last_touch_s, &t.precip_at_touch_mm] {
                bits.extend(v.iter().map(|x| x.to_bits()));
            }
        }
        bits.extend(wheels.0);
        Ok(bits)
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Long trains on a 1.2 km section, so that the tracks are rolled on
    /// two threads (each has well over the engine's minimum of contacts).
    #[test]
    fn threads_and_wavefront_give_the_serial_bits(
        trains in prop::collection::vec(train_spec(), 1..5),
        extra_axles in 8..40usize,
        config in effects(),
    ) {
        let cfg = ModelConfig::from_overlay_str(&config, "prop").unwrap();
        let mut section = section();
        section.length_m = 1200.0;
        let trains: Vec<TrainSpec> = trains
            .into_iter()
            .map(|mut t| {
                let first = t.axles[0];
                t.axles.extend(std::iter::repeat_n(first, extra_axles));
                t
            })
            .collect();
        let events = events_on(&trains, section.length_m);
        // One wheel at a time in the serial order (what a sink that wants a
        // field snapshot after every wheel gets), as the engine rolled
        // before the wavefront; every wheel's contacts are compared too.
        let serial = EngineOptions {
            snapshot_every_wheel: true,
            every_wheel_contacts: true,
            ..EngineOptions::default()
        };
        let contacts = EngineOptions { every_wheel_contacts: true, ..EngineOptions::default() };
        let run = |opts, threads| {
            rolled_bits(&cfg, &section, &events, opts, threads).map_err(TestCaseError::fail)
        };
        let reference = run(serial, 1)?;
        for threads in [1, 2] {
            let wavefront = run(contacts, threads)?;
            prop_assert!(reference == wavefront, "the wavefront on {} thread(s) differs", threads);
        }
        let beside = EngineOptions { beside_output_threads: true, ..contacts };
        prop_assert!(reference == run(beside, 2)?, "the tracks beside output threads differ");
        // Without the per-wheel calls: the same state and balance.
        let plain_reference = run(EngineOptions { every_wheel_contacts: false, ..serial }, 1)?;
        for threads in [1, 2] {
            let plain = run(EngineOptions::default(), threads)?;
            prop_assert!(plain_reference == plain, "the plain wavefront on {} thread(s) differs", threads);
        }
        // Carrying the tangents (contacts one by one, with the tangent
        // steps beside): the same masses, bit for bit.
        let tangents = run(EngineOptions { tangents: true, ..EngineOptions::default() }, 2)?;
        prop_assert!(plain_reference == tangents, "the replay with tangents differs");
    }
}
