//! `skinflow_nodes::outputs::check_graph` on graphs parsed from text (no file needs to exist:
//! paths not there yet are compared normalized): an output file over the graph file, over a
//! file a node reads or over another node's output is refused at the writer's param, and a
//! logger's `strategies` must name strategies that arrive on its `forces`, derived from the
//! correctors' and splitters' params; a producer not known here (a plugin) is not second-guessed.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, KindInfo, NodeError, NodeImpl, NodeParams, ParamDoc, PortSpec, Registry, Role, typed};
use skinflow_nodes::outputs::check_graph;
use skinflow_nodes::payload::{Contacts, Forces, Split};

/// Params of the stand-in plugin kinds: a `path` it may read or write.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PluginParams {
    /// Only parsed: these kinds are never built.
    #[serde(default)]
    #[allow(dead_code)]
    path: Option<PathBuf>,
}

impl NodeParams for PluginParams {}

/// The built-in kinds, plus kinds standing in for plugins (never run): a forces producer with
/// a `path` param, a splitter and a segmenter.
fn registry() -> Registry {
    let mut r = skinflow_nodes::registry();
    let never = |_: PluginParams, _: &skinflow_core::BuildContext| -> Result<NodeImpl, NodeError> {
        Err(NodeError::msg("not built in these tests"))
    };
    r.register(typed(
        KindInfo::new("plugin-forces", Role::Source, "a plugin's forces")
            .output(PortSpec::output::<Forces>("forces", "forces"))
            .param(ParamDoc::new("path", "path", "none", "a file it reads or writes")),
        never,
    ))
    .unwrap();
    r.register(typed(
        KindInfo::new("plugin-splitter", Role::Source, "a plugin's splits")
            .output(PortSpec::output::<Split>("split", "splits")),
        never,
    ))
    .unwrap();
    r.register(typed(
        KindInfo::new("plugin-contacts", Role::Source, "a plugin's contacts")
            .output(PortSpec::output::<Contacts>("contacts", "contacts")),
        never,
    ))
    .unwrap();
    r
}

/// The directory the graph files "are in" (nothing is written there).
fn base() -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join("outputs-check")
}

/// The errors of `check_graph` on `text` as the graph file `base()/g.toml`, one per line with
/// that directory written `DIR` (empty: accepted).
fn errors(text: &str) -> String {
    let file = base().join("g.toml");
    let spec = GraphSpec::parse(SourceFile::new(file, text.to_owned()), &registry()).expect("a valid graph");
    match check_graph(&spec) {
        Ok(()) => String::new(),
        Err(e) => e.to_string().replace(&base().display().to_string(), "DIR"),
    }
}

const REPLAY: &str = "[[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = { path = \"rec.h5\" }\n";

fn logger(id: &str, params: &str) -> String {
    format!("[[node]]\nid = \"{id}\"\nkind = \"hdf5_logger\"\nparams = {{ {params} }}\n")
}

fn edge(from: &str, to: &str) -> String {
    format!("[[edge]]\nfrom = \"{from}\"\nto = \"{to}\"\n")
}

#[test]
fn a_logger_over_the_recording_it_replays_is_refused_at_its_path() {
    for (path, same) in [("rec.h5", ""), ("sub/../rec.h5", ", the same file"), ("./rec.h5", ", the same file")] {
        let text = format!(
            "{REPLAY}{}{}",
            logger("log", &format!("path = {path:?}, overwrite = true")),
            edge("replay.eit", "log.eit")
        );
        assert_eq!(
            errors(&text),
            format!(
                "DIR/g.toml:8:12: node \"log\": param \"path\": writes DIR/{path}, the recording replay \"replay\" \
                 reads (its `path` DIR/rec.h5{same}): the run would overwrite that input, whatever `overwrite` says, \
                 and what it holds would be lost; give `path` another file"
            ),
            "{path}"
        );
    }
    // Without overwrite too, and for a file of another name: accepted.
    let text = format!("{REPLAY}{}{}", logger("log", "path = \"rec.h5\""), edge("replay.eit", "log.eit"));
    assert!(errors(&text).contains("the recording replay \"replay\" reads"), "{}", errors(&text));
    let text = format!("{REPLAY}{}{}", logger("log", "path = \"out.h5\""), edge("replay.eit", "log.eit"));
    assert_eq!(errors(&text), "");
}

