//! Fitting a [`Calibration`] from single-contact samples (paper §III).
//!
//! Input: one [`CalibSample`] per EIT frame with a detected contact and ground truth. Frames
//! of one hold are averaged ([`super::average`], the paper's 6-frame means), outliers are
//! rejected (non-finite, C <= 0, F <= 0, centroid farther than `max_location_error_mm` from
//! the truth; then dP <= 0, and gross pressure spikes per location,
//! [`super::quality::pressure_outliers`]; each counted and warned), then per signal: f by
//! least squares over all locations (the NoCal map; a quadratic, or with fewer than 3 force
//! levels a line or a line through the origin, [`FShape`]), and g, b by ridge towards
//! alpha0 = (1, 0, 0, 0, 0, 0), beta = 0 with (lambda_g, lambda_b) = grid x T chosen by inner
//! k-fold CV. With `f_fit = "joint"` (the default) f is then re-estimated together with g and
//! b on the same penalized objective ([`super::joint`]), the weights are chosen again by CV
//! on the final f, and the scale shared by f and g is fixed so that g averages 1 over the
//! samples; `"sequential"` stops after the paper's order. Degenerate data (too few samples
//! or locations, a region narrower than `min_span_mm`, locations that do not determine a
//! quadratic field, a single force level) keep the prior, with a warning.

use super::average::{Holds, average_holds, locations};
use super::calibration::{
    AreaAware, Calibration, CvGroups, FFit, FORMAT, FORMAT_VERSION, LocAware, Provenance, R2Table, SignalCalibration,
    TrainingSummary,
};
use super::field::{NPHI, QuadField, Region, locaware_design, phi};
use super::fit::{CvSearch, FShape, RidgeProblem, cross_validate, fit_quadratic, fold_of, r_squared};
use super::forward::{ForwardModel, ForwardSample};
use super::joint::{JointProblem, fit_joint, normalize_gain};
use super::map::SignalMap;
use super::quality::{
    FLAT_MAP_RISE_REL, MIN_LAYOUT_EIGENVALUE, force_levels, layout_eigenvalue, map_rise, pressure_outliers,
};
use super::strategy::{Strategy, StrategyKind};
use crate::segment::Contact;
use crate::split::{SensitivityField, SensitivitySample};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One calibration frame (or hold average): EIT contact, pneumatic share and ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CalibSample {
    /// EIT centroid, mm.
    pub x_mm: f64,
    /// EIT centroid, mm.
    pub y_mm: f64,
    /// True indenter centre, mm.
    pub true_x_mm: f64,
    /// True indenter centre, mm.
    pub true_y_mm: f64,
    /// True normal force, N.
    pub force_n: f64,
    /// Tared pressure change, kPa.
    pub dp_kpa: f64,
    /// Conductivity decrease sum C of the contact.
    pub cond_sum: f64,
    /// ROI area, mm^2.
    pub area_mm2: f64,
    /// Indenter diameter, mm.
    pub diameter_mm: f64,
    /// The hold the frame was acquired in, as its source numbers them (0 if it does not):
    /// consecutive frames are averaged together only with the same hold and the same load
    /// (within a load cell's jitter, [`crate::correct::average::same_load`]), so two
    /// indentations with the same truth (a repeated protocol, the next recording) stay two
    /// samples.
    pub hold: u64,
}

impl CalibSample {
    fn contact(&self) -> Contact {
        Contact { x_mm: self.x_mm, y_mm: self.y_mm, sum: self.cond_sum, area_mm2: self.area_mm2, peak: 0.0, label: 0 }
    }
}

/// Fitting options (the `calibrate` command's knobs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibParams {
    /// Average the consecutive frames of each hold (same hold number and load) before fitting.
    pub average_holds: bool,
    /// Folds of the inner cross-validation of the ridge weights.
    pub folds: usize,
    /// What one inner cross-validation fold holds out: `"location"` (whole locations) or
    /// `"sample"`.
    pub cv_groups: CvGroups,
    /// Folds of whole locations in the location-held-out check (capped at the number of
    /// locations); 0 turns the check off (it repeats the whole fit once per fold).
    pub holdout_folds: usize,
    /// Ridge weights searched, relative to the number of samples T (weight = rel x T); each
    /// >= [`LAMBDA_REL_MIN`].
    pub lambda_grid_rel: Vec<f64>,
    /// Fewer samples than this keep the prior fields.
    pub min_samples: usize,
    /// Fewer distinct true locations than this keep the prior fields.
    pub min_locations: usize,
    /// A centroid spread narrower than this (mm, either axis) keeps the prior fields.
    pub min_span_mm: f64,
    /// True positions closer than this (mm) are the same location.
    pub location_tolerance_mm: f64,
    /// Samples whose centroid is farther than this from the truth (mm) are rejected.
    pub max_location_error_mm: f64,
    /// How the location-aware strategies' f is fitted: `"joint"` or `"sequential"`.
    pub f_fit: FFit,
}

