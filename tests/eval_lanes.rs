//! `skinflow eval --plugin LIB --lane SPEC` through the binary: lanes of plugin kinds (the
//! example splitter and corrector) evaluated beside the built-in nine in the table, the JSON,
//! the per-contact CSV, the plots and the printed graph; a lane of built-in strategies giving
//! exactly the figures of the built-in lane it repeats; every refused `--lane` as one line
//! naming it, before any work; a plugin failing while the pipeline runs named by its lane.
//!
//! The recordings (the small fixture scenes) and their calibration are made once and shared
//! by the tests of this module; the plugin libraries are found (or built) as tests/plugins.rs
//! does.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use super::plugins::plugin;
use super::support::{fixture, ok, skinflow, stderr};

/// A directory holding `cal.h5`, `test.h5` (tiny-eval: single and two-contact presses) and
/// `calib.toml`, made once per test process.
fn shared() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = super::support::workdir("eval-lanes", "shared");
        for (scene, out) in [("tiny-calibration.toml", "cal.h5"), ("tiny-eval.toml", "test.h5")] {
            ok(&skinflow(&d, &["simulate", fixture(scene).to_str().unwrap(), "--out", out, "--seed", "3"]));
        }
        ok(&skinflow(&d, &["calibrate", "cal.h5", "--out", "calib.toml"]));
        d
    })
}

/// A fresh work directory for one test, and the arguments `eval <test.h5> --calib <calib>`.
fn setup(test: &str) -> (PathBuf, Vec<String>) {
    let s = shared();
    let d = super::support::workdir("eval-lanes", test);
    let path = |f: &str| s.join(f).to_string_lossy().into_owned();
    (d, vec!["eval".into(), path("test.h5"), "--calib".into(), path("calib.toml")])
}

