//! The graph file's TOML schema, with spans kept for error messages.
//!
//! ```toml
//! [graph]
//! name = "demo"
//! mode = "realtime"          # or "lockstep"
//!
//! [[node]]
//! id = "recon"
//! kind = "reconstructor"
//! trigger = "any"            # "aligned" (align = "seq" | align_window_us = N) or "periodic" (period_ms = N)
//! deadline_us = 500
//! restart = "never"          # or "always"
//! params = { lambda = 0.03 }
//!
//! [[edge]]
//! from = "sim.eit"
//! to = "recon.eit"
//! capacity = 64
//! policy = "block"           # or "drop_oldest"
//! ```

use std::collections::BTreeMap;

use serde::Deserialize;
use toml::Spanned;

use crate::node::Mode;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct GraphFile {
    #[serde(default)]
    pub graph: GraphSection,
    #[serde(default)]
    pub plugin: Vec<PluginEntry>,
    #[serde(default)]
    pub node: Vec<Spanned<NodeEntry>>,
    #[serde(default)]
    pub edge: Vec<Spanned<EdgeEntry>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct GraphSection {
    pub name: Option<String>,
    #[serde(default)]
    pub mode: Mode,
    /// Worker threads for processors; 0 or absent = one per core.
    pub workers: Option<Spanned<usize>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PluginEntry {
    pub path: Spanned<String>,
}

/// Edge queue policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Policy {
    /// Lossless: a full queue holds the producer back.
    #[default]
    Block,
    /// Latest wins: a full queue evicts its oldest message, counted as a drop.
    DropOldest,
}

/// How a processor or sink is triggered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TriggerKind {
    /// One message at a time, from whichever input holds the oldest.
    #[default]
    Any,
    /// One message from every input, matched by sequence number or time window.
    Aligned,
    /// Every `period_ms`, with the newest message of each input (if any).
    Periodic,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlignBy {
    #[default]
    Seq,
    Time,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Restart {
    /// A panicking node stops the graph.
    #[default]
    Never,
    /// A panicking node is rebuilt from its params and started again.
    Always,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ThreadMode {
    /// Processors and sinks: the shared worker pool. Refused on a source, which always runs on
    /// a thread of its own.
    #[default]
    Pool,
    /// A thread of its own (implied by `cpu` or `rt_priority`).
    Dedicated,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct NodeEntry {
    pub id: Spanned<String>,
    pub kind: Spanned<String>,
    pub params: Option<toml::Table>,
    #[serde(default)]
    pub trigger: TriggerKind,
    pub align: Option<Spanned<AlignBy>>,
    pub align_window_us: Option<Spanned<f64>>,
    pub period_ms: Option<Spanned<f64>>,
    pub deadline_us: Option<Spanned<f64>>,
    pub cpu: Option<Spanned<usize>>,
    pub rt_priority: Option<Spanned<u8>>,
    #[serde(default)]
    pub restart: Restart,
    /// Absent = pool (or dedicated, when `cpu` or `rt_priority` asks for a thread of its own).
    pub thread: Option<Spanned<ThreadMode>>,
}

/// The `[[node]]` tables read without their schema: every key and value with its span, so a
/// schema error inside a table can name the node (by its `id`) and the key at fault.
#[derive(Debug, Deserialize)]
pub(crate) struct LooseFile {
    #[serde(default)]
    pub node: Vec<Spanned<LooseTable>>,
}

/// A table read without its schema: every key and value with its span.
pub(crate) type LooseTable = BTreeMap<Spanned<String>, Spanned<toml::Value>>;

/// The whole file read without its schema: each section with its span, so
/// that a section at fault can be set aside and the rest of the file checked
/// (`validate::parse_file` reports every schema error, not only the first).
#[derive(Debug, Deserialize)]
pub(crate) struct LooseSections {
    pub graph: Option<Spanned<LooseTable>>,
    #[serde(default)]
    pub plugin: Vec<Spanned<LooseTable>>,
    #[serde(default)]
    pub node: Vec<Spanned<LooseTable>>,
    #[serde(default)]
    pub edge: Vec<Spanned<LooseTable>>,
}

/// The sections [`LooseSections`] reads; any other top-level key is one the schema lacks.
pub(crate) const SECTIONS: [&str; 4] = ["graph", "plugin", "node", "edge"];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct EdgeEntry {
    pub from: Spanned<String>,
    pub to: Spanned<String>,
    pub capacity: Option<Spanned<usize>>,
    #[serde(default)]
    pub policy: Policy,
}
