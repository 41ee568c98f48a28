//! Schema violations are refused with an error naming the file, the HDF5 path and the problem
//! (CONTRACTS.md section 2). Each case starts from a valid file and breaks one thing.

use std::path::{Path, PathBuf};

use hdf5::types::VarLenUnicode;
use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{
    ForceRow, RecordError, Recording, RecordingWriter, SchemaProblem, Streams, SyncRow, TruthContact, WriterOptions,
};

/// An empty directory of its own for one test.
fn fresh_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-schema-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A writer of `/eit`, `/derived/sync` and one force strategy `s` at `dir/name`.
fn sync_and_forces_writer(dir: &Path, name: &str) -> (PathBuf, RecordingWriter) {
    let path = dir.join(name);
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { sync: true, force_strategies: vec!["s".into()], ..Streams::default() };
    let w = RecordingWriter::create(&path, &opts).unwrap();
    (path, w)
}

/// [`sync_and_forces_writer`]'s file with 5 frames, each with a sync row and a force of
/// strategy `s` carrying guard bits `flags`.
fn sync_and_forces_file(dir: &Path, name: &str, flags: u32) -> PathBuf {
    let (path, mut w) = sync_and_forces_writer(dir, name);
    let sync = SyncRow {
        dp_kpa: 1.0,
        pressure_samples: 3,
        pressure_sd_kpa: 0.01,
        settled: true,
        no_load: false,
        p0_kpa: 0.0,
        noise_kpa: 0.01,
    };
    for i in 0..5u64 {
        let t = i as f64 * 0.1;
        w.append_eit(t, i, &[1.0; 120]).unwrap();
        w.append_sync(t, &sync).unwrap();
        w.append_forces(0, t, &[ForceRow { force_n: 2.0, dp_kpa: 1.0, flags }]).unwrap();
    }
    w.close().unwrap();
    path
}

fn valid_file(dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(name);
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { truth: true, ..Streams::default() };
    let mut w = RecordingWriter::create(&path, &opts).unwrap();
    w.set_reference(&[0.5; 120]).unwrap();
    for i in 0..10u64 {
        w.append_eit(i as f64 * 0.1, i, &[1.0; 120]).unwrap();
        w.append_pressure(i as f64 * 0.1, 2.0).unwrap();
    }
    w.append_truth(0.0, &[]).unwrap();
    w.append_truth(0.5, &[TruthContact { x_mm: 1.0, y_mm: 2.0, force_n: 3.0, diameter_mm: 4.0 }]).unwrap();
    w.close().unwrap();
    path
}

fn set_str_attr(f: &hdf5::File, name: &str, value: &str) {
    if f.attr_names().unwrap().iter().any(|n| n == name) {
        f.delete_attr(name).unwrap();
    }
    let v: VarLenUnicode = value.parse().unwrap();
    f.new_attr::<VarLenUnicode>().shape(()).create(name).unwrap().write_scalar(&v).unwrap();
}

fn replace_dataset(f: &hdf5::File, path: &str, values: &[f64], shape: &[usize]) {
    f.unlink(path).unwrap();
    let arr = ndarray::ArrayD::from_shape_vec(shape.to_vec(), values.to_vec()).unwrap();
    f.new_dataset_builder().with_data(&arr).create(path).unwrap();
}

type Break = fn(&hdf5::File);

