//! `tortwin live`: the twin beside the track. Follows a recording while a
//! logger writes it, or a folder in which the logger's hour or day files
//! appear, and writes what `tortwin replay` of the finished files writes,
//! as it goes.
//!
//! **Inputs.** A file is followed record by record until its end (the
//! reader's `Follow`: a half-written chunk is waited for, a summary is not
//! needed). A folder's `*.mcap` files are taken in name order, each followed
//! to its end and continuing the state of the one before (as `tortwin
//! replay --state-in` does); then the follower waits for the next one.
//!
//! **Outputs.** In `--out-dir`: the MCAP output of each recording per UTC
//! day, `STEM.YYYY-MM-DD.mcap` (McapSink::daily), each complete on its own
//! and moved into place when the next day begins or the recording ends; the
//! messages of all of them, in order, are those of the replay's output (each
//! later day opens with the `/twin/section` message again).
//!
//! **Checkpoints.** After each finished recording, `live-checkpoint.json`
//! (which recordings are done and the section's state after them) and
//! `--state-out`, both written atomically. A follower killed at any moment
//! and started again with the same command continues from the checkpoint:
//! the finished recordings are not read again; the one it was in is stepped
//! again from the checkpoint's state, and of its outputs only the days not
//! yet in place are written (those in place were complete, and the same
//! messages would be written again). So no train is in the outputs twice or
//! missing, and the state is the replay's.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use tortwin_engine::alerts::Alerting;
use tortwin_engine::sink::{
    Alert, Fanout, FieldSnapshot, Sink, SinkError, SinkResult, SnapshotKind,
};
use tortwin_engine::{EngineOptions, EngineState};
use tortwin_files::usage::UsageError;
use tortwin_outputs::mcap_out::{FoxgloveServer, McapSink};
use tortwin_outputs::provenance::Provenance;
use tortwin_outputs::rerun_out::{RerunOptions, RerunSink};
use tortwin_outputs::rerun_sdk;
use tortwin_recording::error::InputError;
use tortwin_recording::reader::{Abandoned, Follow, Followed as ReadStep, ReaderContext};
use tortwin_recording::RecordingReader;
use tortwin_study::{Error, Result};

use super::load_config;
use super::replay::{config_name, engine_for, read_state, SavedState};

