//! `skinflow bench GRAPH.toml --replay REC.h5 --vary node.param=v1,v2,... [--out DIR]`: runs
//! every combination of the varied params on the same recording, in lockstep, and writes a
//! speed-against-error table (`bench.md`, `bench.json`) and a Pareto plot (`pareto.png`).
//!
//! The graph needs a `replay` node (its `path` is replaced by `--replay`) and a `compare` sink,
//! whose per-lane report (latency p50/p99, force RMSE against truth) gives one point per
//! (variant, lane). Each variant is the graph's TOML with the params overridden, so relative
//! paths and `[[plugin]]` entries resolve as in the original file. Thread placement
//! (`[graph] workers`, a node's `cpu`, `rt_priority`, `thread`) is dropped: a lockstep run is one
//! thread, and lockstep graphs refuse those options. The params bench sets itself
//! ([`OWNED`]) cannot be varied.
//!
//! Variant `k`'s `compare` report goes to `DIR/variant-k.json`; bench removes it before the run
//! and reads only what the run wrote. Each variant's node errors and edge drops go into the
//! outputs, with a warning when the points do not cover the same frames. The first variant runs
//! once, unmeasured (for at most [`WARM_UP`]), before the measured passes, so that none of them
//! runs cold. A variant that fails does not stop the others: the outputs show what ran, then
//! bench fails with the first cause.

mod report;

use std::path::{Path, PathBuf};
use std::time::Duration;

use super::paths::Output;
use anyhow::{Context as _, Result, anyhow, bail};
use skinflow_core::graph::{GraphErrors, SourceFile, plugin_paths};
use skinflow_core::{GraphSpec, Registry, RunOptions};

use report::{Health, Point, Variant};

/// The params bench sets itself, by node kind: refused by `--vary`.
const OWNED: [(&str, &[&str]); 2] =
    [("replay", &["path", "speed", "loop"]), ("compare", &["json", "report_s", "print"])];

/// The longest the unmeasured warm-up pass runs (the first variant, from the recording's start).
const WARM_UP: Duration = Duration::from_secs(3);

/// One `--vary node.param=v1,v2,...`.
#[derive(Debug, Clone, PartialEq)]
pub struct Vary {
    pub node: String,
    pub param: String,
    pub values: Vec<toml::Value>,
}

/// A TOML value as written, or a string when it does not parse (`exp` -> "exp").
fn value(text: &str) -> toml::Value {
    toml::from_str::<toml::Table>(&format!("v = {text}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(text.to_owned()))
}

impl std::str::FromStr for Vary {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Vary> {
        let hint = "expected node.param=v1,v2,... (e.g. recon.lambda=0.01,0.03)";
        let (key, vals) = s.split_once('=').ok_or_else(|| anyhow!("--vary \"{s}\": {hint}"))?;
        let (node, param) = key.split_once('.').ok_or_else(|| anyhow!("--vary \"{s}\": {hint}"))?;
        let values: Vec<toml::Value> = vals.split(',').map(str::trim).filter(|v| !v.is_empty()).map(value).collect();
        if node.is_empty() || param.is_empty() || values.is_empty() {
            bail!("--vary \"{s}\": {hint}");
        }
        Ok(Vary { node: node.to_owned(), param: param.to_owned(), values })
    }
}

/// The overrides of one variant: (node id, param, value).
pub type Overrides = Vec<(String, String, toml::Value)>;

/// Every combination of the varied values, as (label, overrides).
fn combinations(vary: &[Vary]) -> Vec<(String, Overrides)> {
    let mut out: Vec<(String, Overrides)> = vec![(String::new(), Vec::new())];
    for v in vary {
        let mut next = Vec::with_capacity(out.len() * v.values.len());
        for (label, set) in &out {
            for x in &v.values {
                let mut set = set.clone();
                set.push((v.node.clone(), v.param.clone(), x.clone()));
                let sep = if label.is_empty() { "" } else { " " };
                next.push((format!("{label}{sep}{}.{}={x}", v.node, v.param), set));
            }
        }
        out = next;
    }
    if out.len() == 1 && out[0].0.is_empty() {
        out[0].0 = "as written".into();
    }
    out
}

fn nodes_mut(doc: &mut toml::Table) -> Result<&mut Vec<toml::Value>> {
    match doc.get_mut("node") {
        Some(toml::Value::Array(a)) => Ok(a),
        _ => bail!("the graph has no [[node]]"),
    }
}

fn params_of(node: &mut toml::Value) -> Result<&mut toml::Table> {
    let t = node.as_table_mut().ok_or_else(|| anyhow!("a [[node]] is not a table"))?;
    let p = t.entry("params").or_insert_with(|| toml::Value::Table(toml::Table::new()));
    p.as_table_mut().ok_or_else(|| anyhow!("a node's params is not a table"))
}

fn field<'a>(node: &'a toml::Value, key: &str) -> Option<&'a str> {
    node.get(key).and_then(toml::Value::as_str)
}

