//! Each record's time stamps: the read that brought its first byte ([`Arrivals`]), and for
//! records with a device time, that time on the host clock ([`ClockMap`]), bounded by the
//! records that arrived with it. Pure (reads and their host times are passed in), so the
//! stamping of a record spread over many reads is tested without a port.

use super::arrival::Arrivals;
use super::stamp::ClockMap;
use crate::decode::Decode;

/// The times of one record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct RecordTimes {
    /// Host time of the read that returned the record's first byte, s.
    pub first_read_s: f64,
    /// When the record was sent as far as the host can tell, s: its device time on the host
    /// clock, or `first_read_s` for records without one.
    pub t_s: f64,
}

/// Stamps the records of one reader's stream (see the module docs).
#[derive(Debug, Clone)]
pub(super) struct RecordTimer<D: Decode> {
    arrivals: Arrivals,
    clock: ClockMap,
    /// For timed decoders: a copy of the decoder that decodes each read ahead (buffers reused).
    shadow: Option<D>,
    /// Per record the current read completes, in order: the tightest offset bound of the
    /// records from it to the end of its device run within the read (see `run_bounds`); `len`
    /// filled, `next` the next record's. Capacity: every record takes at least 2 bytes, and
    /// `run_bounds` needs two slots per record.
    bounds: Box<[f64]>,
    len: usize,
    next: usize,
    /// The decoder's `counter_resets` at the last record stamped: a record that raised it
    /// starts a new device run, which the clock map anchors afresh.
    resets: u64,
}

impl<D: Decode> RecordTimer<D> {
    /// A timer for reads of at most `rx_len` bytes decoded by `decoder`.
    pub(super) fn new(decoder: &D, rx_len: usize) -> Self {
        Self {
            arrivals: Arrivals::new(),
            clock: ClockMap::new(),
            shadow: D::TIMED.then(|| decoder.clone()),
            bounds: vec![0.0; if D::TIMED { rx_len } else { 0 }].into_boxed_slice(),
            len: 0,
            next: 0,
            resets: decoder.stats().counter_resets,
        }
    }

    /// Bytes read so far: the stream position of the next byte read.
    pub(super) fn end(&self) -> u64 {
        self.arrivals.end()
    }

    /// A read returned `bytes` at `read_s`; `decoder` is in its state before decoding them. For
    /// timed decoders the read is decoded ahead with a copy (the real pass finds the same
    /// records: decoding is deterministic). Allocation-free: the copy reuses its buffers.
    pub(super) fn on_read(&mut self, decoder: &D, bytes: &[u8], read_s: f64) {
        let base = self.arrivals.end();
        self.arrivals.push(bytes.len(), read_s);
        self.len = 0;
        self.next = 0;
        let Some(shadow) = self.shadow.as_mut() else { return };
        shadow.clone_from(decoder);
        self.len = run_bounds(shadow, bytes, base, &self.arrivals, &mut self.bounds);
    }

    /// The times of the record `decoder` just completed, whose last byte is at stream position
    /// `end_pos - 1`.
    pub(super) fn stamp(&mut self, decoder: &D, end_pos: u64) -> RecordTimes {
        let first_read_s = self.arrivals.read_time_of(first_pos(end_pos, decoder.record_span()));
        let t_s = match decoder.device_time_s() {
            Some(device_s) => {
                let bound = self.bounds[..self.len].get(self.next).copied().unwrap_or(first_read_s - device_s);
                self.next += 1;
                let resets = decoder.stats().counter_resets;
                let new_run = resets > self.resets;
                self.resets = resets;
                self.clock.stamp(first_read_s, device_s, bound, new_run)
            }
            None => first_read_s,
        };
        RecordTimes { first_read_s, t_s }
    }
}

/// Stream position of the first byte of a record of `span` bytes ending before `end_pos`.
fn first_pos(end_pos: u64, span: usize) -> u64 {
    end_pos.saturating_sub(span.max(1) as u64)
}