/// The checkpoint's name in the output folder.
pub const CHECKPOINT: &str = "live-checkpoint.json";
/// Where a rerun viewer listens by default.
pub const DEFAULT_VIEWER_URL: &str = "rerun+http://127.0.0.1:9876/proxy";
/// Where `--foxglove` serves by default (Foxglove's usual port).
pub const DEFAULT_FOXGLOVE_ADDRESS: &str = "127.0.0.1:8765";
const CHECKPOINT_FORMAT: &str = "tortwin-live-checkpoint";
const CHECKPOINT_VERSION: u32 = 1;

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct LiveArgs {
    /// The recording a logger is writing (MCAP), or a folder in which its
    /// recordings appear (taken in name order, each continuing the state
    /// of the one before).
    pub input: PathBuf,
    /// Folder of the outputs: the MCAP output per recording and UTC day
    /// (`STEM.YYYY-MM-DD.mcap`) and the checkpoint (`live-checkpoint.json`).
    /// Empty or missing at the first start; the same folder continues a
    /// follower that was stopped.
    #[cfg_attr(feature = "cli", arg(long))]
    pub out_dir: PathBuf,
    /// Model configuration overlaid on the built-in defaults (TOML).
    #[cfg_attr(feature = "cli", arg(long))]
    pub config: Option<super::ConfigSource>,
    /// Start the first recording from the state an earlier replay wrote.
    #[cfg_attr(feature = "cli", arg(long))]
    pub state_in: Option<PathBuf>,
    /// Write the section's state here after every finished recording.
    #[cfg_attr(feature = "cli", arg(long))]
    pub state_out: Option<PathBuf>,
    /// How often to look for more data, in milliseconds.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 20, value_name = "MS"))]
    pub poll_ms: u64,
    /// How far behind the latest message read a message may still be
    /// written, in seconds (a source that reaches the logger late); trains
    /// are stepped this much later. 0: the logger writes in time order.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0, value_name = "S"))]
    pub max_delay_s: f64,
    /// Print a JSON line per train and rail band as its field comes out
    /// (mu's least and mean, the length below and above the target band),
    /// and per alert.
    #[cfg_attr(feature = "cli", arg(long))]
    pub json: bool,
    /// Stream to a running rerun viewer (or a gRPC server relaying to
    /// viewers) at URL, default rerun+http://127.0.0.1:9876/proxy: what
    /// `replay --out-rrd` would write, train by train, with its layout.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "URL", num_args = 0..=1, default_missing_value = DEFAULT_VIEWER_URL)
    )]
    pub connect: Option<String>,
    /// Serve the MCAP output's channels live over Foxglove's WebSocket
    /// protocol on HOST:PORT (default 127.0.0.1:8765; 0.0.0.0:8765 for
    /// other machines): the Foxglove app connects to ws://HOST:PORT and
    /// shows them with the shipped layout.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "HOST:PORT", num_args = 0..=1, default_missing_value = DEFAULT_FOXGLOVE_ADDRESS)
    )]
    pub foxglove: Option<String>,
    /// Start a rerun viewer (the `rerun` program on PATH, e.g. from `pip
    /// install rerun-sdk`) and stream to it, as `--connect` does.
    #[cfg_attr(feature = "cli", arg(long, conflicts_with = "connect"))]
    pub spawn: bool,
    /// With a folder: a recording that has not grown for this many seconds
    /// while a later one is in the folder was left by its logger (crashed
    /// mid-file): it ends at its last whole record, with a warning.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 60.0, value_name = "S"))]
    pub abandon_s: f64,
    /// With a folder: stop once no new recording has appeared for this many
    /// seconds after the last one ended (default: wait for ever).
    #[cfg_attr(feature = "cli", arg(long, value_name = "S"))]
    pub idle_exit_s: Option<f64>,
    /// Do not print a line per recording.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

/// What `live-checkpoint.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Checkpoint {
    format: String,
    version: u32,
    /// The input followed, as given.
    input: PathBuf,
    /// The recordings finished, in order (file names).
    done: Vec<String>,
    /// The section's state after them.
    state: Option<EngineState>,
}

/// A recording the follower finished.
#[derive(Debug, Clone)]
pub struct Followed {
    pub recording: PathBuf,
    pub trains: u64,
    pub measurements: u64,
}

/// What the caller of [`live`] is told as the follow goes, and how it
/// stops it.
pub struct LiveHooks<'a> {
    /// Each recording finished.
    pub on_recording: &'a mut dyn FnMut(&Followed),
    /// Each JSON line of a train's rail band or an alert (`--json`'s
    /// lines, [`alert_line`]); `None`: printed on stdout with `--json`.
    pub on_line: Option<&'a mut dyn FnMut(&str)>,
    /// Set from another thread to stop: the follow ends as a SIGKILL would
    /// end it (the checkpoint is the last finished recording's, the day
    /// files in place stay), and [`live`] returns what was finished.
    pub stop: Option<Arc<AtomicBool>>,
}

