//! Running a validated graph: build every node (failing before any data flows), wire the
//! edges, start the executor ([`pool`] threads or [`lockstep`]), and shut down in order:
//! stop sources, drain queues, flush processors in topological order ([`flush`]: what they
//! still buffer goes downstream), stop processors and sinks (flush, close), report.

mod cell;
mod flush;
mod handle;
mod lockstep;
mod pool;
mod rt;
#[cfg(test)]
mod tests;

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering::SeqCst;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam::atomic::AtomicCell;
use crossbeam::deque::Worker;
use crossbeam::queue::ArrayQueue;
use crossbeam::queue::SegQueue;
use crossbeam::sync::Parker;

use cell::{Cell, Recipe};
pub use handle::GraphHandle;
use pool::{Exec, IDLE, Shared, Sleeper, Slot};

use crate::edge::{EdgeTx, edge};
use crate::error::NodeError;
use crate::graph::{GraphSpec, ThreadMode, Trigger};
use crate::io::{Inputs, Outputs};
use crate::node::{Context, Mode, NodeImpl};
use crate::registry::{BuildContext, Role};
use crate::stats::{NodeStats, StatsReport};

/// Longest the shutdown waits for queues to drain and processors to flush before it counts
/// what is left as undelivered (or discarded, by the nodes holding it) and stops the nodes
/// anyway (a node that never stops asking to rerun). Once it has passed no node is called
/// again: workers and node threads exit, `wait` returns, and the run's failures name the
/// nodes still running or queued then.
pub(crate) const DRAIN_TIMEOUT: Duration = Duration::from_secs(30);

/// The failure a node still running or queued when the drain timeout passed is reported with.
pub(crate) fn drain_timeout_error() -> NodeError {
    NodeError::msg(
        "still running when the drain timeout passed (a node that never stops asking to be rerun, or one too slow \
         for its backlog): stopped without the end-of-stream flush, what it held counted as discarded and its \
         queued input as undelivered",
    )
}

/// Why a run did not go as planned.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("node \"{node}\" (kind \"{kind}\") failed to start: {error}")]
    Start { node: String, kind: String, error: NodeError },
    #[error("node \"{node}\": {error}")]
    Node { node: String, error: NodeError },
    #[error("node \"{node}\" failed to stop: {error}")]
    Stop { node: String, error: NodeError },
    #[error("no node \"{0}\" in this graph")]
    UnknownNode(String),
    #[error("node \"{node}\": swap refused: {problem}")]
    Swap { node: String, problem: String },
    #[error(
        "node \"{node}\": swap not installed within {timeout:?} (the node was not called: a source waiting for its next message, or the graph ending); cancelled: the node runs as before"
    )]
    SwapTimeout { node: String, timeout: Duration },
    #[error("node \"{node}\": control \"{command}\" rejected: {error}")]
    Control { node: String, command: String, error: NodeError },
    #[error(
        "node \"{node}\": control \"{command}\" got no answer within {timeout:?} (the node was not called: the graph may have ended); it stays queued"
    )]
    ControlTimeout { node: String, command: String, timeout: Duration },
    #[error(
        "node \"{node}\": control \"{command}\" not run: the node runs no more (a source whose stream ended, a node that failed, or the run is over)"
    )]
    Ended { node: String, command: String },
}

/// The result of a run that started.
#[derive(Debug)]
pub struct RunReport {
    pub stats: StatsReport,
    /// Fatal node errors, panics without restart and stop failures, in order.
    pub failures: Vec<RunError>,
}

/// How long to run and how to be told to stop.
#[derive(Clone, Default)]
pub struct RunOptions {
    /// Stop after this long (sources stop, queues drain).
    pub duration: Option<Duration>,
    /// Set by a Ctrl-C handler (or a test) to stop the run cleanly.
    pub stop: Option<Arc<AtomicBool>>,
}

