//! `tortwin discover` against recordings whose truth is known: `tortwin
//! synth` hides one effect of docs/spec/effects.md (or none, or two)
//! in the truth model of a 3-day recording with Gaussian noise of
//! sigma = 0.01, and discover must name exactly the hidden effects, recover
//! their parameters within 25 % and bring the RMSE to within 1.2 × sigma.
//!
//! Each hidden parameter is one that makes its effect clearly visible: the
//! key's RMSE of the default model against the noise-free truth is checked
//! to be at least 1.5 × sigma before discover runs. Every recording rains
//! about once a day (`--rain-events-per-day 1`) so that rain wash-off has
//! something to show. The seeds are fixed: the recordings are the same
//! bytes on every machine.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::{check, tortwin};
use tortwin_discover::{self as discover, data::Dataset, Options, Silent};
use tortwin_model::config::ModelConfig;
use tortwin_recording::{EventKind, Quantity};

const SIGMA: f64 = 0.01;

/// A 3-day synthetic recording with `hidden` effects; returns its path and key.
fn synth(dir: &Path, seed: u64, hidden: &[&str]) -> (PathBuf, serde_json::Value) {
    let out = dir.join("rec.mcap");
    let mut cmd = tortwin();
    cmd.args(["synth", "--days", "3", "--noise-sigma", "0.01"])
        .args(["--rain-events-per-day", "1", "--seed", &seed.to_string()])
        .arg("--out")
        .arg(&out)
        .arg("-q");
    for h in hidden {
        cmd.args(["--hidden", h]);
    }
    check(&cmd.output().unwrap(), "tortwin synth");
    let key = std::fs::read_to_string(dir.join("rec.key.json")).unwrap();
    (out, serde_json::from_str(&key).unwrap())
}

type Found = BTreeMap<String, BTreeMap<String, f64>>;

fn found(report: &serde_json::Value) -> Found {
    report["effects_found"]
        .as_array()
        .expect("effects_found is an array")
        .iter()
        .map(|e| {
            let params = e["params"]
                .as_object()
                .expect("params is an object")
                .iter()
                .map(|(k, v)| (k.clone(), v.as_f64().expect("a number")))
                .collect();
            (e["name"].as_str().expect("a name").to_string(), params)
        })
        .collect()
}

/// Generates, checks the effect is visible, discovers, and asserts the
/// issue's criteria: exactly the hidden effects, parameters within 25 %,
/// RMSE after within 1.2 sigma.
fn hidden_case(seed: u64, hidden: &[(&str, &[(&str, f64)])]) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let specs: Vec<String> = hidden
        .iter()
        .map(|(name, params)| {
            if params.is_empty() {
                name.to_string()
            } else {
                let p: Vec<String> = params.iter().map(|(k, v)| format!("{k}={v}")).collect();
                format!("{name}:{}", p.join(","))
            }
        })
        .collect();
    let spec_refs: Vec<&str> = specs.iter().map(String::as_str).collect();
    let (rec, key) = synth(dir.path(), seed, &spec_refs);
    let visible = key["rmse_baseline_vs_truth"].as_f64().unwrap();
    if !hidden.is_empty() {
        assert!(
            visible >= 1.5 * SIGMA,
            "{specs:?}: the default model is only {visible:.4} from the truth: too weak a test"
        );
    }

    let report_dir = dir.path().join("report");
    let report = common::discover_report(&rec, &report_dir);
    let got = found(&report);
    let rmse_before = report["rmse_before"].as_f64().unwrap();
    let rmse_after = report["rmse_after"].as_f64().unwrap();
    let noise = report["noise_estimate"].as_f64().unwrap();
    eprintln!(
        "hidden {specs:?} (baseline vs truth {visible:.5}): found {got:?}; RMSE {rmse_before:.5} -> \
         {rmse_after:.5}, noise estimate {noise:.5}, {} engine runs in {:.1} s",
        report["engine_runs"], report["elapsed_s"].as_f64().unwrap()
    );

    let names: Vec<&str> = hidden.iter().map(|(n, _)| *n).collect();
    let got_names: Vec<&str> = got.keys().map(String::as_str).collect();
    let mut want = names.clone();
    want.sort_unstable();
    assert_eq!(got_names, want, "effects found");
    for (name, params) in hidden {
        for (param, truth) in *params {
            let fitted = got[*name][*param];
            assert!(
                (fitted - truth).abs() <= 0.25 * truth.abs(),
                "{name}.{param}: fitted {fitted}, truth {truth}"
            );
        }
    }
    assert!(
        rmse_after <= 1.2 * SIGMA,
        "RMSE after {rmse_after} > 1.2 sigma"
    );
    // The noise estimate does not depend on the fit: it finds sigma.
    assert!(
        (noise - SIGMA).abs() < 0.1 * SIGMA,
        "noise estimate {noise}"
    );
    if !hidden.is_empty() {
        assert!(rmse_before > rmse_after);
        assert!(report["unexplained"].is_null());
    }
    check_outputs(&rec, &report_dir, &report);
    report
}

