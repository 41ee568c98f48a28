//! `skinflow eval REC.h5 [MORE.h5 ...] --calib CALIB.toml [--json OUT] [--plots DIR]`: every
//! force strategy on recordings with ground truth: the paper's Table III plus per-diameter RMSE,
//! localization, multi-contact per-contact RMSE, RES50/RES75 and each strategy's latency.
//! Several recordings (test sessions of one skin) are pooled into one report. `--lane` adds
//! lanes after the built-in nine: other strategies, or node kinds of `--plugin` libraries.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context as _, Result, bail};
use skinflow_contact::eval::metrics::{FrameInput, TruthContact, resolution};
use skinflow_contact::eval::{Evaluator, plots};
use skinflow_contact::{Calibration, ImageGrid, SegmentParams, Segmenter};
use skinflow_nodes::payload::{Contacts, Forces};

use super::pipeline::{PipelineArgs, SettledBy};

mod lanes;
pub use lanes::{ExtraLanes, LaneArgs};

/// (lane name, splitter, corrector strategy, label), in report order: the paper's four, then ours.
pub const LANES: [(&str, &str, &str, &str); 9] = [
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
    ("pneumatic-forward", "proportional", "pneumatic-forward", "Pneumatic-Forward"),
    ("pneumatic-forward-balance", "force-balance", "pneumatic-forward", "Pneumatic-Forward, force-balance split"),
];

/// The segmenter's output of a frame (its image, contacts and floor) with the true contact
/// centres of that frame, mm.
pub type Example = (Arc<Contacts>, Vec<(f64, f64)>);

pub struct EvalOutcome {
    pub evaluator: Evaluator,
    /// One CSV line per matched, missed or spurious contact of every evaluated frame (empty
    /// unless asked for).
    pub contact_rows: Vec<String>,
    /// A loaded frame's image with its contacts and truth, for the conductivity plot.
    pub example: Option<Example>,
}

/// Runs every lane over each recording and feeds one evaluator, so the figures pool the
/// recordings' frames (each recording is reconstructed against its own no-load reference and
/// tared on its own, as recorded); `want_rows` says whether to build the per-contact CSV lines.
pub fn evaluate(recordings: &[PathBuf], calib: &Path, args: &PipelineArgs, want_rows: bool) -> Result<EvalOutcome> {
    evaluate_lanes(recordings, calib, args, &ExtraLanes::default(), want_rows)
}

/// As [`evaluate`], with `extra` lanes after the built-in nine.
pub fn evaluate_lanes(
    recordings: &[PathBuf],
    calib: &Path,
    args: &PipelineArgs,
    extra: &ExtraLanes,
    want_rows: bool,
) -> Result<EvalOutcome> {
    let mut outcome =
        EvalOutcome { evaluator: Evaluator::new(&extra.labels()), contact_rows: Vec::new(), example: None };
    for recording in recordings {
        let frames = outcome.evaluator.frames();
        evaluate_one(recording, calib, args, extra, want_rows, &mut outcome)?;
        let evaluated = outcome.evaluator.frames() - frames;
        if evaluated == 0 {
            bail!(
                "{}: no frame to evaluate: every frame is a no-load frame (nothing pressed), was acquired while the \
                 load changed, or has no pressure (counts above)",
                recording.display()
            );
        }
        if recordings.len() > 1 {
            eprintln!("{}: {evaluated} frames evaluated", recording.display());
        }
    }
    Ok(outcome)
}

