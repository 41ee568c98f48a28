//! `repair` salvages a recording whose last flush was cut short: each table is cut to the rows
//! all its datasets hold (without an unwritten tail), nothing else changes, the input is never
//! modified, and a file a cut cannot mend is refused without writing anything.
//!
//! Torn files are made by writing a whole recording and then growing or shrinking single
//! datasets with HDF5, the states a writer stopped between two datasets of a flush leaves.

use std::path::{Path, PathBuf};

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{ForceRow, Recording, RecordingWriter, Streams, TruthContact, WriterOptions, repair};

fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-repair-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const FRAMES: usize = 30;

/// A whole recording: 30 EIT frames, 3 pressure samples per frame, truth every 5 frames, one
/// force strategy; small chunks so every table spans several chunks.
fn write_whole(path: &Path) -> Recording {
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.created = Some("2026-01-02T03:04:05Z".into());
    opts.graph_toml = Some("# the graph\n".into());
    opts.chunk_rows = 8;
    opts.truth_max_contacts = 2;
    opts.derived_max_contacts = 2;
    opts.streams = Streams {
        eit: true,
        pressure: true,
        truth: true,
        force_strategies: vec!["pneumatic-locaware".into()],
        ..Streams::default()
    };
    let mut w = RecordingWriter::create(path, &opts).unwrap();
    let m = w.eit_width();
    for i in 0..FRAMES {
        let t = i as f64 * 0.02;
        let frame: Vec<f64> = (0..m).map(|j| (i * 1000 + j) as f64 * 1e-3).collect();
        w.append_eit(t, i as u64, &frame).unwrap();
        for k in 0..3 {
            w.append_pressure(t + k as f64 * 0.005, 0.1 * (i * 3 + k) as f64).unwrap();
        }
        if i % 5 == 0 {
            let contacts: Vec<TruthContact> = (0..i / 5 % 3)
                .map(|j| TruthContact { x_mm: j as f64 * 20.0, y_mm: -5.0, force_n: 2.0, diameter_mm: 10.0 })
                .collect();
            w.append_truth(t, &contacts).unwrap();
        }
        let force = ForceRow { force_n: i as f64 * 0.1, dp_kpa: 0.5, flags: 0 };
        w.append_forces(0, t, &[force]).unwrap();
    }
    w.close().unwrap();
    Recording::open(path).unwrap()
}

/// Sets the row count of one dataset in place (growing fills with the fill value, NaN).
fn set_rows(path: &Path, dataset: &str, rows: usize) {
    let file = hdf5::File::open_rw(path).unwrap();
    let ds = file.dataset(dataset).unwrap();
    let mut shape = ds.shape();
    shape[0] = rows;
    ds.resize(shape).unwrap();
    file.close().unwrap();
}

/// Writes `values` into rows `start..` of a 2-D dataset, growing it.
fn append_rows(path: &Path, dataset: &str, start: usize, values: &ndarray::Array2<f64>) {
    let file = hdf5::File::open_rw(path).unwrap();
    let ds = file.dataset(dataset).unwrap();
    let width = ds.shape()[1];
    ds.resize([start + values.nrows(), width]).unwrap();
    ds.write_slice(values, (start.., ..)).unwrap();
    file.close().unwrap();
}

/// Equal as read, NaN padding included (`PartialEq` says NaN != NaN); no dump on failure.
fn same<T: std::fmt::Debug + ?Sized>(a: &T, b: &T) -> bool {
    format!("{a:?}") == format!("{b:?}")
}

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap()
}

