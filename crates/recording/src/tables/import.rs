//! A folder of tables (module [`super`]) -> a recording (MCAP).
//!
//! Each row becomes the wire message of its topic ([`crate::wire`]), then
//! all of them go through the reader's own rules ([`crate::decode`]) in
//! replay order, so an import accepts exactly what a replay would; an
//! error names the file, the line and the column of the field it is about.
//! The messages are written in replay order, after the `/section`.
//!
//! The rows are held in memory between reading and writing (the whole set
//! is sorted into replay order): about 200 bytes an axle.

use std::collections::HashMap;
use std::fs::File;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::{
    active, parse_time, rail_columns, LOG_TIME_NS, MEASUREMENTS_FILE, MEASUREMENT_COLUMNS,
    PASSAGES_FILE, PASSAGE_COLUMNS, PULSES_FILE, PULSE_COLUMNS, SECTION_FILE, TIME_UTC,
    WEATHER_COLUMNS, WEATHER_FILE,
};
use crate::decode::{self, DecodeError, Decoder};
use crate::error::{ConvertError, InputError};
use crate::event::{BogiePosition, Direction, Quantity};
use crate::topic::Topic;
use crate::wire::{
    ApplicatorMsg, AxleMsg, CreepageMsg, MeasurementMsg, PassageMsg, PerRail, PulseMsg, SectionMsg,
    SiteMsg, WeatherMsg,
};
use crate::RecordingWriter;

/// What an import wrote.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct ImportSummary {
    pub trains: u64,
    pub axles: u64,
    pub pulses: u64,
    pub weather: u64,
    pub measurements: u64,
    pub first_ns: u64,
    pub last_ns: u64,
}

/// Reads the tables in `dir` and writes the recording `out` (under a
/// temporary name beside it, renamed when complete).
pub fn import_dir(dir: &Path, out: &Path) -> Result<ImportSummary, ConvertError> {
    let section_path = dir.join(SECTION_FILE);
    let section = read_section(&section_path)?;
    let rails = section.msg.rails.clone();
    let mut items: Vec<Item> = Vec::new();
    let mut summary = ImportSummary::default();

    let passages = dir.join(PASSAGES_FILE);
    read_passages(&passages, &rails, &mut items)?;
    for (file, topic) in [
        (PULSES_FILE, Topic::Pulse),
        (WEATHER_FILE, Topic::Weather),
        (MEASUREMENTS_FILE, Topic::Measurement),
    ] {
        let path = dir.join(file);
        if path.exists() {
            read_events(&path, topic, &mut items)?;
        }
    }

    // Replay order: log_time, then topic, then the order of the rows.
    items.sort_by_key(|item| (item.log_time_ns, item.topic, item.seq));
    let section_ns = match section.time_ns {
        Some(ns) => ns,
        None => items.first().map_or(0, |i| i.log_time_ns),
    };
    if let Some(early) = items.iter().find(|i| i.log_time_ns < section_ns) {
        return Err(early
            .origin
            .error(
                None,
                format!(
                    "this row is at {}, before the section's `time_utc` in {SECTION_FILE} \
                     ({}): the section must take effect first",
                    super::format_time(early.log_time_ns),
                    super::format_time(section_ns)
                ),
            )
            .into());
    }

    // Every rule a replay checks, in replay order, located in the tables.
    let typed = decode::section(&section.msg).map_err(|e| section.error(&section_path, &e))?;
    let origin_ns = i64::try_from(section_ns).unwrap_or(i64::MAX);
    let mut decoder = Decoder::new(typed, None, origin_ns, f64::NEG_INFINITY);
    for item in &items {
        let result = match &item.msg {
            Msg::Passage(m) => decoder.passage(m.into(), item.log_time_ns).map(drop),
            Msg::Pulse(m) => decoder.pulse(m.into()).map(drop),
            Msg::Weather(m) => decoder.weather(m).map(drop),
            Msg::Measurement(m) => decoder.measurement(m.into()).map(drop),
        };
        if let Err(e) = result {
            return Err(item.origin.error(e.field.as_deref(), e.message).into());
        }
        match &item.msg {
            Msg::Passage(m) => {
                summary.trains += 1;
                summary.axles += m.axles.len() as u64;
            }
            Msg::Pulse(_) => summary.pulses += 1,
            Msg::Weather(_) => summary.weather += 1,
            Msg::Measurement(_) => summary.measurements += 1,
        }
    }
    summary.first_ns = section_ns;
    summary.last_ns = items.last().map_or(section_ns, |i| i.log_time_ns);

    write(out, section_ns, &section.msg, &items)?;
    Ok(summary)
}

