//! Times before 0: the reader accepts them (the contract allows any monotonic clock), but a
//! replay cannot send them (the engine's clock starts at 0): `Recording::check_replayable`
//! (cheap, first rows only) and `Recording::check_replay_times` refuse them naming the file,
//! the dataset, the row and the value, and how far to shift the clock.

use std::path::{Path, PathBuf};

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{RecordError, Recording, RecordingWriter, Streams, TruthContact, WriterOptions};

fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-clock-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A recording of 5 EIT frames and pressure samples from `eit_t0` and `pressure_t0` (0.1 s
/// apart), and truth rows at `truth_t`.
fn write(path: &Path, eit_t0: f64, pressure_t0: f64, truth_t: &[f64]) {
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { truth: true, ..Streams::default() };
    let mut w = RecordingWriter::create(path, &opts).unwrap();
    for i in 0..5u32 {
        w.append_eit(eit_t0 + f64::from(i) * 0.1, u64::from(i), &[0.5; 120]).unwrap();
        w.append_pressure(pressure_t0 + f64::from(i) * 0.1, 1.0).unwrap();
    }
    let c = TruthContact { x_mm: 0.0, y_mm: 0.0, force_n: 1.0, diameter_mm: 10.0 };
    for &t in truth_t {
        w.append_truth(t, &[c]).unwrap();
    }
    w.close().unwrap();
}

/// The error of both checks, which must agree.
fn refused(path: &Path) -> String {
    let cheap = Recording::check_replayable(path).unwrap_err();
    let rec = Recording::open(path).expect("the reader accepts times before 0");
    let full = rec.check_replay_times().unwrap_err();
    assert!(matches!(cheap, RecordError::NegativeTime { .. }), "{cheap:?}");
    assert_eq!(cheap.to_string(), full.to_string());
    cheap.to_string()
}

#[test]
fn times_before_0_are_refused_for_replay_naming_the_dataset_row_and_value() {
    let dir = tempdir("clock");
    let p = dir.join("eit.h5");
    write(&p, -9.615, 0.0, &[0.5]);
    assert_eq!(
        refused(&p),
        format!(
            "{}: /eit/t[0] = -9.615 s: times before 0 cannot be replayed (the engine's clock starts at 0); shift \
             the recording's clock: add 9.615 s or more to every time dataset (/eit/t, /pressure/t, /truth/t and \
             the /derived ones)",
            p.display()
        )
    );
    // The first dataset in /eit, /pressure, /truth order is named; the shift covers the
    // earliest time of all three.
    let p = dir.join("pressure.h5");
    write(&p, 0.0, -0.25, &[-2.0, 0.1]);
    let e = refused(&p);
    assert!(e.contains(": /pressure/t[0] = -0.25 s: times before 0") && e.contains("add 2 s or more"), "{e}");
    let p = dir.join("truth.h5");
    write(&p, 0.0, 0.0, &[-0.5]);
    assert!(refused(&p).contains(": /truth/t[0] = -0.5 s: "));

    // From 0 on (and without some streams) it replays.
    let p = dir.join("ok.h5");
    write(&p, 0.0, 0.0, &[0.0]);
    Recording::check_replayable(&p).unwrap();
    Recording::open(&p).unwrap().check_replay_times().unwrap();
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { eit: false, ..Streams::default() };
    let empty = dir.join("empty.h5");
    RecordingWriter::create(&empty, &opts).unwrap().close().unwrap();
    Recording::check_replayable(&empty).unwrap();
    // The cheap check is the header check too.
    let e = Recording::check_replayable(dir.join("missing.h5")).unwrap_err();
    assert!(matches!(e, RecordError::Io { .. }), "{e:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
