//! Calibration fit, strategies and guards on synthetic data with known nonuniformity.

use crate::synth;

use skinflow_contact::correct::average_holds;
use skinflow_contact::correct::calibrate::{CalibParams, CalibSample, CalibWarning, calibrate};
use skinflow_contact::correct::calibration::{
    Calibration, CvGroups, FFit, FORMAT_VERSION, OLDEST_FORMAT_VERSION, Provenance, RecordingRef, SensorRef,
};
use skinflow_contact::correct::field::{NPHI, Region, phi};
use skinflow_contact::correct::fit::{CvSearch, RidgeProblem, cross_validate, fold_of};
use skinflow_contact::{Contact, Strategy, StrategyKind};

fn provenance() -> Provenance {
    Provenance {
        recording: "synthetic.h5".into(),
        recording_hash: "sha256:0000".into(),
        software_version: "0.1.0".into(),
        more_recordings: Vec::new(),
        pipeline: None,
        sensor: None,
    }
}

fn fitted() -> Calibration {
    calibrate(&synth::paper_like(11), &CalibParams::default(), provenance()).unwrap().calibration
}

fn contact(x_mm: f64, y_mm: f64, sum: f64) -> Contact {
    Contact { x_mm, y_mm, sum, area_mm2: 400.0, peak: 1.0, label: 1 }
}

/// Rows [f Phi, Phi] over a 7 x 7 grid of normalized points and 4 signal levels.
fn field_problem(noise_sd: f64, seed: u64) -> (Vec<f64>, Vec<f64>, [f64; 6], [f64; 6]) {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let alpha = [1.05, 0.02, -0.03, 0.08, -0.04, 0.06];
    let beta = [0.1, -0.05, 0.02, 0.03, 0.0, -0.02];
    let (mut d, mut y) = (Vec::new(), Vec::new());
    for i in 0..7 {
        for j in 0..7 {
            for f in [1.0, 3.0, 6.0, 9.0] {
                let (u, v) = (-1.0 + i as f64 / 3.0, -1.0 + j as f64 / 3.0);
                let p = phi(u, v);
                let g: f64 = p.iter().zip(&alpha).map(|(a, b)| a * b).sum();
                let b: f64 = p.iter().zip(&beta).map(|(a, b)| a * b).sum();
                d.extend(p.iter().map(|v| v * f));
                d.extend_from_slice(&p);
                y.push(g * f + b + noise_sd * n.sample(&mut rng));
            }
        }
    }
    (d, y, alpha, beta)
}

fn cv_fit(d: &[f64], y: &[f64]) -> skinflow_contact::correct::fit::CvFit {
    let mut prior = vec![0.0; 2 * NPHI];
    prior[0] = 1.0;
    let grid: Vec<f64> = (0..=16).map(|i| 10f64.powf(-4.0 + 0.5 * i as f64) * y.len() as f64).collect();
    let problem = RidgeProblem { design: d, y, p: 2 * NPHI, prior: &prior, base_penalty: &[0.0; 2 * NPHI] };
    cross_validate(&problem, &CvSearch { blocks: &[0..NPHI, NPHI..2 * NPHI], grid: &grid, folds: 5, groups: None })
        .unwrap()
}

#[test]
fn ridge_cv_recovers_known_gain_and_offset_fields() {
    let (d, y, alpha, beta) = field_problem(0.0, 1);
    let fit = cv_fit(&d, &y);
    // Noise-free: CV picks the smallest weights (1e-4 x T); the prior's pull then biases
    // the coefficients by ~1e-4 relative, far below the 2e-3 tolerance.
    for k in 0..NPHI {
        assert!((fit.coeffs[k] - alpha[k]).abs() < 2e-3, "alpha[{k}] {} vs {}", fit.coeffs[k], alpha[k]);
        assert!((fit.coeffs[NPHI + k] - beta[k]).abs() < 2e-3, "beta[{k}] {} vs {}", fit.coeffs[NPHI + k], beta[k]);
    }
    assert_eq!(fit.lambdas[0], 1e-4 * y.len() as f64);
}

#[test]
fn cross_validation_picks_larger_weights_on_noisy_data() {
    let (d, clean, _, _) = field_problem(0.0, 2);
    let (_, noisy, _, _) = field_problem(3.0, 2);
    let a = cv_fit(&d, &clean);
    let b = cv_fit(&d, &noisy);
    assert!(b.lambdas[0] > a.lambdas[0] && b.lambdas[1] > a.lambdas[1], "clean {:?}, noisy {:?}", a.lambdas, b.lambdas);
}

