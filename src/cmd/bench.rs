//! `skinflow bench GRAPH.toml --replay REC.h5 --vary node.param=v1,v2,... [--out DIR]`: runs
//! every combination of the varied params on the same recording, in lockstep, and writes a
//! speed-against-error table (`bench.md`, `bench.json`) and a Pareto plot (`pareto.png`).
//!
//! The graph needs a `replay` node (its `path` is replaced by `--replay`) and a `compare` sink,
//! whose per-lane report (latency p50/p99, force RMSE against truth) gives one point per
//! (variant, lane). Each variant is the graph's TOML with the params overridden, so relative
//! paths and `[[plugin]]` entries resolve as in the original file. Thread placement
//! (`[graph] workers`, a node's `cpu`, `rt_priority`, `thread`) is dropped: a lockstep run is one
//! thread, and lockstep graphs refuse those options.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context as _, Result, anyhow, bail};
use plotters::prelude::*;
use skinflow_core::graph::{GraphErrors, SourceFile, plugin_paths};
use skinflow_core::{GraphSpec, Registry, RunOptions};

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

/// One point of the table: a lane of a variant.
#[derive(Debug, Clone)]
pub struct Point {
    pub variant: String,
    pub lane: String,
    pub frames: u64,
    pub latency_us_p50: Option<f64>,
    pub latency_us_p99: Option<f64>,
    pub rmse_n: Option<f64>,
    pub localization_mean_mm: Option<f64>,
    pub pareto: bool,
}

/// The overrides of one variant: (node id, param, value).
type Overrides = Vec<(String, String, toml::Value)>;

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

