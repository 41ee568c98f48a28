//! The no-load reference frame for time-difference imaging, and where it came from.
//!
//! Precedence: a recorded `/eit/reference` (`from_reference`) or an explicit `tare` replaces
//! whatever was there; otherwise the mean of the first `n` frames (`accumulate`), or of fewer
//! if the no-load period ends first (`finish`). The mean is taken per channel over that
//! channel's finite values, so one dead channel (NaN in every frame) does not hold the
//! reference back: it forms from the other channels, and the dead one is left non-finite there
//! for the channel mask to exclude (`mask::detect_into` checks the reference too). With the
//! mask's thresholds given ([`ReferenceTracker::with_mask`]), a value the mask calls bad in its
//! frame (at the rail, or at 0 V: an electrode dead for a moment of the no-load period) is left
//! out of its channel's mean the same way: averaged in, one rail frame of six would pull the
//! channel to a value the mask accepts, and every later frame would image the difference. Only
//! a frame with no usable value at all is not averaged (counted in `skipped`). Allocation
//! happens at construction only.

use crate::error::EitError;
use crate::mask::{MaskParams, usable, zero_floor};

/// Where the current reference came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReferenceSource {
    /// No reference yet (still accumulating).
    None,
    /// The recording's `/eit/reference`.
    Recorded,
    /// Mean of the first `frames` no-load frames.
    MeanOfFirst { frames: usize },
    /// A `tare` control message: the frame it named.
    Tare,
}

/// Tracks the reference frame (M values, volts).
#[derive(Debug, Clone)]
pub struct ReferenceTracker {
    /// The reference once set; before that, the running per-channel mean.
    reference: Vec<f64>,
    sum: Vec<f64>,
    /// Finite values summed per channel.
    count: Vec<u32>,
    wanted: usize,
    seen: usize,
    /// Frames not averaged because they held no finite value.
    pub skipped: usize,
    /// Frames averaged with some channels left out (non-finite or, with the mask's
    /// thresholds, bad there).
    pub partial: usize,
    source: ReferenceSource,
    /// The mask's thresholds: values bad by them are left out of the mean (none: only
    /// non-finite ones are).
    mask: Option<MaskParams>,
    /// For the zero floor's median (M values).
    scratch: Vec<f64>,
}

impl ReferenceTracker {
    /// A tracker for M channels that averages the first `n` frames (n >= 1).
    pub fn new(m: usize, n: usize) -> Result<ReferenceTracker, EitError> {
        if n == 0 {
            return Err(crate::error::invalid("reference_frames", "must be >= 1 (got 0)"));
        }
        Ok(ReferenceTracker {
            reference: vec![f64::NAN; m],
            sum: vec![0.0; m],
            count: vec![0; m],
            wanted: n,
            seen: 0,
            skipped: 0,
            partial: 0,
            source: ReferenceSource::None,
            mask: None,
            scratch: Vec::new(),
        })
    }

    /// Leaves out of the mean, per frame and channel, the values the channel mask with these
    /// thresholds calls bad in that frame (non-finite, at or beyond `saturation_v`, at or
    /// below its zero floor), not only the non-finite ones.
    #[must_use]
    pub fn with_mask(mut self, params: &MaskParams) -> ReferenceTracker {
        self.scratch = vec![0.0; self.reference.len()];
        self.mask = Some(params.clone());
        self
    }

    /// A tracker whose reference is a recorded frame.
    pub fn from_reference(v: &[f64]) -> ReferenceTracker {
        ReferenceTracker {
            reference: v.to_vec(),
            sum: vec![0.0; v.len()],
            count: vec![0; v.len()],
            wanted: 1,
            seen: 0,
            skipped: 0,
            partial: 0,
            source: ReferenceSource::Recorded,
            mask: None,
            scratch: Vec::new(),
        }
    }

    fn check(&self, frame: &[f64]) -> Result<(), EitError> {
        if frame.len() != self.reference.len() {
            return Err(EitError::Length { what: "frame", expected: self.reference.len(), got: frame.len() });
        }
        Ok(())
    }

    /// Feeds a frame: while no reference is set, adds its finite values to the per-channel
    /// mean of the first N. Returns whether a reference is available after this frame.
    pub fn accumulate(&mut self, frame: &[f64]) -> Result<bool, EitError> {
        self.check(frame)?;
        if self.source != ReferenceSource::None {
            return Ok(true);
        }
        let floor = self.mask.as_ref().map(|p| zero_floor(frame, p, &mut self.scratch));
        let usable = |v: f64| match (&self.mask, floor) {
            (Some(p), Some(floor)) => usable(v, p, floor),
            _ => v.is_finite(),
        };
        if !frame.iter().any(|&v| usable(v)) {
            self.skipped += 1;
            return Ok(false);
        }
        let mut left_out = false;
        for (((s, c), r), &v) in self.sum.iter_mut().zip(&mut self.count).zip(&mut self.reference).zip(frame) {
            if usable(v) {
                *s += v;
                *c += 1;
                *r = *s / f64::from(*c);
            } else {
                left_out = true;
            }
        }
        self.partial += usize::from(left_out);
        self.seen += 1;
        if self.seen == self.wanted {
            self.source = ReferenceSource::MeanOfFirst { frames: self.seen };
        }
        Ok(self.source != ReferenceSource::None)
    }

