//! The reader refuses ground truth that would poison calibrate/eval silently: every `/truth`
//! column is either a contact (finite x and y, finite force >= 0 N, finite diameter > 0 mm) or
//! NaN in all four arrays (CONTRACTS.md: a force of 0 is not how "no contact" is written). The
//! error names the file, the dataset holding the bad value, its row and column, and the cause.

use std::path::{Path, PathBuf};

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{RecordError, Recording, RecordingWriter, SchemaProblem, Streams, WriterOptions};

const NAN: f64 = f64::NAN;
const INF: f64 = f64::INFINITY;

/// Truth rows, C = 2 columns.
const ROWS: usize = 3;
const C: usize = 2;

/// `/truth/x_mm`, `/truth/y_mm`, `/truth/force_n`, `/truth/diameter_mm`, row-major [3, 2]: no
/// contact, one contact, two contacts.
#[derive(Clone, Copy)]
struct Truth {
    x: [f64; ROWS * C],
    y: [f64; ROWS * C],
    f: [f64; ROWS * C],
    d: [f64; ROWS * C],
}

const VALID: Truth = Truth {
    x: [NAN, NAN, 10.0, NAN, -20.0, 20.0],
    y: [NAN, NAN, -5.0, NAN, 0.0, 5.0],
    f: [NAN, NAN, 2.0, NAN, 1.0, 3.5],
    d: [NAN, NAN, 10.0, NAN, 12.5, 8.0],
};

/// An empty directory of its own for one test.
fn fresh_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-truth-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn replace_dataset(f: &hdf5::File, path: &str, values: &[f64]) {
    f.unlink(path).unwrap();
    let arr = ndarray::Array2::from_shape_vec((ROWS, C), values.to_vec()).unwrap();
    f.new_dataset_builder().with_data(&arr).create(path).unwrap();
}

/// A recording at `dir/name` whose `/truth` arrays hold `truth` as given (written past the
/// writer, as h5py or MATLAB would).
fn file_with_truth(dir: &Path, name: &str, truth: &Truth) -> PathBuf {
    let path = dir.join(name);
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { truth: true, ..Streams::default() };
    opts.truth_max_contacts = C;
    let mut w = RecordingWriter::create(&path, &opts).unwrap();
    for i in 0..ROWS {
        w.append_truth(i as f64 * 0.5, &[]).unwrap();
    }
    w.close().unwrap();
    let f = hdf5::File::open_rw(&path).unwrap();
    replace_dataset(&f, "/truth/x_mm", &truth.x);
    replace_dataset(&f, "/truth/y_mm", &truth.y);
    replace_dataset(&f, "/truth/force_n", &truth.f);
    replace_dataset(&f, "/truth/diameter_mm", &truth.d);
    path
}

/// `VALID` with cell `[row, column]` of one array set by `edit`.
fn with(edit: impl FnOnce(&mut Truth, usize), row: usize, column: usize) -> Truth {
    let mut t = VALID;
    edit(&mut t, row * C + column);
    t
}

/// Opens a file holding `truth` and returns the error text, panicking when it opens.
fn refused(dir: &Path, name: &str, truth: &Truth) -> (PathBuf, String) {
    let path = file_with_truth(dir, name, truth);
    let err = Recording::open(&path).expect_err(name);
    assert!(matches!(err, RecordError::Schema { .. }), "{name}: {err}");
    (path.clone(), err.to_string())
}

/// The text of a refused contact value: `path` the dataset, `value` and `expected` its rule.
fn bad_contact(file: &Path, path: &str, row: usize, column: usize, value: &str, expected: &str, x: &str) -> String {
    format!(
        "{}: {path}: row {row} column {column}: {value} is not {expected}, but /truth/x_mm holds a contact there \
         (x_mm = {x})",
        file.display()
    )
}

fn without_contact(file: &Path, path: &str, row: usize, column: usize, value: &str) -> String {
    format!(
        "{}: {path}: row {row} column {column}: holds {value} where /truth/x_mm is NaN (no contact); no contact \
         is NaN in every truth array, not 0 or another value",
        file.display()
    )
}

