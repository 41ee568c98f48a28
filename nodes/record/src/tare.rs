//! The leading no-load period (CONTRACTS.md section 2): the time before the first truth row
//! that has a contact; without truth (or with an empty one), the first `tare_s` seconds of the
//! recording. EIT frames and pressure samples with t < `end_s` are the no-load reference.

use std::ops::Range;

use crate::read::Recording;

/// Default length of the no-load period of a recording without truth, in seconds.
pub const DEFAULT_TARE_S: f64 = 2.0;

/// How the end of the no-load period was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoLoadSource {
    /// Time of the first truth row with a contact.
    Truth,
    /// The truth never has a contact: the whole recording is no-load (`end_s` is +inf).
    TruthWithoutContact,
    /// No truth: the recording's first time plus `tare_s`.
    TareSeconds,
}

/// The no-load period: times t < `end_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoLoad {
    pub end_s: f64,
    pub source: NoLoadSource,
}

impl Recording {
    /// The leading no-load period; `tare_s` is used only without truth (see `DEFAULT_TARE_S`).
    pub fn no_load(&self, tare_s: f64) -> NoLoad {
        if let Some(truth) = self.truth.as_ref().filter(|t| !t.is_empty()) {
            return match (0..truth.len()).find(|&i| truth.row(i).contact_count() > 0) {
                Some(i) => NoLoad { end_s: truth.t_s[i], source: NoLoadSource::Truth },
                None => NoLoad { end_s: f64::INFINITY, source: NoLoadSource::TruthWithoutContact },
            };
        }
        let firsts = [self.eit.as_ref().map(|s| &s.t_s), self.pressure.as_ref().map(|s| &s.t_s)];
        let start = firsts.into_iter().flatten().filter_map(|t| t.first().copied()).fold(f64::INFINITY, f64::min);
        let start = if start.is_finite() { start } else { 0.0 };
        NoLoad { end_s: start + tare_s, source: NoLoadSource::TareSeconds }
    }

    /// Indices of the EIT frames in the no-load period (a leading range; times assumed sorted).
    pub fn no_load_eit_frames(&self, tare_s: f64) -> Range<usize> {
        let end = self.no_load(tare_s).end_s;
        0..self.eit.as_ref().map_or(0, |s| s.t_s.partition_point(|&t| t < end))
    }

    /// Indices of the pressure samples in the no-load period.
    pub fn no_load_pressure_samples(&self, tare_s: f64) -> Range<usize> {
        let end = self.no_load(tare_s).end_s;
        0..self.pressure.as_ref().map_or(0, |s| s.t_s.partition_point(|&t| t < end))
    }
}