#[test]
fn holds_are_averaged_and_their_spread_reported() {
    let frames = synth::paper_like(3);
    let holds = average_holds(&frames);
    assert_eq!(holds.samples.len(), 25 * 5);
    assert!(holds.sd_dp_kpa > 0.005 && holds.sd_dp_kpa < 0.015, "{}", holds.sd_dp_kpa);
    let first = &frames[..6];
    let mean_dp = first.iter().map(|s| s.dp_kpa).sum::<f64>() / 6.0;
    assert!((holds.samples[0].dp_kpa - mean_dp).abs() < 1e-12);
}

#[test]
fn calibration_reproduces_the_paper_ordering_on_training_data() {
    let cal = fitted();
    let rmse = &cal.training.train_rmse_n;
    let r = |k: StrategyKind| rmse[k.name()];
    assert!(r(StrategyKind::PneumaticLocAware) < 0.5 * r(StrategyKind::PneumaticNoCal), "{rmse:?}");
    assert!(r(StrategyKind::PneumaticNoCal) < r(StrategyKind::EitNoCal), "{rmse:?}");
    assert!(r(StrategyKind::EitLocAware) < r(StrategyKind::EitNoCal), "{rmse:?}");
    // Table II shape: pneumatic beats EIT, the centre beats all locations.
    let t = cal.r2;
    assert!(t.pneumatic_all.unwrap() > t.eit_all.unwrap());
    assert!(t.pneumatic_center.unwrap() >= t.pneumatic_all.unwrap());
    assert_eq!(cal.training.center_location_mm, Some([0.0, 0.0]));
    assert_eq!((cal.training.samples, cal.training.locations, cal.training.frames), (125, 25, 750));
    assert!(!cal.pneumatic.locaware.prior_fallback);
    // Edges are less sensitive (k < 1), so the gain is higher at a corner than at the centre.
    let g = &cal.pneumatic.locaware.gain;
    assert!(g.at(1.0, 1.0) > g.at(0.0, 0.0));
}

#[test]
fn joint_f_fit_removes_the_pooled_curve_bias_and_sequential_keeps_the_papers_order() {
    // dP = 0.3 F k(u, v): F = f(dP) / k is separable, but the pooled F(dP) mixes locations of
    // different k and so bends; only the joint fit can find the straight f.
    let frames = synth::paper_like(11);
    let joint = calibrate(&frames, &CalibParams::default(), provenance()).unwrap().calibration;
    let params = CalibParams { f_fit: FFit::Sequential, ..CalibParams::default() };
    let seq = calibrate(&frames, &params, provenance()).unwrap().calibration;
    assert_eq!(joint.pneumatic.locaware.f_fit, FFit::Joint);
    assert_eq!(seq.pneumatic.locaware.f_fit, FFit::Sequential);
    // Sequential: the fields multiply the pooled map, as in the paper.
    assert_eq!(seq.pneumatic.locaware.map, seq.pneumatic.map);
    // NoCal is untouched by the choice.
    assert_eq!(joint.pneumatic.map, seq.pneumatic.map);
    let name = StrategyKind::PneumaticLocAware.name();
    let (j, s) = (joint.training.train_rmse_n[name], seq.training.train_rmse_n[name]);
    assert!(j < 0.7 * s, "joint {j} N vs sequential {s} N");
    // The joint f is nearly straight: its curvature over the range is small next to its slope.
    let q = joint.pneumatic.locaware.map.quadratic;
    let hi = joint.pneumatic.locaware.map.signal_max;
    assert!((q.a2 * hi).abs() < 0.05 * q.a1, "{q:?}");
    // And the area-aware strategy builds on the same f.
    assert_eq!(joint.area_aware.fields.map, joint.pneumatic.locaware.map);
}

/// The held-out check by hand: locations (in order of first appearance) dealt into folds with
/// the same fixed-seed deal, a fit without each fold, predicting that fold's hold means.
fn holdout_by_hand(frames: &[CalibSample], params: &CalibParams) -> (Vec<f64>, usize) {
    let mut sites: Vec<(f64, f64)> = frames.iter().map(|f| (f.true_x_mm, f.true_y_mm)).collect();
    sites.dedup();
    let fold = fold_of(sites.len(), params.holdout_folds);
    let fold_of_frame = |f: &CalibSample| fold[sites.iter().position(|&s| s == (f.true_x_mm, f.true_y_mm)).unwrap()];
    let mut sse = vec![0.0; StrategyKind::ALL.len()];
    let mut n = 0;
    for k in 0..params.holdout_folds {
        let train: Vec<CalibSample> = frames.iter().copied().filter(|f| fold_of_frame(f) != k).collect();
        let held: Vec<CalibSample> = frames.iter().copied().filter(|f| fold_of_frame(f) == k).collect();
        // The fit alone: its own held-out check does not change the fitted calibration.
        let fit_only = CalibParams { holdout_folds: 0, ..params.clone() };
        let without = calibrate(&train, &fit_only, provenance()).unwrap().calibration;
        for s in average_holds(&held).samples {
            for (e, kind) in sse.iter_mut().zip(StrategyKind::ALL) {
                let c = Contact { area_mm2: s.area_mm2, ..contact(s.x_mm, s.y_mm, s.cond_sum) };
                *e += (Strategy::new(&without, kind).estimate(&c, s.dp_kpa).force_n - s.force_n).powi(2);
            }
            n += 1;
        }
    }
    (sse.iter().map(|e| (e / n as f64).sqrt()).collect(), n)
}

