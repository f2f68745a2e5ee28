//! The twin's outputs as tables for the tools engineers use (pandas,
//! Excel, DuckDB, Spark): Parquet and CSV, written as the replay goes.
//!
//! | table | one row per | columns |
//! |---|---|---|
//! | `measurements` | input measurement | `time_utc`, `index_in_file`, `site`, `rail`, `quantity`, `train_id`, `axle_index`, `measured`, `simulated`, `residual` (measured − simulated) |
//! | `field` | train × rail/band × grid point | `train_id`, `time_utc` (the train's last axle leaves), `rail`, `band`, `wheel_pass`, `d_m`, `mu`, `adhesion`, `rail_mass_mg`, `wheel_mass_mg` |
//! | `trains` | train × rail/band | `train_id`, `time_utc` (front enters), `end_utc`, `direction`, `speed_mps`, `axles`, `rail`, `band`, `wheel_pass`, `mu_min`, `mu_mean`, `mu_max`, `share_in_band`, `share_below_band`, `rail_product_g`, `wheel_mass_out_mg` |
//!
//! The field table is long (one row per grid point) so that it filters and
//! groups like any other; `mu`, `adhesion` and `wheel_mass_mg` are what the
//! train's last wheel on that rail saw (interfaces.md, `/twin/field`).
//! `share_in_band` is the share of the grid points whose mu lies in the
//! target band, `share_below_band` below it (over-application).
//!
//! In Parquet, times are timestamps in ns, UTC; in CSV, RFC 3339 text.
//! Rows are written in batches of [`BATCH_ROWS`]: memory stays flat over a
//! year of trains. Each file is written under a temporary name and moved
//! into place by [`Sink::finish`].

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{
    ArrayRef, Float64Builder, StringBuilder, TimestampNanosecondBuilder, UInt32Builder,
    UInt64Builder,
};
use arrow::datatypes::{DataType, Field, Schema, TimeUnit};
use arrow::record_batch::RecordBatch;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::WriterProperties;

use tortwin_engine::sink::{
    FieldSnapshot, MeasurementOutput, RunSummary, SectionInfo, Sink, SinkResult, SnapshotKind,
    TrainEvent,
};
use tortwin_recording::tables::{format_number, format_time};
use tortwin_recording::Direction;

use crate::files::{FileError, PartialFile};
use tortwin_recording::tables::inert;

/// Rows kept before they are written.
pub const BATCH_ROWS: usize = 65_536;

/// Why a table could not be written.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error(transparent)]
    File(#[from] FileError),
    #[error("writing {}: {source}", .path.display())]
    Parquet {
        path: PathBuf,
        #[source]
        source: parquet::errors::ParquetError,
    },
    #[error("writing {}: {source}", .path.display())]
    Csv {
        path: PathBuf,
        #[source]
        source: csv::Error,
    },
    #[error("building a batch of {table}: {source}")]
    Arrow {
        table: &'static str,
        #[source]
        source: arrow::error::ArrowError,
    },
}

/// Which files to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Formats {
    pub parquet: bool,
    pub csv: bool,
    /// Keep the record batches in memory ([`TableSink::into_tables`]), for
    /// the Python package.
    pub memory: bool,
}

/// Options of the tables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableOptions {
    pub formats: Formats,
    /// The target band of mu, for `share_in_band` (the strategy's default
    /// band: 0.30 to 0.40).
    pub band: (f64, f64),
    /// Write the long field table (the largest by far).
    pub field: bool,
}

impl Default for TableOptions {
    fn default() -> Self {
        Self {
            formats: Formats {
                parquet: true,
                csv: true,
                memory: false,
            },
            band: (0.30, 0.40),
            field: true,
        }
    }
}

/// One column of a table: its name and type; the values are pushed row by
/// row into builders that mirror it.
enum Column {
    Time(TimestampNanosecondBuilder),
    Text(StringBuilder),
    Float(Float64Builder),
    Count(UInt64Builder),
    Index(UInt32Builder),
}