    /// Completes the reference with the frames averaged so far, when fewer than N no-load
    /// frames exist (the no-load period ended early). Returns whether a reference is set.
    pub fn finish(&mut self) -> bool {
        if self.source == ReferenceSource::None && self.seen > 0 {
            self.source = ReferenceSource::MeanOfFirst { frames: self.seen };
        }
        self.source != ReferenceSource::None
    }

    /// Frames the mean is to have (`reference_frames`).
    pub fn wanted(&self) -> usize {
        self.wanted
    }

    /// Changes the number of frames to average (a replacement node's `reference_frames`,
    /// n >= 1, 0 is taken as 1). A reference already set stays; while accumulating, one that
    /// has now seen at least `n` frames completes at once with the frames seen (their sum is
    /// all it keeps, so it cannot go back to only the first `n`). Returns whether a reference
    /// is set.
    pub fn set_wanted(&mut self, n: usize) -> bool {
        self.wanted = n.max(1);
        if self.source == ReferenceSource::None && self.seen >= self.wanted {
            self.finish();
        }
        self.source != ReferenceSource::None
    }

    /// Makes `frame` the reference (a `tare` message). A frame without one finite channel (a
    /// dead board) is refused and the reference stays as it was: every frame would be masked
    /// whole against it, even once the board recovers.
    pub fn tare(&mut self, frame: &[f64]) -> Result<(), EitError> {
        self.check(frame)?;
        if !frame.iter().any(|v| v.is_finite()) {
            return Err(EitError::NoFiniteReference);
        }
        self.reference.copy_from_slice(frame);
        self.source = ReferenceSource::Tare;
        Ok(())
    }

    /// The reference, once available. A channel with no finite value in it is NaN.
    pub fn reference(&self) -> Option<&[f64]> {
        (self.source != ReferenceSource::None).then_some(&self.reference[..])
    }

    /// While the reference is still accumulating, the per-channel mean of the frames so far,
    /// once there are at least two (a frame differenced against itself images nothing). A
    /// channel with no finite value yet is NaN.
    pub fn running_mean(&self) -> Option<&[f64]> {
        (self.source == ReferenceSource::None && self.seen > 1).then_some(&self.reference[..])
    }

    /// Channels of the reference (or of the running mean) with no finite value.
    pub fn missing_channels(&self) -> usize {
        self.reference.iter().filter(|v| !v.is_finite()).count()
    }

