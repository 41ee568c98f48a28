//! Load-cell line decoder: force lines in newtons from the Sauter FH force gauge.
//!
//! A line is a decimal number with optional sign and surrounding spaces, optionally followed
//! by the unit `N` (e.g. `   12.345 N`). A number in another unit the gauge can print (`kgf`,
//! `lbf`, ...; [`OTHER_UNITS`]) is rejected as a bad line and counted in `wrong_unit_lines`, so
//! a gauge left in kgf or lbf mode is noticed (the warning names the unit) instead of read as
//! newtons. A bare number is taken as newtons: a gauge set to print no unit cannot be checked.
//! The force is reported as printed (compression positive when the gauge is set so); the line
//! carries no device time.

use super::line::{LineSplitter, MAX_LINE_LEN, parse_finite};
use super::{Decode, DecodeStats, Hint, Step};

/// Units of force gauges other than N, as they print them.
pub const OTHER_UNITS: [&str; 11] = ["kgf", "kg", "gf", "g", "lbf", "lb", "ozf", "oz", "kN", "mN", "daN"];

/// One decoded force reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceReading {
    /// Force as printed by the gauge, N.
    pub force_n: f64,
}

/// Incremental decoder of load-cell lines.
#[derive(Debug, Clone)]
pub struct ForceDecoder {
    lines: LineSplitter,
    reading: ForceReading,
    /// The last other unit seen (`wrong_unit_lines`).
    unit: Option<&'static str>,
}

impl Default for ForceDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl ForceDecoder {
    /// A decoder.
    #[must_use]
    pub fn new() -> Self {
        Self { lines: LineSplitter::new(), reading: ForceReading { force_n: 0.0 }, unit: None }
    }
}

/// Parses `<number>[ ]*[N]`.
fn parse_line(line: &[u8]) -> Option<f64> {
    let trimmed = line.trim_ascii_end();
    let number = trimmed.strip_suffix(b"N").unwrap_or(trimmed);
    parse_finite(number)
}

/// The unit of a line `<number>[ ]*<unit>` whose unit is one of [`OTHER_UNITS`].
fn other_unit(line: &[u8]) -> Option<&'static str> {
    let trimmed = line.trim_ascii_end();
    let at = trimmed.iter().rposition(|b| !b.is_ascii_alphabetic()).map_or(0, |p| p + 1);
    let (number, unit) = trimmed.split_at(at);
    let unit = OTHER_UNITS.iter().find(|u| u.as_bytes() == unit)?;
    parse_finite(number).map(|_| *unit)
}

impl Decode for ForceDecoder {
    type Record<'a> = ForceReading;

    const RECORD_NAME: &'static str = "force line";

    fn step(&mut self, bytes: &[u8]) -> Step {
        let Self { lines, reading, unit } = self;
        lines.step(bytes, |line, stats: &mut DecodeStats| match parse_line(line) {
            Some(force_n) => {
                reading.force_n = force_n;
                true
            }
            None => {
                if let Some(u) = other_unit(line) {
                    stats.wrong_unit_lines += 1;
                    *unit = Some(u);
                }
                false
            }
        })
    }

    fn record(&self) -> ForceReading {
        self.reading
    }

    fn skip_to_record_start(&mut self) {
        self.lines.skip_partial_line();
    }

    fn reset(&mut self) {
        self.lines.reset();
    }

    fn stats(&self) -> &DecodeStats {
        &self.lines.stats
    }

    /// Every bad line: force lines carry no sequence, so each rejected line is a lost reading.
    fn records_lost(&self) -> u64 {
        self.lines.stats.bad_lines
    }

    fn record_span(&self) -> usize {
        self.lines.span()
    }

