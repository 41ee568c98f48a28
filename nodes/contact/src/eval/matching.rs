//! One-to-one matching of predicted to true contacts (CONTRACTS.md §4).
//!
//! Rule: first the largest number of pairs at most `max_dist_mm` apart, then among those the
//! smallest total distance. Solved exactly as a rectangular assignment problem (Hungarian
//! algorithm, O(n^3)) with cost `d - M` for allowed pairs and 0 otherwise, where
//! `M` exceeds any possible total distance, so one more pair always beats any distance saving.

/// A matched pair: indices into the predicted and true lists, and their distance (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// Index of the predicted contact.
    pub pred: usize,
    /// Index of the true contact.
    pub truth: usize,
    /// Euclidean distance, mm.
    pub dist_mm: f64,
}

/// Minimum-cost assignment of rows to columns of a square `n x n` cost matrix (row-major);
/// returns the column of every row. Potentials-based Hungarian algorithm.
pub fn assign(cost: &[f64], n: usize) -> Vec<usize> {
    const INF: f64 = f64::INFINITY;
    // 1-based arrays with a virtual column 0, as in the classic shortest-augmenting-path form.
    let (mut u, mut v) = (vec![0.0; n + 1], vec![0.0; n + 1]);
    let (mut p, mut way) = (vec![0usize; n + 1], vec![0usize; n + 1]);
    for i in 1..=n {
        p[0] = i;
        let mut j0 = 0;
        let mut minv = vec![INF; n + 1];
        let mut used = vec![false; n + 1];
        loop {
            used[j0] = true;
            let i0 = p[j0];
            let mut delta = INF;
            let mut j1 = 0;
            for j in 1..=n {
                if !used[j] {
                    let cur = cost[(i0 - 1) * n + (j - 1)] - u[i0] - v[j];
                    if cur < minv[j] {
                        minv[j] = cur;
                        way[j] = j0;
                    }
                    if minv[j] < delta {
                        delta = minv[j];
                        j1 = j;
                    }
                }
            }
            for j in 0..=n {
                if used[j] {
                    u[p[j]] += delta;
                    v[j] -= delta;
                } else {
                    minv[j] -= delta;
                }
            }
            j0 = j1;
            if p[j0] == 0 {
                break;
            }
        }
        loop {
            let j1 = way[j0];
            p[j0] = p[j1];
            j0 = j1;
            if j0 == 0 {
                break;
            }
        }
    }
    let mut row_to_col = vec![0; n];
    for j in 1..=n {
        if p[j] > 0 {
            row_to_col[p[j] - 1] = j - 1;
        }
    }
    row_to_col
}

/// Matches predicted to true positions (mm); pairs sorted by predicted index.
pub fn match_contacts(pred: &[(f64, f64)], truth: &[(f64, f64)], max_dist_mm: f64) -> Vec<Pair> {
    let n = pred.len().max(truth.len());
    if pred.is_empty() || truth.is_empty() {
        return Vec::new();
    }
    let dist = |i: usize, j: usize| (pred[i].0 - truth[j].0).hypot(pred[i].1 - truth[j].1);
    let big = max_dist_mm * (n as f64 + 1.0) + 1.0;
    let mut cost = vec![0.0; n * n];
    for i in 0..pred.len() {
        for j in 0..truth.len() {
            let d = dist(i, j);
            if d <= max_dist_mm {
                cost[i * n + j] = d - big;
            }
        }
    }
    let cols = assign(&cost, n);
    (0..pred.len())
        .filter_map(|i| {
            let j = cols[i];
            (j < truth.len() && dist(i, j) <= max_dist_mm).then(|| Pair { pred: i, truth: j, dist_mm: dist(i, j) })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exhaustive reference: best (pairs, -distance) over all injective partial assignments.
    fn brute(pred: &[(f64, f64)], truth: &[(f64, f64)], max: f64) -> (usize, f64) {
        fn rec(i: usize, pred: &[(f64, f64)], truth: &[(f64, f64)], used: &mut Vec<bool>, max: f64) -> (usize, f64) {
            if i == pred.len() {
                return (0, 0.0);
            }
            let mut best = rec(i + 1, pred, truth, used, max);
            for j in 0..truth.len() {
                let d = (pred[i].0 - truth[j].0).hypot(pred[i].1 - truth[j].1);
                if !used[j] && d <= max {
                    used[j] = true;
                    let (n, s) = rec(i + 1, pred, truth, used, max);
                    used[j] = false;
                    if n + 1 > best.0 || (n + 1 == best.0 && s + d < best.1) {
                        best = (n + 1, s + d);
                    }
                }
            }
            best
        }
        rec(0, pred, truth, &mut vec![false; truth.len()], max)
    }

    #[test]
    fn more_pairs_beat_a_smaller_total_distance() {
        // p0 is 1 mm from t0 and 10 mm from t1; p1 is 14 mm from t0 only. Greedy nearest
        // would pair p0-t0 and leave p1 unmatched; the rule wants two pairs: p0-t1, p1-t0.
        let pred = [(0.0, 0.0), (-13.0, 0.0)];
        let truth = [(1.0, 0.0), (0.0, 10.0)];
        let m = match_contacts(&pred, &truth, 15.0);
        assert_eq!(m.len(), 2);
        assert_eq!((m[0].pred, m[0].truth, m[1].pred, m[1].truth), (0, 1, 1, 0));
    }

    #[test]
    fn pairs_farther_than_the_limit_are_not_matched() {
        let m = match_contacts(&[(0.0, 0.0)], &[(15.5, 0.0)], 15.0);
        assert!(m.is_empty());
        let m = match_contacts(&[(0.0, 0.0)], &[(15.0, 0.0)], 15.0);
        assert_eq!(m.len(), 1);
        assert!(match_contacts(&[], &[(0.0, 0.0)], 15.0).is_empty());
    }

    #[test]
    fn hungarian_agrees_with_exhaustive_search() {
        // Deterministic pseudo-random layouts with up to 5 x 6 contacts.
        let mut state = 12345u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 33) as f64 / (1u64 << 31) as f64) * 40.0
        };
        for case in 0..300 {
            let (np, nt) = (case % 5 + 1, (case / 5) % 6 + 1);
            let pred: Vec<(f64, f64)> = (0..np).map(|_| (next(), next())).collect();
            let truth: Vec<(f64, f64)> = (0..nt).map(|_| (next(), next())).collect();
            let m = match_contacts(&pred, &truth, 15.0);
            let total: f64 = m.iter().map(|p| p.dist_mm).sum();
            let (bn, bd) = brute(&pred, &truth, 15.0);
            assert_eq!(m.len(), bn, "case {case}");
            assert!((total - bd).abs() < 1e-9, "case {case}: {total} vs {bd}");
        }
    }
}
