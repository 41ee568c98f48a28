//! Pressure board line decoder: `t_ms,kPa` lines from the Teensy at 20 Hz.
//!
//! `t_ms` is the board's `millis()` (wrapping u32), unwrapped to seconds; `kPa` is gauge
//! pressure. Lines carry no checksum, so the time stamp is the integrity check: a line whose time
//! does not advance by 1..=`max_jump_ms` from the last accepted one (two lines merged by a lost
//! line end, a repeat, a restart) is held back as a bad line; the next line is judged against it
//! too, and a stream continuing from it is a device restart (`counter_resets`). With a period,
//! gaps over 1.5 periods count round(gap / period) - 1 lost samples, and at a restart the lines
//! rejected since the last accepted one (among them the held first line of the new run) count as
//! lost too. A wrong digit that keeps the time plausible is undetectable.

use super::line::MAX_LINE_LEN;
use super::line::{LineSplitter, parse_finite};
use super::{Decode, DecodeStats, Hint, PeriodMedian, Step};
use crate::error::ParamError;

/// Default largest forward time step accepted without confirmation, ms (200 periods at 20 Hz).
pub const DEFAULT_MAX_JUMP_MS: u32 = 10_000;

/// One decoded pressure sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureReading {
    /// Device time stamp as sent, ms on the board's wrapping u32 clock.
    pub device_time_ms: u32,
    /// Device time unwrapped across u32 wraps, seconds (restarts when the device restarts).
    pub device_t_s: f64,
    /// Gauge pressure, kPa.
    pub kpa: f64,
}

/// Incremental decoder of pressure lines.
#[derive(Debug)]
pub struct PressureDecoder {
    // Configuration
    period_ms: Option<u32>,
    max_jump_ms: u32,
    // Internal state
    lines: LineSplitter,
    reading: PressureReading,
    /// Time of the last accepted line.
    last_ms: Option<u32>,
    /// Time of the last line rejected as implausible, awaiting confirmation.
    held_ms: Option<u32>,
    /// The stream was interrupted: the next line is accepted whatever its time.
    rebase: bool,
    epoch_ms: u64,
    /// `bad_lines` when the last line was accepted (the lines rejected since are pending).
    bad_at_accept: u64,
    /// Device-time steps between accepted lines of one run, s (not per sample: a step over a
    /// lost line is two periods, and a board at another rate shows here).
    steps: PeriodMedian,
}

/// `clone_from` reuses the line buffer (see `EitDecoder`'s `Clone`).
impl Clone for PressureDecoder {
    fn clone(&self) -> Self {
        Self { lines: self.lines.clone(), ..*self }
    }

    fn clone_from(&mut self, source: &Self) {
        let mut lines = std::mem::replace(&mut self.lines, LineSplitter::empty());
        lines.clone_from(&source.lines);
        *self = Self { lines, ..*source };
    }
}

impl PressureDecoder {
    /// A decoder; `period_ms` is the board's sample period (50 for 20 Hz), used to count lost
    /// samples from time-stamp gaps (`None`: no loss accounting). Time steps up to
    /// [`DEFAULT_MAX_JUMP_MS`] are accepted directly.
    ///
    /// # Errors
    /// [`ParamError::Positive`] if `period_ms` is `Some(0)`.
    pub fn try_new(period_ms: Option<u32>) -> Result<Self, ParamError> {
        Self::with_max_jump(period_ms, DEFAULT_MAX_JUMP_MS)
    }

    /// Like [`PressureDecoder::try_new`] with the largest directly accepted time step, ms.
    ///
    /// # Errors
    /// [`ParamError::Positive`] if `period_ms` is `Some(0)` or `max_jump_ms` is 0.
    pub fn with_max_jump(period_ms: Option<u32>, max_jump_ms: u32) -> Result<Self, ParamError> {
        if period_ms == Some(0) {
            return Err(ParamError::Positive { param: "period_ms", got: 0 });
        }
        if max_jump_ms == 0 {
            return Err(ParamError::Positive { param: "max_jump_ms", got: 0 });
        }
        Ok(Self {
            period_ms,
            max_jump_ms,
            lines: LineSplitter::new(),
            reading: PressureReading { device_time_ms: 0, device_t_s: 0.0, kpa: 0.0 },
            last_ms: None,
            held_ms: None,
            rebase: false,
            epoch_ms: 0,
            bad_at_accept: 0,
            steps: PeriodMedian::default(),
        })
    }
}

