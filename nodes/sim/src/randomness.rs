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

/// Press-to-press variability of a load level (how the indenter seats): level `level` scales
/// its response by g = 1 + sd N(0, 1), at least 0, a pure function of (seed, stream, level);
/// exactly 1 when sd is 0. The EIT layer (`foam_seating_jitter`, `Stream::FoamSeating`) and the
/// pneumatic one (`seating_jitter`, `Stream::Seating`) each draw their own.
#[derive(Debug, Clone, Copy)]
pub struct Seating {
    seed: u64,
    stream: Stream,
    sd: f64,
}

impl Seating {
    pub fn new(seed: u64, stream: Stream, sd: f64) -> Seating {
        Seating { seed, stream, sd }
    }

    /// The factor g of load level `level`.
    pub fn factor(&self, level: u32) -> f64 {
        if self.sd == 0.0 {
            return 1.0;
        }
        (1.0 + self.sd * indexed_normal(self.seed, self.stream, u64::from(level))).max(0.0)
    }
}

/// Per contact slot (index in a list of loads), the last per-item draw made for it and the
/// item (press or level) it was for. An `indexed_normal` sets up a generator each time (a
/// ChaCha seeding and a block refill, most of a static-hold frame's cost when done per block),
/// while a contact keeps its slot and its press and level from one instant to the next: the
/// memo draws once per item per slot and returns the stored value, the same to the bit, after.
#[derive(Debug, Clone, Default)]
pub struct SlotMemo<V> {
    slots: Vec<(u32, V)>,
}

impl<V: Copy> SlotMemo<V> {
    /// Room for `slots` slots without reallocation.
    pub fn with_capacity(slots: usize) -> SlotMemo<V> {
        SlotMemo { slots: Vec::with_capacity(slots) }
    }

    /// The value of `item` in `slot`: the stored one if the slot's last item was `item`, else
    /// `draw(item)`, stored. `draw` must be a pure function of the item.
    pub fn get(&mut self, slot: usize, item: u32, draw: impl FnOnce(u32) -> V) -> V {
        match self.slots.get_mut(slot) {
            Some((last, value)) if *last == item => *value,
            Some(stored) => {
                let value = draw(item);
                *stored = (item, value);
                value
            }
            None => {
                let value = draw(item);
                // callers walk their slots in order, so a new slot is the next one; any other
                // is served unstored rather than leaving a gap of made-up entries
                if slot == self.slots.len() {
                    self.slots.push((item, value));
                }
                value
            }
        }
    }
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
    fn seating_is_one_without_jitter_and_a_pure_function_of_the_level() {
        let still = Seating::new(3, Stream::Seating, 0.0);
        assert!((0..50).all(|level| still.factor(level) == 1.0));
        let g = Seating::new(3, Stream::Seating, 0.05);
        for level in [0, 1, 7, 1_000_000] {
            let expected = (1.0 + 0.05 * indexed_normal(3, Stream::Seating, u64::from(level))).max(0.0);
            assert_eq!(g.factor(level).to_bits(), expected.to_bits());
        }
        // its own stream: the EIT layer's draws are not the pneumatic layer's
        assert_ne!(g.factor(1), Seating::new(3, Stream::FoamSeating, 0.05).factor(1));
        // never negative, however wide the jitter
        assert!((0..200).all(|level| Seating::new(1, Stream::Seating, 5.0).factor(level) >= 0.0));
    }

    #[test]
    fn a_slot_memo_draws_once_per_item_and_slot() {
        let mut memo = SlotMemo::with_capacity(2);
        let mut draws = Vec::new();
        let mut get = |memo: &mut SlotMemo<f64>, slot: usize, item: u32| {
            memo.get(slot, item, |i| {
                draws.push((slot, i));
                f64::from(i) * 10.0 + slot as f64
            })
        };
        assert_eq!(get(&mut memo, 0, 4), 40.0);
        assert_eq!(get(&mut memo, 0, 4), 40.0);
        assert_eq!(get(&mut memo, 1, 5), 51.0);
        assert_eq!(get(&mut memo, 0, 4), 40.0);
        assert_eq!(get(&mut memo, 1, 5), 51.0);
        // a new item in a slot is drawn and replaces the old one there
        assert_eq!(get(&mut memo, 0, 6), 60.0);
        assert_eq!(get(&mut memo, 0, 4), 40.0);
        // a slot out of order is served but not stored
        assert_eq!(get(&mut memo, 5, 1), 15.0);
        assert_eq!(get(&mut memo, 5, 1), 15.0);
        assert_eq!(draws, vec![(0, 4), (1, 5), (0, 6), (0, 4), (5, 1), (5, 1)]);
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
