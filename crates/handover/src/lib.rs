//! The one batched hand-over between two threads, used by the recording
//! reader's read-ahead (events to the engine), the sink thread (the
//! engine's calls to the output files) and the MCAP writer thread
//! (serialized messages to zstd and the file).
//!
//! Items cross in batches, not one by one: a hand-over wakes the other
//! thread, and a wake-up per item cost the engine's thread a tenth of its
//! time (the MCAP writer, measured). At most `queue` batches wait in the
//! channel, so the memory in flight is bounded whatever the recording's
//! length. The receiving side gives each batch back emptied
//! ([`Batch::clear`]) and the sending side fills it again: the steady state
//! allocates nothing. Either side may stop: the other sees it at its next
//! hand-over ([`Gone`]) or when the batches end.
//!
//! Beside it, [`pool`]: the command line's thread pool, joined where a
//! replay first wants it.

pub mod pool;

use std::sync::mpsc::{sync_channel, Receiver, SyncSender};

/// The nice value a thread behind the engine ([`behind_the_engine`])
/// takes where Linux refuses it the idle policy: the highest, 19 (a weight
/// of 15 against a normal thread's 1024).
pub const BEHIND_NICE: i32 = 19;

/// Marks the calling thread as one that feeds or drains the engine (the
/// recording's read-ahead, the sink thread, the MCAP writer): on Linux it
/// takes the scheduling policy `SCHED_IDLE` (or, where that is refused,
/// the nice value [`BEHIND_NICE`]), so that while the engine's stepping
/// threads want both cores they keep them, and this thread runs in the
/// time they leave (while the engine settles a train, emits, or waits for
/// it). It cannot stall the engine: the hand-over is bounded, so an engine
/// that runs ahead of this thread blocks on it, and the core is this
/// thread's again.
///
/// Why the idle policy rather than only the nice value: a core that runs
/// nothing but idle-policy threads counts as free when the scheduler
/// places a thread that wakes, a core running a thread at nice 19 does not.
/// The engine wakes a rayon worker for a train's second rail; at nice 19
/// that worker was queued behind the engine on the engine's own core (for
/// 2-3 ms, longer than the rail takes) while the helper held the other
/// core, and the engine's thread rolled both rails itself (`perf sched`, the
/// 3-day curve benchmark: the worker ran 7 ms against the engine's 74;
/// with the idle policy 23 against 63, and the run took 4 % less time).
/// Measured before that on 8 days of the example line with MCAP out:
/// without either, the engine's thread waited, runnable, a sixth of the
/// replay for a core these threads held.
///
/// The price: such a thread yields to every thread of normal priority in
/// its scheduling group (on a desktop, the terminal session's processes),
/// not only to its engine, so beside other busy work the replay's reading
/// and writing wait for it. A batch replay's threads are put behind; a
/// live twin's (`tortwin live`, which must keep up with the recording as
/// it is written) are not, nor the MCAP writer of a long replay and the
/// thread that feeds it, whose work weighs as much as the engine's
/// (`McapCompression::runs_behind_the_engine` in tortwin-outputs).
///
/// Linux keeps the policy and the nice value per thread, so only the
/// calling thread changes; neither can be undone without privileges, so
/// call it on a thread of your own only. Elsewhere, and where the calls
/// fail, nothing changes (the order of the work does not depend on it).
pub fn behind_the_engine() {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: sched_setscheduler reads the parameter it is given (a
        // plain struct that lives through the call); pid 0 is the calling
        // thread. gettid and setpriority take and return plain integers;
        // PRIO_PROCESS with a thread id acts on that thread only (Linux).
        unsafe {
            let param = libc::sched_param { sched_priority: 0 };
            if libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) != 0 {
                let tid = libc::gettid() as libc::id_t;
                libc::setpriority(libc::PRIO_PROCESS, tid, BEHIND_NICE);
            }
        }
    }
}

/// What crosses: a container that can be emptied for reuse.
pub trait Batch: Send + 'static {
    /// A new, empty batch (the first few, and when none came back yet).
    fn fresh() -> Self;
    /// Whether it holds nothing (an empty batch is never handed over).
    fn is_empty(&self) -> bool;
    /// Empties it, keeping its memory.
    fn clear(&mut self);
}

impl<T: Send + 'static> Batch for Vec<T> {
    fn fresh() -> Self {
        Vec::new()
    }
    fn is_empty(&self) -> bool {
        Vec::is_empty(self)
    }
    fn clear(&mut self) {
        Vec::clear(self);
    }
}

/// The receiving side has stopped (its thread ended, on an error or a
/// panic, or it was dropped): nothing more can be handed over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Gone;

/// A bounded hand-over of batches of type `B`: at most `queue` batches
/// wait in it, at most `queue + 2` come back for reuse.
pub fn channel<B: Batch>(queue: usize) -> (Filler<B>, Taker<B>) {
    let (to, from) = sync_channel::<B>(queue);
    let (give_back, spare) = sync_channel::<B>(queue + 2);
    (
        Filler {
            to: Some(to),
            spare,
            filling: B::fresh(),
        },
        Taker { from, give_back },
    )
}

