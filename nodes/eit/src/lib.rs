//! EIT for the skin: sensor model, mesh, CEM forward solver, adjoint Jacobian, NOSER.

pub mod sensor;

pub use sensor::{Electrode, Measurement, Protocol, Sensor, SensorError};
