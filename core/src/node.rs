//! The node roles and the per-node context.
//!
//! One trait per role: a [`Source`] produces messages (on its own thread, so it may block on
//! I/O), a [`Processor`] turns inputs into outputs on the worker pool, a [`Sink`] consumes.
//! Lifecycle: the kind's factory constructs the node (reads params, allocates every buffer,
//! fails here) -> `start` -> `poll`/`process`/`consume` (hot: no allocation) -> for processors,
//! [`Processor::flush`] once the stream has ended (emit what is still buffered) -> `stop`
//! (flush, close; called once, also after errors).
//!
//! No silent loss: whatever a node holds and can no longer emit (its flush could not run or
//! finish) it counts with [`Context::count_discarded`] in its `stop`; the run report shows it
//! beside the edges' drops.
//!
//! Hot swap (see [`crate::runtime::GraphHandle::swap`]): the replacement is built and started
//! off the data path; between two calls the engine asks the old instance for its learned state
//! ([`Processor::export_state`], e.g. an EIT reference frame, a tare, a noise estimate,
//! buffered input), offers it to the replacement ([`Processor::import_state`]), and then stops
//! the old instance. A replacement that does not recognize the state (another kind, another
//! channel count) returns it; the engine logs why and gives it back to the old instance before
//! its `stop`, so nothing it buffered is silently dropped. A replacement that cannot go on
//! from the state at all (a source asked to continue another recording or scene, a logger
//! asked to write the file the running instance is writing) refuses the swap instead
//! ([`StateRefused::refuse_swap`]): the old instance takes its state back and keeps running,
//! the replacement is stopped, and the swap is answered with the reason. The same hooks exist
//! on every role.

use std::any::Any;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::error::NodeError;
use crate::io::{Inputs, Outputs};
use crate::stats::NodeStats;

/// How the graph is scheduled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Sources on their own threads, processors on the worker pool, real-time pacing.
    #[default]
    Realtime,
    /// One thread, fixed order, no pacing: bit-identical outputs run to run.
    Lockstep,
}

/// What a source's `poll` did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourcePoll {
    /// Put messages in its output slots (or consumed input without output); poll again.
    Emitted,
    /// Nothing available yet (a read timed out); poll again.
    Idle,
    /// The source is exhausted; it will not be polled again.
    Finished,
}

/// What a node's instance learned from the stream, handed to its replacement in a hot swap.
/// Opaque to the engine: each kind exports its own type and downcasts on import.
pub type NodeState = Box<dyn Any + Send>;

/// A hand-over the replacement refused: the state goes back to the replaced instance.
pub struct StateRefused {
    pub state: NodeState,
    /// Why (e.g. "state of another kind", "the sensor has 208 channels, the state 192").
    pub reason: String,
    /// The replacement cannot take the node over at all ([`StateRefused::refuse_swap`]): the
    /// swap is refused and the replaced instance goes on. `false`: the replacement starts
    /// afresh ([`StateRefused::new`]).
    pub swap_refused: bool,
}

impl StateRefused {
    /// The replacement does not take this state over and starts afresh; the swap goes on.
    pub fn new(state: NodeState, reason: impl Into<String>) -> StateRefused {
        StateRefused { state, reason: reason.into(), swap_refused: false }
    }

    /// The replacement cannot go on from this state, and starting afresh would break what
    /// the node already emitted (a source's time and sequence numbers would go back, a
    /// recording would be replaced): the swap is refused with `reason`. The engine gives the
    /// state back to the running instance ([`Source::import_state`] and the like, which must
    /// take its own state back), which keeps running; the replacement is stopped.
    pub fn refuse_swap(state: NodeState, reason: impl Into<String>) -> StateRefused {
        StateRefused { state, reason: reason.into(), swap_refused: true }
    }
}