/// The sending side: fills a batch ([`Filler::batch`]) and hands it over.
pub struct Filler<B: Batch> {
    to: Option<SyncSender<B>>,
    spare: Receiver<B>,
    filling: B,
}

impl<B: Batch> Filler<B> {
    /// The batch being filled.
    pub fn batch(&mut self) -> &mut B {
        &mut self.filling
    }

    /// Hands the batch being filled over (nothing if it is empty; waits
    /// while `queue` batches are waiting) and starts filling one that came
    /// back, or a fresh one. [`Gone`] if the receiving side has stopped or
    /// this side was closed.
    pub fn hand_over(&mut self) -> Result<(), Gone> {
        if self.filling.is_empty() {
            return if self.to.is_some() { Ok(()) } else { Err(Gone) };
        }
        let to = self.to.as_ref().ok_or(Gone)?;
        let next = self.spare.try_recv().unwrap_or_else(|_| B::fresh());
        let full = std::mem::replace(&mut self.filling, next);
        to.send(full).map_err(|_| Gone)
    }

    /// Ends the hand-over: the receiving side's [`Taker::take`] returns
    /// `None` once it has taken what was handed over before. What is being
    /// filled and not handed over is dropped.
    pub fn close(&mut self) {
        self.to = None;
        self.filling.clear();
    }

    /// Whether [`Filler::close`] was called.
    pub fn is_closed(&self) -> bool {
        self.to.is_none()
    }
}

/// The receiving side: takes the batches in the order they were handed
/// over and gives them back emptied.
pub struct Taker<B: Batch> {
    from: Receiver<B>,
    give_back: SyncSender<B>,
}

impl<B: Batch> Taker<B> {
    /// The next batch (waits for it); `None` once the sending side is
    /// closed or dropped and every batch it handed over was taken.
    pub fn take(&self) -> Option<B> {
        self.from.recv().ok()
    }

    /// Gives a batch back for reuse, emptied (dropped if the sending side
    /// has stopped taking them back).
    pub fn give_back(&self, mut batch: B) {
        batch.clear();
        let _ = self.give_back.try_send(batch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The calling thread's scheduling policy.
    #[cfg(target_os = "linux")]
    fn policy_of_this_thread() -> i32 {
        // SAFETY: plain integers in and out; pid 0 is the calling thread.
        unsafe { libc::sched_getscheduler(0) }
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_thread_behind_the_engine_yields_and_the_others_do_not() {
        let before = policy_of_this_thread();
        assert_ne!(before, libc::SCHED_IDLE);
        let behind = std::thread::spawn(|| {
            behind_the_engine();
            policy_of_this_thread()
        })
        .join()
        .expect("the thread");
        assert_eq!(behind, libc::SCHED_IDLE);
        // Only the thread that asked: not the process, not its spawner.
        assert_eq!(policy_of_this_thread(), before);
        let sibling = std::thread::spawn(policy_of_this_thread).join();
        assert_eq!(sibling.expect("the thread"), before);
    }

    #[test]
    fn batches_arrive_in_order_and_come_back_for_reuse() {
        let (mut filler, taker) = channel::<Vec<u32>>(2);
        let received = std::thread::scope(|s| {
            let t = s.spawn(move || {
                let mut got = Vec::new();
                while let Some(batch) = taker.take() {
                    got.extend_from_slice(&batch);
                    taker.give_back(batch);
                }
                got
            });
            let mut reused = 0;
            for i in 0..1000u32 {
                filler.batch().push(i);
                if filler.batch().len() == 10 {
                    filler.hand_over().unwrap();
                    reused += usize::from(filler.batch().capacity() >= 10);
                }
            }
            filler.hand_over().unwrap();
            filler.close();
            let got = t.join().unwrap();
            assert!(reused > 0, "no batch came back for reuse");
            got
        });
        assert_eq!(received, (0..1000).collect::<Vec<_>>());
    }

    #[test]
    fn an_empty_batch_is_not_handed_over() {
        let (mut filler, taker) = channel::<Vec<u8>>(1);
        filler.hand_over().unwrap();
        filler.batch().push(7);
        filler.hand_over().unwrap();
        filler.close();
        assert_eq!(taker.take(), Some(vec![7]));
        assert_eq!(taker.take(), None);
    }

    #[test]
    fn a_stopped_receiver_is_seen_at_the_next_hand_over() {
        let (mut filler, taker) = channel::<Vec<u8>>(1);
        drop(taker);
        filler.batch().push(1);
        assert_eq!(filler.hand_over(), Err(Gone));
    }

    #[test]
    fn a_closed_filler_hands_nothing_over() {
        let (mut filler, _taker) = channel::<Vec<u8>>(1);
        filler.close();
        assert!(filler.is_closed());
        filler.batch().push(1);
        assert_eq!(filler.hand_over(), Err(Gone));
    }
}
