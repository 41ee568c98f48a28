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
    let step = if grid > 1 { 80.0 / (grid - 1) as f64 } else { 0.0 };
    let mut locations = Vec::with_capacity(grid * grid);
    for i in 0..grid {
        for j in 0..grid {
            let (tx, ty) = (-40.0 + step * i as f64 * f64::from(u8::from(grid > 1)), -40.0 + step * j as f64);
            locations.push(if grid == 1 { (0.0, 0.0) } else { (tx, ty) });
        }
    }
    frames_at(seed, &locations, forces, per_hold, dp_noise_kpa)
}

/// [`frames`] at the given true locations (centroid noise 1.5 mm, C noise 2 %).
pub fn frames_at(
    seed: u64,
    locations: &[(f64, f64)],
    forces: &[f64],
    per_hold: usize,
    dp_noise_kpa: f64,
) -> Vec<CalibSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let mut out = Vec::new();
    for &(tx, ty) in locations {
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
                    hold: 0,
                });
            }
        }
    }
    out
}

/// The paper-like calibration set: 5 x 5 locations, 5 forces, 6 frames per hold.
pub fn paper_like(seed: u64) -> Vec<CalibSample> {
    frames(seed, 5, &[1.0, 3.0, 5.0, 7.0, 9.0], 6, 0.01)
}

/// Blur of the synthetic reconstruction, mm (a Gaussian blob per contact).
pub const SIGMA_MM: f64 = 8.0;
/// Segmentation floor for the synthetic images (image units).
pub const FLOOR: f64 = 0.01;

/// Peak conductivity decrease of a contact (image units): 0.02 F^0.7 e(x, y).
pub fn amplitude(force_n: f64, x_mm: f64, y_mm: f64) -> f64 {
    0.02 * force_n.powf(0.7) * e_eit(x_mm, y_mm)
}

/// A 64 x 64 image over the 100 mm sensor with one negative Gaussian per (x, y, F) contact.
pub fn image(contacts: &[(f64, f64, f64)]) -> Vec<f64> {
    let g = skinflow_contact::ImageGrid::centred(64, 64, 100.0, 100.0);
    let mut img = vec![0.0; g.len()];
    for row in 0..g.height {
        for col in 0..g.width {
            let (x, y) = (g.x_mm(col), g.y_mm(row));
            img[row * g.width + col] = -contacts
                .iter()
                .map(|&(cx, cy, f)| {
                    amplitude(f, cx, cy) * (-((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * SIGMA_MM * SIGMA_MM)).exp()
                })
                .sum::<f64>();
        }
    }
    img
}

/// Calibration frames produced by segmenting synthetic images (the lead's pipeline path):
/// 5 x 5 locations over [-40, 40], forces 2..10 N, 2 frames per hold, 15 mm indenter.
pub fn segmented_frames() -> Vec<CalibSample> {
    let grid = skinflow_contact::ImageGrid::centred(64, 64, 100.0, 100.0);
    let mut seg = skinflow_contact::Segmenter::new(grid, &skinflow_contact::SegmentParams::with_floor(FLOOR)).unwrap();
    let mut out = seg.new_contacts();
    let mut frames = Vec::new();
    for i in 0..5 {
        for j in 0..5 {
            let (tx, ty) = (-40.0 + 20.0 * i as f64, -40.0 + 20.0 * j as f64);
            for f in [2.0, 4.0, 6.0, 8.0, 10.0] {
                seg.segment_into(&image(&[(tx, ty, f)]), &mut out).unwrap();
                let c = *out.as_slice().first().expect("every calibration contact is above the floor");
                for _ in 0..2 {
                    frames.push(CalibSample {
                        x_mm: c.x_mm,
                        y_mm: c.y_mm,
                        true_x_mm: tx,
                        true_y_mm: ty,
                        force_n: f,
                        dp_kpa: dp_of(f, tx, ty),
                        cond_sum: c.sum,
                        area_mm2: c.area_mm2,
                        diameter_mm: 15.0,
                        hold: 0,
                    });
                }
            }
        }
    }
    frames
}