fn write(
    out: &Path,
    section_ns: u64,
    section: &SectionMsg,
    items: &[Item],
) -> Result<(), ConvertError> {
    let io = |what: &'static str, path: &Path| {
        let path = path.to_path_buf();
        move |source| ConvertError::Io { what, path, source }
    };
    let mut temp = tortwin_files::PartialFile::beside(out)?;
    let temp_file = temp
        .open_with(|path| File::create(path))
        .map_err(io("opening", temp.temp_path()))?;
    let write_error = |source| ConvertError::Write {
        path: out.to_path_buf(),
        source,
    };
    let file = std::io::BufWriter::new(&temp_file);
    let options = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .chunk_size(Some(1 << 20));
    let mut writer = RecordingWriter::new(file, options, None).map_err(write_error)?;
    writer.write(section_ns, section).map_err(write_error)?;
    for item in items {
        match &item.msg {
            Msg::Passage(m) => writer.write(item.log_time_ns, m),
            Msg::Pulse(m) => writer.write(item.log_time_ns, m),
            Msg::Weather(m) => writer.write(item.log_time_ns, m),
            Msg::Measurement(m) => writer.write(item.log_time_ns, m),
        }
        .map_err(write_error)?;
    }
    let mut file = writer.finish().map_err(write_error)?;
    std::io::Write::flush(&mut file).map_err(io("writing", out))?;
    drop(file);
    drop(temp_file);
    temp.commit()?;
    Ok(())
}

// ------------------------------------------------------------ the rows

enum Msg {
    Passage(PassageMsg),
    Pulse(PulseMsg),
    Weather(WeatherMsg),
    Measurement(MeasurementMsg),
}

/// A message with where it came from.
struct Item {
    log_time_ns: u64,
    topic: Topic,
    /// Row order over every file, for ties.
    seq: usize,
    msg: Msg,
    origin: Origin,
}

/// The rows a message came from: a file, its header, the line of each row
/// (a passage has one per axle).
struct Origin {
    file: std::rc::Rc<TableInfo>,
    lines: Vec<u64>,
}

struct TableInfo {
    path: PathBuf,
    /// Column names in file order.
    header: Vec<String>,
    /// The time column's name.
    time: &'static str,
}

impl TableInfo {
    fn column(&self, name: &str) -> usize {
        self.header
            .iter()
            .position(|h| h == name)
            .map_or(1, |i| i + 1)
    }
}

impl Origin {
    /// The error at the cell of `field` (a wire field path such as
    /// `axles[3].offset_m`, `rail`, `log_time`); the message's first row
    /// when the field is not a column.
    fn error(&self, field: Option<&str>, message: String) -> InputError {
        let info = &self.file;
        let first = self.lines.first().copied().unwrap_or(1);
        let (line, column) = match field {
            Some(field) => {
                let (axle, rest) = match field.strip_prefix("axles[") {
                    Some(tail) => match tail.split_once("].") {
                        Some((i, rest)) => (i.parse::<usize>().ok(), rest),
                        None => (None, field),
                    },
                    None => (None, field),
                };
                let line = axle
                    .and_then(|i| self.lines.get(i).copied())
                    .unwrap_or(first);
                let column = match rest.split_once('.') {
                    Some(("wheel_load_kN", rail)) => format!("wheel_load_kN_{rail}"),
                    // `creepage.RAIL.cx` is the column `cx_RAIL` (the
                    // creepage as a whole: its `cx_RAIL`).
                    Some(("creepage", tail)) => match tail.split_once('.') {
                        Some((rail, part)) => format!("{part}_{rail}"),
                        None => format!("cx_{tail}"),
                    },
                    _ => match rest {
                        "log_time" => info.time.to_string(),
                        "offset_m" => "axle_offset_m".to_string(),
                        other => other.to_string(),
                    },
                };
                // The column by its name too: the message speaks of the
                // wire field (`axles[3].creepage.high.cy`).
                match info.header.iter().position(|h| *h == column) {
                    Some(i) if !message.contains(&format!("`{column}`")) => {
                        return InputError::cell(
                            &info.path,
                            line,
                            i + 1,
                            format!("column `{column}`: {message}"),
                        );
                    }
                    _ => (line, info.column(&column)),
                }
            }
            None => (first, 1),
        };
        InputError::cell(&info.path, line, column, message)
    }
}

