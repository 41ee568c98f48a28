//! Whole-binary tests of the hardware path and of crash safety: a full graph (serial sources ->
//! sync -> pipeline -> logger) against `skinflow emulate` over real pseudo-terminals, boards
//! that send the wrong thing, nothing, or restart (ptys the test writes, and the emulator's
//! `restart` fault), and a logging `skinflow run` killed with SIGKILL.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::support::{bin, ok, read_recording, root, skinflow, spawn, status, stderr, text, wait_for_file};

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
    // One CRC failure: the frame is lost, and counted as the EIT node's discarded message.
    let mut emu = spawn(
        Command::new(bin())
            .args(["emulate", &fixture("tiny-eval.toml"), "--dir", emu_dir.to_str().unwrap(), "--fault", "eit:5:crc"])
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    // The emulator prints "eit PATH", "pressure PATH", "loadcell PATH" once its ptys exist.
    let mut lines = BufReader::new(emu.stdout.take().unwrap()).lines();
    let mut paths = std::collections::HashMap::new();
    while paths.len() < 3 {
        let l = lines.next().expect("emulator output").unwrap();
        let (dev, p) = l.split_once(' ').unwrap();
        paths.insert(dev.to_owned(), p.to_owned());
    }
    // The emulator sends from its start, before the graph opens the ports: keep that backlog
    // (the default clears it), so every frame sent can be accounted for.
    let graph = format!(
        "[[node]]\nid = \"eit\"\nkind = \"serial_eit\"\nparams = {{ port = {:?}, clear_input_at_open = false }}\n\
         [[node]]\nid = \"pressure\"\nkind = \"serial_pressure\"\nparams = {{ port = {:?}, clear_input_at_open = false }}\n\
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
    let run = spawn(
        Command::new(bin())
            .args(["run", "g.toml", "--for", "1000", "--stats-json", "stats.json"])
            .current_dir(&d)
            .env("RUST_LOG", "warn")
            .env("XDG_CACHE_HOME", d.join("cache"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    // The emulator ends with its scene (real rates: about 14 s); then stop the graph.
    let t0 = Instant::now();
    let emu_out = emu.wait_with_output().unwrap();
    assert!(emu_out.status.success(), "{}", stderr(&emu_out));
    std::thread::sleep(Duration::from_millis(300));
    status(Command::new("kill").args(["-INT", &run.id().to_string()]));
    let out = run.wait_with_output().unwrap();
    let stderr = stderr(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(t0.elapsed() < Duration::from_secs(120));
    let summary = inspect(&d, "live.h5");
    // Every frame the emulated board sent arrives and goes through every stage, but the one
    // whose CRC failed: it shows as a gap of one frame, and as the EIT node's drop.
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
    assert_eq!(rows(&summary, "/eit"), sent - 1, "{summary}");
    assert!(summary.contains("eit gaps: 1 gaps, 1 frames lost"), "{summary}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let node = |id: &str, field: &str| {
        stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).unwrap()[field].as_u64().unwrap()
    };
    assert_eq!(node("force", "msgs_out"), sent - 1);
    assert_eq!((node("eit", "discarded"), node("eit", "drops")), (1, 1));
    assert!(logged(&stderr, "eit").iter().any(|l| l.contains("crc_errors=1")), "{stderr}");
}

/// The log lines of node `id` in a run's stderr.
fn logged<'a>(stderr: &'a str, id: &str) -> Vec<&'a str> {
    stderr.lines().filter(|l| l.contains(&format!("node=\"{id}\""))).collect()
}

/// A pseudo-terminal the test writes as a board would: the master, and the slave, kept open
/// so bytes written before the graph opens the port are buffered (raw, so binary passes
/// untouched), published at `link`.
struct Board {
    master: std::fs::File,
    _slave: std::fs::File,
}

impl Board {
    fn new(link: &Path) -> Board {
        use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
        let pty = nix::pty::openpty(None, None).expect("openpty");
        for fd in [&pty.master, &pty.slave] {
            let mut t = tcgetattr(fd).unwrap();
            cfmakeraw(&mut t);
            tcsetattr(fd, SetArg::TCSANOW, &t).unwrap();
        }
        let name = nix::unistd::ttyname(&pty.slave).unwrap();
        std::os::unix::fs::symlink(name, link).unwrap();
        Board { master: std::fs::File::from(pty.master), _slave: std::fs::File::from(pty.slave) }
    }

    fn send(&mut self, bytes: &[u8]) {
        use std::io::Write;
        self.master.write_all(bytes).unwrap();
    }
}

/// Three boards on ptys, their bytes written before the run (kept at open): pressure lines on
/// an EIT port (a wrong device: bytes, no frame), a silent one, and an EIT board whose frame
/// 104 fails its CRC and which then restarts (counter and clock back to 0). The run warns about
/// each, `/eit/seq` goes on at +1 across the restart (no gap of 2^32), and the one lost frame is
/// the EIT node's drop.
#[test]
fn a_wrong_device_a_silent_board_and_a_board_restart_are_reported() {
    use skinflow_serial::encode::{encode_eit_frame, encode_pressure_line};
    let d = workdir("boards");
    let mut wrong = Board::new(&d.join("wrong"));
    let _mute = Board::new(&d.join("mute"));
    let mut eit = Board::new(&d.join("eit"));
    let mut lines = Vec::new();
    for k in 0..40 {
        encode_pressure_line(&mut lines, 50 * k, 1.5);
    }
    wrong.send(&lines);
    let volts = vec![0.01; 120];
    let mut frames = Vec::new();
    for (i, counter) in (100..110).chain(0..10).enumerate() {
        let time_us = if counter >= 100 { 5_000_000 + 769_000 * i as u32 } else { 769_000 * counter };
        encode_eit_frame(&mut frames, counter, time_us, &volts);
        if counter == 104 {
            // Its CRC's last byte: the frame fails its check.
            let last = frames.len() - 1;
            frames[last] ^= 0x01;
        }
    }
    eit.send(&frames);
    let keep = "clear_input_at_open = false";
    let graph = format!(
        "[[node]]\nid = \"wrong\"\nkind = \"serial_eit\"\nparams = {{ port = \"wrong\", {keep} }}\n\
         [[node]]\nid = \"mute\"\nkind = \"serial_eit\"\nparams = {{ port = \"mute\", {keep} }}\n\
         [[node]]\nid = \"eit\"\nkind = \"serial_eit\"\nparams = {{ port = \"eit\", {keep} }}\n\
         [[node]]\nid = \"sink\"\nkind = \"null\"\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"boards.h5\" }}\n\
         [[edge]]\nfrom = \"wrong.eit\"\nto = \"sink.in\"\n\
         [[edge]]\nfrom = \"mute.eit\"\nto = \"sink.in\"\n\
         [[edge]]\nfrom = \"eit.eit\"\nto = \"log.eit\"\ncapacity = 64\n"
    );
    std::fs::write(d.join("g.toml"), graph).unwrap();
    let out = skinflow(&d, &["run", "g.toml", "--for", "3", "--stats-json", "stats.json"]);
    ok(&out);
    let err = stderr(&out);
    let said = |id: &str, what: &str| logged(&err, id).iter().any(|l| l.contains(what));
    assert!(said("wrong", "bytes and no valid EIT frame"), "{err}");
    assert!(said("wrong", "wrong device, baud rate or protocol?"), "{err}");
    assert!(said("mute", "no byte received in"), "{err}");
    assert!(said("eit", "the device restarted"), "{err}");
    assert!(said("eit", "crc_errors=1 lost_frames=1 counter_resets=1"), "{err}");

    let summary = inspect(&d, "boards.h5");
    assert_eq!(rows(&summary, "/eit"), 19, "{summary}");
    assert!(summary.contains("eit gaps: 1 gaps, 1 frames lost, largest 1\n"), "{summary}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let node = |id: &str, field: &str| {
        stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).unwrap()[field].as_u64().unwrap()
    };
    assert_eq!((node("eit", "msgs_out"), node("eit", "discarded")), (19, 1));
    assert_eq!((node("wrong", "msgs_out"), node("mute", "msgs_out")), (0, 0));
    // The link counters are in the statistics too (JSON and table), not only in the log.
    let counter = |id: &str, name: &str| {
        let n = stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).unwrap();
        n["counters"][name].as_u64().unwrap_or_else(|| panic!("{id}: no counter {name}: {n}"))
    };
    let eit_counters =
        ["crc_errors", "lost_frames", "counter_resets", "disconnects", "lost_at_restarts"].map(|c| counter("eit", c));
    assert_eq!(eit_counters, [1, 1, 1, 0, 0]);
    assert_eq!(counter("wrong", "discarded_bytes"), lines.len() as u64);
    let table = text(&out.stdout);
    assert!(
        table.contains(
            "  eit (serial_eit): counter_resets 1, crc_errors 1, discarded_bytes 494, lost_frames 1, resyncs 1"
        ),
        "{table}"
    );
}

