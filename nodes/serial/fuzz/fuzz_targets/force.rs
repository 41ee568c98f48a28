//! Fuzzes the load-cell line decoder: no panic, only finite forces, bounded accounting.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinflow_serial::decode::{Decode, ForceDecoder, decode_all};

fuzz_target!(|data: &[u8]| {
    let Some((&head, bytes)) = data.split_first() else {
        return;
    };
    let piece = 1 + usize::from(head);
    let mut d = ForceDecoder::new();
    for chunk in bytes.chunks(piece) {
        decode_all(&mut d, chunk, |r| assert!(r.force_n.is_finite()));
    }
    d.reset();
    assert!(d.stats().discarded_bytes <= bytes.len() as u64);
});
