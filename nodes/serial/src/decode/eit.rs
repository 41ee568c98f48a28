//! EIT board frame decoder: sync hunt, header check, CRC check, counter-gap accounting.
//!
//! The decoder keeps at most one frame's bytes. A failed candidate (wrong measurement count or
//! CRC) is not thrown away whole: its first byte is discarded and the rest is searched again for
//! a sync, so a valid frame that starts inside a torn or garbage candidate is still recovered.
//! Values are f32 volts on the wire, widened to f64; counters and device time are u32 that wrap.
//!
//! A wrap is told from a device restart by [`is_restart`]: both the counter and the clock must
//! step forward by less than half their range (2^31 frames; 2^31 µs, 35.8 min) for the frame to
//! continue the same run.

use super::{Decode, DecodeStats, DiscardRun, Hint, PeriodMedian, Step, StreamMismatch};
use crate::crc16::crc16;
use crate::encode::{EIT_HEADER_LEN, EIT_MAX_MEASUREMENTS, EIT_SYNC, eit_frame_len};
use crate::error::ParamError;

/// Consecutive headers with the same wrong count that prove a misconfigured measurement count.
const MISMATCH_PROOF_RUN: u32 = 3;

/// One decoded EIT frame, borrowed from the decoder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EitFrame<'a> {
    /// Device frame counter (wrapping u32).
    pub counter: u32,
    /// Device time stamp as sent, µs on the board's wrapping u32 clock.
    pub device_time_us: u32,
    /// Device time unwrapped across u32 wraps, seconds since the device's clock zero
    /// (restarts at the raw value when the device restarts).
    pub device_t_s: f64,
    /// Measurements in protocol order, volts (f32 on the wire).
    pub volts: &'a [f64],
    /// This frame is the first after a device restart ([`is_restart`]): its counter does not
    /// continue the previous frame's, so frames cannot be counted across it.
    pub restarted: bool,
}

/// Half the range of the u32 counter and clock: a forward step at least this long is a step back.
const HALF_U32: u32 = 1 << 31;

/// Whether a frame comes from a restarted device rather than continuing the last accepted
/// frame's run, given its counter step `d` and device-time step `dt_us` from that frame (both
/// wrapping u32 differences). A restart: the counter repeats or goes back (`d == 0` or
/// `d >= 2^31`), or the clock goes back (`dt_us >= 2^31` µs) while the counter advances (a
/// board that restarted early in a session can come back with a counter above the last one
/// seen, but its clock restarts from zero). A genuine wrap (counter 0xFFFFFFFD -> 2, clock
/// 0xFFFFFF00 -> 0x100) is a small forward step of both. Cost of the rule: an outage longer than
/// 35.8 min with the board running is taken for a restart (reported as one, not as lost frames).
#[must_use]
pub(crate) fn is_restart(d: u32, dt_us: u32) -> bool {
    d == 0 || d >= HALF_U32 || dt_us >= HALF_U32
}

/// Incremental decoder of EIT frames with a fixed measurement count.
#[derive(Debug)]
pub struct EitDecoder {
    // Configuration
    measurements: usize,
    frame_len: usize,
    // Internal state
    /// Bytes of the current candidate, starting with the sync; capacity `frame_len`.
    buf: Vec<u8>,
    /// Values of the last accepted frame.
    volts: Vec<f64>,
    counter: u32,
    device_time_us: u32,
    device_t_s: f64,
    last_counter: Option<u32>,
    last_time_us: Option<u32>,
    /// Multiples of 2^32 µs added to the device time by unwrapping.
    time_epoch_us: u64,
    /// The last accepted frame followed a device restart.
    restarted: bool,
    /// CRC-failed and torn candidates since the last accepted frame (see
    /// [`Decode::rejected_pending`]).
    rejected: u64,
    /// Last wrong measurement count seen and how many headers in a row carried it.
    wrong_count: Option<(u16, u32)>,
    /// Device time per frame between frames of one run (clock step / counter step).
    period: PeriodMedian,
    run: DiscardRun,
    stats: DecodeStats,
}

