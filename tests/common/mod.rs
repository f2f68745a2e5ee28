//! Scaffolding shared by the integration tests: where the reference data
//! is, the binary, one Python runner, one sink that records what a run
//! publishes, and ([`recording`]) the one builder of input recordings with
//! the reader's section fixture. Each test file uses some of it.
#![allow(dead_code)]

/// The recordings builder lives beside the recording crate's own tests
/// (crates/recording/tests/support), which use it too: one copy.
#[path = "../../crates/recording/tests/support/recording.rs"]
pub mod recording;

use std::ffi::OsStr;
use std::path::PathBuf;
use std::process::{Command, Output};

use tortwin_engine::sink::{FieldSnapshot, MeasurementOutput, Sink, SnapshotKind, TrainEvent};
use tortwin_model::Quantity;

/// `tests/reference/NAME`: values and recordings from the independent
/// implementation (tests/reference/README.md says where each comes from).
pub fn reference(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/reference")
        .join(name)
}

/// `tests/reference/recordings/NAME`.
pub fn reference_recording(name: &str) -> PathBuf {
    reference("recordings").join(name)
}

/// `recordings/demo_day.mcap`: the recording bundled for the README's
/// main job.
pub fn demo_day() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("recordings/demo_day.mcap")
}

/// `tortwin replay recordings/demo_day.mcap --out-mcap DIR/demo.mcap`,
/// which must succeed; returns the output's path.
pub fn replay_demo_mcap(dir: &std::path::Path) -> PathBuf {
    let mcap = dir.join("demo.mcap");
    let o = tortwin()
        .arg("replay")
        .arg(demo_day())
        .arg("--out-mcap")
        .arg(&mcap)
        .arg("--quiet")
        .output()
        .unwrap();
    check(&o, "tortwin replay recordings/demo_day.mcap --out-mcap");
    mcap
}

/// `tortwin synth --days 4` into `dir/four_days.mcap`: a recording long
/// enough for a run to be killed or interrupted in the middle.
pub fn four_days(dir: &std::path::Path) -> PathBuf {
    let recording = dir.join("four_days.mcap");
    check(
        &tortwin()
            .args(["synth", "--quiet", "--days", "4", "--out"])
            .arg(&recording)
            .output()
            .unwrap(),
        "synth",
    );
    recording
}

/// The `tortwin` binary of this build.
pub fn tortwin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tortwin"))
}

/// Panics with the command's output unless it succeeded.
pub fn check(o: &Output, what: &str) {
    assert!(
        o.status.success(),
        "{what} failed ({})\n{}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// `tortwin discover RECORDING --report DIR` (its summary and its cost
/// echoed to stderr); returns report.json.
pub fn discover_report(recording: &std::path::Path, report: &std::path::Path) -> serde_json::Value {
    let o = tortwin()
        .arg("discover")
        .arg(recording)
        .arg("--report")
        .arg(report)
        .output()
        .unwrap();
    check(&o, "tortwin discover");
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));
    let json = report.join("report.json");
    let provenance = python("check_provenance.py", &[json.as_path(), recording]);
    check(&provenance, "check_provenance.py report.json");
    let text = std::fs::read_to_string(&json).unwrap();
    // What the case cost, beside its findings (a failing or slow case
    // shows where its time went).
    let md = std::fs::read_to_string(report.join("report.md")).unwrap_or_default();
    for line in md.lines().filter(|l| l.starts_with("| engine runs |")) {
        eprintln!("{line}");
    }
    serde_json::from_str(&text).unwrap()
}

/// Runs `tests/python/SCRIPT` with `args` under `$TORTWIN_PYTHON` (default
/// `python3`): the independent readers, whose packages .ci/run installs from
/// tests/python/requirements.txt. Fails, never skips, without them.
pub fn python<S: AsRef<OsStr>>(script: &str, args: &[S]) -> Output {
    let python = std::env::var("TORTWIN_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/python")
        .join(script);
    Command::new(&python)
        .arg(&path)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run {python} {} ({e}); install Python 3 and \
                 pip install -r tests/python/requirements.txt",
                path.display()
            )
        })
}

/// One measurement as the engine published it.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementRow {
    pub index_in_file: u64,
    pub log_time_ns: u64,
    pub site: String,
    pub rail: String,
    pub quantity: Quantity,
    pub train_id: Option<String>,
    pub axle_index: Option<usize>,
    pub measured: f64,
    pub simulated: f64,
}

