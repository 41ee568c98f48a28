//! What every target checks of its decoder, whatever the bytes (included by each target with
//! `#[path]`; not a target of its own).
//!
//! The stream is decoded twice with the decoder's own `step` / `record` loop: cut into pieces
//! and whole. Checked after every step: a step consumes something or completes a record (no
//! livelock); `records_lost` never decreases; a measured period is finite and positive; a hint
//! formats (the warnings print it); each record's `record_span` (what the reader stamps it by,
//! the read of its first byte) lies within the bytes fed so far. And the pieces do not matter:
//! both passes give the same records and the same counters, so a record or a `\r\n` cut
//! across two reads decodes as when it arrives whole.

use skinflow_serial::decode::{Decode, DecodeStats};

/// Feeds `stream` to `d` in pieces of `piece` bytes (whole when `piece >= stream.len()`),
/// checking the per-step properties above; `summary` turns each completed record (read from
/// the decoder) into a comparable value. Returns the records' summaries and spans.
pub fn decode<D: Decode, T>(
    d: &mut D,
    stream: &[u8],
    piece: usize,
    mut summary: impl FnMut(&D) -> T,
) -> Vec<(T, usize)> {
    let mut out = Vec::new();
    let (mut fed, mut lost) = (0usize, d.records_lost());
    for chunk in stream.chunks(piece.max(1)) {
        let mut bytes = chunk;
        while !bytes.is_empty() {
            let step = d.step(bytes);
            assert!(step.consumed <= bytes.len(), "consumed {} of {}", step.consumed, bytes.len());
            assert!(step.consumed > 0 || step.complete, "a step that takes no byte and completes nothing");
            fed += step.consumed;
            bytes = &bytes[step.consumed..];
            if step.complete {
                let span = d.record_span();
                assert!((1..=fed).contains(&span), "record span {span} with {fed} bytes fed");
                out.push((summary(d), span));
            }
            let now = d.records_lost();
            assert!(now >= lost, "records_lost went back from {lost} to {now}");
            lost = now;
            if let Some(p) = d.measured_period_s() {
                assert!(p.is_finite() && p > 0.0, "measured period {p}");
            }
            if let Some(hint) = d.hint() {
                assert!(!hint.to_string().is_empty());
            }
        }
    }
    out
}

/// Decodes `stream` with two fresh decoders from `new`, in pieces of `piece` bytes and whole,
/// and checks they agree (records, spans and counters, after a final `reset`). `start` is
/// applied to each decoder first (e.g. `skip_to_record_start`). Returns the decoder that took
/// the pieces (reset) and its records.
pub fn decode_both_ways<D: Decode, T: PartialEq + std::fmt::Debug>(
    new: impl Fn() -> D,
    start: impl Fn(&mut D),
    stream: &[u8],
    piece: usize,
    summary: impl Fn(&D) -> T,
) -> (D, Vec<(T, usize)>) {
    let (mut pieces, mut whole) = (new(), new());
    start(&mut pieces);
    start(&mut whole);
    let got = decode(&mut pieces, stream, piece, &summary);
    let want = decode(&mut whole, stream, stream.len(), &summary);
    assert_eq!(got, want, "records differ in pieces of {piece} bytes and whole");
    let pending = pieces.rejected_pending();
    assert_eq!(pending, whole.rejected_pending());
    pieces.reset();
    whole.reset();
    let stats: DecodeStats = *pieces.stats();
    assert_eq!(stats, *whole.stats(), "counters differ in pieces of {piece} bytes and whole");
    assert_eq!(stats.frames, got.len() as u64);
    (pieces, got)
}
