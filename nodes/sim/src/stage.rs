//! Where the contacts really land: the scene (and the truth) give the positions the test stage
//! was commanded to, but a real sensor sits on the stage with a small offset and rotation, and
//! each press lands within the stage's repeatability. `Stage::place` maps commanded positions
//! to actual ones before any physics; the truth keeps the commanded ones, as a bench would.
//! A placed centre never leaves the skin (see `Stage::place`).
//!
//! Units: mm, degrees. All draws are pure functions of the seed (per press for repeatability).

use crate::profile::Profile;
use crate::randomness::{SlotMemo, Stream, indexed_normal, normal, stream};
use crate::timeline::Load;
use skinflow_eit::Sensor;

/// The sensor's placement under the stage.
#[derive(Debug, Clone)]
pub struct Stage {
    offset_mm: [f64; 2],
    cos: f64,
    sin: f64,
    repeatability_mm: f64,
    /// Half width and half height of the sensor, mm: placed centres stay within them.
    half_extents_mm: (f64, f64),
    seed: u64,
}

impl Stage {
    /// The stage of `profile` over `sensor`, its mounting drawn from `seed`.
    pub fn new(profile: &Profile, sensor: &Sensor, seed: u64) -> Stage {
        let mut rng = stream(seed, Stream::StageMount);
        let offset_mm = [profile.stage_offset_mm * normal(&mut rng), profile.stage_offset_mm * normal(&mut rng)];
        let angle = (profile.stage_rotation_deg * normal(&mut rng)).to_radians();
        Stage {
            offset_mm,
            cos: angle.cos(),
            sin: angle.sin(),
            repeatability_mm: profile.stage_repeatability_mm,
            half_extents_mm: sensor.half_extents_mm(),
            seed,
        }
    }

    /// Whether `place` changes anything.
    pub fn is_exact(&self) -> bool {
        self.offset_mm == [0.0, 0.0] && self.sin == 0.0 && self.repeatability_mm == 0.0
    }

    /// Replaces commanded positions by actual ones, in place.
    ///
    /// The actual centre is clamped to the sensor, per axis, to the closed rectangle. A modelling
    /// choice: a scene's positions are targets on the skin (a centre outside it is refused),
    /// and an operator registers the stage to the skin and checks edge targets on it, so the
    /// mounting and repeatability errors may move an indenter along or up to the skin's edge
    /// but do not put its centre onto the frame. Unclamped, a press commanded 1 mm inside a
    /// corner could land off the skin: the pneumatic channel (S = 0 off the skin, unblurred)
    /// would read almost nothing while the EIT footprint (blurred 3 mm by the foam) still
    /// reaches the skin, and the truth would report a press at a point the skin was never
    /// pressed. Only the centre is clamped: a disc may still overhang the edge as a commanded
    /// one may (both channels lose that part of the load to the frame), and a contact whose
    /// centre stays on the skin is placed exactly as without the clamp.
    pub fn place(&self, loads: &mut [Load]) {
        self.place_each(loads, |_, press| self.repeat_error_mm(press));
    }

    /// [`Stage::place`] with each press's repeatability draw kept per contact slot in `memo`:
    /// the same positions to the bit, but a press that stays in its slot (a hold, a ramp) is
    /// drawn once instead of at every instant it is placed.
    pub fn place_cached(&self, loads: &mut [Load], memo: &mut SlotMemo<[f64; 2]>) {
        self.place_each(loads, |slot, press| memo.get(slot, press, |p| self.repeat_error_mm(p)));
    }

    /// Where press `press` lands off its mounted position, mm per axis (repeatability).
    fn repeat_error_mm(&self, press: u32) -> [f64; 2] {
        let k = 2 * u64::from(press);
        [
            self.repeatability_mm * indexed_normal(self.seed, Stream::StageRepeat, k),
            self.repeatability_mm * indexed_normal(self.seed, Stream::StageRepeat, k + 1),
        ]
    }

