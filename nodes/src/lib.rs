//! skinflow's built-in nodes: thin engine wrappers over the domain crates
//! (`skinflow-eit`, `skinflow-contact`, `skinflow-record`, `skinflow-serial`, `skinflow-sim`).
//!
//! [`registry`] returns every built-in kind, plus the engine's toy kinds used by demos and tests.

use skinflow_core::Registry;

/// Every built-in node kind.
pub fn registry() -> Registry {
    let mut r = Registry::new();
    skinflow_core::toy::register(&mut r).expect("built-in kinds have distinct names");
    r
}
