//! Plugin sources and sinks through the engine, on tables built in this binary by the SDK's
//! export code (the same bytes a plugin's entry point returns): the loader's role checks, a
//! source feeding a built-in node feeding a sink (lockstep, every value once and in order), a
//! source's waits ended by a stop request and its stop flag seen inside a poll, a sink's errors
//! counted and its panics handled by the restart policy. Built libraries are run in the
//! workspace's tests/plugins.rs.

use crate::common;

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Registry, Role, RunOptions, RunReport};
use skinflow_plugin_sdk::export::{KindEntry, Table, entry, sink, source};
use skinflow_plugin_sdk::host::{Codecs, read_table};
use skinflow_plugin_sdk::{Columns, KindSpec, Outputs, PluginSink, PluginSource, Poll, SourceCtx};

/// What the test kinds saw, per `tag` (tests run in parallel, each with its own tag).
#[derive(Default, Debug, Clone)]
struct Seen {
    /// (seq, value) consumed by `t-record`.
    values: Vec<(u64, u64)>,
    source_stops: u32,
    sink_stops: u32,
}

fn seen() -> &'static Mutex<HashMap<String, Seen>> {
    static SEEN: OnceLock<Mutex<HashMap<String, Seen>>> = OnceLock::new();
    SEEN.get_or_init(Default::default)
}

fn with_seen(tag: &str, f: impl FnOnce(&mut Seen)) {
    f(seen().lock().unwrap().entry(tag.to_owned()).or_default());
}

fn seen_by(tag: &str) -> Seen {
    seen().lock().unwrap().get(tag).cloned().unwrap_or_default()
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CountParams {
    tag: String,
    count: u64,
    /// Paced: after each value, nothing until `wait_s` later.
    #[serde(default)]
    wait_s: f64,
    /// After the first value, a poll loops over short "reads" until the graph is stopping.
    #[serde(default)]
    loop_until_stop: bool,
}

/// Emits 1..=count (default headers).
struct Count {
    p: CountParams,
    next: u64,
}

impl PluginSource for Count {
    type Params = CountParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-count", "1..=count").output("out", "count", "values")
    }

    fn validate(p: &CountParams) -> Result<(), String> {
        if p.count == 0 { Err("param \"count\": must be >= 1".into()) } else { Ok(()) }
    }

    fn new(p: CountParams, _: &Path) -> Result<Self, String> {
        Ok(Count { p, next: 1 })
    }

    fn poll(&mut self, ctx: &SourceCtx<'_>, out: &mut Outputs) -> Result<Poll, String> {
        if self.next > self.p.count {
            return Ok(Poll::Finished);
        }
        if self.next > 1 && self.p.loop_until_stop {
            while !ctx.stopping() {
                std::thread::sleep(Duration::from_millis(5)); // a bounded read
            }
            return Ok(Poll::Finished);
        }
        out.port(0).scalar("value", self.next as f64);
        self.next += 1;
        if ctx.paced() && self.p.wait_s > 0.0 {
            return Ok(Poll::IdleUntil(ctx.now_ns() + (self.p.wait_s * 1e9) as u64));
        }
        Ok(Poll::Emitted)
    }

    fn stop(&mut self) -> Result<(), String> {
        with_seen(&self.p.tag, |s| s.source_stops += 1);
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RecordParams {
    tag: String,
    #[serde(default)]
    error_on: u64,
    #[serde(default)]
    panic_on: u64,
}

/// Records (seq, value); errs or panics on a given value.
struct Record(RecordParams);

impl PluginSink for Record {
    type Params = RecordParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-record", "records what it consumes").input("in", "count", "values")
    }

    fn new(p: RecordParams, _: &Path) -> Result<Self, String> {
        Ok(Record(p))
    }

    fn consume(&mut self, inputs: &[Columns<'_>]) -> Result<(), String> {
        let v = inputs[0].scalar("value")? as u64;
        if v == self.0.panic_on {
            panic!("sink panic on {v}");
        }
        if v == self.0.error_on {
            return Err(format!("sink error on {v}"));
        }
        with_seen(&self.0.tag, |s| s.values.push((inputs[0].seq(), v)));
        Ok(())
    }

    fn stop(&mut self) -> Result<(), String> {
        with_seen(&self.0.tag, |s| s.sink_stops += 1);
        Ok(())
    }
}

fn codecs() -> Codecs {
    let mut c = Codecs::new();
    c.register("derived", common::Derived::codec);
    c
}

fn registry() -> Registry {
    static TABLE: OnceLock<Table> = OnceLock::new();
    common::registry(&TABLE, "roles", "libroles.so", || vec![source::<Count>(), sink::<Record>()])
}

/// t-count -> scale (x10, built-in) -> t-record.
fn run(mode: &str, count: &str, record: &str, restart: &str, opts: &RunOptions) -> RunReport {
    let reg = registry();
    let text = format!(
        "[graph]\nname = \"roles\"\nmode = \"{mode}\"\n\n\
         [[node]]\nid = \"src\"\nkind = \"t-count\"\nparams = {{ {count} }}\n\n\
         [[node]]\nid = \"x10\"\nkind = \"scale\"\nparams = {{ factor = 10 }}\n\n\
         [[node]]\nid = \"rec\"\nkind = \"t-record\"\nrestart = \"{restart}\"\nparams = {{ {record} }}\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"x10.in\"\n\n[[edge]]\nfrom = \"x10.out\"\nto = \"rec.in\"\n"
    );
    let spec = GraphSpec::parse(SourceFile::new("<roles>", text), &reg).expect("valid graph");
    skinflow_core::run(&spec, opts).expect("starts")
}

fn node<'a>(r: &'a RunReport, id: &str) -> &'a skinflow_core::stats::NodeReport {
    r.stats.nodes.iter().find(|n| n.id == id).unwrap()
}