/// Decodes `bytes` (starting at stream position `base`) with `decoder` and writes to `bounds`,
/// for each record completed (up to `bounds.len()`), the tightest offset bound
/// `first-byte read time - device time` of the records from it to the last of `bytes` in the
/// same device run (the run ends where the decoder counts a restart or device time goes back).
/// Returns how many were written.
fn run_bounds<D: Decode>(decoder: &mut D, bytes: &[u8], base: u64, arrivals: &Arrivals, bounds: &mut [f64]) -> usize {
    // First pass: (device time, own bound) per record, in pairs; runs are closed backwards.
    let mut len = 0;
    let mut at = 0usize;
    let mut rest = bytes;
    while !rest.is_empty() {
        let resets = decoder.stats().counter_resets;
        let step = decoder.step(rest);
        rest = &rest[step.consumed..];
        at += step.consumed;
        if step.complete
            && let Some(device_s) = decoder.device_time_s()
            && 2 * len + 1 < bounds.len()
        {
            let first = first_pos(base + at as u64, decoder.record_span());
            // The first record of a new run is noted at device time -inf, so that no record
            // before it counts as its run (the backward pass compares device times).
            let new_run = decoder.stats().counter_resets > resets;
            bounds[2 * len] = if new_run { f64::NEG_INFINITY } else { device_s };
            bounds[2 * len + 1] = arrivals.read_time_of(first) - device_s;
            len += 1;
        }
    }
    // Backwards: each record's bound becomes the smallest of its run from it on.
    let (mut next_device, mut next_bound) = (f64::NAN, f64::NAN);
    for k in (0..len).rev() {
        let (device_s, own) = (bounds[2 * k], bounds[2 * k + 1]);
        let same_run = next_device > f64::NEG_INFINITY && next_device >= device_s;
        let bound = if same_run { own.min(next_bound) } else { own };
        bounds[2 * k + 1] = bound;
        (next_device, next_bound) = (device_s, bound);
    }
    // Compact to one bound per record.
    for k in 0..len {
        bounds[k] = bounds[2 * k + 1];
    }
    len
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::{EitDecoder, PressureDecoder, decode_all};
    use crate::encode::{encode_eit_frame, encode_pressure_line};

    /// What `SerialReader::poll_next` does with `reads` (bytes and the host time each read
    /// returned): every record with its completing read's time and its [`RecordTimes`].
    fn stamp_reads<D: Decode>(decoder: &mut D, reads: &[(Vec<u8>, f64)]) -> Vec<(f64, RecordTimes)> {
        let mut timer = RecordTimer::new(decoder, 4096);
        let mut out = Vec::new();
        for (bytes, read_s) in reads {
            let base = timer.end();
            timer.on_read(decoder, bytes, *read_s);
            let mut at = 0;
            while at < bytes.len() {
                let step = decoder.step(&bytes[at..]);
                at += step.consumed;
                if step.complete {
                    out.push((*read_s, timer.stamp(decoder, base + at as u64)));
                }
            }
        }
        out
    }

    /// `bytes` as a UART bridge delivers them at `baud` (10 bits per byte): `piece` bytes per
    /// read, each read returning `latency_s` after its last byte arrived, the first byte sent at
    /// host time `sent_s`.
    fn on_the_wire(bytes: &[u8], sent_s: f64, baud: f64, piece: usize, latency_s: f64) -> Vec<(Vec<u8>, f64)> {
        let byte_s = 10.0 / baud;
        let mut reads = Vec::new();
        for (k, chunk) in bytes.chunks(piece).enumerate() {
            let last_byte = k * piece + chunk.len();
            reads.push((chunk.to_vec(), sent_s + last_byte as f64 * byte_s + latency_s));
        }
        reads
    }

    /// The reviewer's case: 494-byte EIT frames at 9600 baud take 0.51 s on the wire. Each is
    /// stamped by the read of its first byte, not ~0.5 s later at the read that completed it.
    #[test]
    fn a_frame_slow_on_the_wire_is_stamped_by_the_read_of_its_first_byte() {
        let (period_s, offset_s, baud, piece, latency_s) = (0.769, 100.0, 9600.0, 16, 0.004);
        let mut reads = Vec::new();
        for k in 0..4u32 {
            let device_s = period_s * f64::from(k);
            let mut frame = Vec::new();
            encode_eit_frame(&mut frame, k, (device_s * 1e6).round() as u32, &[0.5; 120]);
            reads.extend(on_the_wire(&frame, offset_s + device_s, baud, piece, latency_s));
        }
        let got = stamp_reads(&mut EitDecoder::new(120), &reads);
        assert_eq!(got.len(), 4);
        let first_read = 16.0 * 10.0 / baud + latency_s;
        for (k, (host_t_s, times)) in got.iter().enumerate() {
            let sent = offset_s + period_s * k as f64;
            // Late by one piece's wire time and the bridge's latency (20.7 ms), not 0.51 s.
            assert!((times.first_read_s - (sent + first_read)).abs() < 1e-9, "frame {k}: {times:?}");
            assert!((times.t_s - (sent + first_read)).abs() < 1e-9, "frame {k}: {times:?}");
            assert!(host_t_s - times.t_s > 0.49, "frame {k} completes 0.49 s after its first read");
        }
    }

    /// Pressure lines are stamped the same way: a line's first byte bounds it.
    #[test]
    fn pressure_lines_are_stamped_by_their_first_byte_too() {
        let mut reads = Vec::new();
        for k in 0..6u32 {
            let mut line = Vec::new();
            encode_pressure_line(&mut line, 5000 + 50 * k, 1.0);
            // 1200 baud, 4 bytes per read: a 13-byte line takes 108 ms on the wire.
            reads.extend(on_the_wire(&line, 20.0 + 0.05 * f64::from(k), 1200.0, 4, 0.0));
        }
        let got = stamp_reads(&mut PressureDecoder::try_new(Some(50)).unwrap(), &reads);
        assert_eq!(got.len(), 6);
        for (k, (host_t_s, times)) in got.iter().enumerate() {
            let first_read = 20.0 + 0.05 * k as f64 + 4.0 * 10.0 / 1200.0;
            assert!((times.t_s - first_read).abs() < 1e-9, "line {k}: {times:?}");
            // Completed by its `\r`, in the third read, 67 ms after the first.
            assert!(host_t_s - times.t_s > 0.06, "line {k}");
        }
    }

    #[test]
    fn each_record_of_a_read_is_bounded_by_the_later_ones_of_its_device_run() {
        // The reader's decoder holds a partial line ("10") from the last read, at 1.0 s; the copy
        // starts from its state. The read at 2.0 s: that line's end, two more lines, the board's
        // restart (time back to 20 ms) and two lines of the new run.
        let mut reader = PressureDecoder::try_new(Some(50)).unwrap();
        let earlier = b"1000,0.5\n10";
        decode_all(&mut reader, earlier, |_| {});
        let mut copy = PressureDecoder::try_new(Some(50)).unwrap();
        copy.clone_from(&reader);
        let mut arrivals = Arrivals::new();
        arrivals.push(earlier.len(), 1.0);
        let bytes = b"50,0.5\n1100,0.5\n1150,0.5\n20,0.1\n70,0.1\n120,0.1\n";
        arrivals.push(bytes.len(), 2.0);
        let mut bounds = [0.0; 16];
        let n = run_bounds(&mut copy, bytes, earlier.len() as u64, &arrivals, &mut bounds);
        // 1050 (its first bytes read at 1.0 s), 1100, 1150; 20 is held (a restart must be
        // confirmed), 70 confirms it, then 120.
        assert_eq!(n, 5);
        let (old_run, new_run) = (2.0 - 1150.0 * 1e-3, 2.0 - 120.0 * 1e-3);
        assert_eq!(bounds[..n], [1.0 - 1050.0 * 1e-3, old_run, old_run, new_run, new_run]);
    }

    /// A board whose clock counts from its reset, rebooting for longer than its first run
    /// lasted: the new run's clock reads ahead of the old run's. Its frames, read together with
    /// the old run's last one, are stamped from their own run, not predicted from the old one.
    #[test]
    fn a_restart_whose_clock_reads_ahead_starts_a_new_run_in_a_read_and_in_the_map() {
        let frame = |c: u32, device_s: f64| {
            let mut b = Vec::new();
            encode_eit_frame(&mut b, c, (device_s * 1e6).round() as u32, &[0.25; 3]);
            b
        };
        // Old run: counters 0..=2 every 0.25 s from device 0, read 2 ms after each was sent at
        // host 10.0 + device time. Then 6 s of reboot: the new run's counter 0 at device 6.0 is
        // sent at host 16.75, and counter 1 at 6.25 at 17.0.
        let mut reads = vec![(frame(0, 0.0), 10.002), (frame(1, 0.25), 10.252)];
        // The reader starved: the old run's last frame and the new run's two come in one read.
        let mut burst = frame(2, 0.5);
        burst.extend(frame(0, 6.0));
        burst.extend(frame(1, 6.25));
        reads.push((burst, 17.002));
        let mut decoder = EitDecoder::new(3);
        let got = stamp_reads(&mut decoder, &reads);
        assert_eq!(decoder.stats().counter_resets, 1);
        let stamps: Vec<f64> = got.iter().map(|(_, t)| t.t_s).collect();
        assert_eq!(stamps.len(), 5);
        // The old run keeps its anchor (its late frame drifts by at most `MAX_DRIFT` x 0.25 s);
        // the new run is anchored by its own last record of the read (17.002 - 6.25), so its
        // first frame is 0.25 s before it. Each is stamped about 2 ms after it was sent; without
        // the restart the new run's first frame came out 0.69 s early.
        for (got, want) in stamps.iter().zip([10.002, 10.252, 10.502, 16.752, 17.002]) {
            assert!((got - want).abs() <= 0.25 * super::super::stamp::MAX_DRIFT + 1e-9, "{stamps:?}");
        }
    }

    #[test]
    fn more_records_than_room_are_left_out_and_eit_frames_count_too() {
        let mut bytes = Vec::new();
        for c in 0..4u32 {
            encode_eit_frame(&mut bytes, c, 1000 * c, &[0.25; 3]);
        }
        let mut arrivals = Arrivals::new();
        arrivals.push(bytes.len(), 5.0);
        let mut bounds = [0.0; 7];
        assert_eq!(run_bounds(&mut EitDecoder::new(3), &bytes, 0, &arrivals, &mut bounds), 3);
        // The fourth frame did not fit; the three noted end their run at the third.
        assert_eq!(bounds[..3], [5.0 - 2e-3; 3]);
    }
}
