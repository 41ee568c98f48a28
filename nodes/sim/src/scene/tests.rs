use super::*;

fn parse(text: &str) -> Result<Scene, SceneError> {
    Scene::from_str(text, "t.toml")
}

/// The error's `file:line:column` prefix and message.
fn fails(text: &str) -> (usize, usize, String) {
    match parse(text).unwrap_err() {
        SceneError::At { file, line, column, problem } => {
            assert_eq!(file, "t.toml");
            (line, column, problem)
        }
        e => panic!("unexpected {e}"),
    }
}

const HEAD: &str = "[scene]\nname = \"t\"\nprofile = \"ideal\"\n\n[[step]]\nrest_s = 2.0\n\n";

#[test]
fn line_column_counts_from_one() {
    let t = "ab\ncd\n";
    assert_eq!(line_column(t, 0), (1, 1));
    assert_eq!(line_column(t, 4), (2, 2));
    assert_eq!(line_column(t, 99), (3, 1));
}

#[test]
fn staircase_grid_expands_to_holds_and_ramps() {
    let text = format!(
        "{HEAD}[[step]]\ngrid = {{ x_mm = [-20.0, 20.0], y_mm = [-20.0, 20.0], n = [2, 2] }}\n\
         diameter_mm = 15.0\nforces_n = {{ from = 1.0, to = 3.0, n = 3 }}\nloading = \"staircase\"\n\
         hold_s = 2.0\nramp_s = 0.5\nrelease_s = 0.25\nrest_s = 1.0\n"
    );
    let s = parse(&text).unwrap();
    assert_eq!(s.rates.eit_fps, 1.3);
    assert_eq!(s.rates.pressure_hz, 20.0);
    let tl = &s.timeline;
    // rest + 4 positions x (3 x (ramp + hold) + release + rest)
    assert_eq!(tl.segments.len(), 1 + 4 * 8);
    let per_position = 3.0 * 2.5 + 0.25 + 1.0;
    assert!((tl.duration_s() - (2.0 + 4.0 * per_position)).abs() < 1e-9);
    let first = &tl.segments[1].contacts[0];
    assert_eq!((first.x_mm, first.y_mm), (-20.0, -20.0));
    assert_eq!((first.start_force_n, first.end_force_n), (0.0, 1.0));
    let second_hold = &tl.segments[4].contacts[0];
    assert_eq!((second_hold.start_force_n, second_hold.end_force_n), (2.0, 2.0));
    // the second position is to the right of the first (raster scan from the bottom left)
    let second_pos = &tl.segments[9].contacts[0];
    assert_eq!((second_pos.x_mm, second_pos.y_mm), (20.0, -20.0));
    assert_ne!(first.press, second_pos.press);
    assert_eq!(tl.smallest_diameter_mm(), Some(15.0));
}

#[test]
fn separate_indentations_repeat_at_each_position() {
    let text = format!(
        "{HEAD}[[step]]\nat_mm = [[0.0, 0.0], [10.0, 5.0]]\ndiameter_mm = 10.0\nforces_n = [5.0]\nhold_frames = 6\nrepeat = 3\nrest_s = 0.5\n"
    );
    let s = parse(&text).unwrap();
    let presses: std::collections::BTreeSet<u32> =
        s.timeline.segments.iter().flat_map(|g| g.contacts.iter().map(|c| c.press)).collect();
    assert_eq!(presses.len(), 6);
    let hold = &s.timeline.segments[2];
    assert!((hold.end_s - hold.start_s - 6.0 / 1.3).abs() < 1e-12);
    // the first three indentations are at the first position
    assert_eq!(s.timeline.segments[1 + 3 * 4].contacts[0].x_mm, 10.0);
}

#[test]
fn multi_contact_and_profile_steps() {
    let text = format!(
        "{HEAD}[[step]]\ncontacts = [{{ x_mm = -30.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 0.98 }},\n\
         {{ x_mm = 30.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 1.96 }}]\nhold_frames = 6\nrest_s = 1.0\n\n\
         [[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 15.0\nforce_profile = [[0.0, 0.0], [2.0, 4.0], [3.0, 4.0]]\nramp_s = 0.0\nrelease_s = 0.5\n"
    );
    let s = parse(&text).unwrap();
    assert_eq!(s.timeline.max_contacts(), 2);
    let hold = &s.timeline.segments[2];
    assert_eq!(hold.contacts[1].end_force_n, 1.96);
    let last_ramp = s.timeline.segments.iter().rev().find(|g| !g.is_static()).unwrap();
    assert_eq!(last_ramp.contacts[0].start_force_n, 4.0);
}

