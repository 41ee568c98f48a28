//! Property tests of the decoders on bad bytes (fixed seed, regressions file committed if any).
//!
//! Random streams never panic and every byte is accounted for; valid records embedded in
//! garbage and cut into random pieces are all recovered, exactly, in order.

use proptest::prelude::*;
use proptest::test_runner::{Config, FileFailurePersistence, RngSeed};
use skinflow_serial::decode::{Decode, EitDecoder, ForceDecoder, PressureDecoder, decode_all};
use skinflow_serial::encode::{eit_frame_len, encode_eit_frame, encode_force_line, encode_pressure_line};

fn config(cases: u32) -> Config {
    Config {
        cases,
        rng_seed: RngSeed::Fixed(0x5EED_0007),
        // Relative to the package root (cargo test's working directory); commit it if it appears.
        failure_persistence: Some(Box::new(FileFailurePersistence::Direct("proptest-regressions/decode_props.txt"))),
        ..Config::default()
    }
}

/// Garbage rich in sync bytes, line ends and digits, so false starts are common.
fn garbage(max_len: usize) -> impl Strategy<Value = Vec<u8>> {
    let byte = prop_oneof![
        4 => any::<u8>(),
        2 => Just(0xAAu8),
        2 => Just(0x55u8),
        1 => Just(b'\n'),
        1 => prop::sample::select(b"0123456789,.- N\r".to_vec()),
    ];
    prop::collection::vec(byte, 0..max_len)
}

/// Splits `bytes` at the given cut fractions and feeds the pieces one by one.
fn feed_in_pieces<D: Decode>(d: &mut D, bytes: &[u8], cuts: &[f64], mut on: impl FnMut(D::Record<'_>)) {
    let mut at: Vec<usize> = cuts.iter().map(|c| (c * bytes.len() as f64) as usize).collect();
    at.push(0);
    at.push(bytes.len());
    at.sort_unstable();
    for w in at.windows(2) {
        decode_all(d, &bytes[w[0]..w[1]], &mut on);
    }
}

/// Garbage followed by a torn frame of width `m`: a real frame cut after `keep` bytes, the
/// hardest case for resynchronization (its header is valid, its CRC is not).
fn torn_garbage(max_len: usize, m: usize) -> impl Strategy<Value = Vec<u8>> {
    (garbage(max_len), any::<u32>(), 0..eit_frame_len(m)).prop_map(move |(mut junk, counter, keep)| {
        let mut frame = Vec::new();
        encode_eit_frame(&mut frame, counter, counter, &vec![0.5; m]);
        junk.extend_from_slice(&frame[..keep]);
        junk
    })
}

fn cuts() -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(0.0..1.0f64, 0..12)
}

