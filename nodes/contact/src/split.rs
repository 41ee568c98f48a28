//! Sharing the pneumatic pressure change among contacts (paper eq. 15 and two alternatives).
//!
//! `Proportional` is the paper: dP_i = C_i / sum_j C_j * dP. Its stated weakness is EIT's
//! nonuniform sensitivity: the same force gives different C at different places (on the
//! simulated skin, up to 2.5x between mirrored points, from the foam's local compliance).
//!
//! `SensitivityCompensated` turns each C_i into a force equivalent w_i = (C_i / k(x_i, y_i))^(1/gamma)
//! with the single-contact EIT response C = k(x, y) F^gamma learned by `skinflow calibrate`
//! ([`SensitivityField`]), and shares dP in proportion to w_i.
//!
//! `ForceBalance` (the paper's future work: a non-linear split) uses the same w_i as the
//! *ratios of the forces* and the forward pneumatic model P(F, x, y) ([`ForwardModel`]) for
//! how pressure adds up: it finds the scale s with sum_i P(s w_i, x_i) = dP and gives contact i
//! the share P(s w_i, x_i). Pressure is what the chamber adds (the displaced volumes), so the
//! shares stay consistent with the single-contact calibration however many contacts there are.
//!
//! dP is in kPa and may be negative (drift); then every splitter shares it in proportion to
//! the weights, keeping its sign.

use crate::correct::field::Region;
use crate::correct::forward::{ForwardModel, LocalResponse};
use crate::correct::kernel::KernelField;
use crate::segment::Contact;
use serde::{Deserialize, Serialize};

/// Smallest and largest exponent gamma accepted from a fit of C = k F^gamma.
const EXPONENT_RANGE: (f64, f64) = (0.25, 4.0);

/// The single-contact EIT response C = k(x, y) F^gamma (C in image units x pixels, F in N).
///
/// log k is a [`KernelField`] through per-site values, the sites being the calibration's
/// indenter positions at their mean EIT centroid: it follows local structure (a soft patch of
/// foam, a misplaced electrode) that a quadratic cannot. No sites means uniform sensitivity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensitivityField {
    /// gamma: C grows as F^gamma at a fixed place.
    pub exponent: f64,
    /// log k over the sensor (clamped onto the calibrated region).
    pub log_k: KernelField,
}

/// One calibration sample for [`SensitivityField::fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensitivitySample {
    /// EIT centroid, mm.
    pub x_mm: f64,
    /// EIT centroid, mm.
    pub y_mm: f64,
    /// Index of the true location (samples of one site share it).
    pub site: usize,
    /// Conductivity decrease sum C.
    pub cond_sum: f64,
    /// True force, N.
    pub force_n: f64,
}

impl SensitivityField {
    /// Uniform sensitivity 1 and gamma = 1 (makes the compensated splitter proportional).
    pub fn uniform(region: Region) -> Self {
        Self { exponent: 1.0, log_k: KernelField::constant(region, 0.0) }
    }

    /// log k at a point (mm), clamped onto the region.
    pub fn log_k(&self, x_mm: f64, y_mm: f64) -> f64 {
        self.log_k.at(x_mm, y_mm)
    }

    /// Force equivalent (N, >= 0) of a conductivity sum at a point: (C / k)^(1 / gamma).
    pub fn force_equivalent(&self, cond_sum: f64, x_mm: f64, y_mm: f64) -> f64 {
        if !(cond_sum > 0.0 && cond_sum.is_finite()) {
            return 0.0;
        }
        ((cond_sum.ln() - self.log_k(x_mm, y_mm)) / self.exponent).exp()
    }

