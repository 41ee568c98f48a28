//! The `sync` node inside a graph: pressure windows, tare, truth and the no-load flag, on the
//! ideal (noise-free) simulated skin, driven in lockstep.

use std::path::Path;
use std::sync::{Arc, Mutex};

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, RunOptions};
use skinflow_nodes::payload::SyncedFrame;
use skinflow_nodes::pipeline::{Captured, registry_with_capture};

fn run_press() -> Vec<SyncedFrame> {
    run_scene("press.toml").into_iter().map(|(_, f)| f).collect()
}

/// Every sync output of a fixture scene with its time stamp, s.
fn run_scene(fixture: &str) -> Vec<(f64, SyncedFrame)> {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(fixture);
    let graph = format!(
        "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"skin\"\nkind = \"sim\"\nparams = {{ scene = {scene:?}, pacing = \"fast\" }}\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
         [[edge]]\nfrom = \"skin.eit\"\nto = \"sync.eit\"\n\
         [[edge]]\nfrom = \"skin.pressure\"\nto = \"sync.pressure\"\n\
         [[edge]]\nfrom = \"skin.truth\"\nto = \"sync.truth\"\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"cap.in\"\n"
    );
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let reg = registry_with_capture(captured.clone());
    let spec = GraphSpec::parse(SourceFile::new("press-graph.toml", graph), &reg).unwrap();
    let report = skinflow_core::run(&spec, &RunOptions::default()).unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    assert_eq!(report.stats.total_drops(), 0);
    let rows = captured.lock().unwrap();
    rows.iter().map(|r| (r[0].header.t_s(), r[0].get::<SyncedFrame>().unwrap().clone())).collect()
}

#[test]
fn frames_carry_tared_pressure_truth_and_the_no_load_flag() {
    let frames = run_press();
    assert!(frames.len() >= 8, "{} frames", frames.len());
    // Leading rest: no-load frames, tared to ~0 (the ideal skin has no noise or drift).
    let rest: Vec<&SyncedFrame> = frames.iter().take_while(|f| f.no_load).collect();
    assert!(rest.len() >= 3, "{} no-load frames", rest.len());
    // A frame is no-load only when its whole window precedes the press (a frame stamped
    // before the first contact row whose window reaches into the press is not: it would put
    // part of the contact into the EIT reference). So every no-load frame is flat.
    for f in &rest {
        assert!(f.dp_kpa.abs() < 1e-9, "no-load dP {}", f.dp_kpa);
        assert!(f.pressure_samples >= 10, "window of a 20 Hz stream at 1.3 frames/s: {}", f.pressure_samples);
        assert!(f.p0_kpa.is_finite());
    }
    // The first loaded frame's window does contain the start of the press.
    let first_loaded = &frames[rest.len()];
    assert!(first_loaded.dp_kpa > 1e-6, "first frame after the rest: dP {}", first_loaded.dp_kpa);
    // The hold: truth says 6 N at (10, -5) and the pressure has risen.
    let held: Vec<&SyncedFrame> = frames
        .iter()
        .filter(|f| f.truth.as_ref().is_some_and(|t| t.contacts.len() == 1 && t.contacts[0].force_n == 6.0))
        .collect();
    assert!(held.len() >= 3, "{} held frames", held.len());
    for f in &held {
        let c = f.truth.as_ref().unwrap().contacts[0];
        assert_eq!((c.x_mm, c.y_mm, c.diameter_mm), (10.0, -5.0, 15.0));
        assert!(!f.no_load);
        assert!(f.dp_kpa > 0.0, "held dP {}", f.dp_kpa);
    }
    // Frames of one hold see (nearly) the same dP.
    let dps: Vec<f64> = held.iter().map(|f| f.dp_kpa).collect();
    let (lo, hi) = dps.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    assert!(hi - lo < 0.05 * hi, "held dP spread {dps:?}");
}

#[test]
fn every_frame_is_emitted_once_and_in_order() {
    let frames = run_press();
    let seqs: Vec<u64> = frames.iter().map(|f| f.frame.v.len() as u64).collect();
    assert!(seqs.iter().all(|&m| m == 120), "120 values per frame");
    // The simulator's frame count for the scene: every one reaches the output.
    let t_total: f64 = 3.0 + 0.2 + 4.0 / 1.3 + 0.2 + 1.0;
    assert!(frames.len() as f64 >= (t_total * 1.3).floor() - 1.0, "{} frames for {t_total} s", frames.len());
}

/// The settled flag on both skins: it is set exactly on the frames whose window holds no part
/// of a ramp, whatever the noise. The threshold follows the measured no-load noise (0.01 kPa on
/// the paper skin); the ideal skin's zero noise falls back to `settle_floor_kpa`.
#[test]
fn the_settled_flag_follows_the_load_not_the_noise() {
    for fixture in ["press.toml", "press-paper.toml"] {
        let frames = run_scene(fixture);
        let half = 0.5 / 1.3;
        // The scene: a 0.2 s ramp from 3.0 s; the hold ends with the acquisition of its last
        // frame, then a 0.2 s release.
        let last_held = frames
            .iter()
            .filter(|(_, f)| f.truth.as_ref().is_some_and(|t| !t.contacts.is_empty()))
            .map(|(t, _)| *t)
            .fold(f64::NEG_INFINITY, f64::max);
        let release = last_held + half;
        let ramps = [(3.0, 3.2), (release, release + 0.2)];
        let mut counts = (0, 0);
        for (t, f) in &frames {
            let (lo, hi) = (t - half, t + half);
            let still = ramps.iter().all(|&(a, b)| hi <= a || lo >= b);
            assert_eq!(f.settled, still, "{fixture}: frame at {t:.3} s, window SD {:.4} kPa", f.pressure_sd_kpa);
            if still { counts.0 += 1 } else { counts.1 += 1 }
        }
        assert!(counts.0 >= 6 && counts.1 >= 3, "{fixture}: settled / not: {counts:?}");
    }
}