/// A board at 10 frames/s pressed once, for [`an_emulated_board_restart_is_reported_and_its_hidden_frames_counted`]:
/// 5 s of rest give the graph time to open the ports before the restarts.
const RESTART_SCENE: &str = "[scene]\nname = \"restart\"\nprofile = \"paper\"\n[rates]\neit_fps = 10.0\n\
    [[step]]\nrest_s = 5.0\n\
    [[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\nforces_n = [4.0]\nhold_frames = 5\nrest_s = 1.0\n";

/// The number before `what` in the emulator's "emulating SCENE: N EIT frames, P pressure
/// samples, ..." line.
fn emulated(stderr: &str, what: &str) -> usize {
    let line = stderr.lines().find(|l| l.starts_with("emulating")).unwrap_or_else(|| panic!("no counts:\n{stderr}"));
    let before = line.split(what).next().filter(|b| b.len() < line.len()).unwrap_or_else(|| panic!("{line}"));
    before.split_whitespace().last().and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("{line}"))
}

/// `skinflow emulate --fault eit:50:restart=0.3 --fault pressure:90:restart=0.3`, in real time:
/// each board goes silent for 0.3 s, making none of the records due meanwhile (3 EIT frames, 6
/// pressure samples, counted as `records_unmeasured`), then sends on from counter 0 (EIT) and
/// with its clock from the reset (both), as firmware after a reset, on the same port. A graph
/// of the two serial sources and a logger reads them. The EIT source reports the restart
/// (`counter_resets`), numbers the frames after it on from `/eit/seq` by the frames the outage
/// hid (estimated from the host-time gap: `round(gap / period) - 1`, here at least 3 as the
/// gap spans the 3 frames not made; exactly 3, the feed's frame index going on, when the
/// stamps are on time) plus one, and counts those as `lost_at_restarts` and as its
/// discarded messages: the recording's seq gap is exactly what was counted. Every frame sent is
/// recorded, the new run's to the end. The pressure source reports its restart too; the new
/// run's first line, held because its time went back, is counted as lost. Waits are for conditions, bounded; deterministic (fixed seed,
/// no assertion on speed).
#[test]
fn an_emulated_board_restart_is_reported_and_its_hidden_frames_counted() {
    const EIT_AT: usize = 50;
    const PRESSURE_AT: usize = 90;
    const PERIOD_S: f64 = 0.1;
    let d = workdir("restart");
    std::fs::write(d.join("scene.toml"), RESTART_SCENE).unwrap();
    let mut emu = spawn(
        Command::new(bin())
            .args(["emulate", "scene.toml", "--seed", "3", "--dir", "emu", "--devices", "eit,pressure"])
            .args([
                "--fault",
                &format!("eit:{EIT_AT}:restart=0.3"),
                "--fault",
                &format!("pressure:{PRESSURE_AT}:restart=0.3"),
            ])
            .current_dir(&d)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    let mut lines = BufReader::new(emu.stdout.take().unwrap()).lines();
    let mut paths = std::collections::HashMap::new();
    while paths.len() < 2 {
        let l = lines.next().expect("emulator output").unwrap();
        let (dev, p) = l.split_once(' ').unwrap();
        paths.insert(dev.to_owned(), p.to_owned());
    }
    // The emulator sends from its start: keep what it sent before the graph opened the ports.
    let keep = "clear_input_at_open = false";
    let graph = format!(
        "[[node]]\nid = \"eit\"\nkind = \"serial_eit\"\nparams = {{ port = {:?}, frame_period_s = {PERIOD_S}, {keep} }}\n\
         [[node]]\nid = \"pressure\"\nkind = \"serial_pressure\"\nparams = {{ port = {:?}, {keep} }}\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"restart.h5\" }}\n\
         [[edge]]\nfrom = \"eit.eit\"\nto = \"log.eit\"\ncapacity = 4096\n\
         [[edge]]\nfrom = \"pressure.pressure\"\nto = \"log.pressure\"\ncapacity = 4096\n",
        paths["eit"], paths["pressure"]
    );
    std::fs::write(d.join("g.toml"), graph).unwrap();
    let run = spawn(
        Command::new(bin())
            .args(["run", "g.toml", "--for", "1000", "--stats-json", "stats.json", "--control", "ctl.sock"])
            .current_dir(&d)
            .env("RUST_LOG", "warn")
            .env("XDG_CACHE_HOME", d.join("cache"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    // The emulator ends once its scene is sent and read (real rates: about 7 s).
    let emu_out = emu.wait_with_output().unwrap();
    let emu_err = stderr(&emu_out);
    assert!(emu_out.status.success(), "{emu_err}");
    let (fed_frames, fed_samples) = (emulated(&emu_err, "EIT frames"), emulated(&emu_err, "pressure samples"));
    assert!(fed_frames > EIT_AT + 5 && fed_samples > PRESSURE_AT + 10, "{emu_err}");
    // What each board sent: its feed less the records due while it booted (0.3 s: 3 frames of
    // 0.1 s, 6 samples of 50 ms).
    let mut unmeasured = Vec::new();
    for (device, booting) in [("eit", 3), ("pressure", 6)] {
        let line = emu_err.lines().find(|l| l.starts_with(&format!("{device}: DeviceStats"))).expect("device stats");
        assert!(line.contains("restarts: 1,") && line.contains(&format!("records_unmeasured: {booting},")), "{line}");
        unmeasured.push(booting);
    }
    let (frames, samples) = (fed_frames - unmeasured[0], fed_samples - unmeasured[1]);
    // Wait until the sources have put out every record they will (the pressure board's first
    // line after its restart is lost), then stop the graph.
    let out_of = |stats: &serde_json::Value, id: &str| {
        stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).map_or(0, |n| n["msgs_out"].as_u64().unwrap())
    };
    let t0 = Instant::now();
    loop {
        let reply = skinflow(&d, &["send", "ctl.sock", r#"{"cmd":"stats"}"#]);
        let reply: serde_json::Value = serde_json::from_str(ok(&reply).trim()).unwrap();
        let (eit, pressure) = (out_of(&reply["stats"], "eit"), out_of(&reply["stats"], "pressure"));
        if eit == frames as u64 && pressure == samples as u64 - 1 {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "{eit} of {frames} frames, {pressure} of {samples} lines");
        std::thread::sleep(Duration::from_millis(100));
    }
    status(Command::new("kill").args(["-INT", &run.id().to_string()]));
    let out = run.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");

    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let node = |id: &str| stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).unwrap().clone();
    let counter = |id: &str, name: &str| {
        node(id)["counters"][name].as_u64().unwrap_or_else(|| panic!("{id}: no counter {name}: {}", node(id)))
    };
    // The EIT source: one restart, no frame lost on the wire, the frames the outage held counted.
    let hidden = counter("eit", "lost_at_restarts");
    assert!(hidden >= 3, "the 3 frames not made during the 0.3 s boot are hidden, counted {hidden}");
    // The port stays through a restart: never reopened (the emulator's end closes it, a
    // disconnect after the last frame, so `disconnects` is not 0).
    assert_eq!(
        ["counter_resets", "lost_frames", "crc_errors", "torn_frames", "reconnects"].map(|c| counter("eit", c)),
        [1, 0, 0, 0, 0]
    );
    assert_eq!(
        (node("eit")["msgs_out"].as_u64(), node("eit")["discarded"].as_u64()),
        (Some(frames as u64), Some(hidden))
    );
    // The pressure source: one restart, the held first line of the new run lost and counted.
    assert_eq!(["counter_resets", "lost_frames", "bad_lines"].map(|c| counter("pressure", c)), [1, 1, 1]);
    assert_eq!(node("pressure")["discarded"].as_u64(), Some(1));
    let said = |id: &str, what: &str| logged(&err, id).iter().any(|l| l.contains(what));
    assert!(said("eit", "the device restarted") && said("pressure", "the device restarted"), "{err}");
    assert!(said("eit", &format!("/eit/seq jumps by {}", hidden + 1)), "{err}");

    // The recording: every frame, seq on by `hidden + 1` at the restart and then by 1 to the
    // end, the jump being the host-time gap in periods (the stamps' half windows are equal).
    let rec = read_recording(d.join("restart.h5"));
    let eit = rec.eit.expect("/eit");
    assert_eq!(eit.len(), frames);
    let want: Vec<u64> = (0..EIT_AT as u64).chain((EIT_AT as u64 + hidden..).take(frames - EIT_AT)).collect();
    assert_eq!(eit.seq, want);
    let gap_periods = (eit.t_s[EIT_AT] - eit.t_s[EIT_AT - 1]) / PERIOD_S;
    eprintln!("restart after a 0.3 s silence: a gap of {gap_periods:.2} periods, /eit/seq + {}", hidden + 1);
    assert_eq!(gap_periods.round() as u64 - 1, hidden, "gap of {gap_periods:.2} periods");
    assert_eq!(rec.pressure.expect("/pressure").len(), samples - 1);
    let summary = inspect(&d, "restart.h5");
    assert!(summary.contains(&format!("eit gaps: 1 gaps, {hidden} frames lost, largest {hidden}\n")), "{summary}");
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

/// Killed between flushes or inside one, a logging run leaves a file that opens with the rows
/// flushed before the kill, the EIT rows a gap-free prefix. The logger stores uncompressed by
/// default, so a flush rewrites the last chunk of each column in place: with deflate (which
/// moves a growing chunk to new file space at every flush) 6 and 13 of 60 kills in two runs
/// left a column unreadable, uncompressed none of 100 and 150
/// (`scripts/research/kill-stress/kill-stress.sh`; README, "Recording"). So every one of three kills, each at another moment, must leave a readable file.
#[test]
fn a_logging_run_killed_with_sigkill_leaves_a_readable_file() {
    let d = workdir("sigkill");
    let graph = logging_graph(&fixture("tiny-calibration.toml"));
    // The simulator alone is fast; loop it through a replay would be faster still, but the
    // point is a logger in the middle of writing: kill it while the scene is being logged.
    std::fs::write(d.join("g.toml"), graph).unwrap();
    for (attempt, wait_ms) in [700, 530, 910].into_iter().enumerate() {
        let _ = std::fs::remove_file(d.join("crash.h5"));
        let child = spawn(
            Command::new(bin())
                .args(["run", "g.toml"])
                .current_dir(&d)
                .env("RUST_LOG", "info")
                .stderr(Stdio::piped())
                .stdout(Stdio::null()),
        );
        // Wait until the logger announces the file, then past a few flush intervals.
        wait_for_file(&d.join("crash.h5"), Duration::from_secs(60), "the logger never created its file");
        std::thread::sleep(Duration::from_millis(wait_ms));
        status(Command::new("kill").args(["-KILL", &child.id().to_string()]));
        let _ = child.wait_with_output();
        let out = skinflow(&d, &["inspect", "crash.h5"]);
        assert!(out.status.success(), "attempt {attempt}: the killed run's file is refused: {}", stderr(&out));
        let summary = String::from_utf8_lossy(&out.stdout).into_owned();
        let p = rows(&summary, "/pressure");
        assert!(p > 0, "attempt {attempt}: rows flushed before the kill survive:\n{summary}");
        assert!(
            summary.contains("0 frames lost"),
            "attempt {attempt}: the EIT rows that survived are a gap-free prefix:\n{summary}"
        );
    }
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
        let mut child = spawn(
            Command::new(bin()).args(["run", "g.toml"]).current_dir(&d).stdout(Stdio::null()).stderr(Stdio::null()),
        );
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

/// `simulate` interrupted with Ctrl-C (SIGINT) mid-scene fails saying nothing was written, and
/// leaves no file at all: not the recording, not its hidden `.NAME.PID.partial` (which a big
/// scene grew to hundreds of MB). A scene that cannot fit in the free disk space is refused
/// before anything is simulated.
#[test]
fn an_interrupted_simulate_leaves_no_file() {
    let d = workdir("simulate-sigint");
    // Long enough that the interrupt lands mid-scene on any machine (about 130,000 frames).
    std::fs::write(
        d.join("long.toml"),
        "[scene]\nname = \"long\"\nprofile = \"paper\"\n\n[[step]]\nrest_s = 100000.0\n",
    )
    .unwrap();
    let child = spawn(
        Command::new(bin())
            .args(["simulate", "long.toml", "--out", "long.h5"])
            .current_dir(&d)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    // Interrupt once the recording is being written.
    let t0 = Instant::now();
    let writing =
        || std::fs::read_dir(&d).unwrap().any(|e| e.unwrap().file_name().to_string_lossy().ends_with(".partial"));
    while !writing() {
        assert!(t0.elapsed() < Duration::from_secs(60), "simulate never started writing");
        std::thread::sleep(Duration::from_millis(20));
    }
    status(Command::new("kill").args(["-INT", &child.id().to_string()]));
    let out = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("interrupted (--out long.h5: nothing written)"), "{err}");
    let left: Vec<String> =
        std::fs::read_dir(&d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, ["long.toml"]);

    // The longest scene at the highest rates: 2.6 TB, more than a test machine's disk holds.
    std::fs::write(
        d.join("huge.toml"),
        "[scene]\nname = \"huge\"\nprofile = \"paper\"\n\n[rates]\neit_fps = 1000.0\npressure_hz = 100000.0\n\n\
         [[step]]\nrest_s = 999000.0\n",
    )
    .unwrap();
    let out = skinflow(&d, &["simulate", "huge.toml", "--out", "huge.h5"]);
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("--out huge.h5: the scene's recording needs at least ") && err.contains("GB free"), "{err}");
    assert!(!d.join("huge.h5").exists());
}

/// A board's frame width (`serial_eit`'s `measurements`) is held to the sensor of the nodes
/// its frames reach: `check` refuses a 16-value board feeding a logger and a reconstructor of
/// the 120-value default sensor, at their lines (a run used to die at the first frame).
#[test]
fn check_holds_a_boards_frame_width_to_the_sensor_downstream() {
    let d = workdir("board-width");
    let graph = |measurements: u32| {
        format!(
            "[[node]]\nid = \"eit\"\nkind = \"serial_eit\"\nparams = {{ port = \"/dev/ttyUSB9\", measurements = {measurements} }}\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"rec.h5\" }}\n\
             [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\n\
             [[node]]\nid = \"sink\"\nkind = \"null\"\n\
             [[node]]\nid = \"pressure\"\nkind = \"serial_pressure\"\nparams = {{ port = \"/dev/ttyUSB8\" }}\n\
             [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
             [[edge]]\nfrom = \"eit.eit\"\nto = \"log.eit\"\n\
             [[edge]]\nfrom = \"eit.eit\"\nto = \"sync.eit\"\n\
             [[edge]]\nfrom = \"pressure.pressure\"\nto = \"sync.pressure\"\n\
             [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n\
             [[edge]]\nfrom = \"recon.image\"\nto = \"sink.in\"\n"
        )
    };
    std::fs::write(d.join("narrow.toml"), graph(16)).unwrap();
    std::fs::write(d.join("paper.toml"), graph(120)).unwrap();
    ok(&skinflow(&d, &["check", "paper.toml"]));
    let out = skinflow(&d, &["check", "narrow.toml"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    for (line, node) in [(5, "log"), (9, "recon")] {
        let at = format!("narrow.toml:{line}:1: node \"{node}\": ");
        let problem = "whose frames are 120 values wide, but its frames come from serial_eit \"eit\", whose \
                       `measurements` = 16: every frame would be refused when the run gets it; set the board's \
                       `measurements` to 120";
        assert!(err.lines().any(|l| l.contains(&at) && l.contains(problem)), "{node}:\n{err}");
    }
}

/// A load-cell rig's indenter position (`x_mm`, `y_mm`) is held to the sensor of the logger
/// recording its truth: `check` refuses a rig at (99, 0) mm on the 100 mm skin, at the logger
/// (its truth would be a contact off the skin).
#[test]
fn check_holds_a_rigs_position_to_the_sensor_of_its_logger() {
    let d = workdir("rig-position");
    let graph = |x_mm: f64| {
        format!(
            "[[node]]\nid = \"rig\"\nkind = \"serial_loadcell\"\nparams = {{ port = \"/dev/ttyUSB7\", x_mm = {x_mm:?}, y_mm = -10.0 }}\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"rec.h5\" }}\n\
             [[edge]]\nfrom = \"rig.truth\"\nto = \"log.truth\"\n"
        )
    };
    std::fs::write(d.join("on.toml"), graph(45.0)).unwrap();
    std::fs::write(d.join("off.toml"), graph(99.0)).unwrap();
    ok(&skinflow(&d, &["check", "on.toml"]));
    // A 120 mm indenter on a 150 x 100 mm sensor: wider than its shorter side.
    std::fs::write(d.join("wide.toml"), "[sensor]\nname = \"wide\"\nwidth_mm = 150.0\nheight_mm = 100.0\n").unwrap();
    let wide = |diameter_mm: f64| {
        graph(0.0)
            .replace("y_mm = -10.0 }", &format!("y_mm = -10.0, diameter_mm = {diameter_mm:?} }}"))
            .replace("path = \"rec.h5\" }", "path = \"rec.h5\", sensor = \"wide.toml\" }")
    };
    std::fs::write(d.join("wide-120.toml"), wide(120.0)).unwrap();
    std::fs::write(d.join("wide-90.toml"), wide(90.0)).unwrap();
    ok(&skinflow(&d, &["check", "wide-90.toml"]));
    let err = stderr(&skinflow(&d, &["check", "wide-120.toml"]));
    assert!(err.contains("whose indenter is 120 mm wide, wider than the sensor's shorter side (100 mm)"), "{err}");
    let out = skinflow(&d, &["check", "off.toml"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("off.toml:5:1: node \"log\": ")
            && err.contains(
                "100 x 100 mm (x in [-50, 50], y in [-50, 50] mm), but its truth comes from serial_loadcell \"rig\", \
                 whose indenter is at (99, -10) mm, off the sensor"
            ),
        "{err}"
    );
}

/// The load cell's `at X Y [D]` over the control socket is held to the rule its params are:
/// a position off the sensor of the logger recording its truth, or an indenter wider than
/// that sensor, is refused naming the command and why (it had been recorded as truth off the
/// skin with `ok: true`); a position on the skin is taken.
#[test]
fn the_load_cells_at_command_is_held_to_the_sensor_of_its_logger() {
    let d = workdir("rig-at");
    let _cell = Board::new(&d.join("cell"));
    let graph = "[[node]]\nid = \"rig\"\nkind = \"serial_loadcell\"\nparams = { port = \"cell\", x_mm = 0.0, y_mm = 0.0 }\n\
                 [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = { path = \"rec.h5\" }\n\
                 [[edge]]\nfrom = \"rig.truth\"\nto = \"log.truth\"\n";
    std::fs::write(d.join("g.toml"), graph).unwrap();
    /// The run, killed if the test fails before it is stopped (it would run on).
    struct Run(std::process::Child);
    impl Drop for Run {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let mut run = Run(spawn(
        Command::new(bin())
            .args(["run", "g.toml", "--control", "c.sock"])
            .current_dir(&d)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    ));
    wait_for_file(&d.join("c.sock"), Duration::from_secs(20), "no control socket");
    let at = |command: &str| {
        skinflow(&d, &["send", "c.sock", &format!(r#"{{"cmd":"control","node":"rig","command":"{command}"}}"#)])
    };
    let off = stderr(&at("at 500 500"));
    assert!(off.contains("control command \"at 500 500\" refused: ") && off.contains("off the sensor"), "{off}");
    let wide = stderr(&at("at 10 10 1e9"));
    assert!(wide.contains("wider than the sensor"), "{wide}");
    ok(&at("at 10 -10 8"));
    let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(run.0.id() as i32), nix::sys::signal::Signal::SIGINT);
    assert!(run.0.wait().unwrap().success());
}
