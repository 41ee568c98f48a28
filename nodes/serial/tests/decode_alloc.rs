//! Zero allocation per record: decoders and the reader's steady state, proven with a counting
//! global allocator that counts only on the thread under test (its own test binary).

mod feeds;

use std::time::{Duration, Instant};

use skinflow_serial::decode::{Decode, EitDecoder, ForceDecoder, PressureDecoder, decode_all};
use skinflow_serial::encode::{encode_eit_frame, encode_force_line, encode_pressure_line};
use skinflow_serial::read::SerialReader;
use skinflow_serial::{Device, Emulator, EmulatorConfig, EmulatorFeed, FaultPlan, Pacing};

use skinflow_core::alloc_count::{CountingAlloc, allocations_in as allocations};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn decoders_and_reader_do_not_allocate_per_record() {
    // The counter sees allocations at all.
    assert_eq!(allocations(|| drop(std::hint::black_box(Vec::<u8>::with_capacity(16)))), 1);

    // Decoders, on streams with garbage, CRC errors and torn frames, fed in small pieces.
    let volts: Vec<f64> = (0..120).map(|k| 1e-3 * k as f64).collect();
    let mut eit_stream = vec![0xAA, 0x55, 0x13];
    let mut lines = b"junk\r\n".to_vec();
    for c in 0..50u32 {
        let start = eit_stream.len();
        encode_eit_frame(&mut eit_stream, c, c * 1000, &volts);
        if c % 7 == 3 {
            eit_stream[start + 40] ^= 0x01;
        }
        if c % 11 == 5 {
            eit_stream.truncate(start + 100);
        }
        encode_pressure_line(&mut lines, c * 50, 1.0);
        encode_force_line(&mut lines, 2.0);
    }
    let mut eit = EitDecoder::new(120);
    let mut pressure = PressureDecoder::try_new(Some(50)).unwrap();
    let mut force = ForceDecoder::new();
    let mut seen = 0usize;
    let n = allocations(|| {
        for chunk in eit_stream.chunks(37) {
            decode_all(&mut eit, chunk, |f| seen += f.volts.len());
        }
        for chunk in lines.chunks(5) {
            decode_all(&mut pressure, chunk, |_| seen += 1);
            decode_all(&mut force, chunk, |_| seen += 1);
        }
    });
    assert_eq!(n, 0, "decoders allocated {n} times");
    assert!(eit.stats().frames > 30 && eit.stats().crc_errors > 0 && seen > 0);

    // Reader steady state through a pty: warm up, then 100 frames with no allocation. The read
    // timeout is long so no timed-out read (whose io::Error allocates) happens while data flows.
    let feed = EmulatorFeed::default().with_eit(feeds::busy_frames(120, 200, 0.01));
    let emulator = Emulator::spawn(
        EmulatorConfig { pacing: Pacing::AsFastAsPossible, ..Default::default() },
        feed,
        FaultPlan::default(),
    )
    .unwrap();
    let mut config = feeds::config(emulator.path(Device::Eit).unwrap());
    config.read_timeout_s = 10.0;
    let mut reader = SerialReader::open(config, EitDecoder::new(120), Instant::now()).unwrap();
    let until = Instant::now() + Duration::from_secs(30);
    let mut counters = Vec::with_capacity(200);
    while counters.len() < 10 {
        if let Some(r) = reader.poll_next(until).unwrap() {
            counters.push(r.record.counter);
        }
    }
    let n = allocations(|| {
        while counters.len() < 110 {
            if let Some(r) = reader.poll_next(until).unwrap() {
                counters.push(r.record.counter);
            }
        }
    });
    assert_eq!(counters, (0..110).collect::<Vec<u32>>());
    assert_eq!(n, 0, "reader allocated {n} times over 100 frames");

    // The same for pressure lines, several per read: the reader decodes each read ahead with a
    // copy of its decoder (for the time stamps), which must reuse its buffers.
    let feed = EmulatorFeed::default().with_pressure(feeds::pressures(400, 0.05));
    let emulator = Emulator::spawn(
        EmulatorConfig { pacing: Pacing::AsFastAsPossible, ..Default::default() },
        feed,
        FaultPlan::default(),
    )
    .unwrap();
    let mut config = feeds::config(emulator.path(Device::Pressure).unwrap());
    config.read_timeout_s = 10.0;
    let mut reader = SerialReader::open(config, PressureDecoder::try_new(Some(50)).unwrap(), Instant::now()).unwrap();
    let mut times = Vec::with_capacity(400);
    while times.len() < 10 {
        if let Some(r) = reader.poll_next(until).unwrap() {
            times.push(r.t_s);
        }
    }
    let n = allocations(|| {
        while times.len() < 310 {
            if let Some(r) = reader.poll_next(until).unwrap() {
                times.push(r.t_s);
            }
        }
    });
    assert_eq!(n, 0, "pressure reader allocated {n} times over 300 lines");
    assert!(times.windows(2).all(|w| w[1] >= w[0]), "stamps never decrease");
}