/// A CSV file with its header resolved.
struct Table {
    info: std::rc::Rc<TableInfo>,
    reader: csv::Reader<RowLimit<File>>,
    columns: HashMap<String, usize>,
}

/// The most bytes a line of a table may hold: a passage row is about 200;
/// a cell of hundreds of megabytes (in a column tortwin does not even
/// read) would otherwise be held whole by the CSV reader.
pub const MAX_LINE_BYTES: u64 = 1 << 20;

/// A reader that fails on a line longer than [`MAX_LINE_BYTES`], saying
/// which (1-based), before the CSV reader has buffered more of it.
struct RowLimit<R> {
    inner: R,
    /// Bytes since the last line feed, and lines ended so far.
    since_newline: u64,
    lines: u64,
}

/// The error [`RowLimit`] gives, found again by [`csv_error`].
#[derive(Debug)]
struct LineTooLong {
    line: u64,
}

impl std::fmt::Display for LineTooLong {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "line {} is longer than {MAX_LINE_BYTES} bytes; a table's line holds one row of a \
             few hundred",
            self.line
        )
    }
}

impl std::error::Error for LineTooLong {}

impl<R: std::io::Read> std::io::Read for RowLimit<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        for &b in &buf[..n] {
            if b == b'\n' {
                self.lines += 1;
                self.since_newline = 0;
            } else {
                self.since_newline += 1;
                if self.since_newline > MAX_LINE_BYTES {
                    return Err(std::io::Error::other(LineTooLong {
                        line: self.lines + 1,
                    }));
                }
            }
        }
        Ok(n)
    }
}

impl Table {
    fn open(path: &Path, required: &[String]) -> Result<Self, InputError> {
        let file = tortwin_files::open_input(path)
            .map_err(|e| InputError::file(path, format!("cannot open the table: {e}")))?;
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .has_headers(true)
            .from_reader(RowLimit {
                inner: file,
                since_newline: 0,
                lines: 0,
            });
        let header: Vec<String> = reader
            .headers()
            .map_err(|e| csv_error(path, e))?
            .iter()
            .map(str::to_string)
            .collect();
        let columns: HashMap<String, usize> = header
            .iter()
            .enumerate()
            .map(|(i, h)| (h.clone(), i))
            .collect();
        if columns.len() != header.len() {
            let twice = header
                .iter()
                .enumerate()
                .find(|(i, h)| header[..*i].contains(h))
                .map_or((0, ""), |(i, h)| (i, h.as_str()));
            return Err(InputError::cell(
                path,
                1,
                twice.0 + 1,
                format!("column `{}` appears twice in the header", twice.1),
            ));
        }
        if let (Some(_), Some(&second)) = (columns.get(TIME_UTC), columns.get(LOG_TIME_NS)) {
            return Err(InputError::cell(
                path,
                1,
                second + 1,
                format!(
                    "both `{TIME_UTC}` and `{LOG_TIME_NS}` are columns; a table gives its \
                     times in one of them"
                ),
            ));
        }
        let time = if columns.contains_key(TIME_UTC) {
            TIME_UTC
        } else if columns.contains_key(LOG_TIME_NS) {
            LOG_TIME_NS
        } else {
            return Err(InputError::cell(
                path,
                1,
                header.len() + 1,
                format!(
                    "missing column `{TIME_UTC}` (RFC 3339) or `{LOG_TIME_NS}` (ns since the \
                     epoch); the header has: {}",
                    header.join(", ")
                ),
            ));
        };
        for name in required {
            if !columns.contains_key(name) {
                return Err(InputError::cell(
                    path,
                    1,
                    header.len() + 1,
                    format!(
                        "missing column `{name}`; the header has: {}",
                        header.join(", ")
                    ),
                ));
            }
        }
        Ok(Self {
            info: std::rc::Rc::new(TableInfo {
                path: path.to_path_buf(),
                header,
                time,
            }),
            reader,
            columns,
        })
    }

