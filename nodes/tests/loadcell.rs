//! The load cell's `at` command: a calibration session moves the indenter over a grid while the
//! graph runs, and the truth rows follow. An emulated load cell on a pseudo-terminal sends a
//! press, a 1.5 s pause and a second press at real rates; the command is sent in the pause
//! (after the first press and a few pause readings have arrived), so only the second press is
//! at the new position.
//!
//! Hot swap keeps the `at` position: the running node moves to a second emulated load cell
//! with params that give the same position as before, and the second load cell's presses are
//! truth at the `at` position; with params that move the position, at the params'. A swap on
//! the same port takes the open port over (no reading lost), or, with other port settings,
//! reopens it; two nodes on one port are refused. Deterministic: rows are told apart by their
//! force, and every wait is for a condition. Every load cell here keeps what its port buffered
//! before it opened (`clear_input_at_open = false`, [`KEEP`]): the emulator starts sending
//! when it is spawned, and the tests count every reading from the first.

use std::sync::atomic::{AtomicBool, Ordering::SeqCst};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphHandle, GraphSpec, Params, Registry, RunOptions, RunReport, RunningGraph};
use skinflow_nodes::payload::Truth;
use skinflow_nodes::pipeline::{Captured, registry_with_capture};
use skinflow_serial::{Device, Emulator, EmulatorConfig, EmulatorFeed, FaultPlan, TimedForce};

const PERIOD_S: f64 = 0.05;
/// Readings: 10 at 2 N, 30 at 0 N (1.5 s), 10 at 3 N.
const FIRST: usize = 10;
const PAUSE: usize = 30;
const SECOND: usize = 10;
const LIMIT: Duration = Duration::from_secs(30);
/// The param every load cell of these tests takes (see the module docs).
const KEEP: &str = "clear_input_at_open = false";

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

/// A running graph: load cell "lc" on `port` (quoted) at (-10, 5), its truth into "cap".
struct Rig {
    captured: Captured,
    reg: Registry,
    handle: GraphHandle,
    stop: Arc<AtomicBool>,
    runner: std::thread::JoinHandle<RunReport>,
}

impl Rig {
    fn start(port: &str) -> Rig {
        let captured: Captured = Arc::new(Mutex::new(Vec::new()));
        let reg = registry_with_capture(captured.clone());
        let graph = format!(
            "[[node]]\nid = \"lc\"\nkind = \"serial_loadcell\"\nparams = {{ port = {port}, x_mm = -10.0, y_mm = 5.0, {KEEP} }}\n\
             [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
             [[edge]]\nfrom = \"lc.truth\"\nto = \"cap.in\"\n"
        );
        let spec = GraphSpec::parse(SourceFile::new("loadcell.toml", graph), &reg).unwrap();
        let running = RunningGraph::start(&spec).unwrap();
        let handle = running.handle();
        let stop = Arc::new(AtomicBool::new(false));
        let opts = RunOptions { duration: None, stop: Some(stop.clone()) };
        let runner = std::thread::spawn(move || running.wait(&opts));
        Rig { captured, reg, handle, stop, runner }
    }

    /// Sends `at 12.5 -25 20`, swaps "lc" for a load cell with `params`, waits for the whole
    /// 3 N press, and finishes the run.
    fn at_then_swap(self, params: &str) -> RunReport {
        self.handle.control_wait("lc", "at 12.5 -25 20", Duration::from_secs(5)).unwrap();
        let params = Params::from_toml(&format!("{params}\n{KEEP}")).unwrap();
        self.handle.swap("lc", self.reg.get("serial_loadcell").unwrap().clone(), params).unwrap();
        wait_for_pressed(&self.captured, 3.0, SECOND);
        self.finish()
    }

    /// Stops the run; it must have had no failure.
    fn finish(self) -> RunReport {
        self.stop.store(true, SeqCst);
        let report = self.runner.join().unwrap();
        assert!(report.failures.is_empty(), "{:?}", report.failures);
        report
    }
}

