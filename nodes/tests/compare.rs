//! The `compare` sink across a hot swap, as a user ran `graphs/ab-replay.toml`: the splitter of
//! the lane whose corrector is named "proportional" is swapped to `eit-force` mid-run. The
//! lane's figures up to the swap are closed and a new lane goes on from the first frame the
//! new splitter made, each with the figures of a run of its strategy alone over its frames (no
//! blend), in the JSON `skinflow bench` reads.
//!
//! Deterministic: lockstep, behind a gate that holds the scripted source after `GATE` frames
//! while the swap is queued (as `handover.rs`).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::SeqCst};
use std::time::{Duration, Instant};

use serde::Deserialize;
use serde_json::Value;
use skinflow_contact::Contact;
use skinflow_core::graph::SourceFile;
use skinflow_core::{
    Context, GraphSpec, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, Params, PortSpec,
    Registry, Role, RunOptions, RunningGraph, Source, SourcePoll, typed,
};
use skinflow_nodes::payload::{Contacts, Image, SyncedFrame, Truth, TruthContact};

/// Frames of a whole run, and those let through before the swap.
const FRAMES: u64 = 10;
const GATE: u64 = 4;

#[derive(Default)]
struct Gate {
    /// Frames let through before holding (u64::MAX: never hold).
    limit: AtomicU64,
    open: AtomicBool,
    frames: AtomicU64,
    /// Polls answered while held.
    held: AtomicU64,
}

/// Params of `contacts_script`: frames `from..to` of one scripted stream.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScriptParams {
    from: u64,
    to: u64,
}

impl NodeParams for ScriptParams {}

/// Two contacts per frame, of different conductivity sums and places, pressed with 2 N and
/// 5 N, the frame settled under 3 kPa: the two splitters share that differently.
struct Script {
    next: u64,
    to: u64,
    gate: Arc<Gate>,
}

fn contacts(seq: u64) -> Contacts {
    let wobble = seq as f64 * 0.01;
    let contact =
        |x_mm: f64, sum: f64| Contact { x_mm, y_mm: 5.0, sum: sum + wobble, area_mm2: 60.0, peak: 0.1, label: 1 };
    let truth = Truth {
        contacts: vec![
            TruthContact { x_mm: -20.0, y_mm: 5.0, force_n: 2.0, diameter_mm: 10.0 },
            TruthContact { x_mm: 20.0, y_mm: 5.0, force_n: 5.0, diameter_mm: 10.0 },
        ],
    };
    let src = SyncedFrame {
        dp_kpa: 3.0,
        pressure_samples: 10,
        pressure_sd_kpa: 0.01,
        settled: true,
        noise_kpa: 0.01,
        p0_kpa: 0.0,
        truth: Some(Arc::new(truth)),
        ..SyncedFrame::default()
    };
    let image = Image { src: Arc::new(src), ..Image::default() };
    Contacts {
        image: Arc::new(image),
        contacts: vec![contact(-20.0, 1.0), contact(20.0, 3.0)],
        dropped: 0,
        floor: 0.0,
        compute_ns: 0,
    }
}

impl Source for Script {
    fn poll(&mut self, _ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let g = &self.gate;
        if !g.open.load(SeqCst) && g.frames.load(SeqCst) >= g.limit.load(SeqCst) {
            g.held.fetch_add(1, SeqCst);
            std::thread::yield_now();
            return Ok(SourcePoll::Idle);
        }
        if self.next == self.to {
            return Ok(SourcePoll::Finished);
        }
        let header = Header { seq: self.next, t_ns: (self.next + 1) * 100_000_000, origin: 0 };
        out.send(0, Message::new(header, contacts(self.next)))?;
        self.next += 1;
        g.frames.fetch_add(1, SeqCst);
        Ok(SourcePoll::Emitted)
    }
}

fn registry(gate: Arc<Gate>) -> Registry {
    let mut r = skinflow_nodes::registry();
    r.register(typed(
        KindInfo::new("contacts_script", Role::Source, "test: scripted contacts")
            .output(PortSpec::output::<Contacts>("contacts", "contacts")),
        move |p: ScriptParams, _| Ok(NodeImpl::Source(Box::new(Script { next: p.from, to: p.to, gate: gate.clone() }))),
    ))
    .unwrap();
    r
}

fn calibration() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs/calib/paper.toml")
}

/// Splitter params for `strategy`.
fn split_params(strategy: &str) -> String {
    format!("strategy = \"{strategy}\", calibration = {:?}", calibration())
}

/// What is hot-swapped after `GATE` frames.
#[derive(Clone, Copy)]
enum Swap<'a> {
    /// Lane 0's splitter, to this strategy.
    Splitter(&'a str),
    /// The compare node itself, to a new `report_s`.
    Compare,
}

