//! `tortwin._native`: the commands of the `tortwin` binary for the Python
//! package (python/tortwin/), on the same library crates.
//!
//! Each function takes the command's arguments as the command line would
//! (parsed by the same clap definitions, so the Python keywords and the
//! flags cannot drift apart), plus what only Python has: a configuration
//! given as a dict (written as TOML text by tomli-w), a state held in
//! memory. Tables come back as
//! Arrow IPC streams (pyarrow reads them without a copy per value), reports
//! as JSON text.
//!
//! A job runs on a thread of its own while the calling thread, without the
//! GIL, waits for it and checks for signals every 100 ms: Ctrl-C in a
//! notebook asks the job to stop (it does at its next check, leaving no
//! output under a final name) and raises KeyboardInterrupt.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

use arrow::array::{
    ArrayRef, BooleanArray, Float64Array, StringArray, TimestampNanosecondArray, UInt32Array,
    UInt64Array,
};
use arrow::datatypes::{DataType, Field, Schema, TimeUnit};
use arrow::ipc::writer::StreamWriter;
use arrow::record_batch::RecordBatch;
use clap::Parser;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyRuntimeError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use tortwin_discover::data::Dataset;
use tortwin_discover::Discovery;
use tortwin_engine::sink::Sink;
use tortwin_engine::EngineState;
use tortwin_jobs::replay::{self as job, SavedState};
use tortwin_jobs::{self as jobs, Cli, Command, ConfigSource};
use tortwin_outputs::tables::{Formats, MemoryTable, TableOptions, TableSink};
use tortwin_strategy::TrainRail;
use tortwin_study::{Error, Progress};

create_exception!(
    tortwin,
    TortwinError,
    PyException,
    "A tortwin job that could not finish (the command line's exit status 1)."
);
create_exception!(
    tortwin,
    InputError,
    TortwinError,
    "Bad input: a recording, state, table or configuration that breaks its format, or an \
     impossible request (the command line's exit status 2). The message names the file and \
     where in it (topic, log_time, index; the configuration key)."
);

/// `argv` as a command; a bad argument is an [`InputError`] with clap's
/// message.
fn parse(argv: Vec<String>) -> PyResult<Command> {
    let words = std::iter::once("tortwin".to_owned()).chain(argv);
    Cli::try_parse_from(words)
        .map(|cli| cli.command)
        .map_err(|e| InputError::new_err(e.to_string()))
}

fn to_py(err: Error) -> PyErr {
    if err.is_input() {
        InputError::new_err(err.full_message())
    } else {
        TortwinError::new_err(err.full_message())
    }
}

/// The configuration given to a Python function: `("file", path, _)` or
/// `("toml", text, name)` (a dict written as TOML by the package, or TOML
/// text; `name` stands for it in messages).
fn config_source(config: Option<(String, String, String)>) -> PyResult<Option<ConfigSource>> {
    match config {
        None => Ok(None),
        Some((kind, value, name)) => match kind.as_str() {
            "file" => Ok(Some(ConfigSource::File(value.into()))),
            "toml" => Ok(Some(ConfigSource::Text { text: value, name })),
            other => Err(PyRuntimeError::new_err(format!(
                "unknown kind of configuration {other:?}"
            ))),
        },
    }
}

/// Asks the job to stop once the waiting thread saw a signal.
struct Cancel(Arc<AtomicBool>);

