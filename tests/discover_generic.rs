//! `tortwin discover` beyond the catalogue: `tortwin synth` hides generic
//! terms (effects.md, "Generic terms"), gross outliers or a local change no
//! term describes in 3-day recordings with sigma = 0.01, and discover must
//! name exactly what is hidden (acts_on, driver, scope), with g within 25 %
//! of the truth's effect over the observed range, the RMSE within 1.2 sigma
//! where there are no outliers, and model.toml must reproduce rmse_after.

mod common;

use std::path::{Path, PathBuf};

use common::{check, tortwin};
use tortwin_discover::data::Dataset;
use tortwin_model::config::{GenericTerm, ModelConfig, TermEffect};

const SIGMA: f64 = 0.01;

/// A 3-day recording; `extra` are more synth arguments.
fn synth(dir: &Path, seed: u64, extra: &[&str]) -> (PathBuf, serde_json::Value) {
    let out = dir.join("rec.mcap");
    let o = tortwin()
        .args(["synth", "--days", "3", "--noise-sigma", "0.01"])
        .args(["--rain-events-per-day", "1", "--seed", &seed.to_string()])
        .args(extra)
        .arg("--out")
        .arg(&out)
        .arg("-q")
        .output()
        .unwrap();
    check(&o, "tortwin synth");
    let key = std::fs::read_to_string(dir.join("rec.key.json")).unwrap();
    (out, serde_json::from_str(&key).unwrap())
}

/// g of a term at x (through the model's own form), for terms with a driver.
fn g_of(term: &GenericTerm, x: f64) -> f64 {
    match term.effect {
        TermEffect::Factor { driver, form } => form.g(x, driver.x_ref().unwrap_or(0.0)),
        TermEffect::Offset { offset } => offset,
    }
}

/// The one generic term of a model.toml.
fn found_term(report_dir: &Path) -> (ModelConfig, GenericTerm) {
    let model = ModelConfig::from_file(&report_dir.join("model.toml")).expect("model.toml loads");
    assert_eq!(model.effects.generic.len(), 1, "{:?}", model.effects);
    let term = model.effects.generic[0].clone();
    (model, term)
}

/// model.toml loaded back reproduces rmse_after (outliers left out).
fn reproduces_rmse(rec: &Path, model: &ModelConfig, report: &serde_json::Value) {
    let data = Dataset::read(rec).unwrap();
    let sim = data.simulate(model).unwrap();
    let outliers: Vec<u64> = report["outliers"]["index_in_file"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    let (mut sse, mut n) = (0.0, 0usize);
    for (row, s) in data.rows.iter().zip(&sim) {
        if !outliers.contains(&row.index_in_file) {
            sse += (row.measured - s).powi(2);
            n += 1;
        }
    }
    let rmse = (sse / n as f64).sqrt();
    let want = report["rmse_after"].as_f64().unwrap();
    assert!((rmse - want).abs() <= 1e-12 * want, "{rmse} vs {want}");
}

fn found_list(report: &serde_json::Value) -> &Vec<serde_json::Value> {
    report["effects_found"].as_array().unwrap()
}

#[test]
fn a_clogged_nozzle_is_named_with_its_applicator_and_time() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, key) = synth(
        dir.path(),
        11,
        &[
            "--hidden",
            "generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,t0_utc=2024-04-09T12:00:00Z,f=0.6",
        ],
    );
    assert!(key["rmse_baseline_vs_truth"].as_f64().unwrap() > 1.5 * SIGMA);
    let report_dir = dir.path().join("report");
    let report = common::discover_report(&rec, &report_dir);
    let found = found_list(&report);
    assert_eq!(found.len(), 1, "{found:?}");
    let e = &found[0];
    assert_eq!(e["name"], "generic");
    assert_eq!(e["acts_on"], "pulse_mass");
    assert_eq!(e["driver"], "time");
    assert_eq!(e["form"], "step");
    assert_eq!(e["scope"], serde_json::json!({"applicator": "A1"}));
    let f = e["params"]["f"].as_f64().unwrap();
    assert!(
        (f - 0.6).abs() <= 0.25 * 0.4,
        "f = {f}: g − 1 within 25 % of the truth's −0.4"
    );
    let description = e["description"].as_str().unwrap();
    assert!(
        description.contains("A1") && description.contains("nozzle"),
        "{description}"
    );
    // t0 between the last train before 12:00 and the first after: no
    // train ran in between, so any such t0 is the same term.
    let (_, term) = found_term(&report_dir);
    let t0 = term.t0_utc().unwrap();
    assert!(
        t0.as_str() >= "2024-04-09T10:00:00Z" && t0.as_str() <= "2024-04-09T14:00:00Z",
        "{t0}"
    );
    let rmse_after = report["rmse_after"].as_f64().unwrap();
    assert!(rmse_after <= 1.2 * SIGMA, "{rmse_after}");
    let (model, _) = found_term(&report_dir);
    reproduces_rmse(&rec, &model, &report);
}

