//! Site constants (docs/spec/interfaces.md, "Site constants (calibration)"):
//! on synthetic sites whose truth differs from the laboratory only in its
//! constants, `discover` calibrates them and finds no effect and no change
//! in time; with nothing moved, nothing changes; `calibrate` on its own
//! writes its report and a model.toml that carries the values.
//!
//! The truth of each recording is known (`--truth-config`): every check is
//! against it, not against what tortwin produced before.

use std::path::{Path, PathBuf};

use tortwin_model::config::ModelConfig;
use tortwin_model::product::ProductKey;

mod common;
use common::{check, tortwin};

const SIGMA: f64 = 0.01;

/// A 3-day synthetic recording (sigma 0.01) of `preset` with the truth's
/// `[product]` overlay `truth` and the `--hidden` effects `hidden`.
fn synth(dir: &Path, preset: &str, seed: u64, truth: &str, hidden: &[&str]) -> PathBuf {
    let truth_path = dir.join("truth.toml");
    std::fs::write(&truth_path, truth).unwrap();
    let out = dir.join("rec.mcap");
    let mut cmd = tortwin();
    cmd.args(["synth", "--days", "3", "--preset", preset, "--seed"])
        .arg(seed.to_string())
        .args([
            "--noise-sigma",
            "0.01",
            "--rain-events-per-day",
            "1",
            "--truth-config",
        ])
        .arg(&truth_path);
    for h in hidden {
        cmd.args(["--hidden", h]);
    }
    let o = cmd.arg("--out").arg(&out).arg("-q").output().unwrap();
    check(&o, "tortwin synth");
    out
}

/// `tortwin calibrate REC --report DIR`; returns report.json.
fn calibrate(recording: &Path, report: &Path, config: Option<&Path>) -> serde_json::Value {
    let mut cmd = tortwin();
    cmd.arg("calibrate")
        .arg(recording)
        .arg("--report")
        .arg(report);
    if let Some(c) = config {
        cmd.arg("--config").arg(c);
    }
    let o = cmd.output().unwrap();
    check(&o, "tortwin calibrate");
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("report.json")).unwrap())
            .unwrap();
    // The replay its run-equivalents are counted in is reported, with
    // how many replays were timed: every replay but the first (which finds
    // the outliers).
    let runs = json["engine_runs"].as_u64().unwrap();
    let ms = json["replay_ms"].as_f64().unwrap();
    assert!(ms > 0.0 && ms < 60_000.0, "replay_ms {ms}");
    let timed = match runs - 1 {
        1 => "the one replay timed".to_string(),
        n => format!("the mean of {n} replays timed"),
    };
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(
        md.contains(&format!("run-equivalents of {ms:.0} ms ({timed})")),
        "{md}"
    );
    json
}

/// The site constant `key` (`product.mu_d`) of a report.
fn constant<'a>(report: &'a serde_json::Value, key: &str) -> &'a serde_json::Value {
    report["site_constants"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["key"] == key)
        .unwrap_or_else(|| panic!("no {key} in {}", report["site_constants"]))
}

/// Every determined constant's 95 % interval holds the truth's value (the
/// laboratory's where the truth does not set it); returns how many.
fn determined_hold_the_truth(report: &serde_json::Value, truth: &ModelConfig) -> usize {
    let mut n = 0;
    for c in report["site_constants"].as_array().unwrap() {
        let key = c["key"].as_str().unwrap().trim_start_matches("product.");
        let Some(k) = ProductKey::ALL.into_iter().find(|k| k.name() == key) else {
            panic!("unknown constant {key}");
        };
        if c["determined"].as_bool().unwrap() {
            let ci = c["ci95"].as_array().unwrap();
            let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
            let want = k.get(&truth.product);
            assert!(
                lo <= want && want <= hi,
                "{key}: truth {want} not in [{lo}, {hi}]: {c}"
            );
            let value = c["value"].as_f64().unwrap();
            assert!(
                lo <= value && value <= hi,
                "{key}: value {value} outside its interval: {c}"
            );
            n += 1;
        } else {
            assert!(c["ci95"].is_null(), "{c}");
        }
    }
    n
}

