//! `skinflow eval REC.h5 --calib CALIB.toml [--json OUT] [--plots DIR]`: every force strategy
//! on a recording with ground truth: the paper's Table III plus per-diameter RMSE,
//! localization, multi-contact per-contact RMSE, RES50/RES75 and each strategy's latency.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context as _, Result};
use skinflow_contact::eval::metrics::{FrameInput, TruthContact, resolution};
use skinflow_contact::eval::{Evaluator, plots};
use skinflow_contact::{Calibration, ImageGrid, Segmenter};
use skinflow_nodes::payload::{Forces, Image};

use super::calibrate::require_truth;
use super::pipeline::{PipelineArgs, Settled};

/// (lane name, splitter, corrector strategy, label), in report order: the paper's four, then ours.
pub const LANES: [(&str, &str, &str, &str); 7] = [
    ("eit-nocal", "proportional", "eit-nocal", "EIT-NoCal"),
    ("pneumatic-nocal", "proportional", "pneumatic-nocal", "Pneumatic-NoCal"),
    ("eit-locaware", "proportional", "eit-locaware", "EIT-LocAware"),
    ("pneumatic-locaware", "proportional", "pneumatic-locaware", "Pneumatic-LocAware (proposed)"),
    (
        "pneumatic-locaware-sensitivity",
        "sensitivity-compensated",
        "pneumatic-locaware",
        "Pneumatic-LocAware, sens.-comp. split",
    ),
    ("pneumatic-locaware-eitforce", "eit-force", "pneumatic-locaware", "Pneumatic-LocAware, EIT-force split"),
    ("pneumatic-area-aware", "proportional", "pneumatic-area-aware", "Pneumatic-AreaAware"),
];

/// An image with the true contact centres of its frame, mm.
pub type Example = (Arc<Image>, Vec<(f64, f64)>);

pub struct EvalOutcome {
    pub evaluator: Evaluator,
    /// A loaded frame's image with its contacts and truth, for the conductivity plot.
    pub example: Option<Example>,
}

/// Runs every lane over the recording and feeds the evaluator.
pub fn evaluate(recording: &Path, calib: &Path, args: &PipelineArgs) -> Result<EvalOutcome> {
    let rec = require_truth(recording)?;
    let settled = Settled::of(&rec, args.all_frames);
    drop(rec);
    let mut spec = args.spec(recording.to_path_buf());
    spec.calibration = Some(calib.to_path_buf());
    spec.lanes = LANES.iter().map(|(n, s, c, _)| ((*n).to_owned(), (*s).to_owned(), (*c).to_owned())).collect();
    if args.print_graph {
        println!("{}", spec.graph_toml());
    }
    let rows = spec.run().map_err(|e| anyhow::anyhow!("{}: pipeline: {e}", recording.display()))?;
    let labels: Vec<(&str, &str)> = LANES.iter().map(|(n, _, _, l)| (*n, *l)).collect();
    let mut ev = Evaluator::new(&labels);
    let mut example: Option<Example> = None;
    let mut truth = Vec::new();
    let mut detected = Vec::new();
    let mut transitions = 0usize;
    for row in &rows {
        let forces: Vec<&Forces> = row.iter().filter_map(|m| m.get::<Forces>()).collect();
        let Some(first) = forces.first() else { continue };
        let contacts = &first.split.contacts;
        let synced = &contacts.image.src;
        if synced.no_load {
            continue;
        }
        if !settled.is_settled(row[0].header.t_s()) {
            transitions += 1;
            continue;
        }
        truth.clear();
        if let Some(t) = &synced.truth {
            truth.extend(t.contacts.iter().map(|c| TruthContact {
                x_mm: c.x_mm,
                y_mm: c.y_mm,
                force_n: c.force_n,
                diameter_mm: c.diameter_mm,
            }));
        }
        detected.clear();
        detected.extend(contacts.contacts.iter().map(|c| (c.x_mm, c.y_mm)));
        let per_lane: Vec<Vec<f64>> = forces.iter().map(|f| f.forces.iter().map(|e| e.force_n).collect()).collect();
        let per_lane_ref: Vec<&[f64]> = per_lane.iter().map(Vec::as_slice).collect();
        let latency: Vec<f64> = forces.iter().map(|f| f.pipeline_ns() as f64 / 1e3).collect();
        let res = if truth.len() == 1 && contacts.contacts.len() == 1 {
            resolution(&contacts.image.pixels, &contacts.contacts)
        } else {
            None
        };
        ev.push(&FrameInput {
            truth: &truth,
            detected_mm: &detected,
            forces_n: &per_lane_ref,
            latency_us: &latency,
            resolution: res,
        })
        .map_err(anyhow::Error::msg)?;
        let better = example.as_ref().is_none_or(|(_, t)| truth.len() > t.len());
        if better && !contacts.contacts.is_empty() {
            example = Some((contacts.image.clone(), truth.iter().map(|t| (t.x_mm, t.y_mm)).collect()));
        }
    }
    if transitions > 0 {
        eprintln!(
            "{}: {transitions} frames acquired while the load changed were not evaluated (--all-frames includes them)",
            recording.display()
        );
    }
    Ok(EvalOutcome { evaluator: ev, example })
}

pub fn run(
    recording: &Path,
    calib: &Path,
    json: Option<&Path>,
    plots_dir: Option<&Path>,
    args: &PipelineArgs,
) -> Result<()> {
    let outcome = evaluate(recording, calib, args)?;
    let report = outcome.evaluator.report(&recording.display().to_string());
    println!("{report}");
    if let Some(p) = json {
        std::fs::write(p, report.to_json()).with_context(|| format!("{}: cannot write", p.display()))?;
        eprintln!("JSON written to {}", p.display());
    }
    if let Some(dir) = plots_dir {
        write_plots(dir, calib, &outcome, args)?;
    }
    Ok(())
}

fn write_plots(dir: &Path, calib: &Path, o: &EvalOutcome, args: &PipelineArgs) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let cal = Calibration::read(calib).map_err(anyhow::Error::msg)?;
    let p = |name: &str| -> PathBuf { dir.join(name) };
    plots::predicted_vs_true(&p("predicted_vs_true.png"), &o.evaluator).map_err(anyhow::Error::msg)?;
    plots::fields(&p("fields.png"), &cal).map_err(anyhow::Error::msg)?;
    if let Some((img, truth)) = &o.example {
        let grid = ImageGrid::centred(img.width, img.height, img.width_mm, img.height_mm);
        let (hx, hy) = (img.width_mm / 2.0, img.height_mm / 2.0);
        plots::localization_map(&p("localization.png"), &o.evaluator, (-hx, hx, -hy, hy))
            .map_err(anyhow::Error::msg)?;
        let seg_params: skinflow_nodes::segment::SegmenterParams =
            toml::from_str(&args.segment).map_err(|e| anyhow::anyhow!("--segment: {}", e.message()))?;
        let mut seg = Segmenter::new(grid, &seg_params.math()).map_err(anyhow::Error::msg)?;
        let mut found = seg.new_contacts();
        seg.segment_into(&img.pixels, &mut found).map_err(anyhow::Error::msg)?;
        plots::conductivity(&p("conductivity.png"), &img.pixels, &grid, seg.labels(), found.as_slice(), truth)
            .map_err(anyhow::Error::msg)?;
    }
    eprintln!("plots written to {}", dir.display());
    Ok(())
}
