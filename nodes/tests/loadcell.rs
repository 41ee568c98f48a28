//! The load cell's `at` command: a calibration session moves the indenter over a grid while the
//! graph runs, and the truth rows follow. An emulated load cell on a pseudo-terminal sends a
//! press, a 1.5 s pause and a second press at real rates; the command is sent in the pause
//! (after the first press and a few pause readings have arrived), so only the second press is
//! at the new position.

use std::sync::atomic::{AtomicBool, Ordering::SeqCst};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, RunOptions, RunningGraph};
use skinflow_nodes::payload::Truth;
use skinflow_nodes::pipeline::{Captured, registry_with_capture};
use skinflow_serial::{Device, Emulator, EmulatorConfig, EmulatorFeed, FaultPlan, TimedForce};

const PERIOD_S: f64 = 0.05;
/// Readings: 10 at 2 N, 30 at 0 N (1.5 s), 10 at 3 N.
const FIRST: usize = 10;
const PAUSE: usize = 30;
const SECOND: usize = 10;
const LIMIT: Duration = Duration::from_secs(30);

fn readings() -> Vec<TimedForce> {
    (0..FIRST + PAUSE + SECOND)
        .map(|i| {
            let force_n = match i {
                i if i < FIRST => 2.0,
                i if i < FIRST + PAUSE => 0.0,
                _ => 3.0,
            };
            TimedForce { t_s: i as f64 * PERIOD_S, force_n }
        })
        .collect()
}

fn truth_rows(captured: &Captured) -> Vec<Arc<Truth>> {
    let calls = captured.lock().unwrap();
    calls.iter().flatten().map(|m| m.arc::<Truth>().expect("truth")).collect()
}

fn wait_for_rows(captured: &Captured, n: usize) {
    let t0 = Instant::now();
    while truth_rows(captured).len() < n {
        assert!(t0.elapsed() < LIMIT, "only {} of {n} readings arrived", truth_rows(captured).len());
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn at_moves_the_truth_position_of_the_following_readings() {
    let emulator = Emulator::spawn(
        EmulatorConfig::default(),
        EmulatorFeed::default().with_loadcell(readings()),
        FaultPlan::default(),
    )
    .expect("emulator");
    let port = emulator.path(Device::Loadcell).expect("load cell pty").to_path_buf();
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let reg = registry_with_capture(captured.clone());
    let graph = format!(
        "[[node]]\nid = \"lc\"\nkind = \"serial_loadcell\"\nparams = {{ port = {port:?}, x_mm = -10.0, y_mm = 5.0 }}\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
         [[edge]]\nfrom = \"lc.truth\"\nto = \"cap.in\"\n"
    );
    let spec = GraphSpec::parse(SourceFile::new("loadcell.toml", graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let stop = Arc::new(AtomicBool::new(false));
    let opts = RunOptions { duration: None, stop: Some(stop.clone()) };
    let runner = std::thread::spawn(move || running.wait(&opts));

    // In the pause: the first press and three pause readings are in.
    wait_for_rows(&captured, FIRST + 3);
    handle.control_wait("lc", "at 12.5 -25 20", Duration::from_secs(5)).unwrap();
    let e = handle.control_wait("lc", "at 12.5", Duration::from_secs(5)).unwrap_err().to_string();
    assert!(e.contains("expected at X_MM Y_MM [DIAMETER_MM]"), "{e}");
    wait_for_rows(&captured, FIRST + PAUSE + SECOND);
    stop.store(true, SeqCst);
    let report = runner.join().unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    emulator.stop().unwrap();

    let rows = truth_rows(&captured);
    assert_eq!(rows.len(), FIRST + PAUSE + SECOND);
    let at = |t: &Truth| t.contacts.iter().map(|c| (c.x_mm, c.y_mm, c.diameter_mm, c.force_n)).collect::<Vec<_>>();
    for (i, row) in rows.iter().enumerate() {
        let expected = match i {
            i if i < FIRST => vec![(-10.0, 5.0, 15.0, 2.0)],
            i if i < FIRST + PAUSE => vec![],
            _ => vec![(12.5, -25.0, 20.0, 3.0)],
        };
        assert_eq!(at(row), expected, "reading {i}");
    }
}
