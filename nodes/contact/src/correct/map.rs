//! The signal-to-force map f(s) (paper eq. 11) with guards that keep it monotone.
//!
//! The signal `s` is the pneumatic share dP_i (kPa) or the conductivity sum C_i (image units).
//! Inside the calibrated signal range [lo, hi] the map is the running maximum of the fitted
//! quadratic (so it never turns down, even if the fit bends over); beyond `hi` it continues
//! linearly with the end slope (>= 0), below `lo` likewise with the start slope; both are
//! reported as extrapolation. Non-positive signals are the caller's no-load case.

use super::fit::Quadratic;
use serde::{Deserialize, Serialize};

/// A fitted quadratic plus the signal range it was fitted on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SignalMap {
    /// f(s) = a0 + a1 s + a2 s^2, force in N.
    pub quadratic: Quadratic,
    /// Smallest calibration signal.
    pub signal_min: f64,
    /// Largest calibration signal.
    pub signal_max: f64,
}

/// Where a signal fell relative to the calibrated range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Range {
    /// Inside [signal_min, signal_max].
    Inside,
    /// Below signal_min (linear continuation).
    Below,
    /// Above signal_max (linear continuation).
    Above,
}

impl SignalMap {
    /// Monotone envelope inside the range: max over [lo, s] of the quadratic, evaluated in
    /// closed form (the quadratic has at most one turning point).
    fn inside(&self, s: f64) -> f64 {
        let q = &self.quadratic;
        let lo = self.signal_min;
        let vertex = if q.a2 != 0.0 { -q.a1 / (2.0 * q.a2) } else { f64::INFINITY };
        // Concave with its top before s: the running max is the top (or lo if the top is left of lo).
        let s_eff = if q.a2 < 0.0 && vertex < s { vertex.max(lo) } else { s };
        // Convex with its bottom after lo: values dip below f(lo) and the running max holds f(lo).
        q.at(s_eff).max(q.at(lo))
    }

    /// Slope of the envelope at `s` inside the range, never negative.
    fn inside_slope(&self, s: f64) -> f64 {
        let q = &self.quadratic;
        if self.inside(s) > q.at(s) { 0.0 } else { q.slope(s).max(0.0) }
    }

    /// Whether the force rises over the calibrated range (`f(signal_max) > f(signal_min)`; a
    /// range of one signal counts as rising): a map that stays flat or falls gives every
    /// contact the same force (0 N once it clamps).
    pub fn rises(&self) -> bool {
        self.signal_max <= self.signal_min || self.inside(self.signal_max) > self.inside(self.signal_min)
    }

    /// Force for signal `s` and whether it was extrapolated.
    pub fn eval(&self, s: f64) -> (f64, Range) {
        let (lo, hi) = (self.signal_min, self.signal_max);
        if s > hi {
            (self.inside(hi) + self.inside_slope(hi) * (s - hi), Range::Above)
        } else if s < lo {
            (self.inside(lo) + self.inside_slope(lo) * (s - lo), Range::Below)
        } else {
            (self.inside(s), Range::Inside)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(a0: f64, a1: f64, a2: f64) -> SignalMap {
        SignalMap { quadratic: Quadratic { a0, a1, a2 }, signal_min: 1.0, signal_max: 3.0 }
    }

    /// The audit's maps: falling (a1 < 0) and flat (a1 = a2 = 0) do not rise; fitted shapes,
    /// a bent-over concave one included, and a one-signal range do.
    #[test]
    fn a_map_that_stays_flat_or_falls_does_not_rise() {
        assert!(!map(0.0, -6.87, 0.0).rises());
        assert!(!map(2.0, 0.0, 0.0).rises());
        assert!(map(0.0, 1.0, 0.0).rises() && map(0.0, 2.0, -0.4).rises() && map(-1.0, 0.5, 0.2).rises());
        let single = SignalMap { signal_min: 2.0, signal_max: 2.0, ..map(2.0, 0.0, 0.0) };
        assert!(single.rises());
    }

    fn assert_monotone(m: &SignalMap) {
        let mut prev = f64::NEG_INFINITY;
        for i in 0..=600 {
            let (f, _) = m.eval(0.01 * i as f64);
            assert!(f >= prev - 1e-12, "not monotone at s = {}: {f} < {prev}", 0.01 * i as f64);
            prev = f;
        }
    }

    #[test]
    fn inside_the_range_the_fit_is_used() {
        let m = map(0.5, 2.0, 0.1);
        assert_eq!(m.eval(2.0), (0.5 + 4.0 + 0.4, Range::Inside));
        assert_monotone(&m);
    }

    #[test]
    fn beyond_the_range_continues_with_the_end_slope() {
        let m = map(0.0, 1.0, 0.25);
        // f(3) = 3 + 2.25 = 5.25, f'(3) = 1 + 1.5 = 2.5
        let (f, r) = m.eval(4.0);
        assert_eq!(r, Range::Above);
        assert!((f - (5.25 + 2.5)).abs() < 1e-12);
        // f(1) = 1.25, f'(1) = 1.5
        let (f, r) = m.eval(0.5);
        assert_eq!(r, Range::Below);
        assert!((f - (1.25 - 0.75)).abs() < 1e-12);
    }

    #[test]
    fn a_fit_that_bends_over_is_flattened_never_turning_down() {
        // Concave with its top at s = 2 inside [1, 3]: flat after 2 and beyond 3.
        let m = map(0.0, 4.0, -1.0);
        assert_eq!(m.eval(2.5).0, 4.0);
        assert_eq!(m.eval(10.0).0, 4.0);
        assert_monotone(&m);
        // Convex with its bottom at s = 2: holds f(1) until the curve climbs back.
        let m = map(5.0, -4.0, 1.0);
        assert_eq!(m.eval(2.0).0, 2.0);
        assert_monotone(&m);
        // Decreasing everywhere: constant.
        assert_monotone(&map(5.0, -1.0, 0.0));
    }
}
