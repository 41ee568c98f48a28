//! Zero heap allocations per message in steady state through hosted plugin nodes, including
//! the provenance lookup of derived outputs among the retained earlier inputs: a counting
//! global allocator (this test binary only); the same lockstep chain with few and with many
//! messages must allocate the same (building and reporting are fixed costs).

mod common;

use std::collections::VecDeque;
use std::path::Path;
use std::sync::OnceLock;

use serde::Deserialize;
use skinflow_core::alloc_count::CountingAlloc;
use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Registry, RunOptions};
use skinflow_plugin_sdk::export::{Table, kind, sink};
use skinflow_plugin_sdk::{Columns, Flush, KindSpec, Outputs, PluginNode, PluginSink};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LagParams {
    lag: usize,
}

/// Emits each input `lag` calls later under its own header, as a derived payload (whose
/// provenance the host then finds among the retained inputs); the rest at flush.
struct Lag {
    lag: usize,
    held: VecDeque<(u64, u64)>,
}

impl Lag {
    fn emit(&mut self, out: &mut Outputs) {
        if let Some((seq, t_ns)) = self.held.pop_front() {
            out.port(0).header(seq, t_ns);
            out.port(0).scalar("from", 0.0);
        }
    }
}

impl PluginNode for Lag {
    type Params = LagParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-lag", "emits each input lag calls later")
            .input("in", "count", "values")
            .output("out", "derived", "the value of the input it was made from")
            .param("lag", "integer", "", "calls an input is held")
    }

    fn new(p: LagParams, _: &Path) -> Result<Self, String> {
        Ok(Lag { lag: p.lag, held: VecDeque::with_capacity(p.lag + 1) })
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String> {
        self.held.push_back((inputs[0].seq(), inputs[0].t_ns()));
        if self.held.len() > self.lag {
            self.emit(out);
        }
        Ok(())
    }

    fn flush(&mut self, out: &mut Outputs) -> Result<Flush, String> {
        self.emit(out);
        Ok(if self.held.is_empty() { Flush::Done } else { Flush::More })
    }

    fn held(&self) -> u64 {
        self.held.len() as u64
    }
}

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
    common::registry(&TABLE, "alloc", "liballoc.so", || vec![kind::<Lag>(), sink::<Check>()])
}

/// Allocations on this thread (all of a lockstep run) by running counter -> t-lag (lag 5) ->
/// t-check with `count` messages.
fn allocations(reg: &Registry, count: u64) -> u64 {
    let text = format!(
        "[graph]\nname = \"alloc\"\nmode = \"lockstep\"\n\n\
         [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = {count}, start = 1 }}\n\n\
         [[node]]\nid = \"lag\"\nkind = \"t-lag\"\nparams = {{ lag = 5 }}\n\n\
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
