//! Per-frame hot path without heap allocation: once a hold's state is solved, further EIT
//! frames, pressure samples and truth rows of the hold allocate nothing (counting allocator,
//! in a test binary of its own so no other test's allocations are counted).

use skinflow_sim::{Scene, Simulator};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
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
fn static_hold_frames_do_not_allocate() {
    let text = "[scene]\nprofile = \"paper\"\n[model]\nmesh_min_elements = 600\nmesh_max_elements = 700\n\
        [[step]]\nrest_s = 3.0\n[[step]]\nat_mm = [[5.0, 5.0]]\ndiameter_mm = 15.0\nforces_n = [4.0]\nhold_s = 30.0\n";
    let scene = Scene::from_str(text, "t.toml").unwrap();
    let mut sim = Simulator::new(&scene, 4).unwrap();
    let mut v = vec![0.0; sim.measurement_count()];
    let mut truth = Vec::with_capacity(sim.max_contacts());
    // run into the hold: its state gets solved (allocations inside the forward solver)
    let mut t = 0.0;
    while t < 10.0 {
        match sim.next_into(&mut v, &mut truth).unwrap().unwrap() {
            skinflow_sim::EventKind::Eit { t_s, .. } | skinflow_sim::EventKind::Pressure { t_s, .. } => t = t_s,
            skinflow_sim::EventKind::Truth { t_s } => t = t_s,
        }
    }
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    // the hold ends at 33.5 s (3 s rest + 0.5 s ramp + 30 s); stop before the release
    let mut events = 0;
    loop {
        let t_s = match sim.next_into(&mut v, &mut truth).unwrap().unwrap() {
            skinflow_sim::EventKind::Eit { t_s, .. } | skinflow_sim::EventKind::Pressure { t_s, .. } => t_s,
            skinflow_sim::EventKind::Truth { t_s } => t_s,
        };
        if t_s > 32.5 {
            break;
        }
        events += 1;
    }
    let after = ALLOCATIONS.load(Ordering::Relaxed);
    assert!(events > 400, "{events} events");
    assert_eq!(after - before, 0, "{} allocations in {events} events of a static hold", after - before);
}