/// One recording's frames into `outcome` (see [`evaluate`]).
fn evaluate_one(
    recording: &Path,
    calib: &Path,
    args: &PipelineArgs,
    extra: &ExtraLanes,
    want_rows: bool,
    outcome: &mut EvalOutcome,
) -> Result<()> {
    let (rows, settled) = args.run(recording, |spec| {
        spec.calibration = Some(calib.to_path_buf());
        extra.configure(spec);
    })?;
    let lanes = outcome.evaluator.names().len();
    let EvalOutcome { evaluator: ev, contact_rows, example } = outcome;
    let mut truth = Vec::new();
    let mut detected = Vec::new();
    let mut transitions = 0usize;
    let mut without_pressure = 0usize;
    // Frames (loaded, not no-load) settled by each criterion: [truth only, pressure only, both, neither].
    let mut agreement = [0usize; 4];
    let csv_recording = csv_field(&recording.display().to_string());
    for row in &rows {
        let forces: Vec<&Forces> = row.iter().filter_map(|m| m.get::<Forces>()).collect();
        let Some(first) = forces.first() else { continue };
        let contacts = &first.split.contacts;
        let synced = &contacts.image.src;
        if synced.no_load {
            continue;
        }
        // No pneumatic force exists for it (placeholders flagged `no_pressure`): the frame is
        // left out for every strategy, so all are evaluated on the same frames.
        if !synced.has_pressure() {
            without_pressure += 1;
            continue;
        }
        let by_truth = settled.by_truth(row[0].header.t_s());
        agreement[match (by_truth, synced.settled) {
            (true, false) => 0,
            (false, true) => 1,
            (true, true) => 2,
            (false, false) => 3,
        }] += 1;
        if !settled.is_settled(row[0].header.t_s(), synced) {
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
        let frame = ev.frames();
        let pairs = ev
            .push(&FrameInput {
                truth: &truth,
                detected_mm: &detected,
                forces_n: &per_lane_ref,
                latency_us: &latency,
                resolution: res,
            })
            .map_err(anyhow::Error::msg)?;
        if want_rows {
            let ctx = CsvFrame {
                recording: &csv_recording,
                frame,
                t_s: row[0].header.t_s(),
                dp_kpa: synced.dp_kpa,
                n_truth: truth.len(),
                lanes,
            };
            for (t, truth_c) in truth.iter().enumerate() {
                let pred = pairs.iter().find(|p| p.truth == t).map(|p| p.pred);
                let lane_forces: Vec<f64> = pred.map_or_else(Vec::new, |p| per_lane.iter().map(|l| l[p]).collect());
                contact_rows.push(ctx.line(Some(truth_c), pred.map(|p| &contacts.contacts[p]), &lane_forces));
            }
            for (p, c) in contacts.contacts.iter().enumerate() {
                if !pairs.iter().any(|m| m.pred == p) {
                    let lane_forces: Vec<f64> = per_lane.iter().map(|l| l[p]).collect();
                    contact_rows.push(ctx.line(None, Some(c), &lane_forces));
                }
            }
        }
        let better = example.as_ref().is_none_or(|(_, t)| truth.len() > t.len());
        if better && !contacts.contacts.is_empty() {
            *example = Some((Arc::clone(contacts), truth.iter().map(|t| (t.x_mm, t.y_mm)).collect()));
        }
    }
    if transitions > 0 {
        let by = match settled.by {
            SettledBy::Truth => "truth",
            SettledBy::Pressure => "pressure",
        };
        eprintln!(
            "{}: {transitions} frames acquired while the load changed (judged by {by}) were not evaluated (--all-frames includes them)",
            recording.display()
        );
    }
    if without_pressure > 0 {
        eprintln!(
            "{}: {without_pressure} frames without pressure (no sample in their acquisition window, or before the tare) \
             were not evaluated: their pneumatic forces are flagged placeholders",
            recording.display()
        );
    }
    let [truth_only, pressure_only, both, neither] = agreement;
    eprintln!(
        "{}: settled frames by truth / by pressure: {} / {} of {} frames with pressure after the no-load period ({both} both, \
         {neither} neither, {truth_only} by truth only, {pressure_only} by pressure only)",
        recording.display(),
        truth_only + both,
        pressure_only + both,
        truth_only + pressure_only + both + neither,
    );
    let synced =
        || rows.iter().filter_map(|r| r.iter().find_map(|m| m.get::<Forces>())).map(|f| &*f.split.contacts.image.src);
    settled.warn_short_no_load(recording, synced());
    settled.warn_unknown_noise(recording, synced());
    Ok(())
}

/// A CSV field, quoted (RFC 4180) when it holds a comma, a quote or a line break.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) { format!("\"{}\"", text.replace('"', "\"\"")) } else { text.to_owned() }
}

/// Per-frame columns of the `--contacts-csv` table.
struct CsvFrame<'a> {
    /// The recording's path, as a CSV field.
    recording: &'a str,
    frame: usize,
    t_s: f64,
    dp_kpa: f64,
    n_truth: usize,
    /// Force columns (one per lane).
    lanes: usize,
}