/// `clone_from` reuses the buffers (a reader copies its decoder to decode a read ahead, per
/// read, without allocating); every other field is `Copy`, so a new non-`Copy` field fails to
/// compile here instead of being missed.
impl Clone for EitDecoder {
    fn clone(&self) -> Self {
        Self { buf: self.buf.clone(), volts: self.volts.clone(), ..*self }
    }

    fn clone_from(&mut self, source: &Self) {
        let (mut buf, mut volts) = (std::mem::take(&mut self.buf), std::mem::take(&mut self.volts));
        buf.clone_from(&source.buf);
        volts.clone_from(&source.volts);
        *self = Self { buf, volts, ..*source };
    }
}

impl EitDecoder {
    /// A decoder for frames of `measurements` values (120 for the default sensor).
    ///
    /// # Errors
    /// [`ParamError::MeasurementCount`] unless `1 <= measurements <= 65535`.
    pub fn try_new(measurements: usize) -> Result<Self, ParamError> {
        if measurements == 0 || measurements > EIT_MAX_MEASUREMENTS {
            return Err(ParamError::MeasurementCount { got: measurements });
        }
        let frame_len = eit_frame_len(measurements);
        Ok(Self {
            measurements,
            frame_len,
            buf: Vec::with_capacity(frame_len),
            volts: vec![0.0; measurements],
            counter: 0,
            device_time_us: 0,
            device_t_s: 0.0,
            last_counter: None,
            last_time_us: None,
            time_epoch_us: 0,
            restarted: false,
            rejected: 0,
            wrong_count: None,
            period: PeriodMedian::default(),
            run: DiscardRun::default(),
            stats: DecodeStats::default(),
        })
    }

    /// Like [`EitDecoder::try_new`].
    ///
    /// # Panics
    /// If `measurements` is 0 or above 65535.
    #[must_use]
    pub fn new(measurements: usize) -> Self {
        Self::try_new(measurements).expect("EitDecoder::new")
    }

    /// Configured measurement count.
    #[must_use]
    pub fn measurements(&self) -> usize {
        self.measurements
    }

    fn discard(&mut self, n: usize) {
        self.run.discard(&mut self.stats, n);
    }

    fn count_at(&self, p: usize) -> u16 {
        u16::from_le_bytes([self.buf[p + 10], self.buf[p + 11]])
    }

    fn header_at(&self, p: usize) -> bool {
        self.buf[p..p + 2] == EIT_SYNC && usize::from(self.count_at(p)) == self.measurements
    }

    /// Drops the candidate's first byte and everything up to the next possible sync.
    fn rescan(&mut self) {
        let len = self.buf.len();
        let mut p = 1;
        while p < len {
            if self.buf[p] == EIT_SYNC[0] && (p + 1 == len || self.buf[p + 1] == EIT_SYNC[1]) {
                break;
            }
            p += 1;
        }
        self.discard(p);
        self.buf.copy_within(p.., 0);
        self.buf.truncate(len - p);
    }

    fn note_wrong_count(&mut self, got: u16) {
        self.stats.length_mismatches += 1;
        self.wrong_count = match self.wrong_count {
            Some((c, n)) if c == got => Some((c, n.saturating_add(1))),
            _ => Some((got, 1)),
        };
    }

    /// Checks the candidate after it grew; true when a frame was accepted.
    fn settle(&mut self) -> bool {
        loop {
            let len = self.buf.len();
            if len >= EIT_HEADER_LEN && !self.header_at(0) {
                let got = self.count_at(0);
                self.note_wrong_count(got);
                self.rescan();
                continue;
            }
            if len == self.frame_len {
                let crc_at = self.frame_len - 2;
                let sent = u16::from_le_bytes([self.buf[crc_at], self.buf[crc_at + 1]]);
                if crc16(&self.buf[EIT_SYNC.len()..crc_at]) == sent {
                    self.accept();
                    return true;
                }
                // A CRC written big-endian: the frame is rejected (the protocol is little-endian)
                // but counted apart, so the warning can say so. A complete header of the right
                // width inside the candidate means the candidate lost bytes and ran into the
                // next frame; otherwise its bytes were altered.
                if crc16(&self.buf[EIT_SYNC.len()..crc_at]) == sent.swap_bytes() {
                    self.stats.crc_errors += 1;
                    self.stats.crc_byte_swapped += 1;
                } else if (2..=len - EIT_HEADER_LEN).any(|p| self.header_at(p)) {
                    self.stats.torn_frames += 1;
                } else {
                    self.stats.crc_errors += 1;
                }
                self.rejected += 1;
                self.rescan();
                continue;
            }
            return false;
        }
    }

