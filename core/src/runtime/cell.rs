//! A node instance with its queue ends, and the per-call protocol shared by every executor:
//! is it ready (trigger satisfied, room on its lossless outputs), then fire (select inputs,
//! call the node under `catch_unwind`, time it, publish its outputs, wake its consumers); and
//! the same for a processor's end-of-stream flush.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::sync::atomic::Ordering::SeqCst;
use std::time::Instant;

use crate::edge::{EdgeRx, EdgeTx};
use crate::error::NodeError;
use crate::graph::{Restart, Trigger};
use crate::io::{Inputs, Outputs};
use crate::node::{Context, NodeImpl, SourcePoll};
use crate::params::Params;
use crate::registry::{BuildContext, NodeFactory};
use crate::stats::{NodeStats, bump};

use super::pool::{Control, SWAP_PENDING, SWAP_TAKEN, Shared, Swap};

/// Wakes nodes made runnable by a push (consumers) or a pop (waiting producers).
pub(crate) trait Notify {
    fn notify(&self, node: usize);
}

/// What rebuilding a node needs (restart after a panic, hot swap).
#[derive(Clone)]
pub(crate) struct Recipe {
    pub factory: Arc<dyn NodeFactory>,
    pub params: Params,
    pub build: BuildContext,
}

/// Outcome of one call, for the executor.
pub(crate) enum Fired {
    Ok,
    /// A source finished.
    Finished,
    /// The node cannot go on and the graph must stop.
    Fatal(NodeError),
}

/// Outcome of one end-of-stream flush call.
pub(crate) enum Flushed {
    /// The node asked to be flushed again (more buffered output).
    More,
    /// Nothing more to flush (or the call failed: an error ends the node's flush).
    Done,
    /// The node cannot go on and the graph must stop.
    Fatal(NodeError),
}

/// Where a processor is in its end of stream, which it may reach before the run's end: once
/// every input has ended (its producer finished, its queue is empty) it is flushed and its
/// outputs are closed, so an aligned consumer downstream knows that an empty input stays
/// empty (as it does for a source's outputs). Periodic processors are left open until the
/// run's end: a tick may emit without input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Eos {
    /// Inputs may still bring messages.
    Open,
    /// Every input has ended: the next calls are flush calls.
    Flushing,
    /// Flushed, outputs closed: never called again, nor flushed at the run's end.
    Closed,
}

pub(crate) struct Cell {
    pub imp: NodeImpl,
    pub ctx: Context,
    pub inputs: Vec<EdgeRx>,
    pub in_io: Inputs,
    pub outputs: Vec<Vec<EdgeTx>>,
    pub out_io: Outputs,
    pub trigger: Trigger,
    pub deadline_ns: Option<u64>,
    pub restart: Restart,
    pub recipe: Recipe,
    pub stats: Arc<NodeStats>,
    /// Set after a panic without restart or a fatal error: the node is never called again.
    pub dead: bool,
    /// A periodic tick is pending.
    pub tick: bool,
    /// Set by [`Cell::ready`]: the trigger is satisfied, so the next call takes its inputs.
    /// A call made only because the node asked to be rerun takes none.
    pub armed: bool,
    /// Per input: the warning that it ended (its producer finished, its queue is empty) and
    /// that the aligned trigger drops the other inputs' messages was given.
    pub ended_warned: Vec<bool>,
    /// The processor's own end of stream (see [`Eos`]).
    pub eos: Eos,
}

pub(crate) fn panic_message(p: Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "non-string panic payload".to_owned()
    }
}

/// How an instance's `stop`, called under `catch_unwind` ([`stop_caught`]), went wrong.
pub(crate) enum StopFailure {
    /// `stop` returned an error.
    Error(NodeError),
    /// `stop` panicked; the payload's message.
    Panic(String),
}

impl std::fmt::Display for StopFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopFailure::Error(e) => write!(f, "{e}"),
            StopFailure::Panic(msg) => write!(f, "stop panicked: {msg}"),
        }
    }
}

