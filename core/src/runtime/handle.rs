//! A handle on a running graph, usable from other threads (a control socket, a file watcher):
//! live statistics, control commands, and hot swaps of a node's kind or parameters.
//!
//! A swap builds and starts the replacement off the data path, then hands it to the node's
//! executor as a control message: it takes effect between two calls, the node's queues (and
//! every message in them) stay where they are, and the old instance is stopped. Only a
//! replacement with the same ports (names and types, in order) is accepted: edges index ports.
//! A swap counts (`swaps`, and the kind the statistics show) once it is installed, not when it
//! is asked: [`GraphHandle::swap_wait`] answers with the outcome, and a swap its node never
//! gets to (a source whose stream ended, the end of the run) has its replacement stopped
//! unused and its asker told so.
//!
//! State hand-over: at the switch the old instance exports what it learned from the stream
//! ([`crate::Processor::export_state`]) and the replacement imports it
//! ([`crate::Processor::import_state`]), so a node rebuilt with new parameters keeps e.g. its
//! EIT reference frame, tare and noise estimates instead of re-learning them from data that is
//! no longer no-load. Every swap goes through here (`skinflow run --watch` edits and control
//! socket swaps alike). A replacement that refuses the state (another kind, another channel
//! count) starts afresh with a warning naming the reason; one that cannot go on from it at all
//! (a source asked to continue another recording or scene, a logger asked to write the file
//! the running instance writes) refuses the swap ([`crate::StateRefused::refuse_swap`]): the
//! running instance takes its state back and goes on. No hand-over after a panic: a restart
//! or a swap of a dead instance starts from scratch.

