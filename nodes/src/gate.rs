//! A source held at a gate, for deterministic hot-swap and control tests: the graph runs in
//! lockstep, the gate holds the source after some messages, the test sends its commands and
//! queues its swaps while it is held, then raises or opens the gate. Test support, used by this crate's tests and the workspace's `tests/plugins.rs`.

use std::sync::atomic::{AtomicU64, Ordering::SeqCst};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Deserialize;
use skinflow_core::{
    BuildContext, Context, NodeError, NodeImpl, NodeParams, NodeState, Outputs, Params, Registry, Source, SourcePoll,
    StateRefused, typed,
};

/// Where a gated source stops: once it has sent `limit` messages it answers its polls idle
/// until the limit is raised ([`Gate::raise`], [`Gate::open_after`]).
#[derive(Debug)]
pub struct Gate {
    /// Messages let through before holding (`u64::MAX`: never hold).
    limit: AtomicU64,
    /// Counts only the messages on this output; `None`: every emitted poll.
    port: Option<usize>,
    passed: AtomicU64,
    /// The limit the source was last held at, and the polls it answered idle there.
    held: Mutex<(u64, u64)>,
}

impl Gate {
    /// A gate that holds its source after `limit` messages (`None`: never), counting those on
    /// output `port` only, or every emitted poll with `None`.
    pub fn new(limit: Option<u64>, port: Option<usize>) -> Arc<Gate> {
        Arc::new(Gate {
            limit: AtomicU64::new(limit.unwrap_or(u64::MAX)),
            port,
            passed: AtomicU64::new(0),
            held: Mutex::new((0, 0)),
        })
    }

    /// Waits until the source is held at the current limit and was polled there twice: what
    /// it sent before has gone through the graph (a lockstep pass drains between two polls).
    ///
    /// # Panics
    /// When the source is not held there within 300 s (a limit beyond the source's end).
    pub fn wait_held(&self) {
        let limit = self.limit.load(SeqCst);
        let t0 = Instant::now();
        loop {
            let (at, polls) = *self.held.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            if at == limit && polls >= 2 {
                return;
            }
            // A guard against a hang, not a timing assertion.
            assert!(t0.elapsed() < Duration::from_secs(300), "the source was never held at {limit}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Lets the source go on to `limit` messages (`u64::MAX`: to its end).
    pub fn raise(&self, limit: u64) {
        self.limit.store(limit, SeqCst);
    }

    /// Waits until the source is held ([`Gate::wait_held`]), runs `while_held` (queue the
    /// swaps), then opens the gate for good.
    pub fn open_after(&self, while_held: impl FnOnce()) {
        self.wait_held();
        while_held();
        self.raise(u64::MAX);
    }
}

/// A source behind a gate; commands and hot-swap state go to the source it wraps.
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
        let limit = g.limit.load(SeqCst);
        if g.passed.load(SeqCst) >= limit {
            let mut held = g.held.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            *held = if held.0 == limit { (limit, held.1 + 1) } else { (limit, 1) };
            drop(held);
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
    fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        self.inner.control(ctx, cmd)
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
