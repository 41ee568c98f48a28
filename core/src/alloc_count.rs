//! A counting global allocator for allocation tests ("zero allocations per message" and the
//! like). A test binary installs it with
//! `#[global_allocator] static GLOBAL: CountingAlloc = CountingAlloc;` and reads
//! [`CountingAlloc::total`] (every thread) or [`allocations_in`] (the calling thread only)
//! around the code under test. Each allocating call (`alloc`, `alloc_zeroed`, `realloc`)
//! counts once; frees are not counted.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Allocations by every thread.
static TOTAL: AtomicU64 = AtomicU64::new(0);

thread_local! {
    /// Allocations by this thread (const-initialised and without a destructor, so reading it
    /// never allocates and works during thread teardown).
    static MINE: Cell<u64> = const { Cell::new(0) };
}

/// The system allocator, counting allocating calls.
pub struct CountingAlloc;

impl CountingAlloc {
    /// Allocating calls by every thread so far.
    pub fn total() -> u64 {
        TOTAL.load(Relaxed)
    }

    /// Allocating calls by the calling thread so far.
    pub fn this_thread() -> u64 {
        MINE.with(Cell::get)
    }
}

/// Allocating calls `f` makes on the calling thread (the counting allocator must be installed).
pub fn allocations_in(f: impl FnOnce()) -> u64 {
    let before = CountingAlloc::this_thread();
    f();
    CountingAlloc::this_thread() - before
}

fn count() {
    TOTAL.fetch_add(1, Relaxed);
    MINE.with(|m| m.set(m.get() + 1));
}

// SAFETY: every call forwards to the system allocator with the caller's arguments unchanged;
// the only addition is counter increments, which neither allocate nor panic.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: forwarded unchanged (see above).
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: forwarded unchanged.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: forwarded unchanged.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
