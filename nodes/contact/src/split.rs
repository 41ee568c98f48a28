//! Sharing the pneumatic pressure change among contacts (paper eq. 15 and an alternative).
//!
//! `Proportional` is the paper: dP_i = C_i / sum_j C_j * dP. Its stated weakness is EIT's
//! nonuniform sensitivity (the same force gives different C at different places).
//! `SensitivityCompensated` divides each C_i by a relative sensitivity s(x_i, y_i) learned
//! from the single-contact calibration (quadratic field fitted to C / F, mean 1, floored),
//! then maps r = C / s through w(r) = a1 r + a2 r^2 (fitted to F through the origin, since C
//! grows sub-linearly with force), so the weights estimate force, not conductivity.
//! dP is in kPa and may be negative (drift); shares keep its sign.

use crate::correct::field::{NPHI, QuadField, Region, phi};
use crate::correct::fit::{CvSearch, RidgeProblem, cross_validate, ridge};
use crate::segment::Contact;
use serde::{Deserialize, Serialize};

/// Relative EIT sensitivity s(x, y) (dimensionless, mean 1 over the calibration samples).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensitivityField {
    /// Region of the normalized coordinates (clamped outside).
    pub region: Region,
    /// Quadratic field of the relative sensitivity.
    pub field: QuadField,
    /// Smallest sensitivity used, so a weight never divides by ~0 or a negative value.
    pub floor: f64,
    /// Linear coefficient of the force equivalent w(r) = a1 r + a2 r^2 (N per unit of C).
    pub force_a1: f64,
    /// Quadratic coefficient of w(r).
    pub force_a2: f64,
    /// Largest calibration r; w continues linearly with its end slope beyond it.
    pub ratio_max: f64,
}

impl SensitivityField {
    /// Uniform sensitivity 1 (makes the compensated splitter proportional).
    pub fn uniform(region: Region) -> Self {
        Self { region, field: QuadField::constant(1.0), floor: 0.1, force_a1: 1.0, force_a2: 0.0, ratio_max: 1.0 }
    }

    /// Force equivalent (N, >= 0) of a conductivity sum at a point: w(C / s(x, y)).
    pub fn force_equivalent(&self, cond_sum: f64, x_mm: f64, y_mm: f64) -> f64 {
        let r = cond_sum.max(0.0) / self.at(x_mm, y_mm);
        let (a1, a2, r_max) = (self.force_a1, self.force_a2, self.ratio_max);
        let w = if r <= r_max {
            a1 * r + a2 * r * r
        } else {
            a1 * r_max + a2 * r_max * r_max + (a1 + 2.0 * a2 * r_max) * (r - r_max)
        };
        w.max(0.0)
    }

    /// Sensitivity at a point (mm), floored.
    pub fn at(&self, x_mm: f64, y_mm: f64) -> f64 {
        let n = self.region.normalize(x_mm, y_mm);
        self.field.at(n.u, n.v).max(self.floor)
    }

    /// Fits s to C / F over single-contact samples `(x_mm, y_mm, cond_sum, force_n)` by ridge
    /// (constant unpenalized, spatial terms shrunk to 0, weight chosen by CV over `grid`).
    /// `None` with fewer than 2 * 6 usable samples (F > 0, C > 0).
    pub fn fit(region: Region, samples: &[(f64, f64, f64, f64)], grid: &[f64], folds: usize) -> Option<Self> {
        let used: Vec<_> = samples.iter().filter(|s| s.2 > 0.0 && s.3 > 0.0 && s.2.is_finite()).collect();
        if used.len() < 2 * NPHI {
            return None;
        }
        let mean = used.iter().map(|s| s.2 / s.3).sum::<f64>() / used.len() as f64;
        let mut design = Vec::with_capacity(used.len() * NPHI);
        let mut y = Vec::with_capacity(used.len());
        for s in &used {
            let n = region.normalize(s.0, s.1);
            design.extend_from_slice(&phi(n.u, n.v));
            y.push(s.2 / s.3 / mean);
        }
        let prior = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let problem = RidgeProblem { design: &design, y: &y, p: NPHI, prior: &prior, base_penalty: &[0.0; NPHI] };
        let cv = cross_validate(&problem, &CvSearch { blocks: std::slice::from_ref(&(1..NPHI)), grid, folds })?;
        let mut coeffs = [0.0; NPHI];
        coeffs.copy_from_slice(&cv.coeffs);
        let mut out =
            Self { region, field: QuadField { coeffs }, floor: 0.1, force_a1: 1.0, force_a2: 0.0, ratio_max: 1.0 };
        // F ~ a1 r + a2 r^2 through the origin, on r scaled by its maximum for conditioning.
        let r: Vec<f64> = used.iter().map(|s| s.2 / out.at(s.0, s.1)).collect();
        let f: Vec<f64> = used.iter().map(|s| s.3).collect();
        let r_max = r.iter().copied().fold(0.0, f64::max);
        let scaled: Vec<f64> = r.iter().flat_map(|&v| [v / r_max, (v / r_max).powi(2)]).collect();
        let fit = ridge(&scaled, &f, 2, &[0.0; 2], &[0.0; 2]);
        let monotone = |a: &[f64]| a[0] > 0.0 && a[0] + 2.0 * a[1] > 0.0;
        match fit {
            // w' > 0 at r = 0 and r = r_max, hence on the whole range (w' is linear).
            Some(a) if monotone(&a) => {
                out.force_a1 = a[0] / r_max;
                out.force_a2 = a[1] / (r_max * r_max);
            }
            // Not monotone: a straight line through the origin (mean force / mean r).
            _ => out.force_a1 = f.iter().sum::<f64>() / r.iter().sum::<f64>(),
        }
        out.ratio_max = r_max;
        Some(out)
    }
}

