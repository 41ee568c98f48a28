//! The skin pipeline as a library call: a recording replayed through the real nodes
//! (`replay -> sync -> reconstructor -> segmenter -> splitter -> corrector`) in lockstep, with
//! every lane's output captured in memory. `skinflow calibrate` and `skinflow eval` use it, so
//! their figures are those of the graph a user runs, bit for bit. A lane's splitter or
//! corrector may be any kind with fitting ports, a plugin's too (`eval --lane`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::{
    Context, GraphSpec, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, PortSpec, Registry, Role,
    RunOptions, Sink, StatsReport, typed,
};

/// Messages captured per call of the capture sink: one per lane, in lane order.
pub type Captured = Arc<Mutex<Vec<Vec<Message>>>>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

impl NodeParams for NoParams {}

struct Capture {
    into: Captured,
}

impl Sink for Capture {
    fn consume(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError> {
        let row: Vec<Message> = inputs.iter_port(0).map(|(_, m)| m.clone()).collect();
        self.into.lock().map_err(|_| NodeError::msg("capture buffer poisoned"))?.push(row);
        Ok(())
    }
}

/// The built-in registry plus a `capture` sink writing into `into`.
pub fn registry_with_capture(into: Captured) -> Registry {
    let mut r = crate::registry();
    r.register(typed(
        KindInfo::new("capture", Role::Sink, "captures messages in memory (used by calibrate and eval)")
            .input(PortSpec::any("in", "anything").multi()),
        move |_: NoParams, _| Ok(NodeImpl::Sink(Box::new(Capture { into: into.clone() }))),
    ))
    .expect("capture is not a built-in kind");
    r
}

/// A failed [`PipelineSpec::run`]: what went wrong (its `Display`, naming the lane of a lane's
/// node), and the statistics of the run up to the failure, so a caller can show how far each
/// node got.
#[derive(Debug)]
pub struct PipelineError {
    pub message: String,
    /// Every node's and edge's counters when the run ended (messages in and out, calls,
    /// errors, drops, latency); `None` when no node ran: the graph was refused, a plugin
    /// library did not load, or a node did not start.
    pub stats: Option<StatsReport>,
}

impl std::fmt::Display for PipelineError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for PipelineError {}

impl PipelineError {
    /// An error before any node ran: no statistics.
    fn before_run(message: String) -> PipelineError {
        PipelineError { message, stats: None }
    }
}

/// One node of a lane: its splitter or its corrector.
#[derive(Debug, Clone, PartialEq)]
pub enum Stage {
    /// The built-in `splitter` (or `corrector`) with this `strategy` and the spec's
    /// calibration; a corrector also gets its lane's name as the `name` param.
    Strategy(String),
    /// Any kind (a plugin's, say) with its params in full; `input` and `output` are the ports
    /// wired into the lane (a splitter: `contacts` in, `split` out; a corrector: `split` in,
    /// `forces` out).
    Node { kind: String, params: toml::Table, input: String, output: String },
}

impl Stage {
    /// The port wired into the lane: the built-in kind's, or the given one.
    fn input_port(&self, built_in: &'static str) -> &str {
        match self {
            Stage::Strategy(_) => built_in,
            Stage::Node { input, .. } => input,
        }
    }

