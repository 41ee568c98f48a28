//! skinflow's plugin SDK: node kinds in a separately built library (`cdylib`), loaded at run
//! time by a graph's `[[plugin]] path = "..."`.
//!
//! - [`abi`]: the versioned `#[repr(C)]` function table and message layout (named `f64`
//!   columns plus a header), the only thing both sides share.
//! - [`export`]: for plugin authors. Implement [`PluginNode`] (a processor, optionally with an
//!   end-of-stream [`PluginNode::flush`]), [`PluginSource`] or
//!   [`PluginSink`] on an ordinary struct, then
//!   `skinflow_plugin_sdk::export_plugin!(name = "my-plugin", kinds = [MyNode], sources = [MyBoard], sinks = [MyOut]);`.
//!   Panics are caught in the plugin and reported as errors; they never cross the boundary.
//! - [`columns`]: reading ([`Columns`]) and writing ([`ColumnBuf`]) messages as columns.
//! - Run-time hooks of every role, with defaults: a control command ([`PluginNode::control`])
//!   and a hot swap's hand-over ([`PluginNode::export_state`]: bytes the plugin encodes, e.g.
//!   with [`StateWriter`]; [`PluginNode::import_state`] answers an [`ImportOutcome`]; both in
//!   [`state`]), so a swapped instance, e.g. of a rebuilt library, goes on where the running
//!   one stopped.
//! - `host` (feature `host`): loading libraries, checking ABI version and struct sizes, and
//!   wrapping plugin kinds as engine processors, sources and sinks through payload codecs.
//!
//! # A plugin crate outside the skinflow workspace
//!
//! This crate is not published: depend on it by path (or git), without the `host` feature,
//! and give `version` and `edition` explicitly (the in-tree examples inherit them from the
//! workspace, so a copy of one fails with "error inheriting edition from workspace"):
//!
//! ```toml
//! [package]
//! name = "my-plugin"
//! version = "0.1.0"
//! edition = "2024"
//!
//! [lib]
//! crate-type = ["cdylib"]
//!
//! [dependencies]
//! skinflow-plugin-sdk = { path = "/path/to/skinflow/plugins/sdk" }
//! serde = { version = "1", features = ["derive"] }
//! ```
//!
//! Param docs ([`KindSpec::param`]) use the type names of [`export::PARAM_TYPES`] (checked at
//! load): a file the kind writes is an `output-path` ([`export::OUTPUT_PATH`]), one it only
//! reads an `input-path`, so the graph checks refuse two nodes writing one file or a node
//! writing a file another reads; an EIT source names the sensor of its frames with a `sensor`
//! ([`export::SENSOR`]), so they refuse a reconstructor it feeds that images on another. A param
//! `name` is also read by the host as the name of the node's outputs. What a
//! derived output (`contacts`, `split`, `forces`) carries of its input is found by header:
//! see [`PluginNode::process`]. More in `plugins/README.md`.

pub mod abi;
pub mod columns;
pub mod export;
#[cfg(feature = "host")]
pub mod host;
pub mod state;

pub use columns::{ColumnBuf, Columns};
pub use export::{Flush, KindSpec, Outputs, PluginNode, PluginSink, PluginSource, Poll, SourceCtx};
pub use state::{ImportOutcome, StateReader, StateWriter};
