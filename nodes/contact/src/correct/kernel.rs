//! A smooth field through per-site values: Gaussian-kernel ridge regression with its length and
//! ridge chosen by leave-one-site-out cross-validation.
//!
//! Calibration data come as sites (indenter positions) with one fitted value each (the local
//! EIT sensitivity, the local pneumatic sensitivity). The paper's quadratic fields cannot follow
//! local structure such as a soft patch of foam or the stiff rim; this field can, and it reverts
//! to the mean between sites farther apart than its length:
//!
//! ```text
//! f(p) = mean + sum_j alpha_j exp(-|p - p_j|^2 / (2 length^2)),   p clamped onto the region
//! ```
//!
//! `alpha = (K + ridge I)^-1 (v - mean)`; the leave-one-out residual of site j has the closed
//! form `alpha_j / [(K + ridge I)^-1]_jj`. The constant field (no kernel) competes too and is
//! kept unless the kernel beats it by [`KERNEL_MARGIN`].

use super::field::Region;
use serde::{Deserialize, Serialize};

/// Kernel lengths (mm) searched.
const LENGTHS_MM: [f64; 7] = [8.0, 12.0, 16.0, 24.0, 32.0, 48.0, 64.0];
/// Ridge weights searched (relative to the kernel's unit diagonal).
const RIDGES: [f64; 8] = [0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0];
/// Relative leave-one-site-out improvement the kernel needs over the constant field.
pub const KERNEL_MARGIN: f64 = 0.2;

/// f(x, y) = mean + sum_j alpha_j exp(-|p - p_j|^2 / (2 length^2)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KernelField {
    /// The evaluation point is clamped onto this region.
    pub region: Region,
    /// The field's constant part (the mean of the site values for a constant field).
    pub mean: f64,
    /// Kernel length, mm.
    pub length_mm: f64,
    /// Kernel centres and weights, [x_mm, y_mm, alpha]; empty for a constant field.
    pub sites: Vec<[f64; 3]>,
    /// Leave-one-site-out RMSE of the chosen field (absent when not cross-validated).
    pub loo_rmse: Option<f64>,
}

impl KernelField {
    /// The constant field `value`.
    pub fn constant(region: Region, value: f64) -> Self {
        Self { region, mean: value, length_mm: 1.0, sites: Vec::new(), loo_rmse: None }
    }

    /// The value at a point (mm), clamped onto the region; a non-finite point is taken at the
    /// region's centre.
    pub fn at(&self, x_mm: f64, y_mm: f64) -> f64 {
        if self.sites.is_empty() {
            return self.mean;
        }
        let ((x, y), _) = self.region.clamp(x_mm, y_mm);
        let inv = -0.5 / (self.length_mm * self.length_mm);
        self.mean
            + self.sites.iter().map(|s| s[2] * (((x - s[0]).powi(2) + (y - s[1]).powi(2)) * inv).exp()).sum::<f64>()
    }

