//! The command line's thread pool, joined where a replay first wants it.
//!
//! The command line makes its main thread one of the threads of rayon's
//! global pool (`tortwin_jobs::join_rayon_pool`): the engine runs there and
//! takes a share of a train's tracks itself. Making the pool starts its
//! workers and waits until each has started, and a replay of a short
//! recording with output files rolls its tracks in parallel only for long
//! trains (the output threads take the second core): on the 3-day curve,
//! which has none, the pool's start was 0.2-1.3 ms of the replay's 60, and
//! the replay ran 1-3 % faster without it (median pair ratios of rounds of
//! 30-40 interleaved runs: 0.974, 0.974, 0.985 with the start left out;
//! 0.999 and 0.986 deferred as here). So a
//! replay defers the start ([`defer_pool_start`]) to the first place that
//! would use the pool ([`before_pool_use`]): the tracks' parallel roll,
//! the layout pass's scans of a recording laid out before the replay.

use std::sync::{Once, OnceLock};
use std::thread::ThreadId;

/// The deferred start and the thread that deferred it.
static DEFERRED: OnceLock<(ThreadId, fn())> = OnceLock::new();
static STARTED: Once = Once::new();

/// Defers `start` (which makes the calling thread one of the threads of
/// rayon's global pool) to the first [`before_pool_use`] on this thread.
/// Only the first deferral counts.
pub fn defer_pool_start(start: fn()) {
    let _ = DEFERRED.set((std::thread::current().id(), start));
}

/// Runs the deferred start once, on the thread that deferred it; call it
/// before a use of rayon's global pool. On any other thread, or with
/// nothing deferred, it does nothing (rayon then makes its default pool on
/// first use, as for any user of the library).
pub fn before_pool_use() {
    if let Some((thread, start)) = DEFERRED.get() {
        if *thread == std::thread::current().id() {
            STARTED.call_once(*start);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    static STARTS: AtomicUsize = AtomicUsize::new(0);

    fn count_start() {
        STARTS.fetch_add(1, Ordering::SeqCst);
    }

    /// The start runs once, on the deferring thread only, and only when
    /// a use comes (one test: the deferral is process-wide).
    #[test]
    fn the_start_runs_once_on_the_deferring_thread() {
        defer_pool_start(count_start);
        assert_eq!(STARTS.load(Ordering::SeqCst), 0, "deferred, not run");
        std::thread::spawn(before_pool_use).join().unwrap();
        assert_eq!(STARTS.load(Ordering::SeqCst), 0, "not on another thread");
        before_pool_use();
        before_pool_use();
        assert_eq!(STARTS.load(Ordering::SeqCst), 1);
    }
}
