//! The `sync` node inside a graph: pressure windows, tare, truth and the no-load flag, on the
//! ideal (noise-free) simulated skin, driven in lockstep.

use std::path::Path;
use std::sync::{Arc, Mutex};

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Header, RunOptions};
use skinflow_nodes::payload::{EitFrame, SyncedFrame};
use skinflow_nodes::pipeline::{Captured, registry_with_capture};

fn run_press() -> Vec<SyncedFrame> {
    run_scene("press.toml").into_iter().map(|(_, f)| f).collect()
}

/// Every sync output of a fixture scene with its time stamp, s.
fn run_scene(fixture: &str) -> Vec<(f64, SyncedFrame)> {
    run_scene_with_frames(fixture).1.into_iter().map(|(h, f)| (h.t_s(), f)).collect()
}

/// The EIT frames the simulated skin sent and every sync output, in arrival order, with their
/// headers.
type SceneRun = (Vec<(Header, Arc<EitFrame>)>, Vec<(Header, SyncedFrame)>);

/// Runs a fixture scene through `sync`; one capture sink takes both the skin's EIT frames and
/// the sync output (told apart by payload type).
fn run_scene_with_frames(fixture: &str) -> SceneRun {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(fixture);
    let graph = format!(
        "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"skin\"\nkind = \"sim\"\nparams = {{ scene = {scene:?}, pacing = \"fast\" }}\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
         [[edge]]\nfrom = \"skin.eit\"\nto = \"sync.eit\"\n\
         [[edge]]\nfrom = \"skin.pressure\"\nto = \"sync.pressure\"\n\
         [[edge]]\nfrom = \"skin.truth\"\nto = \"sync.truth\"\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"cap.in\"\n\
         [[edge]]\nfrom = \"skin.eit\"\nto = \"cap.in\"\n"
    );
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let reg = registry_with_capture(captured.clone());
    let spec = GraphSpec::parse(SourceFile::new("press-graph.toml", graph), &reg).unwrap();
    let report = skinflow_core::run(&spec, &RunOptions::default()).unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    assert_eq!(report.stats.total_drops(), 0);
    let rows = captured.lock().unwrap();
    let (mut eit, mut synced) = (Vec::new(), Vec::new());
    for m in rows.iter().flatten() {
        match (m.arc::<EitFrame>(), m.get::<SyncedFrame>()) {
            (Some(f), _) => eit.push((m.header, f)),
            (_, Some(s)) => synced.push((m.header, s.clone())),
            _ => panic!("unexpected payload {}", m.type_name()),
        }
    }
    (eit, synced)
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

/// Each EIT frame the skin sent comes out exactly once, in order, carrying that very frame:
/// also the last ones, whose window no later pressure sample closes (the end-of-stream flush
/// emits them, with the samples their window got).
#[test]
fn every_frame_is_emitted_once_and_in_order() {
    for fixture in ["press.toml", "press-paper.toml"] {
        let (eit, synced) = run_scene_with_frames(fixture);
        // The simulator's frame count for the scene (3 s rest, 0.2 s ramp, 4 frames held,
        // 0.2 s release, 1 s rest at 1.3 frames/s).
        let t_total: f64 = 3.0 + 0.2 + 4.0 / 1.3 + 0.2 + 1.0;
        assert!(eit.len() as f64 >= (t_total * 1.3).floor() - 1.0, "{fixture}: {} frames for {t_total} s", eit.len());
        let key = |h: &Header| (h.seq, h.t_ns);
        let sent: Vec<(u64, u64)> = eit.iter().map(|(h, _)| key(h)).collect();
        let got: Vec<(u64, u64)> = synced.iter().map(|(h, _)| key(h)).collect();
        assert_eq!(got, sent, "{fixture}: every frame once, in order");
        for ((_, frame), (h, s)) in eit.iter().zip(&synced) {
            assert!(Arc::ptr_eq(frame, &s.frame), "{fixture}: frame {} carries its own EIT data", h.seq);
            assert_eq!(s.frame.v.len(), 120, "{fixture}: 120 values per frame");
            // Pressure flows until the scene's end: every window, the last ones included, has
            // samples (they are not mistaken for frames without pressure).
            assert!(s.pressure_samples > 0 && s.dp_kpa.is_finite(), "{fixture}: frame {}: {s:?}", h.seq);
        }
        // Frames are stamped in increasing time.
        assert!(got.windows(2).all(|w| w[0].1 < w[1].1), "{fixture}: {got:?}");
    }
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

/// EIT frame period of [`write_cut_recording`], s.
const T: f64 = 0.5;
/// Frames of [`write_cut_recording`], the first at `T`.
const FRAMES: u64 = 12;
/// The frames whose window the pressure board missed: one in the no-load period, one loaded.
const DROPOUTS: [u64; 2] = [1, 7];

fn frame_t(k: u64) -> f64 {
    T * (k + 1) as f64
}

/// The pressure of [`write_cut_recording`]: (t, kPa) at 20 Hz (offset so that no sample lies
/// on a window's edge), 1 kPa at rest and 2 kPa from the first contact at 3 s, without the
/// samples in the windows of [`DROPOUTS`], ending 0.35 s before the last frame: no sample can
/// close the last two frames' windows, and the last window holds none.
fn cut_pressure() -> Vec<(f64, f64)> {
    let dropped = |t: f64| DROPOUTS.iter().any(|&k| (t - frame_t(k)).abs() <= 0.5 * T);
    (0..)
        .map(|i| 0.01 + 0.05 * f64::from(i))
        .take_while(|&t| t < frame_t(FRAMES - 1) - 0.35)
        .filter(|&t| !dropped(t))
        .map(|t| (t, if t < 3.0 { 1.0 } else { 2.0 }))
        .collect()
}

/// A recording of [`FRAMES`] frames with the pressure of [`cut_pressure`] and a first contact
/// at 3 s.
fn write_cut_recording(path: &Path) {
    write_recording(path, FRAMES, &cut_pressure(), true);
}

/// A recording of `frames` frames (the first at `T`) with `pressure`, and with `truth` a first
/// contact at 3 s (without: no `/truth` at all).
fn write_recording(path: &Path, frames: u64, pressure: &[(f64, f64)], truth: bool) {
    use skinflow_record::{RecordingWriter, Streams, TruthContact, WriterOptions};
    let mut opts = WriterOptions::new(skinflow_eit::sensor::PAPER_100MM_TOML);
    opts.streams = Streams { eit: true, pressure: true, truth, ..Streams::default() };
    opts.overwrite = true;
    let mut w = RecordingWriter::create(path, &opts).unwrap();
    for &(t, kpa) in pressure {
        w.append_pressure(t, kpa).unwrap();
    }
    for k in 0..frames {
        w.append_eit(frame_t(k), k, &[1.0 + 1e-3 * k as f64; 120]).unwrap();
    }
    if truth {
        w.append_truth(0.0, &[]).unwrap();
        w.append_truth(3.0, &[TruthContact { x_mm: 0.0, y_mm: 0.0, force_n: 4.0, diameter_mm: 15.0 }]).unwrap();
    }
    w.close().unwrap();
}

/// The recording replayed through `sync` in `mode`: the sync output in arrival order.
fn replay_sync(path: &Path, mode: &str) -> Vec<(Header, SyncedFrame)> {
    let graph = format!(
        "[graph]\nmode = {mode:?}\n\
         [[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = {path:?}, speed = 0.0 }}\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
         [[edge]]\nfrom = \"replay.eit\"\nto = \"sync.eit\"\n\
         [[edge]]\nfrom = \"replay.pressure\"\nto = \"sync.pressure\"\n\
         [[edge]]\nfrom = \"replay.truth\"\nto = \"sync.truth\"\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"cap.in\"\n"
    );
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let reg = registry_with_capture(captured.clone());
    let spec = GraphSpec::parse(SourceFile::new("cut-graph.toml", graph), &reg).unwrap();
    let report = skinflow_core::run(&spec, &RunOptions::default()).unwrap();
    assert!(report.failures.is_empty(), "{mode}: {:?}", report.failures);
    assert_eq!(report.stats.total_drops(), 0, "{mode}: {}", report.stats);
    let sync = report.stats.node("sync").unwrap();
    assert_eq!(sync.discarded, 0, "{mode}");
    let rows = captured.lock().unwrap();
    rows.iter().flatten().map(|m| (m.header, m.get::<SyncedFrame>().unwrap().clone())).collect()
}

/// A recording that ends while the last frames' windows are still open: the end-of-stream
/// flush emits them, in order, with the samples their windows got, in both executors. Frames
/// whose window the pressure board missed come out too, without pressure: `pressure_samples`
/// 0, a NaN dP, and `no_load` only where they were acquired before the first contact.
#[test]
fn a_cut_recording_keeps_every_frame_and_its_pressure_dropouts() {
    let dir = std::env::temp_dir().join(format!("skinflow-nodes-sync-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cut.h5");
    write_cut_recording(&path);
    let pressure = cut_pressure();
    for mode in ["lockstep", "realtime"] {
        let frames = replay_sync(&path, mode);
        let seqs: Vec<u64> = frames.iter().map(|(h, _)| h.seq).collect();
        assert_eq!(seqs, (0..FRAMES).collect::<Vec<_>>(), "{mode}: every frame once, in order");
        for (h, f) in &frames {
            let k = h.seq;
            assert!((f.frame.v[0] - (1.0 + 1e-3 * k as f64)).abs() < 1e-12, "{mode}: frame {k} carries its data");
            let (lo, hi) = (frame_t(k) - 0.5 * T, frame_t(k) + 0.5 * T);
            assert_eq!(f.no_load, hi <= 3.0, "{mode}: frame {k}");
            let window: Vec<f64> = pressure.iter().filter(|(t, _)| *t >= lo && *t < hi).map(|(_, p)| *p).collect();
            assert_eq!(f.pressure_samples as usize, window.len(), "{mode}: frame {k}");
            let without = DROPOUTS.contains(&k) || k == FRAMES - 1;
            assert_eq!(f.has_pressure(), !without, "{mode}: frame {k}: {f:?}");
            if without {
                assert!(f.pressure_samples == 0 && f.dp_kpa.is_nan(), "{mode}: frame {k}: {f:?}");
            } else {
                // The window's mean over the tare (1 kPa at rest).
                let want = window.iter().sum::<f64>() / window.len() as f64 - 1.0;
                assert!((f.dp_kpa - want).abs() < 1e-9, "{mode}: frame {k}: want dP {want}: {f:?}");
            }
        }
        let second_last = &frames[FRAMES as usize - 2].1;
        assert!(second_last.pressure_samples < 10, "{mode}: a partial window: {second_last:?}");
    }
}

/// A recording without truth replayed through a graph that wires the truth edge (as
/// `graphs/ab-replay.toml` does): no truth row ever comes, so the no-load period is the first
/// `tare_s` (2) seconds after the earliest time seen (the first pressure sample, 0.01 s), as
/// without truth, not the whole recording; the same in both executors. The same recording
/// with truth keeps its no-load period up to the first contact (3 s).
#[test]
fn without_truth_rows_the_no_load_period_is_the_first_tare_s_seconds() {
    let dir = std::env::temp_dir().join(format!("skinflow-nodes-sync-notruth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let pressure = cut_pressure();
    for (name, truth, no_load_end) in [("notruth.h5", false, 0.01 + 2.0), ("truth.h5", true, 3.0)] {
        let path = dir.join(name);
        write_recording(&path, FRAMES, &pressure, truth);
        for mode in ["lockstep", "realtime"] {
            let frames = replay_sync(&path, mode);
            assert_eq!(frames.len() as u64, FRAMES, "{name} {mode}");
            for (h, f) in &frames {
                let hi = frame_t(h.seq) + 0.5 * T;
                assert_eq!(f.no_load, hi <= no_load_end, "{name} {mode}: frame {}", h.seq);
                assert_eq!(f.truth.is_some(), truth, "{name} {mode}: frame {}", h.seq);
                // P0 from the 1 kPa rest either way: the press (2 kPa from 3 s) reads 1 kPa.
                if f.has_pressure() {
                    assert!((f.p0_kpa - 1.0).abs() < 1e-12, "{name} {mode}: frame {}: {f:?}", h.seq);
                }
            }
            let no_load = frames.iter().filter(|(_, f)| f.no_load).count();
            assert_eq!(no_load, if truth { 5 } else { 3 }, "{name} {mode}");
        }
    }

    // A recording that ends within those 2 s: the last frame's window reaches past them with
    // no later input to say so; the end of stream does (no truth row can come any more).
    let path = dir.join("short.h5");
    let short: Vec<(f64, f64)> = pressure.iter().copied().filter(|&(t, _)| t < 1.9).collect();
    write_recording(&path, 4, &short, false);
    for mode in ["lockstep", "realtime"] {
        let no_load: Vec<bool> = replay_sync(&path, mode).iter().map(|(_, f)| f.no_load).collect();
        assert_eq!(no_load, [true, true, true, false], "{mode}: the last window ends at 2.25 s");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
