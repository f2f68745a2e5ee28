//! The paper's Figures 7 and 13 against an independent implementation of
//! docs/spec/model.md (tests/reference/paper_fig7.csv and
//! paper_fig13.csv), to 1e-9 relative; and model.md's check of the Figure 13
//! numbers that the paper states in its text.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// this file's helpers are test code too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use std::path::PathBuf;

use tortwin_model::config::ModelConfig;
use tortwin_strategy::paper::{twin_disc, WaysideScenario};

fn reference(name: &str) -> Vec<Vec<f64>> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/reference")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|x| x.trim().parse::<f64>().unwrap())
                .collect()
        })
        .collect()
}

fn assert_close(what: &str, got: f64, want: f64, rel: f64) {
    let scale = want.abs().max(1e-300);
    assert!(
        (got - want).abs() <= rel * scale || (want == 0.0 && got.abs() < 1e-300),
        "{what}: got {got:e}, reference {want:e}, relative error {:e}",
        (got - want).abs() / scale
    );
}

#[test]
fn figure_7_twin_disc_matches_the_reference() {
    let rows = reference("paper_fig7.csv");
    assert_eq!(rows.len(), 3000);
    let cfg = ModelConfig::default();
    for (col, m0_g) in [(1, 0.1), (2, 0.3), (3, 0.5)] {
        let mu = twin_disc(&cfg, m0_g * 1e-3, rows.len());
        for (row, got) in rows.iter().zip(&mu) {
            assert_close(
                &format!("fig 7 m0 = {m0_g} g, N = {}", row[0]),
                *got,
                row[col],
                1e-9,
            );
        }
    }
}

#[test]
fn figure_13_matches_the_reference() {
    let rows = reference("paper_fig13.csv");
    let cfg = ModelConfig::default();
    let fields = WaysideScenario::default().run(&cfg, &[100]).unwrap();
    let f = &fields[0];
    assert_eq!(f.d_m.len(), rows.len(), "grid points");
    for (i, row) in rows.iter().enumerate() {
        assert_close(&format!("d at {i}"), f.d_m[i], row[0], 1e-12);
        assert_close(&format!("mu at {} m", row[0]), f.mu[i], row[1], 1e-9);
        assert_close(
            &format!("rail mass at {} m", row[0]),
            f.rail_mass_kg[i] * 1e6,
            row[2],
            1e-9,
        );
        assert_close(
            &format!("wheel mass at {} m", row[0]),
            f.wheel_mass_kg[i] * 1e6,
            row[3],
            1e-9,
        );
    }
}

#[test]
fn figure_13_shows_what_the_paper_says() {
    // model.md, "Check with the paper": mu 0.276 at the applicator, 0.31 at
    // 81 m, 0.41 at 150 m; rail product below 1 mg from about 240 m; the
    // wheel keeps about 27 mg at 500 m.
    let cfg = ModelConfig::default();
    let f = &WaysideScenario::default().run(&cfg, &[100]).unwrap()[0];
    let at = |d: f64| f.d_m.iter().position(|&x| x >= d - 1.5).unwrap();
    assert!((f.mu[0] - 0.276).abs() < 0.0005, "{}", f.mu[0]);
    assert!((f.mu[at(81.0)] - 0.31).abs() < 0.01, "{}", f.mu[at(81.0)]);
    assert!((f.mu[at(150.0)] - 0.41).abs() < 0.01, "{}", f.mu[at(150.0)]);
    let below_1mg = f.rail_mass_kg.iter().position(|&m| m < 1e-6).unwrap();
    assert!(
        (220.0..260.0).contains(&f.d_m[below_1mg]),
        "{}",
        f.d_m[below_1mg]
    );
    assert!((f.wheel_mass_kg[at(500.0)] * 1e6 - 27.0).abs() < 2.0);
}
