//! What `skinflow bench` writes: the points (one per lane of a variant) with their Pareto
//! marks, each variant's run health (node errors, drops, failure), the warnings when the points
//! do not cover the same frames, and the three outputs (`bench.md`, `bench.json`,
//! `pareto.png`).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};
use plotters::prelude::*;
use skinflow_core::StatsReport;

use super::Overrides;

/// The first line of `bench.md` (an existing file under that name that does not start so is
/// not bench's, and is not replaced).
pub const MD_TITLE: &str = "# skinflow bench";

/// What bench says about its latency figures, in `bench.md` (and the README).
pub const TIMING_NOTE: &str = "Latency is wall time on this machine, one lockstep pass per variant, after a \
     discarded warm-up pass of the first variant (so it does not run cold). Identical \
     configurations have differed by about 10 % in p50 from one pass to the next, so a Pareto \
     mark decided by a smaller latency difference is noise: run bench again before relying on it.";

/// One point of the table: a lane of a variant.
#[derive(Debug, Clone, Default)]
pub struct Point {
    pub variant: String,
    /// The variant's index (its report is `variant-<index>.json`).
    pub variant_index: usize,
    pub lane: String,
    /// Frames timed (the latency is over these).
    pub frames: u64,
    /// Frames whose errors were scored (RMSE and localization): `frames - unsettled_frames`.
    pub scored_frames: u64,
    /// Frames timed but not scored, acquired while the load changed.
    pub unsettled_frames: u64,
    /// Frames left out because the lane's forces were placeholders (no pressure): not in `frames`.
    pub no_pressure_frames: u64,
    /// Contacts matched to the truth on scored frames (the RMSE is over these).
    pub matched: u64,
    pub missed: u64,
    pub spurious: u64,
    pub latency_us_p50: Option<f64>,
    pub latency_us_p99: Option<f64>,
    pub rmse_n: Option<f64>,
    pub relative_error_pct: Option<f64>,
    pub localization_mean_mm: Option<f64>,
    pub pareto: bool,
}

fn num(v: &serde_json::Value, key: &str) -> Option<f64> {
    v.get(key).and_then(serde_json::Value::as_f64)
}

fn count(v: &serde_json::Value, key: &str) -> Result<u64> {
    v.get(key).and_then(serde_json::Value::as_u64).ok_or_else(|| anyhow!("a lane without \"{key}\""))
}

/// The points of one variant's `compare` report (its JSON: `{"lanes": [...]}`).
pub fn points_of(label: &str, index: usize, report: &serde_json::Value) -> Result<Vec<Point>> {
    let lanes = report.get("lanes").and_then(serde_json::Value::as_array).ok_or_else(|| anyhow!("no \"lanes\""))?;
    lanes
        .iter()
        .map(|l| {
            Ok(Point {
                variant: label.to_owned(),
                variant_index: index,
                lane: l
                    .get("name")
                    .and_then(serde_json::Value::as_str)
                    .ok_or_else(|| anyhow!("a lane without \"name\""))?
                    .to_owned(),
                frames: count(l, "frames")?,
                unsettled_frames: count(l, "unsettled_frames")?,
                // Compare's own count: frames with truth or a reference lane to score against.
                scored_frames: count(l, "scored_frames")?,
                no_pressure_frames: count(l, "no_pressure_frames")?,
                matched: count(l, "matched")?,
                missed: count(l, "missed")?,
                spurious: count(l, "spurious")?,
                latency_us_p50: num(l, "latency_us_p50"),
                latency_us_p99: num(l, "latency_us_p99"),
                rmse_n: num(l, "rmse_n"),
                relative_error_pct: num(l, "relative_error_pct"),
                localization_mean_mm: num(l, "localization_mean_mm"),
                pareto: false,
            })
        })
        .collect()
}

/// A node that erred, panicked, was restarted or discarded messages in a variant's run.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct NodeTrouble {
    pub node: String,
    pub errors: u64,
    pub panics: u64,
    pub restarts: u64,
    pub discarded: u64,
}

/// An edge that lost messages in a variant's run.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct EdgeTrouble {
    pub from: String,
    pub to: String,
    pub dropped_full: u64,
    pub dropped_unaligned: u64,
    pub dropped_coalesced: u64,
    pub undelivered: u64,
}

/// What a variant's run report says beyond its lanes: every node error and drop. Any of them
/// means some frames did not reach `compare` (or reached it in fewer lanes), so that variant's
/// points may cover other frames than the rest.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Health {
    pub nodes: Vec<NodeTrouble>,
    pub edges: Vec<EdgeTrouble>,
}

