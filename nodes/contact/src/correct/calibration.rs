//! The force calibration file: every fitted coefficient, the normalization, the chosen ridge
//! weights, a training summary and provenance, as TOML (`skinflow calibrate --out`).
//!
//! Units: forces N, pressures kPa, conductivity sums in image units x pixels (see
//! [`crate::segment`]), coordinates mm; the fields take coordinates normalized by `region`.
//! [`R2Table`] prints the paper's Table II layout. Loading checks `format`/`format_version`.

use super::field::{QuadField, Region};
use super::forward::ForwardModel;
use super::kernel::KernelField;
use super::map::SignalMap;
use crate::split::SensitivityField;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

/// Value of the `format` key.
pub const FORMAT: &str = "skinflow-calibration";
/// Current `format_version`.
pub const FORMAT_VERSION: u32 = 8;
/// Oldest `format_version` still read (version 3 lacks the location-held-out figures, versions
/// 3 and 4 the `cv_groups` choice, versions 3 to 5 `provenance.more_recordings`, versions 3 to
/// 6 the breakdown of the rejected samples, read as 0, and `provenance.pipeline`, versions 3
/// to 7 `provenance.sensor`).
pub const OLDEST_FORMAT_VERSION: u32 = 3;

/// Where a calibration came from (all given by the caller).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// Path of the recording the samples came from (the first, when there were several).
    pub recording: String,
    /// Content hash of that recording (e.g. "sha256:...").
    pub recording_hash: String,
    /// Version of the software that fitted it.
    pub software_version: String,
    /// The further recordings whose samples were pooled with the first, in the order given
    /// (`skinflow calibrate A.h5 B.h5 ...`); empty, and not written, for one recording.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub more_recordings: Vec<RecordingRef>,
    /// The reconstructor and segmenter settings the samples were taken with. The conductivity
    /// sums the EIT strategies and the area terms read scale with the image grid, lambda and
    /// the ROI (4x from a 64 x 64 to a 128 x 128 image), so `eval` warns when its own differ.
    /// Absent before version 7.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pipeline: Option<PipelineSettings>,
    /// The sensor the recordings were made with, so a calibration is not applied to another
    /// sensor's recordings (its region, fields and conductivity scale belong to this one).
    /// Absent before version 8.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<SensorRef>,
}

/// A sensor as far as a calibration depends on it: its size, electrodes and protocol (the
/// name is for messages; two sensors of one design calibrate alike).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorRef {
    pub name: String,
    pub width_mm: f64,
    pub height_mm: f64,
    pub electrodes: usize,
    pub protocol: String,
}

impl SensorRef {
    /// Whether `other` has the same size (to 1 µm), electrode count and protocol, whatever
    /// its name.
    pub fn same_geometry(&self, other: &SensorRef) -> bool {
        (self.width_mm - other.width_mm).abs() < 1e-3
            && (self.height_mm - other.height_mm).abs() < 1e-3
            && self.electrodes == other.electrodes
            && self.protocol == other.protocol
    }
}

impl fmt::Display for SensorRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "\"{}\" ({} x {} mm, {} electrodes, {})",
            self.name, self.width_mm, self.height_mm, self.electrodes, self.protocol
        )
    }
}

/// The reconstructor's and segmenter's params as the bodies of their TOML params tables
/// (`skinflow calibrate --recon ... --segment ...`); "" is every default.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineSettings {
    pub recon: String,
    pub segment: String,
}

/// One recording of a calibration's provenance.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingRef {
    /// Its path as given.
    pub recording: String,
    /// Content hash of its bytes (e.g. "sha256:...").
    pub recording_hash: String,
}

/// How the f of the location-aware model is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FFit {
    /// f, g and b minimize the paper's penalized objective together ([`super::joint`]).
    #[default]
    Joint,
    /// The paper's order: f on all locations pooled, then g and b with f fixed.
    Sequential,
}

/// What the inner cross-validation of the ridge weights holds out together.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CvGroups {
    /// Samples dealt into folds one by one: a held-out sample usually has samples of its own
    /// location in training (what files of format version 4 and older, without the field, used).
    #[default]
    Sample,
    /// Whole locations dealt into folds: the weights are chosen for places the fit has not
    /// seen, which is what the fields are used for.
    Location,
}

