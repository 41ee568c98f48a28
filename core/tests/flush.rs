//! End of stream: a processor that buffers (the toy `lag`, which always holds its last `by`
//! messages) emits what it holds through `Processor::flush` once its sources are done, in
//! both executors, in topological order (a flushed message goes through the flushing nodes
//! downstream), also after a stop request, a failure upstream or a hot swap; what a node can
//! no longer emit is counted as discarded in the report.
//!
//! No assertion depends on timing: counts are compared with what the source reports it sent.

use crate::kinds;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering::SeqCst};
use std::time::Duration;

use kinds::{graph, rows, temp_dir, wait_for, within};
use skinflow_core::{Mode, Params, RunError, RunOptions, RunReport, RunningGraph, run};

const LIMIT: Duration = Duration::from_secs(60);

/// Counter (`count` messages, `counter` extra params) -> lag(by = 3) -> lag(by = 5) -> collect,
/// every edge of capacity 1, so each flushed message must go downstream before the next
/// flush call has room.
fn lagging(dir: &std::path::Path, mode: Mode, count: u64, counter: &str) -> skinflow_core::GraphSpec {
    let mut g = graph(
        dir,
        &format!(
            r#"
            [[node]]
            id = "c"
            kind = "counter"
            params = {{ count = {count}{counter} }}
            [[node]]
            id = "a"
            kind = "lag"
            params = {{ by = 3 }}
            [[node]]
            id = "b"
            kind = "lag"
            params = {{ by = 5 }}
            [[node]]
            id = "out"
            kind = "collect"
            params = {{ path = "out.csv" }}
            [[edge]]
            from = "c.out"
            to = "a.in"
            capacity = 1
            [[edge]]
            from = "a.out"
            to = "b.in"
            capacity = 1
            [[edge]]
            from = "b.out"
            to = "out.in"
            capacity = 1
            "#
        ),
    );
    g.mode = mode;
    g
}

/// Every message the counter sent, in order, arrived; nothing dropped or discarded.
fn assert_all_delivered(dir: &std::path::Path, r: &RunReport, what: &str) {
    let sent = r.stats.node("c").unwrap().msgs_out;
    let want: Vec<(u64, u64)> = (0..sent).map(|k| (k, k)).collect();
    assert_eq!(rows(&dir.join("out.csv")), want, "{what}");
    for id in ["a", "b"] {
        let n = r.stats.node(id).unwrap();
        assert_eq!((n.msgs_in, n.msgs_out, n.discarded), (sent, sent, 0), "{what}: node {id}");
    }
    assert_eq!(r.stats.total_drops(), 0, "{what}");
}

#[test]
fn flushed_messages_reach_the_sink_through_flushing_nodes_in_both_modes() {
    for mode in [Mode::Lockstep, Mode::Realtime] {
        let dir = temp_dir(&format!("flush-{mode:?}"));
        let spec = lagging(&dir, mode, 100, "");
        let r = within(LIMIT, move || run(&spec, &RunOptions::default())).unwrap();
        assert!(r.failures.is_empty(), "{mode:?}: {:?}", r.failures);
        assert_eq!(r.stats.node("c").unwrap().msgs_out, 100);
        assert_all_delivered(&dir, &r, &format!("{mode:?}"));
        // Each lag's last `by` messages came out of its flush calls, one per call (a's 3 were
        // processed by b: its 100 calls), counted apart from the calls of `process`.
        let calls = |id: &str| {
            let n = r.stats.node(id).unwrap();
            (n.calls, n.flushes)
        };
        assert_eq!((calls("a"), calls("b")), ((100, 3), (100, 5)), "{mode:?}");
        assert_eq!(calls("out"), (100, 0), "{mode:?}: a sink's stop is its flush");
    }
}

#[test]
fn a_stop_request_still_flushes_what_was_received() {
    // Real time: a paced counter, stopped from outside once messages flow.
    let dir = temp_dir("flush-stop-realtime");
    let spec = lagging(&dir, Mode::Realtime, 1_000_000_000, ", rate_hz = 2000.0");
    let g = RunningGraph::start(&spec).unwrap();
    wait_for("some messages", || g.stats().node("out").unwrap().msgs_in >= 20);
    let stop = Arc::new(AtomicBool::new(false));
    stop.store(true, SeqCst);
    let opts = RunOptions { duration: None, stop: Some(stop) };
    let r = within(LIMIT, move || g.wait(&opts));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert_all_delivered(&dir, &r, "realtime, stop request");

    // Lockstep: the duration limit ends a counter that would run for hours.
    let dir = temp_dir("flush-stop-lockstep");
    let spec = lagging(&dir, Mode::Lockstep, 1_000_000_000_000, "");
    let opts = RunOptions { duration: Some(Duration::from_millis(50)), stop: None };
    let r = within(LIMIT, move || run(&spec, &opts)).unwrap();
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert!(r.stats.node("c").unwrap().msgs_out > 8);
    assert_all_delivered(&dir, &r, "lockstep, duration limit");
}

