//! Progress of a long job, for whoever shows it (the binary's bar or stage
//! lines, a notebook, nothing). The jobs never print.

use crate::{Error, Result};

/// Receives a long job's progress. Every method defaults to doing nothing.
pub trait Progress: Sync {
    /// A new stage whose length is not known ("reading demo_day.mcap").
    fn stage(&self, _message: &str) {}
    /// A new stage of `total` units ("replaying demo_day.mcap", 6035
    /// messages; "step 1: fitting 12 candidates", 12 fits): a display can
    /// show a bar and an estimate of the time left.
    fn stage_of(&self, message: &str, _total: u64) {
        self.stage(message);
    }
    /// `done` units of the current stage finished so far.
    fn done(&self, _done: u64) {}
    /// Whoever shows the progress wants the job stopped (Ctrl-C in a
    /// notebook): the job ends with [`Error::Cancelled`] at its next check,
    /// leaving no output under its final name.
    fn cancelled(&self) -> bool {
        false
    }
}

/// [`Error::Cancelled`] if `progress` asks the job to stop.
pub fn check(progress: &dyn Progress) -> Result<()> {
    if progress.cancelled() {
        Err(Error::Cancelled)
    } else {
        Ok(())
    }
}

/// No display.
pub struct Silent;

impl Progress for Silent {}
