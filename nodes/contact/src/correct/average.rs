//! Averaging the frames of a hold (the paper's 6-frame means) and grouping true locations.
//!
//! A hold is a run of consecutive frames with one hold number ([`CalibSample::hold`]: the
//! source breaks it where the load was released or changed) and the same load ([`same_load`]:
//! the place within [`SAME_PLACE_MM`], the force within a load cell's jitter, the diameter
//! equal, a missing (NaN) one included); its frames are averaged into one [`CalibSample`], the
//! truth too, and their spread is reported. A frame with a non-finite measurement (centroid, dP,
//! C, area) is left out of its hold's mean and counted, so one bad frame does not cost the whole
//! hold. Locations are true positions clustered greedily within a tolerance (mm).

use super::calibrate::CalibSample;

/// Two truth contacts this close (mm) are at the same place (the stage's repeatability is
/// about 0.5 mm; the rig's grid steps are millimetres or more).
pub const SAME_PLACE_MM: f64 = 0.5;
/// Absolute part of the force tolerance of a repeated load (N): a few counts of a load cell's
/// last digit (0.01 N).
pub const SAME_FORCE_N: f64 = 0.05;
/// Relative part of the force tolerance of a repeated load: a hold's creep.
pub const SAME_FORCE_REL: f64 = 0.02;

/// Whether a contact `b` = [x mm, y mm, force N, diameter mm] holds the same load as `a`:
/// exactly, or within a load cell's jitter (`tolerant`: the place within [`SAME_PLACE_MM`], the
/// force within [`SAME_FORCE_N`] plus [`SAME_FORCE_REL`] of `a`'s). The diameter is always
/// compared exactly; two NaNs (unknown) count as equal.
pub fn same_load(a: [f64; 4], b: [f64; 4], tolerant: bool) -> bool {
    let (place_mm, force_n, force_rel) =
        if tolerant { (SAME_PLACE_MM, SAME_FORCE_N, SAME_FORCE_REL) } else { (0.0, 0.0, 0.0) };
    let same = |p: f64, q: f64, tol: f64| (p - q).abs() <= tol || (p.is_nan() && q.is_nan());
    let ([ax, ay, af, ad], [bx, by, bf, bd]) = (a, b);
    (ax - bx).hypot(ay - by) <= place_mm && same(ad, bd, 0.0) && same(af, bf, force_n + force_rel * af.abs())
}

fn load(s: &CalibSample) -> [f64; 4] {
    [s.true_x_mm, s.true_y_mm, s.force_n, s.diameter_mm]
}

/// Averages of the holds and the mean within-hold spread.
#[derive(Debug, Clone, PartialEq)]
pub struct Holds {
    /// One averaged sample per hold, in order.
    pub samples: Vec<CalibSample>,
    /// Mean within-hold standard deviation of dP, kPa.
    pub sd_dp_kpa: f64,
    /// Mean within-hold standard deviation of C.
    pub sd_cond_sum: f64,
    /// Frames left out of their hold's mean for a non-finite measurement.
    pub non_finite_frames: usize,
}

fn finite(s: &CalibSample) -> bool {
    [s.x_mm, s.y_mm, s.dp_kpa, s.cond_sum, s.area_mm2].iter().all(|v| v.is_finite())
}

