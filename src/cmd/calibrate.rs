//! `skinflow calibrate REC.h5 [MORE.h5 ...] --out CALIB.toml`: fits the force calibration
//! (paper section III) from single-contact recordings with ground truth, and prints the paper's
//! Table II. Several recordings (sessions of one skin, e.g. a grid recorded in two parts, or a
//! repaired recording and the one that finished the grid) are pooled: each is reconstructed
//! against its own no-load reference, and their samples are fitted together.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};
use sha2::{Digest, Sha256};
use skinflow_contact::CalibSample;
use skinflow_contact::correct::{
    CalibParams, Calibrated, CvGroups, FFit, PipelineSettings, Provenance, RecordingRef, SensorRef, calibrate,
};
use skinflow_nodes::payload::Contacts;

use super::pipeline::{PipelineArgs, Settled, SettledBy};

/// `sha256:<hex>` of a file's bytes.
pub fn content_hash(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let digest = Sha256::digest(&bytes);
    Ok(format!("sha256:{}", digest.iter().map(|b| format!("{b:02x}")).collect::<String>()))
}

/// Loaded frames a calibration left out, by cause.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct LeftOut {
    /// Their pressure change is unknown (`SyncedFrame::has_pressure`: a pressure dropout, no
    /// tare yet).
    pub without_pressure: usize,
    /// Acquired while the load changed, by the settled criterion in use.
    pub unsettled: usize,
}

/// Calibration samples: one per settled, loaded single-contact frame with a detection and a
/// known pressure change; and the loaded frames left out, by cause. Each sample carries its
/// hold number ([`CalibSample::hold`], from `first_hold` on): a frame acquired while the load
/// changed (not settled) or under another contact count (a release: none) ends the hold, so
/// repeated indentations with the same truth are averaged one by one, never into one sample.
/// A frame of a hold left out for its own reasons (no pressure sample, no detection) does not,
/// but a change of the truth since the hold's last sample does (the one frame spanning it may
/// have been left out so).
pub fn samples(
    rows: &[Vec<skinflow_core::Message>],
    settled: &Settled,
    first_hold: u64,
) -> (Vec<CalibSample>, LeftOut) {
    let mut out = Vec::new();
    let mut left = LeftOut::default();
    let mut hold = first_hold;
    // Whether the hold of the last sample goes on: a load change or release ends it.
    let mut in_hold = false;
    // The frame time of the last sample, s.
    let mut last_t = f64::NEG_INFINITY;
    for row in rows {
        let Some(m) = row.first() else { continue };
        let Some(c) = m.get::<Contacts>() else { continue };
        let synced = &c.image.src;
        if synced.no_load {
            continue;
        }
        if !synced.has_pressure() {
            left.without_pressure += 1;
            continue;
        }
        if !settled.is_settled(m.header.t_s(), synced) {
            left.unsettled += 1;
            in_hold = false;
            continue;
        }
        let Some(truth) = synced.truth.as_ref().filter(|t| t.contacts.len() == 1) else {
            in_hold = false;
            continue;
        };
        let t = truth.contacts[0];
        // The strongest detection is the indenter; weaker ones are artefacts.
        let Some(best) = c.contacts.iter().max_by(|a, b| a.sum.total_cmp(&b.sum)) else { continue };
        let t_s = m.header.t_s();
        if !in_hold || settled.load_changed_between(last_t, t_s) {
            hold += 1;
            in_hold = true;
        }
        last_t = t_s;
        out.push(CalibSample {
            x_mm: best.x_mm,
            y_mm: best.y_mm,
            true_x_mm: t.x_mm,
            true_y_mm: t.y_mm,
            force_n: t.force_n,
            dp_kpa: synced.dp_kpa,
            cond_sum: best.sum,
            area_mm2: best.area_mm2,
            diameter_mm: t.diameter_mm,
            hold,
        });
    }
    (out, left)
}

/// The `--fit` option of `calibrate` and `reproduce`.
#[derive(Debug, Clone, clap::Args)]
pub struct FitArgs {
    /// Calibration fit params, e.g. 'f_fit = "sequential"' (the paper's fitting order) or
    /// 'holdout_folds = 0' (no location-held-out check).
    #[arg(long, value_name = "TOML", default_value = "")]
    pub fit: String,
}