impl Progress for Cancel {
    fn cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// Runs `job` on a thread of its own; the caller waits without the GIL and
/// checks for signals (Ctrl-C) every 100 ms.
fn run_job<T, F>(py: Python<'_>, job: F) -> PyResult<T>
where
    T: Send + 'static,
    F: FnOnce(&dyn Progress) -> Result<T, Error> + Send + 'static,
{
    let flag = Arc::new(AtomicBool::new(false));
    let (tx, rx) = mpsc::channel();
    let cancel = Cancel(flag.clone());
    let worker = std::thread::Builder::new()
        .name("tortwin-job".into())
        .spawn(move || {
            // The receiver may be gone only if the caller itself failed.
            let _ = tx.send(job(&cancel));
        })
        .map_err(|e| TortwinError::new_err(format!("cannot start the job's thread: {e}")))?;
    let mut rx = Some(rx);
    let outcome = loop {
        // The receiver moves into the closure and back (it is Send, not Sync).
        let (received, back) = match rx.take() {
            Some(r) => py.detach(move || (r.recv_timeout(Duration::from_millis(100)), r)),
            None => break Err(TortwinError::new_err("the job's result was lost")),
        };
        rx = Some(back);
        match received {
            Ok(result) => break result.map_err(to_py),
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if let Err(interrupt) = py.check_signals() {
                    flag.store(true, Ordering::Relaxed);
                    // Wait for the job to stop at its next check, so that
                    // nothing goes on writing behind the caller's back.
                    if let Some(r) = rx.take() {
                        let _ = py.detach(move || r.recv());
                    }
                    break Err(interrupt);
                }
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => break Err(TortwinError::new_err(
                "the job's thread stopped without a result (a bug in tortwin: please report it)",
            )),
        }
    };
    let _ = py.detach(|| worker.join());
    outcome
}

/// Record batches as an Arrow IPC stream.
fn ipc(table: &MemoryTable) -> Result<Vec<u8>, arrow::error::ArrowError> {
    let mut out = Vec::new();
    let mut writer = StreamWriter::try_new(&mut out, &table.schema)?;
    for batch in &table.batches {
        writer.write(batch)?;
    }
    writer.finish()?;
    drop(writer);
    Ok(out)
}

fn ipc_error(e: arrow::error::ArrowError) -> Error {
    Error::Inconsistent(format!("building an Arrow table: {e}"))
}

/// What a replay job gives: summary and state (JSON), the measurements,
/// field, trains and per-train metrics tables (Arrow IPC).
type ReplayResult = (
    String,
    String,
    Vec<u8>,
    Option<Vec<u8>>,
    Vec<u8>,
    Option<Vec<u8>>,
);

/// [`ReplayResult`] as Python objects.
type ReplayOut = (
    String,
    String,
    Py<PyBytes>,
    Option<Py<PyBytes>>,
    Py<PyBytes>,
    Option<Py<PyBytes>>,
);

/// `tortwin replay ARGV`, starting from `state_json` (a state's JSON text)
/// when given. Returns the summary (JSON), the state at the end (JSON) and
/// the measurements, field (unless `field` is false) and trains tables as
/// Arrow IPC streams; with `per_train`, also every train's contacts in the
/// target band, carry-on and product per rail.
#[pyfunction]
#[pyo3(signature = (argv, config=None, state_json=None, field=true, per_train=false))]
fn replay(
    py: Python<'_>,
    argv: Vec<String>,
    config: Option<(String, String, String)>,
    state_json: Option<String>,
    field: bool,
    per_train: bool,
) -> PyResult<ReplayOut> {
    let Command::Replay(mut args) = parse(argv)? else {
        return Err(PyRuntimeError::new_err("not a replay command"));
    };
    if let Some(source) = config_source(config)? {
        args.config = Some(source);
    }
    args.per_train = per_train;
    let state: Option<EngineState> = state_json
        .map(|text| {
            serde_json::from_str(&text).map_err(|e| {
                InputError::new_err(format!("the state passed in: not a tortwin state: {e}"))
            })
        })
        .transpose()?;
    let run = move |progress: &dyn Progress| -> Result<ReplayResult, Error> {
        let options = TableOptions {
            formats: Formats {
                parquet: false,
                csv: false,
                memory: true,
            },
            field,
            ..TableOptions::default()
        };
        let mut tables = TableSink::create(Path::new("."), options)?;
        let start = state.as_ref().map(|s| SavedState {
            state: s,
            name: "the state passed in".into(),
            file: None,
        });
        let done = job::replay(&args, start, &mut [&mut tables as &mut dyn Sink], progress)?;
        let summary = serde_json::to_string(&done.summary).map_err(|source| Error::Json {
            what: "the summary",
            source,
        })?;
        let state = serde_json::to_string(&done.state).map_err(|source| Error::Json {
            what: "the state",
            source,
        })?;
        let t = tables.into_tables();
        let per_train = done
            .per_train
            .as_deref()
            .map(|rows| per_train_table(rows).and_then(|t| ipc(&t)))
            .transpose()
            .map_err(ipc_error)?;
        Ok((
            summary,
            state,
            ipc(&t.measurements).map_err(ipc_error)?,
            t.field.as_ref().map(ipc).transpose().map_err(ipc_error)?,
            ipc(&t.trains).map_err(ipc_error)?,
            per_train,
        ))
    };
    let (summary, state, measurements, field, trains, per_train) = run_job(py, run)?;
    let bytes = |b: &[u8]| PyBytes::new(py, b).unbind();
    Ok((
        summary,
        state,
        bytes(&measurements),
        field.as_deref().map(bytes),
        bytes(&trains),
        per_train.as_deref().map(bytes),
    ))
}

/// The per-train metrics as a table: a row per train and rail.
fn per_train_table(rows: &[TrainRail]) -> Result<MemoryTable, arrow::error::ArrowError> {
    let time = DataType::Timestamp(TimeUnit::Nanosecond, Some("UTC".into()));
    let schema = Arc::new(Schema::new(vec![
        Field::new("train_id", DataType::Utf8, false),
        Field::new("time_utc", time, false),
        Field::new("rail", DataType::Utf8, false),
        Field::new("wheel_passes", DataType::UInt64, false),
        Field::new("in_band_share", DataType::Float64, false),
        Field::new("below_band_share", DataType::Float64, false),
        Field::new("carry_on_m", DataType::Float64, false),
        Field::new("pulses", DataType::UInt64, false),
        Field::new("product_g", DataType::Float64, false),
    ]));
    let f = |get: fn(&TrainRail) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(rows.iter().map(get)))
    };
    let columns: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from_iter_values(
            rows.iter().map(|r| r.train_id.as_str()),
        )),
        Arc::new(
            TimestampNanosecondArray::from_iter_values(
                rows.iter()
                    .map(|r| i64::try_from(r.log_time_ns).unwrap_or(i64::MAX)),
            )
            .with_timezone("UTC"),
        ),
        Arc::new(StringArray::from_iter_values(
            rows.iter().map(|r| r.rail.as_str()),
        )),
        Arc::new(UInt64Array::from_iter_values(
            rows.iter().map(|r| r.wheel_passes),
        )),
        f(|r| r.in_band_share),
        f(|r| r.below_band_share),
        f(|r| r.carry_on_m),
        Arc::new(UInt64Array::from_iter_values(rows.iter().map(|r| r.pulses))),
        f(|r| r.product_g),
    ];
    let batch = RecordBatch::try_new(schema.clone(), columns)?;
    Ok(MemoryTable {
        schema,
        batches: vec![batch],
    })
}

