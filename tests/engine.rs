//! The engine through the `skinflow` binary: `check`, `run` (Ctrl-C, statistics, JSON,
//! start-up failure, panics), `nodes` and `dot`. Graphs are written to a fresh temp directory.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const LIMIT: Duration = Duration::from_secs(60);

use super::support::{bin, spawn, status, text};

fn skinflow() -> Command {
    let mut c = Command::new(bin());
    c.env("RUST_LOG", "info");
    c
}

/// A fresh work directory for one test of this module.
fn temp_dir(name: &str) -> PathBuf {
    super::support::workdir("engine", name)
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Runs to completion, failing the test if it takes longer than `LIMIT` (a hang).
fn run_to_end(cmd: &mut Command) -> Output {
    let mut child = spawn(cmd.stdout(Stdio::piped()).stderr(Stdio::piped()));
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > LIMIT {
            let _ = child.kill();
            panic!("hang: skinflow did not exit within {LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child.wait_with_output().unwrap()
}

fn rows(path: &Path) -> Vec<(u64, u64)> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| {
            let (s, v) = l.split_once(',').unwrap();
            (s.parse().unwrap(), v.parse().unwrap())
        })
        .collect()
}

#[test]
fn check_reports_file_line_and_column_and_exits_2() {
    let dir = temp_dir("check");
    let bad = write(
        &dir,
        "bad.toml",
        "[[node]]\nid = \"c\"\nkind = \"counter\"\n\n[[node]]\nid = \"x\"\nkind = \"nope\"\n\n[[edge]]\nfrom = \"c.out\"\nto = \"x.in\"\ncapacity = 0\n",
    );
    let out = run_to_end(skinflow().arg("check").arg(&bad));
    assert_eq!(out.status.code(), Some(2), "stderr: {}", text(&out.stderr));
    let err = text(&out.stderr);
    let want = format!("{}:7:8: node \"x\": unknown kind \"nope\" (known kinds: ", bad.display());
    assert!(err.contains(&want), "{err}");
    assert!(err.contains(&format!("{}:12:12: edge capacity must be >= 1 (got 0)", bad.display())), "{err}");

    let good = write(
        &dir,
        "good.toml",
        "[[node]]\nid = \"c\"\nkind = \"counter\"\n[[node]]\nid = \"n\"\nkind = \"null\"\n[[edge]]\nfrom = \"c.out\"\nto = \"n.in\"\n",
    );
    let out = run_to_end(skinflow().arg("check").arg(&good));
    assert!(out.status.success(), "stderr: {}", text(&out.stderr));
    assert!(text(&out.stdout).contains("ok (2 nodes, 1 edges)"), "{}", text(&out.stdout));

    // `run` refuses an invalid graph the same way.
    let out = run_to_end(skinflow().arg("run").arg(&bad));
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains(&want));
}