#[test]
fn a_failure_upstream_still_flushes_what_the_node_received() {
    for mode in [Mode::Lockstep, Mode::Realtime] {
        let dir = temp_dir(&format!("flush-fail-{mode:?}"));
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
            params = { at = 50 }
            [[node]]
            id = "a"
            kind = "lag"
            params = { by = 5 }
            [[node]]
            id = "out"
            kind = "collect"
            params = { path = "out.csv" }
            [[edge]]
            from = "c.out"
            to = "f.in"
            [[edge]]
            from = "f.out"
            to = "a.in"
            [[edge]]
            from = "a.out"
            to = "out.in"
            "#,
        );
        spec.mode = mode;
        let r = within(LIMIT, move || run(&spec, &RunOptions::default())).unwrap();
        assert!(matches!(&r.failures[..], [RunError::Node { node, .. }] if node == "f"), "{mode:?}: {:?}", r.failures);
        // The 49 messages before the failure went through `a`, its last 5 by its flush.
        let want: Vec<(u64, u64)> = (0..49).map(|k| (k, k)).collect();
        assert_eq!(rows(&dir.join("out.csv")), want, "{mode:?}");
        assert_eq!(r.stats.node("a").unwrap().discarded, 0, "{mode:?}");
    }
}

/// Counter -> lag(by = 50) -> collect in real time; once 300 messages passed the lag it is
/// swapped for `kind` (`params`). Returns the report and the collected rows.
fn swap_lag(name: &str, kind: &str, params: &str) -> (RunReport, Vec<(u64, u64)>) {
    let dir = temp_dir(&format!("flush-swap-{name}"));
    let spec = graph(
        &dir,
        r#"
        [[node]]
        id = "c"
        kind = "counter"
        params = { count = 2000, rate_hz = 3000.0 }
        [[node]]
        id = "a"
        kind = "lag"
        params = { by = 50 }
        [[node]]
        id = "out"
        kind = "collect"
        params = { path = "out.csv" }
        [[edge]]
        from = "c.out"
        to = "a.in"
        capacity = 8
        [[edge]]
        from = "a.out"
        to = "out.in"
        capacity = 8
        "#,
    );
    let reg = kinds::registry();
    let g = RunningGraph::start(&spec).unwrap();
    let handle = g.handle();
    wait_for("300 messages through the lag", || handle.stats().node("a").unwrap().msgs_out >= 300);
    handle.swap("a", reg.get(kind).unwrap().clone(), Params::from_toml(params).unwrap()).unwrap();
    let r = within(LIMIT, move || g.wait(&RunOptions::default()));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert_eq!(r.stats.node("a").unwrap().swaps, 1);
    (r, rows(&dir.join("out.csv")))
}

#[test]
fn a_swapped_in_replacement_flushes_what_it_took_over() {
    // The replacement takes over the 50 held messages and holds 10 from then on: every
    // message arrives once, in order, the last 10 by its flush.
    let (r, got) = swap_lag("handover", "lag", "by = 10");
    let want: Vec<(u64, u64)> = (0..2000).map(|k| (k, k)).collect();
    assert_eq!(got, want);
    assert_eq!((r.stats.node("a").unwrap().discarded, r.stats.total_drops()), (0, 0));
}

#[test]
fn what_a_node_cannot_emit_is_counted_as_discarded() {
    // `scale` refuses the lag's state: the 50 messages held at the swap go back to the old
    // instance, which is stopped without a flush and counts them; the report shows them.
    let (r, got) = swap_lag("refused", "scale", "");
    let a = r.stats.node("a").unwrap();
    assert_eq!(a.discarded, 50);
    assert_eq!(a.drops, 50, "a node's drops include what it discarded");
    assert_eq!(r.stats.total_drops(), 50);
    assert_eq!(got.len(), 2000 - 50);
    let text = r.stats.to_string();
    assert!(text.contains("discarded by nodes (held or received, never emitted; sources: records lost on their link):\n  a (scale): 50"), "{text}");
    // Exactly the held ones are missing: the 50 before the first message the replacement saw.
    let gap = got.windows(2).position(|w| w[1].0 != w[0].0 + 1).expect("a gap of 50");
    assert_eq!(got[gap + 1].0 - got[gap].0, 51, "{:?}", &got[gap..gap + 2]);
}
