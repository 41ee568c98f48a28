//! Whole-binary tests of the graph checks on output files and logged strategies
//! (`skinflow_nodes::outputs`): `check` refuses, and `run` stops before any node starts on,
//! a logger writing the recording its graph replays, the graph file itself, the file another
//! logger writes, or listing a strategy no corrector produces; each error is located at the
//! param and the inputs are left as they were. The same for the example plugin sinks, whose
//! `path` is an `output-path` (plugins/csv-writers): two `forces-csv` sinks on one file, one
//! over the recording replayed or the calibration a corrector reads, a `pressure-csv` over the
//! file a `csv-pressure` source reads (its `input-path`); a sink on a file of its own runs.

use std::path::{Path, PathBuf};

use super::plugins::plugin;
use super::support::{fixture, ok, read_recording, skinflow, stderr};

fn workdir(test: &str) -> PathBuf {
    super::support::workdir("outputs", test)
}

/// A replay of `rec.h5` (simulated from a tiny fixture scene) into `logger`'s params, with
/// `extra` nodes and edges appended; written as `d/g.toml`.
fn replay_graph(d: &Path, loggers: &[(&str, &str)], extra: &str) -> String {
    let mut graph = "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = { path = \"rec.h5\", speed = 0.0 }\n"
        .to_owned();
    for (id, params) in loggers {
        graph += &format!("[[node]]\nid = \"{id}\"\nkind = \"hdf5_logger\"\nparams = {{ {params} }}\n");
    }
    for (id, _) in loggers {
        graph += &format!("[[edge]]\nfrom = \"replay.eit\"\nto = \"{id}.eit\"\n");
        graph += &format!("[[edge]]\nfrom = \"replay.truth\"\nto = \"{id}.truth\"\n");
    }
    graph += extra;
    std::fs::write(d.join("g.toml"), &graph).unwrap();
    graph
}