#[test]
fn at_moves_the_truth_position_of_the_following_readings() {
    let (emulator, port) = load_cell(readings());
    let rig = Rig::start(&port);
    // In the pause: the first press and three pause readings are in.
    wait_for_rows(&rig.captured, FIRST + 3);
    rig.handle.control_wait("lc", "at 12.5 -25 20", Duration::from_secs(5)).unwrap();
    let e = rig.handle.control_wait("lc", "at 12.5", Duration::from_secs(5)).unwrap_err().to_string();
    assert!(e.contains("expected at X_MM Y_MM [DIAMETER_MM]"), "{e}");
    wait_for_rows(&rig.captured, FIRST + PAUSE + SECOND);
    let captured = rig.captured.clone();
    rig.finish();
    emulator.stop().unwrap();

    let rows = truth_rows(&captured);
    assert_eq!(rows.len(), FIRST + PAUSE + SECOND);
    for (i, row) in rows.iter().enumerate() {
        let expected = match i {
            i if i < FIRST => vec![(-10.0, 5.0, 15.0, 2.0)],
            i if i < FIRST + PAUSE => vec![],
            _ => vec![(12.5, -25.0, 20.0, 3.0)],
        };
        assert_eq!(contacts(row), expected, "reading {i}");
    }
}

/// A truth row's contacts as (x, y, diameter, force).
fn contacts(t: &Truth) -> Vec<(f64, f64, f64, f64)> {
    t.contacts.iter().map(|c| (c.x_mm, c.y_mm, c.diameter_mm, c.force_n)).collect()
}

/// Rows with a contact of `force_n`.
fn pressed(captured: &Captured, force_n: f64) -> Vec<Arc<Truth>> {
    truth_rows(captured).into_iter().filter(|t| t.contacts.iter().any(|c| c.force_n == force_n)).collect()
}

