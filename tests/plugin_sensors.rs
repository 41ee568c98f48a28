//! A plugin EIT source names the sensor of its frames with a param of type `sensor`
//! (`skinflow_plugin_sdk::export::SENSOR`), and `skinflow check` (and `run`, before any node
//! starts) holds a reconstructor it feeds to that sensor, as for a `replay` recording or a `sim`
//! scene: the same sensor passes (or one of the same geometry, whatever its name), another is
//! refused naming the plugin node, the reconstructor and both sensors, and a sensor file that
//! cannot be read is refused at the plugin's param. On the `fixture-eit` kind of the faulty
//! fixture library (plugins/fixtures/faulty).

use std::path::{Path, PathBuf};

use super::plugins::plugin;
use super::support::{ok, skinflow, stderr, text};

/// A fresh work directory for one test of this module, holding `small.toml`, a 60 mm sensor,
/// and `paper.toml`, a sensor of `paper-100mm`'s geometry under another name.
fn workdir(test: &str) -> PathBuf {
    let d = super::support::workdir("plugin-sensors", test);
    std::fs::write(d.join("small.toml"), "[sensor]\nname = \"small-60mm\"\nwidth_mm = 60.0\nheight_mm = 60.0\n")
        .unwrap();
    std::fs::write(d.join("paper.toml"), "[sensor]\nname = \"paper-copy\"\n").unwrap();
    d
}

fn quoted(p: &Path) -> String {
    toml::Value::String(p.to_string_lossy().into_owned()).to_string()
}

/// `g.toml` in `dir`: the plugin source `board` (params `board`) -> `sync` -> `recon` (params
/// `recon`), with the faulty fixture library loaded. Line 11 is `board`'s params, line 13
/// `recon`'s `[[node]]`, line 16 its params.
fn graph(dir: &Path, board: &str, recon: &str) -> PathBuf {
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let g = format!(
        "[graph]\nname = \"plugin-sensor\"\nmode = \"lockstep\"\n\n\
         [[plugin]]\npath = {}\n\n\
         [[node]]\nid = \"board\"\nkind = \"fixture-eit\"\nparams = {{ {board} }}\n\n\
         [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\nparams = {{ {recon} }}\n\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\n\
         [[edge]]\nfrom = \"board.eit\"\nto = \"sync.eit\"\n\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n",
        quoted(&lib)
    );
    let path = dir.join("g.toml");
    std::fs::write(&path, g).unwrap();
    path
}

