//! Force strategies: signal choice x correction (paper §IV-A, plus two extensions).
//!
//! A [`Strategy`] is resolved once from a [`Calibration`] and then maps one contact and its
//! pressure share to a [`ForceEstimate`] without allocating. Pneumatic strategies use the
//! share dP_i (kPa), EIT ones the conductivity sum C_i. Guards: a signal <= 0 (no load, or
//! drift below the tare) gives exactly 0 N; signals outside the calibrated range extrapolate
//! monotonically (see [`super::map`]) and are flagged; a centroid outside the calibrated
//! region is clamped onto it and flagged; the gain is floored at [`GAIN_FLOOR`] so force
//! never decreases with the signal; a negative result is clamped to 0 N and flagged.

use super::calibration::Calibration;
use super::field::{QuadField, Region};
use super::forward::ForwardModel;
use super::map::{Range, SignalMap};
use crate::segment::Contact;
use crate::split::Splitter;

/// Smallest gain used, so F stays non-decreasing in the signal even where a fitted field dips.
/// Absolute, so it relies on the gain's scale: the ridge prior pulls g towards 1, and the
/// calibration fixes the scale the joint f fit leaves free so that g averages 1 over the
/// calibration samples ([`super::joint::normalize_gain`]). The floor is then 5 % of the mean
/// gain.
pub const GAIN_FLOOR: f64 = 0.05;

/// The strategies, in report order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum StrategyKind {
    /// f_C(C_i).
    EitNoCal,
    /// f_P(dP_i), proportional split.
    PneumaticNoCal,
    /// g_C f_C(C_i) + b_C.
    EitLocAware,
    /// g_P f_P(dP_i) + b_P, proportional split (the paper's proposal).
    PneumaticLocAware,
    /// As PneumaticLocAware, with the sensitivity-compensated split.
    PneumaticLocAwareSensitivity,
    /// Location- and contact-area-aware pneumatic model (the paper's future work).
    PneumaticAreaAware,
    /// Inverse of the forward pneumatic model P(F, x, y), proportional split.
    PneumaticForward,
    /// As PneumaticForward, with the force-balance split (sensitivity-compensated ratios).
    PneumaticForwardBalance,
}

impl StrategyKind {
    /// Every strategy, paper's four first.
    pub const ALL: [StrategyKind; 8] = [
        StrategyKind::EitNoCal,
        StrategyKind::PneumaticNoCal,
        StrategyKind::EitLocAware,
        StrategyKind::PneumaticLocAware,
        StrategyKind::PneumaticLocAwareSensitivity,
        StrategyKind::PneumaticAreaAware,
        StrategyKind::PneumaticForward,
        StrategyKind::PneumaticForwardBalance,
    ];

    /// Key used in the eval JSON and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            StrategyKind::EitNoCal => "eit-nocal",
            StrategyKind::PneumaticNoCal => "pneumatic-nocal",
            StrategyKind::EitLocAware => "eit-locaware",
            StrategyKind::PneumaticLocAware => "pneumatic-locaware",
            StrategyKind::PneumaticLocAwareSensitivity => "pneumatic-locaware-sensitivity",
            StrategyKind::PneumaticAreaAware => "pneumatic-area-aware",
            StrategyKind::PneumaticForward => "pneumatic-forward",
            StrategyKind::PneumaticForwardBalance => "pneumatic-forward-balance",
        }
    }

    /// Label used in printed tables (the paper's spelling).
    pub fn label(self) -> &'static str {
        match self {
            StrategyKind::EitNoCal => "EIT-NoCal",
            StrategyKind::PneumaticNoCal => "Pneumatic-NoCal",
            StrategyKind::EitLocAware => "EIT-LocAware",
            StrategyKind::PneumaticLocAware => "Pneumatic-LocAware (proposed)",
            StrategyKind::PneumaticLocAwareSensitivity => "Pneumatic-LocAware, sens.-comp. split",
            StrategyKind::PneumaticAreaAware => "Pneumatic-AreaAware",
            StrategyKind::PneumaticForward => "Pneumatic-Forward",
            StrategyKind::PneumaticForwardBalance => "Pneumatic-Forward, force-balance split",
        }
    }

    /// Parses [`StrategyKind::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// True for the strategies whose signal is the pneumatic share.
    pub fn is_pneumatic(self) -> bool {
        !matches!(self, StrategyKind::EitNoCal | StrategyKind::EitLocAware)
    }
}