/// Follows `args.input` (see the module documentation), telling `hooks`
/// as it goes. Returns when the input ends (a file at its end, a folder
/// after `idle_exit_s` without a new recording) or `hooks.stop` is set.
pub fn live(args: &LiveArgs, hooks: LiveHooks<'_>) -> Result<Vec<Followed>> {
    let LiveHooks {
        on_recording,
        on_line,
        stop,
    } = hooks;
    let stop = stop.unwrap_or_default();
    let mut print = |line: &str| print_line(line);
    let mut on_line: Option<&mut dyn FnMut(&str)> = match on_line {
        Some(f) => Some(f),
        None if args.json => Some(&mut print),
        None => None,
    };
    let _inputs = tortwin_outputs::files::InputScope::enter();
    let cfg = load_config(args.config.as_ref())?;
    let alerts = super::load_alerts(args.config.as_ref())?;
    let mut poster = alerts
        .post_url
        .as_deref()
        .filter(|_| alerts.enabled)
        .map(crate::alert_post::AlertPoster::start);
    let source = config_name(args.config.as_ref());
    if !(args.abandon_s.is_finite() && (0.0..=31_536_000.0).contains(&args.abandon_s)) {
        return Err(UsageError(format!(
            "--abandon-s {} is not a duration of 0 to a year in s",
            args.abandon_s
        ))
        .into());
    }
    if !(args.max_delay_s.is_finite() && (0.0..=86_400.0).contains(&args.max_delay_s)) {
        return Err(UsageError(format!(
            "--max-delay-s {} is not a delay of 0 to 86400 s",
            args.max_delay_s
        ))
        .into());
    }
    tortwin_outputs::files::make_folder(&args.out_dir)?;
    let foxglove = args
        .foxglove
        .as_deref()
        .map(|address| {
            let server = FoxgloveServer::start(address)
                .map_err(|e| UsageError(format!("--foxglove: {e}")))?;
            if !args.quiet {
                eprintln!("serving Foxglove's WebSocket protocol on {}", server.url());
            }
            Ok::<_, UsageError>(Arc::new(server))
        })
        .transpose()?;
    let viewer = match (args.spawn, &args.connect) {
        (true, _) => {
            rerun_sdk::spawn(&rerun_sdk::SpawnOptions::default()).map_err(|e| {
                UsageError(format!(
                    "--spawn: cannot start a rerun viewer ({e}); install one (pip install \
                     rerun-sdk) or give --connect URL"
                ))
            })?;
            Some(DEFAULT_VIEWER_URL.to_owned())
        }
        (false, url) => url.clone(),
    };
    let checkpoint_path = args.out_dir.join(CHECKPOINT);
    let mut checkpoint = match checkpoint_path.exists() {
        true => read_checkpoint(&checkpoint_path, &args.input)?,
        false => {
            refuse_foreign_outputs(&args.out_dir)?;
            let state = args.state_in.as_deref().map(read_state).transpose()?;
            let checkpoint = Checkpoint {
                format: CHECKPOINT_FORMAT.to_string(),
                version: CHECKPOINT_VERSION,
                input: args.input.clone(),
                done: Vec::new(),
                state,
            };
            // Before any output: a restart knows the folder is its own.
            write_checkpoint(&checkpoint_path, &checkpoint)?;
            checkpoint
        }
    };
    let folder = args.input.is_dir();
    let follow = Follow {
        max_delay: Duration::from_secs_f64(args.max_delay_s),
        stop: stop.clone(),
        ..Follow::new(Duration::from_millis(args.poll_ms.max(1)))
    };
    let provenance = Provenance::of_run(
        &args
            .config
            .as_ref()
            .and_then(super::ConfigSource::path)
            .into_iter()
            .chain(args.state_in.as_deref())
            .collect::<Vec<_>>(),
        &cfg,
    )?;
    // One recording in the viewer for the whole follow, a folder's files
    // one after the other: its id is the output folder's.
    let recording_id = format!("tortwin live {}", args.out_dir.display());
    let stream_options = |name: String| RerunOptions {
        provenance: Some(provenance.clone()),
        recording_name: Some(name),
        ..RerunOptions::default()
    };
    let stream = viewer
        .as_deref()
        .map(|url| {
            RerunSink::viewer_stream(url, &recording_id, &stream_options(file_name(&args.input)))
        })
        .transpose()?;
    let url = viewer.as_deref().unwrap_or_default();
    let mut followed = Vec::new();
    let result = (|| -> Result<()> {
        loop {
            let next = match folder {
                false if checkpoint.done.is_empty() => Some(args.input.clone()),
                false => None,
                true => next_in_folder(&args.input, checkpoint.done.last(), args, &follow, &stop)?,
            };
            let Some(recording) = next else {
                break;
            };
            let start = checkpoint.state.as_ref().map(|state| SavedState {
                state,
                name: checkpoint_path.display().to_string(),
                file: None,
            });
            let ctx = match &start {
                Some(s) => ReaderContext {
                    origin_ns: Some(s.state.origin_ns),
                    occupied_until_s: s.state.occupied_until_s.unwrap_or(f64::NEG_INFINITY),
                },
                None => ReaderContext::default(),
            };
            // A recording finished before it is reached (a folder's backlog, a
            // restart after the logger ended) is read as `replay` reads it:
            // in any order.
            // In a folder, a later recording beside one that stopped growing
            // means its logger left it (and began the next).
            let left = Arc::new(AtomicBool::new(false));
            let mut follow_this = follow.clone();
            if folder {
                let (dir, name, left) = (args.input.clone(), file_name(&recording), left.clone());
                let later = move || {
                    let later = std::fs::read_dir(&dir)
                        .into_iter()
                        .flatten()
                        .flatten()
                        .any(|e| {
                            e.file_name().to_str().is_some_and(|n| {
                                n.ends_with(".mcap") && !n.starts_with('.') && n > name.as_str()
                            })
                        });
                    left.store(later, Ordering::Relaxed);
                    later
                };
                follow_this.abandon = Some((
                    Duration::from_secs_f64(args.abandon_s),
                    Abandoned(Arc::new(later)),
                ));
            }
            let reader = match tortwin_recording::reader::looks_finished(&recording) {
                true => RecordingReader::open(&recording, ctx)?,
                false => RecordingReader::follow(&recording, ctx, follow_this)?,
            };
            let mut engine = engine_for(
                &reader,
                cfg.clone(),
                EngineOptions::default(),
                start.as_ref(),
                &source,
            )?;
            let stem = recording
                .file_stem()
                .map_or_else(|| "recording".into(), |s| s.to_string_lossy().into_owned());
            let mut mcap = McapSink::daily(
                &args.out_dir,
                &stem,
                Some(&provenance),
                reader.line().is_some(),
            );
            if let Some(server) = &foxglove {
                server
                    .advertise(reader.line().is_some())
                    .map_err(|e| UsageError(format!("--foxglove: {e}")))?;
                mcap = mcap.publishing(server.clone());
            }
            let memory = super::replay::alert_memory(&reader, start.as_ref())?;
            let mut rrd = stream
                .as_ref()
                .map(|rec| {
                    RerunSink::on_stream(rec.clone(), url, stream_options(file_name(&recording)))
                })
                .transpose()?;
            let mut lines = on_line.as_mut().map(|out| TrainLines { out: &mut **out });
            let mut fanout: Fanout<&mut dyn Sink> = Fanout::default();
            fanout.sinks.push(&mut mcap);
            if let Some(s) = rrd.as_mut() {
                fanout.sinks.push(s);
            }
            if let Some(lines) = lines.as_mut() {
                fanout.sinks.push(lines);
            }
            if let Some(p) = poster.as_mut() {
                fanout.sinks.push(p);
            }
            let mut fanout = Alerting::new(alerts.clone(), memory, fanout);
            let mut reader = reader;
            let mut trains = 0u64;
            let mut measurements = 0u64;
            let replay_error = |source| Error::Replay {
                what: recording.display().to_string(),
                source,
            };
            while let Some(step) = reader.next_followed() {
                match step? {
                    // Nothing before `t` is to come: the trains that left before
                    // it are rolled now, not at the next event.
                    ReadStep::Time(t) => engine.advance_to(t, &mut fanout).map_err(replay_error)?,
                    ReadStep::Event(event) => {
                        match event.kind {
                            tortwin_recording::EventKind::Passage(_) => trains += 1,
                            tortwin_recording::EventKind::Measurement(_) => measurements += 1,
                            _ => {}
                        }
                        engine.push(event, &mut fanout).map_err(replay_error)?;
                    }
                }
            }
            engine.finish(&mut fanout, reader.unknown_topic_messages())?;
            let memory = fanout.memory();
            drop(fanout);
            drop(mcap);
            drop(rrd);
            let mut state = engine.state();
            state.alerts = memory;
            if let Some(path) = &args.state_out {
                let text = serde_json::to_string(&state).map_err(|source| Error::Json {
                    what: "the state",
                    source,
                })?;
                tortwin_outputs::files::write_atomically(path, text.as_bytes())?;
            }
            checkpoint.done.push(file_name(&recording));
            checkpoint.state = Some(state);
            write_checkpoint(&checkpoint_path, &checkpoint)?;
            let done = Followed {
                recording,
                trains,
                measurements,
            };
            if left.load(Ordering::Relaxed) {
                eprintln!(
                    "warning: {} ended without its end record (not grown for {} s while a \
                     later recording was in the folder: its logger left it); what was written \
                     whole was stepped",
                    done.recording.display(),
                    args.abandon_s
                );
            }
            on_recording(&done);
            followed.push(done);
        }
        Ok(())
    })();
    // Stopped by the caller: what was finished (the reader's error only
    // says it was stopped).
    let result = match result {
        Err(_) if stop.load(Ordering::Relaxed) => Ok(followed),
        Err(e) => Err(e),
        Ok(()) => Ok(followed),
    };
    if let Some(rec) = stream {
        RerunSink::let_go(rec, url);
    }
    if let Some(server) = foxglove.and_then(Arc::into_inner) {
        server.stop();
    }
    result
}

