//! Least-squares fits used by the calibration: the quadratic signal-to-force map (paper eq. 11),
//! ridge regression towards a prior (the location-aware fields), and k-fold cross-validation
//! of one ridge weight per block of columns over a log grid.
//!
//! Design matrices are row-major `T x p` slices. Systems are solved by Cholesky on the
//! `p x p` normal equations (p <= ~14 here); columns are not rescaled, so callers keep
//! their regressors O(1) (normalized coordinates, forces in N). Folds are a fixed-seed
//! shuffle of the sample indices, so results are deterministic.

use std::ops::Range;

/// `y = a0 + a1 s + a2 s^2`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Quadratic {
    /// Constant term.
    pub a0: f64,
    /// Linear coefficient.
    pub a1: f64,
    /// Quadratic coefficient.
    pub a2: f64,
}

impl Quadratic {
    /// Value at `s`.
    pub fn at(&self, s: f64) -> f64 {
        self.a0 + s * (self.a1 + s * self.a2)
    }

    /// Derivative at `s`.
    pub fn slope(&self, s: f64) -> f64 {
        self.a1 + 2.0 * self.a2 * s
    }
}

impl Quadratic {
    /// The quadratic in `s` equal to `c0 + c1 t + c2 t^2` with `t = (s - mid) / half`.
    ///
    /// Expanding into powers of `s` is exact algebra, but evaluating the result far from 0
    /// cancels terms of size `|c2| (mid / half)^2`: [`Quadratic::at`] is then accurate to
    /// about `eps (|a0| + |a1 s| + |a2 s^2|)`, the rounding level of this representation.
    pub fn from_centred(c: [f64; 3], mid: f64, half: f64) -> Self {
        let (k1, k2) = (c[1] / half, c[2] / (half * half));
        Quadratic { a0: c[0] - k1 * mid + k2 * mid * mid, a1: k1 - 2.0 * k2 * mid, a2: k2 }
    }
}

/// Least-squares quadratic through `(s, y)`; `None` with fewer than 3 points or fewer than
/// 3 distinct `s` (the fit would be singular). See [`fit_polynomial`].
pub fn fit_quadratic(s: &[f64], y: &[f64]) -> Option<Quadratic> {
    fit_polynomial(s, y, 2)
}

/// Least-squares polynomial of `degree` 1 (a line, `a2 = 0`) or 2 through `(s, y)`; `None`
/// with fewer than `degree + 1` points or distinct `s`, non-finite input, or another degree.
///
/// The signal is centred and scaled onto [-1, 1] (`t = (s - mid) / half`) before the normal
/// equations are formed, and the coefficients are mapped back ([`Quadratic::from_centred`]).
/// Scaling alone (`s / max|s|`) leaves an offset signal, e.g. `1e4 + [0, 10]`, with columns
/// `1, t, t^2` that agree to 1e-3 and a Gram matrix whose condition number is ~1e18: the
/// solve then loses every digit. Centred, the Gram matrix of `[1, t, t^2]` on [-1, 1] is
/// well conditioned whatever the offset.
pub fn fit_polynomial(s: &[f64], y: &[f64], degree: usize) -> Option<Quadratic> {
    if !(1..=2).contains(&degree) || s.len() != y.len() || s.len() <= degree {
        return None;
    }
    if !s.iter().chain(y).all(|v| v.is_finite()) {
        return None;
    }
    let mut distinct = s.to_vec();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    if distinct.len() <= degree {
        return None;
    }
    let (lo, hi) = (distinct[0], distinct[distinct.len() - 1]);
    let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    if !(half > 0.0 && half.is_finite()) {
        return None;
    }
    let p = degree + 1;
    let design: Vec<f64> = s
        .iter()
        .flat_map(|&v| {
            let t = (v - mid) / half;
            [1.0, t, t * t].into_iter().take(p)
        })
        .collect();
    let c = ridge(&design, y, p, &[0.0; 3][..p], &[0.0; 3][..p])?;
    Some(Quadratic::from_centred([c[0], c[1], if degree == 2 { c[2] } else { 0.0 }], mid, half))
}

