//! The pneumatic layer: a sealed, gyroid-filled TPE chamber under the foam, read by a gauge
//! pressure sensor at 20 Hz. Each contact adds
//! dP_i = S(footprint) * g_level * F / (1 + F / F_nl(d)), where S is the local sensitivity
//! (kPa/N, lower near the stiff boundary, with smooth random infill irregularity, 0 outside the
//! sensor where the frame takes the load) averaged over the indenter footprint, g_level the
//! seating variability of the load level, and F_nl(d) = F_nl min(1, (d_ref/d)^q) the mild
//! saturation that larger indenters reach sooner. The sum passes a play operator (hysteresis)
//! that relaxes towards the load (creep), then P0, slow drift, an optional steady ramp (a leak)
//! and sensor noise are added.
//!
//! Units: kPa (gauge), N, mm, s. Samples must be requested in non-decreasing time.
//!
//! Cost follows the scene: what a contact's response depends on besides its force (footprint
//! sensitivity, seating gain, saturation force) is kept per contact slot and recomputed only
//! when the placed contact changes, so a static hold or a ramp of one indentation averages its
//! footprint once (`footprint_evaluations`), not on every sample.

use crate::profile::Profile;
use crate::randomness::{Drift, Seating, SmoothField, Stream, normal, stream};
use crate::timeline::Load;
use rand_chacha::ChaCha8Rng;
use skinflow_eit::Sensor;

/// Footprint quadrature: rings of points at these fractions of the radius, with these counts
/// (equal-area rings, so the points carry equal weight together with the centre).
const FOOTPRINT_RINGS: [(f64, usize); 3] = [(0.408, 6), (0.707, 12), (0.913, 18)];

/// What one placed contact contributes per newton: everything of
/// `S_fp * g_level * F / (1 + F / F_nl(d))` except the force, with the placement it is for.
#[derive(Debug, Clone, Copy)]
struct PlacedContact {
    x_mm: f64,
    y_mm: f64,
    diameter_mm: f64,
    level: u32,
    /// Footprint sensitivity S_fp, kPa/N.
    sensitivity_kpa_per_n: f64,
    /// Seating gain g_level of `level`.
    gain: f64,
    /// Saturation force F_nl(d), N.
    saturation_n: f64,
}

impl PlacedContact {
    /// Whether the footprint (position and diameter) is this load's.
    fn has_footprint_of(&self, l: &Load) -> bool {
        self.x_mm == l.x_mm && self.y_mm == l.y_mm && self.diameter_mm == l.diameter_mm
    }

    /// Pressure change under `force_n`, kPa.
    fn dp_kpa(&self, force_n: f64) -> f64 {
        self.sensitivity_kpa_per_n * self.gain * force_n / (1.0 + force_n / self.saturation_n)
    }
}

/// The pressure channel.
#[derive(Debug, Clone)]
pub struct Pneumatic {
    // Configuration
    p0_kpa: f64,
    sensitivity_kpa_per_n: f64,
    edge_stiffening: f64,
    edge_length_mm: f64,
    nonlinearity_force_n: f64,
    reference_diameter_mm: f64,
    area_exponent: f64,
    hysteresis_kpa: f64,
    hysteresis_tau_s: f64,
    /// Per-level seating gain g_level (`seating_jitter`).
    seating: Seating,
    noise_kpa: f64,
    ramp_kpa_per_s: f64,
    half_extents_mm: (f64, f64),
    heterogeneity: SmoothField,
    // Internal state
    /// Output of the play operator (hysteresis), kPa above P0.
    play_kpa: f64,
    last_t_s: f64,
    drift: Drift,
    noise: ChaCha8Rng,
    /// Per contact slot (index in the loads of a sample): the last placed contact seen there.
    placed: Vec<PlacedContact>,
    /// Footprint averages computed by `sample` (cache misses).
    footprint_evaluations: u64,
}