fn write_checkpoint(path: &Path, checkpoint: &Checkpoint) -> Result<()> {
    let text = serde_json::to_string(checkpoint).map_err(|source| Error::Json {
        what: "the checkpoint",
        source,
    })?;
    Ok(tortwin_outputs::files::write_atomically(
        path,
        text.as_bytes(),
    )?)
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
}

/// The folder's next recording after `last` in name order, waiting for it
/// to appear; `None` after `idle_exit_s` without one.
fn next_in_folder(
    folder: &Path,
    last: Option<&String>,
    args: &LiveArgs,
    follow: &Follow,
    stop: &AtomicBool,
) -> Result<Option<PathBuf>> {
    let since = Instant::now();
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(None);
        }
        let entries = std::fs::read_dir(folder).map_err(|e| {
            InputError::file(folder, format!("cannot list the recordings' folder: {e}"))
        })?;
        let mut names: Vec<String> = entries
            .flatten()
            .filter_map(|e| e.file_name().into_string().ok())
            .filter(|n| n.ends_with(".mcap") && !n.starts_with('.'))
            .filter(|n| last.is_none_or(|last| n.as_str() > last.as_str()))
            .collect();
        names.sort();
        if let Some(name) = names.into_iter().next() {
            return Ok(Some(folder.join(name)));
        }
        if args
            .idle_exit_s
            .is_some_and(|s| since.elapsed().as_secs_f64() >= s)
        {
            return Ok(None);
        }
        std::thread::sleep(follow.poll.max(Duration::from_millis(50)));
    }
}