    /// Fits gamma (within-site regression of log C on log F), then per-site log k, then the
    /// kernel field through them. `None` with fewer than 2 usable samples (C > 0, F > 0, finite).
    pub fn fit(region: Region, samples: &[SensitivitySample]) -> Option<Self> {
        let used: Vec<&SensitivitySample> = samples
            .iter()
            .filter(|s| {
                s.cond_sum > 0.0
                    && s.force_n > 0.0
                    && [s.x_mm, s.y_mm, s.cond_sum, s.force_n].iter().all(|v| v.is_finite())
            })
            .collect();
        if used.len() < 2 {
            return None;
        }
        // Per site (any indices: grouped by value): count, sums of log F, log C, x, y.
        let mut by_site: std::collections::BTreeMap<usize, [f64; 5]> = std::collections::BTreeMap::new();
        for s in &used {
            let a = by_site.entry(s.site).or_insert([0.0; 5]);
            a[0] += 1.0;
            a[1] += s.force_n.ln();
            a[2] += s.cond_sum.ln();
            a[3] += s.x_mm;
            a[4] += s.y_mm;
        }
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for s in &used {
            let a = &by_site[&s.site];
            let (df, dc) = (s.force_n.ln() - a[1] / a[0], s.cond_sum.ln() - a[2] / a[0]);
            sxy += df * dc;
            sxx += df * df;
        }
        let exponent = if sxx > 1e-9 { (sxy / sxx).clamp(EXPONENT_RANGE.0, EXPONENT_RANGE.1) } else { 1.0 };
        let sites: Vec<(f64, f64, f64)> =
            by_site.values().map(|a| (a[3] / a[0], a[4] / a[0], (a[2] - exponent * a[1]) / a[0])).collect();
        Some(Self { exponent, log_k: KernelField::fit(region, &sites) })
    }
}

/// How the total pressure change is shared among the contacts of a frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Splitter {
    /// dP_i = C_i / sum C_j * dP (the paper).
    Proportional,
    /// dP_i = w_i / sum_j w_j * dP, w_i the force equivalent of C_i.
    SensitivityCompensated(SensitivityField),
    /// dP_i = P(s w_i, x_i) with sum_i dP_i = dP.
    ForceBalance {
        /// Force ratios from the EIT response.
        sensitivity: SensitivityField,
        /// How each contact's force becomes pressure.
        forward: ForwardModel,
    },
}

/// Bisection steps of the force-balance scale (relative precision 2^-60).
const BALANCE_STEPS: usize = 60;
/// Doublings tried to bracket the force-balance scale (2^1100 covers every finite f64 ratio).
const BRACKET_STEPS: usize = 1100;
/// Contacts whose weights (and force-balance responses) a split caches on the stack.
const BALANCE_STACK: usize = 16;

