//! Accumulating per-frame results and reducing them to the CONTRACTS.md §4 metrics.
//!
//! [`Evaluator::push`] takes one evaluated frame: its truth, the detected centroids, each
//! strategy's per-contact forces (aligned with the detections) and per-frame latency, and
//! optionally the frame's image sharpness ([`resolution_pct`]). It matches detections to truth
//! ([`super::matching`]) and keeps one [`MatchRecord`] per pair. Statistics: RMSE over
//! matched contacts; SD = sample standard deviation (n - 1) of the absolute errors;
//! percentiles by linear interpolation between order statistics.

use super::matching::{Pair, match_contacts};
use crate::segment::Contact;

/// CONTRACTS.md §4 matching radius, mm.
pub const MATCH_RADIUS_MM: f64 = 15.0;

/// One true contact of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthContact {
    /// True centre, mm.
    pub x_mm: f64,
    /// True centre, mm.
    pub y_mm: f64,
    /// True normal force, N.
    pub force_n: f64,
    /// Indenter diameter, mm.
    pub diameter_mm: f64,
}

/// RES50 and RES75 of one frame, percent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resolution {
    /// 100 (1 - sqrt(A_0.5 / A)).
    pub res50_pct: f64,
    /// 100 (1 - sqrt(A_0.75 / A)).
    pub res75_pct: f64,
}

/// One evaluated frame.
#[derive(Debug, Clone, Copy)]
pub struct FrameInput<'a> {
    /// True contacts (empty when nothing touches).
    pub truth: &'a [TruthContact],
    /// Detected centroids, mm.
    pub detected_mm: &'a [(f64, f64)],
    /// Per strategy (evaluator order), the force of each detection, N.
    pub forces_n: &'a [&'a [f64]],
    /// Per strategy, the frame's wall time from EIT frame to forces, us.
    pub latency_us: &'a [f64],
    /// Image sharpness of this frame, if the caller computed it.
    pub resolution: Option<Resolution>,
}

/// A matched (detected, true) pair with every strategy's force.
#[derive(Debug, Clone, PartialEq)]
pub struct MatchRecord {
    /// Index of the frame in push order.
    pub frame: usize,
    /// The true contact.
    pub truth: TruthContact,
    /// The detected centroid, mm.
    pub detected_mm: (f64, f64),
    /// Localization error, mm.
    pub dist_mm: f64,
    /// Number of true contacts in the frame.
    pub truth_in_frame: usize,
    /// Estimated force per strategy, N.
    pub forces_n: Vec<f64>,
}

/// Why a frame was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// Force or latency arrays do not match the strategies or detections.
    #[error("eval: frame {frame}: {what} has {got} entries, expected {expected}")]
    Shape { frame: usize, what: &'static str, got: usize, expected: usize },
}

/// Accumulates frames for a fixed list of strategies.
#[derive(Debug, Clone)]
pub struct Evaluator {
    pub(crate) names: Vec<String>,
    pub(crate) labels: Vec<String>,
    pub(crate) frames: usize,
    pub(crate) records: Vec<MatchRecord>,
    pub(crate) missed: usize,
    /// Every finite truth diameter seen (mm, sorted), matched or missed: each has its
    /// per-diameter RMSE key, `null` when none of its contacts was matched.
    pub(crate) diameters_mm: Vec<f64>,
    pub(crate) spurious: usize,
    pub(crate) multi_frames: usize,
    pub(crate) latencies_us: Vec<Vec<f64>>,
    pub(crate) resolutions: Vec<Resolution>,
}

impl Evaluator {
    /// An evaluator for strategies given as (JSON name, table label).
    pub fn new(strategies: &[(&str, &str)]) -> Self {
        Self {
            names: strategies.iter().map(|s| s.0.to_string()).collect(),
            labels: strategies.iter().map(|s| s.1.to_string()).collect(),
            frames: 0,
            records: Vec::new(),
            missed: 0,
            diameters_mm: Vec::new(),
            spurious: 0,
            multi_frames: 0,
            latencies_us: vec![Vec::new(); strategies.len()],
            resolutions: Vec::new(),
        }
    }

    /// An evaluator for built-in strategies.
    pub fn for_kinds(kinds: &[crate::StrategyKind]) -> Self {
        let s: Vec<(&str, &str)> = kinds.iter().map(|k| (k.name(), k.label())).collect();
        Self::new(&s)
    }

    /// Strategy names in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Frames pushed so far (the index the next frame will get).
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Every matched pair so far.
    pub fn records(&self) -> &[MatchRecord] {
        &self.records
    }

