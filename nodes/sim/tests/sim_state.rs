//! What the simulator's caches and placement may and may not change: the EIT solve cache never
//! changes a value (a solved state is reused only for a state with the same seating draw), the
//! pneumatic footprint cache evaluates each placed contact once, a placement error never takes
//! a contact's centre off the skin, and the truth stream generated as it goes is the timeline's.

use skinflow_sim::truth::truth_rows;
use skinflow_sim::{Scene, SimEvent, Simulator, TruthContact};

/// Small mesh so the debug-build tests stay fast; the physics is unchanged.
const SMALL_MESH: &str = "mesh_min_elements = 600\nmesh_max_elements = 700\n";

/// Two separate 5 N presses at the centre (holds at [4, 12) and [15, 23) s without ramps), no
/// EIT noise or drift and no per-press stage error: the two holds differ only by their load
/// level's seating draw.
fn two_presses(profile: &str, ramp_s: f64) -> Scene {
    let text = format!(
        "[scene]\nprofile = \"{profile}\"\n[model]\n{SMALL_MESH}stage_repeatability_mm = 0.0\neit_noise_rel = 0.0\n\
         eit_drift_rel = 0.0\n[[step]]\nrest_s = 4.0\n[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 15.0\n\
         forces_n = [5.0, 5.0]\nhold_s = 8.0\nramp_s = {ramp_s}\nrelease_s = {ramp_s}\nrest_s = 3.0\n"
    );
    Scene::from_str(&text, "t.toml").unwrap()
}

/// EIT frames (mid-time, values) of a whole run.
fn eit_frames(scene: &Scene, seed: u64) -> (Vec<(f64, Vec<f64>)>, u64) {
    let mut sim = Simulator::new(scene, seed).unwrap();
    let frames = sim
        .by_ref()
        .filter_map(|e| if let SimEvent::Eit { t_s, v, .. } = e.unwrap() { Some((t_s, v)) } else { None })
        .collect();
    (frames, sim.solve_count())
}

/// The first frame whose whole window lies in `[a, b)`.
fn frame_in(frames: &[(f64, Vec<f64>)], period_s: f64, a: f64, b: f64) -> (f64, Vec<f64>) {
    frames.iter().find(|(t, _)| t - 0.5 * period_s >= a && t + 0.5 * period_s <= b).cloned().unwrap()
}

#[test]
fn eit_values_do_not_depend_on_what_the_solve_cache_holds() {
    let period = 1.0 / 1.3;
    let (frames, solves) = eit_frames(&two_presses("paper", 0.0), 5);
    // no load, hold 1, hold 2: nothing else is ever solved without ramps
    assert_eq!(solves, 3);
    let (_, reference) = frame_in(&frames, period, 0.0, 4.0);
    let (_, hold_1) = frame_in(&frames, period, 4.0, 12.0);
    let (t_2, hold_2) = frame_in(&frames, period, 15.0, 23.0);
    // the second press seats differently (another load level): it is not the first one's solve
    let sum_dv = |v: &[f64]| v.iter().zip(&reference).map(|(a, b)| a - b).sum::<f64>();
    let (s1, s2) = (sum_dv(&hold_1), sum_dv(&hold_2));
    assert!(s1 > 0.0 && s2 > 0.0 && (s2 / s1 - 1.0).abs() > 1e-3, "sum of dV: press 1 {s1}, press 2 {s2}");
    // the same frame solved from an empty cache, and in a run whose ramps flushed the cache in
    // between, is the same to the bit
    let mut fresh = Simulator::new(&two_presses("paper", 0.0), 5).unwrap();
    let mut alone = vec![0.0; fresh.measurement_count()];
    fresh.eit_frame_at_into(t_2, &mut alone).unwrap();
    assert_eq!(alone, hold_2);
    let (ramped, _) = eit_frames(&two_presses("paper", 0.6), 5);
    // holds of the ramped scene: [4.6, 12.6) and [16.2, 24.2)
    assert_eq!(frame_in(&ramped, period, 16.2, 24.2).1, hold_2);
    assert_eq!(frame_in(&ramped, period, 4.6, 12.6).1, hold_1);
}

#[test]
fn equal_states_of_different_levels_share_a_solve_without_seating_jitter() {
    let period = 1.0 / 1.3;
    let (frames, solves) = eit_frames(&two_presses("ideal", 0.0), 5);
    assert_eq!(solves, 2, "no load and the 5 N hold");
    assert_eq!(frame_in(&frames, period, 4.0, 12.0).1, frame_in(&frames, period, 15.0, 23.0).1);
}

/// A pressure-only scene from `graphs/scenes`.
fn shipped_pressure_only(name: &str) -> Scene {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../graphs/scenes");
    let mut scene = Scene::from_file(format!("{dir}/{name}.toml")).unwrap();
    scene.channels.eit = false;
    scene
}

