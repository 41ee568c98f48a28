//! Crosstalk between contacts, by the reconstruction's point spread: sidelobes that are not
//! presses, and the part of one contact's conductivity sum that another contact spilled into it.
//!
//! A one-step EIT reconstruction is linear, so an image of k presses is, to first order, the sum
//! of k point-spread images, each scaled by its press's depth. Over contact i's ROI that reads
//!
//! ```text
//! S_i = sum_j a_j P_ij,    P_ij = sum over ROI_i of the point-spread image of a unit source at
//!                                 contact j's centroid = w_i . u_j
//! ```
//!
//! with S_i the contact's conductivity sum C_i, a_j the unknown depths, u_j the data of a unit
//! source at contact j and w_i the sum of the image matrix's rows over ROI i (both given by a
//! [`PointSpread`], w_i as a sum over the ROI's runs of consecutive pixels). Solving the k x k system gives each contact's own share `a_i P_ii / S_i`:
//! about 1 for a press, about 0 for a region that only the other contacts' sidelobes put there (a
//! "ghost": on the paper's square sensor, a press near a corner mirrors across the corner's
//! diagonal at a fifth of its peak). Regions whose own share is below `ghost_share` are removed
//! one at a time, weakest share first, re-solving after each; with `deblend`, each remaining
//! contact's sum becomes its own share `S_i - sum_{j != i} a_j P_ij` (>= 0), which is what the
//! proportional split of the pressure needs. Centroids, areas and peaks are left as segmented.
//!
//! The model is linear and the source a fixed disc, so it is first order: real presses are
//! nonlinear (a deep press images wider and flatter than the linear model says), which is why a
//! ghost is judged by a share threshold and not by a share of exactly zero.

use super::{Contacts, SegmentParams};

/// The linear image model of a reconstruction, as far as crosstalk needs it. Implemented by the
/// EIT reconstructor (`skinflow_eit::PointSpread`); the segmenter knows nothing of EIT.
///
/// Conventions: the predicted DECREASE at pixel q (image units, positive for a press) of a
/// source of depth `a` at (x, y) is `a * row_q . u(x, y)`.
pub trait PointSpread: Send + Sync {
    /// Length of `u` and of a row.
    fn data_len(&self) -> usize;
    /// `out = u(x, y)`, the data of a unit source centred at (x, y) mm. Must not allocate.
    fn source_into(&self, x_mm: f64, y_mm: f64, out: &mut [f64]);
    /// `out += sum of row_q for q in first..end` (row-major image indices; a run may cross
    /// image rows). The pass calls it once per run of consecutive ROI pixels of one contact, so
    /// an implementation that keeps running sums of its rows answers in O(data_len) per run.
    /// Must not allocate.
    fn add_pixel_run(&self, first: usize, end: usize, out: &mut [f64]);
}

/// What a crosstalk pass did to one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CrosstalkOutcome {
    /// Regions removed as sidelobes of the other contacts.
    pub ghosts: usize,
    /// False when the k x k system was singular or not finite (the contacts were left as
    /// segmented).
    pub solved: bool,
}

/// Scratch of the crosstalk pass (sized on first use, then reused).
#[derive(Debug, Clone, Default)]
pub(crate) struct Crosstalk {
    m: usize,
    /// Contact index of each region label (`u32::MAX`: not a reported contact).
    slot: Vec<u32>,
    u: Vec<f64>,
    w: Vec<f64>,
    p: Vec<f64>,
    lu: Vec<f64>,
    rhs: Vec<f64>,
    alive: Vec<bool>,
    index: Vec<usize>,
}

impl Crosstalk {
    /// Sizes the buffers for `labels` region labels, `k_max` contacts and data length `m`.
    fn reserve(&mut self, labels: usize, k_max: usize, m: usize) {
        if self.slot.len() < labels {
            self.slot.resize(labels, u32::MAX);
        }
        if self.m != m || self.alive.len() < k_max {
            self.m = m;
            self.u = vec![0.0; k_max * m];
            self.w = vec![0.0; k_max * m];
            self.p = vec![0.0; k_max * k_max];
            self.lu = vec![0.0; k_max * k_max];
            self.rhs = vec![0.0; k_max];
            self.alive = vec![false; k_max];
            self.index = vec![0; k_max];
        }
    }

