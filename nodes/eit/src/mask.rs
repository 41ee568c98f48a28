//! Channel masking: which channels of a frame are unusable, and which electrodes are dead.
//!
//! A channel is bad when its value, in the frame or in the reference it is differenced
//! against, is NaN or infinite, reaches `saturation_v` in magnitude (the rail), or is at or
//! below the zero floor: `zero_fraction` x the median |v| of the reference's finite channels
//! (of the frame's, when there is no reference yet). A 0 V reading is what an open input or a
//! lifted electrode gives; unmasked, it is a -100 % change in normalized mode (and 0/0 when the
//! reference reads 0 V too), which images as an edge artefact 40x a real contact.
//! An electrode is dead when at least `dead_electrode_fraction` of the channels that use it (as
//! drive or sense) are bad; then every channel using it is excluded, also the ones that still
//! look valid (their drive or sense path runs through a broken contact).
//!
//! A channel is stuck when its value has not changed, bit for bit, for `stuck_frames`
//! consecutive frames while most channels did change ([`StuckTracker`]): a frozen ADC or
//! multiplexer path. Its reading no longer follows the skin, so its difference from the
//! reference would image as a fixed artefact; it is excluded like a bad one until it changes.
//! A frame where most channels did not change either (a noiseless or quantised board at rest)
//! flags none.

use crate::error::{EitError, check_positive, invalid};
use crate::sensor::Measurement;
use serde::Deserialize;

/// Masking thresholds (TOML table `[mask]`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MaskParams {
    /// |v| at or above this is saturated, volts (set it to the device's rail; the default 2 V
    /// is 5.4x the largest value of the default sensor at the default 10 uA, 0.37 V).
    pub saturation_v: f64,
    /// Fraction of an electrode's channels that must be bad to call it dead, in (0, 1].
    pub dead_electrode_fraction: f64,
    /// |v| at or below this fraction of the reference's median |v| reads as 0 V (an open
    /// input), in [0, 1); 0 masks exact zeros only. The default 1e-3 sits 600x below the
    /// smallest channel of the default sensor (0.19 V against a median of 0.31 V) and 40x
    /// below the smallest of the adjacent protocol (9.5e-5 V against a median of 2.3 mV), so
    /// no healthy channel of either is masked.
    pub zero_fraction: f64,
    /// Frames a channel's value must stay bit-identical, while most channels change, to be
    /// taken as stuck; 0 turns the check off. The default 10 is 8 s at the paper board's
    /// 1.3 frames/s; a channel with any noise above the ADC's step never repeats that long.
    pub stuck_frames: usize,
}

impl Default for MaskParams {
    fn default() -> Self {
        MaskParams { saturation_v: 2.0, dead_electrode_fraction: 0.5, zero_fraction: 1e-3, stuck_frames: 10 }
    }
}

impl MaskParams {
    pub fn validate(&self) -> Result<(), EitError> {
        check_positive("saturation_v", self.saturation_v)?;
        let f = self.dead_electrode_fraction;
        if !(f > 0.0 && f <= 1.0) {
            return Err(invalid("dead_electrode_fraction", format!("must be in (0, 1] (got {f})")));
        }
        let z = self.zero_fraction;
        if !(0.0..1.0).contains(&z) {
            return Err(invalid("zero_fraction", format!("must be in [0, 1) (got {z})")));
        }
        Ok(())
    }
}

/// Excluded channels (protocol order) and dead electrodes.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ChannelMask {
    /// `excluded[k]`: channel k is not used.
    pub excluded: Vec<bool>,
    /// `dead[l]`: electrode l is dead.
    pub dead: Vec<bool>,
}

impl ChannelMask {
    /// A mask that excludes nothing.
    pub fn none(channels: usize, electrodes: usize) -> ChannelMask {
        ChannelMask { excluded: vec![false; channels], dead: vec![false; electrodes] }
    }

    /// A mask excluding every channel that uses one of `electrodes_dead`.
    pub fn from_dead_electrodes(
        measurements: &[Measurement],
        electrodes: usize,
        electrodes_dead: &[usize],
    ) -> ChannelMask {
        let mut m = ChannelMask::none(measurements.len(), electrodes);
        for &l in electrodes_dead {
            if l < electrodes {
                m.dead[l] = true;
            }
        }
        for (x, meas) in m.excluded.iter_mut().zip(measurements) {
            *x = uses_any(meas, &m.dead);
        }
        m
    }

    /// Indices of the excluded channels.
    pub fn excluded_channels(&self) -> Vec<usize> {
        (0..self.excluded.len()).filter(|&k| self.excluded[k]).collect()
    }

    /// Indices of the dead electrodes.
    pub fn dead_electrodes(&self) -> Vec<usize> {
        (0..self.dead.len()).filter(|&l| self.dead[l]).collect()
    }

