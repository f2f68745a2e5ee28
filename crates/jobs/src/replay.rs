//! `tortwin replay`: a recording in, the friction field out.

use serde::Deserialize;
use std::path::{Path, PathBuf};

use tortwin_engine::alerts::{AlertMemory, Alerting};
use tortwin_engine::sink::{Fanout, RunSummary, Sink, SinkThread};
use tortwin_engine::{Engine, EngineOptions, EngineState};
use tortwin_files::usage::UsageError;
use tortwin_outputs::mcap_out::McapSink;
use tortwin_outputs::provenance::Provenance;
use tortwin_outputs::rerun_out::{RerunOptions, RerunSink};
use tortwin_recording::error::InputError;
use tortwin_recording::reader::{read_ahead, ReaderContext};
use tortwin_recording::RecordingReader;

use super::load_config;
use tortwin_strategy::{PerTrain, Target, TrainRail};
use tortwin_study::progress::Progress;
use tortwin_study::{Error, Result};

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct ReplayArgs {
    /// The recording to replay (MCAP, docs/spec/recording-format.md), e.g.
    /// recordings/demo_day.mcap in the repository.
    pub recording: PathBuf,
    /// Model configuration overlaid on the built-in defaults (TOML; only
    /// the keys it changes, e.g. a `tortwin discover` model.toml).
    #[cfg_attr(feature = "cli", arg(long))]
    pub config: Option<super::ConfigSource>,
    /// Write the MCAP output here (Foxglove-readable).
    #[cfg_attr(feature = "cli", arg(long))]
    pub out_mcap: Option<PathBuf>,
    /// Write the rerun recording here (open with `rerun FILE.rrd`).
    #[cfg_attr(feature = "cli", arg(long))]
    pub out_rrd: Option<PathBuf>,
    /// Start from the state an earlier replay wrote with --state-out.
    #[cfg_attr(feature = "cli", arg(long))]
    pub state_in: Option<PathBuf>,
    /// Write the section's state at the end, for the next recording.
    #[cfg_attr(feature = "cli", arg(long))]
    pub state_out: Option<PathBuf>,
    /// Snapshot the field after every wheel pass in the rerun recording
    /// (default: after every train).
    #[cfg_attr(feature = "cli", arg(long))]
    pub every_wheel: bool,
    /// On a line: the axle (0-based) whose view the rerun recording has,
    /// with the next one: the mu both saw along each rail and the axle's
    /// tread bands F, C, G.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0, value_name = "K"))]
    pub line_axle: usize,
    /// Do not print the summary.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
    /// Count every train's contacts in the default target band, its
    /// carry-on and its product ([`Replayed::per_train`]; the fleet's
    /// metrics). Not a command-line flag.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub per_train: bool,
}

impl ReplayArgs {
    /// A quiet replay of `recording` with the default model and no outputs;
    /// set the fields a caller needs.
    pub fn new(recording: impl Into<PathBuf>) -> Self {
        Self {
            recording: recording.into(),
            config: None,
            out_mcap: None,
            out_rrd: None,
            state_in: None,
            state_out: None,
            every_wheel: false,
            line_axle: 0,
            quiet: true,
            per_train: false,
        }
    }
}

/// Reads a state written by `--state-out`.
pub fn read_state(path: &Path) -> Result<EngineState, InputError> {
    let text =
        tortwin_outputs::files::read_text_input(path, tortwin_outputs::files::MAX_STATE_BYTES)
            .map_err(|e| InputError::file(path, format!("cannot read the state: {e}")))?;
    // The path names the field a value that does not read sits in.
    let mut json = serde_json::Deserializer::from_str(&text);
    let mut track = serde_path_to_error::Track::new();
    let state = EngineState::deserialize(serde_path_to_error::Deserializer::new(
        &mut json, &mut track,
    ))
    .and_then(|state| json.end().map(|()| state))
    .map_err(|e| {
        let at = track.path();
        let field = if at.iter().next().is_some() {
            format!("field `{at}`: ")
        } else {
            String::new()
        };
        InputError::file(path, format!("not a tortwin state: {field}{e}"))
    })?;
    Ok(state)
}

