//! Checks on calibration data that a least-squares fit cannot make on its own: whether the
//! locations determine a quadratic field, how many force levels there are, which samples are
//! gross pressure spikes, and whether a fitted f rises over its signal range.
//!
//! Every threshold here is fixed a priori (the comments give the reasoning) and is meant to
//! leave ordinary calibration data alone: each check only fires on data the fit cannot use.

use super::field::{NPHI, phi};
use super::map::SignalMap;

/// Smallest eigenvalue of `Phi^T Phi / L` over the L locations (normalized coordinates) below
/// which the locations do not determine a quadratic field.
///
/// Why 1e-3: full grids of 3 x 3 to 7 x 7 locations on [-1, 1]^2 give 0.10 to 0.11, and the
/// layouts on which a quadratic is not determined give 0 up to the centroid noise (a line in
/// any direction: 1e-11 to 1e-7 with 0.3 to 1.5 mm of noise on +-40 mm; two rows, a cross, a
/// circle: u v, v^2 - 1 or u^2 + v^2 - 1 vanish on them). A unit coefficient vector c has RMS
/// sqrt(c^T M c) over the locations but can reach |Phi| |c| = sqrt(6) at a corner of the
/// region, so at 1e-3 some field direction is amplified ~80 times from what the data show to
/// what the strategies use; the ridge prior, not the data, then decides it.
pub const MIN_LAYOUT_EIGENVALUE: f64 = 1e-3;

/// Smallest eigenvalue of `Phi^T Phi / L` over `points` (normalized coordinates, one per
/// location); `None` for no points or a non-finite coordinate.
pub fn layout_eigenvalue(points: &[(f64, f64)]) -> Option<f64> {
    if points.is_empty() || points.iter().any(|(u, v)| !(u.is_finite() && v.is_finite())) {
        return None;
    }
    let mut m = nalgebra::SMatrix::<f64, NPHI, NPHI>::zeros();
    for &(u, v) in points {
        let p = nalgebra::SVector::<f64, NPHI>::from(phi(u, v));
        m += p * p.transpose();
    }
    m /= points.len() as f64;
    Some(m.symmetric_eigenvalues().min())
}

/// Forces closer than this fraction of the largest force are one level.
///
/// Why 2 %: levels of a calibration protocol differ by 10 % or more of the largest force
/// (1, 3, ... 9 N), while the scatter of a load cell within one level is well under 1 %. A
/// continuous sweep counts as many levels, as it should.
pub const FORCE_LEVEL_TOL_REL: f64 = 0.02;

/// Distinct force levels: sorted forces, a new level whenever a force is more than
/// [`FORCE_LEVEL_TOL_REL`] x the largest |force| above the first force of the current level
/// (measured from that first force, so a continuous ramp does not chain into one level).
pub fn force_levels(forces: &[f64]) -> usize {
    let mut f: Vec<f64> = forces.iter().copied().filter(|v| v.is_finite()).collect();
    f.sort_by(f64::total_cmp);
    let tol = FORCE_LEVEL_TOL_REL * f.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut levels = 0;
    let mut start = f64::NEG_INFINITY;
    for v in f {
        if levels == 0 || v > start + tol {
            levels += 1;
            start = v;
        }
    }
    levels
}

/// A pressure spike is at least this many robust standard deviations (1.4826 x the median
/// absolute residual of its location) off its location's power law.
///
/// Why 5: for Gaussian scatter a sample is that far out with probability 6e-7, so the rule
/// cuts nothing of clean data by chance.
pub const SPIKE_ROBUST_SDS: f64 = 5.0;

/// A pressure spike is also more than this factor above or below its location's power law.
///
/// Why 2: the robust SD is 0 for noise-free data and tiny for long holds, so the SD test
/// alone would cut any mild curvature the power law does not follow. No mechanical effect of
/// a sealed chamber (saturation, hysteresis, drift between neighbouring holds) moves a hold's
/// mean pressure by a factor of two off its neighbours; a dropout or a spike does (one
/// 30 kPa frame in a 6-frame 1 N hold: a factor of 17).
pub const SPIKE_MIN_FACTOR: f64 = 2.0;

