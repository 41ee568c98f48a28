//! A handle on a running graph, usable from other threads (a control socket, a file watcher):
//! live statistics, control commands, and hot swaps of a node's kind or parameters.
//!
//! A swap builds and starts the replacement off the data path, then hands it to the node's
//! executor as a control message: it takes effect between two calls, the node's queues (and
//! every message in them) stay where they are, and the old instance is stopped. Only a
//! replacement with the same ports (names and types, in order) is accepted: edges index ports.
//!
//! State hand-over: at the switch the old instance exports what it learned from the stream
//! ([`crate::Processor::export_state`]) and the replacement imports it
//! ([`crate::Processor::import_state`]), so a node rebuilt with new parameters keeps e.g. its
//! EIT reference frame, tare and noise estimates instead of re-learning them from data that is
//! no longer no-load. Every swap goes through here (`skinflow run --watch` edits and control
//! socket swaps alike). A replacement that refuses the state (another kind, another channel
//! count) starts afresh with a warning naming the reason. No hand-over after a panic: a restart
//! or a swap of a dead instance starts from scratch.

use std::path::PathBuf;
use std::sync::atomic::Ordering::SeqCst;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::RunError;
use super::cell::Recipe;
use super::pool::{Control, Shared, Swap};
use crate::edge::EdgeShared;
use crate::error::NodeError;
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
    pub kinds: Mutex<Vec<String>>,
    pub signatures: Vec<Signature>,
    /// Per node, the names of its inputs with an edge (a replacement's params are checked
    /// against them, as at load).
    pub wired: Vec<Vec<String>>,
    pub edges: Vec<Arc<EdgeShared>>,
    pub name: String,
    pub mode: Mode,
    pub t0: Instant,
    pub base_dir: PathBuf,
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
    /// if it rejects the command. A node that is not called within `timeout` (the graph has
    /// ended, a source blocked in a read) gives [`RunError::ControlTimeout`]; the command
    /// stays queued and may still run.
    pub fn control_wait(&self, node: &str, cmd: &str, timeout: Duration) -> Result<(), RunError> {
        let i = self.index(node)?;
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        self.push(i, Control::Command(cmd.to_owned(), Some(tx)));
        match rx.recv_timeout(timeout) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(error)) => Err(RunError::Control { node: node.to_owned(), command: cmd.to_owned(), error }),
            Err(_) => Err(RunError::ControlTimeout { node: node.to_owned(), command: cmd.to_owned(), timeout }),
        }
    }

    /// Replaces a node by one built from `factory` and `params`. The replacement is built and
    /// started here (the running node keeps working meanwhile) and installed between two of
    /// the node's calls; its queues are kept, so a `block` edge loses nothing.
    pub fn swap(&self, node: &str, factory: Arc<dyn NodeFactory>, params: Params) -> Result<(), RunError> {
        let i = self.index(node)?;
        let swap_err = |problem: String| RunError::Swap { node: node.to_owned(), problem };
        let info = factory.info();
        if signature(info) != self.inner.signatures[i] {
            return Err(swap_err(format!(
                "kind \"{}\" has other ports than the running node; changing ports needs a restart",
                info.name
            )));
        }
        factory.check(&params).map_err(|e| swap_err(e.to_string()))?;
        let wired: Vec<&str> = self.inner.wired[i].iter().map(String::as_str).collect();
        factory.check_wiring(&params, &Wiring::new(&wired)).map_err(|e| swap_err(e.to_string()))?;
        let build =
            BuildContext { base_dir: self.inner.base_dir.clone(), mode: self.inner.mode, node_id: node.to_owned() };
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
        let kind = info.name.to_string();
        self.push(
            i,
            Control::Swap(Box::new(Swap { imp, recipe: Recipe { factory, params, build }, kind: kind.clone() })),
        );
        self.inner.kinds.lock().unwrap_or_else(|p| p.into_inner())[i] = kind;
        Ok(())
    }

    /// A live snapshot of the statistics.
    pub fn stats(&self) -> StatsReport {
        let inner = &self.inner;
        let kinds = inner.kinds.lock().unwrap_or_else(|p| p.into_inner()).clone();
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
