//! The host side (feature `host`): [`load`] a plugin library into a
//! [`skinflow_core::Registry`], with [`Codecs`] that turn payloads into columns and back.
//! Plugin kinds then build ordinary engine nodes by their role: [`HostedNode`] (processor),
//! [`HostedSource`], [`HostedSink`], each with the run-time hooks (a control command, a hot
//! swap's [`PluginState`]).

mod codec;
mod load;
mod node;

pub use codec::{Codec, Codecs, Decode, MakeCodec, RETAINED_INPUTS};
pub use load::{Loaded, PluginError, PluginLibrary, load, load_all, read_table, register_kinds};
pub use node::{HostedNode, HostedSink, HostedSource, KindFns, PluginFactory, PluginKind, PluginState};