/// How the total pressure change is shared among the contacts of a frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Splitter {
    /// dP_i = C_i / sum C_j * dP (the paper).
    Proportional,
    /// dP_i = w(C_i / s_i) / sum_j w(C_j / s_j) * dP.
    SensitivityCompensated(SensitivityField),
}

impl Splitter {
    /// The splitter's name as used in strategy names and reports.
    pub fn name(&self) -> &'static str {
        match self {
            Splitter::Proportional => "proportional",
            Splitter::SensitivityCompensated(_) => "sensitivity-compensated",
        }
    }

    /// Unnormalized weight of one contact (>= 0).
    pub fn weight(&self, c: &Contact) -> f64 {
        let sum = if c.sum.is_finite() { c.sum.max(0.0) } else { 0.0 };
        match self {
            Splitter::Proportional => sum,
            Splitter::SensitivityCompensated(s) => s.force_equivalent(sum, c.x_mm, c.y_mm),
        }
    }

    /// Writes each contact's share of `dp_kpa` into `out[..contacts.len()]`. A single contact
    /// gets all of it; if every weight is 0 the change is shared equally. No allocation.
    pub fn split_into(&self, dp_kpa: f64, contacts: &[Contact], out: &mut [f64]) {
        let total: f64 = contacts.iter().map(|c| self.weight(c)).sum();
        let n = contacts.len() as f64;
        for (o, c) in out.iter_mut().zip(contacts) {
            *o = if total > 0.0 { self.weight(c) / total * dp_kpa } else { dp_kpa / n };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contact(x_mm: f64, sum: f64) -> Contact {
        Contact { x_mm, y_mm: 0.0, sum, area_mm2: 100.0, peak: 1.0, label: 1 }
    }

    fn region() -> Region {
        Region { x_min_mm: -40.0, x_max_mm: 40.0, y_min_mm: -40.0, y_max_mm: 40.0 }
    }

    #[test]
    fn proportional_follows_the_paper_equation() {
        let cs = [contact(-20.0, 1.0), contact(20.0, 3.0)];
        let mut out = [0.0; 2];
        Splitter::Proportional.split_into(2.0, &cs, &mut out);
        assert_eq!(out, [0.5, 1.5]);
        let mut one = [0.0];
        Splitter::Proportional.split_into(-0.3, &cs[..1], &mut one);
        assert_eq!(one, [-0.3]);
        Splitter::Proportional.split_into(1.0, &[contact(0.0, 0.0), contact(1.0, 0.0)], &mut out);
        assert_eq!(out, [0.5, 0.5]);
    }

    #[test]
    fn compensation_undoes_a_known_sensitivity() {
        // Sensitivity 2 on the right (u > 0 -> 1 + u), equal forces: C is twice as large on
        // the right at u = 1, and the compensated split must be equal again.
        let field = SensitivityField {
            region: region(),
            field: QuadField { coeffs: [1.0, 1.0, 0.0, 0.0, 0.0, 0.0] },
            floor: 0.1,
            force_a1: 1.0,
            force_a2: 0.0,
            ratio_max: 10.0,
        };
        let cs = [contact(0.0, 1.0), contact(40.0, 2.0)];
        let mut out = [0.0; 2];
        Splitter::SensitivityCompensated(field).split_into(2.0, &cs, &mut out);
        assert!((out[0] - 1.0).abs() < 1e-12 && (out[1] - 1.0).abs() < 1e-12);
        let uniform = Splitter::SensitivityCompensated(SensitivityField::uniform(region()));
        uniform.split_into(2.0, &cs, &mut out);
        assert!((out[0] - 2.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn fitted_sensitivity_recovers_a_linear_trend() {
        // C = F * (1 + 0.5 u) over a 5 x 5 grid and two forces: the normalized field is 1 + 0.5 u.
        let mut samples = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                for f in [2.0, 6.0] {
                    let (x, y) = (-40.0 + 20.0 * i as f64, -40.0 + 20.0 * j as f64);
                    samples.push((x, y, f * (1.0 + 0.5 * x / 40.0), f));
                }
            }
        }
        let grid = [1e-6, 1e-3, 1.0, 1e3];
        let s = SensitivityField::fit(region(), &samples, &grid, 5).unwrap();
        assert!((s.at(40.0, 0.0) - 1.5).abs() < 1e-3 && (s.at(-40.0, 10.0) - 0.5).abs() < 1e-3);
        // C / s = F exactly, so the force equivalent is the identity: a1 = 1, a2 = 0.
        let w = s.force_equivalent(4.0 * 1.25, 20.0, 0.0);
        assert!((w - 4.0).abs() < 1e-3, "{w}");
        assert!(s.force_equivalent(0.0, 0.0, 0.0) == 0.0);
    }

    #[test]
    fn force_equivalent_is_monotone_and_linear_beyond_the_range() {
        let mut s = SensitivityField::uniform(region());
        (s.force_a1, s.force_a2, s.ratio_max) = (2.0, -0.5, 1.5);
        // w(1.5) = 3 - 1.125 = 1.875, w'(1.5) = 2 - 1.5 = 0.5 -> w(3.5) = 1.875 + 1.0
        assert!((s.force_equivalent(3.5, 0.0, 0.0) - 2.875).abs() < 1e-12);
        let mut prev = 0.0;
        for i in 0..100 {
            let w = s.force_equivalent(0.05 * i as f64, 0.0, 0.0);
            assert!(w >= prev);
            prev = w;
        }
    }
}