impl StopFailure {
    /// As a node error: a panic becomes [`NodeError::Panic`].
    pub fn into_error(self) -> NodeError {
        match self {
            StopFailure::Error(e) => e,
            StopFailure::Panic(msg) => NodeError::Panic(msg),
        }
    }
}

/// The panic-safe stop of an instance, with the node's context: its `stop` counts what it
/// held; an error or a panic there is returned, never propagated. Used for a node's own
/// instance at the end of the run ([`Cell::stop_at_end`]), for an instance taken out of the
/// node ([`Cell::stop_replaced`]), for the nodes already started when another's `start`
/// fails, and for a swap replacement that is never installed.
pub(crate) fn stop_caught(imp: &mut NodeImpl, ctx: &mut Context) -> Result<(), StopFailure> {
    match catch_unwind(AssertUnwindSafe(|| imp.stop(ctx))) {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(StopFailure::Error(e)),
        Err(p) => Err(StopFailure::Panic(panic_message(p))),
    }
}

impl Cell {
    /// Room on every lossless output (registers for a wake-up when not).
    pub fn outputs_have_space(&self) -> bool {
        self.outputs.iter().flatten().all(|tx| tx.has_space_or_wait())
    }

    fn take(&mut self, i: usize, n: &dyn Notify) -> Option<crate::message::Message> {
        let (m, wake) = self.inputs[i].take();
        if wake {
            n.notify(self.inputs[i].shared.spec.from_node);
        }
        m
    }

    /// Whether the processor or sink may fire now: its trigger is satisfied (the call then
    /// takes inputs per the trigger), or it asked to be rerun (a call that takes only what
    /// the trigger would take anyway: none when the trigger is not satisfied; see
    /// [`Context::request_rerun`]). May discard unalignable heads (counted).
    pub fn ready(&mut self, n: &dyn Notify) -> bool {
        if self.dead || self.eos == Eos::Closed || !self.outputs_have_space() {
            self.armed = false;
            return false;
        }
        self.armed = self.triggered(n);
        if self.armed || self.ctx.rerun {
            return true;
        }
        if self.eos == Eos::Open && self.inputs_all_ended() {
            self.eos = Eos::Flushing;
        }
        self.eos == Eos::Flushing
    }

    /// Whether this is a processor that will never receive a message again: every input
    /// ended. Periodic processors never count as such (see [`Eos`]).
    fn inputs_all_ended(&mut self) -> bool {
        matches!(self.imp, NodeImpl::Processor(_))
            && !matches!(self.trigger, Trigger::Periodic { .. })
            && !self.inputs.is_empty()
            && (0..self.inputs.len()).all(|i| self.input_ended(i))
    }

    /// Whether the trigger is satisfied. May discard unalignable heads (counted).
    fn triggered(&mut self, n: &dyn Notify) -> bool {
        match self.trigger {
            Trigger::Any => self.inputs.iter_mut().any(|rx| rx.peek().is_some()),
            Trigger::Periodic { .. } => self.tick,
            Trigger::AlignedSeq | Trigger::AlignedWindow { .. } => loop {
                if self.inputs.is_empty() {
                    return false;
                }
                let mut lo = (u64::MAX, 0usize);
                let mut hi = 0u64;
                let mut empty = None;
                for (i, rx) in self.inputs.iter_mut().enumerate() {
                    let Some(h) = rx.peek() else {
                        empty = Some(i);
                        break;
                    };
                    let key = match self.trigger {
                        Trigger::AlignedSeq => h.header.seq,
                        _ => h.header.t_ns,
                    };
                    if key < lo.0 {
                        lo = (key, i);
                    }
                    hi = hi.max(key);
                }
                if let Some(i) = empty {
                    if self.input_ended(i) {
                        self.drop_unalignable(i, n);
                    }
                    return false;
                }
                let aligned = match self.trigger {
                    Trigger::AlignedWindow { window_ns } => hi - lo.0 <= window_ns,
                    _ => hi == lo.0,
                };
                if aligned {
                    return true;
                }
                // The oldest head can never be matched: every other input is already past it.
                if self.take(lo.1, n).is_some() {
                    bump(&self.inputs[lo.1].shared.stats.dropped_unaligned, 1);
                }
            },
        }
    }

