//! Fuzzes the pressure line decoder. The first byte picks how the stream is cut into pieces,
//! the second the decoder's `period_ms` (none, or 1..=127 ms: the loss accounting and the
//! "board slower than period_ms" hint) and whether the stream starts mid-line (the port's
//! input cleared at open), the third its `max_jump_ms` (restart and corruption judgement).
//! Checked: no panic; what `common.rs` checks of every decoder (the same records and counters
//! in pieces and whole, spans, measured periods and hints, `records_lost` never decreasing);
//! only finite pressures at device times >= 0 that the decoder reports for the reader to map;
//! each record spans at most a whole line and its line end; a restart is confirmed by an
//! accepted line; losses are the gaps with a period, the bad lines without; every byte is in
//! an accepted line or discarded, but the `\n` of a `\r\n` after an accepted line.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use skinflow_serial::decode::{Decode, PressureDecoder};

fuzz_target!(|data: &[u8]| {
    let [head, config, jump, bytes @ ..] = data else {
        return;
    };
    let piece = 1 + usize::from(*head);
    let period_ms = (config & 0x7F != 0).then_some(u32::from(config & 0x7F));
    let cleared = config & 0x80 != 0;
    // At least 2 periods (as the node requires), up to the default 10 000 ms.
    let max_jump_ms = (u32::from(*jump) * 40).max(2 * period_ms.unwrap_or(1));

    let new = || PressureDecoder::with_max_jump(period_ms, max_jump_ms).expect("valid params");
    let skip = |d: &mut PressureDecoder| {
        if cleared {
            d.skip_to_record_start();
        }
    };
    let summary = |d: &PressureDecoder| {
        let r = d.record();
        assert!(r.kpa.is_finite() && r.device_t_s >= 0.0);
        assert_eq!(d.device_time_s(), Some(r.device_t_s), "the device time the reader maps");
        (r.device_time_ms, r.device_t_s.to_bits(), r.kpa.to_bits())
    };
    let (d, lines) = common::decode_both_ways(new, skip, bytes, piece, summary);
    for (_, span) in &lines {
        assert!((2..=65).contains(span), "a line of 1..=64 bytes and its line end, not {span}");
    }
    let s = *d.stats();
    assert!(s.counter_resets <= s.frames, "a restart is confirmed by an accepted line");
    // Without a period no gap can be measured: every bad line is a lost sample instead.
    let lost = if period_ms.is_some() { s.lost_frames } else { s.bad_lines };
    assert_eq!(d.records_lost(), lost);
    assert!(period_ms.is_some() || s.lost_frames == 0, "a gap counted without a period");
    assert!(d.rejected_pending() <= s.bad_lines);
    let spans: u64 = lines.iter().map(|(_, span)| *span as u64).sum();
    let unaccounted = (bytes.len() as u64).checked_sub(spans + s.discarded_bytes).expect("bytes counted twice");
    assert!(unaccounted <= s.frames, "{unaccounted} bytes in neither a line nor discarded");
});