impl Splitter {
    /// The splitter's name as used in strategy names and reports.
    pub fn name(&self) -> &'static str {
        match self {
            Splitter::Proportional => "proportional",
            Splitter::SensitivityCompensated(_) => "sensitivity-compensated",
            Splitter::ForceBalance { .. } => "force-balance",
        }
    }

    /// Unnormalized weight of one contact (>= 0): C_i, or its force equivalent.
    pub fn weight(&self, c: &Contact) -> f64 {
        let sum = if c.sum.is_finite() { c.sum.max(0.0) } else { 0.0 };
        match self {
            Splitter::Proportional => sum,
            Splitter::SensitivityCompensated(s) | Splitter::ForceBalance { sensitivity: s, .. } => {
                s.force_equivalent(sum, c.x_mm, c.y_mm)
            }
        }
    }

    /// Writes each contact's share of `dp_kpa` into `out[..contacts.len()]`. A single contact
    /// gets all of it; if every weight is 0 the change is shared equally. No allocation.
    pub fn split_into(&self, dp_kpa: f64, contacts: &[Contact], out: &mut [f64]) {
        self.split_with(dp_kpa, contacts, |i, v| out[i] = v);
    }

    /// As [`Splitter::split_into`], handing each share (contact index, kPa) to `set`.
    pub fn split_with(&self, dp_kpa: f64, contacts: &[Contact], mut set: impl FnMut(usize, f64)) {
        let n = contacts.len();
        if n == 1 {
            set(0, dp_kpa);
            return;
        }
        // Each contact's weight (and, for the force balance, its local pressure response)
        // resolved once: on the stack for up to BALANCE_STACK contacts, recomputed on use beyond.
        let forward = match self {
            Splitter::ForceBalance { forward, .. } => Some(forward),
            _ => None,
        };
        let mut cached = [(0.0, LocalResponse::ZERO); BALANCE_STACK];
        for (slot, c) in cached.iter_mut().zip(contacts) {
            *slot = (self.weight(c), forward.map_or(LocalResponse::ZERO, |f| f.at(c.x_mm, c.y_mm).0));
        }
        let weight = |i: usize| cached.get(i).map_or_else(|| self.weight(&contacts[i]), |e| e.0);
        let total: f64 = (0..n).map(weight).sum();
        let usable = total > 0.0 && total.is_finite();
        if let Some(forward) = forward
            && dp_kpa > 0.0
            && usable
        {
            let term = |i: usize, s: f64| {
                let r = cached.get(i).map_or_else(|| forward.at(contacts[i].x_mm, contacts[i].y_mm).0, |e| e.1);
                r.pressure(s * weight(i))
            };
            let total_pressure = |s: f64| (0..n).map(|i| term(i, s)).sum::<f64>();
            // Bracket: the summed pressure is increasing in s and 0 at s = 0. Weights that
            // overflow or vanish (a corrupt calibration) leave no bracket: proportional below.
            let mut hi = 1.0 / total;
            for _ in 0..BRACKET_STEPS {
                if !(hi.is_finite() && hi > 0.0) || total_pressure(hi) >= dp_kpa {
                    break;
                }
                hi *= 2.0;
            }
            if hi.is_finite() && hi > 0.0 && total_pressure(hi) >= dp_kpa {
                let mut lo = 0.0;
                for _ in 0..BALANCE_STEPS {
                    let mid = 0.5 * (lo + hi);
                    if total_pressure(mid) < dp_kpa {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                let s = 0.5 * (lo + hi);
                let sum = total_pressure(s);
                if sum > 0.0 && sum.is_finite() {
                    for i in 0..n {
                        set(i, term(i, s) * (dp_kpa / sum));
                    }
                    return;
                }
            }
        }
        if usable {
            for i in 0..n {
                set(i, weight(i) / total * dp_kpa);
            }
            return;
        }
        // Weights that overflow (a corrupt or extreme calibration): the infinite ones share dP;
        // finite ones whose sum overflows are rescaled by the largest; none usable: equal shares.
        let infinite = (0..n).filter(|&i| weight(i) == f64::INFINITY).count();
        let largest = (0..n).map(weight).filter(|w| w.is_finite()).fold(0.0f64, f64::max);
        let scaled_total: f64 = if largest > 0.0 { (0..n).map(|i| weight(i) / largest).sum() } else { 0.0 };
        for i in 0..n {
            let share = if infinite > 0 {
                if weight(i) == f64::INFINITY { 1.0 / infinite as f64 } else { 0.0 }
            } else if scaled_total > 0.0 && scaled_total.is_finite() {
                weight(i) / largest / scaled_total
            } else {
                1.0 / n as f64
            };
            set(i, share * dp_kpa);
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

    /// Samples of C = k(x, y) F^gamma over a 5 x 5 grid of sites and forces 1..10 N.
    fn grid_samples(k: impl Fn(f64, f64) -> f64, gamma: f64) -> Vec<SensitivitySample> {
        let mut out = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                let (x, y) = (-40.0 + 20.0 * f64::from(i), -40.0 + 20.0 * f64::from(j));
                for f in 1..=10 {
                    let f = f64::from(f);
                    out.push(SensitivitySample {
                        x_mm: x,
                        y_mm: y,
                        site: (5 * i + j) as usize,
                        cond_sum: k(x, y) * f.powf(gamma),
                        force_n: f,
                    });
                }
            }
        }
        out
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
    fn a_uniform_field_makes_the_compensated_split_proportional() {
        let cs = [contact(0.0, 1.0), contact(40.0, 2.0)];
        let mut out = [0.0; 2];
        Splitter::SensitivityCompensated(SensitivityField::uniform(region())).split_into(3.0, &cs, &mut out);
        assert!((out[0] - 1.0).abs() < 1e-12 && (out[1] - 2.0).abs() < 1e-12, "{out:?}");
    }

    #[test]
    fn the_fit_recovers_exponent_and_a_local_hot_spot() {
        // A hot patch at (-40, -40) (3x), gamma = 0.8: the quadratic the paper's fields use
        // could not follow it; the kernel field must, at the sites and between them.
        let k = |x: f64, y: f64| 0.1 * (1.0 + 2.0 * (-((x + 40.0).powi(2) + (y + 40.0).powi(2)) / 800.0).exp());
        let f = SensitivityField::fit(region(), &grid_samples(k, 0.8)).unwrap();
        assert!((f.exponent - 0.8).abs() < 1e-9, "{}", f.exponent);
        assert!(!f.log_k.sites.is_empty());
        for (x, y) in [(-40.0, -40.0), (40.0, 40.0), (0.0, -40.0), (-30.0, -30.0)] {
            let rel = (f.log_k(x, y) - k(x, y).ln()).abs();
            assert!(rel < 0.1, "log k at ({x}, {y}): {} vs {}", f.log_k(x, y), k(x, y).ln());
        }
        // The force equivalent undoes the response: w(k F^gamma) = F.
        let w = f.force_equivalent(k(-40.0, -40.0) * 5f64.powf(0.8), -40.0, -40.0);
        assert!((w - 5.0).abs() < 0.25, "{w}");
        assert_eq!(f.force_equivalent(0.0, 0.0, 0.0), 0.0);
        assert_eq!(f.force_equivalent(f64::NAN, 0.0, 0.0), 0.0);
    }

    #[test]
    fn a_flat_response_keeps_the_constant_field() {
        // Equal sensitivity everywhere: cross-validation must prefer no kernel at all.
        let f = SensitivityField::fit(region(), &grid_samples(|_, _| 0.2, 1.0)).unwrap();
        assert!(f.log_k.sites.is_empty(), "{:?}", f.log_k.sites);
        assert!((f.log_k(13.0, -7.0) - 0.2f64.ln()).abs() < 1e-9);
        // One site, one force: gamma cannot be identified and stays 1.
        let one = [SensitivitySample { x_mm: 0.0, y_mm: 0.0, site: 0, cond_sum: 1.0, force_n: 2.0 }; 3];
        let f = SensitivityField::fit(region(), &one).unwrap();
        assert_eq!(f.exponent, 1.0);
        assert!(SensitivityField::fit(region(), &one[..1]).is_none());
    }

    #[test]
    fn compensation_gives_equal_shares_to_equal_forces() {
        let k = |x: f64, _: f64| 0.1 * (1.0 + 0.025 * (x + 40.0)); // 3x from left to right
        let f = SensitivityField::fit(region(), &grid_samples(k, 1.0)).unwrap();
        let cs = [contact(-20.0, k(-20.0, 0.0) * 3.0), contact(20.0, k(20.0, 0.0) * 3.0)];
        let mut out = [0.0; 2];
        Splitter::SensitivityCompensated(f).split_into(2.0, &cs, &mut out);
        assert!((out[0] - 1.0).abs() < 0.02 && (out[1] - 1.0).abs() < 0.02, "{out:?}");
    }

    #[test]
    fn force_balance_recovers_forces_under_an_additive_pneumatic_layer() {
        // Pneumatic layer: P(F) = a(x) F - 0.004 F^2, a varying along x; uniform EIT.
        let mut fwd = ForwardModel::linear(region(), 0.3, 10.0);
        fwd.sensitivity.sites = vec![[40.0, 0.0, -0.1]]; // softer towards the right edge
        fwd.sensitivity.length_mm = 40.0;
        fwd.curvature = -0.004;
        let sens = SensitivityField::uniform(region());
        let forces = [2.0, 6.0, 3.0];
        let xs = [-30.0, 10.0, 35.0];
        let cs: Vec<Contact> = forces.iter().zip(xs).map(|(&f, x)| contact(x, f)).collect();
        let dp: f64 = cs.iter().map(|c| fwd.at(c.x_mm, 0.0).0.pressure(c.sum)).sum();
        let split = Splitter::ForceBalance { sensitivity: sens, forward: fwd.clone() };
        let mut out = [0.0; 3];
        split.split_into(dp, &cs, &mut out);
        assert!((out.iter().sum::<f64>() - dp).abs() < 1e-12);
        for ((share, c), f) in out.iter().zip(&cs).zip(forces) {
            let (back, _) = fwd.at(c.x_mm, 0.0).0.force(*share);
            assert!((back - f).abs() < 1e-9, "{back} vs {f}");
        }
        // The paper's proportional split does not: shares follow C, not the local response.
        Splitter::Proportional.split_into(dp, &cs, &mut out);
        let back = fwd.at(35.0, 0.0).0.force(out[2]).0;
        assert!((back - 3.0).abs() > 0.05, "{back}");
    }

    #[test]
    fn force_balance_edge_cases() {
        let split = Splitter::ForceBalance {
            sensitivity: SensitivityField::uniform(region()),
            forward: ForwardModel::linear(region(), 0.3, 10.0),
        };
        let cs = [contact(-20.0, 1.0), contact(20.0, 3.0)];
        let mut out = [0.0; 2];
        // Negative dP (drift): proportional, sign kept; zero weights: equal.
        split.split_into(-0.4, &cs, &mut out);
        assert!((out[0] + 0.1).abs() < 1e-12 && (out[1] + 0.3).abs() < 1e-12, "{out:?}");
        split.split_into(1.0, &[contact(0.0, 0.0), contact(1.0, 0.0)], &mut out);
        assert_eq!(out, [0.5, 0.5]);
        // A huge dP far beyond the calibrated range still balances (linear continuation).
        split.split_into(1e4, &cs, &mut out);
        assert!((out[1] / out[0] - 3.0).abs() < 1e-9 && (out[0] + out[1] - 1e4).abs() < 1e-6, "{out:?}");
        let mut one = [0.0];
        split.split_into(0.7, &cs[..1], &mut one);
        assert_eq!(one, [0.7]);
        // Weights that overflow (a corrupt or extreme calibration) end in a finite split, never
        // a hang: exponent 0.25 turns C = 1e200 into an infinite force equivalent.
        let mut extreme = SensitivityField::uniform(region());
        extreme.exponent = 0.25;
        let wild = Splitter::ForceBalance { sensitivity: extreme, forward: ForwardModel::linear(region(), 0.3, 10.0) };
        wild.split_into(1.0, &[contact(0.0, 1e200), contact(5.0, 1.0)], &mut out);
        assert_eq!(out, [1.0, 0.0], "the infinite weight takes dP");
        // Finite weights whose sum overflows: rescaled, still in proportion.
        let mut big = SensitivityField::uniform(region());
        big.exponent = 1.0;
        let proportional = Splitter::SensitivityCompensated(big);
        proportional.split_into(1.0, &[contact(0.0, 1.5e308), contact(5.0, 0.5e308)], &mut out);
        assert!((out[0] - 0.75).abs() < 1e-12 && (out[1] - 0.25).abs() < 1e-12, "{out:?}");
        // More contacts than the stack cache holds: the same answer as the proportional split
        // (uniform linear layer), through the uncached path.
        let many: Vec<Contact> = (0..BALANCE_STACK + 4).map(|i| contact(i as f64, 1.0 + i as f64)).collect();
        let (mut a, mut b) = (vec![0.0; many.len()], vec![0.0; many.len()]);
        split.split_into(2.0, &many, &mut a);
        Splitter::Proportional.split_into(2.0, &many, &mut b);
        assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-12), "{a:?}");
    }
}