/// Refuses a `--vary` of a node the graph does not have, of a param bench sets itself
/// ([`OWNED`]: the variant would not be what the table says, or its report would not be
/// where bench reads it), and of one param given twice.
fn check_vary(base: &toml::Table, vary: &[Vary]) -> Result<()> {
    let nodes = match base.get("node") {
        Some(toml::Value::Array(a)) => a.as_slice(),
        _ => &[],
    };
    for (i, v) in vary.iter().enumerate() {
        let key = format!("{}.{}", v.node, v.param);
        let node = nodes
            .iter()
            .find(|n| field(n, "id") == Some(v.node.as_str()))
            .ok_or_else(|| anyhow!("--vary \"{key}\": no node \"{}\" in the graph", v.node))?;
        let kind = field(node, "kind").unwrap_or_default();
        if let Some((_, owned)) = OWNED.iter().find(|(k, params)| *k == kind && params.contains(&v.param.as_str())) {
            bail!(
                "--vary \"{key}\": bench sets param \"{}\" of the {kind} node itself ({} of a {kind} node), so it cannot be varied",
                v.param,
                owned.join(", ")
            );
        }
        if vary[..i].iter().any(|w| w.node == v.node && w.param == v.param) {
            bail!("--vary \"{key}\": given twice (list every value in one --vary)");
        }
    }
    Ok(())
}

/// The graph text of one variant: the overrides applied, then what bench sets itself.
fn variant_text(
    base: &toml::Table,
    replay: &Path,
    set: &[(String, String, toml::Value)],
    json: &Path,
) -> Result<String> {
    let mut doc = base.clone();
    let graph = doc.entry("graph").or_insert_with(|| toml::Value::Table(toml::Table::new()));
    let graph = graph.as_table_mut().ok_or_else(|| anyhow!("[graph] is not a table"))?;
    graph.insert("mode".into(), "lockstep".into());
    // Thread placement means nothing in lockstep (validation refuses it there).
    graph.remove("workers");
    let nodes = nodes_mut(&mut doc)?;
    for (node, param, v) in set {
        let n = nodes
            .iter_mut()
            .find(|n| field(n, "id") == Some(node.as_str()))
            .ok_or_else(|| anyhow!("--vary: no node \"{node}\" in the graph"))?;
        params_of(n)?.insert(param.clone(), v.clone());
    }
    let (mut replays, mut compares) = (0, 0);
    for n in nodes.iter_mut() {
        if let Some(table) = n.as_table_mut() {
            for placement in ["cpu", "rt_priority", "thread"] {
                table.remove(placement);
            }
        }
        // The params of OWNED.
        match field(n, "kind") {
            Some("replay") => {
                replays += 1;
                let p = params_of(n)?;
                p.insert("path".into(), replay.to_string_lossy().into_owned().into());
                p.insert("speed".into(), 0.0.into());
                p.insert("loop".into(), false.into()); // a looping replay would never end
            }
            Some("compare") => {
                compares += 1;
                let p = params_of(n)?;
                p.insert("json".into(), json.to_string_lossy().into_owned().into());
                p.insert("report_s".into(), 0.0.into());
                p.insert("print".into(), false.into());
            }
            _ => {}
        }
    }
    if replays == 0 {
        bail!("the graph has no \"replay\" node for --replay");
    }
    if compares != 1 {
        bail!("the graph needs exactly one \"compare\" node (found {compares})");
    }
    Ok(toml::to_string(&doc)?)
}