/// Location-aware gain and offset fields F = g(u, v) f(s) + b(u, v) (paper eq. 12-14).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LocAware {
    /// The f these fields multiply: the pooled map (`sequential`) or re-estimated with the
    /// pneumatic (or EIT) location-aware fields (`joint`); same signal range as the pooled
    /// map. The area-aware fields reuse the pneumatic one.
    pub map: SignalMap,
    /// How `map` was fitted.
    pub f_fit: FFit,
    /// Gain field g (dimensionless), coefficients alpha. With `f_fit = "joint"` its scale (shared
    /// with f) is fixed so that it averages 1 over the calibration samples.
    pub gain: QuadField,
    /// Offset field b (N), coefficients beta.
    pub offset: QuadField,
    /// Ridge weight on ||alpha - alpha0||^2 (absent when the prior was used).
    pub lambda_g: Option<f64>,
    /// Ridge weight on ||beta||^2 (absent when the prior was used).
    pub lambda_b: Option<f64>,
    /// Cross-validated RMSE of the fit, N (absent when the prior was used). Only g and b are
    /// held out: with the joint fit, f was fitted on every sample, so this is optimistic.
    pub cv_rmse_n: Option<f64>,
    /// True when the data were degenerate and the prior g = 1, b = 0 was kept.
    pub prior_fallback: bool,
}

impl LocAware {
    /// The prior g = 1, b = 0 on the pooled map.
    pub fn prior(map: SignalMap) -> Self {
        Self {
            map,
            f_fit: FFit::Sequential,
            gain: QuadField::constant(1.0),
            offset: QuadField::constant(0.0),
            lambda_g: None,
            lambda_b: None,
            cv_rmse_n: None,
            prior_fallback: true,
        }
    }
}

/// Area-aware extension: F = g f + b + a (k_gain f + k_offset), a = area / area_ref - 1
/// (clamped to the calibrated range of a).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AreaAware {
    /// Location fields fitted jointly with the area terms.
    pub fields: LocAware,
    /// Coefficient of a * f(dP) (dimensionless).
    pub area_gain: f64,
    /// Coefficient of a (N).
    pub area_offset: f64,
    /// Reference area: mean ROI area of the calibration samples, mm^2.
    pub area_ref_mm2: f64,
    /// Calibrated range of a = area / area_ref - 1.
    pub rel_area_min: f64,
    /// Calibrated range of a.
    pub rel_area_max: f64,
    /// Ridge weight on the two area coefficients (absent when the prior was used).
    pub lambda_a: Option<f64>,
}

/// One force signal's calibration: its map f and its location-aware fields.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SignalCalibration {
    /// f(signal) fitted on all locations pooled (the NoCal strategies).
    pub map: SignalMap,
    /// g and b, and the f they multiply.
    pub locaware: LocAware,
}

/// Signal-force R^2 of quadratic fits (paper Table II); absent where not computable.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct R2Table {
    /// EIT conductivity change sum, centre location.
    pub eit_center: Option<f64>,
    /// EIT conductivity change sum, all locations.
    pub eit_all: Option<f64>,
    /// Pneumatic pressure, centre location.
    pub pneumatic_center: Option<f64>,
    /// Pneumatic pressure, all locations.
    pub pneumatic_all: Option<f64>,
}

impl fmt::Display for R2Table {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let cell = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| format!("{v:.3}"));
        writeln!(f, "Signal-force correlation (R^2)")?;
        writeln!(f, "{:<30} {:>16} {:>14}", "Signal", "Center location", "All locations")?;
        writeln!(f, "{:<30} {:>16} {:>14}", "EIT conductivity change sum", cell(self.eit_center), cell(self.eit_all))?;
        write!(f, "{:<30} {:>16} {:>14}", "Pneumatic pressure", cell(self.pneumatic_center), cell(self.pneumatic_all))
    }
}

