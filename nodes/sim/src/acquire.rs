//! The EIT channel: one frame = the sensor's protocol measured in sequence over the acquisition
//! window [t - T/2, t + T/2). Values are the full nonlinear CEM forward solve (skinflow-eit) of
//! the conductivity that `compress` derives from the contacts, on the simulator's own mesh
//! (finer than, and generated differently from, any reconstruction mesh: no inverse crime).
//!
//! The window is split into `EIT_BLOCKS` blocks acquired at their mid-times; a block whose
//! contact state (placed positions, diameters, forces and seating draws: all the solve depends
//! on) equals a recently solved one reuses it, so a static hold costs one solve and afterwards
//! only fresh noise, and no value depends on what the cache held. Drift scales all values by 1 / (1 + d(t)) (liquid conductivity
//! and electrode impedance drift together with temperature); noise is Gaussian with standard
//! deviation rel * |v| + abs. Volts, protocol order (CONTRACTS.md section 1). A dead electrode
//! (scene `[[fault]]`) pins every channel that uses it to the rail voltage while it lasts.

use crate::compress::Compressor;
use crate::profile::Profile;
use crate::randomness::{Drift, SlotMemo, Stream, normal, stream};
use crate::scene::Fault;
use crate::stage::Stage;
use crate::timeline::{Load, Timeline};
use rand_chacha::ChaCha8Rng;
use skinflow_eit::{CemParams, ChannelMask, EitError, ForwardModel, Measurement, Mesh, MeshParams, Sensor};

/// Blocks per acquisition window: measurements in block b see the contacts at the block's
/// mid-time (4 resolves a ramp within a frame to a quarter frame).
pub const EIT_BLOCKS: usize = 4;
/// Solved contact states kept for reuse.
const CACHE_STATES: usize = 4;
/// Minimum angle of the simulation mesh, degrees: differs from the reconstruction default (28)
/// so the two meshes never coincide even at equal element counts.
const SIM_MESH_MIN_ANGLE_DEG: f64 = 25.0;
/// Electrode edge ratio of the simulation mesh (reconstruction default: 0.2, `MeshParams`).
const SIM_MESH_ELECTRODE_RATIO: f64 = 0.5;

/// Element count of the simulation mesh for the smallest indenter of a scene: equilateral
/// triangles of edge `mesh_edge_per_diameter * d_min`, clamped to the profile's bounds.
pub fn sim_mesh_elements(profile: &Profile, sensor: &Sensor, smallest_diameter_mm: Option<f64>) -> usize {
    let Some(d) = smallest_diameter_mm else {
        return profile.mesh_min_elements;
    };
    let edge = profile.mesh_edge_per_diameter * d;
    let triangle_area = 3f64.sqrt() / 4.0 * edge * edge;
    let n = (sensor.width_mm * sensor.height_mm / triangle_area).ceil() as usize;
    n.clamp(profile.mesh_min_elements, profile.mesh_max_elements)
}

/// What the solved values of one contact depend on: its placed position and diameter (mm),
/// its force (N) and its load level's seating factor (`Compressor::seating`). Two contact sets
/// with equal keys give the same conductivity, so the cached values can stand in for a solve;
/// ids (press, level) are left out, so equal states of different levels share a solve when the
/// seating factors are equal (always without jitter).
#[derive(Debug, Clone, Copy, PartialEq)]
struct LoadKey {
    x_mm: f64,
    y_mm: f64,
    diameter_mm: f64,
    force_n: f64,
    seating: f64,
}

/// Largest displacement of an electrode, in standard deviations (keeps it on its side).
const MISPLACEMENT_CLIP_SD: f64 = 3.0;