/// Fewer samples than this at a location are not judged: with 3, the repeated median's
/// slope for a clean sample is the mean of a clean and a spiked pair slope.
pub const SPIKE_MIN_SAMPLES: usize = 4;

/// Which samples are gross pressure spikes.
///
/// Per location (`loc_of`), ln dP is fitted on ln F by Siegel's repeated median (a power law
/// dP = c F^gamma, robust to up to half the samples being wrong; pairs at one force level are
/// skipped, and a location with one level gets slope 0), and a sample is a spike when its
/// residual exceeds both [`SPIKE_ROBUST_SDS`] robust SDs and ln [`SPIKE_MIN_FACTOR`]. Samples
/// need F > 0 and dP > 0 (the quality filter's job); any other sample is never flagged.
pub fn pressure_outliers(force_n: &[f64], dp_kpa: &[f64], loc_of: &[usize]) -> Vec<bool> {
    let n = force_n.len().min(dp_kpa.len()).min(loc_of.len());
    let mut out = vec![false; force_n.len()];
    let usable = |t: usize| force_n[t] > 0.0 && dp_kpa[t] > 0.0 && force_n[t].is_finite() && dp_kpa[t].is_finite();
    let mut sites: Vec<usize> = loc_of[..n].to_vec();
    sites.sort_unstable();
    sites.dedup();
    let same_level = (1.0 + FORCE_LEVEL_TOL_REL).ln();
    for site in sites {
        let idx: Vec<usize> = (0..n).filter(|&t| loc_of[t] == site && usable(t)).collect();
        if idx.len() < SPIKE_MIN_SAMPLES {
            continue;
        }
        let x: Vec<f64> = idx.iter().map(|&t| force_n[t].ln()).collect();
        let y: Vec<f64> = idx.iter().map(|&t| dp_kpa[t].ln()).collect();
        let per_sample: Vec<f64> = (0..idx.len())
            .filter_map(|i| {
                let slopes: Vec<f64> = (0..idx.len())
                    .filter(|&j| (x[j] - x[i]).abs() > same_level)
                    .map(|j| (y[j] - y[i]) / (x[j] - x[i]))
                    .collect();
                median(&slopes)
            })
            .collect();
        let slope = median(&per_sample).unwrap_or(0.0);
        let offsets: Vec<f64> = x.iter().zip(&y).map(|(a, b)| b - slope * a).collect();
        let Some(intercept) = median(&offsets) else { continue };
        let resid: Vec<f64> = x.iter().zip(&y).map(|(a, b)| b - slope * a - intercept).collect();
        let Some(mad) = median(&resid.iter().map(|r| r.abs()).collect::<Vec<_>>()) else { continue };
        let cut = (SPIKE_ROBUST_SDS * 1.4826 * mad).max(SPIKE_MIN_FACTOR.ln());
        for (&t, r) in idx.iter().zip(&resid) {
            out[t] = r.abs() > cut;
        }
    }
    out
}

fn median(v: &[f64]) -> Option<f64> {
    crate::eval::metrics::percentile(v, 50.0)
}

/// An f whose rise over its signal range is under this fraction of the calibration's force
/// range is called flat.
///
/// Why 0.1: with the gain normalized to mean 1, g f + b spans about f's rise over the signal
/// range at one location, while every location saw the force range. A rise under a tenth of
/// it leaves at least 90 % of the force variation to the offset field, which does not depend
/// on the signal: such an f (a constant, at the extreme) reports roughly one force for any
/// press.
pub const FLAT_MAP_RISE_REL: f64 = 0.1;