impl Pneumatic {
    pub fn new(profile: &Profile, sensor: &Sensor, seed: u64) -> Pneumatic {
        let heterogeneity = SmoothField::new(
            &mut stream(seed, Stream::SensitivityField),
            profile.sensitivity_heterogeneity,
            profile.sensitivity_heterogeneity_length_mm,
        );
        Pneumatic {
            p0_kpa: profile.p0_kpa,
            sensitivity_kpa_per_n: profile.sensitivity_kpa_per_n,
            edge_stiffening: profile.edge_stiffening,
            edge_length_mm: profile.edge_length_mm,
            nonlinearity_force_n: profile.nonlinearity_force_n,
            reference_diameter_mm: profile.reference_diameter_mm,
            area_exponent: profile.area_exponent,
            hysteresis_kpa: profile.hysteresis_kpa,
            hysteresis_tau_s: profile.hysteresis_tau_s,
            seating: Seating::new(seed, Stream::Seating, profile.seating_jitter),
            noise_kpa: profile.pressure_noise_kpa,
            ramp_kpa_per_s: profile.pressure_ramp_kpa_per_s,
            half_extents_mm: sensor.half_extents_mm(),
            heterogeneity,
            play_kpa: 0.0,
            last_t_s: 0.0,
            drift: Drift::new(
                stream(seed, Stream::PressureDrift),
                profile.pressure_drift_kpa,
                profile.pressure_drift_tau_s,
            ),
            noise: stream(seed, Stream::PressureNoise),
            placed: Vec::new(),
            footprint_evaluations: 0,
        }
    }

    /// Footprint averages `sample` has computed so far: one per change of a contact's placed
    /// position or diameter, none for samples of a hold or a ramp of the same indentation.
    pub fn footprint_evaluations(&self) -> u64 {
        self.footprint_evaluations
    }

    /// Local sensitivity at a point, kPa/N (0 outside the sensor).
    pub fn sensitivity_kpa_per_n(&self, x_mm: f64, y_mm: f64) -> f64 {
        let (hx, hy) = self.half_extents_mm;
        let (dx, dy) = (hx - x_mm.abs(), hy - y_mm.abs());
        if dx < 0.0 || dy < 0.0 {
            return 0.0;
        }
        let l = self.edge_length_mm;
        let interior = (1.0 - (-dx / l).exp()) * (1.0 - (-dy / l).exp());
        let edge = 1.0 - interior;
        self.sensitivity_kpa_per_n
            * (1.0 - self.edge_stiffening * edge)
            * (1.0 + self.heterogeneity.at(x_mm, y_mm)).max(0.0)
    }

    /// Sensitivity averaged over a disc footprint, kPa/N.
    pub fn footprint_sensitivity_kpa_per_n(&self, x_mm: f64, y_mm: f64, diameter_mm: f64) -> f64 {
        let r = 0.5 * diameter_mm;
        let mut sum = self.sensitivity_kpa_per_n(x_mm, y_mm);
        let mut count = 1usize;
        for (frac, n) in FOOTPRINT_RINGS {
            for k in 0..n {
                let a = std::f64::consts::TAU * (k as f64 + 0.5) / n as f64;
                sum += self.sensitivity_kpa_per_n(x_mm + frac * r * a.cos(), y_mm + frac * r * a.sin());
                count += 1;
            }
        }
        sum / count as f64
    }

    /// Saturation force F_nl(d) of an indenter of `diameter_mm`, N.
    fn saturation_n(&self, diameter_mm: f64) -> f64 {
        let area = (self.reference_diameter_mm / diameter_mm).powf(self.area_exponent).min(1.0);
        self.nonlinearity_force_n * area
    }

    /// The force-independent part of a load's response (evaluates its footprint).
    fn place(&self, l: &Load) -> PlacedContact {
        PlacedContact {
            x_mm: l.x_mm,
            y_mm: l.y_mm,
            diameter_mm: l.diameter_mm,
            level: l.level,
            sensitivity_kpa_per_n: self.footprint_sensitivity_kpa_per_n(l.x_mm, l.y_mm, l.diameter_mm),
            gain: self.seating.factor(l.level),
            saturation_n: self.saturation_n(l.diameter_mm),
        }
    }

    /// Pressure change of the loads with no history (quasi-static, noiseless), kPa.
    pub fn static_dp_kpa(&self, loads: &[Load]) -> f64 {
        loads.iter().map(|l| self.place(l).dp_kpa(l.force_n)).sum()
    }

