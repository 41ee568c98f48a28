//! EIT for the skin: sensor model, mesh, CEM forward solver, adjoint Jacobian, one-step NOSER.
//!
//! Flow: `Sensor` -> `Mesh::generate` -> `ForwardModel` (CEM) -> `jacobian` -> `DualSystem`
//! (prior, dual form) -> `precompute::Model::fold` (with the `ImageMap`) -> `Reconstructor`
//! (one matrix-vector product per frame, cached on disk, channel masking). `ReferenceTracker`
//! keeps the no-load frame.
//!
//! # Model, units and conventions
//! - Geometry in mm, sensor frame of CONTRACTS.md (origin at the centre, x right, y up).
//! - The skin is a 2-D sheet of thickness `CemParams::thickness_mm` (default 5 mm); conductivity
//!   per element in S/m (default background 0.02 S/m = 200 uS/cm, the paper's saline); contact
//!   impedance in ohm*mm^2 (default 5e4, i.e. 2 kohm over a 5 x 5 mm contact face); drive
//!   current in uA (default 10 uA: 0.19-0.37 V, median 0.31 V, on the default pairwise sensor;
//!   0.1-32 mV with the adjacent protocol); values in volts.
//! - Protocol values: current in at drive.0, out at drive.1, value V[sense.0] - V[sense.1].
//! - Jacobian: rows = measurements in protocol order, columns = elements, V per (S/m).
//! - Difference data: normalized dv = (v - v_ref) / v_ref (default) or plain dv = v - v_ref.
//! - Inverse: ds = (J^T J + lambda^2 R)^-1 J^T dv in dual form; default prior NOSER,
//!   R = diag(J^T J)^0.5, trace-normalised so lambda is dimensionless (default 0.1); also
//!   identity and Laplacian priors. The unknown is the relative change dsigma/sigma0; outputs
//!   are dsigma in S/m: negative = conductivity decrease (a press on the paper's skin). They
//!   are one-step linearised estimates, not conductivities: nothing bounds them by sigma0, and
//!   their scale depends on lambda and on where the change is. A disc at 1 % of the 0.02 S/m
//!   background images as -1.86 S/m on an electrode but -5.9e-3 S/m at the centre (true
//!   change -0.0198 S/m), so sums or peaks of them are signals to calibrate, not physical
//!   conductances.
//! - Image: 64 x 64 pixels tiling the rectangle, index iy * nx + ix, iy = 0 at the bottom.
//!
//! # Per-frame API (the `reconstructor` node)
//! `Reconstructor::new(&Sensor, &ReconParams)` (loads or precomputes; `info()` reports cache
//! use, mesh size and minimum angle, lambda, prior). Per frame, no allocation:
//! `reconstruct_image_into(v, v_ref, image)`, `reconstruct_elements_into(v, v_ref, elements)` or
//! `reconstruct_into(v, v_ref, image, elements)`; `detect_mask_into(v, Some(v_ref), &mut mask)`
//! (NaN, rail and 0 V channels of the frame or the reference, dead electrodes) then
//! `set_mask(&mask)` (a new mask builds its matrix once, then it is cached in memory and on
//! disk). Pixel geometry: `grid()` (`pixel_centre_mm`, `pixel_area_mm2`, `pixel_at`).
//! `ReferenceTracker` picks the reference frame; `choose_lambda` + `set_lambda` tune lambda.
//! `point_spread(radius_mm)` gives the active matrix's linear point spread (`spread`), which a
//! segmenter uses to tell a press from another press's sidelobe (builds the model once).
//!
//! # Stable forward API (used by the simulator)
//! `Mesh::generate(&Sensor, &MeshParams) -> Result<Mesh, EitError>` (fields `nodes` in mm,
//! `triangles`; `element_centroids_mm()`, `element_areas_mm2()`),
//! `ForwardModel::new(&Sensor, &Mesh, &CemParams) -> Result<ForwardModel, EitError>` (symbolic
//! factorization once), `ForwardModel::measure(&self, sigma_s_per_m: &[f64]) -> Result<Vec<f64>>`
//! (volts, protocol order) and `ForwardModel::solve(&self, sigma)` returning a
//! `ForwardSolution` with `electrode_voltages(drive)` and `measurement(&Measurement)`.

pub mod cache;
pub mod error;
pub mod forward;
pub mod image;
pub mod jacobian;
pub mod lambda;
pub mod mask;
pub mod mesh;
pub mod noser;
pub mod precompute;
pub mod reconstruct;
pub mod reference;
pub mod sensor;
pub mod spread;

pub use error::EitError;
pub use forward::{CemParams, ForwardModel, ForwardSolution};
pub use image::{ImageGrid, ImageMap};
pub use jacobian::jacobian;
pub use lambda::{LambdaChoice, LambdaMethod};
pub use mask::{ChannelMask, MaskParams};
pub use mesh::{Mesh, MeshParams};
pub use noser::{DualSystem, Prior};
pub use precompute::{DifferenceMode, Model};
pub use reconstruct::{CacheStatus, Precision, ReconInfo, ReconParams, Reconstructor};
pub use reference::{ReferenceSource, ReferenceTracker};
pub use sensor::{Electrode, Measurement, Protocol, Sensor, SensorError};
pub use spread::{PointSpread, SpreadBasis};
