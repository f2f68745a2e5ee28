//! Read-out parameters without a replay (issue 44): the values read from
//! one replay's read-outs at other read-out parameters (`muD`, `muC`, `km`,
//! `friction_dry` and `friction_boundary` terms, `measurement` offsets)
//! equal a full replay with those parameters, to 1e-12, on recordings with
//! every kind of measurement, every named effect and every kind of generic
//! term. A state parameter changed the same way is not a read-out: the
//! read values then differ from the replay (the check can fail).

mod common;

use std::path::PathBuf;

use common::truth_of;

use tortwin_discover::data::Dataset;
use tortwin_model::config::ModelConfig;
use tortwin_model::product::ProductKey;
use tortwin_model::role::Role;
use tortwin_recording::Quantity;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Read-out terms of every kind, on top of whatever `cfg` has.
const READ_OUT_TERMS: &str = r#"
[product]
mu_d = 0.51
mu_c = 0.17
km_kg = 1.1e-4

[[effects.generic]]
acts_on = "friction_dry"
driver = "relative_humidity"
form = "linear"
gamma = -0.4

[[effects.generic]]
acts_on = "friction_boundary"
driver = "wheel_load_kN"
form = "power"
n = 0.2

[[effects.generic]]
acts_on = "friction_dry"
driver = "time"
form = "step"
t0_utc = "2024-04-15T12:00:00Z"
f = 0.9

[[effects.generic]]
acts_on = "measurement"
quantity = "adhesion"
offset = 0.004
"#;