#[test]
fn contact_outside_sensor_is_rejected_at_its_line() {
    let text = format!(
        "{HEAD}[[step]]\ncontacts = [\n  {{ x_mm = 60.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 1.0 }},\n]\nhold_s = 1.0\n"
    );
    let (line, col, msg) = fails(&text);
    assert_eq!((line, col), (10, 3), "{msg}");
    assert!(msg.contains("outside the sensor"), "{msg}");
}

#[test]
fn negative_force_and_diameter_are_rejected() {
    let (line, _, msg) = fails(&format!(
        "{HEAD}[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\nforces_n = [1.0, -2.0]\nhold_s = 1.0\n"
    ));
    assert_eq!(line, 11);
    assert!(msg.contains("forces_n") && msg.contains("-2"), "{msg}");
    let (line, col, msg) =
        fails(&format!("{HEAD}[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = -10.0\nforces_n = [1.0]\nhold_s = 1.0\n"));
    assert_eq!((line, col), (10, 15));
    assert!(msg.contains("diameter_mm") && msg.contains("> 0"), "{msg}");
}

#[test]
fn absurd_forces_diameters_durations_and_rates_are_rejected_at_their_line() {
    let step = |body: &str| format!("{HEAD}[[step]]\nat_mm = [[0.0, 0.0]]\n{body}");
    for (text, line, what) in [
        (step("diameter_mm = 10.0\nforces_n = [1.0, 5e9]\nhold_s = 1.0\n"), 11, "forces_n"),
        (step("diameter_mm = 150.0\nforces_n = [1.0]\nhold_s = 1.0\n"), 10, "diameter_mm"),
        (step("diameter_mm = 10.0\nforce_profile = [[0.0, 1.0], [1.0, 300.0]]\n"), 11, "force_profile"),
        (
            format!(
                "{HEAD}[[step]]\ncontacts = [{{ x_mm = 0.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 1e4 }}]\nhold_s = 1.0\n"
            ),
            9,
            "force_n",
        ),
        (format!("[rates]\neit_fps = 1e6\n\n{HEAD}"), 2, "eit_fps"),
        (format!("[rates]\npressure_hz = 1e7\n\n{HEAD}"), 2, "pressure_hz"),
    ] {
        let (l, _, msg) = fails(&text);
        assert!(msg.contains(what) && msg.contains("at most"), "{what}: {msg}");
        assert_eq!(l, line, "{what}: {msg}");
    }
    // The timeline as a whole: 5e9 s of rest is a slip, not an experiment.
    let (line, _, msg) = fails(&format!("{HEAD}[[step]]\nrest_s = 5e9\n"));
    assert_eq!(line, 8, "{msg}");
    assert!(
        msg.contains(
            "[[step]] 2: this step lasts 5e9 s (rest_s = 5000000000), which makes the scene 5.000000002e9 s long"
        ) && msg.contains("11.6 days"),
        "{msg}"
    );
    // The limits themselves are accepted.
    parse(&step("diameter_mm = 100.0\nforces_n = [200.0]\nhold_s = 1.0\n")).unwrap();
}

#[test]
fn empty_timeline_is_rejected() {
    let (_, _, msg) = fails("[scene]\nname = \"x\"\n");
    assert!(msg.contains("empty timeline"), "{msg}");
    let (_, _, msg) = fails("[scene]\n[[step]]\nrest_s = 0.0\n");
    assert!(msg.contains("empty timeline"), "{msg}");
}

#[test]
fn first_step_must_be_no_load() {
    let (line, _, msg) =
        fails("[scene]\n[[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 10.0\nforces_n = [1.0]\nhold_s = 1.0\n");
    assert_eq!(line, 2);
    assert!(msg.contains("no-load"), "{msg}");
}

#[test]
fn syntax_and_unknown_keys_name_line_and_column() {
    let (line, col, msg) = fails("[scene]\nname = \"x\"\n[[step]]\nrest_s = 1.0\nrestt_s = 2.0\n");
    assert_eq!((line, col), (5, 1), "{msg}");
    assert!(msg.contains("restt_s"), "{msg}");
    let (line, _, _) = fails("[scene]\nname = \"x\n");
    assert_eq!(line, 2);
    let (line, _, msg) = fails("[scene]\nprofile = \"perfect\"\n[[step]]\nrest_s = 1.0\n");
    assert_eq!(line, 2);
    assert!(msg.contains("perfect"), "{msg}");
}

