//! Force correction (paper §II-C, §III): the signal-to-force map, location-aware fields,
//! the strategies that apply them per contact, and the calibration that fits them.
//!
//! Offline, [`calibrate::calibrate`] turns single-contact samples into a
//! [`calibration::Calibration`] (TOML). Per frame, a [`strategy::Strategy`] resolved from it
//! maps a contact and its pressure share to a force with guard flags.

pub mod average;
pub mod calibrate;
pub mod calibration;
pub mod field;
pub mod fit;
pub mod forward;
pub mod joint;
pub mod kernel;
pub mod map;
pub mod quality;
pub mod strategy;

pub use average::{Holds, average_holds};
pub use calibrate::{CalibParams, CalibSample, CalibWarning, CalibrateError, Calibrated, calibrate};
pub use calibration::{
    Calibration, CalibrationFileError, CvGroups, FFit, PipelineSettings, Provenance, R2Table, RecordingRef, SensorRef,
};
pub use strategy::{ForceEstimate, ForceFlags, Strategy, StrategyKind};