impl Default for CalibParams {
    fn default() -> Self {
        Self {
            average_holds: true,
            folds: 5,
            cv_groups: CvGroups::Sample,
            holdout_folds: 5,
            lambda_grid_rel: (0..=16).map(|i| 10f64.powf(-4.0 + 0.5 * i as f64)).collect(),
            min_samples: 4 * NPHI,
            min_locations: NPHI,
            min_span_mm: 5.0,
            location_tolerance_mm: 2.0,
            max_location_error_mm: 15.0,
            f_fit: FFit::Joint,
        }
    }
}

/// Smallest relative ridge weight accepted in `lambda_grid_rel`.
///
/// Why 1e-8: a row of the field design is [f Phi, Phi] with |Phi|^2 <= 6 on [-1, 1]^2 and f up
/// to ~10 N, so the Gram matrix's largest eigenvalue is at most ~600 T. The penalty rel x T is
/// the smallest eigenvalue in a direction the data do not determine (collinear locations), so
/// the system's condition number is at most ~600 / rel: at 1e-8 about 6e10, which leaves 5
/// significant digits of a double-precision solve. At 1e-12 (6e14) about one digit is left, and
/// the audit saw 8.7e6 N training errors. The default grid starts at 1e-4.
pub const LAMBDA_REL_MIN: f64 = 1e-8;

/// A strategy whose RMSE on its own training samples is above this many times its
/// cross-validated RMSE (plus [`TRAIN_CV_SLACK_N`]) is warned about.
///
/// Why 10: a held-out error is normally the larger of the two; a stored model ten times worse
/// on the data it was fitted to than the model the cross-validation scored is not that model
/// (a gain floor or an envelope changed it).
pub const TRAIN_CV_RATIO: f64 = 10.0;

/// Absolute slack of the training-versus-CV check, N: far below any force sensor's resolution,
/// so rounding on noise-free data (CV RMSE ~1e-12 N) raises nothing.
pub const TRAIN_CV_SLACK_N: f64 = 1e-3;

impl CalibParams {
    /// Checks every field; run at load.
    pub fn validate(&self) -> Result<(), CalibrateError> {
        let bad = |name, problem| Err(CalibrateError::Param { name, problem });
        if self.folds < 2 {
            return bad("folds", "must be >= 2");
        }
        if self.holdout_folds == 1 {
            return bad("holdout_folds", "must be 0 (no held-out check) or >= 2");
        }
        if self.lambda_grid_rel.is_empty()
            || self.lambda_grid_rel.iter().any(|l| !(l.is_finite() && *l >= LAMBDA_REL_MIN))
        {
            return bad(
                "lambda_grid_rel",
                "must be non-empty, finite and >= 1e-8 (a smaller weight leaves the field directions the data do not determine to rounding error)",
            );
        }
        // A zero span would let a calibration whose centroids lie on a line through: its region
        // has no height, and the fields' normalization divides by it.
        if !(self.min_span_mm.is_finite() && self.min_span_mm > 0.0) {
            return bad("min_span_mm", "must be finite and > 0");
        }
        for (name, v) in [
            ("location_tolerance_mm", self.location_tolerance_mm),
            ("max_location_error_mm", self.max_location_error_mm),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, "must be finite and >= 0");
            }
        }
        Ok(())
    }
}