#[test]
fn torn_tables_are_cut_to_their_common_rows_and_nothing_else_changes() {
    let dir = tempdir("torn");
    let input = dir.join("torn.h5");
    let whole = write_whole(&input);
    let m = whole.eit.as_ref().unwrap().width;
    // /eit: two more frames of values and counters than times (values are written first).
    append_rows(&input, "/eit/v", FRAMES, &ndarray::Array2::from_elem((2, m), 7.0));
    set_rows(&input, "/eit/seq", FRAMES + 2);
    // /pressure: times grown but never written (NaN fill), values written.
    set_rows(&input, "/pressure/t", 3 * FRAMES + 4);
    set_rows(&input, "/pressure/kpa", 3 * FRAMES + 4);
    // Forces: the force column three rows short of its times.
    set_rows(&input, "/derived/forces/pneumatic-locaware/force_n", FRAMES - 3);
    let refused = Recording::open(&input).unwrap_err().to_string();
    assert!(refused.contains("has 32 rows, but /eit/t has 30"), "{refused}");
    let before = bytes(&input);

    let out = dir.join("fixed.h5");
    let report = repair(&input, &out, false).unwrap();
    assert_eq!(bytes(&input), before, "the input is never modified");

    let cut: Vec<(&str, usize, usize)> =
        report.cuts.iter().map(|c| (c.table.as_str(), c.rows_kept, c.unwritten_rows)).collect();
    assert_eq!(
        cut,
        [
            ("/eit/t", FRAMES, 0),
            ("/pressure/t", 3 * FRAMES, 4),
            ("/derived/forces/pneumatic-locaware/t", FRAMES - 3, 0)
        ]
    );
    let eit_rows: Vec<(&str, usize)> = report.cuts[0].rows_before.iter().map(|(p, n)| (p.as_str(), *n)).collect();
    assert_eq!(eit_rows, [("/eit/t", FRAMES), ("/eit/seq", FRAMES + 2), ("/eit/v", FRAMES + 2)]);
    assert!(!report.swmr_mark && report.not_copied.is_empty());

    let fixed = Recording::open(&out).unwrap();
    // Every stream that was whole is unchanged, the cut ones are prefixes of the originals.
    assert!(same(&fixed.eit, &whole.eit) && same(&fixed.pressure, &whole.pressure));
    assert!(same(&fixed.truth, &whole.truth), "truth rows, NaN padding included");
    let (f, w) = (&fixed.derived.forces[0], &whole.derived.forces[0]);
    assert_eq!(f.t_s, w.t_s[..FRAMES - 3]);
    assert!(same(&f.force_n[..], &w.force_n[..2 * (FRAMES - 3)]));
    assert!(same(&f.flags.as_deref(), &Some(&w.flags.as_ref().unwrap()[..2 * (FRAMES - 3)])));
    // Root attributes are carried over.
    assert_eq!(
        (&fixed.sensor_toml, &fixed.created, &fixed.graph_toml, &fixed.software_version),
        (&whole.sensor_toml, &whole.created, &whole.graph_toml, &whole.software_version)
    );
    assert!(same(&report.recording, &fixed));
    let text = report.to_string();
    assert!(
        text.contains("/pressure: rows were /pressure/t 94, /pressure/kpa 94; kept 90 (4 allocated but never written)"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unwritten_eit_frames_at_the_end_are_cut() {
    let dir = tempdir("eit-fill");
    let input = dir.join("rec.h5");
    let whole = write_whole(&input);
    // Times and counters written for 3 more frames, their values allocated but never written.
    for (path, rows) in [("/eit/v", FRAMES + 3), ("/eit/seq", FRAMES + 3)] {
        set_rows(&input, path, rows);
    }
    let file = hdf5::File::open_rw(&input).unwrap();
    let t = file.dataset("/eit/t").unwrap();
    t.resize(FRAMES + 3).unwrap();
    t.write_slice(&[0.6, 0.62, 0.64], FRAMES..).unwrap();
    file.close().unwrap();
    assert!(Recording::open(&input).is_ok(), "same lengths: the reader cannot tell fill from data");

    let out = dir.join("fixed.h5");
    let report = repair(&input, &out, false).unwrap();
    assert_eq!(report.cuts.len(), 1);
    assert_eq!((report.cuts[0].rows_kept, report.cuts[0].unwritten_rows), (FRAMES, 3));
    assert!(same(&Recording::open(&out).unwrap().eit, &whole.eit));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_whole_file_is_copied_unchanged() {
    let dir = tempdir("whole");
    let fixture = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/h5py_v1.h5");
    let out = dir.join("copy.h5");
    let report = repair(&fixture, &out, false).unwrap();
    assert!(report.cuts.is_empty());
    assert!(report.to_string().contains("every table is whole; nothing was cut"));
    // h5py's contiguous datasets, fixed-length strings and double version attribute all survive.
    let (mut a, b) = (Recording::open(&fixture).unwrap(), Recording::open(&out).unwrap());
    a.path = b.path.clone();
    assert!(same(&a, &b), "the copy reads back as the original");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn contiguous_datasets_of_other_writers_are_rewritten_cut() {
    let dir = tempdir("contiguous");
    let input = dir.join("ext.h5");
    {
        let file = hdf5::File::create(&input).unwrap();
        let s = |v: &str| v.parse::<hdf5::types::VarLenUnicode>().unwrap();
        file.new_attr::<hdf5::types::VarLenUnicode>()
            .shape(())
            .create("format")
            .unwrap()
            .write_scalar(&s("skinflow-recording"))
            .unwrap();
        file.new_attr::<f64>().shape(()).create("format_version").unwrap().write_scalar(&1.0).unwrap();
        file.new_attr::<hdf5::types::VarLenUnicode>()
            .shape(())
            .create("sensor")
            .unwrap()
            .write_scalar(&s(PAPER_100MM_TOML))
            .unwrap();
        file.new_attr_builder().with_data(&[1.5f64, 2.5, 3.5]).create("gains").unwrap();
        file.create_group("pressure").unwrap();
        let t: Vec<f64> = (0..10).map(|i| i as f64 * 0.01).collect();
        file.new_dataset_builder().with_data(&t).create("/pressure/t").unwrap();
        file.new_dataset_builder().with_data(&[1i32, 2, 3, 4, 5, 6, 7]).create("/pressure/kpa").unwrap();
        file.close().unwrap();
    }
    assert!(Recording::open(&input).is_err());
    let out = dir.join("fixed.h5");
    let report = repair(&input, &out, false).unwrap();
    assert_eq!(report.cuts[0].rows_kept, 7);
    let fixed = Recording::open(&out).unwrap();
    let p = fixed.pressure.unwrap();
    assert_eq!(p.t_s, [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06]);
    assert_eq!(p.kpa, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    let file = hdf5::File::open(&out).unwrap();
    assert_eq!(file.attr("gains").unwrap().read_raw::<f64>().unwrap(), [1.5, 2.5, 3.5], "extra attributes are kept");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn what_a_cut_cannot_mend_is_refused_and_nothing_is_written() {
    let dir = tempdir("refused");
    let input = dir.join("rec.h5");
    write_whole(&input);
    // A time stepping back in the middle, plus a torn pressure table.
    let file = hdf5::File::open_rw(&input).unwrap();
    file.dataset("/eit/t").unwrap().write_slice(&[5.0], 10..11).unwrap();
    file.close().unwrap();
    set_rows(&input, "/pressure/kpa", 3 * FRAMES - 1);
    let out = dir.join("fixed.h5");
    let err = repair(&input, &out, false).unwrap_err().to_string();
    assert!(err.contains("cannot be repaired: after cutting /pressure/t to 89 rows"), "{err}");
    assert!(err.contains("/eit/t: is not increasing at row 11"), "{err}");
    assert!(!err.contains(".partial"), "the removed staging file is not named: {err}");
    let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, [std::ffi::OsString::from("rec.h5")], "no output and no staging file");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn outputs_are_never_clobbered_and_other_files_are_refused() {
    let dir = tempdir("refuse-paths");
    let input = dir.join("rec.h5");
    write_whole(&input);
    let err = repair(&input, &input, true).unwrap_err().to_string();
    assert!(err.contains("the output is the input file"), "{err}");
    let out = dir.join("out.h5");
    std::fs::write(&out, b"keep me").unwrap();
    let err = repair(&input, &out, false).unwrap_err().to_string();
    assert!(err.contains("exists"), "{err}");
    assert_eq!(std::fs::read(&out).unwrap(), b"keep me");
    repair(&input, &out, true).unwrap();
    assert!(Recording::open(&out).is_ok());

    let other = dir.join("other.h5");
    let file = hdf5::File::create(&other).unwrap();
    file.new_attr::<i64>().shape(()).create("format_version").unwrap().write_scalar(&1).unwrap();
    file.close().unwrap();
    let err = repair(&other, &dir.join("x.h5"), false).unwrap_err().to_string();
    assert!(err.contains("other.h5: an HDF5 file, but not a skinflow recording"), "{err}");
    let err = repair(&dir.join("absent.h5"), &dir.join("y.h5"), false).unwrap_err().to_string();
    assert!(err.contains("absent.h5"), "{err}");
    // A recording without its sensor is refused before anything is written, naming the input.
    let nosensor = dir.join("nosensor.h5");
    let file = hdf5::File::create(&nosensor).unwrap();
    let format: hdf5::types::VarLenUnicode = "skinflow-recording".parse().unwrap();
    file.new_attr::<hdf5::types::VarLenUnicode>().shape(()).create("format").unwrap().write_scalar(&format).unwrap();
    file.new_attr::<i64>().shape(()).create("format_version").unwrap().write_scalar(&1).unwrap();
    file.close().unwrap();
    let err = repair(&nosensor, &dir.join("z.h5"), false).unwrap_err().to_string();
    assert!(err.starts_with(&format!("{}: / attr sensor: is missing", nosensor.display())), "{err}");
    assert!(!dir.join("z.h5").exists() && !err.contains(".partial"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A damaged file (here a chunk B-tree node whose signature is overwritten, as a disk or a
/// transfer may leave it) is refused naming the file, the dataset and HDF5's cause, before
/// anything is written: HDF5's object copy crashes the process on such a file (a segfault, not
/// an error), so `repair` reads every object before it copies one.
#[test]
fn a_damaged_chunk_index_is_refused_naming_the_dataset_and_nothing_is_written() {
    let dir = tempdir("damaged");
    let whole = dir.join("whole.h5");
    write_whole(&whole);
    let clean = bytes(&whole);
    // Version 1 B-tree nodes of chunk indexes: "TREE", then node type 1 (groups use type 0).
    let nodes: Vec<usize> = clean.windows(5).enumerate().filter(|(_, w)| w == b"TREE\x01").map(|(i, _)| i).collect();
    assert!(nodes.len() >= 10, "every dataset of the recording is chunked: {} chunk indexes", nodes.len());
    let datasets = [
        "/eit/t",
        "/eit/seq",
        "/eit/v",
        "/pressure/t",
        "/pressure/kpa",
        "/truth/t",
        "/truth/x_mm",
        "/derived/forces/pneumatic-locaware/t",
        "/derived/forces/pneumatic-locaware/force_n",
    ];
    for (k, at) in nodes.into_iter().enumerate() {
        let input = dir.join(format!("damaged-{k}.h5"));
        let mut damaged = clean.clone();
        damaged[at..at + 4].copy_from_slice(b"XXXX");
        std::fs::write(&input, &damaged).unwrap();
        // The dataset whose index this is: the one HDF5 can no longer read.
        let file = hdf5::File::open(&input).unwrap();
        let broken: Vec<&str> =
            datasets.iter().copied().filter(|p| file.dataset(p).unwrap().read_raw::<f64>().is_err()).collect();
        drop(file);

        let out = dir.join(format!("fixed-{k}.h5"));
        let err = repair(&input, &out, false).unwrap_err().to_string();
        assert!(err.starts_with(&format!("{}: cannot be repaired: /", input.display())), "{err}");
        assert!(err.contains("HDF5 cannot read it (") && err.contains("B-tree signature"), "{err}");
        if let [one] = broken[..] {
            assert!(err.contains(&format!("repaired: {one}: HDF5")), "{one}: {err}");
        }
        assert_eq!(bytes(&input), damaged, "the input is never modified");
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.') || n.starts_with("fixed"))
            .collect();
        assert!(left.is_empty(), "no output and no staging file: {left:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