/// A graph whose nodes are built and started.
pub struct RunningGraph {
    shared: Arc<Shared>,
    topo: Vec<usize>,
    mode: Mode,
    sources: Vec<JoinHandle<()>>,
    threads: Vec<JoinHandle<()>>,
    timer: Option<JoinHandle<()>>,
    timer_stop: Arc<AtomicBool>,
    handle: GraphHandle,
    /// [`DRAIN_TIMEOUT`], shorter in tests.
    drain_timeout: Duration,
}

/// Builds, starts and runs a graph to its end; the convenience form of [`RunningGraph`].
pub fn run(spec: &GraphSpec, opts: &RunOptions) -> Result<RunReport, RunError> {
    Ok(RunningGraph::start(spec)?.wait(opts))
}

impl RunningGraph {
    /// Builds every node and calls `start` on each (sinks first). Any failure stops the nodes
    /// already started and returns the error naming the node; no data has flowed.
    pub fn start(spec: &GraphSpec) -> Result<RunningGraph, RunError> {
        let t0 = Instant::now();
        let stop = Arc::new(AtomicBool::new(false));
        let base_dir = spec.source.base_dir();
        let n = spec.nodes.len();

        // Build.
        let mut imps: Vec<Option<NodeImpl>> = Vec::with_capacity(n);
        let mut recipes = Vec::with_capacity(n);
        for ns in &spec.nodes {
            let build =
                BuildContext::new(base_dir.clone(), spec.mode, ns.id.clone()).with_graph_text(spec.source.text.clone());
            let imp = ns.factory.build(&ns.params, &build).map_err(|error| RunError::Start {
                node: ns.id.clone(),
                kind: ns.kind.clone(),
                error,
            })?;
            let declared = ns.factory.info().role;
            if imp.role() != declared {
                return Err(RunError::Start {
                    node: ns.id.clone(),
                    kind: ns.kind.clone(),
                    error: NodeError::msg(format!("factory built a {:?} for a kind declared {declared:?}", imp.role())),
                });
            }
            imps.push(Some(imp));
            recipes.push(Recipe { factory: ns.factory.clone(), params: ns.params.clone(), build });
        }

        // Wire.
        let mut txs: Vec<Vec<Vec<EdgeTx>>> =
            spec.nodes.iter().map(|ns| (0..ns.factory.info().outputs.len()).map(|_| Vec::new()).collect()).collect();
        let mut rxs: Vec<Vec<(usize, crate::edge::EdgeRx)>> = (0..n).map(|_| Vec::new()).collect();
        let mut edges = Vec::with_capacity(spec.edges.len());
        for e in &spec.edges {
            let (tx, rx) = edge(e.clone());
            edges.push(tx.shared.clone());
            txs[e.from_node][e.from_port].push(tx);
            rxs[e.to_node].push((e.to_port, rx));
        }

        // Cells.
        let mut cells: Vec<Box<Cell>> = Vec::with_capacity(n);
        let mut stats = Vec::with_capacity(n);
        for (i, (ns, (outs, mut ins))) in spec.nodes.iter().zip(txs.into_iter().zip(rxs)).enumerate() {
            ins.sort_by_key(|(port, _)| *port); // stable: lanes keep file order
            let n_inputs = ins.len();
            let port_of: Vec<usize> = ins.iter().map(|(p, _)| *p).collect();
            let connected: Vec<bool> = outs.iter().map(|v| !v.is_empty()).collect();
            let st = Arc::new(NodeStats::default());
            stats.push(st.clone());
            cells.push(Box::new(Cell {
                imp: imps[i].take().expect("built above"),
                ctx: Context::new(i as u32, Arc::from(ns.id.as_str()), t0, spec.mode, stop.clone(), st.clone()),
                inputs: ins.into_iter().map(|(_, rx)| rx).collect(),
                in_io: Inputs::new(port_of),
                outputs: outs,
                out_io: Outputs::new(connected),
                trigger: ns.trigger,
                deadline_ns: ns.deadline_us.map(|us| (us * 1e3) as u64),
                restart: ns.restart,
                recipe: recipes[i].clone(),
                stats: st,
                dead: false,
                tick: false,
                armed: false,
                ended_warned: vec![false; n_inputs],
                eos: cell::Eos::Open,
            }));
        }

        // Start, sinks first so consumers are ready before producers.
        let mut started: Vec<usize> = Vec::new();
        for &i in spec.topo.iter().rev() {
            let c = &mut cells[i];
            if let Err(error) = c.imp.start(&mut c.ctx) {
                // The nodes already started are stopped, each under `catch_unwind`: the start
                // error is what the run reports; a stop's own failure is logged.
                for &j in &started {
                    let c = &mut cells[j];
                    if let Err(e) = cell::stop_caught(&mut c.imp, &mut c.ctx) {
                        tracing::warn!(node = %spec.nodes[j].id, "failed to stop after another node failed to start: {e}");
                    }
                }
                let ns = &spec.nodes[i];
                return Err(RunError::Start { node: ns.id.clone(), kind: ns.kind.clone(), error });
            }
            started.push(i);
        }

        let workers =
            if spec.workers == 0 { std::thread::available_parallelism().map_or(2, |p| p.get()) } else { spec.workers };
        let locals: Vec<Worker<usize>> = (0..workers).map(|_| Worker::new_lifo()).collect();
        let parkers: Vec<Parker> = (0..workers).map(|_| Parker::new()).collect();
        let slots = spec
            .nodes
            .iter()
            .zip(cells)
            .zip(stats)
            .map(|((ns, cell), st)| {
                let exec = match ns.factory.info().role {
                    Role::Source => Exec::Source,
                    _ if ns.thread == ThreadMode::Dedicated || ns.cpu.is_some() || ns.rt_priority.is_some() => {
                        Exec::Dedicated
                    }
                    _ => Exec::Pool,
                };
                Slot {
                    state: std::sync::atomic::AtomicU8::new(IDLE),
                    cell: AtomicCell::new(Some(cell)),
                    exec,
                    thread: std::sync::OnceLock::new(),
                    control: SegQueue::new(),
                    has_control: AtomicBool::new(false),
                    tick: AtomicBool::new(false),
                    periodic: matches!(ns.trigger, Trigger::Periodic { .. }),
                    stats: st,
                    ended: AtomicBool::new(false),
                }
            })
            .collect();
        let shared = Arc::new(Shared {
            slots,
            injector: ArrayQueue::new(n.max(1)),
            stealers: locals.iter().map(Worker::stealer).collect(),
            sleepers: parkers
                .iter()
                .map(|p| Sleeper { sleeping: AtomicBool::new(false), unparker: p.unparker().clone() })
                .collect(),
            active: std::sync::atomic::AtomicUsize::new(0),
            stop,
            shutdown: AtomicBool::new(false),
            failures: std::sync::Mutex::new(Vec::new()),
            kinds: std::sync::Mutex::new(spec.nodes.iter().map(|n| n.kind.clone()).collect()),
        });

        let handle = GraphHandle::new(handle::Inner {
            shared: shared.clone(),
            ids: spec.nodes.iter().map(|n| n.id.clone()).collect(),
            signatures: spec.nodes.iter().map(|n| GraphHandle::signature_of(n.factory.info())).collect(),
            wired: (0..spec.nodes.len()).map(|i| spec.connected_inputs(i)).collect(),
            edges,
            name: spec.name.clone(),
            mode: spec.mode,
            t0,
            base_dir: spec.source.base_dir(),
            graph_text: std::sync::Mutex::new(spec.source.text.clone()),
        });
        let mut g = RunningGraph {
            topo: spec.topo.clone(),
            mode: spec.mode,
            sources: Vec::new(),
            threads: Vec::new(),
            timer: None,
            timer_stop: Arc::new(AtomicBool::new(false)),
            shared,
            handle,
            drain_timeout: DRAIN_TIMEOUT,
        };
        if spec.mode == Mode::Realtime {
            g.spawn_threads(spec, locals, parkers);
        }
        Ok(g)
    }

