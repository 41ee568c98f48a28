//! Appending rows between chunk writes allocates nothing: rows go into buffers sized at
//! construction. Counted with a global allocator, in a test binary of its own.

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{ContactRow, ForceRow, RecordingWriter, Streams, SyncRow, TruthContact, WriterOptions};

use skinflow_core::alloc_count::CountingAlloc;

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn appends_between_chunk_writes_do_not_allocate() {
    let dir = std::env::temp_dir().join(format!("skinflow-record-alloc-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.streams = Streams {
        truth: true,
        image_hw: Some([8, 8]),
        contacts: true,
        sync: true,
        force_strategies: vec!["pneumatic-locaware".into()],
        ..Streams::default()
    };
    opts.flush_interval_s = 1e6; // no time-based flush during the count
    let mut w = RecordingWriter::create(dir.join("rec.h5"), &opts).unwrap();
    let frame = [0.25; 120];
    let image = [1.0; 64];
    let truth = [TruthContact { x_mm: 1.0, y_mm: 2.0, force_n: 3.0, diameter_mm: 10.0 }; 2];
    let forces = [1.0, 2.0, 3.0].map(|force_n| ForceRow { force_n, dp_kpa: 0.5, flags: 2 });
    let sync = SyncRow {
        dp_kpa: 1.0,
        pressure_samples: 5,
        pressure_sd_kpa: 0.01,
        settled: true,
        no_load: false,
        p0_kpa: 0.1,
        noise_kpa: 0.005,
    };
    let strategy = w.strategy_index("pneumatic-locaware").unwrap();
    let before = CountingAlloc::total();
    for i in 0..500u64 {
        let t = i as f64 * 0.01;
        w.append_eit(t, i, &frame).unwrap();
        w.append_pressure(t, 1.0).unwrap();
        w.append_truth(t, &truth).unwrap();
        w.append_image(t, &image).unwrap();
        let contacts = (0..3).map(|k| ContactRow { x_mm: k as f64, y_mm: 0.0, sum: 1.0, area_mm2: 20.0 });
        w.append_contacts(t, contacts).unwrap();
        w.append_forces(strategy, t, &forces).unwrap();
        w.append_sync(t, &sync).unwrap();
    }
    let allocations = CountingAlloc::total() - before;
    assert_eq!(allocations, 0, "{allocations} allocations in 3500 appends");
    assert_eq!(w.close().unwrap().rows_written, 3500);
}
