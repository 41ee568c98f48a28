//! Model constants of the simulated skin, grouped by channel, with two presets: `ideal`
//! (no noise, drift, jitter or hysteresis: for tests) and `paper` (tuned so that the pipeline
//! reproduces the paper's baselines; figures in MODEL.md). A scene picks a preset by name and
//! may override single constants in its `[model]` table (same key names as the fields below).
//!
//! Units: conductivity S/m, contact impedance ohm mm^2, current uA, lengths mm, pressure kPa, force N, time s.

use serde::{Deserialize, Serialize};
use skinflow_toml::Num;

/// Fewest elements of the simulation mesh (a coarser one would not resolve an indenter).
pub const MIN_MESH_ELEMENTS: usize = 100;
/// Most elements of the simulation mesh: the largest mesh skinflow-eit generates
/// (`MeshParams::elements`); the simulator clamps to `[mesh_min_elements, mesh_max_elements]`.
pub const MAX_MESH_ELEMENTS: usize = 2_000_000;
/// Largest `contact_impedance_ohm_mm2`: each electrode's is it times max(1 + spread N(0, 1),
/// 0.1) with spread < 1, a factor far below 1e8 for any draw, so every electrode's stays
/// finite (the forward model refuses an infinite one).
pub const MAX_CONTACT_IMPEDANCE_OHM_MM2: f64 = 1e300;

/// Every constant of the model. Field docs are the `[model]` TOML reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    // ---- test stage: where contacts land relative to where they were commanded
    /// Standard deviation of the sensor's offset under the stage, per axis, mm (fixed per seed).
    pub stage_offset_mm: f64,
    /// Standard deviation of the sensor's rotation under the stage, degrees (fixed per seed).
    pub stage_rotation_deg: f64,
    /// Standard deviation of each press's landing position, per axis, mm (stage repeatability).
    pub stage_repeatability_mm: f64,

    // ---- EIT layer: conductivity of the soaked foam and its response to compression
    /// Conductivity of the unloaded, liquid-filled foam, S/m (saline 125-300 uS/cm in PU foam).
    pub sigma0_s_per_m: f64,
    /// Foam thickness, mm; the indenter footprint is blurred by a Gaussian of this standard
    /// deviation times `spread_per_thickness` (load spreads through the layer).
    pub foam_thickness_mm: f64,
    /// Gaussian blur sigma of the footprint, in foam thicknesses.
    pub spread_per_thickness: f64,
    /// Largest volumetric compression the foam reaches (fraction of its pore volume expelled).
    pub strain_max: f64,
    /// Local contact pressure at which compression reaches 63 % of `strain_max`, kPa.
    pub pressure_sat_kpa: f64,
    /// Archie exponent m in sigma = sigma0 (1 - strain)^m (conductivity of a partly drained foam).
    pub archie_exponent: f64,
    /// Relative standard deviation of the foam's local compliance (smooth random field, fixed
    /// per seed): real foam is not uniform, so equal forces give unequal conductivity drops.
    pub foam_heterogeneity: f64,
    /// Correlation length of that field, mm.
    pub foam_heterogeneity_length_mm: f64,
    /// Relative standard deviation of the foam's compression per load level (how the indenter
    /// seats and how much liquid a given press expels vary from press to press).
    pub foam_seating_jitter: f64,
    /// Specific electrode contact impedance, ohm mm^2 (CEM z_l over the electrode's contact face).
    pub contact_impedance_ohm_mm2: f64,
    /// Relative spread of the contact impedance across electrodes (fixed per seed).
    pub contact_impedance_spread: f64,
    /// Standard deviation of each electrode's displacement along its side from the nominal
    /// layout, mm (hand-applied silver tape; the reconstruction assumes the nominal layout).
    pub electrode_misplacement_mm: f64,
    /// Measurement noise: standard deviation relative to each value.
    pub eit_noise_rel: f64,
    /// Measurement noise: absolute standard deviation, V.
    pub eit_noise_abs_v: f64,
    /// Slow drift of the liquid's conductivity (temperature, evaporation): stationary relative
    /// standard deviation of an Ornstein-Uhlenbeck process; all values scale by 1/(1 + drift).
    pub eit_drift_rel: f64,
    /// Time constant of the EIT drift, s.
    pub eit_drift_tau_s: f64,
    /// Injected current amplitude, uA.
    pub current_ua: f64,
    /// Simulation mesh: target element edge as a fraction of the smallest indenter diameter.
    pub mesh_edge_per_diameter: f64,
    /// Simulation mesh: lower bound on the element count (keeps it finer than the
    /// reconstruction mesh even for big indenters).
    pub mesh_min_elements: usize,
    /// Simulation mesh: upper bound on the element count (cost cap).
    pub mesh_max_elements: usize,

    // ---- pneumatic layer: sealed air chamber under the foam
    /// No-load gauge pressure P0, kPa (the pipeline tares it).
    pub p0_kpa: f64,
    /// Pressure change per newton at the centre for small loads, kPa/N.
    pub sensitivity_kpa_per_n: f64,
    /// Fractional loss of sensitivity at the boundary (shell stiffening), 0..1.
    pub edge_stiffening: f64,
    /// Decay length of the edge stiffening from each side, mm.
    pub edge_length_mm: f64,
    /// Relative standard deviation of a smooth random sensitivity field (infill irregularity).
    pub sensitivity_heterogeneity: f64,
    /// Correlation length of that field, mm.
    pub sensitivity_heterogeneity_length_mm: f64,
    /// Load at which the response of a `reference_diameter_mm` indenter has lost half its
    /// slope (mild saturation: dP ~ F / (1 + F / F_nl)), N.
    pub nonlinearity_force_n: f64,
    /// Indenter diameter of the calibration, mm; larger indenters saturate earlier.
    pub reference_diameter_mm: f64,
    /// Exponent q of the contact-area effect: F_nl(d) = F_nl (d_ref / d)^q.
    pub area_exponent: f64,
    /// Width of the rate-independent hysteresis (play operator), kPa.
    pub hysteresis_kpa: f64,
    /// Relaxation time of the hysteresis state towards the load, s.
    pub hysteresis_tau_s: f64,
    /// Relative standard deviation of the per-level seating gain (indenter seating and foam
    /// friction differ from one load level to the next).
    pub seating_jitter: f64,
    /// Sensor noise, kPa (standard deviation per sample).
    pub pressure_noise_kpa: f64,
    /// Slow drift (air temperature): stationary standard deviation, kPa.
    pub pressure_drift_kpa: f64,
    /// Time constant of the pressure drift, s.
    pub pressure_drift_tau_s: f64,
    /// Steady pressure ramp from t = 0, kPa/s (a slow leak or a steady temperature change;
    /// negative: the chamber loses pressure). 0 in both presets.
    pub pressure_ramp_kpa_per_s: f64,
}

