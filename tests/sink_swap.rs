//! Hot swaps of the csv-writers plugin sinks (plugins/csv-writers) while a graph runs: a
//! replacement used to truncate the sink's CSV file when it was built, so a swap onto the same
//! file lost every row written before it, and a refused swap left the running sink writing at
//! its old offset past the truncation (a hole of NUL bytes). Now a replacement touches no file
//! until it is installed and takes over the running sink's file: a swap with the same `path`
//! (from the control socket, or a rebuilt library reloaded by `--watch`) goes on appending, and
//! a swap to another `path` (a `--watch` edit) starts that file while the first keeps every row
//! written before the swap. A refused swap cannot be provoked through the binary
//! deterministically (the sinks refuse only a state they cannot read, another build's format);
//! the crate's unit tests cover it.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use super::support::{bin, fixture, ok, read_recording, root, skinflow, spawn, stderr, wait_for_file};

fn workdir(test: &str) -> PathBuf {
    super::support::workdir("sink-swap", test)
}

fn quoted(p: &Path) -> String {
    toml::Value::String(p.to_string_lossy().into_owned()).to_string()
}

/// `d/in.h5`: the tiny evaluation scene, simulated with seed 3 (34 EIT frames over 26.8 s).
fn simulate_input(d: &Path) {
    let scene = fixture("tiny-eval.toml");
    ok(&skinflow(d, &["simulate", scene.to_str().unwrap(), "--out", "in.h5", "--seed", "3"]));
}

/// `in.h5` replayed at `speed` (real time) through the pipeline into corrector `correct`, with
/// the csv-writers library `lib` and `sinks` (id, kind, params): `forces-csv` sinks get
/// `correct.forces`, `pressure-csv` sinks and an `hdf5_logger` get `replay.pressure` too.
fn graph(lib: &str, speed: f64, sinks: &[(&str, &str, &str)]) -> String {
    let mut g = format!(
        "[graph]\nname = \"sink-swap\"\n\
         [[plugin]]\npath = {lib}\n\
         [[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = \"in.h5\", speed = {speed:?} }}\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\n\
         [[node]]\nid = \"segment\"\nkind = \"segmenter\"\n\
         [[node]]\nid = \"split\"\nkind = \"splitter\"\nparams = {{ strategy = \"proportional\" }}\n\
         [[node]]\nid = \"correct\"\nkind = \"corrector\"\n\
         params = {{ strategy = \"pneumatic-locaware\", calibration = {} }}\n",
        quoted(&root().join("graphs/calib/paper.toml"))
    );
    for (id, kind, params) in sinks {
        g += &format!("[[node]]\nid = \"{id}\"\nkind = \"{kind}\"\nparams = {{ {params} }}\n");
    }
    g += "[[edge]]\nfrom = \"replay.eit\"\nto = \"sync.eit\"\n\
          [[edge]]\nfrom = \"replay.pressure\"\nto = \"sync.pressure\"\n\
          [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n\
          [[edge]]\nfrom = \"recon.image\"\nto = \"segment.image\"\n\
          [[edge]]\nfrom = \"segment.contacts\"\nto = \"split.contacts\"\n\
          [[edge]]\nfrom = \"split.split\"\nto = \"correct.split\"\n";
    for (id, kind, _) in sinks {
        let (from, port) = match *kind {
            "forces-csv" => ("correct.forces", "forces"),
            "pressure-csv" => ("replay.pressure", "pressure"),
            _ => {
                g += &format!(
                    "[[edge]]\nfrom = \"correct.forces\"\nto = \"{id}.forces\"\n\
                     [[edge]]\nfrom = \"replay.pressure\"\nto = \"{id}.pressure\"\n"
                );
                continue;
            }
        };
        g += &format!("[[edge]]\nfrom = \"{from}\"\nto = \"{id}.{port}\"\n");
    }
    g
}

