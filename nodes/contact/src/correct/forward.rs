//! The forward pneumatic model: the pressure change a contact causes, dP = P(F, x, y).
//!
//! The paper maps pressure to force (F = g f(dP) + b). That inverse form is fine for one
//! contact, but it cannot say how contacts add up: the sealed chamber sees the sum of the
//! volumes the contacts displace, so pressure, not force, is additive. This model is the
//! forward direction,
//!
//! ```text
//! P(F, x, y) = a(u, v) F + c F^2        (kPa; F in N; u, v the normalized coordinates)
//! ```
//!
//! with `a` a quadratic field (kPa/N, the local sensitivity; stiffer near the rim) and `c` a
//! global curvature (kPa/N^2, mild saturation). It passes through the origin: no force, no
//! pressure. Its inverse is the `pneumatic-forward` corrector, and the `force-balance`
//! splitter uses it to share dP so that the shares add up the way the chamber does.
//!
//! Guards: `a` is floored at [`A_FLOOR_REL`] of its mean; above the calibrated force range P
//! continues linearly with its end slope (floored), so P is strictly increasing in F and its
//! inverse is unique. Fit: ridge least squares on dP with the spatial terms of `a` shrunk
//! towards 0 by a weight chosen by k-fold cross-validation (as for the paper's fields).

use super::field::{NPHI, QuadField, Region, phi};
use super::fit::{CvSearch, RidgeProblem, cross_validate};
use serde::{Deserialize, Serialize};

/// Smallest local sensitivity used, as a fraction of the field's constant term.
pub const A_FLOOR_REL: f64 = 0.1;

/// P(F, x, y) = a(u, v) F + c F^2 on `region`; linear above `force_max_n`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForwardModel {
    /// Normalization of the coordinates (clamped outside).
    pub region: Region,
    /// Local sensitivity field a, kPa/N.
    pub sensitivity: QuadField,
    /// Curvature c, kPa/N^2.
    pub curvature: f64,
    /// Largest calibration force, N: P continues linearly beyond it.
    pub force_max_n: f64,
    /// Ridge weight chosen for the spatial terms (absent when not cross-validated).
    pub lambda: Option<f64>,
    /// Cross-validated RMSE of dP, kPa.
    pub cv_rmse_kpa: Option<f64>,
}

/// The pressure response of one contact location, resolved once per contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalResponse {
    a: f64,
    c: f64,
    f_max: f64,
}

impl LocalResponse {
    /// dP for force `f_n` (>= 0), kPa.
    pub fn pressure(&self, f_n: f64) -> f64 {
        let f = f_n.max(0.0);
        if f <= self.f_max {
            self.a * f + self.c * f * f
        } else {
            self.pressure(self.f_max) + self.end_slope() * (f - self.f_max)
        }
    }

    fn end_slope(&self) -> f64 {
        (self.a + 2.0 * self.c * self.f_max).max(A_FLOOR_REL * self.a)
    }

    /// The force that causes `dp_kpa` (0 for dP <= 0); the second value is true when dP lies
    /// beyond the calibrated force range (linear continuation).
    pub fn force(&self, dp_kpa: f64) -> (f64, bool) {
        if dp_kpa.is_nan() || dp_kpa <= 0.0 {
            return (0.0, false);
        }
        let p_max = self.pressure(self.f_max);
        if dp_kpa > p_max {
            return (self.f_max + (dp_kpa - p_max) / self.end_slope(), true);
        }
        // Root of c F^2 + a F - dP = 0 in [0, f_max], in the cancellation-free form.
        let disc = self.a * self.a + 4.0 * self.c * dp_kpa;
        (2.0 * dp_kpa / (self.a + disc.max(0.0).sqrt()), false)
    }
}

impl ForwardModel {
    /// A uniform linear response of `a_kpa_per_n` everywhere.
    pub fn linear(region: Region, a_kpa_per_n: f64, force_max_n: f64) -> Self {
        Self {
            region,
            sensitivity: QuadField::constant(a_kpa_per_n),
            curvature: 0.0,
            force_max_n,
            lambda: None,
            cv_rmse_kpa: None,
        }
    }

    /// The response at a point (mm), clamped onto the region; the flag says it was clamped.
    pub fn at(&self, x_mm: f64, y_mm: f64) -> (LocalResponse, bool) {
        let n = self.region.normalize(x_mm, y_mm);
        let floor = A_FLOOR_REL * self.sensitivity.coeffs[0].abs();
        let a = self.sensitivity.at(n.u, n.v).max(floor).max(f64::MIN_POSITIVE);
        // With c < 0 the parabola's top must lie beyond the calibrated range.
        let c = if self.curvature < 0.0 { self.curvature.max(-a / (2.0 * self.force_max_n)) } else { self.curvature };
        (LocalResponse { a, c, f_max: self.force_max_n }, n.clamped)
    }

