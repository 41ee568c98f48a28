//! Choosing lambda by generalised cross-validation (GCV) on difference frames.
//!
//! With the dual system's eigendecomposition K = U diag(s) U^T (K = J R^-1 J^T, normalised), the
//! influence matrix is A = K (K + lambda^2 I)^-1 = U diag(s / (s + lambda^2)) U^T, so
//! GCV(lambda) = M |(I - A) dv|^2 / tr(I - A)^2 costs O(M) per lambda after one projection
//! b = U^T dv per frame. Scores are summed over the frames given. The minimum over a logarithmic
//! sweep is chosen; the whole curve is returned so the choice can be reported and plotted.

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
    /// (lambda, score) over the sweep, ascending lambda.
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
    let s = dual.eigenvalues();
    let mut curve = Vec::with_capacity(lambdas.len());
    for &lambda in lambdas {
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(invalid("lambda sweep", format!("values must be finite and > 0 (got {lambda})")));
        }
        let l2 = lambda * lambda;
        let trace: f64 = s.iter().map(|&x| l2 / (x + l2)).sum();
        let resid: f64 =
            projections.iter().map(|b| b.iter().zip(s).map(|(bk, &x)| (l2 / (x + l2) * bk).powi(2)).sum::<f64>()).sum();
        curve.push((lambda, m as f64 * resid / (trace * trace)));
    }
    let best = curve.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1)).expect("non-empty sweep");
    Ok(LambdaChoice { lambda: best.0, method: LambdaMethod::Gcv, curve })
}
