//! A source held at a gate, for deterministic hot-swap tests: the graph runs in lockstep, the
//! gate holds the source after some messages, the test queues its swaps while it is held, then
//! opens the gate. Test support, used by this crate's unit and integration tests.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::SeqCst};
use std::time::{Duration, Instant};

use serde::Deserialize;
use skinflow_core::{
    BuildContext, Context, NodeError, NodeImpl, NodeParams, NodeState, Outputs, Params, Registry, Source, SourcePoll,
    StateRefused, typed,
};

/// Where a gated source stops until [`Gate::open_after`] opens it.
#[derive(Debug)]
pub struct Gate {
    /// Messages let through before holding (`u64::MAX`: never hold).
    limit: u64,
    /// Counts only the messages on this output; `None`: every emitted poll.
    port: Option<usize>,
    open: AtomicBool,
    passed: AtomicU64,
    /// Polls answered while held.
    held: AtomicU64,
}

impl Gate {
    /// A gate that holds its source after `limit` messages (`None`: never), counting those on
    /// output `port` only, or every emitted poll with `None`.
    pub fn new(limit: Option<u64>, port: Option<usize>) -> Arc<Gate> {
        Arc::new(Gate {
            limit: limit.unwrap_or(u64::MAX),
            port,
            open: AtomicBool::new(false),
            passed: AtomicU64::new(0),
            held: AtomicU64::new(0),
        })
    }

    /// Waits until the source has been held twice (so everything before the gate has run
    /// through: a lockstep pass drains), runs `while_held` (queue the swaps), then opens.
    ///
    /// # Panics
    /// When the source is never held within 300 s (a gate beyond the source's end).
    pub fn open_after(&self, while_held: impl FnOnce()) {
        let t0 = Instant::now();
        while self.held.load(SeqCst) < 2 {
            assert!(t0.elapsed() < Duration::from_secs(300), "the source was never held");
            std::thread::sleep(Duration::from_millis(5));
        }
        while_held();
        self.open.store(true, SeqCst);
    }
}

/// A source behind a gate; hands its inner source's state over in a swap.
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
        if !g.open.load(SeqCst) && g.passed.load(SeqCst) >= g.limit {
            g.held.fetch_add(1, SeqCst);
            std::thread::yield_now();
            return Ok(SourcePoll::Idle);
        }
        let r = self.inner.poll(ctx, out)?;
        let passed = match g.port {
            Some(p) => out.is_taken(p),
            None => r == SourcePoll::Emitted,
        };
        if passed {
            g.passed.fetch_add(1, SeqCst);
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

/// The params of the kind behind the gate, passed on as they are.
#[derive(Deserialize)]
struct Pass {
    #[serde(flatten)]
    table: toml::Table,
}
impl NodeParams for Pass {}

/// Registers kind `name`: source kind `inner` (already in `reg`, same params and outputs)
/// behind `gate`.
///
/// # Panics
/// When `inner` is not a registered source kind or `name` is taken.
pub fn register(reg: &mut Registry, inner: &str, name: &'static str, gate: Arc<Gate>) {
    let factory = reg.get(inner).unwrap_or_else(|| panic!("no kind \"{inner}\"")).clone();
    let mut info = factory.info().clone();
    info.name = name.into();
    reg.register(typed(info, move |p: Pass, ctx: &BuildContext| {
        match factory.build(&Params::from_table(p.table), ctx)? {
            NodeImpl::Source(inner) => Ok(NodeImpl::Source(Box::new(Gated { inner, gate: gate.clone() }))),
            _ => Err(NodeError::msg("the gated kind is not a source")),
        }
    }))
    .unwrap_or_else(|e| panic!("{e}"));
}
