//! A counting global allocator that reports heap allocations made on the RT thread.
//!
//! What this module **is**: a thin wrapper around the system allocator. Counting is off unless the
//! RT thread calls [`set_counting`]`(true)` (it does so after READY when the env var
//! `FRICTIOND_ALLOC_REPORT` names a report file). Allocations inside an [`exempt`] scope (iceoryx2
//! 0.10's one 48-byte `Box` per published sample, see `docs/realtime.md` §2.6) are counted
//! separately so the report shows both numbers.
//!
//! What it is **not**: not a profiler; no stack traces; the cost when not counting is one
//! thread-local read per allocation.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

/// The wrapper allocator.
pub struct CountingAlloc;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static EXEMPT: Cell<bool> = const { Cell::new(false) };
}

static COUNTED: AtomicU64 = AtomicU64::new(0);
static EXEMPTED: AtomicU64 = AtomicU64::new(0);

#[inline]
fn note() {
    // `try_with`: during thread teardown the TLS may be gone; then nothing is counted.
    let counting = COUNTING.try_with(Cell::get).unwrap_or(false);
    if counting {
        if EXEMPT.try_with(Cell::get).unwrap_or(false) {
            EXEMPTED.fetch_add(1, Ordering::Relaxed);
        } else {
            COUNTED.fetch_add(1, Ordering::Relaxed);
        }
    }
}

// SAFETY: forwards every call unchanged to `System`; only counts.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Turns counting on/off for the calling thread.
pub fn set_counting(on: bool) {
    COUNTING.with(|c| c.set(on));
}

/// Whether counting is on for the calling thread.
pub fn counting() -> bool {
    COUNTING.try_with(Cell::get).unwrap_or(false)
}

/// Runs `f` with its allocations counted as exempt.
#[inline]
pub fn exempt<R>(f: impl FnOnce() -> R) -> R {
    EXEMPT.with(|c| c.set(true));
    let r = f();
    EXEMPT.with(|c| c.set(false));
    r
}

/// (counted, exempt) allocations so far.
pub fn totals() -> (u64, u64) {
    (
        COUNTED.load(Ordering::Relaxed),
        EXEMPTED.load(Ordering::Relaxed),
    )
}
