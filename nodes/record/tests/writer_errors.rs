//! The writer refuses bad options and bad rows with errors that name the file and the path.

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{RecordError, Recording, RecordingWriter, Streams, SyncRow, TruthContact, WriterOptions};

fn tempdir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-writer_errors-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn invalid_options_are_named() {
    let dir = tempdir("bad-options");
    let base = WriterOptions::new(PAPER_100MM_TOML);
    let cases: Vec<(&str, WriterOptions)> = vec![
        ("sensor_toml", WriterOptions::new("[sensor]\nwidth_mm = 0.0\n")),
        ("flush_interval_s", WriterOptions { flush_interval_s: f64::NAN, ..base.clone() }),
        ("rotate_mb", WriterOptions { rotate_mb: Some(-1.0), ..base.clone() }),
        ("rotate_s", WriterOptions { rotate_s: Some(0.0), ..base.clone() }),
        ("chunk_rows", WriterOptions { chunk_rows: 0, ..base.clone() }),
        ("deflate_level", WriterOptions { deflate_level: 10, ..base.clone() }),
        ("truth_max_contacts", WriterOptions { truth_max_contacts: 0, ..base.clone() }),
        (
            "streams.image_hw",
            WriterOptions { streams: Streams { image_hw: Some([0, 4]), ..Streams::default() }, ..base.clone() },
        ),
        (
            "streams.force_strategies",
            WriterOptions {
                streams: Streams { force_strategies: vec!["a/b".into()], ..Streams::default() },
                ..base.clone()
            },
        ),
    ];
    for (name, opts) in cases {
        match RecordingWriter::create(dir.join("x.h5"), &opts) {
            Err(RecordError::InvalidOption { name: got, .. }) => assert_eq!(got, name),
            Err(other) => panic!("{name}: unexpected error {other}"),
            Ok(_) => panic!("{name}: accepted"),
        }
    }
    assert!(!dir.join("x.h5").exists(), "no file is created for invalid options");
}

#[test]
fn bad_rows_are_refused_and_the_file_stays_valid() {
    let dir = tempdir("bad-rows");
    let path = dir.join("rec.h5");
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { truth: true, pressure: false, ..Streams::default() };
    opts.truth_max_contacts = 2;
    let mut w = RecordingWriter::create(&path, &opts).unwrap();
    let shown = path.display().to_string();
    let e = w.append_eit(0.0, 0, &[0.0; 119]).unwrap_err().to_string();
    assert_eq!(e, format!("{shown}: /eit/v: row has 119 values, expected 120"));
    let e = w.append_pressure(0.0, 1.0).unwrap_err().to_string();
    assert_eq!(e, format!("{shown}: /pressure: stream was not declared in the writer options"));
    let c = TruthContact { x_mm: 0.0, y_mm: 0.0, force_n: 1.0, diameter_mm: 10.0 };
    let e = w.append_truth(0.0, &[c; 3]).unwrap_err();
    assert!(matches!(e, RecordError::TooManyTruthContacts { found: 3, max: 2, .. }));
    assert_eq!(
        e.to_string(),
        format!(
            "{shown}: /truth: row has 3 contacts, more than truth_max_contacts = 2, the columns of the truth \
             arrays, fixed when the file was created (hint: set truth_max_contacts to 3 or more)"
        )
    );
    assert!(w.append_eit(f64::NAN, 0, &[0.0; 120]).unwrap_err().to_string().contains("/eit/t: time NaN is not finite"));
    assert!(w.append_image(0.0, &[]).is_err() && w.append_forces(0, 0.0, &[]).is_err());
    let sync = SyncRow {
        dp_kpa: 0.0,
        pressure_samples: 0,
        pressure_sd_kpa: f64::NAN,
        settled: false,
        no_load: true,
        p0_kpa: f64::NAN,
        noise_kpa: f64::NAN,
    };
    let e = w.append_sync(0.0, &sync).unwrap_err().to_string();
    assert_eq!(e, format!("{shown}: /derived/sync: stream was not declared in the writer options"));
    w.append_eit(0.0, 0, &[0.0; 120]).unwrap();
    w.append_truth(0.0, &[c; 2]).unwrap();
    let stats = w.close().unwrap();
    assert_eq!((stats.eit_rows, stats.truth_rows), (1, 1));
    let rec = Recording::open(&path).unwrap();
    assert_eq!(rec.eit.unwrap().len(), 1);
    assert!(rec.pressure.is_none());
    assert_eq!(rec.truth.unwrap().row(0).contact_count(), 2);
}

#[test]
fn existing_files_are_not_overwritten_unless_asked() {
    let dir = tempdir("overwrite");
    let path = dir.join("rec.h5");
    std::fs::write(&path, b"precious").unwrap();
    let opts = WriterOptions::new(PAPER_100MM_TOML);
    let err = RecordingWriter::create(&path, &opts).err().expect("existing file refused");
    assert!(err.to_string().starts_with(&path.display().to_string()), "{err}");
    assert_eq!(std::fs::read(&path).unwrap(), b"precious");
    let opts = WriterOptions { overwrite: true, ..opts };
    RecordingWriter::create(&path, &opts).unwrap().close().unwrap();
    assert!(Recording::open(&path).unwrap().eit.unwrap().is_empty());
    // A socket (as a FIFO or a device) is never replaced, overwrite or not: the finished
    // recording is renamed over its path. (Made in-process: a child spawned here would hold
    // the other tests' HDF5 file locks while it runs.)
    let sock = dir.join("sock");
    let _listener = std::os::unix::net::UnixListener::bind(&sock).unwrap();
    let err = RecordingWriter::create(&sock, &opts).err().expect("a socket refused");
    assert!(err.to_string().contains("is not a regular file"), "{err}");
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata(&sock).unwrap().file_type().is_socket());
}

#[test]
fn reference_after_swmr_start_is_refused() {
    let dir = tempdir("swmr-reference");
    let path = dir.join("rec.h5");
    let opts = WriterOptions { swmr: true, ..WriterOptions::new(PAPER_100MM_TOML) };
    let mut w = RecordingWriter::create(&path, &opts).unwrap();
    w.set_reference(&[1.0; 120]).unwrap();
    w.append_eit(0.0, 0, &[2.0; 120]).unwrap();
    w.flush().unwrap();
    assert!(matches!(w.set_reference(&[1.0; 120]), Err(RecordError::ReferenceAfterSwmr { .. })));
    w.close().unwrap();
    let rec = Recording::open(&path).unwrap();
    assert_eq!(rec.reference.as_deref(), Some(&[1.0; 120][..]));
}

#[test]
fn writer_moves_to_a_logging_thread_and_recordings_are_shareable() {
    fn send<T: Send>() {}
    fn send_sync<T: Send + Sync>() {}
    send::<RecordingWriter>();
    send_sync::<Recording>();
    let dir = tempdir("thread");
    let path = dir.join("rec.h5");
    let mut w = RecordingWriter::create(&path, &WriterOptions::new(PAPER_100MM_TOML)).unwrap();
    let stats = std::thread::spawn(move || {
        w.append_pressure(0.0, 1.5).unwrap();
        w.close().unwrap()
    })
    .join()
    .unwrap();
    assert_eq!(stats.pressure_rows, 1);
    assert_eq!(Recording::open(&path).unwrap().pressure.unwrap().kpa, [1.5]);
}