/// No effect found, and in particular no change in time.
fn no_effect(report: &serde_json::Value) {
    let found = report["effects_found"].as_array().unwrap();
    assert!(found.is_empty(), "effects found: {found:?}");
    assert!(
        report["rmse_after"].as_f64().unwrap() < 1.1 * SIGMA,
        "{}",
        report["rmse_after"]
    );
}

/// The first case: a site whose dry friction is 0.52 (not 0.58)
/// and whose consumption follows the creepage more (kc 0.80). Before
/// calibration, discover reported "muD is about 89 % of the model's since
/// 02:28" (where the measurements start). Now: no effect, no change in
/// time; muD and kc calibrated, their intervals holding the truth, and
/// model.toml carrying them.
#[test]
fn other_dry_friction_is_a_site_constant_not_a_change_in_time() {
    let dir = tempfile::tempdir().unwrap();
    let truth_text = "[product]\nmu_d = 0.52\nkc = 0.80\n";
    let rec = synth(dir.path(), "curve", 31, truth_text, &[]);
    let report = common::discover_report(&rec, &dir.path().join("report"));
    no_effect(&report);
    let truth = ModelConfig::from_overlay_str(truth_text, "truth").unwrap();
    assert!(determined_hold_the_truth(&report, &truth) >= 2);
    for (key, want) in [("product.mu_d", 0.52), ("product.kc", 0.80)] {
        let c = constant(&report, key);
        let value = c["value"].as_f64().unwrap();
        assert!((value / want - 1.0).abs() < 0.05, "{key} {value}: {c}");
    }
    let mu_d = constant(&report, "product.mu_d");
    assert_eq!(mu_d["determined"], true, "{mu_d}");
    assert!(report["verdict"].as_str().unwrap().contains("mu_d"));
    // model.toml carries the calibrated values.
    let model = ModelConfig::from_file(&dir.path().join("report/model.toml")).unwrap();
    assert_eq!(model.product.mu_d, mu_d["value"].as_f64().unwrap());
    assert!(model.effects.names().is_empty() && model.effects.generic.is_empty());
}

/// The second case: km 1.2e-4 and kt 0.35 on the tangent. Before
/// calibration, discover told of "muC about 17 % of the model's since"
/// the first measurement. Now no effect; the constants that differ are
/// calibrated (determined, or as the combination the recording fixes) and
/// the model predicts a later recording of the same site (other traffic
/// and weather) within a quarter of the noise.
#[test]
fn km_and_kt_on_the_tangent_are_site_constants() {
    let dir = tempfile::tempdir().unwrap();
    let truth_text = "[product]\nkm_kg = 1.2e-4\nkt = 0.35\n";
    let rec = synth(dir.path(), "tangent", 32, truth_text, &[]);
    let report = common::discover_report(&rec, &dir.path().join("report"));
    no_effect(&report);
    let truth = ModelConfig::from_overlay_str(truth_text, "truth").unwrap();
    determined_hold_the_truth(&report, &truth);
    let moved: Vec<&str> = report["site_constants"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["value"] != c["default"])
        .map(|c| c["key"].as_str().unwrap())
        .collect();
    assert!(!moved.is_empty(), "nothing calibrated");

    // A later recording of the same site: the model found against the truth.
    let later = dir.path().join("later.mcap");
    let o = tortwin()
        .args([
            "synth", "--days", "2", "--preset", "tangent", "--seed", "33",
        ])
        .args(["--start", "2024-04-29T00:00:00Z", "--trains-per-day", "30"])
        .arg("--truth-config")
        .arg(dir.path().join("truth.toml"))
        .arg("--out")
        .arg(&later)
        .arg("-q")
        .output()
        .unwrap();
    check(&o, "tortwin synth (later)");
    let simulated = |config: &Path| -> Vec<f64> {
        let out = dir.path().join("later-out.mcap");
        let o = tortwin()
            .arg("replay")
            .arg(&later)
            .arg("--config")
            .arg(config)
            .arg("--out-mcap")
            .arg(&out)
            .arg("-q")
            .output()
            .unwrap();
        check(&o, "tortwin replay (later)");
        let bytes = std::fs::read(&out).unwrap();
        mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(Result::unwrap)
            .filter(|m| m.channel.topic == "/twin/measurement")
            .map(|m| {
                let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                v["simulated"].as_f64().unwrap()
            })
            .collect()
    };
    let found = simulated(&dir.path().join("report/model.toml"));
    let want = simulated(&dir.path().join("truth.toml"));
    let lab_config = dir.path().join("lab.toml");
    std::fs::write(&lab_config, "").unwrap();
    let lab = simulated(&lab_config);
    let rms = |a: &[f64]| -> f64 {
        (a.iter()
            .zip(&want)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            / want.len() as f64)
            .sqrt()
            / SIGMA
    };
    let (found_sigma, lab_sigma) = (rms(&found), rms(&lab));
    eprintln!("later recording: found {found_sigma:.3} sigma, laboratory {lab_sigma:.3} sigma");
    assert!(found_sigma <= 0.25, "{found_sigma} sigma");
    // The laboratory's constants are off by less than the noise here (the
    // reason nothing warned the user), but several times more than the
    // calibrated ones.
    assert!(
        lab_sigma > 4.0 * found_sigma.max(0.05),
        "the laboratory's constants fit as well: {lab_sigma}"
    );
}