impl std::fmt::Debug for StateRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StateRefused")
            .field("reason", &self.reason)
            .field("swap_refused", &self.swap_refused)
            .finish_non_exhaustive()
    }
}

/// The default `import_state`: this kind takes over nothing.
fn refuse(state: NodeState) -> Result<(), StateRefused> {
    Err(StateRefused::new(state, "this kind takes over no state"))
}

/// A producer of messages.
pub trait Source: Send {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        Ok(())
    }
    /// Produces at most one message per output port. May block (read with a timeout of at
    /// most ~100 ms so a stop request is seen promptly). Pacing sources should wait with
    /// [`Context::sleep_until_ns`], which returns early on stop and never sleeps in lockstep.
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError>;
    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        Ok(())
    }
    /// A control command (e.g. `tare`) from the control socket or a test.
    fn control(&mut self, _ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        Err(NodeError::msg(format!("control command \"{cmd}\" is not supported by this node")))
    }
    /// Hot swap: this instance is being replaced. Returns what it learned from the stream
    /// (references, tares, noise estimates, buffered input) for the replacement; called after
    /// its last call and before its `stop` (when the replacement refuses the swap, the state
    /// comes back through `import_state` and this instance goes on). Default: nothing.
    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        None
    }
    /// Hot swap: takes over the state exported by the replaced instance, before this
    /// instance's first call. Returns it (with the reason) when it is not of a type this node
    /// knows or does not fit; it then goes back to the replaced instance. Returned with
    /// [`StateRefused::refuse_swap`], the swap is refused and the replaced instance goes on,
    /// so an instance must take its own exported state back. Default: refuse (start afresh).
    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        refuse(state)
    }
}

/// A transformer of messages.
pub trait Processor: Send {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        Ok(())
    }
    /// Handles the inputs selected by the node's trigger; at most one message per output port.
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError>;
    /// End of stream: emits what the node still buffers (e.g. frames waiting for a window that
    /// no more input can fill), so nothing it received is lost when its sources end.
    ///
    /// Called once every node upstream of this one is done (sources finished or stopped on
    /// request, processors flushed) and this node's inputs are drained; before the nodes
    /// downstream are flushed and before any node is stopped, so what it emits is processed
    /// downstream, reaches the sinks and is counted in the run report. At most one message per
    /// output port per call, as in `process`: [`Context::request_rerun`] asks to be called
    /// again once these outputs are published and there is room downstream. Also runs after a
    /// stop request (Ctrl-C, a duration limit): data already received is still emitted, within
    /// the shutdown's drain timeout. Not called on a dead instance (panicked, failed) or when
    /// the drain timed out: `stop` then counts what is left with [`Context::count_discarded`].
    /// This may come mid-run, once every input of a (non-periodic) processor has ended while
    /// other branches of the graph go on: the node is flushed there, never called again, and
    /// its outputs are closed, so consumers downstream know that no more comes from it.
    /// Default: nothing buffered, nothing to emit.
    fn flush(&mut self, _ctx: &mut Context, _out: &mut Outputs) -> Result<(), NodeError> {
        Ok(())
    }
    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        Ok(())
    }
    fn control(&mut self, _ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        Err(NodeError::msg(format!("control command \"{cmd}\" is not supported by this node")))
    }
    /// Hot swap: this instance is being replaced. Returns what it learned from the stream
    /// (references, tares, noise estimates, buffered input) for the replacement; called after
    /// its last call and before its `stop` (when the replacement refuses the swap, the state
    /// comes back through `import_state` and this instance goes on). Default: nothing.
    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        None
    }
    /// Hot swap: takes over the state exported by the replaced instance, before this
    /// instance's first call. Returns it (with the reason) when it is not of a type this node
    /// knows or does not fit; it then goes back to the replaced instance. Returned with
    /// [`StateRefused::refuse_swap`], the swap is refused and the replaced instance goes on,
    /// so an instance must take its own exported state back. Default: refuse (start afresh).
    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        refuse(state)
    }
}