use std::path::PathBuf;
use std::sync::atomic::AtomicU8;
use std::sync::atomic::Ordering::SeqCst;
use std::sync::mpsc::{RecvTimeoutError, SyncSender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::RunError;
use super::cell::Recipe;
use super::pool::{Control, SWAP_CANCELLED, SWAP_PENDING, Shared, Swap};
use crate::edge::EdgeShared;
use crate::error::NodeError;
use crate::graph::Restart;
use crate::node::{Context, Mode};
use crate::params::Params;
use crate::registry::{BuildContext, KindInfo, NodeFactory, Wiring};
use crate::stats::{EdgeReport, NodeReport, StatsReport};

/// (name, type) of each port, in declaration order.
type Ports = Vec<(String, String)>;
/// Inputs then outputs: what a replacement must match.
pub(crate) type Signature = (Ports, Ports);

/// Port names and types of a kind.
fn signature(k: &KindInfo) -> Signature {
    let ports = |v: &[crate::port::PortSpec]| v.iter().map(|p| (p.name.to_string(), p.ty.to_string())).collect();
    (ports(&k.inputs), ports(&k.outputs))
}

pub(crate) struct Inner {
    pub shared: Arc<Shared>,
    pub ids: Vec<String>,
    pub signatures: Vec<Signature>,
    /// Per node, the names of its inputs with an edge (a replacement's params are checked
    /// against them, as at load).
    pub wired: Vec<Vec<String>>,
    pub edges: Vec<Arc<EdgeShared>>,
    pub name: String,
    pub mode: Mode,
    pub t0: Instant,
    pub base_dir: PathBuf,
    /// The graph text replacements are built with ([`GraphHandle::set_graph_text`]).
    pub graph_text: Mutex<Arc<str>>,
}

/// Cheap to clone; `Send + Sync`.
#[derive(Clone)]
pub struct GraphHandle {
    pub(crate) inner: Arc<Inner>,
}

impl GraphHandle {
    /// Index of a node by id.
    pub fn node_index(&self, id: &str) -> Option<usize> {
        self.inner.ids.iter().position(|x| x == id)
    }

    /// Node ids in graph order.
    pub fn node_ids(&self) -> &[String] {
        &self.inner.ids
    }

    /// Whether node `node` runs no more: a source whose stream ended, a node that failed, or
    /// every node once the run is over. Its queued control work is then never run.
    pub fn node_ended(&self, node: &str) -> Result<bool, RunError> {
        Ok(self.inner.shared.slots[self.index(node)?].ended.load(SeqCst))
    }

    fn index(&self, node: &str) -> Result<usize, RunError> {
        self.node_index(node).ok_or_else(|| RunError::UnknownNode(node.to_owned()))
    }

    fn push(&self, i: usize, c: Control) {
        let slot = &self.inner.shared.slots[i];
        slot.control.push(c);
        slot.has_control.store(true, SeqCst);
        self.inner.shared.notify_external(i);
    }

    /// Sends a control command (e.g. `tare`) to a node; it runs between two of its calls.
    /// Does not wait: the node's answer is only logged (see [`GraphHandle::control_wait`]).
    pub fn control(&self, node: &str, cmd: &str) -> Result<(), RunError> {
        let i = self.index(node)?;
        self.push(i, Control::Command(cmd.to_owned(), None));
        Ok(())
    }

    /// Sends a control command and waits at most `timeout` for the node's answer: its error
    /// if it rejects the command. A node that runs no more ([`GraphHandle::node_ended`], before
    /// or while waiting) is answered at once with [`RunError::Ended`]. A node that is not called
    /// within `timeout` (a source blocked in a read) gives [`RunError::ControlTimeout`]; the
    /// command stays queued and may still run.
    pub fn control_wait(&self, node: &str, cmd: &str, timeout: Duration) -> Result<(), RunError> {
        let i = self.index(node)?;
        let answer = |r: Result<(), NodeError>| {
            r.map_err(|error| RunError::Control { node: node.to_owned(), command: cmd.to_owned(), error })
        };
        let ended = || RunError::Ended { node: node.to_owned(), command: cmd.to_owned() };
        let slot = &self.inner.shared.slots[i];
        if slot.ended.load(SeqCst) {
            return Err(ended());
        }
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        self.push(i, Control::Command(cmd.to_owned(), Some(tx)));
        let deadline = Instant::now() + timeout;
        loop {
            let now = Instant::now();
            if now >= deadline {
                return Err(RunError::ControlTimeout { node: node.to_owned(), command: cmd.to_owned(), timeout });
            }
            match rx.recv_timeout((deadline - now).min(Duration::from_millis(20))) {
                Ok(r) => return answer(r),
                Err(RecvTimeoutError::Disconnected) => return Err(ended()),
                Err(RecvTimeoutError::Timeout) if slot.ended.load(SeqCst) => {
                    // Answered just before it ended, or never will be.
                    return rx.try_recv().map_or_else(|_| Err(ended()), answer);
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
    }

    /// Sets the graph text that replacements are built with from now on
    /// ([`BuildContext::graph_text`]): the edited file's, when a graph edit is applied.
    /// Initially the text of the graph the run started from.
    pub fn set_graph_text(&self, text: Arc<str>) {
        *self.inner.graph_text.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = text;
    }

    /// Replaces a node by one built from `factory` and `params`. The replacement is built and
    /// started here (the running node keeps working meanwhile) and installed between two of
    /// the node's calls; its queues are kept, so a `block` edge loses nothing. Does not wait
    /// for the install: `Ok` means queued. A swap the replacement refuses at the install (see
    /// [`crate::StateRefused::refuse_swap`]) is only logged, and one the node never gets to
    /// (the run ends first) is stopped unused; neither counts as a swap or changes the kind
    /// the statistics show. [`GraphHandle::swap_wait`] answers with the outcome.
    pub fn swap(&self, node: &str, factory: Arc<dyn NodeFactory>, params: Params) -> Result<(), RunError> {
        self.queue_swap(node, factory, params, None).map(|_| ())
    }

    /// [`GraphHandle::swap`], then waits at most `timeout` for the node to install it: `Ok`
    /// once the replacement runs, the refusal's reason when it refused to take the node over
    /// (the node then runs as before). A swap not installed within `timeout` (the node is not
    /// called: a source waiting for its next message, the graph ending) or whose node ends
    /// first is cancelled, the replacement stopped unused, and an error returned.
    pub fn swap_wait(
        &self,
        node: &str,
        factory: Arc<dyn NodeFactory>,
        params: Params,
        timeout: Duration,
    ) -> Result<(), RunError> {
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        let (i, claim) = self.queue_swap(node, factory, params, Some(tx))?;
        let refused = |problem: String| RunError::Swap { node: node.to_owned(), problem };
        let deadline = Instant::now() + timeout;
        let slot = &self.inner.shared.slots[i];
        loop {
            match rx.recv_timeout(Duration::from_millis(20)) {
                Ok(result) => return result.map_err(refused),
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(refused("the graph ended before the swap was installed".into()));
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
            let ended = slot.ended.load(SeqCst);
            if !ended && Instant::now() < deadline {
                continue;
            }
            if claim.compare_exchange(SWAP_PENDING, SWAP_CANCELLED, SeqCst, SeqCst).is_ok() {
                return Err(if ended {
                    refused("the node runs no more (a source whose stream ended, or the run is over)".into())
                } else {
                    RunError::SwapTimeout { node: node.to_owned(), timeout }
                });
            }
            // The node took it: the install (or refusal) is under way, and always answered.
            return match rx.recv() {
                Ok(result) => result.map_err(refused),
                Err(_) => Err(refused("the graph ended before the swap was installed".into())),
            };
        }
    }

    /// Checks, builds and starts a replacement and queues it for node `node`. Returns the
    /// node's index and the swap's claim (see [`Swap::claim`]).
    fn queue_swap(
        &self,
        node: &str,
        factory: Arc<dyn NodeFactory>,
        params: Params,
        reply: Option<SyncSender<Result<(), String>>>,
    ) -> Result<(usize, Arc<AtomicU8>), RunError> {
        let i = self.index(node)?;
        let swap_err = |problem: String| RunError::Swap { node: node.to_owned(), problem };
        let ended = || {
            swap_err("the node runs no more (a source whose stream ended, or the run is over): nothing to swap".into())
        };
        if self.inner.shared.slots[i].ended.load(SeqCst) {
            return Err(ended());
        }
        let info = factory.info();
        if signature(info) != self.inner.signatures[i] {
            return Err(swap_err(format!(
                "kind \"{}\" has other ports than the running node; changing ports needs a restart",
                info.name
            )));
        }
        factory.check(&params).map_err(|e| swap_err(e.to_string()))?;
        info.no_empty_paths(&params).map_err(|e| swap_err(e.to_string()))?;
        let wired: Vec<&str> = self.inner.wired[i].iter().map(String::as_str).collect();
        factory.check_wiring(&params, &Wiring::new(&wired)).map_err(|e| swap_err(e.to_string()))?;
        let text = self.inner.graph_text.lock().unwrap_or_else(std::sync::PoisonError::into_inner).clone();
        let build = BuildContext::new(self.inner.base_dir.clone(), self.inner.mode, node).with_graph_text(text);
        // The input files the params name, as `check` and `run` open them before a run.
        factory.check_files(&params, &build).map_err(|e| swap_err(e.to_string()))?;
        let mut imp = factory.build(&params, &build).map_err(|e| swap_err(format!("build failed: {e}")))?;
        if imp.role() != info.role {
            return Err(swap_err(format!("factory built a {:?} for a kind declared {:?}", imp.role(), info.role)));
        }
        let shared = &self.inner.shared;
        let mut ctx = Context::new(
            i as u32,
            Arc::from(node),
            self.inner.t0,
            self.inner.mode,
            shared.stop.clone(),
            shared.slots[i].stats.clone(),
        );
        imp.start(&mut ctx).map_err(|e: NodeError| swap_err(format!("start failed: {e}")))?;
        if shared.slots[i].ended.load(SeqCst) {
            // Ended while the replacement was built: it is stopped unused.
            if let Err(e) = super::cell::stop_caught(&mut imp, &mut ctx) {
                tracing::warn!(node, "an unused swap replacement failed to stop: {e}");
            }
            return Err(ended());
        }
        let claim = Arc::new(AtomicU8::new(SWAP_PENDING));
        let kind = info.name.to_string();
        self.push(
            i,
            Control::Swap(Box::new(Swap {
                imp,
                recipe: Recipe { factory, params, build },
                kind,
                claim: claim.clone(),
                reply,
            })),
        );
        Ok((i, claim))
    }

    /// Sets a node's per-call deadline (`deadline_us`, `None`: none) and restart policy, from
    /// its next call on (what a `--watch` edit of those keys applies without a swap).
    pub fn set_policy(&self, node: &str, deadline_us: Option<f64>, restart: Restart) -> Result<(), RunError> {
        let i = self.index(node)?;
        self.push(i, Control::Policy { deadline_ns: deadline_us.map(|us| (us * 1e3) as u64), restart });
        Ok(())
    }

    /// A live snapshot of the statistics.
    pub fn stats(&self) -> StatsReport {
        let inner = &self.inner;
        let kinds = inner.shared.kinds.lock().unwrap_or_else(|p| p.into_inner()).clone();
        let nodes = (0..inner.ids.len())
            .map(|i| {
                let inputs: Vec<&crate::stats::EdgeStats> =
                    inner.edges.iter().filter(|e| e.spec.to_node == i).map(|e| &e.stats).collect();
                NodeReport::from_stats(&inner.ids[i], &kinds[i], &inner.shared.slots[i].stats, &inputs)
            })
            .collect();
        let edges = inner
            .edges
            .iter()
            .map(|e| EdgeReport::from_stats(&e.spec.from, &e.spec.to, e.spec.policy, e.spec.capacity, &e.stats))
            .collect();
        StatsReport {
            graph: inner.name.clone(),
            mode: inner.mode,
            wall_s: inner.t0.elapsed().as_secs_f64(),
            nodes,
            edges,
        }
    }

    pub(crate) fn new(inner: Inner) -> GraphHandle {
        GraphHandle { inner: Arc::new(inner) }
    }

    pub(crate) fn signature_of(k: &KindInfo) -> Signature {
        signature(k)
    }
}
