//! Whole-binary tests of recordings at the edges of the format: a clock with times before 0
//! (refused by `check`, `run`, `eval` and `calibrate` instead of being stamped at 0), rotated
//! logger parts that each start with the truth row in effect and carry the graph that wrote
//! them, the logger's `truth_max_contacts`, and `/eit/reference` kept through replay -> logger.

use std::path::Path;

use super::support::{fixture, hdf5_io, ok, read_recording, rewrite_recording, root, skinflow, stderr};

/// A fresh work directory for one test of this module.
fn workdir(test: &str) -> std::path::PathBuf {
    super::support::workdir("recordings", test)
}

/// Copies recording `src` into `dst` with every time of `/eit`, `/pressure` and `/truth`
/// moved by `by_s`.
fn shift_clock(src: &Path, dst: &Path, by_s: f64) {
    rewrite_recording(src, dst, by_s, |_, t, kpa| Some((t, kpa)));
}

/// A lockstep graph replaying `rec` into a `null` sink.
fn replay_graph(d: &Path, name: &str, rec: &str) {
    let graph = format!(
        "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = {rec:?}, speed = 0.0 }}\n\
         [[node]]\nid = \"sink\"\nkind = \"null\"\n\
         [[edge]]\nfrom = \"replay.eit\"\nto = \"sink.in\"\n"
    );
    std::fs::write(d.join(name), graph).unwrap();
}

