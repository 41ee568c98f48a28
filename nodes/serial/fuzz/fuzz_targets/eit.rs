//! Fuzzes the EIT frame decoder: the first byte picks the measurement count and how the rest
//! is cut into pieces; the decoder must not panic, frames must have the configured width, and
//! every input byte must end up in an accepted frame or in `discarded_bytes`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinflow_serial::decode::{Decode, EitDecoder, decode_all};
use skinflow_serial::encode::eit_frame_len;

fuzz_target!(|data: &[u8]| {
    let Some((&head, bytes)) = data.split_first() else { return };
    let m = 1 + usize::from(head & 0x0F);
    let piece = 1 + usize::from(head >> 4) * 17;
    let mut d = EitDecoder::new(m);
    let mut frames = 0u64;
    for chunk in bytes.chunks(piece) {
        decode_all(&mut d, chunk, |f| {
            assert_eq!(f.volts.len(), m);
            frames += 1;
        });
    }
    d.reset();
    let s = *d.stats();
    assert_eq!(s.frames, frames);
    assert_eq!(s.frames * eit_frame_len(m) as u64 + s.discarded_bytes, bytes.len() as u64);
});