/// Parses the `--fit` TOML (fields of `CalibParams`; empty: the defaults). Errors are one
/// line naming the flag and its text (not the TOML parser's multi-line snippet).
pub fn fit_params(text: &str) -> Result<CalibParams> {
    let params: CalibParams =
        skinflow_toml::from_str(text).map_err(|e| anyhow::anyhow!("--fit '{text}': {}", e.message()))?;
    params.validate().map_err(|e| anyhow::anyhow!("--fit '{text}': {e}"))?;
    Ok(params)
}

/// Opens every recording before any is run through the pipeline: refuses one the pipeline
/// cannot use (not a recording, no EIT, pressure or truth, no finite EIT value at all) and
/// recordings of different sensors (sizes, electrodes or protocol: their samples or frames are
/// not comparable), naming the files. Returns the sensor they share.
pub fn check_recordings(recordings: &[PathBuf]) -> Result<SensorRef> {
    let mut first: Option<(SensorRef, &Path)> = None;
    for recording in recordings {
        let rec = super::pipeline::require_truth(recording)?;
        // NaN channels are masked (a dead electrode), but with none left there is no image:
        // every frame would fail in the reconstructor and leave "no frame" to use.
        if let Some(eit) = rec.eit.as_ref().filter(|e| !e.v.iter().any(|v| v.is_finite())) {
            bail!(
                "{}: /eit/v: no finite value in any of its {} frames (all NaN or infinite): there is nothing to reconstruct",
                recording.display(),
                eit.len()
            );
        }
        let sensor = skinflow_nodes::sensors::sensor_ref(&rec.sensor);
        drop(rec);
        match &first {
            None => first = Some((sensor, recording)),
            Some((shared, by)) if !shared.same_geometry(&sensor) => bail!(
                "{}: recorded on sensor {sensor}, but {} on {shared}; recordings of different sensors cannot be pooled",
                recording.display(),
                by.display()
            ),
            Some(_) => {}
        }
    }
    first.map(|(s, _)| s).ok_or_else(|| anyhow::anyhow!("no recording given"))
}

/// The calibration fitted on the samples of `recordings`; an error names them.
pub fn fit_samples(
    recordings: &[PathBuf],
    samples: &[CalibSample],
    params: &CalibParams,
    provenance: Provenance,
) -> Result<Calibrated> {
    calibrate(samples, params, provenance).map_err(|e| {
        let names: Vec<String> = recordings.iter().map(|r| r.display().to_string()).collect();
        anyhow::anyhow!("{}: {e}", names.join(", "))
    })
}

/// Runs the pipeline over a calibration recording and fits the calibration.
pub fn fit(recording: &Path, params: &CalibParams, args: &PipelineArgs) -> Result<Calibrated> {
    let recordings = [recording.to_path_buf()];
    let (samples, provenance) = collect(&recordings, args)?;
    fit_samples(&recordings, &samples, params, provenance)
}

/// Each recording with its content hash, in the order given; refuses the same recording given
/// twice (under any name), since its `what` (samples, frames) would count double.
pub fn distinct(recordings: &[PathBuf], what: &str) -> Result<Vec<RecordingRef>> {
    let mut refs: Vec<RecordingRef> = Vec::with_capacity(recordings.len());
    for recording in recordings {
        let hash = content_hash(recording)?;
        if let Some(same) = refs.iter().find(|r| r.recording_hash == hash) {
            bail!(
                "{}: the same recording as {} (both {hash}); give each recording once, or its {what} count double",
                recording.display(),
                same.recording
            );
        }
        refs.push(RecordingRef { recording: recording.display().to_string(), recording_hash: hash });
    }
    Ok(refs)
}