    /// Adds one evaluated frame; returns its matches.
    pub fn push(&mut self, f: &FrameInput) -> Result<Vec<Pair>, EvalError> {
        let frame = self.frames;
        let shape = |what, got, expected| {
            if got == expected { Ok(()) } else { Err(EvalError::Shape { frame, what, got, expected }) }
        };
        shape("forces_n", f.forces_n.len(), self.names.len())?;
        shape("latency_us", f.latency_us.len(), self.names.len())?;
        for forces in f.forces_n {
            shape("a strategy's forces_n", forces.len(), f.detected_mm.len())?;
        }
        self.frames += 1;
        let truth_xy: Vec<(f64, f64)> = f.truth.iter().map(|t| (t.x_mm, t.y_mm)).collect();
        let pairs = match_contacts(f.detected_mm, &truth_xy, MATCH_RADIUS_MM);
        self.spurious += f.detected_mm.len() - pairs.len();
        self.missed += f.truth.len() - pairs.len();
        for d in f.truth.iter().map(|t| t.diameter_mm).filter(|d| d.is_finite()) {
            if let Err(at) = self.diameters_mm.binary_search_by(|x| x.total_cmp(&d)) {
                self.diameters_mm.insert(at, d);
            }
        }
        if f.truth.len() >= 2 {
            self.multi_frames += 1;
        }
        for p in &pairs {
            self.records.push(MatchRecord {
                frame,
                truth: f.truth[p.truth],
                detected_mm: f.detected_mm[p.pred],
                dist_mm: p.dist_mm,
                truth_in_frame: f.truth.len(),
                forces_n: f.forces_n.iter().map(|s| s[p.pred]).collect(),
            });
        }
        for (acc, &l) in self.latencies_us.iter_mut().zip(f.latency_us) {
            if l.is_finite() {
                acc.push(l);
            }
        }
        if let (1, 1, Some(r)) = (f.truth.len(), pairs.len(), f.resolution) {
            self.resolutions.push(r);
        }
        Ok(pairs)
    }
}

/// A running sum of squares kept scaled by the largest magnitude so far (as BLAS's `nrm2`),
/// so values whose squares overflow f64 (errors of 1e200 N from truth in the wrong unit) still
/// give their finite root mean square. For streaming reductions (the `compare` node's lanes).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SumOfSquares {
    scale: f64,
    ssq: f64,
    nan: bool,
    inf: bool,
}

impl SumOfSquares {
    pub fn push(&mut self, v: f64) {
        let a = v.abs();
        if a.is_nan() {
            self.nan = true;
        } else if a.is_infinite() {
            self.inf = true;
        } else if a > self.scale {
            self.ssq = 1.0 + self.ssq * (self.scale / a) * (self.scale / a);
            self.scale = a;
        } else if a > 0.0 {
            self.ssq += (a / self.scale) * (a / self.scale);
        }
    }

    /// sqrt(sum / n): NaN if a value was NaN or `n` is 0, infinite if one was infinite.
    pub fn root_mean(&self, n: u64) -> f64 {
        match (self.nan || n == 0, self.inf) {
            (true, _) => f64::NAN,
            (false, true) => f64::INFINITY,
            _ => self.scale * (self.ssq / n as f64).sqrt(),
        }
    }
}

/// Root mean square; `None` when empty. Through [`SumOfSquares`]: finite where the plain
/// sum of squares would overflow; NaN if any value is NaN, else infinite if one is.
pub fn rms(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (mut sum, mut n) = (SumOfSquares::default(), 0u64);
    for v in values {
        sum.push(v);
        n += 1;
    }
    (n > 0).then(|| sum.root_mean(n))
}

/// Mean; `None` when empty.
pub fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (mut s, mut n) = (0.0, 0usize);
    for v in values {
        s += v;
        n += 1;
    }
    (n > 0).then(|| s / n as f64)
}

/// Sample standard deviation (n - 1); 0 for one value, `None` when empty.
pub fn sd(values: &[f64]) -> Option<f64> {
    let m = mean(values.iter().copied())?;
    if values.len() == 1 {
        return Some(0.0);
    }
    let n = values.len() as f64;
    rms(values.iter().map(|v| v - m)).map(|r| r * (n / (n - 1.0)).sqrt())
}