/// Nothing moved: every determined constant's interval holds its default,
/// nothing is changed, and model.toml is the laboratory's.
#[test]
fn nothing_moved_nothing_changed() {
    let dir = tempfile::tempdir().unwrap();
    let rec = synth(dir.path(), "curve", 34, "", &[]);
    let report = calibrate(&rec, &dir.path().join("report"), None);
    let lab = ModelConfig::default();
    assert!(determined_hold_the_truth(&report, &lab) >= 2);
    for c in report["site_constants"].as_array().unwrap() {
        assert_eq!(c["value"], c["default"], "{c}");
    }
    assert!(report["effects_found"].as_array().unwrap().is_empty());
    let model = ModelConfig::from_file(&dir.path().join("report/model.toml")).unwrap();
    assert_eq!(model.product, lab.product);
    let verdict = report["verdict"].as_str().unwrap();
    assert!(
        verdict.contains("laboratory's as far as this recording tells"),
        "{verdict}"
    );
    // The report's files.
    for f in ["report.md", "model.toml", "residuals.rrd"] {
        assert!(dir.path().join("report").join(f).is_file(), "{f}");
    }
    let md = std::fs::read_to_string(dir.path().join("report/report.md")).unwrap();
    assert!(md.contains("## Site constants") && md.contains("`product.mu_d`"));
}

/// A recording whose model misses much (rail ageing and a dry friction
/// falling with wheel load, both hidden: RMSE four times the noise) is
/// calibrated without effects: the fit with every constant free is then a
/// poor guide to where the representatives start, and the calibration
/// ended worse than it began (RMSE 0.0385 -> 0.0457, seven constants on
/// their bounds; 0.0843 before 2026-11-29's line search). A calibration
/// never ends worse than its starting constants.
#[test]
fn a_calibration_never_ends_worse_than_it_started() {
    let dir = tempfile::tempdir().unwrap();
    let rec = synth(
        dir.path(),
        "tangent",
        5,
        "",
        &[
            "rail_ageing:tau_s=7200",
            "generic:acts_on=friction_dry,driver=wheel_load_kN,form=power,n=-0.3",
        ],
    );
    let report = calibrate(&rec, &dir.path().join("report"), None);
    let before = report["rmse_before"].as_f64().unwrap();
    let after = report["rmse_after"].as_f64().unwrap();
    assert!(after <= before, "RMSE {before} -> {after}");
}

/// A starting configuration's constants are where the calibration starts
/// and what "held" means: a recording made with mu_d 0.52, calibrated from
/// a configuration that says 0.52, keeps 0.52 (its interval holds it) and
/// names it the starting model's value.
#[test]
fn calibrate_starts_from_the_configuration() {
    let dir = tempfile::tempdir().unwrap();
    let truth_text = "[product]\nmu_d = 0.52\n";
    let rec = synth(dir.path(), "tangent", 35, truth_text, &[]);
    let report = calibrate(
        &rec,
        &dir.path().join("report"),
        Some(&dir.path().join("truth.toml")),
    );
    let mu_d = constant(&report, "product.mu_d");
    assert_eq!(mu_d["start"], 0.52, "{mu_d}");
    assert_eq!(mu_d["default"], 0.58, "{mu_d}");
    assert_eq!(mu_d["value"], 0.52, "{mu_d}");
    assert_eq!(mu_d["determined"], true, "{mu_d}");
    let truth = ModelConfig::from_overlay_str(truth_text, "truth").unwrap();
    determined_hold_the_truth(&report, &truth);
}