/// A value of a row, for both files.
enum Value<'a> {
    Time(u64),
    Text(Option<&'a str>),
    Float(f64),
    /// A value that may be missing, NaN for missing: null in Parquet, an
    /// empty cell in CSV (a line's band no wheel used at a point, and the
    /// statistics over such a band's points).
    Maybe(f64),
    Count(u64),
    Index(Option<u32>),
}

/// The columns that may hold nulls: ids a row may lack, and what a
/// line's band holds where no wheel used it ([`Value::Maybe`]).
const NULLABLE: [&str; 11] = [
    "train_id",
    "axle_index",
    "mu",
    "adhesion",
    "wheel_mass_mg",
    "mu_min",
    "mu_mean",
    "mu_max",
    "share_in_band",
    "share_below_band",
    "wheel_mass_out_mg",
];

/// One table: its columns, the rows not yet written, and its files.
struct Table {
    name: &'static str,
    schema: Arc<Schema>,
    columns: Vec<Column>,
    rows: usize,
    parquet: Option<(PartialFile, ArrowWriter<BufWriter<File>>)>,
    csv: Option<(PartialFile, csv::Writer<BufWriter<File>>)>,
    /// The batches kept in memory (`Formats::memory`).
    batches: Option<Vec<RecordBatch>>,
}

impl Table {
    fn new(
        dir: &Path,
        name: &'static str,
        fields: &[(&str, DataType)],
        formats: Formats,
    ) -> Result<Self, TableError> {
        let schema = Arc::new(Schema::new(
            fields
                .iter()
                .map(|(n, t)| {
                    let nullable = NULLABLE.contains(n);
                    Field::new(*n, t.clone(), nullable)
                })
                .collect::<Vec<_>>(),
        ));
        let columns = fields
            .iter()
            .map(|(_, t)| match t {
                DataType::Timestamp(_, _) => {
                    Column::Time(TimestampNanosecondBuilder::new().with_timezone("UTC"))
                }
                DataType::Utf8 => Column::Text(StringBuilder::new()),
                DataType::UInt64 => Column::Count(UInt64Builder::new()),
                DataType::UInt32 => Column::Index(UInt32Builder::new()),
                _ => Column::Float(Float64Builder::new()),
            })
            .collect();
        let open = |file: &str| -> Result<(PartialFile, BufWriter<File>), TableError> {
            let partial = PartialFile::beside(&dir.join(file))?;
            let out = partial
                .open_with(|path| File::create(path))
                .map_err(|source| FileError::Write {
                    path: partial.final_path().to_path_buf(),
                    source,
                })?;
            Ok((partial, BufWriter::new(out)))
        };
        let parquet = if formats.parquet {
            let (partial, out) = open(&format!("{name}.parquet"))?;
            let props = WriterProperties::builder()
                .set_compression(Compression::ZSTD(ZstdLevel::default()))
                .set_created_by(format!("tortwin {}", env!("CARGO_PKG_VERSION")))
                .build();
            let writer = ArrowWriter::try_new(out, schema.clone(), Some(props))
                .map_err(|source| parquet_error(partial.final_path(), source))?;
            Some((partial, writer))
        } else {
            None
        };
        let csv = if formats.csv {
            let (partial, out) = open(&format!("{name}.csv"))?;
            let mut writer = csv::Writer::from_writer(out);
            writer
                .write_record(fields.iter().map(|(n, _)| *n))
                .map_err(|source| csv_error(partial.final_path(), source))?;
            Some((partial, writer))
        } else {
            None
        };
        Ok(Self {
            name,
            schema,
            columns,
            rows: 0,
            parquet,
            csv,
            batches: formats.memory.then(Vec::new),
        })
    }

