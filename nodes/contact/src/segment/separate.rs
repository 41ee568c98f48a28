//! Separating touching contacts inside one foreground component (the paper's future work:
//! "improved ROI separation methods ... to better handle closely spaced contacts").
//!
//! EIT blurs two nearby presses into one connected blob with two maxima and a saddle between
//! them (on the simulated skin: 10 mm indenters 42 mm apart, one at the centre where the
//! image is least sharp). Connected components then report one contact at the midpoint, and
//! both forces land on it. This pass splits a component at its saddles:
//!
//! 1. every foreground pixel points to its steepest-ascent 8-neighbour (a pixel with no higher
//!    neighbour is a peak), so each pixel drains into one peak's basin;
//! 2. basins meet along saddles; the saddle of two basins is the highest `min(d_p, d_q)`
//!    over their adjacent pixel pairs;
//! 3. saddles are visited from the highest down (persistence): two regions stay apart only
//!    when both peaks rise above the saddle by at least `depth` times the lower peak;
//!    otherwise the lower one joins the higher.
//!
//! A blob with one maximum is never split, so a single contact stays one contact, and noise
//! ripples (a few percent of the peak) merge back. `depth = 0` is not used: the segmenter
//! skips this pass then (the paper's plain connected components). No allocation after `new`.

/// Buffers for [`Separator::run`].
#[derive(Debug, Clone)]
pub struct Separator {
    /// Steepest-ascent parent of each pixel, then its basin's peak pixel.
    basin: Vec<u32>,
    /// Union-find parent over peak pixels.
    set: Vec<u32>,
    /// Candidate saddles: (saddle value, basin a, basin b).
    saddles: Vec<(f64, u32, u32)>,
    /// Compact output label of each set root (0 = none yet).
    compact: Vec<u32>,
    /// Foreground pixel indices of the current frame, row-major.
    fg: Vec<u32>,
    /// Decrease of the foreground pixels, -inf elsewhere.
    dec: Vec<f64>,
}

const NONE: u32 = u32::MAX;

impl Separator {
    /// Buffers for images of `n` pixels.
    pub fn new(n: usize) -> Self {
        Self {
            basin: vec![NONE; n],
            set: vec![NONE; n],
            saddles: Vec::with_capacity(4 * n),
            compact: vec![0; n],
            fg: Vec::with_capacity(n),
            dec: vec![f64::NEG_INFINITY; n],
        }
    }

    fn find(&mut self, mut p: u32) -> u32 {
        while self.set[p as usize] != p {
            let up = self.set[self.set[p as usize] as usize];
            self.set[p as usize] = up;
            p = up;
        }
        p
    }

    /// Labels the foreground of `mask` (row-major, 0/1) into `labels` (0 = background,
    /// 1..=k row-major by first pixel) with touching peaks separated. `image` is the
    /// conductivity change (a contact is a decrease: negative; NaN counts as 0). Returns k.
    ///
    /// `min_peak` is the decrease the mask was cut at: a basin whose peak is below it exists
    /// only because the closing filled a dip (or a NaN pixel), and always merges.
    #[allow(clippy::too_many_arguments)]
    pub fn run(
        &mut self,
        width: usize,
        height: usize,
        image: &[f64],
        mask: &[u8],
        depth: f64,
        min_peak: f64,
        labels: &mut [u32],
    ) -> u32 {
        let n = width * height;
        // The decrease of every foreground pixel, -inf elsewhere, so one comparison both
        // tests membership and height. A NaN pixel can become foreground through the
        // closing; it counts as no decrease.
        self.fg.clear();
        for p in 0..n {
            self.dec[p] = if mask[p] == 0 {
                f64::NEG_INFINITY
            } else {
                self.fg.push(p as u32);
                if image[p].is_finite() { -image[p] } else { 0.0 }
            };
        }
        let dec = &self.dec;
        // 1. Steepest ascent (interior pixels by fixed offsets, the border with bounds).
        let w = width as isize;
        let offsets = [-w - 1, -w, -w + 1, -1, 1, w - 1, w, w + 1];
        for &p in &self.fg {
            let p = p as usize;
            let (col, row) = (p % width, p / width);
            let (mut best, mut best_v) = (p, dec[p]);
            if col > 0 && row > 0 && col + 1 < width && row + 1 < height {
                for off in offsets {
                    let q = (p as isize + off) as usize;
                    if dec[q] > best_v {
                        (best, best_v) = (q, dec[q]);
                    }
                }
            } else {
                for r in row.saturating_sub(1)..=(row + 1).min(height - 1) {
                    for c in col.saturating_sub(1)..=(col + 1).min(width - 1) {
                        let q = r * width + c;
                        if dec[q] > best_v {
                            (best, best_v) = (q, dec[q]);
                        }
                    }
                }
            }
            self.basin[p] = best as u32;
        }
        // Follow parents to the peak (values strictly increase, so this ends), compressing
        // each path so every pixel is walked over about once.
        for &p in &self.fg {
            let p = p as usize;
            let mut top = p;
            while self.basin[top] as usize != top {
                top = self.basin[top] as usize;
            }
            let mut q = p;
            while q != top {
                let next = self.basin[q] as usize;
                self.basin[q] = top as u32;
                q = next;
            }
            self.set[top] = top as u32;
        }
        // 2. Saddles between basins (each unordered pixel pair once: right and the row above).
        self.saddles.clear();
        for &p in &self.fg {
            let p = p as usize;
            let (col, row) = (p % width, p / width);
            let bp = self.basin[p];
            let mut look = |q: usize| {
                if dec[q] > f64::NEG_INFINITY && self.basin[q] != bp {
                    self.saddles.push((dec[p].min(dec[q]), bp, self.basin[q]));
                }
            };
            if col + 1 < width {
                look(p + 1);
            }
            if row + 1 < height {
                let up = p + width;
                look(up);
                if col > 0 {
                    look(up - 1);
                }
                if col + 1 < width {
                    look(up + 1);
                }
            }
        }
        // 3. Persistence merge, highest saddle first.
        self.saddles.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
        for i in 0..self.saddles.len() {
            let (s, a, b) = self.saddles[i];
            let (ra, rb) = (self.find(a), self.find(b));
            if ra == rb {
                continue;
            }
            let (pa, pb) = (self.dec[ra as usize], self.dec[rb as usize]);
            let lower = pa.min(pb);
            if lower <= 0.0 || lower < min_peak || lower - s < depth * lower {
                // The lower peak is not a contact of its own: it joins the higher.
                let (hi, lo) = if pa >= pb { (ra, rb) } else { (rb, ra) };
                self.set[lo as usize] = hi;
            }
        }
        // Compact labels in row-major order of first appearance (`fg` is in row-major order).
        labels.fill(0);
        let mut k = 0u32;
        for i in 0..self.fg.len() {
            let p = self.fg[i] as usize;
            let root = self.find(self.basin[p]) as usize;
            if self.compact[root] == 0 {
                k += 1;
                self.compact[root] = k;
            }
            labels[p] = self.compact[root];
        }
        for i in 0..self.fg.len() {
            let root = self.find(self.basin[self.fg[i] as usize]) as usize;
            self.compact[root] = 0;
        }
        k
    }

