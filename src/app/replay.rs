//! `tortwin replay`: a recording in, the friction field out.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

use crate::config::ModelConfig;
use crate::engine::{Engine, EngineOptions, EngineState};
use crate::error::{InputError, UsageError};
use crate::recording::reader::ReaderContext;
use crate::recording::RecordingReader;
use crate::sink::mcap_out::McapSink;
use crate::sink::rerun_out::{RerunOptions, RerunSink};
use crate::sink::{Fanout, RunSummary, Sink};

#[derive(Debug, Clone, clap::Args)]
pub struct ReplayArgs {
    /// The recording (MCAP). Default: the bundled demo recording.
    #[arg(default_value = super::DEFAULT_RECORDING)]
    pub recording: PathBuf,
    /// Model configuration overlaid on the built-in defaults (TOML).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Write the MCAP output here (Foxglove-readable).
    #[arg(long)]
    pub out_mcap: Option<PathBuf>,
    /// Write the rerun recording here (open with `rerun FILE.rrd`).
    #[arg(long)]
    pub out_rrd: Option<PathBuf>,
    /// Start from the state an earlier replay wrote with --state-out.
    #[arg(long)]
    pub state_in: Option<PathBuf>,
    /// Write the section's state at the end, for the next recording.
    #[arg(long)]
    pub state_out: Option<PathBuf>,
    /// Snapshot the field after every wheel pass in the rerun recording
    /// (default: after every train).
    #[arg(long)]
    pub every_wheel: bool,
    /// Do not print the summary.
    #[arg(long, short)]
    pub quiet: bool,
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
            quiet: true,
        }
    }
}

pub fn main(args: ReplayArgs) -> Result<()> {
    let summary = replay(&args, &mut [])?;
    if !args.quiet {
        print!("{}", super::summary::render(&args.recording, &summary));
        for (what, path) in [
            ("rerun recording", &args.out_rrd),
            ("MCAP output", &args.out_mcap),
        ] {
            if let Some(path) = path {
                println!("{what}: {}", path.display());
            }
        }
        if let Some(path) = &args.out_rrd {
            println!(
                "open it with: pip install rerun-sdk==0.36.3 && rerun {}",
                path.display()
            );
        }
        if let Some(path) = &args.out_mcap {
            println!(
                "or open {} in Foxglove (https://app.foxglove.dev, Open local file)",
                path.display()
            );
        }
    }
    Ok(())
}

/// Loads the model configuration: the defaults, overlaid by `path`.
pub fn load_config(path: Option<&Path>) -> Result<ModelConfig> {
    Ok(match path {
        Some(p) => ModelConfig::from_file(p)?,
        None => ModelConfig::default(),
    })
}

/// Reads a state written by `--state-out`.
pub fn read_state(path: &Path) -> Result<EngineState> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| InputError::file(path, format!("cannot read the state: {e}")))?;
    let state: EngineState = serde_json::from_str(&text)
        .map_err(|e| InputError::file(path, format!("not a tortwin state: {e}")))?;
    Ok(state)
}

/// Replays `args.recording` through the engine into the outputs the
/// arguments ask for, plus `extra` sinks. Returns the run's summary.
pub fn replay(args: &ReplayArgs, extra: &mut [&mut dyn Sink]) -> Result<RunSummary> {
    let cfg = load_config(args.config.as_deref())?;
    for (a, b) in [
        (&args.out_mcap, &args.out_rrd),
        (&args.state_out, &args.out_mcap),
        (&args.state_out, &args.out_rrd),
    ] {
        if let (Some(a), Some(b)) = (a, b) {
            if a == b {
                return Err(
                    UsageError(format!("two outputs would be written to {}", a.display())).into(),
                );
            }
        }
    }
    let saved = args.state_in.as_deref().map(read_state).transpose()?;
    let ctx = match &saved {
        Some(s) => ReaderContext {
            origin_ns: Some(s.origin_ns),
            occupied_until_s: s.occupied_until_s.unwrap_or(f64::NEG_INFINITY),
        },
        None => ReaderContext::default(),
    };
    let mut reader = RecordingReader::open(&args.recording, ctx)?;
    let opts = EngineOptions {
        snapshot_every_wheel: args.every_wheel,
        ..EngineOptions::default()
    };
    let section = reader.section().clone();
    let source = args.config.as_deref().map_or_else(
        || "built-in defaults".to_string(),
        |p| p.display().to_string(),
    );
    crate::config::check_terms_against(&cfg.effects.generic, &section, &source)?;
    let mut engine = match (&saved, &args.state_in) {
        (Some(s), Some(path)) => Engine::from_state(section, cfg, opts, s)
            .map_err(|e| InputError::file(path, e.to_string()))?,
        _ => Engine::new(section, cfg, opts, reader.origin_ns()),
    };

    let mut mcap = args.out_mcap.as_deref().map(McapSink::create).transpose()?;
    let mut rrd = args
        .out_rrd
        .as_deref()
        .map(|p| RerunSink::create(p, RerunOptions::default()))
        .transpose()?;
    let mut fanout = Fanout::default();
    if let Some(s) = mcap.as_mut() {
        fanout.sinks.push(s);
    }
    if let Some(s) = rrd.as_mut() {
        fanout.sinks.push(s);
    }
    for s in extra.iter_mut() {
        fanout.sinks.push(&mut **s);
    }

    let progress = ProgressBar::new_spinner();
    progress.set_style(
        ProgressStyle::with_template("{spinner} {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    let mut events = 0u64;
    for event in reader.by_ref() {
        let event = event?;
        events += 1;
        if events.is_multiple_of(4096) {
            progress.set_message(format!(
                "{events} events, {}",
                crate::app::summary::utc(event.log_time_ns)
            ));
            progress.tick();
        }
        engine
            .push(event, &mut fanout)
            .with_context(|| format!("replaying {}", args.recording.display()))?;
    }
    let summary = engine.finish(&mut fanout, reader.unknown_topic_messages())?;
    progress.finish_and_clear();

    if let Some(path) = &args.state_out {
        let text = serde_json::to_string(&engine.state()).context("cannot serialize the state")?;
        super::write_atomically(path, text.as_bytes())?;
    }
    Ok(summary)
}
