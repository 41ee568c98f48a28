//! Hot-swap latency: from `GraphHandle::swap` (build + start of the replacement included) to
//! the swap being applied between two calls of the running node, in a pooled chain that keeps
//! flowing at 10 kHz. The data path never waits for the build: only the install is on it.

use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Params, Registry, RunOptions, RunningGraph};

fn swap_latency(c: &mut Criterion) {
    let mut reg = Registry::new();
    skinflow_core::toy::register(&mut reg).unwrap();
    let graph = "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = { count = 100000000, rate_hz = 10000.0 }\n\
        [[node]]\nid = \"f\"\nkind = \"scale\"\n\
        [[node]]\nid = \"out\"\nkind = \"null\"\n\
        [[edge]]\nfrom = \"src.out\"\nto = \"f.in\"\n\
        [[edge]]\nfrom = \"f.out\"\nto = \"out.in\"\n";
    let spec = GraphSpec::parse(SourceFile::new("swap.toml", graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let scale = reg.get("scale").unwrap().clone();
    let mut k = 0u64;
    c.bench_function("swap_applied_at_10khz", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                k += 1;
                let before = handle.stats().node("f").unwrap().swaps;
                let params = Params::from_toml(&format!("add = {k}")).unwrap();
                let t0 = Instant::now();
                handle.swap("f", scale.clone(), params).unwrap();
                while handle.stats().node("f").unwrap().swaps == before {
                    std::hint::spin_loop();
                }
                total += t0.elapsed();
            }
            total
        })
    });
    let report = running.wait(&RunOptions { duration: Some(Duration::from_millis(1)), stop: None });
    assert_eq!(report.stats.total_drops(), 0, "a swap drops nothing");
}

criterion_group!(benches, swap_latency);
criterion_main!(benches);
