//! Link health while a reader runs: what to tell the user, and when.
//!
//! A wrong device, a wrong baud rate (both give bytes that never decode), a silent board and a
//! lossy link all look like "no data" downstream. [`LinkMonitor`] watches the reader's counters
//! and raises an [`Alert`] as soon as one of them shows:
//!
//! - [`Alert::NoRecord`]: bytes keep arriving and at least [`NO_RECORD_MIN_BYTES`] of them were
//!   discarded, but no record decoded for the monitor's window: once per such episode, again
//!   only after a record arrived;
//! - [`Alert::Silent`]: the reader counted a stall (no byte for `stall_after_s`);
//! - [`Alert::Disconnected`] / [`Alert::Reconnected`]: the port failed / was reopened;
//! - [`Alert::Restarted`]: the device restarted (its sequence or clock went back);
//! - [`Alert::Problems`]: a loss counter went up (CRC errors, torn or lost frames, wrong frame
//!   widths, bad lines): at once the first time, then at most every
//!   [`REPORT_EVERY_S`] while they keep going up, so a bad link is reported while the run goes on
//!   without flooding the log.
//!
//! Pure: times are passed in (seconds since the port was opened), so the rules are tested
//! without waiting. [`Counters`] formats the nonzero counters for these messages and the summary
//! at close.

use std::fmt;

use super::LinkStats;
use crate::decode::DecodeStats;

/// Discarded bytes without a record that make a "no valid record" episode: more than a stray
/// byte or a torn record at the start (a whole pressure line is about 20 bytes).
pub const NO_RECORD_MIN_BYTES: u64 = 64;

/// Shortest interval between two [`Alert::Problems`], s.
pub const REPORT_EVERY_S: f64 = 10.0;

/// Something the user should hear about now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Alert {
    /// `bytes` arrived (`discarded` of them not part of any record) and no record decoded in the
    /// last `for_s` seconds (since the port opened, when `since_open`): wrong device, baud rate
    /// or protocol.
    NoRecord { bytes: u64, discarded: u64, for_s: f64, since_open: bool },
    /// No byte for `for_s` seconds while the port stayed open (since it opened, when
    /// `since_open`); `stalls` so far.
    Silent { for_s: f64, since_open: bool, stalls: u64 },
    /// The port failed (read error, end of file, hang-up); the reader reopens it with backoff.
    Disconnected,
    /// The port was reopened `after_s` seconds after it failed.
    Reconnected { after_s: f64 },
    /// The device restarted (`counter_resets` went up to `restarts`).
    Restarted { restarts: u64 },
    /// Loss counters went up since the last report.
    Problems,
}

/// The counters whose increase is a loss worth reporting during the run.
fn losses(d: &DecodeStats) -> [u64; 5] {
    [d.crc_errors, d.torn_frames, d.lost_frames, d.length_mismatches, d.bad_lines]
}

/// Watches a reader's counters (see the module docs).
#[derive(Debug, Clone)]
pub struct LinkMonitor {
    // Configuration
    window_s: f64,
    // Internal state
    frames: u64,
    /// When the last record was seen (0: the port opening).
    record_s: f64,
    bytes_at_record: u64,
    discarded_at_record: u64,
    no_record_alerted: bool,
    bytes: u64,
    /// When the byte count last changed (0: the port opening).
    bytes_s: f64,
    stalls: u64,
    disconnects: u64,
    reconnects: u64,
    disconnected_s: f64,
    restarts: u64,
    reported: [u64; 5],
    report_s: Option<f64>,
}

impl LinkMonitor {
    /// A monitor for a port opened at time 0; `window_s` is how long bytes may arrive without a
    /// record before [`Alert::NoRecord`] (at least a few record periods).
    #[must_use]
    pub fn new(window_s: f64) -> Self {
        Self {
            window_s,
            frames: 0,
            record_s: 0.0,
            bytes_at_record: 0,
            discarded_at_record: 0,
            no_record_alerted: false,
            bytes: 0,
            bytes_s: 0.0,
            stalls: 0,
            disconnects: 0,
            reconnects: 0,
            disconnected_s: 0.0,
            restarts: 0,
            reported: [0; 5],
            report_s: None,
        }
    }

