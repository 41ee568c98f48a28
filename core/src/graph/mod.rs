//! Graphs: parse a TOML graph file ([`file`]), validate it against a [`Registry`]
//! ([`validate`]) into a [`GraphSpec`] that the runtime instantiates, render it as Graphviz ([`dot`]).

pub mod dot;
pub mod error;
pub mod file;
pub mod source;
mod validate;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

pub use error::{GraphError, GraphErrorKind, GraphErrors};
pub use file::{Policy, Restart, ThreadMode};
pub use source::SourceFile;

use crate::node::Mode;
use crate::params::Params;
use crate::port::PortSpec;
use crate::registry::{NodeFactory, Registry};

/// Default queue capacity of an edge, in messages.
pub const DEFAULT_CAPACITY: usize = 64;

/// When a processor or sink runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trigger {
    /// On any input: one message per call, the oldest head first.
    Any,
    /// On all inputs aligned by equal `Header::seq`; older unmatched heads are dropped (counted).
    AlignedSeq,
    /// On all inputs whose head timestamps lie within `window_ns`; older heads are dropped (counted).
    AlignedWindow { window_ns: u64 },
    /// Every period, with the newest message of each input; older ones are counted as coalesced.
    Periodic { period: Duration },
}

/// A validated node.
#[derive(Clone)]
pub struct NodeSpec {
    pub id: String,
    pub kind: String,
    pub factory: Arc<dyn NodeFactory>,
    pub params: Params,
    pub trigger: Trigger,
    /// Per-call budget in microseconds; overruns are counted.
    pub deadline_us: Option<f64>,
    pub cpu: Option<usize>,
    pub rt_priority: Option<u8>,
    pub restart: Restart,
    pub thread: ThreadMode,
}

/// A validated edge between an output port and an input port.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeSpec {
    pub from_node: usize,
    pub from_port: usize,
    pub to_node: usize,
    pub to_port: usize,
    pub capacity: usize,
    pub policy: Policy,
    /// `"node.port"` as written.
    pub from: String,
    pub to: String,
}

/// A graph that passed validation.
#[derive(Clone)]
pub struct GraphSpec {
    pub source: SourceFile,
    pub name: String,
    pub mode: Mode,
    /// Worker threads; 0 = one per core.
    pub workers: usize,
    pub plugins: Vec<PathBuf>,
    pub nodes: Vec<NodeSpec>,
    pub edges: Vec<EdgeSpec>,
    /// Node indices in a topological order (ties in file order).
    pub topo: Vec<usize>,
}

impl GraphSpec {
    /// Reads and validates a graph file. Plugins named in it must already be in `registry`
    /// (see [`plugin_paths`] to load them first).
    pub fn load(path: &Path, registry: &Registry) -> Result<GraphSpec, GraphErrors> {
        let src = SourceFile::read(path).map_err(|e| {
            GraphErrors(vec![GraphError {
                file: path.to_path_buf(),
                line: 1,
                col: 1,
                node: None,
                kind: GraphErrorKind::Syntax(format!("cannot read: {e}")),
            }])
        })?;
        GraphSpec::parse(src, registry)
    }

    /// Validates graph text.
    pub fn parse(src: SourceFile, registry: &Registry) -> Result<GraphSpec, GraphErrors> {
        validate::validate(src, registry)
    }

    pub fn node_index(&self, id: &str) -> Option<usize> {
        self.nodes.iter().position(|n| n.id == id)
    }

    /// The names of node `i`'s inputs that have at least one edge, in port order.
    pub fn connected_inputs(&self, i: usize) -> Vec<String> {
        connected_inputs(&self.nodes[i].factory.info().inputs, i, &self.edges).into_iter().map(str::to_owned).collect()
    }
}

/// The `[[plugin]] path` entries of a graph file, resolved against its directory, so the
/// caller can load them into the registry before validation.
pub fn plugin_paths(src: &SourceFile) -> Result<Vec<PathBuf>, GraphErrors> {
    validate::plugin_paths(src)
}

/// The names of node `node`'s `inputs` that one of `edges` reaches, in port order.
pub(crate) fn connected_inputs<'a>(inputs: &'a [PortSpec], node: usize, edges: &[EdgeSpec]) -> Vec<&'a str> {
    (0..inputs.len())
        .filter(|&p| edges.iter().any(|e| e.to_node == node && e.to_port == p))
        .map(|p| inputs[p].name.as_ref())
        .collect()
}
