//! Quadratic spatial fields on normalized coordinates (paper eq. g = Phi alpha, b = Phi beta).
//!
//! [`Region`] is the calibrated region, the bounding box of the calibration centroids (mm).
//! It maps (x_mm, y_mm) to (u, v) in [-1, 1]^2; points outside are clamped to its edge and
//! the clamp is reported. [`phi`] is the basis `[1, u, v, u^2, u v, v^2]` and [`QuadField`]
//! holds its six coefficients.

use serde::{Deserialize, Serialize};

/// Number of basis functions.
pub const NPHI: usize = 6;

/// The basis `[1, u, v, u^2, u v, v^2]` at normalized coordinates.
pub fn phi(u: f64, v: f64) -> [f64; NPHI] {
    [1.0, u, v, u * u, u * v, v * v]
}

/// Design rows of the location-aware model F = g f + b: `[f_t Phi_t, Phi_t]` per sample, plus
/// `[f_t a_t, a_t]` when contact-area terms `rel_area` are given; row-major.
pub fn locaware_design(phis: &[[f64; NPHI]], fs: &[f64], rel_area: Option<&[f64]>) -> Vec<f64> {
    let width = 2 * NPHI + if rel_area.is_some() { 2 } else { 0 };
    let mut d = Vec::with_capacity(phis.len() * width);
    for (t, (p, &f)) in phis.iter().zip(fs).enumerate() {
        d.extend(p.iter().map(|v| v * f));
        d.extend_from_slice(p);
        if let Some(a) = rel_area {
            d.extend_from_slice(&[f * a[t], a[t]]);
        }
    }
    d
}

/// `Phi . c` for the first `NPHI` coefficients `c`: a quadratic field's value from its basis row.
pub fn field_value(phi_row: &[f64; NPHI], coeffs: &[f64]) -> f64 {
    phi_row.iter().zip(coeffs).map(|(p, c)| p * c).sum()
}

/// The calibrated region: an axis-aligned box in mm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// Smallest calibrated x, mm (maps to u = -1).
    pub x_min_mm: f64,
    /// Largest calibrated x, mm (maps to u = +1).
    pub x_max_mm: f64,
    /// Smallest calibrated y, mm (maps to v = -1).
    pub y_min_mm: f64,
    /// Largest calibrated y, mm (maps to v = +1).
    pub y_max_mm: f64,
}

/// A point mapped into a region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalized {
    /// Normalized x in [-1, 1].
    pub u: f64,
    /// Normalized y in [-1, 1].
    pub v: f64,
    /// True when the input lay outside the region (or was not finite) and was clamped.
    pub clamped: bool,
}

impl Region {
    /// Bounding box of the points, widened symmetrically to at least `min_span_mm` per axis
    /// so that a degenerate set (one location) still normalizes without dividing by zero.
    pub fn bounding(points: impl Iterator<Item = (f64, f64)>, min_span_mm: f64) -> Option<Self> {
        let mut r = Region {
            x_min_mm: f64::INFINITY,
            x_max_mm: f64::NEG_INFINITY,
            y_min_mm: f64::INFINITY,
            y_max_mm: f64::NEG_INFINITY,
        };
        for (x, y) in points.filter(|(x, y)| x.is_finite() && y.is_finite()) {
            r.x_min_mm = r.x_min_mm.min(x);
            r.x_max_mm = r.x_max_mm.max(x);
            r.y_min_mm = r.y_min_mm.min(y);
            r.y_max_mm = r.y_max_mm.max(y);
        }
        if !r.x_min_mm.is_finite() {
            return None;
        }
        let widen = |lo: &mut f64, hi: &mut f64| {
            let span = *hi - *lo;
            if span < min_span_mm {
                let pad = 0.5 * (min_span_mm - span);
                *lo -= pad;
                *hi += pad;
            }
        };
        widen(&mut r.x_min_mm, &mut r.x_max_mm);
        widen(&mut r.y_min_mm, &mut r.y_max_mm);
        Some(r)
    }

    /// Width and height, mm.
    pub fn span_mm(&self) -> (f64, f64) {
        (self.x_max_mm - self.x_min_mm, self.y_max_mm - self.y_min_mm)
    }

    /// The point clamped onto the region, mm, and whether it was outside. A point with a
    /// non-finite coordinate has no place: it goes to the centre, flagged.
    pub fn clamp(&self, x_mm: f64, y_mm: f64) -> ((f64, f64), bool) {
        if !(x_mm.is_finite() && y_mm.is_finite()) {
            return ((0.5 * (self.x_min_mm + self.x_max_mm), 0.5 * (self.y_min_mm + self.y_max_mm)), true);
        }
        let p = (x_mm.clamp(self.x_min_mm, self.x_max_mm), y_mm.clamp(self.y_min_mm, self.y_max_mm));
        (p, p != (x_mm, y_mm))
    }

