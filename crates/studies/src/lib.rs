//! The studies tortwin runs on top of the engine, and the jobs the `tortwin`
//! commands are made of.
//!
//! - [`jobs`]: each command as a library function: options in, files and a
//!   result out (replay, paper, synth, discover, strategy). The binary only
//!   parses the command line, shows progress and maps errors to exit codes.
//! - [`discover`]: the discrepancy workflow: residuals, covariates, candidate
//!   effects (named and generic terms) fitted by re-running the engine,
//!   forward selection.
//! - [`strategy`]: application strategies evaluated over a section's traffic.
//! - [`synth`]: synthetic recordings whose measurements come from the engine
//!   run with a truth model (hidden effects), plus noise.
//! - [`paper`]: the paper's scenarios (wayside and on-board application).
//! - [`Progress`]: how a long job reports progress to whoever shows it.
//! - [`Error`]: why a study or job stopped, and whether the input is at
//!   fault ([`Error::is_input`]).

#![warn(unreachable_pub)]

pub mod discover;
mod error;
pub mod jobs;
pub mod paper;
mod progress;
pub mod strategy;
pub mod synth;

pub use error::{Error, Result};
pub use progress::{Progress, Silent};