/// Largest |read − replayed| over the rows.
fn worst(read: &[f64], replayed: &[f64]) -> f64 {
    assert_eq!(read.len(), replayed.len());
    read.iter()
        .zip(replayed)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

fn check(data: &Dataset, base: &ModelConfig, other: &ModelConfig) {
    assert_eq!(base.state_part(), other.state_part(), "the test's pair");
    let (at_base, readouts) = data.simulate_with_readouts(base).unwrap();
    assert_eq!(
        at_base,
        data.simulate(base).unwrap(),
        "asking for read-outs changes nothing"
    );
    let read = data.read_out(other, &readouts);
    let replayed = data.simulate(other).unwrap();
    let diff = worst(&read, &replayed);
    assert!(
        diff <= 1e-12,
        "{}: read-out vs replay differ by {diff:e}",
        data.path.display()
    );
    // The read-out parameters changed something (the pair is not trivial).
    assert!(worst(&at_base, &replayed) > 1e-3);
    // Every quantity was read.
    for q in [Quantity::Mu, Quantity::Adhesion, Quantity::RailMu] {
        assert!(
            data.rows.iter().any(|r| r.quantity == q),
            "{q:?} in {}",
            data.path.display()
        );
    }
}

#[test]
fn read_outs_equal_a_replay_with_generic_terms_of_every_kind() {
    let rec = root().join("tests/reference/recordings/generic_day.mcap");
    let data = Dataset::read(&rec).unwrap();
    let cfg = ModelConfig::from_file(&rec.with_extension("config.toml")).unwrap();
    // The recording's own terms (state and read-out ones), and the same
    // state with other read-outs.
    let mut other = cfg.clone();
    other.overlay_str(READ_OUT_TERMS, "read-out terms").unwrap();
    check(&data, &cfg, &other);
    check(&data, &cfg.state_part(), &cfg);
}

#[test]
fn read_outs_equal_a_replay_with_every_named_effect() {
    for name in ["curve_day_all_effects", "curve_day_bands_rain"] {
        let rec = root().join("recordings").join(format!("{name}.mcap"));
        let data = Dataset::read(&rec).unwrap();
        let truth = truth_of(&rec);
        let mut other = truth.clone();
        other.overlay_str(READ_OUT_TERMS, "read-out terms").unwrap();
        check(&data, &truth, &other);
    }
}

#[test]
fn a_state_parameter_is_not_read_out() {
    let rec = root().join("recordings/demo_day.mcap");
    let data = Dataset::read(&rec).unwrap();
    let base = ModelConfig::default();
    let (_, readouts) = data.simulate_with_readouts(&base).unwrap();
    for key in ProductKey::ALL {
        let mut other = base.clone();
        key.set(&mut other.product, key.get(&base.product) * 1.2);
        if other.validate("test").is_err() {
            continue;
        }
        let diff = worst(
            &data.read_out(&other, &readouts),
            &data.simulate(&other).unwrap(),
        );
        match key.role() {
            Role::ReadOut => assert!(diff <= 1e-12, "{key:?}: {diff:e}"),
            // Read as if it were a read-out, a state constant is wrong
            // somewhere (those the demo day shows at all).
            Role::State => {
                if !matches!(key, ProductKey::MMaxKg | ProductKey::K0Kg) {
                    assert!(
                        diff > 1e-9,
                        "{key:?} read out as if it did not move product"
                    );
                }
            }
        }
    }
}

/// A time step at `unix_s` on `acts_on`, as a configuration overlay.
fn time_step(acts_on: &str, unix_s: f64, f: f64) -> String {
    format!(
        "[[effects.generic]]\nacts_on = \"{acts_on}\"\ndriver = \"time\"\nform = \"step\"\n\
         t0_utc = \"{}\"\nf = {f}\n",
        tortwin_model::config::format_utc(unix_s)
    )
}

#[test]
fn a_replay_continued_from_a_checkpoint_equals_one_from_the_start() {
    let rec = root().join("tests/reference/recordings/generic_day.mcap");
    let data = Dataset::read(&rec).unwrap();
    let cfg = ModelConfig::from_file(&rec.with_extension("config.toml")).unwrap();
    let base = cfg.state_part();
    let (_, readouts, checkpoints) = data.simulate_with_checkpoints(&base, 16).unwrap();
    assert_eq!(checkpoints.len(), 16);
    let first_s = data.rows[0].log_time_ns as f64 * 1e-9;
    let last_s = data.rows[data.rows.len() - 1].log_time_ns as f64 * 1e-9;
    let at = |share: f64| first_s + share * (last_s - first_s);

    // A clogging nozzle half-way and more consumption later: both act
    // only after some checkpoints, so the replay continues from one.
    let mut later = base.clone();
    later
        .overlay_str(&time_step("pulse_mass", at(0.5), 0.4), "steps")
        .unwrap();
    later
        .overlay_str(&time_step("consumption", at(0.7), 1.5), "steps")
        .unwrap();
    let resumed = data
        .resume(&later, &checkpoints, &readouts)
        .expect("a checkpoint before the steps")
        .unwrap();
    let (from_start, full) = data.simulate_with_readouts(&later).unwrap();
    // The values of the model with read-outs (the recording's own terms).
    let mut with_readouts = later.clone();
    with_readouts.effects.generic = cfg.effects.generic.clone();
    with_readouts.effects.generic.extend(
        later.effects.generic[base.effects.generic.len()..]
            .iter()
            .cloned(),
    );
    let read_resumed = data.read_out(&later, &resumed);
    assert_eq!(
        read_resumed, from_start,
        "continued vs from the start, bit for bit"
    );
    assert_eq!(
        data.read_out(&with_readouts, &resumed),
        data.read_out(&with_readouts, &full)
    );
    // The steps changed the values (the check can fail).
    assert!(worst(&read_resumed, &data.read_out(&base, &readouts)) > 1e-3);

    // What cannot continue: a step before the first event, a term
    // that is not a time step, a changed constant, a term put before the
    // checkpointed ones.
    let mut early = base.clone();
    early
        .overlay_str(
            &time_step(
                "pulse_mass",
                data.events[0].log_time_ns as f64 * 1e-9 - 60.0,
                0.4,
            ),
            "early",
        )
        .unwrap();
    assert!(data.resume(&early, &checkpoints, &readouts).is_none());
    let mut weather = base.clone();
    weather
        .overlay_str(
            "[[effects.generic]]\nacts_on = \"consumption\"\ndriver = \"relative_humidity\"\n\
             form = \"linear\"\ngamma = 0.1\n",
            "weather",
        )
        .unwrap();
    assert!(data.resume(&weather, &checkpoints, &readouts).is_none());
    let mut constant = later.clone();
    constant.product.kc *= 1.1;
    assert!(data.resume(&constant, &checkpoints, &readouts).is_none());
    let mut reordered = later.clone();
    reordered.effects.generic.rotate_right(1);
    assert!(data.resume(&reordered, &checkpoints, &readouts).is_none());
}
