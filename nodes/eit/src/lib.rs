//! EIT for the skin: sensor model, mesh, CEM forward solver, adjoint Jacobian, NOSER.
//!
//! Stable forward API (used by the simulator):
//! `Mesh::generate(&Sensor, &MeshParams) -> Result<Mesh, EitError>` (fields `nodes` in mm,
//! `triangles`; `element_centroids_mm()`, `element_areas_mm2()`),
//! `ForwardModel::new(&Sensor, &Mesh, &CemParams) -> Result<ForwardModel, EitError>` (symbolic
//! factorization once), `ForwardModel::measure(&self, sigma_s_per_m: &[f64]) -> Result<Vec<f64>>`
//! (volts, protocol order) and `ForwardModel::solve(&self, sigma)` returning a
//! `ForwardSolution` with `electrode_voltages(drive)` and `measurement(&Measurement)`.

pub mod error;
pub mod forward;
pub mod mesh;
pub mod sensor;

pub use error::EitError;
pub use forward::{CemParams, ForwardModel, ForwardSolution};
pub use mesh::{Mesh, MeshParams};
pub use sensor::{Electrode, Measurement, Protocol, Sensor, SensorError};