/// Reads the checkpoint of an earlier follower of `input`.
fn read_checkpoint(path: &Path, input: &Path) -> Result<Checkpoint> {
    // Read without registering it as an input: it is rewritten after
    // every recording (`tortwin_files::InputScope` would refuse that).
    let text = std::fs::metadata(path)
        .and_then(|m| {
            if m.len() > tortwin_outputs::files::MAX_STATE_BYTES {
                Err(std::io::Error::other(format!(
                    "{} bytes, more than a checkpoint holds",
                    m.len()
                )))
            } else {
                std::fs::read_to_string(path)
            }
        })
        .map_err(|e| InputError::file(path, format!("cannot read the checkpoint: {e}")))?;
    let checkpoint: Checkpoint = serde_json::from_str(&text)
        .map_err(|e| InputError::file(path, format!("not a tortwin live checkpoint: {e}")))?;
    if checkpoint.format != CHECKPOINT_FORMAT || checkpoint.version != CHECKPOINT_VERSION {
        return Err(InputError::file(
            path,
            format!(
                "not a tortwin live checkpoint of version {CHECKPOINT_VERSION} (format {:?}, \
                 version {})",
                checkpoint.format, checkpoint.version
            ),
        )
        .into());
    }
    if checkpoint.input != input {
        return Err(UsageError(format!(
            "{} continues a follower of {}, not of {}: use another --out-dir",
            path.display(),
            checkpoint.input.display(),
            input.display()
        ))
        .into());
    }
    Ok(checkpoint)
}