/// The sensor as built: each electrode moved along its side by N(0, sd) mm (clipped to 3 sd and
/// to the side), a pure function of the seed. sd 0 returns the nominal sensor.
pub fn misplace_electrodes(sensor: &Sensor, sd_mm: f64, seed: u64) -> Sensor {
    let mut built = sensor.clone();
    if sd_mm == 0.0 {
        return built;
    }
    let (hx, hy) = sensor.half_extents_mm();
    let mut rng = stream(seed, Stream::ElectrodePlacement);
    for e in &mut built.electrodes {
        let len = e.length_mm();
        let dir = [(e.end_mm[0] - e.start_mm[0]) / len, (e.end_mm[1] - e.start_mm[1]) / len];
        let mut shift = (sd_mm * normal(&mut rng)).clamp(-MISPLACEMENT_CLIP_SD * sd_mm, MISPLACEMENT_CLIP_SD * sd_mm);
        // keep both ends on the side (the electrode may not wrap a corner)
        for p in [e.start_mm, e.end_mm] {
            for (axis, half) in [(0, hx), (1, hy)] {
                if dir[axis] != 0.0 {
                    let moved = p[axis] + shift * dir[axis];
                    if moved.abs() > half {
                        shift -= (moved - moved.signum() * half) / dir[axis];
                    }
                }
            }
        }
        for p in [&mut e.start_mm, &mut e.end_mm] {
            p[0] += shift * dir[0];
            p[1] += shift * dir[1];
        }
    }
    built
}

/// A dead-electrode fault as applied: the channels that use the electrode read `rail_v` in
/// frames whose mid-time is in `[from_s, until_s)`.
#[derive(Debug, Clone)]
struct DeadChannels {
    channels: Vec<usize>,
    from_s: f64,
    until_s: f64,
    rail_v: f64,
}

#[derive(Debug, Clone)]
struct CachedState {
    key: Vec<LoadKey>,
    values: Vec<f64>,
    last_used: u64,
}

/// The simulated EIT acquisition.
#[derive(Debug)]
pub struct EitChannel {
    // Configuration
    forward: ForwardModel,
    measurements: Vec<Measurement>,
    compressor: Compressor,
    noise_rel: f64,
    noise_abs_v: f64,
    dead: Vec<DeadChannels>,
    // Internal state
    drift: Drift,
    noise: ChaCha8Rng,
    cache: Vec<CachedState>,
    clock: u64,
    solves: u64,
    /// Per contact slot: the last press's placement error and the last level's seating factor
    /// (pure functions of press and level, each an `indexed_normal` away: drawn once per slot
    /// and press or level, not in every block of every frame).
    placement: SlotMemo<[f64; 2]>,
    seating: SlotMemo<f64>,
    // Scratch
    sigma: Vec<f64>,
    block_loads: Vec<Load>,
    block_key: Vec<LoadKey>,
}

