//! Scene input that must be refused, with an error that names the file, the line, the field and
//! the cause; and what the shipped scenes' comments claim about their holds.

use skinflow_sim::{Scene, SceneError};
use std::path::{Path, PathBuf};

const FILE: &str = "s.toml";

/// `(line, column, problem)` of the error `text` must give.
fn refused(text: &str) -> (usize, usize, String) {
    match Scene::from_str(text, FILE) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(SceneError::At { file, line, column, problem }) => {
            assert_eq!(file, FILE);
            (line, column, problem)
        }
        Err(e) => panic!("unexpected {e}"),
    }
}

fn accepted(text: &str) -> Scene {
    Scene::from_str(text, FILE).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// A scene with a 2 s lead-in (lines 1-3) and then `body` from line 4.
fn scene(body: &str) -> String {
    format!("[scene]\n[[step]]\nrest_s = 2.0\n{body}")
}

/// A press at the centre from line 4 ([[step]] on line 4), with `hold` lines after it.
fn press(hold: &str) -> String {
    scene(&format!("[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\nforces_n = [1.0]\n{hold}"))
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

// ---- finding 1: the caps are checked before the timeline is built

#[test]
fn a_huge_scene_is_refused_before_it_is_built() {
    // 1e6 positions x 1e4 forces x 1e5 repeats: building it exhausted the memory (SIGABRT).
    let text = scene(
        "\n[[step]]\ngrid = { x_mm = [-40.0, 40.0], y_mm = [-40.0, 40.0], n = [1000, 1000] }\n\
         diameter_mm = 15.0\nforces_n = { from = 1.0, to = 10.0, n = 10000 }\nhold_s = 1\nrepeat = 100000\n",
    );
    let (line, _, msg) = refused(&text);
    assert_eq!(line, 5, "the [[step]] line: {msg}");
    assert!(msg.starts_with("[[step]] 2: this step lasts 2e15 s"), "{msg}");
    assert!(msg.contains("(1000000 position(s) x 100000 repeat(s) x 10000 force(s) x 2 s)"), "{msg}");
    assert!(msg.contains("11.6 days"), "{msg}");
    let shown = Scene::from_str(&text, FILE).unwrap_err().to_string();
    assert!(shown.starts_with("s.toml:5:1: [[step]] 2:"), "{shown}");
}

#[test]
fn a_scene_of_too_many_segments_is_refused_even_when_short() {
    // 2e6 holds and ramps of 1 ms: 2,000 s in all, but two million segments.
    let text = scene(
        "[[step]]\ngrid = { x_mm = [-40.0, 40.0], y_mm = [-40.0, 40.0], n = [1000, 1000] }\n\
         diameter_mm = 15.0\nforces_n = [1.0]\nhold_s = 0.001\nramp_s = 0.001\nrelease_s = 0.0\n",
    );
    let (line, _, msg) = refused(&text);
    assert_eq!(line, 4, "{msg}");
    assert!(msg.contains("[[step]] 2: this step makes 2000000 rests, ramps and holds"), "{msg}");
    assert!(msg.contains("more than the 1000000 a scene may have"), "{msg}");
    // the cap is on the whole scene: steps that pass alone add up (the lead-in is 1 segment,
    // each of these 200,000)
    let fifth = "[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 15.0\nforces_n = [1.0]\nhold_s = 0.1\n\
                 ramp_s = 0.1\nrelease_s = 0.0\nrepeat = 100000\n";
    let (_, _, msg) = refused(&scene(&fifth.repeat(5)));
    assert!(msg.starts_with("[[step]] 6: this step makes 200000") && msg.contains("1000001 in the scene"), "{msg}");
    // the longest scene is accepted
    assert_eq!(accepted("[scene]\n[[step]]\nrest_s = 1e6\n").duration_s(), 1e6);
}

/// A `contacts` step of `n` contacts (on a 10-wide raster 8 mm apart), `hold_s = 1`, with the
/// given `extra` lines.
fn many_contacts(n: usize, extra: &str) -> String {
    let list: Vec<String> = (0..n)
        .map(|i| {
            let (x, y) = (-36.0 + 8.0 * (i % 10) as f64, -36.0 + 8.0 * (i / 10 % 10) as f64);
            format!("{{ x_mm = {x}, y_mm = {y}, diameter_mm = 5.0, force_n = 0.5 }}")
        })
        .collect();
    format!("[[step]]\ncontacts = [{}]\nhold_s = 1.0\n{extra}", list.join(", "))
}

#[test]
fn a_scene_holding_too_many_contacts_is_refused_before_it_is_built() {
    // 100 contacts x 100,000 repeats: 2e5 s and 4e5 segments pass, but the 3e7 contacts held
    // by the ramps, holds and releases took 1.44 GB to build.
    let (line, _, msg) = refused(&scene(&many_contacts(
        100,
        "repeat = 100000
",
    )));
    assert_eq!(line, 4, "the [[step]] line: {msg}");
    assert!(
        msg.starts_with(
            "[[step]] 2: this step holds 30000000 contacts over its ramps, holds and releases \
             (100 contacts x 3 ramp(s), hold(s) and release(s) x 100000 repeat(s)), 30000000 in the scene, \
             more than the 2000000 a scene may hold"
        ),
        "{msg}"
    );
    // the cap itself is accepted (100 contacts x 2 x 10,000: no release), one repeat more not
    let at_cap = many_contacts(100, "release_s = 0.0\nrepeat = 10000\n");
    let held = |s: Scene| s.timeline.segments.iter().map(|g| g.contacts.len()).sum::<usize>();
    assert_eq!(held(accepted(&scene(&at_cap))), 2_000_000, "48 bytes each: 96 MB");
    let (_, _, msg) = refused(&scene(&at_cap.replace("10000", "10001")));
    assert!(msg.contains("(100 contacts x 2 ramp(s), hold(s) and release(s) x 10001 repeat(s))"), "{msg}");
    assert!(msg.contains("2000200 in the scene"), "{msg}");
    // the cap is on the whole scene; segments without force hold no contact
    let steps = format!(
        "{}\n[[step]]\ncontacts = [{{ x_mm = 0.0, y_mm = 0.0, diameter_mm = 5.0, force_n = 0.0 }}]\nhold_s = 1.0\n\n\
         [[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 5.0\nforces_n = {{ from = 0.0, to = 5.0, n = 101 }}\nhold_s = 1.0\n",
        many_contacts(100, "repeat = 6666\n")
    );
    let (line, _, msg) = refused(&scene(&steps));
    assert_eq!(line, 13, "the third contact step: {msg}");
    assert!(
        msg.starts_with(
            "[[step]] 4: this step holds 300 contacts over its ramps, holds and releases (1 position(s) x \
             1 repeat(s) x 300 ramp(s), hold(s) and release(s) under load), 2000100 in the scene"
        ),
        "{msg}"
    );
}

// ---- finding 2: the scene opens with a no-load EIT frame

#[test]
fn the_scene_must_start_with_a_no_load_frame() {
    for lead_in in ["0.0", "0.1", "0.76"] {
        let text = format!(
            "[scene]\n[[step]]\nrest_s = {lead_in}\n[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\n\
             forces_n = [1.0]\nhold_s = 1.0\n"
        );
        let (line, col, msg) = refused(&text);
        assert_eq!((line, col), (3, 10), "at the lead-in's value: {msg}");
        assert!(msg.contains("at least one EIT frame period without load (1/eit_fps = 0.7692 s"), "{msg}");
        assert!(msg.contains("tares on the no-load frames"), "{msg}");
    }
    // the frame period follows eit_fps
    let slow = format!("[rates]\neit_fps = 0.5\n{}", press("hold_s = 1.0\n"));
    let (_, _, msg) = refused(&slow.replace("rest_s = 2.0", "rest_s = 1.5"));
    assert!(msg.contains("1/eit_fps = 2.0000 s; the first contact starts at 1.5 s"), "{msg}");
    accepted(&slow);
    // one frame period is enough, also when made of several rests
    accepted(&press("hold_s = 1.0\n").replace("rest_s = 2.0", "rest_s = 0.77"));
    accepted(&press("hold_s = 1.0\n").replace("rest_s = 2.0", "rest_s = 0.4\n[[step]]\nrest_s = 0.4"));
    // a force profile that waits at 0 counts as no load
    accepted(
        "[scene]\n[[step]]\nrest_s = 0.2\n[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\n\
         force_profile = [[1.0, 0.0], [2.0, 3.0]]\nramp_s = 0.0\n",
    );
}

#[test]
fn a_scene_may_say_it_starts_under_load() {
    let loaded = "[scene]\nstart_under_load = true\n[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\n\
                  forces_n = [1.0]\nhold_s = 3.0\n";
    let s = accepted(loaded);
    assert!(!s.timeline.segments[0].contacts.is_empty());
    let short = press("hold_s = 1.0\n").replace("[scene]\n", "[scene]\nstart_under_load = true\n");
    accepted(&short.replace("rest_s = 2.0", "rest_s = 0.2"));
    let (line, _, msg) = refused(&loaded.replace("true", "false"));
    assert_eq!(line, 3, "{msg}");
    assert!(msg.contains("must be a no-load period"), "{msg}");
}

// ---- finding 3: inputs that were silently accepted

#[test]
fn contacts_that_would_never_touch_are_refused() {
    let (line, _, msg) = refused(&press("hold_s = 0.0\nramp_s = 0.0\nrelease_s = 0.0\n"));
    assert_eq!(line, 4, "{msg}");
    assert!(msg.contains("hold_s, ramp_s and release_s are all 0: the contacts would never be on the skin"), "{msg}");
    let (line, _, msg) = refused(&scene(
        "[[step]]\ncontacts = [{ x_mm = 0.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 1.0 }]\n\
         hold_frames = 0\nramp_s = 0.0\n",
    ));
    assert_eq!(line, 4, "{msg}");
    assert!(msg.contains("never be on the skin"), "{msg}");
    let (line, _, msg) = refused(&scene(
        "[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\nforce_profile = [[1.0, 3.0]]\nramp_s = 0.0\n",
    ));
    assert_eq!(line, 7, "at the profile: {msg}");
    assert!(msg.contains("ramp_s, release_s and the profile's length are all 0"), "{msg}");
    // a press of no hold is still a press while it ramps
    accepted(&press("hold_s = 0.0\nramp_s = 0.5\nrelease_s = 0.0\n"));
}

#[test]
fn overlapping_contacts_are_accepted() {
    // Two indenters on one spot are simulated, not an input error; exactly the same place and
    // diameter is warned about (tests/contacts_on_skin.rs), overlapping ones nearby are not.
    let s = accepted(&scene(
        "[[step]]\ncontacts = [{ x_mm = 5.0, y_mm = 5.0, diameter_mm = 10.0, force_n = 1.0 },\n\
         { x_mm = 5.0, y_mm = 5.0, diameter_mm = 10.0, force_n = 2.0 }]\nhold_s = 1.0\n",
    ));
    assert_eq!(s.timeline.max_contacts(), 2);
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    let s = accepted(&scene(
        "[[step]]\ncontacts = [{ x_mm = 5.0, y_mm = 5.0, diameter_mm = 10.0, force_n = 1.0 },\n\
         { x_mm = 9.0, y_mm = 5.0, diameter_mm = 10.0, force_n = 2.0 }]\nhold_s = 1.0\n",
    ));
    assert_eq!(s.timeline.max_contacts(), 2);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

#[test]
fn a_frame_rate_that_yields_no_frame_is_refused() {
    let (line, _, msg) = refused(&format!("[rates]\neit_fps = 0.01\n{}", press("hold_s = 1.0\n")));
    assert_eq!(line, 2, "{msg}");
    assert!(msg.contains("\"eit_fps\": one EIT frame takes 1/eit_fps = 100 s"), "{msg}");
    assert!(msg.contains("no EIT frame"), "{msg}");
    // without the EIT channel there are no frames to miss
    let text = "[scene]\nchannels = [\"pressure\"]\n[rates]\neit_fps = 0.01\n[[step]]\nrest_s = 200.0\n";
    accepted(text);
}

#[test]
fn a_fault_that_never_shows_is_refused() {
    let fault = |extra: &str| {
        format!("{}[[fault]]\nkind = \"dead_electrode\"\nelectrode = 6\n{extra}", press("hold_s = 1.0\n"))
    };
    // the scene ends at 2 + 0.5 + 1 + 0.5 = 4 s
    let (line, _, msg) = refused(&fault("from_s = 500.0\n"));
    assert_eq!(line, 12, "at from_s: {msg}");
    assert!(
        msg.starts_with("[[fault]] 1 (dead electrode 6) \"from_s\": 500 s is not before the scene's end (4 s)"),
        "{msg}"
    );
    // frames at 1.3 fps: the last ends at 3.85 s, stamped at 3.46 s
    let (line, _, msg) = refused(&fault("from_s = 3.5\n"));
    assert_eq!(line, 9, "at the [[fault]]: {msg}");
    assert!(msg.contains("no EIT frame is stamped in [from_s, until_s) = [3.5, inf) s"), "{msg}");
    let (_, _, msg) = refused(&fault("from_s = 0.0\nuntil_s = 0.3\n"));
    assert!(msg.contains("[0, 0.3)"), "{msg}");
    accepted(&fault("from_s = 3.4\n"));
    accepted(&fault("from_s = 0.0\nuntil_s = 0.4\n"));
    let no_eit = fault("").replace("[scene]\n", "[scene]\nchannels = [\"pressure\"]\n");
    let (_, _, msg) = refused(&no_eit);
    assert!(msg.contains("no \"eit\" channel"), "{msg}");
}

#[test]
fn hold_frames_must_be_whole() {
    let (line, col, msg) = refused(&press("hold_frames = 2.5\n"));
    assert_eq!((line, col), (8, 15), "{msg}");
    assert!(msg.contains("\"hold_frames\": must be a whole number of EIT frame periods (got 2.5"), "{msg}");
    let s = accepted(&press("hold_frames = 3.0\n"));
    let hold = &s.timeline.segments[2];
    assert!((hold.end_s - hold.start_s - 3.0 / 1.3).abs() < 1e-12);
}

// ---- finding 4: errors that say what is wrong, where

#[test]
fn forces_n_errors_give_the_accepted_forms() {
    for (value, cause) in [
        ("\"five\"", "the string \"five\" is not a list of forces"),
        ("{ from = 1.0, to = 2.0 }", "the range has no \"n\""),
        ("{ from = 1.0, to = 2.0, n = 2.5 }", "\"n\" is the number 2.5, not a whole number"),
        ("{ from = 1.0, to = 2.0, n = 2, step = 1 }", "unknown key \"step\" in the range"),
        ("[1.0, \"2\"]", "element 1 is the string \"2\", not a force"),
    ] {
        let text =
            scene(&format!("[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\nforces_n = {value}\nhold_s = 1.0\n"));
        let (line, col, msg) = refused(&text);
        assert_eq!((line, col), (7, 12), "{value}: {msg}");
        assert!(msg.starts_with(&format!("\"forces_n\": {cause}; give a list of forces in N")), "{value}: {msg}");
        assert!(msg.contains("`forces_n = { from = 1.0, to = 10.0, n = 9 }`"), "{msg}");
    }
    let s = accepted(&press("hold_s = 1.0\n").replace("[1.0]", "{ from = 1, to = 3, n = 3 }"));
    let holds: Vec<f64> = s
        .timeline
        .segments
        .iter()
        .filter(|g| g.is_static() && !g.contacts.is_empty())
        .map(|g| g.contacts[0].end_force_n)
        .collect();
    assert_eq!(holds, [1.0, 2.0, 3.0]);
}

#[test]
fn model_errors_name_the_constant_at_its_line() {
    let model = |lines: &str| format!("[scene]\n[model]\n{lines}[[step]]\nrest_s = 2.0\n");
    let (line, col, msg) = refused(&model("pressure_noise_kpa = 0.01\np0_kpa = \"high\"\n"));
    assert_eq!((line, col), (4, 10), "{msg}");
    assert_eq!(msg, "[model] \"p0_kpa\": expected a number (got the string \"high\")");
    let (line, _, msg) = refused(&model("mesh_min_elements = -5\n"));
    assert_eq!(line, 3, "{msg}");
    assert_eq!(msg, "[model] \"mesh_min_elements\": expected a whole number >= 0 (got the integer -5)");
    let (line, _, msg) =
        refused(&model("strain_max = 0.5\nmesh_min_elements = 100000000\nmesh_max_elements = 100000000\n"));
    assert_eq!(line, 4, "{msg}");
    assert_eq!(
        msg,
        "[model] \"mesh_min_elements\": must be in [100, 2000000] (the forward solver's mesh limit) (got 100000000)"
    );
    let (line, _, msg) = refused(&model("mesh_max_elements = 3e6\n"));
    assert_eq!(line, 3, "{msg}");
    assert!(msg.starts_with("[model] \"mesh_max_elements\": must be in [mesh_min_elements = 5000, 2000000]"), "{msg}");
    let (line, col, msg) = refused(&model("\nbogus = 1\n"));
    assert_eq!((line, col), (4, 1), "{msg}");
    assert!(msg.starts_with("[model] \"bogus\": unknown constant"), "{msg}");
    // counts may be written as floats, rates as integers
    let s = accepted(&model("mesh_min_elements = 6e3\nmesh_max_elements = 7000\np0_kpa = 1\n"));
    assert_eq!((s.profile.mesh_min_elements, s.profile.mesh_max_elements, s.profile.p0_kpa), (6000, 7000, 1.0));
}

#[test]
fn sensor_errors_point_into_the_scene_file() {
    let sensor =
        |lines: &str| format!("[scene]\nname = \"x\"\n\n[sensor]\nname = \"s\"\n{lines}\n[[step]]\nrest_s = 2.0\n");
    let (line, col, msg) = refused(&sensor("width_mm = 100.0\nbogus = 1\n"));
    assert_eq!((line, col), (7, 1), "{msg}");
    assert!(msg.starts_with("[sensor] \"bogus\": unknown field `bogus`, expected one of"), "{msg}");
    assert!(!msg.contains("line 2") && !msg.contains("TOML parse error"), "{msg}");
    let (line, col, msg) = refused(&sensor("height_mm = 80.0\nwidth_mm = \"wide\"\n"));
    assert_eq!((line, col), (7, 12), "{msg}");
    assert!(msg.starts_with("[sensor] \"width_mm\": invalid type: string \"wide\""), "{msg}");
    let (line, col, msg) = refused(&sensor("height_mm = 80.0\nwidth_mm = -100.0\n"));
    assert_eq!((line, col), (7, 12), "{msg}");
    assert_eq!(msg, "[sensor] \"width_mm\": must be finite and > 0 (got -100)");
    // An extreme value in scientific notation, not 309 digits.
    let (_, _, msg) = refused(&sensor("height_mm = 80.0\nwidth_mm = -1e308\n"));
    assert_eq!(msg, "[sensor] \"width_mm\": must be finite and > 0 (got -1e308)");
    // explicit electrodes: the entry and its field
    let el = |a: &str| format!("[[sensor.electrode]]\nstart_mm = {a}\nend_mm = [-35.0, -50.0]\n");
    let electrodes = format!("{}{}{}", el("[-40.0, -50.0]"), el("[-30.0, -50.0]"), el("[-45.0, -10.0]"));
    let (line, col, msg) = refused(&sensor(&electrodes));
    assert_eq!((line, col), (13, 12), "{msg}");
    assert!(msg.starts_with("[sensor] \"electrode[2].start_mm\": (-45, -10) is not on the boundary"), "{msg}");
    let (line, _, msg) = refused(&sensor(&electrodes.replacen("end_mm", "stop_mm", 1)));
    assert_eq!(line, 8, "{msg}");
    assert!(msg.starts_with("[sensor] \"electrode[0].stop_mm\": unknown field `stop_mm`"), "{msg}");
}

// ---- finding 5: what hold_frames gives, as the shipped scenes' comments and MODEL.md say

/// EIT frame windows of a scene: frame k covers [k T, (k + 1) T) and is emitted when it ends
/// by the scene's end.
fn frame_windows(scene: &Scene) -> Vec<(f64, f64)> {
    let t = 1.0 / scene.rates.eit_fps;
    (0..).map(|k| (k as f64 * t, (k + 1) as f64 * t)).take_while(|&(_, b)| b <= scene.duration_s()).collect()
}

/// `(holds, [(whole frames, holds with that many)], frames)`.
type Census = (usize, Vec<(usize, usize)>, usize);

fn census(counts: &[usize]) -> Census {
    let mut by_count = std::collections::BTreeMap::new();
    for &c in counts {
        *by_count.entry(c).or_insert(0) += 1;
    }
    (counts.len(), by_count.into_iter().collect(), counts.iter().sum())
}

/// Census of the frames wholly inside each hold (a static segment with contacts), and of the
/// frames whose window lies within one truth row with contacts (what a recording's truth
/// shows, and how `tests/paper_profile.rs` picks held frames). The truth
/// samples ramps at the pressure rate, so a frame that ends less than one pressure period into
/// the next ramp counts as held there; neither channel sees that ramp yet (its last pressure
/// sample and EIT block come before the ramp's first truth row).
fn hold_census(name: &str) -> (Census, Census) {
    let scene = Scene::from_file(root().join("graphs/scenes").join(name)).unwrap();
    let windows = frame_windows(&scene);
    // frames are half-open: one that ends where the next row starts is inside (as in eval)
    let inside = |a: f64, b: f64| windows.iter().filter(|&&(s, e)| s >= a - 1e-9 && e <= b + 1e-9).count();
    let by_timeline: Vec<usize> = scene
        .timeline
        .segments
        .iter()
        .filter(|g| g.is_static() && !g.contacts.is_empty())
        .map(|g| inside(g.start_s, g.end_s))
        .collect();
    let rows = skinflow_sim::truth::truth_rows(&scene.timeline, scene.rates.pressure_hz);
    let by_truth: Vec<usize> = rows
        .iter()
        .enumerate()
        .filter(|(_, r)| !r.contacts.is_empty())
        .map(|(i, r)| inside(r.t_s, rows.get(i + 1).map_or(scene.duration_s(), |n| n.t_s)))
        .filter(|&n| n > 0)
        .collect();
    (census(&by_timeline), census(&by_truth))
}

#[test]
fn hold_frames_n_gives_n_minus_one_whole_frames_in_most_holds() {
    // calibration.toml: hold_frames = 6
    let (timeline, truth) = hold_census("calibration.toml");
    // (one hold starts on a frame boundary)
    assert_eq!(timeline, (225, vec![(5, 224), (6, 1)], 1126));
    assert_eq!(truth, (225, vec![(5, 218), (6, 7)], 1132));
    // cross-diameter.toml: hold_frames = 4
    let (timeline, truth) = hold_census("cross-diameter.toml");
    // (7 holds start on a frame boundary, e.g. the fourth: 5.5 + 3 x (1.5 + 4 T) = 25 T)
    assert_eq!(timeline, (135, vec![(3, 128), (4, 7)], 412));
    assert_eq!(truth, (135, vec![(3, 127), (4, 8)], 413));
    // single-contact.toml: hold_frames = 2, "at least one frame lies wholly inside it"
    let (timeline, truth) = hold_census("single-contact.toml");
    assert_eq!(timeline, (294, vec![(1, 279), (2, 15)], 309));
    assert_eq!(truth, (294, vec![(1, 274), (2, 20)], 314));
    // and the other scenes whose comments give the figure (hold_frames = 6)
    assert_eq!(hold_census("calibration-two-sizes.toml").1, (450, vec![(5, 439), (6, 11)], 2261));
    assert_eq!(hold_census("multi-contact.toml").1, (8, vec![(5, 8)], 40));
}

#[test]
fn shipped_scenes_and_fixtures_load() {
    let mut n = 0;
    for dir in ["graphs/scenes", "tests/fixtures", "nodes/tests/fixtures"] {
        for entry in std::fs::read_dir(root().join(dir)).unwrap() {
            let path = entry.unwrap().path();
            let text = std::fs::read_to_string(&path).unwrap_or_default();
            if path.extension().is_some_and(|e| e == "toml") && text.contains("[[step]]") {
                Scene::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
                n += 1;
            }
        }
    }
    assert!(n >= 13, "found only {n} scenes");
}

// ---- scenes that reading passed but `Simulator::new` refused (meshing, contact impedance)

/// A sensor with explicit electrodes from line 4: one from the bottom-left corner to `end`, and
/// three short ones on the other sides.
fn electrodes(end: &str) -> String {
    format!(
        "[scene]\n[sensor]\nwidth_mm = 100.0\n[[sensor.electrode]]\nstart_mm = [-50.0, -50.0]\nend_mm = {end}\n\
         [[sensor.electrode]]\nstart_mm = [10.0, -50.0]\nend_mm = [20.0, -50.0]\n\
         [[sensor.electrode]]\nstart_mm = [50.0, 10.0]\nend_mm = [50.0, 20.0]\n\
         [[sensor.electrode]]\nstart_mm = [10.0, 50.0]\nend_mm = [20.0, 50.0]\n[[step]]\nrest_s = 2.0\n"
    )
}

#[test]
fn a_scene_the_simulator_cannot_mesh_is_refused_when_read() {
    // an electrode from a corner to another side crosses the sensor: skinflow-eit accepted it,
    // and meshing refused it ("electrode 0: boundary edges cover -0 mm of its 111.8 mm")
    let (line, col, msg) = refused(&electrodes("[0.0, 50.0]"));
    assert_eq!((line, col), (4, 1), "{msg}");
    let want = "[sensor] \"electrode[0]\": from (-50, -50) to (0, 50) mm: must lie on one side (it may not wrap a \
                corner or cross the sensor)";
    assert_eq!(msg, want);
    let (_, _, msg) = refused(&electrodes("[50.0, 50.0]"));
    assert!(msg.starts_with("[sensor] \"electrode[0]\": from (-50, -50) to (50, 50) mm: must lie on one"), "{msg}");
    // from a corner along either of its sides is an electrode on one side
    for end in ["[-40.0, -50.0]", "[-50.0, -40.0]"] {
        let s = accepted(&electrodes(end));
        skinflow_sim::Simulator::new(&s, 1).unwrap_or_else(|e| panic!("{end}: {e}"));
    }
    // corners beyond the mesher's range (spade: 2^201 mm) refused meshing ("TooLarge")
    let big = "[scene]\n[sensor]\nwidth_mm = 1e62\n[[step]]\nrest_s = 2.0\n";
    let (line, col, msg) = refused(big);
    assert_eq!((line, col), (3, 12), "{msg}");
    assert_eq!(msg, "[sensor] \"width_mm\": must be at most 1e6 mm (1 km; the mesher's range) (got 1e62)");
}

#[test]
fn a_contact_impedance_that_overflows_per_electrode_is_refused_when_read() {
    // each electrode's is drawn around it: at 1.7e308 it overflowed to inf for most seeds
    let text = "[scene]\n[model]\ncontact_impedance_ohm_mm2 = 1.7e308\n[[step]]\nrest_s = 2.0\n";
    let (line, _, msg) = refused(text);
    assert_eq!(line, 3, "{msg}");
    assert!(msg.starts_with("[model] \"contact_impedance_ohm_mm2\": must be at most 1e300 (got 1.7e308)"), "{msg}");
}

/// `Scene::read`, as `skinflow check` calls it for a `sim` node, names the file.
#[test]
fn reading_a_scene_file_refuses_what_the_simulator_could_not_set_up() {
    let dir = std::env::temp_dir().join(format!("skinflow-sim-meshable-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("crossing.toml");
    std::fs::write(&path, electrodes("[0.0, 50.0]")).unwrap();
    let e = Scene::read(&path).unwrap_err().to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(e.starts_with(&format!("{}:4:1: [sensor] \"electrode[0]\"", path.display())), "{e}");
}

/// Contacts that make no physical sense on the skin: a centre off the skin is refused, an
/// indenter overhanging the skin's edge and two identical contacts pressed together are
/// accepted with a warning that says what the simulator makes of them; overlapping contacts at
/// nearby places (a deliberate hard case) stay silent. The default sensor is 100 x 100 mm.
mod contacts_on_skin {
    use super::*;
    use skinflow_sim::pneumatic::Pneumatic;
    use skinflow_sim::{Load, Profile};

    /// The warnings of a scene that must be accepted.
    fn warnings(text: &str) -> Vec<String> {
        Scene::from_str(text, FILE).unwrap_or_else(|e| panic!("{e}\n{text}")).warnings
    }

    /// A scene with a 2 s lead-in (lines 1-3) and then `body` from line 4.
    fn scene(body: &str) -> String {
        format!("[scene]\n[[step]]\nrest_s = 2.0\n{body}")
    }

    /// A `contacts` step ([[step]] on line 4, one contact a line from line 6).
    fn contacts(list: &[(f64, f64, f64, f64)]) -> String {
        let lines: Vec<String> = list
            .iter()
            .map(|(x, y, d, f)| format!("  {{ x_mm = {x:?}, y_mm = {y:?}, diameter_mm = {d:?}, force_n = {f:?} }},\n"))
            .collect();
        scene(&format!("[[step]]\ncontacts = [\n{}]\nhold_s = 1.0\n", lines.concat()))
    }

    /// A single-contact step at `places` (`at_mm = ...` or `grid = ...`, line 5) of `diameter`.
    fn single(places: &str, diameter: f64) -> String {
        scene(&format!("[[step]]\n{places}\ndiameter_mm = {diameter:?}\nforces_n = [2.0]\nhold_s = 1.0\n"))
    }

    #[test]
    fn a_centre_off_the_skin_is_refused_naming_the_step_the_contact_and_its_line() {
        let (line, col, msg) = refused(&contacts(&[(0.0, 0.0, 10.0, 1.0), (0.0, 50.5, 10.0, 1.0)]));
        assert_eq!((line, col), (7, 3), "{msg}");
        assert_eq!(
            msg,
            "[[step]] 2, contact 2 of \"contacts\": the centre (0, 50.5) mm is outside the sensor (x in [-50, 50], \
             y in [-50, 50]): an indenter centred off the skin would press on the frame, not the skin"
        );
        let shown = Scene::from_str(&contacts(&[(0.0, 0.0, 10.0, 1.0), (0.0, 50.5, 10.0, 1.0)]), FILE).unwrap_err();
        assert!(shown.to_string().starts_with("s.toml:7:3: [[step]] 2, contact 2"), "{shown}");
        // an `at_mm` entry: at its own line and column
        let (line, col, msg) = refused(&single("at_mm = [[0.0, 0.0],\n  [-60.0, 10.0]]", 10.0));
        assert_eq!((line, col), (6, 3), "{msg}");
        assert!(
            msg.starts_with("[[step]] 2, \"at_mm\" position 2: the centre (-60, 10) mm is outside the sensor"),
            "{msg}"
        );
        // a grid position: at the grid, by its number, column and row
        let (line, col, msg) =
            refused(&single("grid = { x_mm = [-40.0, 40.0], y_mm = [0.0, 55.0], n = [3, 2] }", 10.0));
        assert_eq!((line, col), (5, 8), "{msg}");
        assert!(
            msg.starts_with("[[step]] 2, \"grid\" position 4 (column 1, row 2): the centre (-40, 55) mm is outside"),
            "{msg}"
        );
        // NaN is not on the skin either (TOML writes it `nan`)
        let (_, _, msg) = refused(&scene(
            "[[step]]\ncontacts = [{ x_mm = nan, y_mm = 0.0, diameter_mm = 10.0, force_n = 1.0 }]\nhold_s = 1.0\n",
        ));
        assert!(msg.contains("the centre (NaN, 0) mm is outside the sensor"), "{msg}");
    }

    #[test]
    fn a_centre_on_the_edge_or_in_a_corner_is_accepted() {
        // the sensor is the closed rectangle: a centre on its edge is on the skin (and half its
        // disc overhangs, which is warned about)
        let w = warnings(&contacts(&[(50.0, -50.0, 10.0, 1.0)]));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("75.0 % of the 10 mm disc at (50, -50) mm is off the skin"), "{w:?}");
    }

    #[test]
    fn an_overhanging_disc_is_warned_about_with_the_share_off_the_skin_and_what_is_simulated() {
        // a 15 mm disc 5 mm from the edge: the circular segment beyond it is 10.96 % of the disc
        let w = warnings(&contacts(&[(-20.0, 0.0, 10.0, 1.0), (45.0, 0.0, 15.0, 2.0)]));
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(
            w[0],
            "s.toml:7:3: [[step]] 2, 1 of 2 contacts put part of the disc off the skin, up to 11.0 % (contact 2 of \
             \"contacts\": the 15 mm disc at (45, 0) mm): that part presses on the frame. The truth keeps the full \
             force at the commanded centre, but only the part of the disc on the skin loads the EIT foam (at the \
             disc's pressure, force / its whole area) and the pneumatic chamber (no sensitivity off the skin), so \
             both channels respond as to a smaller force"
        );
        // one position: named alone, at its line
        let w = warnings(&single("at_mm = [\n  [0.0, 46.0]]", 10.0));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with("s.toml:6:3: [[step]] 2, \"at_mm\" position 1: 5.2 % of the 10 mm disc at (0, 46) mm"),
            "{w:?}"
        );
        // a grid: one warning for the step, the worst position named (a corner)
        let w = warnings(&single("grid = { x_mm = [-40.0, 40.0], y_mm = [-40.0, 40.0], n = [5, 5] }", 22.0));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with(
                "s.toml:5:8: [[step]] 2, 16 of 25 positions put part of the disc off the skin, up to 3.2 % (\"grid\" \
                 position 1 (column 1, row 1): the 22 mm disc at (-40, -40) mm)"
            ),
            "{w:?}"
        );
        // force profiles go through the same positions
        let profile =
            scene("[[step]]\nat_mm = [[49.0, 0.0]]\ndiameter_mm = 10.0\nforce_profile = [[0.0, 0.0], [1.0, 2.0]]\n");
        assert_eq!(warnings(&profile).len(), 1);
    }

    #[test]
    fn a_disc_touching_the_edge_or_inside_it_is_not_warned_about() {
        assert_eq!(warnings(&contacts(&[(42.5, 0.0, 15.0, 1.0), (-42.5, -42.5, 15.0, 1.0)])), Vec::<String>::new());
        assert_eq!(
            warnings(&single("grid = { x_mm = [-40.0, 40.0], y_mm = [-40.0, 40.0], n = [5, 5] }", 20.0)),
            Vec::<String>::new()
        );
    }

    #[test]
    fn the_warning_says_what_the_pneumatic_channel_does() {
        // without heterogeneity and edge stiffening the footprint sensitivity is S0 times the share
        // of the footprint's quadrature points on the skin: an overhanging disc reads less
        let mut profile = Profile::ideal();
        profile.edge_stiffening = 0.0;
        profile.sensitivity_heterogeneity = 0.0;
        let sensor = skinflow_eit::Sensor::paper_100mm();
        let p = Pneumatic::new(&profile, &sensor, 1);
        let load = |x: f64| Load { x_mm: x, y_mm: 0.0, diameter_mm: 15.0, force_n: 2.0, press: 0, level: 0 };
        let inside = p.static_dp_kpa(&[load(0.0)]);
        let over = p.static_dp_kpa(&[load(45.0)]);
        assert!(inside > 0.0);
        // 11 % of the disc is off the skin; the 37-point rule puts 6 of its points there
        let ratio = over / inside;
        assert!((ratio - 31.0 / 37.0).abs() < 1e-12, "{ratio}");
    }

    #[test]
    fn identical_contacts_pressed_together_are_warned_about_and_nearby_ones_are_not() {
        let w = warnings(&contacts(&[(5.0, 5.0, 10.0, 1.0), (-20.0, 0.0, 10.0, 1.0), (5.0, 5.0, 10.0, 2.0)]));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with(
                "s.toml:8:3: [[step]] 2, contact 3 of \"contacts\": at the place of contact 1 with the same diameter \
                 (x_mm = 5, y_mm = 5, diameter_mm = 10), pressed at the same time"
            ),
            "{w:?}"
        );
        assert!(w[0].contains("if one indenter is meant, give one contact with force_n = 3"), "{w:?}");
        // -0 and 0 are one place
        assert_eq!(warnings(&contacts(&[(0.0, -0.0, 10.0, 1.0), (-0.0, 0.0, 10.0, 1.0)])).len(), 1);
        // overlapping at nearby places, or concentric of another size: the hard cases, silent
        for list in [
            [(5.0, 5.0, 10.0, 1.0), (5.0, 5.1, 10.0, 1.0)],
            [(5.0, 5.0, 10.0, 1.0), (10.0, 5.0, 10.0, 1.0)],
            [(5.0, 5.0, 10.0, 1.0), (5.0, 5.0, 12.0, 1.0)],
        ] {
            assert_eq!(warnings(&contacts(&list)), Vec::<String>::new(), "{list:?}");
        }
        // the same place in successive steps, or twice in an `at_mm` list, is pressed at other times
        let twice = scene(
            "[[step]]\ncontacts = [{ x_mm = 5.0, y_mm = 5.0, diameter_mm = 10.0, force_n = 1.0 }]\nhold_s = 1.0\n\
             [[step]]\ncontacts = [{ x_mm = 5.0, y_mm = 5.0, diameter_mm = 10.0, force_n = 1.0 }]\nhold_s = 1.0\n",
        );
        assert_eq!(warnings(&twice), Vec::<String>::new());
        assert_eq!(warnings(&single("at_mm = [[1.0, 1.0], [1.0, 1.0]]", 10.0)), Vec::<String>::new());
    }

    /// Three or more contacts at one place: one warning for the place, of the total force there
    /// (not one per pair, each of a pair's sum); another place of two gets its own.
    #[test]
    fn contacts_at_one_place_give_one_warning_of_their_total_force() {
        let w = warnings(&contacts(&[
            (10.0, 0.0, 10.0, 3.0),
            (-20.0, 0.0, 10.0, 0.5),
            (10.0, 0.0, 10.0, 2.0),
            (-20.0, 0.0, 10.0, 0.25),
            (10.0, 0.0, 10.0, 1.0),
        ]));
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].starts_with(
                "s.toml:8:3: [[step]] 2, contacts 3 and 5 of \"contacts\": at the place of contact 1 with the same \
                 diameter (x_mm = 10, y_mm = 0, diameter_mm = 10), pressed at the same time: simulated as 3 loads on \
                 one footprint (the EIT foam as under one indenter of 6 N, the summed force; the pneumatic chamber \
                 as the sum of 3 separately saturating contacts), and the truth lists all 3 contacts at the one place"
            ),
            "{w:?}"
        );
        assert!(w[0].ends_with("give one contact with force_n = 6)"), "{w:?}");
        assert!(
            w[1].starts_with("s.toml:9:3: [[step]] 2, contact 4 of \"contacts\": at the place of contact 2"),
            "{w:?}"
        );
        assert!(w[1].contains("simulated as two loads") && w[1].contains("lists both contacts"), "{w:?}");
        assert!(w[1].ends_with("give one contact with force_n = 0.75)"), "{w:?}");
    }

    #[test]
    fn shipped_scenes_warn_only_where_a_disc_overhangs() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut found = Vec::new();
        for dir in ["graphs/scenes", "tests/fixtures", "nodes/tests/fixtures"] {
            let mut paths: Vec<_> = std::fs::read_dir(root.join(dir)).unwrap().map(|e| e.unwrap().path()).collect();
            paths.sort();
            for path in paths {
                let text = std::fs::read_to_string(&path).unwrap_or_default();
                if path.extension().is_some_and(|e| e == "toml") && text.contains("[[step]]") {
                    let scene = Scene::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
                    for w in scene.warnings {
                        found.push((format!("{dir}/{}", path.file_name().unwrap().to_string_lossy()), w));
                    }
                }
            }
        }
        // the two scenes whose grids reach within a radius of the edge, and nothing else
        let expected = [
            (
                "graphs/scenes/calibration-two-sizes.toml",
                ":30:8: [[step]] 3, 16 of 25 positions put part of the disc off the skin, up to 3.2 % (\"grid\" position 1 \
                 (column 1, row 1): the 22 mm disc at (-40, -40) mm)",
            ),
            (
                "graphs/scenes/single-contact.toml",
                ":14:8: [[step]] 2, 24 of 49 positions put part of the disc off the skin, up to 21.8 % (\"grid\" position \
                 1 (column 1, row 1): the 15 mm disc at (-45, -45) mm)",
            ),
        ];
        assert_eq!(found.len(), expected.len(), "{found:#?}");
        for ((file, w), (want_file, want)) in found.iter().zip(expected) {
            assert_eq!(file, want_file);
            assert!(w.contains(want), "{w}");
        }
    }
}
