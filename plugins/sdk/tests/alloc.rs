//! Zero heap allocations per message in steady state through hosted plugin nodes, including
//! the provenance lookup of derived outputs among the retained earlier inputs: a counting
//! global allocator (this test binary only); the same lockstep chain with few and with many
//! messages must allocate the same (building and reporting are fixed costs).

mod common;
#[path = "common/late.rs"]
mod late;

use std::path::Path;
use std::sync::OnceLock;

use serde::Deserialize;
use skinflow_core::alloc_count::CountingAlloc;
use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Registry, RunOptions};
use skinflow_plugin_sdk::export::{Table, kind, sink};
use skinflow_plugin_sdk::{Columns, KindSpec, PluginSink};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

/// Checks each derived payload's provenance (value = seq + 1) and keeps nothing.
struct Check;

impl PluginSink for Check {
    type Params = NoParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-check", "checks derived payloads").input("in", "derived", "derived payloads")
    }

    fn new(_: NoParams, _: &Path) -> Result<Self, String> {
        Ok(Check)
    }

    fn consume(&mut self, inputs: &[Columns<'_>]) -> Result<(), String> {
        let (seq, from) = (inputs[0].seq(), inputs[0].scalar("from")?);
        if from == (seq + 1) as f64 { Ok(()) } else { Err("wrong provenance".into()) }
    }
}

fn registry() -> Registry {
    static TABLE: OnceLock<Table> = OnceLock::new();
    common::registry(&TABLE, "alloc", "liballoc.so", || vec![kind::<late::Late>(), sink::<Check>()])
}

/// Allocations on this thread (all of a lockstep run) by running counter -> t-late (lag 5) ->
/// t-check with `count` messages.
fn allocations(reg: &Registry, count: u64) -> u64 {
    let text = format!(
        "[graph]\nname = \"alloc\"\nmode = \"lockstep\"\n\n\
         [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = {count}, start = 1 }}\n\n\
         [[node]]\nid = \"lag\"\nkind = \"t-late\"\nparams = {{ lag = 5 }}\n\n\
         [[node]]\nid = \"check\"\nkind = \"t-check\"\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"lag.in\"\ncapacity = 16\n\n\
         [[edge]]\nfrom = \"lag.out\"\nto = \"check.in\"\ncapacity = 16\n"
    );
    let spec = GraphSpec::parse(SourceFile::new("alloc.toml", text), reg).unwrap();
    let before = CountingAlloc::this_thread();
    let report = skinflow_core::run(&spec, &RunOptions::default()).unwrap();
    let n = CountingAlloc::this_thread() - before;
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    let (lag, check) = (report.stats.node("lag").unwrap(), report.stats.node("check").unwrap());
    assert_eq!((lag.msgs_out, lag.errors, check.msgs_in, check.errors), (count, 0, count, 0));
    n
}

#[test]
fn hosted_plugins_and_provenance_lookup_allocate_nothing_per_message() {
    let reg = registry();
    allocations(&reg, 1_000); // warm-up: lazily initialised statics
    let small = allocations(&reg, 1_000);
    let large = allocations(&reg, 20_000);
    assert_eq!(large, small, "{} allocations for 19,000 more messages", large as i64 - small as i64);
}