#[test]
fn every_violation_is_refused_with_file_path_and_problem() {
    let dir = fresh_dir("schema");
    let sensor_12 = PAPER_100MM_TOML.replace("electrodes_per_side = 4", "electrodes_per_side = 3");
    let cases: Vec<(&str, Break, &str, SchemaProblem)> = vec![
        (
            "other format",
            |f| set_str_attr(f, "format", "other-thing"),
            "/ attr format",
            SchemaProblem::WrongFormat { found: "other-thing".into() },
        ),
        (
            "format is a number",
            |f| {
                f.delete_attr("format").unwrap();
                f.new_attr::<i32>().shape(()).create("format").unwrap().write_scalar(&7).unwrap();
            },
            "/ attr format",
            SchemaProblem::NotString { found: "int32".into() },
        ),
        (
            "newer version",
            |f| {
                f.delete_attr("format_version").unwrap();
                f.new_attr::<i64>().shape(()).create("format_version").unwrap().write_scalar(&2).unwrap();
            },
            "/ attr format_version",
            SchemaProblem::NewerVersion { found: 2, supported: 1 },
        ),
        (
            "fractional version",
            |f| {
                f.delete_attr("format_version").unwrap();
                f.new_attr::<f64>().shape(()).create("format_version").unwrap().write_scalar(&1.5).unwrap();
            },
            "/ attr format_version",
            SchemaProblem::NotNumeric { found: "1.5".into() },
        ),
        ("no sensor", |f| f.delete_attr("sensor").unwrap(), "/ attr sensor", SchemaProblem::Missing),
        (
            "eit/seq shorter",
            |f| {
                f.unlink("/eit/seq").unwrap();
                f.new_dataset_builder().with_data(&[0u64, 1, 2][..]).create("/eit/seq").unwrap();
            },
            "/eit/seq",
            SchemaProblem::LengthMismatch { found: 3, other: "/eit/t".into(), expected: 10 },
        ),
        (
            "eit/seq fractional (as doubles)",
            |f| replace_dataset(f, "/eit/seq", &[0.0, 1.0, 2.0, 3.5, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0], &[10]),
            "/eit/seq",
            SchemaProblem::NotACount { row: 3, value: 3.5 },
        ),
        (
            "eit/seq negative (as int64)",
            |f| {
                f.unlink("/eit/seq").unwrap();
                let seq: Vec<i64> = (-1..9).collect();
                f.new_dataset_builder().with_data(&seq[..]).create("/eit/seq").unwrap();
            },
            "/eit/seq",
            SchemaProblem::NotACount { row: 0, value: -1.0 },
        ),
        (
            "eit/t in integer milliseconds",
            |f| {
                f.unlink("/eit/t").unwrap();
                let t_ms: Vec<i64> = (0..10).map(|i| i * 100).collect();
                f.new_dataset_builder().with_data(&t_ms[..]).create("/eit/t").unwrap();
            },
            "/eit/t",
            SchemaProblem::IntegerTimes { found: "int64".into() },
        ),
        (
            "truth/t as unsigned integers",
            |f| {
                f.unlink("/truth/t").unwrap();
                f.new_dataset_builder().with_data(&[0u32, 1][..]).create("/truth/t").unwrap();
            },
            "/truth/t",
            SchemaProblem::IntegerTimes { found: "uint32".into() },
        ),
        (
            "pressure/kpa longer",
            |f| replace_dataset(f, "/pressure/kpa", &[0.0; 11], &[11]),
            "/pressure/kpa",
            SchemaProblem::LengthMismatch { found: 11, other: "/pressure/t".into(), expected: 10 },
        ),
        (
            "eit/v one-dimensional",
            |f| replace_dataset(f, "/eit/v", &[0.0; 1200], &[1200]),
            "/eit/v",
            SchemaProblem::WrongRank { found: 1, expected: 2 },
        ),
        (
            "eit/v narrower than the protocol",
            |f| replace_dataset(f, "/eit/v", &[0.0; 1190], &[10, 119]),
            "/eit/v",
            SchemaProblem::WidthMismatch { found: 119, expected: 120, protocol: "pairwise".into() },
        ),
        (
            "truth/force_n narrower",
            |f| replace_dataset(f, "/truth/force_n", &[0.0; 2], &[2, 1]),
            "/truth/force_n",
            SchemaProblem::ColumnMismatch { found: 1, other: "/truth/x_mm".into(), expected: 8 },
        ),
        ("truth/t missing", |f| f.unlink("/truth/t").unwrap(), "/truth/t", SchemaProblem::Missing),
        (
            "reference of the wrong length",
            |f| replace_dataset(f, "/eit/reference", &[0.0; 119], &[119]),
            "/eit/reference",
            SchemaProblem::ColumnMismatch { found: 119, other: "/eit/v".into(), expected: 120 },
        ),
        (
            "infinite time in eit/t",
            |f| replace_dataset(f, "/eit/t", &[0.0, 0.1, 0.2, f64::INFINITY, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9], &[10]),
            "/eit/t",
            SchemaProblem::NonFiniteTimeAt { row: 3, t_s: f64::INFINITY },
        ),
        (
            "pressure/t steps back",
            |f| replace_dataset(f, "/pressure/t", &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.35, 0.8, 0.9], &[10]),
            "/pressure/t",
            SchemaProblem::NotIncreasing { row: 7, t_s: 0.35, previous_s: 0.6 },
        ),
        (
            "truth/t steps back",
            |f| replace_dataset(f, "/truth/t", &[0.5, 0.2], &[2]),
            "/truth/t",
            SchemaProblem::NotIncreasing { row: 1, t_s: 0.2, previous_s: 0.5 },
        ),
        (
            "eit/t ends in rows never written (NaN)",
            |f| replace_dataset(f, "/eit/t", &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, f64::NAN, f64::NAN, f64::NAN], &[10]),
            "/eit/t",
            SchemaProblem::UnwrittenTail { row: 7, last: 9 },
        ),
        (
            "pressure/t ends in zeros (h5py's fill value)",
            |f| replace_dataset(f, "/pressure/t", &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.0, 0.0, 0.0], &[10]),
            "/pressure/t",
            SchemaProblem::ZeroTail { row: 7, last: 9, previous_s: 0.6 },
        ),
        (
            "eit/t holds strings",
            |f| {
                f.unlink("/eit/t").unwrap();
                let s: Vec<VarLenUnicode> = (0..10).map(|_| "x".parse().unwrap()).collect();
                f.new_dataset_builder().with_data(&s).create("/eit/t").unwrap();
            },
            "/eit/t",
            SchemaProblem::NotNumericData { found: "unicode (var len)".into() },
        ),
    ];
    for (i, (what, break_it, path, problem)) in cases.into_iter().enumerate() {
        let file = valid_file(&dir, &format!("case{i}.h5"));
        break_it(&hdf5::File::open_rw(&file).unwrap());
        let err = Recording::open(&file).expect_err(what);
        let msg = err.to_string();
        assert!(msg.starts_with(&format!("{}: {path}: ", file.display())), "{what}: {msg}");
        // The header-only check sees the root attributes (format, version, sensor) the same
        // way, and leaves the streams to `open`.
        match Recording::check_header(&file) {
            Err(e) => assert_eq!((path.starts_with("/ attr"), e.to_string()), (true, msg.clone()), "{what}"),
            Ok(()) => assert!(!path.starts_with("/ attr"), "{what}: the header check passed"),
        }
        match err {
            RecordError::Schema { path: p, problem: got, file: f } => {
                assert_eq!((f, p.as_str(), got), (file.clone(), path, problem), "{what}");
            }
            other => panic!("{what}: expected a schema error, got {other}"),
        }
    }
    // Counters written as doubles (MATLAB) or int64 (h5py) with whole values read as they are.
    let file = valid_file(&dir, "seq-doubles.h5");
    let seq: Vec<f64> = (0..10).map(|i| (i * 3) as f64).collect();
    replace_dataset(&hdf5::File::open_rw(&file).unwrap(), "/eit/seq", &seq, &[10]);
    assert_eq!(Recording::open(&file).unwrap().eit.unwrap().seq, (0..10).map(|i| i * 3).collect::<Vec<u64>>());
    let file = valid_file(&dir, "seq-int64.h5");
    {
        let f = hdf5::File::open_rw(&file).unwrap();
        f.unlink("/eit/seq").unwrap();
        f.new_dataset_builder().with_data(&(5..15).collect::<Vec<i64>>()[..]).create("/eit/seq").unwrap();
    }
    assert_eq!(Recording::open(&file).unwrap().eit.unwrap().seq, (5..15).collect::<Vec<u64>>());
    // A NaN time (NaN != NaN, so checked by its message).
    let file = valid_file(&dir, "nan-time.h5");
    replace_dataset(
        &hdf5::File::open_rw(&file).unwrap(),
        "/eit/t",
        &[0.0, 0.1, 0.2, 0.3, 0.4, f64::NAN, 0.6, 0.7, 0.8, 0.9],
        &[10],
    );
    let msg = Recording::open(&file).unwrap_err().to_string();
    assert_eq!(msg, format!("{}: /eit/t: row 5 is not a finite time (NaN)", file.display()));
    // The sensor's protocol decides M: a 12-electrode sensor has 66 pairwise measurements.
    let file = valid_file(&dir, "sensor12.h5");
    set_str_attr(&hdf5::File::open_rw(&file).unwrap(), "sensor", &sensor_12);
    let msg = Recording::open(&file).unwrap_err().to_string();
    assert_eq!(
        msg,
        format!(
            "{}: /eit/v: width 120 disagrees with the sensor's protocol \"pairwise\" (66 measurements)",
            file.display()
        )
    );
    let file = valid_file(&dir, "badsensor.h5");
    set_str_attr(&hdf5::File::open_rw(&file).unwrap(), "sensor", "[sensor]\nwidth_mm = -1.0\n");
    assert!(matches!(
        Recording::open(&file),
        Err(RecordError::Schema { problem: SchemaProblem::BadSensor { .. }, .. })
    ));
    // No format attribute at all: HDF5, but not a skinflow recording.
    let file = valid_file(&dir, "no-format.h5");
    hdf5::File::open_rw(&file).unwrap().delete_attr("format").unwrap();
    let msg = Recording::open(&file).unwrap_err().to_string();
    assert!(msg.starts_with(&format!("{}: an HDF5 file, but not a skinflow recording", file.display())), "{msg}");
    // It holds the streams all the same: said, as a recording whose root lost its attributes.
    assert!(
        msg.contains(
            "no `format` attribute, yet it holds /eit, /pressure, /truth: a writer that left the root attributes \
             out, or a damaged root header"
        ),
        "{msg}"
    );
    // An HDF5 file with none of them is just not a recording.
    let other = dir.join("other.h5");
    hdf5::File::create(&other).unwrap().create_group("images").unwrap();
    let msg = Recording::open(&other).unwrap_err().to_string();
    assert_eq!(
        msg,
        format!(
            "{}: an HDF5 file, but not a skinflow recording (its root has no `format` attribute; CONTRACTS.md section 2)",
            other.display()
        )
    );
}

