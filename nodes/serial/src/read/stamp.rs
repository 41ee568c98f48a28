//! Host time stamps from device time: records get the times they were sent.
//!
//! One `read()` returns every byte the port buffered, so records that piled up (a reader starved
//! for a moment, the bytes a device sent while its port was being reopened) would all get the
//! time of that read; and a record that takes long on the wire (a 494-byte EIT frame is ~0.5 s
//! at 9600 baud) completes long after it was sent. For records that carry a device time (EIT
//! frames, pressure lines), [`ClockMap`] maps the device clock onto the host clock instead:
//!
//! - the offset `host - device` is estimated as the smallest `first-byte read time - device
//!   time` seen: a record's first byte is never received before the record is sent (its device
//!   time), so every record bounds the offset from above, and the read that returned its FIRST
//!   byte (`arrival.rs`) bounds it tighter than the read that completed it by the record's wire
//!   time. The reader decodes each read ahead, so a record's bound is also taken from the later
//!   records of its read (and of its device run), the tightest that read gives (`timer.rs`);
//! - a record's time is its device time plus that offset, so never later than the read of its
//!   first byte, and a burst keeps the device's spacing;
//! - the offset may grow by at most [`MAX_DRIFT`] per second of device time between records, so
//!   a device clock slower than the host's is followed (the smallest delay seen long ago would
//!   otherwise pin the estimate);
//! - the map re-anchors on that bound when the decoder saw the device restart (its counter or
//!   clock went back: the new run's clock says nothing about the old run's, even when it reads
//!   ahead of it, as a clock counting from a reset does after a long reboot), when the device
//!   clock did not advance (a stuck clock) or when the record arrived more than
//!   [`MAX_BACKLOG_S`] later than the map predicts (a clock that does not match the host's);
//! - stamps never decrease, across restarts too.
//!
//! Limit: the delay of the least delayed first byte is not known; stamps are late by that much:
//! the firmware's time from stamping to sending, one byte's wire time (1.04 ms at 9600 baud,
//! 0.09 ms at 115200), a UART bridge's latency timer (FTDI default 16 ms, CP210x and CH340 a
//! few ms), USB polling (1 ms) and the host's wake-up. A record whose first byte arrives
//! together with the end of the previous one (back-to-back records) is bounded by that read.

/// Largest growth of the estimated offset per second of device time. Crystal clocks disagree by
/// about 1e-4; 1e-2 also follows a poor RC oscillator. Between two records that arrive with the
/// usual delay the estimate moves with them; the bound matters only inside a burst, whose
/// stamps it shifts by at most 1 % of the burst's span.
pub const MAX_DRIFT: f64 = 1e-2;

/// A record that arrives this much later than the map predicts re-anchors it, s: no backlog of a
/// working link is this old (a reconnect reopens the port within `backoff_max_s`), so the device
/// clock and the host clock no longer agree.
pub const MAX_BACKLOG_S: f64 = 10.0;

/// Maps device time onto host time (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct ClockMap {
    /// Estimated host time minus device time, s; `None` before the first record.
    offset_s: Option<f64>,
    last_device_s: f64,
    last_stamp_s: f64,
    anchors: u64,
}

