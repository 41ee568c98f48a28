//! Hot swap: a node's instance is replaced between two calls while the graph runs; its queues
//! are kept, so nothing is lost on `block` edges; ports that differ are refused.

use std::time::{Duration, Instant};

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Params, Registry, RunError, RunOptions, RunningGraph};

fn registry() -> Registry {
    let mut r = Registry::new();
    skinflow_core::toy::register(&mut r).unwrap();
    r
}

#[test]
fn swapping_parameters_mid_run_loses_nothing_and_switches_once() {
    let dir = std::env::temp_dir().join(format!("skinflow-swap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("swap.csv");
    let graph = format!(
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 3000, rate_hz = 3000.0 }}\n\
         [[node]]\nid = \"f\"\nkind = \"scale\"\nparams = {{ factor = 2 }}\n\
         [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = {out:?} }}\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"f.in\"\ncapacity = 8\n\
         [[edge]]\nfrom = \"f.out\"\nto = \"out.in\"\ncapacity = 8\n"
    );
    let reg = registry();
    let spec = GraphSpec::parse(SourceFile::new(dir.join("g.toml"), graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let t0 = Instant::now();
    while handle.stats().node("f").unwrap().msgs_out < 300 {
        assert!(t0.elapsed() < Duration::from_secs(20), "the graph does not run");
        std::thread::sleep(Duration::from_millis(2));
    }
    let scale = reg.get("scale").unwrap().clone();
    handle.swap("f", scale, Params::from_toml("add = 1000000").unwrap()).unwrap();
    let report = running.wait(&RunOptions::default());
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    assert_eq!(report.stats.total_drops(), 0);
    assert_eq!(report.stats.node("f").unwrap().swaps, 1);

    let rows: Vec<(u64, u64)> = std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .map(|l| {
            let (a, b) = l.split_once(',').unwrap();
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect();
    assert_eq!(rows.len(), 3000, "every message arrives across the swap");
    // Before the swap v -> 2v; after it v -> v + 1e6; exactly one switch, in order.
    let switch = rows.iter().position(|&(_, y)| y >= 1_000_000).expect("the swap took effect");
    assert!(switch >= 300);
    for (i, &(seq, y)) in rows.iter().enumerate() {
        assert_eq!(seq, i as u64);
        let expected = if i < switch { 2 * seq } else { seq + 1_000_000 };
        assert_eq!(y, expected, "row {i}");
    }
}

#[test]
fn a_swap_to_other_ports_or_bad_params_is_refused_and_the_graph_goes_on() {
    let graph = "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = { count = 10 }\n\
         [[node]]\nid = \"f\"\nkind = \"scale\"\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"f.in\"\n\
         [[edge]]\nfrom = \"f.out\"\nto = \"out.in\"\n";
    let reg = registry();
    let spec = GraphSpec::parse(SourceFile::new("g.toml", graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let h = running.handle();
    let sum = reg.get("sum").unwrap().clone();
    match h.swap("f", sum, Params::empty()) {
        Err(RunError::Swap { node, problem }) => {
            assert_eq!(node, "f");
            assert!(problem.contains("other ports"), "{problem}");
        }
        other => panic!("expected a refused swap, got {other:?}"),
    }
    let scale = reg.get("scale").unwrap().clone();
    let e = h.swap("f", scale, Params::from_toml("factr = 3").unwrap()).unwrap_err();
    assert!(e.to_string().contains("factr"), "{e}");
    assert!(matches!(
        h.swap("nope", reg.get("scale").unwrap().clone(), Params::empty()),
        Err(RunError::UnknownNode(_))
    ));
    let report = running.wait(&RunOptions::default());
    assert!(report.failures.is_empty());
    assert_eq!(report.stats.node("f").unwrap().msgs_out, 10);
    assert_eq!(report.stats.node("f").unwrap().swaps, 0);
}

/// A stateful toy: `out = running total of the inputs + offset`. Its total is the state a swap
/// hands over.
mod total {
    use serde::Deserialize;
    use skinflow_core::toy::Count;
    use skinflow_core::{
        Context, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, Outputs, PortSpec, Processor,
        Registry, Role, StateRefused, typed,
    };

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct P {
        #[serde(default)]
        offset: u64,
    }
    impl NodeParams for P {}

    struct Total {
        offset: u64,
        total: u64,
    }

    /// What `Total` hands over.
    struct Running(u64);

    impl Processor for Total {
        fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
            let Some(m) = inputs.get(0) else { return Ok(()) };
            self.total += m.get::<Count>().unwrap().0;
            out.send(0, Message::new(m.header, Count(self.total + self.offset)))
        }
        fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
            Some(Box::new(Running(self.total)))
        }
        fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
            let r = state.downcast::<Running>().map_err(|s| StateRefused::new(s, "not a running total"))?;
            self.total = r.0;
            Ok(())
        }
    }

    pub fn register(r: &mut Registry) {
        r.register(typed(
            KindInfo::new("total", Role::Processor, "test: running total + offset")
                .input(PortSpec::input::<Count>("in", "the value"))
                .output(PortSpec::output::<Count>("out", "the total")),
            |p: P, _| Ok(NodeImpl::Processor(Box::new(Total { offset: p.offset, total: 0 }))),
        ))
        .unwrap();
    }
}

fn rows_of(path: &std::path::Path) -> Vec<(u64, u64)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let (a, b) = l.split_once(',').unwrap();
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect()
}

/// Runs counter -> `kind` (params) -> collect in real time and swaps the middle node to
/// `to_kind` (to_params) once 300 messages passed it. Returns the collected rows.
fn swap_mid_run(name: &str, params: &str, to_kind: &str, to_params: &str) -> Vec<(u64, u64)> {
    let dir = std::env::temp_dir().join(format!("skinflow-swap-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("rows.csv");
    let graph = format!(
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 2000, rate_hz = 3000.0 }}\n\
         [[node]]\nid = \"f\"\nkind = \"total\"\nparams = {{ {params} }}\n\
         [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = {out:?} }}\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"f.in\"\ncapacity = 8\n\
         [[edge]]\nfrom = \"f.out\"\nto = \"out.in\"\ncapacity = 8\n"
    );
    let mut reg = registry();
    total::register(&mut reg);
    let spec = GraphSpec::parse(SourceFile::new(dir.join("g.toml"), graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let t0 = Instant::now();
    while handle.stats().node("f").unwrap().msgs_out < 300 {
        assert!(t0.elapsed() < Duration::from_secs(20), "the graph does not run");
        std::thread::sleep(Duration::from_millis(2));
    }
    handle.swap("f", reg.get(to_kind).unwrap().clone(), Params::from_toml(to_params).unwrap()).unwrap();
    let report = running.wait(&RunOptions::default());
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    assert_eq!(report.stats.node("f").unwrap().swaps, 1);
    let rows = rows_of(&out);
    assert_eq!(rows.len(), 2000, "every message arrives across the swap");
    rows
}

#[test]
fn a_swap_hands_the_old_instances_state_to_the_replacement() {
    let rows = swap_mid_run("handover", "", "total", "offset = 1000000000");
    // The running total goes on across the swap: only the offset changes, once.
    let switch = rows.iter().position(|&(_, y)| y >= 1_000_000_000).expect("the swap took effect");
    assert!(switch >= 300);
    let mut total = 0;
    for (i, &(seq, y)) in rows.iter().enumerate() {
        total += seq;
        assert_eq!(y, if i < switch { total } else { total + 1_000_000_000 }, "row {i}");
    }
}

#[test]
fn a_replacement_that_refuses_the_state_starts_afresh() {
    // `scale` takes over nothing: after the swap the values are the plain inputs.
    let rows = swap_mid_run("refused", "", "scale", "add = 1000000000");
    let switch = rows.iter().position(|&(_, y)| y >= 1_000_000_000).expect("the swap took effect");
    let mut total = 0;
    for (i, &(seq, y)) in rows.iter().enumerate() {
        total += seq;
        assert_eq!(y, if i < switch { total } else { seq + 1_000_000_000 }, "row {i}");
    }
}

#[test]
fn control_wait_returns_the_nodes_answer() {
    let graph = "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = { count = 100000, rate_hz = 1000.0 }\n\
         [[node]]\nid = \"f\"\nkind = \"scale\"\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"f.in\"\n\
         [[edge]]\nfrom = \"f.out\"\nto = \"out.in\"\n";
    let reg = registry();
    let spec = GraphSpec::parse(SourceFile::new("g.toml", graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let wait = Duration::from_secs(30);
    match running.control_wait("f", "bogus", wait) {
        Err(RunError::Control { node, command, error }) => {
            assert_eq!((node.as_str(), command.as_str()), ("f", "bogus"));
            assert!(error.to_string().contains("not supported"), "{error}");
        }
        other => panic!("expected the node's refusal, got {other:?}"),
    }
    assert!(matches!(running.control_wait("ghost", "tare", wait), Err(RunError::UnknownNode(_))));
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let report = running.wait(&RunOptions { stop: Some(stop), ..RunOptions::default() });
    assert!(report.failures.is_empty(), "{:?}", report.failures);
}