/// The test graph: frames `from..to` through two splitter + corrector lanes into `compare`
/// (lane 0: splitter `split`, corrector named "proportional"; lane 1: proportional,
/// "reference"), whose node table ends with `compare` (its trigger and params lines).
fn graph((from, to): (u64, u64), split: &str, compare: &str) -> String {
    let cal = calibration();
    format!(
        "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"src\"\nkind = \"contacts_script\"\nparams = {{ from = {from}, to = {to} }}\n\
         [[node]]\nid = \"split-a\"\nkind = \"splitter\"\nparams = {{ {} }}\n\
         [[node]]\nid = \"split-b\"\nkind = \"splitter\"\n\
         [[node]]\nid = \"force-a\"\nkind = \"corrector\"\nparams = {{ calibration = {cal:?}, name = \"proportional\" }}\n\
         [[node]]\nid = \"force-b\"\nkind = \"corrector\"\nparams = {{ calibration = {cal:?}, name = \"reference\" }}\n\
         [[node]]\nid = \"cmp\"\nkind = \"compare\"\n{compare}\n\
         [[edge]]\nfrom = \"src.contacts\"\nto = \"split-a.contacts\"\n\
         [[edge]]\nfrom = \"src.contacts\"\nto = \"split-b.contacts\"\n\
         [[edge]]\nfrom = \"split-a.split\"\nto = \"force-a.split\"\n\
         [[edge]]\nfrom = \"split-b.split\"\nto = \"force-b.split\"\n\
         [[edge]]\nfrom = \"force-a.forces\"\nto = \"cmp.forces\"\n\
         [[edge]]\nfrom = \"force-b.forces\"\nto = \"cmp.forces\"\n",
        split_params(split)
    )
}

