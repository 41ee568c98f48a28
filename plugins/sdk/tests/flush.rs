//! A plugin processor's end-of-stream flush through the engine (lockstep), on a table built in
//! this binary by the SDK's export code (the same bytes a plugin's entry point returns). The
//! kind under test, `t-hold`, emits nothing from `process`: it holds every input and emits the
//! held messages only at flush, one per call. Every input arrives downstream, in order and with
//! its header, also through a second holding plugin and a built-in node; a flush error is
//! counted, ends the node's flush, and what the node still holds is counted as discarded at
//! stop; a flush panic stops the graph (`restart = "never"`) or rebuilds the node
//! (`restart = "always"`); an output that needs its inputs' provenance cannot be emitted at
//! flush once its input left the host's window of retained inputs (an error, and the rest
//! counted as discarded; within the window it can, `tests/provenance.rs`).

use crate::common;

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::stats::NodeReport;
use skinflow_core::{GraphSpec, Registry, RunOptions, RunReport};
use skinflow_plugin_sdk::export::{Table, kind, sink};
use skinflow_plugin_sdk::{Columns, Flush, KindSpec, Outputs, PluginNode, PluginSink};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HoldParams {
    /// Flush call (1-based) that returns an error; 0 = never.
    #[serde(default)]
    error_at_flush: u64,
    /// Flush call (1-based) that panics; 0 = never.
    #[serde(default)]
    panic_at_flush: u64,
}

/// Holds every input (seq, t_ns, value); emits them at flush, one per call, in order, each
/// with the header of the input it came from.
struct Hold {
    p: HoldParams,
    held: VecDeque<(u64, u64, f64)>,
    flushes: u64,
}

impl Hold {
    fn new(p: HoldParams) -> Hold {
        Hold { p, held: VecDeque::new(), flushes: 0 }
    }

    fn process(&mut self, inputs: &[Columns<'_>]) -> Result<(), String> {
        let c = &inputs[0];
        self.held.push_back((c.seq(), c.t_ns(), c.scalar("value")?));
        Ok(())
    }

    fn flush(&mut self, out: &mut Outputs) -> Result<Flush, String> {
        self.flushes += 1;
        if self.flushes == self.p.panic_at_flush {
            panic!("flush panic at {}", self.flushes);
        }
        if self.flushes == self.p.error_at_flush {
            return Err(format!("flush error at {}", self.flushes));
        }
        if let Some((seq, t_ns, v)) = self.held.pop_front() {
            out.port(0).header(seq, t_ns);
            out.port(0).scalar("value", v);
        }
        Ok(if self.held.is_empty() { Flush::Done } else { Flush::More })
    }
}

impl PluginNode for Hold {
    type Params = HoldParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-hold", "holds every input; emits them at flush").input("in", "count", "values").output(
            "out",
            "count",
            "the same values, at end of stream",
        )
    }

    fn new(p: HoldParams, _: &Path) -> Result<Self, String> {
        Ok(Hold::new(p))
    }

    fn process(&mut self, inputs: &[Columns<'_>], _out: &mut Outputs) -> Result<(), String> {
        Hold::process(self, inputs)
    }

    fn flush(&mut self, out: &mut Outputs) -> Result<Flush, String> {
        Hold::flush(self, out)
    }

    fn held(&self) -> u64 {
        self.held.len() as u64
    }
}

/// `t-hold` with an output of a payload derived from inputs (like `split`).
struct HoldDerived(Hold);

