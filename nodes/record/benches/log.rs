//! Sustained logging throughput: EIT frames of 120 f64 through `RecordingWriter` with deflate,
//! from the first append to a closed file (chunk writes and flushes included). Frames are
//! smooth per-channel levels plus deterministic noise, like ADC data; 4096 distinct frames, more
//! than a chunk, so deflate cannot profit from repeated frames.

use std::path::PathBuf;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{RecordingWriter, WriterOptions};

const FRAMES: usize = 20_000;
const M: usize = 120;

fn frames() -> Vec<Vec<f64>> {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    (0..4096)
        .map(|_| {
            (0..M)
                .map(|j| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    let noise = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                    0.1 + 0.9 * (j as f64 / M as f64) + 1e-4 * noise
                })
                .collect()
        })
        .collect()
}

fn log_eit(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("skinflow-record-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let pool = frames();
    let mut group = c.benchmark_group("log");
    group.sample_size(10);
    group.throughput(Throughput::Elements(FRAMES as u64));
    for level in [0u8, 1, 4] {
        let path: PathBuf = dir.join(format!("bench-deflate{level}.h5"));
        let opts = WriterOptions { deflate_level: level, overwrite: true, ..WriterOptions::new(PAPER_100MM_TOML) };
        group.bench_function(format!("eit_120x{FRAMES}_deflate{level}"), |b| {
            b.iter_batched(
                || RecordingWriter::create(&path, &opts).unwrap(),
                |mut w| {
                    for i in 0..FRAMES {
                        w.append_eit(i as f64 * 1e-3, i as u64, &pool[i % pool.len()]).unwrap();
                    }
                    w.close().unwrap()
                },
                BatchSize::PerIteration,
            )
        });
        let size = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        println!(
            "deflate {level}: file {:.2} MB for {FRAMES} frames ({:.1} B/frame)",
            size as f64 / 1e6,
            size as f64 / FRAMES as f64
        );
    }
    group.finish();
    // Criterion reports wall time, which on a shared machine includes time spent waiting for a
    // core; the logger thread's cost is its CPU time, printed here from /proc (Linux only).
    for level in [1u8, 4] {
        let opts = WriterOptions { deflate_level: level, overwrite: true, ..WriterOptions::new(PAPER_100MM_TOML) };
        let Some(cpu0) = process_cpu_s() else { break };
        let n = 10 * FRAMES;
        let mut w = RecordingWriter::create(dir.join("cpu.h5"), &opts).unwrap();
        for i in 0..n {
            w.append_eit(i as f64 * 1e-3, i as u64, &pool[i % pool.len()]).unwrap();
        }
        w.close().unwrap();
        if let Some(cpu) = process_cpu_s().map(|c| c - cpu0).filter(|c| *c > 0.0) {
            println!(
                "deflate {level}: {n} frames in {cpu:.2} s of CPU time = {:.0} frames per CPU-second",
                n as f64 / cpu
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// User + system CPU time of this process, in seconds (clock ticks of 1/100 s).
fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit(')').next()?.split_whitespace().collect();
    let ticks = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

criterion_group!(benches, log_eit);
criterion_main!(benches);