    /// Whether input `i` will never have a message again: its producer ended (a source whose
    /// stream ended) and its queue is empty. The flag is set after the producer's last push,
    /// so the queue is looked at again once it is seen.
    fn input_ended(&mut self, i: usize) -> bool {
        let rx = &mut self.inputs[i];
        rx.shared.producer_ended.load(SeqCst) && rx.peek().is_none()
    }

    /// Input `ended` of an aligned node will never have a message again: what the other
    /// inputs hold can never be aligned. Drops it, counted as `dropped_unaligned` (and frees
    /// their producers, which would otherwise wait on a full `block` edge forever); says so
    /// once per ended input.
    fn drop_unalignable(&mut self, ended: usize, n: &dyn Notify) {
        let mut dropped = 0u64;
        for j in 0..self.inputs.len() {
            if j == ended {
                continue;
            }
            let mut k = 0;
            while self.take(j, n).is_some() {
                k += 1;
            }
            bump(&self.inputs[j].shared.stats.dropped_unaligned, k);
            dropped += k;
        }
        if dropped > 0 && !std::mem::replace(&mut self.ended_warned[ended], true) {
            tracing::warn!(
                node = %self.ctx.id,
                input = %self.inputs[ended].shared.spec.to,
                from = %self.inputs[ended].shared.spec.from,
                "aligned input ended (its producer finished and its queue is empty): the messages on the other inputs can never be aligned and are dropped (counted as dropped_unaligned)"
            );
        }
    }

    /// This node produces no more (a source whose stream ended): marks its output edges so
    /// aligned consumers know an empty input stays empty, and wakes the consumers to look.
    pub fn close_outputs(&self, n: &dyn Notify) {
        for tx in self.outputs.iter().flatten() {
            if !tx.shared.producer_ended.swap(true, SeqCst) {
                n.notify(tx.shared.spec.to_node);
            }
        }
    }

    /// Fills `in_io` per the trigger. Returns the number of messages taken.
    fn select_inputs(&mut self, n: &dyn Notify) -> u64 {
        // A rerun call whose trigger is not satisfied takes nothing (and leaves a periodic
        // node's tick for its next tick call).
        if !std::mem::take(&mut self.armed) {
            return 0;
        }
        match self.trigger {
            Trigger::Any => {
                let mut best: Option<(u64, usize)> = None;
                for (i, rx) in self.inputs.iter_mut().enumerate() {
                    if let Some(h) = rx.peek()
                        && best.is_none_or(|(t, _)| h.header.t_ns < t)
                    {
                        best = Some((h.header.t_ns, i));
                    }
                }
                match best {
                    Some((_, i)) => {
                        self.in_io.slots[i] = self.take(i, n);
                        1
                    }
                    None => 0,
                }
            }
            Trigger::AlignedSeq | Trigger::AlignedWindow { .. } => {
                let mut k = 0;
                for i in 0..self.inputs.len() {
                    self.in_io.slots[i] = self.take(i, n);
                    k += u64::from(self.in_io.slots[i].is_some());
                }
                k
            }
            Trigger::Periodic { .. } => {
                self.tick = false;
                let mut k = 0;
                for i in 0..self.inputs.len() {
                    let mut latest = None;
                    while let Some(m) = self.take(i, n) {
                        if latest.replace(m).is_some() {
                            bump(&self.inputs[i].shared.stats.dropped_coalesced, 1);
                        }
                    }
                    k += u64::from(latest.is_some());
                    self.in_io.slots[i] = latest;
                }
                k
            }
        }
    }

