//! The `sync` node through the binary, on a recording that ends while its last frames' windows
//! are still open and whose pressure board missed two frames: every recorded frame comes out
//! (the engine's end-of-stream flush), in both executors, and a frame without pressure goes
//! down the pipeline flagged as such (logged with the no-pressure guard bit, never the no-load
//! one), is counted by the nodes at stop, and is left out by `eval`.

use std::path::Path;

use super::cli::{check_pipeline_stats, derived_streams_agree, pipeline_graph};
use super::support::{fixture, hdf5_io, ok, read_recording, rewrite_pressure, skinflow, stderr};

/// EIT frames (0-based) whose acquisition window the pressure board misses: both after the
/// first contact (tiny-eval rests 4 s, about 5 frames).
const DROPOUTS: [usize; 2] = [12, 20];

/// Simulates tiny-eval and writes `cut.h5`: its pressure without the samples in the windows of
/// [`DROPOUTS`] and ending half a frame period before the last frame, whose window so holds no
/// sample and can never be closed by a later one. Returns the EIT frame times.
fn cut_recording(d: &Path) -> Vec<f64> {
    ok(&skinflow(d, &["simulate", fixture("tiny-eval.toml").to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
    let eit_t = read_recording(d.join("rec.h5")).eit.unwrap().t_s;
    let half = 0.5 * (eit_t[1] - eit_t[0]);
    let last = eit_t[eit_t.len() - 1];
    // A margin of 10 ms keeps samples off the windows' edges.
    let missed = |t: f64| DROPOUTS.iter().any(|&k| (t - eit_t[k]).abs() < half + 0.01);
    rewrite_pressure(&d.join("rec.h5"), &d.join("cut.h5"), |_, t, kpa| {
        (t < last - half - 0.01 && !missed(t)).then_some((t, kpa))
    });
    eit_t
}

#[test]
fn every_recorded_frame_is_synced_and_a_frame_without_pressure_is_flagged() {
    let d = super::support::workdir("sync", "cut");
    let eit_t = cut_recording(&d);
    let without: Vec<usize> = DROPOUTS.iter().copied().chain([eit_t.len() - 1]).collect();

    // Real time first (the worker pool), then lockstep, whose log the checks below read.
    let graph = pipeline_graph(&d, "cut.h5", "pneumatic-locaware");
    let text = std::fs::read_to_string(d.join(&graph)).unwrap();
    std::fs::write(d.join("realtime.toml"), text.replace("mode = \"lockstep\"", "mode = \"realtime\"")).unwrap();
    for g in ["realtime.toml", graph.as_str()] {
        let _ = std::fs::remove_file(d.join("out.h5"));
        let out = skinflow(&d, &["run", g, "--stats-json", "stats.json"]);
        ok(&out);
        let (frames, _) = check_pipeline_stats(&d, "cut.h5");
        assert_eq!(frames, eit_t.len(), "{g}");
        // Counted at stop: by the sync node (by cause) and by the corrector.
        let err = stderr(&out);
        assert!(err.contains("no_sample_in_window=3") && err.contains("frames without pressure"), "{g}: {err}");
        assert!(err.contains("frames=3") && err.contains("no_pressure"), "{g}: {err}");
    }

    let log = d.join("out.h5");
    let shares = derived_streams_agree(&log, eit_t.len());
    assert!(shares.no_pressure > 0 && shares.loaded > 0, "{shares:?}");
    let rec = read_recording(&log);
    let sync = rec.derived.sync.as_ref().unwrap();
    // A sync row per recorded frame, the last one included (times went through nanoseconds).
    assert_eq!(sync.t_s.len(), eit_t.len());
    assert!(sync.t_s.iter().zip(&eit_t).all(|(a, b)| (a - b).abs() < 1e-6), "{:?} vs {eit_t:?}", sync.t_s);
    for (k, (dp, n)) in sync.dp_kpa.iter().zip(&sync.pressure_samples).enumerate() {
        let lost = without.contains(&k);
        assert_eq!((dp.is_nan(), *n == 0.0), (lost, lost), "frame {k}: dP {dp}, {n} samples");
        assert!(!(lost && sync.no_load[k]), "frame {k}: a frame without pressure after the rest is not no-load");
    }
    let text = ok(&skinflow(&d, &["inspect", "out.h5"]));
    assert!(text.contains("in the no-load period, 3 without pressure"), "{text}");
    assert!(text.contains(&format!("{} no pressure", shares.no_pressure)), "{text}");

    // eval leaves the frames without pressure out, and says so.
    let calib = fixture("../../graphs/calib/paper.toml");
    let out = skinflow(&d, &["eval", "cut.h5", "--calib", calib.to_str().unwrap(), "--json", "eval.json"]);
    ok(&out);
    let err = stderr(&out);
    assert!(err.contains("cut.h5: 3 frames without pressure") && err.contains("were not evaluated"), "{err}");
}

/// A copy of recording `src` with its EIT frames, their no-load reference and its pressure,
/// and of its truth the rows from the first whose index `keep_from` gives (`None`: no truth at
/// all, a session recorded without a load cell), under [`hdf5_io`].
fn copy_recording(src: &Path, dst: &Path, keep_from: impl Fn(&skinflow_record::TruthStream) -> Option<usize>) {
    use skinflow_record::{Recording, RecordingWriter, Streams, WriterOptions};
    hdf5_io(|| {
        let rec = Recording::open(src).unwrap();
        let truth = rec.truth.as_ref().and_then(|t| keep_from(t).map(|from| (t, from)));
        let mut opts = WriterOptions::new(rec.sensor_toml.clone());
        opts.streams = Streams { eit: true, pressure: true, truth: truth.is_some(), ..Streams::default() };
        if let Some((t, _)) = truth {
            opts.truth_max_contacts = t.max_contacts;
        }
        let mut w = RecordingWriter::create(dst, &opts).unwrap();
        let eit = rec.eit.as_ref().unwrap();
        for i in 0..eit.len() {
            w.append_eit(eit.t_s[i], eit.seq[i], eit.frame(i)).unwrap();
        }
        if let Some(reference) = &rec.reference {
            w.set_reference(reference).unwrap();
        }
        let p = rec.pressure.as_ref().unwrap();
        for i in 0..p.len() {
            w.append_pressure(p.t_s[i], p.kpa[i]).unwrap();
        }
        if let Some((t, from)) = truth {
            for i in from..t.len() {
                let contacts: Vec<_> = t.row(i).contacts().collect();
                w.append_truth(t.t_s[i], &contacts).unwrap();
            }
        }
        w.close().unwrap();
    });
}

/// A copy of recording `src` without its truth: EIT frames, their no-load reference and the
/// pressure only (a session recorded without a load cell), under [`hdf5_io`].
fn copy_without_truth(src: &Path, dst: &Path) {
    copy_recording(src, dst, |_| None);
}

/// `graphs/ab-replay.toml` on a recording without truth (its truth edge wired, nothing on
/// it): the sync node tares on the first `tare_s` seconds and says so, and `compare` times and
/// scores the frames after them, the second lane by its disagreement with the first, and
/// counts the no-load frames it left out.
#[test]
fn a_recording_without_truth_is_tared_by_time_and_its_lanes_compared() {
    let d = super::support::workdir("sync", "notruth");
    ok(&skinflow(&d, &["simulate", fixture("tiny-eval.toml").to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
    copy_without_truth(&d.join("rec.h5"), &d.join("notruth.h5"));
    assert!(read_recording(d.join("notruth.h5")).truth.is_none());
    let root = super::support::root();
    let graph = std::fs::read_to_string(root.join("graphs/ab-replay.toml"))
        .unwrap()
        .replace("\"../out/multi.h5\"", "\"notruth.h5\"")
        .replace("\"../out/ab-replay.json\"", "\"ab.json\"")
        .replace("\"calib/paper.toml\"", &format!("{:?}", root.join("graphs/calib/paper.toml")));
    std::fs::write(d.join("ab.toml"), graph).unwrap();
    let out = skinflow(&d, &["run", "ab.toml"]);
    let table = ok(&out);
    let err = stderr(&out);
    assert!(err.contains("no truth row arrived in the first tare_s seconds"), "{err}");
    assert!(!err.contains("the lane scored no frame"), "{err}");
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("ab.json")).unwrap()).unwrap();
    let lanes = report["lanes"].as_array().unwrap();
    assert_eq!(lanes.len(), 2, "{report}");
    let frames = read_recording(d.join("notruth.h5")).eit.unwrap().len() as u64;
    for l in lanes {
        let count = |k: &str| l[k].as_u64().unwrap();
        // 2 s of 4 s rest at 1.3 frames/s: two or three no-load frames.
        assert!((2..=3).contains(&count("no_load_frames")), "{l}");
        assert_eq!(count("no_load_frames") + count("frames") + count("no_pressure_frames"), frames, "{l}");
        assert!(count("scored_frames") > 0 && count("matched") == 0, "{l}");
    }
    // The reference lane has no disagreement with itself; the other lane has one.
    assert!(lanes[0]["disagreement_rmse_n"].is_null(), "{report}");
    assert!(lanes[1]["disagreement_rmse_n"].as_f64().is_some_and(|x| x.is_finite() && x > 0.0), "{report}");
    assert!(table.contains("| sensitivity-compensated |"), "{table}");
}

/// A recording whose truth starts at the first press (a writer that logs truth rows from the
/// first contact on, not an empty row at the start): its no-load period still lasts until that
/// press (CONTRACTS.md section 2), so `eval` evaluates the same frames with the same result as
/// on the recording with the leading empty row. Before, the replay sent that first row at its
/// time, 4 s in, and `sync` had taken the truth input for silent after `tare_s` (2 s): the
/// frames between were evaluated, and P0 and the EIT reference came from the first 2 s only.
#[test]
fn truth_recorded_from_the_first_press_on_keeps_the_no_load_period_until_that_press() {
    let d = super::support::workdir("sync", "late-truth");
    ok(&skinflow(&d, &["simulate", fixture("tiny-eval.toml").to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
    let first_contact = |t: &skinflow_record::TruthStream| (0..t.len()).find(|&i| t.row(i).contacts().next().is_some());
    copy_recording(&d.join("rec.h5"), &d.join("late.h5"), first_contact);
    let truth = read_recording(d.join("late.h5")).truth.unwrap();
    assert!(truth.t_s[0] > 3.9 && truth.row(0).contacts().next().is_some(), "{:?}", truth.t_s);
    let calib = super::support::root().join("graphs/calib/paper.toml");
    let eval = |rec: &str, json: &str| {
        let out = skinflow(&d, &["eval", rec, "--calib", calib.to_str().unwrap(), "--json", json]);
        ok(&out);
        let err = stderr(&out);
        assert!(!err.contains("no truth row arrived") && !err.contains("no-load frame"), "{rec}: {err}");
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join(json)).unwrap()).unwrap();
        v
    };
    let (whole, late) = (eval("rec.h5", "whole.json"), eval("late.h5", "late.json"));
    assert_eq!(late["frames"], whole["frames"]);
    assert_eq!(late["localization"], whole["localization"]);
    for (name, s) in whole["strategies"].as_object().unwrap() {
        assert_eq!(late["strategies"][name]["rmse_n"], s["rmse_n"], "{name}");
    }
}

/// Pressure samples that are not finite numbers (a board sending `inf` or `nan`) are left out
/// of every window and of P0, as before, but no longer silently: `sync` warns at the first and
/// counts them at stop, and `eval` shows both.
#[test]
fn non_finite_pressure_samples_are_counted_not_dropped_silently() {
    let d = super::support::workdir("sync", "non-finite");
    ok(&skinflow(&d, &["simulate", fixture("tiny-eval.toml").to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
    let mut bad = 0;
    rewrite_pressure(&d.join("rec.h5"), &d.join("inf.h5"), |i, t, kpa| {
        let inf = i % 40 == 7;
        bad += usize::from(inf);
        Some((t, if inf { f64::INFINITY } else { kpa }))
    });
    assert!(bad > 5);
    let calib = super::support::root().join("graphs/calib/paper.toml");
    let out = skinflow(&d, &["eval", "inf.h5", "--calib", calib.to_str().unwrap()]);
    ok(&out);
    let err = stderr(&out);
    assert!(err.contains("a pressure sample is not a finite number") && err.contains("kpa=inf"), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("pressure samples that were not finite numbers"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(line.contains(&format!("samples={bad}")), "{line}");
}