fn recording(d: &Path) {
    let scene = fixture("tiny-eval.toml");
    ok(&skinflow(d, &["simulate", scene.to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
}

/// `check g.toml` and `run g.toml` both exit 2 with exactly `want` on stderr, and print no "ok".
fn refused(d: &Path, want: &str) {
    for cmd in ["check", "run"] {
        let out = skinflow(d, &[cmd, "g.toml"]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{cmd}: {err}");
        assert_eq!(err.trim_end(), want, "{cmd}");
        assert!(out.stdout.is_empty(), "{cmd}: no \"ok\" line");
    }
}

#[test]
fn a_logger_over_the_recording_replayed_or_the_graph_file_is_refused_and_both_are_kept() {
    let d = workdir("over-inputs");
    recording(&d);
    let rec = std::fs::read(d.join("rec.h5")).unwrap();
    let truth_rows = read_recording(d.join("rec.h5")).truth.unwrap().len();
    assert!(truth_rows > 0);

    // The audit's case: overwrite = true over the replay's recording (under another spelling
    // too). Before, `check` said ok and `run` replaced the recording with its own rows.
    for (path, same) in [("rec.h5", ""), ("./sub/../rec.h5", ", the same file")] {
        std::fs::create_dir_all(d.join("sub")).unwrap();
        replay_graph(&d, &[("log", &format!("path = {path:?}, overwrite = true"))], "");
        refused(
            &d,
            &format!(
                "g.toml:10:12: node \"log\": param \"path\": writes {path}, the recording replay \"replay\" reads \
                 (its `path` rec.h5{same}): the run would overwrite that input, whatever `overwrite` says, and what \
                 it holds would be lost; give `path` another file"
            ),
        );
        assert_eq!(std::fs::read(d.join("rec.h5")).unwrap(), rec, "{path}: the recording is untouched");
    }
    let kept = read_recording(d.join("rec.h5"));
    assert_eq!(kept.truth.unwrap().len(), truth_rows);

    // The graph file itself.
    let graph = replay_graph(&d, &[("log", "path = \"g.toml\", overwrite = true")], "");
    refused(
        &d,
        "g.toml:10:12: node \"log\": param \"path\": writes g.toml, which is this graph's own file g.toml: the run \
         would replace the graph with its output, whatever `overwrite` says; give `path` another file",
    );
    assert_eq!(std::fs::read_to_string(d.join("g.toml")).unwrap(), graph, "the graph file is untouched");
}

#[test]
fn two_loggers_on_one_file_are_refused_at_the_second() {
    let d = workdir("two-loggers");
    recording(&d);
    replay_graph(&d, &[("a", "path = \"out.h5\""), ("b", "path = \"./out.h5\", overwrite = true")], "");
    refused(
        &d,
        "g.toml:14:12: node \"b\": param \"path\": writes ./out.h5, which hdf5_logger \"a\" writes too (its `path` \
         out.h5, the same file): each would replace the other's output, whatever `overwrite` says; give each node \
         its own file",
    );
    assert!(!d.join("out.h5").exists(), "nothing ran");
    // Distinct files: accepted.
    replay_graph(&d, &[("a", "path = \"out.h5\""), ("b", "path = \"out2.h5\"")], "");
    ok(&skinflow(&d, &["check", "g.toml"]));
}

/// The pipeline after the replay: sync, reconstructor, segmenter, a proportional and a
/// force-balance splitter, and correctors `(id, params)` after `(splitter)`, all into logger
/// "log"'s `forces`.
fn pipeline(correctors: &[(&str, &str, &str)]) -> String {
    let calib = fixture("../../graphs/calib/paper.toml");
    let mut text = format!(
        "[[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\n\
         [[node]]\nid = \"seg\"\nkind = \"segmenter\"\n\
         [[node]]\nid = \"split\"\nkind = \"splitter\"\n\
         [[node]]\nid = \"split-fb\"\nkind = \"splitter\"\nparams = {{ strategy = \"force-balance\", calibration = {calib:?} }}\n"
    );
    for (id, splitter, params) in correctors {
        text +=
            &format!("[[node]]\nid = \"{id}\"\nkind = \"corrector\"\nparams = {{ calibration = {calib:?}{params} }}\n");
        text += &format!("[[edge]]\nfrom = \"{splitter}.split\"\nto = \"{id}.split\"\n");
        text += &format!("[[edge]]\nfrom = \"{id}.forces\"\nto = \"log.forces\"\n");
    }
    text + "[[edge]]\nfrom = \"replay.eit\"\nto = \"sync.eit\"\n\
         [[edge]]\nfrom = \"replay.pressure\"\nto = \"sync.pressure\"\n\
         [[edge]]\nfrom = \"replay.truth\"\nto = \"sync.truth\"\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n\
         [[edge]]\nfrom = \"recon.image\"\nto = \"seg.image\"\n\
         [[edge]]\nfrom = \"seg.contacts\"\nto = \"split.contacts\"\n\
         [[edge]]\nfrom = \"seg.contacts\"\nto = \"split-fb.contacts\"\n"
}

#[test]
fn a_listed_strategy_no_corrector_produces_is_refused_naming_those_that_arrive() {
    let d = workdir("strategy-typo");
    recording(&d);
    let correctors = [
        ("paper", "split", ""),
        ("ours", "split-fb", ", strategy = \"pneumatic-forward\", name = \"pneumatic-forward-balance\""),
    ];
    let logged = "path = \"out.h5\", strategies = [\"pneumatic-locaware\", \"pneumatic-forwrd-balance\"]";
    replay_graph(&d, &[("log", logged)], &pipeline(&correctors));
    refused(
        &d,
        "g.toml:10:29: node \"log\": param \"strategies\": strategy \"pneumatic-forwrd-balance\" is not produced by \
         any corrector connected to `forces`, so nothing would be logged under it; the names that arrive: \
         \"pneumatic-locaware\" (corrector \"paper\"), \"pneumatic-forward-balance\" (corrector \"ours\") (a \
         corrector's `name`, else its strategy, suffixed with -<splitter strategy> for a pneumatic one after a \
         splitter other than proportional)",
    );
    assert!(!d.join("out.h5").exists(), "nothing ran");
    let fixed = logged.replace("forwrd", "forward");
    replay_graph(&d, &[("log", &fixed)], &pipeline(&correctors));
    ok(&skinflow(&d, &["check", "g.toml"]));
}

/// Forces of a strategy the logger does not list are left out with one warning, and each of
/// their frames is counted as discarded in the logger's statistics (before, only a log line
/// said so, and the stats showed 0 drops). The other strategy's name, derived at check from
/// the corrector's and splitter's params, is the one its forces carry: its table is complete.
#[test]
fn forces_of_an_unlisted_strategy_are_counted_as_discarded() {
    let d = workdir("unlisted-discarded");
    recording(&d);
    let correctors = [("paper", "split", ""), ("fwd", "split-fb", ", strategy = \"pneumatic-forward\"")];
    let logged = "path = \"out.h5\", strategies = [\"pneumatic-forward-force-balance\"]";
    replay_graph(&d, &[("log", logged)], &pipeline(&correctors));
    let out = skinflow(&d, &["run", "g.toml", "--stats-json", "stats.json"]);
    ok(&out);
    let err = stderr(&out);
    assert_eq!(err.matches("is not in `strategies`").count(), 1, "{err}");
    assert!(err.contains("forces of strategy \"pneumatic-locaware\" are not logged"), "{err}");

    let frames = read_recording(d.join("rec.h5")).eit.unwrap().len() as u64;
    assert!(frames > 10);
    assert!(err.contains(&format!("frames={frames}")) && err.contains("force frames not logged"), "{err}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("stats.json")).unwrap()).unwrap();
    let node = |id: &str| stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).unwrap().clone();
    let log = node("log");
    assert_eq!(log["errors"], 0, "{log}");
    assert_eq!((log["discarded"].as_u64(), log["drops"].as_u64()), (Some(frames), Some(frames)), "{log}");
    assert_eq!(node("paper")["msgs_out"].as_u64(), Some(frames), "{stats}");
    let edge_drops: u64 = stats["edges"].as_array().unwrap().iter().map(|e| e["drops"].as_u64().unwrap()).sum();
    assert_eq!(edge_drops, 0, "{stats}");

    let rec = read_recording(d.join("out.h5"));
    let tables: Vec<(&str, usize)> = rec.derived.forces.iter().map(|f| (f.name.as_str(), f.t_s.len())).collect();
    assert_eq!(tables, [("pneumatic-forward-force-balance", frames as usize)]);
}

/// A TOML string of `p`.
fn quoted(p: &Path) -> String {
    toml::Value::String(p.to_string_lossy().into_owned()).to_string()
}

/// The 1-based line of the `params` of node `id` in `graph` (where its errors are located).
fn params_line(graph: &str, id: &str) -> usize {
    let lines: Vec<&str> = graph.lines().collect();
    let at = lines.iter().position(|l| *l == format!("id = \"{id}\"")).unwrap_or_else(|| panic!("{id}: {graph}"));
    at + lines[at..].iter().position(|l| l.starts_with("params = ")).expect("a params line") + 1
}

/// The csv-writers library, then a replay of `rec.h5` through the pipeline into corrector
/// "paper" (calibration `calib.toml`, a copy of the paper's), whose forces go to `forces-csv`
/// sinks `(id, path)`; written as `d/g.toml`.
fn forces_csv_graph(d: &Path, sinks: &[(&str, &str)]) -> String {
    let calib = d.join("calib.toml");
    if !calib.exists() {
        std::fs::copy(fixture("../../graphs/calib/paper.toml"), &calib).unwrap();
    }
    let mut graph = format!(
        "[graph]\nmode = \"lockstep\"\n\
         [[plugin]]\npath = {}\n\
         [[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = \"rec.h5\", speed = 0.0 }}\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\n\
         [[node]]\nid = \"seg\"\nkind = \"segmenter\"\n\
         [[node]]\nid = \"split\"\nkind = \"splitter\"\n\
         [[node]]\nid = \"paper\"\nkind = \"corrector\"\nparams = {{ calibration = \"calib.toml\" }}\n",
        quoted(&plugin("skinflow-plugin-csv-writers"))
    );
    for (id, path) in sinks {
        graph += &format!("[[node]]\nid = \"{id}\"\nkind = \"forces-csv\"\nparams = {{ path = {path:?} }}\n");
    }
    graph += "[[edge]]\nfrom = \"replay.eit\"\nto = \"sync.eit\"\n\
         [[edge]]\nfrom = \"replay.pressure\"\nto = \"sync.pressure\"\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n\
         [[edge]]\nfrom = \"recon.image\"\nto = \"seg.image\"\n\
         [[edge]]\nfrom = \"seg.contacts\"\nto = \"split.contacts\"\n\
         [[edge]]\nfrom = \"split.split\"\nto = \"paper.split\"\n";
    for (id, _) in sinks {
        graph += &format!("[[edge]]\nfrom = \"paper.forces\"\nto = \"{id}.forces\"\n");
    }
    std::fs::write(d.join("g.toml"), &graph).unwrap();
    graph
}

/// Before, two plugin sinks on one file passed `check` (a plugin's `path` param could be
/// read or written) and overwrote each other's rows; with `path` an `output-path`, the later
/// one is refused, naming both nodes.
#[test]
fn two_plugin_sinks_on_one_file_are_refused_naming_both_nodes() {
    let d = workdir("plugin-two-sinks");
    recording(&d);
    let graph = forces_csv_graph(&d, &[("a", "forces.csv"), ("b", "./forces.csv")]);
    refused(
        &d,
        &format!(
            "g.toml:{}:12: node \"b\": param \"path\": writes ./forces.csv, which forces-csv \"a\" writes too (its \
             `path` forces.csv, the same file): each would replace the other's output; \
             give each node its own file",
            params_line(&graph, "b")
        ),
    );
    assert!(!d.join("forces.csv").exists(), "nothing ran");
}

#[test]
fn a_plugin_sink_over_the_recording_or_the_calibration_is_refused_and_both_are_kept() {
    let d = workdir("plugin-over-inputs");
    recording(&d);
    let rec = std::fs::read(d.join("rec.h5")).unwrap();
    let graph = forces_csv_graph(&d, &[("csv", "rec.h5")]);
    let calib = std::fs::read(d.join("calib.toml")).unwrap();
    refused(
        &d,
        &format!(
            "g.toml:{}:12: node \"csv\": param \"path\": writes rec.h5, the recording replay \"replay\" reads (its \
             `path` rec.h5): the run would overwrite that input, and what it holds would \
             be lost; give `path` another file",
            params_line(&graph, "csv")
        ),
    );
    let graph = forces_csv_graph(&d, &[("csv", "sub/../calib.toml")]);
    refused(
        &d,
        &format!(
            "g.toml:{}:12: node \"csv\": param \"path\": writes sub/../calib.toml, the calibration corrector \
             \"paper\" reads (its `calibration` calib.toml, the same file): the run would overwrite that input, \
             and what it holds would be lost; give `path` another file",
            params_line(&graph, "csv")
        ),
    );
    assert_eq!(std::fs::read(d.join("rec.h5")).unwrap(), rec, "the recording is untouched");
    assert_eq!(std::fs::read(d.join("calib.toml")).unwrap(), calib, "the calibration is untouched");
}

/// The csv-pressure and csv-writers libraries, then `csv-pressure` "daq" (its `path` `source`)
/// -> `pressure-csv` "out" (params `out_params`), lockstep; written as `d/g.toml`.
fn csv_pass_through_graph(d: &Path, source: &str, out_params: &str) -> String {
    let graph = format!(
        "[graph]\nmode = \"lockstep\"\n\
         [[plugin]]\npath = {}\n[[plugin]]\npath = {}\n\
         [[node]]\nid = \"daq\"\nkind = \"csv-pressure\"\nparams = {{ path = \"{source}\", speed = 0.0 }}\n\
         [[node]]\nid = \"out\"\nkind = \"pressure-csv\"\nparams = {{ {out_params} }}\n\
         [[edge]]\nfrom = \"daq.pressure\"\nto = \"out.pressure\"\n",
        quoted(&plugin("skinflow-plugin-csv-pressure")),
        quoted(&plugin("skinflow-plugin-csv-writers"))
    );
    std::fs::write(d.join("g.toml"), &graph).unwrap();
    graph
}

/// `csv-pressure`'s `path` is an `input-path`: a `pressure-csv` writing that file is refused
/// (it would truncate the samples being replayed).
#[test]
fn a_plugin_sink_over_the_file_a_plugin_source_reads_is_refused() {
    let d = workdir("plugin-over-plugin-input");
    std::fs::write(d.join("p.csv"), "t_s,kpa\n0,101.25\n0.5,101.5\n").unwrap();
    let graph = csv_pass_through_graph(&d, "p.csv", "path = \"p.csv\", append = true");
    refused(
        &d,
        &format!(
            "g.toml:{}:12: node \"out\": param \"path\": writes p.csv, the file csv-pressure \"daq\" reads (its \
             `path` p.csv): the run would overwrite that input, and what it holds would be \
             lost; give `path` another file",
            params_line(&graph, "out")
        ),
    );
    assert_eq!(std::fs::read_to_string(d.join("p.csv")).unwrap(), "t_s,kpa\n0,101.25\n0.5,101.5\n");
    // Another file: the samples are copied.
    csv_pass_through_graph(&d, "p.csv", "path = \"q.csv\", append = true");
    ok(&skinflow(&d, &["run", "g.toml"]));
    assert_eq!(std::fs::read_to_string(d.join("q.csv")).unwrap(), "t_s,kpa\n0,101.25\n0.5,101.5\n");
}

/// A plugin's `output-path` or `input-path` given as "" is refused at `check` and `run`,
/// naming the param. Before, it passed `check`, and `run` exited 0 with the sink failing on
/// every message ("pressure-csv: : No such file or directory").
#[test]
fn an_empty_plugin_file_param_is_refused() {
    let d = workdir("plugin-empty-path");
    std::fs::write(d.join("p.csv"), "t_s,kpa\n0,101.25\n").unwrap();
    let graph = csv_pass_through_graph(&d, "p.csv", "path = \"\"");
    let line = params_line(&graph, "out");
    refused(&d, &format!("g.toml:{line}:12: node \"out\": param \"path\": is empty: give a file or device path"));
    let graph = csv_pass_through_graph(&d, "", "path = \"q.csv\"");
    let line = params_line(&graph, "daq");
    refused(&d, &format!("g.toml:{line}:12: node \"daq\": param \"path\": is empty: give a file or device path"));
    assert!(!d.join("q.csv").exists(), "nothing ran");
    // A directory as the sink's file: refused by `check` too, not only when `run` builds it.
    std::fs::create_dir_all(d.join("adir")).unwrap();
    let graph = csv_pass_through_graph(&d, "p.csv", "path = \"adir\"");
    let line = params_line(&graph, "out");
    refused(
        &d,
        &format!(
            "g.toml:{line}:12: node \"out\": param \"path\": writes adir, which is a directory; give `path` a file path"
        ),
    );
}

/// Two plugin sinks on files of their own pass `check` and each gets every row.
#[test]
fn plugin_sinks_on_files_of_their_own_run() {
    let d = workdir("plugin-own-files");
    recording(&d);
    forces_csv_graph(&d, &[("a", "a.csv"), ("b", "sub/b.csv")]);
    ok(&skinflow(&d, &["check", "g.toml"]));
    ok(&skinflow(&d, &["run", "g.toml"]));
    let a = std::fs::read_to_string(d.join("a.csv")).unwrap();
    assert!(a.starts_with("seq,t_s,contact,x_mm,y_mm,area_mm2,dp_kpa,force_n\n"), "{a}");
    assert!(a.lines().count() > 1, "rows written: {a}");
    assert_eq!(std::fs::read_to_string(d.join("sub/b.csv")).unwrap(), a, "each sink wrote every row");
}

/// `run --stats-json` (and `--control`) given a file the graph reads or writes: refused
/// before any node starts, naming the node and its param; the file is left as it was. Before,
/// only the graph file itself was refused, and the statistics replaced a calibration.
#[test]
fn stats_json_over_a_file_the_graph_reads_or_writes_is_refused() {
    let d = workdir("stats-json");
    recording(&d);
    replay_graph(&d, &[("log", "path = \"out.h5\"")], "");
    let rec = std::fs::read(d.join("rec.h5")).unwrap();
    let cases = [
        (
            "--stats-json",
            "sub/../rec.h5",
            "--stats-json sub/../rec.h5 is the recording replay \"replay\" reads (its `path` ",
        ),
        ("--stats-json", "out.h5", "--stats-json out.h5 is the file hdf5_logger \"log\" writes (its `path` "),
        ("--control", "out.h5", "--control out.h5 is the file hdf5_logger \"log\" writes (its `path` "),
    ];
    std::fs::create_dir_all(d.join("sub")).unwrap();
    for (flag, file, want) in cases {
        let out = skinflow(&d, &["run", "g.toml", flag, file]);
        let err = stderr(&out);
        assert!(!out.status.success(), "{flag} {file}: {err}");
        assert!(err.contains(want), "{flag} {file}: {err}");
        assert!(err.contains(&format!("give {flag} another file")), "{err}");
        assert!(!d.join("out.h5").exists(), "{flag} {file}: nothing ran");
    }
    assert_eq!(std::fs::read(d.join("rec.h5")).unwrap(), rec, "the recording is untouched");
    // Nor one file for both (the statistics would replace the socket).
    let out = skinflow(&d, &["run", "g.toml", "--stats-json", "s", "--control", "./s"]);
    assert!(!out.status.success() && stderr(&out).contains("--stats-json s and --control ./s name the same file"));
    // A file of its own: the run goes on and writes it.
    ok(&skinflow(&d, &["run", "g.toml", "--stats-json", "stats.json"]));
    assert!(std::fs::read_to_string(d.join("stats.json")).unwrap().contains("\"log\""));
}
