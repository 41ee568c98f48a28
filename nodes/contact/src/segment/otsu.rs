//! Otsu's threshold on values normalized to [0, 1], with a fixed 256-bin histogram.
//!
//! Bin `k` holds values in `[k/256, (k+1)/256)` (1.0 goes to the last bin). The returned
//! threshold `t` splits "background" `v < t` from "foreground" `v >= t`; it is the upper edge
//! of the background class. When several splits give the same between-class variance (a
//! gap in the histogram), the middle of that plateau is returned, so a two-level image is
//! cut halfway between its levels rather than just above the lower one.

/// Number of histogram bins.
pub const BINS: usize = 256;

/// Bin index of a normalized value (values outside [0, 1] are clamped into range).
pub fn bin_of(v: f64) -> usize {
    // `as usize` truncates (= floor for v >= 0) and saturates: negatives and NaN give 0.
    // Avoids `f64::floor`, a libm call on baseline x86-64, in this per-pixel path.
    ((v * BINS as f64) as usize).min(BINS - 1)
}

/// Otsu threshold in [0, 1] from a histogram; `None` when fewer than two bins are occupied.
pub fn otsu_threshold(hist: &[u32; BINS]) -> Option<f64> {
    let total: f64 = hist.iter().map(|&c| c as f64).sum();
    if total == 0.0 {
        return None;
    }
    let sum_all: f64 = hist.iter().enumerate().map(|(k, &c)| k as f64 * c as f64).sum();
    let (mut w0, mut sum0) = (0.0, 0.0);
    let mut best = -1.0_f64;
    let (mut first, mut last) = (0usize, 0usize);
    // Split after bin k: class 0 = bins 0..=k, class 1 = bins k+1..
    for (k, &count) in hist.iter().enumerate().take(BINS - 1) {
        w0 += count as f64;
        sum0 += k as f64 * count as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let m0 = sum0 / w0;
        let m1 = (sum_all - sum0) / w1;
        let between = w0 * w1 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            first = k;
            last = k;
        } else if between == best {
            last = k;
        }
    }
    if best < 0.0 {
        return None;
    }
    let k_mid = (first + last) / 2;
    Some((k_mid + 1) as f64 / BINS as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_level_histogram_is_cut_halfway() {
        // 0.2 -> bin 51, 0.8 -> bin 204; every split in 51..=203 gives the same
        // between-class variance, plateau middle = 127, threshold = 128/256 = 0.5.
        let mut h = [0u32; BINS];
        h[bin_of(0.2)] = 30;
        h[bin_of(0.8)] = 10;
        assert_eq!(bin_of(0.2), 51);
        assert_eq!(bin_of(0.8), 204);
        assert_eq!((bin_of(-0.1), bin_of(f64::NAN), bin_of(1.0), bin_of(7.0)), (0, 0, 255, 255));
        assert_eq!(otsu_threshold(&h), Some(0.5));
    }

    #[test]
    fn three_level_histogram_matches_hand_computation() {
        // Levels at bins 0 (n=2), 100 (n=1), 200 (n=1). Split after 0: w0=2,w1=2,
        // m0=0, m1=150 -> 2*2*150^2 = 90000. Split after 100: w0=3,w1=1,m0=33.3,m1=200
        // -> 3*1*166.7^2 = 83333. Best = split after bin 0 (plateau 0..=99, middle 49).
        let mut h = [0u32; BINS];
        h[0] = 2;
        h[100] = 1;
        h[200] = 1;
        assert_eq!(otsu_threshold(&h), Some(50.0 / 256.0));
    }

    #[test]
    fn single_level_has_no_threshold() {
        let mut h = [0u32; BINS];
        h[7] = 100;
        assert_eq!(otsu_threshold(&h), None);
        assert_eq!(otsu_threshold(&[0; BINS]), None);
    }
}
