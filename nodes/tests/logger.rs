//! The `hdf5_logger` inside a graph, fed by scripted sources (no reconstruction): forces of one
//! strategy name from two edges are refused at the first clash with the rows so far kept, and
//! images are logged at their own size, the optional `image_nx` / `image_ny` checked against
//! it. Lockstep, so every run is the same.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;
use skinflow_contact::ForceEstimate;
use skinflow_core::graph::SourceFile;
use skinflow_core::{
    Context, GraphSpec, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, PortSpec, Registry, Role,
    RunOptions, RunReport, Source, SourcePoll, typed,
};
use skinflow_nodes::payload::{Forces, Image};
use skinflow_record::read::Recording;

/// Frames each scripted source sends, 0.1 s apart.
const FRAMES: u64 = 5;

/// Params of `forces_script`: forces named `name`, one contact of `force_n` per frame.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ForcesScript {
    name: String,
    force_n: f64,
}

impl NodeParams for ForcesScript {}

/// Params of `image_script`: images of the given sizes (width, height), one per frame.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ImageScript {
    sizes: Vec<[usize; 2]>,
}

impl NodeParams for ImageScript {}

/// A source sending `frames` messages, frame `i` at `i` x 0.1 s, made by `make(i)`.
struct Script<F> {
    next: u64,
    frames: u64,
    make: F,
}

impl<F: FnMut(u64) -> Message + Send> Source for Script<F> {
    fn poll(&mut self, _ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        if self.next == self.frames {
            return Ok(SourcePoll::Finished);
        }
        out.send(0, (self.make)(self.next))?;
        self.next += 1;
        Ok(SourcePoll::Emitted)
    }
}

fn header(i: u64) -> Header {
    Header { seq: i, t_ns: (i + 1) * 100_000_000, origin: 0 }
}

fn registry() -> Registry {
    let mut r = skinflow_nodes::registry();
    r.register(typed(
        KindInfo::new("forces_script", Role::Source, "scripted forces")
            .output(PortSpec::output::<Forces>("forces", "forces")),
        |p: ForcesScript, _| {
            let make = move |i| {
                let force = ForceEstimate { force_n: p.force_n, dp_kpa: 0.5, ..ForceEstimate::default() };
                let f = Forces { strategy: p.name.clone(), forces: vec![force], ..Forces::default() };
                Message::new(header(i), f)
            };
            Ok(NodeImpl::Source(Box::new(Script { next: 0, frames: FRAMES, make })))
        },
    ))
    .unwrap();
    r.register(typed(
        KindInfo::new("image_script", Role::Source, "scripted images")
            .output(PortSpec::output::<Image>("image", "images")),
        |p: ImageScript, _| {
            let sizes = p.sizes;
            let frames = sizes.len() as u64;
            let make = move |i: u64| {
                let [width, height] = sizes[i as usize];
                let pixels = (0..width * height).map(|k| -(k as f64) - i as f64).collect();
                Message::from_arc(header(i), Arc::new(Image { width, height, pixels, ..Image::default() }))
            };
            Ok(NodeImpl::Source(Box::new(Script { next: 0, frames, make })))
        },
    ))
    .unwrap();
    r
}

