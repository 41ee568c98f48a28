//! Plugins through the binary: kinds from a built library in `skinflow nodes` and in graphs,
//! every load error (missing file, not a library, not a plugin, wrong ABI version, duplicate
//! kind) as one clear line naming the path (and kind), a plugin's error and panic handled per
//! the node's restart policy (processors and sources), plugin sources and sinks in the shipped
//! CSV graphs checked end to end, a paced plugin source stopped by `run --for`, the example
//! plugins in A/B lanes (each plugin lane named after its node, so `compare` and
//! `hdf5_logger` tell them apart), and `skinflow bench`. The run-time hooks, on built
//! libraries loaded into a graph run in this process: a control command applied, a bad one and
//! one to a kind without commands refused naming the node; a `csv-pressure` source hot-swapped
//! to the same plugin loaded again from another file goes on without a duplicate sample or
//! time going back (and one reading another file is refused); another kind's state is not
//! taken over.
//!
//! The libraries are the workspace's cdylib members, found next to the binary
//! (target/<profile>/lib<name>.so); a missing one is built with `cargo build -p`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphHandle, GraphSpec, Params, Registry, RunOptions, RunReport, RunningGraph};
use skinflow_nodes::gate::{self, Gate};
use skinflow_nodes::payload::PressureSample;
use skinflow_nodes::pipeline::{Captured, registry_with_capture};

use super::support::{bin, hdf5_io, ok, read_recording, root, skinflow, spawn, status, stderr};

/// target/<profile>/, where cargo puts the binary and the cdylibs.
fn profile_dir() -> PathBuf {
    Path::new(bin()).parent().expect("the binary is in a directory").to_path_buf()
}

/// The built library of workspace package `package`, built now if it is missing.
pub(crate) fn plugin(package: &str) -> PathBuf {
    let dir = profile_dir();
    let lib = dir.join(format!("lib{}.so", package.replace('-', "_")));
    if lib.is_file() {
        return lib;
    }
    let profile = match dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") | None => "dev".to_owned(),
        Some(p) => p.to_owned(),
    };
    let target_dir = dir.parent().expect("target/<profile> has a parent");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = status(
        Command::new(cargo)
            .args(["build", "-p", package, "--profile", &profile, "--target-dir"])
            .arg(target_dir)
            .current_dir(root()),
    );
    assert!(
        status.success() && lib.is_file(),
        "{} is missing and `cargo build -p {package}` did not make it",
        lib.display()
    );
    lib
}

/// A fresh work directory for one test of this module.
fn workdir(test: &str) -> PathBuf {
    super::support::workdir("plugins", test)
}

fn quoted(p: &Path) -> String {
    toml::Value::String(p.to_string_lossy().into_owned()).to_string()
}

/// counter (20) -> fixture-scale (plugin) -> collect, with `plugins` loaded.
fn toy_graph(dir: &Path, plugins: &[PathBuf], scale_params: &str, restart: &str) -> PathBuf {
    let mut g = String::from("[graph]\nname = \"plugin-toy\"\nmode = \"lockstep\"\n\n");
    for p in plugins {
        g.push_str(&format!("[[plugin]]\npath = {}\n\n", quoted(p)));
    }
    g.push_str(&format!(
        "[[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 20, start = 1 }}\n\n\
         [[node]]\nid = \"scale\"\nkind = \"fixture-scale\"\nrestart = \"{restart}\"\nparams = {{ {scale_params} }}\n\n\
         [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = \"out.csv\" }}\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"scale.in\"\n\n[[edge]]\nfrom = \"scale.out\"\nto = \"out.in\"\n"
    ));
    let path = dir.join("graph.toml");
    std::fs::write(&path, g).unwrap();
    path
}

/// The values the collect sink wrote.
fn collected(dir: &Path) -> Vec<u64> {
    let text = std::fs::read_to_string(dir.join("out.csv")).unwrap_or_default();
    text.lines().filter_map(|l| l.split(',').nth(1)).filter_map(|v| v.trim().parse().ok()).collect()
}

#[test]
fn plugin_kinds_are_listed_with_their_library_path() {
    let d = workdir("nodes");
    let lib = plugin("skinflow-plugin-split-weighted");
    let text = ok(&skinflow(&d, &["nodes", "--plugin", lib.to_str().unwrap()]));
    for kind in ["area-weighted-splitter", "peak-weighted-splitter"] {
        let line = text.lines().find(|l| l.starts_with(kind)).unwrap_or_else(|| panic!("{kind} missing:\n{text}"));
        assert!(line.contains(&lib.display().to_string()), "origin is not the library path: {line}");
    }
    assert!(text.contains("param exponent"), "{text}");
    assert!(text.lines().any(|l| l.starts_with("splitter") && l.contains("built-in")), "{text}");
}

#[test]
fn a_plugin_kind_runs_in_a_graph() {
    let d = workdir("toy");
    let g = toy_graph(&d, &[plugin("skinflow-plugin-fixture-faulty")], "factor = 3", "never");
    ok(&skinflow(&d, &["run", g.to_str().unwrap()]));
    assert_eq!(collected(&d), (1..=20).map(|v| 3 * v).collect::<Vec<u64>>());
}

