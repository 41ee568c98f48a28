//! The deterministic executor: one thread, fixed order. Each step polls every unfinished
//! source once (in topological, then file, order) and then runs processors and sinks in
//! topological order until none is ready. Periodic nodes fire once per step. No pacing, no
//! races: the same inputs give bit-identical outputs run to run. When the sources are done
//! (finished, or a stop was requested) the sources are stopped and every processor is flushed
//! ([`super::flush`]), still on this thread and in a fixed order.

use std::cell::Cell as StdCell;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering::SeqCst;
use std::time::Instant;

use super::DRAIN_TIMEOUT;
use super::cell::{Cell, Fired, Notify};
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

pub(crate) fn run(shared: &Shared, topo: &[usize], external_stop: &AtomicBool, until: Option<Instant>) {
    let mut cells: Vec<Box<Cell>> =
        shared.slots.iter().map(|s| s.cell.take().expect("cells are in their slots before a lockstep run")).collect();
    let sources: Vec<usize> = topo.iter().copied().filter(|&i| shared.slots[i].exec == Exec::Source).collect();
    let others: Vec<usize> = topo.iter().copied().filter(|&i| shared.slots[i].exec != Exec::Source).collect();
    let mut finished = vec![false; cells.len()];
    let n = Dirty::new(cells.len());
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
            }
        }
        for &i in &others {
            if matches!(cells[i].trigger, Trigger::Periodic { .. }) {
                cells[i].tick = true;
            }
        }
        drain(shared, &mut cells, &others, &n);
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
    drain(shared, &mut cells, &others, &n);
    for &s in &sources {
        cells[s].end_source(shared, s);
    }
    // End of stream: what processors still buffer goes downstream before anything stops.
    super::flush::flush_all(shared, &mut cells, topo, Instant::now() + DRAIN_TIMEOUT);
    for (slot, cell) in shared.slots.iter().zip(cells) {
        slot.cell.store(Some(cell));
    }
}

/// Runs the nodes of `order` (in that order, repeatedly) until none is ready.
pub(crate) fn drain(shared: &Shared, cells: &mut [Box<Cell>], order: &[usize], n: &Dirty) {
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
                if let Fired::Fatal(e) = cell.fire(n) {
                    shared.fail(i, e);
                }
            }
        }
        // Done when nothing ran and nothing was woken meanwhile (an aligned trigger that
        // discards a head can free room for its producer without running).
        if !any && !order.iter().any(|&i| n.0[i].get()) {
            return;
        }
    }
}