    /// `static_dp_kpa` through the per-slot cache: equal to it bit for bit, but a contact whose
    /// placed footprint is the one last seen in its slot is not evaluated again.
    fn cached_dp_kpa(&mut self, loads: &[Load]) -> f64 {
        for (i, l) in loads.iter().enumerate() {
            match self.placed.get(i) {
                Some(p) if p.has_footprint_of(l) => {
                    if p.level != l.level {
                        let gain = self.seating.factor(l.level);
                        let p = &mut self.placed[i];
                        p.level = l.level;
                        p.gain = gain;
                    }
                }
                _ => {
                    let fresh = self.place(l);
                    self.footprint_evaluations += 1;
                    if i < self.placed.len() {
                        self.placed[i] = fresh;
                    } else {
                        self.placed.push(fresh);
                    }
                }
            }
        }
        self.placed.iter().zip(loads).map(|(p, l)| p.dp_kpa(l.force_n)).sum()
    }

    /// One gauge-pressure sample at `t_s` under `loads`, kPa: advances hysteresis and drift.
    pub fn sample(&mut self, t_s: f64, loads: &[Load]) -> f64 {
        let x = self.cached_dp_kpa(loads);
        let dt = (t_s - self.last_t_s).max(0.0);
        self.last_t_s = t_s;
        let h = self.hysteresis_kpa;
        // play operator: the output moves only when the input leaves the band of half-width h
        if x > self.play_kpa + h {
            self.play_kpa = x - h;
        } else if x < self.play_kpa - h {
            self.play_kpa = x + h;
        }
        // and creeps towards the input (viscoelastic relaxation of the shell)
        self.play_kpa += (x - self.play_kpa) * (1.0 - (-dt / self.hysteresis_tau_s).exp());
        let noise = if self.noise_kpa > 0.0 { self.noise_kpa * normal(&mut self.noise) } else { 0.0 };
        self.p0_kpa + self.play_kpa + self.drift.at(t_s) + self.ramp_kpa_per_s * t_s + noise
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(x: f64, y: f64, d: f64, f: f64) -> Load {
        Load { x_mm: x, y_mm: y, diameter_mm: d, force_n: f, press: 0, level: 0 }
    }

    #[test]
    fn ideal_pressure_is_p0_plus_a_monotone_mildly_saturating_response() {
        let p = Profile::ideal();
        let mut pn = Pneumatic::new(&p, &Sensor::paper_100mm(), 7);
        assert_eq!(pn.sample(0.0, &[]), p.p0_kpa);
        let dps: Vec<f64> = (1..=10).map(|f| pn.static_dp_kpa(&[load(0.0, 0.0, 15.0, f as f64)])).collect();
        assert!(dps.windows(2).all(|w| w[1] > w[0]));
        // mild: slope at 10 N is within 25 % of the slope at 1 N
        let (s1, s10) = (dps[1] - dps[0], dps[9] - dps[8]);
        assert!(s10 < s1 && s10 > 0.75 * s1, "{s1} {s10}");
        // centre slope close to the nominal sensitivity (edge term ~ 2 exp(-50/18) at the centre)
        assert!((dps[0] / p.sensitivity_kpa_per_n - 1.0).abs() < 0.15, "{}", dps[0]);
        assert!((pn.sample(1.0, &[load(0.0, 0.0, 15.0, 5.0)]) - p.p0_kpa - dps[4]).abs() < 1e-12);
    }

    #[test]
    fn boundary_is_stiffer_and_large_indenters_saturate_sooner() {
        let pn = Pneumatic::new(&Profile::ideal(), &Sensor::paper_100mm(), 7);
        let centre = pn.static_dp_kpa(&[load(0.0, 0.0, 15.0, 5.0)]);
        let edge = pn.static_dp_kpa(&[load(45.0, 0.0, 15.0, 5.0)]);
        let corner = pn.static_dp_kpa(&[load(45.0, 45.0, 15.0, 5.0)]);
        assert!(centre > edge && edge > corner, "{centre} {edge} {corner}");
        let ratio =
            |d: f64, f: f64| pn.static_dp_kpa(&[load(0.0, 0.0, d, f)]) / pn.static_dp_kpa(&[load(0.0, 0.0, 15.0, f)]);
        assert!(ratio(25.0, 10.0) < ratio(25.0, 1.0));
        assert!(ratio(25.0, 10.0) < 0.95);
        // two contacts add
        let both = pn.static_dp_kpa(&[load(-20.0, 0.0, 10.0, 2.0), load(20.0, 0.0, 10.0, 3.0)]);
        let sum = pn.static_dp_kpa(&[load(-20.0, 0.0, 10.0, 2.0)]) + pn.static_dp_kpa(&[load(20.0, 0.0, 10.0, 3.0)]);
        assert!((both - sum).abs() < 1e-12);
    }

    #[test]
    fn hysteresis_lags_loading_and_relaxes() {
        let p = Profile { hysteresis_kpa: 0.05, hysteresis_tau_s: 2.0, ..Profile::ideal() };
        let mut pn = Pneumatic::new(&p, &Sensor::paper_100mm(), 1);
        let target = pn.static_dp_kpa(&[load(0.0, 0.0, 15.0, 5.0)]);
        let first = pn.sample(0.05, &[load(0.0, 0.0, 15.0, 5.0)]) - p.p0_kpa;
        assert!(first < target && first > target - 0.05);
        let later = pn.sample(20.0, &[load(0.0, 0.0, 15.0, 5.0)]) - p.p0_kpa;
        assert!((later - target).abs() < 1e-4, "{later} {target}");
        // unloading leaves a residual that then relaxes
        let after = pn.sample(20.05, &[]) - p.p0_kpa;
        assert!(after > 0.0 && after < 0.05 + 1e-12);
    }

    #[test]
    fn the_footprint_cache_gives_the_uncached_response_bit_for_bit() {
        // paper profile: heterogeneity and seating jitter make every footprint and level differ
        let mut pn = Pneumatic::new(&Profile::paper(), &Sensor::paper_100mm(), 3);
        let at = |x: f64, d: f64, f: f64, level: u32| Load {
            x_mm: x,
            y_mm: -4.0,
            diameter_mm: d,
            force_n: f,
            press: 0,
            level,
        };
        // (loads of a sample, footprints it evaluates)
        let steps: Vec<(Vec<Load>, u64)> = vec![
            (vec![], 0),
            (vec![at(10.0, 15.0, 0.5, 1)], 1),                          // a ramp begins
            (vec![at(10.0, 15.0, 1.0, 1)], 0),                          // ... goes on
            (vec![at(10.0, 15.0, 1.0, 1)], 0),                          // a hold
            (vec![at(10.0, 15.0, 2.0, 2)], 0),                          // the next level of the staircase: gain only
            (vec![at(10.0, 15.0, 2.0, 2), at(-30.0, 10.0, 1.0, 3)], 1), // a second contact
            (vec![at(10.0, 15.0, 2.0, 2), at(-30.0, 10.0, 1.5, 3)], 0),
            (vec![at(-30.0, 10.0, 1.5, 3)], 1), // the first leaves: the second moves to slot 0
            (vec![], 0),
            (vec![at(10.5, 15.0, 1.0, 4)], 1), // another press, placed elsewhere
            (vec![at(10.5, 20.0, 1.0, 4)], 1), // another diameter
        ];
        let mut expected = 0;
        for (i, (loads, evaluations)) in steps.iter().enumerate() {
            let got = pn.cached_dp_kpa(loads);
            assert_eq!(got.to_bits(), pn.static_dp_kpa(loads).to_bits(), "step {i}: {got}");
            expected += evaluations;
            assert_eq!(pn.footprint_evaluations(), expected, "step {i}");
        }
        // a level's gain is its own: 2 N at level 2 and at level 1 differ
        let mut other = Pneumatic::new(&Profile::paper(), &Sensor::paper_100mm(), 3);
        assert_ne!(other.cached_dp_kpa(&[at(10.0, 15.0, 2.0, 1)]), pn.static_dp_kpa(&[at(10.0, 15.0, 2.0, 2)]));
    }

    #[test]
    fn a_ramp_adds_rate_times_time_to_the_loaded_reading() {
        let p = Profile { pressure_ramp_kpa_per_s: -0.03, ..Profile::ideal() };
        let mut pn = Pneumatic::new(&p, &Sensor::paper_100mm(), 1);
        let l = [load(10.0, 5.0, 15.0, 2.0)];
        let dp = pn.static_dp_kpa(&l);
        for t in [0.0, 1.0, 10.0, 40.0] {
            let got = pn.sample(t, &l) - p.p0_kpa - dp;
            assert!((got - (-0.03 * t)).abs() < 1e-12, "t = {t}: {got}");
        }
    }
}
