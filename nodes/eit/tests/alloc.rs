//! The per-frame path allocates nothing: a counting global allocator, in a test binary of its
//! own so no other test allocates meanwhile.

use skinflow_eit::mask::ChannelMask;
use skinflow_eit::{MeshParams, Precision, ReconParams, Reconstructor, Sensor};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards every call unchanged to the system allocator and only counts; the layout
// contracts of `GlobalAlloc` pass through untouched.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same layout contract as our caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: `ptr` came from `System.alloc` with `layout`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn frames_allocate_nothing() {
    let s = Sensor::paper_100mm();
    for precision in [Precision::F64, Precision::F32] {
        let params =
            ReconParams { mesh: MeshParams { elements: 600, ..Default::default() }, precision, ..Default::default() };
        let mut r = Reconstructor::new(&s, &params).unwrap();
        let m = r.measurement_count();
        let v_ref: Vec<f64> = (0..m).map(|k| 0.3 + 1e-3 * k as f64).collect();
        let mut v = v_ref.clone();
        let mut image = vec![0.0; r.pixel_count()];
        let mut elements = vec![0.0; r.element_count()];
        let mut mask = ChannelMask::none(m, s.electrode_count());
        // A masked matrix built beforehand: switching back and forth to it is allocation-free too.
        let mut masked = mask.clone();
        masked.excluded[3] = true;
        r.set_mask(&masked).unwrap();
        r.set_mask(&mask).unwrap();
        let before = ALLOCATIONS.load(Ordering::SeqCst);
        for f in 0..50 {
            v[f % m] += 1e-4;
            r.detect_mask_into(&v, &mut mask);
            r.set_mask(&mask).unwrap();
            r.reconstruct_image_into(&v, &v_ref, &mut image).unwrap();
            r.reconstruct_elements_into(&v, &v_ref, &mut elements).unwrap();
        }
        r.set_mask(&masked).unwrap();
        r.reconstruct_image_into(&v, &v_ref, &mut image).unwrap();
        let after = ALLOCATIONS.load(Ordering::SeqCst);
        assert_eq!(after - before, 0, "{precision:?}: {} allocations in the frame loop", after - before);
        assert!(image.iter().any(|x| *x != 0.0));
    }
}
