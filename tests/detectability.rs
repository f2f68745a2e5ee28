//! Each effect of docs/spec/effects.md, hidden in the truth of a 3-day
//! synthetic recording (sigma = 0.01), leaves the paper's model (no effects)
//! well above the noise, so the discrepancy workflow can find it. The RMSE
//! is measured here by replaying the recording with the default model, not
//! taken from the generator's key, and printed.

use std::path::Path;

use tortwin_jobs::replay::{replay, ReplayArgs};

mod common;
use common::Recorder;

const SIGMA: f64 = 0.01;

/// The hidden effects and the parameters the tests use: values a field
/// campaign could meet, strong enough to matter.
const CASES: &[(&str, &str)] = &[
    ("rail_ageing", "rail_ageing:tau_s=7200"),
    ("rain_washoff", "rain_washoff:k_per_mm=2"),
    (
        "temperature_consumption",
        "temperature_consumption:beta_per_k=0.15",
    ),
    ("speed_transfer", "speed_transfer:n=4"),
    (
        "wheel_edge_reservoir",
        "wheel_edge_reservoir:alpha=0.2,r=0.05",
    ),
    ("bogie_bands", "bogie_bands"),
];

fn rmse_of_default_model(recording: &Path) -> f64 {
    let args = ReplayArgs::new(recording);
    let mut r = Recorder::default();
    replay(&args, None, &mut [&mut r], &tortwin_study::Silent).unwrap();
    r.rmse()
}

fn synth(out: &Path, hidden: Option<&str>) {
    let mut cmd = common::tortwin();
    cmd.args([
        "synth",
        "--days",
        "3",
        "--seed",
        "7",
        "--rain-events-per-day",
        "1",
        "--noise-sigma",
        "0.01",
        "-q",
    ]);
    cmd.arg("--out").arg(out);
    if let Some(h) = hidden {
        cmd.args(["--hidden", h]);
    }
    let status = cmd.status().unwrap();
    assert!(status.success());
}

#[test]
fn every_effect_stands_well_above_the_noise() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("none.mcap");
    synth(&plain, None);
    let baseline = rmse_of_default_model(&plain);
    eprintln!(
        "no hidden effect: RMSE of the paper's model {baseline:.4} = {:.2} sigma",
        baseline / SIGMA
    );
    assert!(
        (baseline / SIGMA - 1.0).abs() < 0.05,
        "without an effect the model explains the data to the noise"
    );
    for (name, hidden) in CASES {
        let rec = dir.path().join(format!("{name}.mcap"));
        synth(&rec, Some(hidden));
        let rmse = rmse_of_default_model(&rec);
        eprintln!(
            "{hidden:<45} RMSE of the paper's model {rmse:.4} = {:.2} sigma",
            rmse / SIGMA
        );
        assert!(
            rmse > 2.0 * SIGMA,
            "{name}: {rmse} is not well above the noise"
        );
    }
}