/// Something the fit noticed; the calibration is still usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibWarning {
    /// Samples dropped by the quality filter.
    #[error(
        "rejected {count} of {total} samples (non-finite, C <= 0, F <= 0 or centroid > {max_error_mm} mm from truth)"
    )]
    Rejected { count: usize, total: usize, max_error_mm: f64 },
    /// Samples with no pressure response (a pneumatic dropout, or a tare above the loaded
    /// reading): their force cannot come from dP.
    #[error("rejected {count} of {total} samples with dP <= 0 kPa (no pressure response)")]
    NonPositivePressure { count: usize, total: usize },
    /// Gross pressure spikes (see [`super::quality::pressure_outliers`]).
    #[error(
        "rejected {count} of {total} samples as pressure spikes (dP more than a factor of 2 and 5 robust SDs off its location's power law dP = c F^gamma) at {locations} location(s)"
    )]
    PressureSpikes { count: usize, total: usize, locations: usize },
    /// Fewer than 3 force levels: f is not fitted as a quadratic.
    #[error("{levels} distinct force level(s) (a quadratic f needs 3): {fallback}")]
    FewForceLevels { levels: usize, fallback: &'static str },
    /// The locations do not determine a quadratic field (a line, two rows, a circle, ...).
    #[error(
        "the calibration locations do not determine a quadratic field (smallest eigenvalue of Phi^T Phi / L over the {locations} locations {eigenvalue:.1e} < {min:.0e}; e.g. all on a line): location fields fall back to the prior g = 1, b = 0"
    )]
    UndeterminedLayout { locations: usize, eigenvalue: f64, min: f64 },
    /// A fitted f barely rises over its signal range.
    #[error(
        "{what}: f rises only {rise_n:.3} N over its signal range against a {force_range_n:.3} N force range: forces will hardly depend on the signal"
    )]
    FlatMap { what: &'static str, rise_n: f64, force_range_n: f64 },
    /// A strategy's training RMSE far above its cross-validated RMSE.
    #[error(
        "{strategy}: training RMSE {train_rmse_n:.3e} N is far above its cross-validated RMSE {cv_rmse_n:.3e} N: the stored model is not the one validated"
    )]
    TrainAboveCv { strategy: &'static str, train_rmse_n: f64, cv_rmse_n: f64 },
    /// The joint fit's gain does not average to a positive value, so its scale cannot be fixed.
    #[error(
        "{what}: the joint fit's gain does not average to a positive value over the samples; the paper's order (pooled f, then g and b) is kept"
    )]
    JointGauge { what: &'static str },
    /// Frames left out of their hold's mean (the rest of the hold is still used).
    #[error("left {count} of {total} frames out of their holds' means (non-finite centroid, dP, C or area)")]
    NonFiniteFrames { count: usize, total: usize },
    /// Too few samples for the fields.
    #[error("only {samples} samples (need {min}): location fields fall back to the prior g = 1, b = 0")]
    TooFewSamples { samples: usize, min: usize },
    /// Too few locations for the fields.
    #[error("only {locations} distinct locations (need {min}): location fields fall back to the prior g = 1, b = 0")]
    TooFewLocations { locations: usize, min: usize },
    /// Centroids span too small a region.
    #[error(
        "centroids span {span_x_mm:.1} x {span_y_mm:.1} mm (need {min_mm} mm): location fields fall back to the prior"
    )]
    NarrowRegion { span_x_mm: f64, span_y_mm: f64, min_mm: f64 },
    /// A ridge fit could not be solved; its prior is used.
    #[error("{what}: ridge fit failed, prior kept")]
    FitFailed { what: &'static str },
    /// The sensitivity field could not be fitted; the compensated split is proportional.
    #[error("eit sensitivity field not fitted: sensitivity-compensated split equals proportional")]
    UniformSensitivity,
    /// The joint f fit stopped early; the last consistent (f, g, b) is kept.
    #[error("{what}: {problem}; the last consistent f and fields are kept")]
    JointFit { what: &'static str, problem: &'static str },
    /// The location-held-out check could not fit every fold; no held-out figures.
    #[error("location-held-out check skipped: {reason}")]
    HoldoutSkipped { reason: String },
    /// No centre location: the R^2 table's centre column is empty.
    #[error("no location with >= 3 distinct forces near the centre: centre R^2 not computed")]
    NoCenter,
}

/// Why no calibration could be fitted at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrateError {
    /// Too few usable samples for even the signal-to-force quadratic.
    #[error(
        "calibrate: {usable} usable samples (of {frames} frames{why}); the {signal} force map needs >= 3 with 3 distinct signal values"
    )]
    SignalFit {
        signal: &'static str,
        usable: usize,
        frames: usize,
        /// What the fit noticed on the way (the samples it rejected and why), as `: ...`;
        /// empty when nothing.
        why: String,
    },
    /// A parameter out of range.
    #[error("calibrate: param \"{name}\": {problem}")]
    Param { name: &'static str, problem: &'static str },
}

/// A fitted calibration and the warnings raised on the way.
#[derive(Debug, Clone)]
pub struct Calibrated {
    /// The calibration (its `warnings` hold the same messages as text).
    pub calibration: Calibration,
    /// Warnings as data.
    pub warnings: Vec<CalibWarning>,
}

fn fit_map(signal: &[f64], force: &[f64], shape: FShape) -> Option<SignalMap> {
    let quadratic = shape.fit(signal, force)?;
    let lo = signal.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = signal.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some(SignalMap { quadratic, signal_min: lo, signal_max: hi })
}

fn quad_r2(signal: &[f64], force: &[f64]) -> Option<f64> {
    let q = fit_quadratic(signal, force)?;
    let pred: Vec<f64> = signal.iter().map(|&s| q.at(s)).collect();
    r_squared(force, &pred)
}