    /// Runs one call of a processor/sink (`ready` returned true) or a source poll; or, for a
    /// processor whose inputs have all ended, one flush call, closing its outputs once it has
    /// nothing more to flush.
    pub fn fire(&mut self, n: &dyn Notify) -> Fired {
        // A rerun asked meanwhile (by a control, a swap's state hand-over) is a flush rerun:
        // a processor whose inputs have ended is never processed again.
        if self.eos == Eos::Flushing && !self.armed {
            return match self.flush(n) {
                Flushed::More => Fired::Ok,
                Flushed::Done => {
                    self.eos = Eos::Closed;
                    self.close_outputs(n);
                    Fired::Ok
                }
                Flushed::Fatal(e) => Fired::Fatal(e),
            };
        }
        let taken = if matches!(self.imp, NodeImpl::Source(_)) { 0 } else { self.select_inputs(n) };
        self.call(n, Some(taken), |imp, ctx, in_io, out_io| match imp {
            NodeImpl::Source(s) => s.poll(ctx, out_io),
            NodeImpl::Processor(p) => p.process(ctx, in_io, out_io).map(|()| SourcePoll::Emitted),
            NodeImpl::Sink(s) => s.consume(ctx, in_io).map(|()| SourcePoll::Emitted),
        })
        .0
    }

    /// Runs one end-of-stream flush call of a processor (see [`crate::Processor::flush`]) and
    /// publishes what it emitted. The caller makes sure there is room on the outputs.
    pub fn flush(&mut self, n: &dyn Notify) -> Flushed {
        if self.dead || self.eos == Eos::Closed || !matches!(self.imp, NodeImpl::Processor(_)) {
            return Flushed::Done;
        }
        let (fired, ok) =
            self.call(n, None, |imp, ctx, _, out_io| imp.flush(ctx, out_io).map(|()| SourcePoll::Emitted));
        // A rerun request from a flush asks for another flush, never for a `process` call.
        let more = std::mem::take(&mut self.ctx.rerun);
        match fired {
            Fired::Fatal(e) => Flushed::Fatal(e),
            _ if ok && more && !self.dead => Flushed::More,
            _ => Flushed::Done,
        }
    }

    /// The per-call protocol around `f`: under `catch_unwind`, timed, counted; errors, panics
    /// and the restart policy handled; outputs published. `taken`: the messages a call took
    /// (`None` for a flush call, counted apart so `calls` and the latency stay per call of
    /// `process`/`poll`/`consume`). Returns the outcome and whether the call returned `Ok`.
    fn call(
        &mut self,
        n: &dyn Notify,
        taken: Option<u64>,
        f: impl FnOnce(&mut NodeImpl, &mut Context, &Inputs, &mut Outputs) -> Result<SourcePoll, NodeError>,
    ) -> (Fired, bool) {
        self.ctx.rerun = false;
        let span = tracing::trace_span!("node", id = %self.ctx.id);
        let _enter = span.enter();
        let t0 = Instant::now();
        let Cell { imp, ctx, in_io, out_io, .. } = self;
        let result = catch_unwind(AssertUnwindSafe(|| f(imp, ctx, in_io, out_io)));
        let ns = t0.elapsed().as_nanos() as u64;
        drop(_enter);
        self.in_io.clear();
        let st = &self.stats;
        match taken {
            Some(taken) => {
                bump(&st.calls, 1);
                bump(&st.msgs_in, taken);
                st.latency.record_single_writer(ns);
                if self.deadline_ns.is_some_and(|d| ns > d) {
                    bump(&st.deadline_misses, 1);
                }
            }
            None => bump(&st.flushes, 1),
        }
        let outcome = match result {
            Ok(Ok(SourcePoll::Finished)) => (Fired::Finished, true),
            Ok(Ok(_)) => (Fired::Ok, true),
            Ok(Err(e)) if e.is_fatal() => {
                bump(&st.errors, 1);
                self.dead = true;
                (Fired::Fatal(e), false)
            }
            Ok(Err(e)) => {
                bump(&st.errors, 1);
                tracing::warn!(node = %self.ctx.id, "{e}");
                (Fired::Ok, false)
            }
            Err(p) => {
                bump(&st.panics, 1);
                // The inputs the call took die with it: counted as discarded by the node.
                // (What it sent before panicking is not published: see `after_panic`.)
                if let Some(k) = taken.filter(|&k| k > 0) {
                    self.ctx.count_discarded(k);
                }
                let msg = panic_message(p);
                tracing::error!(node = %self.ctx.id, "panicked: {msg}");
                (self.after_panic(msg), false)
            }
        };
        self.publish(n);
        outcome
    }

