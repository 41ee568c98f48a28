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
//! - `host` (feature `host`): loading libraries, checking ABI version and struct sizes, and
//!   wrapping plugin kinds as engine processors, sources and sinks through payload codecs.

pub mod abi;
pub mod columns;
pub mod export;
#[cfg(feature = "host")]
pub mod host;

pub use columns::{ColumnBuf, Columns};
pub use export::{Flush, KindSpec, Outputs, PluginNode, PluginSink, PluginSource, Poll, SourceCtx};
