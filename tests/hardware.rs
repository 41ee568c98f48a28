//! Whole-binary tests of the hardware path and of crash safety: a full graph (serial sources ->
//! sync -> pipeline -> logger) against `skinflow emulate` over real pseudo-terminals, and a
//! logging `skinflow run` killed with SIGKILL.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::support::{bin, ok, root, skinflow, stderr};

/// A fresh work directory for one test of this module.
fn workdir(test: &str) -> PathBuf {
    super::support::workdir("hw", test)
}

fn fixture(name: &str) -> String {
    super::support::fixture(name).to_string_lossy().into_owned()
}

fn calib() -> String {
    root().join("graphs/calib/paper.toml").to_string_lossy().into_owned()
}

fn inspect(dir: &Path, file: &str) -> String {
    ok(&skinflow(dir, &["inspect", file]))
}

/// The row count of a stream in `skinflow inspect` output.
fn rows(summary: &str, stream: &str) -> u64 {
    let line =
        summary.lines().find(|l| l.starts_with(stream)).unwrap_or_else(|| panic!("{stream} missing:\n{summary}"));
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn serial_sources_drive_the_pipeline_through_emulated_boards() {
    let d = workdir("emulate");
    let emu_dir = d.join("emu");
    let mut emu = Command::new(bin())
        .args(["emulate", &fixture("tiny-eval.toml"), "--dir", emu_dir.to_str().unwrap()])
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The emulator prints "eit PATH", "pressure PATH", "loadcell PATH" once its ptys exist.
    let mut lines = BufReader::new(emu.stdout.take().unwrap()).lines();
    let mut paths = std::collections::HashMap::new();
    while paths.len() < 3 {
        let l = lines.next().expect("emulator output").unwrap();
        let (dev, p) = l.split_once(' ').unwrap();
        paths.insert(dev.to_owned(), p.to_owned());
    }
    let graph = format!(
        "[[node]]\nid = \"eit\"\nkind = \"serial_eit\"\nparams = {{ port = {:?} }}\n\
         [[node]]\nid = \"pressure\"\nkind = \"serial_pressure\"\nparams = {{ port = {:?} }}\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\n\
         [[node]]\nid = \"seg\"\nkind = \"segmenter\"\n\
         [[node]]\nid = \"split\"\nkind = \"splitter\"\n\
         [[node]]\nid = \"force\"\nkind = \"corrector\"\nparams = {{ calibration = {:?} }}\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"live.h5\", strategies = [\"pneumatic-locaware\"] }}\n\
         [[edge]]\nfrom = \"eit.eit\"\nto = \"sync.eit\"\n\
         [[edge]]\nfrom = \"pressure.pressure\"\nto = \"sync.pressure\"\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n\
         [[edge]]\nfrom = \"recon.image\"\nto = \"seg.image\"\n\
         [[edge]]\nfrom = \"seg.contacts\"\nto = \"split.contacts\"\n\
         [[edge]]\nfrom = \"split.split\"\nto = \"force.split\"\n\
         [[edge]]\nfrom = \"eit.eit\"\nto = \"log.eit\"\ncapacity = 4096\n\
         [[edge]]\nfrom = \"pressure.pressure\"\nto = \"log.pressure\"\ncapacity = 4096\n\
         [[edge]]\nfrom = \"force.forces\"\nto = \"log.forces\"\ncapacity = 4096\n",
        paths["eit"],
        paths["pressure"],
        calib()
    );
    std::fs::write(d.join("g.toml"), graph).unwrap();
    let run = Command::new(bin())
        .args(["run", "g.toml", "--for", "1000", "--stats-json", "stats.json"])
        .current_dir(&d)
        .env("RUST_LOG", "warn")
        .env("XDG_CACHE_HOME", d.join("cache"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The emulator ends with its scene (real rates: about 14 s); then stop the graph.
    let t0 = Instant::now();
    let emu_out = emu.wait_with_output().unwrap();
    assert!(emu_out.status.success(), "{}", stderr(&emu_out));
    std::thread::sleep(Duration::from_millis(300));
    Command::new("kill").args(["-INT", &run.id().to_string()]).status().unwrap();
    let out = run.wait_with_output().unwrap();
    let stderr = stderr(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(t0.elapsed() < Duration::from_secs(120));
    let summary = inspect(&d, "live.h5");
    // Every frame the emulated board sent arrives and goes through every stage.
    let sent: u64 = emu_out
        .stderr
        .split(|&b| b == b'\n')
        .find_map(|l| {
            let l = String::from_utf8_lossy(l);
            l.split("emulating")
                .nth(1)
                .and_then(|r| r.split(':').nth(1))
                .and_then(|r| r.split_whitespace().next())
                .and_then(|n| n.parse().ok())
        })
        .expect("the emulator reports its frame count");
    assert_eq!(rows(&summary, "/eit"), sent, "{summary}");
    assert!(summary.contains("0 frames lost"), "{summary}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let node = |id: &str| {
        stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).unwrap()["msgs_out"].as_u64().unwrap()
    };
    assert_eq!(node("force"), sent);
}

/// The graph of the SIGKILL tests: a fast simulation logged with a 0.2 s flush interval.
fn logging_graph(scene: &str) -> String {
    format!(
        "[[node]]\nid = \"skin\"\nkind = \"sim\"\nparams = {{ scene = {scene:?}, pacing = \"fast\" }}\n\
         [[node]]\nid = \"pace\"\nkind = \"sync\"\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"crash.h5\", flush_interval_s = 0.2 }}\n\
         [[edge]]\nfrom = \"skin.eit\"\nto = \"log.eit\"\ncapacity = 4096\n\
         [[edge]]\nfrom = \"skin.pressure\"\nto = \"log.pressure\"\ncapacity = 4096\n\
         [[edge]]\nfrom = \"skin.truth\"\nto = \"log.truth\"\ncapacity = 4096\n\
         [[edge]]\nfrom = \"skin.eit\"\nto = \"pace.eit\"\n"
    )
}

#[test]
fn a_logging_run_killed_with_sigkill_leaves_a_readable_file() {
    let d = workdir("sigkill");
    let graph = logging_graph(&fixture("tiny-calibration.toml"));
    // The simulator alone is fast; loop it through a replay would be faster still, but the
    // point is a logger in the middle of writing: kill it while the scene is being logged.
    std::fs::write(d.join("g.toml"), graph).unwrap();
    let child = Command::new(bin())
        .args(["run", "g.toml"])
        .current_dir(&d)
        .env("RUST_LOG", "info")
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    // Wait until the logger announces the file, then past a few flush intervals.
    let t0 = Instant::now();
    while !d.join("crash.h5").exists() {
        assert!(t0.elapsed() < Duration::from_secs(60), "the logger never created its file");
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(700));
    Command::new("kill").args(["-KILL", &child.id().to_string()]).status().unwrap();
    let _ = child.wait_with_output();
    let summary = inspect(&d, "crash.h5");
    let p = rows(&summary, "/pressure");
    assert!(p > 0, "rows flushed before the kill survive:\n{summary}");
    assert!(summary.contains("0 frames lost"), "the EIT rows that survived are a gap-free prefix:\n{summary}");
}

/// Killed while the logger creates its file (before the first flush HDF5 has written no valid
/// superblock): the recording's name must never show a file that does not open. Each run is
/// killed the moment a file of it appears (the logger's hidden staging file
/// `.crash.h5.PID.partial`, or `crash.h5`); then either no `crash.h5` exists yet or it opens.
/// (When the logger created the file under its own name, 27 of 40 such kills left an
/// unreadable `crash.h5`: "file signature not found".)
#[test]
fn a_logging_run_killed_while_creating_its_file_leaves_no_unreadable_file() {
    let d = workdir("sigkill-create");
    std::fs::write(d.join("g.toml"), logging_graph(&fixture("tiny-calibration.toml"))).unwrap();
    let mut named = 0;
    for k in 0..8 {
        let _ = std::fs::remove_file(d.join("crash.h5"));
        let mut child = Command::new(bin())
            .args(["run", "g.toml"])
            .current_dir(&d)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let staging = d.join(format!(".crash.h5.{}.partial", child.id()));
        let t0 = Instant::now();
        while !staging.exists() && !d.join("crash.h5").exists() {
            assert!(t0.elapsed() < Duration::from_secs(60), "run {k}: the logger never created its file");
            std::hint::spin_loop();
        }
        child.kill().unwrap();
        child.wait().unwrap();
        if d.join("crash.h5").exists() {
            named += 1;
            inspect(&d, "crash.h5");
        }
        let _ = std::fs::remove_file(staging);
    }
    eprintln!("{named} of 8 killed runs had named their file");
}