/// The replay job, its one entry point: replays `args.recording` from
/// `start` (a state held in memory) or else from `args.state_in` (or a
/// fresh section), into the outputs the arguments ask for and the `extra`
/// sinks, telling `progress` how far the recording has been read; writes
/// `args.state_out` and returns what the replay left (its summary, the
/// state, the per-train rows). Stops with [`Error::Cancelled`] when
/// `progress` says so.
pub fn replay(
    args: &ReplayArgs,
    start: Option<SavedState<'_>>,
    extra: &mut [&mut dyn Sink],
    progress: &dyn Progress,
) -> Result<Replayed> {
    // The inputs read from here on are this job's (tortwin_files::InputScope).
    let _inputs = tortwin_outputs::files::InputScope::enter();
    let saved;
    let start = match (start, &args.state_in) {
        (Some(start), _) => Some(start),
        (None, Some(path)) => {
            saved = read_state(path)?;
            Some(SavedState {
                state: &saved,
                name: path.display().to_string(),
                file: Some(path),
            })
        }
        (None, None) => None,
    };
    let run = run(args, start, extra, progress)?;
    if let Some(path) = &args.state_out {
        let text = serde_json::to_string(&run.state).map_err(|source| Error::Json {
            what: "the state",
            source,
        })?;
        tortwin_outputs::files::write_atomically(path, text.as_bytes())?;
    }
    Ok(run)
}

/// A state to start a replay from.
pub struct SavedState<'a> {
    pub state: &'a EngineState,
    /// What error messages call it (the file's path, "the state passed in").
    pub name: String,
    /// The file it was read from, for the provenance.
    pub file: Option<&'a Path>,
}

/// What a replay leaves: its summary and the section's state at the end
/// (what `--state-out` writes).
pub struct Replayed {
    pub summary: RunSummary,
    pub state: EngineState,
    /// Per train and rail, with `ReplayArgs::per_train`.
    pub per_train: Option<Vec<TrainRail>>,
}

/// [`replay`] without the state files: from `start` (or a fresh section)
/// into the outputs and `extra`.
fn run(
    args: &ReplayArgs,
    start: Option<SavedState<'_>>,
    extra: &mut [&mut dyn Sink],
    progress: &dyn Progress,
) -> Result<Replayed> {
    // The inputs' scope is [`replay`]'s, which calls this.
    let cfg = load_config(args.config.as_ref())?;
    let alerts = super::load_alerts(args.config.as_ref())?;
    let outputs = [&args.out_mcap, &args.out_rrd, &args.state_out];
    for (k, a) in outputs.iter().enumerate() {
        if let Some(a) = a {
            if outputs[k + 1..].iter().any(|b| b.as_ref() == Some(a)) {
                return Err(
                    UsageError(format!("two outputs would be written to {}", a.display())).into(),
                );
            }
        }
    }
    let ctx = match &start {
        Some(s) => ReaderContext {
            origin_ns: Some(s.state.origin_ns),
            occupied_until_s: s.state.occupied_until_s.unwrap_or(f64::NEG_INFINITY),
        },
        None => ReaderContext::default(),
    };
    // The inputs' sha256 (for the outputs' provenance) is read on a thread
    // of its own while the reader's layout pass reads the recording: both
    // take a few tenths of a second on a year's recording. A recording that
    // cannot be read is reported first, as if one came after the other.
    let provenance_inputs = {
        let mut inputs = vec![args.recording.as_path()];
        inputs.extend(args.config.as_ref().and_then(super::ConfigSource::path));
        inputs.extend(start.as_ref().and_then(|s| s.file));
        inputs
    };
    let wants_provenance = args.out_mcap.is_some() || args.out_rrd.is_some();
    let (reader, provenance) = std::thread::scope(|scope| {
        let hashing =
            wants_provenance.then(|| scope.spawn(|| Provenance::of_run(&provenance_inputs, &cfg)));
        // The layout pass checks the recording beside the replay.
        let reader = RecordingReader::open_beside(&args.recording, ctx);
        let provenance = hashing.map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
        (reader, provenance)
    });
    let mut reader = reader?;
    // What the layout pass finds wrong with the recording goes before an
    // error of the replay's own, as if it had been laid out first.
    replay_opened(
        args,
        &mut reader,
        provenance,
        cfg,
        alerts,
        start,
        extra,
        progress,
    )
    .map_err(|e| layout_first(&mut reader, e))
}