    /// Fits the model to single-contact samples `(x_mm, y_mm, force_n, dp_kpa)`. `grid` holds
    /// the ridge weights searched for the spatial terms. `None` with fewer than 2 (NPHI + 1)
    /// usable samples (finite, F > 0) or when no fit is possible.
    pub fn fit(region: Region, samples: &[(f64, f64, f64, f64)], grid: &[f64], folds: usize) -> Option<Self> {
        const P: usize = NPHI + 1;
        let used: Vec<_> =
            samples.iter().filter(|s| s.2 > 0.0 && [s.0, s.1, s.2, s.3].iter().all(|v| v.is_finite())).collect();
        if used.len() < 2 * P {
            return None;
        }
        let mut design = Vec::with_capacity(used.len() * P);
        let mut y = Vec::with_capacity(used.len());
        for s in &used {
            let n = region.normalize(s.0, s.1);
            design.extend(phi(n.u, n.v).iter().map(|p| p * s.2));
            design.push(s.2 * s.2);
            y.push(s.3);
        }
        let prior = [0.0; P];
        let problem = RidgeProblem { design: &design, y: &y, p: P, prior: &prior, base_penalty: &[0.0; P] };
        let cv = cross_validate(&problem, &CvSearch { blocks: std::slice::from_ref(&(1..NPHI)), grid, folds })?;
        let mut coeffs = [0.0; NPHI];
        coeffs.copy_from_slice(&cv.coeffs[..NPHI]);
        if coeffs[0].is_nan() || coeffs[0] <= 0.0 {
            return None;
        }
        Some(Self {
            region,
            sensitivity: QuadField { coeffs },
            curvature: cv.coeffs[NPHI],
            force_max_n: used.iter().map(|s| s.2).fold(0.0, f64::max),
            lambda: Some(cv.lambdas[0]),
            cv_rmse_kpa: Some(cv.cv_mse.sqrt()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn region() -> Region {
        Region { x_min_mm: -40.0, x_max_mm: 40.0, y_min_mm: -40.0, y_max_mm: 40.0 }
    }

    #[test]
    fn inverse_undoes_the_forward_map_inside_and_beyond_the_range() {
        let mut m = ForwardModel::linear(region(), 0.3, 10.0);
        m.curvature = -0.004;
        let (r, clamped) = m.at(10.0, -5.0);
        assert!(!clamped);
        for f in [0.0, 0.1, 1.0, 5.0, 9.99, 10.0, 12.0, 40.0] {
            let (back, beyond) = r.force(r.pressure(f));
            assert!((back - f).abs() < 1e-9 * (1.0 + f), "{f} -> {back}");
            assert_eq!(beyond, f > 10.0 + 1e-9);
        }
        assert_eq!(r.force(0.0), (0.0, false));
        assert_eq!(r.force(-0.2), (0.0, false));
        assert_eq!(r.force(f64::NAN), (0.0, false));
    }

    #[test]
    fn the_response_is_strictly_increasing_even_for_a_bent_fit() {
        // A curvature that would turn the parabola down inside the range is limited.
        let mut m = ForwardModel::linear(region(), 0.3, 10.0);
        m.curvature = -0.05;
        let (r, _) = m.at(0.0, 0.0);
        let mut prev = -1.0;
        for i in 0..=300 {
            let p = r.pressure(0.1 * f64::from(i));
            assert!(p > prev, "not increasing at {} N", 0.1 * f64::from(i));
            prev = p;
        }
    }

    #[test]
    fn the_fit_recovers_a_known_model() {
        // a = 0.3 (1 - 0.2 u^2), c = -0.003, over a 5 x 5 grid and forces 1..10 N, no noise.
        let truth = |u: f64, f: f64| 0.3 * (1.0 - 0.2 * u * u) * f - 0.003 * f * f;
        let mut samples = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                for k in 1..=10 {
                    let (x, y, f) = (-40.0 + 20.0 * f64::from(i), -40.0 + 20.0 * f64::from(j), f64::from(k));
                    samples.push((x, y, f, truth(x / 40.0, f)));
                }
            }
        }
        let m = ForwardModel::fit(region(), &samples, &[1e-9, 1e-3, 1.0], 5).unwrap();
        assert!((m.curvature + 0.003).abs() < 1e-6, "{}", m.curvature);
        let (r, _) = m.at(40.0, 20.0);
        assert!((r.pressure(5.0) - truth(1.0, 5.0)).abs() < 1e-6);
        assert_eq!(m.force_max_n, 10.0);
        assert!(ForwardModel::fit(region(), &samples[..10], &[1.0], 5).is_none());
    }

    #[test]
    fn outside_the_region_the_response_is_clamped_and_flagged() {
        let mut m = ForwardModel::linear(region(), 0.3, 10.0);
        m.sensitivity.coeffs[1] = 0.1; // a = 0.3 + 0.1 u
        let (inside, _) = m.at(40.0, 0.0);
        let (outside, clamped) = m.at(60.0, 0.0);
        assert!(clamped);
        assert_eq!(inside, outside);
    }
}
