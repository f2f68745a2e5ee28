//! The rerun sink writes an `.rrd` that rerun itself reads back with the
//! values it was given: `tests/python/check_rrd.py` runs `rerun rrd verify`
//! and reads the file with `rerun.experimental.RrdReader`.
//!
//! Needs `python3` (or `$TORTWIN_PYTHON`) with `rerun-sdk[datafusion]==0.36.3`;
//! without them the test fails and says so. Set `TORTWIN_KEEP_RRD=FILE` to
//! keep a copy of the recording for a look in the viewer (`rerun FILE`).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::json;
use tortwin_engine::sink::{
    FieldSnapshot, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink, SnapshotKind,
    TrackInfo, TrainEvent,
};
use tortwin_outputs::rerun_out::{RerunOptions, RerunSink, SERIES_CHUNK_ROWS};
use tortwin_recording::{Applicator, Direction, Quantity, Section, Site};

const GRID_POINTS: usize = 201;
const SPACING_M: f64 = 0.5;
const AXLES: u64 = 8;
const TRAINS: u64 = 3;
const ORIGIN_NS: u64 = 1_700_000_000_000_000_000;
const TRAIN_INTERVAL_NS: u64 = 600_000_000_000;

fn section() -> Section {
    Section {
        section_id: "test-curve".to_owned(),
        length_m: (GRID_POINTS - 1) as f64 * SPACING_M,
        rails: vec!["high".to_owned(), "low".to_owned()],
        curve_radius_m: Some(300.0),
        rail_head_radius_m: 0.3,
        nominal_wheel_diameter_m: 0.92,
        applicators: vec![Applicator {
            id: "A1".to_owned(),
            position_m: 10.0,
            rails: vec![0, 1],
            nominal_pulse_kg: 0.002,
        }],
        sites: vec![Site {
            id: "S1".to_owned(),
            position_m: 60.0,
        }],
    }
}

fn tracks() -> Vec<TrackInfo> {
    [
        (0, "high", "gauge_corner"),
        (0, "high", "top"),
        (1, "low", "top"),
    ]
    .into_iter()
    .map(|(rail, rail_name, band)| TrackInfo {
        rail,
        rail_name: rail_name.to_owned(),
        band: band.to_owned(),
    })
    .collect()
}

/// A made-up but distinct profile for every (track, wheel pass).
fn profile(track: usize, wheel_pass: u64, scale: f64) -> Vec<f64> {
    (0..GRID_POINTS)
        .map(|i| {
            let x = i as f64 * 0.037 + track as f64 * 1.3 + wheel_pass as f64 * 0.21;
            scale * (0.3 + 0.1 * x.sin())
        })
        .collect()
}

/// The friction field after `wheel_pass` wheels on `track`.
struct Field {
    mu: Vec<f64>,
    adhesion: Vec<f64>,
    rail_mass_kg: Vec<f64>,
    wheel_mass_kg: Vec<f64>,
}

fn field(track: usize, wheel_pass: u64) -> Field {
    Field {
        mu: profile(track, wheel_pass, 1.0),
        adhesion: profile(track, wheel_pass, 0.6),
        rail_mass_kg: profile(track, wheel_pass + 100, 1e-4),
        wheel_mass_kg: profile(track, wheel_pass + 200, 2e-5),
    }
}

/// What a run logged on the `time` series: per entity, `(log_time_ns, values)`.
type Logged = BTreeMap<String, Vec<(u64, Vec<f64>)>>;

