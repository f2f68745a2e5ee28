//! Sensitivities in one pass (issue 44): a replay with tangents
//! (`EngineOptions::tangents`, `tortwin_model::tangent`) gives every
//! measurement's derivative with respect to `ln p` of the ten state
//! constants. Checked against central differences of full replays, column
//! by column, on recordings with every kind of measurement, every named
//! effect and generic terms of every kind; and the values of the replay
//! with tangents are those of the plain replay, bit for bit. The same for
//! the effects' own parameters that act on the mass, two at a time in the
//! tangents' effect slots (`tortwin_model::tangent::EffectParam`).

mod common;

use std::path::{Path, PathBuf};

use common::truth_of;

use tortwin_discover::data::Dataset;
use tortwin_model::config::{ModelConfig, TermEffect};
use tortwin_model::effects::Named;
use tortwin_model::generic::{ActsOn, Form};
use tortwin_model::tangent::{EffectParam, EFFECT_SLOTS, STATE_KEYS};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The relative step of the central differences in `ln p`.
const H: f64 = 1e-5;

/// A tangent column against the central differences of the replays at
/// `+h` (`hi`) and `-h` (`lo`): the differences' norm, the norm of the
/// column's miss, and the miss relative to the norm (absolute where the
/// differences are 0).
fn against_central(hi: &[f64], lo: &[f64], h: f64, column: &[f64]) -> (f64, f64, f64) {
    let fd: Vec<f64> = hi
        .iter()
        .zip(lo)
        .map(|(a, b)| (a - b) / (2.0 * h))
        .collect();
    let norm = fd.iter().map(|x| x * x).sum::<f64>().sqrt();
    let miss = fd
        .iter()
        .zip(column)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    (norm, miss, if norm > 0.0 { miss / norm } else { miss })
}

/// Compares the tangent columns of `cfg` on `rec` with central differences;
/// returns the worst column's relative error.
fn check(rec: &Path, cfg: &ModelConfig) -> f64 {
    let data = Dataset::read(rec).unwrap();
    let s = data.simulate_with_tangents(cfg, &STATE_KEYS, &[]).unwrap();
    let (values, columns) = (s.simulated, s.columns);
    let plain = data.simulate(cfg).unwrap();
    assert!(
        values
            .iter()
            .zip(&plain)
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "{}: the replay with tangents changed a value",
        rec.display()
    );
    let mut worst: f64 = 0.0;
    for (key, column) in STATE_KEYS.iter().zip(&columns) {
        let at = |s: f64| {
            let mut c = cfg.clone();
            key.set(&mut c.product, key.get(&cfg.product) * s.exp());
            data.simulate(&c).unwrap()
        };
        let (norm, miss, relative) = against_central(&at(H), &at(-H), H, column);
        eprintln!(
            "{} {:>8}: |J| {norm:.3e}, |J - central| / |J| = {relative:.2e}",
            rec.file_name().unwrap().to_string_lossy(),
            key.name()
        );
        // A constant the recording shows nothing of has a zero column
        // both ways (m_max where nothing is capped).
        assert!(
            relative <= 1e-6 || (norm < 1e-12 && miss < 1e-12),
            "{}: {key:?} tangent vs central differences {relative:e}",
            rec.display()
        );
        worst = worst.max(relative);
    }
    worst
}

#[test]
fn tangents_equal_central_differences_on_the_laboratory_model() {
    check(
        &root().join("recordings/demo_day.mcap"),
        &ModelConfig::default(),
    );
}

#[test]
fn tangents_equal_central_differences_with_every_named_effect() {
    for name in ["curve_day_all_effects", "curve_day_bands_rain"] {
        let rec = root().join("recordings").join(format!("{name}.mcap"));
        check(&rec, &truth_of(&rec));
    }
}

#[test]
fn tangents_equal_central_differences_with_generic_terms() {
    let rec = root().join("tests/reference/recordings/generic_day.mcap");
    let cfg = ModelConfig::from_file(&rec.with_extension("config.toml")).unwrap();
    check(&rec, &cfg);
}

