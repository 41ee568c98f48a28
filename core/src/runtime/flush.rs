//! End of stream, for both executors: every processor emits what it still buffers
//! ([`crate::Processor::flush`]) before any node is stopped, so nothing it received is lost.
//!
//! A processor whose inputs have all ended is flushed where it runs, as soon as they have
//! (mid-run, or in the drain after a stop request, when the stopped sources close their
//! outputs), and its outputs closed ([`super::cell::Eos`]). This phase flushes the processors
//! not flushed so: periodic ones, those downstream of one, those the drain did not get to.
//! Each processor is flushed once: one flushed here is not called again.
//!
//! It runs on one thread that owns every cell, once no source produces any more and the
//! queues have drained (lockstep: after its last pass; pool: after the workers have drained
//! the queues and exited). Processors are flushed in topological order. Before a node's flush
//! its pending control work is applied, so a hot swap queued at the end installs the
//! replacement (which took over the buffered state) and the replacement flushes. After each
//! flush call every node that became ready runs (a flushed frame goes through the whole
//! pipeline to the sinks, and frees room on `block` edges for the next call), so a node is
//! flushed only after everything upstream of it was flushed and processed. The whole phase is
//! bounded by the shutdown's deadline: a node still flushing then is left, and its `stop`
//! counts what it holds (`Context::count_discarded`).

use std::time::Instant;

use super::cell::{Cell, Eos, Flushed};
use super::drain_timeout_error;
use super::lockstep::{Dirty, drain};
use super::pool::{Exec, Shared};
use crate::graph::Trigger;
use crate::node::NodeImpl;

/// Flushes every processor of `topo` (node indices in topological order); `cells` holds
/// every node's cell, indexed by node.
pub(crate) fn flush_all(shared: &Shared, cells: &mut [Box<Cell>], topo: &[usize], deadline: Instant) {
    let order: Vec<usize> = topo.iter().copied().filter(|&i| shared.slots[i].exec != Exec::Source).collect();
    let n = Dirty::new(cells.len());
    if !settle(shared, cells, &order, &n, deadline) {
        return;
    }
    for &i in &order {
        shared.run_controls(i, &mut cells[i]);
        if cells[i].dead || cells[i].eos == Eos::Closed || !matches!(cells[i].imp, NodeImpl::Processor(_)) {
            // A dead instance's state is not trusted; a sink's `stop` is its flush; a Closed
            // processor was flushed mid-run.
            continue;
        }
        loop {
            if Instant::now() >= deadline {
                tracing::warn!(
                    node = %cells[i].ctx.id(),
                    "end-of-stream flush stopped at the shutdown deadline; nodes not flushed count what they hold"
                );
                shared.fail(i, drain_timeout_error());
                return;
            }
            if !cells[i].outputs_have_space() {
                if !settle(shared, cells, &order, &n, deadline) {
                    return;
                }
                if !cells[i].outputs_have_space() {
                    // The consumers cannot take more (dead, or waiting for an input that
                    // will never come): what the node still holds is counted at its stop.
                    tracing::warn!(node = %cells[i].ctx.id(), "end-of-stream flush: no room downstream");
                    break;
                }
            }
            let outcome = cells[i].flush(&n);
            if !settle(shared, cells, &order, &n, deadline) {
                return;
            }
            match outcome {
                Flushed::More => continue,
                Flushed::Done => {
                    // Flushed once, never called again: what still reaches it (from a producer
                    // upstream that had no room when it was visited and went on later) stays
                    // on its inputs, counted as undelivered, rather than being flushed twice.
                    cells[i].eos = Eos::Closed;
                    break;
                }
                Flushed::Fatal(e) => {
                    shared.fail(i, e);
                    break;
                }
            }
        }
    }
}

/// Runs every node that is ready until none is. A periodic node with queued input gets a tick
/// (its timer no longer runs), so flushed messages reach periodic consumers too. False when
/// the deadline passed first (a node that never stops asking to rerun): it fails the run,
/// and the flush ends there.
fn settle(shared: &Shared, cells: &mut [Box<Cell>], order: &[usize], n: &Dirty, deadline: Instant) -> bool {
    for &i in order {
        let c = &mut cells[i];
        if matches!(c.trigger, Trigger::Periodic { .. }) && c.inputs.iter().any(|rx| rx.pending() > 0) {
            c.tick = true;
        }
    }
    match drain(shared, cells, order, n, deadline) {
        Ok(()) => true,
        Err(i) => {
            tracing::warn!(node = %cells[i].ctx.id(), "end-of-stream flush stopped at the shutdown deadline: the node was still being called");
            shared.fail(i, drain_timeout_error());
            false
        }
    }
}