#[test]
fn kinds_are_registered_with_their_roles() {
    let reg = registry();
    let src = reg.get("t-count").unwrap().info();
    assert_eq!((src.role, src.inputs.len(), src.outputs.len()), (Role::Source, 0, 1));
    let snk = reg.get("t-record").unwrap().info();
    assert_eq!((snk.role, snk.inputs.len(), snk.outputs.len()), (Role::Sink, 1, 0));
    assert_eq!(snk.origin, "libroles.so");
}

#[test]
fn a_source_feeds_a_builtin_node_feeding_a_sink() {
    let r = run("lockstep", "tag = \"e2e\", count = 200", "tag = \"e2e\"", "never", &RunOptions::default());
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let s = seen_by("e2e");
    // Default headers: seq 1, 2, ... per port; the built-in scale keeps the header.
    let want: Vec<(u64, u64)> = (1..=200).map(|v| (v, 10 * v)).collect();
    assert_eq!(s.values, want);
    assert_eq!((s.source_stops, s.sink_stops), (1, 1), "each stop called once");
    assert_eq!(node(&r, "src").msgs_out, 200);
    assert_eq!(node(&r, "rec").msgs_in, 200);
}

#[test]
fn a_stop_request_ends_a_sources_wait() {
    // One value, then nothing for an hour: only the stop request (after 0.3 s) ends the run.
    let opts = RunOptions { duration: Some(Duration::from_millis(300)), stop: None };
    let r = run("realtime", "tag = \"wait\", count = 5, wait_s = 3600.0", "tag = \"wait\"", "never", &opts);
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let s = seen_by("wait");
    assert_eq!(s.values, vec![(1, 10)], "the first value, then the wait");
    assert_eq!((s.source_stops, s.sink_stops), (1, 1));
}

#[test]
fn a_poll_sees_the_stop_flag() {
    let opts = RunOptions { duration: Some(Duration::from_millis(300)), stop: None };
    let r = run("realtime", "tag = \"flag\", count = 5, loop_until_stop = true", "tag = \"flag\"", "never", &opts);
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert_eq!(seen_by("flag").values, vec![(1, 10)]);
}

#[test]
fn a_sink_error_is_counted_and_the_graph_goes_on() {
    let r =
        run("lockstep", "tag = \"err\", count = 10", "tag = \"err\", error_on = 30", "never", &RunOptions::default());
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let values: Vec<u64> = seen_by("err").values.iter().map(|v| v.1).collect();
    assert_eq!(values, [10, 20, 40, 50, 60, 70, 80, 90, 100]);
    assert_eq!(node(&r, "rec").errors, 1);
}