    pub fn source(&self) -> ReferenceSource {
        self.source
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_of_first_n_then_tare_overrides() {
        let mut r = ReferenceTracker::new(2, 2).unwrap();
        assert!(!r.accumulate(&[1.0, 2.0]).unwrap());
        assert!(!r.accumulate(&[f64::NAN, f64::INFINITY]).unwrap());
        assert_eq!((r.reference(), r.running_mean()), (None, None));
        assert!(r.accumulate(&[3.0, 4.0]).unwrap());
        assert_eq!(r.reference(), Some(&[2.0, 3.0][..]));
        assert_eq!(r.source(), ReferenceSource::MeanOfFirst { frames: 2 });
        assert_eq!((r.skipped, r.partial, r.missing_channels()), (1, 0, 0));
        // Later frames do not move it.
        r.accumulate(&[9.0, 9.0]).unwrap();
        assert_eq!(r.reference(), Some(&[2.0, 3.0][..]));
        r.tare(&[5.0, 6.0]).unwrap();
        assert_eq!((r.reference(), r.source()), (Some(&[5.0, 6.0][..]), ReferenceSource::Tare));
        assert!(r.tare(&[1.0]).is_err());
        // A frame of a dead board is no reference: refused, the reference kept; one finite
        // channel is enough (the rest are masked against it).
        let e = r.tare(&[f64::NAN, f64::NEG_INFINITY]).unwrap_err();
        assert_eq!(e.to_string(), "frame has no finite channel: it cannot be the reference");
        assert_eq!((r.reference(), r.source()), (Some(&[5.0, 6.0][..]), ReferenceSource::Tare));
        r.tare(&[f64::NAN, 7.0]).unwrap();
        assert_eq!(r.missing_channels(), 1);
    }

    #[test]
    fn a_channel_dead_in_every_frame_does_not_hold_the_reference_back() {
        let mut r = ReferenceTracker::new(3, 3).unwrap();
        assert!(!r.accumulate(&[1.0, f64::NAN, 2.0]).unwrap());
        assert_eq!(r.running_mean(), None);
        // Channel 2 drops out once: its mean is over its two finite values.
        assert!(!r.accumulate(&[3.0, f64::NAN, f64::NAN]).unwrap());
        let m = r.running_mean().unwrap();
        assert_eq!((m[0], m[2]), (2.0, 2.0));
        assert!(m[1].is_nan());
        assert!(r.accumulate(&[5.0, f64::NEG_INFINITY, 8.0]).unwrap());
        let v = r.reference().unwrap();
        assert_eq!((v[0], v[2]), (3.0, 5.0));
        assert!(v[1].is_nan(), "no finite value: left for the mask");
        assert_eq!(
            (r.source(), r.skipped, r.partial, r.missing_channels()),
            (ReferenceSource::MeanOfFirst { frames: 3 }, 0, 3, 1)
        );
        assert_eq!(r.running_mean(), None, "complete: the running mean is no longer offered");
    }

    /// The reviewer's case: an electrode reading its rail (or 0 V) in one of six no-load
    /// frames. Averaged in, its channels came out near 0.9 V, under the 2 V rail the mask
    /// checks, so they were never masked and imaged a -75 % change once it recovered. With the
    /// mask's thresholds those values are left out, as NaN ones are.
    #[test]
    fn values_the_mask_calls_bad_are_left_out_of_the_mean() {
        let params = MaskParams::default();
        for bad in [5.0, 0.0, -5.0] {
            let mut r = ReferenceTracker::new(4, 6).unwrap().with_mask(&params);
            let mut plain = ReferenceTracker::new(4, 6).unwrap();
            for k in 0..6 {
                let frame = [0.3, if k == 0 { bad } else { 0.31 }, 0.2, 0.25];
                r.accumulate(&frame).unwrap();
                plain.accumulate(&frame).unwrap();
            }
            let v = r.reference().unwrap();
            assert!((v[1] - 0.31).abs() < 1e-12, "rail {bad}: {v:?}");
            assert_eq!((r.partial, r.skipped), (1, 0));
            let p = plain.reference().unwrap()[1];
            assert!((p - (bad + 5.0 * 0.31) / 6.0).abs() < 1e-12, "without the thresholds it is averaged in: {p}");
        }
        // A frame with no usable value is skipped whole.
        let mut r = ReferenceTracker::new(2, 2).unwrap().with_mask(&params);
        assert!(!r.accumulate(&[5.0, 0.0]).unwrap());
        assert_eq!(r.skipped, 1);
    }

    #[test]
    fn finish_takes_the_mean_of_the_frames_so_far() {
        let mut r = ReferenceTracker::new(1, 10).unwrap();
        assert!(!r.finish());
        r.accumulate(&[1.0]).unwrap();
        r.accumulate(&[2.0]).unwrap();
        assert!(r.finish());
        assert_eq!(r.reference(), Some(&[1.5][..]));
        assert_eq!(r.source(), ReferenceSource::MeanOfFirst { frames: 2 });
    }

    #[test]
    fn a_new_frame_count_applies_while_accumulating_only() {
        let mut r = ReferenceTracker::new(1, 10).unwrap();
        r.accumulate(&[1.0]).unwrap();
        r.accumulate(&[2.0]).unwrap();
        // More wanted: keeps accumulating up to the new count.
        assert!(!r.set_wanted(3));
        assert!(r.accumulate(&[6.0]).unwrap());
        assert_eq!((r.reference(), r.source()), (Some(&[3.0][..]), ReferenceSource::MeanOfFirst { frames: 3 }));
        // Set references do not move.
        assert!(r.set_wanted(1));
        assert_eq!(r.reference(), Some(&[3.0][..]));
        // Fewer than seen: completes at once with every frame seen.
        let mut r = ReferenceTracker::new(1, 10).unwrap();
        for v in [1.0, 2.0, 3.0] {
            r.accumulate(&[v]).unwrap();
        }
        assert!(r.set_wanted(2));
        assert_eq!((r.reference(), r.source()), (Some(&[2.0][..]), ReferenceSource::MeanOfFirst { frames: 3 }));
        assert_eq!(r.wanted(), 2);
        let mut r = ReferenceTracker::new(1, 4).unwrap();
        assert!(!r.set_wanted(0), "nothing seen: nothing to complete");
        assert_eq!(r.wanted(), 1);
    }

    #[test]
    fn recorded_reference_is_used_at_once() {
        let mut r = ReferenceTracker::from_reference(&[1.0, 1.5]);
        assert_eq!(r.source(), ReferenceSource::Recorded);
        assert!(r.accumulate(&[7.0, 7.0]).unwrap());
        assert_eq!(r.reference(), Some(&[1.0, 1.5][..]));
    }
}