#[test]
fn ctrl_c_stops_sources_drains_flushes_and_exits_0() {
    let dir = temp_dir("sigint");
    // A paced counter that would run for days. `cpu = 4095` does not exist: the node's thread
    // warns when it starts, which tells the test that the run (and its Ctrl-C handler) is up.
    let graph = write(
        &dir,
        "paced.toml",
        r#"
[[node]]
id = "c"
kind = "counter"
params = { count = 1000000000, rate_hz = 500.0 }

[[node]]
id = "s"
kind = "scale"
params = { factor = 2 }
cpu = 4095

[[node]]
id = "out"
kind = "collect"
params = { path = "out.csv" }

[[edge]]
from = "c.out"
to = "s.in"

[[edge]]
from = "s.out"
to = "out.in"
"#,
    );
    let stats_json = dir.join("stats.json");
    let mut child = spawn(
        skinflow()
            .arg("run")
            .arg(&graph)
            .arg("--stats-json")
            .arg(&stats_json)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    let (tx, rx) = mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines() {
            let line = line.unwrap();
            let _ = tx.send(line.clone());
            all += &line;
            all.push('\n');
        }
        all
    });
    let t0 = Instant::now();
    loop {
        match rx.recv_timeout(LIMIT.saturating_sub(t0.elapsed())) {
            Ok(line) if line.contains("cannot pin to CPU 4095") => break,
            Ok(_) => {}
            Err(_) => {
                let _ = child.kill();
                panic!("the run never started (no pinning warning)");
            }
        }
    }
    std::thread::sleep(Duration::from_millis(500)); // let some messages flow
    assert!(status(Command::new("kill").args(["-INT", &child.id().to_string()])).success());
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > LIMIT {
            let _ = child.kill();
            panic!("hang: skinflow did not stop after SIGINT");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let out = child.wait_with_output().unwrap();
    let err = reader.join().unwrap();
    assert_eq!(out.status.code(), Some(0), "stderr: {err}");
    assert!(err.contains("interrupt: stopping sources"), "{err}");
    let stdout = text(&out.stdout);
    assert!(stdout.lines().any(|l| l.starts_with("node ") && l.contains("p99 us")), "no stats table:\n{stdout}");
    for id in ["c", "s", "out"] {
        assert!(stdout.lines().any(|l| l.starts_with(&format!("{id} "))), "{id} missing:\n{stdout}");
    }
    // Every message the counter sent was delivered and flushed, in order, before exit.
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats_json).unwrap()).unwrap();
    let sent = json["nodes"].as_array().unwrap().iter().find(|n| n["id"] == "c").unwrap()["msgs_out"].as_u64().unwrap();
    let got = rows(&dir.join("out.csv"));
    assert!(sent > 0);
    assert_eq!(got, (0..sent).map(|k| (k, 2 * k)).collect::<Vec<_>>());
}