/// A fresh directory for one test's files.
fn dir(test: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("logger").join(test);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `nodes` (graph-file text) with a logger "log" writing `dir/rec.h5` with `log_params`,
/// in lockstep.
fn run(dir: &Path, nodes: &str, log_params: &str) -> Result<RunReport, String> {
    let graph = format!(
        "[graph]\nmode = \"lockstep\"\n{nodes}\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"rec.h5\"{log_params} }}\n"
    );
    let file = dir.join("graph.toml");
    let spec = GraphSpec::parse(SourceFile::new(file, graph), &registry()).map_err(|e| e.to_string())?;
    skinflow_core::run(&spec, &RunOptions::default()).map_err(|e| e.to_string())
}

fn failures(report: &RunReport) -> Vec<String> {
    report.failures.iter().map(ToString::to_string).collect()
}

fn forces_node(id: &str, name: &str, force_n: f64) -> String {
    format!(
        "[[node]]\nid = \"{id}\"\nkind = \"forces_script\"\nparams = {{ name = \"{name}\", force_n = {force_n:?} }}\n\
         [[edge]]\nfrom = \"{id}.forces\"\nto = \"log.forces\"\n"
    )
}

#[test]
fn one_strategy_name_from_two_inputs_is_refused_at_the_first_clash_and_the_rows_so_far_kept() {
    let d = dir("clash");
    let nodes = forces_node("a", "pneumatic-locaware", 1.0) + &forces_node("b", "pneumatic-locaware", 2.0);
    let report = run(&d, &nodes, ", strategies = [\"pneumatic-locaware\"]").unwrap();
    let failures = failures(&report);
    assert_eq!(failures.len(), 1, "{failures:?}");
    let e = &failures[0];
    assert!(
        e.starts_with("node \"log\": input \"forces\": two inputs deliver forces named \"pneumatic-locaware\""),
        "{e}"
    );
    assert!(e.contains("give each corrector its own `name`"), "{e}");

    // The file was closed cleanly and holds the rows of one input only, in time order.
    let rec = Recording::open(d.join("rec.h5")).unwrap();
    let forces = &rec.derived.forces;
    assert_eq!(forces.len(), 1);
    let f = &forces[0];
    assert_eq!(f.name, "pneumatic-locaware");
    assert!(!f.t_s.is_empty() && (f.t_s.len() as u64) < FRAMES, "{:?}", f.t_s);
    assert!(f.t_s.windows(2).all(|w| w[0] < w[1]), "{:?}", f.t_s);
    let first = f.force_n[0];
    assert!(first == 1.0 || first == 2.0);
    assert!(f.force_n.iter().step_by(f.max_contacts).all(|&x| x == first), "one input's rows: {:?}", f.force_n);
}

#[test]
fn distinct_names_from_two_inputs_each_get_their_table() {
    let d = dir("distinct");
    let nodes = forces_node("a", "pneumatic-locaware", 1.0) + &forces_node("b", "eit-locaware", 2.0);
    let report = run(&d, &nodes, ", strategies = [\"pneumatic-locaware\", \"eit-locaware\"]").unwrap();
    assert_eq!(failures(&report), Vec::<String>::new());
    let rec = Recording::open(d.join("rec.h5")).unwrap();
    let mut tables: Vec<(String, usize, f64)> =
        rec.derived.forces.iter().map(|f| (f.name.clone(), f.t_s.len(), f.force_n[0])).collect();
    tables.sort_by(|a, b| a.0.cmp(&b.0));
    let n = FRAMES as usize;
    assert_eq!(tables, [("eit-locaware".into(), n, 2.0), ("pneumatic-locaware".into(), n, 1.0)]);

    // The same name twice, but not logged: nothing interleaves, nothing is refused.
    let d = dir("unlisted");
    let nodes = forces_node("a", "proportional", 1.0) + &forces_node("b", "proportional", 2.0);
    let report = run(&d, &nodes, ", strategies = [\"pneumatic-locaware\"]").unwrap();
    assert_eq!(failures(&report), Vec::<String>::new());
}

fn images(sizes: &[[usize; 2]]) -> String {
    format!(
        "[[node]]\nid = \"img\"\nkind = \"image_script\"\nparams = {{ sizes = {sizes:?} }}\n\
         [[edge]]\nfrom = \"img.image\"\nto = \"log.image\"\n"
    )
}

#[test]
fn images_are_logged_at_their_own_size_and_given_sizes_must_match_it() {
    // 64 wide, 48 high: stored [n, 48, 64], row-major as sent.
    let sizes = [[64, 48]; 3];
    for params in ["", ", image_nx = 64", ", image_ny = 48", ", image_nx = 64, image_ny = 48"] {
        let d = dir("image-size");
        let report = run(&d, &images(&sizes), params).unwrap();
        assert_eq!(failures(&report), Vec::<String>::new(), "{params}");
        let image = Recording::open(d.join("rec.h5")).unwrap().derived.image.expect("images logged");
        assert_eq!((image.t_s.len(), image.hw), (3, [48, 64]), "{params}");
        assert_eq!(image.pixels[64 * 48 + 5], -6.0, "{params}: second image, pixel 5");
    }
    // The SWMR file gets its image dataset at creation: the size must be given.
    let d = dir("image-swmr");
    let report = run(&d, &images(&sizes), ", swmr = true, image_nx = 64, image_ny = 48").unwrap();
    assert_eq!(failures(&report), Vec::<String>::new());
    assert_eq!(Recording::open(d.join("rec.h5")).unwrap().derived.image.unwrap().hw, [48, 64]);
}

#[test]
fn an_image_size_the_params_contradict_stops_the_graph_naming_them() {
    let sizes = [[64, 48]; 3];
    let but = "the images are 64 x 48 pixels (width x height), but";
    for (params, expected) in [
        (", image_nx = 32", format!("param \"image_nx\": {but} image_nx = 32;")),
        (", image_ny = 64", format!("param \"image_ny\": {but} image_ny = 64;")),
        (", image_nx = 64, image_ny = 64", format!("param \"image_ny\": {but} image_nx = 64, image_ny = 64;")),
        (", image_nx = 48, image_ny = 64", format!("param \"image_nx\": {but} image_nx = 48, image_ny = 64;")),
    ] {
        let d = dir("image-mismatch");
        let report = run(&d, &images(&sizes), params).unwrap();
        let failures = failures(&report);
        assert_eq!(failures.len(), 1, "{params}: {failures:?}");
        assert!(failures[0].starts_with(&format!("node \"log\": {expected}")), "{params}: {}", failures[0]);
    }
    // 0 is refused at load, naming the param.
    for param in ["image_nx", "image_ny"] {
        let e = run(&dir("image-zero"), &images(&sizes), &format!(", {param} = 0")).unwrap_err();
        assert!(e.contains(&format!("node \"log\": param \"{param}\": must be >= 1 pixel (got 0)")), "{e}");
    }
    // So is SWMR with `image` connected and no size (the file gets its image dataset at creation).
    for (params, missing) in [(", swmr = true", "image_nx"), (", swmr = true, image_nx = 64", "image_ny")] {
        let e = run(&dir("image-swmr-no-size"), &images(&sizes), params).unwrap_err();
        let expected = format!(
            "node \"log\": param \"{missing}\": with swmr = true and `image` connected, give image_nx and image_ny"
        );
        assert!(e.contains(&expected), "{params}: {e}");
    }
}

#[test]
fn an_image_of_another_size_than_the_first_stops_the_graph_with_the_first_ones_kept() {
    let d = dir("image-change");
    let report = run(&d, &images(&[[64, 48], [64, 48], [32, 32]]), "").unwrap();
    let failures = failures(&report);
    assert_eq!(
        failures,
        ["node \"log\": input \"image\": an image of 32 x 32 pixels (width x height), but this recording's images \
          are 64 x 48 (the first image's size): one recording holds one image size"]
    );
    let image = Recording::open(d.join("rec.h5")).unwrap().derived.image.unwrap();
    assert_eq!((image.t_s.len(), image.hw), (2, [48, 64]));
}

#[test]
fn forces_without_strategies_are_refused_at_load_and_at_a_swap_naming_the_param() {
    let d = dir("no-strategies");
    let nodes = forces_node("a", "pneumatic-locaware", 1.0);
    // The params alone are fine; the wiring needs the list, so the graph is refused at load,
    // the error located at the logger's node.
    let params = skinflow_core::Params::from_toml("path = \"rec.h5\"").unwrap();
    registry().get("hdf5_logger").unwrap().check(&params).unwrap();
    let e = run(&d, &nodes, "").unwrap_err();
    assert!(
        e.ends_with(
            "graph.toml:10:1: node \"log\": param \"strategies\": required when `forces` is connected: list the \
             force strategies (corrector output names) to log"
        ),
        "{e}"
    );
    // A replacement swapped in at run time is checked against the same wiring and refused.
    let spec = GraphSpec::parse(
        SourceFile::new(
            d.join("graph.toml"),
            format!(
                "[graph]\nmode = \"lockstep\"\n{nodes}[[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\n\
                 params = {{ path = \"other.h5\", strategies = [\"pneumatic-locaware\"] }}\n"
            ),
        ),
        &registry(),
    )
    .unwrap();
    let running = skinflow_core::RunningGraph::start(&spec).unwrap();
    let factory = registry().get("hdf5_logger").unwrap().clone();
    let e = running.handle().swap("log", factory, params).unwrap_err().to_string();
    assert!(e.contains("param \"strategies\": required when `forces` is connected"), "{e}");
    drop(running.wait(&RunOptions::default()));
    std::fs::remove_file(d.join("other.h5")).unwrap();
    let left: Vec<_> = std::fs::read_dir(&d).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "{left:?}");

    // Without `forces`, no list is needed.
    let d = dir("no-forces");
    let report = run(&d, &images(&[[8, 8]]), "").unwrap();
    assert_eq!(failures(&report), Vec::<String>::new());
    assert!(Recording::open(d.join("rec.h5")).unwrap().derived.forces.is_empty());
}