    fn spawn_threads(&mut self, spec: &GraphSpec, locals: Vec<Worker<usize>>, parkers: Vec<Parker>) {
        for (idx, (local, parker)) in locals.into_iter().zip(parkers).enumerate() {
            let sh = self.shared.clone();
            self.threads.push(
                std::thread::Builder::new()
                    .name(format!("skinflow-worker-{idx}"))
                    .spawn(move || pool::worker_loop(&sh, idx, local, parker))
                    .expect("spawning a worker thread"),
            );
        }
        for (i, ns) in spec.nodes.iter().enumerate() {
            let exec = self.shared.slots[i].exec;
            if exec == Exec::Pool {
                continue;
            }
            let sh = self.shared.clone();
            let (id, cpu, prio) = (ns.id.clone(), ns.cpu, ns.rt_priority);
            let h = std::thread::Builder::new()
                .name(format!("skinflow-{}", ns.id))
                .spawn(move || {
                    rt::apply(&id, cpu, prio);
                    match exec {
                        Exec::Source => pool::source_loop(&sh, i),
                        _ => pool::dedicated_loop(&sh, i),
                    }
                })
                .expect("spawning a node thread");
            let _ = self.shared.slots[i].thread.set(h.thread().clone());
            h.thread().unpark(); // in case it parked before its handle was registered
            if exec == Exec::Source {
                self.sources.push(h);
            } else {
                self.threads.push(h);
            }
        }
        let periodic: Vec<(usize, Duration)> = spec
            .nodes
            .iter()
            .enumerate()
            .filter_map(|(i, ns)| match ns.trigger {
                Trigger::Periodic { period } => Some((i, period)),
                _ => None,
            })
            .collect();
        if !periodic.is_empty() {
            let sh = self.shared.clone();
            let stop = self.timer_stop.clone();
            self.timer = Some(
                std::thread::Builder::new()
                    .name("skinflow-timer".into())
                    .spawn(move || timer_loop(&sh, &periodic, &stop))
                    .expect("spawning the timer thread"),
            );
        }
    }