#[test]
fn stats_json_has_per_node_fields() {
    let dir = temp_dir("stats-json");
    let graph = write(
        &dir,
        "g.toml",
        r#"
[graph]
name = "json"
mode = "lockstep"

[[node]]
id = "c"
kind = "counter"
params = { count = 500 }

[[node]]
id = "s"
kind = "scale"
deadline_us = 1000000

[[node]]
id = "out"
kind = "collect"
params = { path = "out.csv" }

[[edge]]
from = "c.out"
to = "s.in"
capacity = 8

[[edge]]
from = "s.out"
to = "out.in"
policy = "drop_oldest"
"#,
    );
    let json_path = dir.join("stats.json");
    let out = run_to_end(skinflow().arg("run").arg(&graph).arg("--stats-json").arg(&json_path));
    assert!(out.status.success(), "stderr: {}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    assert_eq!(v["graph"], "json");
    assert_eq!(v["mode"], "lockstep");
    let nodes = v["nodes"].as_array().unwrap();
    let ids: Vec<&str> = nodes.iter().map(|n| n["id"].as_str().unwrap()).collect();
    assert_eq!(ids, ["c", "s", "out"]);
    for n in nodes {
        for key in [
            "kind",
            "msgs_in",
            "msgs_out",
            "latency_us_p50",
            "latency_us_p99",
            "latency_us_max",
            "max_queue_depth",
            "drops",
            "deadline_misses",
        ] {
            assert!(n.get(key).is_some(), "{key} missing in {n}");
        }
    }
    assert_eq!(nodes[1]["msgs_in"], 500);
    assert_eq!(nodes[1]["msgs_out"], 500);
    assert_eq!(nodes[2]["drops"], 0);
    let edges = v["edges"].as_array().unwrap();
    assert_eq!(edges[1]["policy"], "drop_oldest");
    assert_eq!(edges[0]["capacity"], 8);
    assert_eq!(rows(&dir.join("out.csv")).len(), 500);
}

#[test]
fn a_node_that_fails_to_start_stops_the_run_naming_node_and_cause() {
    let dir = temp_dir("start-failure");
    let missing = dir.join("no-such-dir").join("out.csv");
    let graph = write(
        &dir,
        "g.toml",
        &format!(
            "[[node]]\nid = \"c\"\nkind = \"counter\"\n[[node]]\nid = \"sink\"\nkind = \"collect\"\nparams = {{ path = \"{}\" }}\n[[edge]]\nfrom = \"c.out\"\nto = \"sink.in\"\n",
            missing.display()
        ),
    );
    let out = run_to_end(skinflow().arg("run").arg(&graph));
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(err.contains("node \"sink\" (kind \"collect\") failed to start"), "{err}");
    assert!(err.contains(&missing.display().to_string()), "{err}");
    assert!(!text(&out.stdout).contains("p99 us"), "no statistics: nothing ran");
}

/// `--for` longer than a `Duration` holds is refused naming the flag; one the clock cannot add
/// to now (1e19 s) is no limit: the run goes to the end of its sources, statistics and all
/// (both had panicked, the second with the graph running and its recording unflushed).
#[test]
fn a_for_beyond_the_clock_is_refused_or_no_limit_never_a_panic() {
    let dir = temp_dir("for-huge");
    let out_csv = dir.join("out.csv");
    let graph = write(
        &dir,
        "g.toml",
        &format!(
            "[[node]]\nid = \"c\"\nkind = \"counter\"\nparams = {{ count = 50, rate_hz = 1000.0 }}\n[[node]]\nid = \"sink\"\nkind = \"collect\"\nparams = {{ path = \"{}\" }}\n[[edge]]\nfrom = \"c.out\"\nto = \"sink.in\"\n",
            out_csv.display()
        ),
    );
    let out = run_to_end(skinflow().arg("run").arg(&graph).args(["--for", "1e20"]));
    let err = text(&out.stderr);
    assert!(!out.status.success() && err.contains("--for 100000000000000000000: too long for a duration"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let out = run_to_end(skinflow().arg("run").arg(&graph).args(["--for", "1e19"]));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(rows(&out_csv).len(), 50);
    assert!(text(&out.stdout).contains("p99 us"), "statistics printed");
}

#[test]
fn a_panicking_node_is_named_and_the_run_ends() {
    let dir = temp_dir("panic");
    let graph = write(
        &dir,
        "g.toml",
        r#"
[[node]]
id = "c"
kind = "counter"
params = { count = 1000000000000 }

[[node]]
id = "boom"
kind = "panicker"
params = { at = 3 }

[[node]]
id = "out"
kind = "collect"
params = { path = "out.csv" }

[[edge]]
from = "c.out"
to = "boom.in"

[[edge]]
from = "boom.out"
to = "out.in"
"#,
    );
    let out = run_to_end(skinflow().arg("run").arg(&graph));
    assert_eq!(out.status.code(), Some(1));
    let err = text(&out.stderr);
    assert!(err.contains("node \"boom\": panicked: panicker reached message 3"), "{err}");
    assert_eq!(rows(&dir.join("out.csv")), [(0, 0), (1, 1)], "the sink was flushed");
}

#[test]
fn nodes_lists_the_toy_kinds_with_ports_and_params() {
    let out = run_to_end(skinflow().arg("nodes"));
    assert!(out.status.success());
    let s = text(&out.stdout);
    for kind in ["counter", "scale", "sum", "delay", "panicker", "collect", "null"] {
        assert!(s.lines().any(|l| l.starts_with(&format!("{kind} ("))), "{kind} missing:\n{s}");
    }
    assert!(s.contains("param rate_hz"), "{s}");
    assert!(s.contains("in  a: count"), "{s}");
}

#[test]
fn dot_prints_a_digraph() {
    let dir = temp_dir("dot");
    let graph = write(
        &dir,
        "g.toml",
        "[graph]\nname = \"viz\"\n[[node]]\nid = \"c\"\nkind = \"counter\"\n[[node]]\nid = \"n\"\nkind = \"null\"\n[[edge]]\nfrom = \"c.out\"\nto = \"n.in\"\npolicy = \"drop_oldest\"\ncapacity = 3\n",
    );
    let out = run_to_end(skinflow().arg("dot").arg(&graph));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = text(&out.stdout);
    assert!(s.starts_with("digraph \"viz\" {"), "{s}");
    assert!(s.contains("\"c\" -> \"n\" [label=\"out -> in (3)\", style=dashed];"), "{s}");
    assert!(s.trim_end().ends_with('}'));
}