    /// Maps a point to [-1, 1]^2, clamping (and flagging) points outside; a non-finite
    /// coordinate maps to the centre and is flagged.
    pub fn normalize(&self, x_mm: f64, y_mm: f64) -> Normalized {
        let map = |p: f64, lo: f64, hi: f64| -> (f64, bool) {
            if !p.is_finite() {
                return (0.0, true);
            }
            // A degenerate axis (never from `calibrate`, which needs a span) has only a centre.
            if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
                return (0.0, true);
            }
            let t = 2.0 * (p - lo) / (hi - lo) - 1.0;
            if t < -1.0 {
                (-1.0, true)
            } else if t > 1.0 {
                (1.0, true)
            } else {
                (t, false)
            }
        };
        let (u, cu) = map(x_mm, self.x_min_mm, self.x_max_mm);
        let (v, cv) = map(y_mm, self.y_min_mm, self.y_max_mm);
        Normalized { u, v, clamped: cu || cv }
    }

    /// Inverse of [`Region::normalize`] for points inside: (u, v) -> (x_mm, y_mm).
    pub fn denormalize(&self, u: f64, v: f64) -> (f64, f64) {
        (
            self.x_min_mm + 0.5 * (u + 1.0) * (self.x_max_mm - self.x_min_mm),
            self.y_min_mm + 0.5 * (v + 1.0) * (self.y_max_mm - self.y_min_mm),
        )
    }
}

/// A quadratic field `Phi(u, v) . coeffs`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct QuadField {
    /// Coefficients of `[1, u, v, u^2, u v, v^2]`.
    pub coeffs: [f64; NPHI],
}

impl QuadField {
    /// The constant field `c`.
    pub fn constant(c: f64) -> Self {
        Self { coeffs: [c, 0.0, 0.0, 0.0, 0.0, 0.0] }
    }

    /// Value at normalized coordinates.
    pub fn at(&self, u: f64, v: f64) -> f64 {
        field_value(&phi(u, v), &self.coeffs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalize_maps_corners_and_clamps_outside() {
        let r = Region { x_min_mm: -40.0, x_max_mm: 40.0, y_min_mm: -20.0, y_max_mm: 20.0 };
        let n = r.normalize(40.0, -20.0);
        assert_eq!((n.u, n.v, n.clamped), (1.0, -1.0, false));
        let n = r.normalize(0.0, 0.0);
        assert_eq!((n.u, n.v, n.clamped), (0.0, 0.0, false));
        let n = r.normalize(55.0, 10.0);
        assert_eq!((n.u, n.v, n.clamped), (1.0, 0.5, true));
        assert!(r.normalize(f64::NAN, 0.0).clamped);
        assert_eq!(r.denormalize(0.5, -0.5), (20.0, -10.0));
    }

    #[test]
    fn clamp_agrees_with_normalize() {
        let r = Region { x_min_mm: -40.0, x_max_mm: 40.0, y_min_mm: -20.0, y_max_mm: 20.0 };
        assert_eq!(r.clamp(f64::NAN, 5.0), ((0.0, 0.0), true));
        assert_eq!(r.clamp(1.0, f64::INFINITY), ((0.0, 0.0), true));
        for (x, y) in [(40.0, -20.0), (0.0, 0.0), (55.0, 10.0), (-3.0, -21.0), (-41.0, 25.0)] {
            let ((cx, cy), clamped) = r.clamp(x, y);
            let n = r.normalize(x, y);
            assert_eq!(clamped, n.clamped, "({x}, {y})");
            let (dx, dy) = r.denormalize(n.u, n.v);
            assert!((cx - dx).abs() < 1e-12 && (cy - dy).abs() < 1e-12, "({x}, {y}): ({cx}, {cy}) vs ({dx}, {dy})");
        }
    }

    #[test]
    fn bounding_box_widens_a_single_point() {
        let r = Region::bounding([(3.0, 4.0), (3.0, 4.0)].into_iter(), 10.0).unwrap();
        assert_eq!(r, Region { x_min_mm: -2.0, x_max_mm: 8.0, y_min_mm: -1.0, y_max_mm: 9.0 });
        assert!(Region::bounding(std::iter::empty(), 1.0).is_none());
    }

    #[test]
    fn field_evaluates_the_basis() {
        let f = QuadField { coeffs: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0] };
        // 1 + 2u + 3v + 4u^2 + 5uv + 6v^2 at (0.5, -1) = 1 + 1 - 3 + 1 - 2.5 + 6
        assert!((f.at(0.5, -1.0) - 3.5).abs() < 1e-12);
    }
}