/// A site whose consumption is about a third above the laboratory's (kc
/// 0.75 for 0.57) and grows with the air temperature as well
/// (`temperature_consumption`, beta 0.04 per K). Fitted with the
/// laboratory's kc held, the named effect had to make up for kc (beta
/// 0.094) and lost to a power of relative humidity on the consumption,
/// which discover then reported beside the calibrated constants (the
/// calibration campaign of 2026-11-28, `--seed 20261132`, site 14: this
/// recording). The two are now weighed beside the site's constants: the
/// named effect is reported, its beta near the truth, kc above the
/// laboratory's, and the model closes to the noise.
#[test]
fn a_temperature_driven_consumption_at_a_site_with_a_high_kc_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let truth_text = "[product]\nkc = 0.7516\n";
    let hidden = ["temperature_consumption:beta_per_k=0.04"];
    let rec = synth(dir.path(), "tangent", 3190, truth_text, &hidden);
    let report = common::discover_report(&rec, &dir.path().join("report"));
    let found = report["effects_found"].as_array().unwrap();
    assert_eq!(found.len(), 1, "effects found: {found:?}");
    assert_eq!(found[0]["name"], "temperature_consumption", "{found:?}");
    let beta = found[0]["params"]["beta_per_k"].as_f64().unwrap();
    assert!((beta / 0.04 - 1.0).abs() < 0.25, "beta {beta}");
    let kc = constant(&report, "product.kc");
    assert!(kc["value"].as_f64().unwrap() > 1.15 * 0.57, "{kc}");
    assert!(
        report["rmse_after"].as_f64().unwrap() < 1.05 * SIGMA,
        "{}",
        report["rmse_after"]
    );
}