/// Guard flags of one estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ForceFlags {
    /// Signal <= 0 (or not finite): force set to 0 N.
    pub no_load: bool,
    /// The contact's pressure share is unknown (not finite: no pressure sample in the frame's
    /// acquisition window, or no no-load offset P0 yet), so a pneumatic strategy has no force
    /// to give. The force is a 0 N placeholder, not a measurement of no load: this is set
    /// instead of `no_load`, and evaluations leave such forces out.
    pub no_pressure: bool,
    /// Signal above the calibrated range (monotone linear extrapolation).
    pub above_range: bool,
    /// Signal below the calibrated range (monotone linear extrapolation).
    pub below_range: bool,
    /// Centroid outside the calibrated region, clamped onto it.
    pub location_clamped: bool,
    /// Contact area outside the calibrated range, clamped (area-aware only).
    pub area_clamped: bool,
    /// The model gave a negative force, clamped to 0 N.
    pub negative_clamped: bool,
    /// The frame had more contact regions than the segmenter reports (`max_contacts`): the
    /// pressure change was shared over the reported contacts only, so a pneumatic strategy's
    /// forces also carry the unreported regions' part (biased high). Set by the corrector node
    /// from the frame, not by [`Strategy::estimate`]; EIT strategies are not affected.
    pub contacts_dropped: bool,
}

/// Force of one contact.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ForceEstimate {
    /// Estimated normal force, N (>= 0, finite).
    pub force_n: f64,
    /// The pressure share used, kPa (pneumatic strategies; the frame's share otherwise).
    pub dp_kpa: f64,
    /// What the guards did.
    pub flags: ForceFlags,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct AreaTerms {
    gain: f64,
    offset: f64,
    area_ref_mm2: f64,
    rel_min: f64,
    rel_max: f64,
}

/// A resolved strategy: everything `estimate` needs, copied out of the calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Strategy {
    kind: StrategyKind,
    map: SignalMap,
    fields: Option<(QuadField, QuadField)>,
    area: Option<AreaTerms>,
    /// The forward model, for the `pneumatic-forward` strategies.
    forward: Option<ForwardModel>,
    region: Region,
    splitter: Splitter,
}

impl Strategy {
    /// Resolves `kind` from a calibration.
    pub fn new(cal: &Calibration, kind: StrategyKind) -> Self {
        let (sig, locaware) = match kind {
            StrategyKind::EitNoCal => (&cal.eit, false),
            StrategyKind::EitLocAware => (&cal.eit, true),
            StrategyKind::PneumaticNoCal => (&cal.pneumatic, false),
            _ => (&cal.pneumatic, true),
        };
        // NoCal uses the pooled f; location-aware strategies the f fitted with their fields.
        let mut map = if locaware { sig.locaware.map } else { sig.map };
        let mut fields = locaware.then_some((sig.locaware.gain, sig.locaware.offset));
        let mut area = None;
        if kind == StrategyKind::PneumaticAreaAware {
            let a = &cal.area_aware;
            map = a.fields.map;
            fields = Some((a.fields.gain, a.fields.offset));
            area = Some(AreaTerms {
                gain: a.area_gain,
                offset: a.area_offset,
                area_ref_mm2: a.area_ref_mm2,
                rel_min: a.rel_area_min,
                rel_max: a.rel_area_max,
            });
        }
        let forward = matches!(kind, StrategyKind::PneumaticForward | StrategyKind::PneumaticForwardBalance)
            .then(|| cal.forward.clone());
        if forward.is_some() {
            fields = None;
        }
        let splitter = match kind {
            StrategyKind::PneumaticLocAwareSensitivity => Splitter::SensitivityCompensated(cal.sensitivity.clone()),
            StrategyKind::PneumaticForwardBalance => {
                Splitter::ForceBalance { sensitivity: cal.sensitivity.clone(), forward: cal.forward.clone() }
            }
            _ => Splitter::Proportional,
        };
        Self { kind, map, fields, area, forward, region: cal.region, splitter }
    }

