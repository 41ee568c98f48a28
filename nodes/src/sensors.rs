//! Sensor agreement across a graph, for `skinflow check` and `skinflow run` (after
//! `GraphSpec::check_files`) and a hot swap: every `reconstructor` images on its own `sensor`
//! param (default `paper-100mm`), whatever its frames come from. It is refused, at load, when
//!
//! - a `replay` or `sim` node upstream of it (through its `eit` or `reference` output) has
//!   another sensor: the recording's header (`sensor` attribute) or the scene's `[sensor]`;
//! - a plugin node upstream of it (through an `eit_frame` output) declares another sensor: a
//!   plugin kind's param of type `sensor` (`skinflow_plugin_sdk::export::SENSOR`) names the
//!   sensor the frames of its outputs come from, as a reconstructor's `sensor` does (a sensor
//!   TOML file relative to the graph file; not set, `paper-100mm`). The search upstream stops
//!   at such a node: what reaches it from further up is not what it emits;
//! - a `corrector` or `splitter` node downstream of it uses a calibration fitted on another
//!   sensor (`provenance.sensor`; files before format 8 record none and are not checked).
//!
//! An `hdf5_logger` writes its own `sensor` param (default `paper-100mm`) into the recording's
//! `sensor` attribute: it is held to the sources upstream of it the same way (their `truth`
//! outputs count too, as the truth's coordinates are the sensor's), so a recording never names
//! another sensor than the one its frames and truth come from.
//!
//! Sensors agree when they have the same geometry ([`SensorRef::same_geometry`]: size to 1 µm,
//! electrode count, protocol), whatever their names. The recording is opened for its header
//! only; of the scene only its `[sensor]` table is read (`Scene::read_sensor`), so a large
//! scene is not expanded again. A file that cannot be read is skipped here: `check_files`
//! reports it. A plugin's `sensor` param is read here (the host cannot read a sensor for the
//! plugin's own checks): an unreadable or invalid sensor file, or a value that is not a string,
//! is an error located at the param, whether or not the node feeds a reconstructor.
//!
//! A `serial_loadcell` rig's indenter position (`x_mm`, `y_mm`; its `at` command at run time is
//! not checked here) must lie on the sensor of a logger recording its truth.
//! A `serial_eit` board says no sensor, only its frames' width (`measurements`): that width is
//! held to the sensor's measurement count (a reconstructor would drop, a logger refuse, every
//! frame of another width). A plugin kind without a `sensor` param is not checked; a
//! reconstructor drops its frames of another sensor's width when it runs.

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use skinflow_contact::Calibration;
use skinflow_contact::correct::SensorRef;
use skinflow_core::graph::{GraphError, GraphErrorKind, GraphErrors, GraphSpec};
use skinflow_core::{BuildContext, ParamError, Payload};
use skinflow_eit::Sensor;
use skinflow_plugin_sdk::export::SENSOR;
use skinflow_record::Recording;
use skinflow_sim::Scene;

use crate::correct::CorrectorParams;
use crate::log::LoggerParams;
use crate::payload::{EitFrame, SyncedFrame};
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

/// The sensor another node brings, and the file it comes from (`None`: a plugin node's
/// default, its `sensor` param not set).
#[derive(Clone)]
struct Other {
    sensor: SensorRef,
    file: Option<PathBuf>,
}

impl Other {
    fn file(&self) -> std::path::Display<'_> {
        self.file.as_deref().unwrap_or(Path::new("")).display()
    }
}

