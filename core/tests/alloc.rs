//! Zero heap allocations per message in steady state on the engine's path.
//!
//! A counting global allocator (this test binary only) counts every allocation. A run's
//! total is fixed cost (building nodes, queues, threads) plus a per-message cost; running the
//! same chain with few and with many messages and subtracting leaves the per-message cost,
//! which must be zero. The toy nodes fill payloads from a `Recycler`, so every allocation left
//! would be the engine's.

use skinflow_core::alloc_count::CountingAlloc;
use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Mode, Registry, RunOptions, run};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

/// Counter -> scale x4 -> null, lossless edges of capacity 16 (the toy recyclers hold 256
/// buffers, more than can be in flight).
fn chain(count: u64, mode: Mode) -> GraphSpec {
    let mode = match mode {
        Mode::Lockstep => "mode = \"lockstep\"",
        Mode::Realtime => "mode = \"realtime\"\n        workers = 2",
    };
    let text = format!(
        r#"
        [graph]
        {mode}
        [[node]]
        id = "src"
        kind = "counter"
        params = {{ count = {count} }}
        [[node]]
        id = "s1"
        kind = "scale"
        params = {{ factor = 3 }}
        [[node]]
        id = "s2"
        kind = "scale"
        params = {{ add = 1 }}
        [[node]]
        id = "s3"
        kind = "scale"
        [[node]]
        id = "s4"
        kind = "scale"
        deadline_us = 1000
        [[node]]
        id = "sink"
        kind = "null"
        [[edge]]
        from = "src.out"
        to = "s1.in"
        capacity = 16
        [[edge]]
        from = "s1.out"
        to = "s2.in"
        capacity = 16
        [[edge]]
        from = "s2.out"
        to = "s3.in"
        capacity = 16
        policy = "drop_oldest"
        [[edge]]
        from = "s3.out"
        to = "s4.in"
        capacity = 16
        [[edge]]
        from = "s4.out"
        to = "sink.in"
        capacity = 16
        "#
    );
    let mut reg = Registry::new();
    skinflow_core::toy::register(&mut reg).unwrap();
    GraphSpec::parse(SourceFile::new("alloc.toml", text), &reg).unwrap()
}

/// Allocations made by building, running and reporting a chain of `count` messages: by the
/// calling thread (all of a lockstep run) and by every thread (a pooled run; this includes
/// whatever the test harness's own threads happen to do meanwhile).
fn allocations(count: u64, mode: Mode) -> (u64, u64) {
    let spec = chain(count, mode);
    let (all, mine) = (CountingAlloc::total(), CountingAlloc::this_thread());
    let report = run(&spec, &RunOptions::default()).unwrap();
    let (all, mine) = (CountingAlloc::total() - all, CountingAlloc::this_thread() - mine);
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    let sink = report.stats.node("sink").unwrap();
    assert_eq!(sink.msgs_in + report.stats.total_drops(), count);
    (mine, all)
}

/// One test, so no other test's allocations run concurrently with a measurement.
#[test]
fn no_allocation_per_message_in_steady_state() {
    // Lockstep: everything runs on this thread, deterministically; the totals must be equal.
    allocations(1_000, Mode::Lockstep); // warm-up: lazily initialised statics
    let (small, _) = allocations(1_000, Mode::Lockstep);
    let (large, _) = allocations(100_000, Mode::Lockstep);
    assert_eq!(large, small, "lockstep: {} allocations for 99,000 more messages", large as i64 - small as i64);

    // Pooled: sources and workers on their own threads hand nodes to each other through
    // lock-free queues. Count every thread; stray allocations elsewhere in the process only
    // ever add, so the smallest of a few runs of each size is the engine's own count. A few
    // allocations per run still move between runs with thread timing: the work-stealing
    // deques' epoch collector (crossbeam-epoch) registers each thread when it first steals,
    // and frees exited threads' records in batches, allocating a batch node in whichever run
    // fills one. A CI machine once saw 2 more in the large run. That cost is per run, not per
    // message: one allocation per message would add 99,000, one per thousand messages 99, and
    // a buffer that grows by doubling with the messages (never cleared) about 7 (100x more).
    const PER_RUN_SLACK: u64 = 4;
    let min_of = |count: u64| (0..5).map(|_| allocations(count, Mode::Realtime).1).min().unwrap();
    min_of(100_000);
    let small = min_of(1_000);
    let large = min_of(100_000);
    eprintln!("pooled: {small} allocations for 1,000 messages, {large} for 100,000");
    assert!(
        large <= small + PER_RUN_SLACK,
        "pooled: {} allocations for 99,000 more messages (at most {PER_RUN_SLACK} allowed, per run)",
        large as i64 - small as i64
    );
}