impl CsvFrame<'_> {
    /// One row: `kind` is `matched`, `missed` (truth without detection) or `spurious`.
    fn line(&self, truth: Option<&TruthContact>, det: Option<&skinflow_contact::Contact>, forces: &[f64]) -> String {
        let kind = match (truth, det) {
            (Some(_), Some(_)) => "matched",
            (Some(_), None) => "missed",
            _ => "spurious",
        };
        let opt = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v:.6}"));
        let mut cols = vec![
            self.frame.to_string(),
            format!("{:.6}", self.t_s),
            kind.to_owned(),
            self.recording.to_owned(),
            self.n_truth.to_string(),
            format!("{:.6}", self.dp_kpa),
            opt(truth.map(|t| t.x_mm)),
            opt(truth.map(|t| t.y_mm)),
            opt(truth.map(|t| t.force_n)),
            opt(truth.map(|t| t.diameter_mm)),
            opt(det.map(|c| c.x_mm)),
            opt(det.map(|c| c.y_mm)),
            opt(det.map(|c| c.sum)),
            opt(det.map(|c| c.area_mm2)),
            opt(det.map(|c| c.peak)),
        ];
        cols.extend((0..self.lanes).map(|i| opt(forces.get(i).copied())));
        cols.join(",")
    }
}

/// Header of the `--contacts-csv` table (units in the names). `eval_frame` counts evaluated
/// frames over all recordings (no-load and load-change frames are skipped); `recording` is the
/// frame's recording as given on the command line; `t_s` is the frame's time in it. One force
/// column per lane (`names`, in order).
pub fn contacts_csv_header(names: &[String]) -> String {
    debug_assert!(CONTACTS_CSV_HEADER.starts_with(CONTACTS_CSV_START));
    let mut h = String::from(CONTACTS_CSV_HEADER);
    for name in names {
        h.push_str(&format!(",{name}_n"));
    }
    h
}

/// How every `--contacts-csv` table begins: an existing file that does not is not replaced.
const CONTACTS_CSV_START: &str = "eval_frame,t_s,";

/// The `--contacts-csv` columns before the lanes' forces.
const CONTACTS_CSV_HEADER: &str = "eval_frame,t_s,kind,recording,truth_contacts,dp_kpa,true_x_mm,true_y_mm,\
     true_force_n,true_diameter_mm,x_mm,y_mm,c_sum,area_mm2,peak";

/// The figures `--plots DIR` writes into DIR.
const PLOT_FILES: [&str; 4] = ["predicted_vs_true.png", "fields.png", "localization.png", "conductivity.png"];

/// Refuses a `--plots` directory holding, under a figure's name, an input (the recording, the
/// calibration), another output of this run, a FIFO or device, or a file that is no PNG image
/// (an HDF5 recording, a calibration, notes): a figure would replace it, or wait on it.
fn check_plot_files(dir: &Path, inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    use super::paths::{Output, replace_refusal, same_path};
    let d = dir.display();
    for name in PLOT_FILES {
        let file = dir.join(name);
        let (file, f) = (file.as_path(), file.display());
        if let Some((what, input)) = inputs.iter().find(|(_, p)| same_path(p, file)) {
            bail!(
                "--plots {d}: {f} is the {what} {}; a figure is written under that name, refusing to overwrite an \
                 input (give --plots another directory)",
                input.display()
            );
        }
        if let Some((flag, out)) = outputs.iter().find(|(_, p)| same_path(p, file)) {
            bail!("--plots {d} writes {f} and {flag} {} names the same file", out.display());
        }
        match std::fs::metadata(file) {
            // Opening a FIFO waits for its other end; a device is no place for a figure.
            Ok(m) if !m.is_file() && !m.is_dir() => {
                bail!("--plots {d}: {f} is not a regular file (a FIFO or a device); a figure is written as a file")
            }
            Ok(m) if m.is_file() && skinflow_record::read::hdf5_signature(file) == Some(true) => {
                bail!("--plots {d}: {f} is an HDF5 file (a recording?); refusing to replace it with a figure")
            }
            _ => {}
        }
    }
    // Then files of another kind (notes, a calibration not given as --calib) under a figure's name.
    for name in PLOT_FILES {
        let file = dir.join(name);
        if let Some(problem) = replace_refusal(&file, Output::Png) {
            bail!(
                "--plots {d}: {} {problem}; refusing to replace it with a figure: remove it, or give --plots \
                 another directory",
                file.display()
            );
        }
    }
    Ok(())
}

