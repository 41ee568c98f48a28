//! skinflow's built-in nodes: thin engine wrappers over the domain crates
//! (`skinflow-eit`, `skinflow-contact`, `skinflow-record`, `skinflow-serial`, `skinflow-sim`).
//!
//! Data path: sources (`sim`, `replay`, `serial_*`) -> [`sync`] -> `reconstructor` ->
//! `segmenter` -> `splitter` -> `corrector` -> sinks (`hdf5_logger`, `compare`). Messages are
//! the [`payload`] types. [`registry`] returns every built-in kind, plus the engine's toy kinds.

pub mod codec;
pub mod compare;
pub mod correct;
pub mod gate;
pub mod log;
pub mod order;
pub mod output;
pub mod outputs;
pub mod pace;
pub mod payload;
pub mod pipeline;
pub mod reconstruct;
pub mod replay;
pub mod scale;
pub mod segment;
pub mod sensors;
pub mod serial;
pub mod sim;
pub mod split;
#[cfg(test)]
mod swap_test;
pub mod sync;

use skinflow_core::Registry;
use skinflow_core::registry::DuplicateKind;

/// A module's kind registration.
type Register = fn(&mut Registry) -> Result<(), DuplicateKind>;

/// Every check of a graph's files before it runs, in order, each only once the one before
/// passes: the files its nodes read open as the nodes read them
/// ([`GraphSpec::check_files`](skinflow_core::GraphSpec::check_files)), the sensors they name
/// agree ([`sensors::check_graph`]), and no node writes over a file the graph reads or another
/// node writes, and every strategy a logger lists arrives ([`outputs::check_graph`]); last,
/// what would stop a node at start (a logger's file it may not replace, two serial sources on
/// one port: [`outputs::check_start`]). Used by `skinflow check`, `run` and each `bench`
/// variant.
pub fn check_graph_files(spec: &skinflow_core::GraphSpec) -> Result<(), skinflow_core::graph::GraphErrors> {
    spec.check_files()
        .and_then(|()| sensors::check_graph(spec))
        .and_then(|()| outputs::check_graph(spec))
        .and_then(|()| outputs::check_start(spec))
}

/// Every built-in node kind.
pub fn registry() -> Registry {
    let mut r = Registry::new();
    skinflow_core::toy::register(&mut r).expect("built-in kinds have distinct names");
    let reg: [Register; 10] = [
        sim::register,
        replay::register,
        log::register,
        serial::register,
        sync::register,
        reconstruct::register,
        segment::register,
        split::register,
        correct::register,
        compare::register,
    ];
    for f in reg {
        f(&mut r).expect("built-in kinds have distinct names");
    }
    r
}
