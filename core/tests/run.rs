//! Running graphs: drop accounting on both edge policies, the three triggers, deadline
//! misses, lockstep determinism (and agreement with the threaded executor), control commands,
//! real-time option fallback, stopping on request and the statistics report.
//!
//! No assertion depends on timing: where a race could matter, a `gate` node holds the
//! consumer until the test has seen the producer's state.

use crate::kinds;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering::SeqCst};
use std::time::Duration;

use kinds::{gate, graph, rows, temp_dir, wait_for, within};
use skinflow_core::graph::Policy;
use skinflow_core::{Mode, RunError, RunOptions, RunReport, RunningGraph, StatsReport, run};

const LIMIT: Duration = Duration::from_secs(60);

fn run_ok(spec: skinflow_core::GraphSpec) -> RunReport {
    let r = within(LIMIT, move || run(&spec, &RunOptions::default()));
    let r = r.unwrap_or_else(|e| panic!("run failed to start: {e}"));
    assert!(r.failures.is_empty(), "failures: {:?}", r.failures);
    r
}

fn edge<'a>(s: &'a StatsReport, from: &str, to: &str) -> &'a skinflow_core::stats::EdgeReport {
    s.edges.iter().find(|e| e.from == from && e.to == to).unwrap_or_else(|| panic!("no edge {from} -> {to}"))
}

/// Source -> gate -> collect. The source sends message 0, waits until the gate holds it in a
/// call, then sends 1..100 while the gate stays closed until the test opens it.
fn gated(dir: &std::path::Path, key: &str, policy: &str) -> skinflow_core::GraphSpec {
    graph(
        dir,
        &format!(
            r#"
            [graph]
            workers = 2
            [[node]]
            id = "c"
            kind = "paired"
            params = {{ key = "{key}", count = 100 }}
            [[node]]
            id = "g"
            kind = "gate"
            params = {{ key = "{key}" }}
            [[node]]
            id = "out"
            kind = "collect"
            params = {{ path = "out.csv" }}
            [[edge]]
            from = "c.out"
            to = "g.in"
            capacity = 4
            policy = "{policy}"
            [[edge]]
            from = "g.out"
            to = "out.in"
            "#
        ),
    )
}

#[test]
fn block_edge_holds_the_producer_and_loses_nothing() {
    let dir = temp_dir("block");
    let g = RunningGraph::start(&gated(&dir, "block", "block")).unwrap();
    // The gate holds message 0 in its call; the queue fills with 1..=4 and the source waits.
    wait_for("the queue to fill", || edge(&g.stats(), "c.out", "g.in").pushed == 5);
    std::thread::sleep(Duration::from_millis(20));
    assert_eq!(edge(&g.stats(), "c.out", "g.in").pushed, 5, "a full block edge must hold its producer");
    gate("block").store(true, SeqCst);
    let r = within(LIMIT, move || g.wait(&RunOptions::default()));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let e = edge(&r.stats, "c.out", "g.in");
    assert_eq!((e.pushed, e.drops, e.max_depth), (100, 0, 4));
    assert_eq!(r.stats.node("g").unwrap().msgs_in, 100);
    assert_eq!(r.stats.total_drops(), 0);
    let want: Vec<(u64, u64)> = (0..100).map(|k| (k, k)).collect();
    assert_eq!(rows(&dir.join("out.csv")), want);
}

#[test]
fn drop_oldest_edge_keeps_the_newest_and_counts_every_drop() {
    let dir = temp_dir("drop-oldest");
    let g = RunningGraph::start(&gated(&dir, "drop", "drop_oldest")).unwrap();
    // The gate holds its first message; the other 99 go through a queue of 4.
    wait_for("the source to finish", || edge(&g.stats(), "c.out", "g.in").pushed == 100);
    gate("drop").store(true, SeqCst);
    let r = within(LIMIT, move || g.wait(&RunOptions::default()));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let e = edge(&r.stats, "c.out", "g.in");
    let received = r.stats.node("g").unwrap().msgs_in;
    assert_eq!(e.policy, Policy::DropOldest);
    assert_eq!((received, e.dropped_full, e.undelivered), (5, 95, 0));
    assert_eq!(received + e.dropped_full, r.stats.node("c").unwrap().msgs_out);
    let got = rows(&dir.join("out.csv"));
    assert_eq!(got.len(), 5);
    assert_eq!(&got[1..], &[(96, 96), (97, 97), (98, 98), (99, 99)], "latest wins");
}