/// A fresh directory for one test run.
fn test_dir(test: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("compare").join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Params of an inline table body, as in the graph file.
fn inline_params(body: &str) -> Params {
    let table: toml::Table = format!("p = {{ {body} }}").parse().unwrap();
    Params::from_table(table["p"].as_table().unwrap().clone())
}

/// Runs [`graph`] with an aligned `compare` writing JSON; with `swap`, that node is swapped
/// after `GATE` frames. Returns the JSON report's lanes.
fn run(test: &str, frames: (u64, u64), split: &str, swap: Option<Swap>) -> Vec<Value> {
    let dir = test_dir(test);
    let json = dir.join("ab.json");
    let gate = Arc::new(Gate::default());
    gate.limit.store(if swap.is_some() { GATE } else { u64::MAX }, SeqCst);
    let reg = registry(gate.clone());
    let compare = format!("trigger = \"aligned\"\nparams = {{ json = {json:?}, print = false, report_s = 0.0 }}");
    let spec = GraphSpec::parse(SourceFile::new(dir.join("ab.toml"), graph(frames, split, &compare)), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let runner = std::thread::spawn(move || running.wait(&RunOptions::default()));
    if let Some(swap) = swap {
        // Held twice: everything before the gate has run through (a lockstep pass drains).
        let t0 = Instant::now();
        while gate.held.load(SeqCst) < 2 {
            assert!(t0.elapsed() < Duration::from_secs(300), "the source was never held");
            std::thread::sleep(Duration::from_millis(5));
        }
        match swap {
            Swap::Splitter(strategy) => {
                let params = inline_params(&split_params(strategy));
                handle.swap("split-a", reg.get("splitter").unwrap().clone(), params).unwrap();
            }
            Swap::Compare => {
                let params = inline_params(&format!("json = {json:?}, print = false, report_s = 1.0"));
                handle.swap("cmp", reg.get("compare").unwrap().clone(), params).unwrap();
            }
        }
        gate.open.store(true, SeqCst);
    }
    let report = runner.join().unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    assert_eq!(report.stats.total_drops(), 0);
    let swapped = |node: &str| report.stats.node(node).unwrap().swaps;
    assert_eq!(swapped("split-a"), u64::from(matches!(swap, Some(Swap::Splitter(_)))));
    assert_eq!(swapped("cmp"), u64::from(matches!(swap, Some(Swap::Compare))));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    doc["lanes"].as_array().unwrap().clone()
}

/// Runs [`graph`] over every frame with `compare` as given (trigger and params lines): the
/// run's failures, as the engine reports them.
fn failures(test: &str, compare: &str) -> Vec<String> {
    let dir = test_dir(test);
    let gate = Arc::new(Gate::default());
    gate.limit.store(u64::MAX, SeqCst);
    let reg = registry(gate);
    let spec =
        GraphSpec::parse(SourceFile::new(dir.join("ab.toml"), graph((0, FRAMES), "proportional", compare)), &reg)
            .unwrap();
    let report = skinflow_core::run(&spec, &RunOptions::default()).unwrap();
    report.failures.iter().map(ToString::to_string).collect()
}

/// The scored figures of a lane (not its wall-clock latency).
fn scores(l: &Value) -> [&Value; 6] {
    ["rmse_n", "relative_error_pct", "localization_mean_mm", "matched", "missed", "spurious"].map(|k| &l[k])
}

#[test]
fn a_swap_that_changes_a_lanes_strategy_closes_it_and_starts_a_new_lane_with_its_own_figures() {
    let lanes = run("swap", (0, FRAMES), "proportional", Some(Swap::Splitter("eit-force")));
    let row = |l: &Value| {
        (
            l["name"].as_str().unwrap().to_owned(),
            l["frames"].as_u64().unwrap(),
            l["input"].as_u64().unwrap(),
            l["segment"].as_u64().unwrap(),
            l["split"].as_str().unwrap().to_owned(),
            (l["first_frame"].as_u64().unwrap(), l["last_frame"].as_u64().unwrap()),
            l["superseded"].as_bool().unwrap(),
        )
    };
    let rows: Vec<_> = lanes.iter().map(row).collect();
    let s = String::from;
    assert_eq!(
        rows,
        [
            (s("proportional (to frame 3)"), GATE, 0, 0, s("proportional"), (0, GATE - 1), true),
            (s("eit-force (from frame 4)"), FRAMES - GATE, 0, 1, s("eit-force"), (GATE, FRAMES - 1), false),
            (s("reference"), FRAMES, 1, 0, s("proportional"), (0, FRAMES - 1), false),
        ]
    );
    // What `skinflow bench` reads is there for every lane.
    for l in &lanes {
        assert!(l["latency_us_p50"].is_f64() && l["latency_us_p99"].is_f64(), "{l}");
        assert!(l["rmse_n"].is_f64() && l["localization_mean_mm"].is_f64(), "{l}");
    }

    // Each lane's figures are those of its strategy alone over its frames, not a blend.
    let before = run("before", (0, GATE), "proportional", None);
    let after = run("after", (GATE, FRAMES), "eit-force", None);
    assert_eq!(scores(&lanes[0]), scores(&before[0]));
    assert_eq!(scores(&lanes[1]), scores(&after[0]));
    assert_ne!(lanes[0]["rmse_n"], lanes[1]["rmse_n"], "the two splits differ, or this test shows nothing");
    // The untouched lane is one lane over the whole run.
    let whole = run("whole", (0, FRAMES), "proportional", None);
    assert_eq!(whole.len(), 2);
    assert_eq!(scores(&lanes[2]), scores(&whole[1]));
    assert_eq!((whole[0]["name"].as_str(), whole[0]["superseded"].as_bool()), (Some("proportional"), Some(false)));
}

/// The compare node swapped mid-run (a new `report_s`): the replacement takes over every lane
/// with its figures, so the report at the end covers the whole run, as an unswapped one does,
/// and the replaced instance does not leave a report of its own.
#[test]
fn a_swap_of_the_compare_node_keeps_every_lanes_figures() {
    let swapped = run("swap-compare", (0, FRAMES), "proportional", Some(Swap::Compare));
    let whole = run("unswapped", (0, FRAMES), "proportional", None);
    assert_eq!(swapped.len(), 2);
    for (s, w) in swapped.iter().zip(&whole) {
        assert_eq!(scores(s), scores(w));
        for k in ["name", "frames", "scored_frames", "no_load_frames", "first_frame", "last_frame", "superseded"] {
            assert_eq!(s[k], w[k], "{k}: {s} vs {w}");
        }
    }
    assert_eq!((swapped[0]["frames"].as_u64(), swapped[0]["first_frame"].as_u64()), (Some(FRAMES), Some(0)));
}

/// Settings that would leave every lane without a disagreement stop the graph with a cause:
/// a `reference` that is not a lane, and a trigger that does not hand the lanes' forces of
/// one frame over together.
#[test]
fn a_reference_past_the_lanes_or_a_trigger_that_is_not_aligned_stops_the_run() {
    let f = failures("reference", "trigger = \"aligned\"\nparams = { print = false, reference = 5 }");
    assert_eq!(f.len(), 1, "{f:?}");
    assert!(f[0].starts_with("node \"cmp\": param \"reference\": 5 is not a lane: the node has 2 lanes"), "{f:?}");
    // The last lane is fine.
    let f = failures("reference-1", "trigger = \"aligned\"\nparams = { print = false, reference = 1 }");
    assert!(f.is_empty(), "{f:?}");
    for (test, trigger) in [("any", ""), ("periodic", "trigger = \"periodic\"\nperiod_ms = 1")] {
        let f = failures(test, &format!("{trigger}\nparams = {{ print = false }}"));
        assert_eq!(f.len(), 1, "{test}: {f:?}");
        assert!(f[0].starts_with("node \"cmp\": trigger: compare needs trigger = \"aligned\""), "{test}: {f:?}");
    }
}
