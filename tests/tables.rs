//! A recording as tables (`tortwin_recording::tables`): a bundled recording
//! exported to CSV and imported back replays to the same measurements, bit
//! for bit; a bad table is an error that names the file, line and column.

mod common;

use std::path::{Path, PathBuf};

use tortwin_jobs::replay::{replay, ReplayArgs};
use tortwin_recording::tables::{export::export_dir, import::import_dir};

fn bundled(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("recordings")
        .join(name)
}

/// Every measurement's simulated value of a replay, in replay order.
fn measurements(recording: &Path) -> Vec<(u64, String, f64, f64)> {
    let mut sink = common::Recorder::default();
    let args = ReplayArgs::new(recording.to_path_buf());
    replay(&args, None, &mut [&mut sink], &tortwin_study::Silent).unwrap();
    sink.measurements
        .iter()
        .map(|m| {
            let at = format!(
                "{} {} {:?} {:?} {:?}",
                m.site, m.rail, m.quantity, m.train_id, m.axle_index
            );
            (m.log_time_ns, at, m.measured, m.simulated)
        })
        .collect()
}

#[test]
fn a_bundled_recording_exported_and_imported_replays_the_same() {
    for name in [
        "demo_day.mcap",
        "curve_day_all_effects.mcap",
        "tangent_day_ageing.mcap",
    ] {
        let dir = tempfile::tempdir().unwrap();
        let tables = dir.path().join("tables");
        let original = bundled(name);
        let exported = export_dir(&original, &tables).unwrap();
        let back = dir.path().join("back.mcap");
        let imported = import_dir(&tables, &back).unwrap();
        assert_eq!(
            (
                exported.trains,
                exported.axles,
                exported.pulses,
                exported.weather,
                exported.measurements
            ),
            (
                imported.trains,
                imported.axles,
                imported.pulses,
                imported.weather,
                imported.measurements
            ),
            "{name}"
        );
        let (a, b) = (measurements(&original), measurements(&back));
        assert_eq!(a.len(), b.len(), "{name}");
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.0, y.0, "{name}");
            assert_eq!(x.1, y.1, "{name}");
            assert_eq!(
                x.2.to_bits(),
                y.2.to_bits(),
                "{name}: measured {x:?} vs {y:?}"
            );
            assert_eq!(
                x.3.to_bits(),
                y.3.to_bits(),
                "{name}: simulated {x:?} vs {y:?}"
            );
        }
    }
}

/// The tables of the demo day in a fresh folder.
fn demo_tables() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let tables = dir.path().join("tables");
    export_dir(&bundled("demo_day.mcap"), &tables).unwrap();
    (dir, tables)
}

/// Line `line` (1-based) of `file` in `tables`, column `column` (1-based)
/// replaced by `value`; `None` drops the column from every line.
fn edit(tables: &Path, file: &str, line: usize, column: usize, value: Option<&str>) {
    let path = tables.join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(k, l)| {
            let mut cells: Vec<&str> = l.split(',').collect();
            match value {
                None => {
                    cells.remove(column - 1);
                }
                Some(v) if k + 1 == line => cells[column - 1] = v,
                Some(_) => {}
            }
            cells.join(",")
        })
        .collect();
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
}

fn header(tables: &Path, file: &str) -> Vec<String> {
    let text = std::fs::read_to_string(tables.join(file)).unwrap();
    text.lines()
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect()
}

fn column(tables: &Path, file: &str, name: &str) -> usize {
    header(tables, file).iter().position(|h| h == name).unwrap() + 1
}

/// `tortwin import tables`, expecting exit status 2 and an error at
/// `file:line:column` whose text says `says`; nothing may be left in the
/// output folder.
fn fails_at(tables: &Path, file: &str, line: usize, column: usize, says: &str) {
    let folder = tables.parent().unwrap().join("out");
    let out = folder.join("bad.mcap");
    let o = common::tortwin()
        .arg("import")
        .arg(tables)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{text}");
    let at = format!("{file}:{line}:{column}: ");
    assert!(text.contains(&at), "expected {at} in: {text}");
    assert!(text.contains(says), "expected `{says}` in: {text}");
    assert!(!text.contains("panicked"), "{text}");
    let left: Vec<_> = std::fs::read_dir(&folder).unwrap().collect();
    assert!(left.is_empty(), "a failed import left {left:?}");
}

/// The example tables documented in docs/spec/csv-tables.md (made from the
/// demo day by `tortwin export --inputs`) import, through the command line,
/// into a recording that replays to the demo day's measurements bit for
/// bit; the output's folder is made.
#[test]
fn the_documented_example_tables_replay_like_the_demo_day() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("new/folder/imported.mcap");
    let examples = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("docs/examples/demo_day_tables");
    let o = common::tortwin()
        .arg("import")
        .arg(&examples)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    common::check(&o, "tortwin import");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains(
            "trains 40, axles 2808, pulses 2808, weather messages 144, measurements 5899"
        ),
        "{stdout}"
    );
    let (a, b) = (measurements(&bundled("demo_day.mcap")), measurements(&out));
    assert_eq!(a.len(), 5899);
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!((x.0, &x.1), (y.0, &y.1));
        assert_eq!(x.2.to_bits(), y.2.to_bits(), "measured {x:?} vs {y:?}");
        assert_eq!(x.3.to_bits(), y.3.to_bits(), "simulated {x:?} vs {y:?}");
    }
}

