//! `skinflow run --watch --control SOCKET`: edits of the graph file swap changed nodes while
//! the graph runs (an invalid edit is rejected and the graph goes on), and the control socket
//! answers stats and tare requests. Nothing is lost across the swap.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use super::support::{bin, output, read_recording, skinflow, spawn, stderr, wait_for_file, workdir};

fn graph(scale_params: &str, out: &str) -> String {
    format!(
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 1500, rate_hz = 500.0 }}\n\
         [[node]]\nid = \"f\"\nkind = \"scale\"\nparams = {{ {scale_params} }}\n\
         [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = \"{out}\" }}\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"f.in\"\n\
         [[edge]]\nfrom = \"f.out\"\nto = \"out.in\"\n"
    )
}

fn ask(sock: &std::path::Path, req: &str) -> serde_json::Value {
    let mut s = UnixStream::connect(sock).unwrap();
    writeln!(s, "{req}").unwrap();
    let mut line = String::new();
    BufReader::new(s).read_line(&mut line).unwrap();
    serde_json::from_str(&line).unwrap()
}

/// `skinflow run G --watch [--control SOCK]`, once the socket (if any) answers.
fn run_watched(g: &Path, sock: Option<&Path>) -> Child {
    let mut cmd = Command::new(bin());
    cmd.args(["run", g.to_str().unwrap(), "--watch"]);
    if let Some(sock) = sock {
        cmd.args(["--control", sock.to_str().unwrap()]);
    }
    let child = spawn(cmd.env("RUST_LOG", "warn").stdout(Stdio::piped()).stderr(Stdio::piped()));
    let t0 = Instant::now();
    while sock.is_some_and(|s| !s.exists()) {
        assert!(t0.elapsed() < Duration::from_secs(20), "no control socket");
        std::thread::sleep(Duration::from_millis(20));
    }
    child
}

