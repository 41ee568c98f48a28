//! The board's record period as its own clock measures it: the median of the last few
//! per-record device-time steps, so a lost record or a late one does not move it.
//!
//! Used to check the period params (`frame_period_s`, `period_ms`) against the board, and to
//! estimate how many records a device restart hid. Allocation-free and `Copy`.

/// Steps kept; the median of up to this many.
const KEPT: usize = 9;

/// Steps needed before the median is reported: a few, so one odd step cannot decide it.
pub const MIN_STEPS: usize = 5;

/// The last [`KEPT`] per-record device-time steps, s.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PeriodMedian {
    steps: [f64; KEPT],
    len: usize,
    next: usize,
}

impl PeriodMedian {
    /// Notes one step of `step_s` seconds per record (ignored unless finite and positive).
    pub fn push(&mut self, step_s: f64) {
        if !(step_s.is_finite() && step_s > 0.0) {
            return;
        }
        self.steps[self.next] = step_s;
        self.next = (self.next + 1) % KEPT;
        self.len = (self.len + 1).min(KEPT);
    }

    /// The median step, s, once at least [`MIN_STEPS`] were noted.
    #[must_use]
    pub fn median_s(&self) -> Option<f64> {
        (self.len >= MIN_STEPS).then(|| {
            let mut s = self.steps;
            let s = &mut s[..self.len];
            s.sort_unstable_by(f64::total_cmp);
            let mid = self.len / 2;
            if self.len % 2 == 1 { s[mid] } else { 0.5 * (s[mid - 1] + s[mid]) }
        })
    }

    /// Whether every kept step is within `tolerance` (relative) of the median: the steps are
    /// consistent, not a mix of normal periods and occasional gaps.
    #[must_use]
    pub fn consistent(&self, tolerance: f64) -> bool {
        self.median_s().is_some_and(|m| self.steps[..self.len].iter().all(|s| (s - m).abs() <= tolerance * m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_ignores_odd_steps_and_waits_for_a_few() {
        let mut p = PeriodMedian::default();
        for s in [0.1, 0.1, 0.3, 0.1] {
            p.push(s);
        }
        assert_eq!(p.median_s(), None, "4 steps are not enough");
        p.push(0.1);
        assert_eq!(p.median_s(), Some(0.1));
        assert!(!p.consistent(0.1), "0.3 is a gap among 0.1 s periods");
        p.push(f64::NAN);
        p.push(-1.0);
        assert_eq!(p.median_s(), Some(0.1), "invalid steps are ignored");
        // The oldest steps fall out: nine steps of 1 s replace them all.
        for _ in 0..9 {
            p.push(1.0);
        }
        assert_eq!(p.median_s(), Some(1.0));
        assert!(p.consistent(0.01));
    }
}