/// What the calibration was fitted on.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingSummary {
    /// Frames given to the calibration (before averaging holds).
    pub frames: usize,
    /// Samples used in the fits (after averaging holds and rejection).
    pub samples: usize,
    /// Samples rejected, for any reason (the quality filter, dP <= 0 and pressure spikes):
    /// `samples + rejected` is the number of hold means (or frames, without averaging).
    pub rejected: usize,
    /// Of `rejected`: samples with dP <= 0 kPa (no pressure response; absent in older files).
    #[serde(default)]
    pub rejected_non_positive_dp: usize,
    /// Of `rejected`: gross pressure spikes, off their location's power law dP = c F^gamma
    /// by more than a factor of 2 and 5 robust SDs ([`super::quality::pressure_outliers`];
    /// absent in older files).
    #[serde(default)]
    pub rejected_pressure_spikes: usize,
    /// Distinct force levels ([`super::quality::force_levels`]; absent, read as 0, in older
    /// files). Fewer than 3 fit f as a line (2) or through the origin (1).
    #[serde(default)]
    pub force_levels: usize,
    /// Distinct true locations.
    pub locations: usize,
    /// Range of true forces, N.
    pub force_min_n: f64,
    /// Range of true forces, N.
    pub force_max_n: f64,
    /// Indenter diameters seen, mm.
    pub diameters_mm: Vec<f64>,
    /// The location used as "centre" in the R^2 table, mm.
    pub center_location_mm: Option<[f64; 2]>,
    /// Samples at that location.
    pub center_samples: usize,
    /// Mean within-hold standard deviation of dP, kPa (0 when holds had one frame).
    pub hold_sd_dp_kpa: f64,
    /// Mean within-hold standard deviation of C, image units.
    pub hold_sd_cond_sum: f64,
    /// Relative ridge grid (weights searched = grid x samples).
    pub lambda_grid_rel: Vec<f64>,
    /// Folds of the inner cross-validation as requested (each fit clamps it to the samples, or
    /// with `cv_groups = "location"` to the locations, it has).
    pub folds: usize,
    /// What the inner cross-validation held out together (absent in older files: samples).
    #[serde(default)]
    pub cv_groups: CvGroups,
    /// RMSE on the training samples per strategy, N.
    pub train_rmse_n: BTreeMap<String, f64>,
    /// RMSE per strategy at locations the fit did not see, N: the locations are dealt into
    /// `holdout_folds` folds and the whole fit (f, weights, fields, kernels) is repeated
    /// without each fold's locations, which it then predicts. Empty when not computed
    /// (degenerate data, a fold too small to fit or whose fit failed, the check turned off
    /// with `holdout_folds = 0`, or a file of format version 3).
    #[serde(default)]
    pub holdout_rmse_n: BTreeMap<String, f64>,
    /// Folds of the location-held-out check (0 when not computed).
    #[serde(default)]
    pub holdout_folds: usize,
}

/// A complete force calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`FORMAT_VERSION`] of the writer.
    pub format_version: u32,
    /// Where it came from.
    pub provenance: Provenance,
    /// The calibrated region; field coordinates are normalized to it and clamped outside.
    pub region: Region,
    /// Pneumatic pressure signal (dP share, kPa).
    pub pneumatic: SignalCalibration,
    /// EIT conductivity sum signal (C).
    pub eit: SignalCalibration,
    /// Area-aware pneumatic model.
    pub area_aware: AreaAware,
    /// Forward pneumatic model P(F, x, y) (the `pneumatic-forward` corrector and the
    /// `force-balance` splitter).
    pub forward: ForwardModel,
    /// EIT response C = k(x, y) F^gamma for the compensated and force-balance splitters.
    pub sensitivity: SensitivityField,
    /// Paper Table II.
    pub r2: R2Table,
    /// Training-set summary.
    pub training: TrainingSummary,
    /// Warnings raised while fitting (also returned as data by `calibrate`).
    pub warnings: Vec<String>,
}

/// Why a calibration file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationFileError {
    /// File system error.
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    /// Not valid TOML for a calibration, at `line`:`column` when known.
    #[error("{path}{}: {message}", at.map_or(String::new(), |(l, c)| format!(":{l}:{c}")))]
    Parse { path: String, at: Option<(usize, usize)>, message: String },
    /// Wrong `format` or another `format_version`.
    #[error(
        "{path}: not a skinflow calibration this version reads (format \"{format}\", version {version}; expected \"{FORMAT}\" version {OLDEST_FORMAT_VERSION} to {FORMAT_VERSION}): re-run `skinflow calibrate` on the recording"
    )]
    Format { path: String, format: String, version: u32 },
    /// Parsed, but a value is out of range (e.g. a hand-edited file).
    #[error("{path}: {problem}")]
    Invalid { path: String, problem: String },
    /// Serialization failed.
    #[error("calibration: cannot serialize: {0}")]
    Serialize(String),
}

/// The first of `values` (each with its key path in the file) that is not finite, as the error
/// `pneumatic.map.quadratic.a1 = NaN: must be finite`: a hand-edited file is told which key.
fn finite(values: &[(String, f64)]) -> Result<(), String> {
    match values.iter().find(|(_, v)| !v.is_finite()) {
        Some((key, v)) => Err(format!("{key} = {v}: must be finite")),
        None => Ok(()),
    }
}