/// The increase of `map` (its monotone envelope) from the bottom to the top of its range, N.
pub fn map_rise(map: &SignalMap) -> f64 {
    map.eval(map.signal_max).0 - map.eval(map.signal_min).0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::correct::fit::Quadratic;

    #[test]
    fn grids_determine_a_quadratic_and_lines_rows_and_circles_do_not() {
        let grid: Vec<(f64, f64)> =
            (0..3).flat_map(|i| (0..3).map(move |j| (-1.0 + i as f64, -1.0 + j as f64))).collect();
        // 3 x 3 grid on {-1, 0, 1}^2: exactly 1/9 by hand (the u^2 - 2/3 direction).
        assert!((layout_eigenvalue(&grid).unwrap() - 1.0 / 9.0).abs() < 1e-12);
        let line: Vec<(f64, f64)> = (0..9).map(|i| (-1.0 + 0.25 * i as f64, 0.5 * (-1.0 + 0.25 * i as f64))).collect();
        let rows: Vec<(f64, f64)> =
            (0..10).map(|i| (-1.0 + 0.5 * (i % 5) as f64, if i < 5 { -1.0 } else { 1.0 })).collect();
        let circle: Vec<(f64, f64)> = (0..12).map(|i| (i as f64 * std::f64::consts::FRAC_PI_6).sin_cos()).collect();
        for (name, pts) in [("line", line), ("two rows", rows), ("circle", circle)] {
            let e = layout_eigenvalue(&pts).unwrap();
            assert!(e < 1e-12, "{name}: {e}");
        }
        assert!(layout_eigenvalue(&[]).is_none());
        assert!(layout_eigenvalue(&[(f64::NAN, 0.0)]).is_none());
    }

    #[test]
    fn force_levels_count_protocol_levels_not_load_cell_scatter() {
        assert_eq!(force_levels(&[1.0, 3.0, 5.0, 7.0, 9.0, 1.0, 9.0]), 5);
        assert_eq!(force_levels(&[2.0, 8.0, 2.01, 7.99, 8.05]), 2);
        assert_eq!(force_levels(&[5.0; 4]), 1);
        // A ramp 0.1 .. 10 N in 0.01 N steps: one level per 0.2 N.
        let ramp: Vec<f64> = (10..=1000).map(|i| 0.01 * i as f64).collect();
        assert!(force_levels(&ramp) >= 45, "{}", force_levels(&ramp));
        assert_eq!(force_levels(&[]), 0);
    }

    #[test]
    fn a_spiked_hold_is_flagged_and_clean_curved_data_are_not() {
        // Two locations with dP = k F^0.8 (curved in F), 1..9 N; location 1 has one spike.
        let forces = [1.0, 3.0, 5.0, 7.0, 9.0];
        let (mut f, mut p, mut loc) = (Vec::new(), Vec::new(), Vec::new());
        for (site, k) in [(0, 0.30), (1, 0.25)] {
            for &force in &forces {
                f.push(force);
                p.push(k * f64::powf(force, 0.8));
                loc.push(site);
            }
        }
        let clean = pressure_outliers(&f, &p, &loc);
        assert!(clean.iter().all(|&o| !o), "{clean:?}");
        // Even a quadratic bend the power law does not follow (exact data: robust SD 0).
        let bent: Vec<f64> = f.iter().map(|&v| 0.3 * v - 0.012 * v * v).collect();
        assert!(pressure_outliers(&f, &bent, &loc).iter().all(|&o| !o));
        // One 1 N hold whose mean took a 30 kPa frame out of 6: (30 + 5 x 0.3) / 6.
        p[5] = (30.0 + 5.0 * 0.25) / 6.0;
        let spiked = pressure_outliers(&f, &p, &loc);
        assert_eq!(spiked.iter().filter(|&&o| o).count(), 1, "{spiked:?}");
        assert!(spiked[5]);
        // Too few samples at a location: not judged.
        assert!(pressure_outliers(&f[5..8], &p[5..8], &loc[5..8]).iter().all(|&o| !o));
    }

    #[test]
    fn rise_of_a_constant_and_of_a_line() {
        let flat = SignalMap { quadratic: Quadratic { a0: 5.0, a1: 0.0, a2: 0.0 }, signal_min: 0.2, signal_max: 3.0 };
        assert_eq!(map_rise(&flat), 0.0);
        let line = SignalMap { quadratic: Quadratic { a0: 0.0, a1: 3.0, a2: 0.0 }, ..flat };
        assert!((map_rise(&line) - 8.4).abs() < 1e-12);
    }
}