/// Parses `t_ms,kPa`.
fn parse_line(line: &[u8]) -> Option<(u32, f64)> {
    let comma = line.iter().position(|&b| b == b',')?;
    let (t, kpa) = (&line[..comma], &line[comma + 1..]);
    if t.is_empty() || !t.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let t_ms = std::str::from_utf8(t).ok()?.parse::<u32>().ok()?;
    Some((t_ms, parse_finite(kpa)?))
}

/// Whether `t` follows `from` by a plausible forward step (wrapping).
fn follows(from: u32, t: u32, max_jump_ms: u32) -> bool {
    (1..=max_jump_ms).contains(&t.wrapping_sub(from))
}

impl PressureDecoder {
    /// Judges a parsed line; true if accepted (then `reading` holds it).
    fn judge(&mut self, t_ms: u32, kpa: f64, stats: &mut DecodeStats) -> bool {
        match self.last_ms {
            Some(last) if follows(last, t_ms, self.max_jump_ms) => {
                if t_ms < last {
                    self.epoch_ms += 1 << 32;
                }
                let d = t_ms.wrapping_sub(last);
                self.steps.push(f64::from(d) * 1e-3);
                if let Some(p) = self.period_ms
                    && 2 * u64::from(d) > 3 * u64::from(p)
                {
                    let periods = (u64::from(d) + u64::from(p) / 2) / u64::from(p);
                    stats.lost_frames += periods - 1;
                }
            }
            Some(_) if self.rebase => self.restarted(stats),
            Some(_) => {
                let confirmed = self.held_ms.is_some_and(|h| follows(h, t_ms, self.max_jump_ms));
                if !confirmed {
                    self.held_ms = Some(t_ms);
                    return false;
                }
                self.restarted(stats);
            }
            None => {}
        }
        self.bad_at_accept = stats.bad_lines;
        self.last_ms = Some(t_ms);
        self.held_ms = None;
        self.rebase = false;
        self.reading =
            PressureReading { device_time_ms: t_ms, device_t_s: (self.epoch_ms + u64::from(t_ms)) as f64 * 1e-3, kpa };
        true
    }
}

impl PressureDecoder {
    /// The device restarted: its clock starts again, and the lines rejected since the last
    /// accepted one (with a period) are lost, as no gap of the new run can include them.
    fn restarted(&mut self, stats: &mut DecodeStats) {
        stats.counter_resets += 1;
        self.epoch_ms = 0;
        if self.period_ms.is_some() {
            stats.lost_frames += stats.bad_lines - self.bad_at_accept;
        }
    }
}

impl Decode for PressureDecoder {
    type Record<'a> = PressureReading;

    const RECORD_NAME: &'static str = "pressure line";
    const TIMED: bool = true;

    fn step(&mut self, bytes: &[u8]) -> Step {
        // The splitter is moved out for the call so `judge` can borrow the rest of `self`.
        let mut lines = std::mem::replace(&mut self.lines, LineSplitter::empty());
        let step = lines.step(bytes, |line, stats| match parse_line(line) {
            Some((t_ms, kpa)) => self.judge(t_ms, kpa, stats),
            None => false,
        });
        self.lines = lines;
        step
    }

    fn record(&self) -> PressureReading {
        self.reading
    }

    fn skip_to_record_start(&mut self) {
        self.lines.skip_partial_line();
    }

    fn reset(&mut self) {
        self.lines.reset();
        self.rebase = true;
    }

    fn stats(&self) -> &DecodeStats {
        &self.lines.stats
    }

