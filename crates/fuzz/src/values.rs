//! The semantic target (issue 29): well-formed inputs with one value set to
//! the edge of its type or range.
//!
//! The byte and text mutators mostly break the syntax, and a broken file is
//! refused before its values are read. Here the file stays well formed and
//! one number changes: a field of a recording's message (or the message's
//! `log_time`), a configuration key, a state value or a CSV cell becomes 0,
//! -0, a subnormal, 1e308, 2^53, 2^63, u64::MAX, NaN or an infinity, spelled
//! every way JSON, TOML and CSV let it be written (and the ways they do
//! not). A run must replay with finite results (a summary of finite
//! numbers, a state that reads back) or be refused naming the field it
//! changed.
//!
//! A mutant is saved as a header line, `WHERE\tFIELD\tPATH`, then the
//! input: `WHERE` is `mcap`, `config`, `state` or `csv:FILE`; `FIELD` the
//! names a refusal may give for the field (`|`-separated: the keys on its
//! path, the column); `PATH` for the reader.

use rand::Rng;
use serde_json::Value;

/// A placeholder written where the edge value goes, then replaced by its
/// literal text (which is often not valid JSON or TOML: that is the point).
const MARK: &str = "@@tortwin-fuzz-edge@@";

/// Numbers as JSON writes them, and as it does not (`NaN`, `Infinity`,
/// `1e999`, strings and `null` where a number belongs).
pub const JSON_EDGES: [&str; 30] = [
    "0",
    "-0",
    "-0.0",
    "5e-324",
    "1e-310",
    "2.2250738585072014e-308",
    "1e-300",
    "-1e-300",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "1e309",
    "-1e999",
    "9007199254740992",
    "9007199254740993",
    "9223372036854775807",
    "9223372036854775808",
    "-9223372036854775808",
    "18446744073709551615",
    "18446744073709551616",
    "-1",
    "1",
    "0.5",
    "NaN",
    "-NaN",
    "Infinity",
    "-Infinity",
    "\"NaN\"",
    "\"1e308\"",
    "null",
];

/// Numbers as TOML writes them: its `nan`, `inf` with their signs, and
/// integers past what it holds.
pub const TOML_EDGES: [&str; 26] = [
    "0",
    "-0",
    "-0.0",
    "+0.0",
    "5e-324",
    "1e-310",
    "1e-300",
    "-1e-300",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "1e309",
    "9007199254740992",
    "9007199254740993",
    "9223372036854775807",
    "-9223372036854775808",
    "9223372036854775808",
    "18446744073709551615",
    "-1",
    "0.5",
    "nan",
    "+nan",
    "-nan",
    "inf",
    "+inf",
    "-inf",
];

/// Cells as a spreadsheet or another program might write them.
pub const CSV_EDGES: [&str; 26] = [
    "0",
    "-0",
    "5e-324",
    "1e-310",
    "1e-300",
    "1e308",
    "-1e308",
    "1e309",
    "9007199254740993",
    "9223372036854775808",
    "18446744073709551615",
    "18446744073709551616",
    "-1",
    "NaN",
    "nan",
    "-nan",
    "inf",
    "-inf",
    "+inf",
    "Infinity",
    "-Infinity",
    "1e999",
    "1.#INF",
    "#NUM!",
    "",
    " 1 ",
];

/// Message times at the edges: the epoch, 2^53 ns, the last time before
/// 2262 and the ones past it.
pub const TIME_EDGES: [u64; 7] = [
    0,
    1,
    1 << 53,
    (1 << 63) - 1,
    1 << 63,
    u64::MAX - 1,
    u64::MAX,
];

/// A leaf of a JSON document: the keys and indices to it.
#[derive(Debug, Clone)]
pub enum Step {
    Key(String),
    Index(usize),
}

/// The number leaves of `v`, with their paths.
pub fn json_numbers(v: &Value) -> Vec<Vec<Step>> {
    let mut out = Vec::new();
    walk_json(v, &mut Vec::new(), &mut out);
    out
}

fn walk_json(v: &Value, path: &mut Vec<Step>, out: &mut Vec<Vec<Step>>) {
    match v {
        Value::Number(_) => out.push(path.clone()),
        Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                path.push(Step::Index(i));
                walk_json(item, path, out);
                path.pop();
            }
        }
        Value::Object(map) => {
            for (k, item) in map {
                path.push(Step::Key(k.clone()));
                walk_json(item, path, out);
                path.pop();
            }
        }
        _ => {}
    }
}

