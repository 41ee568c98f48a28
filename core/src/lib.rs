//! skinflow's engine. It knows nothing of EIT: it runs typed node graphs.
//!
//! A graph file ([`graph`]) names nodes by kind from a [`Registry`] and joins their typed
//! ports with edges. [`GraphSpec::load`] validates it, reporting every error at its line and
//! column. [`runtime::RunningGraph`] builds the nodes ([`Source`], [`Processor`], [`Sink`]),
//! wires each edge as a bounded lock-free queue ([`edge`]) and runs them on a worker pool with
//! real-time options, or in deterministic lockstep. [`stats`] reports what happened.

pub mod alloc_count;
pub mod edge;
pub mod error;
pub mod graph;
pub mod io;
pub mod message;
pub mod node;
pub mod params;
pub mod port;
pub mod recycle;
pub mod registry;
pub mod runtime;
pub mod stats;
pub mod toy;

pub use error::NodeError;
pub use graph::{GraphErrors, GraphSpec};
pub use io::{Inputs, Outputs};
pub use message::{Header, Message, Payload};
pub use node::{Context, Mode, NodeImpl, NodeState, Processor, Sink, Source, SourcePoll, StateRefused};
pub use params::{ParamError, Params};
pub use port::PortSpec;
pub use recycle::Recycler;
pub use registry::{BuildContext, KindInfo, NodeFactory, NodeParams, ParamDoc, Registry, Role, Wiring, typed};
pub use runtime::{GraphHandle, RunError, RunOptions, RunReport, RunningGraph, run};
pub use stats::{Counter, StatsReport};
