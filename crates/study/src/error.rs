//! Why a study or a job stopped.
//!
//! The errors of the crates below pass through unchanged (their messages
//! name the file, the topic and log_time, the key), and what a study adds
//! says what it was doing ("replaying demo_day.mcap", "discover on ...").
//! [`Error::is_input`] tells bad input (exit status 2 of the command line,
//! docs/spec/interfaces.md) from everything else, so that a caller
//! classifies an error without walking its sources.

use std::path::PathBuf;

use tortwin_engine::EngineError;
use tortwin_files::usage::UsageError;
use tortwin_model::error::ConfigError;
use tortwin_outputs::files::FileError;
use tortwin_outputs::mcap_out::McapError;
use tortwin_outputs::rerun_out::RerunError;
use tortwin_outputs::tables::TableError;
use tortwin_plot::PlotError;
use tortwin_recording::error::{ConvertError, InputError, WriteError};

/// What the studies and jobs return.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A study or job that could not finish.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A recording or state file that breaks its format.
    #[error(transparent)]
    Input(#[from] InputError),
    /// A model configuration that cannot be used.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A request that asks for something impossible.
    #[error(transparent)]
    Usage(#[from] UsageError),
    /// The engine stopped (bad input met during the run, or a sink failed).
    #[error(transparent)]
    Engine(#[from] EngineError),
    /// The engine stopped while replaying `what` (a recording's path, "the
    /// traffic of ..."): the context a long run needs to be found again.
    #[error("replaying {what}")]
    Replay {
        what: String,
        #[source]
        source: EngineError,
    },
    /// An output file (state, key, report) could not be written.
    #[error(transparent)]
    File(#[from] FileError),
    #[error(transparent)]
    Mcap(#[from] McapError),
    #[error(transparent)]
    Rerun(#[from] RerunError),
    #[error(transparent)]
    Plot(#[from] PlotError),
    #[error(transparent)]
    Table(#[from] TableError),
    /// Tables that could not become a recording, a recording's inputs not
    /// written as tables, a recording not cut into days or days not merged.
    #[error(transparent)]
    Convert(#[from] ConvertError),
    /// A synthetic recording could not be written: `what` of `path`.
    #[error("{what} {}", path.display())]
    Recording {
        what: &'static str,
        path: PathBuf,
        #[source]
        source: WriteError,
    },
    /// The file system refused `what` ("cannot create", "removing", ...) on
    /// `path`.
    #[error("{what} {}", path.display())]
    Io {
        what: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// `what` (a report, a key, a state) could not be made JSON.
    #[error("serializing {what}")]
    Json {
        what: &'static str,
        #[source]
        source: serde_json::Error,
    },
    #[error("cannot start the worker threads")]
    Threads(#[source] rayon::ThreadPoolBuildError),
    /// The optimiser (argmin) refused its setup; a failure of the engine
    /// inside an objective is that error, not this one.
    #[error("the optimiser failed")]
    Optimiser(#[source] Box<dyn std::error::Error + Send + Sync + 'static>),
    /// A fit whose every point failed: nothing to report.
    #[error("a fit evaluated no point")]
    NoFitPoint,
    /// The engine gave a measurement no finite value (a configuration under
    /// which friction is undefined there).
    #[error(
        "{}: the engine gave no finite simulated value for the measurement at log_time \
         {log_time_ns} ns{}",
        .file.display(),
        .index_in_file.map_or(String::new(), |i| format!(" (message index {i})"))
    )]
    NotSimulated {
        file: PathBuf,
        log_time_ns: u64,
        index_in_file: Option<u64>,
    },
    /// A synthetic measurement a recording cannot hold (a truth model whose
    /// friction is infinite there, or outside the format's range).
    #[error(
        "{}: the {quantity} measurement at log_time {log_time_ns} ns is {value}, which a \
         recording cannot hold (JSON has no infinity, and a measurement lies within -10 and 10: \
         the truth model drives friction out of any physical range there)",
        .file.display()
    )]
    NotFinite {
        file: PathBuf,
        quantity: &'static str,
        log_time_ns: u64,
        value: f64,
    },
    /// A study's own bookkeeping does not add up (a plan without the train
    /// it counts, a scenario without the pass it was asked for): a bug, not
    /// the input.
    #[error("{0}")]
    Inconsistent(String),
    /// Whoever shows the progress asked the job to stop.
    #[error("interrupted")]
    Cancelled,
    /// `what` the study was doing when `source` stopped it.
    #[error("{what}")]
    Context {
        what: String,
        #[source]
        source: Box<Error>,
    },
}

impl Error {
    /// Whether the user's input is at fault: a recording or state that
    /// breaks its format, a configuration, an impossible request (an output
    /// folder that cannot be made is one), bad input met by the engine, or
    /// an output the machine refuses (a full disk, a read-only folder).
    /// The command line exits with status 2 for these, 1 otherwise.
    pub fn is_input(&self) -> bool {
        match self {
            Error::Input(_) | Error::Config(_) | Error::Usage(_) => true,
            Error::Engine(e) | Error::Replay { source: e, .. } => e.is_input(),
            Error::File(e) => e.is_input(),
            Error::Mcap(e) => e.is_input(),
            Error::Rerun(e) => e.is_input(),
            Error::Plot(e) => e.is_input(),
            Error::Table(TableError::File(e)) => e.is_input(),
            Error::Convert(ConvertError::Input(_)) => true,
            Error::Convert(ConvertError::File(e)) => e.is_input(),
            Error::Context { source, .. } => source.is_input(),
            // The truth model asked for (`--hidden`, `--truth-config`)
            // drives friction where no recording can hold it.
            Error::NotFinite { .. } => true,
            // Outputs (and inputs) the machine refuses: a full disk, a
            // read-only folder, a missing file.
            Error::Table(_) | Error::Convert(_) | Error::Recording { .. } | Error::Io { .. } => {
                tortwin_files::usage::caused_by_environment(self)
            }
            Error::Json { .. }
            | Error::Threads(_)
            | Error::Optimiser(_)
            | Error::NoFitPoint
            | Error::NotSimulated { .. }
            | Error::Inconsistent(_)
            | Error::Cancelled => false,
        }
    }

    /// The message the command line prints after "error: ": every cause,
    /// outer first, joined by ": " (anyhow's `{:#}`).
    pub fn full_message(&self) -> String {
        let mut text = self.to_string();
        let mut source = std::error::Error::source(self);
        while let Some(cause) = source {
            text.push_str(": ");
            text.push_str(&cause.to_string());
            source = cause.source();
        }
        text
    }

    /// `self` as the cause of `what` the caller was doing.
    pub fn context(self, what: impl Into<String>) -> Error {
        Error::Context {
            what: what.into(),
            source: Box::new(self),
        }
    }
}

/// Wraps an optimiser's error (argmin's is an `anyhow::Error`).
pub fn optimiser(e: argmin::core::Error) -> Error {
    Error::Optimiser(e.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn usage() -> UsageError {
        UsageError("impossible".into())
    }

    fn folder() -> FileError {
        FileError::Folder {
            folder: "out".into(),
            source: usage(),
        }
    }

    /// What the binary's exit status rests on: bad input is found under the
    /// context a study adds, in an output folder that cannot be made, and
    /// in a sink's error; the machine's failures are not bad input.
    #[test]
    fn bad_input_is_found_wherever_it_is_wrapped() {
        assert!(Error::from(usage())
            .context("discover on a.mcap")
            .is_input());
        assert!(Error::from(folder()).is_input());
        assert!(Error::from(McapError::File(folder())).is_input());
        assert!(Error::from(RerunError::File(folder())).is_input());
        assert!(Error::from(PlotError::File(folder())).is_input());
        let in_sink = EngineError::Sink(Box::new(McapError::File(folder())));
        assert!(Error::Replay {
            what: "a.mcap".into(),
            source: in_sink,
        }
        .is_input());

        let disk_full = EngineError::Sink(Box::new(std::io::Error::other("disk full")));
        assert!(!Error::from(disk_full).is_input());
        assert!(!Error::NoFitPoint.context("discover on a.mcap").is_input());
    }

    /// A context reads like anyhow's: what was being done, then the cause.
    #[test]
    fn a_context_comes_before_its_cause() {
        let e = Error::from(usage()).context("discover on a.mcap");
        assert_eq!(e.to_string(), "discover on a.mcap");
        let cause = std::error::Error::source(&e).map(ToString::to_string);
        assert_eq!(cause.as_deref(), Some("impossible"));
    }
}
