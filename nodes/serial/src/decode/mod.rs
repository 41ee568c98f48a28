//! Incremental, allocation-free decoders for the three wire protocols (see `PROTOCOLS.md`).
//!
//! Bytes arrive in arbitrary pieces; [`Decode::step`] eats bytes until one record completes
//! and says how many it consumed, [`Decode::record`] then borrows that record from the decoder.
//! [`decode_all`] wraps the loop for callers that take every record of a buffer. Every byte
//! that is not part of an accepted record is counted in [`DecodeStats`], so nothing is dropped
//! silently. Buffers are sized in the constructors; steady-state decoding does not allocate.

mod eit;
mod force;
mod line;
mod pressure;

pub use eit::{EitDecoder, EitFrame};
pub use force::{ForceDecoder, ForceReading};
pub use pressure::{DEFAULT_MAX_JUMP_MS, PressureDecoder, PressureReading};

/// What one [`Decode::step`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Step {
    /// Bytes of the input consumed (all of them unless a record completed earlier).
    pub consumed: usize,
    /// True when a record completed: read it with [`Decode::record`] before the next step.
    pub complete: bool,
}

/// Counters of a decoder since construction. Fields a protocol cannot observe stay 0.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecodeStats {
    /// Records accepted (EIT frames, pressure lines, force lines).
    pub frames: u64,
    /// Bytes that were not part of an accepted record (garbage, rejected candidates, bad lines).
    pub discarded_bytes: u64,
    /// Times the decoder lost lock and hunted for the next record start (runs of discarded bytes).
    pub resyncs: u64,
    /// EIT: complete candidates whose CRC did not match (corrupted on the wire).
    pub crc_errors: u64,
    /// EIT: candidates cut short, either a new frame header starts inside a CRC-failed candidate
    /// (bytes were dropped) or a partial frame was discarded by [`Decode::reset`] (disconnect).
    pub torn_frames: u64,
    /// Records missing according to the device's own sequence: EIT frame-counter gaps
    /// (wrapping u32), pressure time-stamp gaps larger than 1.5 expected periods.
    pub lost_frames: u64,
    /// Times the device sequence went backwards or repeated (device restart); not counted as lost.
    pub counter_resets: u64,
    /// EIT: headers whose measurement count differs from the configured one.
    pub length_mismatches: u64,
    /// Line protocols: lines that could not be parsed, or exceeded the maximum line length.
    pub bad_lines: u64,
}

/// A configuration error the stream itself proves, e.g. the board sends another frame width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StreamMismatch {
    /// Several consecutive EIT headers carry the same measurement count, not the configured one.
    MeasurementCount { expected: usize, got: usize },
}

/// An incremental decoder of one wire protocol.
pub trait Decode {
    /// The decoded record, borrowed from the decoder's buffers.
    type Record<'a>
    where
        Self: 'a;

    /// Consumes bytes from the front of `bytes` until a record completes or the input ends.
    fn step(&mut self, bytes: &[u8]) -> Step;

    /// The record completed by the last [`Decode::step`] that returned `complete`.
    fn record(&self) -> Self::Record<'_>;

    /// Discards a partially received record (the byte stream was interrupted, e.g. by a
    /// disconnect); a partial EIT frame counts as torn. Sequence tracking is kept, so records
    /// lost during the interruption are counted when the stream resumes.
    fn reset(&mut self);

    /// Counters since construction.
    fn stats(&self) -> &DecodeStats;

    /// A configuration mismatch the stream has proven, if any (default: none detectable).
    fn mismatch(&self) -> Option<StreamMismatch> {
        None
    }
}

/// Feeds all of `bytes` to `decoder`, calling `on_record` for each completed record.
pub fn decode_all<D: Decode>(decoder: &mut D, mut bytes: &[u8], mut on_record: impl FnMut(D::Record<'_>)) {
    while !bytes.is_empty() {
        let step = decoder.step(bytes);
        bytes = &bytes[step.consumed..];
        if step.complete {
            on_record(decoder.record());
        }
    }
}

/// Tracks runs of discarded bytes so `resyncs` counts each loss of lock once.
#[derive(Debug, Default, Clone, Copy)]
struct DiscardRun {
    active: bool,
}

impl DiscardRun {
    fn discard(&mut self, stats: &mut DecodeStats, n: usize) {
        if n == 0 {
            return;
        }
        stats.discarded_bytes += n as u64;
        if !self.active {
            self.active = true;
            stats.resyncs += 1;
        }
    }

    fn accept(&mut self) {
        self.active = false;
    }
}
