//! The stepping kernel's builds give the same bits: the vector one (four
//! wheels' exponentials and quotients in one AVX2/FMA register, the
//! default where the CPU has them; where it has AVX-512F, two consecutive
//! groups of a track as one wavefront of eight wheels in AVX-512 registers,
//! unless `EngineOptions::narrow_kernel`) and the portable one
//! (`EngineOptions::portable_kernel`: `f64::exp` and `/` lane by lane).
//! Every measurement's simulated value, every read-out mass and its
//! tangent, the state before every train and at the end, and the run's
//! mass balance are compared bit for bit on the bundled recordings: the
//! paper's model, every named effect, bands and rain, generic terms, a
//! line, with and without tangents.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// this file's helpers are test code too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use std::path::PathBuf;

use tortwin_engine::sink::{MeasurementOutput, Sink, SinkResult};
use tortwin_engine::{Engine, EngineOptions};
use tortwin_model::config::ModelConfig;
use tortwin_recording::event::EventKind;
use tortwin_recording::recording::Recording;

/// The repository's root.
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The truth configuration a bundled recording was written with (its
/// `REC.key.json`, `truth_config_toml`).
fn truth_of(recording: &std::path::Path) -> ModelConfig {
    let key = recording.with_extension("key.json");
    let key: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&key).unwrap()).unwrap();
    ModelConfig::from_overlay_str(key["truth_config_toml"].as_str().unwrap(), "truth").unwrap()
}

/// Every measurement as text that differs wherever a bit does (`{:?}` of
/// an f64 is its shortest round-trip form).
#[derive(Default)]
struct Collect(Vec<String>);

impl Sink for Collect {
    fn measurement(&mut self, m: &MeasurementOutput) -> SinkResult {
        let readout = m.readout.as_deref().map(|r| (r.mass_kg, r.mass_tangent));
        self.0.push(format!(
            "{} {:?} {:?}",
            m.index_in_file, m.simulated, readout
        ));
        Ok(())
    }

    fn wants_readouts(&self) -> bool {
        true
    }
}

/// The measurements and the states (as JSON) of one replay: before every
/// train (after the trains before it have passed) and at the end, then the
/// run's mass balance.
///
/// `serial`: as beside a replay's output threads, where a train's tracks
/// roll on one thread (two at a time, their groups side by side), not in
/// parallel.
fn replay(
    rec: &Recording,
    cfg: &ModelConfig,
    tangents: bool,
    portable: bool,
    (serial, narrow): (bool, bool),
) -> (Vec<String>, Vec<String>) {
    let mut engine = Engine::on_line(
        rec.section.clone(),
        rec.line.clone(),
        cfg.clone(),
        EngineOptions {
            tangents,
            portable_kernel: portable,
            narrow_kernel: narrow,
            beside_output_threads: serial,
            ..EngineOptions::default()
        },
        rec.origin_ns,
    );
    let mut sink = Collect::default();
    let mut states = Vec::new();
    for event in &rec.events {
        if matches!(event.kind, EventKind::Passage(_)) {
            states.push(serde_json::to_string(&engine.state()).unwrap());
        }
        engine.push(event.clone(), &mut sink).unwrap();
    }
    let summary = engine
        .finish(&mut sink, rec.unknown_topic_messages)
        .unwrap();
    states.push(serde_json::to_string(&engine.state()).unwrap());
    // The mass balance's totals (consumed, capped, lost, carried out), in
    // `{:?}`'s round-trip form.
    states.push(format!("{:?}", summary.mass_balance));
    (sink.0, states)
}

#[test]
fn the_vector_kernel_gives_the_portable_kernels_bits() {
    if !tortwin_model::exp::exp4_is_vectorised() {
        eprintln!("this CPU has no AVX2 and FMA: both replays run the portable kernel");
    }
    let cases: Vec<(PathBuf, ModelConfig)> =
        ["demo_day", "curve_day_all_effects", "curve_day_bands_rain"]
            .iter()
            .map(|name| {
                let path = root().join("recordings").join(format!("{name}.mcap"));
                let cfg = truth_of(&path);
                (path, cfg)
            })
            // The paper's model on a recording with two applicators: the
            // vector kernel's clock-free contacts (no time effect, no term
            // moved by time or weather) leave step 1's stores to the
            // track's last wheel; the portable kernel stores every touch.
            .chain(std::iter::once((
                root().join("recordings/curve_day_all_effects.mcap"),
                ModelConfig::default(),
            )))
            // Bogie bands without rain: each band's track keeps its own
            // pulses and touches, clock-free.
            .chain(std::iter::once((
                root().join("recordings/curve_day_bands_rain.mcap"),
                ModelConfig::from_overlay_str("[effects.bogie_bands]\n", "bands").unwrap(),
            )))
            // A line (line.md; no effect is switched on on a line): its
            // rail bands' touches, stored by the last wheel whose row meets
            // each band.
            .chain(std::iter::once((
                root().join("tests/reference/recordings/line_field.mcap"),
                ModelConfig::default(),
            )))
            .chain(std::iter::once({
                let dir = root().join("tests/reference/recordings");
                let text = std::fs::read_to_string(dir.join("generic_day.config.toml")).unwrap();
                let cfg = ModelConfig::from_overlay_str(&text, "generic_day.config.toml").unwrap();
                (dir.join("generic_day.mcap"), cfg)
            }))
            .collect();
    for (path, cfg) in &cases {
        let rec = Recording::read(path).unwrap();
        assert_kernels_agree(&rec, cfg, &path.display().to_string());
    }
    // A second applicator on one rail only, without pulses (a wheel's
    // transfer counts from it all the same): the two rails' tracks have
    // different special points, where a run of ordinary steps of the two
    // side by side must stop for one of them.
    let mut rec = Recording::read(&root().join("recordings/demo_day.mcap")).unwrap();
    let mut second = rec.section.applicators[0].clone();
    second.id = "A2".to_string();
    second.position_m = 0.55 * rec.section.length_m;
    second.rails = vec![1];
    rec.section.applicators.push(second);
    assert_kernels_agree(
        &rec,
        &ModelConfig::default(),
        "demo_day, a second applicator on one rail",
    );
}

/// The vector kernel (tracks in parallel and side by side, in wavefronts
/// of eight wheels where the CPU has AVX-512 and of four) against the
/// portable one on `rec`, with and without tangents.
fn assert_kernels_agree(rec: &Recording, cfg: &ModelConfig, name: &str) {
    for tangents in [false, true] {
        let (portable, portable_state) = replay(rec, cfg, tangents, true, (false, false));
        for (serial, narrow) in [(false, false), (true, false), (false, true), (true, true)] {
            let (vector, vector_state) = replay(rec, cfg, tangents, false, (serial, narrow));
            // The field line has 32 measurements; every section
            // recording more than 100.
            let least = if rec.line.is_some() { 30 } else { 100 };
            assert!(
                vector.len() > least,
                "{name}: {} measurements",
                vector.len()
            );
            let case = format!("{name} (tangents {tangents}, serial {serial}, narrow {narrow})");
            assert_eq!(vector.len(), portable.len(), "{case}");
            if let Some(k) = (0..vector.len()).find(|&k| vector[k] != portable[k]) {
                panic!(
                    "{case}: measurement {k} differs:\nvector   {}\nportable {}",
                    vector[k], portable[k]
                );
            }
            assert_eq!(vector_state.len(), portable_state.len());
            let differs = (0..vector_state.len()).find(|&k| vector_state[k] != portable_state[k]);
            if let Some(k) = differs {
                panic!("{case}: the states before train {k} differ");
            }
        }
    }
}