#[test]
fn an_output_over_the_graph_file_a_scene_a_calibration_or_a_sensor_file_is_refused() {
    let text = format!("{REPLAY}{}{}", logger("log", "path = \"g.toml\""), edge("replay.eit", "log.eit"));
    assert_eq!(
        errors(&text),
        "DIR/g.toml:8:12: node \"log\": param \"path\": writes DIR/g.toml, which is this graph's own file \
         DIR/g.toml: the run would replace the graph with its output, whatever `overwrite` says; give `path` \
         another file"
    );
    // A compare's report over a calibration; a logger over its own sensor file.
    let text = "[[node]]\nid = \"split\"\nkind = \"splitter\"\n\
         [[node]]\nid = \"force\"\nkind = \"corrector\"\nparams = { calibration = \"calib.toml\" }\n\
         [[node]]\nid = \"ab\"\nkind = \"compare\"\nparams = { json = \"calib.toml\" }\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = { path = \"s.toml\", sensor = \"s.toml\", strategies = [\"pneumatic-locaware\"] }\n\
         [[edge]]\nfrom = \"split.split\"\nto = \"force.split\"\n\
         [[edge]]\nfrom = \"force.forces\"\nto = \"ab.forces\"\n\
         [[edge]]\nfrom = \"force.forces\"\nto = \"log.forces\"\n";
    // The splitter has no input here: the graph is only checked, never run.
    let text = text.replace(
        "[[node]]\nid = \"split\"\nkind = \"splitter\"\n",
        "[[node]]\nid = \"split\"\nkind = \"plugin-splitter\"\n",
    );
    let e = errors(&text);
    let lines: Vec<&str> = e.lines().collect();
    assert_eq!(lines.len(), 2, "{e}");
    assert!(
        lines[0].starts_with(
            "DIR/g.toml:11:12: node \"ab\": param \"json\": writes DIR/calib.toml, the calibration corrector \"force\" \
             reads (its `calibration` DIR/calib.toml)"
        ),
        "{e}"
    );
    assert!(
        lines[1].starts_with(
            "DIR/g.toml:15:12: node \"log\": param \"path\": writes DIR/s.toml, the sensor file this node reads (its \
             `sensor` DIR/s.toml)"
        ),
        "{e}"
    );
    // A scene.
    let text = "[[node]]\nid = \"sim\"\nkind = \"sim\"\nparams = { scene = \"/abs/scene.toml\" }\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = { path = \"/abs/x/../scene.toml\" }\n\
         [[edge]]\nfrom = \"sim.eit\"\nto = \"log.eit\"\n";
    assert!(
        errors(text).starts_with(
            "DIR/g.toml:8:12: node \"log\": param \"path\": writes /abs/x/../scene.toml, the scene sim \"sim\" reads \
             (its `scene` /abs/scene.toml, the same file)"
        ),
        "{}",
        errors(text)
    );
}

#[test]
fn two_writers_of_one_file_are_refused_once_at_the_later_whatever_overwrite_says() {
    let text = format!(
        "{REPLAY}{}{}{}{}",
        logger("a", "path = \"out.h5\", overwrite = true"),
        logger("b", "path = \"x/../out.h5\""),
        edge("replay.eit", "a.eit"),
        edge("replay.eit", "b.eit")
    );
    assert_eq!(
        errors(&text),
        "DIR/g.toml:12:12: node \"b\": param \"path\": writes DIR/x/../out.h5, which hdf5_logger \"a\" writes too \
         (its `path` DIR/out.h5, the same file): each would replace the other's output, whatever `overwrite` says; \
         give each node its own file"
    );
    // A rotating logger writes out-0001.h5, out-0002.h5, ...: another writer of one of them.
    let text = format!(
        "{REPLAY}{}{}{}{}",
        logger("a", "path = \"out-0002.h5\""),
        logger("b", "path = \"out.h5\", rotate_s = 60.0"),
        edge("replay.eit", "a.eit"),
        edge("replay.eit", "b.eit")
    );
    assert!(
        errors(&text).starts_with(
            "DIR/g.toml:12:12: node \"b\": param \"path\": writes DIR/out.h5, which hdf5_logger \"a\" writes too"
        ),
        "{}",
        errors(&text)
    );
    // Not rotating: out.h5 and out-0002.h5 are two files.
    let text = text.replace(", rotate_s = 60.0", "");
    assert_eq!(errors(&text), "");
}

#[test]
fn an_output_over_a_file_a_plugin_names_is_refused_but_two_plugin_files_are_not() {
    let plugin = |id: &str, path: &str| {
        format!("[[node]]\nid = \"{id}\"\nkind = \"plugin-forces\"\nparams = {{ path = \"{path}\" }}\n")
    };
    let text = format!(
        "{}{}{}",
        plugin("csv", "p.csv"),
        logger("log", "path = \"p.csv\", strategies = [\"fused\"]"),
        edge("csv.forces", "log.forces")
    );
    assert!(
        errors(&text).starts_with(
            "DIR/g.toml:8:12: node \"log\": param \"path\": writes DIR/p.csv, which plugin-forces \"csv\" (a plugin \
             kind) names in its `path` DIR/p.csv: whether it reads or writes that file"
        ),
        "{}",
        errors(&text)
    );
    let text = format!("{}{}{}", plugin("a", "p.csv"), plugin("b", "p.csv"), "[[node]]\nid = \"n\"\nkind = \"null\"\n")
        + &edge("a.forces", "n.in")
        + &edge("b.forces", "n.in");
    assert_eq!(errors(&text), "");
}