/// Percentile `q` in [0, 100] by linear interpolation of the sorted values; `None` when empty.
pub fn percentile(values: &[f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let pos = (q / 100.0).clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    Some(v[lo] + (pos - lo as f64) * (v[hi] - v[lo]))
}

/// Image sharpness 100 (1 - sqrt(A_t / A)) for `fraction` t of `peak` (a decrease, image
/// units): A_t counts pixels whose decrease `-image` is at least t x peak, A counts all finite
/// pixels (the sensing area on the image grid). `None` unless peak > 0.
pub fn resolution_pct(image: &[f64], peak: f64, fraction: f64) -> Option<f64> {
    if peak.is_nan() || peak <= 0.0 {
        return None;
    }
    let total = image.iter().filter(|v| v.is_finite()).count();
    let above = image.iter().filter(|v| v.is_finite() && -**v >= fraction * peak).count();
    (total > 0).then(|| 100.0 * (1.0 - (above as f64 / total as f64).sqrt()))
}

/// RES50 and RES75 of one frame, with the peak = the largest contact amplitude (CONTRACTS.md
/// §4: the largest [`Contact::peak`] of the frame's segmented contacts); `None` without contacts.
pub fn resolution(image: &[f64], contacts: &[Contact]) -> Option<Resolution> {
    let peak = contacts.iter().map(|c| c.peak).fold(f64::NEG_INFINITY, f64::max);
    Some(Resolution { res50_pct: resolution_pct(image, peak, 0.5)?, res75_pct: resolution_pct(image, peak, 0.75)? })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_by_hand() {
        assert_eq!(rms([3.0, 4.0].into_iter()), Some((12.5f64).sqrt()));
        assert_eq!(sd(&[1.0, 3.0]), Some(2f64.sqrt()));
        assert_eq!(sd(&[5.0]), Some(0.0));
        assert_eq!(percentile(&[4.0, 1.0, 3.0, 2.0], 50.0), Some(2.5));
        assert_eq!(percentile(&[1.0, 2.0, 3.0, 4.0, 5.0], 99.0), Some(4.96));
        assert_eq!(rms(std::iter::empty()), None);
        assert_eq!(percentile(&[], 50.0), None);
    }

    /// The scaled sum agrees with the plain one where that does not overflow, and stays finite
    /// (and exact in ratio) where the squares would overflow.
    #[test]
    fn rms_and_sd_do_not_overflow_and_agree_with_the_plain_sums() {
        let v: Vec<f64> = (0..97).map(|i| ((i * 37 % 101) as f64 - 50.0) * 0.013).collect();
        let plain = (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let r = rms(v.iter().copied()).unwrap();
        assert!((r - plain).abs() <= 1e-15 * plain, "{r} vs {plain}");
        let big: Vec<f64> = v.iter().map(|x| x * 1e300).collect();
        let rb = rms(big.iter().copied()).unwrap();
        assert!(rb.is_finite() && (rb / 1e300 - r).abs() <= 1e-14 * r, "{rb}");
        let (s, sb) = (sd(&v).unwrap(), sd(&big).unwrap());
        assert!(sb.is_finite() && (sb / 1e300 - s).abs() <= 1e-14 * s, "{sb} vs {s}");
        assert!(rms([1.0, f64::NAN, 2.0].into_iter()).unwrap().is_nan());
        assert_eq!(rms([0.0, 0.0].into_iter()), Some(0.0));
        assert_eq!(rms([f64::INFINITY, 1.0].into_iter()), Some(f64::INFINITY));
        assert_eq!(rms([f64::INFINITY, f64::NEG_INFINITY].into_iter()), Some(f64::INFINITY));
    }

    #[test]
    fn resolution_of_a_square_spot() {
        // 10 x 10 image, a 2 x 2 spot at full depth and a ring of 12 pixels at 0.6 of it:
        // A_0.5 = 16 px -> 100 (1 - sqrt(0.16)) = 60; A_0.75 = 4 px -> 100 (1 - 0.2) = 80.
        let mut img = vec![0.0; 100];
        for r in 3..7 {
            for c in 3..7 {
                img[r * 10 + c] = -0.6;
            }
        }
        for r in 4..6 {
            for c in 4..6 {
                img[r * 10 + c] = -1.0;
            }
        }
        let c = Contact { x_mm: 0.0, y_mm: 0.0, sum: 1.0, area_mm2: 1.0, peak: 1.0, label: 1 };
        let res = resolution(&img, &[c]).unwrap();
        assert!((res.res50_pct - 60.0).abs() < 1e-12 && (res.res75_pct - 80.0).abs() < 1e-12);
        assert!(resolution(&img, &[]).is_none());
        assert_eq!(resolution_pct(&img, 0.0, 0.5), None);
    }

    #[test]
    fn missed_spurious_and_shapes() {
        let mut e = Evaluator::new(&[("a", "A")]);
        let truth = [TruthContact { x_mm: 0.0, y_mm: 0.0, force_n: 2.0, diameter_mm: 10.0 }];
        let det = [(1.0, 0.0), (40.0, 0.0)];
        let pairs = e
            .push(&FrameInput {
                truth: &truth,
                detected_mm: &det,
                forces_n: &[&[2.5, 1.0]],
                latency_us: &[10.0],
                resolution: None,
            })
            .unwrap();
        assert_eq!(pairs.len(), 1);
        assert_eq!((e.spurious, e.missed), (1, 0));
        // A frame without contact counts spurious detections only.
        e.push(&FrameInput {
            truth: &[],
            detected_mm: &det[..1],
            forces_n: &[&[0.3]],
            latency_us: &[9.0],
            resolution: None,
        })
        .unwrap();
        assert_eq!((e.spurious, e.missed, e.frames), (2, 0, 2));
        let bad =
            FrameInput { truth: &[], detected_mm: &det, forces_n: &[&[1.0]], latency_us: &[1.0], resolution: None };
        assert!(e.push(&bad).is_err());
    }
}