    /// The next row, or `None` at the end.
    fn next(&mut self) -> Result<Option<Row>, InputError> {
        let mut record = csv::StringRecord::new();
        match self.reader.read_record(&mut record) {
            Ok(false) => Ok(None),
            Ok(true) => Ok(Some(Row {
                line: record.position().map_or(0, |p| p.line()),
                record,
            })),
            Err(e) => Err(csv_error(&self.info.path, e)),
        }
    }

    fn cell<'r>(&self, row: &'r Row, name: &str) -> (&'r str, usize) {
        let i = self.columns.get(name).copied().unwrap_or(usize::MAX);
        (row.record.get(i).unwrap_or(""), i.saturating_add(1))
    }

    fn fail(&self, row: &Row, column: usize, message: String) -> InputError {
        InputError::cell(&self.info.path, row.line, column, message)
    }

    fn text(&self, row: &Row, name: &str) -> Result<String, InputError> {
        let (text, column) = self.cell(row, name);
        if text.is_empty() {
            return Err(self.fail(row, column, format!("`{name}` is empty")));
        }
        Ok(active(text).to_string())
    }

    fn number(&self, row: &Row, name: &str) -> Result<f64, InputError> {
        let (text, column) = self.cell(row, name);
        match text.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            Ok(_) => Err(self.fail(
                row,
                column,
                format!("`{name}` = `{text}` is not a finite number"),
            )),
            Err(_) => Err(self.fail(row, column, format!("`{name}` = `{text}` is not a number"))),
        }
    }

    fn time(&self, row: &Row) -> Result<u64, InputError> {
        let name = self.info.time;
        let (text, column) = self.cell(row, name);
        if name == LOG_TIME_NS {
            let ns = text.parse::<u64>().map_err(|_| {
                self.fail(
                    row,
                    column,
                    format!("`{LOG_TIME_NS}` = `{text}` is not a whole number of ns"),
                )
            })?;
            crate::decode::log_time(ns)
                .map_err(|e| self.fail(row, column, format!("`{LOG_TIME_NS}`: {}", e.message)))?;
            Ok(ns)
        } else {
            parse_time(text).map_err(|m| self.fail(row, column, format!("`{TIME_UTC}`: {m}")))
        }
    }

    fn origin(&self, lines: Vec<u64>) -> Origin {
        Origin {
            file: self.info.clone(),
            lines,
        }
    }
}

struct Row {
    line: u64,
    record: csv::StringRecord,
}

fn csv_error(path: &Path, e: csv::Error) -> InputError {
    if let csv::ErrorKind::Io(io) = e.kind() {
        if let Some(long) = io.get_ref().and_then(|e| e.downcast_ref::<LineTooLong>()) {
            return InputError::cell(path, long.line, 1, long.to_string());
        }
    }
    let line = e.position().map_or(0, |p| p.line());
    let message = match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("this row has {len} fields, the header {expected_len}"),
        csv::ErrorKind::Utf8 { .. } => "the row is not UTF-8 text".to_string(),
        _ => e.to_string(),
    };
    InputError::cell(path, line, 1, message)
}

