//! Incremental, allocation-free decoders for the three wire protocols (see `PROTOCOLS.md`).
//!
//! Bytes arrive in arbitrary pieces; [`Decode::step`] eats bytes until one record completes
//! and says how many it consumed, [`Decode::record`] then borrows that record from the decoder.
//! [`decode_all`] wraps the loop for callers that take every record of a buffer. Every byte
//! that is not part of an accepted record is counted in [`DecodeStats`], so nothing is dropped
//! silently. Buffers are sized in the constructors; steady-state decoding does not allocate.

mod eit;
mod force;
mod hint;
mod line;
mod period;
mod pressure;

pub use eit::{EitDecoder, EitFrame};
pub use force::{ForceDecoder, ForceReading};
pub use hint::Hint;
pub use period::PeriodMedian;
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
    /// EIT: of `crc_errors`, the candidates whose CRC matches with its two bytes swapped: the
    /// board writes its CRC big-endian (the protocol is little-endian).
    pub crc_byte_swapped: u64,
    /// EIT: candidates cut short, either a new frame header starts inside a CRC-failed candidate
    /// (bytes were dropped) or a partial frame was discarded by [`Decode::reset`] (disconnect).
    pub torn_frames: u64,
    /// Records the device sent that never arrived or were rejected, according to its own
    /// sequence: EIT frame-counter gaps (wrapping u32), pressure time-stamp gaps larger than 1.5
    /// expected periods; plus, at a device restart, the records rejected since the last accepted
    /// one (no later record of the same run places them in a gap).
    pub lost_frames: u64,
    /// Times the device restarted (its sequence or clock went back, see `PROTOCOLS.md`). What it
    /// sent between the last record before and the first after the restart is unknowable and
    /// not counted as lost.
    pub counter_resets: u64,
    /// EIT: headers whose measurement count differs from the configured one.
    pub length_mismatches: u64,
    /// Line protocols: lines that could not be parsed, or exceeded the maximum line length.
    pub bad_lines: u64,
    /// Line protocols: of `bad_lines`, the lines that grew past the maximum length (64 bytes)
    /// without a line end (`\r`, `\n` or `\r\n`), counted when they pass it.
    pub long_lines: u64,
    /// Load cell: of `bad_lines`, the lines of a number in another unit than N (`kgf`, `lbf`,
    /// ...): the gauge is set to another unit.
    pub wrong_unit_lines: u64,
}

/// A configuration error the stream itself proves, e.g. the board sends another frame width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StreamMismatch {
    /// Several consecutive EIT headers carry the same measurement count, not the configured one.
    MeasurementCount { expected: usize, got: usize },
}

/// An incremental decoder of one wire protocol. `Clone` so a reader can decode a read ahead
/// with a copy (`clone_from` reuses the copy's buffers).
pub trait Decode: Clone {
    /// The decoded record, borrowed from the decoder's buffers.
    type Record<'a>
    where
        Self: 'a;

    /// What one record is called in messages to the user ("EIT frame", "pressure line").
    const RECORD_NAME: &'static str;

    /// Whether records carry a device time ([`Decode::device_time_s`]); a reader then decodes
    /// each read ahead to time-stamp the records that arrived together. Default: no.
    const TIMED: bool = false;

    /// Consumes bytes from the front of `bytes` until a record completes or the input ends.
    fn step(&mut self, bytes: &[u8]) -> Step;

    /// The record completed by the last [`Decode::step`] that returned `complete`.
    fn record(&self) -> Self::Record<'_>;

    /// Discards a partially received record (the byte stream was interrupted, e.g. by a
    /// disconnect); a partial EIT frame counts as torn. Sequence tracking is kept, so records
    /// lost during the interruption are counted when the stream resumes.
    fn reset(&mut self);

    /// The stream resumes at an arbitrary byte (the port's input was cleared under a record):
    /// skip to the next record boundary the protocol can recognise. Line protocols drop bytes
    /// up to the next `\n`; framed ones need nothing, their sync bytes and CRC resynchronise
    /// (the default).
    fn skip_to_record_start(&mut self) {}

    /// Counters since construction.
    fn stats(&self) -> &DecodeStats;

    /// A configuration mismatch the stream has proven, if any (default: none detectable).
    fn mismatch(&self) -> Option<StreamMismatch> {
        None
    }

    /// Bytes of the stream from the first byte of the record completed by the last `step` to
    /// its last byte (the last one that step consumed), inclusive; the reader time-stamps a
    /// record by the read that brought its first byte. Default 1: only its end is known.
    fn record_span(&self) -> usize {
        1
    }

    /// The device's record period as its own clock measures it ([`PeriodMedian`]), s, once a
    /// few records arrived; `None` for protocols without a device clock (default).
    fn measured_period_s(&self) -> Option<f64> {
        None
    }

    /// What the counters suggest is misconfigured (a byte order, a unit, line ends, a period
    /// param), for the warnings; default none.
    fn hint(&self) -> Option<Hint> {
        None
    }

    /// The device time of the record completed by the last `step`, seconds on the device's
    /// clock (unwrapped), for protocols whose records carry one (default: none). The reader maps
    /// it onto the host clock to time-stamp records that arrived together (`read::ClockMap`).
    fn device_time_s(&self) -> Option<f64> {
        None
    }

    /// Records the device sent that this decoder could not deliver, as far as the stream proves
    /// it so far; never decreases. Default: `lost_frames` (protocols with a sequence, whose gaps
    /// include the records rejected between two delivered ones).
    fn records_lost(&self) -> u64 {
        self.stats().lost_frames
    }

    /// Records rejected (CRC, torn, unparseable) since the last accepted one and not yet in
    /// [`Decode::records_lost`]: the next record's sequence gap will include them, so they are
    /// lost for good only if the stream ends (or the device restarts) first. Default: none.
    fn rejected_pending(&self) -> u64 {
        0
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