pub fn run(
    recordings: &[PathBuf],
    calib: &Path,
    json: Option<&Path>,
    plots_dir: Option<&Path>,
    contacts_csv: Option<&Path>,
    args: &PipelineArgs,
    lane_args: &LaneArgs,
) -> Result<()> {
    // The lanes first: their plugin libraries and calibrations are inputs too.
    let extra = ExtraLanes::resolve(lane_args, calib)?;
    let lane_files = extra.files();
    let mut inputs: Vec<(&str, &Path)> = recordings.iter().map(|r| ("recording", r.as_path())).collect();
    inputs.push(("--calib", calib));
    inputs.extend(lane_files.iter().map(|(what, p)| (what.as_str(), *p)));
    let outputs: Vec<(&str, &Path)> =
        [("--json", json), ("--contacts-csv", contacts_csv)].into_iter().filter_map(|(f, p)| Some((f, p?))).collect();
    super::paths::check_outputs(&inputs, &outputs)?;
    use super::paths::{Output, check_replaces};
    json.map_or(Ok(()), |p| check_replaces("--json", p, Output::JsonWith("strategies")))?;
    contacts_csv.map_or(Ok(()), |p| check_replaces("--contacts-csv", p, Output::TextStarting(CONTACTS_CSV_START)))?;
    if let Some(dir) = plots_dir {
        if inputs.iter().any(|(_, p)| super::paths::same_file(p, dir)) {
            bail!("--plots {}: is an input file, not a directory for the plots", dir.display());
        }
        if let Some((flag, _)) = outputs.iter().find(|(_, p)| *p == dir) {
            bail!("--plots {} and {flag} {} name the same path", dir.display(), dir.display());
        }
        // Before the evaluation, not after the JSON and the table are written.
        super::paths::check_output_dir("--plots", dir)?;
        check_plot_files(dir, &inputs, &outputs)?;
    }
    let cal = check_calibration(calib)?;
    args.validate_with(
        |spec| {
            spec.calibration = Some(calib.to_path_buf());
            extra.configure(spec);
        },
        |spec, node| extra.origin(spec, node),
    )?;
    args.warn_calibration_settings(calib, cal.provenance.pipeline.as_ref());
    // Every recording is checked before the first is evaluated.
    let sensor = super::calibrate::check_recordings(recordings)?;
    if let Some(fitted_on) = &cal.provenance.sensor
        && !fitted_on.same_geometry(&sensor)
    {
        bail!(
            "--calib {}: fitted on sensor {fitted_on}, but {} was recorded on {sensor}; a calibration's region, \
             fields and conductivity scale belong to its sensor: calibrate on recordings of this one",
            calib.display(),
            recordings[0].display()
        );
    }
    // A lane's own calibration gets the checks `--calib` gets.
    for (lane, path) in extra.calibrations(calib) {
        let lane_cal = Calibration::read(path).map_err(|e| anyhow::anyhow!("--lane '{lane}': calibration: {e}"))?;
        if let Some(fitted_on) = &lane_cal.provenance.sensor
            && !fitted_on.same_geometry(&sensor)
        {
            bail!(
                "--lane '{lane}': calibration {}: fitted on sensor {fitted_on}, but {} was recorded on {sensor}; \
                 calibrate on recordings of this one",
                path.display(),
                recordings[0].display()
            );
        }
        args.warn_calibration_settings(path, lane_cal.provenance.pipeline.as_ref());
    }
    if recordings.len() > 1 {
        super::calibrate::distinct(recordings, "frames")?;
    }
    let outcome = evaluate_lanes(recordings, calib, args, &extra, contacts_csv.is_some())?;
    if let Some(p) = contacts_csv {
        let mut text = contacts_csv_header(outcome.evaluator.names());
        text.push('\n');
        for line in &outcome.contact_rows {
            text.push_str(line);
            text.push('\n');
        }
        super::paths::write_file(&format!("--contacts-csv {}", p.display()), p, text.as_bytes())?;
        super::note(&format!("per-contact table written to {}", p.display()));
    }
    let mut names = recordings.iter().map(|r| r.display().to_string());
    let mut report = outcome.evaluator.report(&names.next().unwrap_or_default());
    report.more_recordings = names.collect();
    super::print_or_warn(&format!("{report}\n"), "the evaluation tables");
    if let Some(p) = json {
        super::paths::write_file(&format!("--json {}", p.display()), p, report.to_json().as_bytes())?;
        super::note(&format!("JSON written to {}", p.display()));
    }
    if let Some(dir) = plots_dir {
        write_plots(dir, calib, &outcome, args)?;
    }
    Ok(())
}