#[test]
fn each_placed_contact_is_evaluated_once_however_long_it_is_held() {
    // one contact held 2,000 s at 20 Hz: 40,000 samples, one footprint average
    let text = "[scene]\nprofile = \"paper\"\nchannels = [\"pressure\"]\n[[step]]\nrest_s = 2.0\n[[step]]\n\
                at_mm = [[12.0, -7.0]]\ndiameter_mm = 20.0\nforces_n = [3.0]\nhold_s = 2000.0\n";
    let scene = Scene::from_str(text, "t.toml").unwrap();
    let mut sim = Simulator::new(&scene, 1).unwrap();
    let samples = sim.by_ref().filter(|e| matches!(e, Ok(SimEvent::Pressure { .. }))).count();
    assert!(samples > 40_000, "{samples}");
    assert_eq!(sim.footprint_evaluations(), 1);
    // the calibration scene: 25 indentations, each through a ramp, 9 levels and a release
    let mut sim = Simulator::new(&shipped_pressure_only("calibration"), 1).unwrap();
    let samples = sim.by_ref().filter(|e| matches!(e, Ok(SimEvent::Pressure { .. }))).count();
    assert!(samples > 20_000, "{samples}");
    assert_eq!(sim.footprint_evaluations(), 25);
    // Table IV's cases: 8 sets of 2 or 3 contacts pressed together
    let scene = shipped_pressure_only("multi-contact");
    let contacts: usize = scene
        .timeline
        .segments
        .iter()
        .filter(|s| !s.contacts.is_empty())
        .map(|s| (s.contacts[0].press, s.contacts.len()))
        .collect::<std::collections::BTreeMap<_, _>>()
        .values()
        .sum();
    let mut sim = Simulator::new(&scene, 1).unwrap();
    sim.by_ref().for_each(|e| drop(e.unwrap()));
    assert_eq!(sim.footprint_evaluations(), contacts as u64);
}

/// Mean tared pressure over `[a, b)`, kPa.
fn mean_dp(events: &[SimEvent], tare: (f64, f64), a: f64, b: f64) -> f64 {
    let mean = |lo: f64, hi: f64| {
        let v: Vec<f64> = events
            .iter()
            .filter_map(|e| match e {
                SimEvent::Pressure { t_s, kpa } if *t_s >= lo && *t_s < hi => Some(*kpa),
                _ => None,
            })
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    mean(a, b) - mean(tare.0, tare.1)
}

#[test]
fn a_placement_error_never_takes_a_contact_off_the_skin() {
    // 50 N on a 0.1 mm indenter commanded 1 mm inside the bottom-right corner, with the paper's
    // stage errors: on the skin the corner's sensitivity (about 0.55 S0 on the edge, a quarter
    // of the footprint at worst on the corner itself) gives well over 0.5 kPa; off it, almost
    // nothing (the frame takes the load)
    let text = "[scene]\nprofile = \"paper\"\nchannels = [\"pressure\"]\n[[step]]\nrest_s = 4.0\n[[step]]\n\
                at_mm = [[49.0, -49.0]]\ndiameter_mm = 0.1\nforces_n = [50.0]\nhold_s = 6.0\nrest_s = 1.0\n";
    let scene = Scene::from_str(text, "t.toml").unwrap();
    let mut low = f64::INFINITY;
    for seed in 1..=12 {
        let events: Vec<SimEvent> = Simulator::new(&scene, seed).unwrap().collect::<Result<_, _>>().unwrap();
        // the hold is [4.5, 10.5) s
        let dp = mean_dp(&events, (0.0, 4.0), 5.5, 10.5);
        low = low.min(dp);
        assert!(dp > 0.5, "seed {seed}: dP {dp} kPa for 50 N on the skin");
    }
    eprintln!("lowest hold dP over 12 seeds: {low:.3} kPa");
}

#[test]
fn truth_generated_as_the_stream_goes_is_the_timelines() {
    // ramps, a staircase, a force profile and a multi-contact set, at a rate that does not
    // divide the segment times
    let text = "[scene]\nprofile = \"ideal\"\nchannels = [\"pressure\"]\n[rates]\npressure_hz = 7.3\n\
                [[step]]\nrest_s = 1.0\n[[step]]\nat_mm = [[0.0, 0.0], [10.0, 5.0]]\ndiameter_mm = 15.0\n\
                forces_n = [1.0, 3.0]\nloading = \"staircase\"\nhold_s = 0.7\nramp_s = 0.45\nrelease_s = 0.3\nrest_s = 0.2\n\
                [[step]]\ncontacts = [ { x_mm = -20.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 2.0 },\n\
                { x_mm = 20.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 1.0 } ]\nhold_s = 1.0\n\
                [[step]]\nat_mm = [[5.0, 5.0]]\ndiameter_mm = 15.0\nforce_profile = [[0.0, 0.0], [1.0, 2.0], [1.5, 2.0], [2.0, 0.0]]\n";
    let scene = Scene::from_str(text, "t.toml").unwrap();
    let expected: Vec<(f64, Vec<TruthContact>)> = truth_rows(&scene.timeline, scene.rates.pressure_hz)
        .into_iter()
        .filter(|r| r.t_s < scene.duration_s())
        .map(|r| (r.t_s, r.contacts))
        .collect();
    let streamed: Vec<(f64, Vec<TruthContact>)> = Simulator::new(&scene, 1)
        .unwrap()
        .filter_map(|e| if let SimEvent::Truth { t_s, contacts } = e.unwrap() { Some((t_s, contacts)) } else { None })
        .collect();
    assert!(streamed.len() > 30, "{} rows", streamed.len());
    assert!(streamed.iter().any(|r| r.1.len() == 2) && streamed.iter().any(|r| r.1.is_empty()));
    assert_eq!(streamed, expected);
}
