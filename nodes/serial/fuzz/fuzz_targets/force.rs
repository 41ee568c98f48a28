//! Fuzzes the load-cell line decoder. The first byte picks how the stream is cut into pieces,
//! the line end of an embedded reading (`\r` alone, as a gauge set to CR prints, `\n` or
//! `\r\n`) and whether the stream starts mid-line (the port's input cleared at open:
//! `skip_to_record_start`). The stream is the fuzz bytes, a line end, the reading
//! `   12.345 N`, its line end, then half the fuzz bytes again. Checked: no panic; what
//! `common.rs` checks of every decoder (the same records and counters in pieces and whole, so a
//! `\r\n` cut between two reads is one line end; spans; hints, e.g. another unit;
//! `records_lost` never decreasing); only finite forces; each record spans at most a whole line
//! and its line end; every bad line is a lost reading; every byte is in an accepted line or
//! discarded, but the `\n` of a `\r\n` after an accepted line; and the embedded reading is
//! recovered whatever came before it: a line end always resynchronises.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use skinflow_serial::decode::{Decode, ForceDecoder};

/// The embedded reading, as the emulator prints it.
const READING: &[u8] = b"   12.345 N";

fuzz_target!(|data: &[u8]| {
    let Some((&head, bytes)) = data.split_first() else {
        return;
    };
    let piece = 1 + usize::from(head & 0x1F);
    let end: &[u8] = match (head >> 5) & 0x3 {
        0 | 1 => b"\r",
        2 => b"\n",
        _ => b"\r\n",
    };
    let cleared = head & 0x80 != 0;
    let mut stream = bytes.to_vec();
    for part in [end, READING, end, &bytes[..bytes.len() / 2]] {
        stream.extend_from_slice(part);
    }

    let skip = |d: &mut ForceDecoder| {
        if cleared {
            d.skip_to_record_start();
        }
    };
    let (d, readings) =
        common::decode_both_ways(ForceDecoder::new, skip, &stream, piece, |d| d.record().force_n.to_bits());
    for (bits, span) in &readings {
        assert!(f64::from_bits(*bits).is_finite());
        assert!((2..=65).contains(span), "a line of 1..=64 bytes and its line end, not {span}");
    }
    assert!(readings.iter().any(|(bits, _)| f64::from_bits(*bits) == 12.345), "the embedded reading was lost");
    let s = *d.stats();
    assert_eq!(d.records_lost(), s.bad_lines, "every bad line is a lost reading");
    assert!(s.wrong_unit_lines + s.long_lines <= s.bad_lines);
    // Bytes in accepted lines (their spans) and discarded bytes cover the stream, but for at
    // most one `\n` per accepted line (the second byte of its `\r\n`, in neither).
    let spans: u64 = readings.iter().map(|(_, span)| *span as u64).sum();
    let unaccounted = (stream.len() as u64).checked_sub(spans + s.discarded_bytes).expect("bytes counted twice");
    assert!(unaccounted <= s.frames, "{unaccounted} bytes in neither a line nor discarded");
});