impl PluginNode for HoldDerived {
    type Params = HoldParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-hold-derived", "holds every input; emits a derived payload at flush")
            .input("in", "count", "values")
            .output("out", "derived", "needs its input")
    }

    fn new(p: HoldParams, _: &Path) -> Result<Self, String> {
        Ok(HoldDerived(Hold::new(p)))
    }

    fn process(&mut self, inputs: &[Columns<'_>], _out: &mut Outputs) -> Result<(), String> {
        self.0.process(inputs)
    }

    fn flush(&mut self, out: &mut Outputs) -> Result<Flush, String> {
        self.0.flush(out)
    }

    fn held(&self) -> u64 {
        self.0.held.len() as u64
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

/// Consumes derived payloads (none arrive here: they are held beyond the provenance window).
struct DropDerived;

impl PluginSink for DropDerived {
    type Params = NoParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-drop-derived", "consumes derived payloads").input("in", "derived", "?")
    }

    fn new(_: NoParams, _: &Path) -> Result<Self, String> {
        Ok(DropDerived)
    }

    fn consume(&mut self, _: &[Columns<'_>]) -> Result<(), String> {
        Err("nothing should arrive".into())
    }
}

fn registry() -> Registry {
    static TABLE: OnceLock<Table> = OnceLock::new();
    common::registry(&TABLE, "flush", "libflush.so", || {
        vec![kind::<Hold>(), kind::<HoldDerived>(), sink::<DropDerived>()]
    })
}

/// A fresh directory for one test's files.
fn workdir(test: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("skinflow-sdk-flush-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs a lockstep graph of `nodes` (TOML `[[node]]`/`[[edge]]` tables).
fn run(nodes: &str) -> RunReport {
    let reg = registry();
    let text = format!("[graph]\nname = \"flush\"\nmode = \"lockstep\"\n\n{nodes}");
    let spec = GraphSpec::parse(SourceFile::new("<flush>", text), &reg).expect("valid graph");
    skinflow_core::run(&spec, &RunOptions::default()).expect("starts")
}

/// `counter` (1..=count, seq 0..count) -> t-hold (`hold_params`, `restart`) -> collect.
fn hold_graph(dir: &Path, count: u64, hold_params: &str, restart: &str) -> RunReport {
    run(&format!(
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = {count}, start = 1 }}\n\n\
         [[node]]\nid = \"hold\"\nkind = \"t-hold\"\nrestart = \"{restart}\"\nparams = {{ {hold_params} }}\n\n\
         [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = {} }}\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"hold.in\"\n\n[[edge]]\nfrom = \"hold.out\"\nto = \"out.in\"\n",
        quoted(&dir.join("out.csv"))
    ))
}

fn quoted(p: &Path) -> String {
    toml::Value::String(p.to_string_lossy().into_owned()).to_string()
}

/// The (seq, value) lines the collect sink wrote.
fn collected(dir: &Path) -> Vec<(u64, u64)> {
    let text = std::fs::read_to_string(dir.join("out.csv")).unwrap_or_default();
    text.lines()
        .map(|l| {
            let (s, v) = l.split_once(',').unwrap();
            (s.parse().unwrap(), v.parse().unwrap())
        })
        .collect()
}

fn node<'a>(r: &'a RunReport, id: &str) -> &'a NodeReport {
    r.stats.nodes.iter().find(|n| n.id == id).unwrap()
}

#[test]
fn every_held_input_arrives_in_order_one_per_flush_call() {
    let d = workdir("all");
    let r = hold_graph(&d, 50, "", "never");
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    // The counter's header (seq 0, 1, ...) and value (1, 2, ...), kept through the flush.
    let want: Vec<(u64, u64)> = (0..50).map(|k| (k, k + 1)).collect();
    assert_eq!(collected(&d), want);
    let hold = node(&r, "hold");
    assert_eq!((hold.msgs_in, hold.msgs_out), (50, 50));
    assert_eq!(hold.flushes, 50, "one message per flush call; the last one says done");
    assert_eq!((hold.errors, hold.discarded, hold.drops), (0, 0, 0));
    assert!(r.stats.edges.iter().all(|e| e.drops == 0), "{:?}", r.stats.edges);
}

#[test]
fn flushed_messages_go_through_the_rest_of_the_pipeline() {
    // Two holding plugins in series and a built-in node after them: the second receives what
    // the first flushes (through `process`), then flushes it in turn.
    let d = workdir("series");
    let r = run(&format!(
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 30, start = 1 }}\n\n\
         [[node]]\nid = \"a\"\nkind = \"t-hold\"\n\n[[node]]\nid = \"b\"\nkind = \"t-hold\"\n\n\
         [[node]]\nid = \"x10\"\nkind = \"scale\"\nparams = {{ factor = 10 }}\n\n\
         [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = {} }}\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"a.in\"\n\n[[edge]]\nfrom = \"a.out\"\nto = \"b.in\"\ncapacity = 2\n\n\
         [[edge]]\nfrom = \"b.out\"\nto = \"x10.in\"\ncapacity = 2\n\n[[edge]]\nfrom = \"x10.out\"\nto = \"out.in\"\n",
        quoted(&d.join("out.csv"))
    ));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let want: Vec<(u64, u64)> = (0..30).map(|k| (k, 10 * (k + 1))).collect();
    assert_eq!(collected(&d), want);
    for id in ["a", "b"] {
        let n = node(&r, id);
        assert_eq!((n.msgs_in, n.msgs_out, n.flushes, n.discarded), (30, 30, 30, 0), "{id}");
    }
    assert!(r.stats.edges.iter().all(|e| e.drops == 0), "{:?}", r.stats.edges);
}