    fn push(&mut self, row: &[Value<'_>]) -> Result<(), TableError> {
        for (column, value) in self.columns.iter_mut().zip(row) {
            match (column, value) {
                (Column::Time(b), Value::Time(ns)) => {
                    b.append_value(i64::try_from(*ns).unwrap_or(i64::MAX))
                }
                (Column::Text(b), Value::Text(t)) => b.append_option(*t),
                (Column::Float(b), Value::Float(x)) => b.append_value(*x),
                (Column::Float(b), Value::Maybe(x)) => b.append_option((!x.is_nan()).then_some(*x)),
                (Column::Count(b), Value::Count(n)) => b.append_value(*n),
                (Column::Index(b), Value::Index(i)) => b.append_option(*i),
                _ => unreachable!("a row of {} has its columns' types", self.name),
            }
        }
        if let Some((partial, csv)) = &mut self.csv {
            let fields = row.iter().map(|v| match v {
                Value::Time(ns) => format_time(*ns),
                // Ids as no spreadsheet runs them (csv-tables.md).
                Value::Text(t) => inert(t.unwrap_or_default()).into_owned(),
                Value::Float(x) => format_number(*x),
                Value::Maybe(x) if x.is_nan() => String::new(),
                Value::Maybe(x) => format_number(*x),
                Value::Count(n) => n.to_string(),
                Value::Index(i) => i.map_or(String::new(), |i| i.to_string()),
            });
            csv.write_record(fields)
                .map_err(|source| csv_error(partial.final_path(), source))?;
        }
        self.rows += 1;
        if self.rows >= BATCH_ROWS {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes the rows kept so far as one record batch.
    fn flush(&mut self) -> Result<(), TableError> {
        if self.rows == 0 {
            return Ok(());
        }
        let arrays: Vec<ArrayRef> = self
            .columns
            .iter_mut()
            .map(|c| -> ArrayRef {
                match c {
                    Column::Time(b) => Arc::new(b.finish()),
                    Column::Text(b) => Arc::new(b.finish()),
                    Column::Float(b) => Arc::new(b.finish()),
                    Column::Count(b) => Arc::new(b.finish()),
                    Column::Index(b) => Arc::new(b.finish()),
                }
            })
            .collect();
        self.rows = 0;
        if self.parquet.is_none() && self.batches.is_none() {
            return Ok(());
        }
        let batch = RecordBatch::try_new(self.schema.clone(), arrays).map_err(|source| {
            TableError::Arrow {
                table: self.name,
                source,
            }
        })?;
        if let Some((partial, writer)) = &mut self.parquet {
            writer
                .write(&batch)
                .map_err(|source| parquet_error(partial.final_path(), source))?;
        }
        if let Some(batches) = &mut self.batches {
            batches.push(batch);
        }
        Ok(())
    }

    /// Writes what is left and moves the files into place; the batches in
    /// memory stay.
    fn finish(&mut self) -> Result<(), TableError> {
        self.flush()?;
        if let Some((mut partial, writer)) = self.parquet.take() {
            writer
                .close()
                .map_err(|source| parquet_error(partial.final_path(), source))?;
            partial.commit()?;
        }
        if let Some((mut partial, mut csv)) = self.csv.take() {
            csv.flush().map_err(|source| FileError::Write {
                path: partial.final_path().to_path_buf(),
                source,
            })?;
            drop(csv);
            partial.commit()?;
        }
        Ok(())
    }
}

/// A sink writing the measurements, field and trains tables into a folder.
pub struct TableSink {
    options: TableOptions,
    measurements: Table,
    field: Option<Table>,
    trains: Table,
    /// The train being published: its entry event, kept until its fields.
    train: Option<TrainRow>,
}

struct TrainRow {
    train_id: String,
    log_time_ns: u64,
    end_ns: u64,
    direction: Direction,
    speed_mps: f64,
    axles: usize,
}

impl TableSink {
    /// Creates the tables' files (under temporary names) in `dir`.
    pub fn create(dir: &Path, options: TableOptions) -> Result<Self, TableError> {
        use DataType::{Float64 as F, UInt32, UInt64, Utf8 as S};
        let time = DataType::Timestamp(TimeUnit::Nanosecond, Some("UTC".into()));
        let formats = options.formats;
        let measurements = Table::new(
            dir,
            "measurements",
            &[
                ("time_utc", time.clone()),
                ("index_in_file", UInt64),
                ("site", S),
                ("rail", S),
                ("quantity", S),
                ("train_id", S),
                ("axle_index", UInt32),
                ("measured", F),
                ("simulated", F),
                ("residual", F),
            ],
            formats,
        )?;
        let field = if options.field {
            Some(Table::new(
                dir,
                "field",
                &[
                    ("train_id", S),
                    ("time_utc", time.clone()),
                    ("rail", S),
                    ("band", S),
                    ("wheel_pass", UInt64),
                    ("d_m", F),
                    ("mu", F),
                    ("adhesion", F),
                    ("rail_mass_mg", F),
                    ("wheel_mass_mg", F),
                ],
                formats,
            )?)
        } else {
            None
        };
        let trains = Table::new(
            dir,
            "trains",
            &[
                ("train_id", S),
                ("time_utc", time.clone()),
                ("end_utc", time),
                ("direction", S),
                ("speed_mps", F),
                ("axles", UInt64),
                ("rail", S),
                ("band", S),
                ("wheel_pass", UInt64),
                ("mu_min", F),
                ("mu_mean", F),
                ("mu_max", F),
                ("share_in_band", F),
                ("share_below_band", F),
                ("rail_product_g", F),
                ("wheel_mass_out_mg", F),
            ],
            formats,
        )?;
        Ok(Self {
            options,
            measurements,
            field,
            trains,
            train: None,
        })
    }

    /// The files the sink writes in `dir`, for a summary.
    pub fn file_names(options: &TableOptions) -> Vec<String> {
        let mut names = Vec::new();
        for table in ["measurements", "field", "trains"] {
            if table == "field" && !options.field {
                continue;
            }
            if options.formats.parquet {
                names.push(format!("{table}.parquet"));
            }
            if options.formats.csv {
                names.push(format!("{table}.csv"));
            }
        }
        names
    }
}

impl Sink for TableSink {
    fn begin(&mut self, _info: &SectionInfo<'_>) -> SinkResult {
        Ok(())
    }

    fn train(&mut self, t: &TrainEvent<'_>) -> SinkResult {
        self.train = Some(TrainRow {
            train_id: t.train_id.to_string(),
            log_time_ns: t.log_time_ns,
            end_ns: t.end_ns,
            direction: t.direction,
            speed_mps: t.speed_mps,
            axles: t.axles,
        });
        Ok(())
    }

    fn measurement(&mut self, m: &MeasurementOutput) -> SinkResult {
        self.measurements.push(&[
            Value::Time(m.log_time_ns),
            Value::Count(m.index_in_file),
            Value::Text(Some(&m.site_id)),
            Value::Text(Some(&m.rail_name)),
            Value::Text(Some(m.quantity.as_str())),
            Value::Text(m.train_id.as_deref()),
            Value::Index(m.axle_index.and_then(|a| u32::try_from(a).ok())),
            Value::Float(m.measured),
            Value::Float(m.simulated),
            Value::Float(m.measured - m.simulated),
        ])?;
        Ok(())
    }

    fn field(&mut self, f: &FieldSnapshot<'_>) -> SinkResult {
        if f.kind != SnapshotKind::Train {
            return Ok(());
        }
        if let Some(table) = &mut self.field {
            for i in 0..f.d_m.len() {
                table.push(&[
                    Value::Text(Some(&f.train_id)),
                    Value::Time(f.log_time_ns),
                    Value::Text(Some(&f.rail_name)),
                    Value::Text(Some(&f.band)),
                    Value::Count(f.wheel_pass),
                    Value::Float(f.d_m[i]),
                    Value::Maybe(f.mu[i]),
                    Value::Maybe(f.adhesion[i]),
                    Value::Float(f.rail_mass_kg[i] * 1e6),
                    Value::Maybe(f.wheel_mass_kg[i] * 1e6),
                ])?;
            }
        }
        let Some(train) = &self.train else {
            return Ok(());
        };
        let (lo, hi) = self.options.band;
        // Over the points a wheel of the train touched on this band (every
        // point on a section).
        let touched = f.mu.iter().filter(|m| !m.is_nan()).count();
        let n = match touched {
            0 => f64::NAN,
            k => k as f64,
        };
        let (mut min, mut max, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
        let (mut inside, mut below) = (0usize, 0usize);
        for &mu in f.mu.iter().filter(|m| !m.is_nan()) {
            min = min.min(mu);
            max = max.max(mu);
            sum += mu;
            inside += usize::from((lo..=hi).contains(&mu));
            below += usize::from(mu < lo);
        }
        if touched == 0 {
            (min, max) = (f64::NAN, f64::NAN);
        }
        // The wheel leaves the section carrying what it has after its last
        // contact (the exit end of its direction of travel).
        let out_mg = match train.direction {
            Direction::Up => f.wheel_mass_kg.last(),
            Direction::Down => f.wheel_mass_kg.first(),
        }
        .map_or(0.0, |m| m * 1e6);
        self.trains.push(&[
            Value::Text(Some(&train.train_id)),
            Value::Time(train.log_time_ns),
            Value::Time(train.end_ns),
            Value::Text(Some(match train.direction {
                Direction::Up => "up",
                Direction::Down => "down",
            })),
            Value::Float(train.speed_mps),
            Value::Count(train.axles as u64),
            Value::Text(Some(&f.rail_name)),
            Value::Text(Some(&f.band)),
            Value::Count(f.wheel_pass),
            Value::Maybe(min),
            Value::Maybe(sum / n),
            Value::Maybe(max),
            Value::Maybe(inside as f64 / n),
            Value::Maybe(below as f64 / n),
            Value::Float(f.rail_mass_kg.iter().sum::<f64>() * 1e3),
            Value::Maybe(out_mg),
        ])?;
        Ok(())
    }

    fn finish(&mut self, _summary: &RunSummary) -> SinkResult {
        // The tables move into place together, at the end of a good run.
        self.measurements.finish()?;
        if let Some(field) = &mut self.field {
            field.finish()?;
        }
        self.trains.finish()?;
        Ok(())
    }
}

/// A table kept in memory: its schema and record batches.
pub struct MemoryTable {
    pub schema: Arc<Schema>,
    pub batches: Vec<RecordBatch>,
}

/// The tables of a run kept in memory (`Formats::memory`).
pub struct MemoryTables {
    pub measurements: MemoryTable,
    /// `None` when the options left the field out.
    pub field: Option<MemoryTable>,
    pub trains: MemoryTable,
}

impl TableSink {
    /// The tables kept in memory, after [`Sink::finish`] (a table whose
    /// options did not keep it has no batches).
    pub fn into_tables(self) -> MemoryTables {
        let keep = |t: Table| MemoryTable {
            schema: t.schema,
            batches: t.batches.unwrap_or_default(),
        };
        MemoryTables {
            measurements: keep(self.measurements),
            field: self.field.map(keep),
            trains: keep(self.trains),
        }
    }
}

/// A CSV writer's error; the file system's answer (a full disk) as the
/// [`FileError`] it is, so that it is classified like any other output's.
fn csv_error(path: &Path, source: csv::Error) -> TableError {
    if let csv::ErrorKind::Io(io) = source.kind() {
        return TableError::File(FileError::Write {
            path: path.to_path_buf(),
            source: std::io::Error::new(io.kind(), io.to_string()),
        });
    }
    TableError::Csv {
        path: path.to_path_buf(),
        source,
    }
}

/// A Parquet writer's error, the file system's answer as in [`csv_error`].
fn parquet_error(path: &Path, source: parquet::errors::ParquetError) -> TableError {
    match source {
        parquet::errors::ParquetError::External(e) => match e.downcast::<std::io::Error>() {
            Ok(io) => TableError::File(FileError::Write {
                path: path.to_path_buf(),
                source: *io,
            }),
            Err(e) => TableError::Parquet {
                path: path.to_path_buf(),
                source: parquet::errors::ParquetError::External(e),
            },
        },
        source => TableError::Parquet {
            path: path.to_path_buf(),
            source,
        },
    }
}