/// Leave-one-location-out (holdout_folds = locations) and whole multi-location folds
/// (holdout_folds = 3) give the figures a fit repeated by hand without each fold gives, with the
/// inner cross-validation over samples or over whole locations (its own fold count).
#[test]
fn location_holdout_refits_without_each_fold_of_locations() {
    let frames = synth::frames(11, 3, &[1.0, 3.0, 5.0, 7.0, 9.0], 6, 0.01);
    for (folds, cv_groups) in [(9, CvGroups::Sample), (3, CvGroups::Sample), (3, CvGroups::Location)] {
        let params = CalibParams { holdout_folds: folds, cv_groups, ..CalibParams::default() };
        let cal = calibrate(&frames, &params, provenance()).unwrap().calibration;
        assert_eq!(cal.training.holdout_folds, folds);
        assert_eq!((cal.training.folds, cal.training.cv_groups), (CalibParams::default().folds, cv_groups));
        if cv_groups == CvGroups::Location {
            // The grouping reaches the fit: whole held-out locations give another CV error.
            let by_sample = CalibParams { cv_groups: CvGroups::Sample, ..params.clone() };
            let sample_cal = calibrate(&frames, &by_sample, provenance()).unwrap().calibration;
            let (a, b) = (cal.pneumatic.locaware.cv_rmse_n.unwrap(), sample_cal.pneumatic.locaware.cv_rmse_n.unwrap());
            assert!((a - b).abs() > 1e-6, "location {a} vs sample {b}");
        }
        let (by_hand, n) = holdout_by_hand(&frames, &params);
        assert_eq!(n, cal.training.samples);
        for (want, kind) in by_hand.iter().zip(StrategyKind::ALL) {
            let got = cal.training.holdout_rmse_n[kind.name()];
            assert!((got - want).abs() <= 1e-9 * want.max(1.0), "folds {folds}, {}: {got} vs {want}", kind.name());
        }
        // Unseen places cost something, and the fields still generalize on this smooth skin.
        let (train, held) = (&cal.training.train_rmse_n, &cal.training.holdout_rmse_n);
        let la = StrategyKind::PneumaticLocAware.name();
        assert!(held[la] > train[la], "folds {folds}: {held:?} {train:?}");
        let nocal = held[StrategyKind::PneumaticNoCal.name()];
        match cv_groups {
            CvGroups::Sample => assert!(held[la] < 0.5 * nocal, "folds {folds}: {held:?}"),
            // Each fit sees 6 locations, so a location-grouped inner fold trains the 12 field
            // coefficients on 4 or 5: the weights it picks keep the fields near the prior.
            CvGroups::Location => assert!(held[la] < nocal, "folds {folds}: {held:?}"),
        }
    }
}

#[test]
fn location_holdout_is_skipped_with_a_warning_when_folds_are_too_small() {
    // 9 locations in 5 folds of 1 or 2; fields need 8 locations, so a fold of 2 leaves too few.
    let frames = synth::frames(3, 3, &[1.0, 3.0, 5.0, 7.0, 9.0], 6, 0.01);
    let params = CalibParams { min_locations: 8, ..CalibParams::default() };
    let out = calibrate(&frames, &params, provenance()).unwrap();
    assert!(!out.calibration.pneumatic.locaware.prior_fallback);
    let skipped = out.warnings.iter().find_map(|w| match w {
        CalibWarning::HoldoutSkipped { reason } => Some(reason.clone()),
        _ => None,
    });
    let reason = skipped.unwrap_or_else(|| panic!("{:?}", out.warnings));
    assert!(reason.contains("leaves") && reason.contains("7 locations, too few for the fields"), "{reason}");
    assert!(out.calibration.training.holdout_rmse_n.is_empty());
    assert_eq!(out.calibration.training.holdout_folds, 0);
    assert!(out.calibration.warnings.iter().any(|w| w.starts_with("location-held-out check skipped: fold")));
}