    /// As [`Stage::input_port`], for the output.
    fn output_port(&self, built_in: &'static str) -> &str {
        match self {
            Stage::Strategy(_) => built_in,
            Stage::Node { output, .. } => output,
        }
    }
}

/// One lane: contacts -> splitter -> corrector -> captured forces.
#[derive(Debug, Clone, PartialEq)]
pub struct Lane {
    /// Unique among the spec's lanes; letters, digits, '_' and '-' (it is part of a node id).
    pub name: String,
    pub split: Stage,
    pub correct: Stage,
}

impl Lane {
    /// A lane of the built-in splitter and corrector strategies.
    pub fn strategies(name: &str, split: &str, correct: &str) -> Lane {
        Lane {
            name: name.to_owned(),
            split: Stage::Strategy(split.to_owned()),
            correct: Stage::Strategy(correct.to_owned()),
        }
    }
}

/// What to run.
#[derive(Debug, Clone)]
pub struct PipelineSpec {
    pub recording: PathBuf,
    /// Inline TOML table body (`key = value, ...`) for the reconstructor's params.
    pub reconstructor: String,
    /// Inline TOML table body for the segmenter's params.
    pub segmenter: String,
    /// Inline TOML table body for the sync node's params.
    pub sync: String,
    /// With a calibration: the lanes, in capture order. Splitters shared by lanes (the same
    /// strategy, or the same kind with identical params) run once. Without: contacts are
    /// captured instead of forces.
    pub lanes: Vec<Lane>,
    pub calibration: Option<PathBuf>,
    /// Plugin libraries the lanes' kinds come from (relative to the current directory).
    pub plugins: Vec<PathBuf>,
}

fn quote(s: &str) -> String {
    toml::Value::String(s.to_owned()).to_string()
}

fn path_str(p: &Path) -> String {
    quote(&p.to_string_lossy())
}

/// `s` with every character a node id may not hold (all but ASCII letters, digits, '_' and
/// '-') replaced by '-': a plugin's kind `my.split` gives `my-split`.
fn id_part(s: &str) -> String {
    s.chars().map(|c| if skinflow_toml::is_bare_char(c) { c } else { '-' }).collect()
}

/// `base`, or `base-2`, `base-3`, ... whichever `used` does not hold yet (then added to it).
fn unique_id(base: String, used: &mut Vec<String>) -> String {
    let mut id = base.clone();
    let mut n = 1;
    while used.contains(&id) {
        n += 1;
        id = format!("{base}-{n}");
    }
    used.push(id.clone());
    id
}

/// The lanes' nodes: each distinct splitter once with its id, and per lane the index of its
/// splitter and the id of its corrector.
struct Layout<'a> {
    splitters: Vec<(String, &'a Stage)>,
    lanes: Vec<(usize, String)>,
}

/// The node of a run error, when it names one.
fn failed_node(e: &skinflow_core::RunError) -> Option<&str> {
    use skinflow_core::RunError as E;
    match e {
        E::Start { node, .. } | E::Node { node, .. } | E::Stop { node, .. } | E::Swap { node, .. } => Some(node),
        E::SwapTimeout { node, .. } | E::Control { node, .. } | E::ControlTimeout { node, .. } => Some(node),
        E::Ended { node, .. } => Some(node),
        E::UnknownNode(_) => None,
    }
}

impl PipelineSpec {
    fn layout(&self) -> Layout<'_> {
        let mut used = Vec::new();
        let mut splitters: Vec<(String, &Stage)> = Vec::new();
        let mut lanes = Vec::with_capacity(self.lanes.len());
        for lane in &self.lanes {
            let s = match splitters.iter().position(|(_, s)| **s == lane.split) {
                Some(i) => i,
                None => {
                    let base = match &lane.split {
                        Stage::Strategy(s) => format!("split-{}", id_part(s)),
                        Stage::Node { kind, .. } => format!("split-{}", id_part(kind)),
                    };
                    splitters.push((unique_id(base, &mut used), &lane.split));
                    splitters.len() - 1
                }
            };
            lanes.push((s, String::new()));
        }
        // Correctors after the splitters, so a splitter keeps its id whatever the lane names.
        for ((_, id), lane) in lanes.iter_mut().zip(&self.lanes) {
            *id = unique_id(format!("correct-{}", id_part(&lane.name)), &mut used);
        }
        Layout { splitters, lanes }
    }

    /// The names of the lanes node `id` is part of (a shared splitter is part of several),
    /// in lane order; empty for the shared stages and unknown ids.
    pub fn lanes_of(&self, id: &str) -> Vec<&str> {
        if self.calibration.is_none() {
            return Vec::new();
        }
        let layout = self.layout();
        self.lanes
            .iter()
            .zip(&layout.lanes)
            .filter(|(_, (s, c))| c == id || layout.splitters[*s].0 == id)
            .map(|(lane, _)| lane.name.as_str())
            .collect()
    }