impl ClockMap {
    /// A map with no record seen yet.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// The host time of a record sent at `device_s` (device clock) whose first byte was returned
    /// by a read at `first_read_s` (host clock), where `bound_s` is the tightest offset bound the
    /// records of its read in the same device run give (at most `first_read_s - device_s`, its
    /// own), and `new_run` whether the decoder found it the first record of a new device run
    /// (a restart): at most `first_read_s`, and never before an earlier record's stamp.
    pub fn stamp(&mut self, first_read_s: f64, device_s: f64, bound_s: f64, new_run: bool) -> f64 {
        let own = first_read_s - device_s;
        let bound = bound_s.min(own);
        let offset = match self.offset_s {
            Some(o) if device_s > self.last_device_s && !new_run => {
                let grown = o + MAX_DRIFT * (device_s - self.last_device_s);
                if bound - grown > MAX_BACKLOG_S {
                    self.anchors += 1;
                    bound
                } else {
                    grown.min(bound)
                }
            }
            _ => {
                self.anchors += 1;
                bound
            }
        };
        self.offset_s = Some(offset);
        self.last_device_s = device_s;
        // `offset <= own`, so this is at most `first_read_s`; at its own bound it is
        // `first_read_s` exactly (the sum would round).
        let stamp = if offset >= own { first_read_s } else { (device_s + offset).min(first_read_s) };
        let stamp = stamp.max(self.last_stamp_s);
        self.last_stamp_s = stamp;
        stamp
    }

