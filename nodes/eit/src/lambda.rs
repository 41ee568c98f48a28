//! Choosing lambda by generalised cross-validation (GCV) on difference frames.
//!
//! With the dual system's eigendecomposition K = U diag(s) U^T (K = J R^-1 J^T, normalised), the
//! influence matrix is A = K (K + lambda^2 I)^-1 = U diag(s / (s + lambda^2)) U^T, so
//! GCV(lambda) = M |(I - A) dv|^2 / tr(I - A)^2 costs O(M) per lambda after one projection
//! b = U^T dv per frame. Scores are summed over the frames given. The minimum over a logarithmic
//! sweep is chosen; the whole curve is returned so the choice can be reported and plotted.
//!
//! GCV scores the estimator `DualSystem::matrix` builds, mode by mode from the same weights
//! (`DualSystem::mode_weights`): a clipped mode has filter factor 0, so its share of dv stays in
//! the residual and counts 1 in tr(I - A). Sweeps may go below `DualSystem::min_lambda`: there
//! the scored estimator, like `matrix`, is the pseudo-inverse truncated at the clip level.

use crate::error::{EitError, invalid};
use crate::noser::DualSystem;

/// Which rule chose lambda.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LambdaMethod {
    Gcv,
}

/// The chosen lambda and the evidence for it.
#[derive(Debug, Clone, PartialEq)]
pub struct LambdaChoice {
    pub lambda: f64,
    pub method: LambdaMethod,
    /// (lambda, score) over the sweep, in the sweep's order.
    pub curve: Vec<(f64, f64)>,
}

/// `n` values spaced logarithmically from `lo` to `hi` inclusive.
pub fn log_sweep(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if n < 2 {
        return vec![lo];
    }
    let (a, b) = (lo.ln(), hi.ln());
    (0..n).map(|k| (a + (b - a) * k as f64 / (n - 1) as f64).exp()).collect()
}

/// GCV over `lambdas` for difference frames `dvs` (each M values, in the dual system's units
/// and channel set).
pub fn gcv(dual: &DualSystem, dvs: &[&[f64]], lambdas: &[f64]) -> Result<LambdaChoice, EitError> {
    let m = dual.measurement_count();
    if dvs.is_empty() || lambdas.is_empty() {
        return Err(invalid("lambda sweep", "needs at least one frame and one lambda"));
    }
    let u = dual.eigenvectors();
    let mut projections = Vec::with_capacity(dvs.len());
    for dv in dvs {
        if dv.len() != m {
            return Err(EitError::Length { what: "difference frame", expected: m, got: dv.len() });
        }
        let b: Vec<f64> = (0..m).map(|k| u.col(k).iter().zip(dv.iter()).map(|(a, b)| a * b).sum()).collect();
        projections.push(b);
    }
    let mut curve = Vec::with_capacity(lambdas.len());
    let mut one_minus_filter = vec![0.0; m];
    for &lambda in lambdas {
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(invalid("lambda sweep", format!("values must be finite and > 0 (got {lambda})")));
        }
        let l2 = lambda * lambda;
        if l2 == 0.0 {
            return Err(invalid("lambda sweep", format!("{lambda:e} is too small: its square underflows to 0")));
        }
        // 1 - s w = l2 w for a kept mode (written so, it does not cancel when s >> l2), and 1
        // for a dropped one (w = 0).
        for (r, w) in one_minus_filter.iter_mut().zip(dual.mode_weights(l2)) {
            *r = if w == 0.0 { 1.0 } else { l2 * w };
        }
        let trace: f64 = one_minus_filter.iter().sum();
        let resid: f64 = projections
            .iter()
            .map(|b| b.iter().zip(&one_minus_filter).map(|(bk, r)| (r * bk).powi(2)).sum::<f64>())
            .sum();
        curve.push((lambda, m as f64 * resid / (trace * trace)));
    }
    // Difference frames that are all zero (no-load frames against their own reference) score
    // 0 at every lambda: the choice would be the sweep's first value, not the data's.
    if projections.iter().flatten().all(|&b| b == 0.0) {
        return Err(invalid(
            "lambda sweep",
            "every difference frame is zero (frames equal to the reference): GCV needs frames that differ from it",
        ));
    }
    if let Some(&(lambda, score)) = curve.iter().find(|(_, score)| !score.is_finite()) {
        return Err(invalid("lambda sweep", format!("the GCV score at lambda = {lambda} is {score}")));
    }
    let best = curve.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1)).expect("non-empty sweep");
    Ok(LambdaChoice { lambda: best.0, method: LambdaMethod::Gcv, curve })
}