#[test]
fn a_biased_sensor_is_a_data_quality_finding() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = synth(
        dir.path(),
        5,
        &[
            "--hidden",
            "generic:acts_on=measurement,site=M1,rail=low,quantity=mu,offset=-0.02",
        ],
    );
    let report_dir = dir.path().join("report");
    let report = common::discover_report(&rec, &report_dir);
    let found = found_list(&report);
    assert_eq!(found.len(), 1, "{found:?}");
    let e = &found[0];
    assert_eq!(e["acts_on"], "measurement");
    assert_eq!(
        e["scope"],
        serde_json::json!({"site": "M1", "rail": "low", "quantity": "mu"})
    );
    assert!(e.get("driver").is_none() && e.get("form").is_none(), "{e}");
    let offset = e["params"]["offset"].as_f64().unwrap();
    assert!((offset + 0.02).abs() <= 0.25 * 0.02, "{offset}");
    assert_eq!(e["kind"], "data quality");
    assert!(e["description"].as_str().unwrap().contains("calibration"));
    assert!(report["rmse_after"].as_f64().unwrap() <= 1.2 * SIGMA);
    let (model, _) = found_term(&report_dir);
    reproduces_rmse(&rec, &model, &report);
}

#[test]
fn consumption_following_humidity_is_found_on_the_tangent() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, key) = synth(
        dir.path(),
        5,
        &[
            "--preset",
            "tangent",
            "--hidden",
            "generic:acts_on=consumption,driver=relative_humidity,form=exp,beta=1.5",
        ],
    );
    assert!(key["rmse_baseline_vs_truth"].as_f64().unwrap() > 1.2 * SIGMA);
    let report_dir = dir.path().join("report");
    let report = common::discover_report(&rec, &report_dir);
    let found = found_list(&report);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0]["acts_on"], "consumption");
    assert_eq!(found[0]["driver"], "relative_humidity");
    assert_eq!(found[0]["scope"], serde_json::json!({}));
    // g within 25 % of the truth's effect over the observed humidity.
    let (_, term) = found_term(&report_dir);
    let truth = |x: f64| (1.5 * (x - 0.5)).exp();
    let data = Dataset::read(&rec).unwrap();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for e in &data.events {
        if let tortwin_recording::EventKind::Weather(w) = &e.kind {
            lo = lo.min(w.relative_humidity);
            hi = hi.max(w.relative_humidity);
        }
    }
    for k in 0..=10 {
        let x = lo + (hi - lo) * f64::from(k) / 10.0;
        let (g, t) = (g_of(&term, x), truth(x));
        assert!(
            (g - t).abs() <= 0.25 * (t - 1.0).abs() + 0.01,
            "x {x}: g {g}, truth {t}"
        );
    }
    assert!(report["rmse_after"].as_f64().unwrap() <= 1.2 * SIGMA);
}

