//! Appending rows between chunk writes allocates nothing: rows go into buffers sized at
//! construction. Counted with a global allocator, in a test binary of its own.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{ContactRow, RecordingWriter, Streams, TruthContact, WriterOptions};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards every call to the system allocator unchanged; only counts allocations.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn appends_between_chunk_writes_do_not_allocate() {
    let dir = std::env::temp_dir().join(format!("skinflow-record-alloc-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams {
        truth: true,
        image_hw: Some([8, 8]),
        contacts: true,
        force_strategies: vec!["pneumatic-locaware".into()],
        ..Streams::default()
    };
    opts.flush_interval_s = 1e6; // no time-based flush during the count
    let mut w = RecordingWriter::create(dir.join("rec.h5"), &opts).unwrap();
    let frame = [0.25; 120];
    let image = [1.0; 64];
    let truth = [TruthContact { x_mm: 1.0, y_mm: 2.0, force_n: 3.0, diameter_mm: 10.0 }; 2];
    let strategy = w.strategy_index("pneumatic-locaware").unwrap();
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    for i in 0..500u64 {
        let t = i as f64 * 0.01;
        w.append_eit(t, i, &frame).unwrap();
        w.append_pressure(t, 1.0).unwrap();
        w.append_truth(t, &truth).unwrap();
        w.append_image(t, &image).unwrap();
        let contacts = (0..3).map(|k| ContactRow { x_mm: k as f64, y_mm: 0.0, sum: 1.0, area_mm2: 20.0 });
        w.append_contacts(t, contacts).unwrap();
        w.append_forces(strategy, t, &[1.0, 2.0, 3.0]).unwrap();
    }
    let allocations = ALLOCATIONS.load(Ordering::Relaxed) - before;
    assert_eq!(allocations, 0, "{allocations} allocations in 3000 appends");
    assert_eq!(w.close().unwrap().rows_written, 3000);
}
