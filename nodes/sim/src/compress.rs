//! Contact physics of the EIT layer: pressing the liquid-filled foam expels liquid and lowers
//! the local conductivity. For each contact, the flat indenter's footprint (a disc carrying
//! force / area) is blurred by a Gaussian of about the foam thickness (load spreads through
//! the 5 mm layer); the local pressure p compresses the foam by
//! strain = strain_max * c(x, y) * g * (1 - exp(-p / p_sat)) (saturating; c is the foam's smooth
//! random compliance, g the press's seating factor per load level), and Archie's law gives
//! sigma = sigma0 * (1 - strain)^m.
//!
//! Units: positions mm, pressure kPa (1 N/mm^2 = 1000 kPa), conductivity S/m per element.
//! `Compressor` precomputes the radial footprint kernel of every diameter a scene uses.

use crate::profile::Profile;
use crate::randomness::{Seating, SmoothField, Stream};
use crate::timeline::Load;

/// Samples of each radial kernel table.
const KERNEL_SAMPLES: usize = 512;
/// The kernel is tabulated out to radius + this many blur sigmas (beyond: < 1e-6 of the peak).
const KERNEL_REACH_SIGMAS: f64 = 5.0;
/// Quadrature points per direction (radius, angle) when tabulating a kernel.
const KERNEL_QUADRATURE: usize = 64;
/// Largest strain allowed after the heterogeneity factor (the foam cannot collapse fully).
const STRAIN_CAP: f64 = 0.95;

/// Pressure per newton as a function of the distance from the contact centre, 1/mm^2.
#[derive(Debug, Clone)]
struct RadialKernel {
    diameter_mm: f64,
    step_mm: f64,
    values: Vec<f64>,
}

impl RadialKernel {
    /// Disc of `diameter_mm` with uniform load 1 / area, convolved with a Gaussian of `blur_mm`.
    fn new(diameter_mm: f64, blur_mm: f64) -> RadialKernel {
        let r = 0.5 * diameter_mm;
        let area = std::f64::consts::PI * r * r;
        let reach = r + KERNEL_REACH_SIGMAS * blur_mm.max(1e-9);
        let step_mm = reach / (KERNEL_SAMPLES - 1) as f64;
        let values = (0..KERNEL_SAMPLES)
            .map(|i| {
                let rho = i as f64 * step_mm;
                if blur_mm <= 0.0 {
                    return if rho <= r { 1.0 / area } else { 0.0 };
                }
                // probability that a Gaussian centred rho from the disc centre falls in the disc,
                // by midpoint quadrature in polar coordinates over the disc
                let q = KERNEL_QUADRATURE;
                let (dt, dphi) = (r / q as f64, std::f64::consts::PI / q as f64);
                let s2 = 2.0 * blur_mm * blur_mm;
                let mut sum = 0.0;
                for a in 0..q {
                    let t = (a as f64 + 0.5) * dt;
                    for b in 0..q {
                        let phi = (b as f64 + 0.5) * dphi;
                        let d2 = rho * rho + t * t - 2.0 * rho * t * phi.cos();
                        sum += (-d2 / s2).exp() * t;
                    }
                }
                // factor 2: the angle integral covers [0, pi) of a symmetric integrand
                let prob = 2.0 * sum * dt * dphi / (std::f64::consts::PI * s2);
                prob / area
            })
            .collect();
        RadialKernel { diameter_mm, step_mm, values }
    }

    fn at(&self, rho_mm: f64) -> f64 {
        let u = rho_mm / self.step_mm;
        let i = u as usize;
        if i + 1 >= self.values.len() {
            return 0.0;
        }
        let w = u - i as f64;
        self.values[i] * (1.0 - w) + self.values[i + 1] * w
    }
}

/// Turns the contacts of an instant into a per-element conductivity.
#[derive(Debug, Clone)]
pub struct Compressor {
    // Configuration
    sigma0_s_per_m: f64,
    strain_max: f64,
    pressure_sat_kpa: f64,
    archie_exponent: f64,
    /// Per-level seating factor g (`foam_seating_jitter`).
    seating: Seating,
    kernels: Vec<RadialKernel>,
    // Per element: centroid (mm) and compliance factor (1 + heterogeneity field)
    centroids_mm: Vec<[f64; 2]>,
    compliance: Vec<f64>,
    // Scratch: local pressure per element (kPa) and its seating-weighted sum
    pressure_kpa: Vec<f64>,
    seated_kpa: Vec<f64>,
}

impl Compressor {
    /// For elements with these centroids (mm), the indenter diameters a scene uses, and the
    /// foam's compliance field (relative deviation, zero-mean); `seed` fixes the per-level
    /// seating draws.
    pub fn new(
        profile: &Profile,
        centroids_mm: Vec<[f64; 2]>,
        diameters_mm: &[f64],
        foam: &SmoothField,
        seed: u64,
    ) -> Compressor {
        let blur_mm = profile.foam_thickness_mm * profile.spread_per_thickness;
        let mut kernels: Vec<RadialKernel> = Vec::new();
        for &d in diameters_mm {
            if !kernels.iter().any(|k| k.diameter_mm == d) {
                kernels.push(RadialKernel::new(d, blur_mm));
            }
        }
        let compliance = centroids_mm.iter().map(|c| (1.0 + foam.at(c[0], c[1])).max(0.0)).collect();
        let n = centroids_mm.len();
        Compressor {
            sigma0_s_per_m: profile.sigma0_s_per_m,
            strain_max: profile.strain_max,
            pressure_sat_kpa: profile.pressure_sat_kpa,
            archie_exponent: profile.archie_exponent,
            seating: Seating::new(seed, Stream::FoamSeating, profile.foam_seating_jitter),
            kernels,
            centroids_mm,
            compliance,
            pressure_kpa: vec![0.0; n],
            seated_kpa: vec![0.0; n],
        }
    }