/// Least-squares line through the origin, `y = a1 s`; `None` when every `s` is 0 or an input
/// is not finite. The map used when the calibration saw one force level: the slope is then
/// fixed by that level and by no load giving no force.
pub fn fit_proportional(s: &[f64], y: &[f64]) -> Option<Quadratic> {
    if s.len() != y.len() || !s.iter().chain(y).all(|v| v.is_finite()) {
        return None;
    }
    let ss: f64 = s.iter().map(|v| v * v).sum();
    let sy: f64 = s.iter().zip(y).map(|(a, b)| a * b).sum();
    let a1 = sy / ss;
    (ss > 0.0 && a1.is_finite()).then_some(Quadratic { a0: 0.0, a1, a2: 0.0 })
}

/// The family f is fitted in, chosen by how many force levels the calibration saw
/// ([`super::quality::force_levels`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FShape {
    /// `a0 + a1 s + a2 s^2` (the paper's eq. 11): three or more levels.
    Quadratic,
    /// `a0 + a1 s`: two levels fix a line. A quadratic through two clusters of signals takes
    /// its curvature from how the signal varies across locations within a level, which is the
    /// location effect the fields are for (5 N read as 6.1 N at the centre in the audit).
    Line,
    /// `a1 s`: one level fixes only a slope, through no load giving no force.
    Proportional,
}

impl FShape {
    /// The shape for `levels` distinct force levels.
    pub fn for_levels(levels: usize) -> Self {
        match levels {
            0 | 1 => FShape::Proportional,
            2 => FShape::Line,
            _ => FShape::Quadratic,
        }
    }

    /// Least-squares fit of this shape through `(s, y)` (see [`fit_polynomial`] and
    /// [`fit_proportional`]).
    pub fn fit(self, s: &[f64], y: &[f64]) -> Option<Quadratic> {
        match self {
            FShape::Quadratic => fit_polynomial(s, y, 2),
            FShape::Line => fit_polynomial(s, y, 1),
            FShape::Proportional => fit_proportional(s, y),
        }
    }
}

/// Coefficient of determination of predictions `pred` for observations `y`
/// (1 - SS_res / SS_tot); `None` when `y` has no spread or fewer than 2 points.
pub fn r_squared(y: &[f64], pred: &[f64]) -> Option<f64> {
    if y.len() < 2 || y.len() != pred.len() {
        return None;
    }
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let ss_tot: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
    let ss_res: f64 = y.iter().zip(pred).map(|(a, b)| (a - b).powi(2)).sum();
    (ss_tot > 0.0).then(|| 1.0 - ss_res / ss_tot)
}