#[test]
fn drop_oldest_with_a_slow_consumer_accounts_for_every_message() {
    let dir = temp_dir("slow");
    let spec = graph(
        &dir,
        r#"
        [[node]]
        id = "c"
        kind = "counter"
        params = { count = 2000 }
        [[node]]
        id = "slow"
        kind = "delay"
        params = { delay_us = 20.0 }
        [[node]]
        id = "out"
        kind = "collect"
        params = { path = "out.csv" }
        [[edge]]
        from = "c.out"
        to = "slow.in"
        capacity = 2
        policy = "drop_oldest"
        [[edge]]
        from = "slow.out"
        to = "out.in"
        "#,
    );
    let r = run_ok(spec);
    let e = edge(&r.stats, "c.out", "slow.in");
    let received = r.stats.node("slow").unwrap().msgs_in;
    assert_eq!(received + e.dropped_full, 2000, "received {received} + dropped {} != sent", e.dropped_full);
    assert_eq!(e.pushed, 2000);
    let got = rows(&dir.join("out.csv"));
    assert_eq!(got.len() as u64, received);
    assert!(got.windows(2).all(|w| w[0].0 < w[1].0), "survivors stay in order");
    assert_eq!(got.last(), Some(&(1999, 1999)), "the newest message is never dropped");
}

fn aligned_graph(
    dir: &std::path::Path,
    mode: &str,
    a: (&[u64], &[u64]),
    b: (&[u64], &[u64]),
    align: &str,
) -> skinflow_core::GraphSpec {
    graph(
        dir,
        &format!(
            r#"
            [graph]
            mode = "{mode}"
            [[node]]
            id = "a"
            kind = "stamped"
            params = {{ seq = {:?}, t_ns = {:?} }}
            [[node]]
            id = "b"
            kind = "stamped"
            params = {{ seq = {:?}, t_ns = {:?} }}
            [[node]]
            id = "sum"
            kind = "sum"
            trigger = "aligned"
            {align}
            [[node]]
            id = "out"
            kind = "collect"
            params = {{ path = "out.csv" }}
            [[edge]]
            from = "a.out"
            to = "sum.a"
            [[edge]]
            from = "b.out"
            to = "sum.b"
            [[edge]]
            from = "sum.out"
            to = "out.in"
            "#,
            a.0, a.1, b.0, b.1
        ),
    )
}

#[test]
fn aligned_by_seq_pairs_equal_sequence_numbers() {
    for mode in ["lockstep", "realtime"] {
        let dir = temp_dir(&format!("aligned-seq-{mode}"));
        let a = [0, 1, 2, 3, 4, 5];
        let b = [0, 2, 3, 5];
        let spec = aligned_graph(&dir, mode, (&a, &[0; 6]), (&b, &[0; 4]), "");
        let r = run_ok(spec);
        // Output header is a's; value = a.seq + b.seq.
        assert_eq!(rows(&dir.join("out.csv")), [(0, 0), (2, 4), (3, 6), (5, 10)], "{mode}");
        assert_eq!(edge(&r.stats, "a.out", "sum.a").dropped_unaligned, 2, "{mode}: a's 1 and 4 have no partner");
        assert_eq!(edge(&r.stats, "b.out", "sum.b").drops, 0, "{mode}");
    }
}

#[test]
fn aligned_by_time_window_pairs_close_timestamps() {
    for mode in ["lockstep", "realtime"] {
        let dir = temp_dir(&format!("aligned-time-{mode}"));
        // Window 200 ns: (0,100) pair; 1000 is too old for 1700; 1700 too old for 2000;
        // (2000,2050) pair; 3000 has no partner within 200 ns of 5000; then a has ended.
        let spec = aligned_graph(
            &dir,
            mode,
            (&[10, 11, 12, 13], &[0, 1000, 2000, 3000]),
            (&[20, 21, 22, 23], &[100, 1700, 2050, 5000]),
            "align_window_us = 0.2",
        );
        let r = run_ok(spec);
        assert_eq!(rows(&dir.join("out.csv")), [(10, 30), (12, 34)], "{mode}");
        let ea = edge(&r.stats, "a.out", "sum.a");
        let eb = edge(&r.stats, "b.out", "sum.b");
        assert_eq!((ea.dropped_unaligned, ea.undelivered), (2, 0), "{mode}");
        // a's stream has ended and its queue is empty: 5000 can never be aligned, and is
        // dropped as unaligned rather than left waiting for a partner until the shutdown.
        assert_eq!((eb.dropped_unaligned, eb.undelivered), (2, 0), "{mode}: 5000 can never align once a ended");
        assert_eq!(r.stats.node("sum").unwrap().drops, 4, "{mode}");
    }
}

