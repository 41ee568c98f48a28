//! Rotation by duration and by size: every row lands in exactly one part, in order, so the
//! parts concatenated equal what was written (no gap, no duplicate at the boundaries), except
//! the truth row in effect when a part starts, which that part starts with (at its own time)
//! besides ending the part before: each part alone gives every frame its truth.

use std::path::{Path, PathBuf};

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::rotate::{find_parts, part_path, recording_files};
use skinflow_record::{ForceRow, Recording, RecordingWriter, Streams, SyncRow, TruthContact, WriterOptions};

fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-rotate-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn frame(i: u64, m: usize) -> Vec<f64> {
    (0..m).map(|j| (i * 1000 + j as u64) as f64 * 0.5).collect()
}

/// Writes `n` EIT frames (t = 10 ms steps), a pressure sample per frame and a truth row
/// every 50 frames, plus a sync row and one force of the first strategy per frame when those
/// streams are declared; returns the parts.
fn write(base: &Path, opts: &WriterOptions, n: u64) -> Vec<PathBuf> {
    let mut w = RecordingWriter::create(base, opts).unwrap();
    w.set_reference(&frame(7, 120)).unwrap();
    for i in 0..n {
        let t = i as f64 * 0.01;
        w.append_eit(t, i, &frame(i, 120)).unwrap();
        w.append_pressure(t, i as f64).unwrap();
        if i % 50 == 0 {
            let c = TruthContact { x_mm: i as f64, y_mm: 0.0, force_n: 1.0, diameter_mm: 10.0 };
            w.append_truth(t, &[c]).unwrap();
        }
        if opts.streams.sync {
            let row = SyncRow {
                dp_kpa: i as f64,
                pressure_samples: 1,
                pressure_sd_kpa: f64::NAN,
                settled: i % 2 == 0,
                no_load: false,
                p0_kpa: 0.0,
                noise_kpa: 0.01,
            };
            w.append_sync(t, &row).unwrap();
        }
        if !opts.streams.force_strategies.is_empty() {
            w.append_forces(0, t, &[ForceRow { force_n: i as f64, dp_kpa: 0.5 * i as f64, flags: (i % 64) as u32 }])
                .unwrap();
        }
    }
    let stats = w.close().unwrap();
    let parts = find_parts(base).unwrap();
    assert_eq!(stats.parts as usize, parts.len());
    assert!(!base.exists(), "with rotation the base path itself is never written");
    parts
}

/// Concatenates the parts and checks them against what `write` wrote: the truth of every part
/// but the first starts with the previous part's last row, dropped from the concatenation; in
/// each part alone, every frame has the truth row written last at or before it.
fn check_concatenation(parts: &[PathBuf], n: u64) {
    let (mut seq, mut p_kpa, mut truth_t) = (vec![], vec![], vec![]);
    let (mut sync_dp, mut settled, mut force_n, mut force_dp, mut flags) = (vec![], vec![], vec![], vec![], vec![]);
    for (k, path) in parts.iter().enumerate() {
        let rec = Recording::open(path).unwrap();
        assert_eq!(rec.part, Some(k as i64 + 1));
        assert_eq!(rec.sensor_toml, PAPER_100MM_TOML);
        assert_eq!(rec.reference.as_deref(), Some(&frame(7, 120)[..]), "reference repeated in every part");
        let eit = rec.eit.as_ref().unwrap();
        assert!(!eit.is_empty(), "part {k} has no frame");
        for (i, &s) in eit.seq.iter().enumerate() {
            assert_eq!(eit.t_s[i], s as f64 * 0.01);
            assert_eq!(eit.frame(i), &frame(s, 120)[..]);
        }
        seq.extend_from_slice(&eit.seq);
        p_kpa.extend_from_slice(&rec.pressure.as_ref().unwrap().kpa);
        let truth = rec.truth.as_ref().unwrap();
        // Rows every 50 frames, contact at x = the frame's index: frame s has row s / 50 * 50,
        // but a row appended after its frame's EIT row (as `write` does) may start the next
        // part, which the part's last frame then lacks.
        for (i, (&s, &t)) in eit.seq.iter().zip(&eit.t_s).enumerate() {
            let row = truth.index_at(t).unwrap_or_else(|| panic!("part {k}: frame {s} has no truth row"));
            let x = truth.row(row).x_mm[0];
            let last_of_part = i + 1 == eit.len() && s % 50 == 0 && x == (s - 50.min(s)) as f64;
            assert!(x == (s / 50 * 50) as f64 || last_of_part, "part {k}: frame {s} has the truth of frame {x}");
        }
        let carried = if k == 0 {
            0
        } else {
            assert_eq!(Some(&truth.t_s[0]), truth_t.last(), "part {k} starts with the row in effect");
            assert!(truth.t_s[0] < eit.t_s[0], "part {k}: the row in effect keeps its time");
            1
        };
        truth_t.extend_from_slice(&truth.t_s[carried..]);
        if let Some(s) = &rec.derived.sync {
            assert_eq!(s.t_s, eit.t_s, "part {k}: a sync row per frame, in the same part");
            sync_dp.extend_from_slice(&s.dp_kpa);
            settled.extend_from_slice(&s.settled);
        }
        if let Some(f) = rec.derived.forces.first() {
            assert_eq!(f.t_s, eit.t_s, "part {k}: a force row per frame, in the same part");
            // One contact per row: column 0 of each row.
            let col0 = |v: &[f64]| v.iter().step_by(f.max_contacts).copied().collect::<Vec<_>>();
            force_n.extend(col0(&f.force_n));
            force_dp.extend(col0(f.dp_kpa.as_ref().unwrap()));
            flags.extend(col0(f.flags.as_ref().unwrap()));
        }
    }
    if !sync_dp.is_empty() {
        assert_eq!(sync_dp, (0..n).map(|i| i as f64).collect::<Vec<_>>());
        assert_eq!(settled, (0..n).map(|i| i % 2 == 0).collect::<Vec<_>>());
    }
    if !force_n.is_empty() {
        assert_eq!(force_n, (0..n).map(|i| i as f64).collect::<Vec<_>>());
        assert_eq!(force_dp, (0..n).map(|i| 0.5 * i as f64).collect::<Vec<_>>());
        assert_eq!(flags, (0..n).map(|i| (i % 64) as f64).collect::<Vec<_>>());
    }
    assert_eq!(seq, (0..n).collect::<Vec<_>>());
    assert_eq!(p_kpa, (0..n).map(|i| i as f64).collect::<Vec<_>>());
    assert_eq!(truth_t, (0..n).step_by(50).map(|i| i as f64 * 0.01).collect::<Vec<_>>());
}