fn wait_for_pressed(captured: &Captured, force_n: f64, n: usize) {
    let t0 = Instant::now();
    while pressed(captured, force_n).len() < n {
        assert!(t0.elapsed() < LIMIT, "only {} of {n} {force_n} N readings arrived", pressed(captured, force_n).len());
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// An emulated load cell sending `readings` at real rates.
fn load_cell(readings: Vec<TimedForce>) -> (Emulator, String) {
    let emulator = Emulator::spawn(
        EmulatorConfig::default(),
        EmulatorFeed::default().with_loadcell(readings),
        FaultPlan::default(),
    )
    .expect("emulator");
    let port = format!("{:?}", emulator.path(Device::Loadcell).expect("load cell pty"));
    (emulator, port)
}

/// Readings one per `PERIOD_S`: `n` of each `force_n` in turn.
fn feed(parts: &[(usize, f64)]) -> Vec<TimedForce> {
    parts
        .iter()
        .flat_map(|&(n, force_n)| std::iter::repeat_n(force_n, n))
        .enumerate()
        .map(|(i, force_n)| TimedForce { t_s: i as f64 * PERIOD_S, force_n })
        .collect()
}

/// The rig's first load cell presses `FIRST` readings at 2 N at (-10, 5), then rests (0 N)
/// longer than the test needs; `at 12.5 -25 20` is sent in the rest, then the node is swapped
/// with `swap_params` (`{port}`: the second load cell's port) to a second load cell that rests
/// and then presses `SECOND` readings at 3 N. Returns the second load cell's pressed rows.
fn swap_after_at(swap_params: &str) -> Vec<Arc<Truth>> {
    let (first, second) = (feed(&[(FIRST, 2.0), (200, 0.0)]), feed(&[(PAUSE, 0.0), (SECOND, 3.0)]));
    let (first_cell, first_port) = load_cell(first);
    let rig = Rig::start(&first_port);
    // In the rest: the press and three rest readings are in.
    wait_for_rows(&rig.captured, FIRST + 3);
    let (second_cell, second_port) = load_cell(second);
    let captured = rig.captured.clone();
    let report = rig.at_then_swap(&swap_params.replace("{port}", &second_port));
    assert_eq!(report.stats.node("lc").unwrap().swaps, 1);
    first_cell.stop().unwrap();
    second_cell.stop().unwrap();

    let before = pressed(&captured, 2.0);
    assert_eq!(before.len(), FIRST, "the first press");
    for (i, row) in before.iter().enumerate() {
        assert_eq!(contacts(row), vec![(-10.0, 5.0, 15.0, 2.0)], "first press, reading {i}");
    }
    let after = pressed(&captured, 3.0);
    assert_eq!(after.len(), SECOND, "the second load cell's press, whole");
    let with_contacts = truth_rows(&captured).iter().filter(|t| !t.contacts.is_empty()).count();
    assert_eq!(before.len() + after.len(), with_contacts, "no other contacts");
    after
}

#[test]
fn a_hot_swap_with_the_same_position_in_its_params_keeps_the_at_position() {
    // Another port and threshold; x, y and diameter as before (the diameter by default).
    let after = swap_after_at("port = {port}\nx_mm = -10.0\ny_mm = 5.0\ncontact_threshold_n = 0.1");
    for (i, row) in after.iter().enumerate() {
        assert_eq!(contacts(row), vec![(12.5, -25.0, 20.0, 3.0)], "after the swap, reading {i}");
    }
}

#[test]
fn a_hot_swap_whose_params_move_the_position_puts_the_truth_there() {
    let after = swap_after_at("port = {port}\nx_mm = 30.0\ny_mm = 40.0");
    for (i, row) in after.iter().enumerate() {
        assert_eq!(contacts(row), vec![(30.0, 40.0, 15.0, 3.0)], "after the swap, reading {i}");
    }
}

/// A graph reading the emulated load cell's `readings()` on `port` (ids "lc", "cap"), `at` sent
/// in the pause, then the node swapped in place with `swap_params` (`{port}`: the same port).
/// Returns the truth rows with their header seq, once all of them arrived, and the run's swaps.
fn swap_in_place(swap_params: &str) -> (Vec<(u64, Arc<Truth>)>, u64) {
    let (emulator, port) = load_cell(readings());
    let rig = Rig::start(&port);
    wait_for_rows(&rig.captured, FIRST + 3);
    let captured = rig.captured.clone();
    let report = rig.at_then_swap(&swap_params.replace("{port}", &port));
    emulator.stop().unwrap();
    let rows = captured.lock().unwrap().iter().flatten().map(|m| (m.header.seq, m.arc::<Truth>().unwrap())).collect();
    (rows, report.stats.node("lc").unwrap().swaps)
}

/// A swap that keeps the port and its settings: no reading lost or repeated (the seq goes on
/// 1, 2, 3, ... across the switch), and the second press is truth at the `at` position. (That
/// the open link is taken over rather than reopened is checked on the port itself, in
/// `serial::link`'s unit test: a reopen in the pause loses nothing here either.)
#[test]
fn a_hot_swap_on_the_same_port_takes_the_open_port_over_and_loses_no_reading() {
    let (rows, swaps) = swap_in_place("port = {port}\nx_mm = -10.0\ny_mm = 5.0\ncontact_threshold_n = 0.1");
    assert_eq!(swaps, 1);
    assert_eq!(rows.len(), FIRST + PAUSE + SECOND, "every reading, once");
    for (i, (seq, row)) in rows.iter().enumerate() {
        assert_eq!(*seq, i as u64 + 1, "reading {i}");
        let expected = match i {
            i if i < FIRST => vec![(-10.0, 5.0, 15.0, 2.0)],
            i if i < FIRST + PAUSE => vec![],
            _ => vec![(12.5, -25.0, 20.0, 3.0)],
        };
        assert_eq!(contacts(row), expected, "reading {i}");
    }
}

/// Other port settings (a longer read timeout) cannot use the replaced link: it is closed at
/// the switch and the replacement opens the port on its first poll, in the pause, so the second
/// press arrives whole.
#[test]
fn a_hot_swap_with_other_port_settings_reopens_the_port() {
    let (rows, swaps) = swap_in_place("port = {port}\nx_mm = -10.0\ny_mm = 5.0\nread_timeout_s = 0.08");
    assert_eq!(swaps, 1);
    let second: Vec<_> = rows.iter().filter(|(_, t)| !t.contacts.is_empty() && t.contacts[0].force_n == 3.0).collect();
    assert_eq!(second.len(), SECOND);
    for (_, row) in second {
        assert_eq!(contacts(row), vec![(12.5, -25.0, 20.0, 3.0)]);
    }
}

/// Two nodes cannot read one device: the second is refused at start, naming the first.
#[test]
fn a_port_another_node_holds_is_refused_at_start() {
    let (emulator, port) = load_cell(readings());
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let reg = registry_with_capture(captured);
    let graph = format!(
        "[[node]]\nid = \"lc\"\nkind = \"serial_loadcell\"\nparams = {{ port = {port} }}\n\
         [[node]]\nid = \"lc2\"\nkind = \"serial_loadcell\"\nparams = {{ port = {port} }}\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
         [[edge]]\nfrom = \"lc.truth\"\nto = \"cap.in\"\n\
         [[edge]]\nfrom = \"lc2.truth\"\nto = \"cap.in\"\n"
    );
    let spec = GraphSpec::parse(SourceFile::new("loadcell.toml", graph), &reg).unwrap();
    let e = match RunningGraph::start(&spec) {
        Ok(_) => panic!("two nodes on one port started"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("already open by node \"lc"), "{e}");
    emulator.stop().unwrap();
}