fn periodic_graph(dir: &std::path::Path, mode: &str, counter: &str) -> skinflow_core::GraphSpec {
    graph(
        dir,
        &format!(
            r#"
            [graph]
            mode = "{mode}"
            [[node]]
            id = "c"
            kind = "counter"
            params = {{ {counter} }}
            [[node]]
            id = "tick"
            kind = "scale"
            trigger = "periodic"
            period_ms = 5.0
            [[node]]
            id = "out"
            kind = "collect"
            params = {{ path = "out.csv" }}
            [[edge]]
            from = "c.out"
            to = "tick.in"
            [[edge]]
            from = "tick.out"
            to = "out.in"
            "#
        ),
    )
}

#[test]
fn periodic_trigger_in_lockstep_fires_once_per_step() {
    let dir = temp_dir("periodic-lockstep");
    let r = run_ok(periodic_graph(&dir, "lockstep", "count = 10"));
    let want: Vec<(u64, u64)> = (0..10).map(|k| (k, k)).collect();
    assert_eq!(rows(&dir.join("out.csv")), want);
    assert_eq!(r.stats.node("tick").unwrap().errors, 0, "a tick without new input is not an error");
}

#[test]
fn periodic_trigger_in_realtime_takes_the_newest_and_counts_the_rest() {
    let dir = temp_dir("periodic-realtime");
    let r = run_ok(periodic_graph(&dir, "realtime", "count = 60, rate_hz = 2000.0"));
    let got = rows(&dir.join("out.csv"));
    let e = edge(&r.stats, "c.out", "tick.in");
    let tick = r.stats.node("tick").unwrap();
    assert!(!got.is_empty());
    assert!(got.windows(2).all(|w| w[0].0 < w[1].0), "each tick sees newer data: {got:?}");
    assert_eq!(got.last(), Some(&(59, 59)), "the final tick at shutdown sees the newest message");
    assert_eq!(tick.msgs_in + e.dropped_coalesced, 60, "every message is either used or counted as coalesced");
    assert_eq!(tick.msgs_out, got.len() as u64);
    assert_eq!(tick.errors, 0);
}

#[test]
fn deadline_misses_are_counted() {
    let dir = temp_dir("deadline");
    let spec = graph(
        &dir,
        r#"
        [graph]
        mode = "lockstep"
        [[node]]
        id = "c"
        kind = "counter"
        params = { count = 20 }
        [[node]]
        id = "late"
        kind = "delay"
        params = { delay_us = 200.0 }
        deadline_us = 50
        [[node]]
        id = "roomy"
        kind = "scale"
        deadline_us = 1e9
        [[node]]
        id = "out"
        kind = "null"
        [[edge]]
        from = "c.out"
        to = "late.in"
        [[edge]]
        from = "late.out"
        to = "roomy.in"
        [[edge]]
        from = "roomy.out"
        to = "out.in"
        "#,
    );
    let r = run_ok(spec);
    let late = r.stats.node("late").unwrap();
    // Every call busy-waits 200 us against a 50 us budget: all 20 miss.
    assert_eq!((late.calls, late.deadline_misses), (20, 20));
    assert!(late.latency_us_p50 >= 200.0 * 0.9, "p50 {} us", late.latency_us_p50);
    assert_eq!(r.stats.node("roomy").unwrap().deadline_misses, 0);
}

/// Two sources, fan-out, an aligned sum, a chain and two single-input sinks; every edge lossless.
fn lossless_graph(dir: &std::path::Path, mode: Mode) -> skinflow_core::GraphSpec {
    let mut g = graph(
        dir,
        r#"
        [[node]]
        id = "a"
        kind = "counter"
        params = { count = 3000 }
        [[node]]
        id = "b"
        kind = "counter"
        params = { count = 3000, start = 7 }
        [[node]]
        id = "twice"
        kind = "scale"
        params = { factor = 2, add = 1 }
        [[node]]
        id = "sum"
        kind = "sum"
        trigger = "aligned"
        [[node]]
        id = "cube"
        kind = "scale"
        params = { factor = 3 }
        [[node]]
        id = "sums"
        kind = "collect"
        params = { path = "sums.csv" }
        [[node]]
        id = "cubes"
        kind = "collect"
        params = { path = "cubes.csv" }
        [[edge]]
        from = "a.out"
        to = "twice.in"
        capacity = 3
        [[edge]]
        from = "twice.out"
        to = "sum.a"
        [[edge]]
        from = "b.out"
        to = "sum.b"
        capacity = 2
        [[edge]]
        from = "a.out"
        to = "cube.in"
        [[edge]]
        from = "sum.out"
        to = "sums.in"
        [[edge]]
        from = "cube.out"
        to = "cubes.in"
        capacity = 1
        "#,
    );
    g.mode = mode;
    g
}