/// `tortwin synth ARGV` (the truth configuration from `truth_config`).
/// Returns the key (JSON) and its path.
#[pyfunction]
#[pyo3(signature = (argv, truth_config=None))]
fn synth(
    py: Python<'_>,
    argv: Vec<String>,
    truth_config: Option<(String, String, String)>,
) -> PyResult<(String, String)> {
    let Command::Synth(mut args) = parse(argv)? else {
        return Err(PyRuntimeError::new_err("not a synth command"));
    };
    if let Some(source) = config_source(truth_config)? {
        args.truth_config = Some(source);
    }
    run_job(py, move |progress| {
        let (report, key) = jobs::synth::synth_with(&args, progress)?;
        let json = serde_json::to_string(&report).map_err(|source| Error::Json {
            what: "the key",
            source,
        })?;
        Ok((json, key.display().to_string()))
    })
}

/// `tortwin discover ARGV`. Returns report.json's content and the residual
/// table (Arrow IPC): every measurement with its residual before and after.
#[pyfunction]
#[pyo3(signature = (argv, config=None))]
fn discover(
    py: Python<'_>,
    argv: Vec<String>,
    config: Option<(String, String, String)>,
) -> PyResult<(String, Py<PyBytes>)> {
    let Command::Discover(mut args) = parse(argv)? else {
        return Err(PyRuntimeError::new_err("not a discover command"));
    };
    if let Some(source) = config_source(config)? {
        args.config = Some(source);
    }
    report_with_residuals(py, move |progress| {
        jobs::discover::run_with_data(&args, progress)
    })
}

/// `tortwin calibrate ARGV`. Returns report.json's content (its
/// `site_constants`) and the residual table (Arrow IPC): every measurement
/// with its residual before and after the calibration.
#[pyfunction]
#[pyo3(signature = (argv, config=None))]
fn calibrate(
    py: Python<'_>,
    argv: Vec<String>,
    config: Option<(String, String, String)>,
) -> PyResult<(String, Py<PyBytes>)> {
    let Command::Calibrate(mut args) = parse(argv)? else {
        return Err(PyRuntimeError::new_err("not a calibrate command"));
    };
    if let Some(source) = config_source(config)? {
        args.config = Some(source);
    }
    report_with_residuals(py, move |progress| {
        jobs::discover::calibrate_with_data(&args, progress)
    })
}

