//! Tests of TOML parsing with source spans: one test binary, one module per subject.

mod choices;
mod common;
mod num;
mod strict;