/// Checks that every reconstructor's sensor agrees with its sources' and with the calibrations
/// downstream of it; each disagreement is an error located at the reconstructor's `sensor`
/// param (its `[[node]]` table when it has none), naming both nodes, sensors and the file.
pub fn check_graph(spec: &GraphSpec) -> Result<(), GraphErrors> {
    let base_dir = spec.source.base_dir();
    let ctx = |i: usize| BuildContext::new(base_dir.clone(), spec.mode, spec.nodes[i].id.clone());
    // The sensor of each source or calibration node, read once (None: unreadable or none).
    let mut others: HashMap<usize, Option<Other>> = HashMap::new();
    let mut node_spans: Option<Vec<Range<usize>>> = None;
    let mut errs = Vec::new();
    // Every sensor a plugin node declares, read whether or not it feeds a reconstructor: an
    // error in it is reported nowhere else.
    for i in 0..spec.nodes.len() {
        let Some(param) = sensor_param(spec, i) else { continue };
        let declared = match declared_sensor(spec, i, param, &ctx(i)) {
            Ok(other) => Some(other),
            Err(problem) => {
                errs.push(param_error_at(spec, i, param, problem, &mut node_spans));
                None
            }
        };
        others.insert(i, declared);
    }
    for (r, node) in spec.nodes.iter().enumerate() {
        // What the node does with its sensor, what a disagreement would spoil, and who it is.
        let (sensor, does, spoils, who) = match node.kind.as_str() {
            "reconstructor" => {
                let Ok(params) = node.params.parse::<ReconstructorParams>() else { continue };
                (params.sensor, "reconstructs on", "the images would be wrong", "the reconstructor")
            }
            "hdf5_logger" => {
                let Ok(params) = node.params.parse::<LoggerParams>() else { continue };
                let spoils = "the recording would name the wrong sensor (its frames and truth read against another \
                              geometry)";
                (params.sensor, "records as its `sensor` attribute", spoils, "the logger")
            }
            _ => continue,
        };
        let Ok(own_sensor) = load_sensor(sensor.as_deref(), &ctx(r)) else { continue };
        let own = sensor_ref(&own_sensor);
        let own_desc = match &sensor {
            Some(p) => format!("sensor {own} of {}", ctx(r).resolve(p).display()),
            None => format!("sensor {own}, the default (no `sensor` param)"),
        };
        let mut problems = Vec::new();
        for s in upstream_sources(spec, r, node.kind == "hdf5_logger") {
            if spec.nodes[s].kind == "serial_loadcell" {
                // A rig says where its indenter presses: on the sensor, or its truth is no contact of it.
                let Ok(rig) = spec.nodes[s].params.parse::<crate::serial::LoadcellParams>() else { continue };
                let (hw, hh) = (0.5 * own_sensor.width_mm, 0.5 * own_sensor.height_mm);
                if rig.x_mm.abs() > hw || rig.y_mm.abs() > hh {
                    problems.push(format!(
                        "{does} {own_desc}, {} x {} mm (x in [{}, {hw}], y in [{}, {hh}] mm), but its truth comes from \
                         serial_loadcell \"{}\", whose indenter is at ({}, {}) mm, off the sensor: {spoils}; set the \
                         rig's `x_mm` / `y_mm` to where it presses on the skin (centre origin, CONTRACTS.md section 1)",
                        own_sensor.width_mm, own_sensor.height_mm, -hw, -hh, spec.nodes[s].id, rig.x_mm, rig.y_mm
                    ));
                }
                // A disc wider than the shorter side cannot lie on the skin (as the simulator's scenes).
                let side = own_sensor.width_mm.min(own_sensor.height_mm);
                if rig.diameter_mm > side {
                    problems.push(format!(
                        "{does} {own_desc}, {} x {} mm, but its truth comes from serial_loadcell \"{}\", whose indenter \
                         is {} mm wide, wider than the sensor's shorter side ({side} mm): {spoils}; set the rig's \
                         `diameter_mm` in mm",
                        own_sensor.width_mm, own_sensor.height_mm, spec.nodes[s].id, rig.diameter_mm
                    ));
                }
                continue;
            }
            if spec.nodes[s].kind == "serial_eit" {
                // A board says no sensor, only how wide its frames are.
                let Ok(board) = spec.nodes[s].params.parse::<crate::serial::EitParams>() else { continue };
                let m = own_sensor.measurement_count();
                if board.measurements != m {
                    problems.push(format!(
                        "{does} {own_desc}, whose frames are {m} values wide, but its frames come from serial_eit \
                         \"{}\", whose `measurements` = {}: every frame would be refused when the run gets it; set \
                         the board's `measurements` to {m}, or give {who} `sensor = \"...\"` of the board's sensor",
                        spec.nodes[s].id, board.measurements
                    ));
                }
                continue;
            }
            let Some(other) = others.entry(s).or_insert_with(|| source_sensor(spec, s, &ctx(s))) else { continue };
            if own.same_geometry(&other.sensor) {
                continue;
            }
            if let Some(param) = sensor_param(spec, s) {
                let on = match &other.file {
                    Some(file) => format!("sensor {} of {} (its `{param}` param)", other.sensor, file.display()),
                    None => format!("sensor {}, the default (no `{param}` param)", other.sensor),
                };
                problems.push(format!(
                    "{does} {own_desc}, but its frames come from {} \"{}\" (a plugin kind), on {on}: {spoils}; give \
                     {who} `sensor = \"...\"` matching that sensor (or, if the plugin's frames are of another, that \
                     sensor's file to its `{param}`)",
                    spec.nodes[s].kind, spec.nodes[s].id
                ));
                continue;
            }
            let (what, fix) = match spec.nodes[s].kind.as_str() {
                "replay" => ("recording", "the recording's root `sensor` attribute holds its sensor TOML"),
                _ => ("scene", "a file holding the scene's `[sensor]` table"),
            };
            problems.push(format!(
                "{does} {own_desc}, but its frames come from {} \"{}\", whose {what} {} was made on sensor {}: \
                 {spoils}; give {who} `sensor = \"...\"` matching the {what} ({fix})",
                spec.nodes[s].kind,
                spec.nodes[s].id,
                other.file(),
                other.sensor
            ));
        }
        // A logger applies no calibration.
        let calibrated = if node.kind == "reconstructor" { downstream_calibrated(spec, r) } else { Vec::new() };
        for c in calibrated {
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
                other.file(),
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

/// The `replay` and `sim` nodes whose `eit` or `reference` output reaches node `to` (and the
/// `serial_eit` nodes whose `eit` does), and the
/// nodes declaring their sensor ([`sensor_param`]) whose output of EIT frames (`eit_frame`,
/// `synced_frame`) does, directly or through other nodes (`sync`, ...), in node order. The
/// search does not go on upstream of a node declaring its sensor: its frames are of that one.
/// With `truth`, a `replay`'s, `sim`'s or `serial_loadcell`'s `truth` output counts too (its coordinates are the
/// sensor's: a logger records them).
fn upstream_sources(spec: &GraphSpec, to: usize, truth: bool) -> Vec<usize> {
    let mut seen = vec![false; spec.nodes.len()];
    let mut stack = vec![to];
    let mut found = Vec::new();
    while let Some(n) = stack.pop() {
        for e in spec.edges.iter().filter(|e| e.to_node == n) {
            let from = &spec.nodes[e.from_node];
            let port = from.factory.info().outputs.get(e.from_port);
            let declares = sensor_param(spec, e.from_node).is_some();
            let frames = if declares {
                port.is_some_and(|p| p.ty == EitFrame::TYPE || p.ty == SyncedFrame::TYPE)
            } else {
                match (from.kind.as_str(), port.map(|p| p.name.as_ref())) {
                    ("replay" | "sim", Some("eit" | "reference")) | ("serial_eit", Some("eit")) => true,
                    ("replay" | "sim" | "serial_loadcell", Some("truth")) => truth,
                    _ => false,
                }
            };
            if frames {
                found.push(e.from_node);
            }
            if !declares && !seen[e.from_node] {
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
    Some(Other { sensor: sensor_ref(&sensor), file: Some(file) })
}

/// The param of node `i`'s kind of type `sensor` (a plugin kind's, `export::SENSOR`): the
/// sensor of the EIT frames its outputs carry. At most one (the host refuses a second at load).
fn sensor_param(spec: &GraphSpec, i: usize) -> Option<&str> {
    spec.nodes[i].factory.info().params.iter().find(|p| p.ty == SENSOR).map(|p| p.name.as_ref())
}

/// The sensor node `i` declares in its param `param` of type `sensor`, read as a reconstructor
/// reads its `sensor` ([`load_sensor`]: a sensor TOML file relative to the graph file; not set,
/// `paper-100mm`); the problem, to report at the param, when it cannot be read.
fn declared_sensor(spec: &GraphSpec, i: usize, param: &str, ctx: &BuildContext) -> Result<Other, String> {
    let name = match spec.nodes[i].params.table().get(param) {
        None => None,
        Some(toml::Value::String(name)) => Some(Path::new(name)),
        Some(v) => {
            return Err(format!(
                "must name a sensor TOML file (a string, relative to the graph file; not set: paper-100mm), got {} {v}",
                v.type_str()
            ));
        }
    };
    let sensor = load_sensor(name, ctx).map_err(|e| e.to_string())?;
    Ok(Other { sensor: sensor_ref(&sensor), file: name.map(|n| ctx.resolve(n)) })
}

/// The sensor the calibration of a `corrector` or `splitter` node was fitted on, when it
/// records one.
fn calibration_sensor(spec: &GraphSpec, i: usize, ctx: &BuildContext) -> Option<Other> {
    let file = ctx.resolve(&calibration_path(spec, i)?);
    let sensor = Calibration::read(&file).ok()?.provenance.sensor?;
    Some(Other { sensor, file: Some(file) })
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

    use skinflow_core::graph::SourceFile;
    use skinflow_core::{KindInfo, NodeError, NodeImpl, NodeParams, ParamDoc, PortSpec, Registry, Role, typed};

    use crate::payload::PressureSample;

    #[test]
    fn a_sensor_ref_describes_the_sensor_as_a_calibration_does() {
        let s = sensor_ref(&Sensor::paper_100mm());
        assert_eq!(s.to_string(), "\"paper-100mm\" (100 x 100 mm, 16 electrodes, pairwise)");
    }

    /// Params of the stand-ins for plugin kinds (never built).
    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)] // only parsed
    struct BoardParams {
        sensor: Option<toml::Value>,
    }

    impl NodeParams for BoardParams {}

    /// The built-in kinds, plus stand-ins for plugin kinds declaring a `sensor` param:
    /// `p-board` (a source of EIT frames and pressure) and `p-remap` (EIT frames in, EIT frames
    /// of its own sensor out).
    fn registry() -> Registry {
        let mut r = crate::registry();
        let never =
            |_: BoardParams, _: &BuildContext| -> Result<NodeImpl, NodeError> { Err(NodeError::msg("not built")) };
        r.register(typed(
            KindInfo::new("p-board", Role::Source, "a plugin's board")
                .output(PortSpec::output::<EitFrame>("eit", "frames"))
                .output(PortSpec::output::<PressureSample>("pressure", "pressure"))
                .param(ParamDoc::new("sensor", SENSOR, "none", "its sensor")),
            never,
        ))
        .unwrap();
        r.register(typed(
            KindInfo::new("p-remap", Role::Processor, "a plugin's frames of another sensor")
                .input(PortSpec::input::<EitFrame>("in", "frames"))
                .output(PortSpec::output::<EitFrame>("out", "frames"))
                .param(ParamDoc::new("sensor", SENSOR, "none", "the sensor of its output")),
            never,
        ))
        .unwrap();
        r
    }

    /// A directory with `small.toml`, a 60 mm sensor, and `small-scene.toml`, a scene of it.
    fn dir(test: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("skinflow-sensors-unit-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let small = "[sensor]\nname = \"small-60mm\"\nwidth_mm = 60.0\nheight_mm = 60.0\n";
        std::fs::write(d.join("small.toml"), small).unwrap();
        std::fs::write(d.join("small-scene.toml"), format!("[scene]\nname = \"s\"\n{small}")).unwrap();
        d
    }

    /// The errors of `check_graph` on `text` (as `dir/g.toml`), one per line, `dir` written
    /// `DIR`; empty: accepted.
    fn errors(dir: &Path, text: &str) -> String {
        let spec = GraphSpec::parse(SourceFile::new(dir.join("g.toml"), text.to_owned()), &registry())
            .unwrap_or_else(|e| panic!("a valid graph: {e}"));
        match check_graph(&spec) {
            Ok(()) => String::new(),
            Err(e) => e.to_string().replace(&dir.display().to_string(), "DIR"),
        }
    }

    fn node(id: &str, kind: &str, params: &str) -> String {
        format!("[[node]]\nid = \"{id}\"\nkind = \"{kind}\"\nparams = {{ {params} }}\n")
    }

    fn edge(from: &str, to: &str) -> String {
        format!("[[edge]]\nfrom = \"{from}\"\nto = \"{to}\"\n")
    }

    #[test]
    fn a_plugin_nodes_sensor_is_compared_through_its_frames_alone_and_the_search_stops_there() {
        let d = dir("search");
        let recon = node("recon", "reconstructor", "") + &node("sync", "sync", "") + &edge("sync.frame", "recon.frame");
        // A board of 60 mm into a default reconstructor: refused; the board's pressure alone
        // (its frames from a default board) is not its frames.
        let g = node("b", "p-board", "sensor = \"small.toml\"") + &recon + &edge("b.eit", "sync.eit");
        assert!(errors(&d, &g).contains("frames come from p-board \"b\" (a plugin kind), on sensor \"small-60mm\""));
        let g = node("b", "p-board", "sensor = \"small.toml\"")
            + &node("d", "p-board", "")
            + &recon
            + &edge("d.eit", "sync.eit")
            + &edge("b.pressure", "sync.pressure");
        assert_eq!(errors(&d, &g), "");
        // A scene of 60 mm through a node of the default sensor: its frames are that node's.
        let sim = node("sim", "sim", "scene = \"small-scene.toml\"");
        let g =
            sim.clone() + &node("m", "p-remap", "") + &recon + &edge("sim.eit", "m.in") + &edge("m.out", "sync.eit");
        assert_eq!(errors(&d, &g), "");
        // ... and refused straight.
        let g = sim + &recon + &edge("sim.eit", "sync.eit");
        assert!(errors(&d, &g).contains("frames come from sim \"sim\", whose scene DIR/small-scene.toml"));
    }

    /// A logger writes its `sensor` param (default `paper-100mm`) into the recording: a scene or
    /// a recording of another sensor upstream, through any of its inputs, is refused at that
    /// param (or its table) as for a reconstructor; the same sensor, or one of its geometry,
    /// passes.
    #[test]
    fn a_logger_is_held_to_the_sensor_of_the_frames_it_records() {
        let d = dir("logger");
        let sim = node("sim", "sim", "scene = \"small-scene.toml\"");
        let log = |params: &str| node("log", "hdf5_logger", &format!("path = \"out.h5\"{params}"));
        let g = sim.clone() + &log("") + &edge("sim.eit", "log.eit");
        let e = errors(&d, &g);
        assert!(
            e.starts_with(
                "DIR/g.toml:5:1: node \"log\": param \"sensor\": records as its `sensor` attribute sensor \
                 \"paper-100mm\" (100 x 100 mm, 16 electrodes, pairwise), the default (no `sensor` param), but its \
                 frames come from sim \"sim\", whose scene DIR/small-scene.toml was made on sensor \"small-60mm\""
            ),
            "{e}"
        );
        assert!(
            e.contains("the recording would name the wrong sensor") && e.contains("give the logger `sensor"),
            "{e}"
        );
        // Through its truth input alone, likewise (the truth's coordinates are the sensor's).
        let g = sim.clone() + &log("") + &edge("sim.truth", "log.truth");
        assert!(errors(&d, &g).contains("node \"log\": param \"sensor\": records as its"), "{}", errors(&d, &g));
        // Given the scene's sensor: accepted.
        let g = sim + &log(", sensor = \"small.toml\"") + &edge("sim.eit", "log.eit");
        assert_eq!(errors(&d, &g), "");
    }

    #[test]
    fn a_plugin_sensor_that_cannot_be_read_is_an_error_at_its_param() {
        let d = dir("unreadable");
        let g = node("b", "p-board", "sensor = \"none.toml\"");
        assert_eq!(
            errors(&d, &g),
            "DIR/g.toml:4:12: node \"b\": param \"sensor\": DIR/none.toml: cannot read sensor: No such file or \
             directory (os error 2)"
        );
        let g = node("b", "p-board", "sensor = 60");
        assert_eq!(
            errors(&d, &g),
            "DIR/g.toml:4:12: node \"b\": param \"sensor\": must name a sensor TOML file (a string, relative to \
             the graph file; not set: paper-100mm), got integer 60"
        );
    }
}
