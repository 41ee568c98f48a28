//! `skinflow run --watch --control SOCKET`: edits of the graph file swap changed nodes while
//! the graph runs (an invalid edit is rejected and the graph goes on), and the control socket
//! answers stats and tare requests. Nothing is lost across the swap.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::support::{bin, skinflow, stderr, workdir};

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

#[test]
fn watch_swaps_edited_nodes_and_the_control_socket_answers() {
    let d = workdir("live", "watch");
    let g = d.join("g.toml");
    let sock = d.join("ctl.sock");
    std::fs::write(&g, graph("factor = 2", "out.csv")).unwrap();
    let child = Command::new(bin())
        .args(["run", g.to_str().unwrap(), "--watch", "--control", sock.to_str().unwrap()])
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while !sock.exists() {
        assert!(t0.elapsed() < Duration::from_secs(20), "no control socket");
        std::thread::sleep(Duration::from_millis(20));
    }
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
    let rows: Vec<(u64, u64)> = std::fs::read_to_string(d.join("out.csv"))
        .unwrap()
        .lines()
        .map(|l| {
            let (a, b) = l.split_once(',').unwrap();
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect();
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
    let out = Command::new(bin())
        .args(["run", g.to_str().unwrap(), "--control", precious.to_str().unwrap()])
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(&format!("{}: --control: exists and is not a socket (a file)", precious.display())), "{err}");
    assert_eq!(std::fs::read_to_string(&precious).unwrap(), "keep me", "the file is left alone");
    assert!(!d.join("out.csv").exists(), "the graph did not run");
}
