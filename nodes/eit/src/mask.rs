//! Channel masking: which channels of a frame are unusable, and which electrodes are dead.
//!
//! A channel is bad when its value is NaN or infinite or its magnitude reaches `saturation_v`.
//! An electrode is dead when at least `dead_electrode_fraction` of the channels that use it (as
//! drive or sense) are bad; then every channel using it is excluded, also the ones that still
//! look valid (their drive or sense path runs through a broken contact).

use crate::error::{EitError, check_positive, invalid};
use crate::sensor::Measurement;
use serde::Deserialize;

/// Masking thresholds (TOML table `[mask]`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MaskParams {
    /// |v| at or above this is saturated, volts (set it to the device's rail; the default 2 V
    /// is 4x the largest value of the default sensor at the default 10 uA).
    pub saturation_v: f64,
    /// Fraction of an electrode's channels that must be bad to call it dead, in (0, 1].
    pub dead_electrode_fraction: f64,
}

impl Default for MaskParams {
    fn default() -> Self {
        MaskParams { saturation_v: 2.0, dead_electrode_fraction: 0.5 }
    }
}

impl MaskParams {
    pub fn validate(&self) -> Result<(), EitError> {
        check_positive("saturation_v", self.saturation_v)?;
        let f = self.dead_electrode_fraction;
        if !(f > 0.0 && f <= 1.0) {
            return Err(invalid("dead_electrode_fraction", format!("must be in (0, 1] (got {f})")));
        }
        Ok(())
    }
}

/// Excluded channels (protocol order) and dead electrodes.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ChannelMask {
    /// `excluded[k]`: channel k is not used.
    pub excluded: Vec<bool>,
    /// `dead[l]`: electrode l is dead.
    pub dead: Vec<bool>,
}

impl ChannelMask {
    /// A mask that excludes nothing.
    pub fn none(channels: usize, electrodes: usize) -> ChannelMask {
        ChannelMask { excluded: vec![false; channels], dead: vec![false; electrodes] }
    }

    /// A mask excluding every channel that uses one of `electrodes_dead`.
    pub fn from_dead_electrodes(
        measurements: &[Measurement],
        electrodes: usize,
        electrodes_dead: &[usize],
    ) -> ChannelMask {
        let mut m = ChannelMask::none(measurements.len(), electrodes);
        for &l in electrodes_dead {
            if l < electrodes {
                m.dead[l] = true;
            }
        }
        for (x, meas) in m.excluded.iter_mut().zip(measurements) {
            *x = uses_any(meas, &m.dead);
        }
        m
    }

    /// Indices of the excluded channels.
    pub fn excluded_channels(&self) -> Vec<usize> {
        (0..self.excluded.len()).filter(|&k| self.excluded[k]).collect()
    }

    /// Indices of the dead electrodes.
    pub fn dead_electrodes(&self) -> Vec<usize> {
        (0..self.dead.len()).filter(|&l| self.dead[l]).collect()
    }

    pub fn excluded_count(&self) -> usize {
        self.excluded.iter().filter(|&&x| x).count()
    }
}

fn uses_any(m: &Measurement, dead: &[bool]) -> bool {
    dead[m.drive.0] || dead[m.drive.1] || dead[m.sense.0] || dead[m.sense.1]
}

/// Fills `out` (sized by `ChannelMask::none`) from frame `v`; allocates nothing.
pub fn detect_into(v: &[f64], measurements: &[Measurement], params: &MaskParams, out: &mut ChannelMask) {
    for (x, &val) in out.excluded.iter_mut().zip(v) {
        *x = !val.is_finite() || val.abs() >= params.saturation_v;
    }
    for l in 0..out.dead.len() {
        let (mut total, mut bad) = (0usize, 0usize);
        for (meas, &x) in measurements.iter().zip(&out.excluded) {
            let d = [meas.drive.0, meas.drive.1, meas.sense.0, meas.sense.1];
            if d.contains(&l) {
                total += 1;
                bad += usize::from(x);
            }
        }
        out.dead[l] = total > 0 && bad as f64 >= params.dead_electrode_fraction * total as f64;
    }
    for (x, meas) in out.excluded.iter_mut().zip(measurements) {
        *x = *x || uses_any(meas, &out.dead);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::{Protocol, protocol_measurements};

    #[test]
    fn nan_saturated_and_dead_electrode() {
        let ms = protocol_measurements(Protocol::Pairwise, 16);
        let mut v = vec![0.3; ms.len()];
        v[20] = f64::NAN;
        v[40] = 5.0;
        // Electrode 3 broken: every channel using it saturates except two.
        for (k, m) in ms.iter().enumerate() {
            if m.drive.0 == 3 || m.drive.1 == 3 {
                v[k] = -9.0;
            }
        }
        v[ms.iter().position(|m| m.drive == (0, 3)).unwrap()] = 0.4;
        let mut mask = ChannelMask::none(ms.len(), 16);
        detect_into(&v, &ms, &MaskParams::default(), &mut mask);
        assert_eq!(mask.dead_electrodes(), vec![3]);
        assert!(mask.excluded[20] && mask.excluded[40]);
        assert!(mask.excluded[ms.iter().position(|m| m.drive == (0, 3)).unwrap()]);
        assert_eq!(mask.excluded_count(), 15 + 2);
        assert_eq!(mask, {
            let mut m = ChannelMask::from_dead_electrodes(&ms, 16, &[3]);
            m.excluded[20] = true;
            m.excluded[40] = true;
            m
        });
    }
}