/// In-place Cholesky solve of the SPD system `m x = b` (`m` is `p x p` row-major, only the
/// lower triangle is read, and is overwritten). Returns false if a pivot is not positive.
pub fn solve_spd(m: &mut [f64], b: &mut [f64], p: usize) -> bool {
    for j in 0..p {
        let mut d = m[j * p + j];
        for k in 0..j {
            d -= m[j * p + k] * m[j * p + k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        m[j * p + j] = d;
        for i in j + 1..p {
            let mut v = m[i * p + j];
            for k in 0..j {
                v -= m[i * p + k] * m[j * p + k];
            }
            m[i * p + j] = v / d;
        }
    }
    for i in 0..p {
        let mut v = b[i];
        for k in 0..i {
            v -= m[i * p + k] * b[k];
        }
        b[i] = v / m[i * p + i];
    }
    for i in (0..p).rev() {
        let mut v = b[i];
        for k in i + 1..p {
            v -= m[k * p + i] * b[k];
        }
        b[i] = v / m[i * p + i];
    }
    true
}

/// Normal equations `X^T X` and `X^T y` of the rows in `rows`.
fn gram(design: &[f64], y: &[f64], p: usize, rows: impl Iterator<Item = usize>) -> (Vec<f64>, Vec<f64>) {
    let (mut g, mut r) = (vec![0.0; p * p], vec![0.0; p]);
    for t in rows {
        let x = &design[t * p..(t + 1) * p];
        for i in 0..p {
            r[i] += x[i] * y[t];
            for j in 0..=i {
                g[i * p + j] += x[i] * x[j];
            }
        }
    }
    (g, r)
}

fn solve_penalized(g: &[f64], r: &[f64], p: usize, penalty: &[f64], prior: &[f64]) -> Option<Vec<f64>> {
    let mut m = g.to_vec();
    let mut b = r.to_vec();
    for i in 0..p {
        m[i * p + i] += penalty[i];
        b[i] += penalty[i] * prior[i];
    }
    solve_spd(&mut m, &mut b, p).then_some(b)
}

/// Ridge regression: argmin ||X c - y||^2 + sum_i penalty_i (c_i - prior_i)^2.
/// `None` if the penalized normal matrix is not positive definite.
pub fn ridge(design: &[f64], y: &[f64], p: usize, penalty: &[f64], prior: &[f64]) -> Option<Vec<f64>> {
    let (g, r) = gram(design, y, p, 0..y.len());
    solve_penalized(&g, &r, p, penalty, prior)
}

/// The fold (0..k) of every sample: a fixed-seed Fisher-Yates shuffle dealt round-robin, so
/// samples recorded in order (location by location, force by force) mix across folds.
pub fn fold_of(n: usize, k: usize) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..n).collect();
    let mut state = 0x5eed_5eed_5eed_5eed_u64;
    let mut next = || {
        // splitmix64
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    for i in (1..n).rev() {
        idx.swap(i, (next() % (i as u64 + 1)) as usize);
    }
    let mut fold = vec![0; n];
    for (pos, &i) in idx.iter().enumerate() {
        fold[i] = pos % k.max(1);
    }
    fold
}

/// Result of a cross-validated ridge fit.
#[derive(Debug, Clone, PartialEq)]
pub struct CvFit {
    /// Coefficients refitted on all samples with the chosen weights.
    pub coeffs: Vec<f64>,
    /// Chosen ridge weight of each block.
    pub lambdas: Vec<f64>,
    /// Mean squared held-out error at the chosen weights.
    pub cv_mse: f64,
    /// Number of folds used.
    pub folds: usize,
}

/// A ridge problem: argmin ||X c - y||^2 + sum_i penalty_i (c_i - prior_i)^2.
#[derive(Debug, Clone, Copy)]
pub struct RidgeProblem<'a> {
    /// `X`, row-major `T x p`.
    pub design: &'a [f64],
    /// `y`, length `T`.
    pub y: &'a [f64],
    /// Number of columns.
    pub p: usize,
    /// Prior the penalty pulls towards, length `p`.
    pub prior: &'a [f64],
    /// Fixed penalty per column (0 = free), added to the searched block weights.
    pub base_penalty: &'a [f64],
}

/// What [`cross_validate`] searches: one weight per column block, each from `grid`.
#[derive(Debug, Clone, Copy)]
pub struct CvSearch<'a> {
    /// Column blocks sharing one weight.
    pub blocks: &'a [Range<usize>],
    /// Candidate weights (the full grid is searched for every block).
    pub grid: &'a [f64],
    /// Number of folds (clamped to [2, T], or to [2, groups] with `groups`).
    pub folds: usize,
    /// Group id of every sample (e.g. its location; one entry per sample, any ids), or `None`
    /// (samples dealt one by one): whole groups are dealt into the folds, so a held-out sample
    /// never has a sibling of its group in training.
    pub groups: Option<&'a [usize]>,
}