/// Every effect parameter of `cfg` a tangent can follow: the named
/// effects' (but the bands, which have none) and the smooth parameter of
/// every generic term on the pulse mass, the transfer or the consumption.
fn followable(cfg: &ModelConfig) -> Vec<EffectParam> {
    let mut out = Vec::new();
    for effect in Named::ALL {
        let n = cfg.effects.get(effect).map_or(0, <[f64]>::len);
        out.extend((0..n).map(|param| EffectParam::Named { effect, param }));
    }
    for (term, t) in cfg.effects.generic.iter().enumerate() {
        let on_mass = matches!(
            t.acts_on,
            ActsOn::PulseMass | ActsOn::Transfer | ActsOn::Consumption
        );
        if on_mass && matches!(t.effect, TermEffect::Factor { .. }) {
            out.push(EffectParam::Generic { term });
        }
    }
    out
}

/// `cfg` with effect parameter `p` moved by `d`; the parameter's value.
fn moved(cfg: &ModelConfig, p: EffectParam, d: f64) -> (ModelConfig, f64) {
    let mut c = cfg.clone();
    let value = match p {
        EffectParam::Named { effect, param } => {
            let mut v = cfg.effects.get(effect).unwrap().to_vec();
            let value = v[param];
            v[param] += d;
            c.effects.set(effect, &v);
            value
        }
        EffectParam::Generic { term } => {
            let TermEffect::Factor { driver, form } = cfg.effects.generic[term].effect else {
                unreachable!("only factors are followed")
            };
            let (value, form) = match form {
                Form::Exp { beta } => (beta, Form::Exp { beta: beta + d }),
                Form::Power { n } => (n, Form::Power { n: n + d }),
                Form::Linear { gamma } => (gamma, Form::Linear { gamma: gamma + d }),
                Form::Step { x0, f } => (f, Form::Step { x0, f: f + d }),
            };
            c.effects.generic[term].effect = TermEffect::Factor { driver, form };
            value
        }
    };
    (c, value)
}

/// Compares the effect slots' columns of `cfg` on `rec` with central
/// differences in each parameter; returns how many were compared.
fn check_effects(rec: &Path, cfg: &ModelConfig) -> usize {
    let data = Dataset::read(rec).unwrap();
    let params = followable(cfg);
    assert!(!params.is_empty(), "{}: nothing to follow", rec.display());
    for pair in params.chunks(EFFECT_SLOTS) {
        let s = data.simulate_with_tangents(cfg, &[], pair).unwrap();
        let plain = data.simulate(cfg).unwrap();
        assert!(
            s.simulated
                .iter()
                .zip(&plain)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{}: the replay with effect tangents changed a value",
            rec.display()
        );
        for (&p, column) in pair.iter().zip(&s.columns) {
            let value = moved(cfg, p, 0.0).1;
            let h = 1e-5 * value.abs().max(0.1);
            let (hi, lo) = (
                data.simulate(&moved(cfg, p, h).0).unwrap(),
                data.simulate(&moved(cfg, p, -h).0).unwrap(),
            );
            let (norm, _, relative) = against_central(&hi, &lo, h, column);
            eprintln!(
                "{} {p:?} = {value}: |J| {norm:.3e}, |J - central| / |J| = {relative:.2e}",
                rec.file_name().unwrap().to_string_lossy(),
            );
            assert!(norm > 0.0, "{}: {p:?} shows nothing", rec.display());
            assert!(
                relative <= 1e-6,
                "{}: {p:?} tangent vs central differences {relative:e}",
                rec.display()
            );
        }
    }
    params.len()
}

#[test]
fn effect_tangents_equal_central_differences_for_every_named_effect() {
    let mut named = std::collections::BTreeSet::new();
    for name in ["curve_day_all_effects", "curve_day_bands_rain"] {
        let rec = root().join("recordings").join(format!("{name}.mcap"));
        let cfg = truth_of(&rec);
        for p in followable(&cfg) {
            if let EffectParam::Named { effect, param } = p {
                named.insert((effect.name(), param));
            }
        }
        check_effects(&rec, &cfg);
    }
    // Every named effect's parameter that acts on the mass, seen at least once.
    let expected = [
        ("rail_ageing", 0),
        ("rain_washoff", 0),
        ("temperature_consumption", 0),
        ("speed_transfer", 0),
        ("wheel_edge_reservoir", 0),
        ("wheel_edge_reservoir", 1),
    ];
    for e in expected {
        assert!(named.contains(&e), "{e:?} was not checked: {named:?}");
    }
}

