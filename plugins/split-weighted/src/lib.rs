//! Example plugin: two alternative splitters of a frame's pressure change dP among its
//! contacts, for A/B comparison with the built-in `splitter` (which weights by the
//! conductivity sum C_i).
//!
//! - `area-weighted-splitter`: w_i = A_i (ROI area, mm^2): a chamber's volume change follows
//!   the indented area more than EIT's amplitude, which is biased by distance to the electrodes.
//! - `peak-weighted-splitter`: w_i = peak_i^exponent (largest conductivity decrease of the ROI).
//!
//! dP_i = w_i / sum_j w_j * dP; all-zero weights share dP equally. Input `contacts`
//! (columns `area_mm2`, `peak`, `frame_dp_kpa`), output `split` (column `dp_kpa`, kPa), named
//! after the node (its id, or its `name` param, which the host reads): a built-in corrector
//! after it names its forces `<strategy>-<that name>`.

use std::path::Path;

use serde::Deserialize;
use skinflow_plugin_sdk::{Columns, KindSpec, Outputs, PluginNode};

/// Shares `dp_kpa` by `weights` into `out` (cleared first). Non-finite or negative weights count as 0.
pub fn share(dp_kpa: f64, weights: impl Iterator<Item = f64> + Clone, out: &mut Vec<f64>) {
    let clean = |w: f64| if w.is_finite() { w.max(0.0) } else { 0.0 };
    let total: f64 = weights.clone().map(clean).sum();
    let n = weights.clone().count() as f64;
    out.clear();
    out.extend(weights.map(|w| if total > 0.0 { clean(w) / total * dp_kpa } else { dp_kpa / n }));
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AreaParams {
    /// The split's strategy name; read by the host (see `KindSpec::param`), not used here.
    #[serde(default)]
    pub name: Option<String>,
}

/// The `name` param's doc line (both kinds).
const NAME_DOC: &str = "strategy name of the split (a built-in corrector's suffix); default: the node id";

/// `area-weighted-splitter`.
pub struct AreaWeighted;

impl PluginNode for AreaWeighted {
    type Params = AreaParams;

    fn spec() -> KindSpec {
        KindSpec::new("area-weighted-splitter", "splits dP among contacts in proportion to their ROI areas")
            .input("contacts", "contacts", "segmented contacts (carry the synced dP)")
            .output("split", "split", "dP_i per contact, kPa")
            .param("name", "string", "none", NAME_DOC)
    }

    fn new(_: AreaParams, _: &Path) -> Result<Self, String> {
        Ok(AreaWeighted)
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String> {
        let c = &inputs[0];
        if !c.present() {
            return Ok(());
        }
        let (area, dp) = (c.require("area_mm2")?, c.scalar("frame_dp_kpa")?);
        share(dp, area.iter().copied(), out.port(0).column("dp_kpa"));
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeakParams {
    /// Weight = peak^exponent.
    #[serde(default = "one")]
    pub exponent: f64,
    /// As [`AreaParams::name`].
    #[serde(default)]
    pub name: Option<String>,
}

fn one() -> f64 {
    1.0
}

/// `peak-weighted-splitter`.
pub struct PeakWeighted {
    exponent: f64,
}

impl PluginNode for PeakWeighted {
    type Params = PeakParams;

    fn spec() -> KindSpec {
        KindSpec::new("peak-weighted-splitter", "splits dP among contacts in proportion to peak^exponent")
            .input("contacts", "contacts", "segmented contacts (carry the synced dP)")
            .output("split", "split", "dP_i per contact, kPa")
            .param("exponent", "float", "1.0", "weight = peak^exponent, in [0, 4]")
            .param("name", "string", "none", NAME_DOC)
    }

    fn validate(p: &PeakParams) -> Result<(), String> {
        if (0.0..=4.0).contains(&p.exponent) {
            Ok(())
        } else {
            Err(format!("param \"exponent\": must be in [0, 4] (got {})", p.exponent))
        }
    }

    fn new(p: PeakParams, _: &Path) -> Result<Self, String> {
        Ok(PeakWeighted { exponent: p.exponent })
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String> {
        let c = &inputs[0];
        if !c.present() {
            return Ok(());
        }
        let (peak, dp) = (c.require("peak")?, c.scalar("frame_dp_kpa")?);
        let e = self.exponent;
        share(dp, peak.iter().map(|p| p.max(0.0).powf(e)), out.port(0).column("dp_kpa"));
        Ok(())
    }
}

skinflow_plugin_sdk::export_plugin!(name = "split-weighted", kinds = [AreaWeighted, PeakWeighted]);

#[cfg(test)]
mod tests {
    use super::share;

    #[test]
    fn shares_sum_to_dp_in_weight_proportion() {
        let mut out = Vec::new();
        share(3.0, [1.0, 2.0].into_iter(), &mut out);
        assert_eq!(out, vec![1.0, 2.0]);
    }

    #[test]
    fn zero_or_bad_weights_share_equally() {
        let mut out = Vec::new();
        share(2.0, [0.0, -1.0, f64::NAN, 0.0].into_iter(), &mut out);
        assert_eq!(out, vec![0.5; 4]);
        share(2.0, [f64::INFINITY, 1.0].into_iter(), &mut out);
        assert_eq!(out, vec![0.0, 2.0], "an infinite weight counts as 0");
    }

    #[test]
    fn no_contacts_no_shares() {
        let mut out = vec![9.0];
        share(2.0, std::iter::empty(), &mut out);
        assert!(out.is_empty());
    }
}