    /// Restart policy: rebuild and start again, or stop for good.
    ///
    /// The panicked instance is stopped before it is dropped, so what it held is counted as
    /// discarded (its `stop` counts it: a plugin reports what it held even after the panic;
    /// a built-in node whose state the panic left inconsistent may count less). The inputs
    /// the panicked call took were counted as discarded by [`Cell::call`] (an instance that
    /// had stored one before panicking counts it again in its `stop`: a count may then be
    /// high, never silently low). Without a restart, or when the rebuild fails, it stays as
    /// the node's dead instance and is stopped, and counts, at the end of the run.
    fn after_panic(&mut self, msg: String) -> Fired {
        for slot in &mut self.out_io.slots {
            *slot = None; // outputs of a panicked call are not trusted
        }
        // A rerun asked by the panicked instance is not the restarted one's (nor a dead one's).
        self.ctx.rerun = false;
        if self.restart == Restart::Always {
            let r = &self.recipe;
            match r.factory.build(&r.params, &r.build).and_then(|mut imp| {
                imp.start(&mut self.ctx)?;
                Ok(imp)
            }) {
                Ok(imp) => {
                    let mut old = std::mem::replace(&mut self.imp, imp);
                    self.stop_replaced(&mut old, "the panicked instance");
                    bump(&self.stats.restarts, 1);
                    tracing::warn!(node = %self.ctx.id, "restarted after panic");
                    return Fired::Ok;
                }
                Err(e) => {
                    self.dead = true;
                    return Fired::Fatal(NodeError::msg(format!("panicked ({msg}) and failed to restart: {e}")));
                }
            }
        }
        self.dead = true;
        Fired::Fatal(NodeError::Panic(msg))
    }

    /// Stops an instance taken out of the node (replaced by a swap or a restart, or a
    /// replacement never installed) under `catch_unwind`: its `stop` counts what it held; an
    /// error or a panic there is logged, the node goes on.
    fn stop_replaced(&mut self, imp: &mut NodeImpl, what: &str) {
        match stop_caught(imp, &mut self.ctx) {
            Ok(()) => {}
            Err(StopFailure::Error(e)) => tracing::warn!(node = %self.ctx.id, "{what} failed to stop: {e}"),
            Err(StopFailure::Panic(msg)) => tracing::error!(node = %self.ctx.id, "{what} panicked in its stop: {msg}"),
        }
    }

    /// Stops the node's own instance at the end of the run, under `catch_unwind`: its `stop`
    /// counts what it holds; an error there, or a panic (as [`NodeError::Panic`]), is
    /// returned for the run's report. Not for sources: they were stopped when their stream
    /// ended ([`Cell::end_source`]).
    pub fn stop_at_end(&mut self) -> Result<(), NodeError> {
        stop_caught(&mut self.imp, &mut self.ctx).map_err(StopFailure::into_error)
    }

    /// The end of source `node`'s stream, for both executors (the pool's source thread when
    /// its loop ends; lockstep after its last pass, before the end-of-stream flush): the
    /// source is stopped under `catch_unwind` (an error or a panic in its `stop` fails the
    /// graph as "stop failed: ..." or "stop panicked: ..."), never called again, its slot
    /// marked ended, its output edges closed ([`Cell::close_outputs`]), and the control work
    /// queued for it refused. The caller puts the cell back in its slot.
    pub fn end_source(&mut self, shared: &Shared, node: usize, n: &dyn Notify) {
        match stop_caught(&mut self.imp, &mut self.ctx) {
            Ok(()) => {}
            Err(StopFailure::Error(e)) => shared.fail(node, NodeError::msg(format!("stop failed: {e}"))),
            Err(StopFailure::Panic(msg)) => shared.fail(node, NodeError::msg(format!("stop panicked: {msg}"))),
        }
        self.dead = true; // stopped: never run again
        self.close_outputs(n);
        let slot = &shared.slots[node];
        slot.ended.store(true, SeqCst);
        // Queued before `ended` was set: answered now rather than left waiting for the run's end.
        self.refuse_controls(&slot.control, "its stream has ended (a source that finished or was stopped)");
    }

