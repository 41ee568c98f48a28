//! The forward pneumatic model: the pressure change a contact causes, dP = P(F, x, y).
//!
//! The paper maps pressure to force (F = g f(dP) + b). That inverse form is fine for one
//! contact, but it cannot say how contacts add up: the sealed chamber sees the sum of the
//! volumes the contacts displace, so pressure, not force, is additive. This model is the
//! forward direction,
//!
//! ```text
//! P(F, x, y) = a(x, y) F + c F^2        (kPa; F in N; x, y in mm, clamped onto the region)
//! ```
//!
//! with `a` a kernel field (kPa/N, the local sensitivity; stiffer near the rim; see
//! [`super::kernel`]) and `c` a global curvature (kPa/N^2, mild saturation). It passes through the origin: no force, no
//! pressure. Its inverse is the `pneumatic-forward` corrector, and the `force-balance`
//! splitter uses it to share dP so that the shares add up the way the chamber does.
//!
//! Guards: `a` is floored at [`A_FLOOR_REL`] of its mean; above the calibrated force range P
//! continues linearly with its end slope (floored), so P is strictly increasing in F and its
//! inverse is unique. Fit: least squares of dP on (a_j F, c F^2) with one a_j per calibration
//! site and a common c (closed form), then the kernel field through the a_j.

use super::field::Region;
use super::kernel::KernelField;
use serde::{Deserialize, Serialize};

/// Smallest local sensitivity used, as a fraction of the field's mean.
pub const A_FLOOR_REL: f64 = 0.1;

/// P(F, x, y) = a(u, v) F + c F^2 on `region`; linear above `force_max_n`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForwardModel {
    /// Local sensitivity field a, kPa/N (clamped onto the calibrated region).
    pub sensitivity: KernelField,
    /// Curvature c, kPa/N^2.
    pub curvature: f64,
    /// Largest calibration force, N: P continues linearly beyond it.
    pub force_max_n: f64,
    /// RMSE of dP over the calibration samples, kPa.
    pub fit_rmse_kpa: Option<f64>,
}

/// One calibration sample for [`ForwardModel::fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardSample {
    /// EIT centroid, mm.
    pub x_mm: f64,
    /// EIT centroid, mm.
    pub y_mm: f64,
    /// Index of the true location (samples of one site share it).
    pub site: usize,
    /// True force, N.
    pub force_n: f64,
    /// Tared pressure change, kPa.
    pub dp_kpa: f64,
}

/// The pressure response of one contact location, resolved once per contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalResponse {
    a: f64,
    c: f64,
    f_max: f64,
}