impl EitChannel {
    /// Meshes the sensor for the timeline's smallest indenter and prepares the forward model;
    /// `faults` are applied to the frames they cover.
    pub fn new(
        profile: &Profile,
        sensor: &Sensor,
        timeline: &Timeline,
        faults: &[Fault],
        seed: u64,
    ) -> Result<EitChannel, EitError> {
        let elements = sim_mesh_elements(profile, sensor, timeline.smallest_diameter_mm());
        let sensor = &misplace_electrodes(sensor, profile.electrode_misplacement_mm, seed);
        let mesh = Mesh::generate(
            sensor,
            &MeshParams {
                elements,
                min_angle_deg: SIM_MESH_MIN_ANGLE_DEG,
                electrode_size_ratio: SIM_MESH_ELECTRODE_RATIO,
                ..MeshParams::default()
            },
        )?;
        let mut zrng = stream(seed, Stream::ContactImpedance);
        let z = (0..sensor.electrode_count())
            .map(|_| {
                profile.contact_impedance_ohm_mm2
                    * (1.0 + profile.contact_impedance_spread * normal(&mut zrng)).max(0.1)
            })
            .collect();
        let cem = CemParams {
            background_s_per_m: profile.sigma0_s_per_m,
            thickness_mm: profile.foam_thickness_mm,
            contact_impedance_ohm_mm2: profile.contact_impedance_ohm_mm2,
            electrode_contact_impedance_ohm_mm2: z,
            current_ua: profile.current_ua,
        };
        let forward = ForwardModel::new(sensor, &mesh, &cem)?;
        let mut diameters: Vec<f64> =
            timeline.segments.iter().flat_map(|s| s.contacts.iter().map(|c| c.diameter_mm)).collect();
        diameters.sort_by(f64::total_cmp);
        diameters.dedup();
        let foam = crate::randomness::SmoothField::new(
            &mut stream(seed, Stream::FoamField),
            profile.foam_heterogeneity,
            profile.foam_heterogeneity_length_mm,
        );
        let compressor = Compressor::new(profile, mesh.element_centroids_mm(), &diameters, &foam, seed);
        let n = compressor.element_count();
        let max_contacts = timeline.max_contacts();
        let measurements = sensor.measurements();
        let dead = faults
            .iter()
            .map(|&Fault::DeadElectrode { electrode, from_s, until_s, rail_v }| DeadChannels {
                channels: ChannelMask::from_dead_electrodes(&measurements, sensor.electrode_count(), &[electrode])
                    .excluded_channels(),
                from_s,
                until_s,
                rail_v,
            })
            .collect();
        Ok(EitChannel {
            measurements,
            dead,
            forward,
            compressor,
            noise_rel: profile.eit_noise_rel,
            noise_abs_v: profile.eit_noise_abs_v,
            drift: Drift::new(stream(seed, Stream::EitDrift), profile.eit_drift_rel, profile.eit_drift_tau_s),
            noise: stream(seed, Stream::EitNoise),
            cache: Vec::with_capacity(CACHE_STATES),
            clock: 0,
            solves: 0,
            placement: SlotMemo::with_capacity(max_contacts),
            seating: SlotMemo::with_capacity(max_contacts),
            sigma: vec![0.0; n],
            block_loads: Vec::with_capacity(max_contacts),
            block_key: Vec::with_capacity(max_contacts),
        })
    }

    /// Values per frame (M).
    pub fn measurement_count(&self) -> usize {
        self.measurements.len()
    }

    /// Elements of the simulation mesh.
    pub fn element_count(&self) -> usize {
        self.compressor.element_count()
    }

    /// Forward solves done so far (cache misses).
    pub fn solve_count(&self) -> u64 {
        self.solves
    }

    /// The frame whose window is centred on `t_s` and lasts `period_s`, into `out` (M values);
    /// contacts land where `stage` puts them.
    pub fn frame_into(
        &mut self,
        timeline: &Timeline,
        stage: &Stage,
        t_s: f64,
        period_s: f64,
        out: &mut [f64],
    ) -> Result<(), EitError> {
        let m = self.measurements.len();
        if out.len() != m {
            return Err(EitError::Length { what: "eit frame buffer", expected: m, got: out.len() });
        }
        let start = t_s - 0.5 * period_s;
        let mut hint = 0;
        for b in 0..EIT_BLOCKS {
            let tb = start + (b as f64 + 0.5) * period_s / EIT_BLOCKS as f64;
            hint = timeline.loads_into(tb, hint, &mut self.block_loads);
            stage.place_cached(&mut self.block_loads, &mut self.placement);
            let slot = self.solved()?;
            let (lo, hi) = (b * m / EIT_BLOCKS, (b + 1) * m / EIT_BLOCKS);
            out[lo..hi].copy_from_slice(&self.cache[slot].values[lo..hi]);
        }
        let scale = 1.0 / (1.0 + self.drift.at(t_s));
        for v in out.iter_mut() {
            let clean = *v * scale;
            let sd = self.noise_rel * clean.abs() + self.noise_abs_v;
            *v = if sd > 0.0 { clean + sd * normal(&mut self.noise) } else { clean };
        }
        for dead in self.dead.iter().filter(|d| (d.from_s..d.until_s).contains(&t_s)) {
            dead.channels.iter().for_each(|&k| out[k] = dead.rail_v);
        }
        Ok(())
    }

