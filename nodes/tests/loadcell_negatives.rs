//! The load cell's `negative_readings` in the run statistics: readings below
//! `-contact_threshold_n` (a reversed sign, a missing tare) are counted under the node's own
//! counter, which the node takes at start, so the statistics name it (at 0) for a run without
//! any. An emulated load cell on a pseudo-terminal sends each run's readings; every wait is for
//! a condition, bounded so a regression fails instead of hanging.

use std::sync::atomic::{AtomicBool, Ordering::SeqCst};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, RunOptions, RunningGraph};
use skinflow_nodes::payload::Truth;
use skinflow_nodes::pipeline::{Captured, registry_with_capture};
use skinflow_serial::{Device, Emulator, EmulatorConfig, EmulatorFeed, FaultPlan, TimedForce};

const LIMIT: Duration = Duration::from_secs(30);

/// Runs a load cell node (`contact_threshold_n = 0.5`, the emulator's backlog kept) on an
/// emulated gauge printing `forces_n`, 20 ms apart, until every reading became a truth row;
/// returns the node's counters and the rows' contact forces.
fn run(forces_n: &[f64]) -> (std::collections::BTreeMap<String, u64>, Vec<Vec<f64>>) {
    let readings: Vec<TimedForce> =
        forces_n.iter().enumerate().map(|(i, &force_n)| TimedForce { t_s: 0.02 * i as f64, force_n }).collect();
    let emulator = Emulator::spawn(
        EmulatorConfig::default(),
        EmulatorFeed::default().with_loadcell(readings),
        FaultPlan::default(),
    )
    .expect("emulator");
    let port = emulator.path(Device::Loadcell).expect("load cell pty");
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let reg = registry_with_capture(captured.clone());
    let graph = format!(
        "[[node]]\nid = \"lc\"\nkind = \"serial_loadcell\"\n\
         params = {{ port = {port:?}, contact_threshold_n = 0.5, clear_input_at_open = false }}\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
         [[edge]]\nfrom = \"lc.truth\"\nto = \"cap.in\"\n"
    );
    let spec = GraphSpec::parse(SourceFile::new("negatives.toml", graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let opts = RunOptions { duration: None, stop: Some(stop.clone()) };
    let runner = std::thread::spawn(move || running.wait(&opts));
    let rows = || -> Vec<Arc<Truth>> {
        captured.lock().unwrap().iter().flatten().map(|m| m.arc::<Truth>().expect("truth")).collect()
    };
    let t0 = Instant::now();
    while rows().len() < forces_n.len() {
        assert!(t0.elapsed() < LIMIT, "only {} of {} readings arrived", rows().len(), forces_n.len());
        std::thread::sleep(Duration::from_millis(5));
    }
    stop.store(true, SeqCst);
    let report = runner.join().unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    emulator.stop().unwrap();
    let counters = report.stats.node("lc").expect("node lc in the statistics").counters.clone();
    let forces = rows().iter().map(|t| t.contacts.iter().map(|c| c.force_n).collect()).collect();
    (counters, forces)
}

#[test]
fn negative_readings_are_counted_and_named_in_the_statistics_from_the_start() {
    // Two readings below -0.5 N; -0.2 N is within the threshold (noise around zero).
    let (counters, forces) = run(&[2.0, -1.5, -0.2, 3.0, -2.5, 0.0]);
    assert_eq!(counters.get("negative_readings"), Some(&2), "{counters:?}");
    let none: Vec<f64> = Vec::new();
    assert_eq!(forces, vec![vec![2.0], none.clone(), none.clone(), vec![3.0], none.clone(), none]);

    // Without a negative reading the counter is there all the same, at 0: the node took it at
    // start, not at its first negative reading.
    let (counters, _) = run(&[1.0, 0.0, 2.0]);
    assert_eq!(counters.get("negative_readings"), Some(&0), "{counters:?}");
}