/// `skinflow check g.toml` in `dir` refused with one error; that error.
fn refused(dir: &Path) -> String {
    let out = skinflow(dir, &["check", "g.toml"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "one error: {err}");
    assert!(out.stdout.is_empty(), "no \"ok\" line: {}", text(&out.stdout));
    err
}

const PAPER: &str = "sensor \"paper-100mm\" (100 x 100 mm, 16 electrodes, pairwise)";
const SMALL: &str = "sensor \"small-60mm\" (60 x 60 mm, 16 electrodes, pairwise)";

#[test]
fn a_plugin_source_of_the_reconstructors_sensor_passes_check() {
    let d = workdir("agree");
    for (board, recon) in [
        // Both the default.
        ("", ""),
        // Both one file.
        ("sensor = \"small.toml\"", "sensor = \"small.toml\""),
        // The default's geometry under another name, on either side.
        ("sensor = \"paper.toml\"", ""),
        ("", "sensor = \"paper.toml\""),
    ] {
        graph(&d, board, recon);
        let text = ok(&skinflow(&d, &["check", "g.toml"]));
        assert!(text.starts_with("g.toml: ok ("), "board {{ {board} }}, recon {{ {recon} }}: {text}");
    }
}

#[test]
fn a_plugin_source_of_another_sensor_is_refused_naming_both_nodes_and_sensors() {
    let d = workdir("disagree");

    // A 60 mm board into a default (100 mm) reconstructor: at the reconstructor's table.
    graph(&d, "sensor = \"small.toml\"", "");
    let err = refused(&d);
    let want = format!(
        "g.toml:13:1: node \"recon\": param \"sensor\": reconstructs on {PAPER}, the default (no `sensor` param), but \
         its frames come from fixture-eit \"board\" (a plugin kind), on {SMALL} of small.toml (its `sensor` param): \
         the images would be wrong; give the reconstructor `sensor = \"...\"` matching that sensor (or, if the \
         plugin's frames are of another, that sensor's file to its `sensor`)"
    );
    assert_eq!(err.trim_end(), want);
    // `run` stops on the same error, before any node starts.
    let run = skinflow(&d, &["run", "g.toml"]);
    assert_eq!((run.status.code(), stderr(&run)), (Some(2), err), "run stops on the same error");

    // A default board into a 60 mm reconstructor: at the reconstructor's `sensor` param.
    graph(&d, "", "sensor = \"small.toml\"");
    let err = refused(&d);
    assert!(err.starts_with("g.toml:16:12: node \"recon\": param \"sensor\": "), "at the param: {err}");
    for w in [
        &format!("reconstructs on {SMALL} of small.toml"),
        &format!(
            "its frames come from fixture-eit \"board\" (a plugin kind), on {PAPER}, the default (no `sensor` param)"
        ),
    ] {
        assert!(err.contains(w.as_str()), "want {w:?} in:\n{err}");
    }

    // A board of the reconstructor's sensor on the frames' path, and one of another straight
    // into its `reference` input: the second is named, alone.
    graph(&d, "sensor = \"small.toml\"", "sensor = \"small.toml\"");
    let g = std::fs::read_to_string(d.join("g.toml")).unwrap();
    std::fs::write(
        d.join("g.toml"),
        format!(
            "{g}\n[[node]]\nid = \"ref\"\nkind = \"fixture-eit\"\n\n\
             [[edge]]\nfrom = \"ref.eit\"\nto = \"recon.reference\"\n"
        ),
    )
    .unwrap();
    let err = refused(&d);
    assert!(err.starts_with("g.toml:16:12: node \"recon\": param \"sensor\": "), "at the param: {err}");
    assert!(
        err.contains(&format!(
            "its frames come from fixture-eit \"ref\" (a plugin kind), on {PAPER}, the default (no `sensor` param)"
        )),
        "{err}"
    );
    assert!(!err.contains("\"board\""), "{err}");
}

#[test]
fn a_sensor_of_a_plugin_node_that_cannot_be_read_is_refused_at_its_param() {
    let d = workdir("unreadable");

    // An unknown sensor: no such file, beside the graph.
    graph(&d, "sensor = \"no-such-sensor\"", "");
    let err = refused(&d);
    assert!(
        err.starts_with("g.toml:11:12: node \"board\": param \"sensor\": no-such-sensor: cannot read sensor: "),
        "{err}"
    );

    // A file that is no valid sensor, with the reconstructor's sensor valid: still refused.
    std::fs::write(d.join("bad.toml"), "[sensor]\nwidth_mm = -1.0\n").unwrap();
    graph(&d, "sensor = \"bad.toml\"", "sensor = \"small.toml\"");
    let err = refused(&d);
    assert!(err.starts_with("g.toml:11:12: node \"board\": param \"sensor\": bad.toml: sensor: width_mm: "), "{err}");

    // Whether or not the node feeds a reconstructor.
    let g = std::fs::read_to_string(d.join("g.toml")).unwrap();
    let cut = g.find("[[node]]\nid = \"recon\"").unwrap();
    std::fs::write(
        d.join("g.toml"),
        format!(
            "{}[[node]]\nid = \"sync\"\nkind = \"sync\"\n\n[[edge]]\nfrom = \"board.eit\"\nto = \"sync.eit\"\n",
            &g[..cut]
        ),
    )
    .unwrap();
    let err = refused(&d);
    assert!(err.contains("node \"board\": param \"sensor\": bad.toml: sensor: width_mm: "), "{err}");
}

#[test]
fn skinflow_nodes_lists_the_sensor_param_type() {
    let d = workdir("nodes");
    let lib = plugin("skinflow-plugin-fixture-faulty");
    let text = ok(&skinflow(&d, &["nodes", "--plugin", lib.to_str().unwrap()]));
    assert!(text.contains("param sensor: sensor (default none)  sensor TOML of the frames"), "{text}");
}