#[test]
fn rotation_by_duration_splits_at_rotate_s() {
    let dir = tempdir("rotate-time");
    let base = dir.join("rec.h5");
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams =
        Streams { truth: true, sync: true, force_strategies: vec!["pneumatic-locaware".into()], ..Streams::default() };
    opts.rotate_s = Some(1.0);
    opts.chunk_rows = 64;
    let parts = write(&base, &opts, 350);
    assert_eq!(parts, (1..=4).map(|i| part_path(&base, i)).collect::<Vec<_>>());
    assert_eq!(recording_files(&base).unwrap(), parts, "the base path resolves to its parts");
    let missing = dir.join("other.h5");
    let err = recording_files(&missing).unwrap_err().to_string();
    assert!(err.starts_with(&missing.display().to_string()), "{err}");
    // Part k starts with the first frame at or after k seconds: 100 frames per part.
    let firsts: Vec<f64> = parts.iter().map(|p| Recording::open(p).unwrap().eit.unwrap().t_s[0]).collect();
    assert_eq!(firsts, [0.0, 1.0, 2.0, 3.0]);
    // `inspect`'s duration is each part's own span: the truth row a part starts with (0.5 s
    // before it, for parts 2 and 3) does not lengthen it.
    let durations: Vec<f64> = parts.iter().map(|p| skinflow_record::inspect(p).unwrap().duration_s).collect();
    for (d, want) in durations.iter().zip([0.99, 0.99, 0.99, 0.49]) {
        assert!((d - want).abs() < 1e-9, "{durations:?}");
    }
    check_concatenation(&parts, 350);
}

#[test]
fn rotation_by_size_keeps_every_row_once() {
    let dir = tempdir("rotate-size");
    let base = dir.join("rec.h5");
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { truth: true, ..Streams::default() };
    opts.rotate_mb = Some(0.2);
    opts.deflate_level = 0; // predictable sizes: 64 frames x 960 B per chunk
    opts.chunk_rows = 64;
    let parts = write(&base, &opts, 1500);
    assert!(parts.len() >= 5, "1.4 MB of frames in 0.2 MB parts gave {} parts", parts.len());
    for p in &parts[..parts.len() - 1] {
        assert!(std::fs::metadata(p).unwrap().len() >= 200_000, "{} is below rotate_mb", p.display());
    }
    check_concatenation(&parts, 1500);
}

#[test]
fn name_at_close_names_each_part_only_when_complete() {
    let dir = tempdir("name-at-close");
    let base = dir.join("rec.h5");
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams { truth: true, ..Streams::default() };
    opts.name_at_close = true;
    // Unrotated: the name appears at close, not before; a writer dropped without closing
    // leaves no file under its name.
    let mut w = RecordingWriter::create(&base, &opts).unwrap();
    w.append_eit(0.0, 0, &frame(0, 120)).unwrap();
    w.flush().unwrap();
    assert!(!base.exists(), "named before it was complete");
    w.close().unwrap();
    assert_eq!(Recording::open(&base).unwrap().eit.unwrap().t_s, [0.0]);
    let dropped = dir.join("dropped.h5");
    let mut w = RecordingWriter::create(&dropped, &opts).unwrap();
    w.append_eit(0.0, 0, &frame(0, 120)).unwrap();
    drop(w);
    assert!(!dropped.exists(), "a writer that never closed named its file");
    // Rotated: every part is named once the writer moves past it, the last at close.
    let rotated = dir.join("rot.h5");
    opts.rotate_s = Some(1.0);
    let parts = write(&rotated, &opts, 350);
    assert_eq!(parts, (1..=4).map(|i| part_path(&rotated, i)).collect::<Vec<_>>());
    check_concatenation(&parts, 350);
}
