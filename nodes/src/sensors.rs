//! Sensor agreement across a graph, for `skinflow check` and `skinflow run` (after
//! `GraphSpec::check_files`): every `reconstructor` images on its own `sensor` param (default
//! `paper-100mm`), whatever its frames come from. It is refused, at load, when
//!
//! - a `replay` or `sim` node upstream of it (through its `eit` or `reference` output) has
//!   another sensor: the recording's header (`sensor` attribute) or the scene's `[sensor]`;
//! - a `corrector` or `splitter` node downstream of it uses a calibration fitted on another
//!   sensor (`provenance.sensor`; files before format 8 record none and are not checked).
//!
//! Sensors agree when they have the same geometry ([`SensorRef::same_geometry`]: size to 1 µm,
//! electrode count, protocol), whatever their names. The recording is opened for its header
//! only; of the scene only its `[sensor]` table is read (`Scene::read_sensor`), so a large
//! scene is not expanded again. A file that cannot be read is skipped here: `check_files`
//! reports it.

use std::collections::HashMap;
use std::ops::Range;
use std::path::PathBuf;

use serde::Deserialize;
use skinflow_contact::Calibration;
use skinflow_contact::correct::SensorRef;
use skinflow_core::graph::{GraphError, GraphErrorKind, GraphErrors, GraphSpec};
use skinflow_core::{BuildContext, ParamError};
use skinflow_eit::Sensor;
use skinflow_record::Recording;
use skinflow_sim::Scene;

use crate::correct::CorrectorParams;
use crate::reconstruct::{ReconstructorParams, load_sensor};
use crate::replay::ReplayParams;
use crate::sim::SimParams;
use crate::split::{SplitStrategy, SplitterParams};

/// A sensor as a calibration records it, from a sensor description.
pub fn sensor_ref(s: &Sensor) -> SensorRef {
    SensorRef {
        name: s.name.clone(),
        width_mm: s.width_mm,
        height_mm: s.height_mm,
        electrodes: s.electrodes.len(),
        protocol: s.protocol.name().to_owned(),
    }
}

/// The sensor another node brings, and the file it comes from.
#[derive(Clone)]
struct Other {
    sensor: SensorRef,
    file: PathBuf,
}

/// Checks that every reconstructor's sensor agrees with its sources' and with the calibrations
/// downstream of it; each disagreement is an error located at the reconstructor's `sensor`
/// param (its `[[node]]` table when it has none), naming both nodes, sensors and the file.
pub fn check_graph(spec: &GraphSpec) -> Result<(), GraphErrors> {
    let base_dir = spec.source.base_dir();
    let ctx =
        |i: usize| BuildContext { base_dir: base_dir.clone(), mode: spec.mode, node_id: spec.nodes[i].id.clone() };
    // The sensor of each source or calibration node, read once (None: unreadable or none).
    let mut others: HashMap<usize, Option<Other>> = HashMap::new();
    let mut node_spans: Option<Vec<Range<usize>>> = None;
    let mut errs = Vec::new();
    for (r, node) in spec.nodes.iter().enumerate() {
        if node.kind != "reconstructor" {
            continue;
        }
        let Ok(params) = node.params.parse::<ReconstructorParams>() else { continue };
        let Ok(own) = load_sensor(params.sensor.as_deref(), &ctx(r)) else { continue };
        let own = sensor_ref(&own);
        let own_desc = match &params.sensor {
            Some(p) => format!("sensor {own} of {}", ctx(r).resolve(p).display()),
            None => format!("sensor {own}, the default (no `sensor` param)"),
        };
        let mut problems = Vec::new();
        for s in upstream_sources(spec, r) {
            let Some(other) = others.entry(s).or_insert_with(|| source_sensor(spec, s, &ctx(s))) else { continue };
            if own.same_geometry(&other.sensor) {
                continue;
            }
            let (what, fix) = match spec.nodes[s].kind.as_str() {
                "replay" => ("recording", "the recording's root `sensor` attribute holds its sensor TOML"),
                _ => ("scene", "a file holding the scene's `[sensor]` table"),
            };
            problems.push(format!(
                "reconstructs on {own_desc}, but its frames come from {} \"{}\", whose {what} {} was made on sensor {}: \
                 the images would be wrong; give the reconstructor `sensor = \"...\"` matching the {what} ({fix})",
                spec.nodes[s].kind,
                spec.nodes[s].id,
                other.file.display(),
                other.sensor
            ));
        }
        for c in downstream_calibrated(spec, r) {
            let Some(other) = others.entry(c).or_insert_with(|| calibration_sensor(spec, c, &ctx(c))) else { continue };
            if own.same_geometry(&other.sensor) {
                continue;
            }
            problems.push(format!(
                "reconstructs on {own_desc}, but {} \"{}\" downstream uses calibration {}, fitted on sensor {}: its \
                 forces would be wrong; recalibrate on recordings of this sensor (`skinflow calibrate`), or give the \
                 reconstructor `sensor = \"...\"` matching the calibration's",
                spec.nodes[c].kind,
                spec.nodes[c].id,
                other.file.display(),
                other.sensor
            ));
        }
        for problem in problems {
            errs.push(param_error_at(spec, r, "sensor", problem, &mut node_spans));
        }
    }
    if errs.is_empty() {
        return Ok(());
    }
    errs.sort_by_key(|e| (e.line, e.col));
    Err(GraphErrors(errs))
}