#[test]
fn valid_truth_opens_as_stored() {
    let dir = fresh_dir("valid");
    let path = file_with_truth(&dir, "valid.h5", &VALID);
    let rec = Recording::open(&path).unwrap();
    let truth = rec.require_truth().unwrap();
    assert_eq!((truth.len(), truth.max_contacts), (ROWS, C));
    assert_eq!([0, 1, 2].map(|i| truth.row(i).contact_count()), [0, 1, 2]);
    assert_eq!(truth.force_n[5], 3.5);
}

/// 0 N is a measured force (no contact is NaN, not 0), -0.0 is 0, and positions outside the
/// sensor are left to the callers that know its size.
#[test]
fn zero_force_and_positions_outside_the_sensor_are_accepted() {
    let dir = fresh_dir("edges");
    let mut truth = VALID;
    truth.f[2] = 0.0;
    truth.f[4] = -0.0;
    truth.x[5] = 1.0e6;
    truth.y[5] = -1.0e6;
    let path = file_with_truth(&dir, "edges.h5", &truth);
    let rec = Recording::open(&path).unwrap();
    let contacts: Vec<_> = rec.require_truth().unwrap().row(2).contacts().collect();
    assert_eq!((contacts[1].x_mm, contacts[1].y_mm), (1.0e6, -1.0e6));
}

#[test]
fn infinite_x_is_refused() {
    let dir = fresh_dir("x");
    for (i, (value, text)) in [(INF, "inf"), (-INF, "-inf")].into_iter().enumerate() {
        let (path, msg) = refused(&dir, &format!("x{i}.h5"), &with(|t, c| t.x[c] = value, 2, 0));
        let want = format!(
            "{}: /truth/x_mm: row 2 column 0: {text} is not a finite position (NaN is how no contact is written)",
            path.display()
        );
        assert_eq!(msg, want);
    }
    // An infinity where no contact was is refused too (it is not NaN).
    let (path, msg) = refused(&dir, "x-pad.h5", &with(|t, c| t.x[c] = INF, 1, 1));
    assert!(msg.starts_with(&format!("{}: /truth/x_mm: row 1 column 1: inf is not a finite", path.display())));
    let err = Recording::open(&path).unwrap_err();
    match err {
        RecordError::Schema { problem, .. } => {
            assert_eq!(problem, SchemaProblem::TruthInfiniteX { row: 1, column: 1, x_mm: INF });
        }
        other => panic!("expected a schema error, got {other}"),
    }
}

#[test]
fn contact_y_must_be_finite() {
    let dir = fresh_dir("y");
    for (i, (value, text)) in [(NAN, "NaN"), (INF, "inf"), (-INF, "-inf")].into_iter().enumerate() {
        let (path, msg) = refused(&dir, &format!("y{i}.h5"), &with(|t, c| t.y[c] = value, 1, 0));
        assert_eq!(msg, bad_contact(&path, "/truth/y_mm", 1, 0, text, "a finite position", "10"));
    }
}

#[test]
fn contact_force_must_be_finite_and_not_negative() {
    let dir = fresh_dir("force");
    let cases = [(-0.5, "-0.5"), (NAN, "NaN"), (INF, "inf"), (-INF, "-inf")];
    for (i, (value, text)) in cases.into_iter().enumerate() {
        let (path, msg) = refused(&dir, &format!("f{i}.h5"), &with(|t, c| t.f[c] = value, 2, 1));
        assert_eq!(msg, bad_contact(&path, "/truth/force_n", 2, 1, text, "a finite force >= 0 N", "20"));
    }
    let (path, _) = refused(&dir, "f-typed.h5", &with(|t, c| t.f[c] = -0.5, 2, 1));
    let problem = SchemaProblem::TruthBadContact {
        row: 2,
        column: 1,
        value: -0.5,
        expected: "a finite force >= 0 N",
        x_mm: 20.0,
    };
    assert!(matches!(Recording::open(&path), Err(RecordError::Schema { problem: p, .. }) if p == problem));
}

