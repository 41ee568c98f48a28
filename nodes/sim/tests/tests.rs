//! Tests of the sensor simulator: one test binary, one module per subject.

mod eit_baselines;
mod paper_profile;
mod scene_input;
mod sim_state;
mod simulate;