    /// The foreground pixels of the last [`Separator::run`], row-major.
    pub fn foreground(&self) -> &[u32] {
        &self.fg
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two Gaussian bumps on a 40 x 20 grid at x = 10 and 30 with the given heights.
    fn two_bumps(h1: f64, h2: f64, sigma: f64) -> Vec<f64> {
        let mut d = vec![0.0; 800];
        for (p, v) in d.iter_mut().enumerate() {
            let (x, y) = ((p % 40) as f64, (p / 40) as f64);
            let g = |cx: f64| (-((x - cx).powi(2) + (y - 10.0).powi(2)) / (2.0 * sigma * sigma)).exp();
            *v = h1 * g(10.0) + h2 * g(30.0);
        }
        d
    }

    fn run(d: &[f64], depth: f64) -> (u32, Vec<u32>) {
        let mask: Vec<u8> = d.iter().map(|&v| u8::from(v > 0.05)).collect();
        let mut labels = vec![0; d.len()];
        let image: Vec<f64> = d.iter().map(|v| -v).collect();
        let k = Separator::new(d.len()).run(40, 20, &image, &mask, depth, 0.05, &mut labels);
        (k, labels)
    }

    #[test]
    fn two_peaks_with_a_deep_saddle_are_two_regions() {
        let d = two_bumps(1.0, 0.6, 5.0);
        let (k, labels) = run(&d, 0.2);
        assert_eq!(k, 2);
        // Each peak lies in its own region, and the regions meet near the saddle.
        assert_ne!(labels[10 * 40 + 10], labels[10 * 40 + 30]);
        assert!(labels.iter().all(|&l| l <= 2));
    }

    #[test]
    fn a_shallow_saddle_or_a_single_maximum_stays_one_region() {
        // Close bumps: the saddle is within 20 % of the lower peak.
        let (k, _) = run(&two_bumps(1.0, 1.0, 12.0), 0.2);
        assert_eq!(k, 1);
        // One bump with ripples of 2 %: the ripples merge back.
        let mut d = two_bumps(1.0, 0.0, 8.0);
        for (p, v) in d.iter_mut().enumerate() {
            *v += 0.02 * ((p % 7) as f64 / 7.0);
        }
        let (k, _) = run(&d, 0.2);
        assert_eq!(k, 1);
    }

    #[test]
    fn separate_components_keep_separate_labels_and_buffers_are_reusable() {
        let d = two_bumps(1.0, 1.0, 3.0); // far apart: two components already
        let mask: Vec<u8> = d.iter().map(|&v| u8::from(v > 0.05)).collect();
        let d: Vec<f64> = d.iter().map(|v| -v).collect();
        let mut labels = vec![0; 800];
        let mut sep = Separator::new(800);
        for _ in 0..3 {
            assert_eq!(sep.run(40, 20, &d, &mask, 0.2, 0.05, &mut labels), 2);
        }
        assert_eq!(sep.run(40, 20, &d, &[0; 800], 0.2, 0.05, &mut labels), 0);
        assert!(labels.iter().all(|&l| l == 0));
        // Flat NaN or sub-cut pixels the closing let in never make regions of their own.
        let flat = vec![f64::NAN; 800];
        assert_eq!(sep.run(40, 20, &flat, &[1; 800], 0.2, 0.05, &mut labels), 1);
    }
}