/// The graph text of one variant.
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
    let (mut replays, mut compares) = (0, 0);
    for n in nodes.iter_mut() {
        if let Some(table) = n.as_table_mut() {
            for placement in ["cpu", "rt_priority", "thread"] {
                table.remove(placement);
            }
        }
        match field(n, "kind") {
            Some("replay") => {
                replays += 1;
                let p = params_of(n)?;
                p.insert("path".into(), replay.to_string_lossy().into_owned().into());
                p.insert("speed".into(), 0.0.into());
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
    for (node, param, v) in set {
        let n = nodes
            .iter_mut()
            .find(|n| field(n, "id") == Some(node.as_str()))
            .ok_or_else(|| anyhow!("--vary: no node \"{node}\" in the graph"))?;
        params_of(n)?.insert(param.clone(), v.clone());
    }
    Ok(toml::to_string(&doc)?)
}

fn registry_for(src: &SourceFile) -> Result<Registry> {
    let mut reg = skinflow_nodes::registry();
    let plugins = plugin_paths(src).map_err(|e| anyhow::Error::new(super::InvalidGraph(e.to_string())))?;
    skinflow_nodes::codec::load_plugins(&plugins, &mut reg)
        .map_err(|e| anyhow::Error::new(super::InvalidGraph(format!("{}: {e}", src.path.display()))))?;
    Ok(reg)
}

fn num(v: &serde_json::Value, key: &str) -> Option<f64> {
    v.get(key).and_then(serde_json::Value::as_f64)
}

/// Marks the points no other point beats on both latency p50 and RMSE.
fn mark_pareto(points: &mut [Point]) {
    let xy: Vec<Option<(f64, f64)>> = points.iter().map(|p| p.latency_us_p50.zip(p.rmse_n)).collect();
    for (i, p) in points.iter_mut().enumerate() {
        let Some((x, y)) = xy[i] else { continue };
        p.pareto = !xy
            .iter()
            .enumerate()
            .any(|(j, o)| j != i && o.is_some_and(|(ox, oy)| ox <= x && oy <= y && (ox < x || oy < y)));
    }
}

fn points_json(points: &[Point]) -> serde_json::Value {
    let rows: Vec<serde_json::Value> = points
        .iter()
        .map(|p| {
            serde_json::json!({
                "variant": p.variant, "lane": p.lane, "frames": p.frames,
                "latency_us_p50": p.latency_us_p50, "latency_us_p99": p.latency_us_p99,
                "rmse_n": p.rmse_n, "localization_mean_mm": p.localization_mean_mm, "pareto": p.pareto,
            })
        })
        .collect();
    serde_json::json!({ "points": rows })
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{x:.digits$}"))
}

fn markdown(graph: &Path, replay: &Path, points: &[Point]) -> String {
    let mut s = format!("# skinflow bench\n\ngraph `{}`, recording `{}`\n\n", graph.display(), replay.display());
    s.push_str("| variant | lane | frames | p50 us | p99 us | RMSE N | loc. mm | Pareto |\n|---|---|---|---|---|---|---|---|\n");
    for p in points {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            p.variant,
            p.lane,
            p.frames,
            opt(p.latency_us_p50, 1),
            opt(p.latency_us_p99, 1),
            opt(p.rmse_n, 3),
            opt(p.localization_mean_mm, 2),
            if p.pareto { "yes" } else { "" }
        );
    }
    s
}

fn plot(path: &Path, points: &[Point]) -> Result<()> {
    let xy: Vec<(f64, f64, bool, String)> = points
        .iter()
        .filter_map(|p| {
            p.latency_us_p50.zip(p.rmse_n).map(|(x, y)| (x, y, p.pareto, format!("{} / {}", p.variant, p.lane)))
        })
        .collect();
    if xy.is_empty() {
        bail!("no point has both a latency and an RMSE (does the recording have truth?)");
    }
    // Room on the right for the point labels.
    let pad = |lo: f64, hi: f64, right: f64| {
        let d = (hi - lo).abs().max(hi.abs() * 0.05).max(1e-9);
        (lo - 0.1 * d, hi + right * d)
    };
    let (x0, x1) = pad(
        xy.iter().map(|p| p.0).fold(f64::INFINITY, f64::min),
        xy.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max),
        0.6,
    );
    let (y0, y1) = pad(
        xy.iter().map(|p| p.1).fold(f64::INFINITY, f64::min),
        xy.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max),
        0.1,
    );
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption("speed against error", ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0.max(0.0)..x1, y0.max(0.0)..y1)
        .map_err(|e| err(&e))?;
    chart.configure_mesh().x_desc("latency p50, us").y_desc("force RMSE, N").draw().map_err(|e| err(&e))?;
    let mut front: Vec<(f64, f64)> = xy.iter().filter(|p| p.2).map(|p| (p.0, p.1)).collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart.draw_series(LineSeries::new(front, RED.stroke_width(2))).map_err(|e| err(&e))?;
    for (x, y, pareto, label) in &xy {
        let color = if *pareto { RED } else { BLUE };
        chart.draw_series(std::iter::once(Circle::new((*x, *y), 5, color.filled()))).map_err(|e| err(&e))?;
        chart
            .draw_series(std::iter::once(Text::new(label.clone(), (*x, *y), ("sans-serif", 12))))
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
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

/// Runs the variants and writes `bench.md`, `bench.json` and `pareto.png` into `out_dir`.
pub fn run(graph: &Path, replay: &Path, vary: &[String], out_dir: &Path) -> Result<()> {
    let vary: Vec<Vary> = vary.iter().map(|s| s.parse()).collect::<Result<_>>()?;
    let text = std::fs::read_to_string(graph).with_context(|| format!("{}: cannot read", graph.display()))?;
    let reg = registry_for(&SourceFile::new(graph, text.clone()))?;
    let base: toml::Table = toml::from_str(&text).map_err(|e| anyhow!("{}: {}", graph.display(), e.message()))?;
    let replay = std::path::absolute(replay).with_context(|| format!("{}: bad path", replay.display()))?;
    if !replay.is_file() {
        bail!("{}: recording not found", replay.display());
    }
    let out_abs = std::path::absolute(out_dir)?;
    // Every variant validates before any runs or anything is written.
    let mut variants = Vec::new();
    for (k, (label, set)) in combinations(&vary).into_iter().enumerate() {
        let json = out_abs.join(format!("variant-{k}.json"));
        let src = SourceFile::new(graph, variant_text(&base, &replay, &set, &json)?);
        let spec = GraphSpec::parse(src, &reg).map_err(|e| invalid_variant(graph, &text, &reg, &label, e))?;
        variants.push((label, spec, json));
    }
    std::fs::create_dir_all(out_dir).with_context(|| format!("{}: cannot create", out_dir.display()))?;
    let mut points = Vec::new();
    for (k, (label, spec, json)) in variants.into_iter().enumerate() {
        eprintln!("bench: variant {k}: {label}");
        let report =
            skinflow_core::run(&spec, &RunOptions::default()).map_err(|e| anyhow!("variant \"{label}\": {e}"))?;
        if let Some(f) = report.failures.first() {
            bail!("variant \"{label}\": {f}");
        }
        let lanes: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(&json).with_context(|| format!("{}: cannot read", json.display()))?,
        )?;
        for l in lanes["lanes"].as_array().into_iter().flatten() {
            points.push(Point {
                variant: label.clone(),
                lane: l["name"].as_str().unwrap_or("?").to_owned(),
                frames: l["frames"].as_u64().unwrap_or(0),
                latency_us_p50: num(l, "latency_us_p50"),
                latency_us_p99: num(l, "latency_us_p99"),
                rmse_n: num(l, "rmse_n"),
                localization_mean_mm: num(l, "localization_mean_mm"),
                pareto: false,
            });
        }
    }
    mark_pareto(&mut points);
    let md = markdown(graph, &replay, &points);
    print!("{md}");
    let write = |name: &str, body: &str| {
        std::fs::write(out_dir.join(name), body)
            .with_context(|| format!("{}: cannot write", out_dir.join(name).display()))
    };
    write("bench.md", &md)?;
    write("bench.json", &serde_json::to_string_pretty(&points_json(&points))?)?;
    plot(&out_dir.join("pareto.png"), &points)?;
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
    fn pareto_keeps_undominated_points() {
        let p = |x: f64, y: f64| Point {
            variant: String::new(),
            lane: String::new(),
            frames: 1,
            latency_us_p50: Some(x),
            latency_us_p99: None,
            rmse_n: Some(y),
            localization_mean_mm: None,
            pareto: false,
        };
        let mut pts = vec![p(1.0, 5.0), p(2.0, 2.0), p(3.0, 3.0), p(4.0, 1.0), p(2.0, 2.0)];
        mark_pareto(&mut pts);
        let marks: Vec<bool> = pts.iter().map(|p| p.pareto).collect();
        assert_eq!(marks, vec![true, true, false, true, true], "(3, 3) is beaten by (2, 2); equal points both stay");
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
}
