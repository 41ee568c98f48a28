//! The runtime's own tests: what a panicking instance held, and the input of the call that
//! panicked, are counted; a swap counts (and
//! shows its kind) only once installed, is answered with a replacement's refusal, and never
//! runs when its node does not, and is refused when an input file its params name is not
//! there; deadline and restart policy change while the graph runs; a
//! source's end (its stop, what is queued for it) and a stop that fails or panics go the same
//! way under both executors, and so does a failed start (the nodes already started are
//! stopped, a panic there caught).
//!
//! No assertion depends on timing: waits only give the graph time to reach a state.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::SeqCst};
use std::time::{Duration, Instant};

use serde::Deserialize;

use crate::graph::{GraphSpec, Restart, SourceFile};
use crate::io::{Inputs, Outputs};
use crate::message::{Header, Message};
use crate::node::{Context, NodeImpl, NodeState, Processor, Source, SourcePoll, StateRefused};
use crate::registry::{KindInfo, NodeParams, Registry, Role, typed};
use crate::runtime::{GraphHandle, RunError, RunOptions, RunReport, RunningGraph};
use crate::stats::NodeReport;
use crate::toy::Count;
use crate::{NodeError, Params, PortSpec};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HoldParams {
    /// Messages held back.
    by: usize,
    /// Call (1-based, per instance) that panics, before it takes its input; 0 = never.
    #[serde(default)]
    panic_at: u64,
    /// `stop` panics, after counting what the instance holds.
    #[serde(default)]
    stop_panics: bool,
    /// `start` fails.
    #[serde(default)]
    start_fails: bool,
    /// A file that must exist ([`NodeParams::check_files`]); none by default.
    #[serde(default)]
    needs_file: Option<std::path::PathBuf>,
}

impl NodeParams for HoldParams {
    fn check_files(&self, ctx: &crate::registry::BuildContext) -> Result<(), crate::ParamError> {
        let Some(f) = &self.needs_file else { return Ok(()) };
        let p = ctx.resolve(f);
        std::fs::metadata(&p)
            .map(drop)
            .map_err(|e| crate::ParamError::new("needs_file", format!("{}: {e}", p.display())))
    }
}

/// Emits each input once `by` newer ones arrived (holds its last `by`), flushes them at end
/// of stream, counts what it still holds at stop, panics on call `panic_at` (and in `stop`
/// with `stop_panics`).
struct Hold {
    p: HoldParams,
    held: VecDeque<Message>,
    calls: u64,
    /// Its own counter `inputs_seen` (shared by its instances), taken at start.
    seen: Option<crate::Counter>,
}

impl Processor for Hold {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.seen = Some(ctx.counter("inputs_seen"));
        ctx.counter("never_counted");
        if self.p.start_fails {
            return Err(NodeError::msg("hold: start failed"));
        }
        Ok(())
    }

    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        self.calls += 1;
        if let Some(seen) = &self.seen {
            seen.add(inputs.get(0).map_or(0, |_| 1));
        }
        if self.calls == self.p.panic_at {
            panic!("hold: call {}", self.calls);
        }
        if let Some(m) = inputs.get(0) {
            self.held.push_back(m.clone());
        }
        if self.held.len() > self.p.by
            && let Some(m) = self.held.pop_front()
        {
            out.send(0, m)?;
        }
        Ok(())
    }

    fn flush(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<(), NodeError> {
        if let Some(m) = self.held.pop_front() {
            out.send(0, m)?;
        }
        if !self.held.is_empty() {
            ctx.request_rerun();
        }
        Ok(())
    }

    /// `panic` panics; anything else is applied and counted (`commands_run`).
    fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        if cmd == "panic" {
            panic!("hold: control");
        }
        ctx.counter("commands_run").add(1);
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        ctx.count_discarded(self.held.len() as u64);
        if self.p.stop_panics {
            panic!("hold: stop");
        }
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TotalParams {
    /// Which stream this total belongs to: a replacement of another group refuses the swap.
    group: u64,
    #[serde(default)]
    add: u64,
}

impl NodeParams for TotalParams {}

/// `out = running total of the inputs + add`; hands its total over to a replacement of its
/// group, and refuses the swap to one of another group.
struct Total {
    p: TotalParams,
    total: u64,
}

struct TotalState {
    group: u64,
    total: u64,
}

impl Processor for Total {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let Some(m) = inputs.get(0) else { return Ok(()) };
        self.total += m.get::<Count>().expect("a count").0;
        out.send(0, Message::new(m.header, Count(self.total + self.p.add)))
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(TotalState { group: self.p.group, total: std::mem::take(&mut self.total) }))
    }

    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<TotalState>().map_err(|s| StateRefused::new(s, "not a total"))?;
        if s.group != self.p.group {
            let reason = format!("group {} cannot go on from group {}'s total", self.p.group, s.group);
            return Err(StateRefused::refuse_swap(s, reason));
        }
        self.total = s.total;
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SlowParams {
    /// Messages emitted at graph time k * `every_s`.
    every_s: f64,
}

impl NodeParams for SlowParams {}

/// A paced source that counts its instances' stops and its polls begun in shared counters.
struct Slow {
    every_s: f64,
    next: u64,
    stops: Arc<AtomicU64>,
    polls: Arc<AtomicU64>,
}

impl Source for Slow {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        self.polls.fetch_add(1, SeqCst);
        if !ctx.sleep_until_ns((self.next as f64 * self.every_s * 1e9) as u64) {
            return Ok(SourcePoll::Finished);
        }
        out.send(
            0,
            Message::new(Header { seq: self.next, t_ns: ctx.now_ns(), origin: ctx.index() }, Count(self.next)),
        )?;
        self.next += 1;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        self.stops.fetch_add(1, SeqCst);
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EndsParams {
    /// Messages emitted before the stream ends.
    count: u64,
    /// `stop` returns an error.
    #[serde(default)]
    fail_stop: bool,
    /// `stop` panics.
    #[serde(default)]
    panic_stop: bool,
}

impl NodeParams for EndsParams {}

/// A source whose stream ends after `count` messages; counts its instances' stops in the
/// shared counter, and fails its stop with `fail_stop`, panics there with `panic_stop`.
struct Ends {
    p: EndsParams,
    next: u64,
    stops: Arc<AtomicU64>,
}

impl Source for Ends {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        if self.next == self.p.count {
            return Ok(SourcePoll::Finished);
        }
        out.send(0, Message::new(Header { seq: self.next, t_ns: self.next, origin: ctx.index() }, Count(self.next)))?;
        self.next += 1;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        self.stops.fetch_add(1, SeqCst);
        if self.p.panic_stop {
            panic!("ends: stop panics");
        }
        if self.p.fail_stop {
            return Err(NodeError::msg("ends: stop refused"));
        }
        Ok(())
    }
}

/// The toy kinds, `hold`, `total`, `slow` / `slow2` (two kinds, one behaviour) and `ends`
/// counting their stops in `stops`.
fn registry(stops: &Arc<AtomicU64>) -> Registry {
    registry_counting_polls(stops, &Arc::default())
}