    /// `place`, with `repeat(slot, press)` giving the repeatability error of the load in `slot`.
    fn place_each(&self, loads: &mut [Load], mut repeat: impl FnMut(usize, u32) -> [f64; 2]) {
        if self.is_exact() {
            return;
        }
        for (slot, l) in loads.iter_mut().enumerate() {
            let (x, y) = (l.x_mm, l.y_mm);
            let (mut ax, mut ay) =
                (self.cos * x - self.sin * y + self.offset_mm[0], self.sin * x + self.cos * y + self.offset_mm[1]);
            if self.repeatability_mm > 0.0 {
                let [ex, ey] = repeat(slot, l.press);
                ax += ex;
                ay += ey;
            }
            let (hx, hy) = self.half_extents_mm;
            l.x_mm = ax.clamp(-hx, hx);
            l.y_mm = ay.clamp(-hy, hy);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(x: f64, y: f64, press: u32) -> Load {
        Load { x_mm: x, y_mm: y, diameter_mm: 10.0, force_n: 1.0, press, level: 0 }
    }

    #[test]
    fn exact_stage_changes_nothing_and_mounting_is_rigid() {
        let mut l = [load(10.0, -5.0, 0)];
        let sensor = Sensor::paper_100mm();
        Stage::new(&Profile::ideal(), &sensor, 1).place(&mut l);
        assert_eq!(l[0], load(10.0, -5.0, 0));
        let p =
            Profile { stage_offset_mm: 2.0, stage_rotation_deg: 2.0, stage_repeatability_mm: 0.0, ..Profile::ideal() };
        let stage = Stage::new(&p, &sensor, 1);
        let mut a = [load(0.0, 0.0, 0), load(30.0, 40.0, 1)];
        stage.place(&mut a);
        // rigid: distances are kept
        let d = ((a[1].x_mm - a[0].x_mm).powi(2) + (a[1].y_mm - a[0].y_mm).powi(2)).sqrt();
        assert!((d - 50.0).abs() < 1e-9);
        // same press, same place; repeatability differs per press
        let q = Profile { stage_repeatability_mm: 0.5, ..p };
        let stage = Stage::new(&q, &sensor, 1);
        let (mut b, mut c, mut e) = ([load(5.0, 5.0, 7)], [load(5.0, 5.0, 7)], [load(5.0, 5.0, 8)]);
        stage.place(&mut b);
        stage.place(&mut c);
        stage.place(&mut e);
        assert_eq!(b, c);
        assert_ne!(b, e);
    }

    #[test]
    fn cached_placement_is_the_uncached_one_bit_for_bit() {
        let sensor = Sensor::paper_100mm();
        let stage = Stage::new(&Profile::paper(), &sensor, 9);
        let mut memo = SlotMemo::with_capacity(2);
        // instants of a stream: holds, a second contact, the first leaving (slot 1 moves to 0),
        // a press at the edge (clamped), a new press
        let instants: [&[Load]; 7] = [
            &[],
            &[load(10.0, -5.0, 0)],
            &[load(10.0, -5.0, 0)],
            &[load(10.0, -5.0, 0), load(-30.0, 20.0, 1)],
            &[load(-30.0, 20.0, 1)],
            &[load(50.0, -50.0, 2)],
            &[load(10.0, -5.0, 3), load(-30.0, 20.0, 1)],
        ];
        let mut moved = 0;
        for (i, loads) in instants.iter().enumerate() {
            let (mut cached, mut direct) = (loads.to_vec(), loads.to_vec());
            stage.place_cached(&mut cached, &mut memo);
            stage.place(&mut direct);
            let bits = |l: &[Load]| l.iter().map(|l| (l.x_mm.to_bits(), l.y_mm.to_bits())).collect::<Vec<_>>();
            assert_eq!(bits(&cached), bits(&direct), "instant {i}");
            moved += cached.iter().zip(loads.iter()).filter(|(a, b)| a != b).count();
        }
        assert!(moved >= 7, "the paper stage moves the contacts ({moved} of 8 moved)");
    }

    #[test]
    fn placed_centres_stay_on_the_skin_and_only_those_that_would_leave_it_move() {
        let sensor = Sensor::paper_100mm();
        // errors far beyond the paper's, so that corner presses would often land off the skin
        let p =
            Profile { stage_offset_mm: 4.0, stage_rotation_deg: 3.0, stage_repeatability_mm: 2.0, ..Profile::ideal() };
        let (mut clamped, mut interior) = (0, 0);
        for seed in 0..40 {
            let stage = Stage::new(&p, &sensor, seed);
            for (press, (x, y)) in [(49.0, -49.0), (-50.0, 50.0), (0.0, 49.5), (10.0, -5.0)].into_iter().enumerate() {
                let mut l = [load(x, y, press as u32)];
                stage.place(&mut l);
                let (ax, ay) = (l[0].x_mm, l[0].y_mm);
                assert!(ax.abs() <= 50.0 && ay.abs() <= 50.0, "seed {seed}: ({x}, {y}) placed at ({ax}, {ay})");
                clamped += usize::from(ax.abs() == 50.0 || ay.abs() == 50.0);
                if (x, y) == (10.0, -5.0) {
                    // well inside: the rigid mounting and the press's scatter, nothing else
                    let k = 2 * press as u64;
                    let rx = stage.cos * x - stage.sin * y
                        + stage.offset_mm[0]
                        + 2.0 * indexed_normal(seed, Stream::StageRepeat, k);
                    let ry = stage.sin * x
                        + stage.cos * y
                        + stage.offset_mm[1]
                        + 2.0 * indexed_normal(seed, Stream::StageRepeat, k + 1);
                    assert_eq!((ax, ay), (rx, ry));
                    interior += 1;
                }
            }
        }
        assert!(clamped > 20, "{clamped} edge presses held on the skin");
        assert_eq!(interior, 40);
    }
}