/// `skinflow run g.toml --watch --control ctl.sock --stats-json stats.json` in `d`, once the
/// socket answers.
fn run_live(d: &Path) -> Child {
    let child = spawn(
        Command::new(bin())
            .args(["run", "g.toml", "--watch", "--control", "ctl.sock", "--stats-json", "stats.json"])
            .current_dir(d)
            .env("XDG_CACHE_HOME", d.join("cache"))
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    wait_for_file(&d.join("ctl.sock"), Duration::from_secs(60), "no control socket");
    child
}

/// One request on the control socket, its reply.
fn ask(sock: &Path, req: &str) -> serde_json::Value {
    let mut s = UnixStream::connect(sock).unwrap();
    writeln!(s, "{req}").unwrap();
    let mut line = String::new();
    BufReader::new(s).read_line(&mut line).unwrap();
    serde_json::from_str(&line).unwrap()
}

/// Lines in `path` (0 while it does not exist).
fn lines(path: &Path) -> usize {
    std::fs::read_to_string(path).map_or(0, |t| t.lines().count())
}

/// Waits until `path` has at least `n` lines (a guard against a hang, not a timing assertion).
fn wait_lines(path: &Path, n: usize) {
    let t0 = Instant::now();
    while lines(path) < n {
        assert!(t0.elapsed() < Duration::from_secs(120), "{} never had {n} lines", path.display());
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Waits until node `id` counts `n` swaps (asked through the control socket).
fn wait_swaps(sock: &Path, id: &str, n: u64) {
    let t0 = Instant::now();
    loop {
        let one = ask(sock, &format!(r#"{{"cmd": "stats", "node": "{id}"}}"#));
        if one["node"]["swaps"].as_u64().is_some_and(|k| k >= n) {
            return;
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "node {id} was never swapped {n} times: {one}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The run to its end: successful, its stderr.
fn finished(child: Child) -> String {
    let out: Output = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    err
}

/// A counter of node `id` in `d/stats.json`.
fn count(d: &Path, id: &str, what: &str) -> u64 {
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let node = report["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).unwrap_or_else(|| panic!("{id}"));
    node[what].as_u64().unwrap_or_else(|| panic!("{id}.{what}: {node}"))
}

/// A CSV file written by a csv-writers sink: its header line (asserted once, first) and data
/// lines. No NUL byte anywhere (a write past a truncation leaves a hole of them).
fn csv(path: &Path, header: &str) -> Vec<String> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(!bytes.contains(&0), "{}: NUL bytes (a hole)", path.display());
    let text = String::from_utf8(bytes).unwrap();
    let mut l = text.lines();
    assert_eq!(l.next(), Some(header), "{}: the header first", path.display());
    let rows: Vec<String> = l.map(str::to_owned).collect();
    assert!(!rows.iter().any(|r| r == header), "{}: the header once", path.display());
    rows
}

const FORCES_HEADER: &str = "seq,t_s,contact,x_mm,y_mm,area_mm2,dp_kpa,force_n";

/// Three `forces-csv` sinks on the corrector's forces, the replay paced at 4x: `twin` never
/// swapped; `same` swapped from the control socket to the same params once it has rows (the
/// reviewer's case: the file went from 18 rows to 7); `moved` swapped by an edit of the graph
/// file from `a.csv` to `b.csv` once `a.csv` has rows. `same.csv` ends up byte for byte
/// `twin.csv`, and `a.csv` then `b.csv` hold `twin.csv`'s rows, each once, in order.
#[test]
fn a_forces_csv_swapped_mid_run_keeps_every_row_once_on_its_file_or_across_two() {
    let d = workdir("forces");
    simulate_input(&d);
    let lib = quoted(&super::plugins::plugin("skinflow-plugin-csv-writers"));
    let sinks = |moved: &str| {
        graph(
            &lib,
            4.0,
            &[
                ("twin", "forces-csv", "path = \"twin.csv\""),
                ("same", "forces-csv", "path = \"same.csv\""),
                ("moved", "forces-csv", &format!("path = \"{moved}\"")),
            ],
        )
    };
    std::fs::write(d.join("g.toml"), sinks("a.csv")).unwrap();
    let sock = d.join("ctl.sock");
    let child = run_live(&d);

    wait_lines(&d.join("same.csv"), 6);
    let reply = ask(&sock, r#"{"cmd": "swap", "node": "same", "kind": "forces-csv", "params": {"path": "same.csv"}}"#);
    assert_eq!(reply["ok"], true, "{reply}");
    let at_swap = lines(&d.join("same.csv"));

    wait_lines(&d.join("a.csv"), 6);
    std::fs::write(d.join("g.toml"), sinks("b.csv")).unwrap();
    wait_swaps(&sock, "moved", 1);

    let err = finished(child);
    assert!(err.contains("edit applied: swapped moved\n"), "{err}");
    for id in ["twin", "same", "moved"] {
        assert_eq!(count(&d, id, "msgs_in"), count(&d, "correct", "msgs_out"), "{id}: every frame");
        assert_eq!(count(&d, id, "errors"), 0, "{id}");
        assert_eq!(count(&d, id, "swaps"), u64::from(id != "twin"), "{id}");
    }
    let twin = csv(&d.join("twin.csv"), FORCES_HEADER);
    assert!(twin.len() > 40, "rows: {}", twin.len());
    let same = csv(&d.join("same.csv"), FORCES_HEADER);
    assert!(at_swap >= 6 && same.len() + 1 > at_swap, "rows before ({at_swap} lines) and after the swap");
    assert_eq!(
        std::fs::read(d.join("same.csv")).unwrap(),
        std::fs::read(d.join("twin.csv")).unwrap(),
        "the swapped sink's file is the unswapped one's: every row once"
    );
    let (a, b) = (csv(&d.join("a.csv"), FORCES_HEADER), csv(&d.join("b.csv"), FORCES_HEADER));
    assert!(a.len() >= 5 && !b.is_empty(), "rows before ({}) and after ({}) the swap", a.len(), b.len());
    assert_eq!([a, b].concat(), twin, "a.csv then b.csv: every row once, in order");
}

/// A rebuilt csv-writers library (`lib.so` replaced, as cargo does) reloaded by `--watch` swaps
/// its `forces-csv` and `pressure-csv` sinks (same params) while they write: each file holds
/// every row once, the pressure file every sample of the recording replayed, the forces file
/// the forces an `hdf5_logger` beside it logged.
#[test]
fn a_rebuilt_csv_writers_library_swaps_its_sinks_without_losing_a_row() {
    let d = workdir("reload");
    simulate_input(&d);
    let built = super::plugins::plugin("skinflow-plugin-csv-writers");
    let lib = d.join("lib.so");
    std::fs::copy(&built, &lib).unwrap();
    let g = graph(
        "\"lib.so\"",
        4.0,
        &[
            ("forces", "forces-csv", "path = \"forces.csv\""),
            ("pressure", "pressure-csv", "path = \"pressure.csv\""),
            ("log", "hdf5_logger", "path = \"log.h5\", strategies = [\"pneumatic-locaware\"]"),
        ],
    );
    std::fs::write(d.join("g.toml"), g).unwrap();
    let sock = d.join("ctl.sock");
    let child = run_live(&d);

    wait_lines(&d.join("pressure.csv"), 50);
    wait_lines(&d.join("forces.csv"), 6);
    let tmp = d.join("lib.so.new");
    std::fs::copy(&built, &tmp).unwrap();
    std::fs::rename(&tmp, &lib).unwrap();
    wait_swaps(&sock, "forces", 1);
    wait_swaps(&sock, "pressure", 1);
    let at_swap = lines(&d.join("pressure.csv"));

    let err = finished(child);
    assert!(err.contains("plugin rebuilt and reloaded: swapped forces, pressure"), "{err}");
    assert_eq!((count(&d, "forces", "swaps"), count(&d, "pressure", "swaps")), (1, 1));

    // Pressure: every sample of the recording, once, in order.
    let pressure = csv(&d.join("pressure.csv"), "t_s,kpa");
    let src = read_recording(d.join("in.h5"));
    let samples = src.pressure.as_ref().expect("pressure recorded");
    assert!(at_swap < samples.len(), "rows after the swap ({at_swap} lines at the swap)");
    assert_eq!(pressure.len(), samples.len());
    assert_eq!(count(&d, "pressure", "msgs_in"), samples.len() as u64);
    for (row, (t, kpa)) in pressure.iter().zip(samples.t_s.iter().zip(&samples.kpa)) {
        let (a, b) = row.split_once(',').unwrap();
        let (a, b): (f64, f64) = (a.parse().unwrap(), b.parse().unwrap());
        assert!((a - t).abs() < 1e-9 && b == *kpa, "{row} against ({t}, {kpa})");
    }

    // Forces: each frame's contacts as the logger logged them, every frame once.
    let frames = count(&d, "correct", "msgs_out");
    assert_eq!(count(&d, "forces", "msgs_in"), frames);
    let rec = read_recording(d.join("log.h5"));
    let fs = rec.derived.forces.iter().find(|f| f.name == "pneumatic-locaware").expect("forces logged");
    assert_eq!(fs.t_s.len() as u64, frames);
    let rows: Vec<Vec<f64>> = csv(&d.join("forces.csv"), FORCES_HEADER)
        .iter()
        .map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap()).collect())
        .collect();
    super::plugins::assert_forces_csv_is_the_log(&rows, fs);
}