    /// `message` prefixed with the lanes node `id` belongs to (`lane "a": ...`), if any.
    fn in_lanes(&self, id: Option<&str>, message: String) -> String {
        let lanes = id.map_or_else(Vec::new, |id| self.lanes_of(id));
        match lanes.as_slice() {
            [] => message,
            [one] => format!("lane \"{one}\": {message}"),
            many => {
                let names: Vec<String> = many.iter().map(|n| format!("\"{n}\"")).collect();
                format!("lanes {}: {message}", names.join(", "))
            }
        }
    }

    /// The built-in kinds, the capture sink writing into `into`, and the kinds of
    /// [`PipelineSpec::plugins`].
    pub fn registry(&self, into: Captured) -> Result<Registry, String> {
        let mut reg = registry_with_capture(into);
        crate::codec::load_plugins(&self.plugins, &mut reg).map_err(|e| e.to_string())?;
        Ok(reg)
    }

    /// The graph as TOML text (also what `--print-graph` shows).
    pub fn graph_toml(&self) -> String {
        let mut g = String::new();
        let _ = writeln!(g, "[graph]\nname = \"pipeline\"\nmode = \"lockstep\"\n");
        for p in &self.plugins {
            let _ = writeln!(g, "[[plugin]]\npath = {}\n", path_str(p));
        }
        let _ = writeln!(
            g,
            "[[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = {}, speed = 0.0 }}\n",
            path_str(&self.recording)
        );
        let _ = writeln!(g, "[[node]]\nid = \"sync\"\nkind = \"sync\"\nparams = {{ {} }}\n", self.sync);
        let _ =
            writeln!(g, "[[node]]\nid = \"recon\"\nkind = \"reconstructor\"\nparams = {{ {} }}\n", self.reconstructor);
        let _ = writeln!(g, "[[node]]\nid = \"segment\"\nkind = \"segmenter\"\nparams = {{ {} }}\n", self.segmenter);
        let _ = writeln!(g, "[[node]]\nid = \"capture\"\nkind = \"capture\"\ntrigger = \"aligned\"\n");
        let edge = |g: &mut String, from: &str, to: &str| {
            let _ = writeln!(g, "[[edge]]\nfrom = \"{from}\"\nto = \"{to}\"\ncapacity = 256\n");
        };
        edge(&mut g, "replay.eit", "sync.eit");
        edge(&mut g, "replay.pressure", "sync.pressure");
        edge(&mut g, "replay.truth", "sync.truth");
        edge(&mut g, "replay.reference", "recon.reference");
        edge(&mut g, "sync.frame", "recon.frame");
        edge(&mut g, "recon.image", "segment.image");
        match &self.calibration {
            None => edge(&mut g, "segment.contacts", "capture.in"),
            Some(cal) => {
                let cal = path_str(cal);
                let layout = self.layout();
                let node = |g: &mut String, id: &str, kind: &str, params: &str| {
                    let _ = writeln!(g, "[[node]]\nid = \"{id}\"\nkind = {}\nparams = {params}\n", quote(kind));
                };
                for (id, stage) in &layout.splitters {
                    match stage {
                        Stage::Strategy(s) => {
                            node(&mut g, id, "splitter", &format!("{{ strategy = {}, calibration = {cal} }}", quote(s)))
                        }
                        Stage::Node { kind, params, .. } => node(&mut g, id, kind, &inline_table(params)),
                    }
                    edge(&mut g, "segment.contacts", &format!("{id}.{}", stage.input_port("contacts")));
                }
                for (lane, (s, id)) in self.lanes.iter().zip(&layout.lanes) {
                    match &lane.correct {
                        Stage::Strategy(strategy) => node(
                            &mut g,
                            id,
                            "corrector",
                            &format!(
                                "{{ strategy = {}, calibration = {cal}, name = {} }}",
                                quote(strategy),
                                quote(&lane.name)
                            ),
                        ),
                        Stage::Node { kind, params, .. } => node(&mut g, id, kind, &inline_table(params)),
                    }
                    let (split_id, split) = &layout.splitters[*s];
                    edge(
                        &mut g,
                        &format!("{split_id}.{}", split.output_port("split")),
                        &format!("{id}.{}", lane.correct.input_port("split")),
                    );
                    edge(&mut g, &format!("{id}.{}", lane.correct.output_port("forces")), "capture.in");
                }
            }
        }
        g
    }

