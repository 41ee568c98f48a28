//! Tests of the engine: one test binary, one module per subject.

mod faults;
mod flush;
#[path = "support/kinds.rs"]
mod kinds;
mod run;
mod swap;
mod validation;
