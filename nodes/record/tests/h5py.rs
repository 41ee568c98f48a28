//! A recording written by another tool (h5py, mimicking MATLAB's fixed-length strings and
//! double attributes) reads correctly. The fixture and the script that made it are in
//! tests/fixtures/; expected values repeat the script's float64 arithmetic exactly.

use std::path::PathBuf;

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{Event, NoLoadSource, Recording, Summary};

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/h5py_v1.h5")
}

#[test]
fn attributes_of_every_string_kind_read_back() {
    let rec = Recording::open(fixture()).unwrap();
    assert_eq!(rec.format_version, 1, "float64 1.0 is accepted as version 1");
    // Fixed-length UTF-8, null-padded with 3 extra NULs.
    assert_eq!(rec.sensor_toml, PAPER_100MM_TOML);
    assert_eq!(rec.sensor.name, "paper-100mm");
    // Fixed-length ASCII, space-padded: the padding is not part of the value.
    assert_eq!(rec.created.as_deref(), Some("2025-06-01T10:00:00Z"));
    assert_eq!(rec.graph_toml.as_deref(), Some("# written by h5py\n"));
    assert_eq!(rec.software_version, None);
    assert_eq!(rec.part, None);
}

#[test]
fn streams_read_back_with_type_conversion() {
    let rec = Recording::open(fixture()).unwrap();
    let eit = rec.eit.as_ref().unwrap();
    assert_eq!((eit.len(), eit.width), (50, 120));
    for i in 0..50 {
        assert_eq!(eit.t_s[i], 0.01 * i as f64);
        assert_eq!(eit.seq[i], if i < 20 { i as u64 } else { i as u64 + 3 });
        for j in 0..120 {
            assert_eq!(eit.frame(i)[j], ((i * 120) as f64 + j as f64) * 0.001);
        }
    }
    let reference = rec.reference.as_ref().unwrap();
    assert!(reference.iter().enumerate().all(|(j, r)| *r == j as f64 * -0.5));
    let p = rec.pressure.as_ref().unwrap();
    assert_eq!(p.len(), 100);
    assert!((0..100).all(|j| p.t_s[j] == 0.005 * j as f64 && p.kpa[j] == 0.25 * j as f64));
    let truth = rec.truth.as_ref().unwrap();
    assert_eq!((truth.len(), truth.max_contacts), (5, 1));
    let counts: Vec<usize> = (0..5).map(|i| truth.row(i).contact_count()).collect();
    assert_eq!(counts, [0, 1, 1, 0, 1]);
    let c = truth.row(4).contacts().next().unwrap();
    assert_eq!((c.x_mm, c.y_mm, c.force_n, c.diameter_mm), (-20.0, 30.0, 0.5, 6.0));
    assert!(rec.derived.image.is_none() && rec.derived.forces.is_empty());
}

#[test]
fn no_load_period_ends_at_the_first_truth_row_with_a_contact() {
    let rec = Recording::open(fixture()).unwrap();
    let no_load = rec.no_load(2.0);
    assert_eq!((no_load.end_s, no_load.source), (0.1, NoLoadSource::Truth));
    // EIT frames at 0.00..0.09 s (t < 0.1; 0.01 * 10 == 0.1 exactly) and pressure at 0..0.095 s.
    assert_eq!(rec.no_load_eit_frames(2.0), 0..10);
    assert_eq!(rec.no_load_pressure_samples(2.0), 0..20);
}

#[test]
fn events_are_time_ordered_with_truth_before_pressure_before_eit_at_equal_times() {
    let rec = Recording::open(fixture()).unwrap();
    let events: Vec<Event> = rec.events().collect();
    assert_eq!(events.len(), 50 + 100 + 5);
    assert!(events.windows(2).all(|w| w[0].t_s() <= w[1].t_s()));
    // t = 0: truth row 0, then pressure sample 0, then EIT frame 0.
    assert!(matches!(events[0], Event::Truth { t_s: 0.0, .. }));
    assert!(matches!(events[1], Event::Pressure { t_s: 0.0, kpa: 0.0 }));
    assert!(matches!(events[2], Event::EitFrame { t_s: 0.0, seq: 0, .. }));
    let last_frame = events.iter().rev().find_map(|e| match e {
        Event::EitFrame { seq, v, .. } => Some((*seq, v[119])),
        _ => None,
    });
    assert_eq!(last_frame, Some((52, (49.0 * 120.0 + 119.0) * 0.001)));
}

#[test]
fn inspect_reports_gaps_and_truth_coverage() {
    let rec = Recording::open(fixture()).unwrap();
    let s = Summary::of(&rec);
    let gaps = s.eit_gaps.unwrap();
    assert_eq!((gaps.gaps, gaps.lost_frames, gaps.largest_gap, gaps.non_increasing), (1, 3, 3, 0));
    let truth = s.truth.unwrap();
    assert_eq!((truth.rows, truth.rows_with_contact, truth.eit_frames_covered, truth.eit_frames), (5, 3, 50, 50));
    assert_eq!(s.streams.iter().map(|x| x.rows).collect::<Vec<_>>(), [50, 100, 5]);
    let eit = &s.streams[0];
    assert!((eit.mean_rate_hz.unwrap() - 100.0).abs() < 1e-9);
    assert!((s.duration_s - 0.495).abs() < 1e-12, "pressure ends last, at 0.495 s");
    let text = s.to_string();
    assert!(text.contains("eit gaps: 1 gaps, 3 frames lost, largest 3"), "{text}");
    assert!(text.contains("covers 50/50 EIT frames (100.0 %)"), "{text}");
}