/// A recording whose clock has times before 0 (the contract allows any monotonic clock, and
/// `inspect` reads it) cannot be replayed: the engine stamps messages on its clock, which
/// starts at 0, and clamping gave every such message the time 0 (eval scored 3.15 N RMSE
/// instead of 0.05 N, without a word). `check`, `run`, `eval` and `calibrate` refuse it naming
/// the file, the dataset, the row and the value.
#[test]
fn a_recording_with_times_before_0_is_refused_naming_the_first_one() {
    let d = workdir("negative-times");
    ok(&skinflow(&d, &["simulate", fixture("tiny-eval.toml").to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
    shift_clock(&d.join("rec.h5"), &d.join("shifted.h5"), -20.0);
    let shifted = read_recording(d.join("shifted.h5"));
    let eit_t0 = shifted.eit.as_ref().unwrap().t_s[0];
    let earliest = [&shifted.eit.as_ref().unwrap().t_s, &shifted.pressure.as_ref().unwrap().t_s]
        .into_iter()
        .chain([&shifted.truth.as_ref().unwrap().t_s])
        .map(|t| t[0])
        .fold(f64::INFINITY, f64::min);
    assert!(eit_t0 < 0.0 && earliest <= eit_t0);
    let expected = format!(
        "shifted.h5: /eit/t[0] = {eit_t0} s: times before 0 cannot be replayed (the engine's clock starts at 0); \
         shift the recording's clock: add {} s or more to every time dataset (/eit/t, /pressure/t, /truth/t and the \
         /derived ones)",
        -earliest
    );
    // Read as any recording.
    let text = ok(&skinflow(&d, &["inspect", "shifted.h5"]));
    assert!(text.contains("/eit"), "{text}");

    replay_graph(&d, "g.toml", "shifted.h5");
    replay_graph(&d, "fine.toml", "rec.h5");
    ok(&skinflow(&d, &["check", "fine.toml"]));
    let out = skinflow(&d, &["check", "g.toml"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("node \"replay\"") && err.contains(&expected), "{err}");
    let out = skinflow(&d, &["run", "g.toml"]);
    let err = stderr(&out);
    assert!(!out.status.success() && err.contains(&expected), "{err}");

    let calib = root().join("graphs/calib/paper.toml");
    for args in [
        vec!["eval", "shifted.h5", "--calib", calib.to_str().unwrap(), "--json", "e.json"],
        vec!["calibrate", "shifted.h5", "--out", "c.toml"],
    ] {
        let out = skinflow(&d, &args);
        let err = stderr(&out);
        assert!(!out.status.success(), "{args:?} succeeded: {err}");
        assert!(err.contains(&expected), "{args:?}: {err}");
        assert!(!d.join("e.json").exists() && !d.join("c.toml").exists(), "{args:?} wrote its output");
    }
    // The recording at its own clock (from 0) is evaluated.
    ok(&skinflow(&d, &["eval", "rec.h5", "--calib", calib.to_str().unwrap()]));
}

/// A held press split across rotated logger parts: every part after the first starts with the
/// truth row in effect when it started (the last one of the part before, at its own time), so
/// each part alone gives every frame the truth the whole recording gives it, and a part that
/// starts under load reads as loaded from its first frame.
#[test]
fn rotated_logger_parts_each_start_with_the_truth_row_in_effect() {
    let d = workdir("rotated-truth");
    let scene = "[scene]\nname = \"held\"\nprofile = \"paper\"\n\n\
                 [[step]]\nrest_s = 2.0\n\n\
                 [[step]]\nat_mm = [[10.0, -5.0]]\ndiameter_mm = 15.0\nforces_n = [4.0]\nhold_s = 4.0\nrest_s = 1.5\n";
    std::fs::write(d.join("held.toml"), scene).unwrap();
    let graph = "[graph]\nmode = \"lockstep\"\n\
        [[node]]\nid = \"sim\"\nkind = \"sim\"\nparams = { scene = \"held.toml\", pacing = \"fast\", seed = 3 }\n\
        [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = { path = \"rot.h5\", rotate_s = 1.0 }\n\
        [[edge]]\nfrom = \"sim.eit\"\nto = \"log.eit\"\ncapacity = 1024\n\
        [[edge]]\nfrom = \"sim.pressure\"\nto = \"log.pressure\"\ncapacity = 1024\n\
        [[edge]]\nfrom = \"sim.truth\"\nto = \"log.truth\"\ncapacity = 1024\n";
    std::fs::write(d.join("g.toml"), graph).unwrap();
    ok(&skinflow(&d, &["run", "g.toml"]));
    assert!(!d.join("rot.h5").exists(), "rotating: only the parts are written");
    let parts = hdf5_io(|| skinflow_record::rotate::find_parts(&d.join("rot.h5"))).unwrap();
    assert!(parts.len() >= 6, "7.5 s in 1 s parts gave {} parts", parts.len());
    let recs: Vec<_> = parts.iter().map(read_recording).collect();
    // Each part names the graph that wrote it (`inspect --graph` prints it).
    for (part, rec) in parts.iter().zip(&recs) {
        assert_eq!(rec.graph_toml.as_deref(), Some(graph), "{}", part.display());
    }
    assert_eq!(ok(&skinflow(&d, &["inspect", "--graph", parts[1].to_str().unwrap()])), graph);

    // The whole truth: the parts' rows joined, without each later part's first row, which
    // repeats the last row of the part before.
    let (mut t_all, mut rows_all) = (Vec::new(), Vec::new());
    for (k, rec) in recs.iter().enumerate() {
        let truth = rec.truth.as_ref().unwrap();
        let rows: Vec<(f64, Vec<skinflow_record::TruthContact>)> =
            (0..truth.len()).map(|i| (truth.t_s[i], truth.row(i).contacts().collect())).collect();
        if k > 0 {
            assert_eq!(
                rows.first(),
                t_all.last().map(|t: &f64| (*t, rows_all.last().cloned().unwrap())).as_ref(),
                "part {} starts with the last truth row of part {k}",
                k + 1
            );
        }
        for (t, c) in rows.into_iter().skip(usize::from(k > 0)) {
            t_all.push(t);
            rows_all.push(c);
        }
    }
    assert!(rows_all.iter().any(|c| c.len() == 1), "the press is in the truth");
    let in_effect = |t: f64| t_all.partition_point(|&r| r <= t).checked_sub(1);

    let mut under_load = 0;
    for (k, rec) in recs.iter().enumerate() {
        let truth = rec.truth.as_ref().unwrap();
        let eit = rec.eit.as_ref().unwrap();
        for &t in &eit.t_s {
            let row = truth.index_at(t).unwrap_or_else(|| panic!("part {}: frame at {t} s has no truth", k + 1));
            let whole = in_effect(t).unwrap();
            assert_eq!(
                (truth.t_s[row], truth.row(row).contacts().collect::<Vec<_>>()),
                (t_all[whole], rows_all[whole].clone()),
                "part {}: frame at {t} s",
                k + 1
            );
        }
        let starts_loaded = truth.row(0).contact_count() == 1 && eit.t_s.first().is_some_and(|&t| truth.t_s[0] < t);
        if k > 0 && starts_loaded {
            under_load += 1;
            // No leading no-load period in a part that starts under load.
            assert!(rec.no_load_eit_frames(2.0).is_empty(), "part {}", k + 1);
        }
        // `inspect` of the part alone: every frame covered.
        let text = ok(&skinflow(&d, &["inspect", parts[k].to_str().unwrap()]));
        let coverage = text.lines().find(|l| l.starts_with("truth:")).expect("a truth summary line");
        assert!(coverage.ends_with("(100.0 %)") || eit.is_empty(), "part {}: {coverage}", k + 1);
    }
    assert!(under_load >= 2, "the 4 s hold spans at least two part starts ({under_load})");
}

/// The logger's truth arrays have `truth_max_contacts` columns (default 8): a 9-contact truth
/// is logged with `truth_max_contacts = 9`, and stops a logger left at the default with an
/// error naming the param; 0 is refused by `check`. (The file written here carries no graph,
/// which `inspect --graph` reports.)
#[test]
fn the_logger_logs_as_many_truth_contacts_as_truth_max_contacts() {
    let d = workdir("truth-columns");
    let contacts: Vec<skinflow_record::TruthContact> = (0..9)
        .map(|i| skinflow_record::TruthContact {
            x_mm: -40.0 + 10.0 * f64::from(i),
            y_mm: 0.0,
            force_n: 1.0 + f64::from(i),
            diameter_mm: 10.0,
        })
        .collect();
    hdf5_io(|| {
        let sensor = skinflow_sim::Scene::read_sensor(fixture("tiny-eval.toml")).unwrap();
        let mut opts = skinflow_record::WriterOptions::new(sensor.toml.clone());
        opts.streams = skinflow_record::Streams { eit: false, truth: true, ..skinflow_record::Streams::default() };
        opts.truth_max_contacts = 9;
        let mut w = skinflow_record::RecordingWriter::create(d.join("nine.h5"), &opts).unwrap();
        for i in 0..20u32 {
            let t = f64::from(i) * 0.1;
            if i == 0 || i == 10 {
                w.append_truth(t, if i == 0 { &[] } else { &contacts }).unwrap();
            }
            w.append_pressure(t, 0.0).unwrap();
        }
        w.close().unwrap();
    });
    let graph = |name: &str, extra: &str| {
        let g = format!(
            "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = \"nine.h5\", speed = 0.0 }}\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"{name}.h5\"{extra} }}\n\
             [[edge]]\nfrom = \"replay.pressure\"\nto = \"log.pressure\"\n\
             [[edge]]\nfrom = \"replay.truth\"\nto = \"log.truth\"\n"
        );
        std::fs::write(d.join(format!("{name}.toml")), g).unwrap();
        format!("{name}.toml")
    };
    ok(&skinflow(&d, &["run", &graph("wide", ", truth_max_contacts = 9")]));
    let rec = read_recording(d.join("wide.h5"));
    let truth = rec.truth.as_ref().unwrap();
    assert_eq!((truth.max_contacts, truth.len()), (9, 2));
    assert_eq!(truth.row(1).contacts().collect::<Vec<_>>(), contacts);

    let out = skinflow(&d, &["run", &graph("narrow", "")]);
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains(
            "param \"truth_max_contacts\": ",
        ) && err.contains(
            "narrow.h5: /truth: a truth row has 9 contacts, more than truth_max_contacts = 8 (the columns of the truth \
             arrays, fixed when the file is created); set the logger's truth_max_contacts to 9 or more"
        ),
        "{err}"
    );
    // Written without a graph: `inspect --graph` says so, naming the file.
    let out = skinflow(&d, &["inspect", "--graph", "nine.h5"]);
    assert!(!out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("nine.h5: no `graph` attribute"), "{}", stderr(&out));
    let out = skinflow(&d, &["check", &graph("zero", ", truth_max_contacts = 0")]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("truth_max_contacts") && err.contains("must be in [1, 1024]") && err.contains("got 0)"),
        "{err}"
    );
}

/// A rotating logger run again over its own path: without `overwrite` it is refused at start
/// naming part 1; with it, the earlier, longer run's parts go, so the parts readers join are
/// this run's alone (they used to be joined to the earlier run's later parts).
#[test]
fn a_rotated_recording_run_again_replaces_every_earlier_part() {
    let d = workdir("rotated-again");
    let scene = |hold_s: f64| {
        format!(
            "[scene]\nname = \"held\"\nprofile = \"paper\"\n\n[[step]]\nrest_s = 2.0\n\n\
             [[step]]\nat_mm = [[10.0, -5.0]]\ndiameter_mm = 15.0\nforces_n = [4.0]\nhold_s = {hold_s}\nrest_s = 1.5\n"
        )
    };
    std::fs::write(d.join("long.toml"), scene(4.0)).unwrap();
    std::fs::write(d.join("short.toml"), scene(0.5)).unwrap();
    let graph = |scene: &str, overwrite: bool| {
        let name = format!("g-{scene}-{overwrite}.toml");
        let g = format!(
            "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"sim\"\nkind = \"sim\"\nparams = {{ scene = \"{scene}.toml\", pacing = \"fast\", seed = 3 }}\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"rot.h5\", rotate_s = 1.0, overwrite = {overwrite} }}\n\
             [[edge]]\nfrom = \"sim.eit\"\nto = \"log.eit\"\ncapacity = 1024\n\
             [[edge]]\nfrom = \"sim.pressure\"\nto = \"log.pressure\"\ncapacity = 1024\n"
        );
        std::fs::write(d.join(&name), g).unwrap();
        name
    };
    let parts = || hdf5_io(|| skinflow_record::rotate::find_parts(&d.join("rot.h5"))).unwrap();
    ok(&skinflow(&d, &["run", &graph("long", false)]));
    let long = parts().len();

    let out = skinflow(&d, &["run", &graph("short", false)]);
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("rot-0001.h5: exists: part 1 of a rotated recording at this path"), "{err}");
    assert_eq!(parts().len(), long, "a refused run touches no part");

    ok(&skinflow(&d, &["run", &graph("short", true)]));
    let short = parts();
    assert!(short.len() < long, "{} parts after {long}", short.len());
    // The joined parts are one run: its EIT frames, in order, ending with the short scene.
    let mut t = Vec::new();
    for p in &short {
        t.extend(read_recording(p).eit.unwrap().t_s);
    }
    assert!(t.windows(2).all(|w| w[0] < w[1]), "{t:?}");
    assert!(*t.last().unwrap() < 6.0, "the short scene lasts about 5 s, the joined parts end at {t:?}");
}

/// A logger no message reaches writes no file and says so, also when a file of an earlier run
/// is at its path (which would otherwise pass for this run's recording).
#[test]
fn a_logger_that_gets_no_message_says_nothing_was_recorded() {
    let d = workdir("no-message");
    hdf5_io(|| {
        let sensor = skinflow_sim::Scene::read_sensor(fixture("tiny-eval.toml")).unwrap();
        let mut opts = skinflow_record::WriterOptions::new(sensor.toml.clone());
        opts.streams = skinflow_record::Streams { eit: false, pressure: true, ..skinflow_record::Streams::default() };
        let mut w = skinflow_record::RecordingWriter::create(d.join("pressure-only.h5"), &opts).unwrap();
        for i in 0..20u32 {
            w.append_pressure(f64::from(i) * 0.05, 0.0).unwrap();
        }
        w.close().unwrap();
    });
    let g = "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = { path = \"pressure-only.h5\", speed = 0.0 }\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = { path = \"eit.h5\", overwrite = true }\n\
             [[edge]]\nfrom = \"replay.eit\"\nto = \"log.eit\"\n";
    std::fs::write(d.join("g.toml"), g).unwrap();
    for earlier in [false, true] {
        let out = skinflow(&d, &["run", "g.toml"]);
        let err = stderr(&out);
        assert!(out.status.success(), "{err}");
        assert!(err.contains("no message arrived: nothing recorded, no file written"), "{err}");
        assert_eq!(err.contains("the recording already at this path is from before this run"), earlier, "{err}");
        assert_eq!(d.join("eit.h5").exists(), earlier);
        std::fs::copy(d.join("pressure-only.h5"), d.join("eit.h5")).unwrap();
    }
}

/// Writes a small recording with `/eit/reference` of sensor `sensor_toml` (a sensor file, or
/// a scene for the default sensor) at `path`: 40 EIT frames 50 ms apart and 100 pressure
/// samples 20 ms apart, values from a fixed-seed generator. Returns the reference, whose
/// values use every bit of their mantissa (a copy that is not bit-identical shows).
fn recording_with_reference(path: &Path, sensor_file: &Path) -> Vec<f64> {
    hdf5_io(|| {
        let sensor = skinflow_sim::Scene::read_sensor(sensor_file).unwrap();
        let mut opts = skinflow_record::WriterOptions::new(sensor.toml.clone());
        opts.streams = skinflow_record::Streams::default(); // EIT and pressure
        let mut w = skinflow_record::RecordingWriter::create(path, &opts).unwrap();
        // xorshift64, fixed seed: uniform in [0, 1) with 53 random bits.
        let mut x: u64 = 0x2545_f491_4f6c_dd1d;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let reference: Vec<f64> = (0..sensor.measurement_count()).map(|_| 0.5 + next()).collect();
        w.set_reference(&reference).unwrap();
        for i in 0..40u32 {
            let v: Vec<f64> = reference.iter().map(|r| r + 1e-3 * next()).collect();
            w.append_eit(0.025 + 0.05 * f64::from(i), u64::from(i), &v).unwrap();
        }
        for i in 0..100u32 {
            w.append_pressure(0.01 + 0.02 * f64::from(i), 0.1 * next()).unwrap();
        }
        w.close().unwrap();
        reference
    })
}

/// A graph replaying `rec` as fast as possible into a logger writing `out` with `log_params`
/// (appended to its params), its `reference` input wired when `reference`; lockstep unless
/// `realtime`.
fn relog_graph(rec: &str, out: &str, log_params: &str, reference: bool, realtime: bool) -> String {
    let mode = if realtime { "" } else { "mode = \"lockstep\"\n" };
    let mut g = format!(
        "[graph]\n{mode}\
         [[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = {{ path = {rec:?}, speed = 0.0 }}\n\
         [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = {out:?}{log_params} }}\n\
         [[edge]]\nfrom = \"replay.eit\"\nto = \"log.eit\"\n\
         [[edge]]\nfrom = \"replay.pressure\"\nto = \"log.pressure\"\n"
    );
    if reference {
        g.push_str("[[edge]]\nfrom = \"replay.reference\"\nto = \"log.reference\"\n");
    }
    g
}

/// Whether two time columns agree to the engine's clock resolution (1 ns: a replay stamps
/// its messages in whole nanoseconds).
fn same_times(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-9)
}

/// Whether two frames hold the same values bit for bit.
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// A recording with `/eit/reference` replayed into a logger with its `reference` input wired
/// keeps the reference, bit-identical, in the new file (with and without SWMR, in lockstep and
/// in real time) and in every part of a rotated one; its frames are all there. Before the
/// logger had the input the graph was refused (and a graph without it lost the reference).
#[test]
fn a_replayed_reference_is_logged_again_bit_identical() {
    let d = workdir("relog-reference");
    let reference = recording_with_reference(&d.join("ref.h5"), &fixture("tiny-eval.toml"));
    let original = read_recording(d.join("ref.h5"));
    let frames = original.eit.as_ref().unwrap();
    for (name, params, realtime) in [
        ("plain", "", false),
        ("swmr", ", swmr = true", false),
        ("realtime-swmr", ", swmr = true", true),
        ("rotated", ", rotate_s = 0.5", false),
        ("rotated-swmr", ", rotate_s = 0.5, swmr = true", false),
    ] {
        let out = format!("{name}.h5");
        std::fs::write(d.join(format!("{name}.toml")), relog_graph("ref.h5", &out, params, true, realtime)).unwrap();
        let run = skinflow(&d, &["run", &format!("{name}.toml")]);
        ok(&run);
        let err = stderr(&run);
        assert!(!err.contains("reference"), "{name}: a warning about the reference: {err}");
        let files = hdf5_io(|| skinflow_record::rotate::recording_files(&d.join(&out))).unwrap();
        assert_eq!(files.len() > 1, name.starts_with("rotated"), "{name}: {files:?}");
        let mut t = Vec::new();
        let mut v = Vec::new();
        for f in &files {
            let rec = read_recording(f);
            let stored = rec.reference.as_deref().unwrap_or_else(|| panic!("{}: no /eit/reference", f.display()));
            assert!(same_bits(stored, &reference), "{}: /eit/reference differs from the original's", f.display());
            let eit = rec.eit.unwrap();
            t.extend(eit.t_s.iter().copied());
            v.extend((0..eit.len()).flat_map(|i| eit.frame(i).to_vec()));
        }
        assert!(same_times(&t, &frames.t_s), "{name}: every frame, in order: {t:?}");
        let original: Vec<f64> = (0..frames.len()).flat_map(|i| frames.frame(i).to_vec()).collect();
        assert!(same_bits(&v, &original), "{name}: the frames' values");
    }
    // `inspect` names the reference of the copy.
    let text = ok(&skinflow(&d, &["inspect", "plain.h5"]));
    assert!(text.contains("reference: /eit/reference"), "{text}");
}

/// A logger whose `reference` input is not wired writes no `/eit/reference`, as before,
/// however the recording replayed has one; its rows are the same.
#[test]
fn a_logger_without_its_reference_input_writes_no_reference() {
    let d = workdir("relog-no-reference");
    recording_with_reference(&d.join("ref.h5"), &fixture("tiny-eval.toml"));
    std::fs::write(d.join("g.toml"), relog_graph("ref.h5", "out.h5", "", false, false)).unwrap();
    ok(&skinflow(&d, &["run", "g.toml"]));
    let (original, copy) = (read_recording(d.join("ref.h5")), read_recording(d.join("out.h5")));
    assert!(copy.reference.is_none());
    assert!(same_times(&copy.eit.unwrap().t_s, &original.eit.unwrap().t_s));
    assert_eq!(copy.pressure.unwrap().kpa, original.pressure.unwrap().kpa);
}

/// A reference of another width than the logger's frames is refused: here a recording of
/// the default sensor (120 values) whose reference goes to a logger of a 12-electrode sensor
/// (66 values) while its frames come from a recording of that sensor. `check`, and `run`
/// before any node starts, refuse it naming the logger, its sensor and the replay the
/// reference comes from; no file is written. (A source that reaches the logger's `reference`
/// unchecked is refused when its frame arrives, naming the port and both widths: the unit
/// tests of `skinflow_nodes::log`.)
#[test]
fn a_reference_of_another_sensor_is_refused_before_the_run() {
    let d = workdir("relog-reference-width");
    let small = "[sensor]\nname = \"small\"\nwidth_mm = 100.0\nheight_mm = 100.0\nelectrodes_per_side = 3\n\
                 electrode_length_mm = 5.0\nprotocol = \"pairwise\"\n";
    std::fs::write(d.join("small.toml"), small).unwrap();
    recording_with_reference(&d.join("ref.h5"), &fixture("tiny-eval.toml"));
    let small_reference = recording_with_reference(&d.join("small.h5"), &d.join("small.toml"));
    assert_eq!(small_reference.len(), 66);
    let g = "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"frames\"\nkind = \"replay\"\nparams = { path = \"small.h5\", speed = 0.0 }\n\
             [[node]]\nid = \"ref\"\nkind = \"replay\"\nparams = { path = \"ref.h5\", speed = 0.0 }\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = { path = \"out.h5\", sensor = \"small.toml\" }\n\
             [[edge]]\nfrom = \"frames.eit\"\nto = \"log.eit\"\n\
             [[edge]]\nfrom = \"ref.reference\"\nto = \"log.reference\"\n";
    std::fs::write(d.join("g.toml"), g).unwrap();
    for cmd in ["check", "run"] {
        let out = skinflow(&d, &[cmd, "g.toml"]);
        let err = stderr(&out);
        assert!(!out.status.success(), "{cmd}: {err}");
        assert!(
            err.contains("node \"log\": param \"sensor\": records as its `sensor` attribute sensor")
                && err.contains("but its frames come from replay \"ref\", whose recording")
                && !err.contains("replay \"frames\""),
            "{cmd}: {err}"
        );
        assert!(!d.join("out.h5").exists(), "{cmd}");
    }
    // The same graph with the reference of the logger's own sensor runs and stores it.
    std::fs::write(d.join("ok.toml"), g.replace("ref.h5", "small.h5")).unwrap();
    ok(&skinflow(&d, &["run", "ok.toml"]));
    assert!(same_bits(read_recording(d.join("out.h5")).reference.as_deref().unwrap(), &small_reference));
}