    fn device_time_s(&self) -> Option<f64> {
        Some(self.reading.device_t_s)
    }

    fn record_span(&self) -> usize {
        self.lines.span()
    }

    /// Median device-time step between lines of one run.
    fn measured_period_s(&self) -> Option<f64> {
        self.steps.median_s()
    }

    /// Lines that never end; or steps consistently a multiple (>= 2) of `period_ms`, which
    /// count as lost samples each: the board runs slower than `period_ms` says.
    fn hint(&self) -> Option<Hint> {
        let s = &self.lines.stats;
        if s.long_lines > 0 {
            return Some(Hint::LongLines { long_lines: s.long_lines, max_len: MAX_LINE_LEN });
        }
        let period_ms = self.period_ms?;
        let measured_ms = self.steps.median_s()? * 1e3;
        let ratio = measured_ms / f64::from(period_ms);
        let near_integer = (ratio - ratio.round()).abs() <= 0.1;
        (s.lost_frames > 0 && ratio.round() >= 2.0 && near_integer && self.steps.consistent(0.1))
            .then_some(Hint::PeriodMultiple { measured_ms, period_ms })
    }

    /// With a period, the gaps (`lost_frames`); without, every bad line (no gap to place it in).
    fn records_lost(&self) -> u64 {
        let s = &self.lines.stats;
        if self.period_ms.is_some() { s.lost_frames } else { s.bad_lines }
    }