/// `holdout_folds = 0` turns the check off: no figures, no warning, and the same calibration.
#[test]
fn location_holdout_can_be_turned_off() {
    let frames = synth::frames(11, 3, &[1.0, 3.0, 5.0, 7.0, 9.0], 6, 0.01);
    let on = calibrate(&frames, &CalibParams::default(), provenance()).unwrap();
    let off = calibrate(&frames, &CalibParams { holdout_folds: 0, ..CalibParams::default() }, provenance()).unwrap();
    assert!(!on.calibration.training.holdout_rmse_n.is_empty());
    assert!(off.calibration.training.holdout_rmse_n.is_empty() && off.calibration.training.holdout_folds == 0);
    assert!(off.warnings.iter().all(|w| !matches!(w, CalibWarning::HoldoutSkipped { .. })), "{:?}", off.warnings);
    assert_eq!(off.calibration.pneumatic, on.calibration.pneumatic);
    assert_eq!(off.calibration.training.train_rmse_n, on.calibration.training.train_rmse_n);
}

#[test]
fn table_two_layout() {
    let text = fitted().r2.to_string();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4);
    assert!(
        lines[1].starts_with("Signal") && lines[1].contains("Center location") && lines[1].ends_with("All locations")
    );
    assert!(lines[2].starts_with("EIT conductivity change sum"));
    assert!(lines[3].starts_with("Pneumatic pressure"));
}

#[test]
fn calibration_file_with_too_many_field_coefficients_is_refused_at_the_key() {
    // toml alone reads `gain` into the six coefficients of a quadratic field and drops the
    // rest, a calibration whose forces are several times off; the load must refuse it.
    let text = fitted().to_toml_string().unwrap();
    let mut doc: toml::Table = toml::from_str(&text).unwrap();
    let gain = doc["pneumatic"]["locaware"]["gain"].as_array().unwrap().len();
    assert_eq!(gain, NPHI);
    let locaware = doc.get_mut("pneumatic").and_then(|p| p.get_mut("locaware")).unwrap();
    let gain = locaware.get_mut("gain").and_then(|g| g.as_array_mut()).unwrap();
    gain.extend([toml::Value::Float(0.5), toml::Value::Float(-0.25)]);
    let bad = toml::to_string_pretty(&doc).unwrap();
    let err = Calibration::from_toml_str(&bad, "calib.toml").unwrap_err().to_string();
    assert!(err.starts_with("calib.toml:"), "{err}");
    assert!(err.contains("expected an array of 6 elements, found 8"), "{err}");
    // `file:line:col: key path: cause`, as graph and scene files are reported: the line of the
    // key, the column of its value, and none of toml's snippet.
    let section = bad.find("[pneumatic.locaware]").unwrap();
    let key = section + bad[section..].find("gain = ").unwrap();
    let line = bad[..key].matches('\n').count() + 1;
    assert_eq!(err, format!("calib.toml:{line}:8: pneumatic.locaware.gain: expected an array of 6 elements, found 8"));
    // An integer beyond 64 bits, refused by toml's own reading of the file, is said to be
    // out of range (not "u64 value was too large").
    let version = text.lines().find(|l| l.starts_with("format_version = ")).unwrap();
    let bad = text.replacen(version, "format_version = 18446744073709551615", 1);
    let err = Calibration::from_toml_str(&bad, "calib.toml").unwrap_err().to_string();
    assert!(err.contains(": integer out of range (TOML integers are 64-bit, "), "{err}");
}

