//! The threaded executor: a worker pool for processors and sinks, one thread per source and
//! per dedicated node, and a timer thread for periodic triggers.
//!
//! A node's `state` (idle, queued, running, running-and-notified) guarantees that one thread
//! at a time runs it; its [`Cell`] is handed over through a lock-free `AtomicCell`. A push
//! that makes a consumer runnable puts it in the worker's LIFO slot, so the next hop runs on
//! the same thread with no trip through a shared queue; further ready nodes go to the
//! worker's local deque, which idle workers steal from.

use std::cell::Cell as StdCell;
use std::sync::Arc;
use std::sync::atomic::Ordering::{Relaxed, SeqCst};
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicUsize};
use std::thread::Thread;
use std::time::Duration;

use crossbeam::atomic::AtomicCell;
use crossbeam::deque::{Steal, Stealer, Worker};
use crossbeam::queue::{ArrayQueue, SegQueue};
use crossbeam::sync::{Parker, Unparker};

use super::cell::{Cell, Fired, Notify};
use crate::error::NodeError;
use crate::stats::NodeStats;

pub(crate) const IDLE: u8 = 0;
pub(crate) const QUEUED: u8 = 1;
pub(crate) const RUNNING: u8 = 2;
pub(crate) const NOTIFIED: u8 = 3;

/// Calls a node may make in one activation before it yields its worker to others.
const BUDGET: usize = 64;
/// Longest an idle worker sleeps without a wake-up (a safety net, not the wake-up path).
const IDLE_PARK: Duration = Duration::from_millis(50);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Exec {
    Pool,
    Dedicated,
    Source,
}

pub(crate) struct Slot {
    pub state: AtomicU8,
    pub cell: AtomicCell<Option<Box<Cell>>>,
    pub exec: Exec,
    pub thread: std::sync::OnceLock<Thread>,
    pub control: SegQueue<Control>,
    pub has_control: AtomicBool,
    pub tick: AtomicBool,
    pub periodic: bool,
    pub stats: Arc<NodeStats>,
    /// The node runs no more (a source whose stream ended or that was stopped, or the run is
    /// over): control work queued for it is refused, never left waiting.
    pub ended: AtomicBool,
}

/// Clears a flag and says whether it was set. Checks with a plain load first, so the common
/// case (not set) costs no locked instruction on the hot path.
#[inline]
pub(crate) fn take_flag(f: &AtomicBool) -> bool {
    f.load(std::sync::atomic::Ordering::Acquire) && f.swap(false, SeqCst)
}

/// Work for a node between two of its calls.
pub(crate) enum Control {
    /// A command for the node itself (e.g. `tare`), with where to send its result.
    Command(String, Option<std::sync::mpsc::SyncSender<Result<(), crate::error::NodeError>>>),
    /// Replace the node's instance (hot swap).
    Swap(Box<Swap>),
    /// New per-call deadline and restart policy (a `--watch` edit of `deadline_us`, `restart`).
    Policy { deadline_ns: Option<u64>, restart: crate::graph::Restart },
}

/// A swap not yet looked at by the node's executor ([`Swap::claim`]).
pub(crate) const SWAP_PENDING: u8 = 0;
/// The executor took the swap: it is being installed or refused, and answered.
pub(crate) const SWAP_TAKEN: u8 = 1;
/// The asker gave up waiting: the executor stops the replacement without installing it.
pub(crate) const SWAP_CANCELLED: u8 = 2;

/// A started replacement and how to rebuild it.
pub(crate) struct Swap {
    pub imp: crate::node::NodeImpl,
    pub recipe: super::cell::Recipe,
    pub kind: String,
    /// [`SWAP_PENDING`] until the executor takes the swap or the asker cancels it (whoever
    /// moves it first decides: a swap is installed at most once, and never after its asker
    /// was told it was not).
    pub claim: Arc<AtomicU8>,
    /// Where the outcome goes: `Ok` once installed, or why it was not.
    pub reply: Option<std::sync::mpsc::SyncSender<Result<(), String>>>,
}

pub(crate) struct Sleeper {
    pub sleeping: AtomicBool,
    pub unparker: Unparker,
}