fn split_fields(coeffs: &[f64]) -> (QuadField, QuadField) {
    let (mut a, mut b) = ([0.0; NPHI], [0.0; NPHI]);
    a.copy_from_slice(&coeffs[..NPHI]);
    b.copy_from_slice(&coeffs[NPHI..2 * NPHI]);
    (QuadField { coeffs: a }, QuadField { coeffs: b })
}

/// Most (joint fit, CV) passes of the joint f fit.
const JOINT_PASSES: usize = 4;

fn prior_vec(p: usize) -> Vec<f64> {
    let mut v = vec![0.0; p];
    v[0] = 1.0;
    v
}

/// Fits the calibration (see the module doc for the procedure), then estimates how it does at
/// places it was not fitted on ([`TrainingSummary::holdout_rmse_n`]).
pub fn calibrate(
    frames: &[CalibSample],
    params: &CalibParams,
    provenance: Provenance,
) -> Result<Calibrated, CalibrateError> {
    params.validate()?;
    let fit = fit_once(frames, params, provenance.clone())?;
    let mut out = fit.calibrated;
    if !fit.degenerate && params.holdout_folds > 0 {
        match location_holdout(&fit.samples, &fit.loc_of, fit.locations, params, &provenance) {
            Ok((rmse, folds)) => {
                out.calibration.training.holdout_rmse_n = rmse;
                out.calibration.training.holdout_folds = folds;
            }
            Err(reason) => {
                let w = CalibWarning::HoldoutSkipped { reason };
                out.calibration.warnings.push(w.to_string());
                out.warnings.push(w);
            }
        }
    }
    for w in &out.warnings {
        tracing::warn!(target: "skinflow::calibrate", "{w}");
    }
    Ok(out)
}

/// The location-held-out check: the calibration locations are dealt into `params.holdout_folds` folds
/// (fixed seed); for each fold the whole fit is repeated without that fold's locations and
/// every strategy predicts the held-out samples. Returns the RMSE per strategy (N) over all
/// samples and the number of folds, or why no figure is honest: fewer than two locations, or
/// a fold whose fit is degenerate (too few locations or samples left) or failed.
fn location_holdout(
    samples: &[CalibSample],
    loc_of: &[usize],
    locations: usize,
    params: &CalibParams,
    provenance: &Provenance,
) -> Result<(BTreeMap<String, f64>, usize), String> {
    let k = params.holdout_folds.min(locations);
    if k < 2 {
        return Err(format!("{locations} location(s), none to hold out"));
    }
    let fold = fold_of(locations, k);
    let fold_params = CalibParams { average_holds: false, ..params.clone() };
    let mut sse = [0.0; StrategyKind::ALL.len()];
    for f in 0..k {
        let train: Vec<CalibSample> =
            samples.iter().zip(loc_of).filter(|&(_, &l)| fold[l] != f).map(|(s, _)| *s).collect();
        let fold_name = format!("fold {} of {k}", f + 1);
        let fitted = fit_once(&train, &fold_params, provenance.clone()).map_err(|e| format!("{fold_name}: {e}"))?;
        if fitted.degenerate {
            // A fold can also leave its locations on a line, or one force level.
            let shape = fitted.calibrated.warnings.iter().find(|w| {
                matches!(w, CalibWarning::UndeterminedLayout { .. } | CalibWarning::FewForceLevels { levels: 1, .. })
            });
            return Err(match shape {
                Some(w) => format!("{fold_name}: {w}"),
                None => format!(
                    "{fold_name} leaves {} samples at {} locations, too few for the fields",
                    fitted.samples.len(),
                    fitted.locations
                ),
            });
        }
        if let Some(w) = fitted.calibrated.warnings.iter().find(|w| matches!(w, CalibWarning::FitFailed { .. })) {
            return Err(format!("{fold_name}: {w}"));
        }
        let strategies = StrategyKind::ALL.map(|kind| Strategy::new(&fitted.calibrated.calibration, kind));
        for (s, _) in samples.iter().zip(loc_of).filter(|&(_, &l)| fold[l] == f) {
            for (e, strategy) in sse.iter_mut().zip(&strategies) {
                *e += (strategy.estimate(&s.contact(), s.dp_kpa).force_n - s.force_n).powi(2);
            }
        }
    }
    let n = samples.len() as f64;
    let rmse = StrategyKind::ALL.iter().zip(sse).map(|(kind, e)| (kind.name().to_string(), (e / n).sqrt())).collect();
    Ok((rmse, k))
}

/// One fit and what the held-out check needs of it.
struct FitOnce {
    calibrated: Calibrated,
    /// The samples fitted on (after averaging and rejection).
    samples: Vec<CalibSample>,
    /// Location index of every sample.
    loc_of: Vec<usize>,
    /// Distinct locations.
    locations: usize,
    /// The fields kept the prior (too few samples or locations, or a narrow region).
    degenerate: bool,
}