#[test]
fn calibration_file_round_trips_and_rejects_unknown_keys() {
    let cal = fitted();
    let text = cal.to_toml_string().unwrap();
    let back = Calibration::from_toml_str(&text, "<test>").unwrap();
    assert_eq!(back, cal);
    assert!(text.contains("recording_hash = \"sha256:0000\""));
    let bad = text.replacen("[provenance]", "[provenance]\nsurprise = 1", 1);
    let err = Calibration::from_toml_str(&bad, "calib.toml").unwrap_err().to_string();
    assert!(err.starts_with("calib.toml:") && err.contains("surprise"), "{err}");
    // Values the per-frame math cannot use are refused at load, named.
    let bad = text.replacen("exponent = ", "exponent = -", 1);
    let err = Calibration::from_toml_str(&bad, "calib.toml").unwrap_err().to_string();
    assert!(err.starts_with("calib.toml:") && err.contains("sensitivity.exponent"), "{err}");
    // A hand-edited coefficient that is not finite is named by its key.
    let q = "[pneumatic.map.quadratic]\n";
    let at = text.find(q).expect("the pneumatic map's coefficients") + q.len();
    let line_end = at + text[at..].find('\n').unwrap();
    let (key, _) = text[at..line_end].split_once(" = ").unwrap();
    let bad = format!("{}{key} = nan{}", &text[..at], &text[line_end..]);
    let err = Calibration::from_toml_str(&bad, "calib.toml").unwrap_err().to_string();
    assert!(err.contains(&format!("pneumatic.map.quadratic.{key} = NaN: must be finite")), "{err}");
    // A region the fields divide by (zero width), or a field fitted on another region.
    let mut flat = cal.clone();
    flat.region.x_max_mm = flat.region.x_min_mm;
    let err = Calibration::from_toml_str(&flat.to_toml_string().unwrap(), "calib.toml").unwrap_err().to_string();
    assert!(err.contains("region must be finite with positive width"), "{err}");
    assert!(err.contains(&format!("x_min_mm = {0}, x_max_mm = {0}, ", flat.region.x_min_mm)), "no Debug text: {err}");
    // Non-finite or inverted values the per-frame math would turn into a silent floor, a
    // panic in a clamp, or nonsense forces.
    let mut nan_gain = cal.clone();
    nan_gain.pneumatic.locaware.gain.coeffs[0] = f64::NAN;
    let mut nan_area = cal.clone();
    nan_area.area_aware.rel_area_min = f64::NAN;
    let mut inverted_area = cal.clone();
    (inverted_area.area_aware.rel_area_min, inverted_area.area_aware.rel_area_max) = (0.5, -0.5);
    let mut zero_ref = cal.clone();
    zero_ref.area_aware.area_ref_mm2 = 0.0;
    let mut inverted_signal = cal.clone();
    std::mem::swap(&mut inverted_signal.pneumatic.map.signal_min, &mut inverted_signal.pneumatic.map.signal_max);
    for (c, want) in [
        (nan_gain, "pneumatic.locaware.gain[0] = NaN: must be finite"),
        (nan_area, "area_aware.rel_area_min = NaN: must be finite"),
        (inverted_area, "rel_area_min (0.5) must be <= rel_area_max (-0.5)"),
        (zero_ref, "area_aware.area_ref_mm2 must be finite and > 0"),
        (inverted_signal, "pneumatic.map: signal_min"),
    ] {
        let err = match c.validate() {
            Err(e) => e,
            Ok(()) => panic!("accepted: {want}"),
        };
        assert!(err.contains(want), "{err}");
    }
    let mut moved = cal.clone();
    moved.forward.sensitivity.region.x_max_mm += 5.0;
    let err = Calibration::from_toml_str(&moved.to_toml_string().unwrap(), "calib.toml").unwrap_err().to_string();
    assert!(err.contains("forward.sensitivity.region must equal [region]"), "{err}");
    // Version 3 files (before the location-held-out figures) still load, without them.
    let v3: String = text
        .lines()
        .filter(|l| !l.starts_with("holdout_folds") && !l.starts_with("cv_groups"))
        .collect::<Vec<_>>()
        .join("\n")
        .replacen(
            &format!("format_version = {FORMAT_VERSION}"),
            &format!("format_version = {OLDEST_FORMAT_VERSION}"),
            1,
        );
    let v3 = v3.split("[training.holdout_rmse_n]").next().unwrap().to_string();
    let old = Calibration::from_toml_str(&v3, "v3.toml").unwrap();
    assert!(old.training.holdout_rmse_n.is_empty() && old.training.holdout_folds == 0);
    assert_eq!(old.training.cv_groups, CvGroups::Sample, "what older files did");
    assert_eq!(old.training.train_rmse_n, cal.training.train_rmse_n);
    // Read as the current version, so writing it back gives a consistent file.
    assert_eq!(old.format_version, FORMAT_VERSION);
    assert_eq!(Calibration::from_toml_str(&old.to_toml_string().unwrap(), "<test>").unwrap(), old);
    // Version 4 files (before cv_groups) load as sample folds, keeping their held-out figures.
    let v4: String = text.lines().filter(|l| !l.starts_with("cv_groups")).collect::<Vec<_>>().join("\n").replacen(
        &format!("format_version = {FORMAT_VERSION}"),
        "format_version = 4",
        1,
    );
    let old = Calibration::from_toml_str(&v4, "v4.toml").unwrap();
    assert_eq!(old.training.cv_groups, CvGroups::Sample);
    assert_eq!(old.training.holdout_rmse_n, cal.training.holdout_rmse_n);
    assert_eq!(old.format_version, FORMAT_VERSION);
    // Version 5 files (one recording only) load with no further recordings.
    let v5 = text.replacen(&format!("format_version = {FORMAT_VERSION}"), "format_version = 5", 1);
    let old = Calibration::from_toml_str(&v5, "v5.toml").unwrap();
    assert!(old.provenance.more_recordings.is_empty() && old.provenance == cal.provenance);
    assert!(!text.contains("more_recordings"), "not written for one recording:\n{text}");
    // Several recordings: the further ones are written in order and read back.
    let mut pooled = cal.clone();
    pooled.provenance.more_recordings = vec![
        RecordingRef { recording: "b.h5".into(), recording_hash: "sha256:bbbb".into() },
        RecordingRef { recording: "c.h5".into(), recording_hash: "sha256:cccc".into() },
    ];
    let pooled_text = pooled.to_toml_string().unwrap();
    assert!(pooled_text.find("\"b.h5\"").unwrap() < pooled_text.find("\"c.h5\"").unwrap(), "{pooled_text}");
    assert_eq!(Calibration::from_toml_str(&pooled_text, "<test>").unwrap(), pooled);
    // Another format version is named as such (with what to do), not reported as a parse error.
    for v in ["2", "99"] {
        let wrong = text.replacen(&format!("format_version = {FORMAT_VERSION}"), &format!("format_version = {v}"), 1);
        let err = Calibration::from_toml_str(&wrong, "calib.toml").unwrap_err().to_string();
        assert!(err.contains(&format!("version {v};")) && err.contains("re-run `skinflow calibrate`"), "{err}");
    }
}

