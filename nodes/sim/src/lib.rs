//! A simulated dual-channel skin (EIT layer over a pneumatic chamber) for developing and
//! measuring the pipeline before hardware exists.
//!
//! A `Scene` (TOML) is expanded into a `Timeline` of contact holds and ramps. The `Simulator`
//! walks it in time order and emits `SimEvent`s: EIT frames from a nonlinear CEM forward solve
//! on its own fine mesh (`acquire`, with `compress` turning contacts into conductivity),
//! pressure samples from the `pneumatic` model, and ground-truth rows (`truth`). Constants
//! live in `Profile`; MODEL.md documents the model and what the `paper` profile achieves.

pub mod acquire;
pub mod compress;
pub mod pneumatic;
pub mod profile;
pub mod randomness;
pub mod scene;
pub mod simulate;
pub mod stage;
pub mod timeline;
pub mod truth;

pub use profile::Profile;
pub use scene::{Channels, Fault, Pacing, Rates, Scene, SceneError};
pub use simulate::{EventKind, SimError, SimEvent, Simulator};
pub use timeline::{Load, Segment, SegmentContact, Timeline};
pub use truth::{TruthContact, TruthRow};
