//! Where the contacts really land: the scene (and the truth) give the positions the test stage
//! was commanded to, but a real sensor sits on the stage with a small offset and rotation, and
//! each press lands within the stage's repeatability. `Stage::place` maps commanded positions
//! to actual ones before any physics; the truth keeps the commanded ones, as a bench would.
//!
//! Units: mm, degrees. All draws are pure functions of the seed (per press for repeatability).

use crate::profile::Profile;
use crate::randomness::{Stream, indexed_normal, normal, stream};
use crate::timeline::Load;

/// The sensor's placement under the stage.
#[derive(Debug, Clone)]
pub struct Stage {
    offset_mm: [f64; 2],
    cos: f64,
    sin: f64,
    repeatability_mm: f64,
    seed: u64,
}

impl Stage {
    pub fn new(profile: &Profile, seed: u64) -> Stage {
        let mut rng = stream(seed, Stream::StageMount);
        let offset_mm = [profile.stage_offset_mm * normal(&mut rng), profile.stage_offset_mm * normal(&mut rng)];
        let angle = (profile.stage_rotation_deg * normal(&mut rng)).to_radians();
        Stage { offset_mm, cos: angle.cos(), sin: angle.sin(), repeatability_mm: profile.stage_repeatability_mm, seed }
    }

    /// Whether `place` changes anything.
    pub fn is_exact(&self) -> bool {
        self.offset_mm == [0.0, 0.0] && self.sin == 0.0 && self.repeatability_mm == 0.0
    }

    /// Replaces commanded positions by actual ones, in place.
    pub fn place(&self, loads: &mut [Load]) {
        if self.is_exact() {
            return;
        }
        for l in loads {
            let (x, y) = (l.x_mm, l.y_mm);
            let (mut ax, mut ay) =
                (self.cos * x - self.sin * y + self.offset_mm[0], self.sin * x + self.cos * y + self.offset_mm[1]);
            if self.repeatability_mm > 0.0 {
                let k = 2 * u64::from(l.press);
                ax += self.repeatability_mm * indexed_normal(self.seed, Stream::StageRepeat, k);
                ay += self.repeatability_mm * indexed_normal(self.seed, Stream::StageRepeat, k + 1);
            }
            l.x_mm = ax;
            l.y_mm = ay;
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
        Stage::new(&Profile::ideal(), 1).place(&mut l);
        assert_eq!(l[0], load(10.0, -5.0, 0));
        let p =
            Profile { stage_offset_mm: 2.0, stage_rotation_deg: 2.0, stage_repeatability_mm: 0.0, ..Profile::ideal() };
        let stage = Stage::new(&p, 1);
        let mut a = [load(0.0, 0.0, 0), load(30.0, 40.0, 1)];
        stage.place(&mut a);
        // rigid: distances are kept
        let d = ((a[1].x_mm - a[0].x_mm).powi(2) + (a[1].y_mm - a[0].y_mm).powi(2)).sqrt();
        assert!((d - 50.0).abs() < 1e-9);
        // same press, same place; repeatability differs per press
        let q = Profile { stage_repeatability_mm: 0.5, ..p };
        let stage = Stage::new(&q, 1);
        let (mut b, mut c, mut e) = ([load(5.0, 5.0, 7)], [load(5.0, 5.0, 7)], [load(5.0, 5.0, 8)]);
        stage.place(&mut b);
        stage.place(&mut c);
        stage.place(&mut e);
        assert_eq!(b, c);
        assert_ne!(b, e);
    }
}