#[test]
fn model_overrides_and_rates() {
    let text = "[scene]\nchannels = [\"pressure\"]\n[rates]\npacing = \"fast\"\npressure_hz = 50\n[model]\np0_kpa = 1\npressure_noise_kpa = 0.05\n[[step]]\nrest_s = 1.0\n";
    let s = parse(text).unwrap();
    assert_eq!(s.profile.p0_kpa, 1.0);
    assert_eq!(s.profile.pressure_noise_kpa, 0.05);
    assert_eq!(s.profile_name, "paper");
    assert_eq!(s.rates.pacing, Pacing::Fast);
    assert_eq!(s.rates.pressure_hz, 50.0);
    assert_eq!(s.channels, Channels { eit: false, pressure: true });
    let (line, _, msg) = fails("[scene]\n[model]\nbogus = 1.0\n[[step]]\nrest_s = 1.0\n");
    assert_eq!(line, 3, "the key's line");
    assert!(msg.contains("bogus"), "{msg}");
    let (_, _, msg) = fails("[scene]\n[model]\nstrain_max = 2.0\n[[step]]\nrest_s = 1.0\n");
    assert!(msg.contains("strain_max"), "{msg}");
}

#[test]
fn inline_sensor_is_used() {
    let text = "[scene]\n[sensor]\nname = \"small\"\nwidth_mm = 60.0\nheight_mm = 60.0\n[[step]]\nrest_s = 1.0\n[[step]]\nat_mm = [[35.0, 0.0]]\ndiameter_mm = 10.0\nforces_n = [1.0]\nhold_s = 1.0\n";
    let (line, _, msg) = fails(text);
    assert_eq!(line, 9);
    assert!(msg.contains("outside"), "{msg}");
    let s = parse(&text.replace("35.0", "25.0")).unwrap();
    assert_eq!(s.sensor.width_mm, 60.0);
}

