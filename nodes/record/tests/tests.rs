//! Tests of the HDF5 recording format: one test binary, one module per subject.

mod clock;
mod corrupt;
mod h5py;
mod repair;
mod rotate;
mod roundtrip;
mod schema;
mod truth_checks;
mod writer_errors;