/// A synthetic run: `trains` trains of eight axles over three tracks, a
/// pulse before each, a measurement after each, and wheel snapshots for the
/// second train. Returns the pulses and measurements as the rrd must hold
/// them: a train's pulses summed per applicator and rail (g) at its first
/// snapshot, a measurement as [measured, simulated].
fn feed(sink: &mut dyn Sink, trains: u64) -> Result<Logged, tortwin_engine::sink::SinkError> {
    let mut logged = Logged::new();
    let section = section();
    let tracks = tracks();
    let grid_d_m: Vec<f64> = (0..GRID_POINTS).map(|i| i as f64 * SPACING_M).collect();
    sink.begin(&SectionInfo {
        section: std::borrow::Cow::Borrowed(&section),
        grid_d_m: (&grid_d_m).into(),
        tracks: (&tracks).into(),
        applicator_points: (&[20][..]).into(),
        site_points: (&[120][..]).into(),
        origin_ns: ORIGIN_NS as i64,
        line: None,
    })?;

    for train in 1..=trains {
        let start_ns = ORIGIN_NS + train * TRAIN_INTERVAL_NS;
        let end_ns = start_ns + 20_000_000_000;
        let train_id = format!("T{train}");
        for rail in 0..2 {
            let pulse = PulseEvent {
                log_time_ns: start_ns - 60_000_000_000,
                applicator: 0,
                applicator_id: "A1".into(),
                rail,
                rail_name: (&section.rails[rail]).into(),
                mass_kg: 0.0019 + 0.0001 * train as f64,
            };
            sink.pulse(&pulse)?;
            // The first snapshot of the train: its first wheel's on the
            // second train, else the train's.
            let first_snapshot_s = if train == 2 { 1 } else { AXLES };
            logged
                .entry(format!("/applicator/A1/{}", pulse.rail_name))
                .or_default()
                .push((
                    start_ns + first_snapshot_s * 1_000_000_000,
                    vec![pulse.mass_kg * 1e3],
                ));
        }
        sink.train(&TrainEvent {
            log_time_ns: start_ns,
            end_ns,
            train_id: (&train_id).into(),
            direction: if train % 2 == 0 {
                Direction::Down
            } else {
                Direction::Up
            },
            speed_mps: 20.0,
            axles: AXLES as usize,
        })?;
        let first_wheel = (train - 1) * AXLES + 1;
        let last_wheel = train * AXLES;
        let snapshots = if train == 2 {
            (first_wheel..=last_wheel)
                .map(|w| (SnapshotKind::Wheel, w))
                .collect()
        } else {
            Vec::new()
        };
        for (kind, wheel_pass) in snapshots
            .into_iter()
            .chain([(SnapshotKind::Train, last_wheel)])
        {
            for (index, track) in tracks.iter().enumerate() {
                let f = field(index, wheel_pass);
                sink.field(&FieldSnapshot {
                    kind,
                    log_time_ns: start_ns + (wheel_pass - first_wheel + 1) * 1_000_000_000,
                    train_id: (&train_id).into(),
                    track: index,
                    rail_name: (&track.rail_name).into(),
                    band: (&track.band).into(),
                    wheel_pass,
                    d_m: (&grid_d_m).into(),
                    mu: (&f.mu).into(),
                    adhesion: (&f.adhesion).into(),
                    rail_mass_kg: (&f.rail_mass_kg).into(),
                    wheel_mass_kg: (&f.wheel_mass_kg).into(),
                })?;
            }
        }
        for (rail, quantity) in [(0, Quantity::Mu), (1, Quantity::RailMu)] {
            let m = MeasurementOutput {
                log_time_ns: end_ns + 5_000_000_000,
                index_in_file: train * 10 + rail as u64,
                site_id: "S1".into(),
                site: 0,
                rail_name: section.rails[rail].as_str().into(),
                rail,
                quantity,
                train_id: (quantity == Quantity::Mu).then(|| train_id.as_str().into()),
                axle_index: (quantity == Quantity::Mu).then_some(3),
                measured: 0.25 + 0.01 * train as f64,
                simulated: 0.24 + 0.012 * train as f64,
                readout: None,
            };
            sink.measurement(&m)?;
            logged
                .entry(format!("/sites/S1/{}/{}", m.rail_name, m.quantity.as_str()))
                .or_default()
                .push((m.log_time_ns, vec![m.measured, m.simulated]));
        }
    }
    Ok(logged)
}

/// `logged` as the checker's "series" expectation.
fn series_json(logged: &Logged) -> serde_json::Value {
    logged
        .iter()
        .map(|(entity, points)| (entity.clone(), json!(points)))
        .collect::<serde_json::Map<_, _>>()
        .into()
}

/// What every expectation carries: the grid and the section's plan.
fn with_section(mut expected: serde_json::Value) -> serde_json::Value {
    let section = section();
    expected["d_m"] = json!((0..GRID_POINTS)
        .map(|i| i as f64 * SPACING_M)
        .collect::<Vec<_>>());
    expected["section"] = json!({
        "length_m": section.length_m,
        "curve_radius_m": section.curve_radius_m,
        "rails": section.rails,
    });
    expected
}