    /// Runs the pipeline over the recording; one captured row per EIT frame. A failure or an
    /// error of a lane's node (a plugin's, say) names the lane, as does a lane's node that did
    /// not send one message per frame (whose frames the capture then drops in every lane). An
    /// error of a run that started carries its statistics up to the failure.
    pub fn run(&self) -> Result<Vec<Vec<Message>>, PipelineError> {
        let captured: Captured = Arc::new(Mutex::new(Vec::new()));
        let reg = self.registry(captured.clone()).map_err(PipelineError::before_run)?;
        self.run_with(&reg, &captured)
    }

    /// [`PipelineSpec::run`] with the kinds of `reg`, whose `capture` writes into `captured`.
    fn run_with(&self, reg: &Registry, captured: &Captured) -> Result<Vec<Vec<Message>>, PipelineError> {
        let src = SourceFile::new("<pipeline>", self.graph_toml());
        let spec = GraphSpec::parse(src, reg).map_err(|e| PipelineError::before_run(e.to_string()))?;
        // As `skinflow check` and `run` do: a reconstructor on another sensor than the
        // recording's would make wrong images without a word.
        crate::sensors::check_graph(&spec).map_err(|e| PipelineError::before_run(e.to_string()))?;
        let report = skinflow_core::run(&spec, &RunOptions::default())
            .map_err(|e| PipelineError::before_run(self.in_lanes(failed_node(&e), e.to_string())))?;
        let stats = report.stats;
        let failed = |message: String| PipelineError { message, stats: Some(stats.clone()) };
        if let Some(f) = report.failures.first() {
            return Err(failed(self.in_lanes(failed_node(f), f.to_string())));
        }
        // A lane node that failed on some frames (logged as each happened) would leave those
        // frames out of every lane (the capture aligns the lanes): an error, not fewer frames.
        if let Some(n) = stats.nodes.iter().find(|n| n.errors + n.panics > 0 && !self.lanes_of(&n.id).is_empty()) {
            let what = format!(
                "node \"{}\" (kind \"{}\"): {} of {} calls failed (each is logged with the node's id)",
                n.id,
                n.kind,
                n.errors + n.panics,
                n.calls
            );
            return Err(failed(self.in_lanes(Some(&n.id), what)));
        }
        // Frames no image can be made of (a dead board's) are the reconstructor's: the first
        // its error, the rest its discards. They have no image, and are scored as such, as
        // when each was an error; any other drop loses data and fails the run.
        let recon = stats.node("recon").map_or(0, |n| n.discarded);
        let drops = stats.total_drops() - recon;
        if drops > 0 {
            return Err(failed(self.drops_error(&stats, drops)));
        }
        let rows = std::mem::take(&mut *captured.lock().map_err(|_| failed("capture buffer poisoned".into()))?);
        Ok(rows)
    }
}