#[test]
fn extra_groups_and_attributes_are_ignored() {
    let dir = fresh_dir("extra");
    let file = valid_file(&dir, "extra.h5");
    let before = Recording::open(&file).unwrap();
    let f = hdf5::File::open_rw(&file).unwrap();
    set_str_attr(&f, "operator", "someone");
    f.create_group("calibration").unwrap().new_dataset_builder().with_data(&[1.0, 2.0][..]).create("g").unwrap();
    drop(f);
    let after = Recording::open(&file).unwrap();
    // Debug text compares NaN padding too (NaN != NaN under PartialEq).
    assert!(format!("{before:?}") == format!("{after:?}"), "extra content changed what was read");
}

/// Files written before the logger recorded `/derived/sync` and each force's `dp_kpa` and
/// `flags` still open: those read as absent, everything else as before.
#[test]
fn files_without_sync_or_force_flags_still_open() {
    let dir = fresh_dir("older");
    let path = sync_and_forces_file(&dir, "older.h5", 8);
    let full = Recording::open(&path).unwrap();
    assert_eq!(full.derived.sync.as_ref().unwrap().t_s.len(), 5);
    assert_eq!(full.derived.forces[0].flags.as_ref().unwrap()[0], 8.0);

    let f = hdf5::File::open_rw(&path).unwrap();
    for p in ["/derived/forces/s/dp_kpa", "/derived/forces/s/flags", "/derived/sync"] {
        f.unlink(p).unwrap();
    }
    drop(f);
    let older = Recording::open(&path).unwrap();
    assert!(older.derived.sync.is_none());
    let forces = &older.derived.forces[0];
    assert!(forces.dp_kpa.is_none() && forces.flags.is_none());
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&forces.force_n), bits(&full.derived.forces[0].force_n), "NaN padding included");
    assert_eq!(older.eit, full.eit);
}