    /// Moves the output slots onto their edges and wakes the consumers. Fan-out clones the
    /// `Arc` only; the last edge takes the message itself.
    fn publish(&mut self, n: &dyn Notify) {
        for (port, slot) in self.out_io.slots.iter_mut().enumerate() {
            let Some(msg) = slot.take() else { continue };
            bump(&self.stats.msgs_out, 1);
            let Some((last, rest)) = self.outputs[port].split_last_mut() else { continue };
            for tx in rest {
                if tx.push(msg.clone()) {
                    n.notify(tx.shared.spec.to_node);
                }
            }
            if last.push(msg) {
                n.notify(last.shared.spec.to_node);
            }
        }
    }

    /// Runs a control command, installs (or refuses) a hot-swapped instance, or applies a
    /// new deadline and restart policy, between calls.
    pub fn control(&mut self, c: Control, shared: &Shared) {
        match c {
            // A dead instance (panicked without restart, failed) is not called again, not
            // even for a command: the graph is stopping, the answer says why.
            Control::Command(cmd, reply) if self.dead => {
                tracing::warn!(node = %self.ctx.id, "control \"{cmd}\" not run: the node is dead");
                if let Some(tx) = reply {
                    let _ = tx.try_send(Err(NodeError::msg(
                        "not run: the node is dead (it panicked without a restart, or failed); the graph is stopping",
                    )));
                }
            }
            Control::Command(cmd, reply) => {
                let result = match catch_unwind(AssertUnwindSafe(|| self.imp.control(&mut self.ctx, &cmd))) {
                    Ok(result) => result,
                    // As a panic in a call: counted, and the restart policy applies (or the
                    // graph fails, as for a panic in `process`).
                    Err(p) => {
                        bump(&self.stats.panics, 1);
                        let msg = panic_message(p);
                        tracing::error!(node = %self.ctx.id, "panicked in control \"{cmd}\": {msg}");
                        if let Fired::Fatal(e) = self.after_panic(msg.clone()) {
                            shared.fail(self.ctx.index as usize, e);
                        }
                        Err(NodeError::Panic(msg))
                    }
                };
                match &result {
                    Ok(()) => tracing::info!(node = %self.ctx.id, "control \"{cmd}\" applied"),
                    Err(e) => tracing::warn!(node = %self.ctx.id, "control \"{cmd}\": {e}"),
                }
                if let Some(tx) = reply {
                    let _ = tx.try_send(result); // the asker may have given up waiting
                }
            }
            Control::Swap(s) => {
                let mut s = *s;
                if s.claim.compare_exchange(SWAP_PENDING, SWAP_TAKEN, SeqCst, SeqCst).is_err() {
                    // The asker was told it was not installed (it waited too long).
                    self.stop_replaced(&mut s.imp, "a cancelled swap's replacement");
                    tracing::warn!(node = %self.ctx.id, kind = %s.kind, "hot swap cancelled before it was installed");
                    return;
                }
                let reply = s.reply.take();
                let result = if self.eos == Eos::Closed {
                    // Never called again: a replacement would hold what it took over, unflushed.
                    self.stop_replaced(&mut s.imp, "a swap's replacement never installed");
                    Err("not installed: the node has flushed and closed its outputs (every input of it ended); the node \
                         kept its kind"
                        .to_owned())
                } else {
                    self.install(s, shared)
                };
                if let Err(why) = &result {
                    tracing::warn!(node = %self.ctx.id, "hot swap refused: {why}");
                }
                if let Some(tx) = reply {
                    let _ = tx.try_send(result);
                }
            }
            Control::Policy { deadline_ns, restart } => {
                self.deadline_ns = deadline_ns;
                self.restart = restart;
                tracing::info!(node = %self.ctx.id, ?deadline_ns, ?restart, "deadline and restart policy applied");
            }
        }
    }