    /// Sets the shutdown's drain timeout (default [`DRAIN_TIMEOUT`]); for tests.
    #[cfg(test)]
    pub(crate) fn set_drain_timeout(&mut self, timeout: Duration) {
        self.drain_timeout = timeout;
    }

    /// Index of a node by id.
    pub fn node_index(&self, id: &str) -> Option<usize> {
        self.handle.node_index(id)
    }

    /// The id of node `index` (as in `Header::origin`).
    pub fn node_name(&self, index: u32) -> Option<&str> {
        self.handle.node_ids().get(index as usize).map(String::as_str)
    }

    /// Sends a control command (e.g. `tare`) to a node; it runs between two of its calls.
    pub fn control(&self, node: &str, cmd: &str) -> Result<(), RunError> {
        self.handle.control(node, cmd)
    }

    /// Sends a control command and waits for the node's answer (see [`GraphHandle::control_wait`]).
    pub fn control_wait(&self, node: &str, cmd: &str, timeout: Duration) -> Result<(), RunError> {
        self.handle.control_wait(node, cmd, timeout)
    }

    /// A handle for other threads: statistics, control commands, hot swaps.
    pub fn handle(&self) -> GraphHandle {
        self.handle.clone()
    }

    /// A live snapshot of the statistics.
    pub fn stats(&self) -> StatsReport {
        self.handle.stats()
    }