/// The report directory holds what interfaces.md promises, and model.toml
/// loads back with `--config`.
fn check_outputs(rec: &Path, dir: &Path, report: &serde_json::Value) {
    for key in [
        "effects_found",
        "rmse_before",
        "rmse_after",
        "noise_estimate",
    ] {
        assert!(report.get(key).is_some(), "report.json lacks {key}");
    }
    for file in [
        "report.md",
        "model.toml",
        "rmse_by_step.svg",
        "mu_vs_distance.svg",
        "residuals.rrd",
    ] {
        let meta = std::fs::metadata(dir.join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert!(meta.len() > 0, "{file} is empty");
    }
    // residuals.rrd opens on the finding and holds the residuals the
    // report's RMSE comes from.
    let o = common::python("check_residuals_rrd.py", &[dir]);
    assert!(
        o.status.success(),
        "check_residuals_rrd.py: {}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    for svg in md
        .split("](")
        .skip(1)
        .filter_map(|s| s.split(')').next())
        .filter(|s| s.ends_with(".svg"))
    {
        assert!(
            dir.join(svg).is_file(),
            "report.md shows {svg}, which is missing"
        );
    }
    assert!(
        md.contains("residual_vs_"),
        "the residual plot is in report.md"
    );
    // No temporary files left behind.
    for entry in std::fs::read_dir(dir).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.contains(".partial-"), "left behind: {name}");
    }

    let model = ModelConfig::from_file(&dir.join("model.toml")).expect("model.toml loads");
    let found = found(report);
    assert_eq!(
        model.effects.names(),
        found.keys().map(String::as_str).collect::<Vec<_>>(),
        "model.toml switches on the effects found"
    );
    let toml_text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
    for (name, params) in &found {
        assert!(toml_text.contains(&format!("[effects.{name}]")));
        for (p, v) in params {
            let parsed: toml::Table = toml::from_str(&toml_text).unwrap();
            let got = parsed["effects"][name.as_str()][p.as_str()]
                .as_float()
                .unwrap();
            assert_eq!(got, *v, "{name}.{p} in model.toml");
        }
    }
    let o = tortwin()
        .arg("replay")
        .arg(rec)
        .arg("--config")
        .arg(dir.join("model.toml"))
        .arg("-q")
        .output()
        .unwrap();
    check(&o, "tortwin replay --config model.toml");
}

#[test]
fn rail_ageing_is_found() {
    hidden_case(11, &[("rail_ageing", &[("tau_s", 7200.0)])]);
}

#[test]
fn rain_washoff_is_found() {
    hidden_case(12, &[("rain_washoff", &[("k_per_mm", 1.0)])]);
}

#[test]
fn temperature_consumption_is_found() {
    hidden_case(13, &[("temperature_consumption", &[("beta_per_k", 0.1)])]);
}

#[test]
fn speed_transfer_is_found() {
    hidden_case(14, &[("speed_transfer", &[("n", 3.0)])]);
}

#[test]
fn wheel_edge_reservoir_is_found() {
    hidden_case(
        15,
        &[("wheel_edge_reservoir", &[("alpha", 0.2), ("r", 0.05)])],
    );
}

#[test]
fn bogie_bands_is_found() {
    hidden_case(16, &[("bogie_bands", &[])]);
}

