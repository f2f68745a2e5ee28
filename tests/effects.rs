//! The candidate effects of docs/spec/effects.md inside the engine.
//!
//! 1. Wiring: on a section of two grid points each effect acts at its step
//!    of "one contact" (or of a pulse, or of a reading), checked against a
//!    hand calculation.
//! 2. Direction: replaying a reference recording with the effect on moves the
//!    simulated values the way effects.md says the effect shows in residuals.

use std::collections::HashMap;
use std::path::PathBuf;

use tortwin_engine::{Engine, EngineOptions};
use tortwin_jobs::replay::{replay, ReplayArgs};
use tortwin_model::config::ModelConfig;
use tortwin_model::{contact, product};
use tortwin_recording::{
    Applicator, Axle, AxleRef, BogiePosition, Creepage, Direction, Event, EventKind, Measured,
    Measurement, Passage, Pulse, Quantity, RecordingReader, Section, Site, Weather,
};

mod common;
use common::{MeasurementRow, Recorder};

// ---------------------------------------------------------------- wiring

const S: u64 = 1_000_000_000;

/// Two grid points (d = 0 and 2.89 m); the applicator at 0 on every rail;
/// site M0 at point 0 and M1 at point 1.
fn tiny_section(rails: &[&str]) -> Section {
    Section {
        section_id: "tiny".into(),
        length_m: 5.0,
        rails: rails.iter().map(|r| r.to_string()).collect(),
        curve_radius_m: None,
        rail_head_radius_m: 0.3,
        nominal_wheel_diameter_m: 0.92,
        applicators: vec![Applicator {
            id: "A".into(),
            position_m: 0.0,
            rails: (0..rails.len()).collect(),
            nominal_pulse_kg: 1e-4,
        }],
        sites: vec![
            Site {
                id: "M0".into(),
                position_m: 0.0,
            },
            Site {
                id: "M1".into(),
                position_m: 2.9,
            },
        ],
    }
}

fn ev(t_s: u64, kind: EventKind) -> Event {
    Event {
        log_time_ns: t_s * S,
        index_in_file: t_s,
        kind,
    }
}

fn pulse(t_s: u64, rail: usize, mass_kg: f64) -> Event {
    ev(
        t_s,
        EventKind::Pulse(Pulse {
            applicator: 0,
            rail,
            mass_kg,
        }),
    )
}

fn reading(t_s: u64, site: usize, rail: usize) -> Event {
    ev(
        t_s,
        EventKind::Measurement(Measurement {
            site,
            rail,
            of: Measured::RailMu,
            value: 0.0,
        }),
    )
}

fn weather(t_s: u64, air_temperature_c: f64, precipitation_mm_h: f64) -> Event {
    ev(
        t_s,
        EventKind::Weather(Weather {
            air_temperature_c,
            relative_humidity: 0.5,
            precipitation_mm_h,
        }),
    )
}