#[test]
fn effect_tangents_equal_central_differences_for_generic_terms() {
    let rec = root().join("tests/reference/recordings/generic_day.mcap");
    let cfg = ModelConfig::from_file(&rec.with_extension("config.toml")).unwrap();
    // Pulse mass (a time step, a linear term), transfer (wheel, weather
    // step), consumption (weather exp, wheel power).
    assert_eq!(check_effects(&rec, &cfg), 6);
}

/// A state term at its neutral value (`beta`, `n` or `gamma` 0, a step's
/// `f` 1) multiplies its quantity by 1.0: its replay is the replay without it,
/// bit for bit, which is why the configuration's state part leaves it out
/// (`ModelConfig::state_part`) and a fit's look at a term's neutral point
/// is a read-out of the model it starts from, not a replay.
#[test]
fn a_state_term_at_its_neutral_value_changes_no_bit() {
    let rec = root().join("tests/reference/recordings/generic_day.mcap");
    let cfg = ModelConfig::from_file(&rec.with_extension("config.toml")).unwrap();
    let data = Dataset::read(&rec).unwrap();
    let on_mass = |t: &tortwin_model::config::GenericTerm| {
        matches!(
            t.acts_on,
            ActsOn::PulseMass | ActsOn::Transfer | ActsOn::Consumption
        )
    };
    let mut without = cfg.clone();
    without.effects.generic.retain(|t| !on_mass(t));
    let plain = data.simulate(&without).unwrap();
    let mut checked = 0;
    for term in cfg.effects.generic.iter().filter(|t| on_mass(t)) {
        let TermEffect::Factor { driver, form } = term.effect else {
            unreachable!("a term on the mass is a factor")
        };
        let neutral = match form {
            Form::Exp { .. } => Form::Exp { beta: 0.0 },
            Form::Power { .. } => Form::Power { n: 0.0 },
            Form::Linear { .. } => Form::Linear { gamma: 0.0 },
            Form::Step { x0, .. } => Form::Step { x0, f: 1.0 },
        };
        let mut with = without.clone();
        let mut t = term.clone();
        t.effect = TermEffect::Factor {
            driver,
            form: neutral,
        };
        with.effects.generic.push(t);
        assert_eq!(with.state_part(), without.state_part());
        let values = data.simulate(&with).unwrap();
        assert!(
            values
                .iter()
                .zip(&plain)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{term:?} at its neutral value changed a value"
        );
        checked += 1;
    }
    // Pulse mass (time step, linear), transfer (linear, step),
    // consumption (exp, power): every form on every quantity of the mass.
    assert_eq!(checked, 6);
}

/// The same for the named effects that can change nothing (wash-off's
/// `k_per_mm`, `beta_per_k`, the speed's `n`, the reservoir's `alpha` 0),
/// each beside every other effect of a day that has them all.
#[test]
fn a_named_effect_at_its_neutral_value_changes_no_bit() {
    let mut checked = Vec::new();
    for name in ["curve_day_all_effects", "curve_day_bands_rain"] {
        let rec = root().join("recordings").join(format!("{name}.mcap"));
        let cfg = truth_of(&rec);
        let data = Dataset::read(&rec).unwrap();
        for effect in Named::ALL {
            let Some(params) = cfg.effects.get(effect) else {
                continue;
            };
            let mut zero = params.to_vec();
            if let Some(first) = zero.first_mut() {
                *first = 0.0;
            }
            if !effect.is_neutral(&zero) {
                continue;
            }
            let mut with = cfg.clone();
            with.effects.set(effect, &zero);
            let mut without = cfg.clone();
            without.effects.unset(effect);
            assert_eq!(with.state_part(), without.state_part());
            let (a, b) = (
                data.simulate(&with).unwrap(),
                data.simulate(&without).unwrap(),
            );
            assert!(
                a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{name}: {} at its neutral value changed a value",
                effect.name()
            );
            checked.push(effect.name());
        }
    }
    for effect in [
        "rain_washoff",
        "temperature_consumption",
        "speed_transfer",
        "wheel_edge_reservoir",
    ] {
        assert!(
            checked.contains(&effect),
            "{effect} was not checked: {checked:?}"
        );
    }
}
