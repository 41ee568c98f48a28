//! Tests of the FEM forward model and the NOSER reconstruction: one test binary, one module per
//! subject.

mod forward;
mod noser;
mod params;
mod reconstruct;
mod spread;