/// The fit itself, without the held-out check or logging.
fn fit_once(frames: &[CalibSample], params: &CalibParams, provenance: Provenance) -> Result<FitOnce, CalibrateError> {
    let mut warnings = Vec::new();
    let holds = if params.average_holds {
        average_holds(frames)
    } else {
        Holds { samples: frames.to_vec(), sd_dp_kpa: 0.0, sd_cond_sum: 0.0, non_finite_frames: 0 }
    };
    if holds.non_finite_frames > 0 {
        warnings.push(CalibWarning::NonFiniteFrames { count: holds.non_finite_frames, total: frames.len() });
    }
    let total = holds.samples.len();
    let ok = |s: &CalibSample| {
        [s.x_mm, s.y_mm, s.true_x_mm, s.true_y_mm, s.force_n, s.dp_kpa, s.cond_sum, s.area_mm2]
            .iter()
            .all(|v| v.is_finite())
            && s.cond_sum > 0.0
            && s.force_n > 0.0
            && (s.x_mm - s.true_x_mm).hypot(s.y_mm - s.true_y_mm) <= params.max_location_error_mm
    };
    let passed: Vec<CalibSample> = holds.samples.iter().copied().filter(ok).collect();
    if passed.len() < total {
        warnings.push(CalibWarning::Rejected {
            count: total - passed.len(),
            total,
            max_error_mm: params.max_location_error_mm,
        });
    }
    // No pressure response (as C <= 0 is no EIT response): such a sample would pull f and the
    // fields towards a force at dP = 0, where every strategy reports 0 N anyway.
    let (responding, silent): (Vec<CalibSample>, Vec<CalibSample>) = passed.into_iter().partition(|s| s.dp_kpa > 0.0);
    if !silent.is_empty() {
        warnings.push(CalibWarning::NonPositivePressure { count: silent.len(), total });
    }
    // Gross pressure spikes, judged per location against its own power law.
    let (_, site_of) = locations(&responding, params.location_tolerance_mm);
    let spike = pressure_outliers(
        &responding.iter().map(|s| s.force_n).collect::<Vec<_>>(),
        &responding.iter().map(|s| s.dp_kpa).collect::<Vec<_>>(),
        &site_of,
    );
    let spikes = spike.iter().filter(|&&o| o).count();
    if spikes > 0 {
        let mut sites: Vec<usize> = site_of.iter().zip(&spike).filter(|(_, o)| **o).map(|(l, _)| *l).collect();
        sites.sort_unstable();
        sites.dedup();
        warnings.push(CalibWarning::PressureSpikes { count: spikes, total, locations: sites.len() });
    }
    let samples: Vec<CalibSample> = responding.iter().zip(&spike).filter(|(_, o)| !**o).map(|(s, _)| *s).collect();
    let t = samples.len();
    let force: Vec<f64> = samples.iter().map(|s| s.force_n).collect();
    let dp: Vec<f64> = samples.iter().map(|s| s.dp_kpa).collect();
    let cond: Vec<f64> = samples.iter().map(|s| s.cond_sum).collect();
    let why = if warnings.is_empty() {
        String::new()
    } else {
        format!(": {}", warnings.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))
    };
    let err = |signal| CalibrateError::SignalFit { signal, usable: t, frames: frames.len(), why: why.clone() };
    if t < 3 {
        return Err(err("pneumatic"));
    }
    let levels = force_levels(&force);
    let shape = FShape::for_levels(levels);
    match shape {
        FShape::Quadratic => {}
        FShape::Line => warnings.push(CalibWarning::FewForceLevels { levels, fallback: "f is fitted as a straight line" }),
        FShape::Proportional => warnings.push(CalibWarning::FewForceLevels {
            levels,
            fallback: "f is a line through the origin, and the location fields fall back to the prior g = 1, b = 0 (one level cannot tell gain from offset)",
        }),
    }
    let map_p = fit_map(&dp, &force, shape).ok_or(err("pneumatic"))?;
    let map_c = fit_map(&cond, &force, shape).ok_or(err("eit"))?;

    // Region and degeneracy.
    let raw = Region::bounding(samples.iter().map(|s| (s.x_mm, s.y_mm)), 0.0).ok_or(err("pneumatic"))?;
    let region =
        Region::bounding(samples.iter().map(|s| (s.x_mm, s.y_mm)), params.min_span_mm).ok_or(err("pneumatic"))?;
    let (locs, loc_of) = locations(&samples, params.location_tolerance_mm);
    let mut degenerate = false;
    if t < params.min_samples {
        warnings.push(CalibWarning::TooFewSamples { samples: t, min: params.min_samples });
        degenerate = true;
    }
    if locs.len() < params.min_locations {
        warnings.push(CalibWarning::TooFewLocations { locations: locs.len(), min: params.min_locations });
        degenerate = true;
    }
    let (sx, sy) = raw.span_mm();
    if sx < params.min_span_mm || sy < params.min_span_mm {
        warnings.push(CalibWarning::NarrowRegion { span_x_mm: sx, span_y_mm: sy, min_mm: params.min_span_mm });
        degenerate = true;
    }
    if shape == FShape::Proportional {
        degenerate = true;
    }
    // Collinear (or otherwise quadric-bound) locations span the box but not the basis; only
    // checked when the counts passed, so one cause is named at a time.
    if !degenerate {
        let mut centre = vec![(0.0, 0.0, 0usize); locs.len()];
        for (s, &l) in samples.iter().zip(&loc_of) {
            let n = region.normalize(s.x_mm, s.y_mm);
            centre[l] = (centre[l].0 + n.u, centre[l].1 + n.v, centre[l].2 + 1);
        }
        let points: Vec<(f64, f64)> = centre.iter().map(|&(u, v, k)| (u / k as f64, v / k as f64)).collect();
        let eigenvalue = layout_eigenvalue(&points).unwrap_or(0.0);
        if eigenvalue.is_nan() || eigenvalue < MIN_LAYOUT_EIGENVALUE {
            warnings.push(CalibWarning::UndeterminedLayout {
                locations: locs.len(),
                eigenvalue,
                min: MIN_LAYOUT_EIGENVALUE,
            });
            degenerate = true;
        }
    }

    // R^2 table: centre = the true location nearest the origin.
    let centre = (0..locs.len()).min_by(|&a, &b| locs[a].0.hypot(locs[a].1).total_cmp(&locs[b].0.hypot(locs[b].1)));
    let at_centre: Vec<usize> = (0..t).filter(|&i| Some(loc_of[i]) == centre).collect();
    let pick = |v: &[f64]| at_centre.iter().map(|&i| v[i]).collect::<Vec<f64>>();
    let r2 = R2Table {
        eit_center: quad_r2(&pick(&cond), &pick(&force)),
        eit_all: quad_r2(&cond, &force),
        pneumatic_center: quad_r2(&pick(&dp), &pick(&force)),
        pneumatic_all: quad_r2(&dp, &force),
    };
    if r2.pneumatic_center.is_none() {
        warnings.push(CalibWarning::NoCenter);
    }

    let grid: Vec<f64> = params.lambda_grid_rel.iter().map(|l| l * t as f64).collect();
    let groups = match params.cv_groups {
        CvGroups::Sample => None,
        CvGroups::Location => Some(&loc_of[..]),
    };
    let search = |blocks| CvSearch { blocks, grid: &grid, folds: params.folds, groups };
    let phis: Vec<[f64; NPHI]> = samples
        .iter()
        .map(|s| {
            let n = region.normalize(s.x_mm, s.y_mm);
            phi(n.u, n.v)
        })
        .collect();
    // g, b by CV-chosen ridge on a fixed f.
    let cv_fields = |map: &SignalMap, signal: &[f64]| {
        let fs: Vec<f64> = signal.iter().map(|&s| map.eval(s).0).collect();
        let d = locaware_design(&phis, &fs, None);
        let prior = prior_vec(2 * NPHI);
        let problem =
            RidgeProblem { design: &d, y: &force, p: 2 * NPHI, prior: &prior, base_penalty: &[0.0; 2 * NPHI] };
        cross_validate(&problem, &search(&[0..NPHI, NPHI..2 * NPHI]))
    };
    let fit_locaware = |map: &SignalMap, signal: &[f64], what: &'static str, warnings: &mut Vec<CalibWarning>| {
        if degenerate {
            return LocAware::prior(*map);
        }
        let Some(sequential) = cv_fields(map, signal) else {
            warnings.push(CalibWarning::FitFailed { what });
            return LocAware::prior(*map);
        };
        let mut cv = sequential.clone();
        let mut f_map = *map;
        let mut f_fit = FFit::Sequential;
        if params.f_fit == FFit::Joint {
            // Alternate at the chosen weights, then choose them again on the new f; the
            // weights settle in one or two passes.
            let mut settled = false;
            for _ in 0..JOINT_PASSES {
                let problem = JointProblem {
                    phi: &phis,
                    signal,
                    force: &force,
                    lambda_g: cv.lambdas[0],
                    lambda_b: cv.lambdas[1],
                    linear: shape == FShape::Line,
                };
                let Some(joint) = fit_joint(&problem, f_map) else {
                    warnings.push(CalibWarning::JointFit { what, problem: "field step not solvable" });
                    settled = true;
                    break;
                };
                if !joint.converged {
                    warnings.push(CalibWarning::JointFit { what, problem: "alternation did not converge" });
                }
                if joint.rounds == 0 {
                    settled = true;
                    break;
                }
                let Some(next) = cv_fields(&joint.map, signal) else {
                    warnings.push(CalibWarning::JointFit { what, problem: "cross-validation on the joint f failed" });
                    settled = true;
                    break;
                };
                settled = next.lambdas == cv.lambdas;
                (f_map, cv, f_fit) = (joint.map, next, FFit::Joint);
                if settled {
                    break;
                }
            }
            if !settled {
                warnings
                    .push(CalibWarning::JointFit { what, problem: "ridge weights still changing after the last pass" });
            }
            // The scale f and g share: mean gain 1, so GAIN_FLOOR is a fraction of it.
            if f_fit == FFit::Joint && normalize_gain(&mut f_map, &mut cv.coeffs[..NPHI], &phis).is_none() {
                warnings.push(CalibWarning::JointGauge { what });
                (f_map, cv, f_fit) = (*map, sequential, FFit::Sequential);
            }
        }
        let (gain, offset) = split_fields(&cv.coeffs);
        LocAware {
            map: f_map,
            f_fit,
            gain,
            offset,
            lambda_g: Some(cv.lambdas[0]),
            lambda_b: Some(cv.lambdas[1]),
            cv_rmse_n: Some(cv.cv_mse.sqrt()),
            prior_fallback: false,
        }
    };
    let pneumatic =
        SignalCalibration { map: map_p, locaware: fit_locaware(&map_p, &dp, "pneumatic fields", &mut warnings) };
    let eit = SignalCalibration { map: map_c, locaware: fit_locaware(&map_c, &cond, "eit fields", &mut warnings) };

    // Area-aware: the pneumatic fields' weights are kept; only the area weight is searched.
    let area_ref_mm2 = samples.iter().map(|s| s.area_mm2).sum::<f64>() / t as f64;
    let rel: Vec<f64> = samples.iter().map(|s| s.area_mm2 / area_ref_mm2 - 1.0).collect();
    let rel_min = rel.iter().copied().fold(f64::INFINITY, f64::min);
    let rel_max = rel.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut area_aware = AreaAware {
        fields: LocAware::prior(pneumatic.locaware.map),
        area_gain: 0.0,
        area_offset: 0.0,
        area_ref_mm2,
        rel_area_min: rel_min,
        rel_area_max: rel_max,
        lambda_a: None,
    };
    if let (false, Some(lg), Some(lb)) = (degenerate, pneumatic.locaware.lambda_g, pneumatic.locaware.lambda_b) {
        let f_map = pneumatic.locaware.map;
        let fs: Vec<f64> = dp.iter().map(|&s| f_map.eval(s).0).collect();
        let d = locaware_design(&phis, &fs, Some(&rel));
        let p = 2 * NPHI + 2;
        let prior = prior_vec(p);
        let mut base = vec![lg; p];
        base[NPHI..2 * NPHI].fill(lb);
        base[2 * NPHI..].fill(0.0);
        let problem = RidgeProblem { design: &d, y: &force, p, prior: &prior, base_penalty: &base };
        match cross_validate(&problem, &search(std::slice::from_ref(&(2 * NPHI..p)))) {
            Some(cv) => {
                let (gain, offset) = split_fields(&cv.coeffs);
                area_aware.fields = LocAware {
                    map: f_map,
                    f_fit: pneumatic.locaware.f_fit,
                    gain,
                    offset,
                    lambda_g: Some(lg),
                    lambda_b: Some(lb),
                    cv_rmse_n: Some(cv.cv_mse.sqrt()),
                    prior_fallback: false,
                };
                area_aware.area_gain = cv.coeffs[2 * NPHI];
                area_aware.area_offset = cv.coeffs[2 * NPHI + 1];
                area_aware.lambda_a = Some(cv.lambdas[0]);
            }
            None => warnings.push(CalibWarning::FitFailed { what: "area-aware fields" }),
        }
    }

    let sens_samples: Vec<SensitivitySample> = samples
        .iter()
        .zip(&loc_of)
        .map(|(s, &site)| SensitivitySample {
            x_mm: s.x_mm,
            y_mm: s.y_mm,
            site,
            cond_sum: s.cond_sum,
            force_n: s.force_n,
        })
        .collect();
    let sensitivity = if degenerate { None } else { SensitivityField::fit(region, &sens_samples) };
    let sensitivity = sensitivity.unwrap_or_else(|| {
        warnings.push(CalibWarning::UniformSensitivity);
        SensitivityField::uniform(region)
    });

    // Forward pneumatic model; degenerate data get a uniform line through the origin.
    let force_max = force.iter().copied().fold(0.0, f64::max);
    let fwd_samples: Vec<ForwardSample> = samples
        .iter()
        .zip(&loc_of)
        .map(|(s, &site)| ForwardSample { x_mm: s.x_mm, y_mm: s.y_mm, site, force_n: s.force_n, dp_kpa: s.dp_kpa })
        .collect();
    let forward = if degenerate { None } else { ForwardModel::fit(region, &fwd_samples) };
    let forward = forward.unwrap_or_else(|| {
        if !degenerate {
            warnings.push(CalibWarning::FitFailed { what: "forward pneumatic model" });
        }
        let ff: f64 = force.iter().map(|f| f * f).sum();
        let slope = force.iter().zip(&dp).map(|(f, p)| f * p).sum::<f64>() / ff;
        ForwardModel::linear(region, if slope > 0.0 { slope } else { 1.0 }, force_max)
    });

    let mut diameters: Vec<f64> = samples.iter().map(|s| s.diameter_mm).filter(|d| d.is_finite()).collect();
    diameters.sort_by(f64::total_cmp);
    diameters.dedup();
    // A flat f reports about one force for any press (a constant f was the joint fit's answer
    // to one 500 kPa hold in the audit); the pooled and the location-aware f of each signal.
    let force_range =
        force.iter().copied().fold(f64::NEG_INFINITY, f64::max) - force.iter().copied().fold(f64::INFINITY, f64::min);
    if levels >= 2 {
        for (what, m, pooled) in [
            ("pneumatic f (pooled)", &pneumatic.map, None),
            ("pneumatic location-aware f", &pneumatic.locaware.map, Some(&pneumatic.map)),
            ("eit f (pooled)", &eit.map, None),
            ("eit location-aware f", &eit.locaware.map, Some(&eit.map)),
        ] {
            let rise = map_rise(m);
            if Some(m) != pooled && (rise.is_nan() || rise < FLAT_MAP_RISE_REL * force_range) {
                warnings.push(CalibWarning::FlatMap { what, rise_n: rise, force_range_n: force_range });
            }
        }
    }

    let training = TrainingSummary {
        frames: frames.len(),
        samples: t,
        rejected: total - t,
        rejected_non_positive_dp: silent.len(),
        rejected_pressure_spikes: spikes,
        force_levels: levels,
        locations: locs.len(),
        force_min_n: force.iter().copied().fold(f64::INFINITY, f64::min),
        force_max_n: force.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        diameters_mm: diameters,
        center_location_mm: centre.map(|c| [locs[c].0, locs[c].1]),
        center_samples: at_centre.len(),
        hold_sd_dp_kpa: holds.sd_dp_kpa,
        hold_sd_cond_sum: holds.sd_cond_sum,
        lambda_grid_rel: params.lambda_grid_rel.clone(),
        folds: params.folds,
        cv_groups: params.cv_groups,
        train_rmse_n: BTreeMap::new(),
        holdout_rmse_n: BTreeMap::new(),
        holdout_folds: 0,
    };
    let mut calibration = Calibration {
        format: FORMAT.to_string(),
        format_version: FORMAT_VERSION,
        provenance,
        region,
        pneumatic,
        eit,
        area_aware,
        forward,
        sensitivity,
        r2,
        training,
        warnings: warnings.iter().map(|w| w.to_string()).collect(),
    };
    for kind in StrategyKind::ALL {
        let strategy = Strategy::new(&calibration, kind);
        let sse: f64 =
            samples.iter().map(|s| (strategy.estimate(&s.contact(), s.dp_kpa).force_n - s.force_n).powi(2)).sum();
        calibration.training.train_rmse_n.insert(kind.name().to_string(), (sse / t as f64).sqrt());
    }
    // The strategies whose fields were cross-validated (the sensitivity-compensated one shares
    // pneumatic-locaware's fields, and on single contacts its estimates).
    for (kind, cv_rmse) in [
        (StrategyKind::EitLocAware, calibration.eit.locaware.cv_rmse_n),
        (StrategyKind::PneumaticLocAware, calibration.pneumatic.locaware.cv_rmse_n),
        (StrategyKind::PneumaticAreaAware, calibration.area_aware.fields.cv_rmse_n),
    ] {
        let (Some(cv), Some(&train)) = (cv_rmse, calibration.training.train_rmse_n.get(kind.name())) else { continue };
        if train.is_nan() || train > TRAIN_CV_RATIO * cv + TRAIN_CV_SLACK_N {
            let w = CalibWarning::TrainAboveCv { strategy: kind.name(), train_rmse_n: train, cv_rmse_n: cv };
            calibration.warnings.push(w.to_string());
            warnings.push(w);
        }
    }
    let locations = locs.len();
    Ok(FitOnce { calibrated: Calibrated { calibration, warnings }, samples, loc_of, locations, degenerate })
}