/// The `replay` and `sim` nodes whose `eit` or `reference` output reaches node `to`, directly
/// or through other nodes (`sync`, ...), in node order.
fn upstream_sources(spec: &GraphSpec, to: usize) -> Vec<usize> {
    let mut seen = vec![false; spec.nodes.len()];
    let mut stack = vec![to];
    let mut found = Vec::new();
    while let Some(n) = stack.pop() {
        for e in spec.edges.iter().filter(|e| e.to_node == n) {
            let from = &spec.nodes[e.from_node];
            let port = from.factory.info().outputs.get(e.from_port).map(|p| p.name.as_ref());
            if matches!(from.kind.as_str(), "replay" | "sim") && matches!(port, Some("eit" | "reference")) {
                found.push(e.from_node);
            }
            if !seen[e.from_node] {
                seen[e.from_node] = true;
                stack.push(e.from_node);
            }
        }
    }
    found.sort_unstable();
    found.dedup();
    found
}

/// The `corrector` and `splitter` nodes that node `from` reaches, in node order.
fn downstream_calibrated(spec: &GraphSpec, from: usize) -> Vec<usize> {
    let mut seen = vec![false; spec.nodes.len()];
    let mut stack = vec![from];
    while let Some(n) = stack.pop() {
        for e in spec.edges.iter().filter(|e| e.from_node == n) {
            if !seen[e.to_node] {
                seen[e.to_node] = true;
                stack.push(e.to_node);
            }
        }
    }
    (0..spec.nodes.len())
        .filter(|&i| seen[i] && matches!(spec.nodes[i].kind.as_str(), "corrector" | "splitter"))
        .collect()
}

/// The sensor of a `replay` (its recording's header) or `sim` node (its scene).
fn source_sensor(spec: &GraphSpec, i: usize, ctx: &BuildContext) -> Option<Other> {
    let params = &spec.nodes[i].params;
    let (sensor, file) = match spec.nodes[i].kind.as_str() {
        "replay" => {
            let file = ctx.resolve(&params.parse::<ReplayParams>().ok()?.path);
            (Recording::read_sensor(&file).ok()?, file)
        }
        "sim" => {
            let file = ctx.resolve(&params.parse::<SimParams>().ok()?.scene);
            (Scene::read_sensor(&file).ok()?, file)
        }
        _ => return None,
    };
    Some(Other { sensor: sensor_ref(&sensor), file })
}

/// The sensor the calibration of a `corrector` or `splitter` node was fitted on, when it
/// records one.
fn calibration_sensor(spec: &GraphSpec, i: usize, ctx: &BuildContext) -> Option<Other> {
    let file = ctx.resolve(&calibration_path(spec, i)?);
    let sensor = Calibration::read(&file).ok()?.provenance.sensor?;
    Some(Other { sensor, file })
}

/// The calibration file node `i` applies, as written: a corrector's, or a splitter's that
/// reads one (every strategy but `proportional`).
pub(crate) fn calibration_path(spec: &GraphSpec, i: usize) -> Option<PathBuf> {
    let params = &spec.nodes[i].params;
    match spec.nodes[i].kind.as_str() {
        "corrector" => Some(params.parse::<CorrectorParams>().ok()?.calibration),
        "splitter" => match params.parse::<SplitterParams>().ok()? {
            SplitterParams { strategy, calibration: Some(path) } if strategy != SplitStrategy::Proportional => {
                Some(path)
            }
            _ => None,
        },
        _ => None,
    }
}

/// An error of node `n`'s param `param`, located at the param in the graph file (at its
/// `[[node]]` table when the param is not written; `node_spans` caches those spans).
pub(crate) fn param_error_at(
    spec: &GraphSpec,
    n: usize,
    param: &str,
    problem: String,
    node_spans: &mut Option<Vec<Range<usize>>>,
) -> GraphError {
    let node = &spec.nodes[n];
    let located = node.params.locate::<()>(Err(ParamError::new(param, problem))).unwrap_err();
    let span = located.span.clone().or_else(|| node_spans.get_or_insert_with(|| table_spans(spec)).get(n).cloned());
    let (line, col) = span.map_or((1, 1), |s| spec.source.line_col(s.start));
    GraphError {
        file: spec.source.path.clone(),
        line,
        col,
        node: Some(node.id.clone()),
        kind: GraphErrorKind::Param(located.to_string()),
    }
}

/// The `[[node]]` tables of a graph file read without their schema, for their spans.
#[derive(Deserialize)]
struct NodeTables {
    #[serde(default)]
    node: Vec<toml::Spanned<toml::Table>>,
}

/// The byte span of each `[[node]]` table, in file order (the order of `spec.nodes`).
fn table_spans(spec: &GraphSpec) -> Vec<Range<usize>> {
    toml::from_str::<NodeTables>(&spec.source.text)
        .map_or_else(|_| Vec::new(), |f| f.node.iter().map(|t| t.span()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sensor_ref_describes_the_sensor_as_a_calibration_does() {
        let s = sensor_ref(&Sensor::paper_100mm());
        assert_eq!(s.to_string(), "\"paper-100mm\" (100 x 100 mm, 16 electrodes, pairwise)");
    }
}