/// One train of `bogies.len()` axles (2 m apart) on every rail: 100 kN, cx = 1 %.
fn train(t_s: u64, rails: usize, speed_mps: f64, bogies: &[BogiePosition]) -> Event {
    ev(
        t_s,
        EventKind::Passage(Passage {
            train_id: format!("T{t_s}"),
            train_seq: 0,
            direction: Direction::Up,
            speed_mps,
            axles: bogies
                .iter()
                .enumerate()
                .map(|(k, &bogie_position)| Axle {
                    offset_m: 2.0 * k as f64,
                    bogie_position,
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
                .collect(),
        }),
    )
}

fn mu_of(t_s: u64, train_at_s: u64, site: usize, rail: usize, axle_index: usize) -> Event {
    ev(
        t_s,
        EventKind::Measurement(Measurement {
            site,
            rail,
            of: Measured::Mu(AxleRef {
                train_id: format!("T{train_at_s}").into(),
                train_seq: 0,
                axle_index,
            }),
            value: 0.0,
        }),
    )
}

fn run(section: Section, config: &str, events: Vec<Event>) -> Vec<f64> {
    let cfg = ModelConfig::from_overlay_str(config, "test").unwrap();
    let mut engine = Engine::new(section, cfg, EngineOptions::default(), 0);
    let mut sink = Recorder::default();
    for e in events {
        engine.push(e, &mut sink).unwrap();
    }
    engine.finish(&mut sink, 0).unwrap();
    sink.simulated()
}

fn table2() -> product::ProductParams {
    ModelConfig::default().product
}

fn mu(m_kg: f64) -> f64 {
    let p = table2();
    p.mu_c + (p.mu_d - p.mu_c) * (-m_kg / p.km_kg).exp()
}

fn close(got: f64, want: f64) {
    assert!(
        (got - want).abs() <= 1e-12 * want.abs(),
        "got {got}, hand calculation {want}"
    );
}

#[test]
fn rail_ageing_acts_on_pulses_and_readings() {
    // Pulse 0.1 g at 10 s; another at 3610 s (one tau later); read at 7210 s.
    let events = vec![
        pulse(10, 0, 1e-4),
        pulse(3610, 0, 1e-4),
        reading(7210, 0, 0),
    ];
    let got = run(
        tiny_section(&["r"]),
        "[effects.rail_ageing]\ntau_s = 3600\n",
        events.clone(),
    );
    let e1 = (-1.0f64).exp();
    close(got[0], mu((1e-4 * e1 + 1e-4) * e1));
    // Off: no loss.
    close(run(tiny_section(&["r"]), "", events)[0], mu(2e-4));
}

#[test]
fn rain_washoff_follows_accumulated_precipitation() {
    // 3.6 mm/h from 0 s, dry from 600 s: a pulse at 100 s sees 0.5 mm by 1100 s.
    let events = vec![
        weather(0, 15.0, 3.6),
        pulse(100, 0, 1e-4),
        weather(600, 15.0, 0.0),
        reading(1100, 0, 0),
    ];
    let got = run(
        tiny_section(&["r"]),
        "[effects.rain_washoff]\nk_per_mm = 2.0\n",
        events,
    );
    close(got[0], mu(1e-4 * (-2.0f64 * 3.6 * 500.0 / 3600.0).exp()));
}

/// The wheel after its first contact at point 0 (where it passes the
/// applicator, N = 1) with 0.1 g on the rail, by hand from eq. (1)–(6);
/// `transfer_factor` and `consumption_factor` are the effects' factors.
fn wheel_after_first_contact(transfer_factor: f64, consumption_factor: f64) -> f64 {
    wheel_after(1e-4, 1e-4, transfer_factor, consumption_factor)
}

/// [`wheel_after_first_contact`] with `m_kg` on the rail and `m0_kg` the
/// configuration's m0 (a constant of the product, model.md).
fn wheel_after(m_kg: f64, m0_kg: f64, transfer_factor: f64, consumption_factor: f64) -> f64 {
    let p = table2();
    let steel = contact::Steel {
        e_pa: 210e9,
        nu: 0.3,
    };
    let pm = contact::hertz(100e3, 0.46, f64::INFINITY, 0.3, &steel).pm_pa;
    // cx = 1 %, the reference creepage of eq. (3): fc = 1.
    let fp_fc = 1.0 + p.kp * (pm / 1178e6 - 1.0);
    let m = m_kg;
    let t = (p.kt * (1.0 - (-m / p.cm_kg).exp()) * transfer_factor).min(0.5);
    let wheel = t * m;
    let c = ((p.k0_kg + p.km1_kg * (1.0 - (-m / (m0_kg * p.km2)).exp()) * fp_fc)
        * consumption_factor)
        .min(m);
    wheel * (m - c) / m
}

#[test]
fn temperature_consumption_scales_the_whole_consumption() {
    // 30 °C, beta 0.05: c times e^0.5. M1 (point 1, clean rail) sees the wheel alone.
    let events = |cfg: &str| {
        let e = vec![
            weather(0, 30.0, 0.0),
            pulse(10, 0, 1e-4),
            train(100, 1, 20.0, &[BogiePosition::Leading]),
        ];
        let mut e = e;
        e.push(mu_of(101, 100, 1, 0, 0));
        run(tiny_section(&["r"]), cfg, e)[0]
    };
    let on = events("[effects.temperature_consumption]\nbeta_per_k = 0.05\n");
    assert!((on - mu(wheel_after_first_contact(1.0, 0.5f64.exp()))).abs() < 1e-12);
    let off = events("");
    assert!((off - mu(wheel_after_first_contact(1.0, 1.0))).abs() < 1e-12);
    // More consumption when warm: less product, higher mu.
    assert!(on > off);
}

#[test]
fn speed_transfer_scales_the_transfer_before_its_clamp() {
    let at = |speed: f64, cfg: &str| {
        let e = vec![
            pulse(10, 0, 1e-4),
            train(100, 1, speed, &[BogiePosition::Leading]),
            mu_of(101, 100, 1, 0, 0),
        ];
        run(tiny_section(&["r"]), cfg, e)[0]
    };
    let cfg = "[effects.speed_transfer]\nn = 1.0\n";
    // 40 m/s: t halves; 5 m/s: t x 4, clamped at 0.5.
    assert!((at(40.0, cfg) - mu(wheel_after_first_contact(0.5, 1.0))).abs() < 1e-12);
    assert!((at(5.0, cfg) - mu(wheel_after_first_contact(4.0, 1.0))).abs() < 1e-12);
    assert!((at(20.0, cfg) - at(20.0, "")).abs() < 1e-15);
}

#[test]
fn wheel_edge_reservoir_parks_product_after_the_contact() {
    let (alpha, r) = (0.3, 0.1);
    let cfg = format!("[effects.wheel_edge_reservoir]\nalpha = {alpha}\nr = {r}\n");
    let e = vec![
        pulse(10, 0, 1e-4),
        train(100, 1, 20.0, &[BogiePosition::Leading]),
        mu_of(101, 100, 1, 0, 0),
    ];
    let got = run(tiny_section(&["r"]), &cfg, e)[0];
    // Step 6 at point 0: alpha m_w to the edge, then r of it back.
    let w = wheel_after_first_contact(1.0, 1.0);
    let parked = alpha * w;
    let back = r * parked;
    assert!((got - mu(w - parked + back)).abs() < 1e-12);
}

#[test]
fn bogie_bands_split_the_high_rail() {
    let cfg = "[effects.bogie_bands]\n";
    let e = vec![
        pulse(10, 0, 1e-4),
        pulse(10, 1, 1e-4),
        reading(20, 0, 0),
        reading(20, 0, 1),
        train(
            100,
            2,
            20.0,
            &[BogiePosition::Leading, BogiePosition::Trailing],
        ),
        // Axle 0 (leading) at M0 on high: the gauge-corner band's half pulse.
        mu_of(101, 100, 0, 0, 0),
        // Axle 1 (trailing) at M0 on high: the top band, untouched by axle 0.
        mu_of(101, 100, 0, 0, 1),
        // Axle 1 at M0 on low: behind axle 0 on the same single band.
        mu_of(101, 100, 0, 1, 1),
    ];
    let got = run(tiny_section(&["high", "low"]), cfg, e.clone());
    close(got[0], mu(0.5e-4)); // tribometer on high reads the top band
    close(got[1], mu(1e-4)); // low has one band
    close(got[2], mu(0.5e-4));
    close(got[3], mu(0.5e-4));
    let plain = run(tiny_section(&["high", "low"]), "", e);
    // Without bands the trailing axle on high sees what the leading one left,
    // exactly like low; with bands it sees a fresh band.
    close(plain[3], plain[4]);
    assert_eq!(got[4], plain[4], "the low rail does not change");
    assert!(got[3] != plain[3]);
    // Without a rail named high the effect does nothing.
    let tangent = vec![pulse(10, 0, 1e-4), reading(20, 0, 0)];
    assert_eq!(
        run(tiny_section(&["left", "right"]), cfg, tangent.clone()),
        run(tiny_section(&["left", "right"]), "", tangent)
    );
}

// ------------------------------------------------------- generic terms

/// A `[[effects.generic]]` table from `key = value` pairs (strings quoted).
fn term(pairs: &[(&str, &str)]) -> String {
    let mut t = "[[effects.generic]]\n".to_string();
    for (k, v) in pairs {
        if v.parse::<f64>().is_ok() {
            t.push_str(&format!("{k} = {v}\n"));
        } else {
            t.push_str(&format!("{k} = \"{v}\"\n"));
        }
    }
    t
}

#[test]
fn generic_pulse_mass_scales_the_landing_mass_only() {
    // A time step at 1800 s: the pulse at 10 s lands whole, the one at
    // 3610 s at f = 0.5; the reading at 3700 s sees 0.1 + 0.05 g.
    let step = term(&[
        ("acts_on", "pulse_mass"),
        ("applicator", "A"),
        ("driver", "time"),
        ("form", "step"),
        ("t0_utc", "1970-01-01T00:30:00Z"),
        ("f", "0.5"),
    ]);
    let events = vec![
        pulse(10, 0, 1e-4),
        pulse(3610, 0, 1e-4),
        reading(3700, 0, 0),
    ];
    close(run(tiny_section(&["r"]), &step, events)[0], mu(1.5e-4));
    // Linear in air temperature: 30 °C with gamma 0.1 doubles the pulse
    // that lands (0.025 -> 0.05 g); m0 of eq. (1), which the consumption of
    // the first contact sees, stays the configuration's 0.1 g (model.md).
    let linear = term(&[
        ("acts_on", "pulse_mass"),
        ("driver", "air_temperature_c"),
        ("form", "linear"),
        ("gamma", "0.1"),
    ]);
    let e = vec![
        weather(0, 30.0, 0.0),
        pulse(10, 0, 0.25e-4),
        train(100, 1, 20.0, &[BogiePosition::Leading]),
        mu_of(101, 100, 1, 0, 0),
    ];
    let got = run(tiny_section(&["r"]), &linear, e)[0];
    let want = mu(wheel_after(0.5e-4, 1e-4, 1.0, 1.0));
    assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    // The m0 of the landing mass (the reading before 2026-11-26) is
    // another value: the test tells the two apart.
    assert!((want - mu(wheel_after(0.5e-4, 0.5e-4, 1.0, 1.0))).abs() > 1e-9);
    // A term scoped to another applicator or rail does nothing.
    let elsewhere = term(&[
        ("acts_on", "pulse_mass"),
        ("rail", "s"),
        ("driver", "air_temperature_c"),
        ("form", "linear"),
        ("gamma", "0.1"),
    ]);
    let e = vec![weather(0, 30.0, 0.0), pulse(10, 0, 1e-4), reading(20, 0, 0)];
    assert_eq!(
        run(tiny_section(&["r", "s"]), &elsewhere, e.clone()),
        run(tiny_section(&["r", "s"]), "", e)
    );
}

#[test]
fn generic_transfer_and_consumption_act_at_steps_3_and_4() {
    let at = |speed: f64, cfg: &str| {
        let e = vec![
            weather(0, 30.0, 0.0),
            pulse(10, 0, 1e-4),
            train(100, 1, speed, &[BogiePosition::Leading]),
            mu_of(101, 100, 1, 0, 0),
        ];
        run(tiny_section(&["r"]), cfg, e)[0]
    };
    // Transfer × linear in speed: 30 m/s, gamma -0.02: t × 0.8.
    let linear = term(&[
        ("acts_on", "transfer"),
        ("driver", "speed_mps"),
        ("form", "linear"),
        ("gamma", "-0.02"),
    ]);
    close(at(30.0, &linear), mu(wheel_after(1e-4, 1e-4, 0.8, 1.0)));
    // After speed_transfer's factor (n = 1 at 40 m/s: 0.5) and before the
    // clamp: 0.5 × 0.6.
    let both = format!("[effects.speed_transfer]\nn = 1.0\n{linear}");
    close(at(40.0, &both), mu(wheel_after(1e-4, 1e-4, 0.3, 1.0)));
    // speed_transfer is transfer × power of speed with n negated.
    let power = term(&[
        ("acts_on", "transfer"),
        ("driver", "speed_mps"),
        ("form", "power"),
        ("n", "-1.0"),
    ]);
    close(
        at(40.0, &power),
        at(40.0, "[effects.speed_transfer]\nn = 1.0\n"),
    );
    // temperature_consumption is consumption × exp of air temperature.
    let exp = term(&[
        ("acts_on", "consumption"),
        ("driver", "air_temperature_c"),
        ("form", "exp"),
        ("beta", "0.05"),
    ]);
    close(
        at(20.0, &exp),
        mu(wheel_after(1e-4, 1e-4, 1.0, 0.5f64.exp())),
    );
    close(
        at(20.0, &exp),
        at(
            20.0,
            "[effects.temperature_consumption]\nbeta_per_k = 0.05\n",
        ),
    );
    // Two terms on one quantity multiply: a step in humidity (0.5 >= 0.4:
    // f = 2) on top of the exp.
    let step = term(&[
        ("acts_on", "consumption"),
        ("driver", "relative_humidity"),
        ("form", "step"),
        ("x0", "0.4"),
        ("f", "2.0"),
    ]);
    close(
        at(20.0, &format!("{exp}{step}")),
        mu(wheel_after(1e-4, 1e-4, 1.0, 2.0 * 0.5f64.exp())),
    );
}

#[test]
fn generic_friction_levels_and_measurement_offsets() {
    let p = table2();
    let mu_with =
        |gd: f64, gc: f64, m: f64| p.mu_c * gc + (p.mu_d * gd - p.mu_c * gc) * (-m / p.km_kg).exp();
    // muD × step in time from 1000 s (f 0.9); muC × step in rain >= 1 mm/h (f 0.8).
    let cfg = format!(
        "{}{}",
        term(&[
            ("acts_on", "friction_dry"),
            ("driver", "time"),
            ("form", "step"),
            ("t0_utc", "1970-01-01T00:16:40Z"),
            ("f", "0.9"),
        ]),
        term(&[
            ("acts_on", "friction_boundary"),
            ("driver", "precipitation_mm_h"),
            ("form", "step"),
            ("x0", "1.0"),
            ("f", "0.8"),
        ])
    );
    let e = vec![
        pulse(10, 0, 1e-4),
        reading(500, 0, 0),
        reading(1500, 0, 0),
        weather(1600, 15.0, 2.0),
        reading(1700, 0, 0),
    ];
    let got = run(tiny_section(&["r"]), &cfg, e);
    close(got[0], mu_with(1.0, 1.0, 1e-4));
    close(got[1], mu_with(0.9, 1.0, 1e-4));
    close(got[2], mu_with(0.9, 0.8, 1e-4));
    // A wheel driver has no value at a reading: g = 1 there.
    let load = term(&[
        ("acts_on", "friction_dry"),
        ("driver", "wheel_load_kN"),
        ("form", "power"),
        ("n", "-0.2"),
    ]);
    let e = vec![pulse(10, 0, 1e-4), reading(500, 0, 0)];
    close(run(tiny_section(&["r"]), &load, e)[0], mu(1e-4));
    // At a contact it acts (100 kN = x_ref: g = 1; a heavier wheel: lower muD).
    // Offsets: what site M1 measures of mu, plus 0.02; rail_mu untouched.
    let offset = term(&[
        ("acts_on", "measurement"),
        ("site", "M1"),
        ("quantity", "mu"),
        ("offset", "0.02"),
    ]);
    let e = vec![
        pulse(10, 0, 1e-4),
        reading(20, 1, 0),
        train(100, 1, 20.0, &[BogiePosition::Leading]),
        mu_of(101, 100, 1, 0, 0),
    ];
    let with = run(tiny_section(&["r"]), &offset, e.clone());
    let without = run(tiny_section(&["r"]), "", e);
    assert_eq!(with[0], without[0], "rail_mu is not in the scope");
    assert_eq!(with[1], without[1] + 0.02);
}

/// model.md: the weather in effect at time t is the last weather message
/// with time <= t, whatever the replay position. A weather message sorts
/// after a pulse or a reading with the same log_time (topic order), yet it
/// is in effect at their time, between trains as during an occupation.
#[test]
fn weather_logged_at_the_same_instant_is_in_effect_for_pulses_and_readings() {
    let p = table2();
    // muD x 0.5 from 25 °C on; the pulse mass x 0.5 from 25 °C on.
    let cfg = format!(
        "{}{}",
        term(&[
            ("acts_on", "friction_dry"),
            ("driver", "air_temperature_c"),
            ("form", "step"),
            ("x0", "25.0"),
            ("f", "0.5"),
        ]),
        term(&[
            ("acts_on", "pulse_mass"),
            ("driver", "air_temperature_c"),
            ("form", "step"),
            ("x0", "25.0"),
            ("f", "0.5"),
        ])
    );
    let mu_half_dry = |m: f64| p.mu_c + (0.5 * p.mu_d - p.mu_c) * (-m / p.km_kg).exp();
    // Between trains, in replay order: a pulse and a reading at 60 s, then
    // the 30 °C message at 60 s: both are at 30 °C.
    let e = vec![
        pulse(60, 0, 1e-4),
        reading(60, 0, 0),
        weather(60, 30.0, 0.0),
        reading(70, 0, 0),
    ];
    let got = run(tiny_section(&["r"]), &cfg, e);
    close(got[0], mu_half_dry(0.5e-4));
    close(got[1], mu_half_dry(0.5e-4));
    // The same instant inside a train's occupation gives the same values.
    let e = vec![
        train(59, 1, 0.1, &[BogiePosition::Leading]),
        reading(60, 1, 0),
        weather(60, 30.0, 0.0),
    ];
    let inside = run(tiny_section(&["r"]), &cfg, e);
    close(inside[0], mu_half_dry(0.0));
}

/// A generic factor with no finite value at what the recording gives its
/// driver (a power of a temperature below 0 °C) is refused, naming the
/// term and the message, instead of emptying the rail with a NaN.
#[test]
fn a_factor_without_a_value_is_an_input_error_naming_the_term() {
    let cfg = ModelConfig::from_overlay_str(
        &term(&[
            ("acts_on", "consumption"),
            ("driver", "air_temperature_c"),
            ("form", "power"),
            ("n", "0.5"),
        ]),
        "test",
    )
    .unwrap();
    let mut engine = Engine::new(tiny_section(&["r"]), cfg, EngineOptions::default(), 0);
    let mut sink = Recorder::default();
    engine.push(pulse(10, 0, 1e-4), &mut sink).unwrap();
    let err = engine.push(weather(20, -3.0, 0.0), &mut sink).unwrap_err();
    assert!(err.is_input(), "{err}");
    let text = err.to_string();
    for part in [
        "effects.generic[0]",
        "air_temperature_c = -3",
        "/environment/weather",
        "log_time 20000000000",
    ] {
        assert!(text.contains(part), "{part} missing in: {text}");
    }
}

#[test]
fn generic_terms_with_g_one_change_nothing_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let neutral = [
        term(&[
            ("acts_on", "pulse_mass"),
            ("driver", "time"),
            ("form", "step"),
            ("t0_utc", "2020-01-01T00:00:00Z"),
            ("f", "1.0"),
        ]),
        term(&[
            ("acts_on", "pulse_mass"),
            ("driver", "relative_humidity"),
            ("form", "exp"),
            ("beta", "0.0"),
        ]),
        term(&[
            ("acts_on", "transfer"),
            ("driver", "speed_mps"),
            ("form", "power"),
            ("n", "0.0"),
        ]),
        term(&[
            ("acts_on", "transfer"),
            ("driver", "air_temperature_c"),
            ("form", "linear"),
            ("gamma", "0.0"),
        ]),
        term(&[
            ("acts_on", "consumption"),
            ("driver", "creepage"),
            ("form", "power"),
            ("n", "0.0"),
        ]),
        term(&[
            ("acts_on", "consumption"),
            ("driver", "precipitation_mm_h"),
            ("form", "step"),
            ("x0", "0.5"),
            ("f", "1.0"),
        ]),
        term(&[
            ("acts_on", "friction_dry"),
            ("driver", "wheel_load_kN"),
            ("form", "exp"),
            ("beta", "0.0"),
        ]),
        term(&[
            ("acts_on", "friction_boundary"),
            ("rail", "low"),
            ("driver", "time"),
            ("form", "step"),
            ("t0_utc", "2020-01-01T00:00:00Z"),
            ("f", "1.0"),
        ]),
        term(&[("acts_on", "measurement"), ("offset", "0.0")]),
    ]
    .concat();
    let cfg = dir.path().join("neutral.toml");
    std::fs::write(&cfg, neutral).unwrap();
    let rec = curve_2day();
    let collect = |config: Option<PathBuf>| {
        let mut c = Recorder::default();
        let mut args = ReplayArgs::new(rec.clone());
        args.config = config.map(Into::into);
        replay(&args, None, &mut [&mut c], &tortwin_study::Silent).unwrap();
        c.measurements
            .iter()
            .map(|r| r.simulated.to_bits())
            .collect::<Vec<u64>>()
    };
    assert_eq!(collect(Some(cfg)), collect(None));
}

// ---------------------------------------------------------------- direction

/// A measurement's simulated value with what it needs for the diagnosis.
type Row = MeasurementRow;

fn curve_2day() -> PathBuf {
    common::reference_recording("curve_2day.mcap")
}

fn replay_with(config: &str) -> Recorder {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("c.toml");
    std::fs::write(&cfg, config).unwrap();
    let args = ReplayArgs {
        config: Some(cfg.into()),
        ..ReplayArgs::new(curve_2day())
    };
    let mut c = Recorder::default();
    replay(&args, None, &mut [&mut c], &tortwin_study::Silent).unwrap();
    c
}

/// Per mu measurement: (row, simulated with the effect minus without).
fn deltas(config: &str) -> (Recorder, Vec<(Row, f64)>) {
    let off = replay_with("");
    let on = replay_with(config);
    let d = on
        .measurements
        .iter()
        .zip(&off.measurements)
        .filter(|(a, _)| a.quantity == Quantity::Mu)
        .map(|(a, b)| (a.clone(), a.simulated - b.simulated))
        .collect();
    (on, d)
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n.max(1) as f64
}

/// Bogie position of each (train, axle), and the weather messages with their log_time.
type Facts = (HashMap<(String, usize), BogiePosition>, Vec<(u64, Weather)>);

/// Bogie positions and the weather of the recording, from the reader.
fn recording_facts() -> Facts {
    let reader = RecordingReader::open(&curve_2day(), Default::default()).unwrap();
    let mut bogies = HashMap::new();
    let mut weather = Vec::new();
    for e in reader {
        let e = e.unwrap();
        match e.kind {
            EventKind::Passage(p) => {
                for (k, a) in p.axles.iter().enumerate() {
                    bogies.insert((p.train_id.clone(), k), a.bogie_position);
                }
            }
            EventKind::Weather(w) => weather.push((e.log_time_ns, w)),
            _ => {}
        }
    }
    (bogies, weather)
}

#[test]
fn rail_ageing_raises_mu_most_after_long_gaps() {
    let (on, d) = deltas("[effects.rail_ageing]\ntau_s = 7200\n");
    assert!(
        d.iter().all(|(_, x)| *x >= -1e-12),
        "ageing only removes product"
    );
    // First measured train after a gap of more than 3 hours against the rest.
    let mut starts: Vec<(u64, String)> = Vec::new();
    for r in &on.measurements {
        if let Some(t) = &r.train_id {
            if starts.last().map(|s| &s.1) != Some(t) {
                starts.push((r.log_time_ns, t.clone()));
            }
        }
    }
    let after_gap: Vec<&String> = starts
        .windows(2)
        .filter(|w| w[1].0 - w[0].0 > 3 * 3600 * S)
        .map(|w| &w[1].1)
        .collect();
    let (long, short): (Vec<_>, Vec<_>) = d
        .iter()
        .partition(|(r, _)| after_gap.contains(&r.train_id.as_ref().unwrap()));
    let (m_long, m_short) = (
        mean(long.iter().map(|x| x.1)),
        mean(short.iter().map(|x| x.1)),
    );
    eprintln!("rail_ageing: mean delta after long gaps {m_long:.4}, otherwise {m_short:.4}");
    assert!(!long.is_empty() && m_long > m_short && m_long > 0.01);
}

#[test]
fn rain_washoff_raises_mu_only_once_it_has_rained() {
    let (_, d) = deltas("[effects.rain_washoff]\nk_per_mm = 1.0\n");
    let (_, weather) = recording_facts();
    let first_rain = weather
        .iter()
        .find(|(_, w)| w.precipitation_mm_h > 0.0)
        .unwrap()
        .0;
    let before: Vec<f64> = d
        .iter()
        .filter(|(r, _)| r.log_time_ns <= first_rain)
        .map(|x| x.1)
        .collect();
    let after: Vec<f64> = d
        .iter()
        .filter(|(r, _)| r.log_time_ns > first_rain)
        .map(|x| x.1)
        .collect();
    assert!(
        !before.is_empty() && before.iter().all(|x| *x == 0.0),
        "no rain, no change"
    );
    let m_after = mean(after.iter().copied());
    eprintln!("rain_washoff: mean delta after the first rain {m_after:.4}");
    assert!(after.iter().all(|x| *x >= -1e-12) && m_after > 0.005);
}

#[test]
fn temperature_consumption_follows_air_temperature() {
    let (_, d) = deltas("[effects.temperature_consumption]\nbeta_per_k = 0.05\n");
    let (_, weather) = recording_facts();
    let temp_at = |t: u64| {
        weather
            .iter()
            .rev()
            .find(|(w, _)| *w <= t)
            .map_or(20.0, |(_, w)| w.air_temperature_c)
    };
    let (warm, cold): (Vec<_>, Vec<_>) = d.iter().partition(|(r, _)| temp_at(r.log_time_ns) > 20.0);
    let (m_warm, m_cold) = (
        mean(warm.iter().map(|x| x.1)),
        mean(cold.iter().map(|x| x.1)),
    );
    eprintln!("temperature_consumption: mean delta above 20 C {m_warm:.4} (n = {}), below {m_cold:.4} (n = {})", warm.len(), cold.len());
    assert!(
        m_cold < -0.002,
        "colder than 20 C: less consumption, more product, lower mu"
    );
    assert!(warm.is_empty() || m_warm > m_cold);
}

#[test]
fn speed_transfer_separates_fast_and_slow_trains() {
    let (on, d) = deltas("[effects.speed_transfer]\nn = 2.0\n");
    let speed: HashMap<&String, f64> = on
        .trains
        .iter()
        .map(|t| (&t.train_id, t.speed_mps))
        .collect();
    let (fast, slow): (Vec<_>, Vec<_>) = d
        .iter()
        .partition(|(r, _)| speed[r.train_id.as_ref().unwrap()] > 20.0);
    let (m_fast, m_slow) = (
        mean(fast.iter().map(|x| x.1)),
        mean(slow.iter().map(|x| x.1)),
    );
    eprintln!("speed_transfer: mean delta fast trains {m_fast:.4}, slow trains {m_slow:.4}");
    assert!(!fast.is_empty() && !slow.is_empty());
    assert!((m_fast - m_slow).abs() > 0.01);
}

#[test]
fn wheel_edge_reservoir_changes_with_distance() {
    let (_, d) = deltas("[effects.wheel_edge_reservoir]\nalpha = 0.2\nr = 0.05\n");
    let by_site: Vec<f64> = ["M1", "M2", "M3"]
        .iter()
        .map(|s| mean(d.iter().filter(|(r, _)| r.site == *s).map(|x| x.1)))
        .collect();
    eprintln!("wheel_edge_reservoir: mean delta at M1, M2, M3 {by_site:?}");
    let spread = by_site.iter().cloned().fold(f64::MIN, f64::max)
        - by_site.iter().cloned().fold(f64::MAX, f64::min);
    assert!(spread > 0.01, "{by_site:?}");
}

#[test]
fn bogie_bands_change_the_high_rail_only_and_split_leading_from_trailing() {
    let (_, d) = deltas("[effects.bogie_bands]\n");
    let (bogies, _) = recording_facts();
    assert!(d
        .iter()
        .filter(|(r, _)| r.rail == "low")
        .all(|(_, x)| *x == 0.0));
    let high: Vec<&(Row, f64)> = d.iter().filter(|(r, _)| r.rail == "high").collect();
    let lead = mean(
        high.iter()
            .filter(|(r, _)| {
                bogies[&(r.train_id.clone().unwrap(), r.axle_index.unwrap_or(0))]
                    == BogiePosition::Leading
            })
            .map(|x| x.1),
    );
    let trail = mean(
        high.iter()
            .filter(|(r, _)| {
                bogies[&(r.train_id.clone().unwrap(), r.axle_index.unwrap_or(0))]
                    == BogiePosition::Trailing
            })
            .map(|x| x.1),
    );
    eprintln!("bogie_bands: mean delta on high, leading {lead:.4}, trailing {trail:.4}");
    assert!(high.iter().any(|(_, x)| x.abs() > 0.01));
    assert!((lead - trail).abs() > 0.005);
}