    pub fn element_count(&self) -> usize {
        self.centroids_mm.len()
    }

    /// Conductivity of the unloaded foam, S/m.
    pub fn sigma0_s_per_m(&self) -> f64 {
        self.sigma0_s_per_m
    }

    /// Seating factor g of a load level (1 + `foam_seating_jitter` N(0, 1), at least 0): a pure
    /// function of (seed, level); 1 without jitter. The conductivity under a load depends on its
    /// position, diameter, force and this factor, and on nothing else.
    pub fn seating(&self, level: u32) -> f64 {
        self.seating.factor(level)
    }

    /// Writes the conductivity (S/m) of every element under `loads` into `sigma`. A load whose
    /// diameter was not announced to `new` panics (the simulator announces all of them).
    pub fn conductivity_into(&mut self, loads: &[Load], sigma: &mut [f64]) {
        self.pressure_kpa.fill(0.0);
        self.seated_kpa.fill(0.0);
        for load in loads {
            let seating = self.seating(load.level);
            let k = self
                .kernels
                .iter()
                .find(|k| k.diameter_mm == load.diameter_mm)
                .expect("every diameter of the timeline has a kernel");
            let n_per_mm2_to_kpa = 1000.0;
            let elements = self.pressure_kpa.iter_mut().zip(&mut self.seated_kpa).zip(&self.centroids_mm);
            for ((p, q), c) in elements {
                let rho = ((c[0] - load.x_mm).powi(2) + (c[1] - load.y_mm).powi(2)).sqrt();
                let dp = n_per_mm2_to_kpa * load.force_n * k.at(rho);
                *p += dp;
                *q += dp * seating;
            }
        }
        let elements = sigma.iter_mut().zip(&self.pressure_kpa).zip(&self.seated_kpa).zip(&self.compliance);
        for (((s, p), q), c) in elements {
            // pressure-weighted seating factor of the contacts that load this element
            let seating = if *p > 0.0 { q / p } else { 1.0 };
            let saturation = 1.0 - (-p / self.pressure_sat_kpa).exp();
            let strain = (self.strain_max * c * seating * saturation).min(STRAIN_CAP);
            *s = self.sigma0_s_per_m * (1.0 - strain).powf(self.archie_exponent);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::randomness::stream;

    fn load(x: f64, y: f64, d: f64, f: f64) -> Load {
        Load { x_mm: x, y_mm: y, diameter_mm: d, force_n: f, press: 0, level: 0 }
    }

    #[test]
    fn kernel_integrates_to_one_newton() {
        for (d, blur) in [(15.0, 3.0), (10.0, 0.0), (25.0, 5.0)] {
            let k = RadialKernel::new(d, blur);
            // integral of 2 pi rho K(rho) d rho over the table: force conservation
            let total: f64 = (0..KERNEL_SAMPLES * 4)
                .map(|i| {
                    let rho = (i as f64 + 0.5) * k.step_mm / 4.0;
                    2.0 * std::f64::consts::PI * rho * k.at(rho) * k.step_mm / 4.0
                })
                .sum();
            // midpoint rule on a 2048-point table: the disc edge (blur 0) costs ~1e-3
            assert!((total - 1.0).abs() < 3e-3, "d {d} blur {blur}: {total}");
        }
        // blurring lowers the centre of a small disc and spreads it beyond its edge
        let sharp = RadialKernel::new(10.0, 0.0);
        let soft = RadialKernel::new(10.0, 3.0);
        assert!(soft.at(0.0) < sharp.at(0.0));
        assert!(soft.at(6.0) > 0.0 && sharp.at(6.0) == 0.0);
    }

    #[test]
    fn conductivity_falls_under_load_and_saturates() {
        let p = Profile::ideal();
        let centroids: Vec<[f64; 2]> = vec![[0.0, 0.0], [30.0, 0.0]];
        let field = SmoothField::new(&mut stream(1, Stream::FoamField), 0.0, 10.0);
        let mut c = Compressor::new(&p, centroids, &[15.0], &field, 0);
        let mut s = vec![0.0; 2];
        c.conductivity_into(&[], &mut s);
        assert_eq!(s, vec![p.sigma0_s_per_m; 2]);
        let mut drops = Vec::new();
        for f in [1.0, 5.0, 10.0, 100.0, 1000.0] {
            c.conductivity_into(&[load(0.0, 0.0, 15.0, f)], &mut s);
            assert_eq!(s[1], p.sigma0_s_per_m, "far element untouched");
            drops.push(p.sigma0_s_per_m - s[0]);
        }
        assert!(drops.windows(2).all(|w| w[1] > w[0]), "{drops:?}");
        // increments shrink (saturation), and the limit is sigma0 * (1 - (1 - strain_max)^m)
        assert!(drops[1] - drops[0] > drops[2] - drops[1]);
        let limit = p.sigma0_s_per_m * (1.0 - (1.0 - p.strain_max).powf(p.archie_exponent));
        assert!((drops[4] - limit).abs() < 1e-9 * limit.max(1.0));
    }
}