/// One train as the engine published it.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainRow {
    pub log_time_ns: u64,
    pub end_ns: u64,
    pub train_id: String,
    pub speed_mps: f64,
}

/// One field snapshot, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldRow {
    pub kind: SnapshotKind,
    pub log_time_ns: u64,
    pub train_id: String,
    /// `rail/band`.
    pub track: String,
    pub wheel_pass: u64,
    pub mu: Vec<f64>,
    pub adhesion: Vec<f64>,
    pub rail_mass_kg: Vec<f64>,
    pub wheel_mass_kg: Vec<f64>,
}

/// A sink that records every measurement and train, and the field
/// snapshots when made with [`Recorder::with_fields`].
#[derive(Debug, Default)]
pub struct Recorder {
    pub measurements: Vec<MeasurementRow>,
    pub trains: Vec<TrainRow>,
    pub fields: Vec<FieldRow>,
    keep_fields: bool,
}

impl Recorder {
    pub fn with_fields() -> Self {
        Self {
            keep_fields: true,
            ..Self::default()
        }
    }

    /// The simulated value of every measurement, in publication order.
    pub fn simulated(&self) -> Vec<f64> {
        self.measurements.iter().map(|m| m.simulated).collect()
    }

    /// Root mean square of measured − simulated.
    pub fn rmse(&self) -> f64 {
        let n = self.measurements.len() as f64;
        let sq: f64 = self
            .measurements
            .iter()
            .map(|m| (m.measured - m.simulated).powi(2))
            .sum();
        (sq / n).sqrt()
    }
}

impl Sink for Recorder {
    fn train(&mut self, t: &TrainEvent<'_>) -> tortwin_engine::sink::SinkResult {
        self.trains.push(TrainRow {
            log_time_ns: t.log_time_ns,
            end_ns: t.end_ns,
            train_id: t.train_id.to_string(),
            speed_mps: t.speed_mps,
        });
        Ok(())
    }

    fn measurement(&mut self, m: &MeasurementOutput) -> tortwin_engine::sink::SinkResult {
        self.measurements.push(MeasurementRow {
            index_in_file: m.index_in_file,
            log_time_ns: m.log_time_ns,
            site: m.site_id.to_string(),
            rail: m.rail_name.to_string(),
            quantity: m.quantity,
            train_id: m.train_id.as_deref().map(str::to_string),
            axle_index: m.axle_index,
            measured: m.measured,
            simulated: m.simulated,
        });
        Ok(())
    }

    fn field(&mut self, f: &FieldSnapshot<'_>) -> tortwin_engine::sink::SinkResult {
        if self.keep_fields {
            self.fields.push(FieldRow {
                kind: f.kind,
                log_time_ns: f.log_time_ns,
                train_id: f.train_id.to_string(),
                track: format!("{}/{}", f.rail_name, f.band),
                wheel_pass: f.wheel_pass,
                mu: f.mu.to_vec(),
                adhesion: f.adhesion.to_vec(),
                rail_mass_kg: f.rail_mass_kg.to_vec(),
                wheel_mass_kg: f.wheel_mass_kg.to_vec(),
            });
        }
        Ok(())
    }
}

/// The truth configuration a bundled recording was written with (its
/// `REC.key.json`, `truth_config_toml`).
pub fn truth_of(recording: &std::path::Path) -> tortwin_model::config::ModelConfig {
    let key = recording.with_extension("key.json");
    let key: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&key).unwrap()).unwrap();
    tortwin_model::config::ModelConfig::from_overlay_str(
        key["truth_config_toml"].as_str().unwrap(),
        "truth",
    )
    .unwrap()
}

/// A found effect (report.json `effects_found`) is a step in time of the
/// pulse mass of `applicator` alone: a clogged nozzle.
pub fn assert_nozzle_step(effect: &serde_json::Value, applicator: &str) {
    assert_eq!(
        (&effect["acts_on"], &effect["driver"], &effect["scope"]),
        (
            &serde_json::json!("pulse_mass"),
            &serde_json::json!("time"),
            &serde_json::json!({ "applicator": applicator })
        ),
        "{effect}"
    );
}