    pub fn excluded_count(&self) -> usize {
        self.excluded.iter().filter(|&&x| x).count()
    }
}

/// Bad channels of one side (frame or reference), each counted once, by its first cause in
/// this order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BadCounts {
    pub non_finite: usize,
    pub saturated: usize,
    /// At or below the zero floor (0 V).
    pub near_zero: usize,
    /// Stuck at one value (frame side only; see [`StuckTracker`]).
    pub stuck: usize,
}

impl BadCounts {
    pub fn total(&self) -> usize {
        self.non_finite + self.saturated + self.near_zero + self.stuck
    }
}

/// Per channel, the frames its value has stayed bit-identical: which channels are stuck
/// (see the module doc). Fed every frame in time order; allocates nothing after `new`.
#[derive(Debug, Clone)]
pub struct StuckTracker {
    last: Vec<f64>,
    /// Frames since the channel last changed (0: it changed in the last frame, or no frame yet).
    unchanged: Vec<u32>,
    /// `stuck[k]` after the last `update`.
    stuck: Vec<bool>,
    frames: usize,
}

impl StuckTracker {
    pub fn new(channels: usize, frames: usize) -> StuckTracker {
        StuckTracker {
            last: vec![f64::NAN; channels],
            unchanged: vec![0; channels],
            stuck: vec![false; channels],
            frames,
        }
    }

    /// Takes frame `v` (as wide as the tracker): updates each channel's unchanged count and
    /// which channels are stuck. A channel is stuck when it has not changed for `frames`
    /// frames and fewer than half the channels have been as still (then the board as a whole
    /// is not at rest). NaN never repeats (it is masked as non-finite anyway).
    pub fn update(&mut self, v: &[f64]) {
        for ((last, n), &x) in self.last.iter_mut().zip(&mut self.unchanged).zip(v) {
            *n = if x.to_bits() == last.to_bits() && !x.is_nan() { n.saturating_add(1) } else { 0 };
            *last = x;
        }
        let limit = u32::try_from(self.frames).unwrap_or(u32::MAX);
        let still = self.unchanged.iter().filter(|&&n| n >= limit).count();
        let on = self.frames > 0 && 2 * still < self.unchanged.len();
        for (s, &n) in self.stuck.iter_mut().zip(&self.unchanged) {
            *s = on && n >= limit;
        }
    }

    /// `stuck[k]`: channel k is stuck (after the last [`StuckTracker::update`]).
    pub fn stuck(&self) -> &[bool] {
        &self.stuck
    }

    /// Channels tracked.
    pub fn channels(&self) -> usize {
        self.unchanged.len()
    }

    /// Changes how many unchanged frames make a channel stuck (0: off), from the next
    /// [`StuckTracker::update`] on; the counts so far are kept.
    pub fn set_frames(&mut self, frames: usize) {
        self.frames = frames;
    }
}

/// Why `detect_into` excluded what it did, for logs and reports. A channel bad in both the
/// frame and the reference counts on both sides.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MaskCauses {
    pub frame: BadCounts,
    pub reference: BadCounts,
    /// Channels that looked valid on both sides but use a dead electrode.
    pub via_dead_electrode: usize,
    /// The zero floor used, volts.
    pub zero_floor_v: f64,
}

fn uses_any(m: &Measurement, dead: &[bool]) -> bool {
    dead[m.drive.0] || dead[m.drive.1] || dead[m.sense.0] || dead[m.sense.1]
}

/// Whether the mask uses value `x` (with the frame's or reference's zero floor): finite, below
/// the rail, above the zero floor; [`classify`] counts why it does not.
pub fn usable(x: f64, params: &MaskParams, zero_floor: f64) -> bool {
    x.is_finite() && x.abs() < params.saturation_v && x.abs() > zero_floor
}

/// Counts `x` into `counts` when bad; returns whether it is.
fn classify(x: f64, params: &MaskParams, zero_floor: f64, counts: &mut BadCounts) -> bool {
    if !x.is_finite() {
        counts.non_finite += 1;
    } else if x.abs() >= params.saturation_v {
        counts.saturated += 1;
    } else if x.abs() <= zero_floor {
        counts.near_zero += 1;
    } else {
        return false;
    }
    true
}

/// `zero_fraction` x the median |v| over the finite channels of `v` below the rail (0 when
/// there are none). `scratch` holds at least `v.len()` values; the median is selected in place,
/// without allocating.
pub fn zero_floor(v: &[f64], params: &MaskParams, scratch: &mut [f64]) -> f64 {
    let mut n = 0;
    let usable = v.iter().filter(|x| x.is_finite() && x.abs() < params.saturation_v);
    for (slot, x) in scratch.iter_mut().zip(usable) {
        *slot = x.abs();
        n += 1;
    }
    if n == 0 {
        return 0.0;
    }
    let (_, median, _) = scratch[..n].select_nth_unstable_by(n / 2, f64::total_cmp);
    params.zero_fraction * *median
}