#[test]
fn nothing_hidden_nothing_found() {
    let report = hidden_case(17, &[]);
    assert!(report["unexplained"].is_null());
    let verdict = report["verdict"].as_str().unwrap();
    assert!(
        verdict.contains("explains the data to the noise level"),
        "{verdict}"
    );
    assert_eq!(report["rmse_before"], report["rmse_after"]);
    let steps = report["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 1, "one round of candidates, none accepted");
    assert!(steps[0]["accepted"].is_null());
}

#[test]
fn rail_ageing_and_speed_transfer_are_both_found() {
    hidden_case(
        18,
        &[
            ("rail_ageing", &[("tau_s", 7200.0)]),
            ("speed_transfer", &[("n", 2.0)]),
        ],
    );
}

/// A residual that no effect of effects.md makes: one site's sensor reads
/// 0.03 high. discover must not force it onto an effect, and must report it
/// with the covariate it follows (the site, or its distance from the
/// applicator, which is the same grouping here).
#[test]
fn a_site_bias_is_found_as_a_measurement_offset() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = synth(dir.path(), 20, &[]);
    let data = Dataset::read(&rec).unwrap();
    let biased_site = data
        .section
        .sites
        .iter()
        .position(|s| s.id == "M2")
        .expect("the synthetic section has a site M2");
    let events = data
        .events
        .iter()
        .cloned()
        .map(|mut e| {
            if let EventKind::Measurement(m) = &mut e.kind {
                if m.site == biased_site && m.quantity() == Quantity::Mu {
                    m.value += 0.03;
                }
            }
            e
        })
        .collect();
    let biased = Dataset::from_events(
        &rec,
        data.section.clone(),
        data.origin_ns,
        data.day0_ns,
        events,
        0,
    )
    .unwrap();
    let d = discover::discover(
        &biased,
        &ModelConfig::default(),
        &Options::default(),
        &Silent,
    )
    .unwrap();
    eprintln!("{}", d.verdict);
    for s in &d.steps {
        for c in &s.candidates {
            eprintln!(
                "  step {}: {} {:?} dBIC {:.0} share {:?}",
                s.step, c.name, c.params, c.delta_bic, c.excess_share
            );
            for cv in [&c.cv, &c.cv_site].into_iter().flatten() {
                eprintln!(
                    "     {:?} held out {:.4} (current {:.4})",
                    cv.blocking, cv.held_out_sse, s.cv_sse
                );
                for f in &cv.folds {
                    eprintln!("       {} {:?} {:.4}", f.held_out, f.params, f.held_out_sse);
                }
            }
        }
    }
    // A constant bias of one site's mu is what a generic `measurement`
    // term describes: a data-quality finding, not physics (before generic
    // terms, this test asserted an unexplained residual instead).
    assert_eq!(d.effects_found.len(), 1, "{:?}", d.effects_found);
    let e = &d.effects_found[0];
    assert_eq!(e.acts_on.as_deref(), Some("measurement"));
    let scope = e.scope.clone().unwrap_or_default();
    assert_eq!(scope.get("site").map(String::as_str), Some("M2"), "{e:?}");
    assert_eq!(
        scope.get("quantity").map(String::as_str),
        Some("mu"),
        "{e:?}"
    );
    let offset = e.params["offset"].as_f64().unwrap();
    assert!((offset - 0.03).abs() < 0.25 * 0.03, "{offset}");
    assert_eq!(e.kind.as_deref(), Some("data quality"));
    assert!(d.unexplained.is_none(), "{:?}", d.unexplained);
}

/// Bad input is an input error (exit status 2) that names the file.
#[test]
fn bad_input_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.mcap");
    let o = tortwin()
        .arg("discover")
        .arg(&missing)
        .arg("--report")
        .arg(dir.path().join("r"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.mcap"));

    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[effects.rail_ageing]\ntau_s = -1\n").unwrap();
    let o = tortwin()
        .arg("discover")
        .arg(&missing)
        .arg("--config")
        .arg(&bad)
        .arg("--report")
        .arg(dir.path().join("r"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("effects.rail_ageing.tau_s"));
}

/// Effects already in `--config` stay on and are refitted (step 0), from a
/// poor starting value; they are not "found".
#[test]
fn a_starting_effect_is_refitted() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = synth(dir.path(), 11, &["rail_ageing:tau_s=7200"]);
    let cfg = dir.path().join("start.toml");
    std::fs::write(&cfg, "[effects.rail_ageing]\ntau_s = 2000.0\n").unwrap();
    let report_dir = dir.path().join("report");
    let o = tortwin()
        .arg("discover")
        .arg(&rec)
        .arg("--config")
        .arg(&cfg)
        .arg("--report")
        .arg(&report_dir)
        .output()
        .unwrap();
    check(&o, "tortwin discover --config");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report_dir.join("report.json")).unwrap())
            .unwrap();
    assert!(found(&report).is_empty(), "{:?}", found(&report));
    let refit = &report["start_refit"][0];
    assert_eq!(refit["name"], "rail_ageing");
    let tau = refit["params"]["tau_s"].as_f64().unwrap();
    assert!(
        (tau - 7200.0).abs() <= 0.25 * 7200.0,
        "tau_s refitted to {tau}"
    );
    assert!(report["rmse_after"].as_f64().unwrap() <= 1.2 * SIGMA);
    // model.toml carries it, as the final calibration (the effect fitted
    // with the site's constants) left it: within a hair of step 0's refit.
    let model = ModelConfig::from_file(&report_dir.join("model.toml")).unwrap();
    let final_tau = model
        .effects
        .param(tortwin_model::effects::Named::RailAgeing, 0)
        .expect("rail_ageing stays on");
    assert!(
        (final_tau / tau - 1.0).abs() < 0.01,
        "tau_s {final_tau} in model.toml, {tau} refitted"
    );
}