/// Rain wash-off where it rained on one day of three, on a tangent whose
/// constants are the laboratory's (the calibration campaign of 2026-11-28,
/// `--seed 20261138`, site 10: this recording). The days cannot test such
/// an effect: the fold that holds out the day of the rain is fitted on two
/// dry days, which say nothing about it. Started from the full data's
/// optimum, that fold used to keep it, and the rainy day was predicted by
/// parameters fitted on it; a term on precipitation that reads the
/// friction out passed so and predicted a later recording 1.7 sigma off.
/// Now a fold the other days do not support predicts its day without the
/// effect, an effect seen on one day alone is tested by the sites, and
/// rain wash-off is named.
#[test]
fn rain_on_one_day_is_tested_by_the_sites_and_named() {
    let dir = tempfile::tempdir().unwrap();
    let rec = synth(
        dir.path(),
        "tangent",
        8331,
        "[product]\n",
        &["rain_washoff:k_per_mm=1.5"],
    );
    let report = common::discover_report(&rec, &dir.path().join("report"));
    let found = report["effects_found"].as_array().unwrap();
    assert_eq!(found.len(), 1, "effects found: {found:?}");
    assert_eq!(found[0]["name"], "rain_washoff", "{found:?}");
    let k = found[0]["params"]["k_per_mm"].as_f64().unwrap();
    assert!((k / 1.5 - 1.0).abs() < 0.25, "k_per_mm {k}");
    // Its cross-validation by day: the one fold without support holds out
    // the day it rained, and predicts it as the model without the effect.
    let step = &report["steps"][0];
    let washoff = step["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "rain_washoff")
        .expect("rain_washoff was fitted");
    let cv = &washoff["cv"];
    let folds = cv["folds"].as_array().unwrap();
    let unsupported: Vec<usize> = (0..folds.len())
        .filter(|&j| folds[j]["supported"] == false)
        .collect();
    assert_eq!(unsupported.len(), 1, "{cv}");
    let j = unsupported[0];
    assert_eq!(cv["evidence_in"], folds[j]["held_out"], "{cv}");
    let held_out = folds[j]["held_out_sse"].as_f64().unwrap();
    let without = step["sse_by_day"][j].as_f64().unwrap();
    assert!(
        (held_out / without - 1.0).abs() < 1e-12,
        "{held_out} {without}"
    );
    assert!(washoff["passes_cv_site"] == true, "{washoff}");
    assert!(
        report["rmse_after"].as_f64().unwrap() < 1.05 * SIGMA,
        "{}",
        report["rmse_after"]
    );
}

/// Issue 28: a clogged nozzle (A1 delivering half its mass from 12:00 on
/// the second day) at a site whose km_kg is 25 % below and kt 27 % above
/// the laboratory's (the campaign of 2026-11-29, seed 20261140, site 4: the
/// same recording). The nozzle hides the constants: at the first step the
/// recording moves none. With them at the laboratory's values a step of
/// the transfer everywhere came 2.6 BIC units ahead of the nozzle (a high
/// kt and a lower transfer from then on make up for each other) and was
/// named. Close contenders of another kind are now told apart with the
/// site's constants calibrated beside each, and the nozzle is named.
#[test]
fn a_clogged_nozzle_at_a_site_with_a_high_kt_is_named_not_a_transfer_step() {
    let dir = tempfile::tempdir().unwrap();
    let rec = synth(
        dir.path(),
        "curve",
        6383,
        "[product]\nkm_kg = 0.00012223729536259457\nkt = 0.6340747070346816\n",
        &["generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,t0_utc=2024-04-09T12:00:00Z,f=0.5"],
    );
    let report = common::discover_report(&rec, &dir.path().join("report"));
    let found = report["effects_found"].as_array().unwrap();
    assert_eq!(found.len(), 1, "effects found: {found:?}");
    let nozzle = &found[0];
    common::assert_nozzle_step(nozzle, "A1");
    let f = nozzle["params"]["f"].as_f64().unwrap();
    assert!((f - 0.5).abs() <= 0.25 * 0.5, "f = {f}");
    // The step that told them apart: the transfer step was the first
    // choice, and the nozzle was taken after the calibrations beside both.
    let first = &report["steps"][0];
    assert_eq!(
        first["candidates"][0]["label"]
            .as_str()
            .unwrap()
            .split(" (")
            .next(),
        Some("generic transfer × time"),
        "{}",
        first["candidates"][0]
    );
    assert!(
        report["rmse_after"].as_f64().unwrap() < 1.05 * SIGMA,
        "{}",
        report["rmse_after"]
    );
}

/// Issue 28: a clogged nozzle (A1 at half from 12:00 on the second day) on
/// the tangent at a site whose `k0_kg` is 21 % and `mu_c` 24 % above and
/// `cn` 25 % below the laboratory's (the campaign of 2026-11-30, seed
/// 20261147, site 20: this recording). With the constants still off, a
/// step of the transfer everywhere at the same moment came 290 BIC units
/// ahead of the nozzle at the first step and was taken; the constants came
/// at the second. A step in time is now fitted again as its twins (the
/// pulse mass at each applicator, the transfer, the consumption) beside
/// the model as it stands, and the nozzle replaces the transfer step.
#[test]
fn a_transfer_step_taken_before_the_constants_gives_way_to_its_twin_the_nozzle() {
    let dir = tempfile::tempdir().unwrap();
    let truth_text =
        "[product]\ncn = 9.016668905202298\nk0_kg = 1.262722598432897e-09\nmu_c = 0.18585128964732467\n";
    let rec = synth(
        dir.path(),
        "tangent",
        2435,
        truth_text,
        &["generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,t0_utc=2024-04-09T12:00:00Z,f=0.5"],
    );
    let report = common::discover_report(&rec, &dir.path().join("report"));
    let found = report["effects_found"].as_array().unwrap();
    assert_eq!(found.len(), 1, "effects found: {found:?}");
    common::assert_nozzle_step(&found[0], "A1");
    let f = found[0]["params"]["f"].as_f64().unwrap();
    assert!((f - 0.5).abs() <= 0.25 * 0.5, "f = {f}");
    // The transfer step was taken first and gave way later.
    let steps = report["steps"].as_array().unwrap();
    assert!(
        steps[0]["accepted"]
            .as_str()
            .is_some_and(|a| a.starts_with("generic transfer × time")),
        "{}",
        steps[0]["accepted"]
    );
    assert!(
        steps.iter().any(|s| s["removed"]
            .as_str()
            .is_some_and(|r| r.contains("for generic pulse_mass × time"))),
        "{steps:?}"
    );
    assert!(
        report["rmse_after"].as_f64().unwrap() < 1.05 * SIGMA,
        "{}",
        report["rmse_after"]
    );
    let truth = ModelConfig::from_overlay_str(truth_text, "truth").unwrap();
    assert!(determined_hold_the_truth(&report, &truth) >= 3);
}

/// Issue 28: a dry friction 16 % above the laboratory's that falls with the
/// relative humidity (a linear term, -0.5 per unit of humidity about 0.5)
/// on a curve (the campaign of 2026-11-29, seed 20261142, site 5: this
/// recording). Over the humidities of the recording the two average out
/// near the laboratory's muD, so step 0 moves no dry friction; a factor is
/// 1 at its driver's reference point, so with muD held the humidity term
/// could not say that the level differs too, and the search reported
/// terms on air temperature and speed with a dry-friction step in time.
/// The screening and the fits now weigh such a term with its constant
/// beside it: the humidity term is named, muD is calibrated with an
/// interval that holds the truth, and nothing changes in time.
#[test]
fn a_dry_friction_falling_with_humidity_at_a_site_with_a_high_mu_d_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let mu_d = 0.6754028269180419;
    let rec = synth(
        dir.path(),
        "curve",
        7572,
        &format!("[product]\nmu_d = {mu_d}\n"),
        &["generic:acts_on=friction_dry,driver=relative_humidity,form=linear,gamma=-0.5"],
    );
    let report = common::discover_report(&rec, &dir.path().join("report"));
    let found = report["effects_found"].as_array().unwrap();
    assert_eq!(found.len(), 1, "effects found: {found:?}");
    assert_eq!(found[0]["acts_on"], "friction_dry", "{found:?}");
    assert_eq!(found[0]["driver"], "relative_humidity", "{found:?}");
    let c = constant(&report, "product.mu_d");
    assert_eq!(c["determined"], true, "{c}");
    let ci = c["ci95"].as_array().unwrap();
    let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
    assert!(lo <= mu_d && mu_d <= hi, "mu_d {mu_d} outside {c}");
    // It was taken at the first step, fitted with muD beside it.
    let accepted = report["steps"][0]["accepted"].as_str().unwrap();
    assert!(
        accepted.starts_with("generic friction_dry × relative_humidity")
            && accepted.contains(" with mu_d "),
        "{accepted}"
    );
    assert!(
        report["rmse_after"].as_f64().unwrap() < 1.05 * SIGMA,
        "{}",
        report["rmse_after"]
    );
}

