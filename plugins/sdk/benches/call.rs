//! Call overhead of a plugin node over a built-in one: a no-op processor called directly
//! through `Box<dyn Processor>`, and the same no-op as a plugin kind called through the
//! host wrapper and the C function table (the path of a loaded library: encode inputs, call
//! the `extern "C"` shim under `catch_unwind`, read the outputs). The table is built in this
//! binary with the SDK's export code instead of `dlopen`ed; a call through a function pointer
//! costs the same either way.
//!
//! `count_10k_*` run a lockstep graph `counter (10 000) -> X -> null` with X the built-in toy
//! `scale` or a plugin kind doing the same on the `count` codec (one column in, one out): the
//! per-message cost of the whole plugin path, codecs included.
//!
//! `cargo bench -p skinflow-plugin-sdk --features host --bench call`

use std::hint::black_box;
use std::path::Path;
use std::sync::OnceLock;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::{
    BuildContext, Context, GraphSpec, Inputs, Mode, NodeError, NodeImpl, Outputs, Params, Processor, Registry,
    RunOptions,
};
use skinflow_plugin_sdk::export::{Table, entry, kind};
use skinflow_plugin_sdk::host::{Codecs, read_table, register_kinds};
use skinflow_plugin_sdk::{Columns, KindSpec, PluginNode};

struct BuiltinNoop;

impl Processor for BuiltinNoop {
    fn process(&mut self, _ctx: &mut Context, _inputs: &Inputs, _out: &mut Outputs) -> Result<(), NodeError> {
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

struct PluginNoop;

impl PluginNode for PluginNoop {
    type Params = NoParams;

    fn spec() -> KindSpec {
        KindSpec::new("bench-noop", "does nothing")
    }

    fn new(_: NoParams, _: &Path) -> Result<Self, String> {
        Ok(PluginNoop)
    }

    fn process(&mut self, _inputs: &[Columns<'_>], _out: &mut skinflow_plugin_sdk::Outputs) -> Result<(), String> {
        Ok(())
    }
}

/// `value * 1` on a count, as a plugin kind.
struct PluginScale;

impl PluginNode for PluginScale {
    type Params = NoParams;

    fn spec() -> KindSpec {
        KindSpec::new("bench-scale", "value * 1").input("in", "count", "a count").output(
            "out",
            "count",
            "the same count",
        )
    }

    fn new(_: NoParams, _: &Path) -> Result<Self, String> {
        Ok(PluginScale)
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut skinflow_plugin_sdk::Outputs) -> Result<(), String> {
        let v = inputs[0].scalar("value")?;
        out.port(0).scalar("value", v);
        Ok(())
    }
}

const MESSAGES: u64 = 10_000;

fn graph(reg: &Registry, middle: &str) -> GraphSpec {
    let text = format!(
        "[graph]\nname = \"bench\"\nmode = \"lockstep\"\n\n\
         [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = {MESSAGES} }}\n\n\
         [[node]]\nid = \"mid\"\nkind = \"{middle}\"\n\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"mid.in\"\n\n[[edge]]\nfrom = \"mid.out\"\nto = \"out.in\"\n"
    );
    GraphSpec::parse(SourceFile::new("<bench>", text), reg).expect("valid bench graph")
}

fn registry() -> Registry {
    static TABLE: OnceLock<Table> = OnceLock::new();
    let table = entry(&TABLE, "bench", "0", || vec![kind::<PluginNoop>(), kind::<PluginScale>()]);
    // SAFETY: `entry` returned a pointer to the static table above (non-null: it did not panic).
    let table = unsafe { &*table };
    let path = Path::new("<bench>");
    let kinds = read_table(path, table, &Codecs::new()).expect("valid table");
    let mut reg = Registry::new();
    skinflow_core::toy::register(&mut reg).expect("toy kinds");
    register_kinds(path, kinds, &mut reg).expect("no duplicates");
    reg
}

fn plugin_node() -> Box<dyn Processor> {
    let reg = registry();
    let ctx = BuildContext::new(".", Mode::Lockstep, "noop");
    match reg.get("bench-noop").expect("registered").build(&Params::empty(), &ctx) {
        Ok(NodeImpl::Processor(p)) => p,
        _ => panic!("plugin kind did not build a processor"),
    }
}

fn bench(c: &mut Criterion) {
    let mut ctx = Context::detached("noop", Mode::Lockstep);
    let inputs = Inputs::default();
    let mut out = Outputs::default();
    let mut g = c.benchmark_group("call");
    let mut builtin: Box<dyn Processor> = Box::new(BuiltinNoop);
    g.bench_function("noop_builtin", |b| {
        b.iter(|| black_box(&mut builtin).process(&mut ctx, black_box(&inputs), &mut out))
    });
    let mut plugin = plugin_node();
    g.bench_function("noop_plugin", |b| {
        b.iter(|| black_box(&mut plugin).process(&mut ctx, black_box(&inputs), &mut out))
    });
    g.finish();
    let reg = registry();
    let mut g = c.benchmark_group("graph");
    g.throughput(Throughput::Elements(MESSAGES));
    g.sample_size(20);
    for (name, kind) in [("count_10k_builtin", "scale"), ("count_10k_plugin", "bench-scale")] {
        let spec = graph(&reg, kind);
        g.bench_function(name, |b| {
            b.iter(|| {
                let r = skinflow_core::run(&spec, &RunOptions::default()).expect("runs");
                assert!(r.failures.is_empty());
                r
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