    fn accept(&mut self) {
        let b = &self.buf;
        let counter = u32::from_le_bytes([b[2], b[3], b[4], b[5]]);
        let time_us = u32::from_le_bytes([b[6], b[7], b[8], b[9]]);
        let payload = &b[EIT_HEADER_LEN..EIT_HEADER_LEN + 4 * self.measurements];
        for (v, c) in self.volts.iter_mut().zip(payload.chunks_exact(4)) {
            *v = f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]]));
        }
        self.restarted = false;
        if let (Some(last), Some(last_time)) = (self.last_counter, self.last_time_us) {
            let d = counter.wrapping_sub(last);
            if is_restart(d, time_us.wrapping_sub(last_time)) {
                // Its clock restarted too. The candidates rejected since the last frame belong
                // to the old run, whose gaps can no longer be counted: they are lost as such.
                self.restarted = true;
                self.stats.counter_resets += 1;
                self.stats.lost_frames += self.rejected;
                self.time_epoch_us = 0;
                self.last_time_us = None;
            } else {
                // The gap includes the rejected candidates (they were frames of this run).
                self.stats.lost_frames += u64::from(d - 1);
                self.period.push(f64::from(time_us.wrapping_sub(last_time)) * 1e-6 / f64::from(d));
            }
        }
        self.rejected = 0;
        if let Some(last) = self.last_time_us
            && time_us < last
        {
            self.time_epoch_us += 1 << 32;
        }
        self.last_counter = Some(counter);
        self.last_time_us = Some(time_us);
        self.counter = counter;
        self.device_time_us = time_us;
        self.device_t_s = (self.time_epoch_us + u64::from(time_us)) as f64 * 1e-6;
        self.wrong_count = None;
        self.stats.frames += 1;
        self.run.accept();
        self.buf.clear();
    }
}

impl Decode for EitDecoder {
    type Record<'a> = EitFrame<'a>;

    const RECORD_NAME: &'static str = "EIT frame";
    const TIMED: bool = true;

    fn step(&mut self, bytes: &[u8]) -> Step {
        let mut i = 0;
        while i < bytes.len() {
            match self.buf.len() {
                0 => {
                    let rest = &bytes[i..];
                    match rest.iter().position(|&b| b == EIT_SYNC[0]) {
                        Some(p) => {
                            self.discard(p);
                            self.buf.push(EIT_SYNC[0]);
                            i += p + 1;
                        }
                        None => {
                            self.discard(rest.len());
                            i = bytes.len();
                        }
                    }
                }
                1 => {
                    if bytes[i] == EIT_SYNC[1] {
                        self.buf.push(bytes[i]);
                        i += 1;
                    } else {
                        // Not a sync after all; bytes[i] is looked at again as a sync start.
                        self.buf.clear();
                        self.discard(1);
                    }
                }
                len => {
                    let target = if len < EIT_HEADER_LEN { EIT_HEADER_LEN } else { self.frame_len };
                    let take = (target - len).min(bytes.len() - i);
                    self.buf.extend_from_slice(&bytes[i..i + take]);
                    i += take;
                    if self.settle() {
                        return Step { consumed: i, complete: true };
                    }
                }
            }
        }
        Step { consumed: i, complete: false }
    }