#[test]
fn gross_outliers_are_screened_and_nothing_is_added() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, key) = synth(dir.path(), 7, &["--outlier-share", "0.02"]);
    let report = common::discover_report(&rec, &dir.path().join("report"));
    assert!(
        found_list(&report).is_empty(),
        "{:?}",
        report["effects_found"]
    );
    let truth: Vec<u64> = key["outliers_index_in_file"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    let flagged: Vec<u64> = report["outliers"]["index_in_file"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    let hit = flagged.iter().filter(|i| truth.contains(i)).count();
    eprintln!(
        "{} outliers hidden, {} flagged, {hit} of them hidden ones",
        truth.len(),
        flagged.len()
    );
    // Tribometer readings have no neighbours to compare with; every axle
    // outlier is caught, nothing else is.
    assert!(
        hit as f64 >= 0.95 * truth.len() as f64,
        "{hit} of {}",
        truth.len()
    );
    assert!(
        flagged.len() - hit <= 2,
        "{} false alarms",
        flagged.len() - hit
    );
    assert!(report["rmse_after"].as_f64().unwrap() <= 1.1 * SIGMA);
    assert!(report["noise_estimate"].as_f64().unwrap() < 1.1 * SIGMA);
}

#[test]
fn friction_changed_at_one_site_for_half_a_day_stays_unexplained_and_located() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = synth(
        dir.path(),
        9,
        &["--local-friction", "M2:start_h=30,hours=12,delta=-0.06"],
    );
    let report = common::discover_report(&rec, &dir.path().join("report"));
    let physics: Vec<&serde_json::Value> = found_list(&report)
        .iter()
        .filter(|e| e["kind"] != "data quality")
        .collect();
    assert!(
        physics.is_empty(),
        "no physics term stands in for it: {physics:?}"
    );
    let u = &report["unexplained"];
    assert!(!u.is_null(), "{report}");
    let at = &u["location"];
    assert_eq!(at["site"], "M2", "{at}");
    // The window lies in the hidden one (30 h to 42 h after 2024-04-08).
    let from = at["from_utc"].as_str().unwrap();
    let to = at["to_utc"].as_str().unwrap();
    assert!(
        from >= "2024-04-09T05:00:00Z" && to <= "2024-04-09T18:30:00Z",
        "{from} .. {to}"
    );
    assert!(at["mean_residual"].as_f64().unwrap() < -0.02, "{at}");
}

/// Every value `driver` takes in the recording where a term can act: the
/// weather messages' values (and the defaults), or every wheel's.
fn observed(data: &Dataset, driver: tortwin_model::generic::Driver) -> Vec<f64> {
    use tortwin_model::generic::Driver as D;
    use tortwin_recording::EventKind;
    let mut xs = Vec::new();
    let w0 = tortwin_recording::Weather::default();
    match driver {
        D::AirTemperatureC => xs.push(w0.air_temperature_c),
        D::RelativeHumidity => xs.push(w0.relative_humidity),
        D::PrecipitationMmH => xs.push(w0.precipitation_mm_h),
        _ => {}
    }
    for e in &data.events {
        match &e.kind {
            EventKind::Weather(w) => match driver {
                D::AirTemperatureC => xs.push(w.air_temperature_c),
                D::RelativeHumidity => xs.push(w.relative_humidity),
                D::PrecipitationMmH => xs.push(w.precipitation_mm_h),
                _ => {}
            },
            EventKind::Passage(p) => match driver {
                D::SpeedMps => xs.push(p.speed_mps),
                D::WheelLoadKn => xs.extend(
                    p.axles
                        .iter()
                        .flat_map(|a| a.wheel_load_n.iter().map(|q| q / 1000.0)),
                ),
                D::Creepage => xs.extend(p.axles.iter().flat_map(|a| {
                    a.creepage
                        .iter()
                        .map(|c| (c.cx * c.cx + c.cy * c.cy).sqrt())
                })),
                _ => {}
            },
            _ => {}
        }
    }
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    xs
}

