//! Example plugin: `fused-corrector`, an alternative corrector that fuses both channels'
//! global force maps instead of correcting one by location:
//! F_i = w f_p(dP_i) + (1 - w) f_e(C_i), with f_p, f_e the quadratics `skinflow calibrate`
//! fitted on all locations (`[pneumatic.map]`, `[eit.map]` of the calibration file), each
//! continued linearly (with its end slope, never negative) outside its calibrated signal range.
//! dP_i <= 0 gives 0 N; forces are clamped to >= 0. Units: kPa, image units x pixels, N.
//!
//! ```toml
//! params = { calibration = "calib/paper.toml", weight_pneumatic = 0.8, name = "fused-0.8" }
//! ```
//! Input `split` (columns `dp_kpa`, `sum`), output `forces` (column `force_n`). The forces are
//! named after the node (its id, or `name`: the host reads that param), so several fused lanes
//! in one graph are told apart by `compare` and `hdf5_logger`.
//!
//! Control: `weight_pneumatic W` sets w while the graph runs (in [0, 1]; from the next frame),
//! e.g. `skinflow send SOCKET '{"cmd":"control","node":"fused","command":"weight_pneumatic 0.5"}'`.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use skinflow_plugin_sdk::export::INPUT_PATH;
use skinflow_plugin_sdk::{Columns, KindSpec, Outputs, PluginNode};

/// `f(s) = a0 + a1 s + a2 s^2` fitted on `[signal_min, signal_max]`, as in the calibration file.
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct SignalMap {
    pub quadratic: Quadratic,
    pub signal_min: f64,
    pub signal_max: f64,
}

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Quadratic {
    pub a0: f64,
    pub a1: f64,
    pub a2: f64,
}

impl SignalMap {
    fn at(&self, s: f64) -> f64 {
        let q = &self.quadratic;
        q.a0 + s * (q.a1 + s * q.a2)
    }

    fn slope(&self, s: f64) -> f64 {
        (self.quadratic.a1 + 2.0 * self.quadratic.a2 * s).max(0.0)
    }

    /// Force at signal `s`: the quadratic inside the range, its tangent (slope >= 0) outside.
    pub fn eval(&self, s: f64) -> f64 {
        let (lo, hi) = (self.signal_min, self.signal_max);
        if s > hi {
            self.at(hi) + self.slope(hi) * (s - hi)
        } else if s < lo {
            self.at(lo) + self.slope(lo) * (s - lo)
        } else {
            self.at(s)
        }
    }
}

#[derive(Deserialize)]
struct Channel {
    map: SignalMap,
}

/// The parts of a calibration file this corrector reads (other keys are ignored).
#[derive(Deserialize)]
struct CalibrationMaps {
    format: String,
    pneumatic: Channel,
    eit: Channel,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FusedParams {
    /// Calibration file from `skinflow calibrate` (relative to the graph file).
    pub calibration: PathBuf,
    /// Weight w of the pneumatic estimate, in [0, 1].
    #[serde(default = "default_weight")]
    pub weight_pneumatic: f64,
    /// The forces' strategy name; read by the host (see `KindSpec::param`), not used here.
    #[serde(default)]
    pub name: Option<String>,
}

fn default_weight() -> f64 {
    0.8
}

/// A weight of the pneumatic estimate, in [0, 1].
fn weight(w: f64) -> Result<f64, String> {
    if (0.0..=1.0).contains(&w) { Ok(w) } else { Err(format!("must be in [0, 1] (got {w})")) }
}

/// `fused-corrector`.
pub struct Fused {
    pneumatic: SignalMap,
    eit: SignalMap,
    w: f64,
}

impl Fused {
    /// Force of one contact from its pressure share and conductivity sum.
    pub fn force(&self, dp_kpa: f64, sum: f64) -> f64 {
        if dp_kpa.is_nan() || dp_kpa <= 0.0 {
            return 0.0;
        }
        let f = self.w * self.pneumatic.eval(dp_kpa) + (1.0 - self.w) * self.eit.eval(sum.max(0.0));
        if f.is_finite() { f.max(0.0) } else { 0.0 }
    }
}

impl PluginNode for Fused {
    type Params = FusedParams;

    fn spec() -> KindSpec {
        KindSpec::new("fused-corrector", "per-contact force fusing the pneumatic and EIT global force maps")
            .input("split", "split", "dP_i per contact")
            .output("forces", "forces", "per-contact forces, N")
            .param("calibration", INPUT_PATH, "", "calibration TOML from `skinflow calibrate` (read at load)")
            .param("weight_pneumatic", "float", "0.8", "weight of the pneumatic estimate, in [0, 1]")
            .param(
                "name",
                "string",
                "none",
                "strategy name of the forces (compare lane, logger table); default: the node id",
            )
    }

