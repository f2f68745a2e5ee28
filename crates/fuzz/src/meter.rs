//! The allocation meter: a global allocator (installed by the
//! `tortwin-fuzz` binary) that remembers the largest single request and the
//! peak of live bytes, so that a mutant which makes tortwin allocate far
//! more than its size is a finding even on a machine with memory to spare.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A single allocation above this is a finding: tortwin's inputs never
/// need one (a chunk is at most 256 MiB uncompressed and is the largest
/// buffer a replay holds).
pub const FINDING_BYTES: usize = 300 << 20;

/// Requests above this are refused (the process aborts with "memory
/// allocation of N bytes failed" and the campaign saves the input): the
/// fuzzer must not take the machine down either.
pub const REFUSE_BYTES: usize = 2 << 30;

static LARGEST: AtomicUsize = AtomicUsize::new(0);
static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

/// [`System`] with the counters above.
pub struct Meter;

impl Meter {
    fn note(size: usize) -> bool {
        LARGEST.fetch_max(size, Ordering::Relaxed);
        let live = LIVE.fetch_add(size, Ordering::Relaxed) + size;
        PEAK.fetch_max(live, Ordering::Relaxed);
        size <= REFUSE_BYTES
    }

    /// Counts a request of `size` bytes and makes it with `make`, or refuses
    /// it; takes the count back if nothing was made.
    fn counted(size: usize, make: impl FnOnce() -> *mut u8) -> *mut u8 {
        let p = if Self::note(size) {
            make()
        } else {
            std::ptr::null_mut()
        };
        if p.is_null() {
            LIVE.fetch_sub(size, Ordering::Relaxed);
        }
        p
    }
}

// SAFETY: every call is passed to `System` unchanged, or refused with a
// null pointer (which `GlobalAlloc` allows).
unsafe impl GlobalAlloc for Meter {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        Self::counted(layout.size(), || unsafe { System.alloc(layout) })
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        Self::counted(layout.size(), || unsafe { System.alloc_zeroed(layout) })
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = Self::counted(new_size, || unsafe {
            System.realloc(ptr, layout, new_size)
        });
        if !p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        }
        p
    }
}

/// What the meter saw since the last [`reset`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Reading {
    /// The largest single request, bytes.
    pub largest: usize,
    /// The peak of live bytes above the level at the reset.
    pub peak_above_start: usize,
}

/// Starts a measurement; returns the live bytes now.
pub fn reset() -> usize {
    LARGEST.store(0, Ordering::Relaxed);
    let live = LIVE.load(Ordering::Relaxed);
    PEAK.store(live, Ordering::Relaxed);
    live
}

/// What happened since [`reset`] returned `start`. Without the meter
/// installed (the tests), everything reads 0.
pub fn read(start: usize) -> Reading {
    Reading {
        largest: LARGEST.load(Ordering::Relaxed),
        peak_above_start: PEAK.load(Ordering::Relaxed).saturating_sub(start),
    }
}