/// Refuses a `--calib` that is missing or not a calibration before the pipeline runs.
pub fn check_calibration(calib: &Path) -> Result<Calibration> {
    if !calib.is_file() {
        let why = if calib.exists() { "is not a file" } else { "does not exist" };
        anyhow::bail!("--calib {}: {why} (pass a calibration from `skinflow calibrate`)", calib.display());
    }
    let cal = Calibration::read(calib).map_err(|e| anyhow::anyhow!("--calib: {e}"))?;
    for name in cal.flat_maps() {
        eprintln!(
            "--calib {}: warning: {name}: the force does not rise over its calibrated signal range, so every \
             contact of the strategies using it gets the same force (0 N where it clamps)",
            calib.display()
        );
    }
    Ok(cal)
}

fn write_plots(dir: &Path, calib: &Path, o: &EvalOutcome, args: &PipelineArgs) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("--plots {}: cannot create", dir.display()))?;
    let cal = Calibration::read(calib).map_err(anyhow::Error::msg)?;
    let p = |name: &str| -> PathBuf { dir.join(name) };
    // A figure that fails (a full disk) leaves no truncated PNG behind, and names the flag.
    let drawn = |path: PathBuf, result: Result<(), plots::PlotError>| -> Result<()> {
        result.map_err(|e| {
            let _ = std::fs::remove_file(&path);
            anyhow::anyhow!("--plots {}: {e}", dir.display())
        })
    };
    drawn(p("predicted_vs_true.png"), plots::predicted_vs_true(&p("predicted_vs_true.png"), &o.evaluator))?;
    drawn(p("fields.png"), plots::fields(&p("fields.png"), &cal))?;
    if let Some((contacts, truth)) = &o.example {
        let img = &contacts.image;
        let grid = ImageGrid::centred(img.width, img.height, img.width_mm, img.height_mm);
        let (hx, hy) = (img.width_mm / 2.0, img.height_mm / 2.0);
        let map = p("localization.png");
        drawn(map.clone(), plots::localization_map(&map, &o.evaluator, (-hx, hx, -hy, hy)))?;
        // The frame's regions as the pipeline's segmenter cut them: at the floor it used (the
        // no-load noise's, when higher than `floor`) and through its crosstalk pass, so the
        // figure shows the contacts that were evaluated.
        let seg_params: skinflow_nodes::segment::SegmenterParams =
            skinflow_toml::from_str(&args.segment).map_err(|e| anyhow::anyhow!("--segment: {e}"))?;
        let params = SegmentParams { floor: contacts.floor, ..seg_params.math() };
        let mut seg = Segmenter::new(grid, &params).map_err(anyhow::Error::msg)?;
        let mut found = seg.new_contacts();
        skinflow_nodes::segment::segment_image(&mut seg, &params, img, &mut found).map_err(anyhow::Error::msg)?;
        let image = p("conductivity.png");
        drawn(image.clone(), plots::conductivity(&image, &img.pixels, &grid, seg.labels(), found.as_slice(), truth))?;
    }
    super::note(&format!("plots written to {}", dir.display()));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::csv_field;

    #[test]
    fn csv_fields_are_quoted_only_when_needed() {
        assert_eq!(csv_field("out/a.h5"), "out/a.h5");
        assert_eq!(csv_field("runs,2/a.h5"), "\"runs,2/a.h5\"");
        assert_eq!(csv_field("say \"hi\".h5"), "\"say \"\"hi\"\".h5\"");
    }
}