/// [`registry`], with the polls the `slow` / `slow2` instances begin counted in `polls`.
fn registry_counting_polls(stops: &Arc<AtomicU64>, polls: &Arc<AtomicU64>) -> Registry {
    let mut r = Registry::new();
    crate::toy::register(&mut r).unwrap();
    let count = || PortSpec::output::<Count>("out", "the value");
    r.register(typed(
        KindInfo::new("hold", Role::Processor, "test: holds its last `by` inputs, panics on call `panic_at`")
            .input(PortSpec::input::<Count>("in", "the value"))
            .output(count()),
        |p: HoldParams, _| Ok(NodeImpl::Processor(Box::new(Hold { p, held: VecDeque::new(), calls: 0, seen: None }))),
    ))
    .unwrap();
    r.register(typed(
        KindInfo::new("total", Role::Processor, "test: running total + add, per group")
            .input(PortSpec::input::<Count>("in", "the value"))
            .output(count()),
        |p: TotalParams, _| Ok(NodeImpl::Processor(Box::new(Total { p, total: 0 }))),
    ))
    .unwrap();
    for name in ["slow", "slow2"] {
        let (stops, polls) = (stops.clone(), polls.clone());
        r.register(typed(
            KindInfo::new(name, Role::Source, "test: a paced source").output(count()),
            move |p: SlowParams, _| {
                let (stops, polls) = (stops.clone(), polls.clone());
                Ok(NodeImpl::Source(Box::new(Slow { every_s: p.every_s, next: 0, stops, polls })))
            },
        ))
        .unwrap();
    }
    let stops = stops.clone();
    r.register(typed(
        KindInfo::new("ends", Role::Source, "test: a stream of `count` messages").output(count()),
        move |p: EndsParams, _| Ok(NodeImpl::Source(Box::new(Ends { p, next: 0, stops: stops.clone() }))),
    ))
    .unwrap();
    r
}

fn spec(reg: &Registry, text: &str) -> GraphSpec {
    GraphSpec::parse(SourceFile::new("<runtime-test>", text), reg).expect("valid graph")
}

fn node<'a>(r: &'a RunReport, id: &str) -> &'a NodeReport {
    r.stats.node(id).unwrap()
}