    /// Fits the field through `sites` = (x_mm, y_mm, value). Fewer than 3 sites, or sites the
    /// kernel cannot improve on, give the constant field of their mean.
    pub fn fit(region: Region, sites: &[(f64, f64, f64)]) -> Self {
        let n = sites.len();
        let mean = if n > 0 { sites.iter().map(|s| s.2).sum::<f64>() / n as f64 } else { 0.0 };
        let mut out = Self::constant(region, mean);
        if n < 3 {
            return out;
        }
        // Constant field: leaving site j out moves the mean, residual r_j n / (n - 1).
        let ss: f64 = sites.iter().map(|s| (s.2 - mean).powi(2)).sum();
        let constant = (ss / n as f64).sqrt() * n as f64 / (n as f64 - 1.0);
        out.loo_rmse = Some(constant);
        // Sites that agree to rounding are a constant field.
        if constant <= 1e-12 * mean.abs().max(1e-300) {
            return out;
        }
        // The kernel model is v = mu + K alpha with mu estimated too: the bordered system
        // [[K + ridge I, 1], [1^T, 0]] [alpha; mu] = [v; 0]. Its leave-one-out residuals are
        // (A^-1 [v; 0])_j / (A^-1)_jj (mu re-estimated without site j, as for the constant).
        let v = nalgebra::DVector::from_iterator(n + 1, sites.iter().map(|s| s.2).chain(std::iter::once(0.0)));
        let mut best: Option<(f64, f64, nalgebra::DVector<f64>)> = None;
        for &len in &LENGTHS_MM {
            let inv = -0.5 / (len * len);
            for &ridge in &RIDGES {
                let a = nalgebra::DMatrix::from_fn(n + 1, n + 1, |i, j| match (i < n, j < n) {
                    (true, true) => {
                        let k = (((sites[i].0 - sites[j].0).powi(2) + (sites[i].1 - sites[j].1).powi(2)) * inv).exp();
                        if i == j { k + ridge } else { k }
                    }
                    (false, false) => 0.0,
                    _ => 1.0,
                });
                let Some(a_inv) = a.try_inverse() else { continue };
                let sol = &a_inv * &v;
                let loo = ((0..n).map(|j| (sol[j] / a_inv[(j, j)]).powi(2)).sum::<f64>() / n as f64).sqrt();
                if loo.is_finite() && best.as_ref().is_none_or(|b| loo < b.0) {
                    best = Some((loo, len, sol));
                }
            }
        }
        if let Some((loo, len, sol)) = best
            && loo < (1.0 - KERNEL_MARGIN) * constant
        {
            out.mean = sol[n];
            out.length_mm = len;
            out.sites = sites.iter().zip(sol.iter()).map(|(s, a)| [s.0, s.1, *a]).collect();
            out.loo_rmse = Some(loo);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn region() -> Region {
        Region { x_min_mm: -40.0, x_max_mm: 40.0, y_min_mm: -40.0, y_max_mm: 40.0 }
    }

    fn grid(f: impl Fn(f64, f64) -> f64) -> Vec<(f64, f64, f64)> {
        let mut out = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                let (x, y) = (-40.0 + 20.0 * f64::from(i), -40.0 + 20.0 * f64::from(j));
                out.push((x, y, f(x, y)));
            }
        }
        out
    }

    #[test]
    fn a_local_bump_is_followed_between_the_sites() {
        let f = |x: f64, y: f64| 1.0 + (-((x + 40.0).powi(2) + (y + 40.0).powi(2)) / 800.0).exp();
        let k = KernelField::fit(region(), &grid(f));
        assert!(!k.sites.is_empty());
        for (x, y) in [(-40.0, -40.0), (-30.0, -30.0), (0.0, 0.0), (40.0, -20.0)] {
            // Within 5 % of the value between sites 20 mm apart (the bump's sigma is 20 mm).
            assert!((k.at(x, y) - f(x, y)).abs() < 0.05 * f(x, y), "({x}, {y}): {} vs {}", k.at(x, y), f(x, y));
        }
        // Outside the region the value is the boundary's; a NaN point is the centre's.
        assert_eq!(k.at(-60.0, -70.0), k.at(-40.0, -40.0));
        assert_eq!(k.at(f64::NAN, 3.0), k.at(0.0, 0.0));
    }

    #[test]
    fn noise_without_spatial_structure_keeps_the_constant_field() {
        // Independent noise at each site of small grids: leaving a site out must not favour
        // the kernel (which would pass through every site's noise).
        let mut kernels = 0;
        for seed in 0..50u64 {
            let noise = |x: f64, y: f64| {
                let h = (x * 12.9898 + y * 78.233 + seed as f64 * 37.719).sin() * 43_758.545_3;
                h - h.floor() - 0.5
            };
            let sites: Vec<(f64, f64, f64)> = grid(noise).into_iter().step_by(2).collect();
            if !KernelField::fit(region(), &sites).sites.is_empty() {
                kernels += 1;
            }
        }
        assert!(kernels <= 10, "kernel chosen on pure noise in {kernels} of 50 grids");
    }

    #[test]
    fn flat_or_too_few_sites_give_the_constant_field() {
        let k = KernelField::fit(region(), &grid(|_, _| 0.25));
        assert!(k.sites.is_empty());
        assert_eq!(k.at(11.0, 7.0), 0.25);
        let k = KernelField::fit(region(), &[(0.0, 0.0, 2.0), (10.0, 0.0, 4.0)]);
        assert!(k.sites.is_empty() && k.at(5.0, 5.0) == 3.0);
        assert_eq!(KernelField::fit(region(), &[]).at(0.0, 0.0), 0.0);
    }
}
