//! Sharing the pneumatic pressure change among contacts (paper eq. 15 and an alternative).
//!
//! `Proportional` is the paper: dP_i = C_i / sum_j C_j * dP. Its stated weakness is EIT's
//! nonuniform sensitivity (the same force gives different C at different places).
//! `SensitivityCompensated` divides each C_i by a relative sensitivity s(x_i, y_i) learned
//! from the single-contact calibration (quadratic field fitted to C / F, normalized to mean 1
//! over the calibration samples, floored at `floor`), so the weights estimate force, not
//! conductivity. dP is in kPa and may be negative (drift); shares keep its sign.

use crate::correct::field::{NPHI, QuadField, Region, phi};
use crate::correct::fit::{CvSearch, RidgeProblem, cross_validate};
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
}

impl SensitivityField {
    /// Uniform sensitivity 1 (makes the compensated splitter proportional).
    pub fn uniform(region: Region) -> Self {
        Self {
            region,
            field: QuadField::constant(1.0),
            floor: 0.1,
        }
    }

    /// Sensitivity at a point (mm), floored.
    pub fn at(&self, x_mm: f64, y_mm: f64) -> f64 {
        let n = self.region.normalize(x_mm, y_mm);
        self.field.at(n.u, n.v).max(self.floor)
    }

    /// Fits s to C / F over single-contact samples `(x_mm, y_mm, cond_sum, force_n)` by ridge
    /// (constant unpenalized, spatial terms shrunk to 0, weight chosen by CV over `grid`).
    /// `None` with fewer than 2 * 6 usable samples (F > 0, C > 0).
    pub fn fit(
        region: Region,
        samples: &[(f64, f64, f64, f64)],
        grid: &[f64],
        folds: usize,
    ) -> Option<Self> {
        let used: Vec<_> = samples
            .iter()
            .filter(|s| s.2 > 0.0 && s.3 > 0.0 && s.2.is_finite())
            .collect();
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
        let problem = RidgeProblem {
            design: &design,
            y: &y,
            p: NPHI,
            prior: &prior,
            base_penalty: &[0.0; NPHI],
        };
        let cv = cross_validate(
            &problem,
            &CvSearch {
                blocks: std::slice::from_ref(&(1..NPHI)),
                grid,
                folds,
            },
        )?;
        let mut coeffs = [0.0; NPHI];
        coeffs.copy_from_slice(&cv.coeffs);
        Some(Self {
            region,
            field: QuadField { coeffs },
            floor: 0.1,
        })
    }
}

/// How the total pressure change is shared among the contacts of a frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Splitter {
    /// dP_i = C_i / sum C_j * dP (the paper).
    Proportional,
    /// dP_i = (C_i / s_i) / sum (C_j / s_j) * dP.
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
        let sum = if c.sum.is_finite() {
            c.sum.max(0.0)
        } else {
            0.0
        };
        match self {
            Splitter::Proportional => sum,
            Splitter::SensitivityCompensated(s) => sum / s.at(c.x_mm, c.y_mm),
        }
    }

    /// Writes each contact's share of `dp_kpa` into `out[..contacts.len()]`. A single contact
    /// gets all of it; if every weight is 0 the change is shared equally. No allocation.
    pub fn split_into(&self, dp_kpa: f64, contacts: &[Contact], out: &mut [f64]) {
        let total: f64 = contacts.iter().map(|c| self.weight(c)).sum();
        let n = contacts.len() as f64;
        for (o, c) in out.iter_mut().zip(contacts) {
            *o = if total > 0.0 {
                self.weight(c) / total * dp_kpa
            } else {
                dp_kpa / n
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contact(x_mm: f64, sum: f64) -> Contact {
        Contact {
            x_mm,
            y_mm: 0.0,
            sum,
            area_mm2: 100.0,
            peak: 1.0,
            label: 1,
        }
    }

    fn region() -> Region {
        Region {
            x_min_mm: -40.0,
            x_max_mm: 40.0,
            y_min_mm: -40.0,
            y_max_mm: 40.0,
        }
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
            field: QuadField {
                coeffs: [1.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            },
            floor: 0.1,
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
    }
}
