//! Graph validation, table-driven over `tests/cases/{valid,invalid}-*.toml`.
//!
//! Each invalid case starts with one `# expect: LINE:COL: SUBSTRING` comment per error it must
//! produce, in file order. The test checks the count, the file, line and column of every error,
//! that the rendered message starts with `file:line:col: ` and contains the substring (which
//! names the node where one is involved).

use std::path::{Path, PathBuf};
use std::time::Duration;

use skinflow_core::graph::{GraphErrorKind, Policy, ThreadMode, Trigger};
use skinflow_core::registry::{KindInfo, NodeParams, Registry, Role, typed};
use skinflow_core::{GraphSpec, Inputs, NodeError, NodeImpl, Outputs, Payload, PortSpec, Sink, Source, SourcePoll};

/// A second payload type, so a type mismatch can be built from test kinds.
struct Text;

impl Payload for Text {
    const TYPE: &'static str = "text";
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

impl NodeParams for NoParams {}

/// A fixed-size array param: a longer array in the graph must be refused, not truncated.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PlacedParams {
    #[allow(dead_code)]
    position_mm: [f64; 2],
}

impl NodeParams for PlacedParams {}

struct Silent;

impl Source for Silent {
    fn poll(&mut self, _: &mut skinflow_core::Context, _: &mut Outputs) -> Result<SourcePoll, NodeError> {
        Ok(SourcePoll::Finished)
    }
}

impl Sink for Silent {
    fn consume(&mut self, _: &mut skinflow_core::Context, _: &Inputs) -> Result<(), NodeError> {
        Ok(())
    }
}

fn registry() -> Registry {
    let mut r = Registry::new();
    skinflow_core::toy::register(&mut r).unwrap();
    r.register(typed(
        KindInfo::new("text_source", Role::Source, "test: emits nothing, declares a text output")
            .output(PortSpec::output::<Text>("out", "text")),
        |_: NoParams, _| Ok(NodeImpl::Source(Box::new(Silent))),
    ))
    .unwrap();
    r.register(typed(
        KindInfo::new("text_optional", Role::Sink, "test: an optional text input")
            .input(PortSpec::input::<Text>("in", "text").optional()),
        |_: NoParams, _| Ok(NodeImpl::Sink(Box::new(Silent))),
    ))
    .unwrap();
    r.register(typed(
        KindInfo::new("placed", Role::Sink, "test: a fixed-size array param, an optional text input")
            .input(PortSpec::input::<Text>("in", "text").optional()),
        |_: PlacedParams, _| Ok(NodeImpl::Sink(Box::new(Silent))),
    ))
    .unwrap();
    r
}

fn cases(prefix: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy();
            name.starts_with(prefix) && name.ends_with(".toml")
        })
        .collect();
    v.sort();
    assert!(!v.is_empty(), "no {prefix}*.toml cases in {}", dir.display());
    v
}

struct Expect {
    line: usize,
    col: usize,
    text: String,
}

fn expectations(path: &Path) -> Vec<Expect> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .filter_map(|l| l.strip_prefix("# expect: "))
        .map(|e| {
            let mut parts = e.splitn(3, ':');
            let line = parts.next().unwrap().trim().parse().unwrap();
            let col = parts.next().unwrap().trim().parse().unwrap();
            let text = parts.next().unwrap_or("").trim().to_owned();
            Expect { line, col, text }
        })
        .collect()
}

#[test]
fn valid_cases_load() {
    let reg = registry();
    for path in cases("valid-") {
        if let Err(e) = GraphSpec::load(&path, &reg) {
            panic!("{} should be valid:\n{e}", path.display());
        }
    }
}