#[test]
fn lockstep_is_bit_identical_run_to_run_and_matches_the_threaded_run() {
    let outputs = |name: &str, mode: Mode| {
        let dir = temp_dir(name);
        let r = run_ok(lossless_graph(&dir, mode));
        assert_eq!(r.stats.total_drops(), 0, "{name}");
        (std::fs::read(dir.join("sums.csv")).unwrap(), std::fs::read(dir.join("cubes.csv")).unwrap())
    };
    let first = outputs("lockstep-1", Mode::Lockstep);
    let second = outputs("lockstep-2", Mode::Lockstep);
    assert!(first == second, "two lockstep runs differ");
    let threaded = outputs("threaded", Mode::Realtime);
    assert!(first == threaded, "the threaded run of a lossless graph differs from lockstep");
    // And the content is right: sum = (2a + 1) + (a + 7), cube = 3a.
    let sums = String::from_utf8(first.0).unwrap();
    let want: String = (0..3000u64).map(|k| format!("{k},{}\n", 2 * k + 1 + k + 7)).collect();
    assert_eq!(sums, want);
    let cubes = String::from_utf8(first.1).unwrap();
    let want: String = (0..3000u64).map(|k| format!("{k},{}\n", 3 * k)).collect();
    assert_eq!(cubes, want);
}

fn offset_graph(dir: &std::path::Path, mode: &str, source: &str) -> skinflow_core::GraphSpec {
    graph(
        dir,
        &format!(
            r#"
            [graph]
            mode = "{mode}"
            [[node]]
            id = "src"
            {source}
            [[node]]
            id = "off"
            kind = "offset"
            [[node]]
            id = "out"
            kind = "collect"
            params = {{ path = "out.csv" }}
            [[edge]]
            from = "src.out"
            to = "off.in"
            [[edge]]
            from = "off.out"
            to = "out.in"
            "#
        ),
    )
}

#[test]
fn control_commands_reach_processors_and_sources() {
    // Lockstep: commands queued before the run apply before the first message.
    let dir = temp_dir("control-lockstep");
    let g = RunningGraph::start(&offset_graph(&dir, "lockstep", "kind = \"counter\"\nparams = { count = 5 }")).unwrap();
    g.control("off", "add 100").unwrap();
    g.control("off", "add 20").unwrap();
    g.control("out", "tare").unwrap(); // unsupported: a warning, the run goes on
    assert!(matches!(g.control("ghost", "go"), Err(RunError::UnknownNode(n)) if n == "ghost"));
    let r = within(LIMIT, move || g.wait(&RunOptions::default()));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert_eq!(rows(&dir.join("out.csv")), [(0, 120), (1, 121), (2, 122), (3, 123), (4, 124)]);

    // Threaded: the source idles until it is told to go (a lost command would hang).
    let dir = temp_dir("control-threaded");
    let g = RunningGraph::start(&offset_graph(
        &dir,
        "realtime",
        "kind = \"go_source\"\nparams = { key = \"x\", count = 5 }",
    ))
    .unwrap();
    g.control("src", "go").unwrap();
    let r = within(LIMIT, move || g.wait(&RunOptions::default()));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert_eq!(rows(&dir.join("out.csv")), [(0, 0), (1, 1), (2, 2), (3, 3), (4, 4)]);
}

#[test]
fn pinning_and_priority_fall_back_when_refused() {
    // CPU 4095 does not exist and SCHED_FIFO needs privileges: both warn, the node still runs
    // (on its own thread).
    let dir = temp_dir("rt");
    let spec = graph(
        &dir,
        r#"
        [[node]]
        id = "c"
        kind = "counter"
        params = { count = 500 }
        cpu = 4095
        rt_priority = 50
        [[node]]
        id = "pinned"
        kind = "scale"
        cpu = 4095
        rt_priority = 50
        [[node]]
        id = "dedicated"
        kind = "scale"
        thread = "dedicated"
        [[node]]
        id = "out"
        kind = "collect"
        params = { path = "out.csv" }
        [[edge]]
        from = "c.out"
        to = "pinned.in"
        capacity = 2
        [[edge]]
        from = "pinned.out"
        to = "dedicated.in"
        capacity = 2
        [[edge]]
        from = "dedicated.out"
        to = "out.in"
        "#,
    );
    let r = run_ok(spec);
    let want: Vec<(u64, u64)> = (0..500).map(|k| (k, k)).collect();
    assert_eq!(rows(&dir.join("out.csv")), want);
    assert_eq!(r.stats.total_drops(), 0);
}