/// A hidden case: `hidden` are synth's `--hidden` specs; discover must find
/// exactly `named` (name, param, truth) and one generic term per entry of
/// `generic` (its `[[effects.generic]]` table), with the same acts_on,
/// driver and scope and g within 25 % of the truth's effect (g − 1) at every
/// value the driver takes in the recording, whatever form it chose.
fn generic_case(
    preset: &str,
    seed: u64,
    hidden: &[&str],
    named: &[(&str, &str, f64)],
    generic: &[&str],
    extra: &[&str],
) {
    let dir = tempfile::tempdir().unwrap();
    let mut args: Vec<&str> = vec!["--preset", preset];
    for h in hidden {
        args.extend(["--hidden", h]);
    }
    args.extend(extra);
    let (rec, key) = synth(dir.path(), seed, &args);
    let visible = key["rmse_baseline_vs_truth"].as_f64().unwrap();
    assert!(
        visible >= SIGMA,
        "{hidden:?}: only {visible:.4} from the truth: too weak a test"
    );
    let report_dir = dir.path().join("report");
    let report = common::discover_report(&rec, &report_dir);
    let found = found_list(&report);
    assert_eq!(found.len(), named.len() + generic.len(), "{found:?}");
    for (name, param, truth) in named {
        let e = found
            .iter()
            .find(|e| e["name"] == *name)
            .unwrap_or_else(|| panic!("{name} not found: {found:?}"));
        let v = e["params"][*param].as_f64().unwrap();
        assert!(
            (v - truth).abs() <= 0.25 * truth.abs(),
            "{name}.{param} = {v}, truth {truth}"
        );
    }
    let model = ModelConfig::from_file(&report_dir.join("model.toml")).unwrap();
    let data = Dataset::read(&rec).unwrap();
    for table in generic {
        let truth = ModelConfig::from_overlay_str(table, "truth")
            .unwrap()
            .effects
            .generic[0]
            .clone();
        let term = model
            .effects
            .generic
            .iter()
            .find(|t| {
                t.acts_on == truth.acts_on
                    && t.scope() == truth.scope()
                    && match (t.effect, truth.effect) {
                        (
                            TermEffect::Factor { driver: a, .. },
                            TermEffect::Factor { driver: b, .. },
                        ) => a == b,
                        _ => false,
                    }
            })
            .unwrap_or_else(|| panic!("{table} not found: {:?}", model.effects.generic));
        let TermEffect::Factor { driver, .. } = truth.effect else {
            unreachable!("the cases hide factors")
        };
        let xs = observed(&data, driver);
        let worst = xs
            .iter()
            .map(|&x| {
                let (g, t) = (g_of(term, x), g_of(&truth, x));
                ((g - t).abs() - 0.25 * (t - 1.0).abs(), x, g, t)
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap();
        assert!(
            worst.0 <= 0.005,
            "{table}: at x = {} g = {} vs truth {}",
            worst.1,
            worst.2,
            worst.3
        );
    }
    let rmse_after = report["rmse_after"].as_f64().unwrap();
    assert!(rmse_after <= 1.2 * SIGMA, "RMSE after {rmse_after}");
    reproduces_rmse(&rec, &model, &report);
}

#[test]
fn pulse_mass_following_air_temperature_is_found() {
    generic_case(
        "curve",
        5,
        &["generic:acts_on=pulse_mass,driver=air_temperature_c,form=linear,gamma=0.04"],
        &[],
        &["[[effects.generic]]\nacts_on = \"pulse_mass\"\ndriver = \"air_temperature_c\"\nform = \"linear\"\ngamma = 0.04\n"],
        &[],
    );
}

#[test]
fn transfer_following_speed_on_one_rail_is_found() {
    generic_case(
        "curve",
        5,
        &["generic:acts_on=transfer,rail=high,driver=speed_mps,form=linear,gamma=-0.08"],
        &[],
        &["[[effects.generic]]\nacts_on = \"transfer\"\nrail = \"high\"\ndriver = \"speed_mps\"\nform = \"linear\"\ngamma = -0.08\n"],
        &[],
    );
}

#[test]
fn boundary_friction_in_rain_is_found() {
    generic_case(
        "curve",
        5,
        &["generic:acts_on=friction_boundary,driver=precipitation_mm_h,form=step,x0=1.0,f=0.3"],
        &[],
        &["[[effects.generic]]\nacts_on = \"friction_boundary\"\ndriver = \"precipitation_mm_h\"\nform = \"step\"\nx0 = 1.0\nf = 0.3\n"],
        &[],
    );
}

#[test]
fn dry_friction_falling_with_wheel_load_on_one_rail_is_found() {
    generic_case(
        "curve",
        5,
        &["generic:acts_on=friction_dry,rail=low,driver=wheel_load_kN,form=power,n=-0.4"],
        &[],
        &["[[effects.generic]]\nacts_on = \"friction_dry\"\nrail = \"low\"\ndriver = \"wheel_load_kN\"\nform = \"power\"\nn = -0.4\n"],
        &[],
    );
}

/// On the curve the creepages span a wide range, and a consumption that
/// grows with creepage as a power 0.8 is told from eq. (3)'s linear law
/// (`kc`): the term is found (it beats the constants by 155 BIC units).
#[test]
fn consumption_growing_with_creepage_is_found_on_the_curve() {
    generic_case(
        "curve",
        5,
        &["generic:acts_on=consumption,driver=creepage,form=power,n=0.8"],
        &[],
        &["[[effects.generic]]\nacts_on = \"consumption\"\ndriver = \"creepage\"\nform = \"power\"\nn = 0.8\n"],
        &[],
    );
}

/// On the tangent the creepages span a narrow range, and there the same
/// term is `kc` 78 % high with `km1_kg` 17 % low, to the noise (until
/// 2026-11-28 the calibration's fit stopped at RMSE 1.4 x the noise, so the
/// term was found; the fit with exact Jacobians reaches the constants'
/// optimum). A constant is the plainer story: the constants are taken, no
/// effect is reported, and the verdict names the term the recording cannot
/// tell from them.
#[test]
fn consumption_growing_with_creepage_on_the_tangent_is_told_as_a_rival_of_kc() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = synth(
        dir.path(),
        5,
        &[
            "--preset",
            "tangent",
            "--hidden",
            "generic:acts_on=consumption,driver=creepage,form=power,n=0.8",
        ],
    );
    let report = common::discover_report(&rec, &dir.path().join("report"));
    assert!(found_list(&report).is_empty(), "{:?}", found_list(&report));
    let kc = report["site_constants"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["key"] == "product.kc")
        .unwrap();
    assert!(kc["value"].as_f64().unwrap() > 1.3 * 0.57, "{kc}");
    let noise = report["noise_estimate"].as_f64().unwrap();
    assert!(report["rmse_after"].as_f64().unwrap() <= 1.02 * noise);
    let verdict = report["verdict"].as_str().unwrap();
    assert!(
        verdict.contains("generic consumption × creepage") && verdict.contains("cannot tell"),
        "{verdict}"
    );
}

#[test]
fn a_named_effect_and_a_generic_term_are_both_found() {
    generic_case(
        "tangent",
        5,
        &[
            "rail_ageing:tau_s=7200",
            "generic:acts_on=friction_dry,driver=wheel_load_kN,form=power,n=-0.3",
        ],
        &[("rail_ageing", "tau_s", 7200.0)],
        &["[[effects.generic]]\nacts_on = \"friction_dry\"\ndriver = \"wheel_load_kN\"\nform = \"power\"\nn = -0.3\n"],
        &[],
    );
}

/// Issue 28: a strong generic term accepted first (the clogged nozzle) must
/// not hide a weaker catalogue effect. Once the nozzle is in, the residual
/// follows time_since_last_touch_s, rail_ageing's signature, and
/// rail_ageing is fitted again at that step and found.
#[test]
fn a_catalogue_effect_behind_a_clogged_nozzle_is_found() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = synth(
        dir.path(),
        11,
        &[
            "--hidden",
            "generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,t0_utc=2024-04-09T12:00:00Z,f=0.6",
            "--hidden",
            "rail_ageing:tau_s=7200",
        ],
    );
    let report_dir = dir.path().join("report");
    let report = common::discover_report(&rec, &report_dir);
    let found = found_list(&report);
    assert_eq!(found.len(), 2, "{found:?}");
    let nozzle = found
        .iter()
        .find(|e| e["name"] == "generic")
        .unwrap_or_else(|| panic!("no generic term: {found:?}"));
    common::assert_nozzle_step(nozzle, "A1");
    let f = nozzle["params"]["f"].as_f64().unwrap();
    assert!((f - 0.6).abs() <= 0.25 * 0.4, "f = {f}");
    let ageing = found
        .iter()
        .find(|e| e["name"] == "rail_ageing")
        .unwrap_or_else(|| panic!("rail_ageing not found: {found:?}"));
    let tau = ageing["params"]["tau_s"].as_f64().unwrap();
    assert!((tau - 7200.0).abs() <= 0.25 * 7200.0, "tau_s = {tau}");
    let rmse_after = report["rmse_after"].as_f64().unwrap();
    assert!(rmse_after <= 1.2 * SIGMA, "{rmse_after}");
}

#[test]
fn a_named_effect_is_found_through_two_percent_of_gross_outliers() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = synth(
        dir.path(),
        13,
        &[
            "--hidden",
            "rail_ageing:tau_s=7200",
            "--outlier-share",
            "0.02",
        ],
    );
    let report = common::discover_report(&rec, &dir.path().join("report"));
    let found = found_list(&report);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0]["name"], "rail_ageing");
    let tau = found[0]["params"]["tau_s"].as_f64().unwrap();
    assert!((tau - 7200.0).abs() <= 0.25 * 7200.0, "{tau}");
    assert!(report["outliers"]["count"].as_u64().unwrap() > 100);
    // Without the outliers the fit is at the noise.
    assert!(report["rmse_after"].as_f64().unwrap() <= 1.2 * SIGMA);
}