    /// Every strategy of a calibration, in [`StrategyKind::ALL`] order.
    pub fn all(cal: &Calibration) -> Vec<Strategy> {
        StrategyKind::ALL.iter().map(|&k| Strategy::new(cal, k)).collect()
    }

    /// Which strategy this is.
    pub fn kind(&self) -> StrategyKind {
        self.kind
    }

    /// The calibration's signal-to-force map this strategy applies, by its key in the file
    /// (as [`Calibration::flat_maps`] names it), when that map does not rise over its
    /// calibrated range: every contact then gets the same force. `None` when it rises, and for
    /// the forward strategies, which apply the forward model instead.
    pub fn flat_map(&self) -> Option<&'static str> {
        if self.forward.is_some() || self.map.rises() {
            return None;
        }
        Some(match self.kind {
            StrategyKind::EitNoCal => "eit.map",
            StrategyKind::EitLocAware => "eit.locaware.map",
            StrategyKind::PneumaticNoCal => "pneumatic.map",
            StrategyKind::PneumaticAreaAware => "area_aware.fields.map",
            _ => "pneumatic.locaware.map",
        })
    }

    /// The splitter this strategy shares dP with.
    pub fn splitter(&self) -> &Splitter {
        &self.splitter
    }

    /// Force of one contact given its pressure share `dp_i_kpa` (ignored by EIT strategies).
    /// A share <= 0 gives 0 N flagged `no_load`; a share that is not finite (the frame's
    /// pressure change is unknown) gives a 0 N placeholder flagged `no_pressure`.
    pub fn estimate(&self, contact: &Contact, dp_i_kpa: f64) -> ForceEstimate {
        let mut flags = ForceFlags::default();
        let signal = if self.kind.is_pneumatic() { dp_i_kpa } else { contact.sum };
        if self.kind.is_pneumatic() && !dp_i_kpa.is_finite() {
            flags.no_pressure = true;
            return ForceEstimate { force_n: 0.0, dp_kpa: dp_i_kpa, flags };
        }
        if !(signal > 0.0 && signal.is_finite()) {
            flags.no_load = true;
            return ForceEstimate { force_n: 0.0, dp_kpa: dp_i_kpa, flags };
        }
        if let Some(fwd) = &self.forward {
            let (response, clamped) = fwd.at(contact.x_mm, contact.y_mm);
            let (force, beyond) = response.force(signal);
            flags.location_clamped = clamped;
            flags.above_range = beyond;
            return ForceEstimate { force_n: force, dp_kpa: dp_i_kpa, flags };
        }
        let (f, range) = self.map.eval(signal);
        flags.above_range = range == Range::Above;
        flags.below_range = range == Range::Below;
        let mut force = f;
        if let Some((gain, offset)) = &self.fields {
            let n = self.region.normalize(contact.x_mm, contact.y_mm);
            flags.location_clamped = n.clamped;
            let mut g = gain.at(n.u, n.v);
            let mut b = offset.at(n.u, n.v);
            if let Some(a) = &self.area {
                let rel = contact.area_mm2 / a.area_ref_mm2 - 1.0;
                let rel_c = if rel.is_finite() { rel.clamp(a.rel_min, a.rel_max) } else { 0.0 };
                flags.area_clamped = rel_c != rel;
                g += a.gain * rel_c;
                b += a.offset * rel_c;
            }
            force = g.max(GAIN_FLOOR) * f + b;
        }
        if force.is_nan() || force < 0.0 {
            flags.negative_clamped = true;
            force = 0.0;
        }
        ForceEstimate { force_n: force, dp_kpa: dp_i_kpa, flags }
    }

    /// Splits `dp_kpa` with this strategy's splitter and estimates every contact into
    /// `out[..contacts.len()]`. No allocation.
    pub fn estimate_frame_into(&self, dp_kpa: f64, contacts: &[Contact], out: &mut [ForceEstimate]) {
        self.splitter.split_with(dp_kpa, contacts, |i, share| {
            if let Some(o) = out.get_mut(i) {
                *o = self.estimate(&contacts[i], share);
            }
        });
    }
}