/// `passages.csv`: one row per axle, a train's rows together.
fn read_passages(path: &Path, rails: &[String], items: &mut Vec<Item>) -> Result<(), InputError> {
    let mut required: Vec<String> = PASSAGE_COLUMNS.iter().map(|c| c.to_string()).collect();
    for rail in rails {
        required.extend(rail_columns(rail));
    }
    let mut table = Table::open(path, &required)?;
    // The train being read: its message, time and the line of each axle.
    let mut open: Option<(PassageMsg, u64, Vec<u64>)> = None;
    let mut seen: HashMap<String, u64> = HashMap::new();
    let flush =
        |open: &mut Option<(PassageMsg, u64, Vec<u64>)>, items: &mut Vec<Item>, table: &Table| {
            if let Some((msg, log_time_ns, lines)) = open.take() {
                let seq = items.len();
                items.push(Item {
                    log_time_ns,
                    topic: Topic::Passage,
                    seq,
                    msg: Msg::Passage(msg),
                    origin: table.origin(lines),
                });
            }
        };
    while let Some(row) = table.next()? {
        let train_id = table.text(&row, "train_id")?;
        let log_time_ns = table.time(&row)?;
        let (direction_text, direction_col) = table.cell(&row, "direction");
        let direction = match direction_text {
            "up" => Direction::Up,
            "down" => Direction::Down,
            other => {
                return Err(table.fail(
                    &row,
                    direction_col,
                    format!("`direction` = `{other}`: expected `up` or `down`"),
                ))
            }
        };
        let speed_mps = table.number(&row, "speed_mps")?;
        let (bogie_text, bogie_col) = table.cell(&row, "bogie_position");
        let bogie_position = match bogie_text {
            "leading" => BogiePosition::Leading,
            "trailing" => BogiePosition::Trailing,
            other => {
                return Err(table.fail(
                    &row,
                    bogie_col,
                    format!("`bogie_position` = `{other}`: expected `leading` or `trailing`"),
                ))
            }
        };
        let mut wheel_load_kn = PerRail(Vec::with_capacity(rails.len()));
        let mut creepage = PerRail(Vec::with_capacity(rails.len()));
        for rail in rails {
            let [load, cx, cy, spin] = rail_columns(rail);
            wheel_load_kn
                .0
                .push((rail.clone(), table.number(&row, &load)?));
            creepage.0.push((
                rail.clone(),
                CreepageMsg {
                    cx: table.number(&row, &cx)?,
                    cy: table.number(&row, &cy)?,
                    spin_per_m: table.number(&row, &spin)?,
                },
            ));
        }
        let axle = AxleMsg {
            offset_m: table.number(&row, "axle_offset_m")?,
            bogie_position,
            wheel_diameter_m: table.number(&row, "wheel_diameter_m")?,
            wheel_load_kn,
            creepage,
            segments: None,
        };
        match &mut open {
            Some((msg, t, lines)) if msg.train_id == train_id => {
                // The train's own fields repeat on every row: they must agree.
                let first = lines.first().copied().unwrap_or(row.line);
                if *t != log_time_ns {
                    let (_, col) = table.cell(&row, table.info.time);
                    return Err(table.fail(
                        &row,
                        col,
                        format!(
                            "the time differs from train `{train_id}`'s first row (line {first})"
                        ),
                    ));
                }
                if msg.direction != direction {
                    return Err(table.fail(
                        &row,
                        direction_col,
                        format!("`direction` differs from train `{train_id}`'s first row (line {first})"),
                    ));
                }
                if msg.speed_mps.to_bits() != speed_mps.to_bits() {
                    let (_, col) = table.cell(&row, "speed_mps");
                    return Err(table.fail(
                        &row,
                        col,
                        format!("`speed_mps` differs from train `{train_id}`'s first row (line {first})"),
                    ));
                }
                msg.axles.push(axle);
                lines.push(row.line);
            }
            _ => {
                flush(&mut open, items, &table);
                if let Some(line) = seen.insert(train_id.clone(), row.line) {
                    let (_, col) = table.cell(&row, "train_id");
                    return Err(table.fail(
                        &row,
                        col,
                        format!(
                            "train `{train_id}` starts again here; its rows began at line {line} \
                             (a train's rows are consecutive, and a train_id is used once)"
                        ),
                    ));
                }
                open = Some((
                    PassageMsg {
                        train_id,
                        direction,
                        speed_mps,
                        consist: None,
                        axles: vec![axle],
                    },
                    log_time_ns,
                    vec![row.line],
                ));
            }
        }
    }
    flush(&mut open, items, &table);
    Ok(())
}

