//! The crate's error type: one enum with structured fields, messages lower-case on one line.

use crate::sensor::SensorError;
use thiserror::Error;

/// Errors from meshing, forward solving and reconstruction.
#[derive(Debug, Error)]
pub enum EitError {
    /// The sensor description is invalid.
    #[error(transparent)]
    Sensor(#[from] SensorError),
    /// A parameter is out of range.
    #[error("parameter \"{param}\": {problem}")]
    InvalidParam { param: &'static str, problem: String },
    /// The mesher could not produce a valid mesh.
    #[error("mesh: {problem}")]
    Mesh { problem: String },
    /// A slice has the wrong length.
    #[error("\"{what}\": expected length {expected}, got {got}")]
    Length { what: &'static str, expected: usize, got: usize },
    /// A conductivity value is not finite and positive.
    #[error("conductivity of element {element} must be finite and > 0 (got {value})")]
    Conductivity { element: usize, value: f64 },
    /// A factorization failed (the matrix is not numerically positive definite).
    #[error("{what}: matrix is not positive definite")]
    NotPositiveDefinite { what: &'static str },
    /// Reading or writing the on-disk cache failed.
    #[error("cache {path}: {cause}")]
    Cache { path: String, cause: String },
    /// A channel that is not masked out holds a non-finite difference (mask it first).
    #[error("channel {channel}: difference {value} is not finite (mask the channel)")]
    NonFinite { channel: usize, value: f64 },
    /// A frame offered as the reference has no finite channel (a dead board).
    #[error("frame has no finite channel: it cannot be the reference")]
    NoFiniteReference,
    /// Every channel is masked out, nothing is left to reconstruct from.
    #[error("channel mask excludes all {total} channels")]
    NoChannels { total: usize },
}

pub(crate) fn invalid(param: &'static str, problem: impl Into<String>) -> EitError {
    EitError::InvalidParam { param, problem: problem.into() }
}

/// `x.is_finite() && x > 0.0`, else an `InvalidParam` naming `param`.
pub(crate) fn check_positive(param: &'static str, x: f64) -> Result<(), EitError> {
    if x.is_finite() && x > 0.0 { Ok(()) } else { Err(invalid(param, format!("must be finite and > 0 (got {x})"))) }
}
