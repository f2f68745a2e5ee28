//! Text from inputs that would attack a terminal or a spreadsheet (issue
//! 29, "Untrusted text is echoed raw"): escape sequences, NUL and a
//! right-to-left override in an id reach stderr escaped; a 15 MB id makes a
//! short error line; an id that begins like a formula is exported inert and
//! imported back unchanged.

mod common;

use std::path::Path;

use common::{check, demo_day, tortwin};

/// `tortwin export --inputs` of `recording` into `dir`: the input tables,
/// in `dir/inputs`, which it returns.
fn input_tables(recording: &Path, dir: &Path) -> std::path::PathBuf {
    check(
        &tortwin()
            .arg("export")
            .arg(recording)
            .args(["--inputs", "--no-field", "--quiet", "--out"])
            .arg(dir)
            .output()
            .unwrap(),
        "export --inputs",
    );
    dir.join("inputs")
}

/// `path` (a CSV table) with every non-empty cell of `column` mapped.
fn rewrite_column(path: &Path, column: &str, f: &dyn Fn(&str) -> String) {
    let mut reader = csv::Reader::from_path(path).unwrap();
    let header = reader.headers().unwrap().clone();
    let at = header.iter().position(|h| h == column).unwrap();
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    let mut writer = csv::Writer::from_path(path).unwrap();
    writer.write_record(&header).unwrap();
    for r in &rows {
        let cells: Vec<String> = r
            .iter()
            .enumerate()
            .map(|(i, c)| {
                if i == at && !c.is_empty() {
                    f(c)
                } else {
                    c.to_string()
                }
            })
            .collect();
        writer.write_record(&cells).unwrap();
    }
    writer.flush().unwrap();
}

/// pulses.csv with its first row's `column` set to `value`.
fn set_first_pulse(dir: &Path, column: &str, value: &str) {
    let path = dir.join("pulses.csv");
    let mut reader = csv::Reader::from_path(&path).unwrap();
    let header = reader.headers().unwrap().clone();
    let at = header.iter().position(|h| h == column).unwrap();
    let mut rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    let mut first: Vec<String> = rows[0].iter().map(str::to_string).collect();
    first[at] = value.to_string();
    rows[0] = csv::StringRecord::from(first);
    let mut writer = csv::Writer::from_path(&path).unwrap();
    writer.write_record(&header).unwrap();
    for r in &rows {
        writer.write_record(r).unwrap();
    }
    writer.flush().unwrap();
}

#[test]
fn escape_sequences_and_long_ids_reach_stderr_escaped_and_short() {
    let work = tempfile::tempdir().unwrap();
    let tables = input_tables(&demo_day(), &work.path().join("tables"));
    // The import's error with the first pulse's `column` set to `value`:
    // exit 2, and short whatever the value.
    let refused_with = |column: &str, value: &str| {
        set_first_pulse(&tables, column, value);
        let o = tortwin()
            .arg("import")
            .arg(&tables)
            .arg("--out")
            .arg(work.path().join("x.mcap"))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8(o.stderr).unwrap();
        assert!(err.len() < 4096, "{} bytes on stderr", err.len());
        err
    };
    let evil = "high\u{1b}]0;owned\u{7}\u{1b}[2J\u{202e}\0";
    let err = refused_with("rail", evil);
    assert!(
        err.contains("high\\u{1b}]0;owned\\u{7}\\u{1b}[2J\\u{202e}\\u{0}"),
        "{err}"
    );
    assert!(err.contains("pulses.csv:2:"), "{err}");
    assert!(
        !err.chars().any(|c| c.is_control() && c != '\n'),
        "a control character reached stderr: {err:?}"
    );
    assert_eq!(
        err.lines().filter(|l| l.starts_with("error:")).count(),
        1,
        "{err}"
    );

    // A 900 kB id (a line under the 1 MiB a table's line may hold): the
    // error names it by its start and its length.
    let long = "x".repeat(900 << 10);
    let err = refused_with("applicator_id", &long);
    assert!(err.contains("bytes in all)"), "{err}");

    // A 15 MB id: the line is refused by its length, as short.
    let long = "x".repeat(15 << 20);
    let err = refused_with("applicator_id", &long);
    assert!(
        err.contains("pulses.csv:2:1: line 2 is longer than"),
        "{err}"
    );
}

#[test]
fn an_id_that_begins_like_a_formula_is_exported_inert_and_imported_back() {
    let work = tempfile::tempdir().unwrap();
    let tables = input_tables(&demo_day(), &work.path().join("tables"));
    // The train ids become formulas (in passages.csv and the measurements
    // that name them), written with the quote export would put in front.
    let formula = |id: &str| format!("'=HYPERLINK(\"x\")-{id}");
    for file in ["passages.csv", "measurements.csv"] {
        rewrite_column(&tables.join(file), "train_id", &formula);
    }
    let rec = work.path().join("formula.mcap");
    check(
        &tortwin()
            .arg("import")
            .arg(&tables)
            .arg("--out")
            .arg(&rec)
            .output()
            .unwrap(),
        "import",
    );
    // In the recording the id is itself, without the quote.
    let again = input_tables(&rec, &work.path().join("again"));
    let exported = std::fs::read_to_string(again.join("passages.csv")).unwrap();
    let first = exported.lines().nth(1).unwrap();
    assert!(first.starts_with("\"'=HYPERLINK(\"\"x\"\")-"), "{first}");
    // Written back, the same tables: the round trip is exact.
    let back = work.path().join("back.mcap");
    check(
        &tortwin()
            .arg("import")
            .arg(&again)
            .arg("--out")
            .arg(&back)
            .output()
            .unwrap(),
        "import",
    );
    let third = input_tables(&back, &work.path().join("third"));
    assert_eq!(
        exported,
        std::fs::read_to_string(third.join("passages.csv")).unwrap()
    );
    // The replay's own tables name the trains inertly too.
    let replayed = std::fs::read_to_string(work.path().join("again/trains.csv")).unwrap();
    let row = replayed.lines().nth(1).unwrap();
    assert!(row.starts_with("\"'=HYPERLINK(\"\"x\"\")-"), "{row}");
}