/// `pulses.csv`, `weather.csv` or `measurements.csv`: one message a row.
fn read_events(path: &Path, topic: Topic, items: &mut Vec<Item>) -> Result<(), InputError> {
    let required: &[&str] = match topic {
        Topic::Pulse => &PULSE_COLUMNS,
        Topic::Weather => &WEATHER_COLUMNS,
        _ => &MEASUREMENT_COLUMNS,
    };
    let required: Vec<String> = required.iter().map(|c| c.to_string()).collect();
    let mut table = Table::open(path, &required)?;
    while let Some(row) = table.next()? {
        let log_time_ns = table.time(&row)?;
        let msg = match topic {
            Topic::Pulse => Msg::Pulse(PulseMsg {
                applicator_id: table.text(&row, "applicator_id")?,
                rail: table.text(&row, "rail")?,
                mass_g: table.number(&row, "mass_g")?,
            }),
            Topic::Weather => Msg::Weather(WeatherMsg {
                air_temperature_c: table.number(&row, "air_temperature_c")?,
                relative_humidity: table.number(&row, "relative_humidity")?,
                precipitation_mm_h: table.number(&row, "precipitation_mm_h")?,
            }),
            _ => {
                let (q, q_col) = table.cell(&row, "quantity");
                let quantity = match q {
                    "mu" => Quantity::Mu,
                    "adhesion" => Quantity::Adhesion,
                    "rail_mu" => Quantity::RailMu,
                    other => {
                        return Err(table.fail(
                            &row,
                            q_col,
                            format!(
                                "`quantity` = `{other}`: expected `mu`, `adhesion` or `rail_mu`"
                            ),
                        ))
                    }
                };
                let (train, _) = table.cell(&row, "train_id");
                let (axle, axle_col) = table.cell(&row, "axle_index");
                let axle_index = match axle {
                    "" => None,
                    text => Some(text.parse::<usize>().map_err(|_| {
                        table.fail(
                            &row,
                            axle_col,
                            format!("`axle_index` = `{text}` is not a whole number from 0"),
                        )
                    })?),
                };
                Msg::Measurement(MeasurementMsg {
                    site_id: table.text(&row, "site_id")?,
                    rail: table.text(&row, "rail")?,
                    quantity,
                    train_id: (!train.is_empty()).then(|| active(train).to_string()),
                    axle_index,
                    value: table.number(&row, "value")?,
                })
            }
        };
        let seq = items.len();
        items.push(Item {
            log_time_ns,
            topic,
            seq,
            msg,
            origin: table.origin(vec![row.line]),
        });
    }
    Ok(())
}

// ------------------------------------------------------- section.toml