fn run(d: &Path, args: &[String]) -> std::process::Output {
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    skinflow(d, &args)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn lib(package: &str) -> String {
    plugin(package).to_string_lossy().into_owned()
}

const SPLIT_WEIGHTED: &str = "skinflow-plugin-split-weighted";
const CORRECT_FUSED: &str = "skinflow-plugin-correct-fused";

/// The metrics of strategy `name` that do not depend on timing.
fn figures(v: &serde_json::Value, name: &str) -> Vec<serde_json::Value> {
    let s = &v["strategies"][name];
    assert!(s.is_object(), "strategy {name} missing: {v}");
    vec![
        s["rmse_n"].clone(),
        s["rmse_sd_n"].clone(),
        s["per_diameter_rmse_n"].clone(),
        s["relative_error_pct"].clone(),
        v["multi_contact"]["per_contact_rmse_n"][name].clone(),
    ]
}

#[test]
fn plugin_lanes_are_evaluated_beside_the_built_in_ones() {
    let (d, base) = setup("plugins");
    let mut args = base.clone();
    args.extend(
        [
            "--plugin",
            &lib(SPLIT_WEIGHTED),
            "--plugin",
            &lib(CORRECT_FUSED),
            "--lane",
            r#"name = "peak2", split = "peak-weighted-splitter", split_params = { exponent = 2.0 }"#,
            "--lane",
            r#"name = "fused", correct = "fused-corrector", correct_params = { weight_pneumatic = 0.8 }"#,
            // The same plugin splitter and params as peak2: one node; other params: another.
            "--lane",
            r#"name = "peak2-eit", split = "peak-weighted-splitter", split_params = { exponent = 2.0 }, correct = "eit-nocal""#,
            "--lane",
            r#"name = "peak3", split = "peak-weighted-splitter", split_params = { exponent = 3.0 }, label = "Peak^3 split""#,
            "--json",
            "e.json",
            "--contacts-csv",
            "c.csv",
            "--plots",
            "plots",
            "--print-graph",
        ]
        .map(String::from),
    );
    let out = ok(&run(&d, &args));
    let v = json(&d.join("e.json"));
    let strategies = v["strategies"].as_object().unwrap();
    assert_eq!(strategies.len(), 9 + 4, "{v}");
    for name in ["peak2", "fused", "peak2-eit", "peak3"] {
        let s = &v["strategies"][name];
        for key in ["rmse_n", "rmse_sd_n", "relative_error_pct", "latency_us_p50", "latency_us_p99"] {
            let x = s[key].as_f64().unwrap_or_else(|| panic!("{name}.{key} is not a number: {v}"));
            assert!(x.is_finite() && x >= 0.0, "{name}.{key} = {x}");
        }
        assert!(s["latency_us_p50"].as_f64().unwrap() > 0.0, "{name}: no latency measured: {v}");
        assert!(!s["per_diameter_rmse_n"].as_object().unwrap().is_empty(), "{name}: {v}");
        assert!(v["multi_contact"]["per_contact_rmse_n"][name].as_f64().is_some(), "{name}: {v}");
    }
    // The plugins ran: their estimates differ from the built-in lanes they vary.
    assert_ne!(figures(&v, "fused"), figures(&v, "pneumatic-locaware"));
    assert_ne!(figures(&v, "peak2"), figures(&v, "pneumatic-locaware"));
    assert_ne!(figures(&v, "peak2"), figures(&v, "peak3"));
    // Extra lanes change nothing of the built-in ones (nor the default output's figures).
    let plain = ok(&run(&d, &[base, vec!["--json".into(), "plain.json".into()]].concat()));
    let p = json(&d.join("plain.json"));
    assert_eq!(p["strategies"].as_object().unwrap().len(), 9);
    for name in p["strategies"].as_object().unwrap().keys() {
        assert_eq!(figures(&p, name), figures(&v, name), "{name}");
    }
    assert!(!plain.contains("(plugin)") && !plain.contains("[[plugin]]"), "{plain}");
    // The table: a row per lane, labelled.
    for label in ["peak2 (plugin)", "fused (plugin)", "peak2-eit (plugin)", "Peak^3 split"] {
        assert!(out.lines().any(|l| l.starts_with(label)), "no row {label:?}:\n{out}");
    }
    // The per-contact CSV: a force column per lane, filled for every matched contact.
    let csv = std::fs::read_to_string(d.join("c.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header[header.len() - 4..], ["peak2_n", "fused_n", "peak2-eit_n", "peak3_n"]);
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let matched: Vec<&Vec<&str>> = rows.iter().filter(|r| r[2] == "matched").collect();
    assert_eq!(matched.len() as u64, v["localization"]["matched"].as_u64().unwrap());
    for r in &matched {
        assert_eq!(r.len(), header.len(), "ragged CSV");
        for f in &r[r.len() - 4..] {
            assert!(f.parse::<f64>().is_ok_and(f64::is_finite), "force column {f:?} in {r:?}");
        }
    }
    // The predicted-against-true plot has a panel per lane (it is drawn at all).
    assert!(d.join("plots/predicted_vs_true.png").is_file());
    // And the others: the fields, the localization map and a frame's regions (drawn as the
    // pipeline's segmenter cut them, `segment::segment_image`).
    for png in ["fields.png", "localization.png", "conductivity.png"] {
        assert!(d.join("plots").join(png).is_file(), "{png}");
    }
    // The printed graph: the libraries, the plugin kinds, one node per distinct splitter.
    assert!(out.contains("[[plugin]]\npath = "), "{out}");
    assert_eq!(out.matches("kind = \"peak-weighted-splitter\"").count(), 2, "{out}");
    assert!(out.contains(
        "id = \"split-peak-weighted-splitter\"\nkind = \"peak-weighted-splitter\"\nparams = { exponent = 2.0 }"
    ));
    assert!(out.contains("from = \"split-peak-weighted-splitter.split\"\nto = \"correct-peak2-eit.split\""), "{out}");
    // The plugin corrector got eval's --calib and the lane's name.
    let fused = out.lines().skip_while(|l| *l != "id = \"correct-fused\"").nth(2).unwrap_or_default();
    assert!(
        fused.contains("calibration = ") && fused.contains("calib.toml") && fused.contains("name = \"fused\""),
        "{fused}"
    );
}

#[test]
fn a_lane_of_built_in_strategies_gives_the_built_in_lanes_figures() {
    let (d, mut args) = setup("builtin");
    args.extend(
        [
            "--lane",
            r#"name = "fb", split = "force-balance", correct = "pneumatic-forward""#,
            // The built-in kinds named as kinds, with their params.
            "--lane",
            r#"name = "sens", split = "splitter", split_params = { strategy = "sensitivity-compensated" }, correct = "corrector""#,
            "--lane",
            r#"name = "nocal", correct = "eit-nocal""#,
            "--json",
            "e.json",
        ]
        .map(String::from),
    );
    let out = ok(&run(&d, &args));
    let v = json(&d.join("e.json"));
    assert_eq!(figures(&v, "fb"), figures(&v, "pneumatic-forward-balance"));
    assert_eq!(figures(&v, "sens"), figures(&v, "pneumatic-locaware-sensitivity"));
    assert_eq!(figures(&v, "nocal"), figures(&v, "eit-nocal"));
    assert!(v["strategies"]["fb"]["rmse_n"].as_f64().is_some_and(f64::is_finite), "{v}");
    // No plugin kind: labelled by name alone.
    assert!(out.lines().any(|l| l.starts_with("fb ")), "{out}");
    assert!(!out.contains("(plugin)"), "{out}");
}

#[test]
fn refused_lanes_name_the_lane_and_the_cause_before_any_work() {
    let (d, base) = setup("refused");
    let split_weighted = lib(SPLIT_WEIGHTED);
    let faulty = lib("skinflow-plugin-fixture-faulty");
    let cases: Vec<(Vec<&str>, &str, &str)> = vec![
        (vec![], r#"name = "x", split = "nope""#, "split \"nope\": unknown"),
        (
            vec![],
            r#"name = "x", correct = "fused-corrector""#,
            "no plugin is loaded (load a library with --plugin LIB)",
        ),
        (
            vec!["--plugin", &split_weighted],
            r#"name = "x", correct = "nope""#,
            "plugin kinds: area-weighted-splitter, peak-weighted-splitter",
        ),
        (vec!["--plugin", &faulty], r#"name = "x", split = "fixture-scale""#, "does not fit as a splitter"),
        (
            vec!["--plugin", &split_weighted],
            r#"name = "x", correct = "area-weighted-splitter""#,
            "a corrector needs an input of type \"split\"",
        ),
        (vec![], r#"name = "x", split = "segmenter""#, "its inputs: image (image)"),
        (vec![], r#"name = "pneumatic-locaware""#, "is a built-in lane's"),
        (vec![], r#"name = "x" split = "force-balance""#, "not a TOML table body"),
        (vec![], r#"name = "x", colour = "red""#, "unknown field `colour`"),
        (vec![], r#"split = "force-balance""#, "missing field `name`"),
        (vec![], r#"name = "a b""#, "use ASCII letters, digits"),
        // Params the kind refuses, found when the graph is checked: named by the lane too.
        (
            vec!["--plugin", &split_weighted],
            r#"name = "x", split = "peak-weighted-splitter", split_params = { exponent = 9.0 }"#,
            "param \"exponent\": must be in [0, 4]",
        ),
        (
            vec!["--plugin", &split_weighted],
            r#"name = "x", split = "peak-weighted-splitter", split_params = { exponant = 2.0 }"#,
            "unknown field `exponant`",
        ),
    ];
    for (extra, lane, cause) in cases {
        let mut args = base.clone();
        args.extend(extra.iter().map(|s| s.to_string()));
        args.extend(["--lane".into(), lane.into(), "--json".into(), "e.json".into()]);
        let out = run(&d, &args);
        let err = stderr(&out);
        assert!(!out.status.success(), "{lane}: accepted");
        let line = err.lines().find(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("{lane}: {err}"));
        assert!(line.starts_with(&format!("error: --lane '{lane}': ")) && line.contains(cause), "{lane}: {err}");
        assert!(!err.contains("<pipeline>"), "{lane}: the generated graph is named: {err}");
        assert!(!d.join("e.json").exists(), "{lane}: evaluated anyway");
    }
    // Two lanes of one name: the second is refused, naming the first.
    let mut args = base.clone();
    args.extend(["--lane", r#"name = "a""#, "--lane", r#"name = "a", correct = "eit-nocal""#].map(String::from));
    let err = stderr(&run(&d, &args));
    assert!(
        err.contains(r#"--lane 'name = "a", correct = "eit-nocal"': name "a" is also the name of --lane 'name = "a"'"#),
        "{err}"
    );
    // One library twice (another spelling): refused as such, not as its kinds defined twice.
    let mut args = base.clone();
    let again = format!(
        "{}/./{}",
        Path::new(&split_weighted).parent().unwrap().display(),
        Path::new(&split_weighted).file_name().unwrap().to_string_lossy()
    );
    args.extend(["--plugin", &split_weighted, "--plugin", &again, "--lane", r#"name = "x""#].map(String::from));
    let err = stderr(&run(&d, &args));
    assert!(err.contains(&format!("plugin {again}: given twice (also as {split_weighted})")), "{err}");
    // A library that does not exist.
    let mut args = base;
    args.extend(["--plugin", "no-such.so", "--lane", r#"name = "x""#].map(String::from));
    let out = run(&d, &args);
    assert!(!out.status.success() && stderr(&out).contains("--plugin: plugin no-such.so: file not found"));
}

/// A lane's node that fails while the pipeline runs is named by its lane: an error on some
/// frames, one force too few, frames without forces (which the capture cannot align, so the
/// other lanes' messages are dropped: the lane that sent too few is named, not the drops).
/// Before the error, the statistics of the pipeline's nodes at the failure go to stderr: the
/// failing node's line shows what it received, sent and failed on. A run that succeeds prints
/// none.
#[test]
fn a_plugin_failing_in_the_pipeline_is_named_by_its_lane() {
    let (d, base) = setup("failing");
    let faulty = lib("skinflow-plugin-fixture-faulty");
    for (mode, cause) in
        [("error", "calls failed"), ("short", "calls failed"), ("skip", "each lane must send one message per frame")]
    {
        let mut args = base.clone();
        let lane = format!(r#"name = "bad", correct = "fixture-forces", correct_params = {{ mode = "{mode}" }}"#);
        args.extend(["--plugin".into(), faulty.clone(), "--lane".into(), lane, "--json".into(), "e.json".into()]);
        let out = run(&d, &args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{mode}: {err}");
        let lines: Vec<&str> = err.lines().collect();
        let error = lines.iter().position(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("{mode}: {err}"));
        let line = lines[error];
        assert!(line.contains("test.h5: pipeline: lane \"bad\": node \"correct-bad\""), "{mode}: {line}");
        assert!(line.contains(cause), "{mode}: {line}");
        assert_eq!(lines.iter().filter(|l| l.starts_with("error: ")).count(), 1, "{mode}: {err}");
        assert!(!d.join("e.json").exists(), "{mode}: a report was written");

        // The statistics at the failure, before the error: the graph's line, the header, then
        // every node of the pipeline.
        let label = lines
            .iter()
            .position(|l| l.contains(AT_FAILURE))
            .unwrap_or_else(|| panic!("{mode}: no statistics at the failure: {err}"));
        assert!(label < error, "{mode}: the statistics come after the error: {err}");
        assert!(lines[label].ends_with(&format!("test.h5{AT_FAILURE} (what each had done when the run ended):")));
        assert!(lines[label + 1].starts_with("graph \"pipeline\" (Lockstep), "), "{mode}: {err}");
        let header = ["node", "kind", "calls", "in", "out", "p50", "us", "p99", "us", "max", "us", "depth", "drops"];
        assert!(lines[label + 2].split_whitespace().eq(header.into_iter().chain(["miss", "err"])), "{mode}: {err}");
        let table = lines[label..error].join("\n");
        for id in ["replay", "sync", "recon", "segment", "split-proportional", "correct-pneumatic-locaware", "capture"]
        {
            assert!(node_stats(&table, id).is_some(), "{mode}: no line of node {id}: {table}");
        }
        let good = node_stats(&table, "correct-pneumatic-locaware").unwrap();
        let bad =
            node_stats(&table, "correct-bad").unwrap_or_else(|| panic!("{mode}: no line of correct-bad: {table}"));
        assert_eq!(bad.kind, "fixture-forces", "{mode}");
        // Every split reached the failing lane's corrector as it reached a built-in lane's.
        assert!(bad.msgs_in > 0 && bad.msgs_in == good.msgs_in && bad.calls == bad.msgs_in, "{mode}: {bad:?} {good:?}");
        // The count of failed calls the error gives.
        let failed_calls = || -> u64 {
            let head = line.split(" of ").next().unwrap();
            head.rsplit(' ').next().unwrap().parse().unwrap_or_else(|_| panic!("{line}"))
        };
        match mode {
            // An error on every third frame: nothing sent for it.
            "error" => {
                assert_eq!(bad.errors, bad.msgs_in / 3, "{bad:?}");
                assert_eq!(bad.msgs_out, bad.msgs_in - bad.errors, "{bad:?}");
                assert_eq!(failed_calls(), bad.errors, "{line}");
            }
            // One force too few: refused by the host on every frame with contacts.
            "short" => {
                assert!(bad.errors > 0 && bad.msgs_out + bad.errors == bad.msgs_in, "{bad:?}");
                assert_eq!(failed_calls(), bad.errors, "{line}");
            }
            // Nothing on every third frame: no error, fewer forces out, and the capture's drops.
            _ => {
                assert_eq!(bad.errors, 0, "{bad:?}");
                assert_eq!(bad.msgs_out, bad.msgs_in - bad.msgs_in / 3, "{bad:?}");
                assert!(line.contains(&format!("sent forces for {} of {} frames", bad.msgs_out, bad.msgs_in)));
                assert!(node_stats(&table, "capture").unwrap().drops > 0, "{table}");
                assert!(table.contains("drops by edge:\n") && table.contains(" -> capture.in "), "{table}");
            }
        }
    }
    // The same kind behaving (1 N per contact) is scored, and no statistics are printed.
    let mut args = base;
    args.extend(
        ["--plugin", &faulty, "--lane", r#"name = "one", correct = "fixture-forces""#, "--json", "e.json"]
            .map(String::from),
    );
    let out = run(&d, &args);
    ok(&out);
    let err = stderr(&out);
    assert!(!err.contains(AT_FAILURE) && !err.contains("graph \"pipeline\""), "{err}");
    assert!(json(&d.join("e.json"))["strategies"]["one"]["rmse_n"].as_f64().is_some_and(f64::is_finite));
}

/// The label of the statistics printed at a pipeline's failure (after the recording's path).
const AT_FAILURE: &str = ": the pipeline failed; statistics of its nodes at the failure";

/// A node's line of the printed statistics table.
#[derive(Debug)]
struct NodeStats {
    kind: String,
    calls: u64,
    msgs_in: u64,
    msgs_out: u64,
    drops: u64,
    errors: u64,
}

/// The line of node `id` in the statistics table `table` (columns: node, kind, calls, in, out,
/// p50 us, p99 us, max us, depth, drops, miss, err).
fn node_stats(table: &str, id: &str) -> Option<NodeStats> {
    let line =
        table.lines().skip_while(|l| !l.starts_with("node ")).find(|l| l.split_whitespace().next() == Some(id))?;
    let cols: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(cols.len(), 12, "{line}");
    let n = |i: usize| cols[i].parse::<u64>().unwrap_or_else(|_| panic!("column {i} of {line:?}"));
    Some(NodeStats { kind: cols[1].to_owned(), calls: n(2), msgs_in: n(3), msgs_out: n(4), drops: n(9), errors: n(11) })
}

/// A plugin kind whose name is no valid node id (`fixture.dot`) still makes a lane: the
/// generated graph's ids are made of valid characters.
#[test]
fn a_plugin_kind_of_any_name_makes_a_lane() {
    let (d, mut args) = setup("dot");
    args.extend(
        [
            "--plugin",
            &lib("skinflow-plugin-fixture-faulty"),
            "--lane",
            r#"name = "equal", split = "fixture.dot""#,
            "--json",
            "e.json",
        ]
        .map(String::from),
    );
    let out = run(&d, &args);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(json(&d.join("e.json"))["strategies"]["equal"]["rmse_n"].as_f64().is_some_and(f64::is_finite));
}

/// A lane's calibration gets the checks `--calib` gets: one that does not exist, or was fitted
/// on another sensor, is refused before any frame is run, naming the lane.
#[test]
fn a_lanes_own_calibration_is_checked_like_calib() {
    let (d, base) = setup("lane-calibration");
    let calib = std::fs::read_to_string(shared().join("calib.toml")).unwrap();
    assert!(calib.contains("electrodes = 16"), "{calib}");
    std::fs::write(d.join("other.toml"), calib.replace("electrodes = 16", "electrodes = 32")).unwrap();
    let faulty = lib(CORRECT_FUSED);
    for (lane, cause) in [
        (
            r#"name = "o", correct = "pneumatic-forward", correct_params = { calibration = "other.toml" }"#,
            "calibration other.toml: fitted on sensor",
        ),
        (
            r#"name = "o", correct = "fused-corrector", correct_params = { calibration = "other.toml" }"#,
            "calibration other.toml: fitted on sensor",
        ),
        (
            r#"name = "o", correct = "fused-corrector", correct_params = { calibration = "missing.toml" }"#,
            "missing.toml",
        ),
    ] {
        let mut args = base.clone();
        args.extend(["--plugin", &faulty, "--lane", lane, "--json", "e.json"].map(String::from));
        let out = run(&d, &args);
        let err = stderr(&out);
        assert!(!out.status.success(), "{lane}: {err}");
        let line = err.lines().find(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("{lane}: {err}"));
        assert!(line.starts_with(&format!("error: --lane '{lane}': calibration")), "{lane}: {line}");
        assert!(line.contains(cause), "{lane}: {line}");
        assert!(!d.join("e.json").exists(), "{lane}: evaluated anyway");
    }
}

/// `--json`, `--contacts-csv` and `--plots` may not be a `--plugin` library or a file a lane
/// reads (before, the library was replaced by the JSON); both are kept.
#[test]
fn eval_outputs_over_a_plugin_library_or_a_lane_file_are_refused() {
    let (d, base) = setup("outputs");
    std::fs::copy(plugin(CORRECT_FUSED), d.join("fused.so")).unwrap();
    std::fs::copy(shared().join("calib.toml"), d.join("mine.toml")).unwrap();
    let (lib_bytes, calib_bytes) =
        (std::fs::read(d.join("fused.so")).unwrap(), std::fs::read(d.join("mine.toml")).unwrap());
    let lane = r#"name = "f", correct = "fused-corrector", correct_params = { calibration = "mine.toml" }"#;
    for (flag, file, cause) in [
        ("--json", "fused.so", "is the --plugin library ./fused.so"),
        ("--contacts-csv", "./mine.toml", "is the file correct_params.calibration of --lane \"f\" mine.toml"),
        ("--plots", "mine.toml", "is an input file"),
    ] {
        let mut args = base.clone();
        args.extend(["--plugin", "./fused.so", "--lane", lane, flag, file].map(String::from));
        let out = run(&d, &args);
        let err = stderr(&out);
        assert!(!out.status.success(), "{flag}: {err}");
        assert!(err.contains(&format!("{flag} {file}: ")) && err.contains(cause), "{flag}: {err}");
    }
    assert_eq!(std::fs::read(d.join("fused.so")).unwrap(), lib_bytes, "the library is kept");
    assert_eq!(std::fs::read(d.join("mine.toml")).unwrap(), calib_bytes, "the calibration is kept");
}

/// Rows and plot panels are told apart by their labels: an empty one, a built-in lane's and
/// one another `--lane` has are refused.
#[test]
fn lane_labels_must_tell_the_lanes_apart() {
    let (d, base) = setup("labels");
    for (lanes, cause) in [
        (vec![r#"name = "a", label = " ""#], "label is empty"),
        (vec![r#"name = "a", label = "Pneumatic-Forward""#], "is the built-in lane pneumatic-forward's"),
        (vec![r#"name = "a", label = "x""#, r#"name = "b", label = "x""#], "is also the label of --lane"),
    ] {
        let mut args = base.clone();
        for l in &lanes {
            args.extend(["--lane".to_owned(), (*l).to_owned()]);
        }
        let err = stderr(&run(&d, &args));
        assert!(err.contains(cause), "{lanes:?}: {err}");
        assert!(err.contains(&format!("--lane '{}'", lanes.last().unwrap())), "{err}");
    }
}