fn wait_for(what: &str, mut cond: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(t0.elapsed() < Duration::from_secs(60), "waited a minute for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// counter (12) -> hold (by 3, panics on call 5) -> null, lockstep, `restart`.
fn held_at_panic(restart: &str) -> RunReport {
    let reg = registry(&Arc::default());
    let g = spec(
        &reg,
        &format!(
            "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 12 }}\n\
             [[node]]\nid = \"h\"\nkind = \"hold\"\nrestart = \"{restart}\"\nparams = {{ by = 3, panic_at = 5 }}\n\
             [[node]]\nid = \"out\"\nkind = \"null\"\n\
             [[edge]]\nfrom = \"src.out\"\nto = \"h.in\"\n\
             [[edge]]\nfrom = \"h.out\"\nto = \"out.in\"\n"
        ),
    );
    crate::runtime::run(&g, &RunOptions::default()).unwrap()
}

#[test]
fn what_a_restarted_instance_held_when_it_panicked_is_counted_as_discarded() {
    let r = held_at_panic("always");
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let h = node(&r, "h");
    // Two instances each emit 1 and hold 3 when their 5th call panics; that call's input dies
    // with it; the third takes the last 2 inputs and flushes them. 12 in = 4 out + 8 discarded.
    assert_eq!((h.msgs_in, h.msgs_out, h.panics, h.restarts), (12, 4, 2, 2));
    assert_eq!(h.discarded, 8, "the 3 messages each panicked instance held, and each panicked call's input");
    assert_eq!(h.msgs_in, h.msgs_out + h.discarded, "every input accounted for");
    // A node's own counter goes on across its instances; one at 0 is reported, not shown.
    let counters: Vec<(&str, u64)> = h.counters.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    assert_eq!(counters, [("inputs_seen", 12), ("never_counted", 0)]);
    let table = r.stats.to_string();
    assert!(table.contains("node counters:\n  h (hold): inputs_seen 12\n"), "{table}");
    assert!(!table.contains("never_counted"), "{table}");
}

#[test]
fn what_a_dead_instance_held_is_counted_at_the_end_of_the_run() {
    let r = held_at_panic("never");
    assert_eq!(r.failures.len(), 1, "{:?}", r.failures);
    let h = node(&r, "h");
    assert_eq!((h.msgs_in, h.msgs_out, h.panics, h.restarts), (5, 1, 1, 0));
    assert_eq!(h.discarded, 4, "the 3 messages the panicked instance held, and its panicked call's input");
    assert_eq!(h.msgs_in, h.msgs_out + h.discarded, "every input it took accounted for");
}

/// The rows `collect` wrote.
fn rows(path: &std::path::Path) -> Vec<(u64, u64)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let (a, b) = l.split_once(',').unwrap();
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect()
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("skinflow-runtime-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A swap's params are held to the graph checks' rule on file params: `{"path": ""}` is
/// refused before anything is built, naming the param, and the node writes on to its file.
#[test]
fn a_swap_to_an_empty_path_is_refused_and_the_node_goes_on() {
    let reg = registry(&Arc::default());
    let dir = temp_dir("empty-path");
    let out = dir.join("rows.csv");
    let g = spec(
        &reg,
        &format!(
            "[[node]]\nid = \"src\"\nkind = \"slow\"\nparams = {{ every_s = 1000.0 }}\n\
             [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = {out:?} }}\n\
             [[edge]]\nfrom = \"src.out\"\nto = \"out.in\"\n"
        ),
    );
    // The source's first message at once, the next in 1000 s: the sink runs until stopped.
    let running = RunningGraph::start(&g).unwrap();
    let h = running.handle();
    wait_for("the first row", || h.stats().node("out").unwrap().msgs_in == 1);
    let collect = reg.get("collect").unwrap().clone();
    match h.swap("out", collect, Params::from_toml("path = \"\"").unwrap()) {
        Err(RunError::Swap { node, problem }) => {
            assert_eq!(
                (node.as_str(), problem.as_str()),
                ("out", "param \"path\": is empty: give a file or device path")
            );
        }
        other => panic!("expected the swap refused, got {other:?}"),
    }
    let r = running.wait(&RunOptions { stop: Some(Arc::new(AtomicBool::new(true))), ..RunOptions::default() });
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert_eq!(node(&r, "out").swaps, 0);
    assert_eq!(rows(&out).len(), 1, "the running instance wrote its row");
}

#[test]
fn a_swap_the_replacement_refuses_is_answered_and_the_node_goes_on_with_its_state() {
    let stops = Arc::default();
    let reg = registry(&stops);
    let dir = temp_dir("refused");
    let out = dir.join("rows.csv");
    let g = spec(
        &reg,
        &format!(
            "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 600, rate_hz = 300.0 }}\n\
             [[node]]\nid = \"t\"\nkind = \"total\"\nparams = {{ group = 1 }}\n\
             [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = {out:?} }}\n\
             [[edge]]\nfrom = \"src.out\"\nto = \"t.in\"\ncapacity = 8\n\
             [[edge]]\nfrom = \"t.out\"\nto = \"out.in\"\ncapacity = 8\n"
        ),
    );
    let running = RunningGraph::start(&g).unwrap();
    let h = running.handle();
    let total = reg.get("total").unwrap().clone();
    let wait = Duration::from_secs(30);
    wait_for("100 messages", || h.stats().node("t").unwrap().msgs_out >= 100);
    let group = |g: &str| Params::from_toml(g).unwrap();
    match h.swap_wait("t", total.clone(), group("group = 2\nadd = 5"), wait) {
        Err(RunError::Swap { node, problem }) => {
            assert_eq!(node, "t");
            assert_eq!(problem, "group 2 cannot go on from group 1's total");
        }
        other => panic!("expected the replacement's refusal, got {other:?}"),
    }
    assert_eq!(h.stats().node("t").unwrap().swaps, 0);
    wait_for("200 messages", || h.stats().node("t").unwrap().msgs_out >= 200);
    h.swap_wait("t", total, group("group = 1\nadd = 1000000000"), wait).unwrap();
    assert_eq!(h.stats().node("t").unwrap().swaps, 1, "counted when installed, before the answer");
    let r = running.wait(&RunOptions::default());
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let rows = rows(&out);
    assert_eq!(rows.len(), 600);
    // One running total throughout: kept across the refused swap, handed over by the other.
    let switch = rows.iter().position(|&(_, y)| y >= 1_000_000_000).expect("the second swap took effect");
    let mut sum = 0;
    for (i, &(seq, y)) in rows.iter().enumerate() {
        sum += seq;
        assert_eq!(y, if i < switch { sum } else { sum + 1_000_000_000 }, "row {i}");
    }
}

/// `slow` (one message every `every_s`) -> null, real time.
fn slow_graph(reg: &Registry, every_s: f64) -> RunningGraph {
    let g = spec(
        reg,
        &format!(
            "[[node]]\nid = \"s\"\nkind = \"slow\"\nparams = {{ every_s = {every_s} }}\n\
             [[node]]\nid = \"out\"\nkind = \"null\"\n\
             [[edge]]\nfrom = \"s.out\"\nto = \"out.in\"\n"
        ),
    );
    RunningGraph::start(&g).unwrap()
}

fn kind_of(h: &GraphHandle, id: &str) -> String {
    h.stats().node(id).unwrap().kind.clone()
}

#[test]
fn a_swap_its_node_never_gets_to_is_not_installed_and_its_replacement_is_stopped() {
    let (stops, polls) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let reg = registry_counting_polls(&stops, &polls);
    // The source emits its first message at once and then waits 1000 s for the next: it is
    // not called again before the run is stopped.
    let running = slow_graph(&reg, 1000.0);
    let h = running.handle();
    // In its second poll, the node waits out the 1000 s. (Its first message alone is not
    // enough: a swap queued before that first poll returns is installed between the two.)
    wait_for("the second poll", || polls.load(SeqCst) == 2);
    assert_eq!(h.stats().node("s").unwrap().msgs_out, 1);
    let slow2 = reg.get("slow2").unwrap().clone();
    let params = || Params::from_toml("every_s = 0.001").unwrap();
    let timeout = Duration::from_millis(300);
    match h.swap_wait("s", slow2.clone(), params(), timeout) {
        Err(RunError::SwapTimeout { node, timeout: t }) => assert_eq!((node.as_str(), t), ("s", timeout)),
        other => panic!("expected a timeout, got {other:?}"),
    }
    // Queued without waiting: the run ends before the node is called again.
    h.swap("s", slow2.clone(), params()).unwrap();
    assert_eq!(kind_of(&h, "s"), "slow", "a queued swap does not change the kind");
    let stop = Arc::new(AtomicBool::new(true));
    let r = running.wait(&RunOptions { stop: Some(stop), ..RunOptions::default() });
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let s = node(&r, "s");
    assert_eq!((s.kind.as_str(), s.swaps, s.msgs_out), ("slow", 0, 1), "nothing swapped in ran");
    assert_eq!(stops.load(SeqCst), 3, "the running instance and both replacements were stopped");
    // After the run nothing runs: a swap is refused at once, and the kind stays.
    let e = h.swap("s", slow2.clone(), params()).unwrap_err().to_string();
    assert!(e.contains("node \"s\": swap refused: the node runs no more"), "{e}");
    assert!(h.swap_wait("s", slow2, params(), timeout).is_err());
    assert_eq!(kind_of(&h, "s"), "slow");
}

#[test]
fn a_finished_source_is_not_swapped() {
    let stops = Arc::new(AtomicU64::new(0));
    let reg = registry(&stops);
    let g = spec(
        &reg,
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = { count = 5 }\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"out.in\"\n",
    );
    let running = RunningGraph::start(&g).unwrap();
    let h = running.handle();
    let r = running.wait(&RunOptions::default());
    assert_eq!(node(&r, "src").msgs_out, 5);
    let counter = reg.get("counter").unwrap().clone();
    let e = h.swap("src", counter, Params::from_toml("count = 7").unwrap()).unwrap_err();
    assert!(matches!(e, RunError::Swap { .. }), "{e}");
    assert_eq!(h.stats().node("src").unwrap().swaps, 0);
}

/// A control command for a node that runs no more, while the rest of the graph runs on, is
/// answered at once as not run (not after the timeout, nor at the end of the run).
#[test]
fn a_control_for_a_finished_source_is_answered_at_once() {
    let reg = registry(&Arc::default());
    let g = spec(
        &reg,
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = { count = 5 }\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\
         [[node]]\nid = \"s\"\nkind = \"slow\"\nparams = { every_s = 0.01 }\n\
         [[node]]\nid = \"out2\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"out.in\"\n\
         [[edge]]\nfrom = \"s.out\"\nto = \"out2.in\"\n",
    );
    let running = RunningGraph::start(&g).unwrap();
    let h = running.handle();
    wait_for("the counter to end", || h.node_ended("src").unwrap());
    assert!(!h.node_ended("s").unwrap(), "the paced source runs on");
    // Answered before the timeout (at the timeout it would be a `ControlTimeout`).
    match h.control_wait("src", "tare", Duration::from_secs(30)) {
        Err(RunError::Ended { node, command }) => assert_eq!((node.as_str(), command.as_str()), ("src", "tare")),
        other => panic!("expected `runs no more`, got {other:?}"),
    }
    assert!(!h.node_ended("s").unwrap(), "answered while the graph still ran");
    assert!(matches!(h.node_ended("nope"), Err(RunError::UnknownNode(_))));
    let stop = Arc::new(AtomicBool::new(true));
    let r = running.wait(&RunOptions { stop: Some(stop), ..RunOptions::default() });
    assert!(r.failures.is_empty(), "{:?}", r.failures);
}

#[test]
fn deadline_and_restart_policy_change_while_the_graph_runs() {
    let reg = registry(&Arc::default());
    let g = spec(
        &reg,
        "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = { count = 20 }\n\
         [[node]]\nid = \"d\"\nkind = \"delay\"\nparams = { delay_us = 20.0 }\n\
         [[node]]\nid = \"p\"\nkind = \"panicker\"\nparams = { at = 3 }\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"d.in\"\n\
         [[edge]]\nfrom = \"d.out\"\nto = \"p.in\"\n\
         [[edge]]\nfrom = \"p.out\"\nto = \"out.in\"\n",
    );
    let running = RunningGraph::start(&g).unwrap();
    let h = running.handle();
    // Applied before the first call: every call of `d` busy-waits 20 us, past a 1 us deadline;
    // `p` is rebuilt after its panic instead of stopping the graph.
    h.set_policy("d", Some(1.0), Restart::Never).unwrap();
    h.set_policy("p", None, Restart::Always).unwrap();
    assert!(matches!(h.set_policy("nope", None, Restart::Never), Err(RunError::UnknownNode(_))));
    let r = running.wait(&RunOptions::default());
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let d = node(&r, "d");
    assert_eq!((d.calls, d.deadline_misses), (20, 20));
    let p = node(&r, "p");
    // Each instance panics on its 3rd message: 6 panics in 20 messages, each rebuilt.
    assert_eq!((p.panics, p.restarts, p.msgs_out), (6, 6, 14));
}

#[test]
fn a_source_s_end_is_the_same_under_both_executors() {
    let cases = [("fail_stop", "stop failed: ends: stop refused"), ("panic_stop", "stop panicked: ends: stop panics")];
    for (mode, (how, want)) in ["lockstep", "realtime"].into_iter().flat_map(|m| cases.map(|c| (m, c))) {
        let stops = Arc::new(AtomicU64::new(0));
        let reg = registry(&stops);
        let g = spec(
            &reg,
            &format!(
                "[graph]\nmode = \"{mode}\"\n\
                 [[node]]\nid = \"src\"\nkind = \"ends\"\nparams = {{ count = 5, {how} = true }}\n\
                 [[node]]\nid = \"h\"\nkind = \"hold\"\nparams = {{ by = 2 }}\n\
                 [[node]]\nid = \"out\"\nkind = \"null\"\n\
                 [[edge]]\nfrom = \"src.out\"\nto = \"h.in\"\n\
                 [[edge]]\nfrom = \"h.out\"\nto = \"out.in\"\n"
            ),
        );
        let r = crate::runtime::run(&g, &RunOptions::default()).unwrap();
        // The failed or panicking stop fails the graph (as the source's error, not an
        // end-of-run stop failure), in either executor; what was sent still goes through and
        // is flushed.
        match r.failures.as_slice() {
            [RunError::Node { node, error }] => {
                assert_eq!((node.as_str(), error.to_string().as_str()), ("src", want), "{mode}");
            }
            other => panic!("{mode} {how}: expected the source's stop failure, got {other:?}"),
        }
        assert_eq!(stops.load(SeqCst), 1, "{mode}: the source is stopped once");
        assert_eq!(node(&r, "src").msgs_out, 5, "{mode}");
        let h = node(&r, "h");
        assert_eq!((h.msgs_in, h.msgs_out, h.discarded), (5, 5, 0), "{mode}: everything flushed");
        assert_eq!(node(&r, "out").msgs_in, 5, "{mode}");
    }
}

#[test]
fn a_swap_queued_for_a_lockstep_source_that_never_polls_again_is_not_installed() {
    let stops = Arc::new(AtomicU64::new(0));
    let reg = registry(&stops);
    let g = spec(
        &reg,
        "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"s\"\nkind = \"slow\"\nparams = { every_s = 0.001 }\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"s.out\"\nto = \"out.in\"\n",
    );
    let running = RunningGraph::start(&g).unwrap();
    let h = running.handle();
    // Queued before the run, which is stopped before its first step: the source is never
    // polled (nor its control work run) again, so the swap ends with the source's stream.
    h.swap("s", reg.get("slow2").unwrap().clone(), Params::from_toml("every_s = 0.002").unwrap()).unwrap();
    h.control("s", "tare").unwrap();
    let stop = Arc::new(AtomicBool::new(true));
    let r = running.wait(&RunOptions { stop: Some(stop), ..RunOptions::default() });
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    let s = node(&r, "s");
    assert_eq!((s.kind.as_str(), s.swaps, s.msgs_out), ("slow", 0, 0), "nothing swapped in ran");
    assert_eq!(stops.load(SeqCst), 2, "the running instance and the replacement were stopped");
    let e = h.swap("s", reg.get("slow2").unwrap().clone(), Params::from_toml("every_s = 0.002").unwrap());
    assert!(e.unwrap_err().to_string().contains("the node runs no more"));
}

#[test]
fn a_stop_that_panics_is_logged_for_a_replaced_instance_and_reported_at_the_end_of_the_run() {
    for mode in ["lockstep", "realtime"] {
        let reg = registry(&Arc::default());
        let g = spec(
            &reg,
            &format!(
                "[graph]\nmode = \"{mode}\"\n\
                 [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 12 }}\n\
                 [[node]]\nid = \"h\"\nkind = \"hold\"\nrestart = \"always\"\n\
                 params = {{ by = 3, panic_at = 5, stop_panics = true }}\n\
                 [[node]]\nid = \"out\"\nkind = \"null\"\n\
                 [[edge]]\nfrom = \"src.out\"\nto = \"h.in\"\n\
                 [[edge]]\nfrom = \"h.out\"\nto = \"out.in\"\n"
            ),
        );
        let r = crate::runtime::run(&g, &RunOptions::default()).unwrap();
        // The two panicked instances' stops panic too (logged, the node goes on); the last
        // instance's, at the end of the run, is reported.
        match r.failures.as_slice() {
            [RunError::Stop { node, error: NodeError::Panic(msg) }] => {
                assert_eq!((node.as_str(), msg.as_str()), ("h", "hold: stop"), "{mode}");
            }
            other => panic!("{mode}: expected the end-of-run stop's panic, got {other:?}"),
        }
        let h = node(&r, "h");
        assert_eq!((h.msgs_in, h.msgs_out, h.panics, h.restarts), (12, 4, 2, 2), "{mode}");
        assert_eq!(h.discarded, 8, "{mode}: counted before the stops panicked (and the panicked calls' inputs)");
    }
}

#[test]
fn a_control_command_that_panics_is_counted_and_the_restart_policy_applies() {
    for restart in ["always", "never"] {
        let reg = registry(&Arc::default());
        let g = spec(
            &reg,
            &format!(
                "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 1000000, rate_hz = 1000.0 }}\n\
                 [[node]]\nid = \"h\"\nkind = \"hold\"\nrestart = \"{restart}\"\nparams = {{ by = 2 }}\n\
                 [[node]]\nid = \"out\"\nkind = \"null\"\n\
                 [[edge]]\nfrom = \"src.out\"\nto = \"h.in\"\n\
                 [[edge]]\nfrom = \"h.out\"\nto = \"out.in\"\n"
            ),
        );
        let running = RunningGraph::start(&g).unwrap();
        let wait = Duration::from_secs(60);
        match running.control_wait("h", "panic", wait) {
            Err(RunError::Control { error: NodeError::Panic(msg), .. }) => {
                assert_eq!(msg, "hold: control", "{restart}")
            }
            other => panic!("{restart}: expected the panic as the answer, got {other:?}"),
        }
        if restart == "always" {
            // The rebuilt instance answers the next command; the run goes on.
            running.control_wait("h", "tare", wait).unwrap();
        }
        let stop = Arc::new(AtomicBool::new(true));
        let r = running.wait(&RunOptions { stop: Some(stop), ..RunOptions::default() });
        let h = node(&r, "h");
        match restart {
            "always" => {
                assert!(r.failures.is_empty(), "{:?}", r.failures);
                assert_eq!((h.panics, h.restarts), (1, 1));
            }
            _ => {
                assert_eq!((h.panics, h.restarts), (1, 0));
                assert!(
                    matches!(r.failures.as_slice(), [RunError::Node { node, error: NodeError::Panic(m) }] if node == "h" && m == "hold: control"),
                    "{:?}",
                    r.failures
                );
            }
        }
    }
}

#[test]
fn a_command_queued_behind_a_fatal_panic_is_not_run_on_the_dead_instance() {
    let reg = registry(&Arc::default());
    // Lockstep runs in `wait`: both commands are queued before the node's first call, and
    // applied one after the other there.
    let g = spec(
        &reg,
        "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = { count = 10 }\n\
         [[node]]\nid = \"h\"\nkind = \"hold\"\nrestart = \"never\"\nparams = { by = 1 }\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"h.in\"\n\
         [[edge]]\nfrom = \"h.out\"\nto = \"out.in\"\n",
    );
    let running = RunningGraph::start(&g).unwrap();
    running.control("h", "panic").unwrap();
    running.control("h", "tare").unwrap();
    let r = running.wait(&RunOptions::default());
    let h = node(&r, "h");
    assert_eq!(h.panics, 1);
    assert_eq!(h.counters.get("commands_run").copied().unwrap_or(0), 0, "the dead instance ran a command");
    assert!(
        matches!(r.failures.as_slice(), [RunError::Node { node, error: NodeError::Panic(m) }] if node == "h" && m == "hold: control"),
        "{:?}",
        r.failures
    );
}

#[test]
fn when_a_start_fails_the_nodes_already_started_are_stopped_and_a_stop_that_panics_is_caught() {
    for mode in ["lockstep", "realtime"] {
        let reg = registry(&Arc::default());
        // Sinks start first: `late` (its stop panics) is started when `early` fails to start.
        let g = spec(
            &reg,
            &format!(
                "[graph]\nmode = \"{mode}\"\n\
                 [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 3 }}\n\
                 [[node]]\nid = \"early\"\nkind = \"hold\"\nparams = {{ by = 0, start_fails = true }}\n\
                 [[node]]\nid = \"late\"\nkind = \"hold\"\nparams = {{ by = 0, stop_panics = true }}\n\
                 [[node]]\nid = \"out\"\nkind = \"null\"\n\
                 [[edge]]\nfrom = \"src.out\"\nto = \"early.in\"\n\
                 [[edge]]\nfrom = \"early.out\"\nto = \"late.in\"\n\
                 [[edge]]\nfrom = \"late.out\"\nto = \"out.in\"\n"
            ),
        );
        match RunningGraph::start(&g) {
            Err(RunError::Start { node, kind, error }) => {
                assert_eq!((node.as_str(), kind.as_str()), ("early", "hold"), "{mode}");
                assert_eq!(error.to_string(), "hold: start failed", "{mode}");
            }
            Err(other) => panic!("{mode}: expected the start error, got {other:?}"),
            Ok(_) => panic!("{mode}: the graph started"),
        }
    }
}

#[test]
fn a_swap_whose_input_file_is_missing_is_refused_naming_the_param_and_the_node_goes_on() {
    let reg = registry(&Arc::default());
    let running = RunningGraph::start(&spec(
        &reg,
        "[[node]]\nid = \"src\"\nkind = \"slow\"\nparams = { every_s = 0.001 }\n\
         [[node]]\nid = \"h\"\nkind = \"hold\"\nparams = { by = 0 }\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"h.in\"\n\
         [[edge]]\nfrom = \"h.out\"\nto = \"out.in\"\n",
    ))
    .unwrap();
    let h = running.handle();
    let hold = reg.get("hold").unwrap().clone();
    let missing = "by = 0\nneeds_file = \"no/such/file.toml\"";
    let e = h.swap("h", hold.clone(), Params::from_toml(missing).unwrap()).unwrap_err().to_string();
    assert!(e.contains("node \"h\"") && e.contains("needs_file") && e.contains("no/such/file.toml"), "{e}");
    // A file that is there: the swap goes through.
    let present = format!("by = 0\nneeds_file = \"{}\"", env!("CARGO_MANIFEST_PATH"));
    h.swap_wait("h", hold, Params::from_toml(&present).unwrap(), Duration::from_secs(10)).unwrap();
    let r = running.wait(&RunOptions { stop: Some(Arc::new(AtomicBool::new(true))), ..RunOptions::default() });
    assert!(r.failures.is_empty(), "{:?}", r.failures);
    assert_eq!(node(&r, "h").swaps, 1);
}

// ---------------------------------------------------------------------------------------------
// Reruns and triggers, the drain timeout, periodic periods, aligned inputs that end, control
// work on busy dedicated nodes. Every run that could hang on a regression runs under a
// watchdog ([`within`]): the test fails after a generous bound instead of hanging.
mod engine_bounds {
    use super::*;
    use std::sync::Mutex;

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct BusyParams {
        #[serde(default)]
        busy_us: u64,
    }
    impl NodeParams for BusyParams {}

    /// The (a, b) sequence numbers of each call of a `pairs` node that took inputs.
    type Log = Arc<Mutex<Vec<(Option<u64>, Option<u64>)>>>;

    /// Aligned on (a, b): queues both messages of each set and emits one per call, asking to
    /// be rerun while it holds more (the shape of `sync` or `lag` with a backlog). Records the
    /// inputs of every call that took any; flushes what it still holds at end of stream.
    struct Pairs {
        log: Log,
        queued: VecDeque<Message>,
        empty_calls: Arc<AtomicU64>,
    }
    impl Processor for Pairs {
        fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
            let (a, b) = (inputs.get(0), inputs.get(1));
            if a.is_some() || b.is_some() {
                self.log.lock().unwrap().push((a.map(|m| m.header.seq), b.map(|m| m.header.seq)));
            } else {
                self.empty_calls.fetch_add(1, SeqCst);
            }
            self.queued.extend(a.cloned());
            self.queued.extend(b.cloned());
            if let Some(m) = self.queued.pop_front() {
                out.send(0, m)?;
            }
            if !self.queued.is_empty() {
                ctx.request_rerun();
            }
            Ok(())
        }
        fn flush(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<(), NodeError> {
            if let Some(m) = self.queued.pop_front() {
                out.send(0, m)?;
            }
            if !self.queued.is_empty() {
                ctx.request_rerun();
            }
            Ok(())
        }
        fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
            ctx.count_discarded(self.queued.len() as u64);
            Ok(())
        }
    }

    /// Asks to be rerun forever once it saw an input (the node bug the drain timeout is for).
    struct Spin {
        seen: bool,
    }
    impl Processor for Spin {
        fn process(&mut self, ctx: &mut Context, inputs: &Inputs, _out: &mut Outputs) -> Result<(), NodeError> {
            self.seen |= !inputs.is_empty();
            if self.seen {
                ctx.request_rerun();
            }
            Ok(())
        }
    }

    /// Busy-waits `busy_us` per call, passes its input on, accepts every control command.
    struct Busy {
        d: Duration,
    }
    impl Processor for Busy {
        fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
            let t0 = Instant::now();
            while t0.elapsed() < self.d {
                std::hint::spin_loop();
            }
            if let Some(m) = inputs.get(0) {
                out.send(0, m.clone())?;
            }
            Ok(())
        }
        fn control(&mut self, _ctx: &mut Context, _cmd: &str) -> Result<(), NodeError> {
            Ok(())
        }
    }

    fn reg(log: &Log, empty_calls: &Arc<AtomicU64>) -> Registry {
        let mut r = registry(&Arc::default());
        let count = || PortSpec::output::<Count>("out", "the value");
        let (log, empty_calls) = (log.clone(), empty_calls.clone());
        r.register(typed(
            KindInfo::new("pairs", Role::Processor, "test: aligned pairs, one output per call")
                .input(PortSpec::input::<Count>("a", "a"))
                .input(PortSpec::input::<Count>("b", "b"))
                .output(count()),
            move |_: BusyParams, _| {
                Ok(NodeImpl::Processor(Box::new(Pairs {
                    log: log.clone(),
                    queued: VecDeque::new(),
                    empty_calls: empty_calls.clone(),
                })))
            },
        ))
        .unwrap();
        r.register(typed(
            KindInfo::new("spin", Role::Processor, "test: reruns forever")
                .input(PortSpec::input::<Count>("in", "in"))
                .output(count()),
            |_: BusyParams, _| Ok(NodeImpl::Processor(Box::new(Spin { seen: false }))),
        ))
        .unwrap();
        r.register(typed(
            KindInfo::new("busy", Role::Processor, "test: slow pass-through")
                .input(PortSpec::input::<Count>("in", "in"))
                .output(count()),
            |p: BusyParams, _| Ok(NodeImpl::Processor(Box::new(Busy { d: Duration::from_micros(p.busy_us) }))),
        ))
        .unwrap();
        r
    }

    /// How long a run that should end is given before the test fails (not an assertion on
    /// speed: every run here ends in well under a second).
    const WATCHDOG: Duration = Duration::from_secs(120);

    /// Runs `f` on another thread; fails the test (instead of hanging) when it has not
    /// returned within [`WATCHDOG`].
    fn within<T: Send + 'static>(what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(f());
        });
        match rx.recv_timeout(WATCHDOG) {
            Ok(r) => r,
            Err(_) => panic!("{what}: did not return within {WATCHDOG:?}"),
        }
    }

    fn edge_to<'a>(r: &'a RunReport, to: &str) -> &'a crate::stats::EdgeReport {
        r.stats.edges.iter().find(|e| e.to == to).unwrap()
    }

    #[test]
    fn a_rerun_call_takes_only_what_the_aligned_trigger_would_take_and_loses_nothing() {
        for mode in ["lockstep", "realtime"] {
            let log: Log = Arc::default();
            let empty_calls = Arc::new(AtomicU64::new(0));
            let r = reg(&log, &empty_calls);
            // b's stream lags a's by one message (released at end of stream by `lag`'s
            // flush), so `p` often has a backlog and a rerun while a's next head waits.
            let g = spec(
                &r,
                &format!(
                    "[graph]\nmode = \"{mode}\"\n\
                     [[node]]\nid = \"sa\"\nkind = \"counter\"\nparams = {{ count = 10 }}\n\
                     [[node]]\nid = \"sb\"\nkind = \"counter\"\nparams = {{ count = 10 }}\n\
                     [[node]]\nid = \"lag\"\nkind = \"lag\"\nparams = {{ by = 1 }}\n\
                     [[node]]\nid = \"p\"\nkind = \"pairs\"\ntrigger = \"aligned\"\n\
                     [[node]]\nid = \"out\"\nkind = \"null\"\n\
                     [[edge]]\nfrom = \"sa.out\"\nto = \"p.a\"\n\
                     [[edge]]\nfrom = \"sb.out\"\nto = \"lag.in\"\n\
                     [[edge]]\nfrom = \"lag.out\"\nto = \"p.b\"\n\
                     [[edge]]\nfrom = \"p.out\"\nto = \"out.in\"\n"
                ),
            );
            let rep = within(mode, move || crate::runtime::run(&g, &RunOptions::default()).unwrap());
            assert!(rep.failures.is_empty(), "{mode}: {:?}", rep.failures);
            let calls = log.lock().unwrap().clone();
            let expected: Vec<_> = (0..10).map(|k| (Some(k), Some(k))).collect();
            assert_eq!(calls, expected, "{mode}: every call that took inputs took one aligned set");
            assert!(empty_calls.load(SeqCst) > 0, "{mode}: the reruns were calls without inputs");
            assert_eq!(rep.stats.total_drops(), 0, "{mode}: nothing dropped");
            let p = node(&rep, "p");
            assert_eq!((p.msgs_in, p.msgs_out, p.discarded), (20, 20, 0), "{mode}");
            assert_eq!(node(&rep, "out").msgs_in, 20, "{mode}");
        }
    }

    #[test]
    fn a_node_that_never_stops_asking_to_rerun_is_stopped_at_the_drain_timeout_and_reported() {
        for (mode, thread) in [("lockstep", ""), ("realtime", "pool"), ("realtime", "dedicated")] {
            let r = reg(&Arc::default(), &Arc::default());
            let (workers, placement) = match thread {
                "" => (String::new(), String::new()),
                t => ("workers = 2\n".to_owned(), format!("thread = \"{t}\"\n")),
            };
            let g = spec(
                &r,
                &format!(
                    "[graph]\nmode = \"{mode}\"\n{workers}\
                     [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 1 }}\n\
                     [[node]]\nid = \"s\"\nkind = \"spin\"\n{placement}\
                     [[node]]\nid = \"out\"\nkind = \"null\"\n\
                     [[edge]]\nfrom = \"src.out\"\nto = \"s.in\"\n\
                     [[edge]]\nfrom = \"s.out\"\nto = \"out.in\"\n"
                ),
            );
            let what = format!("{mode}, {thread}");
            let rep = within(&what, move || {
                let mut running = RunningGraph::start(&g).unwrap();
                running.set_drain_timeout(Duration::from_millis(200));
                running.wait(&RunOptions::default())
            });
            match rep.failures.as_slice() {
                [RunError::Node { node, error }] => {
                    assert_eq!(node, "s", "{what}");
                    assert!(error.to_string().contains("drain timeout"), "{what}: {error}");
                }
                other => panic!("{what}: expected the spinning node's failure, got {other:?}"),
            }
            assert_eq!(node(&rep, "s").msgs_in, 1, "{what}");
        }
    }

    #[test]
    fn a_period_below_the_minimum_is_refused_naming_the_param_and_the_minimum() {
        let r = reg(&Arc::default(), &Arc::default());
        let text = |period: &str| {
            format!(
                "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 1 }}\n\
                 [[node]]\nid = \"s\"\nkind = \"scale\"\ntrigger = \"periodic\"\nperiod_ms = {period}\n\
                 [[node]]\nid = \"out\"\nkind = \"null\"\n\
                 [[edge]]\nfrom = \"src.out\"\nto = \"s.in\"\n\
                 [[edge]]\nfrom = \"s.out\"\nto = \"out.in\"\n"
            )
        };
        for tiny in ["0.0000001", "0.009"] {
            let e =
                GraphSpec::parse(SourceFile::new("<runtime-test>", text(tiny).as_str()), &r).err().expect("refused");
            let e = e.to_string();
            assert!(e.contains("node \"s\"") && e.contains("period_ms") && e.contains("at least 0.01 ms"), "{e}");
        }
        // The minimum itself runs, and the run ends.
        let g = spec(&r, &text("0.01"));
        let rep =
            within("a run at the minimum period", move || crate::runtime::run(&g, &RunOptions::default()).unwrap());
        assert!(rep.failures.is_empty(), "{:?}", rep.failures);
        assert_eq!(node(&rep, "s").msgs_in, 1);
    }

    #[test]
    fn the_timer_skips_missed_periods_in_one_step_however_short_the_period() {
        let t = Instant::now();
        let late = t + Duration::from_secs(3600);
        for period in [Duration::ZERO, Duration::from_nanos(1), Duration::from_micros(10), Duration::from_millis(7)] {
            let next = super::super::next_tick(t, late, period);
            let step = period.max(super::super::MIN_TIMER_PERIOD);
            assert!(next > late && next <= late + step, "{period:?}: {:?} after", next - late);
            // On the grid: a whole number of periods after the missed tick.
            assert_eq!((next - t).as_nanos() % step.as_nanos(), 0, "{period:?}");
        }
        let on_time = super::super::next_tick(t, t, Duration::from_millis(5));
        assert_eq!(on_time - t, Duration::from_millis(5));
    }

    #[test]
    fn an_aligned_join_drops_what_can_no_longer_align_once_an_input_has_ended() {
        for mode in ["lockstep", "realtime"] {
            let r = reg(&Arc::default(), &Arc::default());
            let g = spec(
                &r,
                &format!(
                    "[graph]\nmode = \"{mode}\"\n\
                     [[node]]\nid = \"a\"\nkind = \"counter\"\nparams = {{ count = 100 }}\n\
                     [[node]]\nid = \"b\"\nkind = \"counter\"\nparams = {{ count = 5 }}\n\
                     [[node]]\nid = \"sum\"\nkind = \"sum\"\ntrigger = \"aligned\"\n\
                     [[node]]\nid = \"out\"\nkind = \"null\"\n\
                     [[edge]]\nfrom = \"a.out\"\nto = \"sum.a\"\ncapacity = 4\n\
                     [[edge]]\nfrom = \"b.out\"\nto = \"sum.b\"\ncapacity = 4\n\
                     [[edge]]\nfrom = \"sum.out\"\nto = \"out.in\"\n"
                ),
            );
            let rep = within(mode, move || crate::runtime::run(&g, &RunOptions::default()).unwrap());
            assert!(rep.failures.is_empty(), "{mode}: {:?}", rep.failures);
            let sum = node(&rep, "sum");
            assert_eq!((sum.calls, sum.msgs_out), (5, 5), "{mode}: the five aligned pairs");
            let a = edge_to(&rep, "sum.a");
            assert_eq!((a.pushed, a.dropped_unaligned, a.undelivered), (100, 95, 0), "{mode}");
            assert_eq!(edge_to(&rep, "sum.b").drops, 0, "{mode}");
        }
    }

    #[test]
    fn an_aligned_join_fed_through_a_processor_drops_what_can_no_longer_align_once_it_has_flushed() {
        // b ends after 5 messages; `lag` holds its last one until its own end of stream, which
        // comes when its input has ended (not at the run's end): it flushes, closes its output,
        // and `sum` then knows its b input stays empty. Before, `sum` waited for b forever:
        // a lockstep run reported a deadlock, a real-time one hung with `a` blocked.
        for mode in ["lockstep", "realtime"] {
            let r = reg(&Arc::default(), &Arc::default());
            let g = spec(
                &r,
                &format!(
                    "[graph]\nmode = \"{mode}\"\n\
                     [[node]]\nid = \"a\"\nkind = \"counter\"\nparams = {{ count = 10000 }}\n\
                     [[node]]\nid = \"b\"\nkind = \"counter\"\nparams = {{ count = 5 }}\n\
                     [[node]]\nid = \"lag\"\nkind = \"lag\"\nparams = {{ by = 1 }}\n\
                     [[node]]\nid = \"sum\"\nkind = \"sum\"\ntrigger = \"aligned\"\n\
                     [[node]]\nid = \"out\"\nkind = \"null\"\n\
                     [[edge]]\nfrom = \"a.out\"\nto = \"sum.a\"\ncapacity = 4\n\
                     [[edge]]\nfrom = \"b.out\"\nto = \"lag.in\"\n\
                     [[edge]]\nfrom = \"lag.out\"\nto = \"sum.b\"\ncapacity = 4\n\
                     [[edge]]\nfrom = \"sum.out\"\nto = \"out.in\"\n"
                ),
            );
            let rep = within(mode, move || crate::runtime::run(&g, &RunOptions::default()).unwrap());
            assert!(rep.failures.is_empty(), "{mode}: {:?}", rep.failures);
            let lag = node(&rep, "lag");
            assert_eq!((lag.msgs_in, lag.msgs_out, lag.flushes, lag.discarded), (5, 5, 1, 0), "{mode}");
            let sum = node(&rep, "sum");
            assert_eq!((sum.calls, sum.msgs_out), (5, 5), "{mode}: the five aligned pairs");
            let a = edge_to(&rep, "sum.a");
            assert_eq!((a.pushed, a.dropped_unaligned, a.undelivered), (10000, 9995, 0), "{mode}");
            assert_eq!(node(&rep, "out").msgs_in, 5, "{mode}");
        }
    }

    #[test]
    fn a_processor_flushed_at_the_end_of_the_run_is_flushed_once_even_if_input_reaches_it_later() {
        // `u` has no room when the end-of-run flush visits it (`d` waits for the periodic
        // `p`); `i`, downstream of `u`, is flushed then. Once `p` is flushed `u` goes on and
        // ends; what it then sends `i` stays on `i`'s input, counted as undelivered: `i` is
        // never flushed a second time (a node emitting a trailer would emit it twice).
        for mode in ["lockstep", "realtime"] {
            let r = reg(&Arc::default(), &Arc::default());
            let g = spec(
                &r,
                &format!(
                    "[graph]\nmode = \"{mode}\"\n\
                     [[node]]\nid = \"s\"\nkind = \"counter\"\nparams = {{ count = 4 }}\n\
                     [[node]]\nid = \"u\"\nkind = \"lag\"\nparams = {{ by = 1 }}\n\
                     [[node]]\nid = \"i\"\nkind = \"lag\"\nparams = {{ by = 1 }}\n\
                     [[node]]\nid = \"p\"\nkind = \"lag\"\ntrigger = \"periodic\"\nperiod_ms = 1\nparams = {{ by = 5 }}\n\
                     [[node]]\nid = \"d\"\nkind = \"sum\"\ntrigger = \"aligned\"\n\
                     [[node]]\nid = \"out\"\nkind = \"null\"\n\
                     [[edge]]\nfrom = \"s.out\"\nto = \"u.in\"\n\
                     [[edge]]\nfrom = \"s.out\"\nto = \"p.in\"\n\
                     [[edge]]\nfrom = \"u.out\"\nto = \"i.in\"\n\
                     [[edge]]\nfrom = \"u.out\"\nto = \"d.a\"\ncapacity = 1\n\
                     [[edge]]\nfrom = \"p.out\"\nto = \"d.b\"\n\
                     [[edge]]\nfrom = \"i.out\"\nto = \"out.in\"\n\
                     [[edge]]\nfrom = \"d.out\"\nto = \"out.in\"\n"
                ),
            );
            let rep = within(mode, move || crate::runtime::run(&g, &RunOptions::default()).unwrap());
            assert!(rep.failures.is_empty(), "{mode}: {:?}", rep.failures);
            // `lag` with `by = 1` holds one message: one flush call per flush.
            for id in ["u", "i"] {
                assert!(node(&rep, id).flushes <= 1, "{mode}: {id} flushed {} times", node(&rep, id).flushes);
            }
            // Nothing lost uncounted: what `i` took it emitted or counted at its stop, and
            // what it did not take is counted on its input.
            let (i, e) = (node(&rep, "i"), edge_to(&rep, "i.in"));
            assert_eq!(e.pushed, i.msgs_in + e.undelivered, "{mode}: {e:?}");
            assert_eq!(i.msgs_in, i.msgs_out + i.discarded, "{mode}");
        }
    }

    /// Emits one message per call (with or without input); its `control` asks to be rerun.
    struct Kick;
    impl Processor for Kick {
        fn process(&mut self, ctx: &mut Context, _inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
            out.send(0, Message::new(Header { seq: 99, t_ns: 0, origin: ctx.index() }, Count(99)))
        }
        fn control(&mut self, ctx: &mut Context, _cmd: &str) -> Result<(), NodeError> {
            ctx.request_rerun();
            Ok(())
        }
    }

    #[test]
    fn a_processor_flushed_mid_run_is_not_called_again_even_when_a_control_asks_for_a_rerun() {
        let mut r = reg(&Arc::default(), &Arc::default());
        r.register(typed(
            KindInfo::new("kick", Role::Processor, "test: emits per call, a control asks for a rerun")
                .input(PortSpec::input::<Count>("in", "in"))
                .output(PortSpec::output::<Count>("out", "the value")),
            |_: BusyParams, _| Ok(NodeImpl::Processor(Box::new(Kick))),
        ))
        .unwrap();
        let g = spec(
            &r,
            "[graph]\nmode = \"realtime\"\n\
             [[node]]\nid = \"e\"\nkind = \"ends\"\nparams = { count = 1 }\n\
             [[node]]\nid = \"live\"\nkind = \"slow\"\nparams = { every_s = 0.01 }\n\
             [[node]]\nid = \"k\"\nkind = \"kick\"\n\
             [[node]]\nid = \"out\"\nkind = \"null\"\n\
             [[edge]]\nfrom = \"e.out\"\nto = \"k.in\"\n\
             [[edge]]\nfrom = \"k.out\"\nto = \"out.in\"\n\
             [[edge]]\nfrom = \"live.out\"\nto = \"out.in\"\n",
        );
        let (before, after, rep) = within("kick", move || {
            let running = RunningGraph::start(&g).unwrap();
            let h = running.handle();
            wait_for("k flushed mid-run", || h.stats().node("k").unwrap().flushes == 1);
            let before = h.stats().node("k").unwrap().calls;
            h.control_wait("k", "kick", Duration::from_secs(30)).unwrap();
            let after = h.stats().node("k").unwrap().calls;
            let rep = running.wait(&RunOptions { stop: Some(Arc::new(AtomicBool::new(true))), ..Default::default() });
            (before, after, rep)
        });
        assert_eq!((before, after), (1, 1), "a processor flushed mid-run was called again");
        let k = node(&rep, "k");
        assert_eq!((k.calls, k.msgs_out, k.flushes), (1, 1, 1));
    }

    #[test]
    fn a_swap_into_a_processor_flushed_mid_run_is_refused_saying_why() {
        let r = reg(&Arc::default(), &Arc::default());
        let busy = r.get("busy").unwrap().clone();
        let g = spec(
            &r,
            "[graph]\nmode = \"realtime\"\n\
             [[node]]\nid = \"e\"\nkind = \"ends\"\nparams = { count = 1 }\n\
             [[node]]\nid = \"live\"\nkind = \"slow\"\nparams = { every_s = 0.01 }\n\
             [[node]]\nid = \"p\"\nkind = \"busy\"\n\
             [[node]]\nid = \"out\"\nkind = \"null\"\n\
             [[edge]]\nfrom = \"e.out\"\nto = \"p.in\"\n\
             [[edge]]\nfrom = \"p.out\"\nto = \"out.in\"\n\
             [[edge]]\nfrom = \"live.out\"\nto = \"out.in\"\n",
        );
        let (swap, rep) = within("swap into a flushed node", move || {
            let running = RunningGraph::start(&g).unwrap();
            let h = running.handle();
            wait_for("p flushed mid-run", || h.stats().node("p").unwrap().flushes == 1);
            let swap = h.swap_wait("p", busy, Params::from_toml("busy_us = 1").unwrap(), Duration::from_secs(30));
            let rep = running.wait(&RunOptions { stop: Some(Arc::new(AtomicBool::new(true))), ..Default::default() });
            (swap, rep)
        });
        match swap {
            Err(RunError::Swap { node, problem }) => {
                assert_eq!(node, "p");
                assert!(problem.contains("has flushed and closed its outputs"), "{problem}");
            }
            other => panic!("expected the refusal, got {other:?}"),
        }
        assert!(rep.failures.is_empty(), "{:?}", rep.failures);
        assert_eq!(node(&rep, "p").swaps, 0);
    }

    #[test]
    fn a_busy_dedicated_node_runs_controls_and_swaps_between_two_calls() {
        for thread in ["pool", "dedicated"] {
            let r = reg(&Arc::default(), &Arc::default());
            let busy = r.get("busy").unwrap().clone();
            let g = spec(
                &r,
                &format!(
                    "[graph]\nworkers = 1\n\
                     [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 1000000 }}\n\
                     [[node]]\nid = \"p\"\nkind = \"busy\"\nthread = \"{thread}\"\nparams = {{ busy_us = 300 }}\n\
                     [[node]]\nid = \"out\"\nkind = \"null\"\n\
                     [[edge]]\nfrom = \"src.out\"\nto = \"p.in\"\n\
                     [[edge]]\nfrom = \"p.out\"\nto = \"out.in\"\n"
                ),
            );
            let rep = within(thread, move || {
                let running = RunningGraph::start(&g).unwrap();
                let h = running.handle();
                wait_for("p running", || h.stats().node("p").unwrap().calls > 100);
                // Generous bounds: a regression fails here rather than hangs.
                let control = h.control_wait("p", "x", Duration::from_secs(30));
                let swap = h.swap_wait("p", busy, Params::from_toml("busy_us = 100").unwrap(), Duration::from_secs(30));
                let still_busy = h.stats().node("p").unwrap().calls < 1_000_000;
                let stop = Arc::new(AtomicBool::new(true));
                let rep = running.wait(&RunOptions { stop: Some(stop), ..Default::default() });
                (control, swap, still_busy, rep)
            });
            let (control, swap, still_busy, rep) = rep;
            assert!(control.is_ok(), "{thread}: {control:?}");
            assert!(swap.is_ok(), "{thread}: {swap:?}");
            assert!(still_busy, "{thread}: the node was still busy (ready) when both were applied");
            assert!(rep.failures.is_empty(), "{thread}: {:?}", rep.failures);
            assert_eq!(node(&rep, "p").swaps, 1, "{thread}");
        }
    }
}