/// `section.toml`: the `/section` message, each value with its place.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SectionFile {
    section_id: Spanned<String>,
    time_utc: Option<Spanned<String>>,
    length_m: Spanned<f64>,
    rails: Spanned<Vec<String>>,
    curve_radius_m: Option<Spanned<f64>>,
    rail_head_radius_m: Spanned<f64>,
    nominal_wheel_diameter_m: Spanned<f64>,
    #[serde(default)]
    applicators: Vec<ApplicatorFile>,
    #[serde(default)]
    measurement_sites: Vec<SiteFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ApplicatorFile {
    id: Spanned<String>,
    position_m: Spanned<f64>,
    rails: Spanned<Vec<String>>,
    nominal_pulse_g: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SiteFile {
    id: Spanned<String>,
    position_m: Spanned<f64>,
}

struct Section {
    msg: SectionMsg,
    time_ns: Option<u64>,
    text: String,
    /// Field path -> byte span in the file.
    spans: Vec<(String, std::ops::Range<usize>)>,
}

impl Section {
    fn error(&self, path: &Path, e: &DecodeError) -> InputError {
        let span = e
            .field
            .as_deref()
            .and_then(|f| {
                self.spans
                    .iter()
                    .find(|(k, _)| k == f)
                    .or_else(|| self.spans.iter().find(|(k, _)| f.starts_with(k.as_str())))
            })
            .map_or(0, |(_, s)| s.start);
        let (line, column) = line_column(&self.text, span);
        InputError::cell(path, line, column, e.message.clone())
    }
}

fn line_column(text: &str, offset: usize) -> (u64, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() as u64 + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

fn read_section(path: &Path) -> Result<Section, InputError> {
    let text = tortwin_files::read_text_input(path, tortwin_files::MAX_TEXT_INPUT_BYTES)
        .map_err(|e| InputError::file(path, format!("cannot read the section description: {e}")))?;
    let file: SectionFile = toml::from_str(&text).map_err(|e| {
        let start = e.span().map_or(0, |s| s.start);
        let (line, column) = line_column(&text, start);
        // The key on that line, for a value TOML cannot hold (1e309).
        let line_text = text[..start.min(text.len())]
            .rsplit('\n')
            .next()
            .unwrap_or_default();
        let message = e.message().trim();
        let message = match line_text.split_once('=') {
            Some((key, _)) if !key.trim().is_empty() && !message.contains('`') => {
                format!("`{}`: {message}", key.trim().trim_matches('"'))
            }
            _ => message.to_string(),
        };
        InputError::cell(path, line, column, message)
    })?;
    let mut spans = Vec::new();
    let mut span = |name: String, range: std::ops::Range<usize>| spans.push((name, range));
    span("section_id".into(), file.section_id.span());
    span("length_m".into(), file.length_m.span());
    span("rails".into(), file.rails.span());
    if let Some(r) = &file.curve_radius_m {
        span("curve_radius_m".into(), r.span());
    }
    span("rail_head_radius_m".into(), file.rail_head_radius_m.span());
    span(
        "nominal_wheel_diameter_m".into(),
        file.nominal_wheel_diameter_m.span(),
    );
    for (i, a) in file.applicators.iter().enumerate() {
        span(format!("applicators[{i}].id"), a.id.span());
        span(format!("applicators[{i}].position_m"), a.position_m.span());
        span(format!("applicators[{i}].rails"), a.rails.span());
        span(
            format!("applicators[{i}].nominal_pulse_g"),
            a.nominal_pulse_g.span(),
        );
    }
    for (i, s) in file.measurement_sites.iter().enumerate() {
        span(format!("measurement_sites[{i}].id"), s.id.span());
        span(
            format!("measurement_sites[{i}].position_m"),
            s.position_m.span(),
        );
    }
    let time_ns = match &file.time_utc {
        None => None,
        Some(t) => Some(parse_time(t.get_ref()).map_err(|m| {
            let (line, column) = line_column(&text, t.span().start);
            InputError::cell(path, line, column, format!("`time_utc`: {m}"))
        })?),
    };
    let msg = SectionMsg {
        section_id: file.section_id.into_inner(),
        length_m: file.length_m.into_inner(),
        rails: file.rails.into_inner(),
        curve_radius_m: file.curve_radius_m.map(Spanned::into_inner),
        rail_head_radius_m: file.rail_head_radius_m.into_inner(),
        nominal_wheel_diameter_m: file.nominal_wheel_diameter_m.into_inner(),
        applicators: file
            .applicators
            .into_iter()
            .map(|a| ApplicatorMsg {
                id: a.id.into_inner(),
                position_m: a.position_m.into_inner(),
                rails: a.rails.into_inner(),
                nominal_pulse_g: a.nominal_pulse_g.into_inner(),
            })
            .collect(),
        measurement_sites: file
            .measurement_sites
            .into_iter()
            .map(|s| SiteMsg {
                id: s.id.into_inner(),
                position_m: s.position_m.into_inner(),
            })
            .collect(),
    };
    Ok(Section {
        msg,
        time_ns,
        text,
        spans,
    })
}