/// A consumer of messages.
pub trait Sink: Send {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        Ok(())
    }
    fn consume(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError>;
    /// Flushes and closes. Called once at shutdown, after every queued message was consumed.
    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        Ok(())
    }
    fn control(&mut self, _ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        Err(NodeError::msg(format!("control command \"{cmd}\" is not supported by this node")))
    }
    /// Hot swap: this instance is being replaced. Returns what it learned from the stream
    /// (references, tares, noise estimates, buffered input) for the replacement; called after
    /// its last call and before its `stop` (when the replacement refuses the swap, the state
    /// comes back through `import_state` and this instance goes on). Default: nothing.
    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        None
    }
    /// Hot swap: takes over the state exported by the replaced instance, before this
    /// instance's first call. Returns it (with the reason) when it is not of a type this node
    /// knows or does not fit; it then goes back to the replaced instance. Returned with
    /// [`StateRefused::refuse_swap`], the swap is refused and the replaced instance goes on,
    /// so an instance must take its own exported state back. Default: refuse (start afresh).
    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        refuse(state)
    }
}

/// A constructed node of any role.
pub enum NodeImpl {
    Source(Box<dyn Source>),
    Processor(Box<dyn Processor>),
    Sink(Box<dyn Sink>),
}

impl NodeImpl {
    pub(crate) fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        match self {
            NodeImpl::Source(n) => n.start(ctx),
            NodeImpl::Processor(n) => n.start(ctx),
            NodeImpl::Sink(n) => n.start(ctx),
        }
    }

    /// End-of-stream flush: processors only (a source has nothing upstream to wait for, a
    /// sink's `stop` is its flush).
    pub(crate) fn flush(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<(), NodeError> {
        match self {
            NodeImpl::Processor(n) => n.flush(ctx, out),
            NodeImpl::Source(_) | NodeImpl::Sink(_) => Ok(()),
        }
    }

    pub(crate) fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        match self {
            NodeImpl::Source(n) => n.stop(ctx),
            NodeImpl::Processor(n) => n.stop(ctx),
            NodeImpl::Sink(n) => n.stop(ctx),
        }
    }

    pub(crate) fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        match self {
            NodeImpl::Source(n) => n.control(ctx, cmd),
            NodeImpl::Processor(n) => n.control(ctx, cmd),
            NodeImpl::Sink(n) => n.control(ctx, cmd),
        }
    }

    pub(crate) fn export_state(&mut self, ctx: &mut Context) -> Option<NodeState> {
        match self {
            NodeImpl::Source(n) => n.export_state(ctx),
            NodeImpl::Processor(n) => n.export_state(ctx),
            NodeImpl::Sink(n) => n.export_state(ctx),
        }
    }

    pub(crate) fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        match self {
            NodeImpl::Source(n) => n.import_state(ctx, state),
            NodeImpl::Processor(n) => n.import_state(ctx, state),
            NodeImpl::Sink(n) => n.import_state(ctx, state),
        }
    }

    pub fn role(&self) -> crate::registry::Role {
        match self {
            NodeImpl::Source(_) => crate::registry::Role::Source,
            NodeImpl::Processor(_) => crate::registry::Role::Processor,
            NodeImpl::Sink(_) => crate::registry::Role::Sink,
        }
    }
}

/// Per-node context: identity, the graph clock, the stop flag, rerun requests and the
/// node's counter of discarded messages.
pub struct Context {
    pub(crate) index: u32,
    pub(crate) id: Arc<str>,
    pub(crate) origin: Instant,
    pub(crate) mode: Mode,
    pub(crate) stop: Arc<AtomicBool>,
    pub(crate) rerun: bool,
    /// The node's statistics (shared with the run report).
    pub(crate) stats: Arc<NodeStats>,
}

/// Longest single park while a source paces, so a stop request is seen within this time even
/// if the unpark is missed.
const PACE_SLICE: Duration = Duration::from_millis(50);