proptest! {
    #![proptest_config(config(512))]

    #[test]
    fn random_bytes_never_panic_and_every_byte_is_accounted(bytes in garbage(2000), pieces in cuts()) {
        let mut eit = EitDecoder::new(6);
        let mut frames = 0u64;
        feed_in_pieces(&mut eit, &bytes, &pieces, |f| {
            assert_eq!(f.volts.len(), 6);
            frames += 1;
        });
        eit.reset();
        let s = *eit.stats();
        prop_assert_eq!(s.frames, frames);
        prop_assert_eq!(s.frames * eit_frame_len(6) as u64 + s.discarded_bytes, bytes.len() as u64);

        let mut pressure = PressureDecoder::try_new(Some(50)).unwrap();
        feed_in_pieces(&mut pressure, &bytes, &pieces, |r| assert!(r.kpa.is_finite()));
        let mut force = ForceDecoder::new();
        feed_in_pieces(&mut force, &bytes, &pieces, |r| assert!(r.force_n.is_finite()));
    }

    #[test]
    fn eit_frames_in_garbage_are_all_recovered(
        chunks in prop::collection::vec((torn_garbage(200, 6), any::<u32>(), any::<u32>(), prop::collection::vec(-1e3f32..1e3, 6)), 1..12),
        tail in garbage(100),
        pieces in cuts(),
    ) {
        let mut stream = Vec::new();
        for (junk, counter, time_us, volts) in &chunks {
            stream.extend_from_slice(junk);
            let v: Vec<f64> = volts.iter().map(|&x| f64::from(x)).collect();
            encode_eit_frame(&mut stream, *counter, *time_us, &v);
        }
        stream.extend_from_slice(&tail);
        let mut d = EitDecoder::new(6);
        let mut got: Vec<(u32, u32, Vec<f64>)> = Vec::new();
        feed_in_pieces(&mut d, &stream, &pieces, |f| got.push((f.counter, f.device_time_us, f.volts.to_vec())));
        // Every embedded frame, in order (garbage could in principle add a CRC-valid frame of its own).
        let mut it = got.iter();
        for (_, counter, time_us, volts) in &chunks {
            let v: Vec<f64> = volts.iter().map(|&x| f64::from(x)).collect();
            prop_assert!(it.any(|g| g.0 == *counter && g.1 == *time_us && g.2 == v), "frame {} not recovered", counter);
        }
    }

    #[test]
    fn pressure_lines_after_garbage_lines_are_all_recovered(
        chunks in prop::collection::vec((garbage(60), 0.0..100.0f64), 1..30),
        pieces in cuts(),
    ) {
        let mut stream = Vec::new();
        for (k, (junk, kpa)) in chunks.iter().enumerate() {
            // Garbage ends in a line end: line protocols resync only there.
            let junk: Vec<u8> = junk.iter().copied().filter(|&b| b != b'\n').collect();
            stream.extend_from_slice(&junk);
            stream.push(b'\n');
            encode_pressure_line(&mut stream, 1000 + 50 * k as u32, *kpa);
        }
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        let mut got = Vec::new();
        feed_in_pieces(&mut d, &stream, &pieces, |r| got.push((r.device_time_ms, r.kpa)));
        let mut it = got.iter();
        for (k, (_, kpa)) in chunks.iter().enumerate() {
            let t = 1000 + 50 * k as u32;
            prop_assert!(it.any(|g| g.0 == t && (g.1 - kpa).abs() <= 0.5e-4 + 1e-9), "line {} not recovered", k);
        }
    }

    #[test]
    fn force_lines_after_garbage_lines_are_all_recovered(
        chunks in prop::collection::vec((garbage(60), -500.0..500.0f64), 1..30),
        pieces in cuts(),
    ) {
        let mut stream = Vec::new();
        for (junk, force_n) in &chunks {
            let junk: Vec<u8> = junk.iter().copied().filter(|&b| b != b'\n').collect();
            stream.extend_from_slice(&junk);
            stream.push(b'\n');
            encode_force_line(&mut stream, *force_n);
        }
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        feed_in_pieces(&mut d, &stream, &pieces, |r| got.push(r.force_n));
        let mut it = got.iter();
        for (k, (_, force_n)) in chunks.iter().enumerate() {
            prop_assert!(it.any(|g| (g - force_n).abs() <= 0.5e-3 + 1e-9), "line {} not recovered", k);
        }
    }
}

proptest! {
    #![proptest_config(config(24))]

    #[test]
    fn full_width_frames_survive_garbage_and_piecewise_delivery(
        junk in torn_garbage(600, 120),
        volts in prop::collection::vec(-10.0f32..10.0, 120),
        pieces in cuts(),
    ) {
        let v: Vec<f64> = volts.iter().map(|&x| f64::from(x)).collect();
        let mut stream = junk.clone();
        for counter in 0..3u32 {
            encode_eit_frame(&mut stream, counter, counter * 769_231, &v);
            stream.extend_from_slice(&junk[..junk.len() / 3]);
        }
        let mut d = EitDecoder::new(120);
        let mut got = Vec::new();
        feed_in_pieces(&mut d, &stream, &pieces, |f| {
            if f.volts == v.as_slice() {
                got.push(f.counter);
            }
        });
        prop_assert_eq!(got, vec![0, 1, 2]);
    }
}