/// The names a refusal may use for the leaf at `path`: its keys.
pub fn names(path: &[Step]) -> Vec<String> {
    path.iter()
        .filter_map(|s| match s {
            Step::Key(k) => Some(k.clone()),
            Step::Index(_) => None,
        })
        .collect()
}

/// `v` with the leaf at `path` written as `literal`, as text.
pub fn json_with(v: &Value, path: &[Step], literal: &str) -> Option<String> {
    let mut v = v.clone();
    let mut at = &mut v;
    for step in path {
        at = match step {
            Step::Key(k) => at.get_mut(k.as_str())?,
            Step::Index(i) => at.get_mut(*i)?,
        };
    }
    *at = Value::String(MARK.to_string());
    let text = serde_json::to_string(&v).ok()?;
    Some(text.replacen(&format!("\"{MARK}\""), literal, 1))
}

/// The number leaves of a TOML document, as key paths.
pub fn toml_numbers(v: &toml::Value) -> Vec<Vec<Step>> {
    let mut out = Vec::new();
    walk_toml(v, &mut Vec::new(), &mut out);
    out
}

fn walk_toml(v: &toml::Value, path: &mut Vec<Step>, out: &mut Vec<Vec<Step>>) {
    match v {
        toml::Value::Integer(_) | toml::Value::Float(_) => out.push(path.clone()),
        toml::Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                path.push(Step::Index(i));
                walk_toml(item, path, out);
                path.pop();
            }
        }
        toml::Value::Table(map) => {
            for (k, item) in map {
                path.push(Step::Key(k.clone()));
                walk_toml(item, path, out);
                path.pop();
            }
        }
        _ => {}
    }
}

/// `v` with the leaf at `path` written as `literal`, as TOML text.
pub fn toml_with(v: &toml::Value, path: &[Step], literal: &str) -> Option<String> {
    let mut v = v.clone();
    let mut at = &mut v;
    for step in path {
        at = match step {
            Step::Key(k) => at.get_mut(k.as_str())?,
            Step::Index(i) => at.get_mut(*i)?,
        };
    }
    *at = toml::Value::String(MARK.to_string());
    let text = toml::to_string(&v).ok()?;
    Some(text.replacen(&format!("\"{MARK}\""), literal, 1))
}

/// A CSV table with one numeric cell set to `literal` (a random one of
/// the data rows), and the cell's column; `None` when it has none.
pub fn csv_with(rng: &mut impl Rng, text: &[u8]) -> Option<(Vec<u8>, String)> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(text);
    let rows: Vec<csv::StringRecord> = reader.records().collect::<Result<_, _>>().ok()?;
    let header = rows.first()?.clone();
    let cells: Vec<(usize, usize)> = rows
        .iter()
        .enumerate()
        .skip(1)
        .flat_map(|(r, row)| {
            row.iter()
                .enumerate()
                .filter(|(_, c)| c.trim().parse::<f64>().is_ok())
                .map(move |(c, _)| (r, c))
        })
        .collect();
    if cells.is_empty() {
        return None;
    }
    let (r, c) = cells[rng.random_range(0..cells.len())];
    let literal = CSV_EDGES[rng.random_range(0..CSV_EDGES.len())];
    let mut writer = csv::Writer::from_writer(Vec::new());
    for (i, row) in rows.iter().enumerate() {
        if i == r {
            let mut cells: Vec<&str> = row.iter().collect();
            cells[c] = literal;
            writer.write_record(&cells).ok()?;
        } else {
            writer.write_record(row).ok()?;
        }
    }
    let column = header.get(c).unwrap_or_default().to_string();
    Some((writer.into_inner().ok()?, column))
}

/// A leaf of `leaves` at random (`None` when there is none).
fn pick<'a>(rng: &mut impl Rng, leaves: &'a [Vec<Step>]) -> Option<&'a [Step]> {
    if leaves.is_empty() {
        None
    } else {
        Some(&leaves[rng.random_range(0..leaves.len())])
    }
}