impl Calibration {
    /// TOML text of the calibration.
    pub fn to_toml_string(&self) -> Result<String, CalibrationFileError> {
        toml::to_string_pretty(self).map_err(|e| CalibrationFileError::Serialize(e.to_string()))
    }

    /// Parses TOML text; `origin` names the source in errors (a path, or `<string>`).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, CalibrationFileError> {
        // `file:line:col: key.path: cause`, as graph, scene and sensor files are reported (not
        // toml's multi-line snippet squeezed onto one line).
        let parse = |e: toml::de::Error| {
            let at = e.span().map(|span| {
                // At a character boundary whatever the span says (toml's fall on one).
                let start = (0..=span.start.min(text.len())).rev().find(|&i| text.is_char_boundary(i)).unwrap_or(0);
                let before = &text[..start];
                let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
                (before.matches('\n').count() + 1, column)
            });
            let message = skinflow_toml::message(&e).replace('\n', " ");
            CalibrationFileError::Parse { path: origin.to_string(), at, message }
        };
        // The header first, so a file of another version is named as such, not as a parse error.
        #[derive(Deserialize)]
        struct Header {
            format: String,
            format_version: u32,
        }
        // Another TOML file (a sensor, a scene, a graph) or an empty one is named as such,
        // not as a missing `format` field at line 1.
        let table: toml::Table = toml::from_str(text).map_err(parse)?;
        if !table.contains_key("format") {
            let what = if table.is_empty() { "is empty" } else { "has no `format` key" };
            return Err(CalibrationFileError::Invalid {
                path: origin.to_string(),
                problem: format!(
                    "not a skinflow calibration: the file {what} (a calibration starts with format = \"{FORMAT}\"; \
                     `skinflow calibrate` writes one)"
                ),
            });
        }
        let h: Header = skinflow_toml::from_str(text).map_err(parse)?;
        if h.format != FORMAT || !(OLDEST_FORMAT_VERSION..=FORMAT_VERSION).contains(&h.format_version) {
            return Err(CalibrationFileError::Format {
                path: origin.to_string(),
                format: h.format,
                version: h.format_version,
            });
        }
        // Strict: toml alone fills `[f64; 6]` from a longer array, dropping the rest.
        let mut cal: Calibration = skinflow_toml::from_str(text).map_err(parse)?;
        cal.validate().map_err(|problem| CalibrationFileError::Invalid { path: origin.to_string(), problem })?;
        // Read as the current version (older files lack only optional figures), so a file
        // written back is consistent with its keys.
        cal.format_version = FORMAT_VERSION;
        Ok(cal)
    }

    /// Checks the values the per-frame math divides by or exponentiates: a hand-edited file
    /// must fail here, at load, rather than give NaN forces (or no split) later.
    /// The signal-to-force maps whose force does not rise over their calibrated signal range
    /// (`SignalMap::rises`), by name: loaded (a calibration may hold one of a layer it could
    /// not fit), but every force of such a strategy is the same, so readers warn.
    pub fn flat_maps(&self) -> Vec<&'static str> {
        [
            ("pneumatic.map", &self.pneumatic.map),
            ("pneumatic.locaware.map", &self.pneumatic.locaware.map),
            ("eit.map", &self.eit.map),
            ("eit.locaware.map", &self.eit.locaware.map),
            ("area_aware.fields.map", &self.area_aware.fields.map),
        ]
        .into_iter()
        .filter(|(_, m)| !m.rises())
        .map(|(name, _)| name)
        .collect()
    }

    pub fn validate(&self) -> Result<(), String> {
        let (w, h) = self.region.span_mm();
        if ![self.region.x_min_mm, self.region.y_min_mm, w, h].iter().all(|v| v.is_finite()) || w <= 0.0 || h <= 0.0 {
            let r = &self.region;
            return Err(format!(
                "region must be finite with positive width and height (got x_min_mm = {}, x_max_mm = {}, \
                 y_min_mm = {}, y_max_mm = {})",
                r.x_min_mm, r.x_max_mm, r.y_min_mm, r.y_max_mm
            ));
        }
        let kernel = |name: &str, k: &KernelField| -> Result<(), String> {
            // Fitted on the calibrated region; another one would clamp and normalize elsewhere.
            if k.region != self.region {
                return Err(format!("{name}.region must equal [region] (got {:?})", k.region));
            }
            if !(k.length_mm.is_finite() && k.length_mm > 0.0) {
                return Err(format!("{name}.length_mm must be finite and > 0 (got {})", k.length_mm));
            }
            finite(&[(format!("{name}.mean"), k.mean)])?;
            for (i, site) in k.sites.iter().enumerate() {
                finite(
                    &site.iter().enumerate().map(|(j, &v)| (format!("{name}.sites[{i}][{j}]"), v)).collect::<Vec<_>>(),
                )?;
            }
            Ok(())
        };
        for (name, m) in [
            ("pneumatic.map", &self.pneumatic.map),
            ("pneumatic.locaware.map", &self.pneumatic.locaware.map),
            ("eit.map", &self.eit.map),
            ("eit.locaware.map", &self.eit.locaware.map),
            ("area_aware.fields.map", &self.area_aware.fields.map),
        ] {
            let q = &m.quadratic;
            finite(&[
                (format!("{name}.quadratic.a0"), q.a0),
                (format!("{name}.quadratic.a1"), q.a1),
                (format!("{name}.quadratic.a2"), q.a2),
                (format!("{name}.signal_min"), m.signal_min),
                (format!("{name}.signal_max"), m.signal_max),
            ])?;
            if m.signal_min > m.signal_max {
                return Err(format!("{name}: signal_min ({}) must be <= signal_max ({})", m.signal_min, m.signal_max));
            }
        }
        // The location fields: a NaN gain would pass the gain floor as the floor itself.
        for (name, l) in [
            ("pneumatic.locaware", &self.pneumatic.locaware),
            ("eit.locaware", &self.eit.locaware),
            ("area_aware.fields", &self.area_aware.fields),
        ] {
            let (gain, offset) = (l.gain.coeffs.iter(), l.offset.coeffs.iter());
            let named = gain
                .enumerate()
                .map(|(i, &v)| (format!("{name}.gain[{i}]"), v))
                .chain(offset.enumerate().map(|(i, &v)| (format!("{name}.offset[{i}]"), v)));
            finite(&named.collect::<Vec<_>>())?;
        }
        let a = &self.area_aware;
        finite(&[
            ("area_aware.area_gain".into(), a.area_gain),
            ("area_aware.area_offset".into(), a.area_offset),
            ("area_aware.rel_area_min".into(), a.rel_area_min),
            ("area_aware.rel_area_max".into(), a.rel_area_max),
        ])?;
        if !(a.area_ref_mm2.is_finite() && a.area_ref_mm2 > 0.0) {
            return Err(format!("area_aware.area_ref_mm2 must be finite and > 0 (got {})", a.area_ref_mm2));
        }
        if a.rel_area_min > a.rel_area_max {
            return Err(format!(
                "area_aware: rel_area_min ({}) must be <= rel_area_max ({})",
                a.rel_area_min, a.rel_area_max
            ));
        }
        let e = self.sensitivity.exponent;
        if !(e.is_finite() && e > 0.0) {
            return Err(format!("sensitivity.exponent must be finite and > 0 (got {e})"));
        }
        kernel("sensitivity.log_k", &self.sensitivity.log_k)?;
        kernel("forward.sensitivity", &self.forward.sensitivity)?;
        if self.forward.sensitivity.mean.is_nan() || self.forward.sensitivity.mean <= 0.0 {
            return Err(format!("forward.sensitivity.mean must be > 0 kPa/N (got {})", self.forward.sensitivity.mean));
        }
        if !(self.forward.force_max_n.is_finite() && self.forward.force_max_n > 0.0) {
            return Err(format!("forward.force_max_n must be finite and > 0 (got {})", self.forward.force_max_n));
        }
        if !self.forward.curvature.is_finite() {
            return Err("forward.curvature must be finite".into());
        }
        Ok(())
    }

    /// Reads a calibration file.
    pub fn read(path: &Path) -> Result<Self, CalibrationFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| {
            let path = path.display().to_string();
            if source.kind() == std::io::ErrorKind::InvalidData {
                // A binary file (a recording given as --calib, say), not the io error's
                // "stream did not contain valid UTF-8".
                let problem = "not a skinflow calibration: not UTF-8 text (a calibration is the TOML file `skinflow calibrate` writes)".to_owned();
                CalibrationFileError::Invalid { path, problem }
            } else {
                CalibrationFileError::Io { path, source }
            }
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Writes a calibration file.
    pub fn write(&self, path: &Path) -> Result<(), CalibrationFileError> {
        std::fs::write(path, self.to_toml_string()?)
            .map_err(|source| CalibrationFileError::Io { path: path.display().to_string(), source })
    }
}