/// [`run`] once the recording is open: the engine and the outputs made,
/// the recording stepped through.
#[allow(clippy::too_many_arguments)]
fn replay_opened(
    args: &ReplayArgs,
    reader: &mut RecordingReader,
    provenance: Option<std::result::Result<Provenance, InputError>>,
    cfg: tortwin_model::config::ModelConfig,
    alerts: tortwin_model::config::alerts::AlertConfig,
    start: Option<SavedState<'_>>,
    extra: &mut [&mut dyn Sink],
    progress: &dyn Progress,
) -> Result<Replayed> {
    let provenance = provenance.transpose()?;
    let opts = EngineOptions {
        snapshot_every_wheel: args.every_wheel,
        every_wheel_contacts: args.per_train,
        line_axle: args.out_rrd.is_some().then_some(args.line_axle),
        // The output files' threads (below) take the second core.
        beside_output_threads: args.out_mcap.is_some() || args.out_rrd.is_some(),
        ..EngineOptions::default()
    };
    let source = config_name(args.config.as_ref());
    let mut per_train = args
        .per_train
        .then(|| PerTrain::new(reader.section(), &cfg, &Target::default()))
        .transpose()?;
    let mut engine = engine_for(reader, cfg, opts, start.as_ref(), &source)?;
    let memory = alert_memory(reader, start.as_ref())?;

    let mcap = args
        .out_mcap
        .as_deref()
        .map(|p| {
            let line = reader.line().is_some();
            McapSink::for_replay(p, provenance.as_ref(), reader.message_count(), line)
        })
        .transpose()?;
    let rrd = args
        .out_rrd
        .as_deref()
        .map(|p| {
            let options = RerunOptions {
                provenance: provenance.clone(),
                ..RerunOptions::default()
            };
            RerunSink::create(p, options)
        })
        .transpose()?;
    // The files are encoded and written on a thread of their own while the
    // engine steps (the same calls in the same order: the same files).
    // Behind the engine unless it feeds an MCAP writer as busy as the
    // engine (McapCompression::runs_behind_the_engine).
    let behind = mcap.as_ref().is_none_or(McapSink::writer_runs_behind);
    let mut files = if mcap.is_some() || rrd.is_some() {
        let mut files: Fanout<Box<dyn Sink + Send>> = Fanout::default();
        files
            .sinks
            .extend(mcap.map(|s| Box::new(s) as Box<dyn Sink + Send>));
        files
            .sinks
            .extend(rrd.map(|s| Box::new(s) as Box<dyn Sink + Send>));
        let path = args.out_mcap.as_ref().or(args.out_rrd.as_ref());
        Some(
            SinkThread::spawn("tortwin-outputs", files, behind).map_err(|source| Error::Io {
                what: "cannot start the thread that writes",
                path: path.cloned().unwrap_or_default(),
                source,
            })?,
        )
    } else {
        None
    };
    let mut fanout: Fanout<&mut dyn Sink> = Fanout::default();
    if let Some(s) = per_train.as_mut() {
        fanout.sinks.push(s);
    }
    if let Some(s) = files.as_mut() {
        fanout.sinks.push(s);
    }
    for s in extra.iter_mut() {
        fanout.sinks.push(&mut **s);
    }
    let mut fanout = Alerting::new(alerts, memory, fanout);

    progress.stage_of(
        &format!("replaying {} (messages)", args.recording.display()),
        reader.message_count(),
    );
    // The /section message was read when the reader opened. The rest are
    // read ahead on a thread of their own while the engine steps.
    let message_count = reader.message_count();
    read_ahead(reader, |events| -> Result<()> {
        let mut messages = 1u64;
        for event in events {
            let event = event?;
            messages += 1;
            if messages.is_multiple_of(1024) {
                progress.done(messages);
                tortwin_study::progress::check(progress)?;
            }
            engine
                .push(event, &mut fanout)
                .map_err(|source| Error::Replay {
                    what: args.recording.display().to_string(),
                    source,
                })?;
        }
        Ok(())
    })?;
    let summary = engine.finish(&mut fanout, reader.unknown_topic_messages())?;
    progress.done(message_count);
    let mut state = engine.state();
    state.alerts = fanout.memory();
    drop(fanout);
    Ok(Replayed {
        summary,
        state,
        per_train: per_train.map(|p| p.rows().to_vec()),
    })
}

