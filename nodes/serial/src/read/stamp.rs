//! Host time stamps from device time: records that arrive together get the times they were sent.
//!
//! One `read()` returns every byte the port buffered, so records that piled up (a reader starved
//! for a moment, the bytes a device sent while its port was being reopened) would all get the
//! time of that read. For records that carry a device time (EIT frames, pressure lines),
//! [`ClockMap`] maps the device clock onto the host clock instead:
//!
//! - the offset `host - device` is estimated as the smallest `read time - device time` seen, i.e.
//!   from the records that arrived with the least delay (a record is never received before it is
//!   sent, so every record bounds the offset from above). The reader decodes each read ahead, so
//!   a record's bound is taken from the last record of its read (and of its device run): the
//!   tightest one that read gives;
//! - a record's time is its device time plus that offset, so never later than its read time, and
//!   a burst keeps the device's spacing;
//! - the offset may grow by at most [`MAX_DRIFT`] per second of device time between records, so
//!   a device clock slower than the host's is followed (the smallest delay seen long ago would
//!   otherwise pin the estimate);
//! - the map re-anchors on that bound (the last record of the read gets its read time, the
//!   records before it their device spacing back from it) when the device clock did not advance
//!   (a device restart, a stuck clock) or when the record arrived more than [`MAX_BACKLOG_S`]
//!   later than the map predicts (a clock that does not match the host's);
//! - stamps never decrease, across restarts too.
//!
//! Limit: the delay of the least delayed record is not known; stamps are late by that much (the
//! transmission time of a record, plus USB or pty latency), the same as read time stamps.

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

    /// The host time of a record sent at `device_s` (device clock) and returned by a read at
    /// `read_s` (host clock), where `tail_s` is the device time of the last record of that read
    /// in the same device run (`device_s` itself when it is the last, or unknown): at most
    /// `read_s`, and never before an earlier record's stamp.
    pub fn stamp(&mut self, read_s: f64, device_s: f64, tail_s: f64) -> f64 {
        // The last record of the read was sent at or before the read: so was this one, its
        // device spacing earlier.
        let bound = read_s - tail_s.max(device_s);
        let offset = match self.offset_s {
            Some(o) if device_s > self.last_device_s => {
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
        // `offset <= bound`, so this is at most `read_s`; for the last record at the bound it
        // is `read_s` exactly (the sum would round).
        let stamp = if offset >= bound && tail_s <= device_s { read_s } else { (device_s + offset).min(read_s) };
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

    #[test]
    fn a_burst_keeps_the_device_spacing_once_anchored() {
        let mut m = ClockMap::new();
        // Device clock 1000 s ahead of the host; records every 50 ms, 2 ms transmission delay.
        let stamps: Vec<f64> = (0..4)
            .map(|k| m.stamp(10.0 + 0.05 * k as f64 + 0.002, 1010.0 + 0.05 * k as f64, 1010.0 + 0.05 * k as f64))
            .collect();
        for (k, s) in stamps.iter().enumerate() {
            assert!((s - (10.002 + 0.05 * k as f64)).abs() < 1e-9, "{k}: {s}");
        }
        // The reader starved: the next five records come back in one read at 10.6 s.
        // The reader decoded the read ahead: the last record of the burst was sent at 1010.40.
        let burst: Vec<f64> = (4..9).map(|k| m.stamp(10.6, 1010.0 + 0.05 * k as f64, 1010.4)).collect();
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
        m.stamp(1.0, 500.0, 500.0);
        m.stamp(1.5, 500.5, 500.5);
        // The board restarted while unplugged; the port reopens at 9.0 s and one read returns
        // the five lines it sent since (device times 0.1 .. 0.5 s).
        let burst: Vec<f64> = (1..=5).map(|k| m.stamp(9.0, 0.1 * k as f64, 0.5)).collect();
        for (k, s) in burst.iter().enumerate() {
            assert!((s - (8.6 + 0.1 * k as f64)).abs() < 1e-9, "record {k}: {s}");
        }
        assert_eq!(burst[4], 9.0, "the last record of the read is stamped at the read");
        assert_eq!(m.anchors(), 2);
        // Stamps never go back, even from a tail that says a record is older than the last one.
        let s = m.stamp(9.05, 0.01, 0.01);
        assert_eq!(s, 9.05);
        let s = m.stamp(9.06, 0.02, 30.0);
        assert!(s >= 9.05, "{s}");
    }

    #[test]
    fn the_offset_follows_the_least_delayed_record_and_never_stamps_after_the_read() {
        let mut m = ClockMap::new();
        // The first record arrived 300 ms late; the next on time: the estimate moves down to it.
        assert_eq!(m.stamp(5.3, 100.0, 100.0), 5.3);
        let s = m.stamp(5.51, 100.5, 100.5);
        assert!((s - 5.51).abs() < 1e-12, "{s}");
        // Later records never get a time after their read, whatever the jitter.
        let mut last = s;
        for (k, delay) in [0.004, 0.0, 0.03, 0.001, 0.2, 0.0].iter().enumerate() {
            let device = 101.0 + 0.5 * k as f64;
            let read = device - 95.0 + delay;
            let s = m.stamp(read, device, device);
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
            let s = m.stamp(host_sent + 0.001, host_sent * 0.995, host_sent * 0.995);
            worst = worst.max((s - host_sent).abs());
        }
        assert!(worst <= 0.001 + 1e-9, "worst error {worst}");
        assert_eq!(m.anchors(), 1);
    }

    #[test]
    fn a_restart_a_stuck_clock_or_a_clock_far_off_reanchors() {
        let mut m = ClockMap::new();
        m.stamp(1.0, 500.0, 500.0);
        m.stamp(1.5, 500.5, 500.5);
        // Restart: device time back to 0.2 s; stamped at its read.
        assert_eq!(m.stamp(9.0, 0.2, 0.2), 9.0);
        assert_eq!(m.anchors(), 2);
        // A stuck clock: the same device time again.
        assert_eq!(m.stamp(9.5, 0.2, 0.2), 9.5);
        assert_eq!(m.anchors(), 3);
        // 20 s later by the host than the device clock says: not a backlog.
        assert_eq!(m.stamp(30.0, 0.7, 0.7), 30.0);
        assert_eq!(m.anchors(), 4);
        // The new anchor holds: a record 0.5 s later by both clocks.
        assert!((m.stamp(30.5, 1.2, 1.2) - 30.5).abs() < 1e-12);
        assert_eq!(m.anchors(), 4);
    }
}
