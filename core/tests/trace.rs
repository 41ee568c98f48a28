//! Observability: every node call (end-of-stream flush calls included) runs inside a tracing
//! span named `node` whose `id` field is the node's id. Its own test binary, because the subscriber is process-wide.

#[path = "support/kinds.rs"]
mod kinds;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering::SeqCst};
use std::sync::{Arc, Mutex};

use kinds::{graph, temp_dir};
use skinflow_core::{RunOptions, run};

/// Counts `node` spans by their `id` field.
#[derive(Default)]
struct SpanCounter {
    spans: Mutex<BTreeMap<String, u64>>,
    next: AtomicU64,
}

struct IdField(String);

impl tracing::field::Visit for IdField {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "id" {
            self.0 = format!("{value:?}");
        }
    }
}

impl tracing::Subscriber for SpanCounter {
    fn enabled(&self, _: &tracing::Metadata<'_>) -> bool {
        true
    }
    fn new_span(&self, span: &tracing::span::Attributes<'_>) -> tracing::span::Id {
        if span.metadata().name() == "node" {
            let mut id = IdField(String::new());
            span.record(&mut id);
            *self.spans.lock().unwrap().entry(id.0).or_default() += 1;
        }
        tracing::span::Id::from_u64(self.next.fetch_add(1, SeqCst) + 1)
    }
    fn record(&self, _: &tracing::span::Id, _: &tracing::span::Record<'_>) {}
    fn record_follows_from(&self, _: &tracing::span::Id, _: &tracing::span::Id) {}
    fn event(&self, _: &tracing::Event<'_>) {}
    fn enter(&self, _: &tracing::span::Id) {}
    fn exit(&self, _: &tracing::span::Id) {}
}

#[test]
fn every_node_call_has_a_tracing_span_named_after_the_node() {
    let counter = Arc::new(SpanCounter::default());
    tracing::subscriber::set_global_default(counter.clone()).unwrap();
    let dir = temp_dir("spans");
    // Threaded: sources, workers and a node on a dedicated thread all report to the subscriber.
    let spec = graph(
        &dir,
        r#"
        [[node]]
        id = "src"
        kind = "counter"
        params = { count = 300 }
        [[node]]
        id = "twice"
        kind = "scale"
        params = { factor = 2 }
        [[node]]
        id = "own-thread"
        kind = "scale"
        thread = "dedicated"
        [[node]]
        id = "out"
        kind = "null"
        [[edge]]
        from = "src.out"
        to = "twice.in"
        [[edge]]
        from = "twice.out"
        to = "own-thread.in"
        [[edge]]
        from = "own-thread.out"
        to = "out.in"
        "#,
    );
    let r = run(&spec, &RunOptions::default()).unwrap();
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let spans = counter.spans.lock().unwrap().clone();
    for n in &r.stats.nodes {
        assert!(n.calls > 0);
        // Processors are flushed once at end of stream (`scale` has nothing to emit).
        assert_eq!(n.flushes, u64::from(n.kind == "scale"), "{}", n.id);
        assert_eq!(spans.get(&n.id).copied(), Some(n.calls + n.flushes), "spans of {}: {spans:?}", n.id);
    }
}
