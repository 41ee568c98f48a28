//! Pressure board line decoder: `t_ms,kPa` lines from the Teensy at 20 Hz.
//!
//! `t_ms` is the board's `millis()` (wrapping u32), unwrapped to seconds; `kPa` is gauge
//! pressure. With an expected period, time-stamp gaps longer than 1.5 periods count
//! round(gap / period) - 1 lost samples; a time stamp that repeats or goes back counts as a
//! device restart. Lines carry no checksum: a corrupted digit that still parses is undetectable.

use super::line::{LineSplitter, parse_finite};
use super::{Decode, DecodeStats, Step};
use crate::error::ParamError;

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
#[derive(Debug, Clone)]
pub struct PressureDecoder {
    // Configuration
    period_ms: Option<u32>,
    // Internal state
    lines: LineSplitter,
    reading: PressureReading,
    last_ms: Option<u32>,
    epoch_ms: u64,
}

impl PressureDecoder {
    /// A decoder; `period_ms` is the board's sample period (50 for 20 Hz), used to count lost
    /// samples from time-stamp gaps (`None`: no loss accounting).
    ///
    /// # Errors
    /// [`ParamError::Positive`] if `period_ms` is `Some(0)`.
    pub fn try_new(period_ms: Option<u32>) -> Result<Self, ParamError> {
        if period_ms == Some(0) {
            return Err(ParamError::Positive {
                param: "period_ms",
                got: 0,
            });
        }
        Ok(Self {
            period_ms,
            lines: LineSplitter::new(),
            reading: PressureReading {
                device_time_ms: 0,
                device_t_s: 0.0,
                kpa: 0.0,
            },
            last_ms: None,
            epoch_ms: 0,
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

impl Decode for PressureDecoder {
    type Record<'a> = PressureReading;

    fn step(&mut self, bytes: &[u8]) -> Step {
        let Self {
            period_ms,
            lines,
            reading,
            last_ms,
            epoch_ms,
        } = self;
        lines.step(bytes, |line, stats: &mut DecodeStats| {
            let Some((t_ms, kpa)) = parse_line(line) else {
                return false;
            };
            if let Some(last) = *last_ms {
                let d = t_ms.wrapping_sub(last);
                if d == 0 || d > i32::MAX as u32 {
                    stats.counter_resets += 1;
                    *epoch_ms = 0;
                } else {
                    if t_ms < last {
                        *epoch_ms += 1 << 32;
                    }
                    if let Some(p) = *period_ms
                        && 2 * u64::from(d) > 3 * u64::from(p)
                    {
                        let periods = (u64::from(d) + u64::from(p) / 2) / u64::from(p);
                        stats.lost_frames += periods - 1;
                    }
                }
            }
            *last_ms = Some(t_ms);
            *reading = PressureReading {
                device_time_ms: t_ms,
                device_t_s: (*epoch_ms + u64::from(t_ms)) as f64 * 1e-3,
                kpa,
            };
            true
        })
    }

    fn record(&self) -> PressureReading {
        self.reading
    }

    fn reset(&mut self) {
        self.lines.reset();
    }

    fn stats(&self) -> &DecodeStats {
        &self.lines.stats
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
        assert_eq!(
            *d.stats(),
            DecodeStats {
                frames: 3,
                ..DecodeStats::default()
            }
        );
    }

    #[test]
    fn garbage_and_bad_lines_are_counted_and_resync_at_newline() {
        let mut d = PressureDecoder::try_new(None).unwrap();
        let got = decode(
            &mut d,
            b"\x00\xffjunk\n1,nan\n2,inf\n,3\n4,1e3\n\r\n5,1.5\r\n",
        );
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
        decode(&mut d, b"0,1\n50,1\n200,1\n260,1\n10,1\n");
        let s = d.stats();
        assert_eq!((s.lost_frames, s.counter_resets), (2, 1));
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
    }
}