    /// Runs until the sources end, the stop flag is set, the duration passes or a node fails;
    /// then drains, stops every node and reports.
    pub fn wait(mut self, opts: &RunOptions) -> RunReport {
        // A duration beyond what the clock can represent is no limit.
        let until = opts.duration.and_then(|d| Instant::now().checked_add(d));
        let never = AtomicBool::new(false);
        let external = opts.stop.as_deref().unwrap_or(&never);
        if self.mode == Mode::Lockstep {
            lockstep::run(&self.shared, &self.topo, external, until, self.drain_timeout);
        } else {
            self.wait_sources(external, until);
            self.drain();
        }
        self.finish()
    }

    fn wait_sources(&mut self, external: &AtomicBool, until: Option<Instant>) {
        loop {
            if self.sources.iter().all(JoinHandle::is_finished) {
                break;
            }
            if external.load(SeqCst) || self.shared.stop.load(SeqCst) || until.is_some_and(|t| Instant::now() >= t) {
                self.shared.stop.store(true, SeqCst);
                for h in &self.sources {
                    h.thread().unpark();
                }
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        for h in self.sources.drain(..) {
            let _ = h.join();
        }
    }

    fn drain(&mut self) {
        self.timer_stop.store(true, SeqCst);
        if let Some(t) = self.timer.take() {
            let _ = t.join();
        }
        // One last tick so periodic nodes see the newest data.
        for (i, slot) in self.shared.slots.iter().enumerate() {
            if slot.periodic {
                slot.tick.store(true, SeqCst);
                self.shared.notify_external(i);
            }
        }
        // Wake every node that still has input, then wait until nothing is queued or running.
        for i in 0..self.shared.slots.len() {
            if self.shared.slots[i].exec != Exec::Source {
                self.shared.notify_external(i);
            }
        }
        let timeout = self.drain_timeout;
        let deadline = Instant::now() + timeout;
        let drained = loop {
            if self.shared.active.load(SeqCst) == 0 {
                break true;
            }
            if Instant::now() >= deadline {
                tracing::warn!("queues did not drain within {timeout:?}; stopping anyway (processors are not flushed)");
                break false;
            }
            std::thread::sleep(Duration::from_millis(1));
        };
        if !drained {
            // The nodes still queued or running (looked at before they are told to stop).
            for (i, slot) in self.shared.slots.iter().enumerate() {
                if slot.exec != Exec::Source && slot.state.load(SeqCst) != IDLE {
                    self.shared.fail(i, drain_timeout_error());
                }
            }
        }
        // Workers and node threads exit, also in the middle of a node's activation: no node
        // is called again (a node that never stops asking to rerun included).
        self.shared.shutdown.store(true, SeqCst);
        for s in &self.shared.sleepers {
            s.unparker.unpark();
        }
        for slot in &self.shared.slots {
            if let Some(t) = slot.thread.get() {
                t.unpark();
            }
        }
        for h in self.threads.drain(..) {
            let _ = h.join();
        }
        if drained {
            self.flush(deadline);
        }
    }

    /// The end-of-stream flush, on this thread: every worker and node thread has exited, so
    /// every cell is in its slot and this thread may own them all.
    fn flush(&self, deadline: Instant) {
        let taken: Vec<Option<Box<Cell>>> = self.shared.slots.iter().map(|s| s.cell.take()).collect();
        if taken.iter().all(Option::is_some) {
            let mut cells: Vec<Box<Cell>> = taken.into_iter().flatten().collect();
            flush::flush_all(&self.shared, &mut cells, &self.topo, deadline);
            for (slot, cell) in self.shared.slots.iter().zip(cells) {
                slot.cell.store(Some(cell));
            }
        } else {
            tracing::warn!("a node's state was not returned by its thread; processors are not flushed");
            for (slot, cell) in self.shared.slots.iter().zip(taken) {
                slot.cell.store(cell);
            }
        }
    }

    fn finish(self) -> RunReport {
        let mut stop_failures = Vec::new();
        for slot in &self.shared.slots {
            slot.ended.store(true, SeqCst);
        }
        for &i in &self.topo {
            let slot = &self.shared.slots[i];
            let Some(mut cell) = slot.cell.take() else { continue };
            // Swaps and commands that came too late to run: a replacement never installed is
            // stopped, and its asker told so; the node's kind stays what ran.
            cell.refuse_controls(&slot.control, "the run ended first");
            for rx in &cell.inputs {
                let left = rx.pending() as u64;
                rx.shared.stats.undelivered.fetch_add(left, std::sync::atomic::Ordering::Relaxed);
            }
            // Sources were stopped when their stream ended (`Cell::end_source`).
            if slot.exec != Exec::Source
                && let Err(error) = cell.stop_at_end()
            {
                stop_failures.push(RunError::Stop { node: self.handle.node_ids()[i].clone(), error });
            }
            slot.cell.store(Some(cell));
        }
        let stats = self.stats();
        let mut failures: Vec<RunError> =
            std::mem::take(&mut *self.shared.failures.lock().unwrap_or_else(|p| p.into_inner()))
                .into_iter()
                .map(|(i, error)| RunError::Node { node: self.handle.node_ids()[i].clone(), error })
                .collect();
        failures.extend(stop_failures);
        RunReport { stats, failures }
    }
}

/// A graph dropped without [`RunningGraph::wait`] (e.g. the caller bailed out) stops its
/// threads instead of leaving them running; nodes are not stopped (no flush) in that case.
impl Drop for RunningGraph {
    fn drop(&mut self) {
        if self.sources.is_empty() && self.threads.is_empty() && self.timer.is_none() {
            return; // waited (or lockstep): nothing is running
        }
        self.shared.stop.store(true, SeqCst);
        self.timer_stop.store(true, SeqCst);
        self.shared.shutdown.store(true, SeqCst);
        for h in &self.sources {
            h.thread().unpark();
        }
        for s in &self.shared.sleepers {
            s.unparker.unpark();
        }
        for slot in &self.shared.slots {
            if let Some(t) = slot.thread.get() {
                t.unpark();
            }
        }
        for h in self.sources.drain(..).chain(self.threads.drain(..)).chain(self.timer.take()) {
            let _ = h.join();
        }
    }
}

/// Shortest period the timer keeps (validation refuses shorter ones, see
/// [`crate::graph::MIN_PERIOD_MS`]): a zero period would never let it move on.
pub(crate) const MIN_TIMER_PERIOD: Duration = Duration::from_micros(1);

/// The first tick time after `now` on the grid `next + k * period` (`next <= now`), in one
/// step however many periods were missed: missed ticks are not made up (one tick pending is
/// what a periodic node sees anyway).
pub(crate) fn next_tick(next: Instant, now: Instant, period: Duration) -> Instant {
    let period = period.max(MIN_TIMER_PERIOD);
    let late = now.saturating_duration_since(next).as_nanos();
    let skip = late / period.as_nanos() + 1; // whole periods, to the first one after `now`
    let ahead = period.as_nanos().saturating_mul(skip);
    next + Duration::from_nanos(u64::try_from(ahead).unwrap_or(u64::MAX).min(u64::MAX / 4))
}

fn timer_loop(shared: &Shared, periodic: &[(usize, Duration)], stop: &AtomicBool) {
    let start = Instant::now();
    let mut next: Vec<Instant> = periodic.iter().map(|(_, p)| start + (*p).max(MIN_TIMER_PERIOD)).collect();
    while !stop.load(SeqCst) {
        let now = Instant::now();
        for (k, &(i, period)) in periodic.iter().enumerate() {
            if now >= next[k] {
                shared.slots[i].tick.store(true, SeqCst);
                shared.notify_external(i);
                next[k] = next_tick(next[k], now, period);
            }
        }
        let wake = next.iter().min().copied().unwrap_or(now + Duration::from_millis(50));
        std::thread::sleep(wake.saturating_duration_since(Instant::now()).min(Duration::from_millis(50)));
    }
}