/// Runs the checker on `rrd` with `expected` (and the section); panics with
/// its output on failure.
fn check_rrd(rrd: &Path, expected: serde_json::Value, dir: &Path, name: &str) {
    let expected = with_section(expected);
    let expected_path = dir.join(format!("{name}.json"));
    std::fs::write(&expected_path, expected.to_string()).expect("writing expected values");
    let output = common::python("check_rrd.py", &[rrd, &expected_path]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "check_rrd.py ({name}) failed with {}:\n{stdout}{stderr}\n\
         (it needs `pip install \"rerun-sdk[datafusion]==0.36.3\"`)",
        output.status
    );
    println!("{stdout}");
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("listing the test directory")
        .map(|entry| entry.expect("reading a directory entry").path())
        .collect();
    files.sort();
    files
}

#[test]
fn rerun_reads_back_the_fields_the_sink_was_given() {
    let dir = tempfile::tempdir().expect("creating a temporary directory");
    let rrd = dir.path().join("run.rrd");
    let mut sink = RerunSink::create(
        &rrd,
        RerunOptions {
            history_rows: 2,
            // The heatmap at every train: the first train's is checked.
            history_every: 1,
            ..RerunOptions::default()
        },
    )
    .expect("creating the rerun sink");
    let logged = feed(&mut sink, TRAINS).expect("feeding the sink");
    assert!(!rrd.exists(), "the target must not exist before finish");
    sink.finish(&RunSummary::default())
        .expect("finishing the sink");
    drop(sink);
    assert_eq!(
        files_in(dir.path()),
        vec![rrd.clone()],
        "finish leaves exactly the target file"
    );

    if let Ok(keep) = std::env::var("TORTWIN_KEEP_RRD") {
        std::fs::copy(&rrd, &keep).expect("copying the recording to $TORTWIN_KEEP_RRD");
    }

    // high/top (track 1) after the last train: blocks of B = 2 trains, the
    // third train the first row of the second block.
    check_rrd(
        &rrd,
        json!({
            "rail": "high",
            "band": "top",
            "wheel_pass": TRAINS * AXLES,
            "mu": field(1, TRAINS * AXLES).mu,
            "check_history": true,
            "history_logged_at": [AXLES, 2 * AXLES, 3 * AXLES],
            "blueprint": true,
        }),
        dir.path(),
        "last_train_high_top",
    );
    // high/gauge_corner (track 0) after the first train: a one-row block,
    // and the band drawn beside its rail.
    check_rrd(
        &rrd,
        json!({
            "rail": "high",
            "band": "gauge_corner",
            "wheel_pass": AXLES,
            "mu": field(0, AXLES).mu,
            "check_history": true,
            "blueprint": true,
        }),
        dir.path(),
        "first_train_high_gauge_corner",
    );
    // low/top (track 2) mid-train: a wheel snapshot of the second train;
    // every pulse and measurement, at its time.
    check_rrd(
        &rrd,
        json!({
            "rail": "low",
            "band": "top",
            "wheel_pass": AXLES + 3,
            "mu": field(2, AXLES + 3).mu,
            "series": series_json(&logged),
        }),
        dir.path(),
        "wheel_low_top",
    );
}

#[test]
fn the_history_is_logged_every_n_trains_and_when_a_block_is_full() {
    let dir = tempfile::tempdir().expect("creating a temporary directory");
    // Blocks of B = 3 trains. E = 2 over three trains: after the second,
    // and after the third, which fills the block. E = 3: after the third
    // only, not twice.
    for (every, logged_at) in [(2, vec![2 * AXLES, 3 * AXLES]), (3, vec![3 * AXLES])] {
        let rrd = dir.path().join(format!("every_{every}.rrd"));
        let mut sink = RerunSink::create(
            &rrd,
            RerunOptions {
                history_rows: 3,
                history_every: every,
                ..RerunOptions::default()
            },
        )
        .expect("creating the rerun sink");
        feed(&mut sink, TRAINS).expect("feeding the sink");
        sink.finish(&RunSummary::default())
            .expect("finishing the sink");
        drop(sink);
        for (track, rail, band) in [(1, "high", "top"), (2, "low", "top")] {
            check_rrd(
                &rrd,
                json!({
                    "rail": rail,
                    "band": band,
                    "wheel_pass": TRAINS * AXLES,
                    "mu": field(track, TRAINS * AXLES).mu,
                    "check_history": true,
                    "history_logged_at": logged_at,
                    "blueprint": true,
                }),
                dir.path(),
                &format!("every_{every}_{rail}_{band}"),
            );
        }
    }
}