impl LocalResponse {
    /// A response that is 0 for every force (placeholder in fixed-size buffers).
    pub const ZERO: LocalResponse = LocalResponse { a: 0.0, c: 0.0, f_max: 0.0 };

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
            let f = self.f_max + (dp_kpa - p_max) / self.end_slope();
            // Beyond the range by more than rounding (a sample at exactly f_max is inside).
            return (f, f > self.f_max * (1.0 + 1e-9));
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
            sensitivity: KernelField::constant(region, a_kpa_per_n),
            curvature: 0.0,
            force_max_n,
            fit_rmse_kpa: None,
        }
    }

    /// The response at a point (mm), clamped onto the region; the flag says it was clamped.
    pub fn at(&self, x_mm: f64, y_mm: f64) -> (LocalResponse, bool) {
        let (_, clamped) = self.sensitivity.region.clamp(x_mm, y_mm);
        let floor = A_FLOOR_REL * self.sensitivity.mean.abs();
        let a = self.sensitivity.at(x_mm, y_mm).max(floor).max(f64::MIN_POSITIVE);
        // With c < 0 the parabola's top must lie beyond the calibrated range.
        let c = if self.curvature < 0.0 { self.curvature.max(-a / (2.0 * self.force_max_n)) } else { self.curvature };
        (LocalResponse { a, c, f_max: self.force_max_n }, clamped)
    }

    /// Fits the model to single-contact samples. `None` without a usable sample (finite,
    /// F > 0) or when the fitted mean sensitivity is not positive.
    pub fn fit(region: Region, samples: &[ForwardSample]) -> Option<Self> {
        let used: Vec<&ForwardSample> = samples
            .iter()
            .filter(|s| s.force_n > 0.0 && [s.x_mm, s.y_mm, s.force_n, s.dp_kpa].iter().all(|v| v.is_finite()))
            .collect();
        if used.is_empty() {
            return None;
        }
        // Per site (any indices: grouped by value): sums of F^2, F^3, F dP, x, y, the count,
        // F^4 and F^2 dP.
        let mut by_site: std::collections::BTreeMap<usize, [f64; 8]> = std::collections::BTreeMap::new();
        for s in &used {
            let (f, p) = (s.force_n, s.dp_kpa);
            let a = by_site.entry(s.site).or_insert([0.0; 8]);
            a[0] += f * f;
            a[1] += f * f * f;
            a[2] += f * p;
            a[3] += s.x_mm;
            a[4] += s.y_mm;
            a[5] += 1.0;
            a[6] += f.powi(4);
            a[7] += f * f * p;
        }
        // Eliminating a_j = (S_j(F dP) - c S_j(F^3)) / S_j(F^2) from the normal equations, site
        // by site: each site's term S_j(F^4) - S_j(F^3)^2 / S_j(F^2) is >= 0 (Cauchy-Schwarz)
        // and 0 when the site saw one force, so the sum cannot cancel to a negative value.
        let acc: Vec<[f64; 8]> = by_site.into_values().collect();
        let (mut den, mut num, mut f4) = (0.0, 0.0, 0.0);
        for a in &acc {
            den += (a[6] - a[1] * a[1] / a[0]).max(0.0);
            num += a[7] - a[1] * a[2] / a[0];
            f4 += a[6];
        }
        let curvature = if den > 1e-12 * f4 { num / den } else { 0.0 };
        let sites: Vec<(f64, f64, f64)> =
            acc.iter().map(|a| (a[3] / a[5], a[4] / a[5], (a[2] - curvature * a[1]) / a[0])).collect();
        let sensitivity = KernelField::fit(region, &sites);
        if sensitivity.mean.is_nan() || sensitivity.mean <= 0.0 {
            return None;
        }
        let force_max_n = used.iter().map(|s| s.force_n).fold(0.0, f64::max);
        let mut model = Self { sensitivity, curvature, force_max_n, fit_rmse_kpa: None };
        let sse: f64 = used.iter().map(|s| (model.at(s.x_mm, s.y_mm).0.pressure(s.force_n) - s.dp_kpa).powi(2)).sum();
        model.fit_rmse_kpa = Some((sse / used.len() as f64).sqrt());
        Some(model)
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
                    let site = (5 * i + j) as usize;
                    samples.push(ForwardSample { x_mm: x, y_mm: y, site, force_n: f, dp_kpa: truth(x / 40.0, f) });
                }
            }
        }
        let m = ForwardModel::fit(region(), &samples).unwrap();
        assert!((m.curvature + 0.003).abs() < 1e-9, "{}", m.curvature);
        // The kernel field smooths the per-site sensitivities slightly (its ridge): within 1 %
        // of the pressure at the sites and between them.
        assert!(m.fit_rmse_kpa.unwrap() < 0.01, "{:?}", m.fit_rmse_kpa);
        for (x, u) in [(40.0, 1.0), (30.0, 0.75), (0.0, 0.0)] {
            let (r, _) = m.at(x, 20.0);
            let want = truth(u, 5.0);
            assert!((r.pressure(5.0) - want).abs() < 0.01 * want, "x = {x}: {} vs {want}", r.pressure(5.0));
        }
        assert_eq!(m.force_max_n, 10.0);
        assert!(ForwardModel::fit(region(), &[]).is_none());
    }

    #[test]
    fn outside_the_region_the_response_is_clamped_and_flagged() {
        let mut m = ForwardModel::linear(region(), 0.3, 10.0);
        m.sensitivity.sites = vec![[40.0, 0.0, 0.1]]; // stiffer on the right
        m.sensitivity.length_mm = 20.0;
        let (inside, _) = m.at(40.0, 0.0);
        let (outside, clamped) = m.at(60.0, 0.0);
        assert!(clamped);
        assert_eq!(inside, outside);
    }
}
