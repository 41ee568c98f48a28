//! Per-frame hot path without heap allocation: once a hold's state is solved, further EIT
//! frames, pressure samples and truth rows of the hold allocate nothing (counting allocator,
//! in a test binary of its own so no other test's allocations are counted); owned events
//! (`next_event`) allocate what they own and nothing else, and through reused buffers
//! (`next_into`, as the writer paths take them) truth rows during ramps allocate nothing.
//! Counted on the calling thread: faer may start its rayon worker pool while the hold is
//! solved, and those threads allocate on their own schedule (a CI run once saw two such
//! allocations land inside the counted window).

use skinflow_sim::{Scene, SimEvent, Simulator};

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

/// The time of an owned event.
fn time(e: &SimEvent) -> f64 {
    match e {
        SimEvent::Eit { t_s, .. } | SimEvent::Pressure { t_s, .. } | SimEvent::Truth { t_s, .. } => *t_s,
    }
}

#[test]
fn owned_events_allocate_what_they_own_and_nothing_else() {
    // a static hold: an EIT frame owns its values (one vector), a pressure sample nothing
    let text = "[scene]\nprofile = \"paper\"\n[model]\nmesh_min_elements = 600\nmesh_max_elements = 700\n\
        [[step]]\nrest_s = 3.0\n[[step]]\nat_mm = [[5.0, 5.0]]\ndiameter_mm = 15.0\nforces_n = [4.0]\nhold_s = 30.0\n";
    let scene = Scene::from_str(text, "t.toml").unwrap();
    let mut sim = Simulator::new(&scene, 4).unwrap();
    while time(&sim.next_event().unwrap().unwrap()) < 10.0 {}
    let (mut frames, mut samples, mut others) = (0, 0, 0);
    let allocations = allocations_in(|| {
        loop {
            let e = sim.next_event().unwrap().unwrap();
            if time(&e) > 32.5 {
                break;
            }
            match e {
                SimEvent::Eit { v, .. } => frames += usize::from(v.len() == sim.measurement_count()),
                SimEvent::Pressure { .. } => samples += 1,
                SimEvent::Truth { .. } => others += 1,
            }
        }
    });
    assert!(frames > 25 && samples > 400 && others == 0, "{frames} frames, {samples} samples, {others} rows");
    // the event past the window is counted too: one more frame or none
    assert!(allocations == frames as u64 || allocations == frames as u64 + 1, "{allocations} for {frames} frames");

    // ramps, pressure only: a truth row owns its contacts (one vector; none without contact)
    let text = "[scene]\nchannels = [\"pressure\"]\n[[step]]\nrest_s = 1.0\n[[step]]\nat_mm = [[5.0, 5.0], [-5.0, 0.0]]\n\
        diameter_mm = 15.0\nforces_n = [2.0, 4.0]\nhold_s = 1.0\nramp_s = 0.5\nrest_s = 1.0\n";
    let scene = Scene::from_str(text, "t.toml").unwrap();
    let mut sim = Simulator::new(&scene, 4).unwrap();
    // past the first indentation (the pressure channel's per-contact state is built then)
    while time(&sim.next_event().unwrap().unwrap()) < 4.0 {}
    let (mut loaded, mut empty, mut samples) = (0u64, 0u64, 0u64);
    let allocations = allocations_in(|| {
        while let Some(e) = sim.next_event().unwrap() {
            match e {
                SimEvent::Truth { contacts, .. } if contacts.is_empty() => empty += 1,
                SimEvent::Truth { .. } => loaded += 1,
                SimEvent::Pressure { .. } => samples += 1,
                SimEvent::Eit { .. } => unreachable!("no eit channel"),
            }
        }
    });
    assert!(
        loaded > 40 && empty >= 3 && samples > 150,
        "{loaded} rows with contacts, {empty} without, {samples} samples"
    );
    assert_eq!(allocations, loaded, "{allocations} allocations for {loaded} rows with contacts");
}

#[test]
fn reused_buffers_take_truth_rows_without_allocating() {
    // The writer paths (`skinflow simulate`, `skinflow emulate`, the `sim` node) take events
    // through `next_into` with buffers kept from event to event: the ramps' truth rows with
    // contacts, which `next_event` allocates one vector for each, then allocate nothing.
    let text = "[scene]\nchannels = [\"pressure\"]\n[[step]]\nrest_s = 1.0\n[[step]]\nat_mm = [[5.0, 5.0], [-5.0, 0.0]]\n\
        diameter_mm = 15.0\nforces_n = [2.0, 4.0]\nhold_s = 1.0\nramp_s = 0.5\nrest_s = 1.0\n";
    let scene = Scene::from_str(text, "t.toml").unwrap();
    let mut sim = Simulator::new(&scene, 4).unwrap();
    let mut v = vec![0.0; sim.measurement_count()];
    let mut truth = Vec::with_capacity(sim.max_contacts());
    // past the first indentation (the pressure channel's per-contact state is built then)
    while let Some(e) = sim.next_into(&mut v, &mut truth).unwrap() {
        if let skinflow_sim::EventKind::Pressure { t_s, .. } = e
            && t_s >= 4.0
        {
            break;
        }
    }
    let (mut loaded, mut samples) = (0u64, 0u64);
    let allocations = allocations_in(|| {
        while let Some(e) = sim.next_into(&mut v, &mut truth).unwrap() {
            match e {
                skinflow_sim::EventKind::Truth { .. } => loaded += u64::from(!truth.is_empty()),
                skinflow_sim::EventKind::Pressure { .. } => samples += 1,
                skinflow_sim::EventKind::Eit { .. } => unreachable!("no eit channel"),
            }
        }
    });
    assert!(loaded > 40 && samples > 150, "{loaded} rows with contacts, {samples} samples");
    assert_eq!(allocations, 0, "{allocations} allocations for {loaded} rows with contacts");
}