pub(crate) struct Shared {
    pub slots: Vec<Slot>,
    /// Nodes queued from outside a worker. Bounded by the node count: the state machine puts
    /// a node in at most one queue at a time, so a push never fails and never allocates
    /// (an unbounded `Injector` allocates a block every 63 pushes).
    pub injector: ArrayQueue<usize>,
    pub stealers: Vec<Stealer<usize>>,
    pub sleepers: Vec<Sleeper>,
    /// Nodes queued or running.
    pub active: AtomicUsize,
    /// Sources stop polling (the contexts' stop flag).
    pub stop: Arc<AtomicBool>,
    /// Workers and dedicated threads exit (the queues drained, or the drain timeout passed:
    /// a running node then makes no further call).
    pub shutdown: AtomicBool,
    pub failures: std::sync::Mutex<Vec<(usize, NodeError)>>,
    /// The kind each node runs now, updated when a swap is installed (not when it is asked).
    pub kinds: std::sync::Mutex<Vec<String>>,
}

impl Shared {
    /// Records a fatal node error and asks the graph to stop (cold path).
    pub fn fail(&self, node: usize, e: NodeError) {
        self.failures.lock().unwrap_or_else(|p| p.into_inner()).push((node, e));
        self.stop.store(true, SeqCst);
    }

    fn inject(&self, node: usize) {
        let pushed = self.injector.push(node);
        debug_assert!(pushed.is_ok(), "a node is queued at most once, so the injector never fills");
    }

    fn wake_one(&self) {
        for s in &self.sleepers {
            if s.sleeping.swap(false, SeqCst) {
                s.unparker.unpark();
                return;
            }
        }
    }

    /// Moves an idle node to queued (true: the caller must enqueue it), or flags a running
    /// node to look at its inputs again before going idle.
    fn mark(&self, node: usize) -> bool {
        let st = &self.slots[node].state;
        loop {
            match st.load(SeqCst) {
                IDLE => {
                    self.active.fetch_add(1, SeqCst);
                    if st.compare_exchange(IDLE, QUEUED, SeqCst, SeqCst).is_ok() {
                        return true;
                    }
                    self.active.fetch_sub(1, SeqCst);
                }
                RUNNING => {
                    if st.compare_exchange(RUNNING, NOTIFIED, SeqCst, SeqCst).is_ok() {
                        return false;
                    }
                }
                _ => return false,
            }
        }
    }

    /// Wakes a node from outside a worker (source threads, timers, control, shutdown).
    pub fn notify_external(&self, node: usize) {
        let slot = &self.slots[node];
        match slot.exec {
            Exec::Source => {
                if let Some(t) = slot.thread.get() {
                    t.unpark();
                }
            }
            Exec::Dedicated => {
                if self.mark(node)
                    && let Some(t) = slot.thread.get()
                {
                    t.unpark();
                }
            }
            Exec::Pool => {
                if self.mark(node) {
                    self.inject(node);
                    self.wake_one();
                }
            }
        }
    }

    /// Applies node `node`'s queued control work (commands, a hot swap) to its cell, between two
    /// of its calls: every executor (pool, dedicated thread, source thread, lockstep) calls this
    /// before it fires a node.
    pub fn run_controls(&self, node: usize, cell: &mut Cell) {
        let slot = &self.slots[node];
        if take_flag(&slot.has_control) {
            while let Some(c) = slot.control.pop() {
                cell.control(c, self);
            }
        }
    }

    /// Runs a queued node until it is not ready, its budget is spent, it is notified no more,
    /// or the shutdown's drain timeout passed ([`Shared::shutdown`] set while it runs). Its
    /// control work (commands, a swap, a policy) is applied before every call, so a node that
    /// stays ready (a dedicated node has no budget) still runs it between two calls.
    pub fn execute(&self, node: usize, n: &dyn Notify, budget: usize) {
        let slot = &self.slots[node];
        slot.state.store(RUNNING, SeqCst);
        let mut cell = slot.cell.take().expect("a queued node's cell is in its slot");
        let mut left = budget;
        loop {
            self.run_controls(node, &mut cell);
            if take_flag(&slot.tick) {
                cell.tick = true;
            }
            while left > 0 && !self.shutdown.load(Relaxed) && cell.ready(n) {
                left -= 1;
                if let Fired::Fatal(e) = cell.fire(n) {
                    self.fail(node, e);
                }
                self.run_controls(node, &mut cell);
            }
            slot.cell.store(Some(cell));
            if left == 0 {
                slot.state.store(QUEUED, SeqCst);
                match slot.exec {
                    Exec::Pool => {
                        self.inject(node);
                        self.wake_one();
                    }
                    _ => {
                        if let Some(t) = slot.thread.get() {
                            t.unpark();
                        }
                    }
                }
                return;
            }
            if slot.state.compare_exchange(RUNNING, IDLE, SeqCst, SeqCst).is_ok() {
                self.active.fetch_sub(1, SeqCst);
                return;
            }
            slot.state.store(RUNNING, SeqCst);
            cell = slot.cell.take().expect("a running node's cell is in its slot");
            left = budget;
        }
    }
}

