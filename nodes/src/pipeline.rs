//! The skin pipeline as a library call: a recording replayed through the real nodes
//! (`replay -> sync -> reconstructor -> segmenter -> splitter -> corrector`) in lockstep, with
//! every lane's output captured in memory. `skinflow calibrate` and `skinflow eval` use it, so
//! their figures are those of the graph a user runs, bit for bit.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::{
    Context, GraphSpec, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, PortSpec, Registry, Role,
    RunOptions, Sink, typed,
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
    /// With a calibration: (lane name, splitter strategy, corrector strategy) per lane.
    /// Without: contacts are captured instead of forces.
    pub lanes: Vec<(String, String, String)>,
    pub calibration: Option<PathBuf>,
}

fn quote(s: &str) -> String {
    toml::Value::String(s.to_owned()).to_string()
}

fn path_str(p: &Path) -> String {
    quote(&p.to_string_lossy())
}

impl PipelineSpec {
    /// The graph as TOML text (also what `--print-graph` shows).
    pub fn graph_toml(&self) -> String {
        let mut g = String::new();
        let _ = writeln!(g, "[graph]\nname = \"pipeline\"\nmode = \"lockstep\"\n");
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
                let mut splitters: Vec<&str> = Vec::new();
                for (_, split, _) in &self.lanes {
                    if !splitters.contains(&split.as_str()) {
                        splitters.push(split);
                    }
                }
                for s in &splitters {
                    let _ = writeln!(
                        g,
                        "[[node]]\nid = \"split-{s}\"\nkind = \"splitter\"\nparams = {{ strategy = {}, calibration = {cal} }}\n",
                        quote(s)
                    );
                    edge(&mut g, "segment.contacts", &format!("split-{s}.contacts"));
                }
                for (name, split, strategy) in &self.lanes {
                    let _ = writeln!(
                        g,
                        "[[node]]\nid = \"correct-{name}\"\nkind = \"corrector\"\nparams = {{ strategy = {}, calibration = {cal}, name = {} }}\n",
                        quote(strategy),
                        quote(name)
                    );
                    edge(&mut g, &format!("split-{split}.split"), &format!("correct-{name}.split"));
                    edge(&mut g, &format!("correct-{name}.forces"), "capture.in");
                }
            }
        }
        g
    }

    /// Runs the pipeline over the recording; one captured row per EIT frame.
    pub fn run(&self) -> Result<Vec<Vec<Message>>, String> {
        let captured: Captured = Arc::new(Mutex::new(Vec::new()));
        let reg = registry_with_capture(captured.clone());
        let src = SourceFile::new("<pipeline>", self.graph_toml());
        let spec = GraphSpec::parse(src, &reg).map_err(|e| e.to_string())?;
        let report = skinflow_core::run(&spec, &RunOptions::default()).map_err(|e| e.to_string())?;
        if let Some(f) = report.failures.first() {
            return Err(f.to_string());
        }
        // Frames no image can be made of (a dead board's) are the reconstructor's: the first
        // its error, the rest its discards. They have no image, and are scored as such, as
        // when each was an error; any other drop loses data and fails the run.
        let recon = report.stats.node("recon").map_or(0, |n| n.discarded);
        let drops = report.stats.total_drops() - recon;
        if drops > 0 {
            return Err(format!("{drops} messages were dropped in the pipeline (see the stats)"));
        }
        let rows = std::mem::take(&mut *captured.lock().map_err(|_| "capture buffer poisoned".to_string())?);
        Ok(rows)
    }
}