impl Context {
    pub(crate) fn new(
        index: u32,
        id: Arc<str>,
        origin: Instant,
        mode: Mode,
        stop: Arc<AtomicBool>,
        stats: Arc<NodeStats>,
    ) -> Context {
        Context { index, id, origin, mode, stop, rerun: false, stats }
    }

    /// A context for driving a node outside a graph (unit tests of nodes, benchmarks).
    pub fn detached(id: &str, mode: Mode) -> Context {
        let stats = Arc::new(NodeStats::default());
        Context::new(0, Arc::from(id), Instant::now(), mode, Arc::new(AtomicBool::new(false)), stats)
    }

    /// The node's id from the graph file.
    pub fn id(&self) -> &str {
        &self.id
    }

    /// The node's index, used as `Header::origin`.
    pub fn index(&self) -> u32 {
        self.index
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Whether sources should pace to real time (false in lockstep).
    pub fn paced(&self) -> bool {
        self.mode == Mode::Realtime
    }

    /// Nanoseconds since the graph started, monotonic.
    pub fn now_ns(&self) -> u64 {
        self.origin.elapsed().as_nanos() as u64
    }

    /// Whether the graph is stopping.
    pub fn stopping(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    /// Asks to be called again although no new input arrived (e.g. more buffered output: one
    /// message per output port per call, so a node with a backlog emits one and asks again).
    ///
    /// The next call comes once this call's outputs are published and there is room on the
    /// node's `block` outputs. A rerun never makes the trigger take inputs it would not take
    /// otherwise: if the trigger is satisfied then (`any`: an input has a message; `aligned`:
    /// every input's head aligns; `periodic`: a tick is due), the call takes its inputs as
    /// usual; if not, the node is called with no inputs (an `aligned` node never sees part of
    /// a set, a `periodic` node's inputs wait for its next tick). The request holds for one
    /// call: ask again in that call to be called again. A request made by a call that panics
    /// is dropped with the panicked instance. In [`Processor::flush`] it asks for another
    /// flush call. A node that never stops asking is stopped at the shutdown's drain timeout.
    pub fn request_rerun(&mut self) {
        self.rerun = true;
    }

    /// Counts `n` messages this node held or received and discards without emitting them
    /// (e.g. frames still buffered in `stop` because the end-of-stream flush could not run, or
    /// records a source's device sent that its link lost or rejected). They appear
    /// as the node's `discarded` in the run report and in its and the graph's drops: data is
    /// never lost silently. A cold path (a locked add).
    pub fn count_discarded(&self, n: u64) {
        self.stats.discarded.fetch_add(n, Ordering::Relaxed);
    }

    /// The node's own counter `name` (registered on first use, a cold path: keep the handle),
    /// shown in the run report (`counters` in `--stats-json` and control-socket `stats`, and
    /// a line per node in the table when above 0). For what only the node knows: a serial
    /// link's disconnects, CRC errors, device restarts. Names are short snake_case words.
    pub fn counter(&self, name: &str) -> crate::stats::Counter {
        self.stats.counter(name)
    }

    /// Messages counted with [`Context::count_discarded`] so far (by this node's instances).
    pub fn discarded(&self) -> u64 {
        self.stats.discarded.load(Ordering::Relaxed)
    }

    /// Sleeps until the graph clock reads `t_ns`. Returns false if the graph is stopping.
    /// Does not sleep in lockstep mode.
    pub fn sleep_until_ns(&self, t_ns: u64) -> bool {
        if !self.paced() {
            return !self.stopping();
        }
        loop {
            if self.stopping() {
                return false;
            }
            let now = self.now_ns();
            if now >= t_ns {
                return true;
            }
            let wait = Duration::from_nanos(t_ns - now).min(PACE_SLICE);
            std::thread::park_timeout(wait);
        }
    }
}