#[test]
fn a_missing_plugin_file_names_the_path() {
    let d = workdir("missing");
    let missing = d.join("no-such-plugin.so");
    let g = toy_graph(&d, std::slice::from_ref(&missing), "", "never");
    let o = skinflow(&d, &["check", g.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    // Located at the `[[plugin]] path` value (line 6 of `toy_graph`'s file, after `path = `).
    let at = format!("{}:6:8: plugin {}: file not found", g.display(), missing.display());
    assert!(e.starts_with(&at), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "one line: {e}");
    // A directory or a device is said to be one, not "not found".
    for (path, what) in
        [(d.clone(), "is a directory, not a library"), (PathBuf::from("/dev/null"), "is not a regular file")]
    {
        let g = toy_graph(&d, std::slice::from_ref(&path), "", "never");
        let e = stderr(&skinflow(&d, &["check", g.to_str().unwrap()]));
        assert!(e.contains(&format!("plugin {}: {what}", path.display())), "{e}");
    }
}

/// `check` opens, read-only, the file a plugin's `input-path` param names (as it opens a
/// built-in node's recording or scene): a missing one or a directory is refused at the param,
/// before any node starts; an existing file passes.
#[test]
fn a_plugin_input_file_that_cannot_be_read_is_refused_at_its_param() {
    let d = workdir("input-path");
    let graph = |path: &str| {
        let g = format!(
            "[[plugin]]\npath = {}\n\
             [[node]]\nid = \"daq\"\nkind = \"csv-pressure\"\nparams = {{ path = {path:?} }}\n\
             [[node]]\nid = \"out\"\nkind = \"null\"\n\
             [[edge]]\nfrom = \"daq.pressure\"\nto = \"out.in\"\n",
            quoted(&plugin("skinflow-plugin-csv-pressure"))
        );
        std::fs::write(d.join("g.toml"), g).unwrap();
    };
    std::fs::create_dir_all(d.join("adir")).unwrap();
    for (path, cause) in
        [("missing.csv", "cannot read: No such file or directory"), ("adir", "is a directory, not a file")]
    {
        graph(path);
        for cmd in ["check", "run"] {
            let out = skinflow(&d, &[cmd, "g.toml"]);
            let err = stderr(&out);
            assert_eq!(out.status.code(), Some(2), "{cmd} {path}: {err}");
            let want = format!("g.toml:6:12: node \"daq\": param \"path\": {path}: {cause}");
            assert!(err.starts_with(&want), "{cmd} {path}: {err}");
        }
    }
    std::fs::write(d.join("p.csv"), "t_s,kpa\n0.0,1.0\n").unwrap();
    graph("p.csv");
    assert!(ok(&skinflow(&d, &["check", "g.toml"])).starts_with("g.toml: ok ("));
}

#[test]
fn a_file_that_is_not_a_library_is_refused() {
    let d = workdir("garbage");
    let bad = d.join("garbage.so");
    std::fs::write(&bad, b"this is not an ELF file").unwrap();
    let o = skinflow(&d, &["check", toy_graph(&d, std::slice::from_ref(&bad), "", "never").to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains(&format!("plugin {}: not a loadable library", bad.display())), "{e}");
    // The loader's reason, not only "dlopen failed"; under the user's path, not the host's copy.
    assert!(e.contains(&format!("dlopen failed: {}: ", bad.display())), "{e}");
}

/// A library cut short (a rebuild caught half way under `run --watch`) is refused with a
/// line that says so. Before, `dlopen` mapped it and the process died of SIGBUS: `nodes`,
/// `check`, and a watched run with all its outputs.
#[test]
fn a_library_cut_short_is_refused_not_a_crash() {
    let d = workdir("cut-short");
    let whole = std::fs::read(plugin("skinflow-plugin-fixture-faulty")).unwrap();
    for (name, len) in [("head.so", 5000), ("half.so", whole.len() / 2)] {
        let cut = d.join(name);
        std::fs::write(&cut, &whole[..len]).unwrap();
        let graph = toy_graph(&d, std::slice::from_ref(&cut), "", "never");
        for args in [["nodes", "--plugin", cut.to_str().unwrap()].as_slice(), &["check", graph.to_str().unwrap()]] {
            let o = skinflow(&d, args);
            let e = stderr(&o);
            assert!(matches!(o.status.code(), Some(1 | 2)), "{args:?}: not a crash: {:?} {e}", o.status);
            assert!(
                e.contains(&format!("plugin {}: not a loadable library: the file is incomplete: ", cut.display()))
                    && e.contains(&format!("but it has {len} bytes; is it still being written")),
                "{args:?}: {e}"
            );
        }
    }
}

/// A library given twice is refused at the second entry, the one that repeats it, also when
/// it is spelt otherwise (`dir/./lib.so`). Before, the error was placed at the first entry
/// while quoting the second's text.
#[test]
fn a_library_given_twice_is_refused_at_the_repeat() {
    let d = workdir("twice");
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let dotted = lib.parent().unwrap().join(".").join(lib.file_name().unwrap());
    for second in [lib.clone(), dotted] {
        let graph = toy_graph(&d, &[lib.clone(), second.clone()], "", "never");
        let o = skinflow(&d, &["check", graph.to_str().unwrap()]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{e}");
        // Lines: [graph] 1-3, blank, [[plugin]] 5-6, blank, [[plugin]] 8, its path 9.
        let want = format!("{}:9:8: plugin {}: given twice (also as ", graph.display(), second.display());
        assert!(e.starts_with(&want), "{e}");
    }
}

/// A plugin param of the wrong type is located at its key, as a built-in param is at its
/// value, not at the `[[node]]` line.
#[test]
fn a_plugin_param_error_is_located_at_the_param() {
    let d = workdir("param-at");
    let graph = toy_graph(&d, &[plugin("skinflow-plugin-fixture-faulty")], "factor = \"two\"", "never");
    let text = std::fs::read_to_string(&graph).unwrap();
    let line = text.lines().position(|l| l.contains("factor = \"two\"")).unwrap() + 1;
    let column = text.lines().nth(line - 1).unwrap().find("factor").unwrap() + 1;
    let o = skinflow(&d, &["check", graph.to_str().unwrap()]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    let want = format!("{}:{line}:{column}: node \"scale\": factor: invalid type: string \"two\"", graph.display());
    assert!(e.starts_with(&want), "{e}");
}

#[test]
fn a_library_without_the_entry_point_is_not_a_plugin() {
    let d = workdir("not-a-plugin");
    let lib = plugin("skinflow-plugin-fixture-not-a-plugin");
    let o = skinflow(&d, &["check", toy_graph(&d, std::slice::from_ref(&lib), "", "never").to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains(&format!("plugin {}: not a skinflow plugin", lib.display())), "{e}");
}

#[test]
fn a_plugin_of_abi_version_3_is_refused_with_one_line() {
    let d = workdir("bad-abi");
    let lib = plugin("skinflow-plugin-fixture-bad-abi");
    let graph = toy_graph(&d, std::slice::from_ref(&lib), "", "never");
    let o = skinflow(&d, &["check", graph.to_str().unwrap()]);
    // The graph cannot be validated: exit 2, as for an invalid graph, naming the graph.
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    // The fixture is a version-3 table (no control or state hooks), as a plugin built before
    // the run-time hooks looks to this host.
    assert_eq!(
        e.trim(),
        format!(
            "{}:6:8: plugin {}: built for plugin ABI version 3, this skinflow loads version 4 (rebuild it against this skinflow-plugin-sdk)",
            graph.display(),
            lib.display()
        )
    );
}

#[test]
fn a_kind_defined_twice_names_both_libraries() {
    let d = workdir("duplicate");
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let copy = d.join("libcopy.so");
    std::fs::copy(&lib, &copy).unwrap();
    let o = skinflow(&d, &["check", toy_graph(&d, &[lib.clone(), copy.clone()], "", "never").to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains(&format!(
            "plugin {}: kind \"fixture-scale\" is already defined by {}",
            copy.display(),
            lib.display()
        )),
        "{e}"
    );
}

#[test]
fn bad_plugin_params_are_reported_by_check() {
    let d = workdir("params");
    let g = toy_graph(&d, &[plugin("skinflow-plugin-fixture-faulty")], "factr = 2", "never");
    let o = skinflow(&d, &["check", g.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("factr"), "the unknown key is named: {e}");
}

#[test]
fn a_plugin_error_is_counted_and_the_graph_goes_on() {
    let d = workdir("error");
    let g = toy_graph(&d, &[plugin("skinflow-plugin-fixture-faulty")], "error_at = 3", "never");
    let json = d.join("stats.json");
    ok(&skinflow(&d, &["run", g.to_str().unwrap(), "--stats-json", json.to_str().unwrap()]));
    let got = collected(&d);
    assert_eq!(got.len(), 19, "the erring call's message is dropped: {got:?}");
    assert!(!got.contains(&3));
    let report = stats(&json);
    let counts = ["errors", "panics", "restarts", "msgs_in", "msgs_out"].map(|what| count(&report, "scale", what));
    assert_eq!(counts, [1, 0, 0, 20, 19], "errors, panics, restarts, in, out");
}

#[test]
fn a_plugin_panic_stops_the_graph_without_restart() {
    let d = workdir("panic-never");
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let g = toy_graph(&d, std::slice::from_ref(&lib), "panic_at = 5", "never");
    let o = skinflow(&d, &["run", g.to_str().unwrap()]);
    assert!(!o.status.success(), "a panic without restart is a failure");
    let e = stderr(&o);
    assert!(e.contains("node \"scale\""), "{e}");
    assert!(e.contains(&format!("plugin kind \"fixture-scale\" ({})", lib.display())), "{e}");
    assert!(e.contains("fixture panic at call 5"), "{e}");
    assert_eq!(collected(&d), vec![1, 2, 3, 4], "messages before the panic were delivered");
}

#[test]
fn a_plugin_panic_with_restart_always_rebuilds_the_node() {
    let d = workdir("panic-always");
    let g = toy_graph(&d, &[plugin("skinflow-plugin-fixture-faulty")], "panic_at = 5", "always");
    let json = d.join("stats.json");
    let text = ok(&skinflow(&d, &["run", g.to_str().unwrap(), "--stats-json", json.to_str().unwrap()]));
    let got = collected(&d);
    // The fresh instance counts calls from 1 again and panics on its 5th call too.
    assert_eq!(got, vec![1, 2, 3, 4, 6, 7, 8, 9, 11, 12, 13, 14, 16, 17, 18, 19], "{text}");
    let report = stats(&json);
    let counts = ["panics", "restarts", "errors"].map(|what| count(&report, "scale", what));
    assert_eq!(counts, [4, 4, 0], "a panic at calls 5, 10, 15 and 20, each followed by a rebuild: {text}");
}

/// graphs/plugin-ab.toml on the tiny fixture scene, with this build's libraries.
#[test]
fn example_plugins_run_as_ab_lanes_and_compare_reports_each() {
    let d = workdir("ab");
    let split = plugin("skinflow-plugin-split-weighted");
    let fused = plugin("skinflow-plugin-correct-fused");
    let text = std::fs::read_to_string(root().join("graphs/plugin-ab.toml")).unwrap();
    let json = d.join("ab.json");
    let text = text
        .replace("\"../target/debug/libskinflow_plugin_split_weighted.so\"", &quoted(&split))
        .replace("\"../target/debug/libskinflow_plugin_correct_fused.so\"", &quoted(&fused))
        .replace("\"scenes/multi-contact.toml\"", &quoted(&root().join("tests/fixtures/tiny-eval.toml")))
        .replace("\"calib/paper.toml\"", &quoted(&root().join("graphs/calib/paper.toml")))
        .replace("\"../out/plugin-ab.json\"", &quoted(&json));
    let g = d.join("plugin-ab.toml");
    std::fs::write(&g, text).unwrap();
    let stats_json = d.join("stats.json");
    let table = ok(&skinflow(&d, &["run", g.to_str().unwrap(), "--stats-json", stats_json.to_str().unwrap()]));
    assert!(table.contains("| peak-weighted (plugin) |"), "{table}");
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let lanes = report["lanes"].as_array().unwrap();
    assert_eq!(lanes.len(), 4);
    for l in lanes {
        assert!(l["frames"].as_u64().unwrap() > 0, "{l}");
        assert!(l["matched"].as_u64().unwrap() > 0, "{l}");
        let rmse = l["rmse_n"].as_f64().unwrap();
        assert!(rmse.is_finite() && rmse >= 0.0, "{l}");
        assert!(l["latency_us_p50"].as_f64().unwrap() > 0.0, "{l}");
    }
    // Same contacts in every lane (one segmentation): identical localization.
    let loc: Vec<f64> = lanes.iter().map(|l| l["localization_mean_mm"].as_f64().unwrap()).collect();
    assert!(loc.iter().all(|&x| x == loc[0]), "{loc:?}");
    // Every lane timed and scored the same frames: their figures compare like with like.
    let frames: Vec<(u64, u64)> =
        lanes.iter().map(|l| (l["frames"].as_u64().unwrap(), l["unsettled_frames"].as_u64().unwrap())).collect();
    assert!(frames.iter().all(|&f| f == frames[0]), "timed and unsettled frames per lane: {frames:?}");
    // No node erred and no edge lost a message on the way.
    let report = stats(&stats_json);
    for n in report["nodes"].as_array().unwrap() {
        assert_eq!((n["errors"].as_u64(), n["drops"].as_u64()), (Some(0), Some(0)), "{n}");
    }
    for e in report["edges"].as_array().unwrap() {
        assert_eq!(e["drops"].as_u64(), Some(0), "{e}");
    }
}

/// Three `fused-corrector` lanes and a built-in corrector after a plugin splitter, into one
/// `compare` (no `names`) and one `hdf5_logger`: each plugin output is named after its node
/// (its id, or its `name` param), so the lanes are told apart and the logger takes all four;
/// every plugin output is attached to its own frame (no provenance or value errors).
#[test]
fn plugin_lanes_are_named_after_their_nodes_in_compare_and_the_logger() {
    let d = workdir("names");
    let calib = quoted(&root().join("graphs/calib/paper.toml"));
    let mut g = format!(
        "[graph]\nname = \"plugin-names\"\nmode = \"lockstep\"\n\n\
         [[plugin]]\npath = {}\n\n[[plugin]]\npath = {}\n\n\
         [[node]]\nid = \"sim\"\nkind = \"sim\"\nparams = {{ scene = {}, pacing = \"fast\" }}\n\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\n[[node]]\nid = \"recon\"\nkind = \"reconstructor\"\n\n\
         [[node]]\nid = \"segment\"\nkind = \"segmenter\"\n\n[[node]]\nid = \"split\"\nkind = \"splitter\"\n\n\
         [[node]]\nid = \"split-area\"\nkind = \"area-weighted-splitter\"\n\n\
         [[node]]\nid = \"fused-a\"\nkind = \"fused-corrector\"\nparams = {{ calibration = {calib}, weight_pneumatic = 0.8 }}\n\n\
         [[node]]\nid = \"fused-b\"\nkind = \"fused-corrector\"\nparams = {{ calibration = {calib}, weight_pneumatic = 0.3 }}\n\n\
         [[node]]\nid = \"fused-c\"\nkind = \"fused-corrector\"\nparams = {{ calibration = {calib}, name = \"fused-eit\", weight_pneumatic = 0.0 }}\n\n\
         [[node]]\nid = \"force-area\"\nkind = \"corrector\"\nparams = {{ calibration = {calib} }}\n\n\
         [[node]]\nid = \"compare\"\nkind = \"compare\"\ntrigger = \"aligned\"\nparams = {{ json = \"ab.json\" }}\n\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\n\
         params = {{ path = \"log.h5\", strategies = [\"fused-a\", \"fused-b\", \"fused-eit\", \"pneumatic-locaware-split-area\"] }}\n\n",
        quoted(&plugin("skinflow-plugin-split-weighted")),
        quoted(&plugin("skinflow-plugin-correct-fused")),
        quoted(&root().join("tests/fixtures/tiny-eval.toml")),
    );
    let edges = [
        ("sim.eit", "sync.eit"),
        ("sim.pressure", "sync.pressure"),
        ("sim.truth", "sync.truth"),
        ("sync.frame", "recon.frame"),
        ("recon.image", "segment.image"),
        ("segment.contacts", "split.contacts"),
        ("segment.contacts", "split-area.contacts"),
        ("split.split", "fused-a.split"),
        ("split.split", "fused-b.split"),
        ("split.split", "fused-c.split"),
        ("split-area.split", "force-area.split"),
    ];
    for (from, to) in edges {
        g.push_str(&format!("[[edge]]\nfrom = \"{from}\"\nto = \"{to}\"\n\n"));
    }
    for lane in ["fused-a", "fused-b", "fused-c", "force-area"] {
        for sink in ["compare", "log"] {
            g.push_str(&format!("[[edge]]\nfrom = \"{lane}.forces\"\nto = \"{sink}.forces\"\ncapacity = 1024\n\n"));
        }
    }
    let graph = d.join("names.toml");
    std::fs::write(&graph, g).unwrap();
    let json = d.join("stats.json");
    ok(&skinflow(&d, &["run", graph.to_str().unwrap(), "--stats-json", json.to_str().unwrap()]));

    let names = ["fused-a", "fused-b", "fused-eit", "pneumatic-locaware-split-area"];
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("ab.json")).unwrap()).unwrap();
    let lanes: Vec<&str> = report["lanes"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    assert_eq!(lanes, names, "compare's lanes are named after the nodes");
    let stats = stats(&json);
    let frames = count(&stats, "split", "msgs_out");
    assert!(frames > 10, "the pipeline produced frames");
    for id in ["split-area", "fused-a", "fused-b", "fused-c"] {
        assert_eq!((count(&stats, id, "errors"), count(&stats, id, "msgs_out")), (0, frames), "{id}");
    }
    let rec = read_recording(d.join("log.h5"));
    let logged: Vec<&str> = rec.derived.forces.iter().map(|f| f.name.as_str()).collect();
    for name in names {
        let f = rec.derived.forces.iter().find(|f| f.name == name).unwrap_or_else(|| panic!("{name}: {logged:?}"));
        assert_eq!(f.t_s.len() as u64, frames, "{name}: every frame logged");
    }
    let forces = |name: &str| -> Vec<f64> {
        let f = rec.derived.forces.iter().find(|f| f.name == name).unwrap();
        f.force_n.iter().copied().filter(|x| !x.is_nan()).collect() // NaN: padding past the contacts
    };
    assert!(!forces("fused-a").is_empty(), "frames with contacts");
    assert_ne!(forces("fused-a"), forces("fused-b"), "two lanes, two tables");
}

#[test]
fn bench_names_file_line_and_column_of_a_broken_graph() {
    let d = workdir("bench-broken");
    std::fs::write(d.join("rec.h5"), b"").unwrap();
    // Valid TOML, so only graph validation catches it: an unknown kind on line 11. The replay
    // node has no `path`: bench fills it in from --replay, so that alone is not an error.
    let graph = "[graph]\nname = \"x\"\n\
        [[node]]\nid = \"replay\"\nkind = \"replay\"\n\
        [[node]]\nid = \"cmp\"\nkind = \"compare\"\n\
        [[node]]\nid = \"recon\"\nkind = \"nope\"\n";
    std::fs::write(d.join("g.toml"), graph).unwrap();
    let o = skinflow(&d, &["bench", "g.toml", "--replay", "rec.h5", "--vary", "recon.lambda=0.1", "--out", "b"]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("g.toml:11:") && err.contains("nope"), "no file:line:column in {err}");
    assert!(!d.join("b").exists(), "nothing written for a broken graph");
    // An error only an override causes names the variant (its regenerated text has no lines
    // the user could look up).
    let ab = root().join("graphs/ab-replay.toml");
    let o =
        skinflow(&d, &["bench", ab.to_str().unwrap(), "--replay", "rec.h5", "--vary", "recon.lambda=-1", "--out", "b"]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("variant \"recon.lambda=-1\"") && err.contains("lambda"), "{err}");
    assert!(!d.join("b").exists(), "nothing written for an invalid variant");
}

/// One `skinflow bench` of graphs/ab-replay.toml on `rec.h5` in `dir`, into `dir/out`, with
/// these `--vary` arguments.
fn bench(dir: &Path, vary: &[&str]) -> std::process::Output {
    let graph = root().join("graphs/ab-replay.toml");
    let mut args = vec!["bench", graph.to_str().unwrap(), "--replay", "rec.h5", "--out", "out"];
    for v in vary {
        args.extend(["--vary", v]);
    }
    skinflow(dir, &args)
}

/// A fresh work directory with the tiny fixture scene simulated into `rec.h5`.
fn bench_workdir(test: &str) -> PathBuf {
    let d = workdir(test);
    let fixture = root().join("tests/fixtures/tiny-eval.toml");
    ok(&skinflow(&d, &["simulate", fixture.to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
    d
}

fn json_file(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// A file bench writes or removes in `--out` (its own outputs, a variant's report, an earlier
/// bench's leftovers) that is an input of the graph is refused before anything is removed.
/// Before, a recording replayed from `out/pareto.png` or `out/variant-3.json` was deleted.
#[test]
fn bench_refuses_an_out_directory_holding_its_inputs_under_its_output_names() {
    let d = bench_workdir("bench-out-inputs");
    std::fs::create_dir_all(d.join("out")).unwrap();
    let rec = std::fs::read(d.join("rec.h5")).unwrap();
    let graph = root().join("graphs/ab-replay.toml");
    for name in ["pareto.png", "variant-3.json", "bench.md"] {
        let kept = d.join("out").join(name);
        std::fs::write(&kept, &rec).unwrap();
        let replay = format!("out/{name}");
        let o = skinflow(
            &d,
            &["bench", graph.to_str().unwrap(), "--replay", &replay, "--vary", "recon.lambda=0.1", "--out", "out"],
        );
        let err = stderr(&o);
        assert!(!o.status.success(), "{err}");
        assert!(
            err.contains(&format!(
                "--out out: bench writes or removes {} there, and that file is the recording",
                kept.display()
            )),
            "{err}"
        );
        assert_eq!(std::fs::read(&kept).unwrap(), rec, "{name} is kept");
        std::fs::remove_file(&kept).unwrap();
    }
    assert_eq!(std::fs::read_dir(d.join("out")).unwrap().count(), 0, "nothing written");
    // Not an input, but not bench's either: notes under bench.md are kept, and said.
    std::fs::write(d.join("out/bench.md"), "my notes\n").unwrap();
    let o = skinflow(
        &d,
        &["bench", graph.to_str().unwrap(), "--replay", "rec.h5", "--vary", "recon.lambda=0.1", "--out", "out"],
    );
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("exists and is not a file this command wrote (it begins \"my notes\")"), "{err}");
    assert_eq!(std::fs::read_to_string(d.join("out/bench.md")).unwrap(), "my notes\n");
}

#[test]
fn bench_varies_a_param_over_a_recording_and_writes_table_and_plot() {
    let d = bench_workdir("bench");
    let o = bench(&d, &["recon.lambda=0.02,0.2"]);
    let md = ok(&o);
    assert!(stderr(&o).contains("bench: warm-up pass (variant 0"), "{}", stderr(&o));
    let rows: Vec<&str> = md.lines().filter(|l| l.starts_with("| recon.lambda=")).collect();
    assert_eq!(rows.len(), 4, "2 variants x 2 lanes:\n{md}");
    for f in ["bench.md", "bench.json", "pareto.png", "variant-0.json", "variant-1.json"] {
        assert!(d.join("out").join(f).is_file(), "{f} missing");
    }
    let png = std::fs::read(d.join("out/pareto.png")).unwrap();
    assert_eq!(&png[..4], b"\x89PNG");

    // bench.json holds each variant's compare report, lane by lane.
    let bench_json = json_file(&d.join("out/bench.json"));
    let points = bench_json["points"].as_array().unwrap();
    assert_eq!(points.len(), 4);
    let variants = bench_json["variants"].as_array().unwrap();
    assert_eq!(variants.len(), 2);
    for (k, v) in variants.iter().enumerate() {
        assert_eq!(v["compare_json"], format!("variant-{k}.json"), "{v}");
        assert!(v["error"].is_null() && v["node_errors"] == serde_json::json!([]), "{v}");
        assert_eq!(v["edge_drops"], serde_json::json!([]), "{v}");
        let lanes = json_file(&d.join("out").join(format!("variant-{k}.json")));
        let lanes = lanes["lanes"].as_array().unwrap();
        assert_eq!(lanes.len(), 2, "two lanes in variant {k}");
        for l in lanes {
            let p = points
                .iter()
                .find(|p| p["variant_index"] == k && p["lane"] == l["name"])
                .unwrap_or_else(|| panic!("variant {k}, lane {}: no point", l["name"]));
            assert_eq!(p["variant"], v["label"]);
            for key in ["frames", "unsettled_frames", "matched", "latency_us_p50", "latency_us_p99", "rmse_n"] {
                assert_eq!(p[key], l[key], "variant {k}, lane {}: {key}", l["name"]);
            }
            let (frames, unsettled) = (l["frames"].as_u64().unwrap(), l["unsettled_frames"].as_u64().unwrap());
            assert!(frames > 10 && unsettled > 0, "{l}");
            assert_eq!(p["scored_frames"].as_u64(), Some(frames - unsettled));
        }
    }
    assert_eq!(variants[0]["overrides"], serde_json::json!({ "recon.lambda": 0.02 }));
    assert_eq!(variants[1]["overrides"], serde_json::json!({ "recon.lambda": 0.2 }));
    // The override took: each lane's RMSE differs between the two lambdas.
    for lane in ["proportional", "sensitivity-compensated"] {
        let rmse: Vec<f64> =
            points.iter().filter(|p| p["lane"] == lane).map(|p| p["rmse_n"].as_f64().unwrap()).collect();
        assert_eq!(rmse.len(), 2, "{lane}");
        assert!((rmse[0] - rmse[1]).abs() > 1e-6, "{lane}: the same RMSE at both lambdas: {rmse:?}");
    }
    // Every point covers the same frames: no warning.
    assert_eq!(bench_json["warnings"], serde_json::json!([]));
    assert!(!md.contains("## Warnings"), "{md}");
    // The Pareto marks are the points no other point beats on both p50 and RMSE.
    let xy: Vec<(f64, f64)> =
        points.iter().map(|p| (p["latency_us_p50"].as_f64().unwrap(), p["rmse_n"].as_f64().unwrap())).collect();
    for (i, p) in points.iter().enumerate() {
        let (x, y) = xy[i];
        let beaten = xy.iter().any(|&(ox, oy)| ox <= x && oy <= y && (ox < x || oy < y));
        assert_eq!(p["pareto"].as_bool(), Some(!beaten), "{p}");
        let row = rows
            .iter()
            .find(|r| {
                r.contains(&format!("| {} |", p["lane"].as_str().unwrap()))
                    && r.starts_with(&format!("| {} |", p["variant"].as_str().unwrap()))
            })
            .unwrap();
        assert_eq!(row.ends_with("| yes |"), !beaten, "{row}");
    }
    // The table's counts are the JSON's.
    assert!(md.contains("| variant | lane | frames | scored | unsettled | matched |"), "{md}");
    let p0 = &points[0];
    let row = format!(
        "| {} | {} | {} | {} | {} | {} |",
        p0["variant"].as_str().unwrap(),
        p0["lane"].as_str().unwrap(),
        p0["frames"],
        p0["scored_frames"],
        p0["unsettled_frames"],
        p0["matched"]
    );
    assert!(md.contains(&row), "{row} not in\n{md}");
    assert!(md.contains("about 10 %"), "the timing noise is stated:\n{md}");

    // Run again into the same directory with one variant: no report of the first run is left.
    ok(&bench(&d, &["recon.lambda=0.2"]));
    assert!(!d.join("out/variant-1.json").exists(), "the earlier run's variant-1.json is left");
    let again = json_file(&d.join("out/bench.json"));
    assert_eq!(again["points"].as_array().unwrap().len(), 2);
    // What bench sets itself cannot be varied: before, the variant read the first run's report.
    let o = bench(&d, &["compare.json=\"/tmp/x.json\""]);
    assert!(!o.status.success(), "a --vary of compare.json is refused");
    assert!(stderr(&o).contains("--vary \"compare.json\": bench sets param \"json\""), "{}", stderr(&o));
    for key in ["replay.path=\"rec.h5\"", "replay.speed=1", "compare.print=true"] {
        let o = bench(&d, &[key]);
        assert!(!o.status.success(), "{key} refused");
        let name = key.split('=').next().unwrap();
        assert!(stderr(&o).contains(&format!("--vary \"{name}\": bench sets param")), "{}", stderr(&o));
    }
}

/// A variant whose reconstructor has another sensor than the recording is refused before
/// anything runs; a variant whose reconstructor errs (every channel at the rail) is reported
/// with its node errors and discarded frames and warned about; a variant naming a missing calibration is refused
/// before anything runs and the last bench's outputs are kept; a variant that cannot start (a
/// logger whose directory is not there) does not lose the variants that ran: they are written,
/// then bench fails naming the variant and its cause.
#[test]
fn bench_reports_node_errors_and_a_failed_variant_after_the_others() {
    let d = bench_workdir("bench-health");
    std::fs::write(d.join("twelve.toml"), "[sensor]\nname = \"twelve\"\nelectrodes_per_side = 3\n").unwrap();
    let o = bench(&d, &[&format!("recon.sensor={}", quoted(&d.join("twelve.toml")))]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains(r#"node "recon": param "sensor": reconstructs on sensor "twelve""#), "{err}");
    assert!(err.contains(r#"rec.h5 was made on sensor "paper-100mm""#), "{err}");
    assert!(!d.join("out").exists(), "nothing ran or was written: {err}");

    let o = bench(&d, &["recon.mask={ saturation_v = 1.0 },{ saturation_v = 1e-9 }"]);
    let md = ok(&o);
    let bench_json = json_file(&d.join("out/bench.json"));
    let variants = bench_json["variants"].as_array().unwrap();
    assert_eq!(variants[0]["node_errors"], serde_json::json!([]), "{}", variants[0]);
    let recon = variants[1]["node_errors"].as_array().unwrap().iter().find(|n| n["node"] == "recon");
    let recon = recon.unwrap_or_else(|| panic!("no recon errors: {}", variants[1]));
    let errors = recon["errors"].as_u64().unwrap();
    assert!(errors >= 1, "{recon}");
    assert!(md.contains("- variant 1 `recon.mask={ saturation_v = 0.000000001 }`: node \"recon\": "), "{md}");
    assert!(
        md.contains("## Warnings") && md.contains(&format!("lost frames on the way: node \"recon\": {errors} errors")),
        "{md}"
    );
    // Every frame of that variant is dropped (none is imaged on the matrix of the channels
    // before: the mask is set on the matrix first), so it also gives no point.
    let warnings = bench_json["warnings"].as_array().unwrap();
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(
        warnings[1].as_str().unwrap().ends_with("gave no point: its compare node received no forces"),
        "{warnings:?}"
    );
    assert!(recon["discarded"].as_u64().unwrap() > 0, "the frames after the first are counted: {recon}");

    // A missing input file is found when the variants are checked: nothing runs, and the
    // last bench's outputs stay as they were.
    let before = std::fs::read(d.join("out/bench.json")).unwrap();
    let o = bench(&d, &["split-sens.calibration=calib/paper.toml,calib/missing.toml"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let variant = r#"variant "split-sens.calibration="calib/missing.toml""#;
    let param = r#"node "split-sens": param "calibration": "#;
    assert!(err.contains(variant) && err.contains(param) && err.contains("missing.toml: No such file"), "{err}");
    assert!(!err.contains("warm-up"), "nothing ran: {err}");
    assert_eq!(std::fs::read(d.join("out/bench.json")).unwrap(), before, "the last bench's report is kept");

    // The shipped graph with a logger: a variant whose logger's directory does not exist is
    // refused when the variants are checked (nothing runs) ...
    let graph = std::fs::read_to_string(root().join("graphs/ab-replay.toml")).unwrap()
        + "\n[[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = { path = \"log.h5\" }\n\
           [[edge]]\nfrom = \"replay.eit\"\nto = \"log.eit\"\n";
    std::fs::create_dir_all(d.join("calib")).unwrap();
    std::fs::copy(root().join("graphs/calib/paper.toml"), d.join("calib/paper.toml")).unwrap();
    std::fs::write(d.join("logged.toml"), graph).unwrap();
    let vary = r#"log.path="log.h5","no/dir/log.h5""#;
    let o = skinflow(&d, &["bench", "logged.toml", "--replay", "rec.h5", "--out", "out", "--vary", vary]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains(r#"variant "log.path="no/dir/log.h5""#) && err.contains("directory no/dir does not exist"),
        "{err}"
    );
    assert!(!d.join("log.h5").exists(), "nothing ran: {err}");
    // ... and one whose logger may not replace its file (there, from the variant before,
    // without `overwrite`) fails at start, after the variant before it ran.
    let vary = "log.overwrite=true,false";
    let o = skinflow(&d, &["bench", "logged.toml", "--replay", "rec.h5", "--out", "out", "--vary", vary]);
    assert!(!o.status.success(), "a variant that cannot start fails the bench");
    let err = stderr(&o);
    let last = err.trim().lines().last().unwrap();
    assert!(last.starts_with(r#"error: variant "log.overwrite=false": "#), "{err}");
    assert!(last.contains("log.h5: exists") && last.contains("1 of 2 variants failed"), "{last}");
    let bench_json = json_file(&d.join("out/bench.json"));
    let points = bench_json["points"].as_array().unwrap();
    assert_eq!(points.len(), 2, "the variant that ran: {bench_json}");
    assert!(points.iter().all(|p| p["variant_index"] == 0 && p["rmse_n"].as_f64().is_some()), "{bench_json}");
    let failed = &bench_json["variants"][1];
    assert!(failed["error"].as_str().unwrap().contains("log.h5: exists"), "{failed}");
    assert!(failed["compare_json"].is_null(), "{failed}");
    let md = std::fs::read_to_string(d.join("out/bench.md")).unwrap();
    assert!(md.contains("| log.overwrite=true | proportional |"), "{md}");
    assert!(md.contains("- variant 1 `log.overwrite=false`: FAILED: "), "{md}");
    assert!(d.join("out/pareto.png").is_file(), "the variants that ran are plotted");
    assert!(d.join("log.h5").is_file(), "the variant that ran logged");
}

/// The run report of `--stats-json F`.
fn stats(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A node's line of a run report.
fn node_stats<'a>(report: &'a serde_json::Value, id: &str) -> &'a serde_json::Value {
    report["nodes"].as_array().unwrap().iter().find(|n| n["id"] == id).unwrap_or_else(|| panic!("no node {id}"))
}

/// A counter of a node's line.
fn count(report: &serde_json::Value, id: &str, what: &str) -> u64 {
    node_stats(report, id)[what].as_u64().unwrap_or_else(|| panic!("{id}.{what}"))
}

/// fixture-count (plugin source, 10 values) -> collect, with the faulty fixture loaded.
fn source_graph(dir: &Path, count_params: &str, restart: &str) -> PathBuf {
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let g = format!(
        "[graph]\nname = \"plugin-source\"\nmode = \"lockstep\"\n\n[[plugin]]\npath = {}\n\n\
         [[node]]\nid = \"src\"\nkind = \"fixture-count\"\nrestart = \"{restart}\"\nparams = {{ count = 10, {count_params} }}\n\n\
         [[node]]\nid = \"out\"\nkind = \"collect\"\nparams = {{ path = \"out.csv\" }}\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"out.in\"\n",
        quoted(&lib)
    );
    let path = dir.join("graph.toml");
    std::fs::write(&path, g).unwrap();
    path
}

#[test]
fn plugin_sources_and_sinks_are_listed_with_their_roles() {
    let d = workdir("roles");
    let (src, snk) = (plugin("skinflow-plugin-csv-pressure"), plugin("skinflow-plugin-csv-writers"));
    let text = ok(&skinflow(&d, &["nodes", "--plugin", src.to_str().unwrap(), "--plugin", snk.to_str().unwrap()]));
    let line =
        |kind: &str| text.lines().find(|l| l.starts_with(&format!("{kind} ("))).unwrap_or_else(|| panic!("{kind}"));
    assert!(line("csv-pressure").starts_with(&format!("csv-pressure (Source, {})", src.display())), "{text}");
    for kind in ["forces-csv", "pressure-csv"] {
        assert!(line(kind).starts_with(&format!("{kind} (Sink, {})", snk.display())), "{text}");
    }
    assert!(text.contains("  out pressure: pressure"), "{text}");
    assert!(text.contains("  in  forces: forces"), "{text}");
}

#[test]
fn a_plugin_source_error_is_counted_and_the_source_goes_on() {
    let d = workdir("source-error");
    let g = source_graph(&d, "error_at = 3", "never");
    let json = d.join("stats.json");
    let o = skinflow(&d, &["run", g.to_str().unwrap(), "--stats-json", json.to_str().unwrap()]);
    ok(&o);
    // The erring poll emits nothing; the next poll emits the value it would have.
    assert_eq!(collected(&d), (1..=10).collect::<Vec<u64>>());
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let e = stderr(&o);
    let warning = e.lines().find(|l| l.contains("fixture source error at poll 3")).unwrap_or_else(|| panic!("{e}"));
    assert!(warning.contains(&format!("plugin kind \"fixture-count\" ({})", lib.display())), "{warning}");
    assert!(warning.contains("node=src"), "{warning}");
    let report = stats(&json);
    assert_eq!((count(&report, "src", "errors"), count(&report, "src", "msgs_out")), (1, 10));
}

#[test]
fn a_plugin_source_panic_stops_the_graph_without_restart() {
    let d = workdir("source-panic-never");
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let o = skinflow(&d, &["run", source_graph(&d, "panic_at = 5", "never").to_str().unwrap()]);
    assert!(!o.status.success(), "a panic without restart is a failure");
    let e = stderr(&o);
    assert!(e.contains("node \"src\""), "{e}");
    assert!(e.contains(&format!("plugin kind \"fixture-count\" ({})", lib.display())), "{e}");
    assert!(e.contains("fixture source panic at poll 5"), "{e}");
    assert_eq!(collected(&d), vec![1, 2, 3, 4], "values before the panic were delivered");
}

#[test]
fn a_plugin_source_panic_with_restart_always_rebuilds_the_source() {
    let d = workdir("source-panic-always");
    let json = d.join("stats.json");
    let g = source_graph(&d, "panic_at = 5", "always");
    ok(&skinflow(&d, &["run", g.to_str().unwrap(), "--stats-json", json.to_str().unwrap()]));
    // The rebuilt source starts again from 1 (the fixture panics in one instance only).
    let want: Vec<u64> = (1..=4).chain(1..=10).collect();
    assert_eq!(collected(&d), want);
    let report = stats(&json);
    assert_eq!((count(&report, "src", "panics"), count(&report, "src", "restarts")), (1, 1));
}

#[test]
fn a_paced_plugin_source_stops_promptly_on_run_for() {
    let d = workdir("source-stop");
    // Two samples an hour apart, paced at speed 1: only the stop request ends the wait.
    std::fs::write(d.join("slow.csv"), "t_s,kpa\n0,101.25\n3600,101.5\n").unwrap();
    let g = format!(
        "[graph]\nname = \"slow\"\nmode = \"realtime\"\n\n\
         [[plugin]]\npath = {}\n\n[[plugin]]\npath = {}\n\n\
         [[node]]\nid = \"daq\"\nkind = \"csv-pressure\"\nparams = {{ path = \"slow.csv\", speed = 1.0 }}\n\n\
         [[node]]\nid = \"out\"\nkind = \"pressure-csv\"\nparams = {{ path = \"got.csv\" }}\n\n\
         [[edge]]\nfrom = \"daq.pressure\"\nto = \"out.pressure\"\n",
        quoted(&plugin("skinflow-plugin-csv-pressure")),
        quoted(&plugin("skinflow-plugin-csv-writers"))
    );
    std::fs::write(d.join("slow.toml"), g).unwrap();
    let mut child = spawn(
        Command::new(bin())
            .args(["run", "slow.toml", "--for", "1"])
            .current_dir(&d)
            .env("RUST_LOG", "warn")
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped()),
    );
    // A guard against a hang, not a timing assertion: a source blocked for the hour would
    // keep the run alive far longer than this.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if std::time::Instant::now() > deadline {
            child.kill().unwrap();
            panic!("`run --for 1` did not end: the paced plugin source did not stop");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{err}");
    assert_eq!(std::fs::read_to_string(d.join("got.csv")).unwrap(), "t_s,kpa\n0,101.25\n", "the first sample only");
}

#[test]
fn a_plugin_source_that_cannot_build_names_node_kind_library_and_line() {
    let d = workdir("source-bad-file");
    let lib = plugin("skinflow-plugin-csv-pressure");
    std::fs::write(d.join("bad.csv"), "t_s,kpa\n0,101\n0.5,x\n").unwrap();
    let g = format!(
        "[graph]\nname = \"bad\"\nmode = \"lockstep\"\n\n[[plugin]]\npath = {}\n\n\
         [[node]]\nid = \"daq\"\nkind = \"csv-pressure\"\nparams = {{ path = \"bad.csv\" }}\n\n\
         [[node]]\nid = \"out\"\nkind = \"null\"\n\n[[edge]]\nfrom = \"daq.pressure\"\nto = \"out.in\"\n",
        quoted(&lib)
    );
    std::fs::write(d.join("bad.toml"), g).unwrap();
    let o = skinflow(&d, &["run", "bad.toml"]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert_eq!(e.trim().lines().count(), 1, "one line: {e}");
    assert!(e.contains("node \"daq\" (kind \"csv-pressure\")"), "{e}");
    assert!(e.contains(&format!("plugin kind \"csv-pressure\" ({})", lib.display())), "{e}");
    assert!(e.contains("bad.csv:3: kpa \"x\" is not a finite number"), "{e}");
}

/// A shipped graph (graphs/NAME) with this build's libraries, the tiny fixture scene and its
/// outputs in `dir`; `extra` appended to it.
fn shipped_csv_graph(dir: &Path, name: &str, extra: &str) -> PathBuf {
    let text = std::fs::read_to_string(root().join("graphs").join(name)).unwrap();
    let text = text
        .replace(
            "\"../target/debug/libskinflow_plugin_csv_writers.so\"",
            &quoted(&plugin("skinflow-plugin-csv-writers")),
        )
        .replace(
            "\"../target/debug/libskinflow_plugin_csv_pressure.so\"",
            &quoted(&plugin("skinflow-plugin-csv-pressure")),
        )
        .replace("\"scenes/multi-contact.toml\"", &quoted(&root().join("tests/fixtures/tiny-eval.toml")))
        .replace("\"calib/paper.toml\"", &quoted(&root().join("graphs/calib/paper.toml")))
        .replace("\"../out/", "\"");
    let unreplaced = text.lines().filter(|l| !l.starts_with('#') && l.contains("../")).collect::<Vec<_>>();
    assert!(unreplaced.is_empty(), "{name}: paths not replaced: {unreplaced:?}");
    let g = dir.join(name);
    std::fs::write(&g, text + extra).unwrap();
    g
}

/// Rows of a CSV file written by a csv-writers sink, as numbers (after its header line).
fn csv_rows(path: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap()).collect()).collect()
}

/// graphs/plugin-csv-out.toml, with an HDF5 logger beside the plugin sinks: the sinks' files
/// hold exactly what the pipeline produced (every force frame, every pressure sample, the same
/// values); then graphs/plugin-csv-in.toml replays the pressure file through the `csv-pressure`
/// source in place of the simulated pressure: every sample arrives, and the forces are the same.
#[test]
fn shipped_csv_graphs_write_and_replay_the_pipeline_exactly() {
    let d = workdir("csv");
    let logger = "\n[[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\n\
        params = { path = \"log.h5\", strategies = [\"pneumatic-locaware\"] }\n\n\
        [[edge]]\nfrom = \"correct.forces\"\nto = \"log.forces\"\ncapacity = 4096\n\n\
        [[edge]]\nfrom = \"sim.pressure\"\nto = \"log.pressure\"\ncapacity = 4096\n";
    let g = shipped_csv_graph(&d, "plugin-csv-out.toml", logger);
    let json = d.join("out.json");
    ok(&skinflow(&d, &["run", g.to_str().unwrap(), "--stats-json", json.to_str().unwrap()]));
    let report = stats(&json);
    let rec = read_recording(d.join("log.h5"));

    // Pressure: one row per sample, the logger's samples exactly.
    let pressure = csv_rows(&d.join("plugin-pressure.csv"));
    let logged = rec.pressure.as_ref().expect("pressure logged");
    assert!(logged.len() > 100, "the scene has pressure samples");
    assert_eq!(pressure.len(), logged.len());
    assert_eq!(count(&report, "pressure-out", "msgs_in"), logged.len() as u64);
    for (row, (t, kpa)) in pressure.iter().zip(logged.t_s.iter().zip(&logged.kpa)) {
        assert!((row[0] - t).abs() < 1e-9 && row[1] == *kpa, "{row:?} against ({t}, {kpa})");
    }

    // Forces: every frame the corrector produced reached the sink; each frame's contacts are
    // the logger's, in order, with the same forces.
    let frames = count(&report, "correct", "msgs_out");
    assert!(frames > 10, "the pipeline produced force frames");
    assert_eq!(count(&report, "forces-out", "msgs_in"), frames);
    assert_eq!(count(&report, "forces-out", "errors"), 0);
    let fs = rec.derived.forces.iter().find(|f| f.name == "pneumatic-locaware").expect("forces logged");
    assert_eq!(fs.t_s.len() as u64, frames);
    let rows = csv_rows(&d.join("plugin-forces.csv"));
    let frames_with_contacts = assert_forces_csv_is_the_log(&rows, fs);
    assert!(frames_with_contacts > 5, "frames with contacts: {frames_with_contacts}");

    // The pressure file through the plugin source in place of the simulated pressure.
    let g = shipped_csv_graph(&d, "plugin-csv-in.toml", "");
    let json = d.join("in.json");
    ok(&skinflow(&d, &["run", g.to_str().unwrap(), "--stats-json", json.to_str().unwrap()]));
    let report = stats(&json);
    assert_eq!(count(&report, "daq", "msgs_out"), pressure.len() as u64, "every sample of the file");
    let edge = report["edges"].as_array().unwrap().iter().find(|e| e["from"] == "daq.pressure").unwrap();
    assert_eq!((edge["pushed"].as_u64(), edge["drops"].as_u64()), (Some(pressure.len() as u64), Some(0)));
    assert_eq!(
        std::fs::read_to_string(d.join("plugin-forces-replayed.csv")).unwrap(),
        std::fs::read_to_string(d.join("plugin-forces.csv")).unwrap(),
        "the replayed pressure gives the same forces"
    );
}

/// Checks that the rows of a `forces-csv` file (parsed as numbers: t_s in column 1, the
/// contact's index in 2, its force in 7) are, frame by frame and contact by contact, the forces
/// an `hdf5_logger` recorded as `fs`, with no row twice and none of a frame the pipeline did
/// not produce; returns how many frames had contacts.
pub(super) fn assert_forces_csv_is_the_log(rows: &[Vec<f64>], fs: &skinflow_record::read::ForceStream) -> usize {
    let mut next = 0;
    let mut frames_with_contacts = 0;
    for (i, t) in fs.t_s.iter().enumerate() {
        let logged: Vec<f64> = fs.force_n[i * fs.max_contacts..(i + 1) * fs.max_contacts]
            .iter()
            .copied()
            .filter(|f| !f.is_nan())
            .collect();
        let frame: Vec<&Vec<f64>> = rows[next..].iter().take_while(|r| (r[1] - t).abs() < 1e-9).collect();
        next += frame.len();
        assert_eq!(frame.len(), logged.len(), "frame at {t} s: one row per contact");
        for (k, (row, f)) in frame.iter().zip(&logged).enumerate() {
            assert_eq!((row[2], row[7]), (k as f64, *f), "frame at {t} s, contact {k}");
        }
        frames_with_contacts += usize::from(!logged.is_empty());
    }
    assert_eq!(next, rows.len(), "no row twice, none of a frame the pipeline did not produce");
    frames_with_contacts
}

// The run-time hooks: graphs run in this process (lockstep), with built libraries loaded into
// the registry, a source held behind a gate while commands and swaps are sent.

/// The built-in kinds, `capture` (into `captured`), the plugins `libs`, and `gated`: source
/// kind `kind` behind `gate`.
fn gated_registry(libs: &[PathBuf], captured: Captured, kind: &str, gate: &Arc<Gate>) -> Registry {
    let mut reg = registry_with_capture(captured);
    skinflow_nodes::codec::load_plugins(libs, &mut reg).expect("the plugins load");
    gate::register(&mut reg, kind, "gated", gate.clone());
    reg
}

/// Plugin `lib` loaded again, from a copy in `dir/rebuilt/` (as a rebuilt library is another
/// file), into a registry of its own.
fn loaded_again(lib: &Path, dir: &Path) -> Registry {
    let rebuilt = dir.join("rebuilt");
    std::fs::create_dir_all(&rebuilt).unwrap();
    let copy = rebuilt.join(lib.file_name().unwrap());
    std::fs::copy(lib, &copy).unwrap();
    let mut reg = Registry::new();
    skinflow_nodes::codec::load_plugins(&[copy], &mut reg).expect("the copy loads");
    reg
}

/// Runs `graph` (a lockstep graph file's text, in `dir`) on `reg`; `at_gate` drives the
/// running graph (the gate is its business); returns the report.
fn run_in_process(dir: &Path, reg: &Registry, graph: &str, at_gate: impl FnOnce(&GraphHandle)) -> RunReport {
    let spec = GraphSpec::parse(SourceFile::new(dir.join("graph.toml"), graph.to_owned()), reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let runner = std::thread::spawn(move || running.wait(&RunOptions::default()));
    at_gate(&handle);
    let report = runner.join().unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    report
}

const WAIT: Duration = Duration::from_secs(300);

/// The captured messages as (seq, t_ns, value) of a `count` or `pressure` payload.
fn captured_values(captured: &Captured) -> Vec<(u64, u64, f64)> {
    let rows = captured.lock().unwrap();
    rows.iter()
        .flatten()
        .map(|m| {
            let v = m
                .get::<skinflow_core::toy::Count>()
                .map(|c| c.0 as f64)
                .or_else(|| m.get::<PressureSample>().map(|p| p.kpa))
                .expect("a count or a pressure sample");
            (m.header.seq, m.header.t_ns, v)
        })
        .collect()
}

/// gated fixture-count (20 values, held after 10) -> scale (fixture-scale) -> capture.
#[test]
fn a_command_to_a_plugin_node_is_applied_and_a_bad_one_is_refused_naming_the_node() {
    let d = workdir("control");
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let gate = Gate::new(Some(10), None);
    let reg = gated_registry(std::slice::from_ref(&lib), captured.clone(), "fixture-count", &gate);
    let graph = "[graph]\nmode = \"lockstep\"\n\
        [[node]]\nid = \"src\"\nkind = \"gated\"\nparams = { count = 20 }\n\
        [[node]]\nid = \"scale\"\nkind = \"fixture-scale\"\nparams = { factor = 1 }\n\
        [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
        [[edge]]\nfrom = \"src.out\"\nto = \"scale.in\"\n[[edge]]\nfrom = \"scale.out\"\nto = \"cap.in\"\n";
    let kind = |k: &str| format!("plugin kind \"{k}\" ({})", lib.display());
    run_in_process(&d, &reg, graph, |h| {
        gate.wait_held();
        h.control_wait("scale", "factor 3", WAIT).expect("applied");
        let e = h.control_wait("scale", "factor x", WAIT).unwrap_err().to_string();
        assert!(e.contains("node \"scale\""), "{e}");
        assert!(
            e.contains(&format!(
                "{}: node \"scale\": factor: \"x\" is not a non-negative integer",
                kind("fixture-scale")
            )),
            "{e}"
        );
        // fixture-count has no control command (the SDK's default): refused, clearly.
        let e = h.control_wait("src", "tare", WAIT).unwrap_err().to_string();
        assert!(
            e.contains(&format!(
                "{}: node \"src\": control command \"tare\" is not supported: this kind takes no control commands",
                kind("fixture-count")
            )),
            "{e}"
        );
        gate.raise(u64::MAX);
    });
    let values: Vec<f64> = captured_values(&captured).into_iter().map(|(_, _, v)| v).collect();
    let want: Vec<f64> = (1..=20).map(|v| if v <= 10 { v } else { 3 * v } as f64).collect();
    assert_eq!(values, want, "factor 1 before the command, 3 after; the bad command changed nothing");
}

/// gated csv-pressure (held after 12 of 30 samples) -> capture; swapped to csv-pressure of
/// the library loaded again from another file.
#[test]
fn a_csv_pressure_source_swapped_to_a_rebuilt_library_goes_on_without_duplicates() {
    let d = workdir("swap-csv");
    let lib = plugin("skinflow-plugin-csv-pressure");
    let rows: Vec<(f64, f64)> = (0..30).map(|i| (0.01 * f64::from(i), 100.0 + f64::from(i) / 4.0)).collect();
    let text: String = rows.iter().map(|(t, kpa)| format!("{t},{kpa}\n")).collect();
    std::fs::write(d.join("p.csv"), format!("t_s,kpa\n{text}")).unwrap();
    std::fs::write(d.join("other.csv"), format!("t_s,kpa\n{text}")).unwrap();
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let gate = Gate::new(Some(12), None);
    let reg = gated_registry(std::slice::from_ref(&lib), captured.clone(), "csv-pressure", &gate);
    let again = loaded_again(&lib, &d);
    let rebuilt = again.get("csv-pressure").unwrap().clone();
    let graph = "[graph]\nmode = \"lockstep\"\n\
        [[node]]\nid = \"src\"\nkind = \"gated\"\nparams = { path = \"p.csv\", speed = 0.0 }\n\
        [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
        [[edge]]\nfrom = \"src.pressure\"\nto = \"cap.in\"\ncapacity = 64\n";
    let params = |path: &str| Params::from_toml(&format!("path = \"{path}\"\nspeed = 0.0")).unwrap();
    let report = run_in_process(&d, &reg, graph, |h| {
        gate.wait_held();
        // The plugin's command; a bad value is refused, naming the node.
        h.control_wait("src", "speed 2", WAIT).expect("applied");
        let e = h.control_wait("src", "speed -1", WAIT).unwrap_err().to_string();
        assert!(e.contains("node \"src\": ") && e.contains("speed: must be a finite number >= 0 (got -1)"), "{e}");
        // Another file: it would start at its first sample, so the swap is refused.
        let e = h.swap_wait("src", rebuilt.clone(), params("other.csv"), WAIT).unwrap_err().to_string();
        assert!(e.contains("node \"src\": swap refused: "), "{e}");
        assert!(
            e.contains(&format!(
                "the replacement reads {}, the running csv-pressure {}: it would start again",
                d.join("other.csv").display(),
                d.join("p.csv").display()
            )),
            "{e}"
        );
        // The same file, from the rebuilt library: it takes the running source's position and
        // runs to the end of the file (it is not behind the gate).
        h.swap_wait("src", rebuilt.clone(), params("p.csv"), WAIT).expect("installed");
    });
    let got = captured_values(&captured);
    let want: Vec<(u64, u64, f64)> =
        rows.iter().enumerate().map(|(i, &(t, kpa))| (i as u64 + 1, (t * 1e9).round() as u64, kpa)).collect();
    assert_eq!(got, want, "every sample once, in order: no duplicate, no time going back");
    let src = report.stats.nodes.iter().find(|n| n.id == "src").unwrap();
    assert_eq!((src.swaps, src.errors, src.msgs_out), (1, 0, 30), "{src:?}");
}

/// gated fixture-count (30 values) -> x -> capture: x starts as fixture-scale (its state: its
/// call count, one u64), is swapped after 10 values to fixture-sum (whose state is one u64
/// too) of the library loaded again, then after 20 to fixture-sum of the first load.
#[test]
fn a_plugin_node_takes_over_its_own_kinds_state_and_not_another_kinds() {
    let d = workdir("swap-kinds");
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let gate = Gate::new(Some(10), None);
    let reg = gated_registry(std::slice::from_ref(&lib), captured.clone(), "fixture-count", &gate);
    let again = loaded_again(&lib, &d);
    let graph = "[graph]\nmode = \"lockstep\"\n\
        [[node]]\nid = \"src\"\nkind = \"gated\"\nparams = { count = 30 }\n\
        [[node]]\nid = \"x\"\nkind = \"fixture-scale\"\n\
        [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
        [[edge]]\nfrom = \"src.out\"\nto = \"x.in\"\n[[edge]]\nfrom = \"x.out\"\nto = \"cap.in\"\n";
    let report = run_in_process(&d, &reg, graph, |h| {
        gate.wait_held();
        // fixture-scale's state (10 calls) is not a sum: fixture-sum starts afresh.
        h.swap_wait("x", again.get("fixture-sum").unwrap().clone(), Params::empty(), WAIT).expect("installed");
        gate.raise(20);
        gate.wait_held();
        // fixture-sum to fixture-sum (another load of the library): the sum goes on.
        h.swap_wait("x", reg.get("fixture-sum").unwrap().clone(), Params::empty(), WAIT).expect("installed");
        gate.raise(u64::MAX);
    });
    let values: Vec<u64> = captured_values(&captured).into_iter().map(|(_, _, v)| v as u64).collect();
    let sums = (11..=30u64).scan(0, |sum, v| {
        *sum += v;
        Some(*sum)
    });
    let want: Vec<u64> = (1..=10).chain(sums).collect();
    assert_eq!(values, want, "values, then their sum from 11 on, unbroken across the second swap");
    let x = report.stats.nodes.iter().find(|n| n.id == "x").unwrap();
    assert_eq!((x.swaps, x.errors), (2, 0), "{x:?}");
}

/// A recording without truth gives speed without error: bench writes its tables (every lane's
/// latency, no RMSE) and succeeds without a Pareto plot, naming the recording; it used to fail
/// after writing them, as if the run had not finished.
#[test]
fn bench_of_a_recording_without_truth_reports_speed_and_draws_no_plot() {
    let d = bench_workdir("bench-no-truth");
    hdf5_io(|| hdf5::File::open_rw(d.join("rec.h5")).unwrap().unlink("/truth").unwrap());
    let o = bench(&d, &["recon.lambda=0.1"]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("rec.h5 has no truth, or no lane scored a frame): wrote bench.md and bench.json"), "{err}");
    assert!(!d.join("out/pareto.png").exists());
    let json = json_file(&d.join("out/bench.json"));
    let points = json["points"].as_array().unwrap();
    assert!(!points.is_empty(), "{json}");
    assert!(points.iter().all(|p| p["latency_us_p50"].is_number() && p["rmse_n"].is_null()), "{json}");
}