/// What error messages call the configuration.
pub(crate) fn config_name(config: Option<&super::ConfigSource>) -> String {
    config.map_or_else(
        || "built-in defaults".to_string(),
        super::ConfigSource::name,
    )
}

/// The engine that replays `reader`'s recording with `cfg` (called `source`
/// in errors), from `start` or a fresh section: the generic terms and, on a
/// line, the configuration checked against the recording.
pub(crate) fn engine_for(
    reader: &RecordingReader,
    cfg: tortwin_model::config::ModelConfig,
    opts: EngineOptions,
    start: Option<&SavedState<'_>>,
    source: &str,
) -> Result<Engine> {
    let section = reader.section().clone();
    tortwin_engine::terms::check_terms_against(&cfg.effects.generic, &section, source)?;
    let line = reader.line().cloned();
    if line.is_some() {
        tortwin_engine::line::check_config(&cfg, source)?;
    }
    Ok(match start {
        Some(s) => Engine::from_state(section, line, cfg, opts, s.state)
            .map_err(|e| InputError::file(Path::new(&s.name), e.to_string()))?,
        None => Engine::on_line(section, line, cfg, opts, reader.origin_ns()),
    })
}

/// `e`, an error of the replay's own, or what the layout pass found wrong
/// with the recording if it did ([`RecordingReader::layout_verdict`]):
/// the error a replay of the recording laid out first would have stopped
/// on.
fn layout_first(reader: &mut RecordingReader, e: impl Into<Error>) -> Error {
    match reader.layout_verdict() {
        Ok(()) => e.into(),
        Err(layout) => layout.into(),
    }
}

/// What `start`'s alerts remembered, checked against `reader`'s section.
pub(crate) fn alert_memory(
    reader: &RecordingReader,
    start: Option<&SavedState<'_>>,
) -> Result<Option<AlertMemory>> {
    let Some(s) = start else {
        return Ok(None);
    };
    let Some(memory) = &s.state.alerts else {
        return Ok(None);
    };
    memory
        .check(reader.section(), s.state.tracks.len())
        .map_err(|e| InputError::file(Path::new(&s.name), e))?;
    Ok(Some(memory.clone()))
}

/// The lines that say where the outputs are and how to open them.
pub fn render_outputs(args: &ReplayArgs) -> String {
    let mut out = String::new();
    for (what, path) in [
        ("rerun recording", &args.out_rrd),
        ("MCAP output", &args.out_mcap),
    ] {
        if let Some(path) = path {
            out += &format!("{what}: {}\n", path.display());
        }
    }
    if let Some(path) = &args.out_rrd {
        out += &format!(
            "open it with: pip install rerun-sdk==0.36.3 && rerun {}\n",
            path.display()
        );
    }
    if let Some(path) = &args.out_mcap {
        out += &format!(
            "or open {} in Foxglove (https://app.foxglove.dev, Open local file)\n",
            path.display()
        );
    }
    out
}