    /// Installs a swap's replacement, after handing it the running instance's state; or, when
    /// the replacement refuses the swap, stops the replacement and leaves the running instance
    /// in place. `Err`: why the swap was refused.
    fn install(&mut self, s: Swap, shared: &Shared) -> Result<(), String> {
        let Swap { mut imp, recipe, kind, .. } = s;
        // A dead instance (panicked, failed) hands nothing over: its state is not trusted.
        if !self.dead
            && let Err(why) = self.hand_over(&mut imp)
        {
            self.stop_replaced(&mut imp, "a refused swap's replacement");
            return Err(why);
        }
        let mut old = std::mem::replace(&mut self.imp, imp);
        self.recipe = recipe;
        self.dead = false;
        self.stop_replaced(&mut old, "the replaced instance");
        bump(&self.stats.swaps, 1);
        if let Some(k) = shared.kinds.lock().unwrap_or_else(|p| p.into_inner()).get_mut(self.ctx.index as usize) {
            k.clone_from(&kind);
        }
        tracing::info!(node = %self.ctx.id, kind = %kind, "hot swap applied");
        Ok(())
    }

    /// Moves the running instance's state into the replacement `new`. A state the replacement
    /// refuses goes back to the running instance (whose `stop` then reports what it held);
    /// `Err` when the replacement refuses the swap itself, or panics taking the state over:
    /// the running instance then has its state back (if it takes it) and stays.
    fn hand_over(&mut self, new: &mut NodeImpl) -> Result<(), String> {
        let id = self.ctx.id.clone();
        let exported = catch_unwind(AssertUnwindSafe(|| self.imp.export_state(&mut self.ctx)));
        let state = match exported {
            Ok(Some(state)) => state,
            Ok(None) => return Ok(()),
            Err(p) => {
                tracing::error!(node = %id, "hot swap: exporting the state panicked ({}); the replacement starts afresh", panic_message(p));
                return Ok(());
            }
        };
        let refused = match catch_unwind(AssertUnwindSafe(|| new.import_state(&mut self.ctx, state))) {
            Ok(Ok(())) => {
                tracing::info!(node = %id, "hot swap: the replacement took over the node's state");
                return Ok(());
            }
            Ok(Err(refused)) => refused,
            Err(p) => {
                return Err(format!(
                    "the replacement panicked taking over the node's state ({}); the running instance goes on without it",
                    panic_message(p)
                ));
            }
        };
        if !refused.swap_refused {
            tracing::warn!(
                node = %id,
                "hot swap: the replacement starts afresh, it did not take over the node's state: {}",
                refused.reason
            );
        }
        let back = catch_unwind(AssertUnwindSafe(|| self.imp.import_state(&mut self.ctx, refused.state)));
        let lost = match back {
            Ok(Ok(())) => None,
            Ok(Err(back)) => Some(back.reason),
            Err(p) => Some(format!("panicked: {}", panic_message(p))),
        };
        if let Some(why) = &lost {
            tracing::error!(node = %id, "the running instance did not take its state back: {why}");
        }
        if refused.swap_refused {
            return Err(match lost {
                None => refused.reason,
                Some(why) => {
                    format!("{} (and the running instance did not take its state back: {why})", refused.reason)
                }
            });
        }
        Ok(())
    }

    /// Answers the control work still queued for a node that runs no more: a swap is not
    /// installed (its replacement is stopped, its asker told why), a command not run.
    pub fn refuse_controls(&mut self, queue: &crossbeam::queue::SegQueue<Control>, why: &str) {
        while let Some(c) = queue.pop() {
            match c {
                Control::Command(cmd, reply) => {
                    tracing::warn!(node = %self.ctx.id, "control \"{cmd}\" not run: {why}");
                    if let Some(tx) = reply {
                        let _ = tx.try_send(Err(NodeError::msg(format!("not run: {why}"))));
                    }
                }
                Control::Swap(s) => {
                    let mut s = *s;
                    let taken = s.claim.compare_exchange(SWAP_PENDING, SWAP_TAKEN, SeqCst, SeqCst).is_ok();
                    self.stop_replaced(&mut s.imp, "a swap's replacement never installed");
                    if taken {
                        tracing::warn!(node = %self.ctx.id, kind = %s.kind, "hot swap not installed: {why}");
                        if let Some(tx) = s.reply {
                            let _ = tx.try_send(Err(format!("not installed: {why}; the node kept its kind")));
                        }
                    }
                }
                Control::Policy { .. } => {}
            }
        }
    }
}
