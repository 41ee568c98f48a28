//! Write then read gives back identical data, bit for bit, for every stream.

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{
    ContactRow, ForceRow, Recording, RecordingWriter, Streams, SyncRow, TruthContact, WriterOptions,
};

/// Deterministic "random" f64 bit patterns (xorshift), including awkward values.
struct Bits(u64);

impl Bits {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        match self.0 % 17 {
            0 => -0.0,
            1 => f64::MIN_POSITIVE / 3.0, // subnormal
            2 => f64::MAX,
            _ => f64::from_bits(self.0 & !(0x7ff << 52) | (0x3ff << 52)) - 1.5 + (self.0 % 1000) as f64 * 1e-3,
        }
    }
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn every_stream_reads_back_bit_exact() {
    let dir = tempdir("roundtrip");
    let path = dir.join("rec.h5");
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.graph_toml = Some("[nodes]\n# graph text\n".into());
    opts.created = Some("2026-01-02T03:04:05Z".into());
    opts.chunk_rows = 7; // several full chunks plus a partial one per stream
    opts.truth_max_contacts = 3;
    opts.derived_max_contacts = 2;
    opts.streams = Streams {
        eit: true,
        pressure: true,
        truth: true,
        image_hw: Some([3, 4]),
        contacts: true,
        sync: true,
        force_strategies: vec!["pneumatic-locaware".into(), "eit-nocal".into()],
    };
    let mut w = RecordingWriter::create(&path, &opts).unwrap();
    let mut rng = Bits(0x9e37_79b9_7f4a_7c15);
    let m = w.eit_width();
    assert_eq!(m, 120);
    let reference: Vec<f64> = (0..m).map(|_| rng.next()).collect();
    w.set_reference(&reference).unwrap();
    let (mut eit_t, mut eit_seq, mut eit_v) = (vec![], vec![], vec![]);
    let (mut p_t, mut p_kpa) = (vec![], vec![]);
    let mut truth_rows = vec![];
    let mut images = vec![];
    let (mut force_rows, mut sync_rows) = (vec![], vec![]);
    for i in 0..40u64 {
        // Odd bits, but in time order as the reader requires (|jitter| <= 1 ns, frames 20 ms apart).
        let t = i as f64 * 0.02 + 1e-9 * rng.next().clamp(-1.0, 1.0);
        let frame: Vec<f64> = (0..m).map(|_| rng.next()).collect();
        w.append_eit(t, i * 2, &frame).unwrap();
        eit_t.push(t);
        eit_seq.push(i * 2);
        eit_v.extend_from_slice(&frame);
        for k in 0..3 {
            let (tp, kpa) = (t + k as f64 * 0.005, rng.next());
            w.append_pressure(tp, kpa).unwrap();
            p_t.push(tp);
            p_kpa.push(kpa);
        }
        if i % 4 == 0 {
            let n = (i / 4 % 4) as usize; // 0..=3 contacts, 0 = no contact
            let row: Vec<TruthContact> = (0..n)
                .map(|j| TruthContact {
                    x_mm: j as f64 * 10.0 - 20.0,
                    y_mm: rng.next(),
                    force_n: 1.5,
                    diameter_mm: 10.0,
                })
                .collect();
            w.append_truth(t, &row).unwrap();
            truth_rows.push((t, row));
        }
        let img: Vec<f64> = (0..12).map(|_| rng.next()).collect();
        w.append_image(t, &img).unwrap();
        images.extend_from_slice(&img);
        let contacts = (0..(i % 4)).map(|j| ContactRow { x_mm: j as f64, y_mm: -(j as f64), sum: 2.0, area_mm2: 30.0 });
        w.append_contacts(t, contacts).unwrap();
        let forces = [0.25, 0.5, 0.75].map(|force_n| ForceRow { force_n, dp_kpa: rng.next(), flags: i as u32 % 64 });
        w.append_forces(1, t, &forces[..(i % 4) as usize]).unwrap();
        force_rows.push(forces);
        let row = SyncRow {
            dp_kpa: rng.next(),
            pressure_samples: i as u32,
            pressure_sd_kpa: rng.next(),
            settled: i % 3 == 0,
            no_load: i < 5,
            p0_kpa: rng.next(),
            noise_kpa: rng.next(),
        };
        w.append_sync(t, &row).unwrap();
        sync_rows.push(row);
    }
    let stats = w.close().unwrap();
    assert_eq!((stats.eit_rows, stats.pressure_rows, stats.truth_rows), (40, 120, 10));
    assert_eq!(stats.rows_written, 40 + 120 + 10 + 40 + 40 + 40 + 40);
    // Rows with 3 contacts (i % 4 == 3) lose one contact and one force each: 10 rows x 2.
    assert_eq!(stats.contacts_dropped, 20);

    let rec = Recording::open(&path).unwrap();
    assert_eq!(rec.format_version, 1);
    assert_eq!(rec.sensor_toml, PAPER_100MM_TOML);
    assert_eq!(rec.graph_toml.as_deref(), Some("[nodes]\n# graph text\n"));
    assert_eq!(rec.created.as_deref(), Some("2026-01-02T03:04:05Z"));
    assert!(rec.software_version.as_deref().unwrap().starts_with("skinflow-record "));
    assert_eq!(rec.part, None);
    let eit = rec.eit.as_ref().unwrap();
    assert_eq!((bits(&eit.t_s), &eit.seq, bits(&eit.v)), (bits(&eit_t), &eit_seq, bits(&eit_v)));
    assert_eq!(bits(rec.reference.as_ref().unwrap()), bits(&reference));
    let p = rec.pressure.as_ref().unwrap();
    assert_eq!((bits(&p.t_s), bits(&p.kpa)), (bits(&p_t), bits(&p_kpa)));
    let truth = rec.truth.as_ref().unwrap();
    assert_eq!(truth.max_contacts, 3);
    assert_eq!(truth.len(), truth_rows.len());
    for (i, (t, row)) in truth_rows.iter().enumerate() {
        assert_eq!(truth.t_s[i].to_bits(), t.to_bits());
        let got: Vec<TruthContact> = truth.row(i).contacts().collect();
        assert_eq!(got.len(), row.len());
        for (g, e) in got.iter().zip(row) {
            assert_eq!(
                [g.x_mm, g.y_mm, g.force_n, g.diameter_mm].map(f64::to_bits),
                [e.x_mm, e.y_mm, e.force_n, e.diameter_mm].map(f64::to_bits)
            );
        }
        // Padding is NaN in every column, never 0.
        assert!(truth.row(i).force_n[row.len()..].iter().all(|f| f.is_nan()));
    }
    let image = rec.derived.image.as_ref().unwrap();
    assert_eq!(image.hw, [3, 4]);
    assert_eq!((bits(&image.t_s), bits(&image.pixels)), (bits(&eit_t), bits(&images)));
    let contacts = rec.derived.contacts.as_ref().unwrap();
    assert_eq!(contacts.max_contacts, 2);
    assert_eq!(bits(&contacts.x_mm[..8]), bits(&[f64::NAN, f64::NAN, 0.0, f64::NAN, 0.0, 1.0, 0.0, 1.0]));
    let names: Vec<&str> = rec.derived.forces.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["eit-nocal", "pneumatic-locaware"]);
    let forces = &rec.derived.forces[0];
    assert_eq!(forces.t_s.len(), 40);
    let nan = f64::NAN;
    assert_eq!(bits(&forces.force_n[..8]), bits(&[nan, nan, 0.25, nan, 0.25, 0.5, 0.25, 0.5]));
    let (dp, flags) = (forces.dp_kpa.as_ref().unwrap(), forces.flags.as_ref().unwrap());
    for (i, row) in force_rows.iter().enumerate() {
        let n = (i % 4).min(2);
        for j in 0..2 {
            let (d, f) = (dp[i * 2 + j], flags[i * 2 + j]);
            if j < n {
                assert_eq!((d.to_bits(), f), (row[j].dp_kpa.to_bits(), f64::from(row[j].flags)));
            } else {
                assert!(d.is_nan() && f.is_nan(), "row {i}, column {j}: padding is NaN");
            }
        }
    }
    assert!(rec.derived.forces[1].t_s.is_empty());
    let sync = rec.derived.sync.as_ref().unwrap();
    assert_eq!(bits(&sync.t_s), bits(&eit_t));
    let col = |f: fn(&SyncRow) -> f64| bits(&sync_rows.iter().map(f).collect::<Vec<_>>());
    assert_eq!(bits(&sync.dp_kpa), col(|r| r.dp_kpa));
    assert_eq!(bits(&sync.pressure_samples), col(|r| f64::from(r.pressure_samples)));
    assert_eq!(bits(&sync.pressure_sd_kpa), col(|r| r.pressure_sd_kpa));
    assert_eq!(bits(&sync.p0_kpa), col(|r| r.p0_kpa));
    assert_eq!(bits(&sync.noise_kpa), col(|r| r.noise_kpa));
    assert_eq!(sync.settled, sync_rows.iter().map(|r| r.settled).collect::<Vec<_>>());
    assert_eq!(sync.no_load, sync_rows.iter().map(|r| r.no_load).collect::<Vec<_>>());
}

fn tempdir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-roundtrip-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