/// The (seq, value) rows the collect sink wrote.
fn rows(path: &Path) -> Vec<(u64, u64)> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .map(|l| {
            let (a, b) = l.split_once(',').unwrap();
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect()
}

#[test]
fn watch_swaps_edited_nodes_and_the_control_socket_answers() {
    let d = workdir("live", "watch");
    let g = d.join("g.toml");
    let sock = d.join("ctl.sock");
    std::fs::write(&g, graph("factor = 2", "out.csv")).unwrap();
    let child = run_watched(&g, Some(&sock));
    let stats = ask(&sock, r#"{"cmd": "stats"}"#);
    assert_eq!(stats["ok"], true, "{stats}");
    assert!(stats["stats"]["nodes"].as_array().unwrap().iter().any(|n| n["id"] == "f"));
    let bad = ask(&sock, r#"{"cmd": "tare", "node": "nope"}"#);
    assert_eq!(bad["ok"], false);
    assert!(bad["error"].as_str().unwrap().contains("nope"), "{bad}");
    // A command the node rejects is answered with the node's error, not ok.
    let rejected = ask(&sock, r#"{"cmd": "control", "node": "f", "command": "bogus"}"#);
    assert_eq!(rejected["ok"], false, "{rejected}");
    let e = rejected["error"].as_str().unwrap();
    assert!(e.contains("\"f\"") && e.contains("bogus") && e.contains("not supported"), "{e}");
    let tare = ask(&sock, r#"{"cmd": "tare", "node": "f"}"#);
    assert_eq!(tare["ok"], false, "scale has no tare: {tare}");
    // A param of the wrong type: the refusal is one line, naming the param.
    let typed = ask(&sock, r#"{"cmd": "swap", "node": "f", "kind": "scale", "params": {"factor": "x"}}"#);
    let e = typed["error"].as_str().unwrap();
    assert!(typed["ok"] == false && e.contains("factor") && !e.contains('\n'), "{typed}");
    // A line that is not UTF-8 is answered, and the connection goes on to the next request.
    {
        let mut s = UnixStream::connect(&sock).unwrap();
        s.write_all(b"\xff\xfe garbage\n{\"cmd\": \"stats\"}\n").unwrap();
        let mut lines = BufReader::new(s).lines();
        let first: serde_json::Value = serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
        assert!(first["ok"] == false && first["error"].as_str().unwrap().starts_with("not UTF-8 text"), "{first}");
        let second: serde_json::Value = serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
        assert_eq!(second["ok"], true, "{second}");
    }
    // `skinflow send`, the scripts' client: one reply line per request, failing on the first
    // that is not ok (the requests after it are not sent).
    let s = sock.to_str().unwrap();
    let sent =
        skinflow(&d, &["send", s, r#"{"cmd":"stats"}"#, r#"{"cmd":"control","node":"f","command":"bogus"}"#, "{}"]);
    assert_eq!(sent.status.code(), Some(1));
    let replies = String::from_utf8_lossy(&sent.stdout).into_owned();
    assert_eq!(replies.lines().count(), 2, "{replies}");
    assert!(replies.lines().next().unwrap().starts_with(r#"{"ok":true,"stats":"#), "{replies}");
    let err = stderr(&sent);
    assert!(err.contains(&format!("{s}: {{\"cmd\":\"control\",\"node\":\"f\",\"command\":\"bogus\"}}: ")), "{err}");
    assert!(err.contains("not supported"), "{err}");
    // Wait until data flows, then an invalid edit (rejected), then a valid one (swapped).
    std::thread::sleep(Duration::from_millis(600));
    std::fs::write(&g, graph("factr = 3", "out.csv")).unwrap();
    std::thread::sleep(Duration::from_millis(600));
    std::fs::write(&g, graph("add = 1000000", "out.csv")).unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = stderr(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("edit rejected") && stderr.contains("factr"), "{stderr}");
    assert!(stderr.contains("swapped f"), "{stderr}");
    let rows = rows(&d.join("out.csv"));
    assert_eq!(rows.len(), 1500, "nothing lost across the swap");
    let switch = rows.iter().position(|&(_, y)| y >= 1_000_000).expect("the edit took effect");
    for (i, &(seq, y)) in rows.iter().enumerate() {
        assert_eq!(seq, i as u64);
        assert_eq!(y, if i < switch { 2 * seq } else { seq + 1_000_000 }, "row {i}");
    }
}

#[test]
fn send_names_a_socket_nobody_serves() {
    let d = workdir("live", "send-nobody");
    let out = skinflow(&d, &["send", "none.sock", r#"{"cmd":"stats"}"#]);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("none.sock: cannot connect (is `skinflow run GRAPH --control none.sock` running?)"), "{err}");
}

#[test]
fn control_refuses_to_replace_a_file_that_is_not_a_socket() {
    let d = workdir("live", "control-file");
    let g = d.join("g.toml");
    std::fs::write(&g, graph("factor = 2", "out.csv")).unwrap();
    let precious = d.join("notes.txt");
    std::fs::write(&precious, "keep me").unwrap();
    let out = output(
        Command::new(bin())
            .args(["run", g.to_str().unwrap(), "--control", precious.to_str().unwrap()])
            .env("RUST_LOG", "warn"),
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(&format!("{}: --control: exists and is not a socket (a file)", precious.display())), "{err}");
    assert_eq!(std::fs::read_to_string(&precious).unwrap(), "keep me", "the file is left alone");
    assert!(!d.join("out.csv").exists(), "the graph did not run");
}

/// An edit is compared with what runs now, not with the last file read: a socket swap, then an
/// edit whose second swap cannot build (applied in part, and said so), then the original file
/// again, which swaps `f` back.
#[test]
fn an_edit_is_compared_with_the_running_graph_and_a_partial_edit_is_reported() {
    let d = workdir("live", "partial");
    let g = d.join("g.toml");
    let sock = d.join("ctl.sock");
    let original = graph("factor = 2", "out.csv").replace("count = 1500", "count = 3000");
    std::fs::write(&g, &original).unwrap();
    let child = run_watched(&g, Some(&sock));
    std::thread::sleep(Duration::from_millis(600));
    let swap = ask(&sock, r#"{"cmd": "swap", "node": "f", "kind": "scale", "params": {"factor": 5}}"#);
    assert_eq!(swap["ok"], true, "{swap}");
    let one = ask(&sock, r#"{"cmd": "stats", "node": "f"}"#);
    assert_eq!(one["node"]["id"], "f", "{one}");
    let none = ask(&sock, r#"{"cmd": "stats", "node": "nope"}"#);
    assert!(none["error"].as_str().unwrap().contains("no node \"nope\""), "{none}");
    std::thread::sleep(Duration::from_millis(600));
    // `f` builds; `out` cannot (its directory does not exist), so the edit stops there.
    std::fs::write(&g, graph("factor = 3", "no-such-dir/out.csv").replace("count = 1500", "count = 3000")).unwrap();
    std::thread::sleep(Duration::from_millis(600));
    std::fs::write(&g, &original).unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = stderr(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("edit partly applied: swapped f; then node \"out\""), "{stderr}");
    assert!(stderr.contains("edit applied: swapped f\n"), "the original file differs from the running f: {stderr}");
    let rows = rows(&d.join("out.csv"));
    assert_eq!(rows.len(), 3000, "nothing lost across the swaps");
    let mut factors: Vec<u64> = Vec::new();
    for &(seq, y) in rows.iter().filter(|r| r.0 > 0) {
        assert_eq!(y % seq, 0, "row {seq}: {y}");
        if factors.last() != Some(&(y / seq)) {
            factors.push(y / seq);
        }
    }
    assert_eq!(factors, [2, 5, 3, 2], "the file's, the socket's, the partial edit's, the file's again");
}

/// A plugin library whose file changes is loaded again and the running nodes of its kinds are
/// swapped to it (a node of it that has ended is left, and does not stop the others); a file
/// that is not a library is refused and the nodes keep running.
#[test]
fn a_rebuilt_plugin_is_reloaded_and_its_nodes_swapped() {
    let d = workdir("live", "plugin-reload");
    let built = super::plugins::plugin("skinflow-plugin-fixture-faulty");
    let lib = d.join("lib.so");
    std::fs::copy(&built, &lib).unwrap();
    let g = d.join("g.toml");
    std::fs::write(
        &g,
        graph("factor = 2", "out.csv")
            .replace("count = 1500", "count = 2000")
            .replace("kind = \"scale\"", "kind = \"fixture-scale\"")
            .replacen("[[node]]", "[[plugin]]\npath = \"lib.so\"\n[[node]]", 1)
            // A source of the same library that has ended by the reload: nothing to swap there,
            // and the library's other nodes are swapped all the same.
            + "[[node]]\nid = \"board\"\nkind = \"fixture-eit\"\nparams = { frames = 3 }\n\
               [[node]]\nid = \"sink\"\nkind = \"null\"\n\
               [[edge]]\nfrom = \"board.eit\"\nto = \"sink.in\"\n",
    )
    .unwrap();
    let child = run_watched(&g, None);
    // Replaced the way cargo does (a new file), then by something that is not a library.
    let replace = |bytes: &[u8]| {
        std::thread::sleep(Duration::from_millis(1000));
        let tmp = d.join("lib.so.new");
        std::fs::write(&tmp, bytes).unwrap();
        std::fs::rename(&tmp, &lib).unwrap();
    };
    replace(&std::fs::read(&built).unwrap());
    replace(b"not a library");
    let out = child.wait_with_output().unwrap();
    let stderr = stderr(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("plugin rebuilt and reloaded: swapped f"), "{stderr}");
    // Located at the library's `[[plugin]]` entry, as `check` and `run` locate it at start.
    let refused = stderr
        .lines()
        .find(|l| l.ends_with("; the library changed but was not reloaded (running nodes keep its previous code)"))
        .unwrap_or_else(|| panic!("no refused reload: {stderr}"));
    let at = refused.strip_prefix(&format!("{}:", g.display())).unwrap_or_else(|| panic!("{refused}"));
    let (line_col, rest) = at.split_once(": ").unwrap();
    assert!(line_col.split(':').all(|n| n.parse::<u32>().is_ok()), "file:line:col: {refused}");
    assert!(rest.starts_with("plugin ") && rest.contains("lib.so"), "{refused}");
    let rows = std::fs::read_to_string(d.join("out.csv")).unwrap();
    assert_eq!(rows.lines().count(), 2000, "nothing lost across the swap");
}

/// `skinflow run G --watch --control SOCK` with `--stats-json stats.json`, once the socket
/// answers.
fn run_watched_with_stats(d: &Path, g: &Path, sock: &Path) -> Child {
    let child = spawn(
        Command::new(bin())
            .args(["run", g.to_str().unwrap(), "--watch", "--control", sock.to_str().unwrap(), "--stats-json"])
            .arg(d.join("stats.json"))
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    wait_for_file(sock, Duration::from_secs(20), "no control socket");
    child
}

/// Waits until node `id` has sent `n` messages (asked through the control socket).
fn wait_for_out(sock: &Path, id: &str, n: u64) {
    let t0 = Instant::now();
    loop {
        let one = ask(sock, &format!(r#"{{"cmd": "stats", "node": "{id}"}}"#));
        if one["node"]["msgs_out"].as_u64().is_some_and(|k| k >= n) {
            return;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "node {id} never sent {n} messages: {one}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `d/in.h5`: the tiny evaluation scene, simulated with seed 3.
fn simulate_input(d: &Path) {
    let scene = super::support::fixture("tiny-eval.toml");
    super::support::ok(&skinflow(d, &["simulate", scene.to_str().unwrap(), "--out", "in.h5", "--seed", "3"]));
}

/// A recording replayed at `speed` into a logger writing `rec.h5`.
fn replay_graph(speed: &str, log_params: &str) -> String {
    format!(
        "[[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = \"in.h5\", speed = {speed} }}\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"rec.h5\"{log_params} }}\n\
         [[edge]]\nfrom = \"replay.eit\"\nto = \"log.eit\"\n\
         [[edge]]\nfrom = \"replay.pressure\"\nto = \"log.pressure\"\n\
         [[edge]]\nfrom = \"replay.truth\"\nto = \"log.truth\"\n"
    )
}

/// The audit's case: a replay sped up mid-run goes on where it was (it used to start again
/// at frame 0, and the recording downstream stepped back in time), and a logger swap onto the
/// file the running logger writes is refused (with `overwrite = true` it used to truncate
/// the session's recording to the rows after the swap).
#[test]
fn a_sped_up_replay_goes_on_and_a_logger_swap_onto_its_own_file_is_refused() {
    let d = workdir("live", "replay-speed");
    simulate_input(&d);
    let g = d.join("g.toml");
    let sock = d.join("ctl.sock");
    std::fs::write(&g, replay_graph("2.0", "")).unwrap();
    let child = run_watched_with_stats(&d, &g, &sock);
    wait_for_out(&sock, "replay", 100);
    // A swap of the logger onto the recording the replay reads is refused as `check` refuses
    // it (the rows compared below show in.h5 intact).
    let reply = ask(
        &sock,
        r#"{"cmd": "swap", "node": "log", "kind": "hdf5_logger", "params": {"path": "in.h5", "overwrite": true}}"#,
    );
    assert_eq!(reply["ok"], false, "{reply}");
    let error = reply["error"].as_str().unwrap();
    assert!(error.contains("the recording replay \"replay\" reads (its `path` ") && error.contains("in.h5"), "{reply}");
    // Nor onto the file this run writes its statistics to (they would replace its rows).
    let reply =
        ask(&sock, r#"{"cmd": "swap", "node": "log", "kind": "hdf5_logger", "params": {"path": "stats.json"}}"#);
    assert_eq!(reply["ok"], false, "{reply}");
    let error = reply["error"].as_str().unwrap();
    assert!(error.contains("--stats-json ") && error.contains("is the file hdf5_logger \"log\" writes"), "{reply}");
    std::fs::write(&g, replay_graph("4.0", "")).unwrap();
    std::thread::sleep(Duration::from_millis(700));
    std::fs::write(&g, replay_graph("4.0", ", overwrite = true, flush_interval_s = 0.5")).unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = stderr(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("edit applied: swapped replay\n"), "{stderr}");
    let refused = format!(
        "edit rejected: node \"log\": swap refused: start failed: {}: the recording a running logger of this run is \
         writing",
        d.join("rec.h5").display()
    );
    assert!(stderr.contains(&refused), "{stderr}");
    // Every row once, in order: the logged streams equal the replayed recording's (times to
    // the nanosecond of the messages' headers).
    let open = |f: &str| read_recording(d.join(f));
    let (src, rec) = (open("in.h5"), open("rec.h5"));
    let ns = |t: &[f64]| t.iter().map(|t| (t * 1e9).round() as u64).collect::<Vec<_>>();
    let (a, b) = (src.eit.as_ref().unwrap(), rec.eit.as_ref().unwrap());
    assert_eq!((&b.seq, ns(&b.t_s)), (&a.seq, ns(&a.t_s)));
    let (a, b) = (src.pressure.as_ref().unwrap(), rec.pressure.as_ref().unwrap());
    assert_eq!((ns(&b.t_s), &b.kpa), (ns(&a.t_s), &a.kpa));
    assert_eq!(ns(&rec.truth.as_ref().unwrap().t_s), ns(&src.truth.as_ref().unwrap().t_s));
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let swaps: Vec<(&str, u64)> = stats["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| (n["id"].as_str().unwrap(), n["swaps"].as_u64().unwrap()))
        .collect();
    assert_eq!(swaps, [("replay", 1), ("log", 0)]);
}

/// `deadline_us` and `restart` edits are applied to the running node; `[graph]` keys and a
/// node's trigger or thread placement need a restart, and the edit says so.
#[test]
fn deadline_and_restart_edits_apply_and_graph_keys_need_a_restart() {
    let d = workdir("live", "policy");
    let g = d.join("g.toml");
    let sock = d.join("ctl.sock");
    let base = graph("factor = 2", "out.csv");
    std::fs::write(&g, &base).unwrap();
    let child = run_watched_with_stats(&d, &g, &sock);
    wait_for_out(&sock, "f", 100);
    std::fs::write(&g, format!("[graph]\nname = \"renamed\"\n{base}")).unwrap();
    std::thread::sleep(Duration::from_millis(600));
    std::fs::write(&g, base.replace("kind = \"scale\"", "kind = \"scale\"\ntrigger = \"periodic\"\nperiod_ms = 5"))
        .unwrap();
    std::thread::sleep(Duration::from_millis(600));
    // A 1 ns budget: every call overruns it from the edit on.
    std::fs::write(&g, base.replace("kind = \"scale\"", "kind = \"scale\"\ndeadline_us = 0.001\nrestart = \"always\""))
        .unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = stderr(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("edit rejected: needs a restart: [graph] name changed"), "{stderr}");
    assert!(stderr.contains("edit rejected: needs a restart: trigger of node \"f\" changed"), "{stderr}");
    assert!(stderr.contains("edit applied: set deadline_us of node \"f\", restart of node \"f\"\n"), "{stderr}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let f = stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == "f").unwrap();
    assert!(f["deadline_misses"].as_u64().unwrap() > 0, "{f}");
    assert_eq!(f["swaps"], 0, "{f}");
    assert_eq!(rows(&d.join("out.csv")).len(), 1500);
}

/// A replay through a reconstructor with `recon_params`, its images to a null sink.
fn recon_graph(recon_params: &str) -> String {
    format!(
        "[[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = \"in.h5\", speed = 2.0 }}\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\nparams = {{ {recon_params} }}\n\
         [[node]]\nid = \"sink\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"replay.eit\"\nto = \"sync.eit\"\n\
         [[edge]]\nfrom = \"replay.pressure\"\nto = \"sync.pressure\"\n\
         [[edge]]\nfrom = \"replay.reference\"\nto = \"recon.reference\"\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n\
         [[edge]]\nfrom = \"recon.image\"\nto = \"sink.in\"\n"
    )
}

/// `check` and `run` refuse a reconstructor on another sensor than its recording's; so do a
/// swap from the control socket and an edit of the graph file (they used to install it, and
/// the images were computed on the wrong sensor). The graph runs on to its end unswapped.
#[test]
fn a_live_swap_or_edit_onto_another_sensor_is_refused() {
    let d = workdir("live", "sensor");
    simulate_input(&d);
    std::fs::write(d.join("small.toml"), "[sensor]\nname = \"small-60mm\"\nwidth_mm = 60.0\nheight_mm = 60.0\n")
        .unwrap();
    let g = d.join("g.toml");
    let sock = d.join("ctl.sock");
    std::fs::write(&g, recon_graph("")).unwrap();
    let child = run_watched_with_stats(&d, &g, &sock);
    wait_for_out(&sock, "recon", 3);
    let mismatch = "small.toml, but its frames come from replay \"replay\", whose recording";
    let small = "node \"recon\": param \"sensor\": reconstructs on sensor \"small-60mm\" (60 x 60 mm, 16 electrodes, \
                 pairwise) of ";
    let reply =
        ask(&sock, r#"{"cmd": "swap", "node": "recon", "kind": "reconstructor", "params": {"sensor": "small.toml"}}"#);
    assert_eq!(reply["ok"], false, "{reply}");
    let error = reply["error"].as_str().unwrap();
    assert!(error.contains(small) && error.contains(mismatch), "{reply}");
    std::fs::write(&g, recon_graph("sensor = \"small.toml\"")).unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    let out = child.wait_with_output().unwrap();
    let stderr = stderr(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains(": edit rejected: ") && stderr.contains(small) && stderr.contains(mismatch), "{stderr}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let recon = stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == "recon").unwrap();
    assert_eq!(recon["swaps"], 0, "{recon}");
}

/// A logger records the graph file it was built from (the root attribute `graph`): the
/// started file's text, and for a logger that an edit brought in, the edited text.
#[test]
fn a_logger_records_the_graph_text_it_was_built_from() {
    let d = workdir("live", "graph-attr");
    simulate_input(&d);
    let g = d.join("g.toml");
    let sock = d.join("ctl.sock");
    let started = replay_graph("2.0", "");
    std::fs::write(&g, &started).unwrap();
    let child = run_watched_with_stats(&d, &g, &sock);
    wait_for_out(&sock, "replay", 20);
    let edited = format!("# moved to rec2.h5\n{}", started.replace("rec.h5", "rec2.h5"));
    std::fs::write(&g, &edited).unwrap();
    let out = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(out.status.success() && err.contains("edit applied: swapped log\n"), "{err}");
    let (first, second) = (read_recording(d.join("rec.h5")), read_recording(d.join("rec2.h5")));
    assert_eq!(first.graph_toml.as_deref(), Some(started.as_str()));
    assert_eq!(second.graph_toml.as_deref(), Some(edited.as_str()));
    // The swap lost no frame: the two files hold the replayed recording's frames between them.
    let frames = |r: &skinflow_record::Recording| r.eit.as_ref().map_or(0, |e| e.seq.len());
    assert_eq!(frames(&first) + frames(&second), frames(&read_recording(d.join("in.h5"))));
}