    fn validate(p: &FusedParams) -> Result<(), String> {
        weight(p.weight_pneumatic).map(drop).map_err(|e| format!("param \"weight_pneumatic\": {e}"))
    }

    fn new(p: FusedParams, base_dir: &Path) -> Result<Self, String> {
        let path = base_dir.join(&p.calibration);
        let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let cal: CalibrationMaps =
            skinflow_toml::from_str(&text).map_err(|e| format!("{}: {}", path.display(), e.message()))?;
        if cal.format != "skinflow-calibration" {
            return Err(format!("{}: not a calibration file (format \"{}\")", path.display(), cal.format));
        }
        Ok(Fused { pneumatic: cal.pneumatic.map, eit: cal.eit.map, w: p.weight_pneumatic })
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String> {
        let s = &inputs[0];
        if !s.present() {
            return Ok(());
        }
        let (dp, sum) = (s.require("dp_kpa")?, s.require("sum")?);
        let force = out.port(0).column("force_n");
        force.extend(dp.iter().zip(sum).map(|(&d, &c)| self.force(d, c)));
        Ok(())
    }

    /// `weight_pneumatic W`: the fusion weight from the next frame on.
    fn control(&mut self, cmd: &str) -> Result<(), String> {
        match cmd.split_whitespace().collect::<Vec<_>>()[..] {
            ["weight_pneumatic", w] => {
                let parsed: f64 = w.parse().map_err(|_| format!("weight_pneumatic: \"{w}\" is not a number"))?;
                self.w = weight(parsed).map_err(|e| format!("weight_pneumatic: {e}"))?;
                Ok(())
            }
            _ => Err(format!("unknown command \"{cmd}\" (fused-corrector takes: weight_pneumatic W)")),
        }
    }
}

skinflow_plugin_sdk::export_plugin!(name = "correct-fused", kinds = [Fused]);

#[cfg(test)]
mod tests {
    use super::*;

    fn map(a0: f64, a1: f64, a2: f64) -> SignalMap {
        SignalMap { quadratic: Quadratic { a0, a1, a2 }, signal_min: 0.5, signal_max: 2.0 }
    }

    #[test]
    fn map_is_quadratic_inside_and_tangent_outside() {
        let m = map(0.1, 2.0, 0.5);
        assert!((m.eval(1.0) - 2.6).abs() < 1e-12);
        // Above: f(2) = 6.1, slope 4 -> f(3) = 10.1.
        assert!((m.eval(3.0) - 10.1).abs() < 1e-12);
        // Below: f(0.5) = 1.225, slope 2.5 -> f(0.1) = 0.225.
        assert!((m.eval(0.1) - 0.225).abs() < 1e-12);
    }

    #[test]
    fn fusion_weights_the_two_maps_and_guards_no_load() {
        let f = Fused { pneumatic: map(0.0, 1.0, 0.0), eit: map(0.0, 3.0, 0.0), w: 0.25 };
        assert!((f.force(1.0, 1.0) - (0.25 + 0.75 * 3.0)).abs() < 1e-12);
        assert_eq!(f.force(0.0, 1.0), 0.0);
        assert_eq!(f.force(f64::NAN, 1.0), 0.0);
        let neg = Fused { pneumatic: map(-5.0, 0.0, 0.0), eit: map(-5.0, 0.0, 0.0), w: 0.5 };
        assert_eq!(neg.force(1.0, 1.0), 0.0, "negative forces clamp to 0");
    }

    #[test]
    fn the_weight_is_set_at_run_time_and_a_bad_one_is_refused() {
        let mut f = Fused { pneumatic: map(0.0, 1.0, 0.0), eit: map(0.0, 3.0, 0.0), w: 0.25 };
        f.control("weight_pneumatic 1").unwrap();
        assert!((f.force(1.0, 1.0) - 1.0).abs() < 1e-12, "the pneumatic map alone");
        assert_eq!(f.control("weight_pneumatic 1.5").unwrap_err(), "weight_pneumatic: must be in [0, 1] (got 1.5)");
        assert_eq!(f.control("weight_pneumatic NaN").unwrap_err(), "weight_pneumatic: must be in [0, 1] (got NaN)");
        assert_eq!(f.control("weight_pneumatic heavy").unwrap_err(), "weight_pneumatic: \"heavy\" is not a number");
        assert_eq!(
            f.control("weight 0.5").unwrap_err(),
            "unknown command \"weight 0.5\" (fused-corrector takes: weight_pneumatic W)"
        );
        assert_eq!(f.w, 1.0, "a refused command changes nothing");
    }
}