/// A JSON document with one number leaf, chosen at random, written as a
/// random edge of [`JSON_EDGES`]: the text and the leaf's path (`None` for
/// text that is not JSON or holds no number).
pub fn json_edge(rng: &mut impl Rng, text: &[u8]) -> Option<(String, Vec<Step>)> {
    let v: Value = serde_json::from_slice(text).ok()?;
    let leaves = json_numbers(&v);
    let path = pick(rng, &leaves)?;
    let literal = JSON_EDGES[rng.random_range(0..JSON_EDGES.len())];
    Some((json_with(&v, path, literal)?, path.to_vec()))
}

/// [`json_edge`] for TOML, with [`TOML_EDGES`].
pub fn toml_edge(rng: &mut impl Rng, text: &[u8]) -> Option<(String, Vec<Step>)> {
    let v: toml::Value = toml::from_str(std::str::from_utf8(text).ok()?).ok()?;
    let leaves = toml_numbers(&v);
    let path = pick(rng, &leaves)?;
    let literal = TOML_EDGES[rng.random_range(0..TOML_EDGES.len())];
    Some((toml_with(&v, path, literal)?, path.to_vec()))
}

/// A document changed by [`json_edge`] or [`toml_edge`], saved as a mutant
/// for `place`.
pub fn saved(place: &str, (text, path): (String, Vec<Step>)) -> Vec<u8> {
    encode(place, &names(&path), &describe(&path), text.as_bytes())
}

/// A saved mutant: header line and input.
pub fn encode(place: &str, names: &[String], path: &str, input: &[u8]) -> Vec<u8> {
    let clean = |s: &str| s.replace(['\t', '\n', '|'], " ");
    let names: Vec<String> = names.iter().map(|n| clean(n)).collect();
    let mut out = format!("{}\t{}\t{}\n", clean(place), names.join("|"), clean(path)).into_bytes();
    out.extend_from_slice(input);
    out
}

/// A saved mutant read back: where, the field's names, the input.
pub fn decode(bytes: &[u8]) -> Option<(String, Vec<String>, &[u8])> {
    let end = bytes.iter().position(|&b| b == b'\n')?;
    let header = std::str::from_utf8(&bytes[..end]).ok()?;
    let mut parts = header.split('\t');
    let place = parts.next()?.to_string();
    let names = parts
        .next()?
        .split('|')
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect();
    Some((place, names, &bytes[end + 1..]))
}

/// How a path reads: `axles[2].wheel_load_kN.high`.
pub fn describe(path: &[Step]) -> String {
    let mut out = String::new();
    for step in path {
        match step {
            Step::Key(k) => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(k);
            }
            Step::Index(i) => out.push_str(&format!("[{i}]")),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn a_json_leaf_is_written_as_the_literal_and_nothing_else_changes() {
        let v: Value = serde_json::from_str(r#"{"a":1.5,"b":[{"c":2},{"c":3}],"s":"x"}"#).unwrap();
        let leaves = json_numbers(&v);
        assert_eq!(leaves.len(), 3);
        assert_eq!(describe(&leaves[1]), "b[0].c");
        assert_eq!(names(&leaves[1]), vec!["b", "c"]);
        let text = json_with(&v, &leaves[2], "NaN").unwrap();
        assert_eq!(text, r#"{"a":1.5,"b":[{"c":2},{"c":NaN}],"s":"x"}"#);
    }

    #[test]
    fn a_toml_leaf_is_written_as_the_literal() {
        let v: toml::Value = toml::from_str("[product]\nmu_d = 0.5\nname = \"x\"\n").unwrap();
        let leaves = toml_numbers(&v);
        assert_eq!(leaves.len(), 1);
        let text = toml_with(&v, &leaves[0], "-nan").unwrap();
        assert!(text.contains("mu_d = -nan"), "{text}");
    }

    #[test]
    fn a_csv_cell_changes_and_its_column_is_named() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (out, column) = csv_with(&mut rng, b"id,value\nA,1.0\nB,2.0\n").unwrap();
        assert_eq!(column, "value");
        let text = String::from_utf8(out).unwrap();
        assert!(text.starts_with("id,value\n"), "{text}");
        assert_ne!(text, "id,value\nA,1.0\nB,2.0\n");
    }

    #[test]
    fn a_saved_mutant_reads_back() {
        let bytes = encode("csv:pulses.csv", &["mass_g".into()], "3:2", b"x\ny");
        let (place, names, input) = decode(&bytes).unwrap();
        assert_eq!(place, "csv:pulses.csv");
        assert_eq!(names, vec!["mass_g"]);
        assert_eq!(input, b"x\ny");
    }
}