impl PipelineSpec {
    /// The error for `drops` messages lost in a run: the lane nodes that did not send one
    /// message per message received (a corrector that sent nothing for some frames, say) are
    /// named with their lanes, as the capture, aligning the lanes frame by frame, then drops the
    /// other lanes' messages of those frames; without such a node, the bare count.
    fn drops_error(&self, stats: &StatsReport, drops: u64) -> String {
        let bare = format!("{drops} messages were dropped in the pipeline (see the stats)");
        if self.calibration.is_none() {
            return bare;
        }
        let layout = self.layout();
        let splitters = layout.splitters.iter().map(|(id, stage)| (id.as_str(), stage.output_port("split")));
        let correctors = self
            .lanes
            .iter()
            .zip(&layout.lanes)
            .map(|(lane, (_, id))| (id.as_str(), lane.correct.output_port("forces")));
        let mut blamed = Vec::new();
        let mut fewer = true;
        for (id, port) in splitters.chain(correctors) {
            let Some(n) = stats.node(id) else { continue };
            // What it sent into the lane: the messages on its lane port (any other port of a
            // plugin's kind aside), else all it sent.
            let from = format!("{id}.{port}");
            let sent = stats.edges.iter().find(|e| e.from == from).map_or(n.msgs_out, |e| e.pushed);
            if sent == n.msgs_in {
                continue;
            }
            fewer &= sent < n.msgs_in;
            let what = match port {
                "forces" => "forces".to_owned(),
                "split" => "splits".to_owned(),
                other => format!("messages on \"{other}\""),
            };
            let line = if sent < n.msgs_in {
                format!("node \"{id}\" sent {what} for {sent} of {} frames", n.msgs_in)
            } else {
                format!("node \"{id}\" sent {sent} {what} for {} frames", n.msgs_in)
            };
            blamed.push(self.in_lanes(Some(id), line));
        }
        if blamed.is_empty() {
            return bare;
        }
        let at_capture: u64 = stats.edges.iter().filter(|e| e.to.starts_with("capture.")).map(|e| e.drops).sum();
        let whose = if fewer { "of the other lanes" } else { "it could not match across the lanes" };
        let all =
            if at_capture == drops { String::new() } else { format!(" ({drops} dropped in the pipeline in all)") };
        format!(
            "{}; each lane must send one message per frame: the capture dropped {at_capture} messages {whose}{all}",
            blamed.join("; ")
        )
    }
}

/// `params` as an inline TOML table (`{ a = 1, b = "x" }`).
fn inline_table(params: &toml::Table) -> String {
    let body: Vec<String> = params.iter().map(|(k, v)| format!("{} = {}", key(k), inline_value(v))).collect();
    if body.is_empty() { "{}".to_owned() } else { format!("{{ {} }}", body.join(", ")) }
}

/// A key, quoted unless bare (letters, digits, '_' and '-').
fn key(k: &str) -> String {
    if skinflow_toml::is_bare_key(k) { k.to_owned() } else { quote(k) }
}