#[test]
fn all_samples_at_one_location_fall_back_to_the_prior() {
    let frames = synth::frames(5, 1, &[1.0, 3.0, 5.0, 7.0, 9.0], 6, 0.01);
    let out = calibrate(&frames, &CalibParams::default(), provenance()).unwrap();
    assert!(out.warnings.iter().any(|w| matches!(w, CalibWarning::TooFewLocations { locations: 1, .. })));
    assert!(out.warnings.iter().any(|w| matches!(w, CalibWarning::NarrowRegion { .. })));
    let la = &out.calibration.pneumatic.locaware;
    assert!(la.prior_fallback && la.lambda_g.is_none());
    assert_eq!(la.gain.coeffs, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert_eq!(la.offset.coeffs, [0.0; 6]);
    assert_eq!(out.calibration.warnings.len(), out.warnings.len());
    let text = out.calibration.to_toml_string().unwrap();
    assert_eq!(Calibration::from_toml_str(&text, "<test>").unwrap(), out.calibration);
    // Still a usable pneumatic map.
    let s = Strategy::new(&out.calibration, StrategyKind::PneumaticLocAware);
    let f = s.estimate(&contact(0.0, 0.0, 100.0), synth::dp_of(5.0, 0.0, 0.0)).force_n;
    assert!((f - 5.0).abs() < 0.1, "{f}");
}

#[test]
fn too_few_samples_fall_back_and_too_few_for_a_map_is_an_error() {
    let frames = synth::frames(6, 2, &[2.0, 6.0, 9.0], 1, 0.01);
    let out = calibrate(&frames, &CalibParams::default(), provenance()).unwrap();
    assert!(out.warnings.iter().any(|w| matches!(w, CalibWarning::TooFewSamples { samples: 12, .. })));
    assert!(out.calibration.pneumatic.locaware.prior_fallback);
    let err = calibrate(&frames[..2], &CalibParams::default(), provenance()).unwrap_err();
    assert!(err.to_string().contains("force map needs >= 3"), "{err}");
    // Samples that were all rejected: the error says why, not only that none was usable.
    let mut negative = frames.clone();
    for f in &mut negative {
        f.force_n = -f.force_n;
    }
    let err = calibrate(&negative, &CalibParams::default(), provenance()).unwrap_err().to_string();
    assert!(
        err.contains("0 usable samples (of 12 frames: rejected 12 of 12 samples (non-finite, C <= 0, F <= 0"),
        "{err}"
    );
}

/// A calibration names the sensor its recordings were made with (read back as written), and
/// files that are not calibrations are named as such rather than by a missing field.
#[test]
fn calibration_file_names_its_sensor_and_other_files_are_named_as_such() {
    let mut cal = fitted();
    let sensor = SensorRef {
        name: "paper-100mm".into(),
        width_mm: 100.0,
        height_mm: 100.0,
        electrodes: 16,
        protocol: "pairwise".into(),
    };
    cal.provenance.sensor = Some(sensor.clone());
    let text = cal.to_toml_string().unwrap();
    assert!(text.contains("[provenance.sensor]"), "{text}");
    assert_eq!(Calibration::from_toml_str(&text, "<test>").unwrap(), cal);
    assert_eq!(sensor.to_string(), "\"paper-100mm\" (100 x 100 mm, 16 electrodes, pairwise)");
    let renamed = SensorRef { name: "skin-b".into(), ..sensor.clone() };
    let smaller = SensorRef { width_mm: 60.0, ..sensor.clone() };
    assert!(sensor.same_geometry(&renamed) && !sensor.same_geometry(&smaller));
    for (text, want) in [
        ("", "x.toml: not a skinflow calibration: the file is empty"),
        ("[sensor]\nwidth_mm = 60.0\n", "x.toml: not a skinflow calibration: the file has no `format` key"),
    ] {
        let err = Calibration::from_toml_str(text, "x.toml").unwrap_err().to_string();
        assert!(err.starts_with(want) && err.contains("skinflow calibrate"), "{err}");
    }
    let dir = std::env::temp_dir().join(format!("skinflow-contact-binary-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let binary = dir.join("rec.h5");
    std::fs::write(&binary, b"\x89HDF\r\n\x1a\n\xff\xfe").unwrap();
    let err = Calibration::read(&binary).unwrap_err().to_string();
    assert!(err.contains("rec.h5: not a skinflow calibration: not UTF-8 text"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn outliers_are_rejected_with_a_warning() {
    let mut frames = synth::paper_like(8);
    frames[0].x_mm += 40.0; // one hold's mean centroid moves ~6.7 mm: kept
    for f in &mut frames[6..12] {
        f.x_mm += 30.0; // a whole hold 30 mm off: rejected
    }
    // One NaN frame costs only itself: the other five frames of its hold still make a sample.
    frames[12].cond_sum = f64::NAN;
    let out = calibrate(&frames, &CalibParams::default(), provenance()).unwrap();
    assert!(
        out.warnings.iter().any(|w| matches!(w, CalibWarning::Rejected { count: 1, total: 125, .. })),
        "{:?}",
        out.warnings
    );
    assert!(out.warnings.contains(&CalibWarning::NonFiniteFrames { count: 1, total: 750 }), "{:?}", out.warnings);
    assert_eq!(out.calibration.training.rejected, 1);
}

#[test]
fn no_load_and_negative_drift_give_zero_force() {
    let cal = fitted();
    for kind in StrategyKind::ALL.into_iter().filter(|k| k.is_pneumatic()) {
        let s = Strategy::new(&cal, kind);
        for dp in [0.0, -0.2] {
            let e = s.estimate(&contact(0.0, 0.0, 100.0), dp);
            assert_eq!(e.force_n, 0.0, "{kind:?} dp {dp}");
            assert!(e.flags.no_load && !e.flags.no_pressure);
        }
        // An unknown share (no pressure in the frame's window) is not a no-load reading.
        for dp in [f64::NAN, f64::INFINITY] {
            let e = s.estimate(&contact(0.0, 0.0, 100.0), dp);
            assert_eq!(e.force_n, 0.0, "{kind:?} dp {dp}");
            assert!(e.flags.no_pressure && !e.flags.no_load, "{kind:?} dp {dp}: {:?}", e.flags);
        }
    }
    let eit = Strategy::new(&cal, StrategyKind::EitLocAware);
    assert_eq!(eit.estimate(&contact(0.0, 0.0, 0.0), 1.0).force_n, 0.0);
}

/// Between no load and the calibrated range (0 < dP < signal_min) the map continues linearly
/// down from the range's bottom: the force rises with dP from 0 N, never negative (a negative
/// model force is clamped to 0 N and flagged), and every such reading is flagged below range.
#[test]
fn small_pressure_below_the_range_is_monotone_non_negative_and_flagged() {
    let cal = fitted();
    for kind in [StrategyKind::PneumaticNoCal, StrategyKind::PneumaticLocAware, StrategyKind::PneumaticAreaAware] {
        let s = Strategy::new(&cal, kind);
        let lo = match kind {
            StrategyKind::PneumaticLocAware => cal.pneumatic.locaware.map.signal_min,
            _ => cal.pneumatic.map.signal_min,
        };
        assert!(lo > 0.0, "{kind:?}: the calibrated range starts above no load");
        let c = contact(-12.0, 8.0, 100.0);
        let mut prev = 0.0;
        for i in 1..=200 {
            let dp = lo * f64::from(i) / 200.0;
            let e = s.estimate(&c, dp);
            assert!(e.force_n >= 0.0 && e.force_n >= prev - 1e-12, "{kind:?} at dp {dp}: {} after {prev}", e.force_n);
            assert_eq!(e.flags.below_range, i < 200, "{kind:?} at dp {dp}");
            assert_eq!(e.flags.negative_clamped, e.force_n == 0.0, "{kind:?} at dp {dp}: {:?}", e.flags);
            assert!(!e.flags.no_load, "{kind:?} at dp {dp}: a positive dP is a load");
            prev = e.force_n;
        }
    }
}

#[test]
fn large_pressure_extrapolates_monotonically_and_is_flagged() {
    let cal = fitted();
    let hi = cal.pneumatic.map.signal_max;
    for kind in [StrategyKind::PneumaticNoCal, StrategyKind::PneumaticLocAware, StrategyKind::PneumaticAreaAware] {
        let s = Strategy::new(&cal, kind);
        let c = contact(10.0, -5.0, 100.0);
        let mut prev = 0.0;
        for i in 1..=400 {
            let dp = hi * 3.0 * i as f64 / 400.0;
            let e = s.estimate(&c, dp);
            assert!(e.force_n >= prev - 1e-12, "{kind:?} not monotone at dp {dp}");
            assert_eq!(e.flags.above_range, dp > hi);
            prev = e.force_n;
        }
    }
}

#[test]
fn centroid_outside_the_calibrated_region_is_clamped_and_flagged() {
    let cal = fitted();
    let s = Strategy::new(&cal, StrategyKind::PneumaticLocAware);
    let Region { x_max_mm, y_max_mm, .. } = cal.region;
    let dp = synth::dp_of(5.0, 0.0, 0.0);
    let edge = s.estimate(&contact(x_max_mm, y_max_mm, 100.0), dp);
    let outside = s.estimate(&contact(x_max_mm + 20.0, y_max_mm + 20.0, 100.0), dp);
    assert!(!edge.flags.location_clamped && outside.flags.location_clamped);
    assert_eq!(edge.force_n, outside.force_n);
    // NoCal ignores the location, so it never clamps.
    let nocal = Strategy::new(&cal, StrategyKind::PneumaticNoCal).estimate(&contact(99.0, 99.0, 100.0), dp);
    assert!(!nocal.flags.location_clamped);
}

#[test]
fn sensitivity_compensated_split_fixes_eit_bias_between_two_equal_contacts() {
    let cal = fitted();
    // Two 4 N contacts where EIT is weak (x = -30) and strong (x = +30).
    let (xl, xr, f) = (-30.0, 30.0, 4.0);
    let cs = [contact(xl, 0.0, synth::cond_of(f, xl, 0.0)), contact(xr, 0.0, synth::cond_of(f, xr, 0.0))];
    let dp = synth::dp_of(f, xl, 0.0) + synth::dp_of(f, xr, 0.0);
    let err = |kind| {
        let mut o = [Default::default(); 2];
        Strategy::new(&cal, kind).estimate_frame_into(dp, &cs, &mut o);
        ((o[0].force_n - f).powi(2) + (o[1].force_n - f).powi(2)).sqrt()
    };
    let proportional = err(StrategyKind::PneumaticLocAware);
    let compensated = err(StrategyKind::PneumaticLocAwareSensitivity);
    assert!(compensated < 0.5 * proportional, "compensated {compensated} vs proportional {proportional}");
}

#[test]
fn bad_calibration_params_are_rejected_by_name() {
    let params = CalibParams { folds: 1, ..CalibParams::default() };
    let err = calibrate(&synth::paper_like(1), &params, provenance()).unwrap_err().to_string();
    assert!(err.contains("\"folds\""), "{err}");
    let params = CalibParams { holdout_folds: 1, ..CalibParams::default() };
    assert!(params.validate().unwrap_err().to_string().contains("\"holdout_folds\""));
    let params = CalibParams { lambda_grid_rel: vec![1.0, -1.0], ..CalibParams::default() };
    assert!(params.validate().unwrap_err().to_string().contains("lambda_grid_rel"));
    let params = CalibParams { max_location_error_mm: f64::NAN, ..CalibParams::default() };
    assert!(params.validate().is_err());
    let params = CalibParams { min_span_mm: 0.0, ..CalibParams::default() };
    assert!(params.validate().unwrap_err().to_string().contains("\"min_span_mm\""));
}

#[test]
fn sensitivity_compensated_split_recovers_unequal_forces() {
    // 2 N where EIT is weak (x = -30) and 6 N where it is strong (x = +30): the proportional
    // split overweights the right contact twice over (sensitivity and C ~ F^0.7 both bias it).
    let cal = fitted();
    let truth = [(-30.0, 10.0, 2.0), (30.0, -10.0, 6.0)];
    let cs: Vec<Contact> = truth.iter().map(|&(x, y, f)| contact(x, y, synth::cond_of(f, x, y))).collect();
    let dp: f64 = truth.iter().map(|&(x, y, f)| synth::dp_of(f, x, y)).sum();
    let worst = |kind| {
        let mut o = [Default::default(); 2];
        Strategy::new(&cal, kind).estimate_frame_into(dp, &cs, &mut o);
        o.iter().zip(&truth).map(|(e, t)| (e.force_n - t.2).abs()).fold(0.0, f64::max)
    };
    let proportional = worst(StrategyKind::PneumaticLocAware);
    let compensated = worst(StrategyKind::PneumaticLocAwareSensitivity);
    assert!(compensated < 0.3, "compensated worst error {compensated} N");
    assert!(proportional > 3.0 * compensated, "proportional {proportional} vs compensated {compensated}");
}
