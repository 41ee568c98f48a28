//! Synthetic single-contact calibration data with known spatial nonuniformity.
//!
//! Pneumatic: dP = 0.3 F k(u, v) kPa with k = 1 - 0.1 (u^2 + v^2) (less sensitive near the
//! edges, as in the paper). EIT: C = 50 F^0.7 e(u, v) with e = 1 + 0.6 u (strongly
//! nonuniform). Area = 300 + 20 F mm^2. Centroid = truth + N(0, 1.5 mm). Locations: a 5 x 5
//! grid over [-40, 40] mm; forces 1, 3, 5, 7, 9 N; 6 frames per hold.
#![allow(dead_code)] // each test binary uses a different subset

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use skinflow_contact::CalibSample;

pub fn k_pneumatic(x_mm: f64, y_mm: f64) -> f64 {
    let (u, v) = (x_mm / 40.0, y_mm / 40.0);
    1.0 - 0.1 * (u * u + v * v)
}

pub fn e_eit(x_mm: f64, _y_mm: f64) -> f64 {
    1.0 + 0.6 * x_mm / 40.0
}

pub fn dp_of(force_n: f64, x_mm: f64, y_mm: f64) -> f64 {
    0.3 * force_n * k_pneumatic(x_mm, y_mm)
}

pub fn cond_of(force_n: f64, x_mm: f64, y_mm: f64) -> f64 {
    50.0 * force_n.powf(0.7) * e_eit(x_mm, y_mm)
}

/// Frames in recording order: location by location, force by force, `per_hold` frames each.
pub fn frames(seed: u64, grid: usize, forces: &[f64], per_hold: usize, dp_noise_kpa: f64) -> Vec<CalibSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let mut out = Vec::new();
    for i in 0..grid {
        for j in 0..grid {
            let step = if grid > 1 { 80.0 / (grid - 1) as f64 } else { 0.0 };
            let (tx, ty) = (-40.0 + step * i as f64 * f64::from(u8::from(grid > 1)), -40.0 + step * j as f64);
            let (tx, ty) = if grid == 1 { (0.0, 0.0) } else { (tx, ty) };
            for &f in forces {
                for _ in 0..per_hold {
                    out.push(CalibSample {
                        x_mm: tx + 1.5 * n.sample(&mut rng),
                        y_mm: ty + 1.5 * n.sample(&mut rng),
                        true_x_mm: tx,
                        true_y_mm: ty,
                        force_n: f,
                        dp_kpa: dp_of(f, tx, ty) + dp_noise_kpa * n.sample(&mut rng),
                        cond_sum: cond_of(f, tx, ty) * (1.0 + 0.02 * n.sample(&mut rng)),
                        area_mm2: 300.0 + 20.0 * f,
                        diameter_mm: 15.0,
                    });
                }
            }
        }
    }
    out
}

/// The paper-like calibration set: 5 x 5 locations, 5 forces, 6 frames per hold.
pub fn paper_like(seed: u64) -> Vec<CalibSample> {
    frames(seed, 5, &[1.0, 3.0, 5.0, 7.0, 9.0], 6, 0.01)
}
