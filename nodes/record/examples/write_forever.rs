//! Writes EIT frames and pressure samples until killed; used by the crash-safety test.
//!
//! `write_forever PATH [swmr]`: frame i has t = i ms, seq = i and values i * 1000 + j; the
//! pressure sample i has t = i ms and kpa = -i. After every flush it prints
//! `durable <rows>` (rows of both streams in the file) on stdout.

use std::io::Write;
use std::time::Duration;

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{RecordingWriter, WriterOptions};

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: write_forever PATH [swmr]");
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.swmr = args.next().as_deref() == Some("swmr");
    opts.flush_interval_s = 0.2;
    opts.chunk_rows = 512;
    opts.overwrite = true;
    let mut writer = RecordingWriter::create(&path, &opts).expect("create recording");
    let mut frame = vec![0.0; writer.eit_width()];
    let mut flushes = writer.stats().flushes;
    let mut stdout = std::io::stdout();
    for i in 0u64.. {
        let t_s = i as f64 * 1e-3;
        for (j, v) in frame.iter_mut().enumerate() {
            *v = (i * 1000 + j as u64) as f64;
        }
        writer.append_eit(t_s, i, &frame).expect("append eit");
        writer.append_pressure(t_s, -(i as f64)).expect("append pressure");
        let stats = writer.stats();
        if stats.flushes != flushes {
            flushes = stats.flushes;
            writeln!(stdout, "durable {}", stats.rows_written).and_then(|_| stdout.flush()).expect("stdout");
        }
        // About 5000 frames per second: a realistic-to-fast EIT rate, files stay small.
        if i % 10 == 0 {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}