/// Averages runs of consecutive frames with one hold number and the same load ([`same_load`]
/// with the run's first frame). Exact equality would split a hold read from a load cell that
/// prints continuously (its force jitters in the last digit) or without a diameter (NaN) into
/// one-frame "holds": no averaging, a zero spread, and more samples than holds.
pub fn average_holds(frames: &[CalibSample]) -> Holds {
    let same = |a: &CalibSample, b: &CalibSample| a.hold == b.hold && same_load(load(a), load(b), true);
    let (mut samples, mut sd_dp, mut sd_c, mut non_finite) = (Vec::new(), 0.0, 0.0, 0);
    let mut run: Vec<CalibSample> = Vec::new();
    let mut start = 0;
    while start < frames.len() {
        let mut end = start + 1;
        while end < frames.len() && same(&frames[start], &frames[end]) {
            end += 1;
        }
        run.clear();
        run.extend(frames[start..end].iter().filter(|s| finite(s)));
        non_finite += (end - start) - run.len();
        if run.is_empty() {
            // No usable frame: the hold's sample is the (non-finite) first frame, which the
            // quality filter rejects and counts.
            samples.push(frames[start]);
            start = end;
            continue;
        }
        let run = &run[..];
        let n = run.len() as f64;
        let mean = |f: fn(&CalibSample) -> f64| run.iter().map(f).sum::<f64>() / n;
        let sd = |f: fn(&CalibSample) -> f64, m: f64| {
            if run.len() < 2 { 0.0 } else { (run.iter().map(|s| (f(s) - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt() }
        };
        let avg = CalibSample {
            x_mm: mean(|s| s.x_mm),
            y_mm: mean(|s| s.y_mm),
            dp_kpa: mean(|s| s.dp_kpa),
            cond_sum: mean(|s| s.cond_sum),
            area_mm2: mean(|s| s.area_mm2),
            true_x_mm: mean(|s| s.true_x_mm),
            true_y_mm: mean(|s| s.true_y_mm),
            force_n: mean(|s| s.force_n),
            ..run[0]
        };
        sd_dp += sd(|s| s.dp_kpa, avg.dp_kpa);
        sd_c += sd(|s| s.cond_sum, avg.cond_sum);
        samples.push(avg);
        start = end;
    }
    let holds = samples.len().max(1) as f64;
    Holds { samples, sd_dp_kpa: sd_dp / holds, sd_cond_sum: sd_c / holds, non_finite_frames: non_finite }
}

/// Distinct true locations (greedy clustering within `tol_mm`) and each sample's location.
pub fn locations(samples: &[CalibSample], tol_mm: f64) -> (Vec<(f64, f64)>, Vec<usize>) {
    let (mut locs, mut of): (Vec<(f64, f64)>, Vec<usize>) = (Vec::new(), Vec::new());
    for s in samples {
        let near = locs.iter().position(|l| (l.0 - s.true_x_mm).hypot(l.1 - s.true_y_mm) <= tol_mm);
        of.push(near.unwrap_or_else(|| {
            locs.push((s.true_x_mm, s.true_y_mm));
            locs.len() - 1
        }));
    }
    (locs, of)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(true_x_mm: f64, force_n: f64, dp_kpa: f64) -> CalibSample {
        CalibSample {
            x_mm: true_x_mm,
            y_mm: 0.0,
            true_x_mm,
            true_y_mm: 0.0,
            force_n,
            dp_kpa,
            cond_sum: 1.0,
            area_mm2: 1.0,
            diameter_mm: 15.0,
            hold: 0,
        }
    }

    /// A load cell printing continuously: the force jitters in its last digits and the
    /// position by a fraction of a millimetre within one hold, and an external writer may give
    /// no diameter (NaN). Each hold is still one sample, with the mean truth; a real change of
    /// load within one hold number still splits.
    #[test]
    fn a_jittering_or_diameterless_hold_is_one_sample() {
        let mut frames: Vec<CalibSample> = [4.99, 5.01, 5.02, 4.98]
            .iter()
            .enumerate()
            .map(|(i, &f)| CalibSample { diameter_mm: f64::NAN, ..frame(0.1 * i as f64, f, i as f64) })
            .collect();
        frames.push(CalibSample { diameter_mm: f64::NAN, ..frame(0.0, 6.0, 10.0) });
        let h = average_holds(&frames);
        assert_eq!(h.samples.len(), 2, "{:?}", h.samples);
        let s = &h.samples[0];
        assert!((s.force_n - 5.0).abs() < 1e-12 && (s.true_x_mm - 0.15).abs() < 1e-12, "{s:?}");
        assert!((s.dp_kpa - 1.5).abs() < 1e-12, "{s:?}");
        assert!(s.diameter_mm.is_nan());
        assert_eq!(h.samples[1].force_n, 6.0, "1 N more is another load");
        assert!(h.sd_dp_kpa > 0.0, "the hold's spread is measured, not 0");
    }

    #[test]
    fn consecutive_identical_truth_is_one_hold() {
        // Two holds at x = 0 (1 N: dP 1, 3; 2 N: dP 5) and a return to 1 N that is a new hold.
        let frames = [frame(0.0, 1.0, 1.0), frame(0.0, 1.0, 3.0), frame(0.0, 2.0, 5.0), frame(0.0, 1.0, 7.0)];
        let h = average_holds(&frames);
        let dp: Vec<f64> = h.samples.iter().map(|s| s.dp_kpa).collect();
        assert_eq!(dp, [2.0, 5.0, 7.0]);
        // SDs: sqrt(2), 0, 0 -> mean sqrt(2) / 3.
        assert!((h.sd_dp_kpa - 2f64.sqrt() / 3.0).abs() < 1e-12);
    }

    /// The reviewer's case: two indentations with the same truth, the release between them
    /// filtered out before averaging, are two samples when their holds differ.
    #[test]
    fn identical_truth_in_two_holds_is_two_samples() {
        let mut frames = [frame(0.0, 1.0, 1.0), frame(0.0, 1.0, 3.0), frame(0.0, 1.0, 5.0), frame(0.0, 1.0, 7.0)];
        frames[2].hold = 1;
        frames[3].hold = 1;
        let dp: Vec<f64> = average_holds(&frames).samples.iter().map(|s| s.dp_kpa).collect();
        assert_eq!(dp, [2.0, 6.0]);
    }

    #[test]
    fn a_non_finite_frame_leaves_the_rest_of_its_hold() {
        // Hold 1: dP 1, NaN, 3 -> mean of the two finite frames; hold 2: only NaN -> its sample
        // stays non-finite (the quality filter rejects it), counted both times.
        let frames = [frame(0.0, 1.0, 1.0), frame(0.0, 1.0, f64::NAN), frame(0.0, 1.0, 3.0), frame(0.0, 2.0, f64::NAN)];
        let h = average_holds(&frames);
        assert_eq!(h.samples.len(), 2);
        assert_eq!(h.samples[0].dp_kpa, 2.0);
        assert!(h.samples[1].dp_kpa.is_nan());
        assert_eq!(h.non_finite_frames, 2);
        assert!(h.sd_dp_kpa.is_finite());
    }

    #[test]
    fn nearby_positions_are_one_location() {
        let s = [frame(0.0, 1.0, 1.0), frame(1.5, 1.0, 1.0), frame(10.0, 1.0, 1.0)];
        let (locs, of) = locations(&s, 2.0);
        assert_eq!(locs.len(), 2);
        assert_eq!(of, [0, 0, 1]);
    }
}
