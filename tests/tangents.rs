//! Sensitivities in one pass (issue 44): a replay with tangents
//! (`EngineOptions::tangents`, `tortwin_model::tangent`) gives every
//! measurement's derivative with respect to `ln p` of the ten state
//! constants. Checked against central differences of full replays, column
//! by column, on recordings with every kind of measurement, every named
//! effect and generic terms of every kind; and the values of the replay
//! with tangents are those of the plain replay, bit for bit.

mod common;

use std::path::{Path, PathBuf};

use common::truth_of;

use tortwin_model::config::ModelConfig;
use tortwin_model::tangent::STATE_KEYS;
use tortwin_studies::discover::data::Dataset;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The relative step of the central differences in `ln p`.
const H: f64 = 1e-5;

/// Compares the tangent columns of `cfg` on `rec` with central differences;
/// returns the worst column's relative error.
fn check(rec: &Path, cfg: &ModelConfig) -> f64 {
    let data = Dataset::read(rec).unwrap();
    let s = data.simulate_with_tangents(cfg, &STATE_KEYS).unwrap();
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
        let (hi, lo) = (at(H), at(-H));
        let fd: Vec<f64> = hi
            .iter()
            .zip(&lo)
            .map(|(a, b)| (a - b) / (2.0 * H))
            .collect();
        let norm = fd.iter().map(|x| x * x).sum::<f64>().sqrt();
        let miss = fd
            .iter()
            .zip(column)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let relative = if norm > 0.0 { miss / norm } else { miss };
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
