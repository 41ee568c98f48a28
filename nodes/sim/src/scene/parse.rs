//! The scene file as written: serde structs mirroring the TOML, with `Spanned` values so that
//! later checks can point at the offending line and column. No validation here.

use serde::Deserialize;
use toml::Spanned;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawScene {
    pub scene: RawHeader,
    #[serde(default)]
    pub rates: Option<RawRates>,
    /// A sensor description as in CONTRACTS.md section 1; absent: `paper-100mm`.
    pub sensor: Option<Spanned<toml::Table>>,
    /// Overrides of single profile constants.
    pub model: Option<Spanned<toml::Table>>,
    #[serde(default)]
    pub step: Vec<Spanned<RawStep>>,
    /// Hardware faults injected into the EIT channel.
    #[serde(default)]
    pub fault: Vec<Spanned<RawFault>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFault {
    pub kind: Spanned<String>,
    pub electrode: Spanned<i64>,
    pub from_s: Option<Spanned<f64>>,
    pub until_s: Option<Spanned<f64>>,
    pub rail_v: Option<Spanned<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawHeader {
    pub name: Option<String>,
    #[allow(dead_code)] // free text for readers of the file
    pub description: Option<String>,
    pub profile: Option<Spanned<String>>,
    /// The scene deliberately starts under load (a test of how the pipeline copes with a
    /// session resumed under load): lifts the rule that it opens with a no-load rest.
    pub start_under_load: Option<Spanned<bool>>,
    pub channels: Option<Spanned<Vec<Spanned<String>>>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRates {
    pub eit_fps: Option<Spanned<f64>>,
    pub pressure_hz: Option<Spanned<f64>>,
    pub pacing: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawStep {
    /// No-load time after the step (the whole step when it has no contacts), s.
    pub rest_s: Option<Spanned<f64>>,
    /// Simultaneous contacts pressed together.
    pub contacts: Option<Spanned<Vec<Spanned<RawContact>>>>,
    /// Single-contact positions on a regular grid.
    pub grid: Option<Spanned<RawGrid>>,
    /// Single-contact positions listed as [x_mm, y_mm] (each spanned, for its errors).
    pub at_mm: Option<Spanned<Vec<Spanned<[f64; 2]>>>>,
    pub diameter_mm: Option<Spanned<f64>>,
    /// A list of forces or a range `{ from, to, n }`; kept as TOML so that `expand` can say
    /// which forms are accepted when it is neither.
    pub forces_n: Option<Spanned<toml::Value>>,
    /// Piecewise-linear force profile [[t_s, force_n], ...] (instead of forces_n and holds).
    pub force_profile: Option<Spanned<Vec<[f64; 2]>>>,
    pub loading: Option<Spanned<String>>,
    pub hold_frames: Option<Spanned<f64>>,
    pub hold_s: Option<Spanned<f64>>,
    pub ramp_s: Option<Spanned<f64>>,
    pub release_s: Option<Spanned<f64>>,
    pub repeat: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawContact {
    pub x_mm: Spanned<f64>,
    pub y_mm: Spanned<f64>,
    pub diameter_mm: Spanned<f64>,
    pub force_n: Spanned<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawGrid {
    pub x_mm: [f64; 2],
    pub y_mm: [f64; 2],
    pub n: [i64; 2],
}