fn registry_for(src: &SourceFile) -> Result<Registry> {
    let mut reg = skinflow_nodes::registry();
    let plugins = plugin_paths(src).map_err(|e| anyhow::Error::new(super::InvalidGraph(e.to_string())))?;
    skinflow_nodes::codec::load_plugins(&plugins, &mut reg).map_err(|e| {
        let located = skinflow_core::graph::plugin_error(src, e.path(), e.to_string());
        anyhow::Error::new(super::InvalidGraph(located.to_string()))
    })?;
    Ok(reg)
}

/// The error for a variant that does not validate. A variant is regenerated TOML, so its line
/// and column mean nothing to the user: each error the graph as written shares is reported at
/// its place in the user's file; the others (caused by an override) name the variant. The
/// graph as written need not validate on its own: the overrides may complete it (a replay
/// `path` left for `--replay` to fill in, say).
fn invalid_variant(graph: &Path, text: &str, reg: &Registry, label: &str, errs: GraphErrors) -> anyhow::Error {
    let written = GraphSpec::parse(SourceFile::new(graph, text.to_owned()), reg).err().map_or_else(Vec::new, |w| w.0);
    let lines: Vec<String> = errs
        .0
        .iter()
        .map(|e| match written.iter().find(|w| w.node == e.node && w.kind == e.kind) {
            Some(w) => w.to_string(),
            None => {
                let node = e.node.as_ref().map(|n| format!("node \"{n}\": ")).unwrap_or_default();
                format!("{}: variant \"{label}\" (--replay and --vary applied): {node}{}", graph.display(), e.kind)
            }
        })
        .collect();
    anyhow::Error::new(super::InvalidGraph(lines.join("\n")))
}

/// Removes `path` if it exists.
fn remove(path: &Path) -> Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            Err(e).with_context(|| format!("{}: cannot remove", path.display()))
        }
        _ => Ok(()),
    }
}

/// The files bench writes in `dir` itself (each variant's report besides).
const OWN_FILES: [&str; 3] = ["bench.md", "bench.json", "pareto.png"];

/// What an earlier bench left in `dir` (`bench.md`, `bench.json`, `pareto.png`,
/// `variant-<k>.json`); none when `dir` does not exist yet.
fn stale_outputs(dir: &Path) -> Result<Vec<PathBuf>> {
    let listing = match std::fs::read_dir(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        r => r.with_context(|| format!("{}: cannot list", dir.display()))?,
    };
    let mut stale = Vec::new();
    for entry in listing {
        let path = entry.with_context(|| format!("{}: cannot list", dir.display()))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let variant = name
            .strip_prefix("variant-")
            .and_then(|r| r.strip_suffix(".json"))
            .is_some_and(|k| !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()));
        if (variant || OWN_FILES.contains(&name)) && path.is_file() {
            stale.push(path);
        }
    }
    Ok(stale)
}

/// Refuses an `--out` directory (`given`; `out_dir` absolute, as are `stale` and the reports'
/// paths) where a file bench writes or removes (its own outputs, every
/// variant's report, an earlier bench's leftovers) is one a variant's graph reads or writes:
/// the recording replayed, a calibration, the graph file. Checked before anything is removed;
/// a variant's own report is the file its compare node writes.
fn check_out_dir(
    given: &Path,
    out_dir: &Path,
    specs: &[(String, Overrides, GraphSpec, PathBuf)],
    stale: &[PathBuf],
) -> Result<()> {
    let dir = given.display();
    let own = OWN_FILES.iter().map(|n| out_dir.join(n));
    let written = specs.iter().map(|(.., json)| json.clone());
    let mut files: Vec<PathBuf> = own.chain(written).chain(stale.iter().cloned()).collect();
    files.sort();
    files.dedup();
    for (_, _, spec, json) in specs {
        for file in files.iter().filter(|f| *f != json) {
            let clashes = skinflow_nodes::outputs::output_clashes(spec, file);
            if let Some(first) = clashes.first() {
                bail!(
                    "--out {dir}: bench writes or removes {} there, and that file is {first}; give --out another \
                     directory (or move the file out of it)",
                    file.display()
                );
            }
        }
    }
    // Not the graph's, but not bench's either: a file of another kind under one of its names.
    for file in &files {
        let name = file.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let kind = match name {
            "pareto.png" => Output::Png,
            "bench.md" => Output::TextStarting(report::MD_TITLE),
            "bench.json" => Output::JsonWith("points"),
            _ => Output::JsonWith("lanes"),
        };
        if let Some(problem) = super::paths::replace_refusal(file, kind) {
            bail!(
                "--out {dir}: bench writes or removes {name} there, and {} {problem}; give --out another directory \
                 (or move the file out of it)",
                file.display()
            );
        }
    }
    Ok(())
}