/// Notifications from outside the pool.
pub(crate) struct ExternalNotify<'a>(pub &'a Shared);

impl Notify for ExternalNotify<'_> {
    fn notify(&self, node: usize) {
        self.0.notify_external(node);
    }
}

/// Notifications from a worker: the first runnable consumer goes to the LIFO slot.
struct WorkerNotify<'a> {
    shared: &'a Shared,
    local: &'a Worker<usize>,
    lifo: StdCell<Option<usize>>,
}

impl Notify for WorkerNotify<'_> {
    fn notify(&self, node: usize) {
        if self.shared.slots[node].exec != Exec::Pool {
            return self.shared.notify_external(node);
        }
        if self.shared.mark(node) {
            match self.lifo.get() {
                None => self.lifo.set(Some(node)),
                Some(_) => {
                    self.local.push(node);
                    self.shared.wake_one();
                }
            }
        }
    }
}

pub(crate) fn worker_loop(shared: &Shared, idx: usize, local: Worker<usize>, parker: Parker) {
    let n = WorkerNotify { shared, local: &local, lifo: StdCell::new(None) };
    loop {
        // Set once the queues drained, or when the drain timeout passed: then nodes may still
        // be queued (one that never stops asking to rerun), and are left so.
        if shared.shutdown.load(SeqCst) {
            return;
        }
        let next = n.lifo.take().or_else(|| local.pop()).or_else(|| steal(shared));
        if let Some(node) = next {
            shared.execute(node, &n, BUDGET);
            continue;
        }
        shared.sleepers[idx].sleeping.store(true, SeqCst);
        if !shared.injector.is_empty() || shared.stealers.iter().any(|s| !s.is_empty()) {
            shared.sleepers[idx].sleeping.store(false, SeqCst);
            continue;
        }
        parker.park_timeout(IDLE_PARK);
        shared.sleepers[idx].sleeping.store(false, SeqCst);
    }
}

fn steal(shared: &Shared) -> Option<usize> {
    if let Some(t) = shared.injector.pop() {
        return Some(t);
    }
    for s in &shared.stealers {
        loop {
            match s.steal() {
                Steal::Success(t) => return Some(t),
                Steal::Retry => continue,
                Steal::Empty => break,
            }
        }
    }
    None
}

/// A node with a thread of its own (pinned or real-time): runs whenever it is queued.
pub(crate) fn dedicated_loop(shared: &Shared, node: usize) {
    let n = ExternalNotify(shared);
    loop {
        if shared.shutdown.load(SeqCst) {
            return;
        } else if shared.slots[node].state.load(SeqCst) == QUEUED {
            shared.execute(node, &n, usize::MAX);
        } else {
            std::thread::park_timeout(IDLE_PARK);
        }
    }
}

/// A source's thread: poll while there is room downstream, until finished or stopped; then
/// ends the source ([`Cell::end_source`]) and puts its cell back in its slot for the report.
pub(crate) fn source_loop(shared: &Shared, node: usize) {
    let slot = &shared.slots[node];
    let mut cell = slot.cell.take().expect("a source's cell is in its slot at start");
    let n = ExternalNotify(shared);
    loop {
        if shared.stop.load(SeqCst) {
            break;
        }
        shared.run_controls(node, &mut cell);
        if !cell.outputs_have_space() {
            std::thread::park_timeout(IDLE_PARK);
            continue;
        }
        match cell.fire(&n) {
            Fired::Ok => {}
            Fired::Finished => break,
            Fired::Fatal(e) => {
                shared.fail(node, e);
                break;
            }
        }
    }
    cell.end_source(shared, node, &n);
    slot.cell.store(Some(cell));
}
