//! Tests of segmentation, splitting, correction, calibration and evaluation: one test binary,
//! one module per subject.

mod calib_robust;
mod correct;
mod crosstalk;
mod eval;
mod pipeline;
mod segment;
mod synth;