#[test]
fn stop_request_ends_a_paced_run_with_every_message_delivered() {
    let dir = temp_dir("stop");
    let spec = graph(
        &dir,
        r#"
        [[node]]
        id = "c"
        kind = "counter"
        params = { count = 1000000000, rate_hz = 2000.0 }
        [[node]]
        id = "s"
        kind = "scale"
        [[node]]
        id = "out"
        kind = "collect"
        params = { path = "out.csv" }
        [[edge]]
        from = "c.out"
        to = "s.in"
        [[edge]]
        from = "s.out"
        to = "out.in"
        "#,
    );
    let stop = Arc::new(AtomicBool::new(false));
    let g = RunningGraph::start(&spec).unwrap();
    wait_for("some messages", || g.stats().node("out").unwrap().msgs_in >= 20);
    stop.store(true, SeqCst);
    let opts = RunOptions { duration: None, stop: Some(stop) };
    let r = within(LIMIT, move || g.wait(&opts));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let sent = r.stats.node("c").unwrap().msgs_out;
    let got = rows(&dir.join("out.csv"));
    let want: Vec<(u64, u64)> = (0..sent).map(|k| (k, k)).collect();
    assert_eq!(got, want, "queues drained and the sink flushed at stop");
    assert_eq!(r.stats.total_drops(), 0);

    // The duration option ends the same graph as well.
    let dir = temp_dir("stop-duration");
    let mut spec = spec_with_dir(&dir);
    spec.mode = Mode::Realtime;
    let opts = RunOptions { duration: Some(Duration::from_millis(50)), stop: None };
    let r = within(LIMIT, move || run(&spec, &opts)).unwrap();
    let sent = r.stats.node("c").unwrap().msgs_out;
    assert_eq!(rows(&dir.join("out.csv")).len() as u64, sent);
}

fn spec_with_dir(dir: &std::path::Path) -> skinflow_core::GraphSpec {
    graph(
        dir,
        r#"
        [[node]]
        id = "c"
        kind = "counter"
        params = { count = 1000000000, rate_hz = 2000.0 }
        [[node]]
        id = "out"
        kind = "collect"
        params = { path = "out.csv" }
        [[edge]]
        from = "c.out"
        to = "out.in"
        "#,
    )
}

#[test]
fn stats_report_has_the_documented_shape() {
    let dir = temp_dir("stats");
    let mut spec = lossless_graph(&dir, Mode::Lockstep);
    spec.name = "shape".into();
    let r = run_ok(spec);
    let v = serde_json::to_value(&r.stats).unwrap();
    assert_eq!(v["graph"], "shape");
    assert_eq!(v["mode"], "lockstep");
    assert!(v["wall_s"].as_f64().unwrap() >= 0.0);
    let nodes = v["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 7);
    for n in nodes {
        for key in [
            "id",
            "kind",
            "calls",
            "flushes",
            "msgs_in",
            "msgs_out",
            "errors",
            "panics",
            "restarts",
            "deadline_misses",
            "latency_us_p50",
            "latency_us_p99",
            "latency_us_max",
            "max_queue_depth",
            "discarded",
            "drops",
        ] {
            assert!(n.get(key).is_some(), "node report lacks {key}: {n}");
        }
    }
    let sum = nodes.iter().find(|n| n["id"] == "sum").unwrap();
    assert_eq!((sum["msgs_in"].as_u64(), sum["msgs_out"].as_u64()), (Some(6000), Some(3000)));
    let edges = v["edges"].as_array().unwrap();
    assert_eq!(edges.len(), 6);
    let e = edges.iter().find(|e| e["from"] == "cube.out").unwrap();
    assert_eq!(
        (e["to"].as_str(), e["policy"].as_str(), e["capacity"].as_u64()),
        (Some("cubes.in"), Some("block"), Some(1))
    );
    for key in ["pushed", "max_depth", "dropped_full", "dropped_unaligned", "dropped_coalesced", "undelivered", "drops"]
    {
        assert!(e.get(key).is_some(), "edge report lacks {key}: {e}");
    }
    // The text report names every node.
    let text = r.stats.to_string();
    for id in ["a", "b", "twice", "sum", "cube", "sums", "cubes"] {
        assert!(text.lines().any(|l| l.starts_with(&format!("{id} "))), "{id} missing from:\n{text}");
    }
}