/// Runs the pipeline over each calibration recording (each with its own no-load reference
/// and tare, as recorded) and pools their samples: the samples in the order given, and the
/// provenance naming every recording. Refuses a recording that gives no sample and the same
/// recording given twice (its samples would count double), naming the files.
pub fn collect(recordings: &[PathBuf], args: &PipelineArgs) -> Result<(Vec<CalibSample>, Provenance)> {
    let sensor = check_recordings(recordings)?;
    let refs = distinct(recordings, "samples")?;
    let mut all: Vec<CalibSample> = Vec::new();
    for recording in recordings {
        // Hold numbers go on across recordings: the next one's first hold is another press.
        let first_hold = all.last().map_or(0, |s| s.hold);
        let samples = collect_one(recording, args, first_hold)?;
        if recordings.len() > 1 {
            eprintln!("{}: {} calibration samples", recording.display(), samples.len());
        }
        all.extend(samples);
    }
    let mut refs = refs.into_iter();
    let first = refs.next().ok_or_else(|| anyhow::anyhow!("no calibration recording given"))?;
    let provenance = Provenance {
        recording: first.recording,
        recording_hash: first.recording_hash,
        software_version: concat!("skinflow ", env!("CARGO_PKG_VERSION")).to_owned(),
        more_recordings: refs.collect(),
        pipeline: Some(PipelineSettings { recon: args.recon.clone(), segment: args.segment.clone() }),
        sensor: Some(sensor),
    };
    Ok((all, provenance))
}

/// The calibration samples of one recording (see [`samples`]); refused when there are none.
fn collect_one(recording: &Path, args: &PipelineArgs, first_hold: u64) -> Result<Vec<CalibSample>> {
    let (rows, settled) = args.run(recording, |_| ())?;
    let (samples, left) = samples(&rows, &settled, first_hold);
    let without_pressure = left.without_pressure;
    if without_pressure > 0 {
        eprintln!(
            "{}: {without_pressure} frames without pressure (no sample in their acquisition window, or before the tare) \
             were not used: their pressure change is unknown",
            recording.display()
        );
    }
    let synced = || rows.iter().filter_map(|r| r.first()?.get::<Contacts>()).map(|c| &*c.image.src);
    settled.warn_short_no_load(recording, synced());
    settled.warn_unknown_noise(recording, synced());
    if samples.is_empty() {
        // Say which filter left nothing: all frames judged unsettled points at the criterion.
        let hint = match (left.unsettled, settled.by) {
            (0, _) => String::new(),
            (n, SettledBy::Truth) => format!(
                " ({n} loaded frames were left out as acquired while the true load changed; if the truth \
                 rows change within every frame, try --settled-by pressure or --all-frames)"
            ),
            (n, SettledBy::Pressure) => format!(
                " ({n} loaded frames were left out as unsettled by pressure; try --settled-by truth or --all-frames)"
            ),
        };
        bail!(
            "{}: no loaded single-contact frame with a detected contact to calibrate from{hint}",
            recording.display()
        );
    }
    Ok(samples)
}

