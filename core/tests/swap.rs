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
