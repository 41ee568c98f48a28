//! Faults: a panicking node is isolated and reported by id (the graph stops, never hangs), or
//! restarted when the graph says `restart = "always"`; a node that fails to build or start
//! stops the run before any data flows, naming the node and the cause.

use crate::kinds;

use std::sync::atomic::Ordering::SeqCst;
use std::time::Duration;

use kinds::{graph, probe, rows, temp_dir, within};
use skinflow_core::{Mode, NodeError, RunError, RunOptions, RunningGraph, run};

const LIMIT: Duration = Duration::from_secs(60);

/// Counter -> panicker (panics on its 5th message) -> collect. The counter would run for
/// hours: only a graph that stops on the panic lets the test finish.
fn panicking(dir: &std::path::Path, mode: Mode, restart: &str, count: u64) -> skinflow_core::GraphSpec {
    let mut g = graph(
        dir,
        &format!(
            r#"
            [[node]]
            id = "c"
            kind = "counter"
            params = {{ count = {count} }}
            [[node]]
            id = "p"
            kind = "panicker"
            params = {{ at = 5 }}
            restart = "{restart}"
            [[node]]
            id = "out"
            kind = "collect"
            params = {{ path = "out.csv" }}
            [[edge]]
            from = "c.out"
            to = "p.in"
            [[edge]]
            from = "p.out"
            to = "out.in"
            "#
        ),
    );
    g.mode = mode;
    g
}

#[test]
fn a_panicking_node_is_reported_by_id_and_stops_the_graph() {
    for mode in [Mode::Realtime, Mode::Lockstep] {
        let dir = temp_dir(&format!("panic-{mode:?}"));
        let spec = panicking(&dir, mode, "never", 1_000_000_000_000);
        let r = within(LIMIT, move || run(&spec, &RunOptions::default())).unwrap();
        assert_eq!(r.failures.len(), 1, "{mode:?}: {:?}", r.failures);
        let f = &r.failures[0];
        match f {
            RunError::Node { node, error: NodeError::Panic(msg) } => {
                assert_eq!(node, "p");
                assert!(msg.contains("panicker reached message 5"), "{msg}");
            }
            other => panic!("{mode:?}: unexpected failure {other:?}"),
        }
        assert!(f.to_string().starts_with("node \"p\": panicked: panicker reached message 5"), "{f}");
        let p = r.stats.node("p").unwrap();
        assert_eq!((p.panics, p.restarts, p.msgs_out), (1, 0, 4), "{mode:?}");
        // The four messages before the panic were delivered and the sink flushed them.
        assert_eq!(rows(&dir.join("out.csv")), [(0, 0), (1, 1), (2, 2), (3, 3)], "{mode:?}");
        // What the dead node never took is accounted for, not silently lost.
        let e = r.stats.edges.iter().find(|e| e.to == "p.in").unwrap();
        let sent = r.stats.node("c").unwrap().msgs_out;
        assert_eq!(e.pushed, sent);
        assert_eq!(p.msgs_in + e.undelivered, sent, "{mode:?}");
    }
}

#[test]
fn restart_always_rebuilds_the_node_and_data_keeps_flowing() {
    for mode in [Mode::Lockstep, Mode::Realtime] {
        let dir = temp_dir(&format!("restart-{mode:?}"));
        // 23 messages; each instance panics on its 5th: messages 4, 9, 14 and 19 are lost
        // to four panics, each followed by a restart.
        let spec = panicking(&dir, mode, "always", 23);
        let r = within(LIMIT, move || run(&spec, &RunOptions::default())).unwrap();
        assert!(r.failures.is_empty(), "{mode:?}: {:?}", r.failures);
        let p = r.stats.node("p").unwrap();
        assert_eq!((p.panics, p.restarts, p.msgs_in, p.msgs_out), (4, 4, 23, 19), "{mode:?}");
        let want: Vec<(u64, u64)> = (0..23).filter(|k| k % 5 != 4).map(|k| (k, k)).collect();
        assert_eq!(rows(&dir.join("out.csv")), want, "{mode:?}");
    }
}

#[test]
fn a_sink_that_cannot_start_stops_the_run_before_any_data_flows() {
    let dir = temp_dir("start-failure");
    let missing = dir.join("missing-dir").join("out.csv");
    // Start order is sinks first: "ok" starts, then "bad" fails, so "ok" must be stopped and
    // the source never started nor polled.
    let spec = graph(
        &dir,
        &format!(
            r#"
            [[node]]
            id = "src"
            kind = "probe_source"
            params = {{ key = "start-src", count = 10 }}
            [[node]]
            id = "bad"
            kind = "collect"
            params = {{ path = "{}" }}
            [[node]]
            id = "ok"
            kind = "probe_sink"
            params = {{ key = "start-sink" }}
            [[edge]]
            from = "src.out"
            to = "bad.in"
            [[edge]]
            from = "src.out"
            to = "ok.in"
            "#,
            missing.display()
        ),
    );
    let err = RunningGraph::start(&spec).err().expect("the run must not start");
    match &err {
        RunError::Start { node, kind, error: NodeError::Path { path, problem } } => {
            assert_eq!((node.as_str(), kind.as_str()), ("bad", "collect"));
            assert_eq!(path, &missing);
            assert!(problem.starts_with("cannot create"), "{problem}");
        }
        other => panic!("unexpected error {other:?}"),
    }
    let msg = err.to_string();
    assert!(msg.starts_with("node \"bad\" (kind \"collect\") failed to start: "), "{msg}");
    assert!(msg.contains(&missing.display().to_string()), "{msg}");
    let (src, sink) = (probe("start-src"), probe("start-sink"));
    assert_eq!((src.starts.load(SeqCst), src.polls.load(SeqCst)), (0, 0), "no data flowed");
    assert_eq!((sink.starts.load(SeqCst), sink.stops.load(SeqCst), sink.msgs.load(SeqCst)), (1, 1, 0));
    assert!(!missing.exists());
}