/// `tortwin export` read back by pyarrow and pandas (tests/python/
/// check_tables.py): the documented columns, one row per /twin/measurement
/// of the same replay's MCAP output with its values bit for bit, one field
/// row per grid point and one trains row per /twin/field message; the
/// tables and the MCAP output name their input by sha256.
#[test]
fn exported_tables_read_back_in_pandas_equal_the_mcap_output() {
    let dir = tempfile::tempdir().unwrap();
    let recording = bundled("curve_day_all_effects.mcap");
    let mcap = dir.path().join("replay/out.mcap");
    let rrd = dir.path().join("replay/out.rrd");
    let o = common::tortwin()
        .arg("replay")
        .arg(&recording)
        .arg("--out-mcap")
        .arg(&mcap)
        .arg("--out-rrd")
        .arg(&rrd)
        .output()
        .unwrap();
    common::check(&o, "tortwin replay");
    let tables = dir.path().join("tables");
    let o = common::tortwin()
        .arg("export")
        .arg(&recording)
        .arg("--out")
        .arg(&tables)
        .arg("--inputs")
        .output()
        .unwrap();
    common::check(&o, "tortwin export");
    let check = common::python("check_tables.py", &[&tables, &mcap]);
    common::check(&check, "check_tables.py");
    let summary = String::from_utf8_lossy(&check.stdout);
    assert!(summary.contains("\"failures\": []"), "{summary}");
    for output in [mcap, rrd, tables.join("provenance.json")] {
        let check = common::python("check_provenance.py", &[&output, &recording]);
        common::check(&check, &format!("check_provenance.py {}", output.display()));
    }
    // The inputs written beside the tables import back.
    let back = dir.path().join("back.mcap");
    let o = common::tortwin()
        .arg("import")
        .arg(tables.join("inputs"))
        .arg("--out")
        .arg(&back)
        .output()
        .unwrap();
    common::check(&o, "tortwin import");
    assert_eq!(measurements(&recording), measurements(&back));
}

/// An output folder that cannot be made is exit status 2 naming it.
#[test]
fn an_export_folder_that_cannot_be_made_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a_file");
    std::fs::write(&file, "x").unwrap();
    let o = common::tortwin()
        .arg("export")
        .arg(bundled("demo_day.mcap"))
        .arg("--out")
        .arg(file.join("tables"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{text}");
    assert!(text.contains("a_file/tables"), "{text}");
}

#[test]
fn a_missing_column_names_the_header_line() {
    let (_dir, tables) = demo_tables();
    let cy = column(&tables, "passages.csv", "cy_low");
    edit(&tables, "passages.csv", 0, cy, None);
    let n = header(&tables, "passages.csv").len();
    fails_at(&tables, "passages.csv", 1, n + 1, "missing column `cy_low`");
}

#[test]
fn a_bad_number_names_its_cell() {
    let (_dir, tables) = demo_tables();
    let speed = column(&tables, "passages.csv", "speed_mps");
    // Line 2 is the first train's first axle: its speed names the train.
    edit(&tables, "passages.csv", 2, speed, Some("fast"));
    fails_at(
        &tables,
        "passages.csv",
        2,
        speed,
        "`speed_mps` = `fast` is not a number",
    );

    let (_dir, tables) = demo_tables();
    let value = column(&tables, "measurements.csv", "value");
    edit(&tables, "measurements.csv", 7, value, Some("NaN"));
    fails_at(&tables, "measurements.csv", 7, value, "not a finite number");
}

#[test]
fn an_unknown_rail_names_its_cell() {
    let (_dir, tables) = demo_tables();
    let rail = column(&tables, "pulses.csv", "rail");
    edit(&tables, "pulses.csv", 5, rail, Some("middle"));
    fails_at(
        &tables,
        "pulses.csv",
        5,
        rail,
        "rail `middle` is not a rail of the section",
    );
}

#[test]
fn decreasing_axle_offsets_name_the_axle() {
    let (_dir, tables) = demo_tables();
    let offset = column(&tables, "passages.csv", "axle_offset_m");
    // The first train's third axle (line 4) behind its second.
    edit(&tables, "passages.csv", 4, offset, Some("0.5"));
    fails_at(&tables, "passages.csv", 4, offset, "offsets never decrease");
}

#[test]
fn a_time_that_does_not_parse_names_its_cell() {
    let (_dir, tables) = demo_tables();
    let time = column(&tables, "weather.csv", "time_utc");
    edit(&tables, "weather.csv", 3, time, Some("08/04/2024 00:20"));
    fails_at(&tables, "weather.csv", 3, time, "is not an RFC 3339 time");
}

#[test]
fn rules_across_rows_are_located_too() {
    // A measurement of an axle the train does not have.
    let (_dir, tables) = demo_tables();
    let axle = column(&tables, "measurements.csv", "axle_index");
    let text = std::fs::read_to_string(tables.join("measurements.csv")).unwrap();
    let line = text
        .lines()
        .skip(1)
        .position(|l| l.split(',').nth(axle - 1).is_some_and(|c| !c.is_empty()))
        .unwrap()
        + 2;
    edit(&tables, "measurements.csv", line, axle, Some("999"));
    fails_at(
        &tables,
        "measurements.csv",
        line,
        axle,
        "axle_index 999 is out of range",
    );

    // A position outside the section, in section.toml.
    let (_dir, tables) = demo_tables();
    let path = tables.join("section.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let edited = text.replacen("position_m = 10.0", "position_m = 10000.0", 1);
    std::fs::write(&path, &edited).unwrap();
    let line = edited.lines().position(|l| l.contains("10000.0")).unwrap() + 1;
    fails_at(&tables, "section.toml", line, 14, "is outside the section");
}