/// A graph from a splitter (`split`, strategy `split`) through correctors (`(id, params)`)
/// into a logger listing `strategies`.
fn forces_graph(split: &str, correctors: &[(&str, &str)], strategies: &str) -> String {
    let mut text = format!(
        "[[node]]\nid = \"seg\"\nkind = \"plugin-contacts\"\n\
         [[node]]\nid = \"split\"\nkind = \"splitter\"\nparams = {{ strategy = \"{split}\", calibration = \"c.toml\" }}\n"
    );
    for (id, params) in correctors {
        text += &format!(
            "[[node]]\nid = \"{id}\"\nkind = \"corrector\"\nparams = {{ calibration = \"c.toml\"{params} }}\n"
        );
    }
    text += &logger("log", &format!("path = \"out.h5\", strategies = {strategies}"));
    text += "[[edge]]\nfrom = \"seg.contacts\"\nto = \"split.contacts\"\n";
    for (id, _) in correctors {
        text += &edge("split.split", &format!("{id}.split"));
        text += &edge(&format!("{id}.forces"), "log.forces");
    }
    text
}

#[test]
fn a_listed_strategy_no_corrector_produces_is_refused_naming_those_that_arrive() {
    let ours = [("paper", ""), ("ours", ", strategy = \"pneumatic-forward\", name = \"pneumatic-forward-balance\"")];
    let text = forces_graph("proportional", &ours, "[\"pneumatic-locaware\", \"pneumatic-forwrd-balance\"]");
    assert!(text.lines().nth(18).unwrap().starts_with("params = { path = \"out.h5\", strategies"), "{text}");
    assert_eq!(
        errors(&text),
        "DIR/g.toml:19:29: node \"log\": param \"strategies\": strategy \"pneumatic-forwrd-balance\" is not produced \
         by any corrector connected to `forces`, so nothing would be logged under it; the names that arrive: \
         \"pneumatic-locaware\" (corrector \"paper\"), \"pneumatic-forward-balance\" (corrector \"ours\") (a \
         corrector's `name`, else its strategy, suffixed with -<splitter strategy> for a pneumatic one after a \
         splitter other than proportional)"
    );
    let text = forces_graph("proportional", &ours, "[\"pneumatic-locaware\", \"pneumatic-forward-balance\"]");
    assert_eq!(errors(&text), "");
    // After another splitter, a pneumatic strategy's name gets its suffix, an EIT one's not.
    let two = [("p", ""), ("e", ", strategy = \"eit-locaware\"")];
    let text = forces_graph("force-balance", &two, "[\"pneumatic-locaware-force-balance\", \"eit-locaware\"]");
    assert_eq!(errors(&text), "");
    let text = forces_graph("force-balance", &two, "[\"pneumatic-locaware\", \"eit-locaware-force-balance\"]");
    let e = errors(&text);
    assert!(
        e.contains(
            "strategies \"pneumatic-locaware\", \"eit-locaware-force-balance\" are not produced by any corrector \
             connected to `forces`, so nothing would be logged under them; the names that arrive: \
             \"pneumatic-locaware-force-balance\" (corrector \"p\"), \"eit-locaware\" (corrector \"e\")"
        ),
        "{e}"
    );
    // A strategy listed but not arriving is refused; one arriving but not listed is not (its
    // frames are counted as discarded at run).
    let text = forces_graph("sensitivity-compensated", &two, "[\"eit-locaware\"]");
    assert_eq!(errors(&text), "");
}

#[test]
fn forces_or_splits_from_a_plugin_leave_the_list_unchecked() {
    // Forces from a plugin: their names are the plugin's own.
    let text = format!(
        "[[node]]\nid = \"fused\"\nkind = \"plugin-forces\"\n{}{}",
        logger("log", "path = \"out.h5\", strategies = [\"anything\"]"),
        edge("fused.forces", "log.forces")
    );
    assert_eq!(errors(&text), "");
    // A built-in corrector after a plugin splitter: the split's strategy name is the plugin's.
    let text = "[[node]]\nid = \"split\"\nkind = \"plugin-splitter\"\n\
         [[node]]\nid = \"force\"\nkind = \"corrector\"\nparams = { calibration = \"c.toml\" }\n"
        .to_owned()
        + &logger("log", "path = \"out.h5\", strategies = [\"pneumatic-locaware-area\"]")
        + &edge("split.split", "force.split")
        + &edge("force.forces", "log.forces");
    assert_eq!(errors(&text), "");
    // With a `name`, the splitter does not matter.
    let text = text.replace("calibration = \"c.toml\" }", "calibration = \"c.toml\", name = \"x\" }");
    assert!(errors(&text).contains("the names that arrive: \"x\" (corrector \"force\")"), "{}", errors(&text));
}
