//! Progress of a long job, for whoever shows it (the binary's spinner, a
//! notebook, nothing). The jobs never print.

/// Receives a long job's progress. Both methods default to doing nothing.
pub trait Progress: Sync {
    /// A new stage ("reading demo_day.mcap", "step 1: fitting 6 candidates").
    fn stage(&self, _message: &str) {}
    /// `done` units of work finished so far (engine runs, strategies).
    fn done(&self, _done: usize) {}
}

/// No display.
pub struct Silent;

impl Progress for Silent {}