/// Chooses one ridge weight per column block by k-fold CV (held-out MSE; on a tie the larger
/// weights win), then refits on all samples. `None` when no weight combination gives a
/// solvable system, or with `groups` of fewer than two distinct ids (nothing to hold out).
pub fn cross_validate(problem: &RidgeProblem, search: &CvSearch) -> Option<CvFit> {
    let RidgeProblem { design, y, p, prior, base_penalty } = *problem;
    let CvSearch { blocks, grid, folds, groups } = *search;
    let n = y.len();
    let (k, fold) = match groups {
        Some(g) => {
            assert_eq!(g.len(), n, "cross_validate: one group per sample");
            let mut ids = g.to_vec();
            ids.sort_unstable();
            ids.dedup();
            if ids.len() < 2 {
                return None;
            }
            let k = folds.clamp(2, ids.len());
            let of_group = fold_of(ids.len(), k);
            // Dense index of each id (ids sorted), so any ids deal evenly.
            let fold = g.iter().filter_map(|i| ids.binary_search(i).ok()).map(|d| of_group[d]).collect();
            (k, fold)
        }
        None => {
            let k = folds.clamp(2, n.max(2));
            (k, fold_of(n, k))
        }
    };
    let (g_all, r_all) = gram(design, y, p, 0..n);
    // Training normal equations of fold f = all minus the held-out rows.
    let train: Vec<(Vec<f64>, Vec<f64>)> = (0..k)
        .map(|f| {
            let (g, r) = gram(design, y, p, (0..n).filter(|&t| fold[t] == f));
            (g_all.iter().zip(&g).map(|(a, b)| a - b).collect(), r_all.iter().zip(&r).map(|(a, b)| a - b).collect())
        })
        .collect();
    let combos = grid.len().pow(blocks.len() as u32);
    let mut best: Option<(f64, Vec<f64>)> = None;
    let mut penalty = vec![0.0; p];
    for combo in 0..combos {
        let mut c = combo;
        let lambdas: Vec<f64> = blocks
            .iter()
            .map(|_| {
                let l = grid[c % grid.len()];
                c /= grid.len();
                l
            })
            .collect();
        penalty.copy_from_slice(base_penalty);
        for (block, &l) in blocks.iter().zip(&lambdas) {
            penalty[block.clone()].iter_mut().for_each(|v| *v += l);
        }
        let mut sse = 0.0;
        let mut ok = true;
        for (f, (g, r)) in train.iter().enumerate() {
            let Some(coef) = solve_penalized(g, r, p, &penalty, prior) else {
                ok = false;
                break;
            };
            for t in (0..n).filter(|&t| fold[t] == f) {
                let x = &design[t * p..(t + 1) * p];
                let pred: f64 = x.iter().zip(&coef).map(|(a, b)| a * b).sum();
                sse += (pred - y[t]).powi(2);
            }
        }
        if !ok || !sse.is_finite() {
            continue;
        }
        let mse = sse / n as f64;
        let better = match &best {
            None => true,
            Some((b, bl)) => {
                let tol = 1e-12 * b.abs().max(f64::MIN_POSITIVE);
                mse < b - tol || (mse <= b + tol && lambdas.iter().sum::<f64>() > bl.iter().sum::<f64>())
            }
        };
        if better {
            best = Some((mse, lambdas));
        }
    }
    let (cv_mse, lambdas) = best?;
    penalty.copy_from_slice(base_penalty);
    for (block, &l) in blocks.iter().zip(&lambdas) {
        penalty[block.clone()].iter_mut().for_each(|v| *v += l);
    }
    let coeffs = solve_penalized(&g_all, &r_all, p, &penalty, prior)?;
    Some(CvFit { coeffs, lambdas, cv_mse, folds: k })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_fit_recovers_exact_coefficients() {
        let s: Vec<f64> = (0..10).map(|i| i as f64 * 0.7).collect();
        let y: Vec<f64> = s.iter().map(|v| 0.3 + 2.0 * v - 0.1 * v * v).collect();
        let q = fit_quadratic(&s, &y).unwrap();
        assert!((q.a0 - 0.3).abs() < 1e-9 && (q.a1 - 2.0).abs() < 1e-9 && (q.a2 + 0.1).abs() < 1e-9);
        let pred: Vec<f64> = s.iter().map(|&v| q.at(v)).collect();
        assert!((r_squared(&y, &pred).unwrap() - 1.0).abs() < 1e-12);
        assert!((q.slope(1.0) - 1.8).abs() < 1e-9);
    }

    #[test]
    fn line_and_proportional_fits() {
        let s = [1.0, 2.0, 2.0, 4.0];
        let y = [3.0, 5.0, 5.0, 9.0];
        let q = fit_polynomial(&s, &y, 1).unwrap();
        assert!((q.a0 - 1.0).abs() < 1e-12 && (q.a1 - 2.0).abs() < 1e-12 && q.a2 == 0.0, "{q:?}");
        assert!(fit_polynomial(&[2.0, 2.0], &[1.0, 1.0], 1).is_none());
        assert!(fit_polynomial(&s, &y, 3).is_none());
        // Through the origin: a1 = sum(s y) / sum(s^2) = (3 + 10 + 10 + 36) / 25.
        let p = fit_proportional(&s, &y).unwrap();
        assert!((p.a1 - 59.0 / 25.0).abs() < 1e-12 && p.a0 == 0.0 && p.a2 == 0.0, "{p:?}");
        assert!(fit_proportional(&[0.0, 0.0], &[1.0, 2.0]).is_none());
    }

    #[test]
    fn quadratic_fit_rejects_too_few_distinct_signals() {
        assert!(fit_quadratic(&[1.0, 1.0, 2.0, 2.0], &[1.0, 1.0, 2.0, 2.0]).is_none());
        assert!(fit_quadratic(&[1.0, 2.0], &[1.0, 2.0]).is_none());
    }

    #[test]
    fn r_squared_by_hand() {
        // y = [1, 2, 3], mean 2, SS_tot = 2; pred = [1, 2, 4], SS_res = 1 -> R^2 = 0.5
        assert_eq!(r_squared(&[1.0, 2.0, 3.0], &[1.0, 2.0, 4.0]), Some(0.5));
        assert_eq!(r_squared(&[1.0, 1.0], &[1.0, 1.0]), None);
    }

    #[test]
    fn cholesky_solves_a_known_system() {
        // m = [[4, 2], [2, 3]], x = [1, -1] -> b = [2, -1]
        let mut m = [4.0, 2.0, 2.0, 3.0];
        let mut b = [2.0, -1.0];
        assert!(solve_spd(&mut m, &mut b, 2));
        assert!((b[0] - 1.0).abs() < 1e-12 && (b[1] + 1.0).abs() < 1e-12);
        assert!(!solve_spd(&mut [1.0, 1.0, 1.0, 1.0], &mut [1.0, 1.0], 2));
    }

    #[test]
    fn ridge_with_huge_penalty_returns_the_prior() {
        let design = [1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let y = [5.0, 6.0, 7.0];
        let c = ridge(&design, &y, 2, &[1e12, 1e12], &[1.0, -2.0]).unwrap();
        assert!((c[0] - 1.0).abs() < 1e-6 && (c[1] + 2.0).abs() < 1e-6);
    }

    #[test]
    fn folds_are_balanced_and_deterministic() {
        let f = fold_of(23, 5);
        assert_eq!(f, fold_of(23, 5));
        for k in 0..5 {
            let n = f.iter().filter(|&&x| x == k).count();
            assert!(n == 4 || n == 5);
        }
    }

    /// One indicator column per group and y = the group's value: a held-out sample whose group
    /// is in training is predicted best with the least penalty, while a held-out group's
    /// coefficient is pinned to the prior by every penalty (a tie, which the larger weight
    /// wins). So sample folds choose the smallest weight and group folds the largest.
    #[test]
    fn grouped_folds_hold_out_whole_groups() {
        let (groups, per) = (6, 4);
        let n = groups * per;
        let mut design = vec![0.0; n * groups];
        let mut y = vec![0.0; n];
        let mut group = vec![0; n];
        for t in 0..n {
            group[t] = t % groups;
            design[t * groups + group[t]] = 1.0;
            y[t] = 1.0 + group[t] as f64;
        }
        let prior = vec![0.0; groups];
        let base = vec![0.0; groups];
        let problem = RidgeProblem { design: &design, y: &y, p: groups, prior: &prior, base_penalty: &base };
        let grid = [1e-3, 1.0, 1e3];
        let all = 0..groups;
        let blocks = std::slice::from_ref(&all);
        let by = |groups| cross_validate(&problem, &CvSearch { blocks, grid: &grid, folds: 3, groups });
        let samples = by(None).unwrap();
        let whole = by(Some(&group)).unwrap();
        assert_eq!(samples.lambdas, vec![1e-3]);
        assert_eq!(whole.lambdas, vec![1e3]);
        // Held-out groups are predicted by the prior 0: the CV error is the mean of y^2.
        let want = y.iter().map(|v| v * v).sum::<f64>() / n as f64;
        assert!((whole.cv_mse - want).abs() < 1e-9 * want, "{} vs {want}", whole.cv_mse);
        assert!(samples.cv_mse < 1e-3, "{}", samples.cv_mse);
        // Any ids: the same groups under sparse ids deal the same way.
        let sparse: Vec<usize> = group.iter().map(|&g| 1000 + 37 * g).collect();
        assert_eq!(by(Some(&sparse)), Some(whole));
        // One group leaves nothing to hold out.
        assert!(by(Some(&vec![7; n])).is_none());
    }
}