    fn record(&self) -> EitFrame<'_> {
        EitFrame {
            counter: self.counter,
            device_time_us: self.device_time_us,
            device_t_s: self.device_t_s,
            volts: &self.volts,
            restarted: self.restarted,
        }
    }

    fn reset(&mut self) {
        let len = self.buf.len();
        if len >= EIT_SYNC.len() {
            self.stats.torn_frames += 1;
            self.rejected += 1;
        }
        self.discard(len);
        self.buf.clear();
    }

    fn stats(&self) -> &DecodeStats {
        &self.stats
    }

    fn mismatch(&self) -> Option<StreamMismatch> {
        match self.wrong_count {
            Some((got, n)) if n >= MISMATCH_PROOF_RUN => {
                Some(StreamMismatch::MeasurementCount { expected: self.measurements, got: usize::from(got) })
            }
            _ => None,
        }
    }

    fn device_time_s(&self) -> Option<f64> {
        Some(self.device_t_s)
    }

    /// A frame's bytes are contiguous in the stream and end with the step's last byte.
    fn record_span(&self) -> usize {
        self.frame_len
    }

    /// Median device time per frame over frames of one run.
    fn measured_period_s(&self) -> Option<f64> {
        self.period.median_s()
    }

    fn hint(&self) -> Option<Hint> {
        let s = &self.stats;
        (s.crc_byte_swapped > 0).then_some(Hint::CrcByteOrder { swapped: s.crc_byte_swapped, crc_errors: s.crc_errors })
    }

    fn rejected_pending(&self) -> u64 {
        self.rejected
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::decode_all;
    use crate::encode::{eit_frame_len, encode_eit_frame};

    const M: usize = 4;

    fn frame(counter: u32, seed: f64) -> Vec<u8> {
        let mut out = Vec::new();
        let v: Vec<f64> = (0..M).map(|k| seed + 0.25 * k as f64).collect();
        encode_eit_frame(&mut out, counter, counter.wrapping_mul(1000), &v);
        out
    }

    fn decode(d: &mut EitDecoder, bytes: &[u8]) -> Vec<(u32, Vec<f64>)> {
        let mut got = Vec::new();
        decode_all(d, bytes, |f| got.push((f.counter, f.volts.to_vec())));
        got
    }

    #[test]
    fn clean_stream_byte_by_byte() {
        let mut d = EitDecoder::new(M);
        let stream: Vec<u8> = (0..3).flat_map(|c| frame(c, c as f64)).collect();
        let mut got = Vec::new();
        for b in &stream {
            decode_all(&mut d, std::slice::from_ref(b), |f| got.push((f.counter, f.volts[3])));
        }
        assert_eq!(got, vec![(0, 0.75), (1, 1.75), (2, 2.75)]);
        assert_eq!(*d.stats(), DecodeStats { frames: 3, ..DecodeStats::default() });
    }

    #[test]
    fn garbage_with_false_syncs_is_discarded_and_counted() {
        let mut d = EitDecoder::new(M);
        let garbage = [0x00, 0xAA, 0xAA, 0x55, 0x01, 0xAA];
        let mut stream = garbage.to_vec();
        stream.extend(frame(7, 1.0));
        let got = decode(&mut d, &stream);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, 7);
        assert_eq!(d.stats().discarded_bytes, garbage.len() as u64);
        assert_eq!(d.stats().resyncs, 1);
    }

    #[test]
    fn crc_error_drops_frame_and_counts_gap() {
        let mut d = EitDecoder::new(M);
        let mut bad = frame(1, 2.0);
        let n = bad.len();
        bad[n - 1] ^= 0x01;
        let stream: Vec<u8> = [frame(0, 1.0), bad, frame(2, 3.0)].concat();
        let got = decode(&mut d, &stream);
        assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![0, 2]);
        let s = d.stats();
        assert_eq!((s.crc_errors, s.torn_frames, s.lost_frames), (1, 0, 1));
        assert_eq!(s.discarded_bytes, n as u64);
    }

    #[test]
    fn torn_frame_followed_by_full_frame_is_recovered() {
        let mut d = EitDecoder::new(M);
        let torn = &frame(1, 2.0)[..15];
        let stream: Vec<u8> = [frame(0, 1.0), torn.to_vec(), frame(2, 3.0)].concat();
        let got = decode(&mut d, &stream);
        assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![0, 2]);
        assert_eq!(got[1].1, vec![3.0, 3.25, 3.5, 3.75]);
        let s = d.stats();
        assert_eq!((s.crc_errors, s.torn_frames, s.lost_frames), (0, 1, 1));
        assert_eq!(s.discarded_bytes, 15);
    }

    #[test]
    fn wrong_width_is_counted_and_proven_after_three_headers() {
        let mut d = EitDecoder::new(M + 1);
        let stream: Vec<u8> = (0..3).flat_map(|c| frame(c, 0.0)).collect();
        assert!(decode(&mut d, &stream).is_empty());
        assert_eq!(d.stats().length_mismatches, 3);
        assert_eq!(d.mismatch(), Some(StreamMismatch::MeasurementCount { expected: M + 1, got: M }));
    }

    #[test]
    fn counter_wrap_is_not_a_loss_and_restart_is_a_reset() {
        let mut d = EitDecoder::new(M);
        let stream: Vec<u8> = [frame(u32::MAX, 0.0), frame(0, 0.0), frame(3, 0.0), frame(1, 0.0)].concat();
        assert_eq!(decode(&mut d, &stream).len(), 4);
        let s = d.stats();
        assert_eq!((s.lost_frames, s.counter_resets), (2, 1));
    }

    /// Counter and device time of each frame, and whether it followed a restart.
    fn steps(d: &mut EitDecoder, frames: &[(u32, u32)]) -> Vec<(u32, bool)> {
        let mut stream = Vec::new();
        for &(counter, time_us) in frames {
            encode_eit_frame(&mut stream, counter, time_us, &[0.0; M]);
        }
        let mut got = Vec::new();
        decode_all(d, &stream, |f| got.push((f.counter, f.restarted)));
        got
    }

    #[test]
    fn a_wrap_of_counter_and_clock_continues_and_a_step_back_of_either_is_a_restart() {
        // Genuine wrap: 0xFFFFFFFD -> 2 (frames ...FE, ...FF, 0, 1 lost), clock wrapping too.
        let mut d = EitDecoder::new(M);
        let got = steps(&mut d, &[(0xFFFF_FFFD, 0xFFFF_FF00), (2, 0x0010_0000)]);
        assert_eq!(got, vec![(0xFFFF_FFFD, false), (2, false)]);
        assert_eq!((d.stats().lost_frames, d.stats().counter_resets), (4, 0));

        // Counter back (unplug, power cycle): a restart, no loss counted.
        let mut d = EitDecoder::new(M);
        let got = steps(&mut d, &[(100, 77_000_000), (101, 77_769_000), (0, 1_000), (1, 770_000)]);
        assert_eq!(got.iter().map(|g| g.1).collect::<Vec<_>>(), vec![false, false, true, false]);
        assert_eq!((d.stats().lost_frames, d.stats().counter_resets), (0, 1));

        // A board restarted early in a session comes back with a counter above the last one
        // seen, but its clock restarted: a restart, not 3 lost frames.
        let mut d = EitDecoder::new(M);
        let got = steps(&mut d, &[(1, 900_000_000), (5, 3_000_000)]);
        assert_eq!(got, vec![(1, false), (5, true)]);
        assert_eq!((d.stats().lost_frames, d.stats().counter_resets), (0, 1));
        assert!(is_restart(0, 10) && is_restart(u32::MAX, 10) && !is_restart(1 << 30, (1 << 31) - 1));
    }

    #[test]
    fn frames_rejected_before_a_restart_are_lost_and_pending_ones_are_reported() {
        let mut d = EitDecoder::new(M);
        let mut bad = frame(11, 1.0);
        let n = bad.len();
        bad[n - 1] ^= 0x01;
        // 10, a CRC-failed 11, then the board restarts at 0: 11 can be placed in no gap.
        let stream: Vec<u8> = [frame(10, 0.0), bad.clone(), frame(0, 0.0)].concat();
        assert_eq!(decode(&mut d, &stream).len(), 2);
        let s = *d.stats();
        assert_eq!((s.crc_errors, s.lost_frames, s.counter_resets), (1, 1, 1));
        assert_eq!((d.records_lost(), d.rejected_pending()), (1, 0));
        // A CRC failure after the last frame is pending: the next frame's gap will count it.
        decode(&mut d, &bad);
        assert_eq!((d.records_lost(), d.rejected_pending()), (1, 1));
        decode(&mut d, &frame(2, 0.0));
        assert_eq!((d.records_lost(), d.rejected_pending()), (2, 0));
        assert_eq!(d.device_time_s(), Some(2e-3));
    }

    #[test]
    fn device_time_unwraps_across_u32() {
        let mut d = EitDecoder::new(M);
        let mut stream = Vec::new();
        encode_eit_frame(&mut stream, 0, u32::MAX - 9, &[0.0; M]);
        encode_eit_frame(&mut stream, 1, 10, &[0.0; M]);
        let mut t = Vec::new();
        decode_all(&mut d, &stream, |f| t.push(f.device_t_s));
        let expected = ((1u64 << 32) + 10) as f64 * 1e-6;
        assert_eq!(t[1], expected);
    }

    #[test]
    fn reset_mid_frame_counts_torn() {
        let mut d = EitDecoder::new(M);
        let f = frame(0, 0.0);
        assert!(decode(&mut d, &f[..9]).is_empty());
        d.reset();
        assert_eq!(decode(&mut d, &frame(1, 0.0)).len(), 1);
        let s = d.stats();
        assert_eq!((s.torn_frames, s.discarded_bytes, s.frames), (1, 9, 1));
    }

    /// Firmware that writes the CRC big-endian: every frame fails, counted apart and hinted.
    #[test]
    fn a_byte_swapped_crc_is_counted_and_hinted() {
        let mut d = EitDecoder::new(M);
        let mut stream = Vec::new();
        for c in 0..3 {
            let mut f = frame(c, 1.0);
            let n = f.len();
            f.swap(n - 2, n - 1);
            stream.extend(f);
        }
        let mut bad = frame(3, 1.0);
        let n = bad.len();
        bad[n - 1] ^= 0x01;
        stream.extend(bad);
        assert!(decode(&mut d, &stream).is_empty());
        let s = d.stats();
        assert_eq!((s.crc_errors, s.crc_byte_swapped), (4, 3));
        let hint = d.hint().expect("a hint").to_string();
        assert!(hint.starts_with("CRC byte order? 3 of 4 CRC failures"), "{hint}");
        assert_eq!(EitDecoder::new(M).hint(), None);
    }

    /// A big-endian header: its count field reads 0x0400 for M = 4; the mismatch names it.
    #[test]
    fn a_big_endian_count_is_proven_and_reported_as_big_endian() {
        let mut d = EitDecoder::new(M);
        let mut stream = Vec::new();
        for c in 0..3 {
            let mut f = frame(c, 1.0);
            f.swap(10, 11);
            stream.extend(f);
        }
        assert!(decode(&mut d, &stream).is_empty());
        let m = d.mismatch().expect("proven");
        assert_eq!(m, StreamMismatch::MeasurementCount { expected: M, got: 0x0400 });
        assert!(m.to_string().contains("looks big-endian"), "{m}");
    }

    /// Steps are per frame and within a run; a restart keeps the steps measured before it (the
    /// board's period does not change with a restart, and `serial_eit` needs it right then).
    #[test]
    fn the_period_is_measured_per_frame_within_a_run() {
        let mut d = EitDecoder::new(M);
        // 0.1 s per frame, frame 3 lost (a 0.2 s step over 2 frames): 3 steps.
        steps(&mut d, &[0u32, 1, 2, 4].map(|c| (c, c * 100_000)));
        assert_eq!(d.measured_period_s(), None, "3 steps");
        // A restart (no step), then one step in the new run.
        steps(&mut d, &[(0, 5_000), (1, 105_000)]);
        assert_eq!(d.measured_period_s(), None, "4 steps");
        steps(&mut d, &[(2, 205_000)]);
        assert!((d.measured_period_s().unwrap() - 0.1).abs() < 1e-12);
        assert_eq!(d.record_span(), eit_frame_len(M));
    }

    #[test]
    fn invalid_counts_are_rejected() {
        assert_eq!(EitDecoder::try_new(0).unwrap_err(), ParamError::MeasurementCount { got: 0 });
        assert!(EitDecoder::try_new(70_000).is_err());
    }
}
