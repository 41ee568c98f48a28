//! The deterministic executor: one thread, fixed order. Each step polls every unfinished
//! source once (in topological, then file, order) and then runs processors and sinks in
//! topological order until none is ready. Periodic nodes fire once per step. No pacing, no
//! races: the same inputs give bit-identical outputs run to run. When the sources are done
//! (finished, or a stop was requested) the sources are stopped and every processor is flushed
//! ([`super::flush`]), still on this thread and in a fixed order.
//!
//! A source whose stream ended closes its output edges: an aligned consumer then drops (counted
//! as unaligned) what can no longer be aligned instead of holding it, so the other sources are
//! not blocked forever (as in real time). A step, and the final drain and flush, are bounded by
//! the drain timeout: a node still being called then (one that never stops asking to rerun)
//! fails the run instead of hanging it.

use std::cell::Cell as StdCell;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering::SeqCst;
use std::time::{Duration, Instant};

use super::cell::{Cell, Fired, Notify};
use super::drain_timeout_error;
use super::pool::{Exec, Shared};
use crate::error::NodeError;
use crate::graph::Trigger;

/// Nodes that may have become runnable since they were last checked: a push gave them input,
/// or a pop gave them room on a full output. Only these (and nodes with a tick or a rerun
/// request) are checked, so an idle node costs one flag test per pass.
pub(crate) struct Dirty(Vec<StdCell<bool>>);

impl Dirty {
    /// Every one of `n` nodes marked: the first pass checks them all.
    pub(crate) fn new(n: usize) -> Dirty {
        Dirty((0..n).map(|_| StdCell::new(true)).collect())
    }
}

impl Notify for Dirty {
    fn notify(&self, node: usize) {
        self.0[node].set(true);
    }
}

/// Runs the graph to its end. `drain_timeout` bounds each step's processing, and the final
/// drain and flush together: a node still being called then (one that never stops asking to
/// rerun) fails the run, no node is called again and nothing is flushed.
pub(crate) fn run(
    shared: &Shared,
    topo: &[usize],
    external_stop: &AtomicBool,
    until: Option<Instant>,
    drain_timeout: Duration,
) {
    let mut cells: Vec<Box<Cell>> =
        shared.slots.iter().map(|s| s.cell.take().expect("cells are in their slots before a lockstep run")).collect();
    let sources: Vec<usize> = topo.iter().copied().filter(|&i| shared.slots[i].exec == Exec::Source).collect();
    let others: Vec<usize> = topo.iter().copied().filter(|&i| shared.slots[i].exec != Exec::Source).collect();
    let mut finished = vec![false; cells.len()];
    let n = Dirty::new(cells.len());
    let mut stuck = None;
    loop {
        if external_stop.load(SeqCst) || shared.stop.load(SeqCst) || until.is_some_and(|t| Instant::now() >= t) {
            break;
        }
        let mut polled = false;
        for &s in &sources {
            if finished[s] {
                continue;
            }
            let cell = &mut cells[s];
            shared.run_controls(s, cell);
            if !cell.outputs_have_space() {
                continue;
            }
            polled = true;
            match cell.fire(&n) {
                Fired::Ok => {}
                Fired::Finished => finished[s] = true,
                Fired::Fatal(e) => {
                    finished[s] = true;
                    shared.fail(s, e);
                }
            }
            if finished[s] {
                shared.slots[s].ended.store(true, SeqCst);
                // Aligned consumers may now know that an empty input stays empty.
                cell.close_outputs(&n);
            }
        }
        for &i in &others {
            if matches!(cells[i].trigger, Trigger::Periodic { .. }) {
                cells[i].tick = true;
            }
        }
        if let Err(i) = drain(shared, &mut cells, &others, &n, Instant::now() + drain_timeout) {
            stuck = Some(i);
            break;
        }
        if sources.iter().all(|&s| finished[s]) {
            break;
        }
        if !polled {
            let blocked: Vec<&str> = sources.iter().filter(|&&s| !finished[s]).map(|&s| cells[s].ctx.id()).collect();
            let e = NodeError::msg(format!(
                "deadlock: sources {} wait for room downstream and no node can run",
                blocked.join(", ")
            ));
            shared.fail(sources.iter().copied().find(|&s| !finished[s]).unwrap_or(0), e);
            break;
        }
    }
    // Final pass: whatever is queued and can run, runs (also after a stop request).
    let deadline = Instant::now() + drain_timeout;
    if stuck.is_none()
        && let Err(i) = drain(shared, &mut cells, &others, &n, deadline)
    {
        stuck = Some(i);
    }
    for &s in &sources {
        cells[s].end_source(shared, s, &n);
    }
    match stuck {
        // End of stream: what processors still buffer goes downstream before anything stops.
        None => super::flush::flush_all(shared, &mut cells, topo, deadline),
        Some(i) => {
            tracing::warn!(
                node = %cells[i].ctx.id(),
                "still running after {drain_timeout:?}; stopping anyway (processors are not flushed)"
            );
            shared.fail(i, drain_timeout_error());
        }
    }
    for (slot, cell) in shared.slots.iter().zip(cells) {
        slot.cell.store(Some(cell));
    }
}

/// Calls between two looks at the clock in [`drain`].
const CALLS_PER_CLOCK_CHECK: u32 = 256;

/// Runs the nodes of `order` (in that order, repeatedly) until none is ready. `Err(node)`:
/// `deadline` passed while `node` was still being called (it stays ready: a node that never
/// stops asking to rerun); nothing more is called.
pub(crate) fn drain(
    shared: &Shared,
    cells: &mut [Box<Cell>],
    order: &[usize],
    n: &Dirty,
    deadline: Instant,
) -> Result<(), usize> {
    let mut calls = 0u32;
    loop {
        let mut any = false;
        for &i in order {
            let cell = &mut cells[i];
            shared.run_controls(i, cell);
            if !n.0[i].replace(false) && !cell.tick && !cell.ctx.rerun {
                continue;
            }
            while cell.ready(n) {
                any = true;
                calls += 1;
                if calls.is_multiple_of(CALLS_PER_CLOCK_CHECK) && Instant::now() >= deadline {
                    n.0[i].set(true); // still ready
                    return Err(i);
                }
                if let Fired::Fatal(e) = cell.fire(n) {
                    shared.fail(i, e);
                }
                shared.run_controls(i, cell);
            }
        }
        // Done when nothing ran and nothing was woken meanwhile (an aligned trigger that
        // discards a head can free room for its producer without running).
        if !any && !order.iter().any(|&i| n.0[i].get()) {
            return Ok(());
        }
    }
}