#[test]
fn a_sink_panic_stops_the_graph_or_rebuilds_the_sink() {
    let r = run("lockstep", "tag = \"pn\", count = 10", "tag = \"pn\", panic_on = 40", "never", &RunOptions::default());
    let failure = r.failures.iter().map(ToString::to_string).collect::<Vec<_>>().join("\n");
    assert!(failure.contains("plugin kind \"t-record\" (libroles.so)"), "{failure}");
    assert!(failure.contains("sink panic on 40"), "{failure}");
    let values: Vec<u64> = seen_by("pn").values.iter().map(|v| v.1).collect();
    assert_eq!(values, [10, 20, 30]);
    assert_eq!(seen_by("pn").sink_stops, 0, "a panicked instance is not stopped");

    let r =
        run("lockstep", "tag = \"pa\", count = 10", "tag = \"pa\", panic_on = 40", "always", &RunOptions::default());
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let values: Vec<u64> = seen_by("pa").values.iter().map(|v| v.1).collect();
    assert_eq!(values, [10, 20, 30, 50, 60, 70, 80, 90, 100], "the panicking message is lost, the rest arrive");
    assert_eq!((node(&r, "rec").panics, node(&r, "rec").restarts), (1, 1));
    assert_eq!(seen_by("pa").sink_stops, 1, "the rebuilt sink is stopped");
}

struct SourceWithInput;

impl PluginSource for SourceWithInput {
    type Params = CountParams;
    fn spec() -> KindSpec {
        KindSpec::new("t-bad-source", "declares an input").input("in", "count", "?").output("out", "count", "?")
    }
    fn new(_: CountParams, _: &Path) -> Result<Self, String> {
        Ok(SourceWithInput)
    }
    fn poll(&mut self, _: &SourceCtx<'_>, _: &mut Outputs) -> Result<Poll, String> {
        Ok(Poll::Finished)
    }
}

struct SourceOfDerived;

impl PluginSource for SourceOfDerived {
    type Params = CountParams;
    fn spec() -> KindSpec {
        KindSpec::new("t-derived-source", "emits a derived payload").output("out", "derived", "?")
    }
    fn new(_: CountParams, _: &Path) -> Result<Self, String> {
        Ok(SourceOfDerived)
    }
    fn poll(&mut self, _: &SourceCtx<'_>, _: &mut Outputs) -> Result<Poll, String> {
        Ok(Poll::Finished)
    }
}

struct SinkWithOutput;

impl PluginSink for SinkWithOutput {
    type Params = RecordParams;
    fn spec() -> KindSpec {
        KindSpec::new("t-bad-sink", "declares an output").input("in", "count", "?").output("out", "count", "?")
    }
    fn new(p: RecordParams, _: &Path) -> Result<Self, String> {
        drop(p);
        Ok(SinkWithOutput)
    }
    fn consume(&mut self, _: &[Columns<'_>]) -> Result<(), String> {
        Ok(())
    }
}

#[test]
fn kinds_that_do_not_fit_their_role_are_refused_at_load() {
    static A: OnceLock<Table> = OnceLock::new();
    static B: OnceLock<Table> = OnceLock::new();
    static C: OnceLock<Table> = OnceLock::new();
    type Case = (&'static OnceLock<Table>, fn() -> Vec<KindEntry>, &'static str);
    let cases: [Case; 3] = [
        (&A, || vec![source::<SourceWithInput>()], "kind \"t-bad-source\": a source has no inputs (it declares 1)"),
        (
            &B,
            || vec![source::<SourceOfDerived>()],
            "kind \"t-derived-source\": output \"out\": a source cannot emit \"derived\" (its payload is derived from inputs a source does not have; a source can emit: count)",
        ),
        (&C, || vec![sink::<SinkWithOutput>()], "kind \"t-bad-sink\": a sink has no outputs (it declares 1)"),
    ];
    for (cell, kinds, want) in cases {
        // SAFETY: `entry` points at the static table in `cell`.
        let t = unsafe { *entry(cell, "bad", "0", kinds) };
        let e = read_table(Path::new("libbad.so"), &t, &codecs()).err().expect("refused").to_string();
        assert_eq!(e, format!("plugin libbad.so: {want}"));
    }
}