impl Profile {
    /// Names of the presets, for error messages.
    pub const NAMES: [&'static str; 2] = ["ideal", "paper"];

    /// The preset of that name, if any.
    pub fn preset(name: &str) -> Option<Profile> {
        match name {
            "ideal" => Some(Profile::ideal()),
            "paper" => Some(Profile::paper()),
            _ => None,
        }
    }

    /// The paper's skin (MODEL.md gives the figures these constants achieve).
    pub fn paper() -> Profile {
        Profile {
            stage_offset_mm: 1.5,
            stage_rotation_deg: 1.0,
            stage_repeatability_mm: 0.5,
            sigma0_s_per_m: 0.02,
            foam_thickness_mm: 5.0,
            spread_per_thickness: 0.6,
            strain_max: 0.6,
            pressure_sat_kpa: 40.0,
            archie_exponent: 2.0,
            foam_heterogeneity: 0.2,
            foam_heterogeneity_length_mm: 20.0,
            foam_seating_jitter: 0.07,
            contact_impedance_ohm_mm2: 5e4,
            contact_impedance_spread: 0.1,
            electrode_misplacement_mm: 1.0,
            eit_noise_rel: 2e-4,
            eit_noise_abs_v: 0.0,
            eit_drift_rel: 2e-3,
            eit_drift_tau_s: 600.0,
            current_ua: 10.0,
            mesh_edge_per_diameter: 0.25,
            mesh_min_elements: 5000,
            mesh_max_elements: 12000,
            p0_kpa: 0.35,
            sensitivity_kpa_per_n: 0.3,
            edge_stiffening: 0.45,
            edge_length_mm: 18.0,
            sensitivity_heterogeneity: 0.05,
            sensitivity_heterogeneity_length_mm: 25.0,
            nonlinearity_force_n: 60.0,
            reference_diameter_mm: 15.0,
            area_exponent: 1.5,
            hysteresis_kpa: 0.02,
            hysteresis_tau_s: 5.0,
            seating_jitter: 0.03,
            pressure_noise_kpa: 0.01,
            pressure_drift_kpa: 0.02,
            pressure_drift_tau_s: 300.0,
            pressure_ramp_kpa_per_s: 0.0,
        }
    }

    /// The paper's skin without noise, drift, jitter, hysteresis or heterogeneity:
    /// deterministic and smooth, for tests.
    pub fn ideal() -> Profile {
        Profile {
            stage_offset_mm: 0.0,
            stage_rotation_deg: 0.0,
            stage_repeatability_mm: 0.0,
            foam_heterogeneity: 0.0,
            foam_seating_jitter: 0.0,
            contact_impedance_spread: 0.0,
            electrode_misplacement_mm: 0.0,
            eit_noise_rel: 0.0,
            eit_noise_abs_v: 0.0,
            eit_drift_rel: 0.0,
            sensitivity_heterogeneity: 0.0,
            hysteresis_kpa: 0.0,
            seating_jitter: 0.0,
            pressure_noise_kpa: 0.0,
            pressure_drift_kpa: 0.0,
            ..Profile::paper()
        }
    }

    /// Checks every constant's range; the error names the field.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let pos = |name: &'static str, x: f64| {
            if x.is_finite() && x > 0.0 {
                Ok(())
            } else {
                Err((name, format!("must be finite and > 0 (got {})", Num(x))))
            }
        };
        let nonneg = |name: &'static str, x: f64| {
            if x.is_finite() && x >= 0.0 {
                Ok(())
            } else {
                Err((name, format!("must be finite and >= 0 (got {})", Num(x))))
            }
        };
        let frac = |name: &'static str, x: f64| {
            if x.is_finite() && (0.0..1.0).contains(&x) {
                Ok(())
            } else {
                Err((name, format!("must be in [0, 1) (got {})", Num(x))))
            }
        };
        nonneg("stage_offset_mm", self.stage_offset_mm)?;
        nonneg("stage_rotation_deg", self.stage_rotation_deg)?;
        nonneg("stage_repeatability_mm", self.stage_repeatability_mm)?;
        pos("sigma0_s_per_m", self.sigma0_s_per_m)?;
        pos("foam_thickness_mm", self.foam_thickness_mm)?;
        nonneg("spread_per_thickness", self.spread_per_thickness)?;
        frac("strain_max", self.strain_max)?;
        pos("pressure_sat_kpa", self.pressure_sat_kpa)?;
        nonneg("archie_exponent", self.archie_exponent)?;
        frac("foam_heterogeneity", self.foam_heterogeneity)?;
        pos("foam_heterogeneity_length_mm", self.foam_heterogeneity_length_mm)?;
        pos("contact_impedance_ohm_mm2", self.contact_impedance_ohm_mm2)?;
        // Each electrode's is this times max(1 + spread N(0, 1), 0.1) (`EitChannel::new`): a
        // value near f64::MAX overflowed to inf there for most seeds, and the run was refused.
        if self.contact_impedance_ohm_mm2 > MAX_CONTACT_IMPEDANCE_OHM_MM2 {
            return Err((
                "contact_impedance_ohm_mm2",
                format!(
                    "must be at most {MAX_CONTACT_IMPEDANCE_OHM_MM2:e} (got {:e}): each electrode's is drawn \
                     around it and must stay finite",
                    self.contact_impedance_ohm_mm2
                ),
            ));
        }
        frac("contact_impedance_spread", self.contact_impedance_spread)?;
        nonneg("electrode_misplacement_mm", self.electrode_misplacement_mm)?;
        nonneg("eit_noise_rel", self.eit_noise_rel)?;
        nonneg("eit_noise_abs_v", self.eit_noise_abs_v)?;
        frac("eit_drift_rel", self.eit_drift_rel)?;
        pos("eit_drift_tau_s", self.eit_drift_tau_s)?;
        pos("current_ua", self.current_ua)?;
        pos("mesh_edge_per_diameter", self.mesh_edge_per_diameter)?;
        if !(MIN_MESH_ELEMENTS..=MAX_MESH_ELEMENTS).contains(&self.mesh_min_elements) {
            return Err((
                "mesh_min_elements",
                format!(
                    "must be in [{MIN_MESH_ELEMENTS}, {MAX_MESH_ELEMENTS}] (the forward solver's mesh limit) (got {})",
                    self.mesh_min_elements
                ),
            ));
        }
        if !(self.mesh_min_elements..=MAX_MESH_ELEMENTS).contains(&self.mesh_max_elements) {
            return Err((
                "mesh_max_elements",
                format!(
                    "must be in [mesh_min_elements = {}, {MAX_MESH_ELEMENTS}] (the forward solver's mesh limit) (got {})",
                    self.mesh_min_elements, self.mesh_max_elements
                ),
            ));
        }
        nonneg("p0_kpa", self.p0_kpa)?;
        pos("sensitivity_kpa_per_n", self.sensitivity_kpa_per_n)?;
        frac("edge_stiffening", self.edge_stiffening)?;
        pos("edge_length_mm", self.edge_length_mm)?;
        frac("sensitivity_heterogeneity", self.sensitivity_heterogeneity)?;
        pos("sensitivity_heterogeneity_length_mm", self.sensitivity_heterogeneity_length_mm)?;
        pos("nonlinearity_force_n", self.nonlinearity_force_n)?;
        pos("reference_diameter_mm", self.reference_diameter_mm)?;
        nonneg("area_exponent", self.area_exponent)?;
        nonneg("hysteresis_kpa", self.hysteresis_kpa)?;
        pos("hysteresis_tau_s", self.hysteresis_tau_s)?;
        frac("seating_jitter", self.seating_jitter)?;
        nonneg("pressure_noise_kpa", self.pressure_noise_kpa)?;
        nonneg("pressure_drift_kpa", self.pressure_drift_kpa)?;
        pos("pressure_drift_tau_s", self.pressure_drift_tau_s)?;
        if !self.pressure_ramp_kpa_per_s.is_finite() {
            return Err(("pressure_ramp_kpa_per_s", format!("must be finite (got {})", self.pressure_ramp_kpa_per_s)));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_ideal_is_noiseless() {
        for name in Profile::NAMES {
            Profile::preset(name).unwrap().validate().unwrap();
        }
        let p = Profile::ideal();
        assert_eq!(p.pressure_noise_kpa, 0.0);
        assert_eq!(p.eit_noise_rel, 0.0);
        assert_eq!(p.pressure_drift_kpa, 0.0);
        assert!(Profile::preset("perfect").is_none());
    }

    #[test]
    fn validate_names_the_field() {
        let p = Profile { strain_max: 1.5, ..Profile::paper() };
        assert_eq!(p.validate().unwrap_err().0, "strain_max");
    }

    #[test]
    fn mesh_bounds_are_capped_at_the_solver_limit() {
        let huge = Profile { mesh_min_elements: 100_000_000, mesh_max_elements: 100_000_000, ..Profile::paper() };
        let (field, msg) = huge.validate().unwrap_err();
        assert_eq!(field, "mesh_min_elements");
        assert!(msg.contains("2000000") && msg.contains("got 100000000"), "{msg}");
        let too_fine = Profile { mesh_max_elements: MAX_MESH_ELEMENTS + 1, ..Profile::paper() };
        assert_eq!(too_fine.validate().unwrap_err().0, "mesh_max_elements");
        let inverted = Profile { mesh_min_elements: 6000, mesh_max_elements: 5000, ..Profile::paper() };
        assert_eq!(inverted.validate().unwrap_err().0, "mesh_max_elements");
        let at_limit =
            Profile { mesh_min_elements: MAX_MESH_ELEMENTS, mesh_max_elements: MAX_MESH_ELEMENTS, ..Profile::paper() };
        at_limit.validate().unwrap();
    }
}