impl Health {
    pub fn of(stats: &StatsReport) -> Health {
        let nodes = stats
            .nodes
            .iter()
            .filter(|n| n.errors + n.panics + n.restarts + n.discarded > 0)
            .map(|n| NodeTrouble {
                node: n.id.clone(),
                errors: n.errors,
                panics: n.panics,
                restarts: n.restarts,
                discarded: n.discarded,
            })
            .collect();
        let edges = stats
            .edges
            .iter()
            .filter(|e| e.dropped_full + e.dropped_unaligned + e.dropped_coalesced + e.undelivered > 0)
            .map(|e| EdgeTrouble {
                from: e.from.clone(),
                to: e.to.clone(),
                dropped_full: e.dropped_full,
                dropped_unaligned: e.dropped_unaligned,
                dropped_coalesced: e.dropped_coalesced,
                undelivered: e.undelivered,
            })
            .collect();
        Health { nodes, edges }
    }

    pub fn is_clean(&self) -> bool {
        self.nodes.is_empty() && self.edges.is_empty()
    }

    /// `node "recon": 3 errors; edge a.x -> b.y: 2 unaligned`, or `no node errors or drops`.
    pub fn describe(&self) -> String {
        if self.is_clean() {
            return "no node errors or drops".into();
        }
        let counts = |parts: &[(u64, &str)]| {
            parts.iter().filter(|(n, _)| *n > 0).map(|(n, what)| format!("{n} {what}")).collect::<Vec<_>>().join(", ")
        };
        let nodes = self.nodes.iter().map(|n| {
            let c = counts(&[
                (n.errors, "errors"),
                (n.panics, "panics"),
                (n.restarts, "restarts"),
                (n.discarded, "discarded"),
            ]);
            format!("node \"{}\": {c}", n.node)
        });
        let edges = self.edges.iter().map(|e| {
            let c = counts(&[
                (e.dropped_full, "evicted"),
                (e.dropped_unaligned, "unaligned"),
                (e.dropped_coalesced, "coalesced"),
                (e.undelivered, "undelivered"),
            ]);
            format!("edge {} -> {}: {c}", e.from, e.to)
        });
        nodes.chain(edges).collect::<Vec<_>>().join("; ")
    }
}

/// One variant as run: its label and overrides, where its `compare` report is, what went wrong.
#[derive(Debug, Clone)]
pub struct Variant {
    pub index: usize,
    pub label: String,
    pub overrides: Overrides,
    /// Its `compare` report (`variant-<index>.json` in the output directory).
    pub json: PathBuf,
    pub health: Health,
    /// Why it gave no points (it did not start, a node failed, no report).
    pub error: Option<String>,
}

/// Marks the points no other point beats on both latency p50 and RMSE.
pub fn mark_pareto(points: &mut [Point]) {
    let xy: Vec<Option<(f64, f64)>> = points.iter().map(|p| p.latency_us_p50.zip(p.rmse_n)).collect();
    for (i, p) in points.iter_mut().enumerate() {
        let Some((x, y)) = xy[i] else { continue };
        p.pareto = !xy
            .iter()
            .enumerate()
            .any(|(j, o)| j != i && o.is_some_and(|(ox, oy)| ox <= x && oy <= y && (ox < x || oy < y)));
    }
}

/// The warnings about figures that are not comparable: variants whose runs had node errors or
/// drops, and points (lanes of variants) that timed or scored different numbers of frames.
pub fn warnings(variants: &[Variant], points: &[Point]) -> Vec<String> {
    let mut out: Vec<String> = variants
        .iter()
        .filter(|v| v.error.is_none() && !v.health.is_clean())
        .map(|v| format!("variant \"{}\" lost frames on the way: {}", v.label, v.health.describe()))
        .collect();
    out.extend(
        variants
            .iter()
            .filter(|v| v.error.is_none() && !points.iter().any(|p| p.variant_index == v.index))
            .map(|v| format!("variant \"{}\" gave no point: its compare node received no forces", v.label)),
    );
    // Points by (timed, scored) frame counts, in order of first appearance.
    let mut groups: Vec<((u64, u64), Vec<String>)> = Vec::new();
    for p in points {
        let key = (p.frames, p.scored_frames);
        let name = format!("{} / {}", p.variant, p.lane);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, names)) => names.push(name),
            None => groups.push((key, vec![name])),
        }
    }
    if groups.len() > 1 {
        let parts: Vec<String> = groups
            .iter()
            .map(|((timed, scored), names)| {
                let who = if names.len() > 3 { format!("{} points", names.len()) } else { names.join(", ") };
                format!("{timed} timed / {scored} scored ({who})")
            })
            .collect();
        out.push(format!(
            "the points do not cover the same frames: {}; their latency and RMSE are over different frame sets",
            parts.join("; ")
        ));
    }
    out
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{x:.digits$}"))
}