    /// Cache slot holding the noiseless values of `self.block_loads`, solving on a miss.
    fn solved(&mut self) -> Result<usize, EitError> {
        self.clock += 1;
        self.block_key.clear();
        let (compressor, seating) = (&self.compressor, &mut self.seating);
        self.block_key.extend(self.block_loads.iter().enumerate().map(|(slot, l)| LoadKey {
            x_mm: l.x_mm,
            y_mm: l.y_mm,
            diameter_mm: l.diameter_mm,
            force_n: l.force_n,
            seating: seating.get(slot, l.level, |level| compressor.seating(level)),
        }));
        if let Some(i) = self.cache.iter().position(|c| c.key == self.block_key) {
            self.cache[i].last_used = self.clock;
            return Ok(i);
        }
        self.compressor.conductivity_into(&self.block_loads, &mut self.sigma);
        let solution = self.forward.solve(&self.sigma)?;
        self.solves += 1;
        let slot = if self.cache.len() < CACHE_STATES {
            self.cache.push(CachedState {
                key: Vec::with_capacity(self.block_key.capacity()),
                values: vec![0.0; self.measurements.len()],
                last_used: 0,
            });
            self.cache.len() - 1
        } else {
            (0..self.cache.len()).min_by_key(|&i| self.cache[i].last_used).expect("cache is not empty")
        };
        let entry = &mut self.cache[slot];
        entry.key.clear();
        entry.key.extend_from_slice(&self.block_key);
        entry.last_used = self.clock;
        solution.measurements_into(&self.measurements, &mut entry.values);
        Ok(slot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misplaced_electrodes_stay_on_their_side_with_their_length() {
        let nominal = Sensor::paper_100mm();
        assert_eq!(misplace_electrodes(&nominal, 0.0, 5), nominal);
        let built = misplace_electrodes(&nominal, 2.0, 5);
        let mut moved = 0.0;
        for (a, b) in nominal.electrodes.iter().zip(&built.electrodes) {
            assert!((a.length_mm() - b.length_mm()).abs() < 1e-9);
            for p in [b.start_mm, b.end_mm] {
                assert!(p[0].abs() <= 50.0 + 1e-9 && p[1].abs() <= 50.0 + 1e-9);
            }
            // same side: the coordinate normal to the side is unchanged
            let along_x = a.start_mm[1] == a.end_mm[1];
            if along_x {
                assert_eq!(a.start_mm[1], b.start_mm[1]);
            } else {
                assert_eq!(a.start_mm[0], b.start_mm[0]);
            }
            moved += (a.centre_mm()[0] - b.centre_mm()[0]).abs() + (a.centre_mm()[1] - b.centre_mm()[1]).abs();
        }
        let mean = moved / 16.0;
        assert!(mean > 0.5 && mean < 4.0, "mean displacement {mean} mm for sd 2 mm");
        // a tight sensor: an electrode at a corner cannot be pushed past it
        let tight = Sensor::from_toml(
            "[sensor]\nwidth_mm = 22.0\nheight_mm = 22.0\nelectrodes_per_side = 1\nelectrode_length_mm = 20.0\n",
        )
        .unwrap();
        for e in misplace_electrodes(&tight, 5.0, 1).electrodes {
            for p in [e.start_mm, e.end_mm] {
                assert!(p[0].abs() <= 11.0 + 1e-9 && p[1].abs() <= 11.0 + 1e-9, "{p:?}");
            }
        }
    }

    #[test]
    fn mesh_follows_the_smallest_indenter_within_bounds() {
        let p = Profile::paper();
        let s = Sensor::paper_100mm();
        assert_eq!(sim_mesh_elements(&p, &s, None), p.mesh_min_elements);
        assert_eq!(sim_mesh_elements(&p, &s, Some(2.0)), p.mesh_max_elements);
        let fine = Profile { mesh_min_elements: 100, ..p.clone() };
        assert!(sim_mesh_elements(&fine, &s, Some(10.0)) > sim_mesh_elements(&fine, &s, Some(20.0)));
    }
}