/// A first start refuses a folder that already holds MCAP files: they
/// would be taken for days already written.
fn refuse_foreign_outputs(folder: &Path) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return Ok(());
    };
    let foreign = entries
        .flatten()
        .filter_map(|e| e.file_name().into_string().ok())
        .find(|n| n.ends_with(".mcap") && !n.starts_with('.'));
    match foreign {
        Some(name) => Err(UsageError(format!(
            "--out-dir {} holds {name} but no {CHECKPOINT}: a follower starts in an empty \
             folder (or continues in its own)",
            folder.display()
        ))
        .into()),
        None => Ok(()),
    }
}

/// The lines `tortwin live` prints for a finished recording.
pub fn render_followed(f: &Followed) -> String {
    format!(
        "{}: {} trains, {} measurements stepped\n",
        f.recording.display(),
        f.trains,
        f.measurements
    )
}

/// `--json`: a line per train and rail band as its field comes out, and
/// per alert (on stdout, flushed at once, or to [`LiveHooks::on_line`]).
struct TrainLines<'a> {
    out: &'a mut dyn FnMut(&str),
}

/// An alert's line (`--json`, and the body `[alerts] post_url` is sent):
/// `{"kind": "alert", "log_time_ns", "alert": {the /twin/alert message}}`.
pub(crate) fn alert_line(alert: &Alert) -> Result<String, SinkError> {
    let message = tortwin_outputs::alerts::alert_json(alert).map_err(|field| {
        format!(
            "alert {} at log_time {} ns: evidence {field} is not a finite number",
            alert.kind.as_str(),
            alert.log_time_ns
        )
    })?;
    let line = serde_json::json!({
        "kind": "alert",
        "log_time_ns": alert.log_time_ns,
        "alert": message,
    });
    Ok(line.to_string())
}

/// Prints a line on stdout and flushes it.
fn print_line(line: &str) {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    // A reader that has gone (`| head`) is not the twin's failure.
    let _ = writeln!(out, "{line}").and_then(|()| out.flush());
}

impl Sink for TrainLines<'_> {
    fn alert(&mut self, alert: &Alert) -> SinkResult {
        (self.out)(&alert_line(alert)?);
        Ok(())
    }

    fn field(&mut self, f: &FieldSnapshot<'_>) -> SinkResult {
        if f.kind != SnapshotKind::Train {
            return Ok(());
        }
        let [lower, upper] = tortwin_outputs::scale::TARGET_BAND;
        // Each grid point stands for the track halfway to its neighbours.
        let width = |k: usize| tortwin_engine::alerts::point_width_m(&f.d_m, k);
        let (mut n, mut sum, mut min) = (0usize, 0.0, f64::INFINITY);
        let (mut below_m, mut above_m) = (0.0, 0.0);
        for (k, &mu) in f.mu.iter().enumerate().filter(|(_, mu)| mu.is_finite()) {
            n += 1;
            sum += mu;
            min = min.min(mu);
            if mu < lower {
                below_m += width(k);
            } else if mu > upper {
                above_m += width(k);
            }
        }
        let line = serde_json::json!({
            "kind": "train",
            "train_id": f.train_id,
            "log_time_ns": f.log_time_ns,
            "rail": f.rail_name,
            "band": f.band,
            "wheel_pass": f.wheel_pass,
            "mu_min": (n > 0).then_some(min),
            "mu_mean": (n > 0).then(|| sum / n as f64),
            "below_band_m": below_m,
            "above_band_m": above_m,
        });
        (self.out)(&line.to_string());
        Ok(())
    }
}