/// Runs one variant and reads the report its `compare` node wrote to `json` (removed first, so
/// a report is never an earlier run's). `health` gets the run's node errors and drops, also
/// when a node then failed.
fn run_variant(spec: &GraphSpec, json: &Path, label: &str, index: usize, health: &mut Health) -> Result<Vec<Point>> {
    remove(json)?;
    let report = skinflow_core::run(spec, &RunOptions::default()).map_err(|e| anyhow!("{e}"))?;
    *health = Health::of(&report.stats);
    if let Some(f) = report.failures.first() {
        match report.failures.len() {
            1 => bail!("{f}"),
            n => bail!("{f} (and {} more failures)", n - 1),
        }
    }
    let text = std::fs::read_to_string(json)
        .with_context(|| format!("its compare node wrote no report to {}", json.display()))?;
    let doc: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not a compare report", json.display()))?;
    report::points_of(label, index, &doc).with_context(|| format!("{}: not a compare report", json.display()))
}

/// Runs the variants and writes `bench.md`, `bench.json` and `pareto.png` into `out_dir`.
pub fn run(graph: &Path, replay: &Path, vary: &[Vary], out_dir: &Path) -> Result<()> {
    let text = std::fs::read_to_string(graph).with_context(|| format!("{}: cannot read", graph.display()))?;
    let reg = registry_for(&SourceFile::new(graph, text.clone()))?;
    let base: toml::Table =
        toml::from_str(&text).map_err(|e| anyhow!("{}: {}", graph.display(), skinflow_toml::message(&e)))?;
    check_vary(&base, vary)?;
    let replay = std::path::absolute(replay).with_context(|| format!("{}: bad path", replay.display()))?;
    if !replay.is_file() {
        bail!("{}: recording not found", replay.display());
    }
    // A file, or a place no directory can be made, before any variant runs.
    super::paths::check_output_dir("--out", out_dir)?;
    let out_abs = std::path::absolute(out_dir)?;
    // Every variant validates, and opens its input files, before any runs or anything is written.
    let mut specs: Vec<(String, Overrides, GraphSpec, PathBuf)> = Vec::new();
    for (k, (label, set)) in combinations(vary).into_iter().enumerate() {
        let json = out_abs.join(format!("variant-{k}.json"));
        let src = SourceFile::new(graph, variant_text(&base, &replay, &set, &json)?);
        // As `run` does: the input files (the recording, scenes, calibrations) are opened too,
        // the sensors they name must agree, and no output may replace an input.
        let spec = GraphSpec::parse(src, &reg)
            .and_then(|spec| skinflow_nodes::check_graph_files(&spec).map(|()| spec))
            .map_err(|e| invalid_variant(graph, &text, &reg, &label, e))?;
        specs.push((label, set, spec, json));
    }
    let stale = stale_outputs(&out_abs)?;
    check_out_dir(out_dir, &out_abs, &specs, &stale)?;
    std::fs::create_dir_all(out_dir).with_context(|| format!("{}: cannot create", out_dir.display()))?;
    for path in &stale {
        remove(path)?;
    }
    // The first variant once, unmeasured: the measured passes all start warm (caches, page
    // faults, allocator, lazily built tables). Its outcome is the measured pass's to report.
    if let Some((label, _, spec, json)) = specs.first() {
        eprintln!("bench: warm-up pass (variant 0, {label}; not measured)");
        let _ = skinflow_core::run(spec, &RunOptions { duration: Some(WARM_UP), ..RunOptions::default() });
        remove(json)?;
    }
    let mut points = Vec::new();
    let mut variants = Vec::new();
    for (index, (label, overrides, spec, json)) in specs.into_iter().enumerate() {
        eprintln!("bench: variant {index}: {label}");
        let mut health = Health::default();
        let error = match run_variant(&spec, &json, &label, index, &mut health) {
            Ok(p) => {
                points.extend(p);
                None
            }
            Err(e) => {
                eprintln!("bench: variant {index} failed: {e:#}");
                Some(format!("{e:#}"))
            }
        };
        variants.push(Variant { index, label, overrides, json, health, error });
    }
    report::mark_pareto(&mut points);
    let warnings = report::warnings(&variants, &points);
    for w in &warnings {
        eprintln!("bench: warning: {w}");
    }
    let md = report::markdown(graph, &replay, &variants, &points, &warnings);
    let write = |name: &str, body: &str| {
        std::fs::write(out_dir.join(name), body)
            .with_context(|| format!("{}: cannot write", out_dir.join(name).display()))
    };
    write("bench.md", &md)?;
    super::print_or_warn(&md, "the bench table (it is in bench.md)");
    let json = report::json(graph, &replay, &variants, &points, &warnings);
    write("bench.json", &(serde_json::to_string_pretty(&json)? + "\n"))?;
    let failed: Vec<&Variant> = variants.iter().filter(|v| v.error.is_some()).collect();
    if let Some(first) = failed.first() {
        if report::plottable(&points)
            && let Err(e) = report::plot(&out_dir.join("pareto.png"), &points)
        {
            eprintln!("bench: {e:#}");
        }
        bail!(
            "variant \"{}\": {} ({} of {} variants failed; {} shows the variants that ran)",
            first.label,
            first.error.as_deref().unwrap_or_default(),
            failed.len(),
            variants.len(),
            out_dir.join("bench.md").display()
        );
    }
    if !report::plottable(&points) {
        // Speed without error: the tables hold every lane's latency; there is no curve to draw.
        eprintln!(
            "bench: no lane has both a latency and an RMSE ({} has no truth, or no lane scored a frame): \
             wrote bench.md and bench.json to {}, no pareto.png",
            replay.display(),
            out_dir.display()
        );
        return Ok(());
    }
    report::plot(&out_dir.join("pareto.png"), &points)?;
    eprintln!("bench: wrote bench.md, bench.json and pareto.png to {}", out_dir.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vary_parses_values_as_toml_or_strings() {
        let v: Vary = "recon.lambda=0.01, 0.1".parse().unwrap();
        assert_eq!((v.node.as_str(), v.param.as_str()), ("recon", "lambda"));
        assert_eq!(v.values, vec![toml::Value::Float(0.01), toml::Value::Float(0.1)]);
        let s: Vary = "split.strategy=proportional,\"sensitivity-compensated\"".parse().unwrap();
        assert_eq!(s.values, vec![toml::Value::from("proportional"), toml::Value::from("sensitivity-compensated")]);
        assert!("recon=0.1".parse::<Vary>().is_err());
        assert!("recon.lambda=".parse::<Vary>().is_err());
    }

    #[test]
    fn combinations_are_the_cartesian_product() {
        let a: Vary = "a.x=1,2".parse().unwrap();
        let b: Vary = "b.y=3,4,5".parse().unwrap();
        let c = combinations(&[a, b]);
        assert_eq!(c.len(), 6);
        assert_eq!(c[0].0, "a.x=1 b.y=3");
        assert_eq!(c[5].0, "a.x=2 b.y=5");
        assert_eq!(combinations(&[])[0].0, "as written");
    }

    #[test]
    fn a_variant_runs_in_lockstep_without_thread_placement() {
        let base: toml::Table = toml::from_str(
            r#"
            [graph]
            mode = "realtime"
            workers = 2
            [[node]]
            id = "replay"
            kind = "replay"
            rt_priority = 10
            cpu = 0
            [[node]]
            id = "cmp"
            kind = "compare"
            thread = "dedicated"
            "#,
        )
        .unwrap();
        let text = variant_text(&base, Path::new("r.h5"), &[], Path::new("o.json")).unwrap();
        let doc: toml::Table = toml::from_str(&text).unwrap();
        assert_eq!(doc["graph"].as_table().unwrap().get("mode").and_then(toml::Value::as_str), Some("lockstep"));
        assert!(doc["graph"].as_table().unwrap().get("workers").is_none());
        for n in doc["node"].as_array().unwrap() {
            let n = n.as_table().unwrap();
            for key in ["cpu", "rt_priority", "thread"] {
                assert!(n.get(key).is_none(), "{key} left in {n:?}");
            }
        }
    }

    const TWO_NODES: &str = r#"
        [[node]]
        id = "replay"
        kind = "replay"
        params = { path = "x.h5", loop = true }
        [[node]]
        id = "cmp"
        kind = "compare"
        params = { json = "mine.json" }
        [[node]]
        id = "recon"
        kind = "reconstructor"
    "#;

    #[test]
    fn params_bench_sets_itself_cannot_be_varied() {
        let base: toml::Table = toml::from_str(TWO_NODES).unwrap();
        let check = |arg: &str| check_vary(&base, &[arg.parse().unwrap()]).map_err(|e| e.to_string());
        assert_eq!(check("recon.lambda=0.1"), Ok(()));
        assert_eq!(check("cmp.frames=\"all\""), Ok(()), "compare's other params can be varied");
        assert_eq!(
            check("cmp.json=\"/tmp/x.json\""),
            Err("--vary \"cmp.json\": bench sets param \"json\" of the compare node itself (json, report_s, print \
                 of a compare node), so it cannot be varied"
                .into())
        );
        for arg in ["cmp.report_s=1", "cmp.print=true", "replay.path=\"a.h5\"", "replay.speed=1", "replay.loop=true"] {
            let e = check(arg).unwrap_err();
            let key = arg.split('=').next().unwrap();
            assert!(e.starts_with(&format!("--vary \"{key}\": bench sets param")), "{arg}: {e}");
        }
        assert_eq!(check("nope.x=1"), Err("--vary \"nope.x\": no node \"nope\" in the graph".into()));
        let twice = check_vary(&base, &["recon.lambda=0.1".parse().unwrap(), "recon.lambda=0.2".parse().unwrap()]);
        assert!(twice.unwrap_err().to_string().contains("given twice"));
    }

    #[test]
    fn what_bench_sets_wins_over_the_graph_and_the_overrides() {
        let base: toml::Table = toml::from_str(TWO_NODES).unwrap();
        // check_vary refuses these; were one to get through, the variant still reports where
        // bench reads it.
        let set = vec![
            ("cmp".to_owned(), "json".to_owned(), toml::Value::from("/tmp/elsewhere.json")),
            ("recon".to_owned(), "lambda".to_owned(), toml::Value::from(0.5)),
        ];
        let text = variant_text(&base, Path::new("/r.h5"), &set, Path::new("/out/variant-0.json")).unwrap();
        let doc: toml::Table = toml::from_str(&text).unwrap();
        let params = |i: usize| doc["node"][i]["params"].as_table().unwrap().clone();
        assert_eq!(params(0)["path"].as_str(), Some("/r.h5"));
        assert_eq!((params(0)["speed"].as_float(), params(0)["loop"].as_bool()), (Some(0.0), Some(false)));
        assert_eq!(params(1)["json"].as_str(), Some("/out/variant-0.json"));
        assert_eq!((params(1)["report_s"].as_float(), params(1)["print"].as_bool()), (Some(0.0), Some(false)));
        assert_eq!(params(2)["lambda"].as_float(), Some(0.5));
    }

    #[test]
    fn an_earlier_runs_outputs_are_found_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("skinflow-bench-clear-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let ours = ["bench.md", "bench.json", "pareto.png", "variant-0.json", "variant-12.json"];
        let theirs = ["variant-.json", "variant-x.json", "notes.md", "variant-1.json.bak"];
        for f in ours.iter().chain(&theirs) {
            std::fs::write(dir.join(f), "x").unwrap();
        }
        let mut stale: Vec<String> = stale_outputs(&dir)
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        stale.sort();
        let mut want: Vec<String> = ours.iter().map(|s| s.to_string()).collect();
        want.sort();
        assert_eq!(stale, want);
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(stale_outputs(&dir).unwrap().is_empty(), "a directory not made yet holds none");
    }
}