    /// Looks at the counters at `now_s` (seconds since the port opened) and calls `alert` for
    /// each thing to report. Allocation-free.
    pub fn observe(&mut self, now_s: f64, d: &DecodeStats, l: &LinkStats, mut alert: impl FnMut(Alert)) {
        if l.bytes != self.bytes {
            self.bytes = l.bytes;
            self.bytes_s = now_s;
        }
        if d.frames != self.frames {
            self.frames = d.frames;
            self.record_s = now_s;
            self.bytes_at_record = l.bytes;
            self.discarded_at_record = d.discarded_bytes;
            self.no_record_alerted = false;
        }
        let discarded = d.discarded_bytes - self.discarded_at_record;
        if !self.no_record_alerted && discarded >= NO_RECORD_MIN_BYTES && now_s - self.record_s >= self.window_s {
            self.no_record_alerted = true;
            alert(Alert::NoRecord {
                bytes: l.bytes - self.bytes_at_record,
                discarded,
                for_s: now_s - self.record_s,
                since_open: d.frames == 0,
            });
        }
        if l.stalls > self.stalls {
            self.stalls = l.stalls;
            alert(Alert::Silent { for_s: now_s - self.bytes_s, since_open: l.bytes == 0, stalls: l.stalls });
        }
        if l.disconnects > self.disconnects {
            self.disconnects = l.disconnects;
            self.disconnected_s = now_s;
            alert(Alert::Disconnected);
        }
        if l.reconnects > self.reconnects {
            self.reconnects = l.reconnects;
            alert(Alert::Reconnected { after_s: now_s - self.disconnected_s });
        }
        if d.counter_resets > self.restarts {
            self.restarts = d.counter_resets;
            alert(Alert::Restarted { restarts: d.counter_resets });
        }
        let losses = losses(d);
        if losses != self.reported && self.report_s.is_none_or(|t| now_s - t >= REPORT_EVERY_S) {
            self.reported = losses;
            self.report_s = Some(now_s);
            alert(Alert::Problems);
        }
    }
}

/// A reader's nonzero counters as `name=value` pairs in a fixed order (`no bytes` when none),
/// for log messages.
#[derive(Debug, Clone, Copy)]
pub struct Counters<'a> {
    pub decode: &'a DecodeStats,
    pub link: &'a LinkStats,
}

impl Counters<'_> {
    /// Whether anything was lost, rejected or went wrong on the link (what makes the summary at
    /// close a warning).
    #[must_use]
    pub fn lossy(&self) -> bool {
        let (d, l) = (self.decode, self.link);
        losses(d).iter().any(|&n| n > 0) || d.counter_resets + l.disconnects + l.failed_attempts + l.stalls > 0
    }
}

