//! The image scale a calibration was fitted on, against the pipeline that applies it.
//!
//! Conductivity sums and contact areas scale with the reconstructor's grid, mesh, prior and
//! lambda and with the segmenter's thresholds; a calibration's EIT strategies, area terms and
//! `sensitivity-compensated` shares read them on the scale it was fitted with, which it records
//! (`provenance.pipeline`: the `--recon` and `--segment` bodies of `skinflow calibrate`, empty
//! for the defaults). `eval` warns when its own flags differ ([`same_recon`],
//! [`same_segment`]); `check` and `run` warn for every `corrector` or `splitter` of a graph
//! whose calibration was fitted with other settings than the `reconstructor` and `segmenter`
//! upstream of it ([`check_graph`]). A warning, not an error: the location-aware pneumatic
//! strategies read only the centroid, and an A/B graph varies these settings on purpose.

use std::collections::HashMap;
use std::path::PathBuf;

use serde::de::DeserializeOwned;
use skinflow_contact::Calibration;
use skinflow_contact::correct::PipelineSettings;
use skinflow_core::BuildContext;
use skinflow_core::graph::GraphSpec;
use skinflow_eit::reconstruct::{Precision, ReconParams};

use crate::reconstruct::ReconstructorParams;
use crate::segment::SegmenterParams;
use crate::sensors::calibration_path;

/// Parses a `--recon` / `--segment` body (`lambda = 0.05, image_nx = 48`) as a node's params.
pub fn parse_body<T: DeserializeOwned>(text: &str) -> Result<T, String> {
    let doc = format!("params = {{ {text} }}");
    let mut table: toml::Table =
        toml::from_str(&doc).map_err(|e| format!("not a TOML table body: {}", skinflow_toml::message(&e)))?;
    let params = table.remove("params").unwrap_or_else(|| toml::Value::Table(toml::Table::new()));
    skinflow_toml::deserialize::<T, _>(params).map_err(|e| e.message().to_owned())
}

/// What of a reconstructor's params sets the image's scale: the math with defaults filled in
/// (an explicit default equals an absent one) and the point spread (the segmenter's crosstalk
/// pass); not its precision (the same image to rounding), cache, reference frames, per-element
/// output or sensor (checked apart: `sensors::check_graph`).
fn recon_scale(p: &ReconstructorParams) -> (ReconParams, f64) {
    let math = ReconParams { precision: Precision::default(), cache_dir: None, ..p.recon() };
    (math, p.point_spread_mm)
}

/// Whether two `--recon` bodies image on the same scale (an unparsable one never does).
pub fn same_recon(a: &str, b: &str) -> bool {
    let scale = |t: &str| parse_body::<ReconstructorParams>(t).ok().map(|p| recon_scale(&p));
    matches!((scale(a), scale(b)), (Some(x), Some(y)) if x == y)
}

/// Whether two `--segment` bodies give equal segmenter params (each shapes the ROIs).
pub fn same_segment(a: &str, b: &str) -> bool {
    let parse = |t: &str| parse_body::<SegmenterParams>(t).ok();
    matches!((parse(a), parse(b)), (Some(x), Some(y)) if x == y)
}

/// One warning per `corrector` or `splitter` (a splitter with a calibration and a strategy
/// other than `proportional`) and per `reconstructor` or `segmenter` upstream of it whose
/// settings differ from those its calibration records, naming both nodes, the calibration and
/// both settings. Files that do not read, and calibrations that record no settings (before
/// format 7), are skipped.
pub fn check_graph(spec: &GraphSpec) -> Vec<String> {
    let base_dir = spec.source.base_dir();
    let mut read: HashMap<PathBuf, Option<PipelineSettings>> = HashMap::new();
    let mut warnings = Vec::new();
    for (c, node) in spec.nodes.iter().enumerate() {
        let Some(path) = calibration_path(spec, c) else { continue };
        let ctx = BuildContext::new(base_dir.clone(), spec.mode, node.id.clone());
        let file = ctx.resolve(&path);
        let recorded = read.entry(file.clone()).or_insert_with(|| Calibration::read(&file).ok()?.provenance.pipeline);
        let Some(recorded) = recorded.as_ref() else { continue };
        for u in upstream(spec, c) {
            let up = &spec.nodes[u];
            let (stage, then, same) = match up.kind.as_str() {
                "reconstructor" => {
                    let Ok(now) = up.params.parse::<ReconstructorParams>() else { continue };
                    let then = parse_body::<ReconstructorParams>(&recorded.recon).ok();
                    ("reconstructor", &recorded.recon, then.is_some_and(|t| recon_scale(&t) == recon_scale(&now)))
                }
                "segmenter" => {
                    let Ok(now) = up.params.parse::<SegmenterParams>() else { continue };
                    let then = parse_body::<SegmenterParams>(&recorded.segment).ok();
                    ("segmenter", &recorded.segment, then.is_some_and(|t| t == now))
                }
                _ => continue,
            };
            if same {
                continue;
            }
            let then = if then.is_empty() {
                format!("the default {stage} settings")
            } else {
                format!("{stage} settings '{then}'")
            };
            let now = match up.params.table() {
                t if t.is_empty() => "its defaults".to_owned(),
                t => toml::Value::Table(t.clone()).to_string(),
            };
            warnings.push(format!(
                "node \"{}\": calibration {} was fitted with {then}, but {stage} \"{}\" upstream runs with \
                 {now}: the EIT strategies, area terms and sensitivity-compensated shares read conductivity sums \
                 and areas on the calibration's scale (the pneumatic location-aware ones only the centroid)",
                node.id,
                file.display(),
                up.id,
            ));
        }
    }
    warnings
}

/// The nodes whose messages reach node `to`, in node order.
fn upstream(spec: &GraphSpec, to: usize) -> Vec<usize> {
    let mut seen = vec![false; spec.nodes.len()];
    let mut stack = vec![to];
    while let Some(n) = stack.pop() {
        for e in spec.edges.iter().filter(|e| e.to_node == n) {
            if !std::mem::replace(&mut seen[e.from_node], true) {
                stack.push(e.from_node);
            }
        }
    }
    (0..spec.nodes.len()).filter(|&i| seen[i]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_explicit_default_is_the_same_scale_and_precision_or_cache_do_not_count() {
        let lambda = ReconParams::default().lambda;
        assert!(same_recon("", &format!("lambda = {lambda:?}")));
        assert!(same_recon("", "precision = \"f32\", no_cache = true, reference_frames = 3"));
        assert!(!same_recon("", "lambda = 0.05"));
        assert!(!same_recon("", "point_spread_mm = 0.0"));
        assert!(!same_recon("", "image_nx = 48"));
        assert!(!same_recon("", "lambda = "), "an unparsable body is never the same");
        assert!(same_segment("", ""));
        assert!(!same_segment("", "floor = 0.5"));
    }
}
