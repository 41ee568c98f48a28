//! Hot swap of a source mid-stream, deterministically: the graph runs in lockstep behind a
//! gate that holds the source after some messages; the swap is queued while it is held, then
//! the gate opens. Shared by the `replay` and `sim` tests.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::SeqCst};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::{
    BuildContext, Context, GraphSpec, NodeError, NodeImpl, NodeParams, NodeState, Outputs, Params, RunOptions,
    RunReport, RunningGraph, Source, SourcePoll, StateRefused, typed,
};

use crate::payload::{EitFrame, PressureSample, Truth};
use crate::pipeline::{Captured, registry_with_capture};

#[derive(Default)]
struct Gate {
    /// Messages let through before holding.
    limit: AtomicU64,
    open: AtomicBool,
    sent: AtomicU64,
    /// Polls answered while held.
    held: AtomicU64,
}

/// A source behind the gate; hands its inner source's state over in a swap.
struct Gated {
    inner: Box<dyn Source>,
    gate: Arc<Gate>,
}

impl Source for Gated {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.inner.start(ctx)
    }
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let g = &self.gate;
        if !g.open.load(SeqCst) && g.sent.load(SeqCst) >= g.limit.load(SeqCst) {
            g.held.fetch_add(1, SeqCst);
            std::thread::yield_now();
            return Ok(SourcePoll::Idle);
        }
        let r = self.inner.poll(ctx, out)?;
        if r == SourcePoll::Emitted {
            g.sent.fetch_add(1, SeqCst);
        }
        Ok(r)
    }
    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.inner.stop(ctx)
    }
    fn export_state(&mut self, ctx: &mut Context) -> Option<NodeState> {
        self.inner.export_state(ctx)
    }
    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        self.inner.import_state(ctx, state)
    }
}

/// The params of the kind behind the gate, as they are.
#[derive(Deserialize)]
struct Pass {
    #[serde(flatten)]
    table: toml::Table,
}
impl NodeParams for Pass {}

/// What a captured message was: its stream, `seq` and `t_ns`.
pub type Sent = (&'static str, u64, u64);

/// Runs source kind `kind` (`params`, an inline-table body) in lockstep into a capture
/// sink, every output connected. With `swap` (after this many messages, to these params),
/// holds the source there, queues a swap to the same kind and opens the gate. Returns
/// what was captured, in order, and the report.
pub fn run(kind: &str, params: &str, swap: Option<(u64, &str)>) -> (Vec<Sent>, RunReport) {
    let gate = Arc::new(Gate::default());
    gate.limit.store(swap.map_or(u64::MAX, |s| s.0), SeqCst);
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let mut reg = registry_with_capture(captured.clone());
    let inner = reg.get(kind).unwrap().clone();
    let mut info = inner.info().clone();
    info.name = "gated".into();
    let outputs: Vec<String> = info.outputs.iter().map(|p| p.name.to_string()).collect();
    let g = gate.clone();
    reg.register(typed(info, move |p: Pass, ctx: &BuildContext| {
        match inner.build(&Params::from_table(p.table), ctx)? {
            NodeImpl::Source(inner) => Ok(NodeImpl::Source(Box::new(Gated { inner, gate: g.clone() }))),
            _ => unreachable!("a source kind"),
        }
    }))
    .unwrap();
    let edges: String =
        outputs.iter().map(|o| format!("[[edge]]\nfrom = \"src.{o}\"\nto = \"cap.in\"\ncapacity = 4096\n")).collect();
    let graph = format!(
        "[graph]\nmode = \"lockstep\"\n[[node]]\nid = \"src\"\nkind = \"gated\"\nparams = {{ {params} }}\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n{edges}"
    );
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let spec = GraphSpec::parse(SourceFile::new(dir.join("swap-test.toml"), graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let runner = std::thread::spawn(move || running.wait(&RunOptions::default()));
    if let Some((_, to)) = swap {
        // Held twice: everything before the gate has run through (a lockstep pass drains).
        let t0 = Instant::now();
        while gate.held.load(SeqCst) < 2 {
            assert!(t0.elapsed() < Duration::from_secs(300), "the source was never held");
            std::thread::sleep(Duration::from_millis(5));
        }
        let table: toml::Table = format!("p = {{ {to} }}").parse().unwrap();
        let params = Params::from_table(table["p"].as_table().unwrap().clone());
        handle.swap("src", reg.get("gated").unwrap().clone(), params).unwrap();
        gate.open.store(true, SeqCst);
    }
    let report = runner.join().unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    let rows = captured.lock().unwrap();
    let sent = rows
        .iter()
        .flatten()
        .map(|m| {
            let stream = if m.get::<EitFrame>().is_some() {
                "eit"
            } else if m.get::<PressureSample>().is_some() {
                "pressure"
            } else if m.get::<Truth>().is_some() {
                "truth"
            } else {
                "other"
            };
            (stream, m.header.seq, m.header.t_ns)
        })
        .collect();
    (sent, report)
}