#[test]
fn a_node_that_cannot_be_built_is_named_with_its_cause() {
    let dir = temp_dir("build-failure");
    let spec = graph(
        &dir,
        r#"
        [[node]]
        id = "src"
        kind = "probe_source"
        params = { key = "build-src", count = 10 }
        [[node]]
        id = "dev"
        kind = "broken"
        [[node]]
        id = "out"
        kind = "probe_sink"
        params = { key = "build-sink" }
        [[edge]]
        from = "src.out"
        to = "dev.in"
        [[edge]]
        from = "dev.out"
        to = "out.in"
        "#,
    );
    let err = RunningGraph::start(&spec).err().expect("the run must not start");
    assert_eq!(
        err.to_string(),
        "node \"dev\" (kind \"broken\") failed to start: /dev/skinflow-missing: no such device"
    );
    // Building happens before anything starts.
    assert_eq!(probe("build-src").starts.load(SeqCst), 0);
    assert_eq!(probe("build-sink").starts.load(SeqCst), 0);
}

#[test]
fn a_fatal_error_stops_the_graph_and_the_sink_is_still_flushed() {
    for mode in [Mode::Realtime, Mode::Lockstep] {
        let dir = temp_dir(&format!("fatal-{mode:?}"));
        let mut spec = graph(
            &dir,
            r#"
            [[node]]
            id = "c"
            kind = "counter"
            params = { count = 1000000000000 }
            [[node]]
            id = "f"
            kind = "fails"
            params = { at = 3 }
            [[node]]
            id = "out"
            kind = "collect"
            params = { path = "out.csv" }
            [[edge]]
            from = "c.out"
            to = "f.in"
            [[edge]]
            from = "f.out"
            to = "out.in"
            "#,
        );
        spec.mode = mode;
        let r = within(LIMIT, move || run(&spec, &RunOptions::default())).unwrap();
        assert_eq!(r.failures.len(), 1, "{mode:?}: {:?}", r.failures);
        assert_eq!(r.failures[0].to_string(), "node \"f\": device lost at message 3");
        assert!(matches!(&r.failures[0], RunError::Node { error, .. } if error.is_fatal()));
        assert_eq!(rows(&dir.join("out.csv")), [(0, 0), (1, 1)], "{mode:?}");
    }
}

#[test]
fn a_non_fatal_error_is_counted_and_the_run_goes_on() {
    let dir = temp_dir("errors");
    // `sum` with the default trigger (any) sees one input per call, so every call fails with
    // "no message" on the other port: counted, inputs dropped, the run completes.
    let spec = graph(
        &dir,
        r#"
        [graph]
        mode = "lockstep"
        [[node]]
        id = "a"
        kind = "stamped"
        params = { seq = [0, 1, 2], t_ns = [0, 1, 2] }
        [[node]]
        id = "b"
        kind = "stamped"
        params = { seq = [0, 1, 2], t_ns = [0, 1, 2] }
        [[node]]
        id = "s"
        kind = "sum"
        [[node]]
        id = "out"
        kind = "collect"
        params = { path = "out.csv" }
        [[edge]]
        from = "a.out"
        to = "s.a"
        [[edge]]
        from = "b.out"
        to = "s.b"
        [[edge]]
        from = "s.out"
        to = "out.in"
        "#,
    );
    let r = within(LIMIT, move || run(&spec, &RunOptions::default())).unwrap();
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let s = r.stats.node("s").unwrap();
    assert_eq!((s.calls, s.errors, s.msgs_in, s.msgs_out), (6, 6, 6, 0));
    assert!(rows(&dir.join("out.csv")).is_empty());
}

#[test]
fn a_graph_dropped_without_wait_stops_its_threads() {
    let dir = temp_dir("drop");
    let spec = graph(
        &dir,
        r#"
        [[node]]
        id = "src"
        kind = "probe_source"
        params = { key = "drop-src", count = 1000000000000 }
        [[node]]
        id = "s"
        kind = "offset"
        [[node]]
        id = "out"
        kind = "null"
        [[edge]]
        from = "src.out"
        to = "s.in"
        [[edge]]
        from = "s.out"
        to = "out.in"
        "#,
    );
    let g = RunningGraph::start(&spec).unwrap();
    kinds::wait_for("the source to run", || probe("drop-src").polls.load(SeqCst) > 10);
    // Dropping joins the source thread, which stops its node on the way out.
    within(LIMIT, move || drop(g));
    let src = probe("drop-src");
    assert_eq!(src.stops.load(SeqCst), 1, "the source thread was joined");
    let polls = src.polls.load(SeqCst);
    std::thread::sleep(Duration::from_millis(20));
    assert_eq!(src.polls.load(SeqCst), polls, "nothing polls after the drop");
}