fn file_name(p: &Path) -> String {
    p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}

pub fn markdown(graph: &Path, replay: &Path, variants: &[Variant], points: &[Point], warnings: &[String]) -> String {
    let mut s = format!("{MD_TITLE}\n\ngraph `{}`, recording `{}`\n\n", graph.display(), replay.display());
    s.push_str(
        "| variant | lane | frames | scored | unsettled | matched | p50 us | p99 us | RMSE N | loc. mm | Pareto |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for p in points {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            p.variant,
            p.lane,
            p.frames,
            p.scored_frames,
            p.unsettled_frames,
            p.matched,
            opt(p.latency_us_p50, 1),
            opt(p.latency_us_p99, 1),
            opt(p.rmse_n, 3),
            opt(p.localization_mean_mm, 2),
            if p.pareto { "yes" } else { "" }
        );
    }
    s.push_str(
        "\nframes: frames timed (p50, p99); scored: those whose errors count (the settled ones, or all \
         with compare's `frames = \"all\"`); unsettled: timed, not scored; matched: contacts matched \
         to the truth on scored frames (RMSE and loc. are over these).\n",
    );
    if !warnings.is_empty() {
        s.push_str("\n## Warnings\n\n");
        for w in warnings {
            let _ = writeln!(s, "- {w}");
        }
    }
    s.push_str("\n## Runs\n\n");
    for v in variants {
        let what = match &v.error {
            Some(e) => format!("FAILED: {e}"),
            None => format!("{}; every lane's report in `{}`", v.health.describe(), file_name(&v.json)),
        };
        let _ = writeln!(s, "- variant {} `{}`: {what}", v.index, v.label);
    }
    let _ = writeln!(s, "\n{TIMING_NOTE}");
    s
}

fn points_json(points: &[Point]) -> Vec<serde_json::Value> {
    points
        .iter()
        .map(|p| {
            serde_json::json!({
                "variant": p.variant, "variant_index": p.variant_index, "lane": p.lane,
                "frames": p.frames, "scored_frames": p.scored_frames, "unsettled_frames": p.unsettled_frames,
                "no_pressure_frames": p.no_pressure_frames, "matched": p.matched, "missed": p.missed,
                "spurious": p.spurious, "latency_us_p50": p.latency_us_p50, "latency_us_p99": p.latency_us_p99,
                "rmse_n": p.rmse_n, "relative_error_pct": p.relative_error_pct,
                "localization_mean_mm": p.localization_mean_mm, "pareto": p.pareto,
            })
        })
        .collect()
}

fn variants_json(variants: &[Variant]) -> Vec<serde_json::Value> {
    variants
        .iter()
        .map(|v| {
            let overrides: BTreeMap<String, &toml::Value> =
                v.overrides.iter().map(|(node, param, x)| (format!("{node}.{param}"), x)).collect();
            serde_json::json!({
                "index": v.index, "label": v.label, "overrides": overrides,
                "compare_json": v.error.is_none().then(|| file_name(&v.json)),
                "error": v.error, "node_errors": v.health.nodes, "edge_drops": v.health.edges,
            })
        })
        .collect()
}

pub fn json(
    graph: &Path,
    replay: &Path,
    variants: &[Variant],
    points: &[Point],
    warnings: &[String],
) -> serde_json::Value {
    serde_json::json!({
        "graph": graph.display().to_string(),
        "recording": replay.display().to_string(),
        "warm_up": "variant 0, run once before the measured passes and discarded",
        "points": points_json(points),
        "variants": variants_json(variants),
        "warnings": warnings,
    })
}

/// Whether [`plot`] has anything to draw.
pub fn plottable(points: &[Point]) -> bool {
    points.iter().any(|p| p.latency_us_p50.is_some() && p.rmse_n.is_some())
}

