//! Fuzzes the pressure line decoder: no panic, only finite pressures, bounded accounting.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinflow_serial::decode::{Decode, PressureDecoder, decode_all};

fuzz_target!(|data: &[u8]| {
    let Some((&head, bytes)) = data.split_first() else {
        return;
    };
    let piece = 1 + usize::from(head);
    let mut d = PressureDecoder::try_new(Some(50)).expect("valid period");
    for chunk in bytes.chunks(piece) {
        decode_all(&mut d, chunk, |r| {
            assert!(r.kpa.is_finite() && r.device_t_s >= 0.0)
        });
    }
    d.reset();
    assert!(d.stats().discarded_bytes <= bytes.len() as u64);
});
