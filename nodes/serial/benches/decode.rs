//! Decoder throughput on clean streams: `eit_120x64` decodes 64 frames of 120 measurements
//! (one frame is 494 bytes), `pressure_lines_1000` decodes 1000 pressure lines.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use skinflow_serial::decode::{EitDecoder, PressureDecoder, decode_all};
use skinflow_serial::encode::{encode_eit_frame, encode_pressure_line};

fn eit_120x64(c: &mut Criterion) {
    let volts: Vec<f64> = (0..120).map(|k| 1e-3 * k as f64).collect();
    let mut stream = Vec::new();
    for counter in 0..64u32 {
        encode_eit_frame(&mut stream, counter, counter * 769_000, &volts);
    }
    let mut decoder = EitDecoder::new(120);
    let mut group = c.benchmark_group("decode");
    group.throughput(Throughput::Bytes(stream.len() as u64));
    group.bench_function("eit_120x64", |b| {
        b.iter(|| {
            let mut sum = 0.0;
            decode_all(&mut decoder, black_box(&stream), |f| sum += f.volts[7]);
            black_box(sum)
        });
    });
    group.finish();
}

fn pressure_lines_1000(c: &mut Criterion) {
    let mut stream = Vec::new();
    for k in 0..1000u32 {
        encode_pressure_line(&mut stream, k * 50, 1.0 + 1e-3 * f64::from(k));
    }
    let mut decoder = PressureDecoder::try_new(Some(50)).expect("valid period");
    let mut group = c.benchmark_group("decode");
    group.throughput(Throughput::Bytes(stream.len() as u64));
    group.bench_function("pressure_lines_1000", |b| {
        b.iter(|| {
            let mut sum = 0.0;
            decode_all(&mut decoder, black_box(&stream), |r| sum += r.kpa);
            black_box(sum)
        });
    });
    group.finish();
}

criterion_group!(benches, eit_120x64, pressure_lines_1000);
criterion_main!(benches);
