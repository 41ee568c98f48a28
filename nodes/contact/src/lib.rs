//! Contact-level math of the dual-channel skin (paper §II-B/C, §III, §IV): pure functions
//! and preallocated structs, no engine dependency.
//!
//! Data flow per frame: [`segment::Segmenter`] turns a conductivity-change image into
//! [`segment::Contact`]s; [`split::Splitter`] shares the pneumatic pressure change among them;
//! [`correct::Strategy`] maps each share (or each conductivity sum) to a force.
//! Offline: [`correct::calibrate()`] fits a [`correct::Calibration`] from single-contact samples,
//! and [`eval`] matches predictions to ground truth and reports CONTRACTS.md §4 metrics.

pub mod segment;

pub use segment::grid::ImageGrid;
pub use segment::{Contact, Contacts, CrosstalkOutcome, PointSpread, SegmentError, SegmentParams, Segmenter};
pub mod correct;
pub mod eval;
pub mod split;

pub use correct::{CalibSample, Calibration, ForceEstimate, ForceFlags, Strategy, StrategyKind};
pub use split::{SensitivityField, SensitivitySample, Splitter};