#[test]
fn a_node_that_holds_nothing_is_flushed_once() {
    let d = workdir("empty");
    let r = hold_graph(&d, 0, "", "never");
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert_eq!(collected(&d), []);
    let hold = node(&r, "hold");
    assert_eq!((hold.flushes, hold.msgs_out, hold.discarded), (1, 0, 0));
}

#[test]
fn a_flush_error_is_counted_and_what_is_still_held_is_discarded_and_counted() {
    let d = workdir("error");
    let r = hold_graph(&d, 10, "error_at_flush = 3", "never");
    assert!(r.failures.is_empty(), "an error at flush is not a failure: {:?}", r.failures);
    // Flushes 1 and 2 emit values 1 and 2; flush 3 errs (it had popped nothing), which ends the
    // node's flush: the 8 values it still holds are counted as discarded at its stop.
    assert_eq!(collected(&d), [(0, 1), (1, 2)]);
    let hold = node(&r, "hold");
    assert_eq!((hold.flushes, hold.errors, hold.msgs_out), (3, 1, 2));
    assert_eq!((hold.discarded, hold.drops), (8, 8), "every input is either delivered or counted");
}

#[test]
fn a_flush_panic_stops_the_graph_without_restart() {
    let d = workdir("panic-never");
    let r = hold_graph(&d, 10, "panic_at_flush = 3", "never");
    let failure = r.failures.iter().map(ToString::to_string).collect::<Vec<_>>().join("\n");
    assert!(failure.contains("plugin kind \"t-hold\" (libflush.so): flush: panicked: flush panic at 3"), "{failure}");
    assert_eq!(collected(&d), [(0, 1), (1, 2)], "what was flushed before the panic was delivered");
    let hold = node(&r, "hold");
    assert_eq!((hold.flushes, hold.panics, hold.restarts), (3, 1, 0));
    assert_eq!(hold.discarded, 8, "what the panicked instance held is counted");
}

#[test]
fn a_flush_panic_with_restart_always_rebuilds_the_node() {
    let d = workdir("panic-always");
    let r = hold_graph(&d, 10, "panic_at_flush = 3", "always");
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    // The rebuilt instance holds nothing (what the panicked one held is counted as discarded)
    // and is not flushed again.
    assert_eq!(collected(&d), [(0, 1), (1, 2)]);
    let hold = node(&r, "hold");
    assert_eq!((hold.flushes, hold.panics, hold.restarts, hold.discarded), (3, 1, 1, 8));
}

#[test]
fn an_output_held_beyond_the_provenance_window_cannot_be_emitted_at_flush() {
    use skinflow_plugin_sdk::host::RETAINED_INPUTS;
    let count = RETAINED_INPUTS as u64 + 8;
    let r = run(&format!(
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = {count} }}\n\n\
         [[node]]\nid = \"hold\"\nkind = \"t-hold-derived\"\n\n[[node]]\nid = \"out\"\nkind = \"t-drop-derived\"\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"hold.in\"\n\n[[edge]]\nfrom = \"hold.out\"\nto = \"out.in\"\n"
    ));
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let hold = node(&r, "hold");
    // The first flush's message (seq 0) is older than the retained window (the last 32
    // inputs): its provenance is not known, so it is an error, not sent; that ends the flush,
    // and the values still held are counted as discarded.
    assert_eq!((hold.flushes, hold.errors, hold.msgs_out, hold.discarded), (1, 1, 0, count - 1));
    assert_eq!(node(&r, "out").msgs_in, 0);
}