/// Runs a discover or calibrate job; returns report.json's content and
/// the residual table (Arrow IPC).
fn report_with_residuals<F>(py: Python<'_>, job: F) -> PyResult<(String, Py<PyBytes>)>
where
    F: FnOnce(&dyn Progress) -> Result<(Discovery, Dataset), Error> + Send + 'static,
{
    let (report, residuals) = run_job(py, move |progress| {
        let (found, data) = job(progress)?;
        let json = serde_json::to_string(&found).map_err(|source| Error::Json {
            what: "the report",
            source,
        })?;
        let table = residual_table(&data, &found).map_err(ipc_error)?;
        Ok((json, ipc(&table).map_err(ipc_error)?))
    })?;
    Ok((report, PyBytes::new(py, &residuals).unbind()))
}

/// One row per measurement of the recording: where and when, the value,
/// the residual (measured − simulated) with the starting model and with
/// the model found, and whether the fits left it out as a gross error.
fn residual_table(
    data: &Dataset,
    found: &Discovery,
) -> Result<MemoryTable, arrow::error::ArrowError> {
    let rows = &data.rows;
    let time = DataType::Timestamp(TimeUnit::Nanosecond, Some("UTC".into()));
    let schema = Arc::new(Schema::new(vec![
        Field::new("time_utc", time, false),
        Field::new("index_in_file", DataType::UInt64, false),
        Field::new("site", DataType::Utf8, false),
        Field::new("rail", DataType::Utf8, false),
        Field::new("quantity", DataType::Utf8, false),
        Field::new("train_id", DataType::Utf8, true),
        Field::new("axle_index", DataType::UInt32, true),
        Field::new("measured", DataType::Float64, false),
        Field::new("residual_before", DataType::Float64, false),
        Field::new("residual_after", DataType::Float64, false),
        Field::new("outlier", DataType::Boolean, false),
    ]));
    let active = &found.outliers.active;
    let columns: Vec<ArrayRef> = vec![
        Arc::new(
            TimestampNanosecondArray::from_iter_values(
                rows.iter()
                    .map(|r| i64::try_from(r.log_time_ns).unwrap_or(i64::MAX)),
            )
            .with_timezone("UTC"),
        ),
        Arc::new(UInt64Array::from_iter_values(
            rows.iter().map(|r| r.index_in_file),
        )),
        Arc::new(StringArray::from_iter_values(
            rows.iter().map(|r| data.site_name(r.site)),
        )),
        Arc::new(StringArray::from_iter_values(
            rows.iter().map(|r| data.rail_name(r.rail)),
        )),
        Arc::new(StringArray::from_iter_values(
            rows.iter().map(|r| r.quantity.as_str()),
        )),
        Arc::new(StringArray::from_iter(rows.iter().map(|r| {
            r.train_seq
                .and_then(|t| data.passages.get(t))
                .map(|p| p.train_id.as_str())
        }))),
        Arc::new(UInt32Array::from_iter(
            rows.iter()
                .map(|r| r.axle_index.and_then(|a| u32::try_from(a).ok())),
        )),
        Arc::new(Float64Array::from_iter_values(
            rows.iter().map(|r| r.measured),
        )),
        Arc::new(Float64Array::from_iter_values(
            found.residual_before.iter().copied(),
        )),
        Arc::new(Float64Array::from_iter_values(
            found.residual_after.iter().copied(),
        )),
        Arc::new(BooleanArray::from_iter(
            (0..rows.len()).map(|i| Some(!active.get(i).copied().unwrap_or(true))),
        )),
    ];
    let batch = RecordBatch::try_new(schema.clone(), columns)?;
    Ok(MemoryTable {
        schema,
        batches: vec![batch],
    })
}

/// `tortwin strategy ARGV`. Returns the path of strategy.json.
#[pyfunction]
#[pyo3(signature = (argv, config=None))]
fn strategy(
    py: Python<'_>,
    argv: Vec<String>,
    config: Option<(String, String, String)>,
) -> PyResult<String> {
    let Command::Strategy(mut args) = parse(argv)? else {
        return Err(PyRuntimeError::new_err("not a strategy command"));
    };
    if let Some(source) = config_source(config)? {
        args.config = Some(source);
    }
    run_job(py, move |progress| {
        jobs::strategy::run_with(&args, progress)?;
        Ok(args.out.join("strategy.json").display().to_string())
    })
}

/// `tortwin split ARGV`: the days written, as (date, path) pairs in time
/// order.
#[pyfunction]
fn split(py: Python<'_>, argv: Vec<String>) -> PyResult<Vec<(String, String)>> {
    let Command::Split(args) = parse(argv)? else {
        return Err(PyRuntimeError::new_err("not a split command"));
    };
    run_job(py, move |progress| {
        let days = jobs::recordings::split(&args, progress)?;
        Ok(days
            .into_iter()
            .map(|d| (d.date, d.path.display().to_string()))
            .collect())
    })
}

/// `tortwin merge ARGV`: the messages written.
#[pyfunction]
fn merge(py: Python<'_>, argv: Vec<String>) -> PyResult<u64> {
    let Command::Merge(args) = parse(argv)? else {
        return Err(PyRuntimeError::new_err("not a merge command"));
    };
    run_job(py, move |progress| jobs::recordings::merge(&args, progress))
}

/// What a follow sends the iterator: a JSON line, or the follow's end.
enum Followed {
    Line(String),
    End(Result<(), Error>),
}

/// `tortwin live ARGV` on a thread of its own, as an iterator of JSON
/// lines: each train's rail band and each alert (`--json`'s lines) as they
/// come out, and `{"kind": "recording", ...}` per recording finished.
#[pyclass(module = "tortwin._native")]
struct Live {
    lines: std::sync::Mutex<mpsc::Receiver<Followed>>,
    stop: Arc<AtomicBool>,
    worker: std::sync::Mutex<Option<std::thread::JoinHandle<()>>>,
}

/// Starts `tortwin live ARGV` (see [`Live`]).
#[pyfunction]
#[pyo3(signature = (argv, config=None))]
fn live(argv: Vec<String>, config: Option<(String, String, String)>) -> PyResult<Live> {
    let Command::Live(mut args) = parse(argv)? else {
        return Err(PyRuntimeError::new_err("not a live command"));
    };
    if let Some(source) = config_source(config)? {
        args.config = Some(source);
    }
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = mpsc::channel();
    let thread_stop = stop.clone();
    let worker = std::thread::Builder::new()
        .name("tortwin-live".into())
        .spawn(move || {
            // A receiver that is gone (the iterator dropped) stops the follow.
            let send = |followed: Followed| {
                if tx.send(followed).is_err() {
                    thread_stop.store(true, Ordering::Relaxed);
                }
            };
            let mut on_line = |line: &str| send(Followed::Line(line.to_owned()));
            let mut on_recording = |f: &jobs::live::Followed| {
                let line = serde_json::json!({
                    "kind": "recording",
                    "recording": f.recording.display().to_string(),
                    "trains": f.trains,
                    "measurements": f.measurements,
                });
                send(Followed::Line(line.to_string()));
            };
            let hooks = jobs::live::LiveHooks {
                on_recording: &mut on_recording,
                on_line: Some(&mut on_line),
                stop: Some(thread_stop.clone()),
            };
            let result = jobs::live::live(&args, hooks).map(|_| ());
            send(Followed::End(result));
        })
        .map_err(|e| TortwinError::new_err(format!("cannot start the follower's thread: {e}")))?;
    Ok(Live {
        lines: std::sync::Mutex::new(rx),
        stop,
        worker: std::sync::Mutex::new(Some(worker)),
    })
}

#[pymethods]
impl Live {
    /// The next line, waiting for it without the GIL (Ctrl-C stops the
    /// follow and raises KeyboardInterrupt); `None` once the follow ended.
    fn next(&self, py: Python<'_>) -> PyResult<Option<String>> {
        loop {
            let received = py.detach(|| {
                let lines = self.lines.lock().unwrap_or_else(|e| e.into_inner());
                lines.recv_timeout(Duration::from_millis(100))
            });
            match received {
                Ok(Followed::Line(line)) => return Ok(Some(line)),
                Ok(Followed::End(result)) => {
                    self.join(py);
                    return result.map(|()| None).map_err(to_py);
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    if let Err(interrupt) = py.check_signals() {
                        self.close(py);
                        return Err(interrupt);
                    }
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    self.join(py);
                    return Ok(None);
                }
            }
        }
    }

    /// Stops the follow (as a SIGKILL would: the checkpoint and the day
    /// files in place stay) and waits for its thread.
    fn close(&self, py: Python<'_>) {
        self.stop.store(true, Ordering::Relaxed);
        self.join(py);
    }
}

impl Live {
    fn join(&self, py: Python<'_>) {
        let worker = self.worker.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(worker) = worker {
            let _ = py.detach(move || worker.join());
        }
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        // Dropped without close(): the follow stops at its next poll.
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// The version of the library crates the module was built from.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("TortwinError", m.py().get_type::<TortwinError>())?;
    m.add("InputError", m.py().get_type::<InputError>())?;
    m.add_function(wrap_pyfunction!(replay, m)?)?;
    m.add_function(wrap_pyfunction!(synth, m)?)?;
    m.add_function(wrap_pyfunction!(discover, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(strategy, m)?)?;
    m.add_function(wrap_pyfunction!(split, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(live, m)?)?;
    m.add_class::<Live>()?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    Ok(())
}