    /// Another unit than N, else lines that never end.
    fn hint(&self) -> Option<Hint> {
        let s = &self.lines.stats;
        match self.unit {
            Some(unit) => Some(Hint::WrongUnit { unit, lines: s.wrong_unit_lines }),
            None => (s.long_lines > 0).then_some(Hint::LongLines { long_lines: s.long_lines, max_len: MAX_LINE_LEN }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::decode_all;

    #[test]
    fn accepts_newtons_rejects_other_units() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        decode_all(&mut d, b"   12.345 N\r\n-0.5\r\n+3N\n 1.0 kgf\r\n2.0 lbf\n N\n", |r| got.push(r.force_n));
        assert_eq!(got, vec![12.345, -0.5, 3.0]);
        assert_eq!(d.stats().bad_lines, 3);
    }

    #[test]
    fn partial_line_across_pushes_and_reset() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        decode_all(&mut d, b"  1.2", |r| got.push(r.force_n));
        decode_all(&mut d, b"50 N\r\n 9.9", |r| got.push(r.force_n));
        d.reset();
        decode_all(&mut d, b"8 N\n4 N\n", |r| got.push(r.force_n));
        assert_eq!(got, vec![1.25, 8.0, 4.0]);
        // The reset dropped " 9.9"; "8 N" is then a line of its own.
        assert_eq!(d.stats().discarded_bytes, 4);
    }

    /// After the port's input was cleared under a line, its tail ("345 N" of "12.345 N") is
    /// dropped, not read as 345 N, and not counted as a bad line (nor, through it, as a lost
    /// reading); the next line is read whole, even split across reads.
    #[test]
    fn the_tail_of_a_cleared_line_is_skipped() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        d.skip_to_record_start();
        decode_all(&mut d, b"345", |r| got.push(r.force_n));
        decode_all(&mut d, b" N\r\n 6.", |r| got.push(r.force_n));
        decode_all(&mut d, b"5 N\n", |r| got.push(r.force_n));
        assert_eq!(got, vec![6.5]);
        assert_eq!((d.stats().bad_lines, d.records_lost(), d.stats().discarded_bytes), (0, 0, 7));
    }

    /// A gauge whose lines end in CR only: every reading used to be lost, counted nowhere.
    #[test]
    fn cr_lf_and_crlf_all_end_lines_and_crlf_is_one_line_end() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        decode_all(&mut d, b"  1.5 N\r  2.5 N\r", |r| got.push(r.force_n));
        decode_all(&mut d, b"\n3.5 N\r", |r| got.push(r.force_n));
        decode_all(&mut d, b"\n4.5\n\n5.5 N\r\n", |r| got.push(r.force_n));
        assert_eq!(got, vec![1.5, 2.5, 3.5, 4.5, 5.5]);
        let s = d.stats();
        // The `\n` after `2.5 N\r` and `3.5 N\r` ends no empty line; `\n\n` does (1 byte).
        assert_eq!((s.bad_lines, s.discarded_bytes, d.records_lost()), (0, 1, 0));
        assert_eq!(d.record_span(), "5.5 N\r".len());
    }

    /// A line with no line end at all is counted bad (and lost) when it passes 64 bytes, its
    /// bytes discarded, and hinted at line ends; a line end then resynchronises.
    #[test]
    fn a_line_that_never_ends_is_counted_when_it_passes_the_bound() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        decode_all(&mut d, &[b'7'; 100], |r| got.push(r.force_n));
        let s = *d.stats();
        assert_eq!((s.bad_lines, s.long_lines, s.discarded_bytes, d.records_lost()), (1, 1, 100, 1));
        let hint = d.hint().expect("a hint").to_string();
        assert!(hint.contains("\\r, \\n or \\r\\n"), "{hint}");
        decode_all(&mut d, b"77\r1 N\r", |r| got.push(r.force_n));
        assert_eq!(got, vec![1.0]);
        assert_eq!((d.stats().bad_lines, d.stats().discarded_bytes), (1, 103));
        // The tail of a cleared line that never ends is an overlong line too.
        let mut d = ForceDecoder::new();
        d.skip_to_record_start();
        decode_all(&mut d, &[b' '; 70], |_| {});
        assert_eq!((d.stats().bad_lines, d.stats().long_lines, d.stats().discarded_bytes), (1, 1, 70));
    }

    #[test]
    fn a_gauge_in_another_unit_is_named() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        decode_all(&mut d, b"   1.020 kgf\r\n  -0.5 lbf\r\n  2 N\r\n 3 xyz\r\n", |r| got.push(r.force_n));
        assert_eq!(got, vec![2.0]);
        let s = d.stats();
        assert_eq!((s.bad_lines, s.wrong_unit_lines), (3, 2));
        let hint = d.hint().expect("a hint").to_string();
        assert!(hint.starts_with("2 lines in lbf, not N: set the gauge's unit to N"), "{hint}");
    }
}
