//! Per-frame hot path without heap allocation: once a hold's state is solved, further EIT
//! frames, pressure samples and truth rows of the hold allocate nothing (counting allocator,
//! in a test binary of its own so no other test's allocations are counted). Counted on the
//! calling thread: faer may start its rayon worker pool while the hold is solved, and those
//! threads allocate on their own schedule (a CI run once saw two such allocations land inside
//! the counted window).

use skinflow_sim::{Scene, Simulator};

use skinflow_core::alloc_count::{CountingAlloc, allocations_in};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

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
    // the hold ends at 33.5 s (3 s rest + 0.5 s ramp + 30 s); stop before the release
    let mut events = 0;
    let allocations = allocations_in(|| {
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
    });
    assert!(events > 400, "{events} events");
    assert_eq!(allocations, 0, "{allocations} allocations in {events} events of a static hold");
}