    /// The pass itself; `in_roi(p)` gives the region label of pixel p when p is in its ROI.
    pub(crate) fn apply(
        &mut self,
        params: &SegmentParams,
        labels: usize,
        pixels: usize,
        in_roi: impl Fn(usize) -> Option<u32>,
        spread: &dyn PointSpread,
        out: &mut Contacts,
    ) -> CrosstalkOutcome {
        let k = out.len();
        let mut outcome = CrosstalkOutcome { ghosts: 0, solved: true };
        if k < 2 || (params.ghost_share <= 0.0 && !params.deblend) {
            return outcome;
        }
        let m = spread.data_len();
        self.reserve(labels, out.hold_len().max(k), m);
        for (i, c) in out.items.iter().enumerate() {
            self.slot[c.label as usize] = i as u32;
        }
        self.w[..k * m].fill(0.0);
        // w_i: the ROI's rows summed run by run (maximal runs of consecutive pixels that belong
        // to the same reported contact).
        let mut run: Option<(u32, usize)> = None;
        for p in 0..=pixels {
            let here =
                if p < pixels { in_roi(p).map(|l| self.slot[l as usize]).filter(|&i| i != u32::MAX) } else { None };
            if run.map(|(i, _)| i) != here {
                if let Some((i, first)) = run {
                    let i = i as usize;
                    spread.add_pixel_run(first, p, &mut self.w[i * m..(i + 1) * m]);
                }
                run = here.map(|i| (i, p));
            }
        }
        for (i, c) in out.items.iter().enumerate() {
            spread.source_into(c.x_mm, c.y_mm, &mut self.u[i * m..(i + 1) * m]);
            self.slot[c.label as usize] = u32::MAX;
        }
        for i in 0..k {
            for j in 0..k {
                let (wi, uj) = (&self.w[i * m..(i + 1) * m], &self.u[j * m..(j + 1) * m]);
                self.p[i * k + j] = wi.iter().zip(uj).map(|(a, b)| a * b).sum();
            }
        }
        self.alive[..k].fill(true);
        loop {
            let n = self.solve(k, out);
            if n == 0 {
                // Every contact stays, also any marked as a ghost before this solve.
                self.alive[..k].fill(true);
                return CrosstalkOutcome { ghosts: 0, solved: false };
            }
            // The weakest own share among the live contacts.
            let weakest = (0..n)
                .map(|r| {
                    let i = self.index[r];
                    (i, self.rhs[r] * self.p[i * k + i] / out.items[i].sum)
                })
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match weakest {
                Some((i, share)) if n > 1 && share < params.ghost_share => {
                    self.alive[i] = false;
                    outcome.ghosts += 1;
                }
                _ => break,
            }
        }
        if params.deblend {
            let n = (0..k).filter(|&i| self.alive[i]).count();
            for r in 0..n {
                let i = self.index[r];
                let own = self.rhs[r] * self.p[i * k + i];
                out.items[i].sum = own.max(0.0);
            }
        }
        let mut i = 0;
        out.items.retain(|_| {
            i += 1;
            self.alive[i - 1]
        });
        out.ghosts += outcome.ghosts;
        outcome
    }

    /// Solves the live contacts' system P a = S into `rhs[..n]` (depths, in `index` order).
    /// Returns n, or 0 when the system is singular or not finite.
    fn solve(&mut self, k: usize, out: &Contacts) -> usize {
        let mut n = 0;
        for i in 0..k {
            if self.alive[i] {
                self.index[n] = i;
                n += 1;
            }
        }
        let scale = self.p[..k * k].iter().fold(0.0f64, |s, v| s.max(v.abs()));
        if !(scale.is_finite() && scale > 0.0) {
            return 0;
        }
        for r in 0..n {
            for c in 0..n {
                self.lu[r * n + c] = self.p[self.index[r] * k + self.index[c]];
            }
            self.rhs[r] = out.items[self.index[r]].sum;
        }
        // Gaussian elimination with partial pivoting (n <= max_contacts, a handful).
        for col in 0..n {
            let piv = (col..n).max_by(|&a, &b| self.lu[a * n + col].abs().total_cmp(&self.lu[b * n + col].abs()));
            let piv = piv.expect("col < n");
            if self.lu[piv * n + col].abs() <= 1e-12 * scale {
                return 0;
            }
            if piv != col {
                for c in 0..n {
                    self.lu.swap(piv * n + c, col * n + c);
                }
                // Rows are equations: the unknowns (columns, `index`) keep their order.
                self.rhs.swap(piv, col);
            }
            for r in col + 1..n {
                let f = self.lu[r * n + col] / self.lu[col * n + col];
                for c in col..n {
                    self.lu[r * n + c] -= f * self.lu[col * n + c];
                }
                self.rhs[r] -= f * self.rhs[col];
            }
        }
        for r in (0..n).rev() {
            let mut s = self.rhs[r];
            for c in r + 1..n {
                s -= self.lu[r * n + c] * self.rhs[c];
            }
            self.rhs[r] = s / self.lu[r * n + r];
        }
        if self.rhs[..n].iter().all(|v| v.is_finite()) { n } else { 0 }
    }
}