#[test]
fn contact_diameter_must_be_finite_and_positive() {
    let dir = fresh_dir("diameter");
    let cases = [(0.0, "0"), (-0.0, "-0"), (-3.0, "-3"), (NAN, "NaN"), (INF, "inf")];
    for (i, (value, text)) in cases.into_iter().enumerate() {
        let (path, msg) = refused(&dir, &format!("d{i}.h5"), &with(|t, c| t.d[c] = value, 2, 0));
        assert_eq!(msg, bad_contact(&path, "/truth/diameter_mm", 2, 0, text, "a finite diameter > 0 mm", "-20"));
    }
}

/// Where `x_mm` is NaN (no contact) the other arrays hold NaN: a force of 0, or a value left
/// behind by a writer that blanked only x, is refused in the array that holds it.
#[test]
fn no_contact_is_nan_in_every_array() {
    let dir = fresh_dir("absent");
    type Edit = fn(&mut Truth, usize);
    let cases: [(&str, Edit, &str); 5] = [
        ("/truth/force_n", |t, c| t.f[c] = 0.0, "0"),
        ("/truth/force_n", |t, c| t.f[c] = 2.0, "2"),
        ("/truth/y_mm", |t, c| t.y[c] = -5.0, "-5"),
        ("/truth/y_mm", |t, c| t.y[c] = INF, "inf"),
        ("/truth/diameter_mm", |t, c| t.d[c] = 10.0, "10"),
    ];
    for (i, (dataset, edit, text)) in cases.into_iter().enumerate() {
        // Row 0 (no contact) and the padding column of row 1 (one contact).
        for (row, column) in [(0, 0), (1, 1)] {
            let (path, msg) = refused(&dir, &format!("a{i}-{row}.h5"), &with(edit, row, column));
            assert_eq!(msg, without_contact(&path, dataset, row, column, text));
        }
    }
}

/// Cells are checked in row order, x first then y, force and diameter: the first bad value
/// is the one reported.
#[test]
fn the_first_bad_value_in_row_order_is_reported() {
    let dir = fresh_dir("order");
    let mut truth = VALID;
    truth.d[2] = 0.0; // row 1 column 0
    truth.f[2] = -1.0; // same cell, force comes before diameter
    truth.x[5] = INF; // row 2 column 1, later
    let (path, msg) = refused(&dir, "order.h5", &truth);
    assert_eq!(msg, bad_contact(&path, "/truth/force_n", 1, 0, "-1", "a finite force >= 0 N", "10"));
}

/// The writer refuses the contacts the reader would refuse, naming the dataset, row and column;
/// nothing of the refused row is written and the file stays readable with the rows before it.
#[test]
fn the_writer_refuses_what_the_reader_would() {
    use skinflow_record::TruthContact;
    let dir = fresh_dir("writer");
    let path = dir.join("w.h5");
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { truth: true, ..Streams::default() };
    opts.truth_max_contacts = C;
    let mut w = RecordingWriter::create(&path, &opts).unwrap();
    let good = TruthContact { x_mm: 10.0, y_mm: -5.0, force_n: 2.0, diameter_mm: 10.0 };
    w.append_truth(0.0, &[good]).unwrap();
    let cases = [
        (
            TruthContact { x_mm: NAN, ..good },
            "/truth/x_mm: row 1 column 1: NaN is not a finite position (NaN is how no contact is written)",
        ),
        (TruthContact { y_mm: -INF, ..good }, "/truth/y_mm: row 1 column 1: -inf is not a finite position"),
        (TruthContact { force_n: -0.5, ..good }, "/truth/force_n: row 1 column 1: -0.5 is not a finite force >= 0 N"),
        (TruthContact { diameter_mm: NAN, ..good }, "/truth/diameter_mm: row 1 column 1: NaN is not a finite diameter"),
    ];
    for (bad, want) in cases {
        let e = w.append_truth(0.5, &[good, bad]).unwrap_err().to_string();
        assert!(e.contains(want), "want {want:?} in {e}");
    }
    w.append_truth(1.0, &[good, TruthContact { force_n: 0.0, ..good }]).unwrap();
    w.close().unwrap();
    let truth = Recording::open(&path).unwrap().truth.unwrap();
    assert_eq!(truth.t_s, [0.0, 1.0], "the refused rows were not written");
    let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&truth.force_n), bits(&[2.0, NAN, 2.0, 0.0]));
}
