//! Fuzzes the EIT frame decoder. The first byte picks the measurement count and how the stream
//! is cut into pieces; the stream is the fuzz bytes, then one valid frame, then half the fuzz
//! bytes again. Checked: no panic; what `common.rs` checks of every decoder (the same records
//! and counters in pieces and whole, spans, periods, hints, `records_lost` never decreasing);
//! frames have the configured width, span exactly one frame and carry their device time (what
//! the reader stamps them by); every byte ends up in an accepted frame or in `discarded_bytes`;
//! and the valid frame is recovered unless the fuzz bytes themselves hold a CRC-valid frame that
//! overlaps it (inherent to any sync-based format).
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use skinflow_serial::decode::{Decode, EitDecoder};
use skinflow_serial::encode::{eit_frame_len, encode_eit_frame};

/// Counter of the embedded frame; values are distinctive too.
const MARK: u32 = 0x5EED_F00D;

/// A frame as compared between the two passes (volts as bits: NaN is a valid value).
type Summary = (u32, u32, u64, bool, Vec<u32>);

fn summary(d: &EitDecoder) -> Summary {
    let f = d.record();
    assert_eq!(d.device_time_s(), Some(f.device_t_s), "the device time the reader maps");
    assert!(f.device_t_s.is_finite() && f.device_t_s >= 0.0);
    let volts = f.volts.iter().map(|v| (*v as f32).to_bits()).collect();
    (f.counter, f.device_time_us, f.device_t_s.to_bits(), f.restarted, volts)
}

fuzz_target!(|data: &[u8]| {
    let Some((&head, bytes)) = data.split_first() else {
        return;
    };
    let m = 1 + usize::from(head & 0x0F);
    let piece = 1 + usize::from(head >> 4) * 17;
    let volts: Vec<f64> = (0..m).map(|k| 0.125 * k as f64 - 0.75).collect();
    let mut stream = bytes.to_vec();
    encode_eit_frame(&mut stream, MARK, 42, &volts);
    stream.extend_from_slice(&bytes[..bytes.len() / 2]);

    let (d, frames) = common::decode_both_ways(|| EitDecoder::new(m), |_| {}, &stream, piece, summary);
    let marked: Vec<u32> = volts.iter().map(|v| (*v as f32).to_bits()).collect();
    let found = frames.iter().any(|((counter, us, _, _, v), _)| *counter == MARK && *us == 42 && *v == marked);
    for ((_, _, _, _, v), span) in &frames {
        assert_eq!(v.len(), m);
        assert_eq!(*span, eit_frame_len(m), "a frame spans its own bytes");
    }
    let s = *d.stats();
    assert_eq!(s.frames * eit_frame_len(m) as u64 + s.discarded_bytes, stream.len() as u64);
    assert!(found || !frames.is_empty(), "valid frame lost without any other frame accepted");
});