    fn rejected_pending(&self) -> u64 {
        if self.period_ms.is_some() { self.lines.stats.bad_lines - self.bad_at_accept } else { 0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::decode_all;

    fn decode(d: &mut PressureDecoder, bytes: &[u8]) -> Vec<(u32, f64)> {
        let mut got = Vec::new();
        decode_all(d, bytes, |r| got.push((r.device_time_ms, r.kpa)));
        got
    }

    #[test]
    fn lines_with_and_without_cr() {
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        let got = decode(&mut d, b"0,0.5\r\n50,-1.25\n100,  2\r\n");
        assert_eq!(got, vec![(0, 0.5), (50, -1.25), (100, 2.0)]);
        assert_eq!(*d.stats(), DecodeStats { frames: 3, ..DecodeStats::default() });
    }

    /// After the input was cleared under "600050,101.3", the tail "050,101.3" would read as a
    /// line at 50 ms and the next one as a restart; it is skipped, uncounted as bad or lost.
    #[test]
    fn the_tail_of_a_cleared_line_is_skipped() {
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        d.skip_to_record_start();
        let got = decode(&mut d, b"050,101.3\r\n600100,101.4\r\n600150,101.5\r\n");
        assert_eq!(got, vec![(600100, 101.4), (600150, 101.5)]);
        let s = d.stats();
        assert_eq!((s.bad_lines, s.counter_resets, d.records_lost(), s.discarded_bytes), (0, 0, 0, 11));
    }

    #[test]
    fn garbage_and_bad_lines_are_counted_and_resync_at_newline() {
        let mut d = PressureDecoder::try_new(None).unwrap();
        let got = decode(&mut d, b"\x00\xffjunk\n1,nan\n2,inf\n,3\n4,1e3\n\r\n5,1.5\r\n");
        assert_eq!(got, vec![(5, 1.5)]);
        let s = d.stats();
        assert_eq!(s.bad_lines, 5);
        assert_eq!(s.discarded_bytes, 7 + 6 + 6 + 3 + 6 + 2);
    }

    #[test]
    fn overlong_line_is_skipped_whole() {
        let mut d = PressureDecoder::try_new(None).unwrap();
        let mut bytes = vec![b'9'; 200];
        bytes.extend_from_slice(b",1\n7,2\n");
        let got = decode(&mut d, &bytes);
        assert_eq!(got, vec![(7, 2.0)]);
        assert_eq!((d.stats().bad_lines, d.stats().discarded_bytes), (1, 203));
    }

    #[test]
    fn gaps_count_lost_samples_and_backwards_time_is_a_restart() {
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        let got = decode(&mut d, b"0,1\n50,1\n200,1\n260,1\n10,1\n60,1\n110,1\n");
        // 10 goes back: held as a bad line until 60 confirms the restart; then it is lost (2 in
        // the gap 50 -> 200, and the held line).
        assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![0, 50, 200, 260, 60, 110]);
        let s = d.stats();
        assert_eq!((s.lost_frames, s.counter_resets, s.bad_lines), (3, 1, 1));
        assert_eq!((d.records_lost(), d.rejected_pending()), (3, 0));
    }

    #[test]
    fn merged_lines_with_implausible_time_are_rejected() {
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        // "1000,1.5\r\n" lost its tail and merged with "1050,...": t = 10001050 ms.
        let got = decode(&mut d, b"950,1\n10001050,2\n1100,3\n1150,4\n");
        assert_eq!(got, vec![(950, 1.0), (1100, 3.0), (1150, 4.0)]);
        let s = d.stats();
        assert_eq!((s.bad_lines, s.lost_frames, s.counter_resets), (1, 2, 0));
    }

    #[test]
    fn a_bad_line_is_pending_until_a_gap_counts_it_and_without_a_period_every_bad_line_is_lost() {
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        decode(&mut d, b"0,1\n50,1\n100,x\n");
        assert_eq!((d.records_lost(), d.rejected_pending()), (0, 1));
        decode(&mut d, b"150,1\n");
        assert_eq!((d.records_lost(), d.rejected_pending()), (1, 0));
        assert_eq!(d.device_time_s(), Some(0.15));

        let mut d = PressureDecoder::try_new(None).unwrap();
        decode(&mut d, b"0,1\n50,1\n100,x\n150,1\n");
        assert_eq!((d.records_lost(), d.rejected_pending(), d.stats().lost_frames), (1, 0, 0));
    }

    #[test]
    fn after_reset_any_time_is_accepted() {
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        decode(&mut d, b"5000,1\n5050,1\n");
        d.reset();
        let got = decode(&mut d, b"20,1\n70,1\n");
        assert_eq!(got.len(), 2);
        assert_eq!((d.stats().counter_resets, d.stats().bad_lines), (1, 0));
    }

    #[test]
    fn millis_wrap_unwraps() {
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        let mut t = Vec::new();
        decode_all(&mut d, b"4294967270,1\n24,1\n", |r| t.push(r.device_t_s));
        assert_eq!(t[1], ((1u64 << 32) + 24) as f64 * 1e-3);
        assert_eq!(d.stats().lost_frames, 0);
    }

    #[test]
    fn zero_period_is_rejected() {
        assert!(PressureDecoder::try_new(Some(0)).is_err());
        assert!(PressureDecoder::with_max_jump(None, 0).is_err());
    }

    /// A 1 Hz board read with the default `period_ms = 50`: every step counts 19 lost samples,
    /// and the hint says `period_ms` may be wrong, with the measured period.
    #[test]
    fn a_board_slower_than_period_ms_is_hinted() {
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        let lines: String = (0..9).map(|k| format!("{},1.0\r\n", 1000 * k)).collect();
        decode(&mut d, lines.as_bytes());
        assert_eq!(d.stats().lost_frames, 8 * 19);
        assert_eq!(d.measured_period_s(), Some(1.0));
        let hint = d.hint().expect("a hint").to_string();
        assert!(hint.contains("consistently 1000 ms, about 20 x param `period_ms` (50 ms)"), "{hint}");

        // A 20 Hz board with a few lost lines: gaps, but not consistent ones; no hint.
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        decode(&mut d, b"0,1\n50,1\n150,1\n200,1\n250,1\n350,1\n400,1\n450,1\n");
        assert_eq!((d.stats().lost_frames, d.hint()), (2, None));
        // CR-only line ends work here too.
        let mut d = PressureDecoder::try_new(Some(50)).unwrap();
        assert_eq!(decode(&mut d, b"0,1.5\r50,2.5\r"), vec![(0, 1.5), (50, 2.5)]);
    }
}