/// `read_sensor` gives the sensor `read` builds, with a `[sensor]` table and without one.
#[test]
fn the_sensor_alone_is_the_sensor_of_the_scene() {
    let dir = std::env::temp_dir().join(format!("skinflow-scene-sensor-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let steps =
        "[[step]]\nrest_s = 1.0\n[[step]]\nat_mm = [[25.0, 0.0]]\ndiameter_mm = 10.0\nforces_n = [1.0]\nhold_s = 1.0\n";
    let sized = "[sensor]\nname = \"small\"\nwidth_mm = 60.0\nheight_mm = 40.0\nelectrodes_per_side = 3\n";
    for (name, text) in
        [("default.toml", format!("[scene]\n{steps}")), ("sized.toml", format!("[scene]\n{sized}{steps}"))]
    {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let alone = Scene::read_sensor(&path).unwrap();
        let (scene, _) = Scene::read(&path).unwrap();
        assert_eq!(alone, scene.sensor, "{name}");
    }
    assert_eq!(Scene::read_sensor(dir.join("sized.toml")).unwrap().width_mm, 60.0);
    let e = Scene::read_sensor(dir.join("missing.toml")).unwrap_err().to_string();
    assert!(e.contains("missing.toml: "), "{e}");
}

#[test]
fn faults_parse_with_defaults_and_bad_ones_are_named_where_they_are() {
    let ok = parse(&format!("{HEAD}[[fault]]\nkind = \"dead_electrode\"\nelectrode = 15\n")).unwrap();
    assert_eq!(
        ok.faults,
        vec![Fault::DeadElectrode {
            electrode: 15,
            from_s: 0.0,
            until_s: f64::INFINITY,
            rail_v: Fault::DEFAULT_RAIL_V
        }]
    );
    assert!(parse(HEAD).unwrap().faults.is_empty());
    let (line, _, p) = fails(&format!("{HEAD}[[fault]]\nkind = \"dead_electrode\"\nelectrode = 16\n"));
    assert_eq!(line, 10);
    assert!(p.contains("\"electrode\": must be 0 to 15 (got 16)"), "{p}");
    let (line, _, p) = fails(&format!("{HEAD}[[fault]]\nkind = \"loose_wire\"\nelectrode = 1\n"));
    assert_eq!(line, 9);
    assert!(p.contains("unknown fault \"loose_wire\""), "{p}");
    let (line, _, p) =
        fails(&format!("{HEAD}[[fault]]\nkind = \"dead_electrode\"\nelectrode = 1\nfrom_s = 5.0\nuntil_s = 5.0\n"));
    assert_eq!(line, 12);
    assert!(p.contains("\"until_s\": must be after from_s = 5"), "{p}");
    let (_, _, p) = fails(&format!("{HEAD}[[fault]]\nkind = \"dead_electrode\"\nelectrode = 1\nrail_v = -1.0\n"));
    assert!(p.contains("\"rail_v\": must be finite and > 0"), "{p}");
    let (_, _, p) = fails(&format!("{HEAD}[[fault]]\nkind = \"dead_electrode\"\nelectrode = 1\nvolts = 3.0\n"));
    assert!(p.contains("volts"), "{p}");
}

/// The figures `admit` refuses on mirror the expansion loops by hand; `Builder::check_admitted`
/// (run after every step in debug builds) compares them with what was built. Every branch, with
/// the zero-length pieces the loops drop: a wrong mirror panics here.
#[test]
fn each_step_builds_what_it_was_admitted_as() {
    let text = format!(
        "{HEAD}[[step]]\nrest_s = 0.0\n\n\
         [[step]]\ncontacts = [{{ x_mm = -30.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 1.0 }},\n\
         {{ x_mm = 30.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 2.0 }}]\nhold_s = 0.7\nramp_s = 0.0\nrepeat = 3\n\n\
         [[step]]\nat_mm = [[0.0, 0.0], [5.0, 5.0]]\ndiameter_mm = 15.0\n\
         force_profile = [[0.5, 0.0], [0.5, 1.0], [2.0, 4.0], [2.0, 4.0], [3.0, 0.0]]\nrelease_s = 0.0\nrest_s = 0.3\nrepeat = 2\n\n\
         [[step]]\ngrid = {{ x_mm = [-20.0, 20.0], y_mm = [0.0, 0.0], n = [3, 1] }}\ndiameter_mm = 15.0\n\
         forces_n = [1.0, 2.0, 3.0]\nloading = \"staircase\"\nhold_s = 0.0\nramp_s = 0.4\nrelease_s = 0.2\nrepeat = 2\n\n\
         [[step]]\nat_mm = [[10.0, 10.0]]\ndiameter_mm = 15.0\nforces_n = {{ from = 1.0, to = 2.0, n = 4 }}\n\
         hold_frames = 3\nramp_s = 0.1\nrelease_s = 0.0\nrest_s = 0.0\nrepeat = 5\n"
    );
    let s = parse(&text).unwrap();
    // kept pieces: lead-in 1, empty rest 0, contacts 3 repeats x the hold, profile 2 positions
    // x 2 repeats x (wait, ramp, 2 non-empty windows, rest), staircase 3 x 2 x (3 ramps,
    // release), separate 5 repeats x 4 forces x (ramp, hold)
    assert_eq!(s.timeline.segments.len(), 1 + 3 + 20 + 24 + 40);
}

/// The contacts held `admit` refuses on: zero forces make segments without contacts
/// (`Builder::push` keeps a segment empty when no force is applied at either end), which the
/// figures must leave out as the loops do; `Builder::check_admitted` compares them with what was
/// built.
#[test]
fn contacts_held_are_admitted_as_built() {
    let text = format!(
        "{HEAD}[[step]]\ncontacts = [{{ x_mm = -30.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 0.0 }},\n\
         {{ x_mm = 30.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 0.0 }}]\nhold_s = 0.7\nrepeat = 2\n\n\
         [[step]]\ncontacts = [{{ x_mm = -30.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 0.0 }},\n\
         {{ x_mm = 30.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 2.0 }}]\nhold_s = 0.7\nrelease_s = 0.0\n\n\
         [[step]]\nat_mm = [[0.0, 0.0], [5.0, 5.0]]\ndiameter_mm = 15.0\n\
         force_profile = [[0.5, 0.0], [1.0, 0.0], [2.0, 4.0], [3.0, 0.0], [4.0, 0.0], [5.0, 1.0]]\n\n\
         [[step]]\nat_mm = [[10.0, 10.0]]\ndiameter_mm = 15.0\nforces_n = [0.0, 0.0, 3.0, 0.0, 1.0]\n\
         loading = \"staircase\"\nhold_s = 0.5\nrepeat = 2\n\n\
         [[step]]\nat_mm = [[10.0, 10.0]]\ndiameter_mm = 15.0\nforces_n = [0.0, 2.0, 0.0]\nhold_s = 0.5\n\
         ramp_s = 0.0\nrelease_s = 0.5\n"
    );
    let s = parse(&text).unwrap();
    let held: usize = s.timeline.segments.iter().map(|g| g.contacts.len()).sum();
    // zero-force contacts 0, one loaded contact of two: 2 x (ramp, hold), profile 2 positions x
    // (2 windows to and from 4 N, 1 to 1 N, release), staircase 2 x (ramp to 3 N, hold, ramp
    // to 0, ramp to 1 N, hold, release), separate (hold, release of 2 N)
    assert_eq!(held, 4 + 8 + 12 + 2);
}

#[cfg(debug_assertions)]
#[test]
#[should_panic(expected = "segments built vs admitted")]
fn a_step_that_builds_other_than_admitted_is_caught() {
    let mut b = expand::Builder::default();
    b.segments.push(crate::timeline::Segment { start_s: 0.0, end_s: 1.0, contacts: Vec::new() });
    b.check_admitted();
}

#[test]
fn too_long_positions_and_grid_counts_are_refused_not_truncated() {
    // toml alone fills `[f64; 2]` from a longer array and drops the rest: a point at
    // (10, 20) where (10, 20, 30) was written, a 2 x 2 grid where [2, 2, 7] was.
    let step = |body: &str| format!("{HEAD}[[step]]\n{body}diameter_mm = 10.0\nforces_n = [1.0]\nhold_s = 1.0\n");
    let (line, column, problem) = fails(&step("at_mm = [[10.0, 20.0, 30.0]]\n"));
    assert_eq!((line, column), (9, 10), "{problem}");
    assert_eq!(problem, "[[step]] 2 \"at_mm[0]\": expected an array of 2 elements, found 3");
    let (line, column, problem) = fails(&step("at_mm = [[0.0, 0.0], [1.0, 2.0, 3.0, 4.0]]\n"));
    assert_eq!((line, column), (9, 22), "{problem}");
    assert_eq!(problem, "[[step]] 2 \"at_mm[1]\": expected an array of 2 elements, found 4");
    let grid = "grid = { x_mm = [-20.0, 20.0], y_mm = [-20.0, 20.0], n = [2, 2, 7] }\n";
    let (line, column, problem) = fails(&step(grid));
    assert_eq!((line, column), (9, 58), "{problem}");
    assert_eq!(problem, "[[step]] 2 \"grid.n\": expected an array of 2 elements, found 3");
    let profile = "at_mm = [[0.0, 0.0]]\nforce_profile = [[0.0, 0.0], [1.0, 2.0, 9.0]]\n";
    let (line, column, problem) = fails(&format!("{HEAD}[[step]]\n{profile}diameter_mm = 10.0\n"));
    assert_eq!((line, column), (10, 30), "{problem}");
    assert_eq!(problem, "[[step]] 2 \"force_profile[1]\": expected an array of 2 elements, found 3");
    // The right lengths still parse.
    parse(&step("at_mm = [[10.0, 20.0]]\n")).unwrap();
}

/// The off-skin share of a disc, in closed form, against a brute-force count over a fine grid
/// of the disc: edges, corners, tangent and concentric discs, a sensor that is not square.
#[test]
fn off_skin_fraction_matches_a_brute_force_count() {
    let text = "[sensor]\nname = \"r\"\nwidth_mm = 80.0\nheight_mm = 50.0\n";
    let sensor = skinflow_eit::Sensor::from_toml(text).unwrap();
    let brute = |x: f64, y: f64, d: f64| {
        let (r, n) = (0.5 * d, 1000);
        let (mut inside_disc, mut off) = (0u64, 0u64);
        for i in 0..n {
            for j in 0..n {
                let (u, v) = (-r + d * (i as f64 + 0.5) / n as f64, -r + d * (j as f64 + 0.5) / n as f64);
                if u * u + v * v <= r * r {
                    inside_disc += 1;
                    off += u64::from(!sensor.contains_mm(x + u, y + v));
                }
            }
        }
        off as f64 / inside_disc as f64
    };
    for (x, y, d) in [
        (0.0, 0.0, 50.0),
        (15.0, 0.0, 50.0),
        (35.0, 0.0, 10.0),
        (-38.0, 20.0, 12.0),
        (40.0, 25.0, 10.0),
        (-40.0, -25.0, 50.0),
        (36.0, -21.0, 12.0),
        (0.0, 23.0, 6.0),
    ] {
        let exact = expand::off_skin_fraction(&sensor, x, y, d);
        let counted = brute(x, y, d);
        assert!((exact - counted).abs() < 2e-3, "({x}, {y}) d {d}: {exact} vs {counted}");
    }
    // exactly inside or tangent: nothing off; a centre in a corner: three quarters
    assert_eq!(expand::off_skin_fraction(&sensor, 0.0, 0.0, 50.0), 0.0);
    assert_eq!(expand::off_skin_fraction(&sensor, 35.0, 20.0, 10.0), 0.0);
    assert!((expand::off_skin_fraction(&sensor, 40.0, -25.0, 10.0) - 0.75).abs() < 1e-12);
    assert!((expand::off_skin_fraction(&sensor, -40.0, 0.0, 10.0) - 0.5).abs() < 1e-12);
}