#[test]
fn invalid_cases_report_located_errors() {
    let reg = registry();
    let mut failures = Vec::new();
    for path in cases("invalid-") {
        let want = expectations(&path);
        assert!(!want.is_empty(), "{} has no `# expect:` line", path.display());
        let got = match GraphSpec::load(&path, &reg) {
            Ok(_) => {
                failures.push(format!("{}: loaded but should fail", path.display()));
                continue;
            }
            Err(e) => e.0,
        };
        let rendered: Vec<String> = got.iter().map(ToString::to_string).collect();
        let ok = got.len() == want.len()
            && got.iter().zip(&want).zip(&rendered).all(|((g, w), r)| {
                g.file == path
                    && (g.line, g.col) == (w.line, w.col)
                    && r.starts_with(&format!("{}:{}:{}: ", path.display(), w.line, w.col))
                    && r.contains(&w.text)
            });
        if !ok {
            let want: Vec<String> = want.iter().map(|w| format!("{}:{}: {}", w.line, w.col, w.text)).collect();
            failures.push(format!("{}\n  want: {want:#?}\n  got:  {rendered:#?}", path.display()));
        }
    }
    assert!(failures.is_empty(), "{} case(s) failed:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn errors_name_the_node_where_one_is_involved() {
    let reg = registry();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases");
    for (case, node) in [
        ("invalid-unknown-kind.toml", "x"),
        ("invalid-unknown-param.toml", "c"),
        ("invalid-param-range.toml", "c"),
        ("invalid-unconnected.toml", "s"),
        ("invalid-deadline.toml", "s"),
        ("invalid-periodic-needs-period.toml", "s"),
        ("invalid-node-field-type.toml", "s"),
        ("invalid-node-field-cpu.toml", "n"),
        ("invalid-unknown-trigger.toml", "n"),
        ("invalid-restart.toml", "n"),
        ("invalid-unknown-node-key.toml", "c"),
        ("invalid-align-misplaced.toml", "s"),
        ("invalid-pool-rt-priority.toml", "s"),
        ("invalid-pool-source.toml", "c"),
        ("invalid-param-array-too-long.toml", "p"),
    ] {
        let errs = GraphSpec::load(&dir.join(case), &reg).err().unwrap().0;
        assert_eq!(errs[0].node.as_deref(), Some(node), "{case}");
    }
}

#[test]
fn unknown_kind_lists_every_known_kind() {
    let reg = registry();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases/invalid-unknown-kind.toml");
    let msg = GraphSpec::load(&path, &reg).err().unwrap().to_string();
    for kind in reg.names() {
        assert!(msg.contains(kind), "{kind} missing from: {msg}");
    }
}

#[test]
fn missing_file_is_an_error_naming_it() {
    let path = Path::new("/nonexistent-skinflow-dir/graph.toml");
    let errs = GraphSpec::load(path, &registry()).err().unwrap();
    let msg = errs.to_string();
    assert!(msg.starts_with("/nonexistent-skinflow-dir/graph.toml:1:1: cannot read"), "{msg}");
}

#[test]
fn valid_chain_has_its_structure() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases/valid-chain.toml");
    let g = GraphSpec::load(&path, &registry()).unwrap();
    assert_eq!(g.name, "chain");
    let ids: Vec<&str> = g.topo.iter().map(|&i| g.nodes[i].id.as_str()).collect();
    assert_eq!(ids, ["src", "s1", "s2", "s3", "s4", "out"]);
    assert_eq!(g.edges.len(), 5);
    assert_eq!(g.edges[0].capacity, skinflow_core::graph::DEFAULT_CAPACITY);
    assert_eq!(g.edges[1].capacity, 4);
    assert_eq!(g.edges[2].policy, Policy::DropOldest);
    assert_eq!(g.nodes[3].deadline_us, Some(500.0));
    assert_eq!(g.nodes[4].restart, skinflow_core::graph::Restart::Always);
}

#[test]
fn valid_triggers_are_parsed() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases/valid-triggers.toml");
    let g = GraphSpec::load(&path, &registry()).unwrap();
    let node = |id: &str| &g.nodes[g.node_index(id).unwrap()];
    assert_eq!(g.mode, skinflow_core::Mode::Realtime);
    assert_eq!(g.workers, 2);
    assert_eq!(node("by-seq").trigger, Trigger::AlignedSeq);
    assert_eq!(node("by-time").trigger, Trigger::AlignedWindow { window_ns: 50_000 });
    assert_eq!(node("tick").trigger, Trigger::Periodic { period: Duration::from_millis(10) });
    assert_eq!(node("tick").cpu, Some(0));
    assert_eq!(node("tick").rt_priority, Some(10));
    assert_eq!(node("a").trigger, Trigger::Any);
    // Two edges into the multi-input sink, in file order.
    let into_sink: Vec<&str> = g.edges.iter().filter(|e| e.to == "sink.in").map(|e| e.from.as_str()).collect();
    assert_eq!(into_sink, ["tick.out", "by-time.out"]);
}

#[test]
fn schema_errors_in_a_node_without_a_usable_id_say_so() {
    let reg = registry();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases");
    for (case, problem) in [
        ("invalid-node-without-id.toml", "without an id"),
        ("invalid-node-field-bad-id.toml", "with an invalid id \"c.1\""),
    ] {
        let errs = GraphSpec::load(&dir.join(case), &reg).err().unwrap().0;
        assert_eq!(errs.len(), 1, "{case}");
        assert_eq!(errs[0].node, None, "{case}");
        let GraphErrorKind::UnnamedNode { problem: got, .. } = &errs[0].kind else { panic!("{case}: {:?}", errs[0]) };
        assert_eq!(got, problem, "{case}");
    }
}

#[test]
fn duplicate_edge_is_one_error_naming_both_lines() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases/invalid-duplicate-edge-single.toml");
    let errs = GraphSpec::load(&path, &registry()).err().unwrap().0;
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert_eq!(
        errs[0].kind,
        GraphErrorKind::DuplicateEdge { from: "c.out".into(), to: "s.in".into(), first_line: 16, line: 24 }
    );
}

#[test]
fn cycle_error_names_only_the_nodes_on_the_cycle() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases/invalid-cycle-downstream.toml");
    let errs = GraphSpec::load(&path, &registry()).err().unwrap().0;
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert_eq!(
        errs[0].kind,
        GraphErrorKind::Cycle { path: "a -> b -> a".into(), from: "b.out".into(), to: "a.b".into() }
    );
    assert!(!errs[0].to_string().contains('z'), "{}", errs[0]);
}

#[test]
fn valid_placement_keeps_the_thread_as_written() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases/valid-placement.toml");
    let g = GraphSpec::load(&path, &registry()).unwrap();
    let node = |id: &str| &g.nodes[g.node_index(id).unwrap()];
    assert_eq!(node("c").rt_priority, Some(20));
    // Absent means pool; the runtime gives a node with rt_priority or cpu a thread of its own.
    assert_eq!((node("implied").thread, node("implied").rt_priority), (ThreadMode::Pool, Some(10)));
    assert_eq!((node("written").thread, node("written").cpu), (ThreadMode::Dedicated, Some(0)));
    assert_eq!(node("pooled").thread, ThreadMode::Pool);
}