pub fn run(recordings: &[PathBuf], out: &Path, fit_toml: &str, args: &PipelineArgs) -> Result<()> {
    let inputs: Vec<(&str, &Path)> = recordings.iter().map(|r| ("recording", r.as_path())).collect();
    super::paths::check_outputs(&inputs, &[("--out", out)])?;
    super::paths::check_replaces("--out", out, super::paths::Output::Calibration)?;
    let params = fit_params(fit_toml)?;
    args.validate()?;
    let (samples, provenance) = collect(recordings, args)?;
    // Its warnings are logged by `calibrate` itself (target skinflow::calibrate).
    let fitted = fit_samples(recordings, &samples, &params, provenance)?;
    let cal = &fitted.calibration;
    // The tables go out in one piece once made (`print_or_warn`): a closed output (`| head`)
    // loses them, never the calibration file.
    let mut tables = String::new();
    let _ = writeln!(tables, "{}", cal.r2);
    let lam = |v: Option<f64>| v.map_or_else(|| "prior".to_string(), |v| format!("{v:.3e}"));
    let t = &cal.training;
    let why = if t.rejected_non_positive_dp + t.rejected_pressure_spikes > 0 {
        format!(": {} with dP <= 0, {} pressure spikes", t.rejected_non_positive_dp, t.rejected_pressure_spikes)
    } else {
        String::new()
    };
    let _ = writeln!(
        tables,
        "samples: {} frames -> {} used ({} rejected{why}) at {} locations, {} force levels; ridge lambda_g / lambda_b: \
         pneumatic {} / {}, EIT {} / {}",
        t.frames,
        t.samples,
        t.rejected,
        t.locations,
        t.force_levels,
        lam(cal.pneumatic.locaware.lambda_g),
        lam(cal.pneumatic.locaware.lambda_b),
        lam(cal.eit.locaware.lambda_g),
        lam(cal.eit.locaware.lambda_b),
    );
    // A weight at the end of the grid: at the top, the field is held at its prior (the data
    // do not support it); at the bottom, the grid may not reach the weight the data want.
    let (lo, hi) = params.lambda_grid_rel.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &l| (lo.min(l), hi.max(l)));
    let at = |rel: f64, v: f64| (v - rel * t.samples as f64).abs() <= 1e-9 * v.abs();
    for (name, field, v) in [
        ("pneumatic", "lambda_g", cal.pneumatic.locaware.lambda_g),
        ("pneumatic", "lambda_b", cal.pneumatic.locaware.lambda_b),
        ("EIT", "lambda_g", cal.eit.locaware.lambda_g),
        ("EIT", "lambda_b", cal.eit.locaware.lambda_b),
    ] {
        let Some(v) = v else { continue };
        let what = if field == "lambda_g" {
            "gain field g(x, y) is held near 1"
        } else {
            "offset field b(x, y) is held near 0"
        };
        if at(hi, v) {
            let _ = writeln!(
                tables,
                "note: {name} {field} is the top of the grid ({v:.3e}): the {what}, the data do not support more"
            );
        } else if at(lo, v) {
            let _ = writeln!(
                tables,
                "note: {name} {field} is the bottom of the grid ({v:.3e}): a smaller weight may fit better \
                 (lambda_grid_rel in --fit)"
            );
        }
    }
    let sign = |v: f64| if v < 0.0 { '-' } else { '+' };
    let folds = match params.cv_groups {
        CvGroups::Sample => "sample",
        CvGroups::Location => "location",
    };
    for (name, la) in [("pneumatic", &cal.pneumatic.locaware), ("EIT", &cal.eit.locaware)] {
        let q = la.map.quadratic;
        let _ = writeln!(
            tables,
            "{name} location-aware f ({}): {:.4} {} {:.4} s {} {:.4} s^2; CV RMSE {} N (the ridge weights' inner CV, \
             {folds} folds, f not held out: optimistic, see the held-out column below)",
            match la.f_fit {
                FFit::Joint => "fitted jointly with g and b",
                FFit::Sequential => "pooled, the paper's order",
            },
            q.a0,
            sign(q.a1),
            q.a1.abs(),
            sign(q.a2),
            q.a2.abs(),
            la.cv_rmse_n.map_or_else(|| "-".into(), |v| format!("{v:.3}")),
        );
    }
    let t = &cal.training;
    if t.holdout_folds > 0 {
        let _ = writeln!(
            tables,
            "RMSE per strategy, N: on the training samples, and at held-out locations ({} folds of the {} locations, the whole fit repeated without each)",
            t.holdout_folds, t.locations
        );
    } else {
        let _ = writeln!(
            tables,
            "RMSE per strategy, N, on the training samples (no held-out figures: {})",
            if params.holdout_folds == 0 { "turned off with holdout_folds = 0" } else { "see the warnings above" }
        );
    }
    let _ = writeln!(tables, "{:<34} {:>9} {:>9}", "strategy", "training", "held out");
    for (name, train) in &t.train_rmse_n {
        let held = t.holdout_rmse_n.get(name).map_or_else(|| "-".into(), |v| format!("{v:.3}"));
        let _ = writeln!(tables, "{name:<34} {train:>9.3} {held:>9}");
    }
    let text = cal.to_toml_string().map_err(anyhow::Error::msg)?;
    super::paths::write_file(&format!("--out {}", out.display()), out, text.as_bytes())?;
    super::print_or_warn(&tables, "the calibration tables");
    super::note(&format!("calibration written to {}", out.display()));
    Ok(())
}