pub fn plot(path: &Path, points: &[Point]) -> Result<()> {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn point(variant: &str, lane: &str, frames: u64, scored: u64) -> Point {
        Point { variant: variant.into(), lane: lane.into(), frames, scored_frames: scored, ..Point::default() }
    }

    fn variant(label: &str, health: Health) -> Variant {
        Variant {
            index: 0,
            label: label.into(),
            overrides: Vec::new(),
            json: PathBuf::from("variant-0.json"),
            health,
            error: None,
        }
    }

    #[test]
    fn pareto_keeps_undominated_points() {
        let p = |x: f64, y: f64| Point { latency_us_p50: Some(x), rmse_n: Some(y), ..Point::default() };
        let mut pts = vec![p(1.0, 5.0), p(2.0, 2.0), p(3.0, 3.0), p(4.0, 1.0), p(2.0, 2.0)];
        mark_pareto(&mut pts);
        let marks: Vec<bool> = pts.iter().map(|p| p.pareto).collect();
        assert_eq!(marks, vec![true, true, false, true, true], "(3, 3) is beaten by (2, 2); equal points both stay");
    }

    #[test]
    fn points_covering_different_frames_are_warned_about() {
        let same = [point("a", "x", 79, 55), point("a", "y", 79, 55), point("b", "x", 79, 55)];
        assert!(warnings(&[], &same).is_empty());
        let differ = [point("a", "x", 79, 55), point("a", "y", 79, 55), point("b", "x", 78, 54)];
        let w = warnings(&[], &differ);
        assert_eq!(
            w,
            ["the points do not cover the same frames: 79 timed / 55 scored (a / x, a / y); \
              78 timed / 54 scored (b / x); their latency and RMSE are over different frame sets"]
        );
        // Same timed frames, fewer scored: also not the same frame set.
        let scored = [point("a", "x", 79, 55), point("b", "x", 79, 50)];
        assert_eq!(warnings(&[], &scored).len(), 1);
    }

    #[test]
    fn node_errors_and_drops_are_described_and_warned_about() {
        let health = Health {
            nodes: vec![NodeTrouble { node: "recon".into(), errors: 3, panics: 0, restarts: 0, discarded: 1 }],
            edges: vec![EdgeTrouble {
                from: "f.forces".into(),
                to: "compare.forces".into(),
                dropped_full: 0,
                dropped_unaligned: 2,
                dropped_coalesced: 0,
                undelivered: 0,
            }],
        };
        assert_eq!(
            health.describe(),
            "node \"recon\": 3 errors, 1 discarded; edge f.forces -> compare.forces: 2 unaligned"
        );
        let (clean, mut lossy) = (variant("clean", Health::default()), variant("lossy", health));
        lossy.index = 1;
        let points = [Point { variant_index: 0, ..Point::default() }, Point { variant_index: 1, ..Point::default() }];
        let w = warnings(&[clean.clone(), lossy.clone()], &points);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].starts_with("variant \"lossy\" lost frames on the way: node \"recon\""), "{w:?}");
        // A variant that gave no point at all is one more warning.
        let w = warnings(&[clean, lossy], &points[..1]);
        assert_eq!(w[1], "variant \"lossy\" gave no point: its compare node received no forces", "{w:?}");
        assert_eq!(Health::default().describe(), "no node errors or drops");
    }

    #[test]
    fn points_read_every_count_of_a_compare_report() {
        let report = serde_json::json!({ "lanes": [{
            "name": "p", "frames": 79, "unsettled_frames": 24, "scored_frames": 55, "no_pressure_frames": 1, "matched": 90,
            "missed": 2, "spurious": 3, "latency_us_p50": 200.0, "latency_us_p99": null, "rmse_n": 0.5,
            "relative_error_pct": 10.0, "localization_mean_mm": 2.0,
        }]});
        let p = &points_of("v", 2, &report).unwrap()[0];
        assert_eq!(
            (p.variant_index, p.frames, p.scored_frames, p.unsettled_frames, p.no_pressure_frames),
            (2, 79, 55, 24, 1)
        );
        assert_eq!((p.matched, p.missed, p.spurious), (90, 2, 3));
        assert_eq!((p.latency_us_p50, p.latency_us_p99, p.rmse_n), (Some(200.0), None, Some(0.5)));
        let missing = serde_json::json!({ "lanes": [{ "name": "p", "frames": 79 }] });
        let e = points_of("v", 0, &missing).unwrap_err().to_string();
        assert_eq!(e, "a lane without \"unsettled_frames\"");
    }
}