#[test]
fn a_long_run_comes_back_whole() {
    // Longer than a chunk of every kind: the snapshots (a few hundred a
    // chunk), a measurement series (SERIES_CHUNK_ROWS rows a chunk) and the
    // default history blocks and cadence.
    const LONG: u64 = 600;
    let dir = tempfile::tempdir().expect("creating a temporary directory");
    let rrd = dir.path().join("long.rrd");
    let options = RerunOptions::default();
    let every = options.history_every as u64;
    let mut sink = RerunSink::create(&rrd, options).expect("creating the rerun sink");
    let mut logged = feed(&mut sink, LONG).expect("feeding the sink");
    let first_ns = ORIGIN_NS + (LONG + 1) * TRAIN_INTERVAL_NS;
    for i in 0..2 * SERIES_CHUNK_ROWS as u64 + 7 {
        let m = MeasurementOutput {
            log_time_ns: first_ns + i * 1_000_000_000,
            index_in_file: 10_000 + i,
            site_id: "S1".into(),
            site: 0,
            rail_name: "high".into(),
            rail: 0,
            quantity: Quantity::Mu,
            train_id: Some("T1".into()),
            axle_index: Some(0),
            measured: 0.3 + 1e-6 * i as f64,
            simulated: 0.31 - 1e-6 * i as f64,
            readout: None,
        };
        sink.measurement(&m).expect("a measurement");
        logged
            .entry("/sites/S1/high/mu".to_owned())
            .or_default()
            .push((m.log_time_ns, vec![m.measured, m.simulated]));
    }
    sink.finish(&RunSummary::default())
        .expect("finishing the sink");
    drop(sink);

    let mut logged_at: Vec<u64> = (1..=LONG / every).map(|n| n * every * AXLES).collect();
    if !LONG.is_multiple_of(every) {
        logged_at.push(LONG * AXLES);
    }
    for wheel_pass in [every * AXLES + AXLES, LONG * AXLES] {
        let mut expected = json!({
            "rail": "high",
            "band": "gauge_corner",
            "wheel_pass": wheel_pass,
            "mu": field(0, wheel_pass).mu,
        });
        if wheel_pass == LONG * AXLES {
            expected["check_history"] = json!(true);
            expected["history_logged_at"] = json!(logged_at);
            expected["series"] = series_json(&logged);
        }
        check_rrd(&rrd, expected, dir.path(), &format!("long_{wheel_pass}"));
    }
}

#[test]
fn dropped_without_finish_leaves_no_file() {
    let dir = tempfile::tempdir().expect("creating a temporary directory");
    let rrd = dir.path().join("failed.rrd");
    let mut sink =
        RerunSink::create(&rrd, RerunOptions::default()).expect("creating the rerun sink");
    feed(&mut sink, 1).expect("feeding the sink");
    assert_eq!(
        files_in(dir.path()).len(),
        1,
        "the temporary file exists while running"
    );
    drop(sink);
    assert!(
        !rrd.exists(),
        "no file at the target after a drop without finish"
    );
    assert_eq!(
        files_in(dir.path()),
        Vec::<PathBuf>::new(),
        "the temporary file is gone"
    );
}

#[test]
fn a_snapshot_off_the_grid_is_an_error() {
    let dir = tempfile::tempdir().expect("creating a temporary directory");
    let rrd = dir.path().join("bad.rrd");
    let mut sink =
        RerunSink::create(&rrd, RerunOptions::default()).expect("creating the rerun sink");
    feed(&mut sink, 1).expect("feeding the sink");
    let short = vec![0.3; GRID_POINTS - 1];
    let err = sink
        .field(&FieldSnapshot {
            kind: SnapshotKind::Train,
            log_time_ns: ORIGIN_NS,
            train_id: "T9".into(),
            track: 0,
            rail_name: "high".into(),
            band: "gauge_corner".into(),
            wheel_pass: 100,
            d_m: (&short).into(),
            mu: (&short).into(),
            adhesion: (&short).into(),
            rail_mass_kg: (&short).into(),
            wheel_mass_kg: (&short).into(),
        })
        .expect_err("a snapshot with fewer points than the grid");
    assert!(err.to_string().contains("T9"), "{err:#}");
}