/// A `/derived` time dataset (`sync/t`, `forces/NAME/t`) stored as integers is refused, naming
/// it, as `/eit/t` is: before, integer milliseconds there were read as seconds.
#[test]
fn derived_integer_times_are_refused() {
    let dir = fresh_dir("derived-integer-times");
    for (name, t_path) in [("sync.h5", "/derived/sync/t"), ("forces.h5", "/derived/forces/s/t")] {
        let path = sync_and_forces_file(&dir, name, 0);
        Recording::open(&path).unwrap();
        let f = hdf5::File::open_rw(&path).unwrap();
        f.unlink(t_path).unwrap();
        let t_ms: Vec<i64> = (0..5).map(|i| i * 100).collect();
        f.new_dataset_builder().with_data(&t_ms[..]).create(t_path).unwrap();
        drop(f);
        let e = Recording::open(&path).unwrap_err();
        match &e {
            RecordError::Schema { path: at, problem, .. } => {
                assert_eq!(at, t_path);
                assert_eq!(problem, &SchemaProblem::IntegerTimes { found: "int64".into() });
            }
            other => panic!("{t_path}: expected a schema error, got {other}"),
        }
    }
}

/// `inspect` counts the settled frames, the frames without pressure and the forces each guard
/// touched, padding excluded.
#[test]
fn inspect_counts_settled_frames_and_guarded_forces() {
    let dir = fresh_dir("guards");
    let (path, mut w) = sync_and_forces_writer(&dir, "guards.h5");
    for i in 0..6u32 {
        let t = f64::from(i) * 0.1;
        w.append_eit(t, u64::from(i), &[1.0; 120]).unwrap();
        // Frame 5 got no pressure sample: its dP is unknown, it is not settled.
        let lost = i == 5;
        let row = SyncRow {
            dp_kpa: if lost { f64::NAN } else { 1.0 },
            pressure_samples: if lost { 0 } else { 3 },
            pressure_sd_kpa: if lost { f64::NAN } else { 0.01 },
            settled: (2..5).contains(&i),
            no_load: i == 0,
            p0_kpa: 0.0,
            noise_kpa: 0.01,
        };
        w.append_sync(t, &row).unwrap();
        // Frame i has i % 3 contacts; flags: 1 (no load) on the first, 2 | 8 | 128 on the second;
        // frame 5's are placeholders flagged 64 (no pressure) only.
        let forces =
            [ForceRow { force_n: 0.0, dp_kpa: -0.1, flags: 1 }, ForceRow { force_n: 3.0, dp_kpa: 9.0, flags: 138 }];
        let placeholders = [ForceRow { force_n: 0.0, dp_kpa: f64::NAN, flags: 64 }; 2];
        let forces = if lost { &placeholders[..] } else { &forces[..(i % 3) as usize] };
        w.append_forces(0, t, forces).unwrap();
    }
    w.close().unwrap();
    let s = skinflow_record::inspect(&path).unwrap();
    let counts = skinflow_record::SyncCounts { frames: 6, settled: 3, no_load: 1, without_pressure: 1 };
    assert_eq!(s.sync, Some(counts));
    let g = &s.guards[0];
    // Contacts per frame 0,1,2,0,1,2: 6 forces, 3 with bit 1, 1 with bits 2, 8 and 128, 2 with 64.
    assert_eq!((g.strategy.as_str(), g.forces), ("s", 6));
    assert_eq!(g.flagged, [3, 1, 0, 1, 0, 0, 2, 1]);
    let text = s.to_string();
    assert!(text.contains("sync:     6 frames: 3 settled, 1 in the no-load period, 1 without pressure"), "{text}");
    assert!(
        text.contains(
            "guards:   s: 6 forces; 3 no load, 1 above range, 1 location clamped, 2 no pressure, 1 contacts dropped"
        ),
        "{text}"
    );
}