/// Fills `out` (sized by `ChannelMask::none`) from frame `v` and the reference `v_ref` it is
/// differenced against (none while there is none yet): a channel bad on either side, or
/// `stuck` (empty: none), is excluded (see the module doc). `scratch` holds at least
/// `v.len()` values. Allocates nothing.
pub fn detect_into(
    v: &[f64],
    v_ref: Option<&[f64]>,
    stuck: &[bool],
    measurements: &[Measurement],
    params: &MaskParams,
    scratch: &mut [f64],
    out: &mut ChannelMask,
) -> MaskCauses {
    let floor = zero_floor(v_ref.unwrap_or(v), params, scratch);
    let mut causes = MaskCauses { zero_floor_v: floor, ..MaskCauses::default() };
    for (k, (x, &val)) in out.excluded.iter_mut().zip(v).enumerate() {
        let mut in_frame = classify(val, params, floor, &mut causes.frame);
        if !in_frame && stuck.get(k).copied().unwrap_or(false) {
            causes.frame.stuck += 1;
            in_frame = true;
        }
        // A reference shorter than the frame has no usable value there.
        let in_ref = v_ref
            .is_some_and(|r| classify(r.get(k).copied().unwrap_or(f64::NAN), params, floor, &mut causes.reference));
        *x = in_frame || in_ref;
    }
    for l in 0..out.dead.len() {
        let (mut total, mut bad) = (0usize, 0usize);
        for (meas, &x) in measurements.iter().zip(&out.excluded) {
            let d = [meas.drive.0, meas.drive.1, meas.sense.0, meas.sense.1];
            if d.contains(&l) {
                total += 1;
                bad += usize::from(x);
            }
        }
        out.dead[l] = total > 0 && bad as f64 >= params.dead_electrode_fraction * total as f64;
    }
    for (x, meas) in out.excluded.iter_mut().zip(measurements) {
        if !*x && uses_any(meas, &out.dead) {
            *x = true;
            causes.via_dead_electrode += 1;
        }
    }
    causes
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::{Protocol, protocol_measurements};

    fn detect(v: &[f64], v_ref: Option<&[f64]>) -> (ChannelMask, MaskCauses) {
        let ms = protocol_measurements(Protocol::Pairwise, 16);
        let mut mask = ChannelMask::none(ms.len(), 16);
        let mut scratch = vec![0.0; ms.len()];
        let causes = detect_into(v, v_ref, &[], &ms, &MaskParams::default(), &mut scratch, &mut mask);
        (mask, causes)
    }

    #[test]
    fn nan_saturated_and_dead_electrode() {
        let ms = protocol_measurements(Protocol::Pairwise, 16);
        let mut v = vec![0.3; ms.len()];
        v[20] = f64::NAN;
        v[40] = 5.0;
        // Electrode 3 broken: every channel using it saturates except two.
        for (k, m) in ms.iter().enumerate() {
            if m.drive.0 == 3 || m.drive.1 == 3 {
                v[k] = -9.0;
            }
        }
        v[ms.iter().position(|m| m.drive == (0, 3)).unwrap()] = 0.4;
        let (mask, causes) = detect(&v, None);
        assert_eq!(mask.dead_electrodes(), vec![3]);
        assert!(mask.excluded[20] && mask.excluded[40]);
        assert!(mask.excluded[ms.iter().position(|m| m.drive == (0, 3)).unwrap()]);
        assert_eq!(mask.excluded_count(), 15 + 2);
        assert_eq!(mask, {
            let mut m = ChannelMask::from_dead_electrodes(&ms, 16, &[3]);
            m.excluded[20] = true;
            m.excluded[40] = true;
            m
        });
        assert_eq!(causes.frame, BadCounts { non_finite: 1, saturated: 1 + 14, near_zero: 0, stuck: 0 });
        assert_eq!((causes.reference.total(), causes.via_dead_electrode), (0, 1));
    }

    #[test]
    fn zero_volt_and_reference_side_channels_are_bad_too() {
        let n = 120;
        let v_ref: Vec<f64> = (0..n).map(|k| 0.2 + 1e-3 * k as f64).collect();
        let mut v = v_ref.clone();
        // 0 V and two microvolts of pickup: below the floor, 1e-3 x the median (2.6e-4 V).
        v[5] = 0.0;
        v[6] = -2e-6;
        // Small but above the floor: kept.
        v[7] = 3e-4;
        let mut r = v_ref.clone();
        r[50] = f64::NAN;
        r[51] = 2.5;
        r[52] = 0.0;
        // 0 V on both sides: one excluded channel, counted on each side.
        r[5] = 0.0;
        let (mask, causes) = detect(&v, Some(&r));
        assert_eq!(mask.excluded_channels(), vec![5, 6, 50, 51, 52]);
        assert_eq!(causes.frame, BadCounts { non_finite: 0, saturated: 0, near_zero: 2, stuck: 0 });
        assert_eq!(causes.reference, BadCounts { non_finite: 1, saturated: 1, near_zero: 2, stuck: 0 });
        // The median of the reference's 118 finite channels below the rail, two of them 0 V.
        assert!(causes.zero_floor_v > 2.5e-4 && causes.zero_floor_v < 2.7e-4, "{}", causes.zero_floor_v);
        // No reference: the frame's own median sets the floor.
        let (mask, _) = detect(&v, None);
        assert_eq!(mask.excluded_channels(), vec![5, 6]);
    }

    #[test]
    fn zero_floor_ignores_bad_channels_and_handles_none_left() {
        let p = MaskParams::default();
        let mut scratch = [0.0; 4];
        assert_eq!(zero_floor(&[f64::NAN, 9.0, f64::INFINITY, -9.0], &p, &mut scratch), 0.0);
        assert_eq!(zero_floor(&[f64::NAN, 0.3, -0.5, 9.0], &p, &mut scratch), 1e-3 * 0.5);
        let bad = MaskParams { zero_fraction: 1.0, ..p };
        assert!(bad.validate().unwrap_err().to_string().contains("zero_fraction"));
    }

    /// Frame `i` of a noisy board: every channel moves every frame (a fixed-seed LCG), but
    /// channel `frozen` holds 0.25 V from frame `from` on.
    fn noisy(i: u64, n: usize, frozen: usize, from: u64) -> Vec<f64> {
        (0..n)
            .map(|k| {
                if k == frozen && i >= from {
                    return 0.25;
                }
                let mut x = (i * 1000 + k as u64).wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                x ^= x >> 33;
                0.3 + 1e-4 * ((x % 1000) as f64 / 1000.0 - 0.5)
            })
            .collect()
    }

    #[test]
    fn a_channel_frozen_while_the_others_move_is_stuck_after_stuck_frames_and_free_once_it_moves() {
        let (n, frames) = (120, 10);
        let mut t = StuckTracker::new(n, frames);
        // Frozen from frame 5: unchanged for 1, 2, ... frames from frame 6 on.
        for i in 0..5 + frames as u64 {
            t.update(&noisy(i, n, 7, 5));
            assert!(t.stuck().iter().all(|&s| !s), "frame {i}: too early");
        }
        t.update(&noisy(15, n, 7, 5));
        assert_eq!((0..n).filter(|&k| t.stuck()[k]).collect::<Vec<_>>(), vec![7]);
        // Through the mask: excluded, counted as stuck on the frame side.
        let ms = protocol_measurements(Protocol::Pairwise, 16);
        let (mut mask, mut scratch) = (ChannelMask::none(n, 16), vec![0.0; n]);
        let v = noisy(15, n, 7, 5);
        let causes = detect_into(&v, Some(&v), t.stuck(), &ms, &MaskParams::default(), &mut scratch, &mut mask);
        assert_eq!((mask.excluded_channels(), causes.frame.stuck, causes.frame.total()), (vec![7], 1, 1));
        // It moves again: free at once.
        t.update(&noisy(16, n, 99, 0));
        assert!(t.stuck().iter().all(|&s| !s));
    }

    #[test]
    fn a_board_at_rest_or_the_check_turned_off_flags_nothing() {
        let n = 120;
        // Noiseless and still: every channel repeats, none is singled out.
        let mut t = StuckTracker::new(n, 10);
        for _ in 0..50 {
            t.update(&vec![0.3; n]);
        }
        assert!(t.stuck().iter().all(|&s| !s));
        // Half the channels still (a quantised board with half its channels below one step):
        // not "most channels moved", so none is flagged.
        let mut t = StuckTracker::new(n, 10);
        for i in 0..50 {
            let mut v = noisy(i, n, usize::MAX, 0);
            v[..n / 2].fill(0.3);
            t.update(&v);
        }
        assert!(t.stuck().iter().all(|&s| !s));
        // stuck_frames = 0: off.
        let mut t = StuckTracker::new(n, 0);
        for i in 0..50 {
            t.update(&noisy(i, n, 7, 0));
        }
        assert!(t.stuck().iter().all(|&s| !s));
        // NaN never counts as repeating.
        let mut t = StuckTracker::new(n, 2);
        for i in 0..10 {
            let mut v = noisy(i, n, usize::MAX, 0);
            v[3] = f64::NAN;
            t.update(&v);
        }
        assert!(!t.stuck()[3]);
    }
}