    /// Times the map was anchored on a record's read time (the first record included).
    #[cfg(test)]
    fn anchors(&self) -> u64 {
        self.anchors
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `stamp` as the reader calls it for a read at `read_s` of whole records, `tail_s` the
    /// device time of the last record of the read in the same run.
    fn tail(m: &mut ClockMap, read_s: f64, device_s: f64, tail_s: f64) -> f64 {
        m.stamp(read_s, device_s, read_s - tail_s.max(device_s), false)
    }

    #[test]
    fn a_burst_keeps_the_device_spacing_once_anchored() {
        let mut m = ClockMap::new();
        // Device clock 1000 s ahead of the host; records every 50 ms, 2 ms transmission delay.
        let stamps: Vec<f64> = (0..4)
            .map(|k| tail(&mut m, 10.0 + 0.05 * k as f64 + 0.002, 1010.0 + 0.05 * k as f64, 1010.0 + 0.05 * k as f64))
            .collect();
        for (k, s) in stamps.iter().enumerate() {
            assert!((s - (10.002 + 0.05 * k as f64)).abs() < 1e-9, "{k}: {s}");
        }
        // The reader starved: the next five records come back in one read at 10.6 s.
        // The reader decoded the read ahead: the last record of the burst was sent at 1010.40.
        let burst: Vec<f64> = (4..9).map(|k| tail(&mut m, 10.6, 1010.0 + 0.05 * k as f64, 1010.4)).collect();
        for (i, s) in burst.iter().enumerate() {
            let k = (i + 4) as f64;
            let drift = MAX_DRIFT * 0.05 * (i + 1) as f64;
            assert!((s - (10.002 + 0.05 * k)).abs() <= drift + 1e-9, "burst record {i}: {s}");
            assert!(*s <= 10.6);
        }
        assert!(burst.windows(2).all(|w| w[1] > w[0]), "{burst:?}");
        assert_eq!(m.anchors(), 1);
    }

    #[test]
    fn the_backlog_of_a_restarted_device_is_spread_back_from_the_last_record_of_its_read() {
        let mut m = ClockMap::new();
        tail(&mut m, 1.0, 500.0, 500.0);
        tail(&mut m, 1.5, 500.5, 500.5);
        // The board restarted while unplugged; the port reopens at 9.0 s and one read returns
        // the five lines it sent since (device times 0.1 .. 0.5 s).
        let burst: Vec<f64> = (1..=5).map(|k| tail(&mut m, 9.0, 0.1 * k as f64, 0.5)).collect();
        for (k, s) in burst.iter().enumerate() {
            assert!((s - (8.6 + 0.1 * k as f64)).abs() < 1e-9, "record {k}: {s}");
        }
        assert_eq!(burst[4], 9.0, "the last record of the read is stamped at the read");
        assert_eq!(m.anchors(), 2);
        // Stamps never go back, even from a tail that says a record is older than the last one.
        let s = tail(&mut m, 9.05, 0.01, 0.01);
        assert_eq!(s, 9.05);
        let s = tail(&mut m, 9.06, 0.02, 30.0);
        assert!(s >= 9.05, "{s}");
    }

    #[test]
    fn the_offset_follows_the_least_delayed_record_and_never_stamps_after_the_read() {
        let mut m = ClockMap::new();
        // The first record arrived 300 ms late; the next on time: the estimate moves down to it.
        assert_eq!(tail(&mut m, 5.3, 100.0, 100.0), 5.3);
        let s = tail(&mut m, 5.51, 100.5, 100.5);
        assert!((s - 5.51).abs() < 1e-12, "{s}");
        // Later records never get a time after their read, whatever the jitter.
        let mut last = s;
        for (k, delay) in [0.004, 0.0, 0.03, 0.001, 0.2, 0.0].iter().enumerate() {
            let device = 101.0 + 0.5 * k as f64;
            let read = device - 95.0 + delay;
            let s = tail(&mut m, read, device, device);
            assert!(s <= read && s >= last, "record {k}: stamp {s}, read {read}, last {last}");
            last = s;
        }
    }

    #[test]
    fn a_device_clock_slower_than_the_host_is_followed() {
        let mut m = ClockMap::new();
        // The device clock runs 0.5 % slow; every record arrives 1 ms after it was sent.
        let mut worst: f64 = 0.0;
        for k in 0..2000 {
            let host_sent = 0.05 * k as f64;
            let s = tail(&mut m, host_sent + 0.001, host_sent * 0.995, host_sent * 0.995);
            worst = worst.max((s - host_sent).abs());
        }
        assert!(worst <= 0.001 + 1e-9, "worst error {worst}");
        assert_eq!(m.anchors(), 1);
    }

    #[test]
    fn a_restart_a_stuck_clock_or_a_clock_far_off_reanchors() {
        let mut m = ClockMap::new();
        tail(&mut m, 1.0, 500.0, 500.0);
        tail(&mut m, 1.5, 500.5, 500.5);
        // Restart: device time back to 0.2 s; stamped at its read.
        assert_eq!(tail(&mut m, 9.0, 0.2, 0.2), 9.0);
        assert_eq!(m.anchors(), 2);
        // A stuck clock: the same device time again.
        assert_eq!(tail(&mut m, 9.5, 0.2, 0.2), 9.5);
        assert_eq!(m.anchors(), 3);
        // 20 s later by the host than the device clock says: not a backlog.
        assert_eq!(tail(&mut m, 30.0, 0.7, 0.7), 30.0);
        assert_eq!(m.anchors(), 4);
        // The new anchor holds: a record 0.5 s later by both clocks.
        assert!((tail(&mut m, 30.5, 1.2, 1.2) - 30.5).abs() < 1e-12);
        assert_eq!(m.anchors(), 4);
    }

    /// A board that ran 0.5 s, then rebooted for 6 s with its clock counting from the reset:
    /// its first record of the new run reads 6.0 s, ahead of the old run's 0.5 s. Predicted from
    /// the old anchor (and its drift allowance) it would be stamped 0.55 s early, by about the old
    /// run's length (within `MAX_BACKLOG_S`, so not caught as a backlog); told of the restart,
    /// the map stamps it at its read.
    #[test]
    fn a_restart_whose_clock_reads_ahead_of_the_old_run_reanchors_too() {
        let mut m = ClockMap::new();
        tail(&mut m, 10.0, 0.0, 0.0);
        tail(&mut m, 10.5, 0.5, 0.5);
        let unflagged = m.clone().stamp(16.6, 6.0, 16.6 - 6.0, false);
        assert!((unflagged - 16.055).abs() < 1e-9, "{unflagged}");
        assert_eq!(m.stamp(16.6, 6.0, 16.6 - 6.0, true), 16.6);
        assert_eq!(m.anchors(), 2);
        // The new run continues from the new anchor.
        assert!((tail(&mut m, 16.7, 6.1, 6.1) - 16.7).abs() < 1e-12);
        assert_eq!(m.anchors(), 2);
    }
}
