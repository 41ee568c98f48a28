//! Tests of the built-in nodes inside graphs: one test binary, one module per subject.

mod compare;
mod handover;
mod loadcell;
mod loadcell_negatives;
mod logger;
mod outputs;
mod param_docs;
mod sync;