/// A value on one line: tables inline, at any depth.
fn inline_value(v: &toml::Value) -> String {
    match v {
        toml::Value::Table(t) => inline_table(t),
        toml::Value::Array(a) => format!("[{}]", a.iter().map(inline_value).collect::<Vec<_>>().join(", ")),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::swap_test::recording;

    fn spec(lanes: Vec<Lane>) -> PipelineSpec {
        PipelineSpec {
            recording: PathBuf::from("rec.h5"),
            reconstructor: String::new(),
            segmenter: String::new(),
            sync: String::new(),
            lanes,
            calibration: Some(PathBuf::from("calib.toml")),
            plugins: vec![PathBuf::from("libp.so")],
        }
    }

    fn node(kind: &str, params: &str, input: &str, output: &str) -> Stage {
        Stage::Node {
            kind: kind.to_owned(),
            params: toml::from_str(params).unwrap(),
            input: input.to_owned(),
            output: output.to_owned(),
        }
    }

    /// Splitters of one strategy, or of one kind with identical params, run once; other params
    /// make another node. A failing node's error names every lane it is part of.
    #[test]
    fn splitters_are_shared_only_when_kind_and_params_are_identical() {
        let peak = |e: &str| node("peak", &format!("exponent = {e}"), "contacts", "split");
        let fused = node("fused", "calibration = \"c.toml\"\nw = { a = [1, 2] }", "split", "forces");
        let s = spec(vec![
            Lane::strategies("a", "proportional", "pneumatic-locaware"),
            Lane::strategies("b", "proportional", "eit-nocal"),
            Lane { name: "p1".into(), split: peak("1.0"), correct: Stage::Strategy("pneumatic-locaware".into()) },
            Lane { name: "p1b".into(), split: peak("1.0"), correct: fused },
            Lane { name: "p2".into(), split: peak("2.0"), correct: Stage::Strategy("pneumatic-locaware".into()) },
        ]);
        let g = s.graph_toml();
        assert!(
            g.starts_with("[graph]\nname = \"pipeline\"\nmode = \"lockstep\"\n\n[[plugin]]\npath = \"libp.so\"\n"),
            "{g}"
        );
        assert_eq!(g.matches("kind = \"splitter\"").count(), 1, "{g}");
        assert_eq!(g.matches("kind = \"peak\"").count(), 2, "{g}");
        assert!(g.contains("id = \"split-peak\"\nkind = \"peak\"\nparams = { exponent = 1.0 }"), "{g}");
        assert!(g.contains("id = \"split-peak-2\"\nkind = \"peak\"\nparams = { exponent = 2.0 }"), "{g}");
        assert!(g.contains("params = { calibration = \"c.toml\", w = { a = [1, 2] } }"), "{g}");
        assert!(g.contains("from = \"split-peak.split\"\nto = \"correct-p1b.split\""), "{g}");
        assert!(g.contains("from = \"split-peak-2.split\"\nto = \"correct-p2.split\""), "{g}");
        assert_eq!(s.lanes_of("split-proportional"), ["a", "b"]);
        assert_eq!(s.lanes_of("split-peak"), ["p1", "p1b"]);
        assert_eq!(s.lanes_of("correct-p2"), ["p2"]);
        assert!(s.lanes_of("recon").is_empty());
        assert_eq!(s.in_lanes(Some("split-peak"), "x".into()), "lanes \"p1\", \"p1b\": x");
        assert_eq!(s.in_lanes(Some("correct-b"), "x".into()), "lane \"b\": x");
        // The generated graph parses with the built-in kinds standing in for the plugin's.
        let builtin = spec(vec![Lane::strategies("a", "force-balance", "pneumatic-forward")]);
        let builtin = PipelineSpec { plugins: Vec::new(), ..builtin };
        let src = SourceFile::new("<pipeline>", builtin.graph_toml());
        GraphSpec::parse(src, &registry_with_capture(Captured::default())).unwrap();
    }

    /// A kind whose name may not be part of a node id (a plugin's `my.split`) gives a node id
    /// of valid characters only, still unique, and the generated graph parses.
    #[test]
    fn node_ids_are_made_of_valid_characters_whatever_the_kind() {
        let s = spec(vec![
            Lane {
                name: "a".into(),
                split: node("my.split", "", "in", "out"),
                correct: node("my corr/ü", "", "in", "out"),
            },
            Lane { name: "b".into(), split: node("my-split", "", "in", "out"), correct: node("pass", "", "in", "out") },
        ]);
        let layout = s.layout();
        let ids: Vec<&str> = layout.splitters.iter().map(|(id, _)| id.as_str()).collect();
        assert_eq!(ids, ["split-my-split", "split-my-split-2"]);
        assert_eq!(s.lanes_of("split-my-split"), ["a"]);
        assert_eq!(s.lanes_of("split-my-split-2"), ["b"]);
        // The kinds registered under those names (standing in for a plugin's): the graph parses.
        let mut reg = registry_with_capture(Captured::default());
        for kind in ["my.split", "my-split", "my corr/ü", "pass"] {
            register_every(&mut reg, kind);
        }
        let s = PipelineSpec { plugins: Vec::new(), ..s };
        let g = GraphSpec::parse(SourceFile::new("<pipeline>", s.graph_toml()), &reg).unwrap();
        let mut ids: Vec<&str> = g.nodes.iter().map(|n| n.id.as_str()).collect();
        ids.sort_unstable();
        assert_eq!(
            ids,
            [
                "capture",
                "correct-a",
                "correct-b",
                "recon",
                "replay",
                "segment",
                "split-my-split",
                "split-my-split-2",
                "sync"
            ]
        );
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct EveryParams {
        /// Leaves out every `skip`-th message (0: none).
        #[serde(default)]
        skip: u64,
    }

    impl NodeParams for EveryParams {}

    /// Passes its input on, but for every `skip`-th message.
    struct Every {
        skip: u64,
        seen: u64,
    }

    impl skinflow_core::Processor for Every {
        fn process(
            &mut self,
            _ctx: &mut Context,
            inputs: &Inputs,
            out: &mut skinflow_core::Outputs,
        ) -> Result<(), NodeError> {
            let Some(m) = inputs.get(0) else { return Ok(()) };
            self.seen += 1;
            if self.skip > 0 && self.seen.is_multiple_of(self.skip) {
                return Ok(());
            }
            out.send(0, m.clone())
        }
    }

    /// Registers kind `kind`: any payload in on `in`, out on `out`, but every `skip`-th.
    fn register_every(reg: &mut Registry, kind: &'static str) {
        let info = KindInfo::new(kind, Role::Processor, "test: passes its input on, but every skip-th")
            .input(PortSpec::any("in", "anything").multi())
            .output(PortSpec::any("out", "its input"));
        reg.register(typed(info, |p: EveryParams, _| {
            Ok(NodeImpl::Processor(Box::new(Every { skip: p.skip, seen: 0 })))
        }))
        .unwrap();
    }

    /// A lane whose node sends nothing for some frames makes the capture drop the other lanes'
    /// messages of those frames: the run fails naming that lane and node and what it sent; a
    /// lane node sending one message per frame is not blamed.
    #[test]
    fn a_lane_node_skipping_frames_is_named_with_its_lane() {
        let rec = recording("skip", 12);
        let every = |skip: u64| node("every", &format!("skip = {skip}"), "in", "out");
        let lanes = vec![
            Lane { name: "full".into(), split: every(0), correct: every(0) },
            Lane { name: "skip".into(), split: every(0), correct: every(3) },
        ];
        let s = PipelineSpec { recording: rec.clone(), plugins: Vec::new(), ..spec(lanes) };
        let captured = Captured::default();
        let mut reg = registry_with_capture(captured.clone());
        register_every(&mut reg, "every");
        let PipelineError { message: e, stats } = s.run_with(&reg, &captured).unwrap_err();
        // The run's statistics come with the error: how far the lane's node got.
        let stats = stats.expect("the run started: its statistics");
        let node = stats.node("correct-skip").expect("the failing lane's node in the statistics");
        assert!(node.msgs_in > 0 && node.msgs_out == node.msgs_in - node.msgs_in / 3, "{node:?}");
        assert!(stats.total_drops() > 0, "{stats}");
        assert!(e.starts_with("lane \"skip\": node \"correct-skip\" sent messages on \"out\" for "), "{e}");
        assert!(e.contains("each lane must send one message per frame: the capture dropped "), "{e}");
        assert!(e.ends_with(" messages of the other lanes"), "{e}");
        assert!(!e.contains("split-every") && !e.contains("correct-full"), "{e}");

        // Every lane node sending one message per frame: the run gives one row per frame.
        let lanes = vec![Lane { name: "full".into(), split: every(0), correct: every(0) }];
        let s = PipelineSpec { recording: rec, plugins: Vec::new(), ..spec(lanes) };
        let captured = Captured::default();
        let mut reg = registry_with_capture(captured.clone());
        register_every(&mut reg, "every");
        let rows = s.run_with(&reg, &captured).unwrap();
        assert!(!rows.is_empty() && rows.iter().all(|r| r.len() == 1), "{}", rows.len());
    }
}
