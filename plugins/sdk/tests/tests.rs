//! Tests of the plugin SDK's host side on tables built in this binary: one test binary, one
//! module per subject.

mod common;
mod flush;
mod hooks;
mod roles;
mod table;
