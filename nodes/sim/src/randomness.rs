//! Seeded randomness of the model: independent ChaCha streams per purpose, smooth random
//! fields (material heterogeneity) and Ornstein-Uhlenbeck drifts (slow temperature-like change).
//!
//! Everything is a pure function of the simulator's seed, so a scene and a seed give the same
//! recording on every machine. Fields are zero-mean with the requested standard deviation and a
//! Gaussian covariance exp(-r^2 / (2 l^2)) (random Fourier features); lengths in mm.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Stream numbers, one per purpose, so adding a draw in one place never shifts another.
#[derive(Debug, Clone, Copy)]
#[repr(u64)]
pub enum Stream {
    FoamField = 1,
    ContactImpedance = 2,
    EitNoise = 3,
    EitDrift = 4,
    SensitivityField = 5,
    PressureNoise = 6,
    PressureDrift = 7,
    Seating = 8,
    ElectrodePlacement = 9,
    FoamSeating = 10,
    StageMount = 11,
    StageRepeat = 12,
}

/// The generator of one stream of one seed.
pub fn stream(seed: u64, s: Stream) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(s as u64);
    rng
}

/// A standard normal draw that is a pure function of (seed, stream, index): per-item
/// randomness (one draw per load level, say) that does not depend on the order of requests.
pub fn indexed_normal(seed: u64, s: Stream, index: u64) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(s as u64);
    // 2 words per draw (StandardNormal may use more, but the word position alone fixes it)
    rng.set_word_pos(u128::from(index) * 64);
    normal(&mut rng)
}

/// A standard normal draw.
pub fn normal(rng: &mut ChaCha8Rng) -> f64 {
    rng.sample(StandardNormal)
}

/// Number of Fourier modes of a smooth field: enough for a visually Gaussian field.
const FIELD_MODES: usize = 64;

/// A smooth, stationary, zero-mean random field on the plane.
#[derive(Debug, Clone)]
pub struct SmoothField {
    /// Wave vector (rad/mm) and phase of each mode.
    modes: Vec<([f64; 2], f64)>,
    /// sd * sqrt(2 / modes).
    scale: f64,
}

impl SmoothField {
    /// A field of standard deviation `sd` and correlation length `length_mm` (sd 0: zero).
    pub fn new(rng: &mut ChaCha8Rng, sd: f64, length_mm: f64) -> SmoothField {
        if sd == 0.0 {
            return SmoothField { modes: Vec::new(), scale: 0.0 };
        }
        let modes = (0..FIELD_MODES)
            .map(|_| {
                let k = [normal(rng) / length_mm, normal(rng) / length_mm];
                (k, rng.random::<f64>() * std::f64::consts::TAU)
            })
            .collect();
        SmoothField { modes, scale: sd * (2.0 / FIELD_MODES as f64).sqrt() }
    }

    /// Value at (x, y) mm.
    pub fn at(&self, x_mm: f64, y_mm: f64) -> f64 {
        self.scale * self.modes.iter().map(|(k, p)| (k[0] * x_mm + k[1] * y_mm + p).cos()).sum::<f64>()
    }
}

/// A stationary Ornstein-Uhlenbeck process, advanced with its exact transition.
#[derive(Debug, Clone)]
pub struct Drift {
    sd: f64,
    tau_s: f64,
    t_s: f64,
    value: f64,
    rng: ChaCha8Rng,
}

impl Drift {
    /// Starts at t = 0 from the stationary distribution (the pipeline tares whatever it is).
    pub fn new(mut rng: ChaCha8Rng, sd: f64, tau_s: f64) -> Drift {
        let value = if sd > 0.0 { sd * normal(&mut rng) } else { 0.0 };
        Drift { sd, tau_s, t_s: 0.0, value, rng }
    }

    /// Value at `t_s` (times must not decrease; an earlier time returns the current value).
    pub fn at(&mut self, t_s: f64) -> f64 {
        if self.sd == 0.0 || t_s <= self.t_s {
            return self.value;
        }
        let a = (-(t_s - self.t_s) / self.tau_s).exp();
        self.value = a * self.value + self.sd * (1.0 - a * a).sqrt() * normal(&mut self.rng);
        self.t_s = t_s;
        self.value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_has_requested_spread_and_is_smooth() {
        let mut sd_sum = 0.0;
        let trials = 40;
        for seed in 0..trials {
            let f = SmoothField::new(&mut stream(seed, Stream::FoamField), 0.2, 20.0);
            let v: Vec<f64> = (0..200).map(|i| f.at((i % 20) as f64 * 50.0, (i / 20) as f64 * 50.0)).collect();
            sd_sum += (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
            // 1 mm apart is much closer than 20 mm correlation: values nearly equal
            assert!((f.at(0.0, 0.0) - f.at(1.0, 0.0)).abs() < 0.05);
        }
        // mean of sample sds of far-apart points ~ 0.2 (Monte-Carlo tolerance)
        assert!((sd_sum / trials as f64 - 0.2).abs() < 0.03, "{}", sd_sum / trials as f64);
    }

    #[test]
    fn drift_is_stationary_with_requested_sd() {
        let mut d = Drift::new(stream(3, Stream::PressureDrift), 0.5, 10.0);
        // samples 100 s apart are nearly independent; 4000 of them give sd within ~3 %
        let v: Vec<f64> = (1..=4000).map(|i| d.at(i as f64 * 100.0)).collect();
        let sd = (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        assert!((sd - 0.5).abs() < 0.03, "{sd}");
        let mut still = Drift::new(stream(3, Stream::PressureDrift), 0.0, 10.0);
        assert_eq!(still.at(50.0), 0.0);
    }
}