/// The seed 20261208 calibration campaign's site 4 (tangent, kc 25 % low,
/// rail ageing hidden): `m_max_kg` is held with no sensitivity left at the
/// final fit (a standard error of millions in `ln p`). Through what held
/// constants may push into a determined one it widened `mu_d` to "95 %
/// 0–inf", written as `null`; a held constant now pushes no more than its
/// range allows. Every determined interval is finite and holds the truth,
/// and a held constant the recording leaves open is said to be open.
#[test]
fn a_held_constant_the_recording_leaves_open_neither_opens_nor_is_fixed() {
    let dir = tempfile::tempdir().unwrap();
    let truth_toml = "[product]\nkc = 0.4284219256840386\n";
    let rec = synth(
        dir.path(),
        "tangent",
        5368,
        truth_toml,
        &["rail_ageing:tau_s=7200"],
    );
    let report = calibrate(&rec, &dir.path().join("report"), None);
    let truth = ModelConfig::from_overlay_str(truth_toml, "truth").unwrap();
    assert!(determined_hold_the_truth(&report, &truth) >= 1);
    let mu_d = constant(&report, "product.mu_d");
    assert_eq!(mu_d["determined"], true, "{mu_d}");
    let ci = mu_d["ci95"].as_array().unwrap();
    assert!(ci[1].as_f64().unwrap() < 0.6, "{mu_d}");
    let m_max = constant(&report, "product.m_max_kg");
    let text = m_max["description"].as_str().unwrap();
    assert!(
        m_max["status"] != "held" || text.contains("leaves it open"),
        "{m_max}"
    );
}