impl fmt::Display for Counters<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (d, l) = (self.decode, self.link);
        let all = [
            ("frames", d.frames),
            ("bytes", l.bytes),
            ("cleared_bytes", l.cleared_bytes),
            ("discarded_bytes", d.discarded_bytes),
            ("resyncs", d.resyncs),
            ("crc_errors", d.crc_errors),
            ("crc_byte_swapped", d.crc_byte_swapped),
            ("torn_frames", d.torn_frames),
            ("lost_frames", d.lost_frames),
            ("counter_resets", d.counter_resets),
            ("length_mismatches", d.length_mismatches),
            ("bad_lines", d.bad_lines),
            ("long_lines", d.long_lines),
            ("wrong_unit_lines", d.wrong_unit_lines),
            ("disconnects", l.disconnects),
            ("reconnects", l.reconnects),
            ("failed_attempts", l.failed_attempts),
            ("stalls", l.stalls),
        ];
        let mut first = true;
        for (name, n) in all.into_iter().filter(|&(_, n)| n > 0) {
            if !first {
                f.write_str(" ")?;
            }
            first = false;
            write!(f, "{name}={n}")?;
        }
        if first {
            f.write_str("no bytes")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(m: &mut LinkMonitor, now_s: f64, d: &DecodeStats, l: &LinkStats) -> Vec<Alert> {
        let mut got = Vec::new();
        m.observe(now_s, d, l, |a| got.push(a));
        got
    }

    #[test]
    fn garbage_without_a_record_is_reported_once_per_episode_after_the_window() {
        let mut m = LinkMonitor::new(2.0);
        let mut d = DecodeStats::default();
        let mut l = LinkStats::default();
        // Garbage at 2000 B/s, all of it discarded.
        for k in 1..=19 {
            let t = 0.1 * k as f64;
            (l.bytes, d.discarded_bytes) = (200 * k, 200 * k);
            assert!(run(&mut m, t, &d, &l).is_empty(), "before the window, at {t} s");
        }
        (l.bytes, d.discarded_bytes) = (4000, 4000);
        assert_eq!(
            run(&mut m, 2.0, &d, &l),
            vec![Alert::NoRecord { bytes: 4000, discarded: 4000, for_s: 2.0, since_open: true }]
        );
        (l.bytes, d.discarded_bytes) = (9000, 9000);
        assert!(run(&mut m, 4.5, &d, &l).is_empty(), "once per episode");
        // A record ends the episode; garbage without a record for another window starts one.
        d.frames = 1;
        assert!(run(&mut m, 5.0, &d, &l).is_empty());
        (l.bytes, d.discarded_bytes) = (9500, 9100);
        assert!(run(&mut m, 6.0, &d, &l).is_empty());
        assert_eq!(
            run(&mut m, 7.0, &d, &l),
            vec![Alert::NoRecord { bytes: 500, discarded: 100, for_s: 2.0, since_open: false }]
        );
    }

    #[test]
    fn a_slow_valid_stream_or_a_stray_byte_is_not_reported() {
        let mut m = LinkMonitor::new(2.0);
        let mut d = DecodeStats::default();
        let mut l = LinkStats::default();
        // One frame every 5 s, a 3-byte glitch between two of them.
        for k in 1..=5u64 {
            (l.bytes, d.frames) = (494 * k, k);
            assert!(run(&mut m, 5.0 * k as f64, &d, &l).is_empty());
        }
        (l.bytes, d.discarded_bytes) = (494 * 5 + 3, 3);
        assert!(run(&mut m, 28.0, &d, &l).is_empty());
    }

    #[test]
    fn a_stall_a_disconnect_and_a_reconnect_are_reported_when_the_reader_counts_them() {
        let mut m = LinkMonitor::new(2.0);
        let d = DecodeStats::default();
        let mut l = LinkStats { stalls: 1, ..LinkStats::default() };
        assert_eq!(run(&mut m, 2.05, &d, &l), vec![Alert::Silent { for_s: 2.05, since_open: true, stalls: 1 }]);
        assert!(run(&mut m, 3.0, &d, &l).is_empty());
        (l.bytes, l.stalls) = (100, 1);
        assert!(run(&mut m, 4.0, &d, &l).is_empty());
        l.stalls = 2;
        assert_eq!(run(&mut m, 6.5, &d, &l), vec![Alert::Silent { for_s: 2.5, since_open: false, stalls: 2 }]);
        l.disconnects = 1;
        assert_eq!(run(&mut m, 7.0, &d, &l), vec![Alert::Disconnected]);
        (l.reconnects, l.failed_attempts) = (1, 4);
        assert_eq!(run(&mut m, 8.25, &d, &l), vec![Alert::Reconnected { after_s: 1.25 }]);
    }

    #[test]
    fn losses_are_reported_at_once_then_at_most_every_interval() {
        let mut m = LinkMonitor::new(2.0);
        let mut d = DecodeStats { frames: 10, ..DecodeStats::default() };
        let l = LinkStats { bytes: 5000, ..LinkStats::default() };
        assert!(run(&mut m, 1.0, &d, &l).is_empty());
        d.crc_errors = 1;
        assert_eq!(run(&mut m, 1.5, &d, &l), vec![Alert::Problems]);
        d.lost_frames = 1;
        assert!(run(&mut m, 2.0, &d, &l).is_empty(), "within the interval");
        assert!(run(&mut m, 11.0, &d, &l).is_empty(), "within the interval");
        assert_eq!(run(&mut m, 11.5, &d, &l), vec![Alert::Problems], "the interval passed");
        assert!(run(&mut m, 30.0, &d, &l).is_empty(), "nothing new");
        d.bad_lines = 1;
        assert_eq!(run(&mut m, 30.1, &d, &l), vec![Alert::Problems]);
    }

    #[test]
    fn each_device_restart_is_reported_at_once() {
        let mut m = LinkMonitor::new(2.0);
        let mut d = DecodeStats { frames: 10, counter_resets: 1, ..DecodeStats::default() };
        let l = LinkStats { bytes: 5000, ..LinkStats::default() };
        assert_eq!(run(&mut m, 1.0, &d, &l), vec![Alert::Restarted { restarts: 1 }]);
        assert!(run(&mut m, 1.1, &d, &l).is_empty());
        (d.frames, d.counter_resets) = (11, 2);
        assert_eq!(run(&mut m, 1.2, &d, &l), vec![Alert::Restarted { restarts: 2 }]);
    }

    #[test]
    fn counters_list_every_nonzero_counter_in_order() {
        let d = DecodeStats {
            frames: 57,
            discarded_bytes: 1016,
            resyncs: 3,
            crc_errors: 1,
            lost_frames: 4,
            length_mismatches: 2,
            counter_resets: 1,
            ..DecodeStats::default()
        };
        let l = LinkStats { bytes: 29174, failed_attempts: 2, cleared_bytes: 9, ..LinkStats::default() };
        let c = Counters { decode: &d, link: &l };
        assert_eq!(
            c.to_string(),
            "frames=57 bytes=29174 cleared_bytes=9 discarded_bytes=1016 resyncs=3 crc_errors=1 lost_frames=4 \
             counter_resets=1 length_mismatches=2 failed_attempts=2"
        );
        assert!(c.lossy());
        let (d, l) = (DecodeStats::default(), LinkStats::default());
        let quiet = Counters { decode: &d, link: &l };
        assert_eq!(quiet.to_string(), "no bytes");
        assert!(!quiet.lossy());
    }
}
